"""The magnetometer as the core's third sensor (issue 26): one description, and every output takes it from there.

One simulated 9-axis log (imucal.mag.simulate: known hard iron, symmetric soft iron, the AK8963 mounting and a
further 1.9 deg rotation) is calibrated once by the command line; the tests read its calibration file, its
`apply` output and its generated C.
"""
from __future__ import annotations

import ctypes
import math

import numpy as np
import pytest
import yaml

from imucal.calibration.frozen import load_calibration
from imucal.errors import ImucalError
from imucal.mag.model import axes_code, build_mag_model, described, label_of, permutation, vectorized
from imucal.mag.simulate import simulate_mag, truth_from_soft_iron
from imucal.model.registry import describe
from imucal.model.sensor import MAGNETOMETER
from imucal.solve.vectorize import apply_values

AK8963 = (0, 1, 0, 1, 0, 0, 0, 0, -1)
SOFT = np.array([[1.05, 0.03, -0.02], [0.03, 0.97, 0.01], [-0.02, 0.01, 1.01]])
HARD = (10.0, -5.0, 3.0)  #: [raw]
FIELD_UT = 48.0
MISALIGNMENT_DEG = (1.0, -0.5, 1.5)
#: The accelerometer's raw readings [g]: scales and offsets of a few per cent
ACC_SCALE, ACC_SHIFT = np.array([1.02, 0.98, 1.01]), np.array([0.02, -0.01, 0.03])
RATE = 100.0  #: [Hz]


def write_log(path, seed: int = 1, columns=("t", "ax", "ay", "az", "mx", "my", "mz")) -> None:
    """A 9-axis log: 24 still poses of 3 s with 1 s turns, the magnetometer in counts of a 1-uT-ish size."""
    truth = truth_from_soft_iron(SOFT, s=HARD, field=FIELD_UT, axes=AK8963, misalignment=np.radians(MISALIGNMENT_DEG),
                                 noise=0.1, acc_noise=0.002)
    sim = simulate_mag(truth, n_poses=24, hold=300, transition=100, seed=seed)
    data = {"t": np.arange(len(sim.acc)) / RATE}
    acc = sim.acc * ACC_SCALE + ACC_SHIFT
    data.update({c: acc[:, i] for i, c in enumerate(("ax", "ay", "az"))})
    data.update({c: sim.mag[:, i] for i, c in enumerate(("mx", "my", "mz"))})
    np.savetxt(path, np.column_stack([data[c] for c in columns]), delimiter=",", header=",".join(columns),
               comments="", fmt="%.8g")


@pytest.fixture(scope="module")
def nine_axis(tmp_path_factory):
    from imucal.cli.main import main

    d = tmp_path_factory.mktemp("mag9")
    write_log(d / "log.csv")
    assert main(["calibrate", "--data", str(d / "log.csv"), "--mag-field", "48uT", "--out", str(d / "out"),
                 "--no-figures", "--quiet"]) == 0
    return d


# --- the description -------------------------------------------------------------------------

def test_the_description_is_named_by_its_mounting_and_field_unit_and_rebuilt_from_the_name():
    m = build_mag_model(AK8963, "uT")
    assert m.kind == MAGNETOMETER and m.name == "magnetometer-ellipsoid[axes=+y+x-z,field=uT]"
    assert axes_code(AK8963) == "+y+x-z" and label_of(AK8963, "uT") == m.name
    assert describe(MAGNETOMETER, m.name) is m and described(m.name) is m
    assert np.array_equal(permutation(m), np.array(AK8963, float).reshape(3, 3))
    assert m.output.columns == ("mx", "my", "mz") and m.output.unit == "uT" and m.inputs == ()
    assert m.evidence_covariates == ("evidence", "ax", "ay", "az")


def test_apply_affine_and_generated_numpy_are_the_models_field_map():
    rng = np.random.default_rng(4)
    m = build_mag_model(AK8963, "uT")
    p = np.array([0.3, -0.2, 0.1, 1.1, 0.9, 1.05, 1.62, 1.52, 1.6, 0.04, -0.07, 0.12, 48.0, -0.9])
    raw = rng.normal(size=(20, 3)) * 40
    want = np.asarray(vectorized(m, "field")(raw.T, p)[0]).T
    assert np.allclose(apply_values(m, p, raw), want, rtol=0, atol=1e-12)
    A, c, B = (np.asarray(v, float) for v in m.affine(p))
    assert B.size == 0 and np.allclose(raw @ A.T + c.ravel(), want, rtol=0, atol=1e-11)


