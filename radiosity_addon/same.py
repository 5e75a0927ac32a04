"""What Relight compares: the scene re-read against the kept bake (:func:`read`: only the
light may have changed), a value of it against the kept one's, and the kept lights against the
scene's (one factor per colour channel, or a cast again)."""

import numpy as np

from ..core.errors import RadiosityError
from . import job
from .extract import ATTRIBUTE, extract

#: Two values of a re-read scene are "unchanged" within this relative difference (float32 at the
#: Blender boundary; the lights' factor is one per colour channel for all of them).
SAME_RTOL = 1e-5


def same(a, b):
    """Whether two values of an extraction (arrays, dataclasses, lists, plain values) are
    the same, float arrays within :data:`SAME_RTOL`."""
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape:
            return False
        if a.dtype.kind in "fc":
            return bool(np.allclose(a, b, rtol=SAME_RTOL, atol=SAME_RTOL * 1e-3))
        return bool(np.array_equal(a, b))
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(same(getattr(a, f), getattr(b, f))
                                          for f in a.__dataclass_fields__)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if hasattr(a, "__dict__") and not isinstance(a, type):
        return type(a) is type(b) and same(sorted(vars(a).items()), sorted(vars(b).items()))
    return a == b


def lights_factor(old, new):
    """(3,) factor per colour channel from the lights ``old`` to ``new`` when they differ by
    one common factor per channel (power and colour scaled alike), else None (cast again)."""
    if old is None or not len(old):
        return np.ones(3) if new is None or not len(new) else None
    if new is None or not len(new):
        return np.zeros(3)                    # every light deleted: the old ones at 0
    if not _same_but_power(old, new):
        return None
    return channel_factor(_power(old), _power(new))


def _same_but_power(old, new):
    """Whether the core Lights ``old`` and ``new`` differ at most in their power."""
    if len(old) != len(new) or list(old.names) != list(new.names):
        return False
    return all(same(getattr(old, f), getattr(new, f)) for f in old.__dataclass_fields__
               if f not in ("intensity", "sun_irradiance"))


def _power(lights):
    """(L, 3): the point and spot lights' intensity, then the suns' irradiance."""
    return np.concatenate([lights.intensity, lights.sun_irradiance]).reshape(-1, 3)


def channel_factor(a, b):
    """(3,) factor per colour channel with ``b = factor * a`` (arrays of RGB rows), else None."""
    a, b = np.asarray(a, np.float64).reshape(-1, 3), np.asarray(b, np.float64).reshape(-1, 3)
    factor = np.ones(3)
    for c in range(3):
        on = a[:, c] > 0
        if np.any(b[~on, c] > 0):
            return None
        if on.any():
            ratio = b[on, c] / a[on, c]
            if not np.allclose(ratio, ratio[0], rtol=SAME_RTOL):
                return None
            factor[c] = ratio[0]
    return factor


def unit_factors(units, old, new):
    """{unit index: (3,) factor} when the scene ``new`` differs from ``old`` only by one factor
    per colour channel for each unit (light_units.Unit) of light: each emissive material's
    strength and colour, each light's power and colour, as its group holds them; None for any
    other change (a unit's parts scaled apart, a world's group scaled, the lights moved).
    ``old``, ``new``: (emission (M, 3), back emission or None, core Lights or None)."""
    (em0, back0, lights0), (em1, back1, lights1) = old, new
    rows0, rows1 = [np.asarray(em0, np.float64)], [np.asarray(em1, np.float64)]
    if back0 is not None:
        rows0.append(np.asarray(back0, np.float64))
        rows1.append(np.asarray(back1, np.float64))
    if (lights0 is None or not len(lights0)) != (lights1 is None or not len(lights1)):
        return None
    if lights0 is not None and len(lights0):
        if not _same_but_power(lights0, lights1):
            return None
        rows0.append(_power(lights0))
        rows1.append(_power(lights1))
    a, b = np.concatenate(rows0), np.concatenate(rows1)
    M, blocks = len(em0), 1 + (back0 is not None)       # rows: emission, back, then lights
    out, free = {}, np.ones(len(a), bool)
    for k, unit in enumerate(units):
        if unit.materials is not None:
            rows = np.concatenate([np.asarray(unit.materials) + i * M for i in range(blocks)])
        else:
            rows = blocks * M + np.asarray(unit.lights, np.int64)
        factor = channel_factor(a[rows], b[rows])
        if factor is not None and np.allclose(factor, 1.0, rtol=0.0, atol=SAME_RTOL):
            factor = np.ones(3)               # unchanged (float32 at the Blender boundary)
        if factor is None or (unit.world and not np.array_equal(factor, np.ones(3))):
            return None                       # the world is as baked (Relight reads it)
        free[rows] = False
        out[k] = factor
    return out if same(a[free], b[free]) else None


