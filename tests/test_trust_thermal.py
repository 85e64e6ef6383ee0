"""Hostile temperature sweeps, stated values and calibration files (the audit of the newer features): a
gyroscope channel that never changes, scales a run file states beyond what readings can carry, temperature
terms that swamp the map, a file in other units. Each is one line on stderr (exit 2) or a calibration,
never a traceback or a numpy warning."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from test_export_tempcal import BIAS, BIAS_COEFFS, calibration
from test_thermal import NOMINAL
from test_thermal_gyro import gyro_sweep
from imucal.calibration.frozen import load_calibration
from imucal.errors import ImucalError
from imucal.gyro.thermal import _select


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """test_thermal_gyro's sweep (z, x, y down over 5 -> 25 -> 5 degC, gx, gy, gz in rad/s) as an array."""
    path = gyro_sweep(tmp_path_factory.mktemp("sweep") / "sweep.csv")
    return np.loadtxt(path, delimiter=",", skiprows=1)


def write(path, data: np.ndarray) -> None:
    np.savetxt(path, data, delimiter=",", header="t,ax,ay,az,gx,gy,gz,temp", comments="", fmt="%.10g")


def number(v: float) -> str:
    """A float as YAML 1.1 reads it (1e-300 is text there, 1.0e-300 a number)."""
    s = repr(float(v))
    return s if "." in s else s.replace("e", ".0e")


def run_file(tmp_path, fix: dict) -> object:
    run = tmp_path / "run.yaml"
    run.write_text("data: {path: sweep.csv, time_unit: s, gyro_unit: rad/s}\n"
                   f"fit: {{fix: {{{', '.join(f'{k}: {number(v)}' for k, v in fix.items())}}}}}\n")
    return run


def test_an_exact_fit_of_a_gyroscope_axis_is_no_division_by_zero():
    pose = np.repeat([0, 1, 2], 20)
    P = (pose[:, None] == np.arange(3)[None, :]).astype(float)
    B = np.linspace(-1, 1, 60)[:, None] ** np.arange(1, 4)
    fit, ps = _select(np.zeros(60), P, B, 1e-3)  # a constant channel: nothing to add
    assert fit.order == 0 and ps == (1.0,)
    fit, ps = _select(P @ [1.0, 2.0, 3.0] + 0.5 * B[:, 0], P, B, 1e-3)  # exactly linear: the order found
    assert fit.order == 1 and ps[0] == 0.0


@pytest.mark.filterwarnings("error")
def test_a_sweep_whose_gyroscope_reads_zero_calibrates(sweep, tmp_path, run_cli):
    """gx, gy, gz all 0 (a gyroscope logged but not running): the order test divided by a zero misfit and the
    run ended as an internal error (ZeroDivisionError)."""
    data = sweep.copy()
    data[:, 4:7] = 0.0
    write(tmp_path / "sweep.csv", data)
    r = run_cli(["discover", "--config", run_file(tmp_path, NOMINAL), "--out", tmp_path / "cal"])
    assert r.code == 0, r.err
    gyro = load_calibration(tmp_path / "cal" / "calibration.yaml").attached[0]
    assert all(v == 0.0 for n, v in gyro.params.value_dict().items() if n.startswith("bias_temperature"))


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("b1", [1e-300, 1e300])
def test_a_stated_scale_no_reading_can_carry_is_one_line_on_a_sweep(sweep, tmp_path, run_cli, unchanged, b1):
    """fit.fix b1: 1e-300 squared to 0 in the rows' weights: numpy's 'divide by zero', then an internal error
    (LinAlgError); 1e300 overflowed."""
    write(tmp_path / "sweep.csv", sweep)
    run = run_file(tmp_path, {**NOMINAL, "b1": b1})
    with unchanged():
        r = run_cli(["discover", "--config", run, "--out", tmp_path / "cal"])
    assert r.code == 2 and r.err.count("\n") == 1, r.err
    assert r.err.startswith(f"imucal: error: {run}: fit.fix.b1: b1 = {b1:g} must be positive, within 1e-30 to 1e+30")


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("fit, field", [
    ("{fix: [s1, s2, s3], initial: {b1: 1.0e-300}}", "fit.initial.b1"),
    ("{fix: {s1: 0.0, s2: 0.0, s3: 0.0, b1: 1.0e+300, b2: 0.1, b3: 0.1, phi: 1.5707963267948966, "
     "psi: 1.5707963267948966, theta: 1.5707963267948966}}", "fit.fix.b1"),
    ("{initial: {s2: -1.0e+31}}", "fit.initial.s2")])
def test_a_stated_value_no_reading_can_carry_is_one_line(si_recording, tmp_path, run_cli, unchanged, fit, field):
    """fit.initial b1: 1e-300 was an internal error (LinAlgError 'SVD did not converge'), all nine stated with
    b1: 1e300 one too (OverflowError)."""
    run = tmp_path / "run.yaml"
    run.write_text(f"data: {{path: {si_recording.path}, unit: m/s^2}}\nfit: {fit}\n")
    with unchanged():
        r = run_cli(["calibrate", run, "--out", tmp_path / "out"])
    assert r.code == 2 and r.err.count("\n") == 1 and r.err.startswith(f"imucal: error: {run}: {field}: "), r.err


