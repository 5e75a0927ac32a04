"""Named tolerances and defaults, in one place.

Each constant says why it has its value. Distances are in scene metres.
"""

from dataclasses import dataclass

#: Reflectance must be below 1: rho = 1 makes (I - rho F) singular in a closed scene.
MAX_REFLECTANCE_EXCLUSIVE = 1.0

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


@dataclass(frozen=True)
class Tolerances:
    """Every geometric tolerance of the core, in one place (read them as ``tol.name``).

    Lengths are relative to the local feature size or the scene's bounding diagonal where they
    guard geometry (see each comment); areas in m^2; cosines and barycentric slack unitless.
    """

    #: Offset of hemicube eyes and ray origins along the patch normal, relative to the scene's
    #: bounding-box diagonal, so that a patch never sees itself or its coplanar neighbours.
    surface_offset: float = 1e-7
    #: Hemicube near plane, as a fraction of the hemicube's half-width (which is 1): geometry nearer
    #: than this along a face's axis is clipped away rather than projected to infinity.
    hemicube_near: float = 1e-6
    #: Faces whose area is below this (m^2) are dropped as degenerate and counted in the report.
    #: 1e-12 m^2 is a square of 1 micrometre: far below any architectural feature, far above the
    #: rounding noise of float64 cross products of coordinates of order 1e3 m.
    face_area: float = 1e-12
    #: A vertex within this fraction of the scene's bounding diagonal from a plane lies in it (1 mm
    #: in a 10 m scene): an object placed on a floor by eye or by snapping touches it.
    contact: float = 1e-4
    #: Faces whose unit normals have |cos| above this are parallel: a coplanar neighbour (the next
    #: floor tile) or a parallel face (a table top above the floor) is not a contact.
    parallel_cos: float = 1.0 - 1e-6
    #: A polygon whose highest corner is below this fraction of its distance from the point,
    #: measured along the point's normal, lies in the point's tangent plane (or under it): F = 0.
    #: Without this, a coplanar polygon around the point would give the horizon's full winding (F =
    #: 1).
    coplanar: float = 1e-12
    #: Visibility rays count as unoccluded if their closest hit is at least this close (as a
    #: fraction of the segment) to the target point: the target itself may be reported as a coplanar
    #: neighbour hit at the same distance.
    visibility: float = 1e-7
    #: Turn (unit cross product of consecutive edges, along the normal) below which a quad corner
    #: counts as reflex. Slightly negative so that a straight corner (a quad with a vertex on an
    #: edge, turn 0 up to rounding) stays "convex": the bilinear grid handles it without folding.
    convex_turn: float = -1e-12
    #: Relative size (against the polygon's squared extent) below which an ear triangle counts as
    #: degenerate (collinear corners) in ear clipping: float64 rounding of 2-D cross products.
    ear_area: float = 1e-14
    #: Ears whose smallest angles differ by less than this (radians) tie in ear clipping, and the
    #: first in the polygon's corner order is clipped: float64 rounding of a regular n-gon's equal
    #: angles (~1e-15) must not decide, or the same polygon scaled or moved elsewhere is
    #: triangulated otherwise (tests/core/test_fuzz.py).
    ear_angle: float = 1e-9
    #: Edges whose lengths differ by less than this fraction tie for a triangle's shortest edge
    #: (the one its fan strip keeps coarse), and the first in the triangle's corner order wins:
    #: an isosceles triangle of a regular n-gon fans the same way wherever it stands.
    edge_tie: float = 1e-9
    #: Slack on the crease cosine: coplanar faces whose float64 normals differ by rounding (cos just
    #: below 1) must still join at crease_angle = 0.
    crease_cos: float = 1e-12
    #: A quad is drawn whole when its 4th corner lies within this fraction of its diagonal from the
    #: plane of the first three (else as two triangles): a 1e-6 warp moves its silhouette by far
    #: less than a pixel at any resolution allowed.
    planar: float = 1e-6
    #: Relative slack in ``ceil(length / max_edge)``: an edge whose length is a whole multiple of
    #: ``max_edge`` up to float64 rounding (0.3 / 0.1 = 2.9999999999999996, 1.2 / 0.4 =
    #: 3.0000000000000004) gets that multiple, not one segment more. Segments may thus exceed
    #: max_edge by 1e-9 relative.
    edge_count: float = 1e-9
    #: A ray counts as parallel to a triangle when |cos| of the angle between the ray and the
    #: plane's normal is below this; such rays never hit it (they would graze it at t = inf or
    #: everywhere).
    ray_parallel: float = 1e-12
    #: Barycentric slack: triangles are enlarged by this fraction of their edges, so that rounding
    #: can never open a crack along an edge shared by two triangles.
    barycentric: float = 1e-12
    #: Corner positions are matched after rounding to this fraction of the scene's size.
    point: float = 1e-9
    #: Blender hands over float32 coordinates: a vertex modelled on an edge or a line is off it by
    #: up to a few float32 roundings of the coordinates' magnitude (4 x 2**-23 of it; 1.4 cm at
    #: 30 km from the origin): the conformity pass (:mod:`core.hierarchy`) allows that much
    #: off an edge, near its line only (``ON_EDGE_SLANT``).
    float32: float = 4.0 * 2.0 ** -23


#: The tolerances (trimesh's ``tol``): ``from .constants import tol``.
tol = Tolerances()
