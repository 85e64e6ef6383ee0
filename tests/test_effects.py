"""The effect library: terms, parameters, units, simulate-fit-recover, refusals, calibration files."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from imucal.calibration.frozen import Calibration

from imucal.calibration.frozen import from_dict
from imucal.config.run import config_from_dict
from imucal.model.effects import (EFFECTS, MIN_TEMPERATURE_SPREAD, REFERENCE_TEMPERATURE, ScaleNonlinearity,
                            check_effects, effects_from_coefficients, make_effect, prepare_parameters,
                            simulate_effects)
from imucal.errors import ImucalError
from imucal.model.sensor import build_model
from imucal.model.parameters import base_parameters
from imucal.pipeline import calibrate_accelerometer
from imucal.analysis.simulate import (PosePlan, SensorSpec, TemperatureProfile, cube_directions, mems_counts_sensor,
                             random_directions, simulate)

G = 9.80665


def _plan(rng, n_random=6, hold=3.0):
    dirs = np.vstack([cube_directions("faces+edges"), random_directions(n_random, rng)])
    return PosePlan(dirs[rng.permutation(len(dirs))], hold=hold, transition=2.0, rate=100.0)


def _write(tmp_path, sim, name="rec.csv"):
    p = tmp_path / name
    p.write_text(sim.to_csv_text())
    return str(p)


# --- parameters, names, units -----------------------------------------------------------------
def test_every_effect_adds_named_parameters_with_units():
    base = base_parameters([100, -50, 20], [1670, 1670, 1670], raw_unit="raw")
    units = {"bias_temperature": "raw/degC", "scale_temperature": "1/degC", "bias_drift": "raw/s",
             "scale_drift": "1/s", "scale_nonlinearity": "1/(m/s^2)",
             "bias_temperature2": "raw/degC^2", "scale_temperature2": "1/degC^2",
             "bias_temperature3": "raw/degC^3", "scale_temperature3": "1/degC^3",
             "bias_drift2": "raw/s^2", "scale_drift2": "1/s^2", "bias_warmup": "raw", "scale_warmup": "1",
             "scale_nonlinearity3": "1/(m/s^2)^2", "cross_axis_nonlinearity": "1/(m/s^2)",
             "scale_asymmetry": "1", "bias_step": "raw", "bias_hysteresis": "raw", "angle_temperature": "rad/degC"}
    assert set(EFFECTS) == set(units)
    for name, unit in units.items():
        e = make_effect(name, (0, 2))
        first, last = e.coefficient_names  # axes x and z (an angle term's phi and theta)
        ps = {p.name: p for p in e.parameters(base)}
        assert len({n for n in ps if n.startswith(name + "_") and not ps[n].fixed and n not in e.shape_names}) == 2
        assert ps[first].unit == unit and not ps[first].fixed and ps[last].unit == unit
        assert ps[first].value == (ps[first].scale if "warmup" in name else 0.0)
        assert ps[first].scale > 0
        if "temp" in e.covariates:  # the reference temperature is a fixed parameter of the file
            assert ps[f"{name}_tref"].fixed and ps[f"{name}_tref"].unit == "degC"
        for n in e.given_names:  # a step's time: fixed, given by a run file or discovery, not by the data
            assert ps[n].fixed and ps[n].unit == "s" and not np.isfinite(ps[n].value)
        if name.endswith(("2", "3")) and "nonlinearity" not in name:  # orthogonal-polynomial constants
            assert ps[f"{name}_a2"].fixed and ps[f"{name}_b2"].unit.endswith("^2")
        if "warmup" in name:  # tau fitted, bounded positive
            tau = ps[f"{name}_tau"]
            assert not tau.fixed and tau.unit == "s" and tau.lower > 0
        model = build_model([e])
        assert model.names[:9] == ("s1", "s2", "s3", "b1", "b2", "b3", "phi", "psi", "theta")
        assert set(model.covariates) == set(e.covariates)


def test_unknown_effect_and_bad_axes_messages():
    with pytest.raises(ImucalError, match="unknown effect 'bias_temp'.*choose from bias_temperature"):
        make_effect("bias_temp", (0,))
    with pytest.raises(ImucalError, match="axes .* non-empty subset"):
        make_effect("bias_drift", (3,))


def test_effect_identity_is_name_and_axes():
    assert make_effect("bias_drift", (1, 0)) == make_effect("bias_drift", (0, 1))
    assert make_effect("bias_drift", (0,)) != make_effect("scale_drift", (0,))
    assert build_model([make_effect("bias_drift", (0,))]) is build_model([make_effect("bias_drift", (0,))])


# --- the nonlinearity is inverted exactly ----------------------------------------------------
@settings(max_examples=200, deadline=None)
@given(q=st.floats(-0.009, 0.009), m=st.floats(-2.5 * G, 2.5 * G))
def test_nonlinearity_correct_inverts_distort(q, m):
    e = ScaleNonlinearity((0,))
    p = {"scale_nonlinearity_x": q}
    u = e.distort([m, 0.0, 0.0], p)[0]
    back = e.correct([u, 0.0, 0.0], None, {}, p)[0]
    assert back == pytest.approx(m, rel=1e-9, abs=1e-9)


# --- the simulator's forward terms ------------------------------------------------------------
def test_simulate_effects_matches_the_model_terms():
    """raw from simulate_effects, put through the model's measured map, gives back m."""
    rng = np.random.default_rng(3)
    n = 50
    m = rng.normal(0, 5, (n, 3))
    t = np.linspace(0, 100, n)
    temp = 25 + 10 * np.sin(t / 20)
    spec = {"bias_temperature": {"bias_temperature_x": 3.0, "bias_temperature_tref": 27.0},
            "scale_temperature": {"scale_temperature_y": 2e-4},
            "bias_drift": {"bias_drift_z": -0.5},
            "scale_drift": {"scale_drift_x": 1e-5},
            "scale_nonlinearity": {"scale_nonlinearity_y": 3e-3}}
    sensor = SensorSpec(s=(10, -20, 30), b=(1600, 1650, 1700), effects=spec)
    raw = sensor.forward(m, t, temp)
    effects = effects_from_coefficients(spec)
    model = build_model(effects)
    vals = {**sensor.values(), "scale_temperature_tref": REFERENCE_TEMPERATURE}
    p = np.array([vals.get(nm, 0.0) for nm in model.names])
    cov = np.column_stack([{"temp": temp, "time": t}[c] for c in model.covariates])
    got = np.asarray(model.measured.map(n)(raw.T, cov.T, p)).T
    np.testing.assert_allclose(got, m, rtol=1e-10, atol=1e-9)