def test_an_unknown_model_name_in_a_file_is_refused_in_one_line():
    with pytest.raises(ImucalError) as e:
        describe(MAGNETOMETER, "magnetometer-ellipsoid[axes=+x+x+z,field=uT]", MAGNETOMETER, "cal.yaml")
    assert str(e.value).startswith("cal.yaml: magnetometer.model: model 'magnetometer-ellipsoid[axes=+x+x+z,")
    with pytest.raises(ImucalError, match="magnetometer.model: model 'nonsense' is not this imucal's magnetometer"):
        describe(MAGNETOMETER, "nonsense", MAGNETOMETER, "cal.yaml")


# --- the run, the file, apply -------------------------------------------------------------------

def test_calibrate_fits_the_magnetometer_and_the_file_holds_its_section(nine_axis):
    doc = yaml.safe_load((nine_axis / "out" / "calibration.yaml").read_text())
    sec = doc["magnetometer"]
    assert doc["format_version"] == 3 and sec["kind"] == "magnetometer"
    assert sec["model"] == "magnetometer-ellipsoid[axes=+y+x-z,field=uT]"  # the AK8963 mounting found
    assert sec["units"] == {"input": "raw", "output": "uT"} and sec["inputs"] == []
    f = sec["fit"]
    assert f["norm_residual_pct"]["after"] < 1.5 * f["norm_residual_pct"]["floor"]
    assert f["dip_scatter_deg"]["after"] < f["dip_scatter_deg"]["before"]
    assert f["misalignment_deg"] == pytest.approx(np.linalg.norm(MISALIGNMENT_DEG), abs=0.1)
    cal = load_calibration(nine_axis / "out" / "calibration.yaml")
    m = cal.sensor(MAGNETOMETER)
    assert cal.sensors == ("accelerometer", "magnetometer") and m is not None
    for i, s in enumerate(HARD, 1):  # hard iron recovered within 5 standard errors
        assert abs(m.params[f"s{i}"].value - s) < 5 * m.std[f"s{i}"]
    assert m.params["F"].fixed and m.params["F"].value == FIELD_UT


