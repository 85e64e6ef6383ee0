"""A bias step while the sensor is still (issue 28's step at an unknown time): the detector cuts a still
interval at given times (static.split, a bias_step term's time), and discover finds a step inside a hold
by the samples' two-mean scan against a line and the long-run noise (imucal.analysis.hold_steps),
without cutting intervals of white, correlated or drifting noise."""
from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from imucal.analysis.discover import DiscoverSettings, Outcome, discover
from imucal.analysis.hold_steps import hold_steps, sup_bridge_sf
from imucal.analysis.simulate import draw_effect_case
from imucal.report.discover_text import discovery_json
from imucal.config.run import config_from_dict
from imucal.data.static import _BATCHES, Intervals, StaticSettings
from imucal.data.stream import StreamedRecording
from imucal.errors import ImucalError
from imucal.pipeline import read_intervals

XSENS = "data/xsens-mti-imutk/xsens_acc.mat"


def _straddles(iv: Intervals, t: float) -> bool:
    return bool(np.any((iv.t_start < t) & (iv.t_end >= t)))


def test_static_split_cuts_an_interval_whole_and_streamed_alike():
    base = read_intervals(config_from_dict({"data": {"path": XSENS}}))[1]
    assert _straddles(base, 62.0) and _straddles(base, 30.0)
    cfg = config_from_dict({"data": {"path": XSENS}, "static": {"split": [30.0, 62.0, 62.001]}})
    iv = read_intervals(cfg)[1]
    assert iv.n == base.n + 2 and not _straddles(iv, 62.0) and not _straddles(iv, 30.0)
    streamed = StreamedRecording(cfg.data, cfg.static, cfg.base_dir).intervals
    assert np.array_equal(streamed.start, iv.start) and np.array_equal(streamed.mean, iv.mean)


def test_a_step_terms_time_cuts_the_interval_it_falls_in():
    """A calibration with a bias step at a time inside a hold: the hold's two sides hold two biases."""
    cfg = config_from_dict({"data": {"path": XSENS}, "fit": {"effects": [{"name": "bias_step", "axes": ["x"]}],
                                                            "initial": {"bias_step_t": 62.0}}})
    assert not _straddles(read_intervals(cfg)[1], 62.0)


@pytest.mark.parametrize("split", [["a"], "1.0", [float("nan")], [True]])
def test_a_split_that_is_not_a_list_of_times_is_refused(split):
    with pytest.raises(ImucalError) as exc:
        config_from_dict({"data": {"path": XSENS}, "static": {"split": split}})
    assert "static.split" in str(exc.value)
    with pytest.raises(ImucalError):
        StaticSettings(split=(1.0, float("inf")))


def test_the_scans_null_tail_is_not_exceeded_on_white_noise():
    """Siegmund's approximation of the sup of the two-mean chi-square over the cuts, for the step judged at
    the best cut beside a line with the long-run variance: on 3000 white holds the share past the 1 % and
    the 0.1 % points stays near or below them."""
    from imucal.analysis.hold_steps import HOLD_SIDE, _judge

    rng = np.random.default_rng(5)
    _, chi2, _ = _judge(rng.normal(size=(3000, 240, 3)), np.tile(np.arange(240) / 100.0, (3000, 1)), 0.0, 1.0)
    p = np.array([sup_bridge_sf(float(c), 3, HOLD_SIDE) for c in chi2])
    assert np.mean(p < 0.01) < 0.015 and np.mean(p < 0.001) < 0.002


def _intervals(x: np.ndarray, n_iv: int, rate: float = 100.0) -> tuple[np.ndarray, Intervals]:
    """``n_iv`` consecutive intervals of len(x) // n_iv samples each, with the detector's pooled
    correlated-noise factor (imucal.data.static.intervals_from: the median batch-means ratio)."""
    m = x.shape[0] // n_iv
    start = np.arange(n_iv) * m
    t = np.arange(x.shape[0]) / rate
    z = np.zeros((n_iv, 3))
    nb = m // _BATCHES
    holds = x[:n_iv * m].reshape(n_iv, m, 3)
    means = holds[:, :nb * _BATCHES].reshape(n_iv, _BATCHES, nb, 3).mean(axis=2)
    ratios = means.var(axis=1, ddof=1) / (holds.var(axis=1, ddof=1) / nb)
    iv = Intervals(start=start, end=start + m, t_start=t[start], t_end=t[start + m - 1], mean=z, std=z + 1,
                   mean_std=z + 0.1, t_mid=t[start + m // 2], temp=None, threshold=1.0,
                   noise_inflation=max(1.0, float(np.median(ratios))))
    return t, iv


@pytest.mark.parametrize("kind", ["white", "correlated", "drift", "walk"])
def test_no_interval_of_noise_or_drift_is_cut(kind):
    rng = np.random.default_rng(11)
    n_iv, m = 100, 400
    e = rng.normal(size=(n_iv * m, 3))
    if kind == "correlated":  # AR(1), 0.9: a filtered sensor
        for k in range(1, e.shape[0]):
            e[k] = 0.9 * e[k - 1] + e[k]
    elif kind == "drift":  # a line through every hold, 3 noise sigmas over it
        e += np.tile(np.linspace(0, 3, m), n_iv)[:, None]
    elif kind == "walk":  # a bias random walk as large as the noise over a hold
        e += np.cumsum(rng.normal(size=e.shape), axis=0) / np.sqrt(m)
    t, iv = _intervals(e, n_iv)
    assert hold_steps(t, e, iv, 0.0, span=10**9) == []


def test_a_step_inside_a_hold_is_found_where_it_is():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(20 * 300, 3))
    x[5 * 300 + 190:6 * 300, 1] += 1.5  # 1.5 noise sigmas on y, 190 samples into interval 5
    t, iv = _intervals(x, 20)
    (s,) = hold_steps(t, x, iv, 0.0, span=10**9)
    assert s.interval == 5 and abs(s.time - t[5 * 300 + 190]) <= 0.03 and s.p < 1e-3
    assert abs(s.shift[1] - 1.5) < 0.4 and abs(s.shift[0]) < 0.4


