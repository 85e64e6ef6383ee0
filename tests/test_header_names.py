"""Exporters' headers read without a mapping (imucal.data.header_names): the role and unit of each
column from its name, the units into the recording, and one line for what a header cannot mean.

The numbers under each header are the same samples (a simulated six-pose recording); every reader
must give the same arrays, in the unit the header states.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from imucal.data.header_names import read_name
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.data.stream import StreamedRecording
from imucal.errors import ImucalError


@pytest.mark.parametrize("name, role, unit", [
    ("t", "t", None), ("Time (s)", "t", "s"), ("#timestamp [ns]", "t", "ns"), ("%time", "t", None),
    ("TimeUS", "t", "us"), ("timestamp", "t", None),
    ("ax", "ax", None), ("gz", "gz", None), ("wx", "gx", None),
    ("acc_x [g]", "ax", "g"), ("Acceleration y (m/s^2)", "ay", "m/s^2"), ("AccZ", "az", None),
    ("AcX", "ax", None), ("accelerometer_m_s2[2]", "az", "m/s^2"), ("a_RS_S_x [m s^-2]", "ax", "m s^-2"),
    ("field.linear_acceleration.y", "ay", "m/s^2"), ("Acc_X", "ax", None),
    ("GyrX", "gx", None), ("gyro_rad[1]", "gy", "rad/s"), ("w_RS_S_z [rad s^-1]", "gz", "rad s^-1"),
    ("field.angular_velocity.x", "gx", "rad/s"), ("Gyroscope x (rad/s)", "gx", "rad/s"), ("GyZ", "gz", None),
    ("Gyr_X", None, None),  # mad-lab-fau's gyr_x: read only when mapped (tests/test_trust_data.py)
    ("Mag_X", "mx", None), ("Magnetic field y (µT)", "my", "µT"), ("field.magnetic_field.z", "mz", None),
    ("temperature [degC]", "temp", "degC"), ("Tmp", None, None), ("FreeAcc_X", None, None),
    ("temperature", "temp", None), ("accelerometer_m_s2[3]", None, None), ("seq", None, None),
])
def test_a_name_states_its_role_and_unit(name, role, unit):
    got = read_name(name)
    assert (got.role, got.unit) == (role, unit)


def _samples(n: int = 600) -> dict[str, np.ndarray]:
    """Six still poses of 1 s at 100 Hz, in m/s^2 and rad/s, and a temperature [degC]."""
    rng = np.random.default_rng(3)
    dirs = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    acc = np.repeat(dirs * 9.81, n // 6, axis=0) + rng.normal(0, 0.01, (n, 3))
    return {"t": np.arange(n) / 100.0, "acc": acc, "gyro": rng.normal(0, 0.001, (n, 3)),
            "temp": 20 + np.arange(n) / n}


#: (file, header, one row from t, acc, gyro, temp, the units the recording must carry, the time unit)
def _px4(t, a, g, T):
    return f"{int(round(t * 1e6))},{g[0]!r},{g[1]!r},{g[2]!r},4000,0,{a[0]!r},{a[1]!r},{a[2]!r},4000"


def _ardupilot(t, a, g, T):
    return f"{1.7e9 + t:.6f},{int(round(t * 1e6))},0,{g[0]!r},{g[1]!r},{g[2]!r},{a[0]!r},{a[1]!r},{a[2]!r},0,0,{T!r}"


def _euroc(t, a, g, T):
    return f"{int(round(1.4e18 + t * 1e9))},{g[0]!r},{g[1]!r},{g[2]!r},{a[0]!r},{a[1]!r},{a[2]!r}"


def _ros(t, a, g, T):
    ns = int(round(1.6e18 + t * 1e9))
    return f"{ns},7,{ns},imu_link,0,0,0,1,{g[0]!r},{g[1]!r},{g[2]!r},{a[0]!r},{a[1]!r},{a[2]!r}"


def _phyphox(t, a, g, T):
    return f"{t!r},{a[0] / 9.80665!r},{a[1] / 9.80665!r},{a[2] / 9.80665!r},{g[0] * 180 / np.pi!r}," \
           f"{g[1] * 180 / np.pi!r},{g[2] * 180 / np.pi!r},{T!r}"


EXPORTERS = {
    "px4": ("timestamp,gyro_rad[0],gyro_rad[1],gyro_rad[2],gyro_integral_dt,accelerometer_timestamp_relative,"
            "accelerometer_m_s2[0],accelerometer_m_s2[1],accelerometer_m_s2[2],accelerometer_integral_dt",
            _px4, ("m/s^2", "rad/s", "us"), False),
    "ardupilot": ("timestamp,TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,EG,EA,T", _ardupilot, ("m/s^2", "rad/s", "s"),
                  True),
    "euroc": ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
              "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]", _euroc, ("m/s^2", "rad/s", "ns"), False),
    "ros": ("%time,field.header.seq,field.header.stamp,field.header.frame_id,field.orientation.x,"
            "field.orientation.y,field.orientation.z,field.orientation.w,field.angular_velocity.x,"
            "field.angular_velocity.y,field.angular_velocity.z,field.linear_acceleration.x,"
            "field.linear_acceleration.y,field.linear_acceleration.z", _ros, ("m/s^2", "rad/s", "ns"), False),
    "units in brackets": ('"Time (s)","Acceleration x (g)","Acceleration y (g)","Acceleration z (g)",'
                          '"Gyroscope x (deg/s)","Gyroscope y (deg/s)","Gyroscope z (deg/s)","temperature [degC]"',
                          _phyphox, ("g", "deg/s", "s"), True),
}


def _write(path: Path, header: str, row, s: dict) -> Path:
    rows = [row(t, a, g, T) for t, a, g, T in zip(s["t"].tolist(), s["acc"].tolist(), s["gyro"].tolist(),
                                                  s["temp"].tolist())]
    path.write_text(header + "\n" + "\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize("stream", ["never", "always"])
@pytest.mark.parametrize("exporter", list(EXPORTERS))
def test_an_exporters_file_is_read_in_the_units_its_header_states(tmp_path, exporter, stream):
    header, row, (unit, gyro_unit, time_unit), has_temp = EXPORTERS[exporter]
    s = _samples()
    p = _write(tmp_path / f"{exporter}.csv", header, row, s)
    spec = DataSpec(path=str(p), stream=stream)
    if stream == "always":  # the chunked reader: the same units, no samples kept
        rec = StreamedRecording(spec).recording
        assert rec.unit == unit and rec.n == s["t"].size
        return
    rec = load_recording(spec)
    assert (rec.unit, rec.gyro_unit, rec.time_unit) == (unit, gyro_unit, time_unit)
    acc = s["acc"] / (9.80665 if unit == "g" else 1.0)
    gyro = s["gyro"] * (180 / np.pi if gyro_unit == "deg/s" else 1.0)
    np.testing.assert_allclose(rec.raw, acc, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(rec.gyro, gyro, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(rec.t, s["t"], atol=2e-6)  # epoch seconds in ArduPilot's timestamp: 1e-6 s digits
    if has_temp:
        np.testing.assert_allclose(rec.temp, s["temp"], rtol=1e-12)
    else:
        assert rec.temp is None


def test_ardupilots_t_is_its_temperature_not_the_time(tmp_path):
    """ArduPilot's IMU message holds TimeUS and T, the IMU's temperature: T used to be read as the time
    (the bare name t), which a warming IMU's rising temperature would pass for."""
    s = _samples()
    s["temp"] = 30 + np.arange(s["t"].size) * 0.01  # rising: strictly increasing, as stamps are
    p = _write(tmp_path / "ap.csv", EXPORTERS["ardupilot"][0], _ardupilot, s)
    rec = load_recording(DataSpec(path=str(p)))
    assert rec.time_column == "timestamp"
    np.testing.assert_allclose(rec.temp, s["temp"])


