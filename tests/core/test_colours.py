"""Corner colours: smooth-surface area-weighted means of patch radiance at scene corners."""

import numpy as np
import pytest

from bench import scenes as samples
from core import scene_from_polygons
from core.colours import corner_colours
from core.patches import make_patches

#: Float64 rounding of weighted means of O(1) values over a few patches.
TIGHT = 1e-12

RHO = [[0.5, 0.5, 0.5], [0.3, 0.6, 0.2], [0.5, 0.5, 0.5]]
LE = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]


def grid_plane(n=4, jitter=0.0, rng=None, size=1.0, material=1):
    """An n x n grid of quads on z = 0 (normal +z), shared vertices; optional interior jitter."""
    s = np.linspace(0.0, size, n + 1)
    x, y = np.meshgrid(s, s, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    if jitter:
        interior = (x.ravel() > 0) & (x.ravel() < size) & (y.ravel() > 0) & (y.ravel() < size)
        v[interior, :2] += jitter * size / n * rng.uniform(-1, 1, size=(interior.sum(), 2))
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    return scene_from_polygons(v, quads.tolist(), [material] * len(quads), RHO, LE)


def reference_colours(scene, p, rad, crease_angle):
    """Independent loop program: patches of valid faces touching each corner's vertex."""
    out = np.zeros((scene.n_corners, 3))
    verts = np.asarray(scene.vertices)
    cos = np.cos(np.radians(crease_angle))
    for f in range(scene.n_faces):
        for c in range(scene.face_starts[f], scene.face_starts[f] + scene.face_sizes[f]):
            v = scene.corner_verts[c]
            num, den = np.zeros(3), 0.0
            for q in range(p.n_patches):
                g = p.face[q]
                s, n = scene.face_starts[g], scene.face_sizes[g]
                if v not in scene.corner_verts[s:s + n]:
                    continue                                    # not topologically at v
                if not np.any(np.all(p.corners[q] == verts[v], axis=1)):
                    continue                                    # patch does not touch v
                same_mat = p.material[q] == scene.face_materials[f]
                if scene.face_valid[f]:
                    ok = g == f or (same_mat and p.normals[q] @ scene.face_normals[f] >= cos - 1e-12)
                else:
                    ok = same_mat
                if ok:
                    num += p.areas[q] * rad[q]
                    den += p.areas[q]
            out[c] = num / den if den > 0 else 0.0
    return out


def test_constant_field_gives_constant_corners():
    scene = samples.cornell_box()
    p = make_patches(scene, 0.2)
    out = corner_colours(scene, p, np.tile([0.3, 1.5, 7.0], (p.n_patches, 1)))
    np.testing.assert_allclose(out, np.tile([0.3, 1.5, 7.0], (scene.n_corners, 1)), rtol=TIGHT)


@pytest.mark.parametrize("crease", [0.0, 30.0, 91.0, 180.0])
def test_matches_independent_loop_program(crease):
    rng = np.random.default_rng(11)
    # Shared vertices across a material boundary (faces 0, 1) and a 90-degree crease (0, 2); a
    # triangle (3) on duplicate vertices at the same positions, which must not join by position.
    v = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0],
         [0, 0, 1], [1, 0, 1], [0, 0, 0], [1, 0, 0]]
    polys = [[0, 1, 2, 3], [1, 4, 5, 2], [1, 0, 6, 7], [8, 9, 7]]
    scene = scene_from_polygons(v, polys, [0, 1, 0, 0], RHO, LE)
    p = make_patches(scene, 0.4)
    rad = rng.random((p.n_patches, 3))
    np.testing.assert_allclose(corner_colours(scene, p, rad, crease_angle=crease),
                               reference_colours(scene, p, rad, crease), rtol=TIGHT, atol=TIGHT)


def test_matches_loop_program_on_cornell_box():
    rng = np.random.default_rng(12)
    scene = samples.cornell_box()
    p = make_patches(scene, 0.25)
    rad = rng.random((p.n_patches, 3))
    np.testing.assert_allclose(corner_colours(scene, p, rad), reference_colours(scene, p, rad, 30.0),
                               rtol=TIGHT, atol=TIGHT)


