"""The calibration file: self-describing YAML that loads back losslessly; unknown versions refused."""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

import imucal
from imucal.calibration.fileformat import FORMAT, FORMAT_VERSION
from imucal.calibration.frozen import from_dict, load_calibration
from imucal.constants import SI_ACCEL_UNIT
from imucal.errors import ImucalError
from imucal.model.parameters import BASE_NAMES


@pytest.fixture(scope="module")
def saved(counts_run, tmp_path_factory):
    path = tmp_path_factory.mktemp("cal") / "calibration.yaml"
    counts_run.calibration.save(path)
    return counts_run.calibration, path


def test_file_describes_itself(saved, counts_recording):
    cal, path = saved
    d = yaml.safe_load(path.read_text())
    assert d["format"] == FORMAT == "imucal-calibration"
    assert d["format_version"] == FORMAT_VERSION
    assert d["model"] == "nakov-ivanov-9"
    assert d["units"]["input"] == "raw" and d["units"]["output"] == SI_ACCEL_UNIT == "m/s^2"
    assert d["units"]["gravity"] == "m/s^2"
    assert d["units"]["angles"] == "rad"
    assert "orthonormal" in d["output_frame"]
    assert d["gravity"] == pytest.approx(9.80665)
    for n in BASE_NAMES:
        e = d["parameters"][n]
        assert set(e) >= {"value", "std", "unit", "lower", "upper", "fixed", "solver_scale"}
        assert "scale" not in e  # the solver's scaling magnitude is not a scale factor b1..b3
        assert e["std"] > 0 and e["fixed"] is False
    assert d["parameters"]["phi"]["unit"] == "rad"
    assert d["parameters"]["b1"]["unit"] == "raw/(m/s^2)"
    A = np.array(d["apply"]["matrix"])
    c = np.array(d["apply"]["offset"])
    assert A.shape == (3, 3) and c.shape == (3,)
    assert A[0, 1] == A[0, 2] == A[1, 2] == 0.0  # exact zeros, lower triangular
    A0, c0 = cal.linear_map()
    np.testing.assert_array_equal(A, A0)
    np.testing.assert_array_equal(c, c0)
    assert d["data"]["file"] == counts_recording.path.name
    assert d["data"]["sha256"] == hashlib.sha256(counts_recording.path.read_bytes()).hexdigest()
    assert d["data"]["samples"] == counts_recording.sim.t.size
    assert d["software"] == {"name": "imucal", "version": imucal.__version__}
    assert d["created"]  # ISO timestamp
    for k in ("rms_residual", "rms_residual_samples", "chi2", "dof", "status", "iterations", "n_intervals"):
        assert k in d["fit"]