def test_simulate_effects_refuses_bad_specs():
    with pytest.raises(ImucalError, match="unknown parameter 'bias_drift_w' of effect bias_drift"):
        effects_from_coefficients({"bias_drift": {"bias_drift_w": 1.0}})
    with pytest.raises(ImucalError, match="unknown effect 'wobble'"):
        effects_from_coefficients({"wobble": {"x": 1.0}})
    sensor = SensorSpec(effects={"bias_temperature": {"bias_temperature_x": 1.0}})
    with pytest.raises(ImucalError, match="temperature effect but the simulation has no temperature profile"):
        simulate_effects(sensor, np.zeros((3, 3)), np.arange(3.0), None)


# --- known truth: simulate, fit, recover -------------------------------------------------------
CASES = [
    ("bias_temperature", (0, 2), {"bias_temperature_x": 4.0, "bias_temperature_z": -3.0}),
    ("scale_temperature", (1,), {"scale_temperature_y": 3e-4}),
    ("bias_drift", (0, 1, 2), {"bias_drift_x": 0.05, "bias_drift_y": -0.04, "bias_drift_z": 0.03}),
    ("scale_drift", (2,), {"scale_drift_z": 3e-5}),
    ("scale_nonlinearity", (0, 1), {"scale_nonlinearity_x": 2e-4, "scale_nonlinearity_y": -3e-4}),
]


@pytest.mark.parametrize("name,axes,coeffs", CASES, ids=[c[0] for c in CASES])
def test_simulate_fit_recover(tmp_path, name, axes, coeffs):
    rng = np.random.default_rng(11)
    sensor = mems_counts_sensor(rng, noise_counts=1.0)
    true = dict(coeffs)
    if make_effect(name, axes).uses_tref:
        true[f"{name}_tref"] = 25.0
    sensor = dataclasses.replace(sensor, effects={name: true})
    sim = simulate(sensor, _plan(rng), seed=5, temperature=TemperatureProfile(period=100.0, swing=4.0))
    cfg = config_from_dict({"data": {"path": _write(tmp_path, sim)},
                            "fit": {"effects": [{"name": name, "axes": ["xyz"[a] for a in axes]}]}})
    run = calibrate_accelerometer(cfg)
    res = run.result
    assert res.redchi < 3.0
    for pname, v in coeffs.items():
        est, sd = res.params[pname].value, res.std[pname]
        assert abs(est - v) < 5 * sd, (pname, est, v, sd)
        assert abs(est - v) < 0.1 * abs(v), (pname, est, v)
    if make_effect(name, axes).uses_tref:  # T_ref = mean interval temperature, stored fixed
        tref = res.params[f"{name}_tref"]
        assert tref.fixed and tref.value == pytest.approx(np.mean(run.intervals.temp), abs=1e-3)
        # s at T_ref: the true shift moved along the temperature line
        for a in axes:
            if name == "bias_temperature":
                expect = sensor.s[a] + coeffs[f"{name}_{'xyz'[a]}"] * (tref.value - 25.0)
                assert res.params[f"s{a + 1}"].value == pytest.approx(expect, abs=5 * res.std[f"s{a + 1}"] + 0.5)


