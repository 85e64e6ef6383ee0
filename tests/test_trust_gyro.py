"""Issue 25, the gyroscope's trust cases: a static interval that is still for the accelerometer but
turns for the gyro (a slow turn about the vertical) no longer pulls the gyro bias, and is reported;
a gyro fit whose residuals exceed its noise warns by the accelerometer's rule.

Every recording is simulated here (imucal.gyro.simulate) with known truth."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import yaml

from conftest import real_file

from imucal.errors import ImucalError
from imucal.gyro.check import still_check
from imucal.gyro.fit import GyroOptions, cross_validate, fit_gyro
from imucal.gyro.result import arrays, excess, motions
from imucal.gyro.segments import GyroData
from imucal.gyro.simulate import GyroTruth, hand_held
from imucal.gyro.still import MIN_INTERVALS, StillTest, _half_means, judge

TRUTH = GyroTruth(bias=np.array([0.01, -0.02, 0.005]), scale=np.array([1.01, 0.99, 1.005]),
                  mis=np.array([1e-3, -2e-3, 3e-3, 0.0, 1e-3, -1e-3]), gsens=np.zeros((3, 3)), noise=0.003)
#: [deg/s] the slow turn about the vertical inside one still pose (a turntable left running, a hand)
TURN = 1.0
POSE = 6


def session(seed: int = 3, turn: float = TURN, truth: GyroTruth = TRUTH, n_poses: int = 20) -> GyroData:
    """A hand-held session in rad/s; still pose POSE turns about the vertical at ``turn`` deg/s."""
    return hand_held(truth, n_poses=n_poses, seed=seed, unit="rad/s", still=(3.0, 4.0),
                     still_turns={POSE: np.radians(turn)} if turn else None)


# --- case 1: the bias from poses that are not still for the gyro ---------------------------------
def test_a_slow_turn_about_the_vertical_pulled_the_bias_and_no_longer_does():
    d = session()
    before_fit = fit_gyro(d, GyroOptions(still="off"))  # every static interval taken as still: the old behaviour
    after_fit = fit_gyro(d)
    before, after = arrays(before_fit), arrays(after_fit)
    turn = np.radians(TURN) / d.n_intervals  # the pull of one interval's turn rate on a mean of n [rad/s]
    assert np.linalg.norm(before.bias - TRUTH.bias) > 0.7 * turn  # pulled ...
    assert np.linalg.norm(before.bias - TRUTH.bias) > 5 * np.linalg.norm(after.bias_std)
    assert np.all(np.abs(after.bias - TRUTH.bias) < 4 * after.bias_std)  # ... and no longer
    still = motions(after_fit).still
    (r,) = still.rejected
    assert r.interval == POSE and r.test is StillTest.MEAN and r.p_value < still.threshold_p
    assert (r.t_start, r.t_end) == (d.t[d.start[POSE]], d.t[d.end[POSE] - 1])
    rate = np.array(r.rate_deg_s)
    assert np.linalg.norm(rate) == pytest.approx(TURN, rel=0.03)  # the turn rate, in deg/s
    up = d.acc[d.start[POSE]:d.end[POSE]].mean(0)  # about the vertical: along the specific force at rest
    assert np.degrees(np.arccos(abs(rate @ up) / np.linalg.norm(rate) / np.linalg.norm(up))) < 3.0
    # no still pose: the motions on both sides of it are one, the other poses all kept
    assert motions(after_fit).segments.size == d.n_intervals - 2
    assert motions(before_fit).segments.size == d.n_intervals - 1
    assert still.keep.sum() == d.n_intervals - 1 and not still.keep[POSE]


def test_the_default_is_no_worse_than_the_fit_without_the_rejected_interval():
    """imucal.gyro.check: the three fits scored on the same motions (between the poses kept)."""
    c = still_check(session())
    assert [r.interval for r in c.rejected] == [POSE] and c.n_segments == c.n_intervals - 2
    assert c.no_worse and c.default_deg == pytest.approx(c.removed_deg, rel=1e-12)
    assert c.all_still_deg > 1.2 * c.default_deg  # taking the turning pose as still costs direction error


def test_drift_inside_an_interval_is_rejected_by_the_drift_test():
    """A rate that ramps within an interval with a zero mean (a turn one way, then back) pulls no
    bias but is no still pose: the drift test (second half against first) finds it."""
    d = session(turn=0.0)
    g = d.gyro.copy()
    i0, i1 = d.start[POSE], d.end[POSE]
    g[i0:i1] += np.linspace(-1, 1, i1 - i0)[:, None] * np.radians([0.3, 0.2, -0.2])  # zero mean
    assert judge(d).rejected == ()
    s = judge(replace(d, gyro=g))
    (r,) = s.rejected
    assert r.interval == POSE and r.test is StillTest.DRIFT
    ramp = np.degrees(np.array(r.drift) - _half_means(d)[0][POSE])  # the half-means of a ramp differ by its amplitude
    np.testing.assert_allclose(ramp, [0.3, 0.2, -0.2], rtol=0.01)


@pytest.mark.parametrize("seed", range(4))
def test_still_sessions_lose_no_interval(seed):
    """Nothing is rejected where every pose is still: plain, with a g-sensitivity, and with a bias
    that moves between poses by 10x an interval mean's standard error (over-dispersed, as real gyros)."""
    G = np.array([[2e-4, -1e-4, 3e-4], [0.0, 1e-4, -2e-4], [1e-4, 0.0, 2e-4]])  # [(rad/s)/(m/s^2)]
    plain = session(seed, turn=0.0)
    rng = np.random.default_rng(seed)
    g, se = plain.gyro.copy(), TRUTH.noise / np.sqrt(300)
    for a, b in zip(plain.start, np.r_[plain.start[1:], len(g)]):
        g[a:b] += 10 * se * rng.normal(size=3)  # a new bias from each pose on
    for d in (plain, session(seed, turn=0.0, truth=replace(TRUTH, gsens=G)), replace(plain, gyro=g)):
        s = judge(d)
        assert s.tested and s.rejected == () and s.keep.all()


