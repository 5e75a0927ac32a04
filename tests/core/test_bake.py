"""Tests of core/bake.py: the whole pipeline against closed forms and identities."""

import dataclasses
import importlib
import threading
import time

import numpy as np
import pytest

from bench.scenes import furnace_box, opposed_squares, room_with_boxes, unit_cube
from builders import horizontal_square
from core import reciprocity, settings as settings_module
from core.bake import BakeResult, BakeSettings, bake, form_factor_matrix, relight
from core.errors import BakeCancelled, SettingsError
from core.scene import scene_from_polygons
from core.solvers import solve_direct

# core/__init__ re-exports the function bake, which hides the module of the same name.

#: Small hemicubes keep the tests fast; the furnace and symmetry identities hold at any R.
R = 32

#: Opposed unit squares 1 apart (Howell C-11).
F_OPPOSED_UNIT = 0.199824895698


def _settings(**kw):
    # These tests were written against the hemicube's closed forms; the default method
    # ('hybrid') is tested in test_reciprocity.py.
    kw.setdefault("method", "hemicube")
    kw.setdefault("resolution", R)
    return BakeSettings(**kw)


def _panel_under_ceiling(n=4, gap=1.0):
    """A ceiling square (normal down, grey) and an emitting panel ``gap`` below it facing down.

    Only the panel's back side faces the ceiling.
    """
    v1, q1 = horizontal_square(gap, 1.0, n, down=True)
    v2, q2 = horizontal_square(0.0, 1.0, n, down=True)
    verts = np.vstack([v1, v2])
    quads = q1 + [[i + len(v1) for i in q] for q in q2]
    mats = [0] * len(q1) + [1] * len(q2)
    return scene_from_polygons(verts, quads, mats, [[0.5] * 3, [0.0] * 3],
                               [[0.0] * 3, [1.0] * 3])


# ----------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize("rho", [0.3, 0.8])
def test_white_furnace(rho):
    # Closed box, uniform rho and Le: L = Le / (1 - rho) inside, whatever the form factors, as
    # long as rows of inside nodes sum to 1 (the hemicube's pixels all see the box). The solve is
    # direct, so only rounding remains.
    # The hemicube's rows are made reciprocal first, which keeps every row sum to within
    # RECIPROCITY_TOL (relative); a row-sum error e changes L by at most e * rho / (1 - rho)
    # relative (Neumann series), so that is the tolerance, plus float32 storage (1e-6).
    scene = furnace_box(rho=rho, le=1.5, n=3)
    res = bake(scene, _settings(patch_size=0.4))
    tol = reciprocity.RECIPROCITY_TOL * rho / (1 - rho) + 1e-6
    np.testing.assert_allclose(res.corner_colours, 1.5 / (1 - rho), rtol=tol)
    P = res.report["patches"]
    np.testing.assert_allclose(res.patch_radiance, 1.5 / (1 - rho), rtol=tol)
    # Both sides emit (Cycles mesh lights): the outer back nodes emit into the void.
    np.testing.assert_allclose(res.node_radiance[P:], 1.5, rtol=1e-12)
    e = res.report["energy"]
    assert abs(e["balance"]) < 1e-6 * e["emitted"]
    assert res.report["solver"] == "direct" and res.report["converged"]


def test_emission_only_scene():
    # rho = 0 everywhere: L = Le on emitters, exactly 0 elsewhere.
    scene = unit_cube(n=2, emitting=("z+",), reflectance=0.0, emission=3.0)
    res = bake(scene, _settings(patch_size=1.0))
    mats = scene.face_materials
    corner_face = np.repeat(np.arange(len(scene.face_sizes)), scene.face_sizes)
    emit = scene.emission[mats[corner_face]]
    np.testing.assert_array_equal(res.corner_colours, emit)


