"""Skies that vary with direction, and the light the hemicube's empty pixels see of them.

A uniform world (``Scene.world`` as a (3,) radiance) lights a receiver with ``world x (1 - row
sum)``: exact for a constant radiance only. A :class:`Sky` is evaluated per direction instead:
what a hemicube eye receives from it is the sum over its *empty* pixels (those no polygon covers,
after the crack fill) of the pixel's delta form factor times the sky's radiance along the pixel's
direction in world space (:func:`gathered`, called by :mod:`core.hemicube_chunk`).

Conventions: +Z is up; the CIE sky gives nothing below the horizon (the ground is not modelled
unless the user models it); radiance is in the bake's units (W/(m^2 sr), Blender's scene-linear RGB).
Illuminance follows :mod:`core.lux`: 683 lm/W and Rec. 709 luminance, so a white sky of
horizontal illuminance E lx has ``Lz = 9 E / (7 pi 683)`` (CIE standard overcast sky).

Sky objects cross to the worker processes (:mod:`core.parallel`) as plain data
(:meth:`Sky.message`, :func:`from_message`): inside Blender the add-on's package has another
module name than the workers' ``core``, so the objects themselves are not pickled.
"""

import threading

import numpy as np

from .errors import SettingsError

#: Illuminance on an unobstructed horizontal plane under a CIE overcast sky of zenith radiance
#: Lz, over Lz: integral of (1 + 2 cos t) / 3 x cos t over the upper hemisphere = 7 pi / 9.
CIE_OVERCAST_HORIZONTAL = 7.0 * np.pi / 9.0


class Sky:
    """A sky's radiance as a function of direction (world space, +Z up).

    Subclasses define :meth:`radiance` and the data of :meth:`message`.
    """

    #: Name in :func:`from_message`.
    kind = None

    #: ``(a, b)`` when the radiance is ``colour x (a + b cos zenith)`` above the horizon and 0
    #: below: :func:`gathered` then needs only two sums per eye over its open pixels above the
    #: horizon (dense arrays, no index gathers). None: any radiance (:meth:`radiance`).
    above_horizon = None

    def radiance(self, directions):
        """(n, 3) radiance along unit ``directions`` (n, 3)."""
        raise NotImplementedError

    def horizontal(self):
        """(3,) irradiance / pi on an unobstructed horizontal plane facing up (what
        :func:`core.lux.lux` turns into the outdoor illuminance)."""
        raise NotImplementedError

    def message(self):
        """(kind, dict of arrays): what :func:`from_message` rebuilds the sky from."""
        return self.kind, dict(vars(self))


class Uniform(Sky):
    """The same radiance (3,) in every direction, below the horizon too: the uniform world, as
    a directional sky (``world x (1 - row sum)`` is its exact shortcut)."""

    kind = "uniform"

    def __init__(self, radiance):
        self.value = _rgb("radiance", radiance)

    def radiance(self, directions):
        n = np.asarray(directions).shape[0]
        return np.broadcast_to(self.value, (n, 3))

    def horizontal(self):
        return self.value.copy()


class CIEOvercast(Sky):
    """CIE standard overcast sky: ``L(t) = Lz (1 + 2 cos t) / 3``, t from the zenith (+Z), and
    nothing below the horizon.

    Parameters
    ----------
    zenith_radiance : float or (3,) float
        Lz, W/(m^2 sr), >= 0 (a number: a white sky). :func:`zenith_radiance` gives it for an
        outdoor horizontal illuminance.
    """

    kind = "cie_overcast"
    above_horizon = (1.0 / 3.0, 2.0 / 3.0)

    def __init__(self, zenith_radiance):
        z = np.asarray(zenith_radiance, dtype=np.float64)
        self.zenith = _rgb("zenith_radiance", np.broadcast_to(z, (3,)) if z.ndim == 0 else z)

    def radiance(self, directions):
        cos = np.asarray(directions, dtype=np.float64)[:, 2]
        shape = np.where(cos >= 0.0, (1.0 + 2.0 * cos) / 3.0, 0.0)
        return shape[:, None] * self.zenith[None, :]

    @property
    def colour(self):
        """(3,) what :attr:`above_horizon` scales: the radiance at the zenith."""
        return self.zenith

    def horizontal(self):
        return self.zenith * (CIE_OVERCAST_HORIZONTAL / np.pi)


