"""One least-squares path for every model: a model extended by an effect held at zero gives the
base model's fit, and the Gauss-Newton and exact Hessians reach the same optimum."""
from __future__ import annotations

import numpy as np
import pytest

from imucal.model.effects import make_effect
from imucal.solve.fit import FitData, fit
from imucal.solve.initial import ellipsoid_guess
from imucal.model.sensor import build_model
from imucal.model.parameters import base_parameters
from imucal.analysis.simulate import PosePlan, cube_directions, mems_counts_sensor, simulate
from imucal.data.static import detect_static

G = 9.80665


@pytest.fixture(scope="module")
def data():
    sim = simulate(mems_counts_sensor(np.random.default_rng(7)),
                   PosePlan(cube_directions("faces+edges+corners"), hold=3.0), gravity=G, seed=7)
    iv = detect_static(sim.t, sim.raw)
    return sim, iv


@pytest.mark.parametrize("mode", ["means", "samples"])
def test_an_effect_held_at_zero_changes_nothing(data, mode):
    sim, iv = data
    guess = ellipsoid_guess(iv.mean, G)
    base = base_parameters(guess.s, guess.b, guess.angles, gravity=G)
    if mode == "means":
        raw, var, grp, t = iv.mean, iv.mean_std**2, np.arange(iv.n), iv.t_mid
    else:
        rows = np.flatnonzero(iv.sample_mask(sim.t.size))
        grp = iv.sample_index()
        raw, var, t = sim.raw[rows], iv.std[grp] ** 2, sim.t[rows]
    plain = fit(FitData(raw, np.zeros((len(raw), 0)), var, grp, mode), base, build_model(), G)
    # The same objective through the CasADi map NLP: an effect whose coefficients are held at 0.
    eff = make_effect("bias_drift", (0, 1, 2))
    model = build_model([eff])
    params = model.parameters(base)
    params = params.with_fixed([n for n in params.names if n not in base.names], values={
        n: 0.0 for n in params.names if n not in base.names})
    mapped = fit(FitData(raw, t[:, None], var, grp, mode), params, model, G)
    assert plain.success and mapped.success
    for n in base.names:
        assert mapped.params[n].value == pytest.approx(plain.params[n].value, abs=1e-4 * plain.std[n]), n
        assert mapped.std[n] == pytest.approx(plain.std[n], rel=1e-4), n
    assert mapped.chi2 == pytest.approx(plain.chi2, rel=1e-8)


@pytest.mark.parametrize("mode", ["means", "samples"])
def test_gauss_newton_and_exact_hessian_reach_the_same_optimum(data, mode):
    sim, iv = data
    guess = ellipsoid_guess(iv.mean, G)
    base = base_parameters(guess.s, guess.b, guess.angles, gravity=G)
    model = build_model([make_effect("scale_nonlinearity", (0, 1, 2))])
    params = model.parameters(base)
    if mode == "means":
        d = FitData(iv.mean, np.zeros((iv.n, 0)), iv.mean_std**2, np.arange(iv.n), mode)
    else:
        rows = np.flatnonzero(iv.sample_mask(sim.t.size))
        grp = iv.sample_index()
        d = FitData(sim.raw[rows], np.zeros((rows.size, 0)), iv.std[grp] ** 2, grp, mode)
    gn = fit(d, params, model, G)
    ex = fit(d, params, model, G, hessian="exact")
    assert gn.success and ex.success
    for n in params.free_names:
        assert ex.params[n].value == pytest.approx(gn.params[n].value, abs=1e-3 * gn.std[n]), n
    assert ex.chi2 == pytest.approx(gn.chi2, rel=1e-7)


@pytest.mark.parametrize("dof, t", [(3, 3.1824), (5, 2.5706), (10, 2.2281), (29, 2.0452), (1000, 1.9623)])
def test_student_t_quantile_in_report(dof, t):
    from imucal.report.text import t_quantile_975

    assert t_quantile_975(dof) == pytest.approx(t, rel=0.01)


def test_a_small_initial_barrier_reaches_the_default_optimum_in_fewer_iterations(monkeypatch):
    """ipopt.LEAST_SQUARES starts IPOPT's barrier near zero: on the auto-weighted Xsens fit (a first
    pass, then one with the weights refreshed at its solution) every pass lands where IPOPT's default
    start (mu_init 0.1) does, in fewer iterations."""
    import imucal
    from conftest import real_file
    from imucal.solve import ipopt
    from imucal.solve import least_squares as lsq

    xs = np.loadtxt(real_file("xsens-mti-imutk", "xsens_acc.mat"))
    solve, iters, runs = lsq.solve, {}, {}

    def counted(key):
        def run(problem, lb, ub):
            x, stats = solve(problem, lb, ub)
            iters[key].append(int(stats["iter_count"]))
            return x, stats
        return run

    for key, options in (("default", ipopt.OPTIONS), ("small", ipopt.LEAST_SQUARES)):
        iters[key] = []
        monkeypatch.setattr(ipopt, "LEAST_SQUARES", options)
        monkeypatch.setattr(lsq, "solve", counted(key))
        lsq._solver.cache_clear()  # built with the options in force
        runs[key] = imucal.calibrate(xs[:, 1:], t=xs[:, 0], gravity=9.81744).result
    lsq._solver.cache_clear()
    s, d = runs["small"], runs["default"]
    assert len(iters["small"]) == len(iters["default"]) >= 2  # the same passes
    assert sum(iters["small"]) < sum(iters["default"])
    assert s.success and d.success
    for n in d.free_names:
        assert s.params[n].value == pytest.approx(d.params[n].value, abs=1e-5 * d.std[n]), n
        assert s.std[n] == pytest.approx(d.std[n], rel=1e-5), n