@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
@pytest.mark.parametrize("name, value", [("bias_temperature_x", 1e20), ("bias_temperature_tref", 1e20)])
def test_temperature_terms_that_swamp_the_map_are_one_line_in_the_exports(tmp_path, run_cli, fmt, name, value):
    """A coefficient or T_ref of 1e20 left A(T), read off the map by differences, singular: an internal error
    (LinAlgError 'Singular matrix') in both exports."""
    p = tmp_path / "cal.yaml"
    calibration(BIAS, BIAS_COEFFS).save(p)
    d = yaml.safe_load(p.read_text())
    d["parameters"][name]["value"] = value
    p.write_text(yaml.safe_dump(d, sort_keys=False))
    r = run_cli(["export", p, "--format", fmt, "--out", tmp_path / "x.param"])
    assert r.code == 2 and r.err.count("\n") == 1, r.err
    assert f"{p}: parameters: the temperature terms leave no invertible map" in r.err
    assert not (tmp_path / "x.param").exists()


@pytest.mark.parametrize("key, value", [("temperature", "degF"), ("temperature", "degC */"), ("time", "ms"),
                                        ("angles", "deg"), ("output", "g")])
def test_a_file_stating_other_units_is_refused(tmp_path, key, value):
    """units.temperature degF was read, and applied, as degC (and 'degC */' taken as well)."""
    p = tmp_path / "cal.yaml"
    calibration(BIAS, BIAS_COEFFS).save(p)
    d = yaml.safe_load(p.read_text())
    d["units"][key] = value
    p.write_text(yaml.safe_dump(d, sort_keys=False))
    with pytest.raises(ImucalError, match=" is not ") as e:
        load_calibration(p)
    assert e.value.field == f"units.{key}" and "\n" not in str(e.value)


@pytest.mark.parametrize("temp, shown", [(-400.0, "-400"), (1e25, "1e+25")])
def test_a_temperature_no_sensor_reads_is_one_line(sweep, tmp_path, run_cli, unchanged, temp, shown):
    """A sweep with temperatures below absolute zero (or one sample at 1e25 degC) was calibrated, and the
    file then refused by the exports ('not a temperature in degC')."""
    data = sweep.copy()
    data[100, 7] = temp
    write(tmp_path / "sweep.csv", data)
    run = run_file(tmp_path, NOMINAL)
    with unchanged():
        r = run_cli(["discover", "--config", run, "--out", tmp_path / "cal"])
    assert r.code == 2 and r.err.count("\n") == 1, r.err
    assert f"sweep.csv: data.columns.temp: sample 100 holds temperature {shown} degC" in r.err


def test_apply_says_when_it_extrapolates_the_temperature_terms(tmp_path, run_cli):
    """Data at 80..129 degC through terms fitted over 15..45 degC were corrected without a word (the cubic
    extrapolated; the autopilots hold the end value): a warning names how many samples and the ranges."""
    p = tmp_path / "cal.yaml"
    calibration(BIAS, BIAS_COEFFS).save(p)
    rows = "".join(f"{i},0.1,0.2,9.8,{t:g}\n" for i, t in enumerate(list(range(80, 130)) + [14.0, 47.0]))
    (tmp_path / "hot.csv").write_text("t,ax,ay,az,temp\n" + rows)
    r = run_cli(["apply", p, "--data", tmp_path / "hot.csv", "--time-unit", "s", "--unit", "m/s^2", "--out",
                 tmp_path / "out.csv", "--no-gravity-check"])
    assert r.code == 0, r.err
    assert ("imucal: warning: 50 of 52 samples are at temperatures well outside the 15..45 degC the calibration's "
            "temperature terms were fitted over (the data span 14..129 degC)") in r.err, r.err
    (tmp_path / "mild.csv").write_text("t,ax,ay,az,temp\n" + "".join(f"{i},0.1,0.2,9.8,{14 + i}\n" for i in range(34)))
    r = run_cli(["apply", p, "--data", tmp_path / "mild.csv", "--time-unit", "s", "--unit", "m/s^2", "--out",
                 tmp_path / "out2.csv", "--no-gravity-check"])
    assert r.code == 0 and "temperatures" not in r.err, r.err  # within a tenth of the range beyond its ends


@pytest.mark.parametrize("how", ["never", "always"])
def test_a_temperature_no_sensor_reads_is_refused_by_both_readers(sweep, tmp_path, run_cli, unchanged, how):
    """The file read in chunks (above 64 MB, or --stream always) builds no Recording: its parse refuses the same
    sample in the same words (it calibrated before)."""
    data = sweep[:, [0, 1, 2, 3, 7]].copy()  # no gyroscope: reading in chunks keeps none
    data[100, 4] = -400.0
    np.savetxt(tmp_path / "sweep.csv", data, delimiter=",", header="t,ax,ay,az,temp", comments="", fmt="%.10g")
    with unchanged():
        r = run_cli(["calibrate", "--data", tmp_path / "sweep.csv", "--time-unit", "s", "--stream", how,
                     "--fix-angles", "--out", tmp_path / "cal"])
    assert r.code == 2 and r.err.count("\n") == 1, r.err
    assert "sweep.csv: data.columns.temp: sample 100 holds temperature -400 degC" in r.err, r.err