def test_rescaled_readings_give_the_same_relative_coefficients(tmp_path):
    """The same recording in counts and in counts / 1000: k scales by 1/1000, c is unchanged."""
    rng = np.random.default_rng(21)
    sensor = dataclasses.replace(mems_counts_sensor(rng, noise_counts=1.0), quantum=0.0,
                                 effects={"bias_temperature": {"bias_temperature_y": 5.0},
                                          "scale_temperature": {"scale_temperature_x": 2e-4}})
    sim = simulate(sensor, _plan(rng), seed=2, temperature=TemperatureProfile(period=90.0, swing=4.0))
    small = dataclasses.replace(sim, raw=sim.raw / 1000.0)
    fx = {"effects": [{"name": "bias_temperature", "axes": ["y"]}, {"name": "scale_temperature", "axes": ["x"]}]}
    r1, r2 = (calibrate_accelerometer(config_from_dict({"data": {"path": _write(tmp_path, s, n)}, "fit": fx})).result
              for s, n in ((sim, "a.csv"), (small, "b.csv")))
    assert r2.params["bias_temperature_y"].value * 1000 == pytest.approx(r1.params["bias_temperature_y"].value,
                                                                          rel=1e-4)
    assert r2.params["scale_temperature_x"].value == pytest.approx(r1.params["scale_temperature_x"].value, rel=1e-4)
    assert r2.chi2 == pytest.approx(r1.chi2, rel=1e-3)


# --- refusals ----------------------------------------------------------------------------------
def test_refuses_temperature_effect_without_temp_column():
    e = [make_effect("bias_temperature", (0,))]
    with pytest.raises(ImucalError) as exc:
        check_effects(e, {"temp": None, "time": np.arange(20.0)}, 20, 10, "rec.csv")
    msg = str(exc.value)
    assert "rec.csv" in msg and "data.columns.temp" in msg and "no temp column" in msg and "fix:" in msg
    assert "\n" not in msg


def test_refuses_constant_temperature():
    e = [make_effect("scale_temperature", (1,))]
    temp = np.full(20, 31.0) + np.linspace(0, MIN_TEMPERATURE_SPREAD / 2, 20)
    with pytest.raises(ImucalError, match=r"temperature is constant \(interval means span 0.25 degC < 0.5 degC\)"):
        check_effects(e, {"temp": temp, "time": np.arange(20.0)}, 20, 10, None)


def test_refuses_too_few_intervals_for_the_effect_parameters():
    e = [make_effect("bias_drift", (0, 1, 2))]
    with pytest.raises(ImucalError, match="14 static intervals are too few for 12 free parameters.*at least 15"):
        check_effects(e, {"temp": None, "time": np.arange(14.0)}, 14, 12, None)


def test_calibrate_refuses_temperature_effect_on_constant_temperature(tmp_path):
    rng = np.random.default_rng(5)
    sim = simulate(mems_counts_sensor(rng), _plan(rng), seed=1,
                   temperature=TemperatureProfile(start=30.0, plateau=30.0, swing=0.0, noise=0.01))
    cfg = config_from_dict({"data": {"path": _write(tmp_path, sim)},
                            "fit": {"effects": [{"name": "bias_temperature", "axes": ["x"]}]}})
    with pytest.raises(ImucalError) as exc:
        calibrate_accelerometer(cfg)
    assert "temperature is constant" in str(exc.value) and "rec.csv" in str(exc.value)


def test_calibrate_refuses_temperature_effect_without_temp(tmp_path):
    rng = np.random.default_rng(6)
    sim = simulate(mems_counts_sensor(rng), _plan(rng), seed=1)
    cfg = config_from_dict({"data": {"path": _write(tmp_path, sim)},
                            "fit": {"effects": [{"name": "scale_temperature", "axes": ["x", "y"]}]}})
    with pytest.raises(ImucalError, match="scale_temperature needs temperature but the data have no temp column"):
        calibrate_accelerometer(cfg)


