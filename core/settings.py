"""Bake settings: one table from which everything about a setting is derived.

Each :class:`Setting` row declares a setting once: its name, type, default, bounds or choices,
unit, a short label (fits Blender's default sidebar width) and a help text. From the table come

* :class:`BakeSettings` (a frozen dataclass; validation on construction, ``SettingsError`` naming
  the setting, the allowed range and the value that came);
* the add-on's panel properties (``radiosity_addon/props.py``), the batch script's command-line
  options (``radiosity_addon/batch.py``) and the report's settings block
  (``radiosity_addon/job.py``): every row with ``exposed=True``.

Adding a setting means adding a row here (and using it where it acts). Lengths (``unit='m'``) are
in scene metres: the add-on converts them from Blender units with the scene's unit scale.
"""

import dataclasses
from dataclasses import dataclass

from .constants import (DEFAULT_CREASE_ANGLE, DEFAULT_MAX_ITERATIONS, DEFAULT_MEMORY_BUDGET,
                        DEFAULT_TOLERANCE, MAX_RESOLUTION)
from .errors import SettingsError
from .validate import is_bool, is_int, is_real

#: Smallest memory_budget accepted (bytes): below this even a small room's rows do not fit.
MIN_MEMORY_BUDGET = 1 << 20


@dataclass(frozen=True)
class Choice:
    """One allowed value of a choice setting: the value, a short label and a help text."""

    value: object
    label: str
    help: str


@dataclass(frozen=True)
class Setting:
    """One row of the settings table.

    Attributes
    ----------
    name : str
        Python identifier (``BakeSettings`` field, panel property, ``--name-with-dashes`` option).
    type : {'float', 'int', 'bool', 'choice', 'bool_or_auto'}
    default : object
    label : str
        Short human words for the panel (at most :data:`MAX_LABEL` characters).
    help : str
        One or two sentences: the panel's tooltip and the ``--help`` text.
    unit : str
        ``'m'`` (a length: converted with the scene's unit scale), ``'deg'``, ``'px'``,
        ``'bytes'``, ``'x patch size'``, or ``''`` (a pure number).
    low, high : float or int, optional
        Bounds (``None``: unbounded on that side).
    open_low, open_high : bool
        The bound itself is excluded.
    even : bool
        Integers only: the value must be even.
    choices : tuple of Choice
        ``type='choice'`` only.
    soft : (float, float), optional
        The slider's range in the panel (the hard bounds still apply to typed values).
    digits : int, optional
        Decimals the panel shows.
    exposed : bool
        In the panel, the batch options and the report's settings block.
    auto : bool
        ``None`` is allowed and means "chosen by the bake" (the panel shows it as 0, the batch
        option takes ``auto``).
    doc : str
        More for the API documentation (why the default, what it costs).
    """

    name: str
    type: str
    default: object
    label: str
    help: str
    unit: str = ""
    low: object = None
    high: object = None
    open_low: bool = False
    open_high: bool = False
    even: bool = False
    choices: tuple = ()
    soft: tuple = None
    digits: int = None
    exposed: bool = False
    doc: str = ""
    auto: bool = False

    @property
    def is_length(self):
        return self.unit == "m"

    def values(self):
        """The allowed values of a choice setting."""
        return tuple(c.value for c in self.choices)

    def describe(self):
        """What a valid value is, for messages and help: 'a number in (0, 1)'."""
        if self.auto:
            return dataclasses.replace(self, auto=False).describe() + " or None (auto)"
        if self.type == "bool":
            return "True or False"
        if self.type == "bool_or_auto":
            return "True, False or 'auto'"
        if self.type == "choice":
            return "one of " + ", ".join(repr(v) for v in self.values())
        word = ("an even integer" if self.even else "an integer") if self.type == "int" \
            else "a number"
        if self.low is not None and self.high is not None:
            text = f"{word} in {'(' if self.open_low else '['}{self.low}, " \
                   f"{self.high}{')' if self.open_high else ']'}"
        elif self.low is not None:
            if self.type == "float":
                word = "a finite number"
            text = f"{word} {'>' if self.open_low else '>='} {self.low}"
        else:
            text = word
        return f"{text} ({self.unit})" if self.unit else text

    def valid(self, value):
        """True when ``value`` is allowed."""
        if value is None:
            return self.auto
        if self.type in ("bool", "bool_or_auto"):
            return is_bool(value) or (self.type == "bool_or_auto" and value == "auto")
        if self.type == "choice":
            return isinstance(value, str) and value in self.values()
        if not (is_int(value) if self.type == "int" else is_real(value)):
            return False
        if self.low is not None and (value <= self.low if self.open_low else value < self.low):
            return False
        if self.high is not None and (value >= self.high if self.open_high
                                      else value > self.high):
            return False
        return not (self.even and value % 2)

    def check(self, value):
        """Return ``value``, or raise SettingsError naming the setting, the range and the value."""
        if not self.valid(value):
            raise SettingsError(f"{self.name} must be {self.describe()}; got {value!r}")
        return value


