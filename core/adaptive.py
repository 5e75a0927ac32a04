"""The adaptive radiosity mesh: receiver elements refined where the light changes, as the output.

Substructuring (Cohen, Greenberg, Immel & Brock 1986): the solve stays on the coarse patches;
the *elements* of a :class:`core.hierarchy.ElementTree` built from them are receivers only. Each
level, the radiance is gathered at the element vertices the level added (a hemicube at the point
over the solved patches, :mod:`core.gather`: the values already gathered stay valid), and the
leaves are split where

* the luminance differs between the leaf's vertices by more than ``contrast`` relative to the
  brighter one, never relative to less than ``DARK_FLOOR`` x the scene's mean luminance, so that
  darkness does not refine for ever (contrast-driven meshing, Lightscape, Blender 2.4x);
* the emitters' or lights' visibility differs between the leaf's vertices (a shadow boundary
  passes: one shadow ray from every vertex to each of ``SHADOW_SAMPLES`` fixed points on the
  emitters, and to each light's centre) and the contrast exceeds ``SHADOW_CONTRAST`` x
  ``contrast``, even where the light across the parent looked linear;
* a contact line runs along the leaf (the light falls off steeply towards an object's foot) and
  the leaf is larger than ``CONTACT_ELEMENT`` x ``min_element``;

(the criteria and their constants: :mod:`core.criteria`), never below ``min_element`` and
within ``vertex_budget`` points, worst first (score: area times how far over the threshold).

The output is the conforming triangulation of the leaves (``tree.conforming()``): every output
corner gathers as a corner of that triangulation, seen as a scene of its own (the leaves'
faces inherit material and object from their parent faces), so creases, material edges and
contact-line vertices split per corner exactly as at the user's own vertices.

A point none of whose adjacent patches receives any light is not gathered (its radiance is its
emission): surfaces no light reaches cost no hemicube.
"""

import dataclasses
import time

import numpy as np

from .creases import find_creases
from .criteria import (SHADOW_SAMPLES, EmitterSamples, contact_edges, contact_points, dark_floor,
                       interpolation_errors, luminance, per_leaf_scores)
from .duplicates import copy_duplicate_faces
from .elements import bake_elements
from .gather import NORMAL_DECIMALS, corner_groups, corner_values, shade
from .farfield import FarField, Seen, compact_with_sums, seen_subset
from .geometry import spatial_order, unique_rows
from .hemicube import point_rows
from .hierarchy import ElementTree, output_mesh
from .parallel import Deferred, ahead
from .progress import SubMonitor
from .rows import RowStore
from .scene import make_scene

#: Default coarse patch size (m) of the mesh output, clamped to the scene's bounding diagonal
#: times [COARSE_MIN_FRACTION, COARSE_MAX_FRACTION]: 1 m keeps a room's walls at a few dozen
#: patches (the solve carries the energy, the elements carry the detail), a 4 m model gets
#: 0.5 m patches (diag / 8), a 400 m site 1 m.
COARSE_PATCH = 1.0
COARSE_MIN_FRACTION = 1.0 / 400.0
COARSE_MAX_FRACTION = 1.0 / 8.0

#: Default smallest element (m) of the mesh output, at most the bounding diagonal times
#: ELEMENT_MAX_FRACTION. Radiance does not change when a whole scene is scaled, so the features
#: of its light (a penumbra, the dark strip at an object's foot) shrink with the model: in the
#: 0.55 m Cornell box 0.05 m is a tenth of the room, and the penumbra behind its short block
#: (5 to 10 cm) was drawn by one element. Measured (bench/compare/coarse.py, the Cornell box
#: modelled coarsely, diagonal 0.96 m): 0.05 m 4.08 % with 1,262 vertices in 3.0 s, 0.035 m
#: 3.71 % with 1,518, 0.025 m 2.89 % with 2,256 in 3.9 s, 0.02 m 2.83 % with 2,659, 0.015 m
#: 2.78 % with 2,876. Rooms (diagonal 2 m and more) keep 0.05 m.
MIN_ELEMENT = 0.05
ELEMENT_MAX_FRACTION = 1.0 / 40.0

#: Refinement stops after this many levels (a 1 m patch halved 12 times is 0.24 mm).
MAX_LEVELS = 12

