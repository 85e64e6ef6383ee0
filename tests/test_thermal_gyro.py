"""The gyroscope's bias(T) carried by the calibration (issue 27): its description takes the grammar's
temperature terms, the sweep's calibration holds them in its gyroscope section, and `imucal apply`, the
generated C and the ArduPilot INS_TCAL1_GYR* / PX4 TC_G0_* parameters all correct with them.

The sweep is test_thermal's (three one-axis-down poses, 5 -> 25 -> 5 degC) with gx, gy, gz written here by an
independent forward model: a constant bias, each pose's Earth rate, plain powers of (T - 15) (not the grammar's
orthogonal terms) and white noise. The firmware formulas are written from the autopilots' sources, as
tests/test_thermal_firmware.py writes them for the accelerometer:
  ArduPilot  AP_InertialSensor_tempcal.cpp TCal::correct_gyro -> correct_sensor: T, T_cal clamped to
             [TMIN, TMAX]; v -= P(T - 35); v += P(T_cal - 35), P(x) = (c1 + (c2 + c3 x) x) x 1e-6 in float,
             T_cal = INS_GYR1_CALTEMP; then _rotate_and_correct_gyro: gyro -= INS_GYROFFS.
  PX4        TemperatureCompensation.cpp calc_thermal_offsets_3D with TC_G0_*: dT = clamp(T) - TREF,
             o = X0 + X1 dT + X2 dT^2 + X3 dT^3 in float; Gyroscope.hpp Correct(): v - o - CAL_GYRO0_*OFF.
"""
from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from test_thermal import MG, NOMINAL, sweep
from test_thermal_firmware import _export, ardupilot, px4
from imucal.analysis.discover import discover
from imucal.calibration.frozen import load_calibration
from imucal.config.run import config_from_dict
from imucal.errors import ImucalError
from imucal.model.effects import make_effect
from imucal.model.gyroscope import LABEL, NAMES, gyro_model
from imucal.model.registry import describe

GCC = shutil.which("gcc")
F = np.float32
#: the accelerometer's truth: bias terms only (both autopilots hold them)
ACC = {"bias1": (0.6 * MG, -2.2 * MG, 2.5 * MG), "bias2": (0.0, 0.05 * MG, 0.0), "scale1": (0.0, 0.0, 0.0)}
#: the gyroscope's truth [rad/s]: bias, and bias(T) = G1 (T - 15) + G2 (T - 15)^2: x linear, y quadratic, z none
G0 = np.array([0.01, -0.02, 0.005])
G1 = np.array([3e-4, -2e-4, 0.0])
G2 = np.array([0.0, 1e-5, 0.0])
#: each pose's Earth rate on the gyro's axes [rad/s] (z, x, y down): the still poses' nuisance
EARTH = np.array([[5e-5, 0.0, -5e-5], [-5e-5, 3e-5, 0.0], [0.0, -5e-5, 3e-5]])
HOURS = 2.0
NOISE = 1e-4  # [rad/s] per 1 Hz sample


def truth(temp: np.ndarray) -> np.ndarray:
    """(n, 3) the gyro's bias at ``temp`` [rad/s]."""
    dT = np.asarray(temp, float) - 15.0
    return G0 + np.outer(dT, G1) + np.outer(dT ** 2, G2)