def test_discover_names_a_step_that_happened_while_the_sensor_was_still(tmp_path):
    """Before the scan, a step in the middle of a hold left that interval's mean between the two biases:
    this case was called stochastic with no term; now the hold is cut and the step named on its axes."""
    case = draw_effect_case(70004, effect="bias_step", snr=30.0, noise_mg=0.3)
    plan, eff = case.config.plan, dict(case.config.sensor.effects["bias_step"])
    cycle = plan.hold + plan.transition
    k = round((eff["bias_step_t"] + 0.5 * plan.transition) / cycle)
    eff["bias_step_t"] = k * cycle + plan.hold / 2  # the middle of the hold after the move it was in
    cfg = dataclasses.replace(case.config, sensor=dataclasses.replace(case.config.sensor, effects={"bias_step": eff}))
    path = tmp_path / "c.csv"
    path.write_text(cfg.run().to_csv_text())
    d = discover(config_from_dict({"data": {"path": str(path), "unit": cfg.sensor.unit}}), DiscoverSettings())
    assert [e.label for e in d.effects] == [case.label] and d.verdict.outcome is Outcome.EXPLAINED
    assert any("moved within it" in n and "static.split" in n for n in d.notes)
    (e,) = d.effects
    assert e.change_point.lower <= eff["bias_step_t"] <= e.change_point.upper
    (cut,) = discovery_json(d)["holds_cut"]  # the cut, typed: where, how large, what it looks like
    assert cut["t_start_s"] < eff["bias_step_t"] < cut["t_end_s"] and abs(cut["time_s"] - eff["bias_step_t"]) < 0.1
    assert cut["kind"] in ("bias_step", "turn_or_bias_step") and cut["p"] < 1e-3


def test_calibrate_warns_of_a_turn_the_detector_did_not_see(tmp_path, run_cli):
    """A hold whose second half is tilted by half a degree, three noise sigmas of a sample, which the moving
    variance does not see: calibrate names a turn (|a| kept), where, and the static.split that cuts it; the
    clean recording has no such warning."""
    from imucal.analysis.simulate import PosePlan, cube_directions, si_sensor, simulate

    rng = np.random.default_rng(4)
    dirs = cube_directions("faces+edges")
    sens = si_sensor(rng, noise=0.03)
    sim = simulate(sens, PosePlan(dirs, hold=6.0, transition=2.0), seed=2)
    clean = tmp_path / "clean.csv"
    clean.write_text(sim.to_csv_text())
    code, _, err = run_cli(["calibrate", "--data", clean, "--unit", "m/s^2", "--out", tmp_path / "a", "--no-figures"])
    assert code == 0 and "moved within it" not in err
    a, b = sim.hold_bounds[5]
    mid = (a + b) // 2
    g = np.linalg.norm(sim.raw[a:b].mean(axis=0))
    u = sim.raw[a:b].mean(axis=0) / g
    across = np.cross(u, [0.0, 0.0, 1.0] if abs(u[2]) < 0.9 else [1.0, 0.0, 0.0])
    sim.raw[mid:b] += g * np.radians(0.5) * across / np.linalg.norm(across)  # half a degree across gravity
    tilted = tmp_path / "tilted.csv"
    tilted.write_text(sim.to_csv_text())
    code, _, err = run_cli(["calibrate", "--data", tilted, "--unit", "m/s^2", "--out", tmp_path / "b", "--no-figures"])
    assert code == 0
    (line,) = [x for x in err.splitlines() if "moved within it" in x]
    turn, at = re.search(r"a turn of ([\d.]+) deg the detector did not see .* static\.split: \[([\d.]+)\]", line).groups()
    assert abs(float(turn) - 0.5) < 0.1 and abs(float(at) - sim.t[mid]) < 0.1


def test_block_means_match_the_samples_up_to_the_recordings_last_one():
    from imucal.analysis.hold_steps import _block_means

    rng = np.random.default_rng(2)
    x = rng.normal(size=(1000, 3))
    t, iv = _intervals(x, 4)  # 250 samples each; the last ends at the recording's last sample
    out = _block_means(x, iv, {0: 7, 3: 9})
    for i, size in ((0, 7), (3, 9)):
        m = 250 // size
        a = int(iv.start[i])
        assert np.allclose(out[i][0], x[a:a + m * size].reshape(m, size, 3).mean(axis=1))
        assert np.array_equal(out[i][1], a + size * np.arange(m))