class Environment(Sky):
    """A radiance map over every direction: a world that Blender textures (a sky texture, an
    environment image), rendered by the add-on (``radiosity_addon/world_map.py``).

    Parameters
    ----------
    texels : (H, 2H, 3) float
        Radiance >= 0, equirectangular: texel (row ``r`` from the top, column ``c``) is the mean
        over longitudes ``(0.5 - (c + [0, 1]) / W) 2 pi`` (from +X towards +Y) and elevations
        ``(0.5 - (r + [0, 1]) / H) pi``. Read bilinearly between texel centres, wrapping in
        longitude; the ground below the horizon is whatever the map holds there (as in Cycles,
        whose rays that miss every surface see the world in any direction).
    """

    kind = "environment"

    def __init__(self, texels):
        t = np.array(texels, dtype=np.float64)
        if t.ndim != 3 or t.shape[2] != 3 or t.shape[1] != 2 * t.shape[0] or t.shape[0] < 1:
            raise ValueError(f"texels must be an (H, 2H, 3) map; got shape {t.shape}")
        if not np.all(np.isfinite(t)) or np.any(t < 0):
            raise ValueError("texels must be finite radiances >= 0")
        t.setflags(write=False)
        self.texels = t

    def radiance(self, directions):
        d = np.asarray(directions, dtype=np.float64)
        h, w = self.texels.shape[:2]
        lon = np.arctan2(d[:, 1], d[:, 0])
        el = np.arcsin(np.clip(d[:, 2], -1.0, 1.0))
        x = (0.5 - lon / (2.0 * np.pi)) * w - 0.5
        y = np.clip((0.5 - el / np.pi) * h - 0.5, 0.0, h - 1.0)
        x0, y0 = np.floor(x), np.minimum(np.floor(y), h - 2.0) if h > 1 else np.zeros_like(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        c0 = x0.astype(np.int64) % w
        c1 = (c0 + 1) % w
        r0 = y0.astype(np.int64)
        r1 = np.minimum(r0 + 1, h - 1)
        t = self.texels
        top = t[r0, c0] * (1.0 - fx) + t[r0, c1] * fx
        bottom = t[r1, c0] * (1.0 - fx) + t[r1, c1] * fx
        return top * (1.0 - fy) + bottom * fy

    def horizontal(self):
        h, w = self.texels.shape[:2]
        lo = (0.5 - (np.arange(h) + 1.0) / h) * np.pi            # each row's elevation band
        hi = (0.5 - np.arange(h) / h) * np.pi
        # Per row, the integral over its band of cos(zenith) d omega above the horizon, over pi:
        # (2 pi / W) x (sin^2 hi - sin^2 lo) / 2 for each texel of the row.
        a, b = np.maximum(lo, 0.0), np.maximum(hi, 0.0)
        weight = (np.sin(b) ** 2 - np.sin(a) ** 2) / (w * 1.0)
        return np.einsum("r,rcj->j", weight, self.texels)


_KINDS = {cls.kind: cls for cls in (Uniform, CIEOvercast, Environment)}


def from_message(message):
    """The sky :meth:`Sky.message` describes (or None for None)."""
    if message is None:
        return None
    kind, data = message
    sky = _KINDS[kind].__new__(_KINDS[kind])
    sky.__dict__.update(data)
    return sky


def _rgb(name, value):
    arr = np.array(value, dtype=np.float64).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be 3 finite radiances >= 0 (RGB) or one number; "
                         f"got {np.asarray(value).tolist()}")
    arr.setflags(write=False)
    return arr


def zenith_radiance(illuminance):
    """Lz (W/(m^2 sr), white) of a CIE overcast sky giving ``illuminance`` lx on an unobstructed
    horizontal plane: ``9 E / (7 pi 683)``."""
    from .lux import LUMENS_PER_WATT     # not at the top: core.lux imports the hemicube
    if not (np.isfinite(illuminance) and illuminance > 0):
        raise ValueError(f"illuminance must be a finite number > 0 (lx); got {illuminance!r}")
    return float(illuminance) / (CIE_OVERCAST_HORIZONTAL * LUMENS_PER_WATT)


def is_directional(world):
    """Whether ``world`` (a Scene's) is a :class:`Sky`, lit through the hemicube's empty pixels,
    rather than None or a uniform (3,) radiance."""
    return isinstance(world, Sky)


def sky_for(settings, world):
    """The world a bake uses: ``world`` itself for ``settings.sky == 'world'``, else the sky the
    settings name (``sky_illuminance`` lx outdoors, horizontal)."""
    if settings.sky == "world":
        return world
    if settings.method != "hemicube":
        raise SettingsError(f"sky={settings.sky!r} needs method='hemicube' (a directional sky "
                            f"is evaluated at the hemicube's empty pixels); got "
                            f"method={settings.method!r}")
    return CIEOvercast(zenith_radiance(settings.sky_illuminance))


def outdoor_lux(world):
    """Outdoor unobstructed horizontal illuminance (lx) of a bake's world: what a daylight
    factor divides by; None without a world."""
    if world is None:
        return None
    if isinstance(world, Sky):
        horizontal = world.horizontal()
    else:                               # a uniform world lights a horizontal plane with pi L
        horizontal = np.asarray(world, dtype=np.float64)
    from .lux import lux                # not at the top: core.lux imports the hemicube
    return float(lux(horizontal[None, :])[0])


def pixel_directions(resolution):
    """(3 R^2, 3) unit directions of the hemicube's pixel centres in the eye frame (x, y
    tangent, z the viewing normal), in pixel-buffer order (:mod:`core.hemicube_delta`): the top
    face's R x R rows, then the R/2 x R rows of the +x, -x, +y, -y sides (row 0 at the horizon).
    Kept per resolution (one per thread)."""
    return _directions(resolution)[0]


