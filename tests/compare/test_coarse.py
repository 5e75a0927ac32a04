"""Point location and interpolation of bench/compare/coarse.py on meshes whose fields are known.

Oracle: a field linear in position is reproduced exactly by barycentric interpolation over any
triangle of its plane, so the sampled values must equal the closed-form field (to rounding); at a
crease the two faces carry different linear fields, so the value tells which face was picked.
"""

import numpy as np
import pytest

from bench.compare import coarse

#: Rounding only: the interpolation of a linear field is exact.
EXACT = 1e-12

#: Linear fields (colour = c0 + G @ p) of the floor and of the wall of the L-shaped mesh.
FLOOR = (np.array([0.2, 0.3, 0.4]), np.array([[0.5, -0.2, 0.0], [0.1, 0.3, 0.0], [0.0, 0.7, 0.0]]))
WALL = (np.array([0.9, 0.1, 0.5]), np.array([[0.0, 0.4, 0.6], [0.0, -0.3, 0.2], [0.0, 0.1, -0.4]]))


def field(params, p):
    c0, G = params
    return c0 + p @ G.T


def l_shape(n=3):
    """One object: a floor z = 0 over [0, 1]^2 and a wall x = 1, both n x n grids of quads
    (separate vertex rows along the crease, as Blender's split normals would have them), plus a
    second object, a quad at z = 0 over [1, 2] x [0, 1] (same plane as the floor, other object).

    Returns vertices (V, 3), corner_verts, face_starts, face_sizes, face_groups, corner colours
    (each face's own field at its corners)."""
    t = np.linspace(0.0, 1.0, n + 1)
    a, b = np.meshgrid(t, t, indexing="ij")
    floor = np.stack([a.ravel(), b.ravel(), np.zeros(a.size)], 1)
    wall = np.stack([np.ones(a.size), b.ravel(), a.ravel()], 1)       # (1, y, z)
    other = np.array([[1.0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0]])
    verts = np.vstack([floor, wall, other])
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    wall_quads = quads + (n + 1) ** 2     # (z, y) order: the normal points to -x
    polys = np.vstack([quads, wall_quads, [np.arange(4) + 2 * (n + 1) ** 2]])
    corner_verts = polys.ravel()
    F = len(polys)
    starts = np.arange(F) * 4
    sizes = np.full(F, 4)
    groups = np.r_[np.zeros(2 * n * n, int), 1]
    params = [FLOOR] * (n * n) + [WALL] * (n * n) + [FLOOR]
    colours = np.vstack([field(params[f], verts[polys[f]]) for f in range(F)])
    return verts, corner_verts, starts, sizes, groups, colours


def sample(mesh, pts, nrm, grp):
    V, cv, fs, fz, fg, cc = mesh
    corners, weights, miss = coarse.locate(V, cv, fs, fz, fg, pts, nrm, grp)
    return coarse.sample_field(cc, corners, weights), miss


def test_planar_field_is_interpolated_exactly_inside_and_on_shared_edges():
    mesh = l_shape()
    rng = np.random.default_rng(3)
    inside = np.c_[rng.uniform(0, 1, (200, 2)), np.zeros(200)]
    # Points on the edges shared by grid quads and on the quads' diagonals.
    t = rng.uniform(0, 1, 50)
    edges = np.vstack([np.c_[np.full(50, 1 / 3), t, np.zeros(50)],
                       np.c_[t, np.full(50, 2 / 3), np.zeros(50)],
                       np.c_[t / 3, t / 3, np.zeros(50)]])
    pts = np.vstack([inside, edges])
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    got, miss = sample(mesh, pts, up, np.zeros(len(pts), int))
    np.testing.assert_allclose(got, field(FLOOR, pts), rtol=0, atol=EXACT)
    assert np.all(miss <= coarse.BARY_TOL)


def test_crease_points_take_the_face_their_normal_names():
    mesh = l_shape()
    y = np.linspace(0, 1, 7)
    crease = np.c_[np.ones(7), y, np.zeros(7)]          # the line floor and wall share
    pts = np.vstack([crease, crease])
    nrm = np.vstack([np.tile([0.0, 0, 1], (7, 1)), np.tile([-1.0, 0, 0], (7, 1))])
    got, _ = sample(mesh, pts, nrm, np.zeros(14, int))
    np.testing.assert_allclose(got[:7], field(FLOOR, crease), rtol=0, atol=EXACT)
    np.testing.assert_allclose(got[7:], field(WALL, crease), rtol=0, atol=EXACT)
    # The fields differ on the crease, so the check above can tell the faces apart.
    assert np.min(np.abs(field(FLOOR, crease) - field(WALL, crease)).max(axis=1)) > 0.1


def test_points_stay_in_their_own_object():
    # The edge x = 1 of the floor is also an edge of object 1's quad, in the same plane.
    V, cv, fs, fz, fg, cc = l_shape()
    cc = cc.copy()
    cc[-4:] = 100.0                                   # object 1 is unmistakable
    pts = np.c_[np.ones(5), np.linspace(0, 1, 5), np.zeros(5)]
    up = np.tile([0.0, 0, 1], (5, 1))
    c, w, _ = coarse.locate(V, cv, fs, fz, fg, pts, up, np.zeros(5, int))
    np.testing.assert_allclose(coarse.sample_field(cc, c, w), field(FLOOR, pts), atol=EXACT)
    c, w, _ = coarse.locate(V, cv, fs, fz, fg, pts, up, np.ones(5, int))
    np.testing.assert_allclose(coarse.sample_field(cc, c, w), 100.0, atol=EXACT)


