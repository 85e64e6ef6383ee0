"""Units no file or option may state wrongly unsaid (trust34): a netCDF temperature whose units imucal does not
know, a temperature in kelvin read as degC, a field magnitude in the readings' own unit far from their field, a
calibration file whose parameter unit labels are not the model's, and what the PX4 export says of the
magnetometer's offsets. Each is one line naming the file, the field and the fix, or a note that cites its source."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from imucal.calibration.frozen import load_calibration
from imucal.data.load import DataSpec, load_recording
from imucal.errors import ImucalError
from test_calibration_sensors import V2
from test_netcdf import write_nc
from test_trust_mag import SOFT, calibrate, log, write  # noqa: F401  (log: the module's fixture)


def one_line(r, start: str) -> str:
    assert r.code == 2 and r.err.count("\n") == 1 and "Traceback" not in r.err, (r.out, r.err)
    assert r.err.startswith("imucal: error: " + start), r.err
    return r.err


# --- 1. a netCDF temperature whose units are not known ---------------------------------------------------------

@pytest.mark.parametrize("units, said", [("rankine", "has units 'rankine'"), (None, "has no units attribute")])
def test_a_netcdf_temperature_in_unknown_units_is_named_not_dropped(tmp_path, run_cli, unchanged, units, said):
    """A variable board_temp in units imucal does not know (or none) was not taken as the temperature, and a sweep
    then had none, without a word."""
    n = 40
    path = write_nc(tmp_path / "t.nc", np.tile([0.0, 0.0, 9.8], (n, 1)), np.arange(n, dtype=float),
                    temp=np.full(n, 20.0), temp_units=units, names={"temp": "board_temp"})
    with unchanged(tmp_path):
        r = run_cli(["calibrate", "--data", path, "--out", tmp_path / "out", "--no-figures"])
    err = one_line(r, f"{path}: board_temp.units: variable 'board_temp' looks like the temperature (temp) but {said}")
    assert "it would be left unread" in err and "fix: set its units to read it (ncatted -a units,board_temp,o,c," in err


def test_a_netcdf_variable_described_as_temperature_is_named_too(tmp_path):
    import h5py

    n = 20
    path = write_nc(tmp_path / "t.nc", np.tile([0.0, 0.0, 9.8], (n, 1)), np.arange(n, dtype=float))
    with h5py.File(path, "a") as f:
        f.create_dataset("ch7", data=np.full(n, 20.0)).attrs["long_name"] = "IMU Temperature"
    with pytest.raises(ImucalError, match="variable 'ch7' looks like the temperature") as e:
        load_recording(str(path))
    assert e.value.field == "ch7.units"


@pytest.mark.parametrize("units", ["degrees C", "degree_C", "degrees_K", "degree_Fahrenheit"])
def test_common_temperature_spellings_are_read(tmp_path, units):
    n = 20
    rec = load_recording(str(write_nc(tmp_path / "t.nc", np.tile([0.0, 0.0, 9.8], (n, 1)), np.arange(n, dtype=float),
                                      temp=np.full(n, 290.0 if "K" in units else 21.5), temp_units=units)))
    want = {"degrees C": 21.5, "degree_C": 21.5, "degrees_K": 290.0 - 273.15, "degree_Fahrenheit": (21.5 - 32) * 5 / 9}
    np.testing.assert_allclose(rec.temp, want[units])


def test_a_netcdf_channel_of_fill_values_only_is_named(tmp_path):
    n = 20
    path = write_nc(tmp_path / "f.nc", np.tile([0.0, 0.0, 9.8], (n, 1)), np.arange(n, dtype=float),
                    temp=np.full(n, np.nan))
    with pytest.raises(ImucalError, match=r"all fill values: 'temperature' holds no value\)"):
        load_recording(str(path))
    path = write_nc(tmp_path / "e.nc", np.zeros((0, 3)), np.zeros(0))
    with pytest.raises(ImucalError, match="variable 'acceleration' holds no samples"):
        load_recording(str(path))



# --- a temperature in kelvin labelled degC ---------------------------------------------------------------------

@pytest.mark.parametrize("stream", ["never", "always"])
def test_a_temperature_in_kelvin_is_refused_not_read_as_300_degc(tmp_path, stream):
    """A temp column of 293..300 (kelvin) was read as 293..300 degC: below the 1000 degC corrupt-value bound, so a
    sweep was fitted at temperatures no sensor works at, and its terms exported as such."""
    t = np.arange(200) / 50.0
    data = np.column_stack([t, np.zeros(200), np.zeros(200), np.full(200, 9.8), np.linspace(293.15, 300.0, 200)])
    path = tmp_path / "k.csv"
    np.savetxt(path, data, delimiter=",", header="t,ax,ay,az,temp", comments="", fmt="%.6g")
    with pytest.raises(ImucalError) as e:
        load_recording(DataSpec(path=str(path), stream=stream))
    assert e.value.field == "data.columns.temp" and str(e.value).startswith(str(path))
    assert "above any MEMS sensor's operating range (at most 200 degC): kelvin (" in str(e.value)
    assert "fix: give the temperature in degC (kelvin less 273.15)" in str(e.value)


def test_a_hot_sensor_in_degc_is_read():
    from imucal.data.recording import temperature_error

    assert temperature_error(np.linspace(-40.0, 150.0, 50), "x.csv") is None


# --- 2. a field magnitude in the readings' own unit far from their field ----------------------------------------

@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("field", ["1e-300", "1e-6", "1e9", "1e308"])
def test_a_field_in_the_readings_unit_far_from_their_field_is_one_line(log, tmp_path, run_cli, unchanged, field):
    """--mag-field 1e-300 (no unit: the readings' own) ended as an internal error (LinAlgError), 1e308 as an
    OverflowError, and 1e9 or 1e-6 calibrated to scales of 1e-7 or 1e7 without a word."""
    write(tmp_path / "log.csv", log)
    with unchanged():
        r = run_cli(["calibrate", "--data", tmp_path / "log.csv", "--unit", "g", "--sample-rate", "50",
                     "--mag-field", field, "--no-figures", "--out", tmp_path / "out"])
    err = one_line(r, f"{tmp_path / 'log.csv'}: mag.field: field magnitude {float(field):g} raw is ")
    assert "times the readings' field (about 4" in err and "fix: give the field with its unit" in err


def test_a_field_in_the_readings_unit_near_their_field_calibrates(log, tmp_path, run_cli):
    write(tmp_path / "log.csv", log)
    r = run_cli(["calibrate", "--data", tmp_path / "log.csv", "--unit", "g", "--sample-rate", "50",
                 "--mag-field", "40", "--no-figures", "--quiet", "--out", tmp_path / "out"])
    assert r.code == 0, r.err


@pytest.mark.parametrize("field", [0.0, -48.0, float("nan"), float("inf")])
def test_the_api_refuses_a_field_that_is_no_magnitude(log, field):
    from imucal.mag.calibrate import MagSettings, calibrate_mag

    with pytest.raises(ImucalError, match="must be a positive number") as e:
        calibrate_mag(log[:, 3:], settings=MagSettings(field=field))
    assert e.value.field == "mag.field"


# --- 3. a calibration file's parameter unit labels --------------------------------------------------------------

@pytest.fixture(scope="module")
def mag_file(log, tmp_path_factory):
    from imucal.cli.main import main

    root = tmp_path_factory.mktemp("magcal")
    write(root / "log.csv", log)
    assert main(["calibrate", "--data", str(root / "log.csv"), "--unit", "g", "--sample-rate", "50", "--mag-field",
                 "48uT", "--mag-unit", "uT", "--no-figures", "--quiet", "--out", str(root / "out")]) == 0
    return yaml.safe_load((root / "out" / "calibration.yaml").read_text())


def _edited(d: dict, where: list[str], unit: str, path: Path) -> Path:
    entry = d
    for k in where:
        entry = entry[k]
    entry["unit"] = unit
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    return path


@pytest.mark.parametrize("where, unit, field, want", [
    (["parameters", "s1"], "m/s^2", "parameters.s1.unit", "'g'"),
    (["parameters", "b2"], "raw/(m/s^2)", "parameters.b2.unit", "'g/(m/s^2)'"),
    (["magnetometer", "parameters", "s1"], "mG", "magnetometer.parameters.s1.unit", "'uT'"),
    (["magnetometer", "parameters", "F"], "nT", "magnetometer.parameters.F.unit", "'uT'"),
    (["magnetometer", "parameters", "b3"], "uT/mG", "magnetometer.parameters.b3.unit", "'uT/uT'"),
])
def test_a_parameter_unit_label_the_model_does_not_give_is_refused(mag_file, tmp_path, run_cli, unchanged, where,
                                                                   unit, field, want):
    """A file edited to state a bias in another unit was taken as is: the number applied as if in the model's."""
    import copy

    path = _edited(copy.deepcopy(mag_file), where, unit, tmp_path / "cal.yaml")
    with unchanged(tmp_path):
        r = run_cli(["export", path, "--format", "ardupilot", "--out", tmp_path / "x.param"])
    err = one_line(r, f"{path}: {field}: {where[-1]} is labelled {unit!r}, but the model with input unit ")
    assert f"has it in {want} (the number is not converted)" in err and "fix: write unit: " in err


def test_a_gyroscope_bias_labelled_in_another_unit_is_refused(tmp_path):
    d = load_calibration(V2).to_dict()
    path = _edited(d, ["gyroscope", "parameters", "bias_x"], "deg/s", tmp_path / "g.yaml")
    with pytest.raises(ImucalError) as e:
        load_calibration(path)
    assert e.value.field == "gyroscope.parameters.bias_x.unit"
    assert "bias_x is labelled 'deg/s', but the model with input unit 'raw' has it in 'raw'" in str(e.value)


def test_the_unit_labels_calibrate_writes_read_back(mag_file, tmp_path):
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump(mag_file, sort_keys=False))
    assert load_calibration(path).sensor("magnetometer") is not None


