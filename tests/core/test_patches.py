"""Patches: area conservation, edge length, conformity (no T-junctions), incidence, subdivision."""

import numpy as np
import pytest

from bench import scenes as samples
from core import SettingsError, scene_from_polygons
from core.geometry import newell_vectors
from core.patches import connected_labels, make_patches, patch_triangles, subdivide_patches

#: Float64 rounding in sums of up to ~1e4 patch areas of O(1) size: 1e-12 relative leaves room.
AREA_RTOL = 1e-12
#: make_patches rounds ceil(length / max_edge) with 1e-9 relative slack (tol.edge_count).
EDGE_RTOL = 1e-9
#: Distance (m) under which a point counts as lying on a segment: rounding of O(1) coordinates.
ON_SEGMENT = 1e-12

RHO = [[0.5, 0.5, 0.5], [0.3, 0.6, 0.2]]
LE = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]


def mixed_mesh():
    """A conforming mesh of every face kind, vertices shared between neighbours.

    Plane z = 0 (normals +z): a square, two triangles, a convex quad, a concave quad and its convex
    complement, a concave pentagon and a convex pentagon; plus a non-planar quad hanging down
    from edge 0-1. Materials: 0 grey, 1 emitter (the convex pentagon).
    """
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0],
                  [0, 1, 0], [1, 1, 0], [2, 1, 0], [3, 1, 0],
                  [0, 2, 0], [1, 2, 0], [2, 2, 0], [3, 2, 0],
                  [0.4, 1.4, 0], [0, 0, 0], [1.5, 1.5, 0],   # vertex 13: unused duplicate
                  [0, 0, -1], [1, 0.2, -0.8]], dtype=float)
    polys = [[0, 1, 5, 4], [1, 2, 6], [1, 6, 5], [2, 3, 7, 6],
             [4, 5, 12, 8], [5, 9, 8, 12],
             [5, 6, 14, 10, 9], [6, 7, 11, 10, 14],
             [1, 0, 15, 16]]
    return scene_from_polygons(v, polys, [0, 0, 0, 0, 0, 0, 0, 1, 0], RHO, LE)


def scenes():
    return {"mixed": mixed_mesh(), "cornell": samples.cornell_box(),
            "room": samples.room_with_boxes(60), "cube": samples.unit_cube(2)}


def newell_of_faces(scene):
    return scene.face_normals * scene.face_areas[:, None]


def patch_edges(corners):
    """(E, 2, 3) directed edges of patch polygons (P, 4, 3), zero-length ones left out."""
    e = np.stack([corners, np.roll(corners, -1, axis=1)], axis=2).reshape(-1, 2, 3)
    return e[np.any(e[:, 0] != e[:, 1], axis=1)]


@pytest.mark.parametrize("name", ["mixed", "cornell", "room", "cube"])
@pytest.mark.parametrize("h", [0.5, 0.23, 0.1])
def test_areas_and_newell_vectors_sum_to_faces(name, h):
    scene = scenes()[name]
    p = make_patches(scene, h)
    planar = np.ones(scene.n_faces, bool)
    if name == "mixed":
        planar[8] = False
    area = np.bincount(p.face, weights=p.areas, minlength=scene.n_faces)
    np.testing.assert_allclose(area[planar], scene.face_areas[planar], rtol=AREA_RTOL)
    # Newell vectors are additive over a partition even for a non-planar face (interior edges
    # cancel); the scene computes the face's own vector independently.
    vec = newell_vectors(p.corners)
    summed = np.stack([np.bincount(p.face, weights=vec[:, k], minlength=scene.n_faces)
                       for k in range(3)], axis=1)
    np.testing.assert_allclose(summed, newell_of_faces(scene), rtol=0,
                               atol=AREA_RTOL * scene.face_areas.max())
    # Every patch faces the way its face does.
    if name != "mixed":
        np.testing.assert_allclose(np.einsum("ij,ij->i", p.normals, scene.face_normals[p.face]),
                                   1.0, atol=1e-12)


@pytest.mark.parametrize("name", ["mixed", "cornell", "room", "cube"])
@pytest.mark.parametrize("h", [0.5, 0.23, 0.1])
def test_max_edge_respected(name, h):
    p = make_patches(scenes()[name], h)
    e = patch_edges(p.corners)
    assert np.max(np.linalg.norm(e[:, 1] - e[:, 0], axis=1)) <= h * (1 + EDGE_RTOL)