def test_the_file_round_trips_and_an_edited_apply_map_is_refused(nine_axis, tmp_path):
    cal = load_calibration(nine_axis / "out" / "calibration.yaml")
    cal.save(tmp_path / "again.yaml")
    back = load_calibration(tmp_path / "again.yaml").sensor(MAGNETOMETER)
    assert back is not None and back.params == cal.sensor(MAGNETOMETER).params
    doc = yaml.safe_load((tmp_path / "again.yaml").read_text())
    doc["magnetometer"]["apply"]["offset"][0] += 1.0
    (tmp_path / "edited.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(ImucalError, match="magnetometer.apply.offset: does not match the parameters"):
        load_calibration(tmp_path / "edited.yaml")


def test_apply_writes_the_calibrated_field_beside_the_acceleration(nine_axis, run_cli):
    out = nine_axis / "applied.csv"
    r = run_cli(["apply", str(nine_axis / "out" / "calibration.yaml"), "--data", str(nine_axis / "log.csv"),
                 "--out", str(out)])
    assert r.code == 0 and "magnetic field [uT]" in r.out
    head = out.read_text().splitlines()[0]
    assert head == "t,ax,ay,az,mx,my,mz"
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    h = data[:, 4:7]
    assert np.sqrt(np.mean((np.linalg.norm(h, axis=1) / FIELD_UT - 1) ** 2)) < 0.005  # |h| = F within the noise
    raw = np.loadtxt(nine_axis / "log.csv", delimiter=",", skiprows=1)[:, 4:7]
    m = load_calibration(nine_axis / "out" / "calibration.yaml").sensor(MAGNETOMETER)
    assert np.allclose(h, m.apply(raw), rtol=1e-8, atol=1e-6)


def test_reports_carry_the_magnetometer(nine_axis):
    html = (nine_axis / "out" / "report.html").read_text()
    assert "Magnetometer" in html and "hard iron x" in html and "dip-angle scatter" in html and "Per pose" in html
    text = (nine_axis / "out" / "report.txt").read_text()
    assert "[[Magnetometer]]" in text and "field-norm residual" in text


# --- refusals -----------------------------------------------------------------------------------

def test_mx_without_my_is_refused_in_one_line_and_nothing_is_written(tmp_path, run_cli, unchanged):
    write_log(tmp_path / "log.csv", columns=("t", "ax", "ay", "az", "mx", "mz"))
    with unchanged(tmp_path):
        r = run_cli(["calibrate", "--data", str(tmp_path / "log.csv"), "--mag-field", "48uT", "--out",
                     str(tmp_path / "out")])
    assert r.code == 2 and r.err.count("\n") == 1 and r.err.startswith(f"imucal: error: {tmp_path / 'log.csv'}: ")
    assert "my" in r.err


def test_a_field_that_is_not_a_magnitude_is_refused_in_one_line(tmp_path, run_cli):
    write_log(tmp_path / "log.csv")
    r = run_cli(["calibrate", "--data", str(tmp_path / "log.csv"), "--mag-field", "-3uT", "--out",
                 str(tmp_path / "out")])
    assert r.code == 2 and r.err.count("\n") == 1 and "--mag-field" in r.err
    assert not (tmp_path / "out").exists()


# --- the C -----------------------------------------------------------------------------------

@pytest.mark.parametrize("precision", ["float", "double"])
def test_generated_c_matches_python_within_the_a_priori_bound(nine_axis, tmp_path, precision):
    from test_codegen import GCC, compile_shared

    from imucal.export.codegen import write_c
    from imucal.export.codegen_sensor import affine_float_error_bound

    if GCC is None:
        pytest.skip("gcc not found")
    cal = load_calibration(nine_axis / "out" / "calibration.yaml")
    m = cal.sensor(MAGNETOMETER)
    write_c(cal, tmp_path, prefix="nine", precision=precision)
    lib = compile_shared(tmp_path, "nine")
    dtype = np.float32 if precision == "float" else np.float64
    raw = np.loadtxt(nine_axis / "log.csv", delimiter=",", skiprows=1)[::7, 4:7]
    raw = np.ascontiguousarray(raw.astype(dtype))
    out = np.zeros_like(raw)
    lib.nine_apply_mag_batch(ctypes.c_void_p(raw.ctypes.data), ctypes.c_void_p(out.ctypes.data),
                             ctypes.c_size_t(raw.shape[0]))
    ref = m.apply(raw.astype(float))
    bound = affine_float_error_bound(m, raw.astype(float), None, precision) + 1e-12 * np.abs(ref)
    assert np.all(np.abs(out - ref) <= bound)
    ints = np.random.default_rng(5).integers(-32768, 32768, (500, 3)).astype(np.int16)
    one = np.zeros(3, dtype)
    for k in range(0, 500, 25):
        v = (ctypes.c_int16 * 3)(*map(int, ints[k]))
        lib.nine_apply_mag_i16(ctypes.byref(v), ctypes.c_void_p(one.ctypes.data))
        want = m.apply(ints[k].astype(float))
        assert np.all(np.abs(one - want) <= affine_float_error_bound(m, ints[k:k + 1].astype(float), None,
                                                                     precision)[0] + 1e-12 * np.abs(want))
    assert math.isfinite(float(np.max(np.abs(out - ref))))


def test_batch_calibrates_the_magnetometer_of_every_unit(tmp_path, run_cli):
    for k in (1, 2):
        write_log(tmp_path / f"U{k}.csv", seed=k)
    (tmp_path / "units.yaml").write_text("units:\n  - {id: U1, data: U1.csv}\n  - {id: U2, data: U2.csv}\n"
                                         "settings:\n  mag: {field: 48.0, field_unit: uT}\n")
    r = run_cli(["batch", str(tmp_path / "units.yaml"), "--out", str(tmp_path / "fleet"), "--workers", "1",
                 "--no-figures"])
    assert r.code == 0, r.err
    for k in (1, 2):
        m = load_calibration(tmp_path / "fleet" / f"U{k}" / "calibration.yaml").sensor(MAGNETOMETER)
        assert m is not None and m.model.output.unit == "uT" and m.params["F"].value == FIELD_UT
    import csv

    rows = list(csv.DictReader((tmp_path / "fleet" / "fleet.csv").open()))
    assert all(float(r["mag_norm_residual_pct"]) < 0.5 and float(r["mag_dip_scatter_deg"]) < 0.1 for r in rows)


def test_the_symmetric_soft_iron_is_symmetric_whatever_the_field_unit():
    """The SKEW rows hold P^T A symmetric to their 1e-6 for a field of 48 uT as for one of 0.5 gauss (a noise floor
    taken across kinds of rows, in the field's unit, once loosened them to 1e-4)."""
    from imucal.mag.calibrate import MagSettings, calibrate_mag

    truth = truth_from_soft_iron(SOFT, s=HARD, field=FIELD_UT, axes=AK8963, misalignment=np.radians(MISALIGNMENT_DEG),
                                 noise=0.1, acc_noise=0.002)
    sim = simulate_mag(truth, n_poses=20, hold=60, transition=30, seed=2)
    cal = calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=FIELD_UT, soft_iron="symmetric"))
    M = permutation(cal.fit.model).T @ cal.linear_map()[0]
    assert not cal.full_soft_iron and np.max(np.abs(M - M.T)) < 1e-5 * np.trace(M) / 3
    assert math.degrees(cal.misalignment) < 1e-3


