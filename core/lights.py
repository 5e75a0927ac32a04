"""Point, spot and sun lights: direct light at points, with shadow rays, in Cycles' units.

Lights that are not surfaces are *shot first* (the usual treatment of point sources in radiosity):
their irradiance ``E`` is computed at every receiver with shadow rays, and enters the solve as the
first bounce, ``Le + rho E / pi`` per node (:class:`core.pipeline.Nodes`); the output points add
``E / pi`` to what their hemicube gathers. The hemicube never sees these lights, so no small
source is aliased.

Units (measured against Cycles bakes with bpy 5.0.1, ``tests/addon/test_lights.py``):

* point and spot: radiant intensity ``I = power x colour / (4 pi)`` (W/sr, Blender's power is the
  power of an isotropic point source; a spot keeps the intensity of the point light of the same
  power and cuts it to its cone). ``E = I cos(theta) / d^2``. With *soft falloff* (Blender 4.0 on,
  the default) and radius ``r``: ``E = I cos(theta) / (d^2 + r^2)``, the irradiance of a disk of
  radius r facing the receiver.
* spot cone: ``smoothstep((cos(a) - cos(size / 2)) / ((1 - cos(size / 2)) x blend))``, 1 inside
  the blend, 0 outside the cone, with no cosine falloff across the cone (a is the angle from the
  spot's axis);
* sun: ``E = strength x colour x cos(theta)`` (strength in W/m^2).
* measured distribution (``photometry``, an IES or EULUMDAT file, :mod:`core.photometry`) on a
  point or spot light: ``I(dir) = power x colour / (4 pi) x f(dir)``, the cone (spot) and soft
  falloff as without. ``photometry_scale`` says what the light's power means:

  - ``'power'`` (default): the file gives the *shape*, the power the total:
    ``f = candela(dir) / mean candela over the sphere``, so the light emits its power, as the
    isotropic light of the same power does (before a spot's cone);
  - ``'cycles'``: what Cycles gives a light whose node tree feeds an IES Texture node (strength
    1) into its Emission strength: ``f = candela(dir) x 4 pi / 177.83``, so a 1 W light emits the
    file's absolute candela (at 177.83 lm/W, Cycles' D65 efficacy) and the power multiplies it.

  Orientation as Cycles' IES Texture node reads it on a light: the light's local -Z (``direction``)
  is the nadir, gamma 0; local -Y (``c0``) is C = 0 and local -X is C = 90 degrees
  (``c90 = direction x c0``).

Soft shadows: the visible fraction of the light, sampled over a disk of the light's radius facing
the receiver (point, spot) or over the cone of the sun's angular diameter: ``samples`` shadow rays
per light and point, cast in two rounds; points whose first ``FIRST_ROUND`` rays (a ring near the
light's rim) and the ray to the light's centre agree take that answer (no penumbra there), the
rest cast ``samples`` more. Deterministic: the sample pattern is a
fixed spiral, turned per point by a hash of the point's position.
"""

import copy
import dataclasses

import numpy as np

from .exact import bilinear, gauss_square, ray_triangles
from .geometry import unit_frames
from .light_list import make_lights
from .progress import checkpoint
from .raycast import any_hit, build_bvh
from .settings import BY_NAME
from .shadow_memo import ONE_RAY, ShadowMemo, point_keys
from .sky import Sky


#: Shadow rays per light and point in the first round, on a ring at RIM x the light's radius (and
#: one to its centre); a point whose first-round rays all agree (lit, or shadowed) casts no
#: more. A straight shadow edge can then hide at most a 2.5 % segment of the light's disk from
#: the first round (8 points at 0.95: the chord beyond 0.95 cos 22.5 deg).
FIRST_ROUND = 8
RIM = 0.95