def _directions(resolution):
    """(:func:`pixel_directions` float64, its columns as float32 (3, 3 R^2)), kept."""
    kept = getattr(_DIRECTIONS, "value", None)
    if kept is not None and kept[0] == resolution:
        return kept[1:]
    r = int(resolution)
    h = 2.0 / r
    u = -1.0 + h * (np.arange(r) + 0.5)                  # columns, every face
    top_v = u                                            # top rows: y
    side_v = h * (np.arange(r // 2) + 0.5)               # side rows: height above the plane
    uu, vv = np.meshgrid(u, top_v)                       # [row, column]
    faces = [np.stack([uu, vv, np.ones_like(uu)], axis=-1)]
    su, sv = np.meshgrid(u, side_v)
    one = np.ones_like(su)
    # As core.hemicube_raster.pixel_coords: +x (u = y), -x (u = -y), +y (u = -x), -y (u = x).
    faces.append(np.stack([one, su, sv], axis=-1))
    faces.append(np.stack([-one, -su, sv], axis=-1))
    faces.append(np.stack([-su, one, sv], axis=-1))
    faces.append(np.stack([su, -one, sv], axis=-1))
    d = np.concatenate([f.reshape(-1, 3) for f in faces])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    _DIRECTIONS.value = (resolution, d, np.ascontiguousarray(d.T, dtype=np.float32))
    return _DIRECTIONS.value[1:]


_DIRECTIONS = threading.local()


def gathered(sky, frames, empty, dff):
    """What each eye receives from ``sky`` through its empty pixels (irradiance / pi).

    Parameters
    ----------
    sky : Sky
    frames : (S, 3, 3) float
        Eye frames, rows x, y, z in world space (z the viewing normal).
    empty : (S, 3 R^2) bool
        Pixels no polygon covers.
    dff : (3 R^2,) float
        Delta form factors in pixel-buffer order (they sum to 1).

    Returns
    -------
    (S, 3) float64
        ``sum over empty pixels of dF x L(direction)``.
    """
    s_n, npix = empty.shape
    r = int(round(np.sqrt(npix / 3.0)))
    if sky.above_horizon is not None:
        return _gathered_above_horizon(sky, frames, empty, dff, r)
    s, p = np.nonzero(empty)
    out = np.zeros((s_n, 3))
    if s.size == 0:
        return out
    local = pixel_directions(r)[p]                                        # (n, 3)
    # Summed over the frame's rows, not einsum over frames[s]: (n, 3, 3) would be 72 bytes per
    # empty pixel.
    world = local[:, :1] * frames[s, 0] + local[:, 1:2] * frames[s, 1] \
        + local[:, 2:] * frames[s, 2]
    light = sky.radiance(world) * dff[p][:, None]
    for c in range(3):
        out[:, c] = np.bincount(s, weights=light[:, c], minlength=s_n)
    return out


def _gathered_above_horizon(sky, frames, empty, dff, r):
    """:func:`gathered` of a sky ``colour x (a + b cos zenith)`` above the horizon: per eye,
    ``a sum(w) + b sum(w z)`` with ``w`` the delta form factors of its open pixels above the
    horizon and ``z`` their directions' world z.

    Dense over (eyes, pixels), in float32 (a relative 1e-7 per pixel, far below the
    hemicube's own error): a few passes at some 5 ns per pixel, against some 25 ns for the
    general path's index arrays. Every step is elementwise or a sum along one eye's row
    (float32 in, float32 out: no buffered casting, whose buffers would span rows), so an eye's
    light does not depend on the other eyes of its chunk. Sums of three products, not a
    matmul: BLAS picks its kernels by the matrix sizes, which differ between chunks.

    Eyes with no open pixel (inside a closed room), or whose every pixel looks below the
    horizon (a ceiling's underside: |x.e_x + y.e_y| <= sqrt(1 - n_z^2) for a unit pixel
    direction (x, y, z), z >= the lowest pixel's), are skipped: their light is 0 either way.
    """
    d64, d32 = _directions(r)
    n_z = frames[:, 2, 2]
    below = np.sqrt(np.maximum(1.0 - n_z * n_z, 0.0)) < -n_z * d64[:, 2].min()
    live = np.flatnonzero(empty.any(axis=1) & ~below)
    out = np.zeros((frames.shape[0], 3))
    if live.size == 0:
        return out
    if live.size < frames.shape[0]:
        frames, empty = frames[live], empty[live]
    up = frames[:, :, 2].astype(np.float32)             # world z of the eye axes (S, 3)
    z = np.multiply(up[:, :1], d32[0])
    part = np.multiply(up[:, 1:2], d32[1])
    z += part
    np.multiply(up[:, 2:], d32[2], out=part)
    z += part
    w = np.multiply(empty & (z >= 0.0), dff.astype(np.float32))
    total = w.sum(axis=1)
    w *= z
    a, b = sky.above_horizon
    light = a * total.astype(np.float64) + b * w.sum(axis=1).astype(np.float64)
    out[live] = light[:, None] * sky.colour[None, :]
    return out
