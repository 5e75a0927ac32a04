"""The adaptive radiosity mesh (output_mode='mesh'): the written field, checked against closed forms.

Oracles, independent of the engine:

* a one-quad floor under a one-quad emitter (no other surface): the floor's radiance is
  ``rho Le F(x -> emitter)``, F by the contour integral (core.exact.point_polygon_form_factor,
  form_factors.md);
* the white furnace: ``B = E / (1 - rho)`` everywhere;
* a black box on a one-quad floor under an area light: ``rho Le F_vis(x)``, F_vis by quadrature
  over the light (a 48 x 48 midpoint grid) with one shadow ray per node
  (core.raycast.any_hit against the box's own triangles, not the engine's patches);
* linearity of relight in the emission.

The written field is read the way a renderer reads it: the OutputMesh corner colours
interpolated linearly over the triangles of its faces (quads split 0-1-2, 0-2-3).
"""

import numpy as np
import pytest

from core import BakeSettings, SettingsError, bake, relight, scene_from_polygons
from core.criteria import STEEP_FLOOR
from core.exact import point_polygon_form_factor
from core.raycast import any_hit, build_bvh
from bench.scenes import furnace_box, room_with_boxes
from builders import floor_field as interpolate

LE, RHO = 10.0, 0.5

#: The written field agrees with the exact one within this on the mean (issue 9: 2 %; the old
#: output, 'vertices', is off by more than VERTICES_OFF on the mean), and everywhere within
#: FIELD_MAX_TOL of the peak: single vertex gathers carry the hemicube's aliasing at R = 64
#: (measured up to 3 % of the peak at a vertex, 2.3 % in the interpolated field).
FIELD_TOL = 0.02
FIELD_MAX_TOL = 0.035
VERTICES_OFF = 0.15
#: Furnace: B = E / (1 - rho) within this (hemicube rows sum to 1 within the pixel error).
FURNACE_TOL = 0.01
#: Umbra: at most this fraction of the open floor (issue 9); penumbra: within this fraction of
#: the open floor of the quadrature (hemicube point gather + linear interpolation).
UMBRA_MAX = 0.05
PENUMBRA_TOL = 0.05


def one_quad_scene():
    """A 4 x 4 m floor as ONE quad, a 1 x 1 m emitter as ONE quad 2 m above its centre."""
    v = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0],
                  [1.5, 1.5, 2], [1.5, 2.5, 2], [2.5, 2.5, 2], [2.5, 1.5, 2]], float)
    return scene_from_polygons(v, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 1],
                               [[RHO] * 3, [0.0] * 3], [[0.0] * 3, [LE] * 3])


def floor_points(n=12, lo=0.05, hi=3.95):
    t = np.linspace(lo, hi, n)
    return np.array([[x, y, 0.0] for x in t for y in t])


@pytest.fixture(scope="module")
def one_quad():
    scene = one_quad_scene()
    return scene, bake(scene, BakeSettings(output_mode="mesh"))


def test_one_quad_receiver_matches_the_exact_field(one_quad):
    scene, result = one_quad
    pts = floor_points()                                         # 144 points inside the floor
    light = scene.vertices[[4, 5, 6, 7]][None]
    exact = RHO * LE * point_polygon_form_factor(pts, np.tile([0, 0, 1.0], (len(pts), 1)),
                                                 light)[:, 0]
    field = interpolate(result.output, pts)[:, 0]
    mean_err = np.mean(np.abs(field - exact)) / np.mean(exact)
    assert mean_err <= FIELD_TOL, f"mean error {mean_err:.3%}"
    err = np.abs(field - exact) / exact.max()
    assert err.max() <= FIELD_MAX_TOL, f"max error {err.max():.3%} of the peak"
    # The same engine writing only at the user's corners cannot show the pool of light.
    old = bake(scene, BakeSettings(output_mode="vertices"))
    assert old.output is None
    floor = old.corner_colours[:4, 0]                            # bilinear over the one quad
    u, v = pts[:, 0] / 4, pts[:, 1] / 4
    old_field = (floor[0] * (1 - u) * (1 - v) + floor[1] * u * (1 - v) + floor[2] * u * v
                 + floor[3] * (1 - u) * v)
    assert np.mean(np.abs(old_field - exact)) / np.mean(exact) > VERTICES_OFF
    assert old.report["face_variation"]["area_share_varying"] == pytest.approx(1.0)


