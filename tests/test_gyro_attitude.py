"""The fast segment path (gyro/attitude.py) against the CasADi graph it replaced: RK4 steps chained
inside one NLP, IPOPT with its exact Hessian. Same residuals, Jacobian, scale search and optimum."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from imucal.gyro import GyroOptions, fit_gyro
from imucal.gyro.attitude import chained_graph
from imucal.gyro.fit import _grid_argmin, _segment_sigma, _steps
from imucal.gyro.gsens import fit_static
from imucal.gyro.segments import motion_segments
from imucal.gyro.simulate import GyroTruth, simulate

TURNS = [(0, 1.5), (1, 1.4), (2, 1.6), (0, -1.3), (1, -1.5), (2, -1.2), (1, 0.9)]
TRUTH = GyroTruth(bias=np.array([32768.0, 32450.0, 32510.0]), scale=np.array([4780.0, 4760.0, 4770.0]),
                  mis=np.array([0.01, -0.02, 0.015, 0.03, -0.025, 0.02]), gsens=np.zeros((3, 3)), noise=3.0)


@pytest.fixture(scope="module")
def case():
    data = simulate(TRUTH, TURNS, seed=7)
    seg = motion_segments(data)
    gm, _, am, _ = data.static_means()
    st = fit_static(gm, am, "off")
    return data, seg, data.gyro - st.bias - data.acc @ st.H.T


@pytest.mark.parametrize("nx", [9, 12])
def test_residuals_and_jacobian_equal_the_chained_graph(case, nx: int) -> None:
    data, seg, corrected = case
    scale0 = TRUTH.scale * 1.01
    xs, rv = chained_graph(data.t, seg, corrected, nx, scale0)
    f = ca.Function("ref", [xs], [rv, ca.jacobian(rv, xs)])
    x = np.random.default_rng(1).normal(size=nx) * 0.02
    r_ref, J_ref = (np.asarray(v) for v in f(x))
    r, J = _steps(data, seg, corrected).jacobian(x, scale0)
    np.testing.assert_allclose(r.ravel(), r_ref.ravel(), rtol=0, atol=1e-13)
    np.testing.assert_allclose(J, J_ref, rtol=0, atol=1e-11 * np.abs(J_ref).max())


def test_optimum_equals_the_exact_hessian_nlp(case) -> None:
    data, seg, corrected = case
    r = fit_gyro(data, GyroOptions(gsens="off", nominal_scale=4700.0))
    scale0 = np.full(3, 4700.0)
    w = 1.0 / _segment_sigma(data, seg, scale0)
    xs, rv = chained_graph(data.t, seg, corrected, 9, scale0)
    obj = 0.5 * ca.sumsqr(rv * ca.DM(np.repeat(w, 3)))
    solver = ca.nlpsol("ref", "ipopt", {"x": xs, "f": obj},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": 1e-12})
    x = np.asarray(solver(x0=np.zeros(9))["x"]).ravel()
    assert solver.stats()["success"]
    np.testing.assert_allclose(r.scale, scale0 * (1 + x[0:3]), rtol=1e-6)
    assert np.all(np.abs(r.scale - scale0 * (1 + x[0:3])) <= 1e-3 * r.scale_std)
    ours = np.array([r.misalignment[i, j] for i, j in ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))])
    sd = np.array([r.misalignment_std[i, j] for i, j in ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))])
    assert np.all(np.abs(ours - x[3:9]) <= 1e-3 * sd), (ours, x[3:9], sd)


def test_pruned_grid_search_is_the_grid_argmin(case) -> None:
    data, seg, corrected = case
    steps = _steps(data, seg, corrected)
    grid = 10.0 ** np.arange(1, 5.01, 0.1)
    brute = grid[int(np.argmin([steps.residuals(np.zeros(9), np.full(3, k)).__pow__(2).sum() for k in grid]))]
    assert _grid_argmin(steps, grid, 9) == brute
    assert abs(np.log10(brute / 4770.0)) < 0.1  # and it found the true scale's basin
