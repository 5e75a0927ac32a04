"""Point, spot and sun lights as given in Blender's terms, validated into arrays.

:func:`make_lights` reads the lights of a scene (dicts, as the add-on extracts them) into one
:class:`Lights`; :mod:`core.lights` computes their direct light (units in its docstring).
"""

from dataclasses import dataclass

import numpy as np

from .errors import SceneError
from .photometry import CYCLES_CANDELA_TO_WATT, Photometry

KINDS = ("point", "spot", "sun")


@dataclass(frozen=True, eq=False)
class Lights:
    """Point, spot and sun lights as arrays (build with :func:`make_lights`).

    Attributes
    ----------
    names : tuple of str
        Every light, point and spot lights first, then suns.
    position : (n, 3) float64
        Point and spot lights.
    intensity : (n, 3) float64
        Radiant intensity (W/sr), RGB.
    radius : (n,) float64
    soft : (n,) bool
        Soft falloff: ``d^2 + r^2`` in the denominator.
    axis : (n, 3) float64
        Spot direction (unit); zero for point lights.
    cos_half : (n,) float64
        Cosine of the half cone angle; -1 for point lights.
    smooth : (n,) float64
        Width of the cone's soft edge in cosine: ``(1 - cos_half) x blend``.
    shadow : (n + m,) bool
        The light casts shadows.
    sun_direction : (m, 3) float64
        Unit vector towards each sun.
    sun_irradiance : (m, 3) float64
        W/m^2 on a surface facing the sun, RGB.
    sun_half_angle : (m,) float64
        Half the sun's angular diameter (rad).
    profiles : tuple
        Per point and spot light, its :class:`LightProfile` (a measured distribution) or None;
        empty when no light has one.
    """

    names: tuple
    position: np.ndarray
    intensity: np.ndarray
    radius: np.ndarray
    soft: np.ndarray
    axis: np.ndarray
    cos_half: np.ndarray
    smooth: np.ndarray
    shadow: np.ndarray
    sun_direction: np.ndarray
    sun_irradiance: np.ndarray
    sun_half_angle: np.ndarray
    profiles: tuple = ()

    @property
    def n_points(self):
        return int(self.position.shape[0])

    @property
    def n_suns(self):
        return int(self.sun_direction.shape[0])

    def __len__(self):
        return self.n_points + self.n_suns

    def scaled(self, factor):
        """The same lights with every length times ``factor`` (intensity x factor^2: the
        irradiance at the scaled distances is unchanged)."""
        return Lights(self.names, self.position * factor, self.intensity * factor ** 2,
                      self.radius * factor, self.soft, self.axis, self.cos_half, self.smooth,
                      self.shadow, self.sun_direction, self.sun_irradiance, self.sun_half_angle,
                      self.profiles)

    @property
    def shines(self):
        """Whether any light gives light (power or strength > 0)."""
        return bool(np.any(self.intensity > 0) or np.any(self.sun_irradiance > 0))


def _vec(light, key, label, default=None, length=3):
    value = light.get(key, default)
    if value is None:
        raise SceneError(f"{label}: missing '{key}'")
    try:
        arr = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise SceneError(f"{label}: '{key}' must be numbers; got {value!r}") from None
    if arr.size != length or not np.all(np.isfinite(arr)):
        raise SceneError(f"{label}: '{key}' must be {length} finite number(s); got {value!r}")
    return arr if length > 1 else float(arr[0])


def _direction(light, label, key="direction", default=None):
    d = _vec(light, key, label, default)
    n = np.linalg.norm(d)
    if n == 0:
        raise SceneError(f"{label}: {key} must be non-zero")
    return d / n


#: What a light's power means with a measured distribution (core.photometry): see the module
#: docstring.
PHOTOMETRY_SCALES = ("power", "cycles")


@dataclass(frozen=True, eq=False)
class LightProfile:
    """A measured distribution placed on a light: ``f(dir) = gain x candela(gamma, C)``.

    Attributes
    ----------
    photometry : core.photometry.Photometry
    nadir, c0, c90 : (3,) float64
        Unit vectors: gamma 0, and C = 0 and C = 90 degrees at gamma 90 (``c90 = nadir x c0``).
    gain : float
        Per candela: 1 / mean candela ('power') or 4 pi / 177.83 ('cycles').
    """

    photometry: Photometry
    nadir: np.ndarray
    c0: np.ndarray
    c90: np.ndarray
    gain: float

    def factor(self, directions):
        """(n,) ``f`` along unit ``directions`` (n, 3) leaving the light (vectorised)."""
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        gamma = np.arccos(np.clip(d @ self.nadir, -1.0, 1.0))
        c = np.arctan2(d @ self.c90, d @ self.c0)
        return self.gain * self.photometry.intensity(gamma, c)