#: Longest panel label (characters): about what Blender's default sidebar shows uncut.
MAX_LABEL = 15

METHODS = (
    Choice("hemicube", "Hemicube", "Cohen-Greenberg hemicube, made reciprocal (default: on the "
                                   "speed-accuracy front against Cycles)"),
    Choice("nusselt", "Hemisphere Base", "Nusselt analog (Doi & Itoh 1998): the scene "
                                         "projected onto the hemisphere's base, one pixel one "
                                         "weight, made reciprocal"),
    Choice("exact", "Exact", "Contour-integral form factors with ray-traced visibility: slow, "
                             "accurate"),
    Choice("hybrid", "Hybrid", "Hemicube, with near patch pairs computed exactly"),
    Choice("raytraced", "Ray Traced", "Wallace et al. 1989: rays from receiver points to samples "
                                      "on the source, each a small disc: slow, noisy near "
                                      "sources"),
)
EXACT_DIRECT = (
    Choice("auto", "Small", "Emitters too narrow for the hemicube (under 4 of its pixels "
           "seen from what they light: small lamps, downlights, LED strips)"),
    Choice("all", "All", "Every emitter (within the limits)"),
    Choice("off", "Off", "The hemicube sees every emitter"),
)
SOLVERS = (
    Choice("auto", "Auto", "Pick the solver from the scene size and memory budget"),
    Choice("direct", "Direct", "Dense linear solve: exact, small scenes only"),
    Choice("jacobi", "Jacobi", "Jacobi iterations"),
    Choice("gauss_seidel", "Gauss-Seidel", "Gauss-Seidel sweeps"),
    Choice("progressive", "Progressive", "Progressive refinement (shooting): no full matrix "
                                         "kept"),
)
CORNERS = (
    Choice("gather", "At Vertex", "Gather the solved light at every vertex: the value there, as "
           "Cycles bakes it (default; about one more hemicube per vertex)"),
    Choice("average", "Patch Average", "Average the patches around each vertex (Gouraud): free, "
           "but a patch mean, off next to lights, in corners and along shadow edges"),
)
OUTPUTS = (
    Choice("mesh", "Radiosity Mesh", "Each baked object gets the radiosity mesh: its faces "
           "subdivided where the light changes, colours at every vertex (the original mesh is "
           "kept; Clear Bake restores it)"),
    Choice("vertices", "Existing Vertices", "Colours only at the vertices you modelled (for "
           "pre-meshed assets); the report says how much the light varies inside your faces"),
)
SKIES = (
    Choice("world", "World", "The scene's world: a uniform colour seen in every direction no "
           "surface covers (or none)"),
    Choice("cie_overcast", "CIE Overcast", "CIE standard overcast sky, L = Lz (1 + 2 cos t) / 3 "
           "from the zenith (+Z up), nothing below the horizon; replaces the world"),
)