def test_a_header_as_a_comment_with_the_datas_columns_is_the_header(tmp_path):
    """EuRoC writes its header as a comment; a comment with another number of fields is a comment."""
    s = _samples()
    p = tmp_path / "c.csv"
    body = "\n".join(_euroc(*r) for r in zip(s["t"].tolist(), s["acc"].tolist(), s["gyro"].tolist(),
                                              s["temp"].tolist()))
    p.write_text("# recorded by a rig, 7 columns follow\n" + EXPORTERS["euroc"][0] + "\n" + body + "\n")
    assert load_recording(DataSpec(path=str(p))).unit == "m/s^2"
    p.write_text("# t gx gy gz\n" + body + "\n")  # four names, seven columns: no header
    with pytest.raises(ImucalError, match="has 7 columns and no header"):
        load_recording(DataSpec(path=str(p)))


@pytest.mark.parametrize("header, given, words", [
    ("t,acc_x [g],acc_y [g],acc_z [g]", {"unit": "m/s^2"},
     "c.csv: data.unit: data.unit 'm/s^2' given, but the header states g (fix: give g (or leave the unit out)"),
    ("t,acc_x [g],acc_y [m/s^2],acc_z [g]", {},
     "c.csv: data.unit: columns 'acc_x [g]' and 'acc_y [m/s^2]' state different units (g, m/s^2)"),
    ("t,acc_x [furlong],acc_y,acc_z", {},
     "c.csv: data.columns.ax: column 'acc_x [furlong]' states 'furlong', where a text file's ax, ay, az are read "
     "in m/s^2, g, mg or counts (fix: write the column in one of those units and name it so, e.g. ax [m/s^2])"),
    ("t,ax,ay,az,mag_x [mT],mag_y [mT],mag_z [mT]", {},
     "c.csv: data.columns.mx: column 'mag_x [mT]' states 'mT', where a text file's mx, my, mz are read in uT, nT, "
     "gauss, milligauss or counts"),
    ("t,ax,ay,az,temp [°F]", {},
     "c.csv: data.columns.temp: the temperature column 'temp [°F]' states '°F': imucal reads degrees Celsius"),
    ("t,acc_x [g],acc_y [g],acc_z [g],Acceleration x (g)", {},
     "c.csv: data.columns.ax: columns 'acc_x [g]' and 'Acceleration x (g)' both name ax (fix: map ax to one of "
     "them, e.g. --columns ax=1)"),
    ("t,acc_x [g],acc_y [g],acc_z [g],gyro_x [deg/s],gyro_y [deg/s],gyro_z [deg/s]", {"gyro_unit": "rad/s"},
     "c.csv: data.gyro_unit: data.gyro_unit 'rad/s' given, but the header states deg/s"),
])
def test_a_header_that_cannot_mean_one_thing_is_one_line(tmp_path, header, given, words):
    p = tmp_path / "c.csv"
    p.write_text(header + "\n" + "\n".join(",".join(["%d" % k] + ["1"] * (header.count(",")))
                                           for k in range(10)) + "\n")
    with pytest.raises(ImucalError) as ei:
        load_recording(DataSpec(path=str(p), **given))
    assert "\n" not in str(ei.value) and words in str(ei.value), str(ei.value)