def test_two_sided_panel_lights_ceiling_from_its_back():
    # Ceiling sees only the panel's back: lit when two-sided (Cycles), dark when one-sided.
    # Oracle: mean ceiling radiance = rho * F * Le with F of opposed unit squares 1 apart
    # (Howell). Tolerance 4 %: hemicube proximity error of 0.25 m patches at 1 m (~2 %) and
    # R = 32 aliasing.
    scene = _panel_under_ceiling(n=4)
    # output_mode='vertices': every front node solved (late rows); the mesh output skips unlit
    # faces.
    two = bake(scene, _settings(patch_size=1.0, rotate_hemicube=False, output_mode="vertices"))
    one = bake(scene, _settings(patch_size=1.0, rotate_hemicube=False, two_sided=False,
                                output_mode="vertices"))
    P = two.report["patches"]
    ceiling = slice(0, P // 2)
    mean = two.patch_radiance[ceiling].mean(axis=0)
    np.testing.assert_allclose(mean, 0.5 * F_OPPOSED_UNIT * 1.0, rtol=0.04)
    assert np.all(one.patch_radiance[ceiling] == 0.0)
    # One-sided: back nodes never active, never emit.
    assert not np.any(one.node_radiance[P:])
    # Every front node is solved (ceiling and panel); no back node ever is.
    assert one.report["nodes_active"] == P


def test_outside_of_closed_box_never_active():
    scene = unit_cube(n=2, emitting=("z+",), reflectance=0.6)
    res = bake(scene, _settings(patch_size=1.0))
    P = res.report["patches"]
    # Inside: all front nodes; outside: only the emitter's back nodes (they emit into the void).
    n_emitter = int(np.count_nonzero(scene.emission[res.patches.material].any(axis=1)))
    assert res.report["nodes_active"] == P + n_emitter
    back = res.node_radiance[P:]
    lit_back = np.flatnonzero(back.any(axis=1))
    assert np.all(scene.emission[res.patches.material[lit_back]].any(axis=1))
    assert res.report["warnings"] == []


def test_flipped_normals_warn():
    # The same box with every polygon reversed: the inside is the back side everywhere.
    scene = unit_cube(n=1, emitting=("z+",), reflectance=0.6)
    polys = [scene.corner_verts[s:s + k][::-1] for s, k in zip(scene.face_starts, scene.face_sizes)]
    flipped = scene_from_polygons(scene.vertices, polys, scene.face_materials, scene.reflectance,
                                  scene.emission)
    res = bake(flipped, _settings(patch_size=1.0, output_mode="vertices"))
    # All six, the emitter included (its front faces the void, its back the room).
    assert any(w.startswith("6 faces (1 of them emitting) receive their light on the back side")
               for w in res.report["warnings"])


# ----------------------------------------------------------------------------- energy


def test_energy_balance_open_scene():
    # Opposed unit squares, one patch each, no rotation: the two hemicubes see mirror images,
    # so F_ef = F_fe exactly (reciprocal) and the balance closes to rounding. Closed forms with
    # that F (emitter e: rho 0, emits both sides; floor f: rho 0.5, its back sees nothing):
    #   L_f = rho F Le; emitted = 2 pi Le; absorbed = pi [(1 - rho) F Le + F L_f];
    #   escaped = pi [Le (1 - F) + Le + L_f (1 - F)].
    scene = opposed_squares(size=1.0, gap=1.0, n=1, rho=0.5, le=2.0)
    res = bake(scene, _settings(patch_size=1.0, rotate_hemicube=False))
    F = form_factor_matrix(res.patches, resolution=R)
    f = F[1, 0]
    assert F[0, 1] == pytest.approx(f, rel=1e-12)
    assert f == pytest.approx(F_OPPOSED_UNIT, rel=0.25)   # hemicube proximity error at gap = size
    Le, rho = 2.0, 0.5
    Lf = rho * f * Le
    # rtol 1e-6: the bake keeps its form factors in float32 (relative rounding 6e-8).
    np.testing.assert_allclose(res.patch_radiance[0], Lf, rtol=1e-6)
    e = res.report["energy"]
    want = dict(emitted=3 * np.pi * 2 * Le,
                absorbed=3 * np.pi * ((1 - rho) * f * Le + f * Lf),
                escaped=3 * np.pi * (Le * (1 - f) + Le + Lf * (1 - f)))
    for key, value in want.items():                       # 3 x: summed over RGB
        assert e[key] == pytest.approx(value, rel=1e-6), key
    assert abs(e["balance"]) < 1e-6 * e["emitted"]
    assert e["escaped"] > 0.5 * e["emitted"]


def test_energy_balance_one_sided_black_backs():
    # An emitter facing down onto a square whose normal also points down: one-sided, the
    # square's lit side is its black back. Sender-based closed forms with f = F(emitter ->
    # square's back node): absorbed = pi A Le f, escaped = pi A Le (1 - f), balance 0 without
    # any reciprocity assumption; the square is reported as lit from behind.
    v1, q1 = horizontal_square(1.0, 1.0, 1, down=True)
    v2, q2 = horizontal_square(0.0, 1.0, 1, down=True)
    scene = scene_from_polygons(np.vstack([v1, v2]), q1 + [[i + 4 for i in q2[0]]], [0, 1],
                                [[0.0] * 3, [0.5] * 3], [[2.0] * 3, [0.0] * 3])
    res = bake(scene, _settings(patch_size=1.0, rotate_hemicube=False, two_sided=False))
    F = form_factor_matrix(res.patches, resolution=R)
    f = F[0, 1 + 2]                                       # node of the square's back (p + P)
    assert 0.15 < f < 0.25                                # Howell: 0.1998 + proximity error
    e = res.report["energy"]
    assert e["emitted"] == pytest.approx(3 * np.pi * 2.0, rel=1e-12)
    # rel 1e-6: rows kept in float32.
    assert e["absorbed"] == pytest.approx(3 * np.pi * 2.0 * f, rel=1e-6)
    assert e["escaped"] == pytest.approx(3 * np.pi * 2.0 * (1 - f), rel=1e-6)
    assert abs(e["balance"]) < 1e-6 * e["emitted"]
    assert not np.any(res.node_radiance[1])               # the square's front sees nothing
    assert "1 faces receive more light on their back side: check normals" in \
        res.report["warnings"]


# ----------------------------------------------------------------------------- solvers in bake


@pytest.fixture(scope="module")
def small_room():
    return room_with_boxes(120)


@pytest.fixture(scope="module")
def small_room_direct(small_room):
    return bake(small_room, _settings(patch_size=1.0, solver="direct"))


@pytest.mark.parametrize("solver", ["jacobi", "gauss_seidel", "progressive"])
def test_bake_solvers_agree_with_direct(small_room, small_room_direct, solver):
    ref = small_room_direct.node_radiance
    res = bake(small_room, _settings(patch_size=1.0, solver=solver, tolerance=1e-7))
    assert res.report["solver"] == solver and res.report["converged"]
    assert np.abs(res.node_radiance - ref).max() / ref.max() < 1e-4


def test_matrix_free_progressive(monkeypatch):
    # Budget below one batch of rows: the bake switches to matrix-free shooting over all nodes.
    # From rows only, shooting solves the system with the reciprocal columns
    # G_js = A_s F_sj / A_j; oracle: a direct solve of that system with F from
    # form_factor_matrix (same rows: no rotation).
    row = settings_module.BY_NAME["memory_budget"]
    monkeypatch.setitem(settings_module.BY_NAME, "memory_budget", dataclasses.replace(row, low=1))
    scene = unit_cube(n=1, emitting=("z+",), reflectance=0.6)
    res = bake(scene, _settings(patch_size=1.0, rotate_hemicube=False, memory_budget=1,
                                tolerance=1e-9))
    assert res.report["solver"] == "progressive"
    assert any("matrix-free" in w for w in res.report["warnings"])
    F = form_factor_matrix(res.patches, resolution=R)
    A = np.tile(res.patches.areas, 2)
    G = (F * A[:, None]).T / A[:, None]
    mat = np.tile(res.patches.material, 2)
    want = solve_direct(G, scene.reflectance[mat], scene.emission[mat]).radiance
    # tol 1e-9 on the unshot power; rows kept in float32 by the cache (6e-8 relative).
    np.testing.assert_allclose(res.node_radiance, want, rtol=1e-6, atol=1e-9)
    assert res.report["nodes_active"] == 7                  # inside + the light's back
    e = res.report["energy"]
    assert 0 <= e["balance"] <= 1e-9 * e["emitted"] * 1.0001   # = the unshot power
    again = relight(res, emission=scene.emission * 2)
    assert any("recomputed" in w for w in again.report["warnings"])
    np.testing.assert_allclose(again.node_radiance, 2 * res.node_radiance, rtol=1e-6, atol=1e-9)


# ----------------------------------------------------------------------------- relight


def _two_boxes():
    """Two unit boxes 3 m apart, box A's top emitting: (vertices, polygons, materials,
    reflectance, emission with box A lit, emission with box B's top lit too, settings).
    Rows of the emitters themselves: the hemicube carries their light (exact_direct 'off')."""
    a = unit_cube(n=1, emitting=("z+",), reflectance=0.5)
    polys = [a.corner_verts[s:s + k] for s, k in zip(a.face_starts, a.face_sizes)]
    verts = np.vstack([a.vertices, a.vertices + [3.0, 0.0, 0.0]])
    polys = polys + [p + len(a.vertices) for p in polys]
    mats = np.concatenate([a.face_materials, a.face_materials + 6])
    rho = np.vstack([a.reflectance, a.reflectance])
    em_a = np.vstack([a.emission, np.zeros((6, 3))])
    em_b = np.vstack([a.emission, a.emission * 2])
    s = _settings(patch_size=1.0, rotate_hemicube=False, output_mode="vertices",
                  exact_direct="off")
    return verts, polys, mats, rho, em_a, em_b, s


def test_relight_equals_fresh_bake(small_room, monkeypatch):
    # Receiver elements are placed where the first bake's light changes, and a relight keeps
    # them (tests/core/test_elements.py): a fresh bake under other lights may place them
    # elsewhere. Without elements a relight must equal a fresh bake exactly.
    # output_mode='vertices': the mesh output also keeps its mesh (placed by the first bake's
    # light).
    base = bake(small_room, _settings(patch_size=1.0, solver="direct", element_levels=0,
                                      output_mode="vertices"))
    original = base.node_radiance.copy()
    rho = small_room.reflectance.copy()
    rho[0] = [0.5, 0.6, 0.3]
    emission = small_room.emission * np.array([1.0, 0.5, 0.25])
    hemicube = importlib.import_module("core.hemicube")
    with monkeypatch.context() as m:      # relight must compute no form factor at all
        m.setattr(hemicube, "hemicube_rows", lambda *a, **k: pytest.fail("rows recomputed"))
        re = relight(base, reflectance=rho, emission=emission)
    fresh_scene = scene_from_polygons(
        small_room.vertices,
        [small_room.corner_verts[s:s + k] for s, k in zip(small_room.face_starts,
                                                          small_room.face_sizes)],
        small_room.face_materials, rho, emission)
    fresh = bake(fresh_scene, _settings(patch_size=1.0, solver="direct", element_levels=0,
                                        output_mode="vertices"))
    np.testing.assert_allclose(re.corner_colours, fresh.corner_colours, rtol=1e-10, atol=1e-12)
    # Wall-clock comparison kept loose: BLAS threads compete with other processes here.
    assert re.report["timings"]["form_factors"] < 0.1 * fresh.report["timings"]["form_factors"]
    # The original result is untouched.
    np.testing.assert_array_equal(base.node_radiance, original)


def test_relight_new_emitter_computes_only_new_rows():
    # Two separate closed boxes; only box A emits at first, so box B is never reached. Relight
    # switches box B's light on: its rows are computed then, and (no rotation, so rows do not
    # depend on the order they are computed in) the result equals a fresh bake.
    verts, polys, mats, rho, em_a, em_b, s = _two_boxes()
    first = bake(scene_from_polygons(verts, polys, mats, rho, em_a), s)
    # All 12 front nodes are solved; of the back nodes only box A's light's (it emits).
    assert first.report["nodes_active"] == 13
    re = relight(first, emission=em_b)
    fresh = bake(scene_from_polygons(verts, polys, mats, rho, em_b), s)
    assert re.report["nodes_active"] == 14
    np.testing.assert_allclose(re.node_radiance, fresh.node_radiance, rtol=1e-12)


def test_relight_back_emission_equals_fresh_bake(small_room):
    # A scene with one-sided emitters carries back_emission (the add-on's area lights): a
    # relight that changes it must equal a fresh bake of the scene with that back emission.
    polys = [small_room.corner_verts[s:s + k] for s, k in zip(small_room.face_starts,
                                                              small_room.face_sizes)]
    s = _settings(patch_size=1.0, solver="direct", element_levels=0, output_mode="vertices")

    def scene(emission, back):
        return scene_from_polygons(small_room.vertices, polys, small_room.face_materials,
                                   small_room.reflectance, emission, back_emission=back)
    em = np.asarray(small_room.emission)
    base = bake(scene(em, em), s)
    em2, back2 = em * [2.0, 1.0, 0.5], em * [0.5, 1.0, 3.0]
    re = relight(base, emission=em2, back_emission=back2)
    fresh = bake(scene(em2, back2), s)
    np.testing.assert_allclose(re.corner_colours, fresh.corner_colours, rtol=1e-10, atol=1e-12)
    kept = relight(base, emission=em2)        # without it, the bake's back emission stays
    np.testing.assert_allclose(kept.corner_colours,
                               bake(scene(em2, em), s).corner_colours, rtol=1e-10, atol=1e-12)


def _count_balancing(monkeypatch):
    """Count the Sinkhorn balancings (calls of make_reciprocal by the pipeline and of the
    Sinkhorn iteration itself) from now on."""
    pipeline = importlib.import_module("core.pipeline")
    calls = dict(balance=0, sinkhorn=0)

    def counted(name, fn):
        def wrapper(*args, **kw):
            calls[name] += 1
            return fn(*args, **kw)
        return wrapper
    monkeypatch.setattr(pipeline, "make_reciprocal",
                        counted("balance", pipeline.make_reciprocal))
    monkeypatch.setattr(reciprocity, "_sinkhorn", counted("sinkhorn", reciprocity._sinkhorn))
    return calls


@pytest.mark.parametrize("solver", ["direct", "gauss_seidel"])
def test_relight_reuses_the_balancing_and_equals_fresh_bake(small_room, monkeypatch, solver):
    # The reciprocity scaling depends on the form factors and areas only: a relight with a new
    # emission and reflectance applies the bake's again (no Sinkhorn sweep) and must still equal
    # an independent fresh bake of the changed scene, to the tolerance of the test above.
    s = _settings(patch_size=1.0, solver=solver, element_levels=0, output_mode="vertices")
    base = bake(small_room, s)
    assert base.report["solver"] == solver and base.report["reciprocity"]["sinkhorn_iterations"]
    rho = small_room.reflectance * 0.9
    emission = small_room.emission * np.array([2.0, 0.5, 0.25])
    with monkeypatch.context() as m:
        calls = _count_balancing(m)
        re = relight(base, reflectance=rho, emission=emission)
        assert calls == dict(balance=0, sinkhorn=0)
        again = relight(re, reflectance=small_room.reflectance,   # back to the bake's
                        emission=small_room.emission)
        assert calls == dict(balance=0, sinkhorn=0)
    assert re.report["reciprocity"] == dict(base.report["reciprocity"], reused=True)
    assert re._state.balance is base._state.balance
    # 8 bytes per solved node (and per unscaled node) are all the kept state gains.
    kept = base._state.balance.balance
    assert kept.nbytes == 8 * (base.report["nodes_active"] + kept.info["unscaled"])
    fresh_scene = dataclasses.replace(small_room, reflectance=rho, emission=emission)
    fresh = bake(fresh_scene, s)
    assert fresh.report["reciprocity"].get("reused") is None
    np.testing.assert_allclose(re.corner_colours, fresh.corner_colours, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(re.node_radiance, fresh.node_radiance, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(again.node_radiance, base.node_radiance, rtol=1e-10, atol=1e-12)


def test_relight_balances_again_when_it_adds_rows(monkeypatch):
    # Box B dark in the bake: a relight that lights it computes its rows, so the matrix grows
    # and its scaling is made again (and kept: a further relight reuses it); a relight that
    # leaves the solved nodes alone reuses the bake's. Each equals a fresh bake.
    verts, polys, mats, rho, em_a, em_b, s = _two_boxes()

    def fresh(em):
        return bake(scene_from_polygons(verts, polys, mats, rho, em), s).node_radiance

    calls = _count_balancing(monkeypatch)
    first = bake(scene_from_polygons(verts, polys, mats, rho, em_a), s)
    assert calls["balance"] == 1
    same = relight(first, emission=3 * em_a)             # same nodes: reused
    assert calls["balance"] == 1
    grown = relight(first, emission=em_b)                # box B's rows added: balanced again
    assert calls["balance"] == 2 and calls["sinkhorn"] >= 2
    assert "reused" not in grown.report["reciprocity"]
    assert grown._state.balance is not first._state.balance
    again = relight(grown, emission=0.5 * em_b)          # the grown matrix's scaling: reused
    assert calls["balance"] == 2 and again.report["reciprocity"]["reused"]
    n = calls["balance"]
    np.testing.assert_allclose(same.node_radiance, fresh(3 * em_a), rtol=1e-12)
    np.testing.assert_allclose(grown.node_radiance, fresh(em_b), rtol=1e-12)
    np.testing.assert_allclose(again.node_radiance, fresh(0.5 * em_b), rtol=1e-12)
    assert calls["balance"] == n + 3                     # the fresh bakes balanced, each once


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_rebalance_repeats_make_reciprocal_bit_for_bit(monkeypatch, dtype):
    # Several blocks (a small block size), and two nodes that cannot be balanced (see
    # tests/core/test_contacts.py): the kept scaling rebuilds the very matrix, in place too.
    monkeypatch.setattr(reciprocity, "_BLOCK", 7)
    rng = np.random.default_rng(5)
    n = 40
    F = rng.random((n, n)) * (rng.random((n, n)) < 0.5)
    np.fill_diagonal(F, 0.0)
    F = F / F.sum(axis=1, keepdims=True) * rng.uniform(0.6, 1.0, size=(n, 1))
    F[-2:], F[:, -2:] = 0.0, 0.0
    F[-2, -1], F[-1, -2] = 0.02, 0.008
    F = F.astype(dtype)
    areas = np.r_[rng.uniform(0.05, 2.0, n - 2), 0.01, 0.01]
    want, info = reciprocity.make_reciprocal(F, areas)
    got, info_too, found = reciprocity.make_reciprocal(F, areas, return_balance=True)
    assert info["unscaled"] == 2 and found.info == info == info_too
    np.testing.assert_array_equal(got, want)
    original = F.copy()
    np.testing.assert_array_equal(reciprocity.rebalance(F, areas, found), want)
    np.testing.assert_array_equal(F, original)                  # not mutated without out=F
    assert reciprocity.rebalance(F, areas, found, out=F) is F
    np.testing.assert_array_equal(F, want)
    with pytest.raises(ValueError, match="F must be square"):
        reciprocity.rebalance(original.astype(np.float16), areas, found)
    with pytest.raises(TypeError, match="found must be a Balance"):
        reciprocity.rebalance(original, areas, info)


def test_relight_validation(small_room_direct):
    with pytest.raises(ValueError,
                       match=r"reflectance must have shape \(M, 3\) = \(5, 3\); got \(4, 3\)"):
        relight(small_room_direct, reflectance=np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"reflectance must lie in \[0, 1\)"):
        relight(small_room_direct, reflectance=np.ones((5, 3)))
    with pytest.raises(ValueError, match="emission must be >= 0"):
        relight(small_room_direct, emission=-np.ones((5, 3)))
    with pytest.raises(ValueError, match="back_emission must be >= 0"):
        relight(small_room_direct, back_emission=-np.ones((5, 3)))
    with pytest.raises(ValueError, match=r"back_emission must have shape \(M, 3\)"):
        relight(small_room_direct, back_emission=np.ones((2, 3)))
    with pytest.raises(ValueError, match="no emitting patch"):
        relight(small_room_direct, emission=np.zeros((5, 3)))
    with pytest.raises(TypeError, match="result must be a BakeResult"):
        relight("nope")


# ----------------------------------------------------------------------------- monitor


def test_progress_non_decreasing(small_room):
    seen = []
    bake(small_room, _settings(patch_size=1.0, solver="gauss_seidel"),
         progress=lambda f, m: seen.append((f, m)))
    fr = [f for f, _ in seen]
    assert fr[0] == 0.0 and fr[-1] == 1.0
    assert all(0.0 <= f <= 1.0 for f in fr)
    assert all(b >= a for a, b in zip(fr, fr[1:]))


def test_cancel_stops_within_half_a_second():
    # The cancel flag is flipped by a timer thread (not by the polls themselves), so the time
    # from the flip to BakeCancelled is the true reaction time of the bake.
    scene = room_with_boxes(3000)                       # ~20 s of form factors at R = 64
    flipped = threading.Event()
    when = {}

    def flip():
        when["t"] = time.perf_counter()
        flipped.set()

    timer = threading.Timer(0.5, flip)
    timer.start()
    try:
        with pytest.raises(BakeCancelled):
            bake(scene, BakeSettings(patch_size=1.0), cancel=flipped.is_set)
        stopped = time.perf_counter()
    finally:
        timer.cancel()
    assert stopped - when["t"] < 0.5, stopped - when["t"]


def test_cancel_stops_within_half_a_second_in_the_lights_stage(monkeypatch):
    # Flipped as the patches' direct light begins (exact emitters: contour integrals, then
    # shadow rays over every patch's Gauss points), which ran 1.2 s with no look at the flag
    # until the lights polled it between passes (core.progress.checkpoint).
    from core import lights

    scene = room_with_boxes(3000)
    flipped = threading.Event()
    when = {}
    real = lights.DirectLight._patch_incident

    def flip_then_run(self, *args, **kwargs):
        when["t"] = time.perf_counter()
        flipped.set()
        return real(self, *args, **kwargs)

    monkeypatch.setattr(lights.DirectLight, "_patch_incident", flip_then_run)
    with pytest.raises(BakeCancelled):
        bake(scene, BakeSettings(patch_size=1.0, exact_direct="all"), cancel=flipped.is_set)
    assert time.perf_counter() - when["t"] < 0.5, time.perf_counter() - when["t"]


def test_deterministic_given_seed(small_room, monkeypatch):
    a = bake(small_room, _settings(patch_size=1.0, seed=7))
    # Batch sizes come from a cost model, never from the clock: a machine ten times slower
    # (simulated by sleeping in every row call) must give the same bits.
    hemicube = importlib.import_module("core.hemicube")
    rows = hemicube.hemicube_rows

    def slow_rows(*args, **kw):
        time.sleep(0.02)
        return rows(*args, **kw)

    with monkeypatch.context() as m:
        m.setattr(hemicube, "hemicube_rows", slow_rows)
        b = bake(small_room, _settings(patch_size=1.0, seed=7))
    c = bake(small_room, _settings(patch_size=1.0, seed=8))
    np.testing.assert_array_equal(a.node_radiance, b.node_radiance)
    assert not np.array_equal(a.node_radiance, c.node_radiance)


def test_report_keys(small_room_direct):
    rep = small_room_direct.report
    assert isinstance(small_room_direct, BakeResult)
    assert set(rep) >= {"patches", "nodes_active", "faces_dropped", "method", "solver",
                        "iterations", "residual", "converged", "timings", "energy",
                        "form_factor_bytes", "warnings"}
    # A "lights" stage exactly when there are direct lights: here the room's ceiling panel,
    # about 3 pixels of these tests' R = 32 hemicube from what it lights (6 at the default 64),
    # is lit exactly (core.emitters.AUTO_PIXELS).
    assert rep["lights"]["exact_emitter_faces"] == 1
    assert set(rep["timings"]) == {"patches", "lights", "form_factors", "solve", "colours",
                                   "total"}
    n = rep["nodes_active"]
    assert rep["matrix_bytes"] == 8 * n * n                # float64 matrix of the direct solve
    assert 0 < rep["form_factor_bytes"] < 5 * n * n        # kept rows: float32 + column indices
    assert rep["timings"]["total"] >= rep["timings"]["form_factors"]


# ----------------------------------------------------------------------------- settings


@pytest.mark.parametrize("name, value, message", [
    ("patch_size", 0.0, "patch_size must be a finite number > 0"),
    ("patch_size", float("nan"), "patch_size must be a finite number > 0"),
    ("method", "radiance", "method must be one of 'hemicube', 'nusselt', 'exact', 'hybrid', "
                          "'raytraced'; got 'radiance'"),
    ("resolution", 33, r"resolution must be an even integer in \[4, 2048\] \(px\); got 33"),
    ("resolution", 64.0, r"resolution must be an even integer in \[4, 2048\] \(px\); got 64.0"),
    ("resolution", 3000, r"resolution must be an even integer in \[4, 2048\] \(px\); got 3000"),
    ("rotate_hemicube", 1, "rotate_hemicube must be True or False; got 1"),
    ("solver", "cg", "solver must be one of 'auto', 'direct', 'jacobi', 'gauss_seidel', "
                     "'progressive'; got 'cg'"),
    ("tolerance", 0.0, r"tolerance must be a number in \(0, 1\); got 0.0"),
    ("tolerance", 1.0, r"tolerance must be a number in \(0, 1\); got 1.0"),
    ("max_iterations", 0, "max_iterations must be an integer >= 1; got 0"),
    ("two_sided", "yes", "two_sided must be True or False; got 'yes'"),
    ("crease_angle", 181.0, r"crease_angle must be a number in \[0, 180\] \(deg\); got 181.0"),
    ("memory_budget", 1000, r"memory_budget must be an integer >= 1048576 \(bytes\); got 1000"),
    ("reciprocity", 1, "reciprocity must be True, False or 'auto'; got 1"),
    ("near", -0.5, r"near must be a finite number >= 0 \(x patch size\); got -0.5"),
    ("seed", -1, "seed must be an integer >= 0; got -1"),
    ("rays", 0, "rays must be an integer >= 1; got 0"),
])
def test_settings_validation(name, value, message):
    with pytest.raises(SettingsError, match=message):
        BakeSettings(**{name: value})


def test_settings_type_and_frozen():
    with pytest.raises(TypeError, match="settings must be a BakeSettings; got dict"):
        bake(unit_cube(), {"patch_size": 1.0})
    s = BakeSettings()
    with pytest.raises(AttributeError):
        s.patch_size = 2.0
