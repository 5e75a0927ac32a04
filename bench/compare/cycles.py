"""Cycles reference bakes through ``bpy`` (Blender as a Python module, ``.venv``).

The harness reads a scene from Blender (or builds one from arrays), bakes Cycles' DIFFUSE pass
with DIRECT + INDIRECT + COLOR into a FLOAT_COLOR corner attribute of every mesh object, adds each
emitter's own emission (strength x colour: the DIFFUSE pass excludes it) and returns one colour per
corner in the scene's corner order. Reference settings follow docs/blender_facts: total and diffuse
bounces 128 (Cycles' default of 4 diffuse bounces leaves a room ~12 % too dark), both clamps 0,
adaptive sampling off (it would stop pixels at a noise threshold we do not control), a fixed seed.

Corner order = objects sorted by name, each object's loops in order; vertices in world space.
Materials are read from the Principled BSDF of each slot: Base Color = reflectance rho, Emission
Color x Emission Strength = emitted radiance. The scene scripts set Specular IOR Level = 0 so the
Principled BSDF is Lambertian (a specular layer would take energy from the diffuse lobe).
"""

import time

import numpy as np

#: Name of the colour attribute the harness bakes into (created or reused on every mesh).
ATTRIBUTE = "RB_Cycles"

#: Reference bake bounces (docs/blender_facts: 128 makes the truncation bias of a rho <= 0.8 room
#: 0.8^128 ~ 4e-13, i.e. nil).
REFERENCE_BOUNCES = 128


def _principled(material):
    if material is None or material.node_tree is None:
        raise ValueError("material %r must use nodes with a Principled BSDF"
                         % getattr(material, "name", None))
    for node in material.node_tree.nodes:
        if node.type == "BSDF_PRINCIPLED":
            return node
    raise ValueError("material %r has no Principled BSDF node" % material.name)


def material_arrays(material):
    """(rho (3,), emission (3,)) of a Principled material: Base Color, Emission Color x Strength."""
    node = _principled(material)
    rho = np.array(node.inputs["Base Color"].default_value[:3], dtype=np.float64)
    emission = (np.array(node.inputs["Emission Color"].default_value[:3], dtype=np.float64)
                * float(node.inputs["Emission Strength"].default_value))
    return rho, emission


def mesh_objects(bpy_scene):
    """The scene's visible mesh objects, sorted by name (the harness's corner order)."""
    return sorted((ob for ob in bpy_scene.objects if ob.type == "MESH" and not ob.hide_render),
                  key=lambda ob: ob.name)


def extract(bpy_scene):
    """Scene arrays in the layout of ``core.scene.make_scene`` (world space, corner order above).

    Returns
    -------
    dict
        ``vertices`` (V, 3), ``corner_verts`` (C,), ``face_starts`` (F,), ``face_sizes`` (F,),
        ``face_materials`` (F,), ``reflectance`` (M, 3), ``emission`` (M, 3), ``face_objects``
        (F,), ``object_names``, ``material_names``. Materials are numbered by first use.
    """
    verts, corners, starts, sizes, fmats, fobjs = [], [], [], [], [], []
    mat_index, rhos, ems = {}, [], []
    v_off = c_off = 0
    objects = mesh_objects(bpy_scene)
    for oi, ob in enumerate(objects):
        me = ob.data
        if len(ob.modifiers):
            raise ValueError("object %r has modifiers; apply them before benchmarking" % ob.name)
        n_v, n_c, n_f = len(me.vertices), len(me.loops), len(me.polygons)
        co = np.empty(3 * n_v, np.float64)
        me.vertices.foreach_get("co", co)
        m = np.array(ob.matrix_world, dtype=np.float64)
        co = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        cv = np.empty(n_c, np.int64)
        me.loops.foreach_get("vertex_index", cv)
        ls = np.empty(n_f, np.int64)
        me.polygons.foreach_get("loop_start", ls)
        lt = np.empty(n_f, np.int64)
        me.polygons.foreach_get("loop_total", lt)
        mi = np.empty(n_f, np.int64)
        me.polygons.foreach_get("material_index", mi)
        slot_to_global = []
        for slot in ob.material_slots:
            mat = slot.material
            if mat is None:
                raise ValueError("object %r has an empty material slot" % ob.name)
            if mat.name not in mat_index:
                rho, em = material_arrays(mat)
                mat_index[mat.name] = len(rhos)
                rhos.append(rho)
                ems.append(em)
            slot_to_global.append(mat_index[mat.name])
        if not slot_to_global:
            raise ValueError("object %r has no material" % ob.name)
        verts.append(co)
        corners.append(cv + v_off)
        starts.append(ls + c_off)
        sizes.append(lt)
        fmats.append(np.asarray(slot_to_global, np.int64)[np.minimum(mi, len(slot_to_global) - 1)])
        fobjs.append(np.full(n_f, oi, np.int64))
        v_off += n_v
        c_off += n_c
    if not objects:
        raise ValueError("the Blender scene has no mesh object")
    return {
        "vertices": np.concatenate(verts), "corner_verts": np.concatenate(corners),
        "face_starts": np.concatenate(starts), "face_sizes": np.concatenate(sizes),
        "face_materials": np.concatenate(fmats), "reflectance": np.array(rhos),
        "emission": np.array(ems), "face_objects": np.concatenate(fobjs),
        "object_names": tuple(ob.name for ob in objects),
        "material_names": tuple(sorted(mat_index, key=mat_index.get)),
    }