def test_a_magnetometer_whose_field_never_turns_is_refused_naming_what_to_record(tmp_path, run_cli, unchanged):
    """The observability check through the command line: one line naming what the directions leave undetermined
    and what to record, exit 2, nothing written (the accelerometer's part is not written either)."""
    write_log(tmp_path / "log.csv")
    d = np.loadtxt(tmp_path / "log.csv", delimiter=",", skiprows=1)
    d[:, 4:7] = np.array([20.0, 5.0, -40.0]) + np.random.default_rng(0).normal(0, 0.1, (len(d), 3))
    np.savetxt(tmp_path / "log.csv", d, delimiter=",", header="t,ax,ay,az,mx,my,mz", comments="", fmt="%.8g")
    with unchanged(tmp_path):
        r = run_cli(["calibrate", "--data", str(tmp_path / "log.csv"), "--mag-field", "48uT", "--out",
                     str(tmp_path / "out")])
    assert r.code == 2 and r.err.count("\n") == 1
    assert r.err.startswith(f"imucal: error: {tmp_path / 'log.csv'}: mx, my, mz: the field's directions ")
    assert ("undetermined (fix: turn the sensor through more orientations, the field along every axis both ways; "
            "or calibrate without the magnetometer: --no-mag (mag.calibrate: false))") in r.err


def test_a_field_that_steps_and_a_pose_far_off_are_named_in_the_warnings():
    """The typed FieldSteps and excluded poses rendered to words in report/ (imucal.report.mag.mag_warnings)."""
    from imucal.mag.calibrate import MagSettings, calibrate_mag
    from imucal.report.mag import mag_warnings

    truth = truth_from_soft_iron(SOFT, axes=AK8963, misalignment=np.radians(MISALIGNMENT_DEG))
    sim = simulate_mag(truth, n_poses=24, seed=11, disturbed={k: 1.04 for k in range(14, 24)})
    words = mag_warnings(calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=truth.field)))
    step = [w for w in words if w.startswith("magnetometer: the field's magnitude steps by +")]
    assert len(step) == 1 and "% after pose 14 (a disturbed environment" in step[0]
    one = simulate_mag(truth, n_poses=24, seed=11, disturbed={7: 1.06})
    cal = calibrate_mag(one.mag, one.acc, still=one.holds, settings=MagSettings(field=truth.field))
    assert any("pose(s) whose field stood out were left out of the fit" in w for w in mag_warnings(cal))


def test_a_large_file_with_magnetometer_columns_is_read_whole(tmp_path, monkeypatch, run_cli):
    """The magnetometer's fit reads every sample, which a file read in chunks does not keep: auto reads a large
    9-axis file whole (as one with a gyroscope), and --stream always is refused in one line naming it."""
    import imucal.data.load as load_mod
    from imucal.data.load import other_sensors, use_stream
    from imucal.data.spec import DataSpec

    write_log(tmp_path / "log.csv")
    monkeypatch.setattr(load_mod, "STREAM_BYTES", 1000)
    spec = DataSpec(path=str(tmp_path / "log.csv"))
    assert other_sensors(spec) == ("magnetometer",) and not use_stream(spec)
    r = run_cli(["calibrate", "--data", str(tmp_path / "log.csv"), "--out", str(tmp_path / "o"), "--stream", "always"])
    assert r.code == 2 and "--stream: has magnetometer data, which reading in chunks does not keep" in r.err
    assert not (tmp_path / "o").exists()