def test_linear_field_on_a_uniform_plane():
    n, h = 4, 1.0 / 16
    scene = grid_plane(n)
    p = make_patches(scene, h)
    g, c0 = np.array([[2.0, -1.0, 0.5], [0.3, 0.7, -4.0], [0.0, 0.0, 0.0]]), np.array([5.0, 5.0, 5.0])
    field = lambda x: c0 + x @ g                            # noqa: E731  (rows: RGB per axis)
    out = corner_colours(scene, p, field(p.centres))
    at_vertex = field(scene.vertices[scene.corner_verts])
    x, y = scene.vertices[scene.corner_verts, 0], scene.vertices[scene.corner_verts, 1]
    interior = (x > 0) & (x < 1) & (y > 0) & (y < 1)
    # Interior vertices: the incident patches sit symmetrically, so their area-weighted centroid is
    # the vertex and a linear field is reproduced up to rounding.
    np.testing.assert_allclose(out[interior], at_vertex[interior], rtol=TIGHT, atol=TIGHT)
    # Boundary vertices see a one-sided average: off by |grad| * h/2 along each cut direction,
    # the O(h) boundary error. Edge (not corner) vertices err by |g_axis| h / 2 exactly.
    err = np.abs(out - at_vertex)
    bound = np.linalg.norm(g[:2], axis=0) * h / 2 * np.sqrt(2)
    assert np.all(err <= bound * (1 + 1e-9))
    on_x0 = (x == 0) & (y > 0) & (y < 1)
    np.testing.assert_allclose(out[on_x0] - at_vertex[on_x0], np.tile(g[0] * h / 2, (on_x0.sum(), 1)),
                               rtol=1e-9)


def test_linear_field_on_a_jittered_plane_is_the_field_at_the_weighted_centroid():
    # Identity for any mesh: the corner value equals the field at the area-weighted centroid of
    # the patches it averages; on a jittered mesh that centroid is within one patch (h) of the
    # interior vertex, so the error is at most |grad| h.
    rng = np.random.default_rng(13)
    scene = grid_plane(5, jitter=0.3, rng=rng)
    h = 0.05
    p = make_patches(scene, h)
    g = np.array([[1.0, 2.0, 3.0], [-2.0, 0.5, 1.0], [0.0, 0.0, 0.0]])
    out = corner_colours(scene, p, p.centres @ g)
    cen = corner_colours(scene, p, p.centres[:, [0, 1, 1]])[:, :2]   # weighted centroid (x, y)
    np.testing.assert_allclose(out, np.c_[cen, np.zeros(len(cen))] @ g, rtol=TIGHT, atol=TIGHT)
    x = scene.vertices[scene.corner_verts]
    err = np.abs(out - x @ g)
    assert np.all(err <= np.linalg.norm(g[:2], axis=0) * h * (1 + 1e-9))


def two_faces(angle_deg, mat2=0, width=1.0):
    """Floor (material 0) and a second face ``width`` wide hinged on the edge x = 1, folded up."""
    a = np.radians(angle_deg)
    v = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
         [1 + width * np.cos(a), 0, width * np.sin(a)], [1 + width * np.cos(a), 1, width * np.sin(a)],
         [5, 5, 5]]
    emitter = [[6, 7, 8]]
    v = v + [[5, 5, 6], [5, 6, 5]]
    return scene_from_polygons(v, [[0, 1, 2, 3], [1, 4, 5, 2]] + emitter, [0, mat2, 1], RHO, LE)


def test_crease_keeps_corners_crisp():
    scene = two_faces(90.0)                  # a room corner: floor and wall at 90 degrees
    p = make_patches(scene, 0.5)
    rad = np.where((p.face == 0)[:, None], 1.0, 2.0) * np.ones((p.n_patches, 3))
    out = corner_colours(scene, p, rad, crease_angle=30.0)
    np.testing.assert_array_equal(out[0:4], 1.0)
    np.testing.assert_array_equal(out[4:8], 2.0)
    # Beyond the fold angle the two sides blend, area-weighted: at vertex 1 the floor has one
    # 0.25 m^2 patch, the wall one 0.25 m^2 patch -> mean 1.5.
    out = corner_colours(scene, p, rad, crease_angle=95.0)
    np.testing.assert_allclose(out[1], 1.5, rtol=TIGHT)
    np.testing.assert_allclose(out[0], 1.0, rtol=TIGHT)


