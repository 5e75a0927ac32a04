"""Worker processes (core.parallel): the same bits as one process, a prompt cancel, and a bake
that survives workers that cannot start or die.

The oracle is the bake in one process (``workers=1``): sharing the hemicubes must not change a
single bit of any output, because a row depends only on its own eye (checked first, by cutting
the same eyes into different chunks).
"""

import os
import signal
import sys
import threading
import time

import numpy as np
import pytest

from bench.scenes import room_with_boxes
from builders import box_quads, quad_patches
from core import hemicube_chunk, parallel
from core.bake import BakeSettings, bake
from core.errors import BakeCancelled
from core.hemicube import hemicube_rows, point_rows


@pytest.fixture
def room_patches():
    walls, _ = box_quads((4.0, 3.0, 2.5), 0.5)
    block, _ = box_quads((1.0, 1.0, 1.0), 0.25)
    block = block[:, ::-1] + np.array([1.5, 1.0, 0.001])
    return quad_patches(np.concatenate([walls, block]))


@pytest.fixture(autouse=True)
def fresh_pool():
    parallel.close()
    yield
    parallel.close()


def _floor_points(n, seed=1):
    pts = np.random.default_rng(seed).uniform([0.1, 0.1, 0.0], [3.9, 2.9, 0.0], (n, 3))
    return pts, np.tile([0.0, 0.0, 1.0], (n, 1))


def test_a_row_does_not_depend_on_which_eyes_share_its_chunk(room_patches, monkeypatch):
    pts, nrm = _floor_points(150)
    sources = np.arange(0, 2 * room_patches.areas.size, 3)
    a = point_rows(room_patches, pts, nrm, resolution=32, rotate=True, rng=5)
    b = hemicube_rows(room_patches, sources, resolution=32, rotate=True, rng=5)
    for pairs, pixels in ((1, 1), (7000, 70_000), (10**9, 10**9)):
        monkeypatch.setattr(hemicube_chunk, "_CHUNK_PAIRS", pairs)
        monkeypatch.setattr(hemicube_chunk, "_CHUNK_PIXELS", pixels)
        assert np.array_equal(point_rows(room_patches, pts, nrm, resolution=32, rotate=True,
                                         rng=5), a)
        assert np.array_equal(hemicube_rows(room_patches, sources, resolution=32, rotate=True,
                                            rng=5), b)


def test_shared_rows_are_the_same_bits(room_patches):
    pts, nrm = _floor_points(200)
    alone = point_rows(room_patches, pts, nrm, resolution=32, rotate=True, rng=3)
    with parallel.using(2) as stats:
        shared = point_rows(room_patches, pts, nrm, resolution=32, rotate=True, rng=3)
        later = point_rows(room_patches, pts, nrm, resolution=32, rotate=True, rng=3,
                           later=True)
        assert isinstance(later, parallel.Deferred)
        later = later.result()
    assert stats["calls"] == 2 and stats["processes"] == 2 and stats["problem"] is None
    assert np.array_equal(shared, alone) and np.array_equal(later, alone)


def _mesh_bake(workers, **kw):
    scene = room_with_boxes(40)
    return bake(scene, BakeSettings(workers=workers, vertex_budget=3000, **kw))


def _outputs(result):
    return (result.corner_colours, result.node_radiance, result.output.vertices,
            result.output.corner_colours, result.output.corner_incident)


@pytest.mark.slow
def test_a_bake_on_two_workers_equals_the_bake_in_one_process():
    one = _mesh_bake(1)
    two = _mesh_bake(2)
    assert one.report["workers"] == dict(processes=1, shared_calls=0)
    assert two.report["workers"]["processes"] == 2
    assert two.report["workers"]["shared_calls"] > 10
    assert two.report["workers"]["cpu_seconds"] > 0
    assert all(np.array_equal(a, b) for a, b in zip(_outputs(one), _outputs(two)))
    assert not any("workers" in w for w in two.report["warnings"])


def test_workers_that_cannot_start_leave_the_bake_in_this_process(monkeypatch):
    monkeypatch.setattr(sys, "executable", "/nonexistent/blender")
    monkeypatch.setattr(sys, "_base_executable", "/nonexistent/blender", raising=False)
    result = _mesh_bake(2, element_levels=0)
    assert result.report["workers"]["processes"] == 1
    assert "no Python interpreter" in result.report["workers"]["problem"]
    assert any(w.startswith("workers: no Python interpreter") for w in result.report["warnings"])
    alone = _mesh_bake(1, element_levels=0)
    assert all(np.array_equal(a, b) for a, b in zip(_outputs(alone), _outputs(result)))