def _profile(light, label):
    """The :class:`LightProfile` of a point or spot light dict, or None."""
    phot = light.get("photometry")
    if phot is None:
        return None
    if not isinstance(phot, Photometry):
        raise SceneError(f"{label}: photometry must be a core.photometry.Photometry (read_ies, "
                         f"read_ldt); got {type(phot).__name__}")
    scale = light.get("photometry_scale", "power")
    if scale not in PHOTOMETRY_SCALES:
        raise SceneError(f"{label}: photometry_scale must be one of {PHOTOMETRY_SCALES}; got "
                         f"{scale!r}")
    nadir = _direction(light, label, default=(0.0, 0.0, -1.0))
    c0 = _direction(light, label, "c0", (0.0, -1.0, 0.0))
    c0 = c0 - (c0 @ nadir) * nadir
    n = np.linalg.norm(c0)
    if n < 1e-6:
        raise SceneError(f"{label}: c0 (C = 0 of the photometry; default (0, -1, 0)) must not be "
                         f"parallel to direction; got {light.get('c0', (0.0, -1.0, 0.0))!r}")
    c0 = c0 / n
    if scale == "power":
        flux = phot.flux()
        if not flux > 0:
            raise SceneError(f"{label}: the photometry of {phot.name} emits no light (flux "
                             f"{flux:g} lm)")
        gain = 4.0 * np.pi / flux
    else:
        gain = CYCLES_CANDELA_TO_WATT
    return LightProfile(phot, nadir, c0, np.cross(nadir, c0), float(gain))


def make_lights(lights):
    """Validate lights given in Blender's terms and convert them to :class:`Lights`.

    Parameters
    ----------
    lights : sequence of dict
        Each has ``kind`` ('point', 'spot' or 'sun'), ``name`` (for messages), ``color`` (RGB,
        default white) and:

        * point, spot: ``position`` (m), ``power`` (W), ``radius`` (m, default 0),
          ``soft_falloff`` (default True);
        * spot: also ``direction`` (the way it points), ``spot_size`` (full cone angle, rad, in
          (0, pi]) and ``spot_blend`` (in [0, 1]);
        * sun: ``direction`` (the way the light travels, Blender's -Z of the sun object),
          ``strength`` (W/m^2) and ``angle`` (angular diameter, rad, default 0);
        * any: ``shadow`` (casts shadows, default True);
        * point, spot, optional: ``photometry`` (a :class:`core.photometry.Photometry`),
          ``photometry_scale`` (one of :data:`PHOTOMETRY_SCALES`, default 'power'),
          ``direction`` (the nadir, the light's -Z; a spot's own direction; default
          (0, 0, -1)) and ``c0`` (C = 0, the light's -Y; default (0, -1, 0); made perpendicular
          to ``direction``): see the module docstring.

    Returns
    -------
    Lights

    Raises
    ------
    SceneError
        Naming the light and the field at fault.
    """
    points, suns = [], []
    for i, light in enumerate(lights):
        if not isinstance(light, dict):
            raise SceneError(f"light {i} must be a dict; got {type(light).__name__}")
        name = str(light.get("name", f"light {i}"))
        label = f'light "{name}"'
        kind = light.get("kind")
        if kind not in KINDS:
            raise SceneError(f"{label}: kind must be one of {KINDS}; got {kind!r}")
        color = _vec(light, "color", label, (1.0, 1.0, 1.0))
        if np.any(color < 0):
            raise SceneError(f"{label}: color must be >= 0; got {color.tolist()}")
        shadow = bool(light.get("shadow", True))
        if kind == "sun":
            if light.get("photometry") is not None:
                raise SceneError(f"{label}: photometry is for point and spot lights; got a sun")
            direction = _direction(light, label)
            strength = _vec(light, "strength", label, length=1)
            angle = _vec(light, "angle", label, 0.0, length=1)
            if strength < 0:
                raise SceneError(f"{label}: strength must be >= 0 W/m^2; got {strength}")
            if not 0 <= angle < np.pi:
                raise SceneError(f"{label}: angle must lie in [0, pi) rad; got {angle}")
            suns.append((name, -direction, strength * color, angle / 2, shadow))
            continue
        pos = _vec(light, "position", label)
        power = _vec(light, "power", label, length=1)
        radius = _vec(light, "radius", label, 0.0, length=1)
        if power < 0:
            raise SceneError(f"{label}: power must be >= 0 W; got {power}")
        if radius < 0:
            raise SceneError(f"{label}: radius must be >= 0 m; got {radius}")
        axis, cos_half, smooth = np.zeros(3), -1.0, 0.0
        if kind == "spot":
            axis = _direction(light, label)
            size = _vec(light, "spot_size", label, length=1)
            blend = _vec(light, "spot_blend", label, 0.0, length=1)
            if not 0 < size <= np.pi:
                raise SceneError(f"{label}: spot_size must lie in (0, pi] rad; got {size}")
            if not 0 <= blend <= 1:
                raise SceneError(f"{label}: spot_blend must lie in [0, 1]; got {blend}")
            cos_half = float(np.cos(size / 2))
            smooth = (1.0 - cos_half) * blend
        points.append((name, pos, power * color / (4 * np.pi), radius,
                       bool(light.get("soft_falloff", True)), axis, cos_half, smooth, shadow,
                       _profile(light, label)))

    def col(rows, k, shape):
        return np.array([r[k] for r in rows], dtype=np.float64).reshape(shape)

    n, m = len(points), len(suns)
    return Lights(
        names=tuple(p[0] for p in points) + tuple(s[0] for s in suns),
        position=col(points, 1, (n, 3)), intensity=col(points, 2, (n, 3)),
        radius=col(points, 3, (n,)), soft=np.array([p[4] for p in points], dtype=bool),
        axis=col(points, 5, (n, 3)), cos_half=col(points, 6, (n,)), smooth=col(points, 7, (n,)),
        shadow=np.array([p[8] for p in points] + [s[4] for s in suns], dtype=bool),
        sun_direction=col(suns, 1, (m, 3)), sun_irradiance=col(suns, 2, (m, 3)),
        sun_half_angle=col(suns, 3, (m,)),
        profiles=tuple(p[9] for p in points) if any(p[9] is not None for p in points) else ())
