"""Flipped normals: bake the side of every face that receives the light.

Models imported from CAD often have faces whose normal points out of the room (into the wall,
the slab, the outside). The solve does not care: with two-sided materials (the default, Cycles'
behaviour) the back of a face reflects and emits like its front, so both sides are solved. What
goes wrong is the output: the corner colours are the front side's, and a flipped face shows the
unlit side that faces the wall.

Convention (docs/design.md, "Orientation"): after the solve, a face whose back side receives
more light than its front (power summed over its patches) is *flipped*: its corner colours and
``patch_radiance`` are those of the back side, the side that faces the room, and the report
names the objects. An emitter's own light makes that test meaningless (a lamp just under the
ceiling lights the ceiling, which lights the lamp's back), so an emitter is flipped when its
front's light mostly leaves the scene (row sum < ``OPEN_SIDE``) while its back's does not:
its front faces the outside. Likewise any face with one side open to the outside (row sum below
``OPEN_SIDE``) and the other closed in, both sides lit, bakes its closed side: the room side of a
wall whose outside the sun lights. Nothing is changed in the user's data. With
``two_sided=False`` back sides are black by request and nothing is flipped.
"""

import dataclasses

import numpy as np

#: A face is flipped when its back side receives more than this times its front side's power.
BACKLIGHT_RATIO = 1.0

#: ... and when its back's irradiance exceeds this fraction of the scene's mean irradiance (a
#: face dark on both sides, like the bottom of a box standing on the floor, stays as it is).
MIN_LIT = 0.01

#: An emitter side whose form factors sum below this faces the outside (most of its light
#: leaves the scene).
OPEN_SIDE = 0.5

#: Objects named in the warning at most.
MAX_NAMED = 5


def flipped_faces(scene, patches, incident, row_sums=None, keep_open=False, detail=False):
    """(F,) bool: faces whose room side is their back (``detail``: and (F,) bool, the faces
    whose back is open to the outside and their front closed in: lit from behind by design).

    Parameters
    ----------
    scene : core.scene.Scene
    patches : core.patches.Patches
        ``P`` patches.
    incident : (2P, 3) float
        Power arriving at every node / pi (front p, back p + P).
    row_sums : (2P,) float, optional
        Form-factor row sum of every node (NaN where not computed). Without it emitters are
        never flipped.
    keep_open : bool
        A face open to the outside on both sides keeps the side its normal points to (with a
        world, both sides of a free-standing wall or a ground plane are lit, and Cycles bakes
        the normal's side).
    """
    P = len(patches.areas)
    power = np.asarray(incident, dtype=np.float64).sum(axis=1)
    F = scene.n_faces
    front = np.bincount(patches.face, weights=power[:P], minlength=F)
    back = np.bincount(patches.face, weights=power[P:], minlength=F)
    area = np.bincount(patches.face, weights=patches.areas, minlength=F)
    mean_irradiance = power.sum() / max(2.0 * float(area.sum()), np.finfo(float).tiny)
    back_lit = back > MIN_LIT * mean_irradiance * area
    flipped = (back > BACKLIGHT_RATIO * front) & back_lit
    emits = np.zeros(F, dtype=bool)
    emits[patches.face[np.any(np.asarray(scene.emission)[patches.material] > 0, axis=1)]] = True
    flipped &= ~emits
    open_back = np.zeros(F, dtype=bool)
    if row_sums is not None:
        s = np.asarray(row_sums, dtype=np.float64)
        known = np.isfinite(s[:P]) & np.isfinite(s[P:])
        w = np.where(known, patches.areas, 0.0)
        wsum = np.bincount(patches.face, weights=w, minlength=F)
        fr = np.bincount(patches.face, weights=w * np.nan_to_num(s[:P]), minlength=F)
        bk = np.bincount(patches.face, weights=w * np.nan_to_num(s[P:]), minlength=F)
        open_front = (fr < OPEN_SIDE * wsum) & (bk >= OPEN_SIDE * wsum) & (wsum > 0)
        open_back = (bk < OPEN_SIDE * wsum) & (fr >= OPEN_SIDE * wsum) & (wsum > 0)
        flipped |= emits & open_front
        # A face with one side open to the outside and the other closed in faces the room with
        # the closed side, whichever side the light reaches more: the sun on a room's outside
        # walls, or a lamp outside a window, must not turn the walls inside out.
        flipped = np.where(~emits & open_back, False, flipped)
        flipped = np.where(~emits & open_front & back_lit, True, flipped)
        if keep_open:
            both_open = (fr < OPEN_SIDE * wsum) & (bk < OPEN_SIDE * wsum) & (wsum > 0)
            flipped &= ~(both_open & ~emits)
    return (flipped, open_back) if detail else flipped


@dataclasses.dataclass(frozen=True)
class Orientation:
    """The side of every face that is baked.

    Attributes
    ----------
    flipped : (F,) bool
    scene : core.scene.Scene
        The scene with the flipped faces' normals reversed (for the corner gathers).
    patches : core.patches.Patches
        The patches with the flipped faces' patch normals reversed (for the patch average).
    patch_flipped : (P,) bool
    open_back : (F,) bool or None
        Faces whose back is open to the outside and front closed in (their back may be lit
        more, by the sun on a room's outside: no sign of a flipped normal).
    """

    flipped: np.ndarray
    scene: object
    patches: object
    patch_flipped: np.ndarray
    open_back: np.ndarray = None

    def room_side(self, node_radiance):
        """(P, 3): the radiance of every patch on its baked side."""
        L = np.asarray(node_radiance)
        P = self.patch_flipped.size
        return np.where(self.patch_flipped[:, None], L[P:], L[:P])

    def warning(self):
        """The report's warning naming the objects with flipped faces, or None."""
        faces = np.flatnonzero(self.flipped)
        if faces.size == 0:
            return None
        scene = self.scene
        objs = np.unique(scene.face_objects[faces])
        names = ", ".join(f'"{scene.object_names[o]}"' for o in objs[:MAX_NAMED])
        more = f" and {objs.size - MAX_NAMED} more" if objs.size > MAX_NAMED else ""
        emit = np.asarray(scene.emission)[scene.face_materials[faces]].max(axis=1) > 0
        lamps = f" ({int(emit.sum())} of them emitting)" if emit.any() else ""
        return (f"{faces.size} faces{lamps} receive their light on the back side (flipped "
                f"normals?) in objects {names}{more}: baked on the side that receives the light")


def orient(scene, patches, incident, two_sided, flipped=None, row_sums=None):
    """The :class:`Orientation` of a solved bake (``flipped`` given: reuse it, e.g. relight)."""
    open_back = None
    if flipped is None:
        if two_sided:
            flipped, open_back = flipped_faces(scene, patches, incident, row_sums,
                                               keep_open=scene.world is not None, detail=True)
        else:
            flipped = np.zeros(scene.n_faces, dtype=bool)
    flipped = np.asarray(flipped, dtype=bool)
    patch_flipped = flipped[patches.face]
    if not flipped.any():
        return Orientation(flipped, scene, patches, patch_flipped, open_back)
    normals = np.where(flipped[:, None], -scene.face_normals, scene.face_normals)
    normals.setflags(write=False)
    p_normals = np.where(patch_flipped[:, None], -patches.normals, patches.normals)
    return Orientation(flipped, dataclasses.replace(scene, face_normals=normals),
                       dataclasses.replace(patches, normals=p_normals), patch_flipped, open_back)