def build(arrays, bpy_scene=None):
    """Create one Blender mesh object per object of ``arrays`` (the ``extract`` layout).

    Used by the tests and to bake procedural core scenes with Cycles. Materials become Principled
    BSDFs with Base Color = rho, Emission Color = emission / max(emission), Strength = max,
    Specular IOR Level = 0. Objects are named ``"%03d_<name>"`` so that ``extract`` keeps order.
    """
    import bpy
    sc = bpy_scene or bpy.context.scene
    refl = np.asarray(arrays["reflectance"], np.float64)
    emis = np.asarray(arrays["emission"], np.float64)
    names = arrays.get("material_names") or tuple("mat%d" % i for i in range(len(refl)))
    mats = [principled_material(names[i], refl[i], emis[i]) for i in range(len(refl))]
    fobj = np.asarray(arrays.get("face_objects", np.zeros(len(arrays["face_starts"]), np.int64)))
    onames = arrays.get("object_names") or tuple("obj%d" % i for i in range(fobj.max() + 1))
    V = np.asarray(arrays["vertices"], np.float64)
    cv = np.asarray(arrays["corner_verts"], np.int64)
    fs = np.asarray(arrays["face_starts"], np.int64)
    fn = np.asarray(arrays["face_sizes"], np.int64)
    fm = np.asarray(arrays["face_materials"], np.int64)
    for oi in range(len(onames)):
        faces = np.flatnonzero(fobj == oi)
        polys = [cv[fs[f]:fs[f] + fn[f]] for f in faces]
        used_v, local = np.unique(np.concatenate(polys), return_inverse=True)
        pos = np.concatenate([[0], np.cumsum([len(p) for p in polys])])
        me = bpy.data.meshes.new(onames[oi])
        me.from_pydata(V[used_v].tolist(), [],
                       [local[pos[k]:pos[k + 1]].tolist() for k in range(len(polys))])
        used_m, slot = np.unique(fm[faces], return_inverse=True)
        for m in used_m:
            me.materials.append(mats[m])
        me.polygons.foreach_set("material_index", slot.astype(np.int32))
        me.update()
        ob = bpy.data.objects.new("%03d_%s" % (oi, onames[oi]), me)
        sc.collection.objects.link(ob)
    return sc


def principled_material(name, rho, emission):
    """A Lambertian Principled BSDF material (Specular IOR Level 0) with the given rho/emission."""
    import bpy
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True  # always on (and deprecated) from Blender 5.0
    node = _principled(mat)
    node.inputs["Base Color"].default_value = (*map(float, rho), 1.0)
    node.inputs["Specular IOR Level"].default_value = 0.0
    node.inputs["Roughness"].default_value = 1.0
    strength = float(np.max(emission))
    colour = np.asarray(emission, np.float64) / strength if strength > 0 else np.ones(3)
    node.inputs["Emission Color"].default_value = (*map(float, colour), 1.0)
    node.inputs["Emission Strength"].default_value = strength
    if strength > 0:
        # Sample the emitter for next-event estimation from both faces: Cycles mesh lights emit
        # from both sides, and AUTO may skip a side it judges unimportant.
        mat.cycles.emission_sampling = "FRONT_BACK"
    return mat