#: The settings table. Order: the panel's and the report's.
TABLE = (
    Setting("output_mode", "choice", "mesh", "Output", "What the bake writes", choices=OUTPUTS,
            exposed=True, doc="core.adaptive: the solve stays on the coarse patches; elements "
            "are receivers, refined where the light changes, conformed and gathered."),
    Setting("patch_size", "float", None, "Patch Size",
            "Largest patch edge of the solve; auto (0 in the panel): 1 m clamped to the "
            "scene's size for the radiosity mesh, 0.5 m for existing vertices", unit="m", low=0,
            open_low=True, soft=(0.01, 5.0), exposed=True, auto=True,
            doc="Auto for 'mesh': core.adaptive.coarse_patch_size, 1 m clamped to [diagonal / "
                "400, diagonal / 8] of the scene's bounding box."),
    Setting("method", "choice", "hemicube", "Form Factors", "How form factors are computed",
            choices=METHODS, exposed=True),
    Setting("resolution", "int", 64, "Resolution",
            "Hemicube resolution: pixels across the top face (even); 'nusselt': across the "
            "base square", unit="px", low=4,
            high=MAX_RESOLUTION, even=True, soft=(8, 512), exposed=True,
            doc=f"At most {MAX_RESOLUTION}: the rasteriser's pixel indices must be exact in "
                "float32."),
    Setting("solver", "choice", "auto", "Solver", "Linear solver of the radiosity system",
            choices=SOLVERS, exposed=True),
    Setting("tolerance", "float", DEFAULT_TOLERANCE, "Tolerance",
            "Relative residual at which iterative solvers stop", low=0, high=1, open_low=True,
            open_high=True, soft=(1e-6, 0.01), digits=6, exposed=True),
    Setting("max_iterations", "int", DEFAULT_MAX_ITERATIONS, "Iteration Cap",
            "Sweep cap of Jacobi / Gauss-Seidel (progressive: shots capped at 50 x nodes)",
            low=1, exposed=True),
    Setting("corners", "choice", "gather", "Corner Colours", "How corner colours are made from the "
            "solution", choices=CORNERS, exposed=True,
            doc="'gather' costs about one more hemicube per vertex; 'average' is free but a "
                "patch-mean value: off by tens of percent next to luminaires, in room corners "
                "and along shadow edges."),
    Setting("refine_levels", "int", 0, "Adaptive Levels",
            "Split patches where the solved light changes between neighbours and solve again, "
            "this many times (0: off)", low=0, high=4, exposed=True,
            doc="Patches are spent where the light changes: shadow edges, light footprints, room "
                "corners (core.refine)."),
    Setting("element_levels", "int", 2, "Receiver Levels",
            "After the solve, split patches where the light changes into smaller receivers for "
            "the vertex colours, this many times (no re-solve; 0: off)", low=0, high=3,
            exposed=True,
            doc="corners='gather' only (core.elements). The vertex gather then sees the light's "
                "gradient across a patch instead of its mean. Costs one hemicube per new "
                "element."),
    Setting("contact_cuts", "bool", True, "Cut at Contacts",
            "Cut patches along the lines where objects touch or pierce a surface (a box on a "
            "floor), so no light leaks under objects and their feet are not too dark",
            exposed=True, doc="core.contacts."),
    Setting("gap_cuts", "bool", True, "Cut at Gaps",
            "With Cut at Contacts: also cut patches where an object's edge runs close in "
            "front of a surface without touching it (a shelf board 2 cm off a wall), so the "
            "dark slot behind it does not take the lit side's light",
            exposed=True,
            doc="core.gaplines: within Min Element. Office (coarse model) against Cycles, "
                "3 x 1024 spp: 2.65 % -> 2.25 %, 1.23x the time."),
    Setting("shadow_cuts", "bool", True, "Cut at Shadows",
            "With Cut at Contacts: also cut patches along the shadow lines that leave an "
            "object's corners on the surface it stands on, towards each light, so a penumbra "
            "narrower than any element is drawn along its edges",
            exposed=True,
            doc="core.footlines. Cornell box (coarse) 2.86 % -> 2.70 % against Cycles; office "
                "3.48 % -> 3.45 % at 14,589 vertices (14,604 without). On by "
                "default since the three failures it brought out are fixed: the far-from-origin "
                "slivers (stability class 10 reads 0.0007 % with it on), the reciprocity "
                "scaling that left a strip beside a shelf 1 % low in the furnace office (its "
                "drifting scales, core.reciprocity.SINKHORN_DRIFT), and core.relight with "
                "moved lights keeping the old lines (it bakes again when they move)."),
    Setting("rotate_hemicube", "bool", True, "Rotate Cubes",
            "Random rotation of each hemicube about its normal (breaks up aliasing; drawn from "
            "seed)"),
    Setting("two_sided", "bool", True, "Two Sided",
            "Both sides of every polygon are surfaces (Cycles' behaviour); off: back sides "
            "absorb"),
    Setting("crease_angle", "float", DEFAULT_CREASE_ANGLE, "Crease Angle",
            "Corner colours average patches whose normals are within this angle", unit="deg",
            low=0, high=180),
    Setting("memory_budget", "int", DEFAULT_MEMORY_BUDGET, "Memory Budget",
            "Bytes allowed for kept form factors; above it the solve runs matrix-free",
            unit="bytes", low=MIN_MEMORY_BUDGET),
    Setting("seed", "int", 0, "Seed",
            "Seed of every random choice (hemicube rotations, rays)", low=0),
    Setting("rays", "int", 16, "Rays",
            "Visibility rays per patch pair of the 'exact' and 'hybrid' methods; source samples "
            "per receiver point of 'raytraced'", low=1),
    Setting("reciprocity", "bool_or_auto", "auto", "Reciprocity",
            "Make the kept form factors reciprocal with their row sums kept; 'auto': on for "
            "'hemicube' and 'nusselt'",
            doc="Dense solves only: matrix-free shooting conserves energy by construction. On "
                "room_with_boxes(500) it cuts the hemicube's error against the exact method "
                "from 85 % to 25 % and the energy imbalance from -27 % to 0; off for 'hybrid' "
                "and 'exact', whose near pairs are already accurate."),
    Setting("near", "float", 1.5, "Near Pairs",
            "'hybrid' only: pairs nearer than this times the larger patch size get exact form "
            "factors", unit="x patch size", low=0),
    Setting("refine_threshold", "float", 0.1, "Refine Step",
            "Relative luminance difference between neighbouring patches that refines both",
            low=0, high=1, open_low=True, open_high=True),
    Setting("element_threshold", "float", 0.3, "Receiver Step",
            "Relative luminance difference between neighbours that splits them into elements",
            low=0, high=1, open_low=True, open_high=True),
    Setting("element_near_threshold", "float", 0.15, "Near Step",
            "The same, for elements next to another surface out of their plane (a wall under "
            "the ceiling, a floor under furniture), split once more than Receiver Levels "
            "(0: off)", low=0, high=1, open_high=True, digits=3,
            doc="core.criteria.near_surfaces: a point gathering next to such an element sees "
                "its near part, not its mean. Measured on the coarse office "
                "(bench/compare/coarse.py): error against Cycles 4.18 % -> 3.48 %, the ceiling "
                "along the walls +6.1 % -> -0.1 %, bake 19.8 s -> 30.8 s; coarse Cornell box "
                "4.44 % -> 4.08 %, 1.5 s -> 2.9 s. Its cost grows with furniture: six furnished "
                "rooms at 30k vertices (bench/bench_scaling.py, 2 workers) 81 s -> 126 s; "
                "their peak memory, 1.15 GB without it, is 0.87 GB with it since the gather "
                "rows keep a far patch in one column (core.farfield.FarField). The gathered "
                "elements next to another surface are gathered again from the elements "
                "(core.elements.NEAR_SWEEPS): a room's corners read nearer Cycles' "
                "(tests/compare/test_room_corners.py)."),
    Setting("contrast", "float", 0.1, "Contrast",
            "Radiosity mesh: split an element when the luminance between its vertices differs by "
            "more than this fraction of the brighter one and the light across it is not linear",
            low=0, high=1, open_low=True,
            open_high=True, soft=(0.02, 0.5), digits=3, exposed=True,
            doc="Never relative to less than a quarter of the scene's mean luminance, so darkness "
                "does not refine forever; an element whose parent's new points lie within this "
                "fraction of linear is not split (the output interpolates linearly). Measured "
                "(bench/bench_adaptive.py): one-quad floor 0.80 % mean error with 178 vertices "
                "at 0.1, 0.58 % with 295 at 0.05; box shadow 1.35 % with 1118 at 0.1, 1.43 % "
                "with 980 at 0.2 (with the floor at half the mean, before 2026-12-05)."),
    Setting("min_element", "float", None, "Min Element",
            "Radiosity mesh: smallest element edge refinement makes (at an object's foot and "
            "in penumbrae, where the light falls steeply, down to a quarter of it); auto (0 in "
            "the panel): 0.05 m "
            "whatever the scene's units, finer in a model smaller than 2 m across", unit="m",
            low=0, open_low=True, soft=(0.005, 1.0), exposed=True, auto=True,
            doc="Auto: core.adaptive.min_element_size, 0.05 m, at most the scene's bounding "
                "diagonal / 40. Measured: box shadow 1.35 % with 1118 vertices at 0.05 m, "
                "1.63 % with 547 at 0.1 m; 0.02 m buys nothing at the default contrast (6571 "
                "vertices, 1.35 %). Auto, not 0.05 in the panel: the panel's lengths are scene "
                "units, and a file in millimetres read 0.05 as 0.05 mm (the mesh then refined "
                "to its vertex budget)."),
    Setting("emitter_levels", "int", 3, "Near Splits",
            "Radiosity mesh: split solve patches near an emitter, this many rounds, until each is "
            "at most 4 times its distance to it, and across thin cavities until each is at most "
            "twice the gap (0: off)", low=0, high=6,
            doc="A hemicube treats its source patch as a point, wrong for surfaces nearer than "
                "about a patch size; near an emitter that error carries most of the energy. "
                "Measured on the office modelled coarsely (bench/compare/coarse.py): error "
                "17.5 % -> 9.9 %, bias +11.6 % -> +0.1 % against converged Cycles; with the "
                "cavity split (the floor under the lowest shelf) 10.0 % -> 6.1 %."),
    Setting("light_samples", "int", 64, "Light Samples",
            "Shadow rays per point, spot or sun light and per exact emitter at each output "
            "point, where the light has a size (radius, angle, area): the softness of its "
            "shadows", low=1, high=1024, soft=(1, 256), exposed=True,
            doc="Points whose first round (8 rays on a ring near the light's rim, 1 to its "
                "centre) agrees, fully lit or fully shadowed, cast no more: only the penumbra "
                "pays for the samples; a light narrower than min_element casts 4 on the ring "
                "first (core.lights.SMALL_ROUND). "
                "The visible fraction's error must stay under the mesh's contrast, or the mesh "
                "refines its noise: across a disk light's straight shadow edge the worst point "
                "is off by 12.2 % of the unshadowed light with 16 rays, 7.4 % with 32, 5.0 % "
                "with 64 (tests/core/test_direct_lights.py)."),
    Setting("exact_direct", "choice", "auto", "Exact Emitters",
            "Which emissive surfaces get their direct light exactly at every point (contour "
            "integral with shadow rays) instead of through the hemicube", choices=EXACT_DIRECT,
            exposed=True,
            doc="At most 64 lamps (faces of one material that share vertices are one lamp, "
                "core.lamps), 1,024 emissive faces and 10 % of the surfaces' area, by material "
                "(core.emitters); the hemicube then carries only what they reflect."),
    Setting("sky", "choice", "world", "Sky", "What lights the scene from outside", choices=SKIES,
            exposed=True,
            doc="'cie_overcast' (core.sky) is gathered per direction through each hemicube's "
                "empty pixels: method='hemicube' only. The ground is not modelled unless you "
                "model it."),
    Setting("sky_illuminance", "float", 10_000.0, "Sky Lux",
            "'cie_overcast': the outdoor illuminance on an unobstructed horizontal plane; "
            "daylight factors are relative to it", unit="lx", low=0, open_low=True,
            soft=(1000.0, 100_000.0), digits=0, exposed=True,
            doc="10 000 lx is the usual daylight-factor convention; Lz = 9 E / (7 pi 683) "
                "W/(m^2 sr), white (683 lm/W, as core.lux)."),
    Setting("workers", "int", None, "Workers",
            "Processes that compute the hemicubes; auto (0 in the panel): one per core; 1: "
            "this process only. The result is the same for any number", low=1, high=256,
            exposed=True, auto=True,
            doc="core.parallel: form-factor rows, element and vertex gathers; bit-identical to "
                "one process."),
    Setting("vertex_budget", "int", 100_000, "Vertex Budget",
            "Radiosity mesh: most output vertices; the worst elements are split first", low=4,
            soft=(1000, 1_000_000), exposed=True,
            doc="About 1 ms per gathered vertex: the default bounds the mesh stage near 2 min."),
)