def test_output_mesh_is_conforming_and_carries_the_user_corners(one_quad):
    scene, result = one_quad
    mesh = result.output
    f = mesh.face_of_corner()
    nxt = np.arange(mesh.corner_verts.size) + 1
    last = mesh.face_starts + mesh.face_sizes - 1
    nxt[last] = mesh.face_starts
    a, b = mesh.corner_verts, mesh.corner_verts[nxt]
    for parent in range(scene.n_faces):
        sel = mesh.face_parent[f] == parent
        key = np.sort(np.stack([a[sel], b[sel]], 1), axis=1)
        _, count = np.unique(key, axis=0, return_counts=True)
        assert set(count.tolist()) <= {1, 2}       # boundary once, interior exactly twice
        # Boundary edges lie on the user's polygon: the union covers the face without cracks.
        area = 0.0
        for s, n in zip(mesh.face_starts[mesh.face_parent == parent],
                        mesh.face_sizes[mesh.face_parent == parent]):
            p = mesh.vertices[mesh.corner_verts[s:s + n]]
            area += 0.5 * np.linalg.norm(sum(np.cross(p[i], p[(i + 1) % n]) for i in range(n)))
        assert area == pytest.approx(scene.face_areas[parent], rel=1e-9)
    # BakeResult.corner_colours at the user's corners are the mesh's values there.
    corner = result._state.gather.user
    assert np.all(corner >= 0)
    np.testing.assert_array_equal(result.corner_colours, mesh.corner_colours[corner])
    obj = result.report["mesh"]["per_object"]["object 0"]
    assert obj["input_faces"] == 2 and obj["output_vertices"] == mesh.vertices.shape[0]


def test_relight_rescales_the_mesh_linearly(one_quad):
    scene, result = one_quad
    again = relight(result, emission=2.0 * np.asarray(scene.emission))
    assert again.output.vertices is result.output.vertices
    np.testing.assert_allclose(again.output.corner_colours, 2.0 * result.output.corner_colours,
                               rtol=1e-9, atol=1e-12)


def test_vertex_budget_and_min_element_are_respected():
    scene = one_quad_scene()
    full = bake(scene, BakeSettings())
    budget = full.output.vertices.shape[0] // 2
    small = bake(scene, BakeSettings(vertex_budget=budget))
    assert small.output.vertices.shape[0] <= budget
    assert small.report["mesh"]["budget_hit"]
    assert not full.report["mesh"]["budget_hit"]
    # A tight contrast wants elements below 0.2 m; min_element stops them there, and leaves
    # steep against the scene's mean at a quarter of it (core.criteria.STEEP_FLOOR).
    def shortest_edge(m):
        edge = []
        for s, n in zip(m.face_starts, m.face_sizes):
            p = m.vertices[m.corner_verts[s:s + n]]
            edge.append(np.linalg.norm(p - np.roll(p, -1, axis=0), axis=1).max())
        return min(edge)

    fine = bake(scene, BakeSettings(contrast=0.02))
    coarse = bake(scene, BakeSettings(contrast=0.02, min_element=0.2))
    assert shortest_edge(fine.output) < 0.2
    assert shortest_edge(coarse.output) >= STEEP_FLOOR * 0.2 * (1 - 1e-9)
    assert coarse.output.vertices.shape[0] < fine.output.vertices.shape[0]