# --- 5. the PX4 export of a magnetometer ---------------------------------------------------------------------------

def test_the_px4_export_says_what_px4_checks_of_the_magnetometer(mag_file, tmp_path, run_cli):
    """The ArduPilot export names COMPASS_OFFS_MAX; the PX4 one said nothing of PX4's own rules: no limit on the
    offsets (its metadata and pre-arm check cited), CAL_MAG0_ROT for an external magnetometer only."""
    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump(mag_file, sort_keys=False))
    r = run_cli(["export", path, "--format", "px4", "--out", tmp_path / "px4.params"])
    assert r.code == 0, r.err
    text = " ".join(line.lstrip("# ") for line in (tmp_path / "px4.params").read_text().splitlines())
    assert "PX4 sets no limit on the offsets (no COMPASS_OFFS_MAX as ArduPilot has)" in text
    assert "(magnetometerCheck.cpp) asks only a CAL_MAG0_ID equal to the device's id" in text
    assert "PX4 forces an internal one's to -1 and rotates it by the board's SENS_BOARD_ROT" in text
    assert "outside the range PX4's parameter metadata gives" not in r.out


def test_a_px4_scale_outside_its_metadata_range_is_said():
    from imucal.export.mag_autopilot import _px4_scale_note

    assert _px4_scale_note(np.diag([1.0, 0.9, 1.1])) == ()
    note = _px4_scale_note(np.diag([3.5, 1.0, 0.05]))[0]
    assert note.startswith("CAL_MAG0_XSCALE = 3.5, CAL_MAG0_ZSCALE = 0.05 outside the range PX4's parameter metadata "
                           "gives the scales (0.1 to 3, src/modules/sensors/module.yaml)")