def gyro_sweep(path: Path, per_rad_s: float = 1.0) -> Path:
    """test_thermal's sweep with gx, gy, gz [rad/s, or ``per_rad_s`` units per rad/s] (module docstring)."""
    acc = np.loadtxt(sweep(path.with_suffix(".acc.csv"), truth=ACC, seed=11, hours=HOURS), delimiter=",", skiprows=1)
    pose = np.minimum((acc[:, 0] // (HOURS * 3600 + 120)).astype(int), 2)
    g = truth(acc[:, 4]) + EARTH[pose] + np.random.default_rng(5).normal(0, NOISE, (acc.shape[0], 3))
    np.savetxt(path, np.column_stack([acc[:, :4], g * per_rad_s, acc[:, 4]]), delimiter=",",
               header="t,ax,ay,az,gx,gy,gz,temp", comments="", fmt="%.10g")
    return path


@pytest.fixture(scope="module")
def cal_path(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("gyrot")
    path = gyro_sweep(root / "sweep.csv")
    d = discover(config_from_dict({"data": {"path": str(path), "time_unit": "s", "gyro_unit": "rad/s"},
                                   "fit": {"fix": dict(NOMINAL)}}))
    assert d.thermal is not None and d.thermal.gyro is not None and d.thermal.gyro.orders == (1, 2, 0)
    out = root / "calibration.yaml"
    d.calibration_run.calibration.save(out)
    return out


def test_a_gyroscope_without_terms_is_described_as_before():
    """No terms: the 21 names, the inputs ax, ay, az, the model's name; the registry reads a name with terms."""
    g = gyro_model()
    assert g.names == NAMES and g.inputs == ("ax", "ay", "az") and g.name == LABEL and g.is_affine
    assert gyro_model([]) is g
    t = gyro_model([make_effect("bias_temperature", (0, 1)), make_effect("bias_temperature2", (1,))])
    assert t.name == LABEL + "+bias_temperature[xy]+bias_temperature2[y]"
    assert t.inputs == ("ax", "ay", "az", "temp") and t.names[:21] == NAMES
    assert {"bias_temperature_x", "bias_temperature_tref", "bias_temperature2_a2"} <= set(t.names)
    assert describe("gyroscope", t.name) is t


def test_a_specific_force_term_is_refused_for_the_gyroscope():
    with pytest.raises(ImucalError, match="the gyroscope takes no 'scale_nonlinearity' term"):
        gyro_model([make_effect("scale_nonlinearity", (0,))])


def test_the_calibration_file_carries_the_gyroscope_bias_over_temperature(cal_path):
    cal = load_calibration(cal_path)
    g = cal.gyro
    assert g is not None
    assert g.model.name == LABEL + "+bias_temperature[xy]+bias_temperature2[y]"
    assert g.params["bias_temperature_x"].unit == "rad/s/degC" and g.params["bias_temperature2_y"].unit == \
        "rad/s/degC^2"
    assert g.params["bias_temperature_tref"].fixed and g.std["bias_temperature_x"] > 0
    assert all(g.params[n].fixed for n in NAMES)  # scale, misalignment, g-sensitivity: not from still poses
    tref = g.reference_inputs()["temp"]
    slope = G1 + 2 * G2 * (tref - 15.0)  # the orthogonal linear term: the slope at T_ref
    for i, a in enumerate("xy"):
        n = f"bias_temperature_{a}"
        assert abs(g.params[n].value - slope[i]) < 5 * g.std[n] + 1e-7, (n, g.params[n].value, slope[i])
    section = yaml.safe_load(cal_path.read_text())["gyroscope"]
    assert section["inputs"] == ["ax", "ay", "az", "temp"]
    assert "at temp = " in section["apply"]["equation"] and "terms move it with temp" in section["apply"]["equation"]


def _apply(cli, cal: Path, gyro: np.ndarray, temp: np.ndarray, tmp: Path) -> np.ndarray:
    """``imucal apply`` on a CSV with ax.., gx.. and temp: the calibrated rate."""
    src, n = tmp / "in.csv", gyro.shape[0]
    acc = np.tile([0.0, 0.0, -9.8], (n, 1))
    np.savetxt(src, np.column_stack([np.arange(n) * 0.01, acc, gyro, temp]), delimiter=",",
               header="t,ax,ay,az,gx,gy,gz,temp", comments="", fmt="%.12g")
    r = cli(["apply", cal, "--data", src, "--out", tmp / "out.csv"])
    assert r.code == 0, r.err
    return np.loadtxt(tmp / "out.csv", delimiter=",", skiprows=1)[:, 4:7]


def test_apply_removes_the_known_bias_over_temperature(cal_path, run_cli, tmp_path):
    """A still gyro's readings over 5..25 degC (the truth's bias(T), 7 mrad/s of change) calibrate to within the
    Earth's rate and the fit's error of zero."""
    T = np.linspace(5.5, 24.5, 39)
    raw = truth(T)
    assert np.ptp(raw, axis=0).max() > 5e-3
    omega = _apply(run_cli, cal_path, raw, T, tmp_path)
    assert np.abs(omega).max() < 1e-4, np.abs(omega).max(axis=0)
    assert np.ptp(omega, axis=0).max() < 2e-5  # the temperature's part is gone


def test_the_file_loads_back_to_the_same_map_and_a_bad_term_name_is_refused(cal_path, tmp_path, run_cli):
    cal = load_calibration(cal_path)
    again = tmp_path / "again.yaml"
    cal.save(again)
    raw, inp = truth(np.array([7.0, 21.0])), np.array([[0, 0, -9.8, 7.0], [0, 0, -9.8, 21.0]])
    np.testing.assert_array_equal(load_calibration(again).gyro.apply(raw, inp), cal.gyro.apply(raw, inp))
    bad = tmp_path / "bad.yaml"
    bad.write_text(cal_path.read_text().replace("+bias_temperature2[y]", "+bias_bogus[y]"))
    r = run_cli(["codegen", bad, "--out", tmp_path / "c"])
    assert r.code == 2 and r.err.count("\n") == 1 and "gyroscope.model" in r.err and "is not this imucal" in r.err
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
def test_the_autopilots_gyro_formula_gives_what_apply_gives(cal_path, run_cli, tmp_path, fmt):
    """Inside the range the firmware's own polynomial equals apply to float precision; outside it the firmware
    holds the end value: apply at the clamped temperature."""
    rng = np.random.default_rng(4)
    raw = truth(rng.uniform(5, 25, 200)) + rng.normal(0, 0.5, (200, 3))
    temp = rng.uniform(-20.0, 60.0, 200)
    params = _export(run_cli, cal_path, fmt, tmp_path)
    lo, hi = (params["INS_TCAL1_TMIN"], params["INS_TCAL1_TMAX"]) if fmt == "ardupilot" else \
        (params["TC_G0_TMIN"], params["TC_G0_TMAX"])
    assert (lo, hi) == pytest.approx(tuple(load_calibration(cal_path).gyro.fit["temperature_range"]), abs=1e-9)
    firmware = ardupilot(params, raw, temp, "GYR") if fmt == "ardupilot" else px4(params, raw, temp, "G")
    ref = _apply(run_cli, cal_path, raw, np.clip(temp, lo, hi), tmp_path)
    assert np.abs(firmware - ref).max() < 1e-6  # float32 on readings of 0.5 rad/s
    inside = (temp > lo) & (temp < hi)
    moved = np.abs(_apply(run_cli, cal_path, raw, temp, tmp_path) - ref).max(axis=1)
    assert inside.any() and np.all(moved[inside] == 0) and moved[~inside].max() > 1e-3


@pytest.mark.skipif(GCC is None, reason="gcc not found")
@pytest.mark.parametrize("precision", ["float", "double"])
def test_the_generated_c_corrects_the_gyro_bias_over_temperature(cal_path, run_cli, tmp_path, precision):
    """imucal codegen: the gyro's function reads temp from cov; compiled with -Werror, equal to apply (float
    and int16 counts)."""
    r = run_cli(["codegen", cal_path, "--out", tmp_path / "c", "--precision", precision, "--prefix", "gt"])
    assert r.code == 0, r.err
    lib = tmp_path / "c" / "libgt.so"
    subprocess.run([GCC, "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-fPIC", "-shared", "-o",
                    str(lib), str(tmp_path / "c" / "gt.c"), "-lm"], check=True, capture_output=True, text=True)
    dll, R = ctypes.CDLL(str(lib)), (F if precision == "float" else np.float64)
    rng = np.random.default_rng(6)
    temp = rng.uniform(0.0, 30.0, 50)
    raw = truth(temp) + rng.normal(0, 0.3, (50, 3))
    acc, cov = np.tile(R([0, 0, -9.8]), (50, 1)), temp.astype(R)[:, None]
    ref = load_calibration(cal_path).gyro.apply(raw.astype(R).astype(float),
                                                np.column_stack([acc.astype(float), cov.astype(float)]))
    tol = 1e-6 if precision == "float" else 1e-13
    out = np.zeros((50, 3), R)
    fn = dll.gt_apply_gyro
    for k in range(50):
        a, g, c = (np.ascontiguousarray(x[k], R) for x in (acc, raw, cov))
        o = np.zeros(3, R)
        fn(g.ctypes.data_as(ctypes.c_void_p), a.ctypes.data_as(ctypes.c_void_p), c.ctypes.data_as(ctypes.c_void_p),
           o.ctypes.data_as(ctypes.c_void_p))
        out[k] = o
    assert np.abs(out - ref).max() < tol
    counts = np.array([[12, -7, 3]], np.int16)  # the integer entry point: the same map on exact conversions
    o = np.zeros(3, R)
    dll.gt_apply_gyro_i16(counts.ctypes.data_as(ctypes.c_void_p), acc[0].ctypes.data_as(ctypes.c_void_p),
                          cov[0].ctypes.data_as(ctypes.c_void_p), o.ctypes.data_as(ctypes.c_void_p))
    want = load_calibration(cal_path).gyro.apply(counts.astype(float), np.r_[acc[0], cov[0]].astype(float)[None])
    assert np.abs(o - want[0]).max() < tol * 100


def _plain(cal_path: Path, tmp: Path) -> Path:
    """The sweep's calibration with an accelerometer without temperature terms (its base parameters only)."""
    from imucal.calibration.frozen import Calibration
    from imucal.model.parameters import BASE_NAMES, Parameters

    cal = load_calibration(cal_path)
    plain = Calibration(params=Parameters([cal.params[n] for n in BASE_NAMES]), std={}, gravity=cal.gravity,
                        raw_unit=cal.raw_unit, attached=(cal.gyro,))
    path = tmp / "plain.yaml"
    plain.save(path)
    return path


def test_apply_reads_temp_for_the_gyroscope_alone_and_refuses_data_without_it(cal_path, run_cli, tmp_path):
    """The accelerometer's map reads no covariate, the gyroscope's reads temp: apply takes the temp column for it;
    data without one are refused in one line, naming the column, and nothing is written."""
    path = _plain(cal_path, tmp_path)
    T = np.array([6.0, 24.0])
    omega = _apply(run_cli, path, truth(T), T, tmp_path)
    assert np.abs(omega).max() < 1e-4
    src = tmp_path / "notemp.csv"
    src.write_text("t,ax,ay,az,gx,gy,gz\n0,0,0,-9.8,0.01,0.02,0.03\n1,0,0,-9.8,0.01,0.02,0.03\n")
    r = run_cli(["apply", path, "--data", src, "--out", tmp_path / "o.csv"])
    assert r.code == 2 and r.err.count("\n") == 1 and not (tmp_path / "o.csv").exists()
    assert "notemp.csv: data.columns.temp: the calibration has a temperature effect but the data have no temp " \
           "column (fix: add temp (degC)" in r.err


@pytest.mark.skipif(GCC is None, reason="gcc not found")
def test_the_c_of_a_gyro_temperature_beside_an_accelerometer_without_terms(cal_path, run_cli, tmp_path):
    """cov then holds what the gyroscope alone reads: NAME_apply stays (raw only), NAME_N_COV is 1 and
    NAME_apply_imu_cov calibrates both, equal to Calibration.apply_all."""
    path = _plain(cal_path, tmp_path)
    r = run_cli(["codegen", path, "--out", tmp_path / "c", "--precision", "double", "--prefix", "pg"])
    assert r.code == 0, r.err
    header = (tmp_path / "c" / "pg.h").read_text()
    assert "#define PG_N_COV 1" in header and "void pg_apply(const double raw[3], double acc[3]);" in header
    assert "#define PG_COV_TEMP 0" in header
    lib = tmp_path / "c" / "libpg.so"
    subprocess.run([GCC, "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-fPIC", "-shared", "-o",
                    str(lib), str(tmp_path / "c" / "pg.c"), "-lm"], check=True, capture_output=True, text=True)
    dll = ctypes.CDLL(str(lib))
    raw_a, raw_g, temp = np.array([0.1, -0.2, -9.7]), truth(np.array([8.0]))[0] + 0.2, np.array([8.0])
    acc, omega = np.zeros(3), np.zeros(3)
    dll.pg_apply_imu_cov(*(x.ctypes.data_as(ctypes.c_void_p) for x in (raw_a, raw_g, temp, acc, omega)))
    want = load_calibration(path).apply_all({"accelerometer": raw_a[None], "gyroscope": raw_g[None]}, {"temp": temp})
    assert np.abs(acc - want["accelerometer"][0]).max() < 1e-12 and np.abs(omega - want["gyroscope"][0]).max() < 1e-13


def test_discover_writes_the_gyroscope_section_and_its_report(cal_path, run_cli, tmp_path):
    """`imucal discover --config run.yaml --out cal` on the sweep: the file's gyroscope section holds bias(T), the
    text report names it as in the file, report.html shows the gyroscope's parameters."""
    cfg = tmp_path / "run.yaml"
    cfg.write_text(f"data: {{path: {cal_path.parent / 'sweep.csv'}, time_unit: s, gyro_unit: rad/s}}\n"
                   f"fit:\n  fix: {NOMINAL}\n".replace("'", ""))
    r = run_cli(["discover", "--config", cfg, "--out", tmp_path / "cal"])
    assert r.code == 0, r.err
    assert "gyroscope bias(T) (in the calibration's gyroscope section" in r.out
    cal = load_calibration(tmp_path / "cal" / "calibration.yaml")
    assert cal.gyro is not None and [e.name for e in cal.gyro.model.effects] == ["bias_temperature",
                                                                                  "bias_temperature2"]
    page = (tmp_path / "cal" / "report.html").read_text()
    assert "bias_temperature2_y" in page and "still poses over a temperature sweep" in page


def test_the_peers_without_temperature_terms_say_what_they_drop(cal_path, run_cli, tmp_path):
    """Kalibr holds no temperature term: the gyroscope's map is written at T_ref, and the note says so."""
    r = run_cli(["export", cal_path, "--format", "kalibr", "--out", tmp_path / "imu.yaml"])
    assert r.code == 0, r.err
    assert ("gyroscope terms not exported: bias_temperature (xy), bias_temperature2 (y); its map written is the "
            "calibration's at temp = ") in r.out + r.err
    g = load_calibration(cal_path).gyro
    offset = yaml.safe_load((tmp_path / "imu.yaml").read_text())["imucal_gyroscope_offset"]
    np.testing.assert_allclose(offset, g.at_reference().forward().s, rtol=1e-12)


def test_a_sweep_in_deg_s_is_calibrated_in_its_own_unit(tmp_path, run_cli):
    """gx, gy, gz in deg/s: the section's raw unit and coefficients in deg/s, apply's output in rad/s."""
    k = 180.0 / np.pi
    path = gyro_sweep(tmp_path / "deg.csv", per_rad_s=k)
    d = discover(config_from_dict({"data": {"path": str(path), "time_unit": "s", "gyro_unit": "deg/s"},
                                   "fit": {"fix": dict(NOMINAL)}}))
    g = d.calibration_run.calibration.gyro
    assert g is not None and g.raw_unit == "deg/s" and g.params["bias_temperature_x"].unit == "deg/s/degC"
    assert g.params["scale_x"].value == pytest.approx(k)
    T = np.linspace(5.5, 24.5, 20)
    omega = g.apply(truth(T) * k, np.column_stack([np.zeros((20, 3)), T]))
    assert np.abs(omega).max() < 1e-4 and np.ptp(omega, axis=0).max() < 2e-5