def test_auto_min_element_follows_a_small_model():
    # Radiance does not change when a whole scene is scaled, so neither should the mesh: the
    # one-quad scene at a tenth of its size (diagonal 0.49 m) refines with min_element = its
    # diagonal / 40 (auto), the same mesh as the full-size scene with ten times that, and the
    # same colours. At full size (diagonal 4.9 m) auto is 0.05 m.
    from core.adaptive import MIN_ELEMENT, min_element_size

    big = one_quad_scene()
    small = scene_from_polygons(big.vertices * 0.1, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 1],
                                big.reflectance, big.emission)
    assert min_element_size(big) == MIN_ELEMENT
    auto = min_element_size(small)
    assert auto == pytest.approx(small.bounding_diagonal() / 40) and auto < MIN_ELEMENT
    a = bake(small, BakeSettings())
    b = bake(big, BakeSettings(min_element=10 * auto, patch_size=10 * a._state.settings.patch_size))
    assert a.output.vertices.shape[0] == b.output.vertices.shape[0]

    def corners(m, scale):            # (position, red) of every corner, sorted
        rows = np.concatenate([np.round(m.vertices[m.corner_verts] * scale, 9),
                               m.corner_colours[:, :1]], axis=1)
        return rows[np.lexsort(rows.T[::-1])]

    ca, cb = corners(a.output, 10.0), corners(b.output, 1.0)
    np.testing.assert_array_equal(ca[:, :3], cb[:, :3])
    # Hemicube pixel ties at the two scales: 1e-6 of the brightest corner.
    np.testing.assert_allclose(ca[:, 3], cb[:, 3], rtol=0, atol=1e-6 * cb[:, 3].max())
    # Auto made the small model finer than 0.05 m would have (at contrast 0.05: at 0.1 its
    # leaves are steep enough to split below 0.05 m either way, core.criteria.STEEP_FLOOR).
    tight = bake(small, BakeSettings(contrast=0.05))
    fixed = bake(small, BakeSettings(contrast=0.05, min_element=MIN_ELEMENT))
    assert tight.output.vertices.shape[0] > fixed.output.vertices.shape[0]


def test_closed_furnace_stays_coarse_and_exact():
    scene = furnace_box(rho=0.5, le=1.0, n=4)
    result = bake(scene, BakeSettings())
    assert result.output.vertices.shape[0] <= 2 * scene.n_corners
    assert all(step.get("split", 0) == 0 for step in result.report["mesh"]["levels"])
    np.testing.assert_allclose(result.output.corner_colours, 1.0 / (1 - 0.5), rtol=FURNACE_TOL)
    varying = bake(scene, BakeSettings(output_mode="vertices")).report["face_variation"]
    assert varying["faces_varying"] == 0


# ------------------------------------------------------------------ a box's shadow
LIGHT = (0.9, 1.5, 1.7, 2.3, 2.0)          # x0, x1, y0, y1, z: a 0.6 m light, facing down
BOX = (1.9, 2.5, 1.7, 2.3, 1.0)            # x0, x1, y0, y1, height: a black box on the floor
BOX_QUADS = ([0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7], [4, 5, 6, 7])


def box_scene():
    x0, x1, y0, y1, z = LIGHT
    bx0, bx1, by0, by1, h = BOX
    v = [[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0],
         [x0, y0, z], [x0, y1, z], [x1, y1, z], [x1, y0, z]]
    c = np.array([[bx0, by0, 0], [bx1, by0, 0], [bx1, by1, 0], [bx0, by1, 0]], float)
    v += c.tolist() + (c + [0, 0, h]).tolist()
    b = 8
    box = [[b + 0, b + 1, b + 5, b + 4], [b + 1, b + 2, b + 6, b + 5], [b + 2, b + 3, b + 7, b + 6],
           [b + 3, b + 0, b + 4, b + 7], [b + 4, b + 5, b + 6, b + 7], [b + 0, b + 3, b + 2, b + 1]]
    return scene_from_polygons(np.array(v, float), [[0, 1, 2, 3], [4, 5, 6, 7]] + box,
                               [0, 1] + [2] * 6, [[RHO] * 3, [0.0] * 3, [0.0] * 3],
                               [[0.0] * 3, [LE] * 3, [0.0] * 3],
                               face_objects=[0, 1] + [2] * 6,
                               object_names=["floor", "light", "box"])


