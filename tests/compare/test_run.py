"""Sweep-runner helpers on small arrays (no Blender needed)."""

import numpy as np
import pytest

from bench.compare import run


def _floor_and_wall():
    # A 2 x 2 grid floor (z = 0, facing up) plus one wall quad at x = 0 (facing +x) and an
    # emitter quad above facing down.
    g = [0.0, 1.0, 2.0]
    V = [(x, y, 0.0) for y in g for x in g] + [(0, 0, 2.0), (0, 2, 2.0), (1, 1, 3.0), (2, 1, 3.0),
                                              (2, 2, 3.0), (1, 2, 3.0)]
    quads = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7],
             [0, 6, 10, 9], [11, 14, 13, 12]]
    return dict(vertices=np.array(V), corner_verts=np.concatenate(quads),
                face_starts=np.arange(6) * 4, face_sizes=np.full(6, 4),
                face_materials=np.array([0, 0, 0, 0, 0, 1]),
                reflectance=np.array([[0.5] * 3, [0.0] * 3]),
                emission=np.array([[0.0] * 3, [1.0] * 3]))


def test_sensor_points_only_where_every_face_looks_up():
    a = _floor_and_wall()
    s = run.sensor_points(a, 100, np.random.default_rng(0))
    # Floor vertices touched by the wall (0 and 6) are excluded, the emitter's (z = 3) too.
    assert set(s.tolist()) == {1, 2, 3, 4, 5, 7, 8}
    assert len(run.sensor_points(a, 3, np.random.default_rng(0))) == 3


def test_sensor_points_skip_a_wall_tilted_by_a_hair():
    # The Cornell box's red wall is not planar: its normal is (-1, 0.01, 0.01), whose z part is
    # positive. It must not count as a floor (Radiance measures irradiance on a horizontal plane).
    a = _floor_and_wall()
    V = a["vertices"].astype(float).copy()
    V[[9, 10], 0] = -0.02     # lean the wall's top edge outwards: normal +x, a little +z
    a["vertices"] = V
    wall = V[[0, 6, 10, 9]]
    n = np.cross(wall[1] - wall[0], wall[3] - wall[0])
    assert n[2] != 0.0                               # the case being tested: tilted
    s = run.sensor_points(a, 100, np.random.default_rng(0))
    assert not set(s.tolist()) & {0, 6, 9, 10}


def test_vertex_values_average_corners():
    a = _floor_and_wall()
    cc = np.zeros((24, 3))
    cc[a["corner_verts"] == 4] = np.arange(4)[:, None]   # vertex 4 has 4 corners: 0, 1, 2, 3
    np.testing.assert_allclose(run.vertex_values(a, cc, [4]), [[1.5] * 3])


def test_face_size_is_longest_edge():
    assert run._face_size(_floor_and_wall()) == pytest.approx(2.0)   # the wall's 2 m edges


def test_summary_speedups():
    rows = [dict(engine="ours", t_total=2.0, rms=0.04), dict(engine="ours", t_total=8.0, rms=0.015),
            dict(engine="cycles", t_total=20.0, rms=0.045), dict(engine="cycles", t_total=90.0,
                                                                rms=0.03)]
    s = run.summary(rows)
    assert s[0.05] == (2.0, 20.0, 10.0)
    assert s[0.02][0] == 8.0 and s[0.02][1] == np.inf and np.isnan(s[0.02][2])


def test_chart_writes_png(tmp_path):
    pytest.importorskip("matplotlib")
    rows = [dict(engine="ours", label="hemicube, patch 0.20 m", method="hemicube",
                 resolution=R, t_total=t, rms=e, solver="gauss_seidel")
            for R, t, e in ((32, 1.0, 0.1), (64, 3.0, 0.05))]
    rows += [dict(engine="cycles", seed=0, samples=n, t_total=t, rms=e)
             for n, t, e in ((16, 0.5, 0.3), (64, 2.0, 0.15))]
    rows.append(dict(engine="reference", rms=0.01))
    path = tmp_path / "c.png"
    run.chart(rows, path, "t")
    assert path.stat().st_size > 1000 and path.read_bytes()[:4] == b"\x89PNG"