#: Estimated new points of one leaf split (a quad adds its centre and four shared midpoints,
#: a triangle three shared midpoints; 2:1 balancing adds some more): used to pick how many
#: leaves fit in the budget. The split is retried with fewer leaves if the estimate was short.
POINTS_PER_SPLIT = 4.0
BUDGET_RETRIES = 6

#: Hemicubes per point_rows call.
GATHER_BATCH = 64

#: Inset directions of per-corner (alone) gathers are matched after rounding to these decimals.
DIRECTION_DECIMALS = 2

OUTPUTS = ("mesh", "vertices")


def coarse_patch_size(scene, patch_size=None):
    """Patch size (m) the solve starts from when the output is the adaptive mesh.

    ``patch_size`` given: used as is. None: ``COARSE_PATCH`` clamped to the bounding diagonal
    times [``COARSE_MIN_FRACTION``, ``COARSE_MAX_FRACTION``].
    """
    if patch_size is not None:
        return float(patch_size)
    diag = scene.bounding_diagonal()
    return float(np.clip(COARSE_PATCH, COARSE_MIN_FRACTION * diag, COARSE_MAX_FRACTION * diag))


def min_element_size(scene, min_element=None):
    """Smallest element edge (m) of the mesh output.

    ``min_element`` given: used as is. None: ``MIN_ELEMENT``, at most the bounding diagonal
    times ``ELEMENT_MAX_FRACTION`` (a scene without extent: ``MIN_ELEMENT``).
    """
    if min_element is not None:
        return float(min_element)
    diag = scene.bounding_diagonal()
    return float(min(MIN_ELEMENT, ELEMENT_MAX_FRACTION * diag)) if diag > 0 else MIN_ELEMENT


class AdaptiveState:
    """What relight needs: the output mesh and the gather rows of its corner groups.

    Attributes
    ----------
    mesh : core.outmesh.OutputMesh
    entry : (C_out,) int64
        Gathered point (index into ``material`` and ``rows``) of every output corner.
    material : (U,) int64
    rows : core.rows.RowStore
        Point-to-node rows of the U points (against the nodes the gathers saw: the solved
        patches, or the receiver elements); points that no light reached have none.
    creases : core.creases.Creases or None
        The rows' entries read at the light of a concave crease (:mod:`core.creases`).
    lit : (P,) bool
        Patches that received light in the bake (relight rebuilds the mesh if more do).
    elements : core.elements.Elements or None
    seen : Seen
        The (lit) patches or elements the gathers drew.
    far_field : core.farfield.FarField or None
        With receiver elements: the rows' columns are its :attr:`~FarField.n_cols` (elements,
        then far patches), read against :meth:`~FarField.radiance`.
    user : (C,) int64
        Output corner whose colour each user corner takes (-1: none, a dropped face).
    direct : (U, 3) float64
        Light from beyond the hemicube's surfaces (irradiance / pi,
        :meth:`core.lights.DirectLight.extra`: the lights' direct light and the world's
        share) at the U points.
    points, normals : (U, 3) float64
        Where the U points gathered, and facing where.
    cast : (U,) bool
        The points whose ``direct`` the lights gave (:mod:`core.recolour` recolours it there).
    """

    def __init__(self, **kw):
        self.__dict__.update(kw)

    def colours(self, scene, node_radiance):
        """(C_out, 3) output corner colours and (C_out, 3) incident light (irradiance / pi)
        for the solved ``node_radiance`` (2P, 3)."""
        L = node_radiance
        if self.elements is not None:
            L = self.elements.node_radiance(scene, node_radiance)
        cols = _rows_radiance(self.seen, self.far_field, L)
        inc = self.rows.incident(cols) + self.direct
        if self.creases is not None:
            inc = self.creases.incident(scene, self.material, inc, cols)
        return shade(scene, self.material, inc)[self.entry], inc[self.entry]


def _rows_radiance(seen, far_field, node_radiance):
    """(n_cols, 3) radiance the kept gather rows read from the (2E, 3) radiance of the nodes
    ``seen`` was taken from: the seen nodes', then (with a far field) its far patches'."""
    L = seen.radiance(node_radiance)
    return L if far_field is None else far_field.radiance(L)