def shadowed_form_factor(scene, points, n=48, quads=BOX_QUADS):
    """F(x -> light) with visibility: midpoint quadrature over the light, one ray per node,
    against the occluder ``quads`` (corner rows of scene.vertices[8:])."""
    x0, x1, y0, y1, z = LIGHT
    s = (np.arange(n) + 0.5) / n
    q = np.array([[x0 + (x1 - x0) * a, y0 + (y1 - y0) * b, z] for a in s for b in s])
    dA = (x1 - x0) * (y1 - y0) / n ** 2
    tris = []
    for quad in quads:
        p = scene.vertices[8:][quad]
        tris += [p[[0, 1, 2]], p[[0, 2, 3]]]
    bvh = build_bvh(np.array(tris))
    out = np.zeros(len(points))
    for i, x in enumerate(points):
        d = q - x
        r2 = np.sum(d * d, axis=1)
        cos = d[:, 2] / np.sqrt(r2)                  # both normals are +-z
        blocked = any_hit(bvh, np.repeat(x[None] + [0, 0, 1e-9], len(q), 0), d, t_max=1.0)
        out[i] = np.sum(~blocked * cos * cos / (np.pi * r2)) * dA
    return out


@pytest.fixture(scope="module")
def box_bake():
    scene = box_scene()
    return scene, bake(scene, BakeSettings())


def test_box_shadow_umbra_is_dark(box_bake):
    scene, result = box_bake
    umbra = np.array([[2.75, 2.0, 0.0], [2.8, 1.95, 0.0], [2.7, 2.05, 0.0]])
    assert np.all(shadowed_form_factor(scene, umbra) == 0.0)       # the oracle agrees: umbra
    open_floor = RHO * LE * shadowed_form_factor(scene, np.array([[1.2, 2.0, 0.0]]))[0]
    field = interpolate(result.output, umbra)[:, 0]
    assert np.all(field <= UMBRA_MAX * open_floor), field / open_floor


def test_box_penumbra_matches_quadrature(box_bake):
    scene, result = box_bake
    line = np.array([[x, 2.0, 0.0] for x in np.linspace(2.55, 3.9, 28)]
                    + [[2.2, y, 0.0] for y in np.linspace(2.35, 3.5, 24)])
    exact = RHO * LE * shadowed_form_factor(scene, line)
    open_floor = RHO * LE * shadowed_form_factor(scene, np.array([[1.2, 2.0, 0.0]]))[0]
    field = interpolate(result.output, line)[:, 0]
    err = np.abs(field - exact) / open_floor
    assert err.max() <= PENUMBRA_TOL, f"max error {err.max():.3%} of the open floor"


def plate_scene():
    """The light, and a black plate hung 0.5 m over the floor (no contact, so no contact line
    and no shadow line: the mesh finds its penumbra, 0.2 m wide, by contrast alone)."""
    x0, x1, y0, y1, z = LIGHT
    v = [[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0], [x0, y0, z], [x0, y1, z], [x1, y1, z],
         [x1, y0, z], [1.6, 1.6, 0.5], [1.6, 2.4, 0.5], [2.4, 2.4, 0.5], [2.4, 1.6, 0.5]]
    return scene_from_polygons(np.array(v, float), [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]],
                               [0, 1, 2], [[RHO] * 3, [0.0] * 3, [0.0] * 3],
                               [[0.0] * 3, [LE] * 3, [0.0] * 3])