# ----------------------------------------------------------------------------- the scene


#: What the user is told whenever the kept bake cannot serve.
BAKE_AGAIN = "bake again"


class RelightError(job.BakeError):
    """Relight cannot run; the message is for the user."""


def read(context, entry):
    """Re-read the scene: (emission (M, 3), back emission (M, 3) or None, the lights (core
    Lights or None), their factor from the kept ones (:func:`lights_factor`: (3,) or None));
    RelightError if anything else changed."""
    try:
        ext = extract(context.evaluated_depsgraph_get(), selected_only=entry.selected_only,
                      world=entry.bake_input.settings.sky == "world")
    except RadiosityError as exc:
        raise RelightError(str(exc)) from exc
    old = entry.bake_input.extraction.arrays
    new = ext.arrays
    if [p.object_name for p in ext.parts] != [p.object_name for p in
                                               entry.bake_input.extraction.parts]:
        raise RelightError(f"Relight: the baked objects changed; {BAKE_AGAIN}")
    for key in sorted(set(old) | set(new)):
        if key in ("emission", "back_emission", "lights"):
            continue
        if not same(old.get(key), new.get(key)):
            what = {"vertices": "geometry", "corner_verts": "geometry",
                    "face_starts": "geometry", "face_sizes": "geometry",
                    "reflectance": "material colours", "back_reflectance": "material colours",
                    "face_materials": "material assignment"}.get(key, key.replace("_", " "))
            raise RelightError(f"Relight: the {what} changed since the bake "
                               f"(Relight takes new lights and emission strength and colour "
                               f"only); {BAKE_AGAIN}")
    emission = np.asarray(new["emission"], dtype=np.float64)
    back = new.get("back_emission")
    if (back is None) != (old.get("back_emission") is None):
        raise RelightError(f"Relight: the one-sided emitters changed; {BAKE_AGAIN}")
    newly = np.any(emission > 0, axis=1) & ~np.any(np.asarray(old["emission"]) > 0, axis=1)
    if newly.any():
        names = new.get("material_names") or ()
        which = ", ".join(f"'{names[m]}'" for m in np.flatnonzero(newly)[:3] if m < len(names))
        raise RelightError(f"Relight: material {which} emits now and did not at the bake "
                           f"(its light needs its own patches and form factors); {BAKE_AGAIN}")
    lights = new.get("lights")
    return emission, None if back is None else np.asarray(back, np.float64), lights, \
        lights_factor(entry.lights_ref, lights)


def check_baked(scene, entry):
    """The kept bake's objects still show it (not undone, not cleared by hand)."""
    for part in entry.bake_input.extraction.parts:
        obj = scene.objects.get(part.object_name)
        if obj is None or obj.type != "MESH":
            raise RelightError(f"Relight: object '{part.object_name}' of the bake is gone; "
                               f"{BAKE_AGAIN}")
        if ATTRIBUTE not in obj.data.color_attributes:
            raise RelightError(f"Relight: object '{obj.name}' no longer shows the bake (undone "
                               f"or cleared); {BAKE_AGAIN}")
