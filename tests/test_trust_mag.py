"""Hostile magnetometer inputs (the audit of the newer features): a log whose magnetometer never changes or
holds values near the smallest floats, a coarsely quantised one, a dip the data contradict, units and dates of
the run file's ``mag:`` section. Each is one line on stderr (exit 2) or a calibration, never a traceback or a
numpy or CasADi warning, and a refusal leaves nothing behind."""
from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from imucal.config.run import MagConfig, config_from_dict
from imucal.errors import ImucalError
from imucal.mag.checks import missing_directions
from imucal.mag.evidence import sample_variance
from imucal.mag.simulate import simulate_mag, truth_from_soft_iron

SOFT = np.array([[1.05, 0.03, -0.02], [0.03, 0.97, 0.01], [-0.02, 0.01, 1.01]])


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    """A 9-axis log in g (no time column, 50 Hz): 30 still poses, the field 48 uT with hard iron."""
    truth = truth_from_soft_iron(SOFT, s=(10.0, -5.0, 3.0), field=48.0, noise=0.1, acc_noise=0.002)
    sim = simulate_mag(truth, n_poses=30, hold=150, transition=40, seed=3)
    return np.column_stack([sim.acc, sim.mag])


def write(path, data: np.ndarray) -> None:
    np.savetxt(path, data, delimiter=",", header="ax,ay,az,mx,my,mz", comments="", fmt="%.8g")


def calibrate(run_cli, tmp_path, *extra):
    return run_cli(["calibrate", "--data", tmp_path / "log.csv", "--unit", "g", "--sample-rate", "50",
                    "--mag-field", "48uT", "--no-figures", "--out", tmp_path / "out", *extra])


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("case", ["constant", "zero", "1e-300"])
def test_a_magnetometer_that_holds_no_field_is_one_line(log, tmp_path, run_cli, unchanged, case):
    """Constant and all-zero columns printed numpy's 'invalid value encountered in divide' before the refusal;
    readings times 1e-300 printed 'divide by zero' and ended with 'parameters.s1.scale: ... got nan'."""
    data = log.copy()
    data[:, 3:] = {"constant": (1.0, 2.0, 3.0), "zero": 0.0, "1e-300": data[:, 3:] * 1e-300}[case]
    write(tmp_path / "log.csv", data)
    with unchanged():
        r = calibrate(run_cli, tmp_path)
    assert r.code == 2 and r.err.count("\n") == 1, r.err
    assert r.err.startswith(f"imucal: error: {tmp_path / 'log.csv'}: mx, my, mz: ") and "fix: " in r.err


def test_the_directions_to_add_ignore_readings_at_the_centre():
    with np.errstate(all="raise"):
        assert sorted(missing_directions(np.zeros((5, 3)))) == ["+x", "+y", "+z", "-x", "-y", "-z"]
        d = np.vstack([np.zeros(3), np.eye(3), -np.eye(3)])
        assert all(len(w) == 4 for w in missing_directions(d))  # the faces covered: the edges come next


def test_a_coarsely_quantised_magnetometer_calibrates(log, tmp_path, run_cli, recwarn):
    """Readings in steps of 5 (the noise below one step): the noise estimate was 0, the coverage check's
    weights overflowed and the run ended as an internal error (LinAlgError). A quantiser's noise is at least
    its step^2 / 12."""
    data = log.copy()
    data[:, 3:] = np.round(data[:, 3:] / 5.0) * 5.0
    write(tmp_path / "log.csv", data)
    assert np.all(sample_variance(data[:, 3:]) >= 25.0 / 12)
    r = calibrate(run_cli, tmp_path)
    assert r.code == 0, r.err
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


def test_a_dip_the_data_contradict_prints_no_solver_warnings(log, tmp_path, capfd):
    """mag.dip_deg 60 on a log whose dip is -60: IPOPT's trial points give a NaN objective, which CasADi
    printed thirty times as 'WARNING(... NaN detected for output f ...)'. The fit's status says it."""
    from imucal.cli.main import main

    write(tmp_path / "log.csv", log)
    run = tmp_path / "run.yaml"
    run.write_text("data: {path: log.csv, unit: g, sample_rate: 50}\nmag: {field: 48, dip_deg: 60}\n")
    code = main(["calibrate", str(run), "--no-figures", "--quiet", "--out", str(tmp_path / "out")])
    err = capfd.readouterr().err
    assert code in (0, 1) and "WARNING(" not in err and "CasADi" not in err, err


