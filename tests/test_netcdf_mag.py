"""A magnetometer in a netCDF-4 file (imucal/data/netcdf.py): read when mapped (data.columns mx: VARIABLE),
in the unit its units attribute states, and calibrated as the same samples in a CSV with mag.unit given."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from imucal.calibration.frozen import load_calibration
from imucal.data.load import DataSpec, load_recording
from imucal.errors import ImucalError
from imucal.mag.simulate import simulate_mag, truth_from_soft_iron
from test_netcdf import write_nc

import h5py  # noqa: E402  (the test extra)

SOFT = np.array([[1.05, 0.03, -0.02], [0.03, 0.97, 0.01], [-0.02, 0.01, 1.01]])
RATE = 50.0


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    """A 9-axis log (acceleration in g, field in uT, 50 Hz) as CSV, and the same samples as netCDF with the
    field in nanotesla (its units attribute says so)."""
    root = tmp_path_factory.mktemp("ncmag")
    truth = truth_from_soft_iron(SOFT, s=(10.0, -5.0, 3.0), field=48.0, noise=0.1, acc_noise=0.002)
    sim = simulate_mag(truth, n_poses=30, hold=150, transition=40, seed=3)
    t = np.arange(sim.acc.shape[0]) / RATE
    csv = root / "log.csv"
    np.savetxt(csv, np.column_stack([t, sim.acc, sim.mag]), delimiter=",", header="t,ax,ay,az,mx,my,mz",
               comments="", fmt="%.17g")
    nc = write_nc(root / "log.nc", sim.acc, t, acc_units="g")
    with h5py.File(nc, "a") as f:
        v = f.create_dataset("magnetic_field", data=sim.mag * 1e3)
        v.attrs["units"] = "nT"
        v.attrs["_FillValue"] = np.nan
        v.dims[0].attach_scale(f["timestamp_utc"])
    return csv, nc, sim


def _run_file(path, data: dict, **mag) -> str:
    path.write_text(yaml.safe_dump({"data": data, **({"mag": mag} if mag else {}),
                                    "output": {"figures": False}}))
    return str(path)


def test_a_mapped_field_variable_is_read_in_its_unit(log):
    _, nc, sim = log
    rec = load_recording(DataSpec(path=str(nc), columns={"mx": "magnetic_field"}))
    np.testing.assert_array_equal(rec.mag, sim.mag * 1e3)
    assert rec.mag_unit == "nT"
    assert load_recording(str(nc)).mag is None  # not mapped: no magnetometer guessed


@pytest.mark.parametrize("units, unit, factor", [("uT", "uT", 1.0), ("microtesla", "uT", 1.0), ("T", "uT", 1e6),
                                                 ("mT", "uT", 1e3), ("gauss", "gauss", 1.0), ("mGauss", "mG", 1.0)])
def test_field_units_are_read(tmp_path, units, unit, factor):
    acc = np.tile([0.0, 0.0, 1.0], (10, 1))
    nc = write_nc(tmp_path / "f.nc", acc, np.arange(10.0), acc_units="g")
    with h5py.File(nc, "a") as f:
        f.create_dataset("b", data=np.full((10, 3), 0.5)).attrs["units"] = units
    rec = load_recording(DataSpec(path=str(nc), columns={"mx": "b"}))
    assert rec.mag_unit == unit and rec.mag[0, 0] == pytest.approx(0.5 * factor)


def test_a_field_variable_in_an_acceleration_unit_is_refused(tmp_path):
    """"mg" is a thousandth of g, not milligauss: the field's units are refused, not guessed."""
    acc = np.tile([0.0, 0.0, 1.0], (10, 1))
    nc = write_nc(tmp_path / "f.nc", acc, np.arange(10.0), acc_units="g")
    with h5py.File(nc, "a") as f:
        f.create_dataset("b", data=np.full((10, 3), 0.5)).attrs["units"] = "mg"
    with pytest.raises(ImucalError) as e:
        load_recording(DataSpec(path=str(nc), columns={"mx": "b"}))
    assert e.value.field == "b.units" and "magnetic field" in str(e.value)


def test_a_netcdf_magnetometer_calibrates_as_its_csv(log, tmp_path, run_cli):
    csv, nc, _ = log
    a = run_cli(["calibrate", _run_file(tmp_path / "a.yaml", {"path": str(csv), "unit": "g"}, unit="uT",
                                        field=48.0, field_unit="uT"), "--out", tmp_path / "a", "--quiet"])
    b = run_cli(["calibrate", _run_file(tmp_path / "b.yaml", {"path": str(nc), "columns": {"mx": "magnetic_field"}},
                                        field=48.0, field_unit="uT"), "--out", tmp_path / "b", "--quiet"])
    assert a.code == b.code == 0, (a.err, b.err)
    ma, mb = (load_calibration(tmp_path / d / "calibration.yaml").sensor("magnetometer") for d in ("a", "b"))
    assert (ma.raw_unit, mb.raw_unit) == ("uT", "nT")
    pa, pb = ma.params.value_dict(), mb.params.value_dict()
    # the field and the hard iron in the readings' unit (nT = 1000 x uT), the scales and angles alike
    assert pb["F"] == pytest.approx(1e3 * pa["F"], rel=1e-6)
    for name, va in pa.items():
        vb = pb[name]
        assert vb == pytest.approx(1e3 * va if name[0] in "sF" else va, rel=1e-5, abs=1e-9), name