def test_interleaved_sensors_are_refused_naming_the_instance_column(tmp_path):
    p = tmp_path / "ap.csv"
    rows = [f"{k // 3 * 0.01:.2f},{k // 3 * 10000 + k % 3},{k % 3},0,0,9.81" for k in range(60)]
    p.write_text("timestamp,TimeUS,I,AccX,AccY,AccZ\n" + "\n".join(rows) + "\n")
    with pytest.raises(ImucalError) as ei:
        load_recording(DataSpec(path=str(p)))
    assert str(ei.value).endswith("/ap.csv: data.path: rows of 3 sensors are interleaved (column 'I' holds "
                                    "'0', '1', '2') (fix: write one sensor's rows to a file (ArduPilot: "
                                    "mavlogdump.py --types IMU --condition 'IMU.I==0' --format csv) and calibrate each)"), str(ei.value)


def test_a_calibration_from_an_exporters_header_equals_the_mapped_one(run_cli, tmp_path, si_recording):
    """The same samples under phyphox's names (units in parentheses) and under imucal's own with the unit
    given: the same calibration, parameter for parameter."""
    d = np.loadtxt(si_recording.path, delimiter=",", skiprows=1)
    own = tmp_path / "own.csv"
    np.savetxt(own, d[:, :4], delimiter=",", header="t,ax,ay,az", comments="", fmt="%.10g")
    ph = tmp_path / "phyphox.csv"
    np.savetxt(ph, d[:, :4], delimiter=",", comments="", fmt="%.10g",
               header='"Time (s)","Acceleration x (m/s^2)","Acceleration y (m/s^2)","Acceleration z (m/s^2)"')
    out = {}
    for name, p, extra in (("own", own, ["--unit", "m/s^2"]), ("phyphox", ph, [])):
        js = tmp_path / f"{name}.json"
        r = run_cli(["calibrate", p, *extra, "--out", tmp_path / name, "--no-figures", "--quiet", "--json", js])
        assert r.code == 0, r.err
        out[name] = json.loads(js.read_text())
    assert out["own"]["params"] == out["phyphox"]["params"] and out["own"]["std"] == out["phyphox"]["std"]
    assert out["own"]["raw_unit"] == out["phyphox"]["raw_unit"] == "m/s^2"