def test_too_few_intervals_are_taken_as_they_are():
    from imucal.report.gyro import still_lines

    d = hand_held(TRUTH, n_poses=MIN_INTERVALS - 1, seed=3, unit="rad/s", still_turns={2: np.radians(TURN)})
    s = judge(d)  # not even the turning pose: there is no spread between intervals to judge it against
    assert not s.tested and s.rejected == () and s.keep.all()
    assert f"too few (< {MIN_INTERVALS}) to judge them on the gyro" in still_lines(s)[0]


def test_cross_validation_folds_the_motions_between_the_still_poses():
    d = session()
    out = cross_validate(d, GyroOptions(lead_in_s=0.0))
    assert out.size == d.n_intervals - 2 and np.all(np.isfinite(out))


def test_a_bad_still_option_names_the_field_and_the_fix():
    with pytest.raises(ImucalError) as e:
        GyroOptions(still="maybe")
    assert str(e.value) == "gyro.still: still 'maybe' is not auto or off (fix: use auto (judge stillness on the gyro too) or off)"


def _csv(d: GyroData, path) -> None:
    np.savetxt(path, np.column_stack([d.t, d.acc, d.gyro]), delimiter=",", header="t,ax,ay,az,gx,gy,gz",
               comments="", fmt="%.10g")


def test_the_report_json_and_calibration_file_name_the_rejected_interval(run_cli, tmp_path):
    from imucal.calibration.frozen import load_calibration

    d = session()
    _csv(d, tmp_path / "rec.csv")
    r = run_cli(["calibrate", "--data", tmp_path / "rec.csv", "--unit", "m/s^2", "--gyro-unit", "rad/s",
                 "--gravity", "9.81", "--out", tmp_path / "o", "--no-figures", "--json", tmp_path / "s.json"])
    assert r.code == 0, r.err
    (ns,) = json.loads((tmp_path / "s.json").read_text())["gyro"]["not_still"]
    assert ns["test"] == "mean rate" and np.linalg.norm(ns["rate_deg_s"]) == pytest.approx(TURN, rel=0.05)
    lo, hi = d.t[d.start[POSE]], d.t[d.end[POSE] - 1]  # the pose as simulated; the detector's edges lie inside
    assert lo <= ns["t_start"] < ns["t_end"] <= hi
    line = (f"interval {ns['interval']} ({ns['t_start']:.2f}..{ns['t_end']:.2f} s): mean rate "
            + " ".join(f"{x:+.3g}" for x in ns["rate_deg_s"]) + " deg/s")
    assert line in r.out and line in (tmp_path / "o" / "report.txt").read_text()
    assert "the gyro shows 1 turning" in r.out
    f = yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())
    assert f["gyroscope"]["fit"]["not_still"] == [ns]
    cal = load_calibration(tmp_path / "o" / "calibration.yaml")  # reads back, and saves the same bytes
    cal.save(tmp_path / "again.yaml")
    assert (tmp_path / "again.yaml").read_bytes() == (tmp_path / "o" / "calibration.yaml").read_bytes()