def test_prepare_parameters_sets_reference_temperature():
    effects = [make_effect("bias_temperature", (0,)), make_effect("scale_temperature", (2,))]
    model = build_model(effects)
    params = model.parameters(base_parameters([0, 0, 0], [1, 1, 1]))
    temp = np.linspace(20, 40, 30)
    out = prepare_parameters(effects, params, {"temp": temp, "time": np.arange(30.0)}, 30)
    assert out["bias_temperature_tref"].value == pytest.approx(30.0)
    assert out["scale_temperature_tref"].value == pytest.approx(30.0)
    assert out["bias_temperature_tref"].fixed


# --- the calibration file carries the effects -----------------------------------------------------
def test_calibration_file_round_trip_and_apply_with_temperature(tmp_path):
    rng = np.random.default_rng(8)
    sensor = dataclasses.replace(mems_counts_sensor(rng, noise_counts=1.0),
                                 effects={"bias_temperature": {"bias_temperature_z": 6.0}})
    sim = simulate(sensor, _plan(rng), seed=3, temperature=TemperatureProfile(period=100.0, swing=4.0))
    cfg = config_from_dict({"data": {"path": _write(tmp_path, sim)},
                            "fit": {"effects": [{"name": "bias_temperature", "axes": ["z"]}]}})
    run = calibrate_accelerometer(cfg)
    cal = run.calibration
    path = tmp_path / "cal.yaml"
    cal.save(path)
    import yaml

    d = yaml.safe_load(path.read_text())
    assert d["effects"] == [{"name": "bias_temperature", "axes": ["z"]}]
    assert d["parameters"]["bias_temperature_z"]["unit"] == "raw/degC"
    assert d["parameters"]["bias_temperature_tref"]["fixed"] is True
    back = from_dict(d, str(path))
    assert isinstance(back, Calibration) and back.covariates == ("temp",)
    still = sim.still
    a = back.apply(sim.raw[still], {"temp": sim.temp[still]})
    a0 = cal.apply(sim.raw[still], {"temp": sim.temp[still]})
    np.testing.assert_allclose(a, a0, rtol=1e-12, atol=1e-12)
    # with the effect the norm is g; the same parameters without it are visibly off at the extremes
    assert abs(np.mean(np.linalg.norm(a, axis=1)) - G) < 2e-3
    with pytest.raises(ImucalError, match=r"needs covariate\(s\) \['temp'\]"):
        back.apply(sim.raw[:5])


def test_effect_without_covariates_applies(tmp_path):
    rng = np.random.default_rng(9)
    sensor = dataclasses.replace(mems_counts_sensor(rng, noise_counts=1.0),
                                 effects={"scale_nonlinearity": {"scale_nonlinearity_x": 5e-4}})
    sim = simulate(sensor, _plan(rng, n_random=8), seed=4)
    fx = {"effects": [{"name": "scale_nonlinearity", "axes": ["x"]}]}
    run = calibrate_accelerometer(config_from_dict({"data": {"path": _write(tmp_path, sim)}, "fit": fx}))
    a = run.calibration.apply(sim.raw[sim.still])
    assert abs(np.sqrt(np.mean((np.linalg.norm(a, axis=1) - G) ** 2))) < 5e-3
    assert math.isfinite(run.result.std["scale_nonlinearity_x"])


# --- the generated C code carries the effects ------------------------------------------------------
@pytest.mark.skipif(__import__("shutil").which("gcc") is None, reason="gcc not found")
def test_generated_c_applies_effects_with_temperature_and_time(tmp_path):
    """A calibration with a temperature, a time and a nonlinearity effect: the C apply map takes
    cov = (temp, time) and matches Calibration.apply to double precision."""
    import ctypes
    import shutil
    import subprocess

    from imucal.export.codegen import write_c

    rng = np.random.default_rng(12)
    spec = {"bias_temperature": {"bias_temperature_x": 4.0}, "bias_drift": {"bias_drift_z": 0.05},
            "scale_nonlinearity": {"scale_nonlinearity_y": 3e-4}}
    sensor = dataclasses.replace(mems_counts_sensor(rng, noise_counts=1.0), effects=spec)
    sim = simulate(sensor, _plan(rng, n_random=8), seed=6, temperature=TemperatureProfile(period=100.0, swing=4.0))
    fx = {"effects": [{"name": n, "axes": [next(iter(c))[-1]]} for n, c in spec.items()]}
    cal = calibrate_accelerometer(config_from_dict({"data": {"path": _write(tmp_path, sim)}, "fit": fx})).calibration
    assert cal.covariates == ("temp", "time")
    write_c(cal, tmp_path / "c", prefix="eff", precision="double")
    src = (tmp_path / "c" / "eff.c").read_text()
    assert "eff_apply_cov" in src
    lib = tmp_path / "c" / "libeff.so"
    subprocess.run([shutil.which("gcc"), "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-fPIC",
                    "-shared", "-o", str(lib), str(tmp_path / "c" / "eff.c"), "-lm"], check=True,
                   capture_output=True, text=True)
    dll = ctypes.CDLL(str(lib))
    fn = dll.eff_apply_cov_batch
    fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t]
    fn.restype = None
    raw = np.ascontiguousarray(sim.raw[::50], dtype=np.float64)
    cov = np.ascontiguousarray(np.column_stack([sim.temp[::50], sim.t[::50]]), dtype=np.float64)
    acc = np.zeros_like(raw)
    fn(raw.ctypes.data, cov.ctypes.data, acc.ctypes.data, raw.shape[0])
    ref = cal.apply(raw, {"temp": cov[:, 0], "time": cov[:, 1]})
    np.testing.assert_allclose(acc, ref, rtol=1e-12, atol=1e-12)