@pytest.mark.parametrize("unit", ["x_y", "/", "a/", "a" * 20, "*/"])
def test_a_mag_unit_the_calibration_file_would_refuse_is_refused_first(log, tmp_path, run_cli, unchanged, unit):
    """mag.unit x_y, /, a/ and 20 letters (the field fitted: the scales' unit unit/unit over 40) were taken;
    the calibration file written then was refused by apply, codegen and export."""
    write(tmp_path / "log.csv", log)
    with unchanged():
        r = calibrate(run_cli, tmp_path, "--mag-unit", unit)
    assert r.code == 2 and r.err.count("\n") == 1 and "--mag-unit: unit " in r.err, r.err


def test_a_mag_unit_it_takes_is_one_the_file_reads_back(log, tmp_path, run_cli):
    write(tmp_path / "log.csv", log)
    r = run_cli(["calibrate", "--data", tmp_path / "log.csv", "--unit", "g", "--sample-rate", "50", "--mag-unit",
                 "a" * 19, "--no-figures", "--out", tmp_path / "out"])
    assert r.code == 0, r.err
    r = run_cli(["codegen", tmp_path / "out" / "calibration.yaml", "--out", tmp_path / "c" / "imu"])
    assert r.code == 0, r.err


def test_a_date_yaml_reads_unquoted_is_a_date():
    """date: 2024-05-17 (YAML's date, not text) was refused as "date datetime.date(2024, 5, 17) is not a date"."""
    cfg = config_from_dict({"data": {"path": "log.csv"},
                            "mag": {"latitude": 45.0, "longitude": 7.0, "date": dt.date(2024, 5, 17)}})
    assert cfg.mag.date == "2024-05-17"
    with pytest.raises(ImucalError, match="is not a date") as e:
        MagConfig(latitude=45.0, longitude=7.0, date="2024-13-45")
    assert e.value.field == "mag.date"


def test_a_bad_date_names_the_run_file(tmp_path, run_cli):
    run = tmp_path / "run.yaml"
    run.write_text("data: {path: log.csv}\nmag: {latitude: 45, longitude: 7, date: \"not a date\"}\n")
    r = run_cli(["calibrate", run, "--out", tmp_path / "out"])
    assert r.code == 2 and r.err.startswith(f"imucal: error: {run}: mag.date: "), r.err


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("case, words", [("text", "not real numbers"), ("complex", "not real numbers"),
                                         ("1e200", r"beyond \+-1e\+30")])
def test_the_api_refuses_magnetometer_arrays_a_file_could_not_hold(log, case, words):
    """imucal.calibrate(acc, mag=...) raised ValueError on text, warned ComplexWarning (dropping the imaginary
    part) on complex readings and ended in OverflowError on readings of 1e200 (a file's beyond 1e30 are refused)."""
    import imucal

    mag = {"text": np.full(log[:, 3:].shape, "x"), "complex": log[:, 3:] + 1j,
           "1e200": log[:, 3:] * 1e200}[case]
    with pytest.raises(ImucalError, match=words) as e:
        imucal.calibrate(log[:, :3] * 9.80665, mag=mag, fs=50.0, mag_field=48.0, mag_field_unit="uT")
    assert e.value.field == "mag" and "\n" not in str(e.value)


def test_mag_settings_for_a_log_without_a_magnetometer_are_said_not_dropped(log, tmp_path, run_cli):
    """--mag-field (or a mag: section) beside a log without mx, my, mz calibrated the accelerometer alone
    without a word: the user asked for a magnetometer and got none."""
    np.savetxt(tmp_path / "acc.csv", log[:, :3], delimiter=",", header="ax,ay,az", comments="", fmt="%.8g")
    r = run_cli(["calibrate", "--data", tmp_path / "acc.csv", "--unit", "g", "--sample-rate", "50", "--mag-field",
                 "48uT", "--no-figures", "--out", tmp_path / "out"])
    assert r.code == 0, r.err
    said = f"magnetometer: mag settings given, but {tmp_path / 'acc.csv'} has no mx, my, mz"
    assert said in r.err and said in (tmp_path / "out" / "report.txt").read_text()
    r = run_cli(["calibrate", "--data", tmp_path / "acc.csv", "--unit", "g", "--sample-rate", "50", "--no-figures",
                 "--out", tmp_path / "plain"])
    assert r.code == 0 and "magnetometer" not in r.err, r.err


