"""The bake's hemicube calls on a Dask distributed cluster (radiosity_addon/cluster.py, issue
13): a LocalCluster of two single-threaded worker processes.

Oracle: the same bake in one process. A row depends only on its own eye, so any cut into parts
gives the same bits (tests/core/test_parallel.py); here the parts run on Dask workers, which
import the repository's ``core`` by name. Also: a cancel reaches the cluster, and a failing
task falls back to this process with the same result and a reported problem.
"""

import importlib.util
import os

import numpy as np
import pytest

from core import BakeSettings, bake, parallel
from core.errors import BakeCancelled

distributed = pytest.importorskip("distributed")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _cluster_module():
    path = os.path.join(ROOT, "radiosity_addon", "cluster.py")
    spec = importlib.util.spec_from_file_location("radiosity_cluster", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


cluster = _cluster_module()


@pytest.fixture(scope="module")
def client():
    c = cluster.connect(workers=2)
    yield c
    c.close()
    c.cluster.close()


@pytest.fixture
def on_dask(client):
    previous = cluster.use(client, parallel)
    yield parallel._backend[0]
    parallel.set_backend(previous)


def _room():
    """A 4 x 3 x 2.5 m room with a lamp and a box: enough patches for shared calls."""
    from core.scene import scene_from_polygons

    W, D, H = 4.0, 3.0, 2.5
    v = [[0, 0, 0], [W, 0, 0], [W, D, 0], [0, D, 0], [0, 0, H], [W, 0, H], [W, D, H], [0, D, H],
         [1.6, 1.2, H - 0.05], [2.4, 1.2, H - 0.05], [2.4, 1.8, H - 0.05], [1.6, 1.8, H - 0.05],
         [0.5, 0.5, 0], [1.3, 0.5, 0], [1.3, 1.3, 0], [0.5, 1.3, 0],
         [0.5, 0.5, 0.7], [1.3, 0.5, 0.7], [1.3, 1.3, 0.7], [0.5, 1.3, 0.7]]
    polys = [[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0],
             [8, 11, 10, 9], [16, 17, 18, 19], [12, 13, 17, 16], [13, 14, 18, 17],
             [14, 15, 19, 18], [15, 12, 16, 19]]
    mats = [0, 1, 1, 1, 1, 1, 2, 3, 3, 3, 3, 3]
    refl = [[0.5, 0.5, 0.5], [0.7, 0.7, 0.7], [0.0, 0.0, 0.0], [0.6, 0.3, 0.2]]
    em = [[0, 0, 0], [0, 0, 0], [5.0, 5.0, 5.0], [0, 0, 0]]
    return scene_from_polygons(np.array(v, float), polys, mats, refl, em)


SETTINGS = dict(output_mode="mesh", patch_size=0.5, seed=3)


def test_a_bake_on_the_cluster_gives_the_bits_of_one_process(on_dask):
    scene = _room()
    on = bake(scene, BakeSettings(**SETTINGS))
    alone = bake(scene, BakeSettings(workers=1, **SETTINGS))      # 1: this process only
    assert np.array_equal(on.output.corner_colours, alone.output.corner_colours)
    assert np.array_equal(on.node_radiance, alone.node_radiance)
    w = on.report["workers"]
    assert w["backend"] == "dask" and w["processes"] == 2 and w["shared_calls"] > 0
    assert "problem" not in w and w["cpu_seconds"] > 0
    assert alone.report["workers"] == dict(processes=1, shared_calls=0)


def test_a_cancel_reaches_the_cluster_and_it_serves_the_next_bake(on_dask):
    scene = _room()
    calls = []

    def cancel():
        calls.append(1)
        return len(calls) > 40        # some way into the form factors

    with pytest.raises(BakeCancelled):
        bake(scene, BakeSettings(**SETTINGS), cancel=cancel)
    assert not on_dask.pending
    again = bake(scene, BakeSettings(**SETTINGS))
    assert "problem" not in again.report["workers"]


def test_a_failing_task_falls_back_to_this_process(on_dask, monkeypatch):
    scene = _room()
    monkeypatch.setattr(on_dask, "_task", _broken)
    got = bake(scene, BakeSettings(**SETTINGS))
    assert "Dask task failed" in got.report["workers"]["problem"]
    alone = bake(scene, BakeSettings(workers=1, **SETTINGS))
    assert np.array_equal(got.output.corner_colours, alone.output.corner_colours)


def _broken(*args):
    raise RuntimeError("a broken worker")
