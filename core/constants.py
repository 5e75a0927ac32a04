"""Named tolerances and defaults, in one place.

Each constant says why it has its value. Distances are in scene metres.
"""

#: Faces whose area is below this (m^2) are dropped as degenerate and counted in the report.
#: 1e-12 m^2 is a square of 1 micrometre: far below any architectural feature, far above the
#: rounding noise of float64 cross products of coordinates of order 1e3 m.
MIN_FACE_AREA = 1e-12

#: Reflectance must be below 1: rho = 1 makes (I - rho F) singular in a closed scene.
MAX_REFLECTANCE_EXCLUSIVE = 1.0

#: Hemicube near plane, as a fraction of the hemicube's half-width (which is 1): geometry nearer
#: than this along a face's axis is clipped away rather than projected to infinity.
HEMICUBE_NEAR = 1e-6

#: Offset of hemicube eyes and ray origins along the patch normal, relative to the scene's
#: bounding-box diagonal, so that a patch never sees itself or its coplanar neighbours.
SURFACE_OFFSET = 1e-7

#: Default stopping tolerance of the iterative solvers: relative residual (or unshot energy
#: relative to emitted energy for progressive refinement).
DEFAULT_TOLERANCE = 1e-4

#: Default iteration cap (sweeps for Jacobi/Gauss-Seidel; shots are capped at 50 x patches).
DEFAULT_MAX_ITERATIONS = 1000

#: Dense form-factor matrices are built only below this many bytes (float32 storage).
DEFAULT_MEMORY_BUDGET = 1 << 30

#: Crease angle (degrees) for corner colours: patches whose normals differ by more than this
#: from the corner's face are not averaged into it (room corners stay crisp).
DEFAULT_CREASE_ANGLE = 30.0

#: Progress and cancel are polled at least this often (seconds of work).
POLL_INTERVAL = 0.2

#: Largest hemicube resolution: the rasteriser's pixel indices of one chunk must be exact in
#: float32 (3 R^2 < 2^24).
MAX_RESOLUTION = 2048