def test_a_magnetometer_mapped_in_a_netcdf_file_is_calibrated(log, tmp_path, run_cli):
    """data.columns.mx in a netCDF file was ignored (the accelerometer calibrated alone, the mapping unsaid),
    then refused; now it is read in the unit its units attribute states (tests/test_netcdf_mag.py)."""
    import h5py

    from imucal.calibration.frozen import load_calibration

    with h5py.File(tmp_path / "log.nc", "w") as f:
        v = f.create_dataset("acc", data=log[:, :3])
        v.attrs["units"], v.attrs["sampling_rate"] = "g", np.array([50.0])
        f.create_dataset("mag", data=log[:, 3:]).attrs["units"] = "uT"
    r = run_cli(["calibrate", "--data", tmp_path / "log.nc", "--columns", "mx=mag", "--mag-field", "48uT",
                 "--no-figures", "--out", tmp_path / "out"])
    assert r.code == 0, r.err
    mag = load_calibration(tmp_path / "out" / "calibration.yaml").sensor("magnetometer")
    assert mag is not None and mag.raw_unit == "uT"


def test_the_ardupilot_export_says_when_its_arming_check_refuses_the_offsets(tmp_path, run_cli):
    """A hard iron of 250 uT (2500 mG) was exported as COMPASS_OFS without a word: ArduPilot's arming check
    refuses offsets longer than COMPASS_OFFS_MAX (default 1800 mG)."""
    truth = truth_from_soft_iron(SOFT, s=(250.0, 0.0, 0.0), field=48.0, noise=0.1, acc_noise=0.002)
    sim = simulate_mag(truth, n_poses=30, hold=150, transition=40, seed=3)
    write(tmp_path / "log.csv", np.column_stack([sim.acc, sim.mag]))
    r = calibrate(run_cli, tmp_path, "--mag-unit", "uT")
    assert r.code == 0, r.err
    r = run_cli(["export", tmp_path / "out" / "calibration.yaml", "--format", "ardupilot", "--out", tmp_path / "x.param"])
    assert r.code == 0, r.err
    assert "COMPASS_OFFS_MAX's default 1800 mG: ArduPilot refuses to arm" in r.out + r.err
    assert "set COMPASS_OFFS_MAX to at least 25" in r.out + r.err


@pytest.mark.parametrize("unit, looks", [("gauss", "uT"), ("nT", "uT"), ("mT", "uT")])
def test_readings_in_another_field_unit_than_stated_are_named(log, tmp_path, run_cli, unit, looks):
    """Readings of about 48 (uT) stated as gauss calibrated to scales of 99 gauss per gauss without a word, and
    the exports then wrote offsets 100 times too large."""
    write(tmp_path / "log.csv", log)
    r = calibrate(run_cli, tmp_path, "--mag-unit", unit)
    assert r.code == 0, r.err
    assert f"the readings are not in {unit} (they look like {looks}: give mag.unit {looks}" in r.err, r.err
    r = calibrate(run_cli, tmp_path, "--mag-unit", "uT")
    assert r.code == 0 and "the readings are not in" not in r.err, r.err


@pytest.mark.parametrize("fmt", ["imutk", "madlab", "matrix", "kalibr"])
def test_a_format_without_a_magnetometer_says_it_drops_it(log, tmp_path, run_cli, fmt):
    """imu_tk, mad-lab, matrix and Kalibr files hold no magnetometer: it was dropped without a word, where the
    gyroscope's dropped terms are stated."""
    write(tmp_path / "log.csv", log)
    assert calibrate(run_cli, tmp_path).code == 0
    r = run_cli(["export", tmp_path / "out" / "calibration.yaml", "--format", fmt, "--out", tmp_path / f"x.{fmt}"])
    assert r.code == 0, r.err
    assert "magnetometer not exported: this format holds none" in r.out + r.err


def test_a_soft_iron_beyond_the_models_bound_is_named(log, tmp_path, run_cli):
    """An off-diagonal soft iron of 0.6 (a magnet or steel next to the sensor) takes an angle to its bound of
    90 deg +- 22.5 deg; before, the warning said only that the solver stopped. A board's soft iron is not named."""
    strong = truth_from_soft_iron(np.array([[1.0, 0.6, 0.0], [0.6, 1.0, 0.0], [0.0, 0.0, 1.0]]), s=(10.0, -5.0, 3.0),
                                  field=48.0, noise=0.1, acc_noise=0.002)
    sim = simulate_mag(strong, n_poses=30, hold=150, transition=40, seed=3)
    write(tmp_path / "log.csv", np.column_stack([sim.acc, sim.mag]))
    r = calibrate(run_cli, tmp_path)
    assert "the soft iron's angle(s) phi reached their bound (90 deg +- 22.5 deg)" in r.err, r.err
    write(tmp_path / "log.csv", log)
    r = calibrate(run_cli, tmp_path)
    assert r.code == 0 and "reached their bound" not in r.err, r.err