def test_a_linear_acceleration_without_gravity_is_named_as_such(run_cli, tmp_path):
    """phyphox's "Linear Acceleration" (gravity removed by the phone): still readings near 0 m/s^2 are not
    counts, and the fix says what to record instead."""
    rng = np.random.default_rng(1)
    t = np.arange(6000) / 100.0
    a = rng.normal(0, 0.02, (6000, 3))
    for k in range(0, 6000, 1000):  # six moves between still spans
        a[k:k + 100] += rng.normal(0, 2, (100, 3))
    p = tmp_path / "lin.csv"
    np.savetxt(p, np.column_stack([t, a]), delimiter=",", comments="", fmt="%.6g",
               header='"Time (s)","Linear Acceleration x (m/s^2)","Linear Acceleration y (m/s^2)",'
                      '"Linear Acceleration z (m/s^2)"')
    r = run_cli(["calibrate", p, "--out", tmp_path / "o", "--no-figures", "--quiet"])
    lines = r.err.strip().splitlines()
    assert r.code == 2 and len(lines) == 1 and not (tmp_path / "o").exists(), r.err
    assert "lin.csv: data.unit: the readings at rest are" in lines[0] and lines[0].endswith(
        "(fix: still readings without gravity are an acceleration with gravity removed (a phone's or a filter's "
        "linear acceleration), which cannot calibrate an accelerometer: record the sensor's own readings "
        "(phyphox: Acceleration with g))"), lines[0]


@pytest.mark.parametrize("stream", ["never", "always"])
def test_a_line_of_units_under_the_names_is_read_as_their_units(tmp_path, stream):
    """Some loggers write the units on the line after the names: read as the units, not refused as a row."""
    s = _samples()
    p = tmp_path / "u.csv"
    rows = "\n".join(f"{t!r},{a[0] / 9.80665!r},{a[1] / 9.80665!r},{a[2] / 9.80665!r},{T!r}"
                     for t, a, T in zip(s["t"].tolist(), s["acc"].tolist(), s["temp"].tolist()))
    p.write_text("t,ax,ay,az,temp\ns,g,g,g,degC\n" + rows + "\n")
    if stream == "always":
        rec = StreamedRecording(DataSpec(path=str(p), stream=stream)).recording
        assert (rec.unit, rec.n) == ("g", s["t"].size)
        return
    rec = load_recording(DataSpec(path=str(p)))
    assert rec.unit == "g" and rec.raw.shape == (s["t"].size, 3)
    np.testing.assert_allclose(rec.raw * 9.80665, s["acc"], rtol=1e-12)
    p.write_text("t,ax,ay,az,temp\ns,g,g,g,degF\n" + rows + "\n")
    with pytest.raises(ImucalError, match="the temperature column 'temp \\[degF\\]' states 'degF'"):
        load_recording(DataSpec(path=str(p)))