@pytest.mark.parametrize("name, turning", [("imu2", True), ("xsens", False)])
def test_real_recordings_default_no_worse_than_without_the_rejected(name, turning):
    """MPU-9150 imu2 (mikoff): poses where the sensor turns while the accelerometer is still; Xsens: none."""
    from imucal.config.run import config_from_dict
    from imucal.gyro.check import run_still_check
    from imucal.pipeline import calibrate_accelerometer

    if name == "xsens":
        data = {"path": str(real_file("xsens-mti-imutk", "xsens_acc.mat")), "unit": "raw",
                "gyro_path": str(real_file("xsens-mti-imutk", "xsens_gyro.mat"))}
    else:
        data = {"path": str(real_file("mpu9150-mikoff", "imu2.log")), "unit": "m/s^2", "gyro_unit": "rad/s",
                "sample_rate": 100, "columns": {"ax": 0, "ay": 1, "az": 2, "gx": 3, "gy": 4, "gz": 5}}
    c = run_still_check(calibrate_accelerometer(config_from_dict({"data": data, "gravity": {"value": 9.81744}})))
    assert c.no_worse and bool(c.rejected) == turning
    if turning:  # taking them as still poses costs direction error on the motions between the still ones
        assert c.all_still_deg > 1.5 * c.default_deg


# --- case 2: a gyro fit whose residuals exceed its noise warns ------------------------------------
def _unmodelled(d: GyroData, size: float = np.radians(0.3)) -> GyroData:
    """The gyro's bias jumps during each motion and is back at rest (an effect no model here holds)."""
    g = d.gyro.copy()
    rng = np.random.default_rng(0)
    for a, b in zip(d.end[:-1], d.start[1:]):
        g[a:b] += size * rng.normal(size=3)
    return replace(d, gyro=g)


def test_a_gyro_fit_beyond_its_noise_warns_as_the_accelerometer_does(run_cli, tmp_path):
    d = _unmodelled(session(turn=0.0))
    res = fit_gyro(d)
    assert excess(res) is not None and excess(res).redchi == pytest.approx(res.redchi) and res.redchi > 10
    _csv(d, tmp_path / "rec.csv")
    r = run_cli(["calibrate", "--data", tmp_path / "rec.csv", "--unit", "m/s^2", "--gyro-unit", "rad/s",
                 "--gravity", "9.81", "--out", tmp_path / "o", "--no-figures", "--quiet", "--json", tmp_path / "s.json"])
    assert r.code == 0, r.err
    s = json.loads((tmp_path / "s.json").read_text())
    red, dof = s["gyro"]["fit"]["redchi"], s["gyro"]["fit"]["dof"]
    want = (f"gyroscope: reduced chi-square {red:.3g} against the noise ({dof} dof, p < 0.001): the residuals "
            "exceed the noise, so the model misses an effect or the noise is underestimated; the gyro's standard "
            f"errors are scaled by it (x {red ** 0.5:.3g})")
    assert f"imucal: warning: {want}\n" in r.err
    assert want in s["warnings"]
    assert want in yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())["fit"]["warnings"]
    assert f"WARNING            = {want}" in (tmp_path / "o" / "report.txt").read_text()
    assert "CHECK: usable, read the warnings" in (tmp_path / "o" / "report.html").read_text(encoding="utf-8")


def test_a_clean_gyro_fit_does_not_warn():
    from imucal.report.gyro import gyro_warnings

    res = fit_gyro(session(turn=0.0))
    assert excess(res) is None and res.redchi < 2 and gyro_warnings(res) == []


def test_one_rule_decides_for_both_sensors(monkeypatch, si_run):
    """Both sensors' warnings come from imucal.solve.misfit: raising its threshold silences both."""
    import imucal.solve.misfit as misfit
    from imucal.pipeline import fit_warnings
    from imucal.report.gyro import gyro_warnings

    res = fit_gyro(_unmodelled(session(turn=0.0)))
    acc = replace(si_run.result, chi2_noise=50.0 * si_run.result.dof)  # an accelerometer fit 50x its noise
    assert gyro_warnings(res) and fit_warnings(acc, si_run.config, si_run.recording, [])
    monkeypatch.setattr(misfit, "POOR_FIT_REDCHI", 1e9)
    assert gyro_warnings(res) == [] and fit_warnings(acc, si_run.config, si_run.recording, []) == []