def _leaf_scene(scene, tree, conf, flipped=None):
    """The conforming triangulation of the leaves as a Scene of its own (the faces of ``flipped``
    user faces with their normals reversed: gathered on the side that faces the room)."""

    leaf = conf["face_leaf"]
    out = make_scene(tree.points, conf["corner_verts"], conf["face_starts"], conf["face_sizes"],
                      np.asarray(tree.material)[leaf], scene.reflectance, scene.emission,
                      face_objects=scene.face_objects[conf["face_parent"]],
                      object_names=scene.object_names, material_names=scene.material_names,
                      back_reflectance=scene.back_reflectance, back_emission=scene.back_emission,
                      lights=scene.lights, world=scene.world)
    if flipped is None or not flipped.any():
        return out
    turn = flipped[conf["face_parent"]]
    normals = np.where(turn[:, None], -out.face_normals, out.face_normals)
    normals.setflags(write=False)
    return dataclasses.replace(out, face_normals=normals)


class _Cache:
    """Gathered groups, keyed by (point, material, normal, inset direction of alone groups)."""

    def __init__(self, n_nodes):
        self.keys = np.zeros((0, 8))
        self.incident = np.zeros((0, 3))
        self.direct = np.zeros((0, 3))
        self.vis = np.zeros(0, dtype=np.int64)
        self.points = np.zeros((0, 3))
        self.normals = np.zeros((0, 3))
        self.cast = np.zeros(0, dtype=bool)
        self.batches = []                      # (key ids (S,), cols (K,), vals (S, K) f32)
        self.n_nodes = n_nodes

    def lookup(self, keys):
        """Index of every key row in the cache (-1: new)."""
        if self.keys.shape[0] == 0:
            return np.full(keys.shape[0], -1, dtype=np.int64)
        both = np.concatenate([self.keys, keys])
        inv = unique_rows(both)[1]
        where = np.full(inv.max() + 1, -1, dtype=np.int64)
        where[inv[:self.keys.shape[0]]] = np.arange(self.keys.shape[0])
        return where[inv[self.keys.shape[0]:]]

    def add(self, keys, incident, vis, direct, points, normals, cast):
        start = self.keys.shape[0]
        self.points = np.concatenate([self.points, points])
        self.normals = np.concatenate([self.normals, normals])
        self.cast = np.concatenate([self.cast, cast])
        self.keys = np.concatenate([self.keys, keys])
        self.incident = np.concatenate([self.incident, incident])
        self.direct = np.concatenate([self.direct, direct])
        self.vis = np.concatenate([self.vis, vis])
        return np.arange(start, start + keys.shape[0])

    def rows_for(self, ids):
        """A RowStore whose group g is cache entry ``ids[g]`` (``ids`` distinct; entries never
        gathered get no row: their incident light is zero). Empties the cache's rows. A half
        store (:data:`core.rows.HALF_SHIFT`): the rows weigh one bounce, are never solved."""
        store = RowStore(ids.size, self.n_nodes, half=True)
        pos = np.full(self.keys.shape[0], -1, dtype=np.int64)
        pos[ids] = np.arange(ids.size)
        # The cache's batches are handed over (a batch whose rows are all kept is not copied)
        # and let go one by one: the rows are not held twice at the end of a large bake.
        batches, self.batches = self.batches, []
        batches.reverse()
        while batches:
            kid, cols, vals = batches.pop()
            g = pos[kid]
            ok = g >= 0
            if ok.all():
                store.add_compact(g, cols, vals)
            elif ok.any():
                store.add_compact(g[ok], cols, vals[ok])
        return store


def _group_keys(leaf_scene, groups, alone):
    """(G, 8) float64 cache keys of the corner groups."""
    ok = np.flatnonzero(groups.group >= 0)
    G = groups.points.shape[0]
    vertex = np.zeros(G, dtype=np.int64)
    vertex[groups.group[ok]] = leaf_scene.corner_verts[ok]
    direction = groups.points - leaf_scene.vertices[vertex]
    length = np.linalg.norm(direction, axis=1, keepdims=True)
    direction = np.divide(direction, length, out=np.zeros_like(direction), where=length > 0)
    direction[~alone[vertex]] = 0.0
    keys = np.concatenate([vertex[:, None].astype(np.float64),
                           groups.material[:, None].astype(np.float64),
                           np.round(groups.normals, NORMAL_DECIMALS),
                           np.round(direction, DIRECTION_DECIMALS)], axis=1)
    return keys