def _worker_pids():
    pool = parallel._pool[0]
    return [] if pool is None else [w.proc.pid for w in pool.workers]


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A killed child stays a zombie until reaped; Pool.close reaps it (wait).
    with open(f"/proc/{pid}/stat") as f:
        return f.read().split(")")[-1].split()[0] != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_worker_killed_mid_bake_costs_time_not_the_bake():
    killed = []

    def kill_one():
        deadline = time.perf_counter() + 60
        while not _worker_pids() and time.perf_counter() < deadline:
            time.sleep(0.01)
        pids = _worker_pids()
        if pids:
            os.kill(pids[0], signal.SIGKILL)
            killed.append(pids[0])

    thread = threading.Thread(target=kill_one)
    thread.start()
    result = _mesh_bake(2)
    thread.join()
    assert killed, "no worker ever started"
    problem = result.report["workers"].get("problem", "")
    assert f"worker process {killed[0]} exited" in problem, result.report["workers"]
    assert any(w.startswith(f"workers: worker process {killed[0]} exited")
               for w in result.report["warnings"])
    alone = _mesh_bake(1)
    assert all(np.array_equal(a, b) for a, b in zip(_outputs(alone), _outputs(result)))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_cancel_reaches_the_workers_within_half_a_second():
    # Cancel is flipped while the workers compute; the time from the flip until the bake has
    # raised and every worker process is gone is what a user waits for after Esc.
    scene = room_with_boxes(1500)
    flipped = threading.Event()
    when, pids = {}, []

    def flip():
        deadline = time.perf_counter() + 60
        while not _worker_pids() and time.perf_counter() < deadline:
            time.sleep(0.005)
        time.sleep(0.3)                 # well inside the form factors (several seconds)
        pids.extend(_worker_pids())
        when["t"] = time.perf_counter()
        flipped.set()

    thread = threading.Thread(target=flip)
    thread.start()
    try:
        with pytest.raises(BakeCancelled):
            bake(scene, BakeSettings(workers=2, output_mode="vertices", patch_size=1.0),
                 cancel=flipped.is_set)
        stopped = time.perf_counter()
    finally:
        thread.join()
    assert len(pids) == 2
    assert stopped - when["t"] < 0.5, stopped - when["t"]
    # Every worker is gone, or idle (kept for the next bake): none still computes.
    before = {p: _cpu_ticks(p) for p in pids}
    time.sleep(0.5)
    after = {p: _cpu_ticks(p) for p in pids}
    busy = {p for p in pids if before[p] is not None and after[p] is not None
            and after[p] - before[p] > 2}
    assert not busy, (before, after)


def _cpu_ticks(pid):
    """utime + stime of a live process in clock ticks, None if it is gone."""
    if not _alive(pid):
        return None
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().split(")")[-1].split()
    return int(fields[11]) + int(fields[12])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_cancel_kills_workers_in_the_middle_of_one_long_call(room_patches):
    # One call of 6000 hemicubes at R = 128 (about 10 s of work per worker here): the cancel
    # cannot wait for the call to end; the workers are killed.
    pts, nrm = _floor_points(6000)
    flipped = threading.Event()
    when = {}

    def flip():
        time.sleep(0.5)
        when["t"] = time.perf_counter()
        flipped.set()

    with parallel.using(2, cancel=flipped.is_set):
        point_rows(room_patches, pts[:64], nrm[:64], resolution=64)     # workers started
        pids = _worker_pids()
        thread = threading.Thread(target=flip)
        thread.start()
        with pytest.raises(BakeCancelled):
            point_rows(room_patches, pts, nrm, resolution=128)
        stopped = time.perf_counter()
        thread.join()
    assert len(pids) == 2
    assert stopped - when["t"] < 0.5, stopped - when["t"]
    assert not any(_alive(p) for p in pids)


def test_shared_rays_are_the_same_bits_even_ahead_of_pending_rows(room_patches):
    """Shadow rays cut among the workers (core.raycast through parallel.share_rays) give the
    same hits as one process, also when they are sent while a gather's rows are still being
    computed (the rays' answers overtake the rows' and the rows come out right)."""
    from core.raycast import any_hit, build_bvh, closest_hit

    rng = np.random.default_rng(5)
    tris = rng.random((400, 3, 3)) * 4.0
    bvh = build_bvh(tris)
    o, d = rng.random((3 * parallel.MIN_RAYS, 3)) * 4.0, rng.normal(size=(3 * parallel.MIN_RAYS, 3))
    pts, nrm = _floor_points(200)
    alone = (any_hit(bvh, o, d, 1.5), closest_hit(bvh, o, d),
             point_rows(room_patches, pts, nrm, resolution=32, rng=3))
    with parallel.using(2) as stats:
        later = point_rows(room_patches, pts, nrm, resolution=32, rng=3, later=True)
        hits, closest = any_hit(bvh, o, d, 1.5), closest_hit(bvh, o, d)
        rows = later.result()
    assert stats["calls"] == 3 and stats["processes"] == 2 and stats["problem"] is None
    assert 0.1 < hits.mean() < 0.9                      # both answers occur
    assert np.array_equal(hits, alone[0])
    assert all(np.array_equal(a, b) for a, b in zip(closest, alone[1]))
    assert np.array_equal(rows, alone[2])