def test_count_is_minimal_for_a_rectangle():
    # A 1 x 0.3 rectangle at h = 0.1: exactly 10 x 3 cells (0.3 / 0.1 rounds to 2.9999999999999996).
    v = [[0, 0, 0], [1, 0, 0], [1, 0.3, 0], [0, 0.3, 0]]
    scene = scene_from_polygons(v, [[0, 1, 2, 3]], [1], RHO, LE)
    assert make_patches(scene, 0.1).n_patches == 30


def shared_edges(scene):
    """(vertex a, vertex b, face 1, face 2) for every mesh edge used by two valid faces."""
    seen = {}
    out = []
    for f in np.flatnonzero(scene.face_valid):
        s, n = scene.face_starts[f], scene.face_sizes[f]
        vs = scene.corner_verts[s:s + n]
        for a, b in zip(vs, np.roll(vs, -1)):
            key = (min(a, b), max(a, b))
            if key in seen and seen[key] != f:
                out.append((key[0], key[1], seen[key], f))
            seen[key] = f
    return out


def edges_on_segment(p, face, a, b):
    """Set of undirected patch edges (as byte strings) of ``face`` lying on segment a-b."""
    e = patch_edges(p.corners[p.face_patch_start[face]:p.face_patch_start[face + 1]])
    d = (b - a) / np.linalg.norm(b - a)
    rel = e - a
    along = rel @ d
    off = np.linalg.norm(rel - along[..., None] * d, axis=2)
    length = np.linalg.norm(b - a)
    on = np.all((off < ON_SEGMENT) & (along > -ON_SEGMENT) & (along < length + ON_SEGMENT), axis=1)
    return {tuple(sorted((x[0].tobytes(), x[1].tobytes()))) for x in e[on]}, e[on]


@pytest.mark.parametrize("h", [0.5, 0.3, 0.13])
def test_shared_edges_have_identical_twins(h):
    scene = mixed_mesh()
    p = make_patches(scene, h)
    pairs = shared_edges(scene)
    assert len(pairs) >= 10
    for a, b, f1, f2 in pairs:
        pa, pb = scene.vertices[a], scene.vertices[b]
        s1, e1 = edges_on_segment(p, f1, pa, pb)
        s2, _ = edges_on_segment(p, f2, pa, pb)
        assert s1 == s2, (f1, f2)
        # ... and those twins tile the whole edge.
        np.testing.assert_allclose(np.linalg.norm(e1[:, 1] - e1[:, 0], axis=1).sum(),
                                   np.linalg.norm(pb - pa), rtol=1e-12)


@pytest.mark.parametrize("name,h", [("mixed", 0.3), ("mixed", 0.11), ("cube", 0.2),
                                    ("cornell", 0.2)])
def test_no_t_junctions(name, h):
    # Independent definition: no patch corner lies inside (not at an end of) any patch edge of
    # the same object. Conformity is promised inside a mesh: separate objects may meet at
    # T-junctions in the input itself (the Cornell ceiling is split around the light's opening,
    # the walls' top edges are not), which patching cannot and need not remove.
    scene = scenes()[name]
    p = make_patches(scene, h)
    if name == "cornell":
        for obj in np.unique(scene.face_objects):
            _assert_no_t_junctions(p.corners[scene.face_objects[p.face] == obj])
    else:
        _assert_no_t_junctions(p.corners)


def _assert_no_t_junctions(corners):
    e = patch_edges(corners)
    pts = np.unique(corners.reshape(-1, 3), axis=0)
    a, d = e[:, 0], e[:, 1] - e[:, 0]
    ln2 = np.einsum("ij,ij->i", d, d)
    for chunk in np.array_split(np.arange(pts.shape[0]), max(1, pts.shape[0] // 200)):
        q = pts[chunk]
        t = np.einsum("ekj,ej->ek", q[None, :, :] - a[:, None, :], d) / ln2[:, None]
        closest = a[:, None, :] + t[..., None] * d[:, None, :]
        dist = np.linalg.norm(q[None, :, :] - closest, axis=2)
        scale = np.sqrt(ln2)[:, None]
        inside = (t > 1e-9) & (t < 1 - 1e-9) & (dist < ON_SEGMENT * 10 * np.maximum(scale, 1))
        assert not inside.any()


def test_triangle_grids_fans_and_quads_conform():
    # Two equilateral triangles (equal counts: triangle grids), a right triangle (a fan strip)
    # and a square, all sharing edges.
    r3 = np.sqrt(3.0) / 2
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, r3, 0], [1.5, r3, 0], [1, -1, 0], [0, -1, 0],
                  [2, 0, 0]], dtype=float)
    scene = scene_from_polygons(v, [[0, 1, 2], [1, 3, 2], [0, 5, 4, 1], [1, 4, 6]], [0, 0, 0, 1],
                                RHO, LE)
    p = make_patches(scene, 0.2)
    counts = np.diff(p.face_patch_start)
    assert counts[0] == counts[1] == 25 and counts[2] == 25
    assert p.is_triangle[:50].all()
    for a, b, f1, f2 in shared_edges(scene):
        s1, _ = edges_on_segment(p, f1, scene.vertices[a], scene.vertices[b])
        s2, _ = edges_on_segment(p, f2, scene.vertices[a], scene.vertices[b])
        assert s1 == s2 and len(s1) == 5
    area = np.bincount(p.face, weights=p.areas)
    np.testing.assert_allclose(area, scene.face_areas, rtol=AREA_RTOL)
    e = patch_edges(p.corners)
    assert np.max(np.linalg.norm(e[:, 1] - e[:, 0], axis=1)) <= 0.2 * (1 + EDGE_RTOL)
    check_incidence(scene, p)