#: Rows by name.
BY_NAME = {row.name: row for row in TABLE}

#: Names of the settings shown in the panel, the batch options and the report.
EXPOSED = tuple(row.name for row in TABLE if row.exposed)

_PY_TYPES = dict(float=float, int=int, bool=bool, choice=str, bool_or_auto=object)


def _docstring():
    lines = ["Settings of a bake, validated on construction (``SettingsError`` names the setting).",
             "", "Built from :data:`core.settings.TABLE`.", "", "Attributes", "----------"]
    for row in TABLE:
        kind = {"choice": "str", "bool_or_auto": "bool or 'auto'"}.get(row.type, row.type)
        lines.append(f"{row.name} : {kind}")
        extra = f" {row.doc}" if row.doc else ""
        lines.append(f"    {row.help}. Must be {row.describe()}; default {row.default!r}.{extra}")
    return "\n".join(lines)


def _post_init(self):
    for name, row in BY_NAME.items():
        row.check(getattr(self, name))
    if self.sky != "world" and self.method != "hemicube":
        raise SettingsError(f"sky={self.sky!r} needs method='hemicube' (a sky that varies with "
                            f"direction is gathered by the hemicube); got method={self.method!r}")


BakeSettings = dataclasses.make_dataclass(
    "BakeSettings", [(row.name, _PY_TYPES[row.type], dataclasses.field(default=row.default))
                     for row in TABLE],
    namespace={"__post_init__": _post_init, "__doc__": _docstring(),
               "__module__": __name__}, frozen=True, kw_only=True)


def as_dict(settings, names=None):
    """The settings' values as a plain dict (JSON-friendly), in table order."""
    names = EXPOSED if names is None else names
    return {name: getattr(settings, name) for name in names}