_PIECES = ["t", "T", "time", "TimeUS", "#timestamp", "%time", "acc", "Acc", "a", "gyro", "gyr", "w", "mag", "temp",
           "field.", "linear_acceleration", "_", ".", " ", "x", "y", "z", "X", "[0]", "[2]", "[9]", " [g]", " (m/s^2)",
           " [rad s^-1]", " (deg/s)", " [degC]", " [°F]", " (s)", " [ns]", " [furlong]", "(", "]", "I", "Tmp", "µ", "\""]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(names=st.lists(st.lists(st.sampled_from(_PIECES) | st.text(max_size=4), min_size=1, max_size=4).map("".join),
                      min_size=3, max_size=9),
       units_row=st.booleans())
def test_any_header_is_read_or_refused_in_one_line(tmp_path, names, units_row):
    """Whatever the names, the reader gives a recording or one ImucalError line: never another exception."""
    names = [n.replace(",", ";").replace("\n", " ").replace("\r", " ") for n in names]
    rows = [",".join(f"{(k * 0.01 if j == 0 else 1.0 + j):g}" for j in range(len(names))) for k in range(30)]
    extra = [",".join(["s", "g", "deg/s", "degC"][j % 4] for j in range(len(names)))] if units_row else []
    p = tmp_path / "h.csv"
    p.write_text("\n".join([",".join(names), *extra, *rows]) + "\n", encoding="utf-8", errors="surrogatepass")
    try:
        load_recording(DataSpec(path=str(p), sample_rate=100.0))
    except ImucalError as exc:
        assert "\n" not in str(exc)


def test_a_rate_stated_above_the_header_times_a_file_without_a_time_column(tmp_path):
    """tomisuarez's MPU-6050 log starts with "Fs,100" and has no time column: read at 100 Hz as with the rate
    given; a rate given that disagrees is refused, naming both."""
    from conftest import real_file

    p = real_file("mpu6050-tomisuarez", "example_data_calibration.csv")
    stated = load_recording(DataSpec(path=str(p)))
    given = load_recording(DataSpec(path=str(p), sample_rate=100.0))
    assert stated.time_note == "no time column: 100 Hz stated above the header"
    assert given.time_note == "no time column: 100 Hz given"
    for a, b in ((stated.t, given.t), (stated.raw, given.raw), (stated.gyro, given.gyro)):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ImucalError) as ei:
        load_recording(DataSpec(path=str(p), sample_rate=200.0))
    assert str(ei.value).endswith("example_data_calibration.csv: data.sample_rate: sample rate 200 Hz given, but "
                                  "the file states 100 Hz above its header: two sources of time disagree (fix: give "
                                  "100 (or leave the rate out), or correct the file's line)"), str(ei.value)
    q = tmp_path / "meta.csv"  # other spellings, and a key that is not a rate
    q.write_text("sampling rate: 50 Hz\nsensor,MPU-6050\nax,ay,az\n" + "0,0,1\n" * 10)
    assert load_recording(DataSpec(path=str(q))).time_note == "no time column: 50 Hz stated above the header"
    q.write_text("samples,50\nax,ay,az\n" + "0,0,1\n" * 10)
    with pytest.raises(ImucalError, match="no time column and no sample rate"):
        load_recording(DataSpec(path=str(q)))


def test_a_magnetometers_stated_unit_reaches_the_recording(tmp_path):
    """phyphox's "Magnetic field x (µT)": the recording's mag_unit, which a run's mag.unit is checked against
    (as a netCDF variable's units attribute)."""
    p = tmp_path / "m.csv"
    p.write_text("t,ax,ay,az,Magnetic field x (µT),Magnetic field y (µT),Magnetic field z (µT)\n"
                 + "\n".join(f"{k * 0.01:.2f},0,0,9.81,20,1,-40" for k in range(20)) + "\n")
    rec = load_recording(DataSpec(path=str(p)))
    assert rec.mag_unit == "uT" and rec.mag.shape == (20, 3)