# --- 4. the magnetometer's lag in apply ----------------------------------------------------------------------------

def test_apply_moves_the_magnetometer_by_its_lag_and_says_so(tmp_path, run_cli):
    """The lag was estimated and taken out of the fit, but apply paired mag[k] with acc[k] (the report did not say
    it): the calibrated field of a log on the move lagged its attitude by 3 samples."""
    from imucal.mag.simulate import simulate_mag, truth_from_soft_iron

    truth = truth_from_soft_iron(SOFT, s=(10.0, -5.0, 3.0), field=48.0, noise=0.1, acc_noise=0.002, lag=3.0)
    sim = simulate_mag(truth, n_poses=30, hold=150, transition=40, seed=3)
    data = np.column_stack([np.arange(len(sim.acc)) / 50.0, sim.acc, sim.mag])
    np.savetxt(tmp_path / "log.csv", data, delimiter=",", header="t,ax,ay,az,mx,my,mz", comments="", fmt="%.8g")
    r = run_cli(["calibrate", "--data", tmp_path / "log.csv", "--unit", "g", "--mag-field", "48uT", "--mag-unit", "uT",
                 "--no-figures", "--quiet", "--out", tmp_path / "cal"])
    assert r.code == 0, r.err
    report = (tmp_path / "cal" / "report.txt").read_text()
    assert "lag: mx, my, mz lag the accelerometer by 3" in report
    assert "`imucal apply` moves them earlier by the nearest whole number of samples" in report
    assert "the generated C and the exports do not: pair mag[k] with acc[k - lag] in firmware" in report
    fit = yaml.safe_load((tmp_path / "cal" / "calibration.yaml").read_text())["magnetometer"]["fit"]
    assert fit["lag_s"] == pytest.approx(fit["lag_samples"] / 50.0)
    r = run_cli(["apply", tmp_path / "cal" / "calibration.yaml", "--data", tmp_path / "log.csv", "--unit", "g",
                 "--out", tmp_path / "out.csv"])
    assert r.code == 0, r.err
    assert ("mx, my, mz moved 3 samples earlier (the magnetometer's lag behind the accelerometer): the last 3 rows' "
            "mx, my, mz are nan") in r.out
    out = np.loadtxt(tmp_path / "out.csv", delimiter=",", skiprows=1)
    assert np.isnan(out[-3:, 4:]).all() and np.isfinite(out[:-3]).all()
    cal = load_calibration(tmp_path / "cal" / "calibration.yaml")
    want = cal.apply_all({"accelerometer": sim.acc[:-3], "magnetometer": sim.mag[3:]})["magnetometer"]
    np.testing.assert_allclose(out[:-3, 4:], want, rtol=1e-7, atol=1e-6)
    # the generated C does not shift: its header says so, with the lag, where it was silent
    r = run_cli(["codegen", tmp_path / "cal" / "calibration.yaml", "--out", tmp_path / "c"])
    assert r.code == 0, r.err
    header = " ".join((tmp_path / "c" / "imucal.h").read_text().split()).replace(" * ", " ")
    assert (f"Time: raw_m lags the accelerometer's readings by {fit['lag_s']:.4g} s ({fit['lag_samples']:.3g} samples "
            "at the recording's rate); this function does not shift it: pass raw_m read that much later (raw_m[k + lag] "
            "with the accelerometer's sample k), as `imucal apply` does.") in header
    assert header.count("Time:") == 1  # the accelerometer's block has no lag
    # a log at twice the rate: the same lag in seconds is twice the samples
    data[:, 0] /= 2.0
    np.savetxt(tmp_path / "fast.csv", data, delimiter=",", header="t,ax,ay,az,mx,my,mz", comments="", fmt="%.8g")
    r = run_cli(["apply", tmp_path / "cal" / "calibration.yaml", "--data", tmp_path / "fast.csv", "--unit", "g",
                 "--out", tmp_path / "fast_out.csv", "--no-gravity-check"])
    assert r.code == 0 and "mx, my, mz moved 6 samples earlier" in r.out, r.err