def test_a_penumbra_away_from_contacts_is_resolved_below_min_element():
    # The light by exact emitters (rays: the points' values carry no hemicube aliasing), so
    # what is left is the mesh's interpolation. Before steep leaves anywhere could split below
    # 2 min_element (core.criteria.STEEP_FLOOR), the penumbra was drawn by 5-10 cm leaves:
    # worst 0.070, mean 0.0056 of the open floor; now 0.028 and 0.0030. Tolerances: the worst
    # point within what 64 shadow rays leave at a straight shadow edge (5 % of the unshadowed
    # light, light_samples); the mean within 0.004, under what the old leaves' interpolation
    # cost.
    scene = plate_scene()
    result = bake(scene, BakeSettings(exact_direct="all"))
    g = np.linspace(1.0, 3.2, 45)
    pts = np.array([[x, y, 0.0] for x in g for y in g])
    plate = ([0, 1, 2, 3],)
    exact = RHO * LE * shadowed_form_factor(scene, pts, quads=plate)
    under = np.array([[1.2, 2.0, 0.0]])
    open_floor = RHO * LE * shadowed_form_factor(scene, under, quads=plate)[0]
    err = np.abs(interpolate(result.output, pts)[:, 0] - exact) / open_floor
    assert err.max() <= 0.05 and err.mean() <= 0.004, (err.max(), err.mean())


# ------------------------------------------------------------------ settings, old output
@pytest.mark.parametrize("name, value", [
    ("output_mode", "corners"), ("contrast", 0.0), ("contrast", 1.0), ("min_element", 0.0),
    ("min_element", float("inf")), ("vertex_budget", 3), ("vertex_budget", 10.5),
    ("patch_size", -1.0)])
def test_bad_settings_name_the_setting(name, value):
    with pytest.raises(SettingsError, match=name):
        BakeSettings(**{name: value})


def test_vertices_output_is_the_old_default():
    scene = one_quad_scene()
    a = bake(scene, BakeSettings(output_mode="vertices"))
    b = bake(scene, BakeSettings(output_mode="vertices", patch_size=0.5))
    assert a.output is None and "mesh" not in a.report
    np.testing.assert_array_equal(a.corner_colours, b.corner_colours)


def test_unlit_ground_outside_a_closed_room_costs_no_gathers():
    """A closed 3 m cube room (light inside) on a 40 x 40 m ground plane: nothing outside is
    lit, so no ground point is gathered and the ground stays black and coarse."""
    from bench.scenes import unit_cube
    room = unit_cube(n=1, emitting=("z+",))
    v = np.vstack([room.vertices * 3.0, [[-20, -20, -0.01], [20, -20, -0.01], [20, 20, -0.01],
                                         [-20, 20, -0.01]]])
    V = room.vertices.shape[0]
    polys = [room.corner_verts[s:s + n].tolist()
             for s, n in zip(room.face_starts, room.face_sizes)] + [[V, V + 1, V + 2, V + 3]]
    scene = scene_from_polygons(v, polys, list(room.face_materials) + [0],
                                room.reflectance, room.emission,
                                face_objects=list(range(6)) + [6],
                                object_names=list(room.object_names) + ["ground"])
    result = bake(scene, BakeSettings())
    mesh = result.output
    ground = mesh.faces_of(np.array([scene.n_faces - 1]))
    corners = np.concatenate([np.arange(s, s + n) for s, n in
                              zip(mesh.face_starts[ground], mesh.face_sizes[ground])])
    assert np.all(mesh.corner_colours[corners] == 0.0)
    ground_points = np.unique(mesh.corner_verts[corners]).size
    levels = result.report["mesh"]["levels"]
    assert levels[0]["unlit"] >= ground_points
    assert sum(step.get("split", 0) for step in levels) < ground_points
    # No late hemicube rows for the ground's patches: they are not among the solved nodes.
    ground_patches = np.count_nonzero(result.patches.face == scene.n_faces - 1)
    assert result.report["nodes_active"] <= 2 * (result.report["patches"] - ground_patches)
    # Relit so that the ground glows: the kept rows never saw it, so the mesh is rebuilt.
    emission = np.array(scene.emission)
    emission[0] = 1.0                        # material 0: the x- wall and the ground
    glow = relight(result, emission=emission)
    assert glow.report["mesh"]["rebuilt"]
    g = glow.output
    lit = np.concatenate([np.arange(s, s + n) for s, n in
                          zip(g.face_starts[g.faces_of(np.array([scene.n_faces - 1]))],
                              g.face_sizes[g.faces_of(np.array([scene.n_faces - 1]))])])
    assert np.all(g.corner_colours[lit] >= 1.0)             # its own emission at least