def test_px4s_sensor_accel_csv_is_read_with_its_temperature(tmp_path):
    """ulog2csv -m sensor_accel (what the ULog refusal tells a user to write): x, y, z before PX4's calibration
    and the temperature, stamped in microseconds."""
    s = _samples()
    p = tmp_path / "log_sensor_accel_0.csv"
    rows = "\n".join(f"{int(round(t * 1e6))},{int(round(t * 1e6)) - 150},2490378,{a[0]!r},{a[1]!r},{a[2]!r},{T!r},0,0,0,0,4"
                     for t, a, T in zip(s["t"].tolist(), s["acc"].tolist(), s["temp"].tolist()))
    p.write_text("timestamp,timestamp_sample,device_id,x,y,z,temperature,error_count,clip_counter[0],"
                 "clip_counter[1],clip_counter[2],samples\n" + rows + "\n")
    rec = load_recording(DataSpec(path=str(p)))
    assert (rec.time_column, rec.time_unit, rec.gyro) == ("timestamp", "us", None)
    np.testing.assert_allclose(rec.raw, s["acc"], rtol=1e-12)
    np.testing.assert_allclose(rec.temp, s["temp"], rtol=1e-12)


def test_a_gyroscope_file_with_named_columns_is_read_as_its_gyroscope(run_cli, tmp_path):
    """imu_tk's second file (t x y z) written with a header that names its gyroscope (t, gx, gy, gz): the same
    gyroscope calibration, not "missing column for ax"; a header's rate unit that the run contradicts: one line."""
    import yaml

    from conftest import real_file

    acc, gyro = real_file("xsens-mti-imutk", "xsens_acc.mat"), real_file("xsens-mti-imutk", "xsens_gyro.mat")
    named = tmp_path / "gyro_named.csv"
    np.savetxt(named, np.loadtxt(gyro), delimiter=",", header="t,gx,gy,gz", comments="", fmt="%.10g")
    cals = {}
    for name, g in (("mat", gyro), ("named", named)):
        r = run_cli(["calibrate", acc, "--gyro-data", g, "--gravity", "9.81744", "--out", tmp_path / name,
                     "--no-figures", "--quiet"])
        assert r.code == 0, r.err
        cals[name] = yaml.safe_load((tmp_path / name / "calibration.yaml").read_text())["gyroscope"]["parameters"]
    assert cals["mat"] == cals["named"]
    stated = tmp_path / "gyro_dps.csv"
    np.savetxt(stated, np.loadtxt(gyro), delimiter=",", header="t,gyro_x [deg/s],gyro_y [deg/s],gyro_z [deg/s]",
               comments="", fmt="%.10g")
    r = run_cli(["calibrate", acc, "--gyro-data", stated, "--gyro-unit", "rad/s", "--gravity", "9.81744",
                 "--out", tmp_path / "o", "--no-figures", "--quiet"])
    lines = r.err.strip().splitlines()
    assert r.code == 2 and len(lines) == 1 and lines[0].endswith(
        "gyro_dps.csv: data.gyro_unit: data.gyro_unit rad/s given, but the gyroscope file's header states deg/s "
        "(fix: give deg/s (or leave it out))"), r.err


def test_the_columns_read_by_an_exporters_names_are_recorded(run_cli, tmp_path, si_recording):
    """The calibration file, report.txt and report.html say which column each role was read from when the
    names were an exporter's (a user checks that AccX is the accelerometer); the names are escaped for each."""
    import html
    import yaml

    from imucal.calibration.frozen import Calibration

    d = np.loadtxt(si_recording.path, delimiter=",", skiprows=1)
    p = tmp_path / "x.csv"
    x_name = "<b>A&amp;x</b>"  # mapped by the user (--columns), beside names read by themselves
    np.savetxt(p, d[:, :4], delimiter=",", comments="", fmt="%.10g",
               header=f'"Time (s)","{x_name}","Acceleration y (m/s^2)","Acceleration z (m/s^2)"')
    r = run_cli(["calibrate", p, "--columns", f"ax={x_name}", "--out", tmp_path / "o", "--quiet"])
    assert r.code == 0, r.err
    cal = yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())
    assert cal["data"]["columns"] == {"t": "Time (s)", "ax": x_name, "ay": "Acceleration y (m/s^2)",
                                      "az": "Acceleration z (m/s^2)"}
    assert Calibration.load(tmp_path / "o" / "calibration.yaml").data["columns"]["ax"] == x_name
    words = f"t: Time (s); ax, ay, az: {x_name}, Acceleration y (m/s^2), Acceleration z (m/s^2)"
    assert f"    columns            = {words}\n" in (tmp_path / "o" / "report.txt").read_text()
    page = (tmp_path / "o" / "report.html").read_text()
    assert f"<td>{html.escape(words)}</td>" in page and "<b>&amp;" not in page
    r = run_cli(["calibrate", si_recording.path, "--out", tmp_path / "own", "--quiet", "--no-figures"])
    assert r.code == 0 and "columns" not in yaml.safe_load((tmp_path / "own" / "calibration.yaml").read_text())["data"]


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(names=st.dictionaries(st.sampled_from(["t", "ax", "ay", "az", "gx", "temp", "mx"]),
                             st.text(min_size=1, max_size=60), min_size=1))