def _split_within(tree, score, budget):
    """Split the worst leaves that fit in ``budget`` points; None when none fits."""
    cand = np.flatnonzero(score > 0)
    cand = cand[np.argsort(-score[cand], kind="stable")]
    n_fit = int((budget - tree.points.shape[0]) // POINTS_PER_SPLIT)
    take = cand[:max(n_fit, 0)]
    for _ in range(BUDGET_RETRIES):
        if take.size == 0:
            return None
        mask = np.zeros(tree.leaves.shape[0], dtype=bool)
        mask[take] = True
        new, _ = tree.split(mask)
        if new.points.shape[0] <= budget:
            return new, int(take.size)
        take = take[:take.size // 2]
    return None


def adaptive_output(scene, settings, patches, node_radiance, incident, *, contacts=None,
                    monitor=None, direct=None, flipped=None):
    """Refine the receiver elements where the light changes; gather at their vertices.

    Parameters
    ----------
    scene : core.scene.Scene
    settings : core.bake.BakeSettings
        Uses ``contrast``, ``min_element``, ``vertex_budget``, ``crease_angle``,
        ``element_levels``/``element_threshold`` (the receiver elements the gathers see),
        ``resolution``, ``rotate_hemicube``, ``seed``.
    patches : core.patches.Patches
        The solved patches (P).
    node_radiance : (2P, 3) float64
        Solved radiance.
    incident : (2P, 3) float64
        Power arriving at every node: points next to no lit patch are not gathered.
    contacts : core.contacts.Contacts, optional
        Contact lines: points on them gather per corner and leaves along them refine.
    monitor : core.progress.Monitor or SubMonitor, optional
    direct : core.lights.DirectLight, optional
        The point, spot and sun lights: their direct light is added at every gathered point,
        and a change in which of them a leaf's vertices see marks a shadow edge.
    flipped : (F,) bool, optional
        User faces baked on their back side (:mod:`core.orient`): their points gather along the
        reversed normal.

    Returns
    -------
    mesh : core.outmesh.OutputMesh
    state : AdaptiveState
    report : dict
        ``levels`` (per level: leaves, points, split, gathered, unlit (points not gathered),
        marked by contrast / shadow / contact, seconds), ``leaves``, ``points``, ``budget_hit``.
    """

    L = np.asarray(node_radiance, dtype=np.float64)
    P = patches.areas.size
    seen, seen_L = patches, L
    gather_monitor = monitor
    elements = bake_elements(scene, patches, L, settings,
                             None if monitor is None else SubMonitor(monitor, 0.0, 0.2), direct)
    if elements is not None:
        seen, seen_L = elements.patches, elements.node_radiance(scene, L)
        gather_monitor = None if monitor is None else SubMonitor(monitor, 0.2, 1.0)
    power = np.asarray(incident)
    if elements is not None:                 # an element has light if its patch has
        power = np.concatenate([power[elements.parent], power[P + elements.parent]])
    if scene.world is None:         # with a world, unlit surfaces still hide the sky
        seen = seen_subset(seen, seen_L, power)
    else:
        seen = Seen(seen, np.arange(seen.areas.size))
    far_field = None
    if elements is not None:
        far_field = FarField(patches, seen, np.asarray(elements.parent)[seen.keep])
    seen_L = _rows_radiance(seen, far_field, seen_L)
    emission = np.asarray(scene.emission)
    lit = _lit(scene, patches, incident, flipped)
    floor = dark_floor(patches, L[:P], scene)
    rng = np.random.default_rng([settings.seed, 2])
    emitters = EmitterSamples(scene, patches, np.random.default_rng([settings.seed, 4]))
    cache = _Cache(seen_L.shape[0])
    tree = ElementTree.from_patches(scene, patches)
    outline = contact_edges(scene, tree, contacts)
    steps = []
    budget_hit = False
    # A split keeps the old points and appends new ones: only those are tested against the
    # contact lines (each test costs points x segments; the office's 14,669 points against
    # its lines took 0.28 s per level, every level).
    alone = np.zeros(0, dtype=bool)
    for level in range(MAX_LEVELS + 1):
        t0 = time.perf_counter()
        conf = tree.conforming()
        leaf_scene = _leaf_scene(scene, tree, conf, flipped)
        fresh = tree.points[alone.size:]
        alone = np.concatenate([alone, contact_points(fresh, contacts)
                                | contact_points(fresh, outline)])
        groups = corner_groups(leaf_scene, crease_angle=settings.crease_angle, on_contact=alone)
        keys = _group_keys(leaf_scene, groups, alone)
        ids = cache.lookup(keys)
        new = np.flatnonzero(ids < 0)
        # Points next to no lit patch see no light: no hemicube.
        ok = np.flatnonzero(groups.group >= 0)
        face_of = np.repeat(np.arange(conf["face_sizes"].size), conf["face_sizes"])
        corner_patch = np.asarray(tree.leaf_patch)[conf["face_leaf"][face_of]]
        group_lit = np.zeros(groups.points.shape[0], dtype=bool)
        np.logical_or.at(group_lit, groups.group[ok], lit[corner_patch[ok]])
        dark = new[~group_lit[new]]
        group_lit[dark] = _sees_a_light(groups.points[dark], groups.normals[dark], emitters,
                                        direct)
        go = new[group_lit[new]]
        go = go[spatial_order(groups.points[go])]
        inc = np.zeros((new.size, 3))
        dl = np.zeros((new.size, 3))
        covered = np.ones(new.size)
        sky = None if direct is None else direct.sky
        sky_in = None if sky is None else np.zeros((new.size, 3))
        vis = np.zeros(new.size, dtype=np.int64)
        batches = []
        pos_in_new = np.searchsorted(new, go)
        kw = dict(resolution=settings.resolution, rotate=settings.rotate_hemicube, rng=rng,
                  later=True)

        def begin(s):
            """The rows of batch ``s`` started (on the worker processes, if the bake uses
            them), and the array its sky light fills when they are ready."""
            g = go[s:s + GATHER_BATCH]
            light = None if sky is None else np.zeros((g.size, 3))
            extra = {} if sky is None else dict(sky=sky, sky_out=light)
            if not seen.areas.size:    # nothing lit to see (exact emitters light a black room)
                return Deferred(lambda n=g.size: (np.zeros(0, dtype=np.int64),
                                                  np.zeros((n, 0), dtype=np.float32),
                                                  np.zeros(n))), light
            if far_field is None:
                return point_rows(seen, groups.points[g], groups.normals[g], **kw,
                                  **extra).then(compact_with_sums), light
            return far_field.rows(groups.points[g], groups.normals[g], compact=True, **kw,
                                  **extra), light

        # Batches start ahead of their use (core.parallel.ahead): this process finishes one
        # while the workers draw the next; used in order, so nothing depends on the timing.
        for s0, (job, light) in ahead(range(0, go.size, GATHER_BATCH), begin):
            cols, vals, sums = job.result()
            at = pos_in_new[s0:s0 + GATHER_BATCH]
            inc[at] = vals.astype(np.float64) @ seen_L[cols]
            covered[at] = sums
            if sky is not None:
                sky_in[at] = light
            batches.append((at, cols, vals))
            if gather_monitor is not None:
                done = (s0 + vals.shape[0]) / go.size      # level k: [1 - 2^-k, 1 - 2^-(k+1)]
                gather_monitor.update(1.0 - 0.5 ** level * (1.0 - 0.5 * done),
                                      f"mesh: level {level}, {tree.points.shape[0]} points")
        if go.size:
            vis[pos_in_new] = emitters.visibility(groups.points[go], groups.normals[go])
            if direct is not None:
                dl[pos_in_new], bits = direct.extra(
                    groups.points[go], groups.normals[go], covered[pos_in_new], bits=True,
                    sky=None if sky is None else sky_in[pos_in_new])
                inc[pos_in_new] += dl[pos_in_new]
                vis[pos_in_new] |= bits << SHADOW_SAMPLES
        cast = np.zeros(new.size, dtype=bool)
        cast[pos_in_new] = direct is not None
        added = cache.add(keys[new], inc, vis, dl, groups.points[new], groups.normals[new], cast)
        cache.batches.extend((added[p], cols, vals) for p, cols, vals in batches)
        batches = None                       # the cache holds them now
        ids[new] = added
        corner_value, corner_inc = corner_values(scene, leaf_scene.corner_verts, groups,
                                                 cache.incident[ids])
        C = leaf_scene.n_corners
        step = dict(level=level, leaves=int(tree.leaves.shape[0]),
                    points=int(tree.points.shape[0]), gathered=int(go.size),
                    unlit=int(new.size - go.size))
        if level == MAX_LEVELS:
            steps.append(step | dict(seconds=time.perf_counter() - t0))
            break
        corner_vis = np.zeros(C, dtype=np.int64)
        corner_vis[ok] = cache.vis[ids][groups.group[ok]]
        emitting_leaf = np.any(emission[np.asarray(tree.material)] > 0, axis=1)
        corner_y = luminance(corner_value)
        interp = interpolation_errors(tree, leaf_scene.corner_verts[ok], corner_y[ok],
                                      floor)[leaf_scene.corner_verts]
        score, marked = per_leaf_scores(tree, conf, corner_y, corner_vis,
                                        alone[leaf_scene.corner_verts], emitting_leaf, floor,
                                        settings, corner_interp=interp)
        step.update(marked)
        split = _split_within(tree, score, settings.vertex_budget) if score.any() else None
        if split is None:
            budget_hit = bool(score.any())
            steps.append(step | dict(split=0, seconds=time.perf_counter() - t0))
            break
        tree, n_split = split
        steps.append(step | dict(split=n_split, seconds=time.perf_counter() - t0))

    if far_field is not None:
        far_field.release()
    u_ids, entry = np.unique(ids, return_inverse=True)
    entry = entry.reshape(-1)
    rows = cache.rows_for(u_ids)
    cache.incident[u_ids] = rows.incident(seen_L) + cache.direct[u_ids]   # as a relight reads
    material = cache.keys[u_ids, 1].astype(np.int64)
    creases = find_creases(cache.points[u_ids], cache.normals[u_ids], rows, seen,
                           crease_angle=settings.crease_angle)
    if len(creases):
        cache.incident[u_ids] = creases.incident(scene, material, cache.incident[u_ids], seen_L)
    corner_value, corner_inc = corner_values(scene, leaf_scene.corner_verts, groups,
                                             cache.incident[ids])
    mesh = output_mesh(scene, tree, conf, corner_value)
    corner_entry = np.zeros(leaf_scene.n_corners, dtype=np.int64)
    corner_entry[ok] = entry[groups.group[ok]]
    mesh, copied = copy_duplicate_faces(scene, mesh)   # stability (issue 11): duplicates' faces
    corner_entry = corner_entry[copied]
    mesh = dataclasses.replace(mesh, corner_incident=corner_inc[copied])
    state = AdaptiveState(mesh=mesh, entry=corner_entry,
                          material=material, rows=rows, creases=creases, lit=lit,
                          elements=elements, seen=seen,
                          far_field=far_field,
                          user=_user_corners(scene, mesh), direct=cache.direct[u_ids],
                          points=cache.points[u_ids], normals=cache.normals[u_ids],
                          cast=cache.cast[u_ids])
    report = dict(levels=steps, leaves=int(tree.leaves.shape[0]),
                  points=int(tree.points.shape[0]), budget_hit=budget_hit,
                  crease_entries=len(creases), per_object=per_object_report(scene, mesh))
    if elements is not None:
        report["elements"] = _elements_report(elements)
    return mesh, state, report


def _sees_a_light(points, normals, emitters, direct):
    """(n,) bool: points of unlit patches that see an emitter sample or receive a light's
    direct light all the same.

    A patch is unlit when its solve received nothing, which is judged at its centre: a patch
    whose centre lies in an object's umbra while its corner lies in the penumbra received
    nothing where nothing else lights it (black surroundings, no world), and its lit corner
    would read black. Measured: the Cornell box's floor behind the short block, every other
    surface black, hemicube emitters: points 0.2-0.5 of the open floor's light read 0.
    """
    if points.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    out = emitters.visibility(points, normals) != 0
    if direct is not None:
        out |= np.any(direct.incident(points, normals) > 0, axis=1)
    return out


def _lit(scene, patches, incident, flipped=None):
    """(P,) bool: patches that receive light (on the side baked: the back of ``flipped`` faces)
    or emit it."""
    P = patches.areas.size
    inc = np.asarray(incident)
    if flipped is not None and flipped.any():
        turn = flipped[patches.face]
        inc = np.where(turn[:, None], inc[P:], inc[:P])
    return np.any(inc[:P] > 0, axis=1) \
        | np.any(np.asarray(scene.emission)[patches.material] > 0, axis=1)


def _elements_report(elements):
    return dict(elements=int(elements.parent.size), gathered=int(elements.computed.size),
                levels=elements.levels)


def _user_corners(scene, mesh):
    """(C,) int64: an output corner at the same position in the same face as each user corner
    (-1: none, for corners of dropped faces)."""
    corners, faces = scene.face_corner_indices()
    user_keys = np.concatenate([faces[:, None].astype(np.float64),
                                scene.vertices[scene.corner_verts[corners]]], axis=1)
    out_face = mesh.face_parent[mesh.face_of_corner()]
    out_keys = np.concatenate([out_face[:, None].astype(np.float64),
                               mesh.vertices[mesh.corner_verts]], axis=1)
    both = np.concatenate([out_keys, user_keys])
    _, inv = np.unique(both, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    where = np.full(inv.max() + 1, -1, dtype=np.int64)
    where[inv[:out_keys.shape[0]]] = np.arange(out_keys.shape[0])
    user = np.full(scene.n_corners, -1, dtype=np.int64)
    user[corners] = where[inv[out_keys.shape[0]:]]
    face_of = np.full(scene.n_corners, -1, dtype=np.int64)
    face_of[corners] = faces
    user[(face_of < 0) | ~scene.face_valid[np.maximum(face_of, 0)]] = -1
    return user


def per_object_report(scene, mesh):
    """Per object name: input faces -> output vertices and faces."""
    out = {}
    obj_of_face = scene.face_objects[mesh.face_parent]
    obj_of_corner = obj_of_face[mesh.face_of_corner()]
    for o, name in enumerate(scene.object_names):
        baked = scene.face_valid if scene.face_duplicate_of is None \
            else scene.face_valid | (scene.face_duplicate_of >= 0)
        n_in = int(np.count_nonzero((scene.face_objects == o) & baked))
        if n_in == 0:
            continue
        verts = np.unique(mesh.corner_verts[obj_of_corner == o])
        out[name] = dict(input_faces=n_in, output_faces=int(np.count_nonzero(obj_of_face == o)),
                         output_vertices=int(verts.size))
    return out


def mesh_colours(scene, settings, patches, node_radiance, incident, state, contacts, monitor,
                 direct, fallback, flipped=None):
    """The 'mesh' output's colours stage of a bake or a relight.

    A relight (``state`` an :class:`AdaptiveState`) keeps the mesh and re-shades its kept rows;
    if light now reaches patches it did not reach before (points there were never gathered),
    the mesh is rebuilt.

    Returns
    -------
    colours : (C, 3) float64
        User corner colours (the output corner at the same place; ``fallback(...)`` for the
        corners of dropped faces).
    mesh : OutputMesh
    state : AdaptiveState
    report : dict
    """
    lit = _lit(scene, patches, incident, flipped)
    t0 = time.perf_counter()
    if isinstance(state, AdaptiveState) and not np.any(lit & ~state.lit):
        value, inc = state.colours(scene, node_radiance)
        mesh = dataclasses.replace(state.mesh, corner_colours=value, corner_incident=inc)
        state = AdaptiveState(**{**state.__dict__, "mesh": mesh})
        report = dict(rebuilt=False, per_object=per_object_report(scene, mesh))
        if state.elements is not None:
            report["elements"] = _elements_report(state.elements)
    else:
        rebuilt = isinstance(state, AdaptiveState)       # a relight that lights new patches
        mesh, state, report = adaptive_output(scene, settings, patches, node_radiance, incident,
                                              contacts=contacts, monitor=monitor, direct=direct,
                                              flipped=flipped)
        report["rebuilt"] = rebuilt
    colours = np.zeros((scene.n_corners, 3))
    has = state.user >= 0
    colours[has] = mesh.corner_colours[state.user[has]]
    if not has.all():
        colours[~has] = fallback()[~has]
    report["seconds"] = time.perf_counter() - t0
    return colours, mesh, state, report
