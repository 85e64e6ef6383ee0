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
from imucal.gyro.result import arrays
from imucal.model.gyroscope import gyro_model, gyro_parameters
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
    return data, seg, st


def _params(st, scale, free_bias=False):
    return gyro_parameters("raw", st.bias, scale, gsens=st.H, free_bias=free_bias)


@pytest.mark.parametrize("free_bias", [False, True])
def test_residuals_and_jacobian_equal_the_chained_graph(case, free_bias: bool) -> None:
    data, seg, st = case
    params = _params(st, TRUTH.scale * 1.01, free_bias)
    free, pfix = params.free_names, np.array(params.values())
    xs, rv = chained_graph(data.t, seg, data.gyro, data.acc, gyro_model(), free, pfix)
    f = ca.Function("ref", [xs], [rv, ca.jacobian(rv, xs)])
    d = np.array([params[n].scale for n in free])
    pfree = np.array([params[n].value for n in free]) + d * np.random.default_rng(1).normal(size=len(free)) * 0.02
    r_ref, J_ref = (np.asarray(v) for v in f(pfree))
    r, J = _steps(data, seg).jacobian(gyro_model(), free, pfree, pfix)
    np.testing.assert_allclose(r.ravel(), r_ref.ravel(), rtol=0, atol=1e-13)
    np.testing.assert_allclose(J * d, J_ref * d, rtol=0, atol=1e-11 * np.abs(J_ref * d).max())


def test_optimum_equals_the_exact_hessian_nlp(case) -> None:
    data, seg, st = case
    r = arrays(fit_gyro(data, GyroOptions(gsens="off", nominal_scale=4700.0)))
    params = _params(st, np.full(3, 4700.0))
    free = params.free_names
    w = 1.0 / _segment_sigma(data, seg, np.full(3, 4700.0))
    xs, rv = chained_graph(data.t, seg, data.gyro, data.acc, gyro_model(), free, np.array(params.values()))
    d = np.array([params[n].scale for n in free])
    p0 = np.array([params[n].value for n in free])
    x = ca.MX.sym("x", len(free))
    obj = 0.5 * ca.sumsqr(ca.substitute(rv, xs, p0 + d * x) * ca.DM(np.repeat(w, 3)))
    solver = ca.nlpsol("ref", "ipopt", {"x": x, "f": obj},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": 1e-12})
    p = p0 + d * np.asarray(solver(x0=np.zeros(len(free)))["x"]).ravel()
    assert solver.stats()["success"]
    ref = dict(zip(free, p))
    scale = np.array([ref[f"scale_{a}"] for a in "xyz"])
    np.testing.assert_allclose(r.scale, scale, rtol=1e-6)
    assert np.all(np.abs(r.scale - scale) <= 1e-3 * r.scale_std)
    ours = np.array([r.misalignment[i, j] for i, j in ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))])
    sd = np.array([r.misalignment_std[i, j] for i, j in ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))])
    mis = np.array([ref[n] for n in ("m_xy", "m_xz", "m_yx", "m_yz", "m_zx", "m_zy")])
    assert np.all(np.abs(ours - mis) <= 1e-3 * sd), (ours, mis, sd)


def test_pruned_grid_search_is_the_grid_argmin(case) -> None:
    data, seg, st = case
    steps = _steps(data, seg)
    params = _params(st, np.ones(3))
    free, pfix = params.free_names, params.values()

    def cost(k: float) -> float:
        return float((steps.residuals(gyro_model(), free, np.r_[np.full(3, k), np.zeros(6)], pfix) ** 2).sum())

    grid = 10.0 ** np.arange(1, 5.01, 0.1)
    costs = [cost(k) for k in grid]
    brute = grid[int(np.argmin(costs))]
    rows = np.vstack([np.tile(grid, (3, 1)), np.zeros((6, grid.size))])  # every scale in one pass, broadcast
    np.testing.assert_allclose(steps.costs(gyro_model(), free, rows, pfix), costs, rtol=1e-12)
    assert _grid_argmin(steps, params, grid) == brute
    assert abs(np.log10(brute / 4770.0)) < 0.1  # and it found the true scale's basin


def test_motion_evidence_integrates_once_per_point(case, monkeypatch) -> None:
    """The fit asks for the residuals at a point twice before its Jacobian: the motions are integrated once."""
    from imucal.gyro.attitude import SegmentSteps
    from imucal.gyro.evidence import MotionEvidence

    data, seg, st = case
    params = _params(st, np.full(3, 4770.0))
    ev = MotionEvidence(gyro_model(), params.free_names, _steps(data, seg), np.full(seg.n, 1e-3), 5.0)
    calls = []
    orig = SegmentSteps.residuals
    monkeypatch.setattr(SegmentSteps, "residuals", lambda self, *a: calls.append(1) or orig(self, *a))
    pfree = np.array([params[n].value for n in params.free_names])
    first = ev.residuals(pfree, params.values())
    assert np.array_equal(ev.residuals(pfree, params.values()), first) and len(calls) == 1
    r, _ = ev.jacobian(pfree, params.values())
    np.testing.assert_allclose(r, first, rtol=0, atol=1e-12)
    ev.residuals(pfree * 1.001, params.values())
    assert len(calls) == 2