def test_gentle_fold_is_smooth_and_area_weighted():
    scene = two_faces(10.0, width=1.7)      # wall patches 0.425 x 0.5, floor patches 0.5 x 0.5
    p = make_patches(scene, 0.5)
    rad = np.where((p.face == 0)[:, None], 1.0, 4.0) * np.ones((p.n_patches, 3))
    out = corner_colours(scene, p, rad)      # default crease 30 > 10: one smooth surface
    a0 = p.areas[(p.face == 0) & np.any(np.all(p.corners == scene.vertices[1], axis=2), axis=1)].sum()
    a1 = p.areas[(p.face == 1) & np.any(np.all(p.corners == scene.vertices[1], axis=2), axis=1)].sum()
    np.testing.assert_allclose(out[1], (a0 * 1.0 + a1 * 4.0) / (a0 + a1), rtol=TIGHT)


def test_material_boundary_keeps_corners_crisp():
    scene = two_faces(0.0, mat2=2)           # coplanar, different material
    p = make_patches(scene, 0.5)
    rad = np.where((p.face == 0)[:, None], 1.0, 3.0) * np.ones((p.n_patches, 3))
    out = corner_colours(scene, p, rad, crease_angle=0.0)
    np.testing.assert_array_equal(out[0:4], 1.0)
    np.testing.assert_array_equal(out[4:8], 3.0)
    same = two_faces(0.0, mat2=0)            # same material: the shared vertices blend
    out = corner_colours(same, make_patches(same, 0.5), rad, crease_angle=0.0)
    np.testing.assert_allclose(out[1], 2.0, rtol=TIGHT)


def test_dropped_face_corners():
    v = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [3, 0, 0], [5, 5, 5], [5, 5, 6],
         [5, 6, 5]]
    # Face 1 is degenerate (collinear), shares vertex 1 with the floor. Same material -> floor's
    # patches at vertex 1; other material -> 0 (nothing of its material there).
    for mat, expect in ((0, 2.0), (2, 0.0)):
        scene = scene_from_polygons(v, [[0, 1, 2, 3], [1, 4, 5], [6, 7, 8]], [0, mat, 1], RHO, LE)
        assert not scene.face_valid[1]
        p = make_patches(scene, 0.5)
        out = corner_colours(scene, p, np.full((p.n_patches, 3), 2.0))
        np.testing.assert_array_equal(out[4], expect)
        np.testing.assert_array_equal(out[5:7], 0.0)


def test_inputs_not_mutated():
    scene = samples.cornell_box()
    p = make_patches(scene, 0.5)
    rad = np.random.default_rng(3).random((p.n_patches, 3))
    before = rad.copy()
    corner_colours(scene, p, rad)
    np.testing.assert_array_equal(rad, before)


@pytest.fixture(scope="module")
def small():
    scene = grid_plane(2)
    return scene, make_patches(scene, 1.0)


def test_invalid_radiance_columns(small):
    scene, p = small
    want = rf"patch_radiance must have shape \({p.n_patches}, 3\).*got \({p.n_patches}, 4\)"
    with pytest.raises(ValueError, match=want):
        corner_colours(scene, p, np.zeros((p.n_patches, 4)))


def test_invalid_radiance_rows(small):
    scene, p = small
    want = rf"patch_radiance must have shape \({p.n_patches}, 3\).*got \(1, 3\)"
    with pytest.raises(ValueError, match=want):
        corner_colours(scene, p, np.zeros((1, 3)))


def test_invalid_radiance_nan(small):
    scene, p = small
    rad = np.zeros((p.n_patches, 3))
    rad[2, 1] = np.nan
    with pytest.raises(ValueError, match="patch_radiance must be finite; row 2"):
        corner_colours(scene, p, rad)


@pytest.mark.parametrize("bad", [-1.0, 180.5, float("nan"), "wide"])
def test_invalid_crease_angle(small, bad):
    scene, p = small
    with pytest.raises(ValueError, match=r"crease_angle must be a number of degrees in \[0, 180\]"):
        corner_colours(scene, p, np.zeros((p.n_patches, 3)), crease_angle=bad)


def test_invalid_patches(small):
    scene, _ = small
    with pytest.raises(TypeError, match="patches must be a Patches; got tuple"):
        corner_colours(scene, (), np.zeros((4, 3)))


def test_invalid_scene(small):
    _, p = small
    with pytest.raises(TypeError, match="scene must be a core.scene.Scene; got list"):
        corner_colours([], p, np.zeros((p.n_patches, 3)))


def test_patches_of_another_scene(small):
    _, p = small
    other = grid_plane(3)
    with pytest.raises(ValueError, match="patches were made for 4 faces; the scene has 9"):
        corner_colours(other, p, np.zeros((p.n_patches, 3)))
