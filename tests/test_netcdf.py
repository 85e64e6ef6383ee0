"""netCDF-4/HDF5 recordings (imucal/data/netcdf.py): variables and units from the file's own attributes,
the same Recording as the CSV of the same samples, and one-line refusals of hostile files."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import real_file, write_simulation
from imucal.analysis.simulate import cube_directions, si_sensor
from imucal.data.load import DataSpec, load_recording
from imucal.errors import ImucalError

import h5py  # noqa: E402  (the test extra: a missing netCDF extra fails here, never skips)


def write_nc(path: Path, acc: np.ndarray | None, t: np.ndarray | None = None, *, gyro: np.ndarray | None = None,
             temp: np.ndarray | None = None, acc_units: str | None = "m/s2", gyro_units: str = "rad/s",
             temp_units: str | None = "degC", time_units: str = "seconds since 2021-09-20 08:52:00",
             rate: float | None = None, names: dict | None = None) -> Path:
    """A netCDF-4-style HDF5 file: (N, 3) variables on a time dimension (a dimension scale with CF units)."""
    names = {"acc": "acceleration", "gyro": "angular_velocity", "temp": "temperature", "t": "timestamp_utc",
             **(names or {})}
    with h5py.File(path, "w") as f:
        f.attrs["history"] = "written by the imucal tests"
        tv = None
        if t is not None:
            tv = f.create_dataset(names["t"], data=t)
            tv.attrs["units"] = time_units
            tv.make_scale(names["t"])
        for key, arr, units in (("acc", acc, acc_units), ("gyro", gyro, gyro_units), ("temp", temp, temp_units)):
            if arr is None:
                continue
            v = f.create_dataset(names[key], data=arr)
            v.attrs["_FillValue"] = np.nan
            if units is not None:
                v.attrs["units"] = units
            if rate is not None:
                v.attrs["sampling_rate"] = np.array([rate])
                v.attrs["sampling_rate_units"] = "Hz"
            if tv is not None and arr.shape[0] == tv.shape[0]:
                v.dims[0].attach_scale(tv)
    return path


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """A simulated recording (m/s^2, with temperature) as CSV, and the same samples as netCDF."""
    root = tmp_path_factory.mktemp("nc")
    rec = write_simulation(root / "sim.csv", si_sensor(np.random.default_rng(7)), cube_directions(), seed=7)
    csv = load_recording(DataSpec(path=str(rec.path), unit="m/s^2"))
    temp = 20.0 + 0.01 * csv.t
    gyro = np.random.default_rng(1).normal(0, 1e-3, csv.raw.shape)
    nc = write_nc(root / "sim.nc", csv.raw, csv.t, gyro=gyro, temp=temp)
    return csv, nc, temp, gyro


def test_a_netcdf_file_reads_as_the_same_samples(sim):
    csv, nc, temp, gyro = sim
    rec = load_recording(str(nc))
    np.testing.assert_array_equal(rec.raw, csv.raw)
    np.testing.assert_allclose(rec.t, csv.t, atol=1e-9)
    np.testing.assert_array_equal(rec.temp, temp)
    np.testing.assert_array_equal(rec.gyro, gyro)
    assert (rec.unit, rec.gyro_unit, rec.time_column) == ("m/s^2", "rad/s", "timestamp_utc")
    assert rec.sample_rate == pytest.approx(csv.sample_rate)
    assert "seconds since 2021-09-20" in rec.time_note
    assert rec.sha256 == __import__("hashlib").sha256(nc.read_bytes()).hexdigest()


def test_a_netcdf_file_calibrates_as_its_csv(sim, run_cli, tmp_path):
    csv, _, _, _ = sim
    a = run_cli(["calibrate", "--data", csv.source, "--unit", "m/s^2", "--out", tmp_path / "a", "--no-figures",
                 "--quiet"])
    nc = write_nc(tmp_path / "acc.nc", csv.raw, csv.t)  # no gyroscope: the accelerometer alone
    b = run_cli(["calibrate", "--data", nc, "--out", tmp_path / "b", "--no-figures", "--quiet"])
    assert a.code == b.code == 0, (a.err, b.err)
    from imucal.calibration.frozen import load_calibration

    ca, cb = (load_calibration(tmp_path / d / "calibration.yaml") for d in ("a", "b"))
    np.testing.assert_allclose(cb.values, ca.values, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("units, scale, unit", [("mrad/s", 1e-3, "rad/s"), ("deg/s", 1.0, "deg/s"),
                                                ("rad s-1", 1.0, "rad/s")])
def test_angular_rate_units_are_converted(tmp_path, units, scale, unit):
    acc, g = np.tile([0.0, 0.0, 9.8], (20, 1)), np.full((20, 3), 5.0)
    rec = load_recording(str(write_nc(tmp_path / "r.nc", acc, np.arange(20.0), gyro=g, gyro_units=units)))
    np.testing.assert_allclose(rec.gyro, 5.0 * scale)
    assert rec.gyro_unit == unit


@pytest.mark.parametrize("units, expect", [("C", 21.5), ("K", 21.5 - 273.15), ("degrees_Celsius", 21.5),
                                           ("degF", (21.5 - 32) * 5 / 9)])
def test_temperature_units_are_converted_to_degc(tmp_path, units, expect):
    acc = np.tile([0.0, 0.0, 9.8], (20, 1))
    rec = load_recording(str(write_nc(tmp_path / "r.nc", acc, np.arange(20.0), temp=np.full(20, 21.5),
                                      temp_units=units)))
    np.testing.assert_allclose(rec.temp, expect)


def test_acceleration_in_g_keeps_its_unit(tmp_path):
    rec = load_recording(str(write_nc(tmp_path / "r.nc", np.tile([0.0, 0.0, 1.0], (20, 1)), np.arange(20.0),
                                      acc_units="g")))
    assert rec.unit == "g"


def test_cf_time_units_and_the_sampling_rate(tmp_path):
    acc = np.tile([0.0, 0.0, 9.8], (50, 1))
    rec = load_recording(str(write_nc(tmp_path / "ms.nc", acc, np.arange(50) * 10.0,
                                      time_units="milliseconds since 2020-01-01")))
    assert rec.sample_rate == pytest.approx(100.0) and rec.t[-1] == pytest.approx(0.49)
    rec = load_recording(str(write_nc(tmp_path / "h.nc", acc, np.arange(50) / 3600.0,
                                      time_units="hours since 2020-01-01")))
    assert rec.sample_rate == pytest.approx(1.0, rel=1e-9)
    rec = load_recording(str(write_nc(tmp_path / "rate.nc", acc, None, rate=50.0)))  # no time variable
    assert rec.sample_rate == 50.0 and rec.t[-1] == pytest.approx(49 / 50)


def test_fill_values_are_dropped_and_leave_a_gap(tmp_path):
    """A logger that paused writes fill values: the rows are left out and the time base keeps the gap."""
    n = 400
    acc = np.tile([0.0, 0.0, 9.8], (n, 1)) + np.random.default_rng(0).normal(0, 0.01, (n, 3))
    acc[100:150] = np.nan
    rec = load_recording(str(write_nc(tmp_path / "gap.nc", acc, np.arange(n) * 0.01)))
    assert rec.n == n - 50
    assert rec.time_base.n_gaps == 1 and rec.time_base.longest_gap == pytest.approx(0.51)
    np.testing.assert_allclose(rec.t[100] - rec.t[99], 0.51)


def test_explicit_variable_mapping(tmp_path):
    n = 30
    with h5py.File(tmp_path / "m.nc", "w") as f:
        for k, a in enumerate("xyz"):
            v = f.create_dataset(f"acc_{a}", data=np.full(n, float(k)))
            v.attrs["units"] = "m/s^2"
        v = f.create_dataset("tt", data=np.arange(n, dtype=float))
        v.attrs["units"] = "seconds since 2000-01-01"
    spec = DataSpec(path=str(tmp_path / "m.nc"), columns={"ax": "acc_x", "ay": "acc_y", "az": "acc_z", "t": "tt"})
    rec = load_recording(spec)
    np.testing.assert_array_equal(rec.raw[0], [0.0, 1.0, 2.0])


def test_the_real_thermal_sweep_is_read_from_its_attributes():
    p = real_file("thermal-cats-skdivemove", "cats_temperature_calib.nc")
    rec = load_recording(str(p))
    assert rec.n == 268081 and rec.unit == "m/s^2" and rec.gyro_unit == "rad/s"
    assert rec.sample_rate == 1.0 and rec.time_column == "timestamp_utc"
    assert 4.7 < rec.temp.min() < 5.0 and 27.5 < rec.temp.max() < 28.0
    assert np.abs(np.median(rec.gyro, axis=0)).max() < 0.05  # mrad/s read as rad/s: a still gyro's bias


def _corrupt(p: Path) -> Path:
    data = bytearray(p.read_bytes())
    data[0:8] = b"\x89HDF\r\n\x1a\n"
    data[8:512] = bytes(range(256)) * 2  # the superblock overwritten
    p.write_bytes(bytes(data))
    return p


def _hostile(tmp_path: Path, case: str) -> tuple[Path, list[str]]:
    n = 40
    t = np.arange(n, dtype=float)
    acc = np.tile([0.0, 0.0, 9.8], (n, 1))
    if case == "truncated":
        good = write_nc(tmp_path / "g.nc", acc, t, temp=np.full(n, 20.0))
        p = tmp_path / "c.nc"
        p.write_bytes(good.read_bytes()[:900])
        return p, []
    if case == "corrupt":
        return _corrupt(write_nc(tmp_path / "c.nc", acc, t)), []
    if case == "text named .nc":
        p = tmp_path / "c.nc"
        p.write_text("t,ax,ay,az\n0,0,0,9.8\n")
        return p, []
    if case == "netcdf classic":
        p = tmp_path / "c.nc"
        p.write_bytes(b"CDF\x01" + bytes(100))
        return p, []
    if case == "variable missing":
        return write_nc(tmp_path / "v.nc", acc, t), ["--columns", "temp=water_temperature"]
    if case == "no acceleration":
        return write_nc(tmp_path / "a.nc", None, t, temp=np.full(n, 20.0)), []
    if case == "wrong shape":
        return write_nc(tmp_path / "s.nc", acc[:, :2], t), []
    if case == "temperature too short":
        with h5py.File(write_nc(tmp_path / "l.nc", acc, t), "a") as f:
            f.create_dataset("temperature", data=np.full(n - 5, 20.0)).attrs["units"] = "degC"
        return tmp_path / "l.nc", []
    if case == "acceleration units unknown":
        return write_nc(tmp_path / "u.nc", acc, t, acc_units="furlong/fortnight2"), ["--columns", "ax=acceleration"]
    if case == "temperature units unknown":
        return write_nc(tmp_path / "u.nc", acc, t, temp=np.full(n, 20.0), temp_units="rankine"), \
            ["--columns", "temp=temperature"]
    if case == "temperature units missing":
        return write_nc(tmp_path / "u.nc", acc, t, temp=np.full(n, 20.0), temp_units=None), \
            ["--columns", "temp=temperature"]
    if case == "time not increasing":
        tt = t.copy()
        tt[20] = tt[10]
        return write_nc(tmp_path / "n.nc", acc, tt), []
    if case == "time units":
        return write_nc(tmp_path / "n.nc", acc, t, time_units="fortnights since 2000-01-01"), \
            ["--columns", "t=timestamp_utc"]
    if case == "column index":
        return write_nc(tmp_path / "i.nc", acc, t), ["--columns", "ax=0"]
    if case == "text option":
        return write_nc(tmp_path / "o.nc", acc, t), ["--time-unit", "ms"]
    if case == "all fill values":
        return write_nc(tmp_path / "f.nc", np.full((n, 3), np.nan), t), []
    if case == "two accelerations":
        with h5py.File(write_nc(tmp_path / "d.nc", acc, t), "a") as f:
            f.create_dataset("acc2", data=acc).attrs["units"] = "m/s^2"
        return tmp_path / "d.nc", []
    raise AssertionError(case)


HOSTILE = {
    "truncated": ("is not a readable netCDF-4/HDF5 file", "c.nc: data.path"),
    "corrupt": ("is not a readable netCDF-4/HDF5 file", "not cut or corrupt"),
    "text named .nc": ("is not a readable netCDF-4/HDF5 file", "export the recording as CSV"),
    "netcdf classic": ("netCDF classic file", "nccopy -k nc4"),
    "variable missing": ("no numeric variable 'water_temperature' (for temp)", "data.columns.temp"),
    "no acceleration": ("no variable with acceleration units", "data.columns.ax"),
    "wrong shape": ("has shape (40, 2): ax needs (N, 3)", "data.columns.ax"),
    "temperature too short": ("has 35 samples, the acceleration 40", "data.columns.temp"),
    "acceleration units unknown": ("units 'furlong/fortnight2' of variable 'acceleration' are not a unit of "
                                   "acceleration imucal knows (m/s^2 (m/s2, m s-2) or g)", "acceleration.units"),
    "temperature units unknown": ("units 'rankine' of variable 'temperature' are not a unit of temperature "
                                  "imucal knows (degC (C, celsius), K or degF)", "temperature.units"),
    "temperature units missing": ("has no units attribute", "temperature.units"),
    "time not increasing": ("time is not strictly increasing at sample 20", "data.columns.t"),
    "time units": ("not \"UNIT since DATE\"", "timestamp_utc.units"),
    "column index": ("mapped by its name, not by a column index", "data.columns.ax"),
    "text option": ("time_unit does not apply to a netCDF file", "data.time_unit"),
    "all fill values": ("no rows with every channel read present", "data"),
    "two accelerations": ("all have acceleration units", "map it"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
@pytest.mark.parametrize("command", ["calibrate", "noise"])
def test_hostile_netcdf_files_are_refused_in_one_line(tmp_path, run_cli, unchanged, case, command):
    path, extra = _hostile(tmp_path, case)
    args = ["calibrate", "--out", tmp_path / "out", "--no-figures"] if command == "calibrate" else ["noise"]
    with unchanged(tmp_path):
        r = run_cli([*args, "--data", path, *extra])
    assert r.code == 2, (r.out, r.err)
    lines = r.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.err, r.err
    assert lines[0].startswith("imucal: error: ")
    for piece in HOSTILE[case]:
        assert piece in lines[0], lines[0]


def test_a_missing_h5py_is_named(tmp_path, run_cli, monkeypatch):
    import builtins

    real_import = builtins.__import__
    p = write_nc(tmp_path / "a.nc", np.tile([0.0, 0.0, 9.8], (10, 1)), np.arange(10.0))

    def no_h5py(name, *a, **kw):
        if name.startswith("h5py"):
            raise ImportError(name)
        return real_import(name, *a, **kw)

    monkeypatch.setattr(builtins, "__import__", no_h5py)
    r = run_cli(["noise", "--data", p])
    assert r.code == 2 and len(r.err.strip().splitlines()) == 1
    assert "install imucal-nlp[netcdf]" in r.err and "a.nc" in r.err


def test_an_hdf5_file_without_the_suffix_is_read_by_its_signature(sim, tmp_path):
    _, nc, _, _ = sim
    p = tmp_path / "recording.bin"
    p.write_bytes(nc.read_bytes())
    assert load_recording(str(p)).n == load_recording(str(nc)).n


def test_api_errors_name_the_file(tmp_path):
    p = write_nc(tmp_path / "s.nc", np.zeros((5, 2)), np.arange(5.0))
    with pytest.raises(ImucalError) as ei:
        load_recording(str(p))
    assert ei.value.file == str(p)


from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(0, 4000), flips=st.lists(st.tuples(st.integers(0, 4000), st.integers(0, 255)), max_size=20))
def test_a_damaged_netcdf_file_never_crashes_the_reader(tmp_path, cut, flips):
    """Any cut or any flipped bytes of a valid file: a Recording, or one ImucalError."""
    good = tmp_path / "good.nc"
    if not good.exists():
        write_nc(good, np.tile([0.0, 0.0, 9.8], (60, 1)), np.arange(60.0), temp=np.full(60, 20.0),
                 gyro=np.zeros((60, 3)))
    data = bytearray(good.read_bytes())
    for at, byte in flips:
        if at < len(data):
            data[at] = byte
    p = tmp_path / "bad.nc"
    p.write_bytes(bytes(data[:cut] if cut else data))
    try:
        load_recording(str(p))
    except ImucalError as exc:
        assert "\n" not in str(exc)