def test_loads_back_losslessly(saved):
    cal, path = saved
    back = load_calibration(path)
    assert back.params.names == cal.params.names
    for n in cal.params:
        p, q = cal.params[n], back.params[n]
        assert (q.value, q.lower, q.upper, q.unit, q.fixed, q.scale) == (p.value, p.lower, p.upper, p.unit,
                                                                         p.fixed, p.scale), n
        assert back.std[n] == cal.std[n]
    assert back.gravity == cal.gravity
    assert back.raw_unit == cal.raw_unit
    assert dict(back.fit) == dict(cal.fit)
    assert dict(back.data) == dict(cal.data)
    assert back.created == cal.created and back.software_version == cal.software_version
    assert back.model_name == cal.model_name
    raw = np.array([[30000.0, 100.0, -16000.0], [1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(back.apply(raw), cal.apply(raw))
    # and a second round trip writes the same text
    again = path.with_name("again.yaml")
    back.save(again)
    assert again.read_text() == path.read_text()


def test_fixed_parameters_round_trip(tmp_path, counts_recording):
    from conftest import calibrate_file

    truth = counts_recording.truth  # held at the true angles: a fit, not a refused misfit
    run = calibrate_file(counts_recording.path, fit={"fix": ["phi", "psi", "theta"],
                                                     "initial": {a: truth[a] for a in ("phi", "psi", "theta")}})
    path = tmp_path / "c.yaml"
    run.calibration.save(path)
    d = yaml.safe_load(path.read_text())
    assert d["parameters"]["phi"]["fixed"] is True and d["parameters"]["phi"]["std"] is None
    back = load_calibration(path)
    assert back.params["phi"].fixed and math.isnan(back.std["phi"])
    assert back.params["phi"].value == truth["phi"]
    assert math.isinf(back.params["s1"].lower) and back.params["s1"].lower < 0


def _dict(saved) -> dict:
    return yaml.safe_load(saved[1].read_text())


@pytest.mark.parametrize("version", [4, 0, "1", 1.5, True, None])
def test_unknown_version_is_refused(saved, tmp_path, version):
    d = _dict(saved)
    d["format_version"] = version
    p = tmp_path / "v.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ImucalError, match=rf"unknown format version {version!r} \(this imucal reads versions 1, 2, 3\)") \
            as ei:
        load_calibration(p)
    assert ei.value.field == "format_version" and str(ei.value).startswith(str(p))
    assert "upgrade imucal" in str(ei.value)


def test_version_1_files_still_load(saved, tmp_path):
    """A file as imucal wrote it before format version 2 (no sensor list) gives the same calibration."""
    d = _dict(saved)
    assert d["format_version"] == 3 and d["sensors"] == ["accelerometer"]
    d["format_version"] = 1
    del d["sensors"]
    p = tmp_path / "v1.yaml"
    p.write_text(yaml.safe_dump(d))
    old, new = load_calibration(p), load_calibration(saved[1])
    assert old.sensors == ("accelerometer",) and old.gyro is None
    raw = np.random.default_rng(0).normal(size=(50, 3)) * 1000
    np.testing.assert_array_equal(old.apply(raw), new.apply(raw))


@pytest.mark.parametrize("sensors", [None, ["accelerometer", "gyroscope"], ["gyroscope"], "accelerometer"])
def test_the_sensor_list_must_match_the_sections(saved, tmp_path, sensors):
    d = _dict(saved)
    d["sensors"] = sensors
    p = tmp_path / "s.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ImucalError) as ei:
        load_calibration(p)
    assert ei.value.field == "sensors"


@pytest.mark.parametrize("mutate, field, match", [
    (lambda d: d.update(format="something-else"), "format", "format 'something-else' is not 'imucal-calibration'"),
    (lambda d: d.pop("format"), "format", "missing key 'format'"),
    (lambda d: d.pop("parameters"), "parameters", "missing key 'parameters'"),
    (lambda d: d["parameters"].pop("psi"), "parameters.psi", "missing key 'psi'"),
    (lambda d: d["parameters"]["b2"].update(value=-3.0), "parameters.b2.value", "scale b2 = -3.0 must be positive"),
    (lambda d: d["parameters"]["b2"].update(value="big"), "parameters.b2.value", "'big' is not a number"),
    (lambda d: d["parameters"]["s1"].update(value=10**400), "parameters.s1.value", "is too large for a float"),
    (lambda d: d.update(gravity=-(10**309)), "gravity", "is too large for a float"),
    (lambda d: d["parameters"]["phi"].update(value=4.0), "parameters.phi.value", r"angle phi = 4.0 rad is outside"),
    (lambda d: [d["parameters"][a].update(value=v) for a, v in (("phi", 0.3), ("psi", 0.3), ("theta", 2.5))],
     "parameters",
     "give no valid frame"),
    (lambda d: d["parameters"]["s1"].update(value=float("nan")), "parameters.s1.value", "value is not finite"),
    (lambda d: d["parameters"]["s1"].update(solver_scale=-1.0), "parameters.s1.solver_scale", "scale must be positive"),
    (lambda d: d["parameters"]["s1"].update(scale=2.0), "parameters.s1.scale", "has both solver_scale and its old name"),
    (lambda d: d["apply"]["matrix"][1].__setitem__(1, d["apply"]["matrix"][1][1] * (1 + 1e-6)), "apply.matrix",
     "disagrees with the parameters"),
    (lambda d: d["apply"]["offset"].__setitem__(2, d["apply"]["offset"][2] + 0.05), "apply.offset",
     "disagrees with the parameters"),
    (lambda d: d["apply"].update(matrix=[[1, 2], [3, 4]]), "apply.matrix", "is not a 3x3 matrix"),
    (lambda d: d["apply"].update(offset="zero"), "apply.offset", "is not a 3-vector"),
    (lambda d: d.update(apply=[1]), "apply", "must be a mapping"),
    (lambda d: d.update(model="nakov-ivanov-6"), "model", "is not this file's model"),
    (lambda d: d.update(created="2024 */ int x; /*"), "created", "is not an ISO 8601 date"),
    (lambda d: d.update(created=20240101), "created", "is not text"),
    (lambda d: d["software"].update(version="1.0 */ evil"), "software.version", "is not a version number"),
    (lambda d: d["units"].update(input="g */ int x; /*"), "units.input", "is not a unit"),
    (lambda d: d["units"].update(input="m//s"), "units.input", "is not a unit"),
    (lambda d: d["units"].update(gravity="ft/s^2"), "units.gravity", r"gravity unit 'ft/s\^2' is not m/s\^2"),
    (lambda d: d["parameters"]["b1"].update(unit="x\n/* y"), "parameters.b1.unit", "is not a unit"),
    (lambda d: d["data"].update(sha256="abc"), "data.sha256", "is not a SHA-256 digest"),
    (lambda d: d["data"].update(file=["a"]), "data.file", "is not a file name"),
    (lambda d: d["parameters"]["s1"].update(fixed="yes"), "parameters.s1.fixed", "'yes' is not true or false"),
    (lambda d: d["parameters"].update(q1={"value": 1.0}), "parameters", r"parameter\(s\) \['q1'\] belong to no effect"),
    (lambda d: d.update(gravity=-9.8), "gravity", "gravity -9.8 is not a local gravity on Earth"),
    (lambda d: d.update(effects=[{"name": "warp_drive", "axes": ["x"]}]), "effects", "unknown effect 'warp_drive'"),
    (lambda d: d.update(effects=[{"name": "bias_drift", "axes": ["w"]}]), "effects[0].axes[0]", "axis 'w' is not x, y or z"),
    (lambda d: d.update(effects=[{"name": "bias_drift", "axes": ["x"]}]), "parameters", "do not match the model's"),
    (lambda d: d.update(effects="all"), "effects", "must be a list"),
    (lambda d: d.update(units=5), "units", "must be a mapping"),
    (lambda d: d["fit"].update(rms_residual="abc"), "fit.rms_residual", "is not an RMS"),
    (lambda d: d["fit"].update(rms_residual=-1e308), "fit.rms_residual", "is not an RMS"),
    (lambda d: d["fit"].update(rms_residual=[1, 2]), "fit.rms_residual", "is not an RMS"),
    (lambda d: d["fit"].update(temperature_range=[40.0, 20.0]), "fit.temperature_range", "min <= max"),
    (lambda d: d["fit"].update(temperature_range={"a": 1}), "fit.temperature_range", "is not a temperature range"),
])
def test_invalid_contents_are_refused(saved, tmp_path, mutate, field, match):
    d = _dict(saved)
    mutate(d)
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ImucalError, match=match) as ei:
        load_calibration(p)
    assert ei.value.field == field
    assert str(ei.value).startswith(str(p)) and "\n" not in str(ei.value)


def test_unreadable_files(tmp_path):
    with pytest.raises(ImucalError, match="file not found") as ei:
        load_calibration(tmp_path / "none.yaml")
    assert "imucal calibrate" in str(ei.value)
    p = tmp_path / "bad.yaml"
    p.write_text("format: [\n")
    with pytest.raises(ImucalError, match="is not valid YAML at line 2"):
        load_calibration(p)
    p.write_text("- 1\n- 2\n")
    with pytest.raises(ImucalError, match="top level is not a mapping"):
        load_calibration(p)
    p.write_bytes(b"\xff\xfe format")
    with pytest.raises(ImucalError, match="is not UTF-8 text"):
        load_calibration(p)
    with pytest.raises(ImucalError, match="is a directory, not a file"):
        load_calibration(tmp_path)


def test_from_dict_of_to_dict_is_identity(saved):
    cal, _ = saved
    back = from_dict(cal.to_dict())
    assert back.to_dict() == cal.to_dict()


def test_apply_checks_its_input(saved):
    cal, _ = saved
    with pytest.raises(ImucalError, match=r"raw data must have shape \(N, 3\) or \(3,\), got \(4,\)"):
        cal.apply(np.zeros(4))


def test_save_is_atomic(saved, tmp_path, monkeypatch):
    """A failing save leaves neither the file nor a temporary behind."""
    cal, _ = saved
    import imucal.calibration.fileformat as mod

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(mod, "dump_yaml", boom)
    with pytest.raises(RuntimeError):
        cal.save(tmp_path / "c.yaml")
    assert list(tmp_path.iterdir()) == []


# --- files written before the solver_scale rename and the model label ---------------------------
OLD = Path(__file__).parent / "data"


@pytest.mark.parametrize("name, fixed", [("calibration_v1_before_rename.yaml", False),
                                         ("calibration_v1_fixed_angles_before_rename.yaml", True)])
def test_files_written_before_the_rename_still_load(name, fixed):
    """Written by `imucal calibrate` (main, commit e33bd3e) on the shipped Xsens recording, with
    `scale:` per parameter and `model: nakov-ivanov-9` even for the 6-parameter fit."""
    path = OLD / name
    d = yaml.safe_load(path.read_text())
    assert "scale" in d["parameters"]["s1"] and d["model"] == "nakov-ivanov-9"
    cal = load_calibration(path)
    assert cal.params["s1"].scale == d["parameters"]["s1"]["scale"]
    assert all(cal.params[a].fixed == fixed for a in ("phi", "psi", "theta"))
    A, c = cal.linear_map()
    np.testing.assert_array_equal(A, np.array(d["apply"]["matrix"]))
    # saved again: the new names, and the same calibration back
    new = cal.to_dict()
    assert new["model"] == ("nakov-ivanov-6" if fixed else "nakov-ivanov-9")
    assert "solver_scale" in new["parameters"]["s1"] and "scale" not in new["parameters"]["s1"]
    assert new["units"]["gravity"] == "m/s^2"
    back = from_dict(new)
    np.testing.assert_array_equal(back.values, cal.values)


def test_derived_values_within_round_off_load(saved, tmp_path):
    d = _dict(saved)
    d["apply"]["matrix"][0][0] *= 1 + 1e-12
    d["apply"]["offset"][0] *= 1 + 1e-12
    p = tmp_path / "roundoff.yaml"
    p.write_text(yaml.safe_dump(d))
    load_calibration(p)


def test_edited_matrix_is_refused_through_the_cli(saved, tmp_path, run_cli, unchanged):
    d = _dict(saved)
    d["apply"]["offset"][0] += 1.0
    p = tmp_path / "edited.yaml"
    p.write_text(yaml.safe_dump(d))
    with unchanged(tmp_path):
        code, out, err = run_cli(["codegen", str(p), "--out", str(tmp_path / "gen")])
    assert code == 2
    assert err.strip().count("\n") == 0
    assert "apply.offset: disagrees with the parameters" in err and "do not edit apply.matrix" in err


@pytest.fixture(scope="module")
def warm_saved(tmp_path_factory):
    """A calibration with a bias warm-up (tau fitted) and a scale drift, from a simulated recording."""
    from conftest import calibrate_file
    from imucal.analysis.simulate import draw_effect_case

    case = draw_effect_case(50010, effect="bias_warmup", axes=(0, 1, 2), snr=40.0, noise_mg=0.3)
    d = tmp_path_factory.mktemp("warm")
    (d / "rec.csv").write_text(case.config.run().to_csv_text())
    run = calibrate_file(d / "rec.csv", data={"unit": case.config.sensor.unit},
                         fit={"effects": ["bias_warmup", "scale_drift"]})
    run.calibration.save(d / "calibration.yaml")
    return d / "calibration.yaml"


@pytest.mark.parametrize("name,value,bounds,whose", [
    ("bias_warmup_tau", 0.0, True, "file's"), ("bias_warmup_tau", -5.0, True, "file's"),
    ("bias_warmup_tau", 1e-300, False, "model's"), ("bias_warmup_tau", -5.0, False, "model's"),
    ("bias_warmup_tau", 1e308, False, "model's"), ("scale_drift_x", -1.0, True, "file's"),
    ("scale_drift_x", -1.0, False, "model's")])
def test_an_effect_value_never_fitted_is_refused(warm_saved, tmp_path, run_cli, name, value, bounds, whose):
    """A warm-up's tau at 0 or below made `apply` write NaN rows and the generated C return NaN or inf;
    a value outside the file's own bounds, or (bounds removed) the model's, was never fitted."""
    d = yaml.safe_load(warm_saved.read_text())
    load_calibration(warm_saved)  # the fitted file loads
    d["parameters"][name]["value"] = value
    if not bounds:
        d["parameters"][name].update(lower=None, upper=None)
    p = tmp_path / "edited.yaml"
    p.write_text(yaml.safe_dump(d, sort_keys=False))
    with pytest.raises(ImucalError, match=f"outside the {whose} bounds") as ei:
        load_calibration(p)
    assert ei.value.field == f"parameters.{name}.value"
    r = run_cli(["codegen", str(p), "--out", str(tmp_path / "c")])
    assert r.code == 2 and f"parameters.{name}.value" in r.err and not (tmp_path / "c").exists()


def test_a_long_parameter_list_makes_a_short_line(saved, tmp_path):
    """5,000 parameters that match no model: the message printed every name (390,000 characters)."""
    d = _dict(saved)
    d["effects"] = [{"name": "bias_drift", "axes": ["x"]}]
    d["parameters"].update({f"bias_drift_{i}": {"value": 0.0} for i in range(5000)})
    p = tmp_path / "many.yaml"
    p.write_text(yaml.safe_dump(d, sort_keys=False))
    with pytest.raises(ImucalError, match="do not match the model's") as ei:
        load_calibration(p)
    assert len(str(ei.value)) < 700
