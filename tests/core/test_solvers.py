"""Tests of core/solvers.py: every solver against closed forms and against the direct solve."""

import numpy as np
import pytest

import core.progress as progress
from bench.scenes import unit_cube
from core.errors import BakeCancelled
from core.progress import Monitor
from core.solvers import (SolveResult, ambient_radiance, solve_direct, solve_gauss_seidel,
                          solve_gauss_seidel_many,
                          solve_jacobi, solve_progressive)

#: Iterative solvers run to this tolerance so that their answer must match the direct solve to
#: AGREE: the error of an iterate is at most residual * rho / (1 - rho) <= 9 x TOL at rho = 0.9.
TOL = 1e-8
AGREE = 1e-4


# ----------------------------------------------------------------------------- fixtures


def _quads(scene):
    """(F, 4, 3) corners of a scene made of quads."""
    c = scene.vertices[scene.corner_verts]
    return c.reshape(-1, 4, 3)


def _point_polygon_ff(points, normals, polys):
    """Lambert's contour formula, polygons fully above every point's plane: (S, Q).

    Independent of core/exact.py: F = |sum_k angle_k (n . unit(R_k x R_k+1))| / (2 pi).
    """
    R = polys[None, :, :, :] - points[:, None, None, :]            # (S, Q, 4, 3)
    Rn = np.roll(R, -1, axis=2)
    cross = np.cross(R, Rn)
    norm = np.linalg.norm(cross, axis=-1)
    cosang = np.einsum("sqkd,sqkd->sqk", R, Rn) / (
        np.linalg.norm(R, axis=-1) * np.linalg.norm(Rn, axis=-1))
    angle = np.arccos(np.clip(cosang, -1, 1))
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(norm[..., None] > 0, cross / norm[..., None], 0.0)
    s = np.einsum("sqkd,sd->sqk", unit, normals) * angle
    return np.abs(s.sum(axis=2)) / (2 * np.pi)


@pytest.fixture(scope="module")
def room():
    """Closed unit cube, 3 x 3 quads per face (54 nodes), point-to-polygon form factors.

    Convex and closed: no occlusion and every row sums to 1 (the quads tile the hemisphere).
    """
    scene = unit_cube(n=3)
    quads = _quads(scene)
    centres = quads.mean(axis=1)
    F = _point_polygon_ff(centres, scene.face_normals, quads)
    F[np.arange(len(F)), np.arange(len(F))] = 0.0
    areas = scene.face_areas.copy()
    # The centre-point rows are not exactly reciprocal; all quads have the same area, so make F
    # symmetric and doubly stochastic (symmetric Sinkhorn scaling, a ~1 % change) to get a
    # closed, reciprocal room matrix on which shooting and gathering solve the same system.
    S = 0.5 * (F + F.T)
    for _ in range(200):
        r = S.sum(axis=1)
        S = S / np.sqrt(r[:, None] * r[None, :])
    return S, areas, scene, F


def _system(room, seed=0, rho_max=0.9):
    F, areas, scene, _ = room
    rng = np.random.default_rng(seed)
    n = len(F)
    rho = rng.uniform(0.1, rho_max, (n, 3))       # a different reflectance per channel
    le = np.zeros((n, 3))
    le[:9] = rng.uniform(1.0, 5.0, (9, 3))        # one face of the cube emits
    return F, areas, rho, le