def test_closed_cube_every_edge_has_a_reversed_twin():
    p = make_patches(samples.unit_cube(3), 0.15)
    e = patch_edges(p.corners)
    fwd = {(x[0].tobytes(), x[1].tobytes()) for x in e}
    rev = {(x[1].tobytes(), x[0].tobytes()) for x in e}
    assert len(fwd) == e.shape[0]          # no edge repeated in the same direction
    # The unit cube's sides are separate objects with their own vertices, welded by position.
    assert fwd == rev


def test_face_kinds_and_triangle_convention():
    scene = mixed_mesh()
    p = make_patches(scene, 10.0)          # coarse: one element = one patch
    counts = np.diff(p.face_patch_start)
    # quad, tri, tri, quad, concave quad (2 tris), quad, concave pentagon (3), pentagon (3), quad
    np.testing.assert_array_equal(counts, [1, 1, 1, 1, 2, 1, 3, 3, 1])
    tri = p.is_triangle
    np.testing.assert_array_equal(tri, np.repeat([False, True, True, False, True, False, True, True,
                                                  False], counts))
    np.testing.assert_array_equal(p.corners[tri, 3], p.corners[tri, 2])
    np.testing.assert_array_equal(p.material, np.asarray(scene.face_materials)[p.face])


def test_faces_contiguous_and_csr():
    scene = samples.cornell_box()
    p = make_patches(scene, 0.2)
    assert np.all(np.diff(p.face) >= 0)
    per_face = np.bincount(p.face, minlength=scene.n_faces)
    np.testing.assert_array_equal(p.face_patch_start, np.r_[0, np.cumsum(per_face)])
    for f in (0, 5, scene.n_faces - 1):
        assert np.all(p.face[p.face_patch_start[f]:p.face_patch_start[f + 1]] == f)


def test_centres_are_area_centroids():
    p = make_patches(mixed_mesh(), 0.4)
    # Independent: area-weighted centroids of the two triangles (unsigned areas; planar faces
    # only, as a non-planar patch's triangles are not coplanar).
    c = p.corners[p.face != 8]
    a1 = np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    a2 = np.linalg.norm(np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 0]), axis=1)
    c1, c2 = (c[:, 0] + c[:, 1] + c[:, 2]) / 3, (c[:, 0] + c[:, 2] + c[:, 3]) / 3
    expected = (a1[:, None] * c1 + a2[:, None] * c2) / (a1 + a2)[:, None]
    np.testing.assert_allclose(p.centres[p.face != 8], expected, atol=1e-12)


def check_incidence(scene, p):
    """Each valid face's every corner appears, with a patch of that face holding the vertex."""
    verts = np.asarray(scene.vertices)
    slot_pts = p.corners[p.incidence_patch, p.incidence_slot]
    np.testing.assert_array_equal(slot_pts, verts[p.incidence_vertex])
    np.testing.assert_array_equal(np.asarray(scene.corner_verts)[p.incidence_corner], p.incidence_vertex)
    faces = np.repeat(np.arange(scene.n_faces), scene.face_sizes)
    local = np.arange(faces.size) - np.repeat(np.cumsum(scene.face_sizes) - scene.face_sizes,
                                              scene.face_sizes)
    loops = np.asarray(scene.face_starts)[faces] + local
    corner_face = np.full(scene.n_corners, -1)
    corner_face[loops] = faces
    np.testing.assert_array_equal(p.face[p.incidence_patch], corner_face[p.incidence_corner])
    expected = set(loops[np.asarray(scene.face_valid)[faces]].tolist())
    assert set(p.incidence_corner.tolist()) == expected
    # Conversely, every patch corner at one of its face's vertices is listed, once per patch.
    listed = set(zip(p.incidence_patch.tolist(), p.incidence_vertex.tolist()))
    assert len(listed) == p.incidence_patch.size
    for f in np.flatnonzero(scene.face_valid):
        fv = scene.corner_verts[scene.face_starts[f]:scene.face_starts[f] + scene.face_sizes[f]]
        sl = slice(p.face_patch_start[f], p.face_patch_start[f + 1])
        at = np.all(p.corners[sl, :, None, :] == verts[fv][None, None, :, :], axis=3).any(axis=1)
        for q, k in zip(*np.nonzero(at)):
            assert (sl.start + q, fv[k]) in listed