def configure(bpy_scene, samples, seed, threads=2, bounces=REFERENCE_BOUNCES, glossy=0):
    """Set Cycles to reference quality on ``bpy_scene`` (CPU, fixed threads, no clamps);
    ``glossy`` bounces (0: the references' Lambertian materials reflect no glossy light)."""
    if int(samples) < 1:
        raise ValueError("samples must be >= 1; got %r" % samples)
    sc = bpy_scene
    sc.render.engine = "CYCLES"
    cy = sc.cycles
    cy.device = "CPU"
    cy.samples = int(samples)
    cy.seed = int(seed)
    cy.use_animated_seed = False
    cy.use_adaptive_sampling = False
    cy.max_bounces = bounces
    cy.diffuse_bounces = bounces
    cy.glossy_bounces = int(glossy)
    cy.transmission_bounces = 0
    cy.min_light_bounces = 0
    cy.sample_clamp_direct = 0.0
    cy.sample_clamp_indirect = 0.0
    sc.render.threads_mode = "FIXED"
    sc.render.threads = int(threads)
    sc.render.bake.target = "VERTEX_COLORS"


def bake(bpy_scene, samples, seed=0, threads=2, bounces=REFERENCE_BOUNCES, glossy=0):
    """Bake Cycles' diffuse radiance per corner, emission added.

    Parameters
    ----------
    bpy_scene : bpy.types.Scene
        Its mesh objects are baked (all at once, one bake call).
    samples : int
        Samples per corner.
    seed : int
        Cycles seed; two seeds give the noise estimate.

    Returns
    -------
    corner_colours : (C, 3) float64
        Outgoing radiance per corner in the ``extract`` corner order.
    seconds : float
        Wall time of the bake call (scene sync, BVH build and path tracing).
    """
    import bpy
    configure(bpy_scene, samples, seed, threads, bounces, glossy)
    objects = mesh_objects(bpy_scene)
    view_layer = bpy.context.view_layer
    for ob in view_layer.objects:
        ob.select_set(False)
    for ob in objects:
        attrs = ob.data.color_attributes
        attr = attrs.get(ATTRIBUTE)
        if attr is None or attr.data_type != "FLOAT_COLOR" or attr.domain != "CORNER":
            if attr is not None:
                attrs.remove(attr)
            attr = attrs.new(ATTRIBUTE, "FLOAT_COLOR", "CORNER")
        attrs.active_color = attr
        ob.select_set(True)
    view_layer.objects.active = objects[0]
    t0 = time.perf_counter()
    result = bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT", "COLOR"},
                                 target="VERTEX_COLORS", use_clear=True)
    seconds = time.perf_counter() - t0
    if "FINISHED" not in result:
        raise RuntimeError("Cycles bake failed: %r" % (result,))
    out = []
    for ob in objects:
        me = ob.data
        buf = np.empty(4 * len(me.loops), np.float32)
        me.color_attributes[ATTRIBUTE].data.foreach_get("color", buf)
        cc = buf.reshape(-1, 4)[:, :3].astype(np.float64)
        # Add each face's own emission to its corners (the DIFFUSE pass leaves it out).
        emis = np.array([material_arrays(s.material)[1] for s in ob.material_slots])
        mi = np.empty(len(me.polygons), np.int64)
        me.polygons.foreach_get("material_index", mi)
        lt = np.empty(len(me.polygons), np.int64)
        me.polygons.foreach_get("loop_total", lt)
        ls = np.empty(len(me.polygons), np.int64)
        me.polygons.foreach_get("loop_start", ls)
        corner_face = np.empty(len(me.loops), np.int64)
        within = np.arange(lt.sum()) - np.repeat(np.cumsum(lt) - lt, lt)
        corner_face[np.repeat(ls, lt) + within] = np.repeat(np.arange(len(lt)), lt)
        cc += emis[np.minimum(mi, len(emis) - 1)][corner_face]
        out.append(cc)
    return np.concatenate(out), seconds


def load(blend_path):
    """Open a .blend file (replacing the current one) and return its scene."""
    import bpy
    bpy.ops.wm.open_mainfile(filepath=str(blend_path))
    return bpy.context.scene