def test_the_lag_in_whole_samples():
    from imucal.mag.run import lag_samples, shift_lag

    assert lag_samples({"lag_samples": 3.2, "lag_s": 0.064}, 100.0) == 6
    assert lag_samples({"lag_samples": 3.2}, 100.0) == 3  # a file without lag_s: its samples
    assert lag_samples({}, 50.0) == 0 and lag_samples({"lag_samples": float("nan")}, 50.0) == 0
    m = np.arange(12.0).reshape(4, 3)
    np.testing.assert_array_equal(shift_lag(m, 1)[:3], m[1:])
    np.testing.assert_array_equal(shift_lag(m, -1)[1:], m[:3])
    assert np.isnan(shift_lag(m, 1)[3]).all() and np.isnan(shift_lag(m, -1)[0]).all() and np.isnan(shift_lag(m, 9)).all()


def test_apply_refuses_a_magnetometer_in_another_unit(log, tmp_path, run_cli, unchanged):
    """A log in nT applied to a calibration of readings in uT wrote a field of 48000 'uT' without a word (the
    accelerometer's |a| at rest is checked, the magnetometer's |h| was not)."""
    write(tmp_path / "log.csv", log)
    assert calibrate(run_cli, tmp_path, "--mag-unit", "uT").code == 0
    data = log.copy()
    data[:, 3:] *= 1000.0
    write(tmp_path / "nT.csv", data)
    with unchanged():
        r = run_cli(["apply", tmp_path / "out" / "calibration.yaml", "--data", tmp_path / "nT.csv", "--unit", "g",
                     "--sample-rate", "50", "--out", tmp_path / "a.csv"])
    err = one_line(r, f"{tmp_path / 'nT.csv'}: data.columns.mx: |h| after calibration is ")
    assert "where the calibration's field is 48 uT: mx, my, mz are not in its input unit uT" in err
    r = run_cli(["apply", tmp_path / "out" / "calibration.yaml", "--data", tmp_path / "nT.csv", "--unit", "g",
                 "--sample-rate", "50", "--out", tmp_path / "a.csv", "--no-gravity-check"])
    assert r.code == 0 and "imucal: warning: |h| after calibration is " in r.err, r.err