@pytest.mark.parametrize("name", ["mixed", "cornell", "room"])
def test_incidence_complete(name):
    scene = scenes()[name]
    for h in (1.0, 0.17):
        check_incidence(scene, make_patches(scene, h))


def test_dropped_faces_make_no_patches():
    v = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [3, 0, 0]]
    scene = scene_from_polygons(v, [[0, 1, 2, 3], [1, 4, 5]], [1, 0], RHO, LE)  # collinear face
    assert not scene.face_valid[1]
    p = make_patches(scene, 0.5)
    assert p.face_patch_start[2] == p.face_patch_start[1] == 4
    assert not np.isin(p.incidence_corner, [4, 5, 6]).any()


@pytest.mark.parametrize("polygon,area", [([0, 1, 2, 3], 0.5),           # quad: corners 1, 2 coincide
                                          ([0, 1, 2, 4, 3], 0.5 + 0.5)])  # pentagon likewise
def test_coincident_corners(polygon, area):
    v = [[0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]
    scene = scene_from_polygons(v, [polygon], [1], RHO, LE)
    p = make_patches(scene, 0.25)
    np.testing.assert_allclose(p.areas.sum(), area, rtol=AREA_RTOL)
    assert np.all(p.areas > 0)
    # The only repeated corner a patch may have is the triangle convention's (slot 3 == slot 2).
    same = np.all(p.corners == np.roll(p.corners, -1, axis=1), axis=2)
    assert not same[:, [0, 1, 3]].any()
    check_incidence(scene, p)


def test_needle_triangle_is_not_over_refined():
    # Base 0.1 m, legs 2.0006 m, h = 0.1: a fan of 21 rows x 1 column, not a 21 x 21 grid.
    v = [[0, 0, 0], [0.1, 0, 0], [0.05, 2, 0]]
    scene = scene_from_polygons(v, [[0, 1, 2]], [1], RHO, LE)
    p = make_patches(scene, 0.1)
    assert p.n_patches == 21
    assert p.is_triangle.sum() == 1
    check_incidence(scene, p)
    e = patch_edges(p.corners)
    assert np.max(np.linalg.norm(e[:, 1] - e[:, 0], axis=1)) <= 0.1 * (1 + EDGE_RTOL)


def test_fan_apex_incidence_lists_every_fan_cell():
    # Right triangle, legs 1 and hypotenuse 1.41 at h = 0.25: counts 4, 4, 6 -> the fan's apex
    # (opposite a leg) is touched by the 4 cells of the last row.
    v = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    scene = scene_from_polygons(v, [[0, 1, 2]], [1], RHO, LE)
    p = make_patches(scene, 0.25)
    touching = np.array([np.sum(np.any(np.all(p.corners == scene.vertices[k], axis=2), axis=1))
                         for k in range(3)])
    np.testing.assert_array_equal(np.bincount(p.incidence_vertex, minlength=3), touching)
    assert touching.max() == 4


def test_patch_triangles():
    p = make_patches(mixed_mesh(), 0.3)
    tris, tri_patch = patch_triangles(p)
    assert tris.shape == (2 * p.n_patches - p.is_triangle.sum(), 3, 3)
    np.testing.assert_array_equal(np.bincount(tri_patch, minlength=p.n_patches),
                                  np.where(p.is_triangle, 1, 2))
    area_vec = 0.5 * np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    # Planar patches: triangles face the patch normal and their areas add up to the patch area.
    planar = p.face != 8
    dots = np.einsum("ij,ij->i", area_vec, p.normals[tri_patch])
    assert np.all(dots[planar[tri_patch]] > 0)
    np.testing.assert_allclose(np.bincount(tri_patch, weights=dots)[planar], p.areas[planar],
                               rtol=AREA_RTOL)
    assert np.all(np.diff(tri_patch) >= 0)


def test_subdivide_conserves_area_and_maps_parents():
    scene = mixed_mesh()
    p = make_patches(scene, 0.5)
    rng = np.random.default_rng(7)
    mask = rng.random(p.n_patches) < 0.5
    mask[:2] = True
    new, parent = subdivide_patches(p, mask)
    assert new.n_patches == p.n_patches + 3 * mask.sum()
    np.testing.assert_array_equal(np.bincount(parent, minlength=p.n_patches), np.where(mask, 4, 1))
    np.testing.assert_array_equal(new.face, p.face[parent])
    np.testing.assert_array_equal(new.material, p.material[parent])
    vec_new = newell_vectors(new.corners)
    summed = np.stack([np.bincount(parent, weights=vec_new[:, k]) for k in range(3)], axis=1)
    np.testing.assert_allclose(summed, newell_vectors(p.corners), atol=1e-15)
    planar = p.face != 8
    child_area = np.bincount(parent, weights=new.areas, minlength=p.n_patches)
    np.testing.assert_allclose(child_area[planar], p.areas[planar], rtol=AREA_RTOL)
    np.testing.assert_array_equal(new.is_triangle, p.is_triangle[parent])
    unsplit = ~mask[parent]
    np.testing.assert_array_equal(new.corners[unsplit], p.corners[parent[unsplit]])
    check_incidence(scene, new)
    assert np.all(np.diff(new.face) >= 0)


def test_subdivide_all_equals_finer_grid():
    # Independent oracle: splitting every patch of a unit square at h = 1 gives the h = 0.5 grid.
    v = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]]
    scene = scene_from_polygons(v, [[0, 1, 2, 3], [1, 4, 2]], [1, 0], RHO, LE)
    coarse = make_patches(scene, 1.5)
    fine = make_patches(scene, 0.75)
    new, _ = subdivide_patches(coarse, np.ones(coarse.n_patches, bool))
    assert new.n_patches == fine.n_patches == 8

    def as_set(corners):      # patches as sets of rounded corner tuples: order-free comparison
        return {tuple(sorted(map(tuple, np.round(x, 12).tolist()))) for x in corners}

    assert as_set(new.corners) == as_set(fine.corners)


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), "abc", None])
def test_invalid_max_edge(bad):
    with pytest.raises(SettingsError, match="max_edge must be a positive"):
        make_patches(mixed_mesh(), bad)