#: The first round of a light narrower than the smallest element (``min_size``): this many rays
#: on the ring, and the centre's. Where they agree the point is lit or shadowed; where they do
#: not, the full rounds. Its penumbrae are narrower than an element only where the occluder
#: stands well away from the light: a box top 10 cm under a 0.38 m panel casts a penumbra
#: metres wide on the floor 1.4 m under it, which one ray to the centre drew as a hard edge
#: (the floor of a closed room took 1.5x its light, 3.2 % of the panel's power counted twice;
#: tests/core/test_fuzz.py).
SMALL_ROUND = 4

#: Sample points per patch (ORDER x ORDER, Gauss-Legendre on the patch's bilinear map) for the
#: patches' mean irradiance, and shadow rays per sample point and light there (the mean over the
#: patch smooths the penumbra).
PATCH_ORDER = 3
PATCH_SAMPLES = 4

#: Gauss order on a patch near an exact emitter (core.emitters.NEAR_PATCH), for the visible
#: fraction: a box's shadow across a 2 m wall patch 0.5 m from a panel read +12 to +17 % from
#: PATCH_ORDER's 9 points (tests/core/test_fuzz.py).
NEAR_ORDER = 6

#: Shadow rays leave the receiver this far (relative to the scene's extent) along its normal, so
#: that they do not hit the receiver's own surface. Relative only: a floor of 1 m x this made a
#: model smaller than 1 m bake differently from the same model scaled up (tests/core/test_fuzz.py).
RAY_OFFSET = 1e-6

#: At each point, the lights whose unshadowed light there adds up to at most this fraction of
#: the point's unshadowed total (luminance) cast one shadow ray each, to their centre (an
#: emitter's anchor), instead of the penumbra's rounds, and leave the mesh's shadow bits
#: alone: a grid of downlights costs full shadow rays to the few that matter at each point.
#: Until 2026-12-05 they cast none and counted as unshadowed, so the direct light was up to
#: this fraction too high wherever they were hidden: the apartment sample with its six lamps
#: lit exactly (in other rooms, behind walls) read +1.2 % bright against Cycles, +0.4 % with
#: the hemicube.
CULL = 0.01

#: Points lit per pass: between passes, and before each light's shadow rays, a cancel is
#: honoured (core.progress.checkpoint); a pass of the patches' Gauss points with exact
#: emitters (contour integrals, then shadow rays) otherwise ran 1.2 s uninterrupted.
POINT_CHUNK = 4096

#: Rec. 709 luminance weights (the culling's measure of a light's share).
LUMA = np.array([0.2126, 0.7152, 0.0722])

#: A light's centre-visibility bit per light, in the bits above the emitter samples' bits
#: (core.criteria): lights beyond this many share bits (modulo).
VISIBILITY_BITS = 40


def same_geometry(a, b):
    """Whether Lights ``a`` and ``b`` differ at most in power and colour (``intensity``,
    ``sun_irradiance``) and names: the same shadows, cones and distributions."""
    if len(a) != len(b) or a.n_points != b.n_points:
        return False
    for f in dataclasses.fields(a):
        if f.name not in ("names", "intensity", "sun_irradiance") \
                and not _same(getattr(a, f.name), getattr(b, f.name)):
            return False
    return True


def _same(x, y):
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        return np.array_equal(x, y)
    if isinstance(x, (tuple, list)) and isinstance(y, (tuple, list)):
        return len(x) == len(y) and all(_same(u, v) for u, v in zip(x, y))
    if dataclasses.is_dataclass(x) and type(x) is type(y):
        return all(_same(getattr(x, f.name), getattr(y, f.name))
                   for f in dataclasses.fields(x))
    if x is y:
        return True
    if hasattr(x, "__dict__") and type(x) is type(y):
        return vars(x).keys() == vars(y).keys() and all(_same(vars(x)[k], vars(y)[k])
                                                        for k in vars(x))
    return x == y


