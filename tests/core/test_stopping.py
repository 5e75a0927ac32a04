"""The stopping tolerance scaled with the reflectance (issue 11).

Oracle (closed form): with row-stochastic form factors (a closed enclosure), one reflectance
and one emitted radiance everywhere, the radiance is Le / (1 - rho) at every node (white
furnace). An iterative solve stopped at tolerance tol must be within tol of it at any rho.
"""

import numpy as np
import pytest

from core.bake import bake
from core.constants import DEFAULT_TOLERANCE
from core.scene import scene_from_polygons
from core.settings import BakeSettings
from core.solvers import (solve_gauss_seidel, solve_jacobi, solve_progressive,
                          stopping_threshold)

#: Iteration cap high enough for rho = 0.99 (Jacobi needs about ln(tol (1 - rho)) / ln(rho)).
MAX_ITERATIONS = 20000


def _stochastic(n, seed):
    rng = np.random.default_rng(seed)
    F = rng.random((n, n))
    np.fill_diagonal(F, 0.0)
    return F / F.sum(axis=1, keepdims=True)


@pytest.mark.parametrize("rho", [0.5, 0.9, 0.99])
@pytest.mark.parametrize("solver", ["jacobi", "gauss_seidel", "gauss_seidel_float32",
                                    "progressive"])
def test_furnace_within_tolerance_at_high_reflectance(rho, solver):
    # gauss_seidel_float32: the bake's float32 matrix, whose gathers are float32 products
    # above core.solvers.F32_FLOOR; at rho = 0.99 the threshold (1e-6) lies below the floor and
    # the last sweeps are float64.
    n, le = 50, 2.0
    F = _stochastic(n, 1)
    if solver == "gauss_seidel_float32":
        solver, F = "gauss_seidel", F.astype(np.float32)
    R = np.full((n, 3), rho)
    E = np.full((n, 3), le)
    if solver == "jacobi":
        res = solve_jacobi(F, R, E, tol=DEFAULT_TOLERANCE, max_iterations=MAX_ITERATIONS)
    elif solver == "gauss_seidel":
        res = solve_gauss_seidel(F, R, E, tol=DEFAULT_TOLERANCE, max_iterations=MAX_ITERATIONS,
                                 block=16)
    else:
        res = solve_progressive(None, np.ones(n), R, E, F=F, tol=DEFAULT_TOLERANCE,
                                max_shots=MAX_ITERATIONS * n)
    assert res.converged
    exact = le / (1.0 - rho)
    err = np.abs(res.radiance / exact - 1.0).max()
    assert err <= DEFAULT_TOLERANCE, f"{solver} at rho={rho}: relative error {err:.3g}"


def test_stopping_threshold_scales_with_max_reflectance():
    rho = np.array([[0.2, 0.5, 0.99], [0.1, 0.1, 0.1]])
    assert stopping_threshold(1e-4, rho) == pytest.approx(1e-6)
    assert stopping_threshold(1e-4, np.zeros((0, 3))) == pytest.approx(1e-4)


@pytest.mark.parametrize("solver", ["gauss_seidel", "jacobi"])
def test_bake_furnace_at_rho_099(solver):
    """A closed 2 m cube, every face emitting Le and reflecting 0.99, baked with an iterative
    solver: the front patches read Le / (1 - rho) within the tolerance plus the hemicube's
    row-sum error (rows of a closed box sum to 1 up to rounding)."""
    rho, le, s = 0.99, 0.5, 2.0
    v = np.array([[0, 0, 0], [s, 0, 0], [s, s, 0], [0, s, 0],
                  [0, 0, s], [s, 0, s], [s, s, s], [0, s, s]], dtype=float)
    polys = [[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]]
    scene = scene_from_polygons(v, polys, [0] * 6, np.full((1, 3), rho), np.full((1, 3), le))
    res = bake(scene, BakeSettings(patch_size=0.5, solver=solver, corners="average",
                                   element_levels=0, max_iterations=MAX_ITERATIONS))
    assert res.report["converged"]
    err = np.abs(res.patch_radiance / (le / (1 - rho)) - 1).max()
    assert err <= 3 * DEFAULT_TOLERANCE, f"relative error {err:.3g}"