def test_a_bake_with_point_lights_shares_its_shadow_rays_and_keeps_its_bits(monkeypatch):
    from bench.interiors import suite

    shared = []
    share_rays = parallel.share_rays

    def counting(*args):
        out = share_rays(*args)
        shared.append(out is not None)
        return out

    monkeypatch.setattr("core.raycast.share_rays", counting)
    settings = dict(vertex_budget=1500, min_element=0.05)
    one = bake(suite(2), BakeSettings(workers=1, **settings))
    assert not any(shared)
    two = bake(suite(2), BakeSettings(workers=2, **settings))
    assert sum(shared) >= 3                   # lights, exact emitters, shadow-edge tests
    assert all(np.array_equal(a, b) for a, b in zip(_outputs(one), _outputs(two)))


def test_workers_send_the_hit_columns_and_the_rows_come_back_exactly(room_patches):
    """A worker sends only the columns its rows hit (core.parallel.hit_columns); the rows put
    back into zeros are the dense rows (oracle: the rows computed in this process)."""
    pts, nrm = _floor_points(40, seed=3)
    want = point_rows(room_patches, pts, nrm, resolution=16)
    hit, values = parallel.hit_columns(want)
    assert 0 < hit.size < want.shape[1]
    back = np.zeros_like(want)
    back[:, hit] = values
    assert np.array_equal(back, want)
    with parallel.using(2):
        shared = point_rows(room_patches, pts, nrm, resolution=16)
    assert np.array_equal(shared, want)


def test_a_cut_geometry_is_sent_as_its_numbers_and_gives_the_same_rows(room_patches,
                                                                       monkeypatch):
    """A Geometry cut out of another (a far-field mix: core.farfield.Union) reaches a worker
    as the cut's numbers when the worker holds the whole, and the worker's cut gives the rows
    this process computes from its own cut (oracle). More cuts than a worker keeps, and an
    evicted one asked for again, keep both sides' kept sets in step."""
    from core.hemicube import draw_polygons

    polys, poly_patch = draw_polygons(room_patches)
    whole = hemicube_chunk.Geometry(polys, poly_patch, room_patches.normals)
    P = room_patches.areas.size
    rng = np.random.default_rng(4)
    keep = [np.flatnonzero(rng.random(P) < share) for share in (0.9, 0.7, 0.8, 0.6, 0.95, 0.75)]
    cuts = []
    for items in keep:
        local = np.full(P, -1)
        local[items] = np.arange(items.size)
        sel = np.flatnonzero(local[poly_patch] >= 0)
        cuts.append((whole.cut(sel, local[poly_patch[sel]]), items.size))
    order = [0, 1, 2, 3, 4, 5, 0, 3, 5]      # 0 and 3 are dropped by then, 5 is not
    assert parallel.KEPT_GEOMETRIES < len(keep)
    pts, _ = _floor_points(48, seed=7)
    eyes = pts + [0.0, 0.0, 1e-3]
    frames = np.broadcast_to(np.eye(3), (eyes.shape[0], 3, 3)).copy()

    def rows(k):
        geometry, n = cuts[k]
        out = np.zeros((eyes.shape[0], 2 * n))
        hemicube_chunk.rows_in_chunks(hemicube_chunk.Scene(geometry, n, 32, False), eyes,
                                      frames, out, None)
        return out

    want = [rows(k) for k in order]
    assert all(w.any() for w in want)
    sent = []
    send = parallel._Worker.send

    def recording(self, message):
        sent.append(message[0])
        send(self, message)

    monkeypatch.setattr(parallel._Worker, "send", recording)
    with parallel.using(2) as stats:
        got = [rows(k) for k in order]
    assert stats["problem"] is None and stats["calls"] == len(order)
    assert sent.count("geometry") == 2              # the whole, once to each worker
    assert sent.count("cut") == 2 * 8               # cuts 0 and 3 twice, 5 once
    assert all(np.array_equal(g, w) for g, w in zip(got, want))
