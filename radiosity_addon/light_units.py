"""Light groups' units and solutions for relight (:mod:`radiosity_addon.relight`).

:func:`units` lists a kept bake's sources of light (each emissive material, each point, spot
and sun light, the world; Blender's light groups merge what they hold) as :class:`Unit`;
:class:`Solution` is the light of one bake, linear in the emission, as job.apply writes it.
"""

from dataclasses import dataclass, replace

import bpy
import numpy as np

from . import surfaces

#: Group name of the world outside a Blender light group.
WORLD = "World"


@dataclass
class Solution:
    """Light of one bake, linear in the emission: the arrays job.apply writes.

    corner, incident : (C, 3) float64 (incident may be None); mesh_corner, mesh_incident :
    (C_out, 3) float64 or None (radiosity mesh output); surfaces : one (S, 3) float64 per
    calculation surface (``surfaces.incident``: its grid points, then its vertices).
    """

    corner: np.ndarray
    incident: np.ndarray = None
    mesh_corner: np.ndarray = None
    mesh_incident: np.ndarray = None
    surfaces: tuple = ()

    @classmethod
    def of(cls, result, calc_surfaces=()):
        out = result.output
        return cls(result.corner_colours, result.corner_incident,
                   None if out is None else out.corner_colours,
                   None if out is None else out.corner_incident,
                   tuple(surfaces.incident(result, surf) for surf in calc_surfaces))

    def combine(self, other, weight=1.0, own=1.0):
        """``own * self + weight * other``; weights scalar or (3,)."""
        def mix(a, b):
            if a is None or b is None:
                return None
            return own * a + weight * b
        return Solution(mix(self.corner, other.corner), mix(self.incident, other.incident),
                        mix(self.mesh_corner, other.mesh_corner),
                        mix(self.mesh_incident, other.mesh_incident),
                        tuple(mix(a, b) for a, b in zip(self.surfaces, other.surfaces)))

    def scaled(self, weight):
        return self.combine(self, weight, own=0.0)

    def as_result(self, template):
        """A BakeResult like ``template`` (report, mesh) with these colours."""
        output = template.output
        if output is not None:
            output = replace(output, corner_colours=self.mesh_corner,
                             corner_incident=self.mesh_incident)
        return replace(template, corner_colours=self.corner, corner_incident=self.incident,
                       output=output)


@dataclass(frozen=True, eq=False)
class Unit:
    """One source of light of a kept bake; the units of one ``group`` name form one group.

    materials : (k,) int64 emissive material indices, or None for a unit of lights and world;
    lights : indices into the kept core Lights (point and spot lights, then suns); world : the
    unit holds the world (a uniform world, a sky, or a textured world with its sun disc)."""

    group: str
    materials: np.ndarray = None
    lights: tuple = ()
    world: bool = False


def units(bake_input, scene, lights=False):
    """[Unit]: every emissive material, then each point, spot and sun light, then the world.

    ``scene``: the Blender scene (its world's light group). ``lights``: the core Lights now
    (default: the bake's). Objects that all sit in one Blender light group take its name; a
    name of one's own (a material's, a light object's, "World") that a light group or another
    unit already uses gets its kind appended, so only Blender's light groups merge."""
    core_scene, arrays = bake_input.scene, bake_input.extraction.arrays
    if lights is False:
        lights = core_scene.lights
    mats = np.asarray(core_scene.face_materials)
    emits = np.any(np.asarray(core_scene.emission) > 0, axis=1)
    if core_scene.back_emission is not None:
        emits |= np.any(np.asarray(core_scene.back_emission) > 0, axis=1)
    names = arrays.get("material_names") or ()
    objects = np.asarray(arrays.get("face_objects", np.zeros(mats.size, np.int64)))
    object_names = arrays.get("object_names") or ()
    raw = []                       # (light group or "", own name, kind, materials, lights, world)
    for m in np.flatnonzero(emits):
        on = mats == m
        if on.any():
            owners = {object_names[i] for i in np.unique(objects[on]) if i < len(object_names)}
            raw.append((lightgroup(owners), names[m] if m < len(names) else f"Material {m}",
                        "material", np.array([m]), (), False))
    world = core_scene.world is not None
    world_group = (getattr(scene.world, "lightgroup", "") or "") if scene.world else ""
    shining = lights is not None and lights.shines
    power = np.concatenate([lights.intensity, lights.sun_irradiance]) if shining else ()
    for j, light in enumerate(lights.names if shining else ()):
        if not np.any(power[j] > 0):
            continue                              # dark, as a material that does not emit
        if light not in bpy.data.objects and light.startswith("World '"):
            raw.append((world_group, WORLD, "world", None, (j,), False))   # a world's sun disc
        else:
            raw.append((lightgroup({light}), light, "light", None, (j,), False))
    if world:
        raw.append((world_group, WORLD, "world", None, (), True))
    reserved, owner, out = {r[0] for r in raw if r[0]}, {}, {}
    for group, name, kind, materials, js, w in raw:
        if not group:
            group = name
            if group in reserved or owner.setdefault(group, (name, kind)) != (name, kind):
                group = f"{name} ({kind})"
        if materials is not None:
            out[len(out)] = Unit(group, materials)
            continue
        was = out.get(("sources", group), Unit(group))
        out[("sources", group)] = Unit(group, None, was.lights + js, was.world or w)
    return list(out.values())


def lightgroup(object_names):
    """The Blender light group that all these objects share, or ''."""
    groups = {getattr(bpy.data.objects.get(n), "lightgroup", "") or "" for n in object_names}
    return groups.pop() if len(groups) == 1 else ""