def test_max_edge_too_small():
    with pytest.raises(SettingsError, match=r"max_edge = 1e-05 m would make .* patches"):
        make_patches(mixed_mesh(), 1e-5)


def test_invalid_scene():
    with pytest.raises(TypeError, match="scene must be a core.scene.Scene; got dict"):
        make_patches({}, 0.5)


def test_invalid_subdivide_mask_shape():
    p = make_patches(mixed_mesh(), 1.0)
    want = rf"mask must be a bool array of shape \({p.n_patches},\); got bool \(3,\)"
    with pytest.raises(ValueError, match=want):
        subdivide_patches(p, np.ones(3, bool))


def test_invalid_subdivide_mask_dtype():
    p = make_patches(mixed_mesh(), 1.0)
    with pytest.raises(ValueError, match="mask must be a bool array .* got int64"):
        subdivide_patches(p, np.ones(p.n_patches, np.int64))


def test_inputs_not_mutated():
    scene = mixed_mesh()
    before = scene.vertices.copy()
    p = make_patches(scene, 0.3)
    mask = np.zeros(p.n_patches, bool)
    mask[0] = True
    corners = p.corners.copy()
    subdivide_patches(p, mask)
    np.testing.assert_array_equal(scene.vertices, before)
    np.testing.assert_array_equal(p.corners, corners)
    assert not p.corners.flags.writeable


def union_find_labels(n, a, b):
    """Independent oracle: textbook union-find, label = smallest member of each component."""
    parent = list(range(n))

    def root(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for x, y in zip(a.tolist(), b.tolist()):
        rx, ry = root(x), root(y)
        if rx != ry:
            parent[max(rx, ry)] = min(rx, ry)
    return np.array([root(x) for x in range(n)])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_edge_classes_match_union_find(seed):
    rng = np.random.default_rng(seed)
    n = 500
    a, b = rng.integers(0, n, 300), rng.integers(0, n, 300)
    chain = rng.permutation(n)[:200]                       # plus one long chain in random order
    a, b = np.r_[a, chain[:-1]], np.r_[b, chain[1:]]
    np.testing.assert_array_equal(connected_labels(n, a, b), union_find_labels(n, a, b))
