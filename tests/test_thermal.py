"""Temperature calibration from still poses over a temperature sweep (imucal/thermal, issue 27).

A sweep is simulated here with an independent forward model (plain powers of T - 15 degC, not the
grammar's orthogonal terms): three one-axis-down poses, each held while the temperature swings
5 -> 25 degC and back. The truth's terms must be found, and nothing else; what the poses cannot
determine is named with what to record; a lag or hysteresis is named only when simulated."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import real_file
from imucal.analysis.discover import discover
from imucal.report.discover_text import discovery_report, verdict_text
from imucal.calibration.frozen import load_calibration
from imucal.config.run import config_from_dict
from imucal.constants import STANDARD_GRAVITY
from imucal.errors import ImucalError
from imucal.solve.observability import Observability, require_observable
from imucal.thermal.determine import interval_advice

G = STANDARD_GRAVITY
MG = G / 1000
NOMINAL = {"b1": 1.0, "b2": 1.0, "b3": 1.0, "phi": np.pi / 2, "psi": np.pi / 2, "theta": np.pi / 2}
#: The truth: bias(T) per axis as plain powers of (T - 15) [m/s^2 / degC^k], scale(T) [1 / degC].
TRUTH = {"bias1": (0.6 * MG, -2.2 * MG, 2.5 * MG), "bias2": (0.0, 0.04 * MG, 0.0), "scale1": (0.0, 0.0, 3e-4)}


def sweep(path: Path, truth: dict = TRUTH, seed: int = 0, hours: float = 4.0, cycles: int = 1, lag: float = 0.0,
          hysteresis: tuple = (0.0, 0.0, 0.0), still_z: bool = False, noise: float = 0.01,
          cut: list | None = None) -> Path:
    """A CSV (t, ax, ay, az, temp) at 1 Hz: z, x, y along -g, each held ``hours`` while the die swings
    ``cycles`` times 5 -> 25 -> 5 degC (``still_z``: the z pose at 20 degC). The temp column lags the die
    by ``lag`` [s] (first order); ``hysteresis`` [m/s^2] is added warming, subtracted cooling; ``cut``:
    [(t0, t1)] spans [s] left out (a logger's pause)."""
    rng = np.random.default_rng(seed)
    n_hold, n_move = int(hours * 3600), 120
    s, tilt = np.array([0.05, -0.1, 0.2]), 0.02
    t_all, raw_all, temp_all = [], [], []
    t0 = 0.0
    for k, axis in enumerate((2, 0, 1)):
        m = np.zeros(3)
        m[axis], m[(axis + 1) % 3] = -G * np.cos(tilt), G * np.sin(tilt)
        t = np.arange(n_hold) * 1.0
        die = 15.0 - 10.0 * np.cos(2 * np.pi * cycles * t / (n_hold - 1))
        if still_z and axis == 2:
            die = np.full(n_hold, 20.0)
        dT = die - 15.0
        bias = np.outer(dT, truth["bias1"]) + np.outer(dT ** 2, truth["bias2"])
        scale = 1.0 + np.outer(dT, truth["scale1"])
        raw = s + bias + scale * m + rng.normal(0, noise, (n_hold, 3))
        raw += np.outer(np.sign(np.gradient(die)), hysteresis)
        sensor = die.copy()
        if lag > 0:  # the temperature sensor lags the die: T_s' = (T_die - T_s) / lag
            for i in range(1, n_hold):
                sensor[i] = sensor[i - 1] + (die[i] - sensor[i - 1]) * (1 - np.exp(-1.0 / lag))
        move = rng.normal(0, 3.0, (n_move, 3)) + m
        t_all += [t0 + t, t0 + n_hold + np.arange(n_move)]
        raw_all += [raw, move]
        temp_all += [sensor + rng.normal(0, 0.01, n_hold), np.full(n_move, sensor[-1])]
        t0 += n_hold + n_move
    t, raw, temp = np.concatenate(t_all), np.vstack(raw_all), np.concatenate(temp_all)
    keep = np.ones(t.size, bool)
    for a, b in cut or []:
        keep &= ~((t >= a) & (t < b))
    np.savetxt(path, np.column_stack([t, raw, temp])[keep], delimiter=",", header="t,ax,ay,az,temp", comments="",
               fmt=["%.1f", "%.7f", "%.7f", "%.7f", "%.4f"])
    return path


def run_config(path: Path, **fit) -> object:
    return config_from_dict({"data": {"path": str(path), "time_unit": "s"},
                             "fit": {"fix": dict(NOMINAL), **fit}})


@pytest.fixture(scope="module")
def truth_sweep(tmp_path_factory):
    p = sweep(tmp_path_factory.mktemp("sweep") / "sweep.csv")
    return p, discover(run_config(p))


def test_the_orders_are_chosen_by_the_data(truth_sweep):
    """bias linear on x, y, z, quadratic on y, scale linear on z: found, and nothing else."""
    _, d = truth_sweep
    assert d.thermal is not None
    assert d.thermal.effects == {"bias_temperature": (0, 1, 2), "bias_temperature2": (1,),
                                 "scale_temperature": (2,)}
    assert {e.name for e in d.effects} == {"bias_temperature", "bias_temperature2", "scale_temperature"}
    assert "explained by temperature" in verdict_text(d.verdict)
    assert not d.thermal.lag.lag_named and not d.thermal.lag.hysteresis_named


def test_the_calibration_holds_each_pose_constant_over_temperature(truth_sweep):
    """The calibration kept (its apply map) turns the noise-free readings of each pose over 5..25 degC into
    one vector: the terms' values are right, not only their names (spread within 0.05 mg; 18 mg before)."""
    _, d = truth_sweep
    cal = d.calibration_run.calibration
    T = np.linspace(5, 25, 41)
    for axis in (2, 0, 1):
        m = np.zeros(3)
        m[axis], m[(axis + 1) % 3] = -G * np.cos(0.02), G * np.sin(0.02)
        dT = T - 15.0
        raw = (np.array([0.05, -0.1, 0.2]) + np.outer(dT, TRUTH["bias1"]) + np.outer(dT ** 2, TRUTH["bias2"])
               + (1.0 + np.outer(dT, TRUTH["scale1"])) * m)
        a = cal.apply(raw, {"temp": T})
        assert np.ptp(a, axis=0).max() < 0.05 * MG, (axis, np.ptp(a, axis=0) / MG)
        assert np.ptp(raw, axis=0).max() > 10 * MG


def test_standard_errors_cover_the_truth(truth_sweep):
    """The linear coefficient of the orthogonal basis is the slope at the rows' mean temperature: the truth's
    d/dT of c1 (T - 15) + c2 (T - 15)^2 there, within 4 standard errors."""
    _, d = truth_sweep
    fit = d.thermal.selection.fit
    tref = fit.params["bias_temperature_tref"].value
    for i, a in enumerate("xyz"):
        slope = TRUTH["bias1"][i] + 2 * TRUTH["bias2"][i] * (tref - 15.0)
        n = f"bias_temperature_{a}"
        if i == 2:  # z reads -g cos(tilt) in its pose: its bias and scale terms are told apart by the poses
            pass
        assert abs(fit.params[n].value - slope) < 4 * fit.std[n] + 1e-4 * MG, (n, fit.params[n].value, slope)


def test_discover_writes_the_calibration_and_apply_uses_the_temp_column(truth_sweep, run_cli, tmp_path):
    path, _ = truth_sweep
    cfg = tmp_path / "run.yaml"
    cfg.write_text(f"data: {{path: {path}, time_unit: s}}\nfit:\n  fix: {NOMINAL}\n".replace("'", ""))
    r = run_cli(["discover", "--config", cfg, "--out", tmp_path / "cal", "--json", tmp_path / "d.json"])
    assert r.code == 0, r.err
    assert "bias_temperature[xyz]" in r.out and "[[Temperature]]" in r.out
    assert "drift" not in r.out.split("[[Notes]]")[0].split("[[Effects found]]")[1]  # names nothing else
    cal = load_calibration(tmp_path / "cal" / "calibration.yaml")
    names = {n for n, _ in cal.effects}
    assert names == {"bias_temperature", "bias_temperature2", "scale_temperature"}
    assert cal.std["scale_temperature_z"] > 0 and not cal.params["scale_temperature_z"].fixed
    flight = tmp_path / "flight.csv"
    flight.write_text("t,ax,ay,az,temp\n0,0.05,-0.1,-9.6,5\n1,0.05,-0.1,-9.6,25\n")
    r = run_cli(["apply", tmp_path / "cal" / "calibration.yaml", "--data", flight, "--out", tmp_path / "o.csv"])
    assert r.code == 0, r.err
    out = np.loadtxt(tmp_path / "o.csv", delimiter=",", skiprows=1)
    assert abs(out[0, 3] - out[1, 3]) > 0.01  # the temperature terms act
    import json

    assert json.loads((tmp_path / "d.json").read_text())["thermal"]["effects"]["bias_temperature"] == ["x", "y", "z"]


def test_no_temperature_effect_no_term(tmp_path):
    d = discover(run_config(sweep(tmp_path / "flat.csv", truth={"bias1": (0, 0, 0), "bias2": (0, 0, 0),
                                                                  "scale1": (0, 0, 0)}, seed=1)))
    assert d.thermal is not None and d.thermal.effects == {}
    assert d.effects == () and verdict_text(d.verdict).startswith("no temperature term is significant")


def test_what_the_poses_cannot_determine_is_named_with_what_to_record(tmp_path):
    """The z pose held at one temperature: z's scale(T) cannot be told (z reads g nowhere over a range)."""
    d = discover(run_config(sweep(tmp_path / "zstill.csv", seed=2, still_z=True)))
    und = {t.label: t for t in d.thermal.selection.undetermined}
    assert "scale_temperature[z]" in und
    assert "scale_temperature" not in d.thermal.effects or 2 not in d.thermal.effects["scale_temperature"]
    text = discovery_report(d)
    assert ("scale_temperature[z] is not determined by these poses" in text
            and "axis z is held along gravity over no temperature range" in text
            and "hold the sensor still with z along gravity (up or down) while the temperature sweeps" in text)


def test_a_lagging_temperature_sensor_is_named(tmp_path):
    d = discover(run_config(sweep(tmp_path / "lag.csv", seed=3, cycles=4, lag=600.0)))
    lag = d.thermal.lag
    assert lag.lag_named and abs(lag.tau - 600.0) < max(4 * lag.tau_std, 150.0), (lag.tau, lag.tau_std)
    assert "named: the die leads the sensor" in discovery_report(d)


def test_hysteresis_is_named_when_present(tmp_path):
    d = discover(run_config(sweep(tmp_path / "hyst.csv", seed=4, cycles=4, hysteresis=(2 * MG, 0.0, -1 * MG))))
    lag = d.thermal.lag
    assert lag.hysteresis_named
    np.testing.assert_allclose(lag.hysteresis, [2 * MG, 0.0, -1 * MG], atol=0.3 * MG)


def test_a_clean_sweep_claims_neither(tmp_path):
    d = discover(run_config(sweep(tmp_path / "clean.csv", seed=5, cycles=4)))
    assert not d.thermal.lag.lag_named and not d.thermal.lag.hysteresis_named
    assert "not shown by these data (none claimed)" in discovery_report(d)


def test_a_recording_with_gaps_is_read_as_separate_spans(tmp_path):
    """Spans cut out (for validation, or a logger's pause) leave gaps: read, not refused; no row spans one."""
    p = sweep(tmp_path / "gaps.csv", seed=6, cut=[(3000, 3600), (20000, 21000)])
    d = discover(run_config(p))
    rec, rows = d.final.recording, d.thermal.rows
    assert rec.time_base.n_gaps == 2
    for a, b in zip(rows.start, rows.end):
        assert np.all(np.diff(rec.t[a:b]) < 1.5)
    assert d.thermal.effects.get("bias_temperature") == (0, 1, 2)


def test_the_observability_refusal_says_which_pose_and_temperature_to_add():
    """|a| = g on still intervals: an undetermined temperature coefficient's refusal names the axis to hold
    along (scale) or across (bias) gravity while the temperature changes, and the range held now."""
    dirs = np.array([[0, 0, -1.0], [0, 0, -1.0], [-1.0, 0, 0], [0, -1.0, 0]])
    temps = np.array([20.0, 20.1, 5.0, 25.0])
    obs = Observability(4, np.arange(4), np.ones(2), ("scale_temperature_z",), {}, ())
    with pytest.raises(ImucalError) as ei:
        require_observable(obs, ("s1", "scale_temperature_z"), "sweep.csv",
                           lambda names: interval_advice(names, dirs, temps))
    msg = str(ei.value)
    assert "leave scale_temperature_z undetermined" in msg
    assert ("hold the sensor still with z along gravity (up or down) while the temperature changes over the "
            "range to calibrate (the intervals with it so span 20.0..20.1 degC)") in msg
    assert interval_advice(("s1", "phi"), dirs, temps) is None


@pytest.mark.slow
def test_the_real_thermal_sweep_workflow(run_cli, tmp_path):
    """thermal-cats-skdivemove: a run file holding what three poses cannot determine; discover names the
    temperature terms (and no drift), writes the calibration; apply corrects a CSV with a temp column."""
    nc = real_file("thermal-cats-skdivemove", "cats_temperature_calib.nc")
    cfg = tmp_path / "run.yaml"
    cfg.write_text(f"data: {{path: {nc}}}\nfit:\n  fix: {NOMINAL}\n".replace("'", ""))
    r = run_cli(["calibrate", cfg, "--out", tmp_path / "plain", "--no-figures"])  # |a| = g without the terms
    assert r.code == 2 and "a sweep, 5.1..25.7 degC" in r.err and f"imucal discover --config {cfg}" in r.err
    assert not (tmp_path / "plain").exists()
    r = run_cli(["discover", "--config", cfg, "--out", tmp_path / "cal"])
    assert r.code == 0, r.err
    assert "explained by temperature: bias_temperature[xyz]" in r.out
    found = r.out.split("[[Effects found]]")[1].split("[[")[0]
    assert "bias_temperature[xyz]" in found and "drift" not in found and "warmup" not in found
    assert "absolute bias and scale at the reference temperature are not determined" in r.out
    assert "(none claimed)" in r.out
    cal = load_calibration(tmp_path / "cal" / "calibration.yaml")
    assert {n for n, _ in cal.effects} >= {"bias_temperature"}
    assert not any("drift" in n or "warmup" in n for n, _ in cal.effects)
    assert "gyroscope bias(T)" in r.out and "confounded" in r.out
    assert cal.raw_unit == "m/s^2"
    # the gyroscope's bias(T) is in the file (issue 27): its section's terms, applied with the temp column
    assert cal.gyro is not None and cal.gyro.raw_unit == "rad/s"
    assert any(e.name == "bias_temperature" for e in cal.gyro.model.effects) and "temp" in cal.gyro.model.inputs
    flight = tmp_path / "flight.csv"
    flight.write_text("t,ax,ay,az,gx,gy,gz,temp\n0,-0.2,0.7,-10.4,0.01,0.02,0.03,5\n"
                      "1,-0.2,0.7,-10.4,0.01,0.02,0.03,20\n")
    r = run_cli(["apply", tmp_path / "cal" / "calibration.yaml", "--data", flight, "--out", tmp_path / "o.csv"])
    assert r.code == 0, r.err
    out = np.loadtxt(tmp_path / "o.csv", delimiter=",", skiprows=1)
    assert np.abs(out[0, 4:7] - out[1, 4:7]).max() > 1e-4  # the gyro's temperature terms act [rad/s]


def test_the_gyroscope_bias_over_temperature_orders_values_and_drift():
    """imucal.gyro.thermal on rows of three poses over 5..25 degC: x linear, y quadratic, z none (plus each
    pose's Earth rate): the orders found, the curve within its errors, named Parameters in the grammar's names."""
    from imucal.gyro.thermal import gyro_bias_temperature
    from imucal.thermal.evidence import ThermalRows

    rng = np.random.default_rng(8)
    T = np.concatenate([np.linspace(5, 25, 80)] * 3)
    pose = np.repeat([0, 1, 2], 80)
    earth = np.array([[7e-5, 0, 1e-5], [0, 7e-5, 0], [2e-5, 0, -7e-5]])[pose]
    dT = T - 15.0
    truth = np.column_stack([2e-4 * dT, -1e-4 * dT + 4e-6 * dT ** 2, np.zeros_like(T)])
    gyro = 0.03 + earth + truth + rng.normal(0, 2e-6, (T.size, 3))
    n = T.size
    rows = ThermalRows(raw=np.zeros((n, 3)), temp=T, t=np.arange(n) * 600.0, pose=pose, n_samples=np.full(n, 100),
                       var=np.ones((n, 3)), gyro=gyro, start=np.arange(n), end=np.arange(n) + 1)
    g = gyro_bias_temperature(rows)
    assert g.orders == (1, 2, 0)
    assert set(g.params.free_names) == {"bias_temperature_x", "bias_temperature_y", "bias_temperature2_y"}
    assert g.params["bias_temperature_tref"].fixed and g.std["bias_temperature_x"] > 0
    curve = g.bias(np.array([5.0, 25.0])) - g.bias(np.array([15.0, 15.0]))
    want = truth[[0, 79]] - np.array([0.0, 0.0, 0.0])
    np.testing.assert_allclose(curve, want, atol=5e-6)
    assert np.sqrt(np.mean(g.after ** 2)) < 3e-6 < np.sqrt(np.mean(g.before ** 2))


@pytest.mark.parametrize("case", ["flat", "none"])
def test_a_few_pose_log_that_is_no_sweep_says_why(tmp_path, run_cli, unchanged, case):
    """Three poses whose temperature never changes (or is not read): discovery's refusal says what a sweep needs
    (before: only "record more static orientations", with nothing about the temperature)."""
    d = np.loadtxt(sweep(tmp_path / "s.csv", hours=1.0), delimiter=",", skiprows=1)
    d[:, 4] = 20.0
    cols = d if case == "flat" else d[:, :4]
    np.savetxt(tmp_path / "log.csv", cols, delimiter=",", header="t,ax,ay,az,temp"[: 10 if case == "none" else None],
               comments="", fmt="%.8g")
    run = tmp_path / "run.yaml"
    run.write_text("data: {path: log.csv, time_unit: s}\nfit: {fix: {"
                   + ", ".join(f"{k}: {v!r}" for k, v in NOMINAL.items()) + "}}\n")
    with unchanged():
        r = run_cli(["discover", "--config", run, "--out", tmp_path / "o"])
    assert r.code == 2 and r.err.count("\n") == 1 and "too few to test effects" in r.err, r.err
    assert ("spans 2 degC, and this log's span at most 0 degC" if case == "flat" else "data.columns.temp") in r.err