def test_point_outside_is_a_miss_and_a_wrong_normal_an_error():
    mesh = l_shape()
    V, cv, fs, fz, fg, cc = mesh
    _, miss = sample(mesh, np.array([[-0.1, 0.5, 0.0]]), np.array([[0.0, 0, 1]]), [0])
    assert miss[0] == pytest.approx(0.1 * 3, rel=1e-9)    # 0.1 outside a 1/3 m quad's edge
    with pytest.raises(ValueError, match="group 0: point 0"):
        coarse.locate(V, cv, fs, fz, fg, np.array([[0.5, 0.5, 0.0]]), np.array([[0.0, 1, 0]]),
                      [0])


def test_triangulate_fans_polygons():
    tris, face = coarse.triangulate([0, 5], [5, 3])
    np.testing.assert_array_equal(tris, [[0, 1, 2], [0, 2, 3], [0, 3, 4], [5, 6, 7]])
    np.testing.assert_array_equal(face, [0, 0, 0, 1])
    with pytest.raises(ValueError, match="face_sizes"):
        coarse.triangulate([0], [2])


def test_at_error_interpolates_a_power_law_in_log_log():
    x = np.array([100.0, 400.0, 1600.0])
    e = 2.0 / np.sqrt(x)                                  # 0.2, 0.1, 0.05
    v, how = coarse.at_error(x, e, 2.0 / np.sqrt(900.0))
    assert how == "interpolated" and v == pytest.approx(900.0, rel=1e-12)
    v, how = coarse.at_error(x, e, 2.0 / np.sqrt(6400.0))
    assert how == "extrapolated" and v == pytest.approx(6400.0, rel=1e-12)


def test_reference_corners_are_sampled_inside_their_faces():
    # A field that jumps across x = 1 (0 on the left quad, 1 on the right; separate vertices on
    # the line, as at the foot of a panel). A reference quad over [0.5, 1] x [0, 1] has two
    # corners on the line; Cycles bakes a corner inside its face, so those corners must read
    # the left quad's 0, never the right one's 1 (or a blend).
    from core.scene import make_scene

    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                      [1, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0]], dtype=float)
    ours = (verts, np.arange(8), np.array([0, 4]), np.array([4, 4]), np.zeros(2, int),
            np.repeat([[0.0] * 3, [1.0] * 3], 4, axis=0))
    ref = dict(vertices=np.array([[0.5, 0, 0], [1, 0, 0], [1, 1, 0], [0.5, 1, 0]], dtype=float),
               corner_verts=np.arange(4), face_starts=np.array([0]), face_sizes=np.array([4]),
               face_materials=np.array([0]), face_objects=np.array([0]), object_names=("A",))
    scene = make_scene(ref["vertices"], ref["corner_verts"], ref["face_starts"],
                       ref["face_sizes"], ref["face_materials"], [[0.5] * 3], [[1.0] * 3])
    pts, nrm, grp = coarse.ref_queries(ref, scene, ["A"])
    assert np.all(pts[:, 0] < 1.0) and np.all(pts[:, 0] > 0.5)
    np.testing.assert_allclose(np.linalg.norm(pts - ref["vertices"], axis=1),
                               coarse.CORNER_INSET
                               * np.linalg.norm(ref["vertices"] - [0.75, 0.5, 0], axis=1))
    values, miss = sample(ours, pts, nrm, grp)
    assert np.all(values == 0.0) and np.all(miss <= coarse.BARY_TOL)


def test_uniform_grids_on_the_design_module_are_told_apart():
    # The office is drawn on 0.2 m: grids that divide it or that it divides have edges on every
    # outline (and at 0.2 and 0.1 m vertices at every reference corner); the others do not.
    for grid in (0.8, 0.4, 0.2, 0.1, 0.05):
        assert coarse.on_module("office", grid), grid
    for grid in (0.3, 0.25, 0.15, 0.12):
        assert not coarse.on_module("office", grid), grid
    rows = [dict(scene="office", method="adaptive", label="adaptive (defaults)", vertices=1000,
                 t_total=1.0, rms=0.04, rms_denoised=0.04, p95=0.1),
            dict(scene="office", method="cycles", t_total=1.0, rms=0.08),
            dict(scene="office", method="cycles", t_total=4.0, rms=0.02)]
    rows += [dict(scene="office", method="uniform", grid=g, vertices=v, t_total=1.0, rms=e)
             for g, v, e in ((0.4, 100, 0.3), (0.2, 400, 0.01), (0.3, 200, 0.16),
                             (0.15, 800, 0.08), (0.12, 1600, 0.02))]
    s = coarse.summary(rows)
    # On all grids, 4 % lies between 0.4 m and 0.2 m; off the module, between 0.15 and 0.12 m
    # (a power law: 8 % -> 2 % over 2x vertices halves the error per 1.41x, so 4 % at 1131).
    assert 100 < s["uniform_vertices"] < 400
    assert s["off_vertices"] == pytest.approx(800 * 2 ** 0.5, rel=1e-9)
    assert s["off_ratio"] == pytest.approx(1000 / (800 * 2 ** 0.5), rel=1e-9)