def test_a_file_with_the_classic_effects_loads_and_applies_as_before():
    """A calibration file as written before the grammar (names, order, tref) loads, and its apply
    inverts the published forward model of those effects (written here)."""
    angles = (1.56, 1.58, 1.57)
    vals = {"s1": 12.0, "s2": -30.0, "s3": 5.0, "b1": 1650.0, "b2": 1680.0, "b3": 1670.0,
            "phi": angles[0], "psi": angles[1], "theta": angles[2],
            "bias_temperature_x": 2.5, "bias_temperature_tref": 26.4, "scale_drift_y": 2e-5,
            "scale_nonlinearity_z": 3e-3}
    units = {"bias_temperature_x": "raw/degC", "bias_temperature_tref": "degC", "scale_drift_y": "1/s",
             "scale_nonlinearity_z": "1/(m/s^2)"}
    d = {"format": "imucal-calibration", "format_version": 1, "gravity": G,
         "effects": [{"name": "bias_temperature", "axes": ["x"]}, {"name": "scale_drift", "axes": ["y"]},
                     {"name": "scale_nonlinearity", "axes": ["z"]}],
         "units": {"input": "raw"},
         "parameters": {n: {"value": v, "unit": units.get(n, ""), "fixed": n.endswith("_tref")} for n, v in vals.items()}}
    cal = from_dict(d, "old.yaml")
    rng = np.random.default_rng(8)
    m = rng.normal(0, 6, (30, 3))
    t, temp = np.linspace(0, 200, 30), 20 + 10 * np.sin(np.linspace(0, 6, 30))
    s, b = np.array([12.0, -30.0, 5.0]), np.array([1650.0, 1680.0, 1670.0])
    raw = np.column_stack([s[0] + 2.5 * (temp - 26.4) + b[0] * m[:, 0],
                           s[1] + b[1] * (1 + 2e-5 * t) * m[:, 1],
                           s[2] + b[2] * (m[:, 2] + 3e-3 * m[:, 2] ** 2)])
    got = np.asarray(cal.model.measured.map(30)(raw.T, np.vstack([temp, t]), cal.values)).T
    np.testing.assert_allclose(got, m, rtol=1e-10, atol=1e-10)
    assert cal.model.covariates == ("temp", "time")


@pytest.mark.parametrize("name", ["bias_drift", "scale_drift"])
def test_a_drift_on_a_plan_that_revisits_every_pose_in_reverse_is_calibrated(tmp_path, name):
    """Every pose held twice, the second pass in reverse order: the mean of each pose's drift column
    over its two visits is near zero, so a rank test on one row per pose saw no drift at all and the
    calibration was refused as undetermined. Revisits at other times are what determines a drift:
    it is calibrated, and the coefficients are the simulated ones."""
    from imucal.analysis.simulate import draw_effect_case

    case = draw_effect_case(50280, effect=name, axes=(0, 1, 2), snr=40.0, noise_mg=0.3, revisit=True)
    path = tmp_path / "revisit.csv"
    path.write_text(case.config.run().to_csv_text())
    run = calibrate_accelerometer(config_from_dict({"data": {"path": str(path), "unit": case.config.sensor.unit},
                                      "fit": {"effects": [{"name": name, "axes": ["x", "y", "z"]}]}}))
    assert np.bincount(run.observability.labels).min() >= 2  # each pose at least twice
    truth = case.config.sensor.effects[name]
    for n in make_effect(name, (0, 1, 2)).coefficient_names:
        est, sd = run.result.params[n].value, run.result.std[n]
        assert abs(est - truth[n]) < 5 * sd, (n, est, truth[n], sd)