def spot_factor(cos_angle, cos_half, smooth):
    """Cycles' spot cone: 0 outside, smoothstep across the blend, 1 inside (vectorised)."""
    cos_angle = np.asarray(cos_angle, dtype=np.float64)
    if smooth <= 0:
        return (cos_angle > cos_half).astype(np.float64)
    x = np.clip((cos_angle - cos_half) / smooth, 0.0, 1.0)
    return np.where(cos_angle > cos_half, x * x * (3.0 - 2.0 * x), 0.0)


def _spiral(k):
    """(k, 2) points of a Vogel spiral filling the unit disk evenly (centre excluded)."""
    i = np.arange(k) + 0.5
    r = np.sqrt(i / k)
    a = i * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def _turn(points):
    """(n,) angle per point from a hash of its position: decorrelates the spirals of
    neighbouring points, deterministically."""
    h = np.sin(points @ np.array([12.9898, 78.233, 37.719])) * 43758.5453
    return 2.0 * np.pi * (h - np.floor(h))


class DirectLight:
    """Direct light of a scene's lights (:class:`core.light_list.Lights`) and exact emitters
    (:class:`core.emitters.Emitters`) at points, with shadow rays.

    Parameters
    ----------
    lights : core.light_list.Lights or None
    patches : core.patches.Patches
        What casts shadows (every patch; emitters included).
    samples : int
        Shadow rays per light and point where the light has a size (radius or angle).
    world : (3,) float, core.sky.Sky or None
        Radiance of a uniform world: :meth:`extra` adds it for the part of a receiver's
        hemisphere that no surface covers; or a sky that varies with direction, whose light
        the hemicube gathers (:attr:`sky`) and :meth:`extra` adds.
    min_size : float
        The smallest element the output can show (m). A light narrower than it (a point or
        spot light of radius below it, a sun whose angle's tangent times the scene's extent is
        below it, an emitter) casts a first round of ``SMALL_ROUND`` rays only, and the full
        rounds where they disagree: its penumbrae are wide only where an occluder stands near
        it (a lamp shade), which the round sees.
    emitters : core.emitters.Emitters or None
        Emissive faces lit exactly: lights ``len(lights)`` on, after the point, spot and sun
        lights.
    """

    def __init__(self, lights, patches, samples=BY_NAME["light_samples"].default, world=None,
                 min_size=0.0, emitters=None, covers=None):
        self.lights = lights if lights is not None else make_lights([])
        self.emitters = emitters if emitters is not None and len(emitters) else None
        n_e = 0 if self.emitters is None else len(self.emitters)
        lt = self.lights
        self._colours = np.concatenate([lt.intensity, lt.sun_irradiance,
                                        np.zeros((0, 3)) if n_e == 0 else
                                        self.emitters.colour]).reshape(-1, 3)
        self.world = None if world is None or isinstance(world, Sky) \
            else np.asarray(world, dtype=np.float64)
        #: A directional sky (core.sky.Sky): the hemicubes gather its light, extra adds it.
        self.sky = world if isinstance(world, Sky) else None
        self.samples = int(samples)
        tris = ray_triangles(patches)[0]
        self.bvh = build_bvh(tris)
        extent = float(np.ptp(patches.corners.reshape(-1, 3), axis=0).max())
        self.lo = patches.corners.reshape(-1, 3).min(axis=0)   # the patterns' origin
        self.offset = RAY_OFFSET * extent
        self.extent = max(extent, np.finfo(float).tiny)
        self.rays = 0
        self.culled = 0                     # (point, light) pairs culled: one ray each (CULL)
        self.min_size = float(min_size)
        #: Faces lying on other faces (core.covered.Covers): the points under them get no light.
        self.covers = covers if covers is not None and len(covers) else None
        self._patch_cache = None
        #: Every shadow ray's result (core.shadow_memo), for :meth:`recoloured` copies.
        self.memo = ShadowMemo(len(self))
        self._replay = False

    def __len__(self):
        return len(self.lights) + (0 if self.emitters is None else len(self.emitters))

    def recoloured(self, lights, emitters=None):
        """This direct light with its lights at another power or colour, or None.

        ``lights``: :class:`core.light_list.Lights` that differ from :attr:`lights` in
        ``intensity`` and ``sun_irradiance`` only (names aside); ``emitters``: the exact
        emitters at their new emission (:meth:`core.emitters.Emitters.recoloured`), or None if
        there are none. The copy reads this one's shadow rays back (:attr:`memo`) and casts
        only the pairs never cast, so it gives what a fresh cast gives. None when anything
        else differs: the lights must be cast again.
        """
        lights = lights if lights is not None else make_lights([])
        if (emitters is None) != (self.emitters is None) \
                or (emitters is not None and len(emitters) != len(self.emitters)) \
                or not same_geometry(self.lights, lights):
            return None
        new = copy.copy(self)
        new.lights, new.emitters = lights, emitters
        new._colours = np.concatenate([lights.intensity, lights.sun_irradiance,
                                       np.zeros((0, 3)) if emitters is None
                                       else emitters.colour]).reshape(-1, 3)
        new._patch_cache, new.rays, new.culled, new._replay = None, 0, 0, True
        return new

    def incident(self, points, normals, *, samples=None, bits=False):
        """Irradiance / pi at ``points`` facing ``normals`` (n, 3): the radiance-equivalent that
        the gathers' ``incident`` holds. With ``bits``: also (n,) int64, bit j set when light j's
        centre (direction, for a sun) lights the point unshadowed."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        n = points.shape[0]
        normals = np.broadcast_to(np.asarray(normals, dtype=np.float64).reshape(-1, 3), (n, 3))
        out = np.zeros((n, 3))
        vis_bits = np.zeros(n, dtype=np.int64)
        for a in range(0, n, POINT_CHUNK):
            s = slice(a, a + POINT_CHUNK)
            for j, _, scale, centre in self._per_light(points[s], normals[s], samples):
                out[s] += scale[:, None] * self._colour(j)[None, :]
                vis_bits[s] |= centre.astype(np.int64) << (j % VISIBILITY_BITS)
        out /= np.pi
        return (out, vis_bits) if bits else out

    def extra(self, points, normals, row_sums, *, bits=False, sky=None):
        """What a gather point receives besides its hemicube's surfaces (irradiance / pi):
        the lights' direct light, and the world in the part of the hemicube no surface covers,
        ``world x (1 - row sum)``; with a directional :attr:`sky`, ``sky`` (n, 3) instead: its
        light as the points' hemicubes gathered it (``point_rows(..., sky=, sky_out=)``).
        ``bits`` as in :meth:`incident`."""
        inc, vis = self.incident(points, normals, bits=True)
        if self.world is not None:
            sky = np.clip(1.0 - np.asarray(row_sums, dtype=np.float64), 0.0, 1.0)
            inc = inc + sky[:, None] * self.world[None, :]
        elif self.sky is not None:
            if sky is None:
                raise ValueError("a directional sky needs its light from the hemicubes: "
                                 "sky=(n, 3) of point_rows(..., sky_out=)")
            inc = inc + np.asarray(sky, dtype=np.float64)
        return (inc, vis) if bits else inc

    def _colour(self, j):
        return self._colours[j]

    def _unshadowed(self, j, origin, normals):
        """Light j at the points before shadows: (bare, scale, ldir, dist, size), see
        :meth:`_per_light` (``dist`` None for a sun; ``size`` its radius, or its angle's
        tangent)."""
        lt = self.lights
        if j < lt.n_points:
            d = lt.position[j] - origin
            dist2 = np.einsum("ij,ij->i", d, d)
            dist = np.sqrt(dist2)
            ldir = d / np.maximum(dist, 1e-300)[:, None]
            cos_r = np.einsum("ij,ij->i", ldir, normals)
            r = lt.radius[j]
            bare = np.where(cos_r > 0, cos_r / np.maximum(dist2, 1e-300), 0.0)
            fall = dist2 + (r * r if lt.soft[j] else 0.0)
            scale = np.where(cos_r > 0, cos_r / np.maximum(fall, 1e-300), 0.0)
            if lt.cos_half[j] > -1.0:
                scale *= spot_factor(-(ldir @ lt.axis[j]), lt.cos_half[j], lt.smooth[j])
            if lt.profiles and lt.profiles[j] is not None:
                scale *= lt.profiles[j].factor(-ldir)
            return bare, scale, ldir, dist, r
        s = j - lt.n_points
        ldir = np.broadcast_to(lt.sun_direction[s], origin.shape)
        bare = np.maximum(normals @ lt.sun_direction[s], 0.0)
        return bare, bare.copy(), ldir, None, np.tan(lt.sun_half_angle[s])

    def _culled(self, unshadowed):
        """(n, m) bool: the lights each point casts no shadow rays to (:data:`CULL`), from
        every light's :meth:`_unshadowed`."""
        m = len(unshadowed)
        n = unshadowed[0][1].shape[0] if m else 0
        if m < 2 or CULL <= 0:
            return np.zeros((n, m), dtype=bool)
        y = np.stack([u[1] * float(self._colour(j) @ LUMA) for j, u in enumerate(unshadowed)],
                     axis=1)
        order = np.argsort(y, axis=1, kind="stable")
        cum = np.cumsum(np.take_along_axis(y, order, axis=1), axis=1)
        drop = cum <= CULL * cum[:, -1:]
        out = np.zeros((n, m), dtype=bool)
        np.put_along_axis(out, order, drop, axis=1)
        return out

    def _per_light(self, points, normals, samples, faces=None, dark=False):
        """Per light j: (j, bare, scale, centre), each (n,): ``bare`` the point light's
        cos / d^2 (a sun's cos) before shadows, cone, photometry and soft falloff, ``scale`` the
        factor of the light's colour in the irradiance, ``centre`` the light's centre lights the
        point. Lights culled at a point (:data:`CULL`) cast one ray there. ``faces``
        (n,), the scene face of each point: points that lie under another face (the floor
        under a box, :class:`core.covered.Covers`) get no light from any light. ``dark``:
        lights of no colour (a light group's relight holds the other groups at 0) are all
        zeros, not computed (so for callers that weight by the colour only)."""
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        k = self.samples if samples is None else int(samples)
        lt = self.lights
        n = points.shape[0]
        if n == 0:
            return
        origin = points + self.offset * normals
        turn = _turn((points - self.lo) / self.extent)   # the same at any scale and place
        off = np.zeros(len(self), dtype=bool)
        if dark:
            off = ~np.any(self._colours > 0, axis=1)
        none = (np.zeros(n), np.zeros(n), None, None, 0.0)
        unshadowed = [none if off[j] else self._unshadowed(j, origin, normals)
                      for j in range(len(lt))]
        if self.emitters is not None:
            em = self.emitters
            if off[len(lt):].all():
                unshadowed += [none] * len(em)
            else:
                unshadowed += [(f, f.copy(), None, None, size)
                               for f, size in zip(em.unshadowed(origin, normals), em.size)]
        culled = self._culled(unshadowed)
        under = None if self.covers is None or faces is None \
            else self.covers.points(points, normals, faces)
        m = len(unshadowed)
        # Shadow rays already cast (core.shadow_memo): read back by a recoloured copy.
        rows, keys = point_keys(points, normals, k)
        entry = self.memo.find(rows, keys, k) if self._replay else np.full(n, -1)
        cast_frac, cast_clear = np.full((n, m), np.nan), np.zeros((n, m), dtype=bool)
        for j, (bare, scale, ldir, dist, size) in enumerate(unshadowed):
            checkpoint()
            if unshadowed[j] is none:
                yield j, bare, scale, np.zeros(n, dtype=bool)
                continue
            centre = scale > 0
            go = np.flatnonzero(centre & ~culled[:, j])
            few = np.flatnonzero(centre & culled[:, j])
            self.culled += int(few.size)
            if few.size and np.any(self._colour(j) > 0):
                # One ray, to the centre: a pair cast in full kept it as its centre ray.
                one = np.full(few.size, np.nan)
                if self._replay:
                    has = entry[few] >= 0
                    known = np.zeros(few.size, dtype=bool)
                    known[has] = ~np.isnan(self.memo.frac[entry[few][has], j])
                    one[known] = self.memo.clear[entry[few][known], j]
                todo = np.isnan(one)
                if todo.any():
                    p = few[todo]
                    one[todo] = self._one_ray(j, origin[p], normals[p], turn[p],
                                              ldir if ldir is None else ldir[p],
                                              dist if dist is None else dist[p], size)
                    cast_frac[p, j], cast_clear[p, j] = ONE_RAY, one[todo] > 0
                scale[few] *= one
            if go.size and self._replay:
                kept = np.full(go.size, np.nan)
                has = entry[go] >= 0
                kept[has] = self.memo.frac[entry[go][has], j]
                known = ~np.isnan(kept) & (kept != ONE_RAY)
                hit = go[known]
                scale[hit] *= kept[known]
                centre[hit] = self.memo.clear[entry[hit], j]
                go = go[~known]
            frac = None
            if j >= len(lt):                        # an exact emitter (core.emitters)
                if go.size:
                    frac, clear = self.emitters.visible(j - len(lt), origin[go], normals[go],
                                                        k, turn[go], self._blocked,
                                                        small=size < self.min_size)
            elif go.size and lt.shadow[j] and np.any(self._colour(j) > 0):
                penumbra = size if dist is not None else size * self.extent
                frac, clear = self._visible(origin[go], ldir[go], dist if dist is None
                                            else dist[go], size, k, turn[go],
                                            small=penumbra < self.min_size)
            if frac is not None:
                scale[go] *= frac
                centre[go] = clear
                cast_frac[go, j], cast_clear[go, j] = frac, clear
            if under is not None:
                scale[under], centre[under] = 0.0, False
            yield j, bare, scale, centre
        new = entry < 0
        self.memo.add(rows[new], keys[new], k, cast_frac[new], cast_clear[new])
        if not new.all():
            self.memo.update(entry[~new], cast_frac[~new], cast_clear[~new])

    def _one_ray(self, j, origin, normals, turn, ldir, dist, size):
        """(n,) 0 or 1: the ray to light ``j``'s centre (an emitter's anchor) is clear; 1 for a
        light that casts no shadows."""
        lt = self.lights
        if j >= len(lt):
            return self.emitters.visible(j - len(lt), origin, normals, 1, turn,
                                         self._blocked)[0]
        if not lt.shadow[j]:
            return np.ones(origin.shape[0])
        return self._visible(origin, ldir, dist, size, 1, turn)[0]

    def _visible(self, origin, ldir, dist, size, k, turn, small=False):
        """Visible fraction (n,) of a light of radius (angle tangent) ``size`` and whether the
        ray to its centre is clear (n,) bool. ``small``: a first round of ``SMALL_ROUND``."""
        n = origin.shape[0]
        if k <= 1 or size <= 0:
            clear = ~self._shadowed(origin, ldir, dist, np.zeros((n, 3)))
            self.rays += n
            return clear.astype(np.float64), clear
        e1, e2 = unit_frames(ldir)
        c, s = np.cos(turn)[:, None], np.sin(turn)[:, None]

        def visible(rows, disk):
            """(len(rows), len(disk)) bool: the rays to the disk's points are clear."""
            u = c[rows] * disk[None, :, 0] - s[rows] * disk[None, :, 1]
            v = s[rows] * disk[None, :, 0] + c[rows] * disk[None, :, 1]
            off = size * (u[..., None] * e1[rows, None] + v[..., None] * e2[rows, None])
            m = disk.shape[0]
            p = np.repeat(rows, m)
            self.rays += p.size
            return ~self._shadowed(origin[p], ldir[p], None if dist is None else dist[p],
                                   off.reshape(-1, 3)).reshape(rows.size, m)

        centre = ~self._shadowed(origin, ldir, dist, np.zeros((n, 3)))
        self.rays += n
        everyone = np.arange(n)
        m = SMALL_ROUND if small else FIRST_ROUND
        if k > m:
            a = 2.0 * np.pi * np.arange(m) / m
            ring = RIM * np.stack([np.cos(a), np.sin(a)], axis=1)
        else:
            ring = _spiral(k)
        first = visible(everyone, ring)
        lit = first.sum(axis=1) + centre
        frac = first.mean(axis=1)
        mixed = np.flatnonzero((lit > 0) & (lit < first.shape[1] + 1))
        if mixed.size and k > m:
            frac[mixed] = visible(mixed, _spiral(k)).mean(axis=1)
        return frac, centre

    def _blocked(self, origin, direction):
        """Shadow rays from ``origin`` ending at ``origin + direction`` (n, 3)."""
        self.rays += origin.shape[0]
        return any_hit(self.bvh, origin, direction, t_max=1.0 - 1e-9)

    def _shadowed(self, origin, ldir, dist, offset):
        """Shadow rays from ``origin`` towards the light's centre moved by ``offset`` (in the
        light's disk for a point light; a direction change for a sun)."""
        if dist is None:                              # sun: a direction, no end
            d = ldir + offset
            return any_hit(self.bvh, origin, d, t_max=np.inf)
        d = ldir * dist[:, None] + offset
        return any_hit(self.bvh, origin, d, t_max=1.0 - 1e-9)

    def patch_incident(self, patches, two_sided=True, *, emitters_only=False):
        """(2P, 3): mean irradiance / pi over every patch, front nodes then back nodes.

        ``PATCH_ORDER`` x ``PATCH_ORDER`` Gauss points per patch (weighted by the bilinear map's
        area element), ``PATCH_SAMPLES`` shadow rays per light at each. Kept for the last
        ``patches`` asked (a relight asks again). ``emitters_only``: the exact emitters' share
        alone.
        """
        cached = self._patch_cache
        if cached is None or cached[0] is not patches or cached[1] != two_sided:
            cached = (patches, two_sided) + self._patch_incident(patches, two_sided)
            self._patch_cache = cached
        return cached[3] if emitters_only else cached[2]

    def _patch_incident(self, patches, two_sided):
        P = patches.areas.size
        c = np.asarray(patches.corners, dtype=np.float64)
        out = np.zeros((2 * P, 3))
        from_emitters = np.zeros((2 * P, 3))
        sides = [(0, 1.0)] + ([(P, -1.0)] if two_sided else [])
        n_lights = len(self.lights)
        near = None
        if self.emitters is not None:
            near = self.emitters.near_patch_means(patches, two_sided)
        everyone = np.arange(P)
        for start, sign in sides:
            near_pairs = {}                          # emitter light -> its near patches
            for j, bare, scale in self._patch_means(patches, everyone, sign, PATCH_ORDER):
                if j >= n_lights:
                    # Patches near an emitter: below, from finer points.
                    p, _ = self._near(near, j - n_lights, start)
                    scale[p] = 0.0
                    if p.size and np.any(self._colour(j) > 0):
                        near_pairs[j] = p
                elif j < self.lights.n_points:
                    # The unshadowed integral of cos / d^2 over a flat patch is the solid angle
                    # it subtends at the light: exact; the samples give only the fraction that
                    # shadows, the cone and the soft falloff leave of it.
                    exact = sign * _solid_angle(c, self.lights.position[j]) / patches.areas
                    scale = np.where(bare > 0, np.maximum(exact, 0.0) * scale
                                     / np.maximum(bare, 1e-300), scale)
                self._add(out, from_emitters, start, j, everyone, scale)
            if near_pairs:
                # Near an emitter the light falls off across a patch, and the shadows of what
                # stands between cut through it: the unshadowed mean integrated from the
                # emitter's side (exact, and power-conserving), times the visible fraction
                # from NEAR_ORDER x NEAR_ORDER points (a patch that straddles the emitter's
                # plane is seen by some of them even where PATCH_ORDER's all miss it).
                again = np.unique(np.concatenate(list(near_pairs.values())))
                for j, bare, scale in self._patch_means(patches, again, sign, NEAR_ORDER):
                    if j not in near_pairs:
                        continue
                    p, exact = self._near(near, j - n_lights, start)
                    k = np.searchsorted(again, p)
                    seen = bare[k] > 0
                    value = np.zeros(p.size)
                    value[seen] = exact[seen] * scale[k[seen]] / bare[k[seen]]
                    self._add(out, from_emitters, start, j, p, value)
        return out / np.pi, from_emitters / np.pi

    @staticmethod
    def _near(near, e, start):
        """(patches, pi F means) of emitter light ``e`` from :meth:`Emitters.near_patch_means`,
        for the front (``start`` 0) or back nodes."""
        light, patch, mean = near
        pick = light == e
        return patch[pick], mean[pick, 0 if start == 0 else 1]

    def _add(self, out, from_emitters, start, j, patches, scale):
        light = scale[:, None] * self._colour(j)[None, :]
        np.add.at(out, start + patches, light)
        if j >= len(self.lights):
            np.add.at(from_emitters, start + patches, light)

    def _patch_means(self, patches, which, sign, order):
        """Per light j: (j, bare, scale), each (len(which),): :meth:`_per_light`'s values
        averaged over ``order`` x ``order`` Gauss points of each patch ``which`` (weighted by
        the bilinear map's area element), seen from the side ``sign`` of its normal."""
        u, v, wt = gauss_square(order)
        R = u.size
        step = max(1, POINT_CHUNK // R)
        bare_mean = np.zeros((len(self), which.size))
        scale_mean = np.zeros((len(self), which.size))
        for a in range(0, which.size, step):
            part = which[a:a + step]
            n = part.size
            c = np.asarray(patches.corners, dtype=np.float64)[part]
            pts, jac = bilinear(c, np.broadcast_to(u, (n, R)), np.broadcast_to(v, (n, R)))
            jac = jac * wt[None]                                             # (n, R)
            jac /= np.maximum(jac.sum(axis=1, keepdims=True), 1e-300)
            nrm = np.repeat(patches.normals[part], R, axis=0)
            faces = np.repeat(patches.face[part], R)
            for j, bare, scale, _ in self._per_light(pts.reshape(-1, 3), sign * nrm,
                                                     PATCH_SAMPLES, faces, dark=True):
                bare_mean[j, a:a + n] = np.einsum("pr,pr->p", jac, bare.reshape(n, R))
                scale_mean[j, a:a + n] = np.einsum("pr,pr->p", jac, scale.reshape(n, R))
        for j in range(len(self)):
            yield j, bare_mean[j], scale_mean[j]


def _solid_angle(corners, p):
    """(P,) solid angle of every patch (P, 4, 3) seen from point ``p``, positive when ``p`` lies
    on the side its normal points to (Van Oosterom & Strackee 1983, two triangles per patch)."""
    out = np.zeros(corners.shape[0])
    for t in ((0, 1, 2), (0, 2, 3)):
        a, b, c = (corners[:, i] - p for i in t)
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        triple = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = la * lb * lc + np.einsum("ij,ij->i", a, b) * lc \
            + np.einsum("ij,ij->i", a, c) * lb + np.einsum("ij,ij->i", b, c) * la
        out -= 2.0 * np.arctan2(triple, den)
    return out