def test_a_mag_unit_that_disagrees_with_the_file_is_one_line(log, tmp_path, run_cli, unchanged):
    _, nc, _ = log
    run = _run_file(tmp_path / "r.yaml", {"path": str(nc), "columns": {"mx": "magnetic_field"}}, unit="uT",
                    field=48.0, field_unit="uT")
    with unchanged(tmp_path):
        r = run_cli(["calibrate", run, "--out", tmp_path / "out"])
    assert r.code == 2 and r.err.count("\n") == 1 and "mag.unit uT disagrees with the file's nT" in r.err
    assert not (tmp_path / "out").exists()


def test_apply_takes_the_field_unit_the_file_states(log, tmp_path, run_cli):
    """A calibration made in uT applied to the netCDF log in nT: the readings are converted (both units are
    stated), the calibrated field the same as applying it to the CSV in uT."""
    csv, nc, _ = log
    r = run_cli(["calibrate", _run_file(tmp_path / "a.yaml", {"path": str(csv), "unit": "g"}, unit="uT",
                                        field=48.0, field_unit="uT"), "--out", tmp_path / "a", "--quiet"])
    assert r.code == 0, r.err
    cal = tmp_path / "a" / "calibration.yaml"
    a = run_cli(["apply", cal, "--data", csv, "--unit", "g", "--out", tmp_path / "a.csv"])
    b = run_cli(["apply", cal, "--data", nc, "--columns", "mx=magnetic_field", "--out", tmp_path / "b.csv"])
    assert a.code == b.code == 0, (a.err, b.err)
    ya, yb = (np.genfromtxt(tmp_path / f, delimiter=",", names=True) for f in ("a.csv", "b.csv"))
    for c in ("mx", "my", "mz"):
        np.testing.assert_allclose(yb[c], ya[c], rtol=1e-9, atol=1e-9)


def test_a_field_variable_not_mapped_is_said_not_dropped(log, tmp_path, run_cli):
    """Without the mapping the accelerometer calibrates alone, and the run says which variable it left
    unread and how to read it (it was silent)."""
    _, nc, _ = log
    r = run_cli(["calibrate", "--data", nc, "--out", tmp_path / "out", "--no-figures", "--quiet"])
    assert r.code == 0, r.err
    said = (f"magnetometer: {nc} holds magnetic_field (nT), not read: no magnetometer calibrated (map it to "
            "calibrate it: --columns mx=magnetic_field")
    assert said in r.err and said in (tmp_path / "out" / "report.txt").read_text()
    assert load_calibration(tmp_path / "out" / "calibration.yaml").sensor("magnetometer") is None


@pytest.mark.parametrize("name", ["b\nimucal: error: injected", "b\x00c", "x" * 300])
def test_a_hostile_field_variable_name_stays_one_line(tmp_path, name):
    """The unread variable's name reaches the warning (stderr, report.txt) as one printable line."""
    nc = write_nc(tmp_path / "f.nc", np.tile([0.0, 0.0, 1.0], (10, 1)), np.arange(10.0), acc_units="g")
    with h5py.File(nc, "a") as f:
        f.create_dataset(name, data=np.full((10, 3), 0.5)).attrs["units"] = "uT"
    rec = load_recording(str(nc))
    assert rec.mag_unread and rec.mag_unread.isprintable() and len(rec.mag_unread) < 80


@pytest.mark.parametrize("case", ["huge", "shape", "units", "length"])
def test_a_hostile_mapped_field_variable_is_one_line(tmp_path, run_cli, unchanged, case):
    n = 40
    acc = np.tile([0.0, 0.0, 1.0], (n, 1))
    nc = write_nc(tmp_path / "f.nc", acc, np.arange(float(n)), acc_units="g")
    data = {"huge": np.full((n, 3), 1e300), "shape": np.full((n, 4), 0.5), "units": np.full((n, 3), 0.5),
            "length": np.full((n - 3, 3), 0.5)}[case]
    with h5py.File(nc, "a") as f:
        f.create_dataset("b", data=data).attrs["units"] = "furlongs" if case == "units" else "uT"
    with unchanged(tmp_path):
        r = run_cli(["calibrate", "--data", nc, "--columns", "mx=b", "--out", tmp_path / "out"])
    assert r.code == 2 and r.err.count("\n") == 1 and "fix: " in r.err, r.err
    assert not (tmp_path / "out").exists()
