"""Stochastic biases (issue 12): bias_random_walk vs bias_instability by REML, GLS weights, the Allan view.

Interval means are made here with a known truth (a bias random walk of density q, or one offset per
visit, per axis, in counts), so the tests are fast; one discovery runs on a simulated recording."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from imucal.analysis.simulate import PosePlan, cube_directions, si_sensor, simulate, simulation_from_dict
from imucal.errors import ImucalError
from imucal.model.geometry import frame_np
from imucal.model.parameters import base_parameters
from imucal.model.sensor import build_model
from imucal.solve import least_squares as lsq
from imucal.solve import stochastic
from imucal.solve.fit import FitData, fit

G = 9.80665
ANGLES = np.array([1.5608, 1.5808, 1.5758])
S, B = np.array([30.0, -12.0, 8.0]), np.array([1670.0, 1660.0, 1675.0])  # counts, counts per m/s^2
SIG = 0.3  # noise of one mean [counts]


def _means(seed: int, q: float = 0.0, tau: float = 0.0, visits: int = 2, with_bias: bool = False):
    """Means of the 18 faces and edges visited ``visits`` times in shuffled order, one every 5 s:
    noise SIG per mean, a random walk of q [m/s^2/sqrt(s)] and an offset of tau [m/s^2] per visit
    (``with_bias``: also that bias of each mean [counts])."""
    rng = np.random.default_rng(seed)
    d = cube_directions("faces+edges")
    u = np.vstack([d[rng.permutation(len(d))] for _ in range(visits)])
    t = 2.5 + 5.0 * np.arange(len(u))
    walk = np.cumsum(rng.normal(0, 1, u.shape) * np.sqrt(np.diff(t, prepend=0.0))[:, None], axis=0) * q
    bias = (walk + rng.normal(0, 1, u.shape) * tau) * B  # [counts]
    raw = S + B * (G * u @ frame_np(ANGLES)) + bias + rng.normal(0, SIG, u.shape)  # Eq. theModel
    data = FitData(raw, np.zeros((len(u), 0)), np.full(u.shape, SIG**2), np.arange(len(u)), "means", t=t)
    return (data, bias) if with_bias else data


def _fit(data: FitData, weights: str):
    p = base_parameters(S * 1.01, B * 0.99, np.full(3, np.pi / 2), gravity=G)
    return fit(data, p, build_model(), G, weights=weights)


def _test(data: FitData) -> stochastic.StochasticFit:
    """The REML test at the noise-weighted fit of ``data``."""
    res = _fit(data, "noise")
    fns, rows = lsq.row_functions(build_model(), res.free_names), lsq.Rows(data.raw, data.cov)
    pv = np.array(res.params.values(), float)
    b = np.array([res.params[f"b{i}"].value for i in (1, 2, 3)])
    return stochastic.select(stochastic.components_at(fns, rows, pv, pv, G, res.sigma, b, data.t))


Q = 1.5e-4  # m/s^2/sqrt(s): the walk moves ~10 noise sigmas of a mean over the 180 s
TAU = 8e-4  # m/s^2 per visit: ~4.5 noise sigmas


def test_a_random_walk_is_named_with_its_density():
    named, z = [], []
    for seed in range(8):
        s = _test(_means(seed, q=Q))
        named.append(s.named)
        if s.named == (stochastic.RANDOM_WALK,):
            z.append((s.q - Q) / s.q_std)
    assert named.count((stochastic.RANDOM_WALK,)) >= 7, named
    assert np.all(np.abs(z) < 3), z  # q within 3 standard errors of the truth
    assert s.values()[stochastic.RANDOM_WALK][2] == "m/s^2/sqrt(s)"


def test_per_visit_offsets_are_bias_instability_not_a_random_walk():
    named = [_test(_means(seed, tau=TAU)).named for seed in range(8)]
    assert named.count((stochastic.INSTABILITY,)) >= 7, named
    assert not any(stochastic.RANDOM_WALK in n for n in named), named


@pytest.mark.parametrize("n_sets", [pytest.param(50, marks=pytest.mark.study), 5])
def test_no_false_alarm_on_clean_sets(n_sets):
    """The test at level 1e-3 run unconditionally (the fit and discovery run it only when the
    chi-square test fails): nothing named on clean sets (50 in the study, 5 in the product's tests)."""
    named = [_test(_means(seed)).named for seed in range(100, 100 + n_sets)]
    assert all(n == () for n in named), [n for n in named if n]


def test_a_jump_is_not_passed_off_as_a_random_walk():
    data = _means(7)
    raw = data.raw.copy()
    raw[len(raw) // 2:, 1] += 40 * SIG  # a step in the bias of y halfway
    s = _test(dataclasses.replace(data, raw=raw))
    assert s.named == () and "jump" in s.notes[0]


def test_a_step_the_walk_absorbs_is_not_passed_off_as_a_random_walk():
    """A step of 20 noise sigmas of a mean in the bias of y: the walk's own q absorbs so much of it
    that its largest innovation passes the outlier test in half of these seeds; one step on top of
    the walk's covariance (stochastic.step_test) does not pass, and is placed where it happened when
    the poses on both sides see y."""
    named, at = [], []
    for seed in range(10):
        data = _means(seed)
        raw, k = data.raw.copy(), len(data.raw) // 2 + seed % 5
        raw[k:, 1] += 20 * SIG
        s = _test(dataclasses.replace(data, raw=raw))
        named.append(s.named)
        if np.isfinite(s.step_at):
            assert s.withheld == (stochastic.RANDOM_WALK,) and "single step" in s.notes[-1]
            at.append(abs(s.step_at - 0.5 * (data.t[k - 1] + data.t[k])))
    assert named == [()] * 10, named
    assert len(at) >= 5 and np.median(at) == 0.0, at


def test_auto_weights_use_the_random_walk_covariance_and_honest_errors():
    """The offsets are the bias averaged over the intervals (issue 25): their truth is S plus the walk's mean."""
    z_auto, z_noise = [], []
    for seed in range(10):
        data, bias = _means(seed, q=Q, with_bias=True)
        s = S + bias.mean(axis=0)
        truth = {"s1": s[0], "s2": s[1], "s3": s[2], "b1": B[0], "b2": B[1], "b3": B[2],
                 "phi": ANGLES[0], "psi": ANGLES[1], "theta": ANGLES[2]}
        a, n = _fit(data, "auto"), _fit(data, "noise")
        assert a.success and a.random_walk > 0 and a.stochastic is not None
        assert a.redchi == pytest.approx(1.0, abs=0.5)  # the excess in the weights: chi-square about its dof
        z_auto += [(a.params[k].value - v) / a.std[k] for k, v in truth.items()]
        z_noise += [(n.params[k].value - v) / n.std[k] for k, v in truth.items()]
    assert 0.6 < np.std(z_auto) < 1.5, np.std(z_auto)  # errors that cover the truth
    assert abs(np.std(z_noise) - 1) > abs(np.std(z_auto) - 1)  # chi2/dof-scaled errors do not describe a walk


def test_without_excess_auto_has_no_stochastic_bias():
    data = _means(3)
    a, u = _fit(data, "auto"), _fit(data, "uniform")
    assert a.random_walk == 0.0 and a.excess == 0.0 and a.bias_drift is None and a.values() == u.values()


def test_simulator_random_walk_and_visit_offsets(tmp_path):
    rng = np.random.default_rng(0)
    sens = si_sensor(rng, noise=0.0)
    plan = PosePlan(cube_directions("faces"), hold=3.0, transition=1.0)
    base = simulate(sens, plan, seed=1)
    rw = simulate(dataclasses.replace(sens, random_walk=(1e-3, 0.0, 0.0)), plan, seed=1)
    vo = simulate(dataclasses.replace(sens, visit_offset=(0.0, 0.0, 1e-2)), plan, seed=1)
    d_rw, d_vo = rw.raw - base.raw, vo.raw - base.raw
    assert np.all(d_rw[:, 1:] == 0) and np.std(np.diff(d_rw[:, 0])) == pytest.approx(1e-3 * 0.1, rel=0.1)
    a, b = vo.hold_bounds[2]
    assert np.ptp(d_vo[a:b, 2]) == 0 and np.all(d_vo[:, :2] == 0)  # one offset per hold, on z only
    with pytest.raises(ImucalError, match="sensor.random_walk"):
        simulation_from_dict({"sensor": {"random_walk": [-1, 0, 0]}})


def test_discover_names_the_random_walk_with_the_allan_view(tmp_path):
    from imucal.analysis.discover import discover
    from imucal.config.run import config_from_dict
    from imucal.report.discover_figures import allan_figure
    from test_figure_units import axis_problems
    from matplotlib.figure import Figure

    # 36 holds (faces and edges twice) after 110 s still, q = 2e-4 m/s^2/sqrt(s). Measured on seeds 0-6:
    # 6 of 7 name only the walk; on seed 0 a drift on z beats the walk's likelihood and is kept.
    rng = np.random.default_rng(1)
    q = 2e-4
    sens = dataclasses.replace(si_sensor(rng, noise=0.003), random_walk=(q,) * 3)
    d = cube_directions("faces+edges")
    dirs = np.vstack([d[rng.permutation(18)], d[rng.permutation(18)]])
    sim = simulate(sens, PosePlan(dirs, hold=3.0, transition=2.0, initial_hold=110.0), seed=1)
    (tmp_path / "rw.csv").write_text(sim.to_csv_text())
    disc = discover(config_from_dict({"data": {"path": str(tmp_path / "rw.csv"), "unit": "m/s^2"}}, None))
    assert disc.effects == ()  # the trends the walk makes are not named as drifts
    assert disc.stochastic.named == (stochastic.RANDOM_WALK,)
    assert abs(disc.stochastic.q - q) < 3 * disc.stochastic.q_std
    from imucal.report.discover_text import discovery_json, verdict_text

    assert "bias_random_walk" in verdict_text(disc.verdict) and "m/s^2/sqrt(s)" in verdict_text(disc.verdict)
    js = discovery_json(disc)
    assert js["stochastic"]["values"]["bias_random_walk"]["unit"] == "m/s^2/sqrt(s)"
    assert js["allan"]["duration_s"] > 100 and len(js["allan"]["line_adev"]) == len(js["allan"]["tau_s"])
    # the curve's own +1/2 slope (one 110 s segment: 14-47 % errors here) agrees with the REML density
    # within 3 combined standard errors on every axis
    s = disc.stochastic
    assert all(abs(v - s.q) < 3 * np.hypot(v * e, s.q_std) for v, e in zip(disc.allan.q_allan, disc.allan.q_allan_rel_err))
    saved = []
    orig = Figure.savefig
    Figure.savefig = lambda self, *a, **k: (saved.append(self), orig(self, *a, **k))[1]
    try:
        allan_figure(disc, tmp_path / "allan.png")
    finally:
        Figure.savefig = orig
    assert saved and axis_problems(saved[0]) == []


def test_the_reml_test_is_skipped_above_its_size_limit(monkeypatch):
    """Dense n x n covariances: above MAX_INTERVALS the auto weights fall back to Paule-Mandel (a
    tiled 5 M-sample log has thousands of intervals and took minutes before this limit)."""
    data = _means(1, q=Q)
    assert _fit(data, "auto").random_walk > 0  # within the limit: the walk is named and weighted
    monkeypatch.setattr(stochastic, "MAX_INTERVALS", len(data.raw) - 1)
    assert not stochastic.feasible(len(data.raw))
    monkeypatch.setattr(stochastic, "select", lambda *a, **k: pytest.fail("the REML test ran above its limit"))
    res = _fit(data, "auto")
    assert res.random_walk == 0.0 and res.excess > 0  # Paule-Mandel's per-visit excess instead


@pytest.mark.parametrize("ml", [False, True])
def test_the_grid_likelihood_is_the_likelihood(ml):
    """reml_grid (one eigendecomposition per tau^2) equals reml() at every grid point, with unequal
    noise, for REML and ML: it is the same likelihood, not an approximation."""
    rng = np.random.default_rng(7)
    n = 40
    t = np.sort(rng.uniform(0, 400, n))
    c = stochastic.components(rng.normal(0, 1e-3, n), 3e-4 * rng.uniform(0.5, 2.0, n), rng.normal(size=(n, 9)),
                              rng.normal(size=(n, 3)), t)
    grid = np.array([(a, b) for a in [0.0, *(1e-7 * 10.0**stochastic._GRID)] for b in [0.0, 1e-9, 1e-7, 1e-5]])
    want = np.array([stochastic.reml(c, a, b, ml=ml)[0] for a, b in grid])
    got = stochastic.reml_grid(c, grid, ml=ml)
    assert np.allclose(got, want, rtol=0, atol=1e-9 * np.max(np.abs(want)))
    assert np.argmax(got) == np.argmax(want)
    alone = grid[:, 1] == 0  # bias_instability's grid: q^2 = 0 throughout, no basis change
    assert np.allclose(stochastic.reml_grid(c, grid[alone], ml=ml), want[alone], rtol=0,
                       atol=1e-9 * np.max(np.abs(want)))


def test_a_drift_the_walk_beats_leaves_a_calibration_without_it(tmp_path):
    """bias_temperature on x and a random walk: the search finds a drift too, which the walk then
    explains (imucal.analysis.discover.stochastic.beaten drops it). The final calibration started from every free parameter of
    the search, the dropped drift's included, and refused it: `fit.initial.bias_drift_x is not a free
    parameter` ended the run (seed 4 of an outside review)."""
    from imucal.analysis.discover import discover
    from imucal.analysis.simulate import TemperatureProfile
    from imucal.config.run import config_from_dict

    rng = np.random.default_rng(4)
    sens = dataclasses.replace(si_sensor(rng, noise=0.003), random_walk=(2e-4,) * 3, effects={
        "bias_temperature": {"bias_temperature_x": 0.002, "bias_temperature_y": 0.0, "bias_temperature_z": 0.0}})
    d = cube_directions("faces+edges")
    dirs = np.vstack([d[rng.permutation(18)], d[rng.permutation(18)]])
    sim = simulate(sens, PosePlan(dirs, hold=3.0, transition=2.0, initial_hold=110.0), seed=4,
                   temperature=TemperatureProfile())
    (tmp_path / "tw.csv").write_text(sim.to_csv_text())
    disc = discover(config_from_dict({"data": {"path": str(tmp_path / "tw.csv"), "unit": "m/s^2"}}, None))
    assert [(e.name, e.axes) for e in disc.effects] == [("bias_temperature", (0,))], disc.verdict
    assert disc.stochastic.named and disc.calibration_run.calibration.fit["weights"] == "auto"