def test_recorded_column_names_are_escaped_for_each_format(tmp_path, names):
    """Whatever a header names its columns (quotes, */, <, control characters, line separators, NUL):
    report.txt's line stays one printable line, the HTML has no markup from it, and calibration.yaml
    gives the names back as written."""
    from imucal.calibration.frozen import Calibration
    from imucal.model.parameters import base_parameters
    from imucal.report.page import esc
    from imucal.report.text import columns_words

    words = columns_words(names)
    assert words.isprintable() and "\n" not in words
    assert "<" not in esc(words) and ">" not in esc(words)
    cal = Calibration(params=base_parameters([0.0] * 3, [1.0] * 3, [np.pi / 2] * 3, raw_unit="raw"), std={},
                      gravity=9.81, data={"file": "x.csv", "sha256": "0" * 64, "columns": names})
    cal.save(tmp_path / "c.yaml")
    assert Calibration.load(tmp_path / "c.yaml").data["columns"] == names


def test_a_gyroscope_file_that_is_no_regular_file_is_one_line(run_cli, tmp_path):
    """The header of a second file is read before it is loaded (gyro_file_spec): a FIFO or a device there is
    refused at once, naming --gyro-data, as the loader refuses them."""
    import os

    from conftest import real_file

    fifo = tmp_path / "gyro.csv"
    os.mkfifo(fifo)
    for g in (fifo, "/dev/zero"):
        r = run_cli(["calibrate", real_file("xsens-mti-imutk", "xsens_acc.mat"), "--gyro-data", g,
                     "--gravity", "9.81744", "--out", tmp_path / "o", "--no-figures", "--quiet"])
        lines = r.err.strip().splitlines()
        assert r.code == 2 and len(lines) == 1 and "--gyro-data" in lines[0] and "regular file" in lines[0], r.err
        assert not (tmp_path / "o").exists()


def test_a_unit_the_header_states_wrongly_is_fixed_in_the_header(run_cli, tmp_path, counts_recording):
    """Counts under names that state m/s^2: the rest check's fix names the header (giving data.unit would
    contradict it, which is refused), not data.unit."""
    d = np.loadtxt(counts_recording.path, delimiter=",", skiprows=1)
    p = tmp_path / "c.csv"
    np.savetxt(p, d[:, :4], delimiter=",", comments="", fmt="%.10g",
               header="t,acc_x [m/s^2],acc_y [m/s^2],acc_z [m/s^2]")
    r = run_cli(["calibrate", p, "--out", tmp_path / "o", "--no-figures", "--quiet"])
    lines = r.err.strip().splitlines()
    assert r.code == 2 and len(lines) == 1 and lines[0].endswith(
        "they are not in m/s^2 (fix: the header states m/s^2 (column acc_x [m/s^2]): correct the header's unit, "
        "e.g. acc_x [counts])"), r.err


def test_a_second_file_with_both_sensors_gives_its_gyroscope(tmp_path):
    """An IMU's CSV given as --gyro-data (t, ax.., gx..): its gyroscope columns are the rates, not its
    accelerometer's (which a second file's default roles would have read)."""
    from imucal.data.layout import gyro_file_spec

    p = tmp_path / "imu.csv"
    p.write_text("t,ax,ay,az,gx,gy,gz\n" + "\n".join(f"{k * 0.01:.2f},0,0,9.81,0.1,0.2,0.3" for k in range(20)) + "\n")
    rec = load_recording(gyro_file_spec(DataSpec(path=str(p)), p))
    np.testing.assert_array_equal(rec.raw[0], [0.1, 0.2, 0.3])