def test_far_patches_drawn_whole_gather_what_their_elements_would():
    # The mesh stage's gathers draw a solved patch whole when it lies > FAR_FIELD x its size from
    # every point of the batch, its form factor spread over its elements by area. Against drawing
    # every element (same rotations): the difference is the form-factor kernel's variation across
    # a far patch times the light's variation across it, here a steep synthetic gradient.
    from core.farfield import FarField
    from core.hemicube import point_rows
    from core.patches import make_patches, subdivide_patches

    scene = room_with_boxes(24)             # the room's walls in a few big quads
    patches = make_patches(scene, 0.5)
    elements, parent = subdivide_patches(patches, np.ones(patches.areas.size, dtype=bool))
    elements, p2 = subdivide_patches(elements, np.ones(elements.areas.size, dtype=bool))
    parent = parent[p2]
    c = elements.centres
    L = np.concatenate([1.0 + c[:, :1] + 0.5 * c[:, 2:] ** 2, 0.2 + 0.1 * c[:, 1:2]])
    L = np.repeat(L, 3, axis=1)
    rng = np.random.default_rng(5)
    points = np.column_stack([rng.uniform(2.0, 2.4, 64), rng.uniform(1.0, 1.4, 64),
                              np.zeros(64)])
    normals = np.tile([0.0, 0.0, 1.0], (64, 1))
    far = FarField(patches, elements, parent)
    kw = dict(resolution=64, rotate=True)
    mixed = far.rows(points, normals, rng=np.random.default_rng(1), **kw)
    full = point_rows(elements, points, normals, rng=np.random.default_rng(1), **kw)
    assert far.drawn_items < elements.areas.size / 2          # the saving is real
    got, want = mixed @ L, full @ L
    # 1 %: at FAR_FIELD = 4 the kernel varies by at most (1 + 1/4)^2 across a far patch, and the
    # far patches carry a part of the light; raster differences of one patch against its 16
    # elements are below that.
    np.testing.assert_allclose(got, want, rtol=0.01)
    # Row sums (what each point sees in all) agree closely: the same surfaces are drawn.
    np.testing.assert_allclose(mixed.sum(axis=1), full.sum(axis=1), rtol=2e-3)
    # The compact form the mesh stage keeps (a far patch in one column, read against its
    # elements' area mean) gathers the same light and row sums as the dense rows, in fewer
    # columns than the dense rows' compact form (float32 values: 1e-6).
    from core.farfield import compact_with_sums
    cols, vals, sums = far.rows(points, normals, rng=np.random.default_rng(1), compact=True,
                                **kw)
    want_cols, _, want_sums = compact_with_sums(mixed)
    assert np.all(np.diff(cols) > 0) and cols.max() < far.n_cols
    assert 0 < cols.size < want_cols.size / 2
    np.testing.assert_allclose(vals.astype(np.float64) @ far.radiance(L)[cols], got, rtol=1e-6)
    np.testing.assert_allclose(sums, want_sums, rtol=1e-6)
    # A far patch's column reads the area mean of its elements' radiance.
    P = patches.areas.size
    mean = np.bincount(parent, weights=elements.areas * L[:parent.size, 0],
                       minlength=P) / patches.areas
    np.testing.assert_allclose(far.radiance(L)[2 * parent.size:2 * parent.size + P, 0], mean,
                               rtol=1e-12)