# --- the hunt: units and clocks the data contradict ----------------------------------------------------------------

def test_accelerometer_readings_in_another_unit_than_stated_are_refused(log, tmp_path, run_cli, unchanged):
    """A 9-axis log in m/s^2 stated as g calibrated without a word (scales of 9.8 g per m/s^2): the calibration
    then carried 'g' into the exports, which convert g to m/s^2 again (PX4's offsets 9.8 times too large)."""
    data = log.copy()
    data[:, :3] *= 9.80665
    write(tmp_path / "log.csv", data)
    with unchanged():
        r = calibrate(run_cli, tmp_path)
    err = one_line(r, f"{tmp_path / 'log.csv'}: data.unit: the readings at rest are 9.807 g (median |mean| of ")
    assert "where readings in g are 1: they are not in g (fix: they look like m/s^2: give data.unit m/s^2" in err


def test_a_netcdf_acceleration_in_g_labelled_m_per_s2_is_refused(log, tmp_path, run_cli, unchanged):
    path = write_nc(tmp_path / "s.nc", log[:, :3], np.arange(len(log)) / 50.0)  # in g, its units m/s2
    with unchanged(tmp_path):
        r = run_cli(["calibrate", "--data", path, "--out", tmp_path / "out", "--no-figures"])
    err = one_line(r, f"{path}: data.unit: the readings at rest are ")
    assert "where readings in m/s^2 are 9.80665: they are not in m/s^2 (fix: they look like g" in err
    assert "a netCDF file: its variable's units attribute" in err


def test_the_stated_unit_check_leaves_counts_and_a_poor_sensor_alone():
    from imucal.analysis.rest import stated_unit_error

    assert stated_unit_error("raw", np.full((5, 3), 1e4)) is None
    assert stated_unit_error("g", np.array([[0.0, 0.0, 1.3], [0.0, 0.85, 0.0]])) is None  # 30 % off: no unit mix-up
    assert "they look like mg" in stated_unit_error("g", np.array([[0.0, 0.0, 1000.0]])).fix


def test_a_second_gyroscope_file_stamped_apart_is_not_paired_by_index(tmp_path):
    """imu_tk's two files with as many samples were paired sample by sample whatever their stamps said: a gyroscope
    file 0.5 s late calibrated (and was applied) without a word."""
    from imucal.gyro.run import gyro_on_accel_samples

    t = np.arange(2000) / 100.0
    np.savetxt(tmp_path / "acc.txt", np.column_stack([t, np.tile([0.0, 0.0, 16384.0], (2000, 1))]), fmt="%.10g")
    rec = load_recording(str(tmp_path / "acc.txt"))
    for dt, ok in ((0.004, True), (0.5, False)):  # within half a sample: the clock's rounding
        np.savetxt(tmp_path / "gyro.txt", np.column_stack([t + dt, np.ones((2000, 3))]), fmt="%.10g")
        if ok:
            assert gyro_on_accel_samples(rec, str(tmp_path / "gyro.txt")).shape == (2000, 3)
            continue
        with pytest.raises(ImucalError) as e:
            gyro_on_accel_samples(rec, str(tmp_path / "gyro.txt"))
        assert e.value.field == "t" and e.value.file == str(tmp_path / "gyro.txt")
        assert "as many samples as the accelerometer, but sample " in str(e.value)
        assert "is stamped 0.5 s apart from the accelerometer's (50 samples): not the same samples on one clock" in str(
            e.value)


@pytest.mark.parametrize("fit", [{"lag_s": "*/ #include <evil.h> /*", "lag_samples": float("nan")},
                                 {"lag_s": True, "lag_samples": "3\n#define X"}, {"lag_s": float("inf")}, {}])
def test_a_hostile_or_missing_lag_writes_no_lag_line_into_the_c_header(fit):
    """The header's lag line is written only from finite numbers: a string (a C comment's end, a newline), a bool,
    nan or inf in the calibration file's fit section reaches the generated C as nothing."""
    from types import SimpleNamespace

    from imucal.export.codegen_sensor import _lag_lines

    assert _lag_lines(SimpleNamespace(fit=fit), "raw_m") == []
    text = " ".join(_lag_lines(SimpleNamespace(fit={"lag_s": 0.06, "lag_samples": "*/ x"}), "raw_m"))
    assert "*/" not in text and "by 0.06 s (n/a samples" in text  # a number beside a hostile one: only the number