def test_room_fixture_identities(room):
    # Sum rule of the closed cube for the raw contour-formula rows (rounding only), and the
    # symmetric scaled matrix: reciprocal (equal areas) and rows summing to 1.
    S, areas, _, F = room
    np.testing.assert_allclose(F.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(S, S.T, atol=1e-15)
    np.testing.assert_allclose(S.sum(axis=1), 1.0, atol=1e-12)
    assert np.abs(S - F).max() < 0.02
    np.testing.assert_allclose(areas, areas[0])


def test_progressive_dense_non_reciprocal_matches_direct(room):
    # With a dense F, shooting uses columns: same answer as gathering on a non-reciprocal F.
    _, areas, _, F = room
    rho = np.full((len(F), 3), 0.7)
    le = np.zeros((len(F), 3))
    le[:9] = 1.0
    ref = solve_direct(F, rho, le).radiance
    res = solve_progressive(None, areas, rho, le, F=F, tol=TOL)
    assert np.abs(res.radiance - ref).max() / ref.max() < AGREE


# ----------------------------------------------------------------------------- closed forms


def test_direct_two_nodes_closed_form():
    f = 0.3
    F = np.array([[0.0, f], [f, 0.0]])
    rho = np.array([[0.5, 0.2, 0.9], [0.7, 0.4, 0.1]])
    le = np.array([[1.0, 2.0, 0.5], [0.0, 1.0, 3.0]])
    # L1 = (Le1 + rho1 f Le2) / (1 - rho1 rho2 f^2), and symmetrically.
    d = 1 - rho[0] * rho[1] * f * f
    want = np.stack([(le[0] + rho[0] * f * le[1]) / d, (le[1] + rho[1] * f * le[0]) / d])
    got = solve_direct(F, rho, le)
    np.testing.assert_allclose(got.radiance, want, rtol=1e-13)
    assert got.converged and got.solver == "direct"


@pytest.mark.parametrize("solver", ["direct", "jacobi", "gauss_seidel", "gauss_seidel_point",
                                    "progressive"])
@pytest.mark.parametrize("rho_value", [0.3, 0.85])
def test_white_furnace(room, solver, rho_value):
    # Closed scene (rows sum to 1), uniform rho and Le: L = Le / (1 - rho) everywhere.
    F, areas, _, _ = room
    n = len(F)
    rho = np.full((n, 3), rho_value)
    le = np.full((n, 3), 2.0)
    res = _solve(solver, F, areas, rho, le)
    assert res.converged
    # error <= residual * rho / (1 - rho) (relative): 20 x TOL covers rho = 0.85 with margin.
    np.testing.assert_allclose(res.radiance, 2.0 / (1 - rho_value), rtol=20 * TOL)


def _solve(solver, F, areas, rho, le, **kw):
    if solver == "direct":
        return solve_direct(F, rho, le)
    if solver == "jacobi":
        return solve_jacobi(F, rho, le, tol=TOL, **kw)
    if solver == "gauss_seidel":
        return solve_gauss_seidel(F, rho, le, tol=TOL, block=16, **kw)
    if solver == "gauss_seidel_point":
        return solve_gauss_seidel(F, rho, le, tol=TOL, block=1, **kw)
    # A uniform furnace at rho = 0.85 needs ~ln(TOL)/ln(rho) x N shots: lift the default cap.
    if solver == "progressive":
        return solve_progressive(None, areas, rho, le, F=F, tol=TOL, max_shots=10**6, **kw)
    if solver == "progressive_free":
        return solve_progressive(lambda s: F[s], areas, rho, le, tol=TOL, max_shots=10**6, **kw)
    raise AssertionError(solver)


# ----------------------------------------------------------------------------- agreement


@pytest.mark.parametrize("solver", ["jacobi", "gauss_seidel", "gauss_seidel_point", "progressive",
                                    "progressive_free"])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_solvers_agree_with_direct(room, solver, dtype):
    F, areas, rho, le = _system(room)
    ref = solve_direct(F, rho, le).radiance
    res = _solve(solver, F.astype(dtype), areas, rho, le)
    assert res.converged
    assert res.residual <= TOL
    # float32 storage of F perturbs it by ~6e-8 relative: far below AGREE.
    err = np.abs(res.radiance - ref).max() / np.abs(ref).max()
    assert err < AGREE, (solver, err)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_gauss_seidel_many_solves_each_emission_as_alone(room, dtype):
    # Oracle: LU (solve_direct) per emission. Four emissions at once, one of them dark and one
    # a thousand times dimmer than the others (each is converged on its own scale, not the
    # brightest's); they share the sweeps, so none stops before it would alone.
    F, areas, rho, le = _system(room)
    rng = np.random.default_rng(5)
    dim = np.zeros_like(le)
    dim[-9:] = 1e-3 * rng.uniform(1.0, 5.0, (9, 3))     # the opposite face, dimly
    les = [le, np.zeros_like(le), dim, le[::-1].copy()]
    many = solve_gauss_seidel_many(F.astype(dtype), rho, les, tol=TOL)
    assert len(many) == 4
    for e, res in zip(les, many):
        alone = solve_gauss_seidel(F.astype(dtype), rho, e, tol=TOL)
        assert res.converged and res.residual <= TOL
        assert res.iterations >= alone.iterations
        ref = solve_direct(F, rho, e).radiance
        scale = max(np.abs(ref).max(), 1e-300)
        assert np.abs(res.radiance - ref).max() <= AGREE * scale
    np.testing.assert_array_equal(many[1].radiance, 0.0)
    with pytest.raises(ValueError, match="le must have shape"):
        solve_gauss_seidel_many(F, rho, [le, le[:5]])


def test_direct_residual_identity(room):
    # The returned L satisfies L = Le + rho F L (checked independently of the solver).
    F, _, rho, le = _system(room, seed=3)
    L = solve_direct(F, rho, le).radiance
    np.testing.assert_allclose(L, le + rho * (F @ L), rtol=1e-12, atol=1e-12)


def test_progressive_matrix_free_batches_and_calls(room):
    F, areas, rho, le = _system(room)
    calls = []

    def rows(nodes):
        calls.append(np.array(nodes))
        return F[nodes]

    ref = solve_direct(F, rho, le).radiance
    res = solve_progressive(rows, areas, rho, le, tol=TOL, batch=5)
    assert all(1 <= len(c) <= 5 for c in calls)
    assert res.stats["row_requests"] == len(calls)
    assert res.iterations == sum(len(c) for c in calls)
    assert np.abs(res.radiance - ref).max() / ref.max() < AGREE


def test_progressive_energy_bookkeeping(room):
    # emitted = absorbed + escaped + unshot, per channel; an open scene (half the rows
    # scaled down) makes escaped non-zero.
    F, areas, rho, le = _system(room)
    F = F.copy()
    F[::2] *= 0.6
    res = solve_progressive(None, areas, rho, le, F=F, tol=1e-3)
    st = res.stats
    np.testing.assert_allclose(st["emitted"], st["absorbed"] + st["escaped"] + st["unshot"],
                               rtol=1e-12)
    assert np.all(st["escaped"] > 0)
    assert st["unshot"].sum() / st["emitted"].sum() == pytest.approx(res.residual, rel=1e-12)


def test_progressive_ambient_conserves_total_energy(room):
    # Closed scene, uniform rho: the unshot power U will still produce U rho / (1 - rho) of
    # outgoing power, which is what the ambient term adds; so after only a few shots the
    # area-weighted total of the display equals the converged total exactly.
    F, areas, _, _ = room
    n = len(F)
    rho = np.full((n, 3), 0.6)
    le = np.zeros((n, 3))
    le[:9] = 1.0
    exact = solve_direct(F, rho, le).radiance
    early = solve_progressive(None, areas, rho, le, F=F, max_shots=20, ambient=True)
    plain = solve_progressive(None, areas, rho, le, F=F, max_shots=20)
    assert not early.converged
    total = (exact * areas[:, None]).sum(axis=0)
    np.testing.assert_allclose((early.radiance * areas[:, None]).sum(axis=0), total, rtol=1e-10)
    assert np.all((plain.radiance * areas[:, None]).sum(axis=0) < 0.99 * total)


def test_ambient_radiance_formula():
    areas = np.array([1.0, 3.0])
    rho = np.array([[0.5, 0.5, 0.5], [0.1, 0.2, 0.3]])
    dL = np.array([[2.0, 0.0, 1.0], [0.0, 4.0, 1.0]])
    rho_avg = (0.5 * 1 + rho[1] * 3) / 4
    amb = (dL * areas[:, None]).sum(axis=0) / 4 / (1 - rho_avg)
    np.testing.assert_allclose(ambient_radiance(areas, rho, dL), rho * amb, rtol=1e-14)


def test_iteration_cap_reports_not_converged(room):
    F, areas, rho, le = _system(room)
    for res in (solve_jacobi(F, rho, le, tol=TOL, max_iterations=2),
                solve_gauss_seidel(F, rho, le, tol=TOL, max_iterations=2, block=8)):
        assert res.iterations == 2 and not res.converged and res.residual > TOL
    res = solve_progressive(None, areas, rho, le, F=F, tol=TOL, max_shots=7, batch=3)
    assert res.iterations == 7 and not res.converged


def test_gauss_seidel_not_slower_than_jacobi(room):
    # Varga's comparison theorem for the M-matrix I - rho F: block GS <= point GS <= Jacobi in
    # asymptotic rate; in sweeps to a tolerance the order shows as well.
    F, _, rho, le = _system(room)
    j = solve_jacobi(F, rho, le, tol=TOL).iterations
    p = solve_gauss_seidel(F, rho, le, tol=TOL, block=1).iterations
    b = solve_gauss_seidel(F, rho, le, tol=TOL, block=27).iterations
    assert b <= p < j


def test_no_emission_gives_zero(room):
    F, areas, rho, _ = _system(room)
    le = np.zeros_like(rho)
    for res in (solve_direct(F, rho, le), solve_jacobi(F, rho, le),
                solve_gauss_seidel(F, rho, le), solve_progressive(None, areas, rho, le, F=F)):
        assert isinstance(res, SolveResult)
        assert res.converged and not np.any(res.radiance)


def test_inputs_not_mutated(room):
    F, areas, rho, le = _system(room)
    copies = [x.copy() for x in (F, areas, rho, le)]
    solve_direct(F, rho, le)
    solve_jacobi(F, rho, le)
    solve_gauss_seidel(F, rho, le)
    solve_progressive(None, areas, rho, le, F=F)
    solve_progressive(lambda s: F[s], areas, rho, le, ambient=True)
    for a, b in zip((F, areas, rho, le), copies):
        np.testing.assert_array_equal(a, b)


# ----------------------------------------------------------------------------- monitor


@pytest.mark.parametrize("solver", ["jacobi", "gauss_seidel", "progressive"])
def test_progress_non_decreasing_and_cancel(room, solver, monkeypatch):
    monkeypatch.setattr(progress, "POLL_INTERVAL", 0.0)   # poll at every opportunity
    F, areas, rho, le = _system(room)
    seen = []
    mon = Monitor(lambda f, m: seen.append(f))
    _solve(solver, F, areas, rho, le, monitor=mon)
    assert seen and all(0.0 <= f <= 1.0 for f in seen)
    assert all(b >= a for a, b in zip(seen, seen[1:]))
    assert seen[-1] == 1.0

    calls = []

    def cancel():
        calls.append(1)
        return len(calls) > 2

    with pytest.raises(BakeCancelled):
        _solve(solver, F, areas, rho, le, monitor=Monitor(None, cancel))


# ----------------------------------------------------------------------------- validation


def test_validation_messages(room):
    F, areas, rho, le = _system(room)
    n = len(F)
    with pytest.raises(ValueError, match=r"F must be a square \(N, N\) array; got \(54, 53\)"):
        solve_direct(F[:, :-1], rho, le)
    with pytest.raises(TypeError, match="F must be float32 or float64; got int64"):
        solve_jacobi(F.astype(np.int64), rho, le)
    with pytest.raises(ValueError,
                       match=rf"rho must have shape \(N, 3\) = \({n}, 3\); got \({n}, 2\)"):
        solve_gauss_seidel(F, rho[:, :2], le)
    with pytest.raises(ValueError, match=r"le must have shape"):
        solve_direct(F, rho, le[:-1])
    with pytest.raises(ValueError, match=r"rho must lie in \[0, 1\)"):
        solve_direct(F, np.ones_like(rho), le)
    with pytest.raises(ValueError, match=r"le must be >= 0"):
        solve_jacobi(F, rho, -le)
    with pytest.raises(ValueError, match="le must be finite"):
        solve_direct(F, rho, np.full_like(le, np.nan))
    with pytest.raises(ValueError, match="tol must be a finite number > 0; got 0.0"):
        solve_jacobi(F, rho, le, tol=0.0)
    with pytest.raises(ValueError, match="max_iterations must be an integer >= 1; got 0"):
        solve_gauss_seidel(F, rho, le, max_iterations=0)
    with pytest.raises(ValueError, match=r"areas must have shape \(N,\)"):
        solve_progressive(None, areas[:, None], rho, le, F=F)
    with pytest.raises(ValueError, match="areas must be finite and > 0"):
        solve_progressive(None, -areas, rho, le, F=F)
    with pytest.raises(TypeError, match="row_fn must be callable when F is None"):
        solve_progressive(None, areas, rho, le)
    with pytest.raises(ValueError, match=r"row_fn must return shape \(\d+, 54\); got"):
        solve_progressive(lambda s: F[s][:, :-1], areas, rho, le)
    with pytest.raises(ValueError, match="batch must be an integer >= 1; got 0"):
        solve_progressive(None, areas, rho, le, F=F, batch=0)
