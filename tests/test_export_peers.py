"""Issue 14: Kalibr, ArduPilot and PX4 exports, every format read back, and `imucal compare`.

Each peer's formula is written HERE from the peer's source (cited), not taken from the export
code: exact agreement (1e-9 relative) where the format holds our model, and the residual the
file states where it cannot (ArduPilot and PX4 hold no misalignment)."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
import yaml

from conftest import calibrate_file, real_file
from imucal.calibration.frozen import Calibration
from imucal.errors import ImucalError
from imucal.export.formats import ExportOptions
from imucal.export.registry import FORMATS, export, read_peer
from imucal.model.effects import make_effect
from imucal.model.parameters import base_parameters

XSENS = ("xsens-mti-imutk", "xsens_acc.mat")
G_XSENS = 9.81744
#: file name per format (matrix twice: JSON and CSV)
FILES = {"imutk": "x.calib", "madlab": "x.json", "matrix": "x.json", "kalibr": "imu.yaml",
         "ardupilot": "x.param", "px4": "x.params"}


@pytest.fixture(scope="module")
def xsens():
    cal = calibrate_file(real_file(*XSENS), gravity={"value": G_XSENS}).calibration
    raw = np.loadtxt(real_file(*XSENS))[::50, 1:]
    return cal, raw


#: m/s^2 per count of the synthetic sensor (~1660 counts per m/s^2): its readings are in m/s^2, the unit
#: ArduPilot and PX4 hold (a calibration of counts is refused there, tests/test_trust_export.py).
K = 1.0 / 1662.0


def synthetic(effects: tuple[tuple[str, tuple[int, ...]], ...] = (), angles=(1.556, 1.585, 1.562)) -> Calibration:
    """A sensor reading m/s^2 (a counts sensor's numbers times K) with misaligned axes and,
    optionally, effects with non-zero coefficients."""
    s, b = [v * K for v in (120.0, -75.0, 40.0)], [v * K for v in (1660.0, 1675.0, 1648.0)]
    params = base_parameters(s, b, angles, raw_unit="m/s^2")
    params = params.with_values({**dict(zip(("s1", "s2", "s3", "b1", "b2", "b3"), s + b)),
                                 "phi": angles[0], "psi": angles[1], "theta": angles[2]})
    for name, axes in effects:
        params = params.extended(make_effect(name, axes).parameters(params))
    values = {n: 0.37 * (K if n.startswith("bias_") else 1.0)
              for n in params.names if n.startswith(("bias_", "scale_")) and not n.endswith("_tref")}
    values.update({n: 23.5 for n in params.names if n.endswith("_tref")})
    params = params.with_values(values)
    return Calibration(params=params, std={n: 0.0 for n in params.names}, gravity=9.80665, raw_unit="m/s^2",
                       effects=effects, data={"file": "synthetic.csv"}, created="2024-05-01T12:00:00+00:00")


def as_si(cal: Calibration, *raws: np.ndarray) -> tuple:
    """The same sensor with its readings converted to m/s^2 as a driver does, (raw - z) / k, z the
    shifts' mean (the ADC's zero) and k the mean sensitivity [raw per m/s^2] (the calibrated
    acceleration is unchanged), and ``raws`` converted alike: ArduPilot and PX4 hold offsets in m/s^2
    and refuse a calibration of counts such as the Xsens one (tests/test_trust_export.py)."""
    import dataclasses

    from imucal.model.parameters import Parameters

    z, k = float(np.mean(cal.values[0:3])), float(np.mean(cal.values[3:6]))
    shift = {"s1": z, "s2": z, "s3": z}
    params = Parameters(dataclasses.replace(
        p, value=(p.value - shift.get(n, 0.0)) / k, lower=(p.lower - shift.get(n, 0.0)) / k,
        upper=(p.upper - shift.get(n, 0.0)) / k, scale=p.scale / k, unit="m/s^2" if n in shift else "1")
        if n in ("s1", "s2", "s3", "b1", "b2", "b3") else p for n, p in cal.params.items())
    return (dataclasses.replace(cal, params=params, raw_unit="m/s^2"), *((r - z) / k for r in raws))


# --- the peers' formulas, from their sources ---------------------------------------------------
def kalibr_apply(text: str, raw: np.ndarray) -> np.ndarray:
    """Kalibr IccSensors.py, IccScaledMisalignedImu: measurement = M a + b_a; here b_a is the shift
    imucal writes beside M (Kalibr estimates its bias online)."""
    d = yaml.safe_load(text)
    assert d["model"] == "scale-misalignment"
    M, b = np.array(d["accelerometers"]["M"]), np.array(d["imucal_accelerometer_offset"])
    assert np.all(np.triu(M, 1) == 0)  # Kalibr's M_accel is lower triangular
    return np.linalg.solve(M, (raw - b).T).T


def ardupilot_apply(text: str, raw: np.ndarray) -> np.ndarray:
    """AP_InertialSensor_Backend::_rotate_and_correct_accel: accel -= offset; accel.x *= scale.x ..."""
    p = dict(ln.split(",") for ln in text.splitlines() if ln and not ln.startswith("#"))
    off = np.array([float(p[f"INS_ACCOFFS_{a}"]) for a in "XYZ"])
    scl = np.array([float(p[f"INS_ACCSCAL_{a}"]) for a in "XYZ"])
    return (raw - off) * scl


def px4_apply(text: str, raw: np.ndarray) -> np.ndarray:
    """PX4 sensor_calibration/Accelerometer.hpp Correct(): (data - thermal_offset - offset).emult(scale)."""
    p = {f[2]: float(f[3]) for f in (ln.split("\t") for ln in text.splitlines() if ln and not ln.startswith("#"))}
    off = np.array([p[f"CAL_ACC0_{a}OFF"] for a in "XYZ"])
    scl = np.array([p[f"CAL_ACC0_{a}SCALE"] for a in "XYZ"])
    return (raw - off) * scl


PEERS = {"kalibr": kalibr_apply, "ardupilot": ardupilot_apply, "px4": px4_apply}


def stated_residual(text: str) -> tuple[float, float]:
    text = " ".join(ln[2:] for ln in text.splitlines() if ln.startswith("# "))  # ArduPilot's comments wrap
    m = re.search(r"is max ([0-9.e+-]+) m/s\^2, RMS ([0-9.e+-]+) m/s\^2", text)
    assert m, "the file states the residual"
    return float(m.group(1)), float(m.group(2))


def sphere(cal: Calibration, n: int = 20000) -> tuple[np.ndarray, np.ndarray]:
    """Raw readings whose calibrated acceleration is g u for random unit directions u."""
    u = np.random.default_rng(7).normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    A, c = cal.linear_map()
    return np.linalg.solve(A, (cal.gravity * u - c).T).T, cal.gravity * u


def best_rotation(a_peer: np.ndarray, a_ours: np.ndarray) -> np.ndarray:
    """R minimising sum |a_peer R - a_ours|^2 (orthogonal Procrustes, by SVD)."""
    U, _, Vt = np.linalg.svd(a_peer.T @ a_ours)
    return U @ Vt


def best_rotation_errors(a_peer: np.ndarray, a_ours: np.ndarray) -> np.ndarray:
    return np.linalg.norm(a_peer @ best_rotation(a_peer, a_ours) - a_ours, axis=1)


# --- exports applied with the peers' formulas ----------------------------------------------------
def test_kalibr_formula_reproduces_our_calibration(xsens):
    cal, raw = xsens
    got = kalibr_apply(export(cal, "kalibr").text, raw)
    np.testing.assert_allclose(got, cal.apply(raw), rtol=1e-9, atol=1e-9 * G_XSENS)


@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
def test_autopilot_exact_for_orthogonal_axes(fmt):
    cal = synthetic(angles=(np.pi / 2,) * 3)  # the diagonal model holds this sensor
    raw, a = sphere(cal, 200)
    out = export(cal, fmt)
    np.testing.assert_allclose(PEERS[fmt](out.text, raw), cal.apply(raw), rtol=1e-9, atol=1e-9 * 9.81)
    assert stated_residual(out.text)[0] < 1e-12


@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
@pytest.mark.parametrize("which", ["xsens", "synthetic"])
def test_autopilot_error_is_the_stated_residual(xsens, fmt, which):
    cal = as_si(xsens[0])[0] if which == "xsens" else synthetic()
    out = export(cal, fmt)
    stated_max, stated_rms = stated_residual(out.text)
    assert any(f"is max {stated_max:.3g} m/s^2" in n for n in out.notes)  # the command prints it too
    raw, a_ours = sphere(cal)
    np.testing.assert_allclose(cal.apply(raw), a_ours, rtol=1e-9, atol=1e-9)
    err = best_rotation_errors(PEERS[fmt](out.text, raw), a_ours)
    half_digit = 0.5 * 10.0 ** (np.floor(np.log10(stated_max)) - 2)  # the file states 3 significant digits
    assert (stated_max - half_digit) * 0.97 <= err.max() <= (stated_max + half_digit) * 1.005
    assert np.sqrt(np.mean(err**2)) == pytest.approx(stated_rms, rel=0.02)
    assert stated_max > (0.05 if which == "xsens" else 0.1)  # 1.2 deg (Xsens), 1.6 deg: not negligible


def test_xsens_residual_on_the_real_samples_is_bounded_by_the_stated_one(xsens):
    cal, raw = as_si(*xsens)
    out = export(cal, "px4")
    sraw, s_ours = sphere(cal)
    R = best_rotation(px4_apply(out.text, sraw), s_ours)  # the frames aligned over all directions
    a_ours = cal.apply(raw)
    err = np.linalg.norm(px4_apply(out.text, raw) @ R - a_ours, axis=1)
    bound = stated_residual(out.text)[0] * np.linalg.norm(a_ours, axis=1) / cal.gravity
    assert np.all(err <= 1.02 * bound + 1e-9)


# --- round trips: export, read back, same map -----------------------------------------------------
def _base(cal: Calibration) -> Calibration:
    """The calibration without its effects (the map at their reference point)."""
    from imucal.model.parameters import BASE_NAMES, Parameters

    params = Parameters([cal.params[n] for n in BASE_NAMES])
    return Calibration(params=params, std={}, gravity=cal.gravity, raw_unit=cal.raw_unit)


CASES = [(f, n) for f, n in FILES.items()] + [("matrix", "x.csv")]


@pytest.mark.parametrize("fmt, name", CASES)
@pytest.mark.parametrize("which", ["xsens", "effects"])
def test_round_trip(xsens, tmp_path, fmt, name, which):
    effects = (("bias_temperature", (0, 1, 2)), ("scale_drift", (2,)))
    cal, raw = (as_si(*xsens) if fmt in ("ardupilot", "px4") else xsens) if which == "xsens" else (
        synthetic(effects), None)
    raw = sphere(cal, 500)[0] if raw is None else raw
    out = export(cal, fmt, ExportOptions(filename=name))
    (tmp_path / name).write_text(out.text)
    back = read_peer(tmp_path / name, fmt)
    ref = _base(cal)
    if fmt in ("ardupilot", "px4"):  # what they hold: offset s and scale 1/b, exactly
        np.testing.assert_allclose(back.o, cal.values[0:3], rtol=1e-12)
        np.testing.assert_allclose(np.diag(back.M), 1 / cal.values[3:6], rtol=1e-12)
        assert np.count_nonzero(back.M - np.diag(np.diag(back.M))) == 0
    else:
        np.testing.assert_allclose(back.apply(raw), ref.apply(raw), rtol=1e-9, atol=1e-9 * 9.81)
        np.testing.assert_allclose(list(back.nine_parameters().values()), ref.values, rtol=1e-9)
    if which == "effects" and fmt in ("ardupilot", "px4"):  # their INS_TCAL1_* / TC_A0_* hold the bias terms
        assert any(n.startswith("effects not exported: scale_drift (z); the map written is the calibration's at "
                                "the reference temperature 23.5 degC and at t = 0 s") for n in out.notes)
        assert any(n.startswith("temperature: the bias terms are written exactly") for n in out.notes)
    elif which == "effects":
        assert any(n.startswith("effects not exported: bias_temperature (xyz), scale_drift (z); the map written "
                                "is the calibration's at the reference temperature 23.5 degC and at t = 0 s")
                   for n in out.notes)
    else:
        assert not any("effects" in n for n in out.notes)


def test_every_export_format_is_covered():
    assert set(FILES) == set(FORMATS)


def test_kalibr_without_offset_reads_back_with_zero_bias_and_says_so(xsens, tmp_path):
    text = "\n".join(ln for ln in export(xsens[0], "kalibr").text.splitlines()
                     if not ln.startswith("imucal_accelerometer_offset"))
    (tmp_path / "imu.yaml").write_text("imu0:\n" + "\n".join(f"  {ln}" for ln in text.splitlines()) + "\n")
    back = read_peer(tmp_path / "imu.yaml", "kalibr")  # Kalibr's results nest the IMU under imu0
    assert back.extra["offset_held"] is False and np.all(back.o == 0)


# --- the command line ---------------------------------------------------------------------------
@pytest.fixture
def xsens_file(xsens, tmp_path):
    p = tmp_path / "cal.yaml"
    xsens[0].save(p)
    return p


def test_cli_export_kalibr_noise_matches_imucal_noise(xsens_file, run_cli, tmp_path):
    data = real_file(*XSENS)
    r = run_cli(["export", xsens_file, "--format", "kalibr", "--out", tmp_path / "imu.yaml", "--data", data])
    assert r.code == 0, r.err
    d = yaml.safe_load((tmp_path / "imu.yaml").read_text())
    r = run_cli(["noise", "--data", data, "--calibration", xsens_file, "--json", tmp_path / "n.json"])
    assert r.code == 0, r.err
    k = json.loads((tmp_path / "n.json").read_text())["kalibr"]
    assert d["accelerometer_noise_density"] == pytest.approx(k["accelerometer_noise_density"], rel=1e-12)
    assert d["update_rate"] == pytest.approx(k["update_rate"], rel=1e-12)
    assert d["accelerometer_random_walk"] == k["accelerometer_random_walk"]  # None on this 52 s segment
    r = run_cli(["export", xsens_file, "--format", "kalibr", "--out", tmp_path / "imu2.yaml"])
    d2 = yaml.safe_load((tmp_path / "imu2.yaml").read_text())
    assert d2["accelerometer_noise_density"] is None and "imucal noise --data STILL_LOG" in r.out


@pytest.fixture
def xsens_si_file(xsens, tmp_path):
    p = tmp_path / "cal_si.yaml"
    as_si(xsens[0])[0].save(p)
    return p


def test_cli_export_prints_the_residual(xsens_si_file, run_cli, tmp_path):
    r = run_cli(["export", xsens_si_file, "--format", "ardupilot", "--out", tmp_path / "x.param"])
    mx, rms = stated_residual((tmp_path / "x.param").read_text())
    assert r.code == 0 and f"is max {mx:.3g} m/s^2, RMS {rms:.3g} m/s^2" in r.out
    r = run_cli(["export", xsens_si_file, "--format", "px4", "--out", tmp_path / "y.params", "--data", "x.csv"])
    assert r.code == 2 and "--data: --data, --gyro-data and --config feed Kalibr's noise fields only" in r.err


def test_cli_compare(xsens, xsens_file, xsens_si_file, run_cli, tmp_path):
    cal, _ = xsens
    data = real_file(*XSENS)
    (tmp_path / FILES["imutk"]).write_text(export(cal, "imutk").text)
    r = run_cli(["compare", xsens_file, tmp_path / "x.calib", "--data", data, "--json", tmp_path / "c.json"])
    assert r.code == 0, r.err
    c = json.loads((tmp_path / "c.json").read_text())
    e = np.array([list(i["errors"].values()) for i in c["intervals"]])
    assert len(e) >= 30 and np.allclose(e[:, 0], e[:, 1], atol=1e-9)  # an exact export: the same numbers
    rms = np.sqrt(np.mean(e[:, 0] ** 2))
    assert r.out.splitlines()[-3].split()[:2] == ["RMS", f"{rms:.5f}"] and c["rms"]["cal.yaml"] == pytest.approx(rms)
    # ours: |a| - g, computed here from the intervals the JSON lists
    raw = np.loadtxt(data)
    i0 = c["intervals"][0]
    sel = (raw[:, 0] >= i0["t_start"] - raw[0, 0] - 1e-9) & (raw[:, 0] <= i0["t_end"] - raw[0, 0] + 1e-9)
    assert np.linalg.norm(cal.apply(raw[sel, 1:]).mean(axis=0)) - G_XSENS == pytest.approx(e[0, 0], abs=2e-4)
    # PX4 holds m/s^2: the same recording and calibration with the readings in m/s^2
    (tmp_path / FILES["px4"]).write_text(export(as_si(cal)[0], "px4").text)
    si_data = tmp_path / "xsens_si.txt"
    np.savetxt(si_data, np.column_stack([raw[:, 0], as_si(cal, raw[:, 1:])[1]]), fmt="%.17g")
    r = run_cli(["compare", xsens_si_file, tmp_path / "x.params", "--data", si_data, "--json", tmp_path / "p.json"])
    assert r.code == 0 and "(px4)" in r.out
    p = json.loads((tmp_path / "p.json").read_text())
    e = np.array([list(i["errors"].values()) for i in p["intervals"]])
    mx = stated_residual((tmp_path / "x.params").read_text())[0]
    assert np.all(np.abs(e[:, 1] - e[:, 0]) <= mx) and p["rms"]["x.params (px4)"] > 5 * p["rms"]["cal_si.yaml"]


# --- malicious inputs: exit 2, one line ---------------------------------------------------------
KALIBR_OK = ("model: scale-misalignment\naccelerometers:\n  M: [[400.0, 0.0, 0.0], [1.0, 410.0, 0.0], "
             "[2.0, 3.0, 405.0]]\nimucal_accelerometer_offset: [1.0, 2.0, 3.0]\n")
AP_OK = "".join(f"INS_ACCOFFS_{a},0.1\nINS_ACCSCAL_{a},1.01\n" for a in "XYZ")
PX4_OK = "".join(f"1\t1\tCAL_ACC0_{a}OFF\t0.1\t9\n1\t1\tCAL_ACC0_{a}SCALE\t1.01\t9\n" for a in "XYZ")
MADLAB_OK = json.dumps({"K_a": np.diag([200.0] * 3).tolist(), "R_a": np.eye(3).tolist(), "b_a": [1.0, 2.0, 3.0],
                        "cal_type": "Ferraris", "_format_version": "2.0"})
MATRIX_OK = json.dumps({"format": "imucal-affine", "matrix": np.eye(3).tolist(), "offset": [0.0, 0.0, 0.0]})

BAD = [
    ("kalibr", "imu.yaml", KALIBR_OK.replace("400.0", ".nan"), "accelerometers.M[0][0]: M is not finite (nan)"),
    ("kalibr", "imu.yaml", KALIBR_OK.replace("400.0", "1.0e+400"), "accelerometers.M[0][0]: M is not finite (inf)"),
    ("kalibr", "imu.yaml", KALIBR_OK.replace("400.0", "1e400"), "accelerometers.M[0][0]: M '1e400' must be a number from -1e+12 to 1e+12"),
    ("kalibr", "imu.yaml", KALIBR_OK.replace("400.0", "1" + "0" * 400), "integer is too large for a float"),
    ("kalibr", "imu.yaml", KALIBR_OK.replace("400.0", "4.0e+13"), "M 40000000000000.0 must be a number from -1e+12 to 1e+12"),
    ("kalibr", "imu.yaml", KALIBR_OK + "accel_noise: 1.0\n", "accel_noise: unknown key 'accel_noise'"),
    ("kalibr", "imu.yaml", KALIBR_OK.replace("[400.0, 0.0, 0.0]", "[400.0, 0.5, 0.0]"),
     "accelerometers.M: is not lower triangular"),
    ("kalibr", "imu.yaml", KALIBR_OK.replace("scale-misalignment", "calibrated"), "model: model 'calibrated'"),
    ("kalibr", "imu.yaml", KALIBR_OK + "accelerometer_noise_density: -1.0\n", "-1.0 must be a positive number (fix: Kalibr refuses values <= 0"),
    ("kalibr", "imu.yaml", KALIBR_OK.replace("[400.0, 0.0, 0.0]", "[400.0, 0.0]"), "accelerometers.M[0]: M [400.0, 0.0] must be a list of 3 values"),
    ("ardupilot", "x.param", AP_OK.replace("INS_ACCSCAL_X,1.01", "INS_ACCSCAL_X,nan"), "INS_ACCSCAL_X: nan is not"),
    ("ardupilot", "x.param", AP_OK.replace("INS_ACCOFFS_Y,0.1", "INS_ACCOFFS_Y,1e999"), "INS_ACCOFFS_Y: inf is not"),
    ("ardupilot", "x.param", AP_OK.replace("INS_ACCSCAL_Z,1.01\n", ""), "INS_ACCSCAL_Z: missing"),
    ("ardupilot", "x.param", AP_OK + "INS_ACCOFFS_X,0.2\n", "line 7: parameter INS_ACCOFFS_X is given twice"),
    ("ardupilot", "x.param", AP_OK + "INS_ACCOFFS_X\n", "line 7: 'INS_ACCOFFS_X' is not NAME,VALUE"),
    ("ardupilot", "x.param", AP_OK.replace("INS_ACCSCAL_X,1.01", "INS_ACCSCAL_X,0"), "singular"),
    ("ardupilot", "x.param", AP_OK.replace("INS_ACCSCAL_X", "ins_accscal_x"), "is not a parameter name"),
    ("px4", "x.params", PX4_OK.replace("\t9\n", "\n", 1), "line 1: '1\\t1\\tCAL_ACC0_XOFF\\t0.1' is not vehicle"),
    ("px4", "x.params", PX4_OK.replace("1.01", "inf", 1), "CAL_ACC0_XSCALE: inf is not"),
    ("madlab", "x.json", MADLAB_OK.replace("200.0", "NaN", 1), "is not valid JSON: NaN is not a JSON number"),
    ("madlab", "x.json", MADLAB_OK.replace('"K_a"', '"K_x"'), "K_x: unknown key 'K_x'"),
    ("madlab", "x.json", MADLAB_OK.replace('"b_a": [1.0, 2.0, 3.0], ', ""), "b_a: missing"),
    ("madlab", "x.json", MADLAB_OK.replace("200.0", "1e999", 1), "K_a[0][0]: K_a is not finite (inf)"),
    ("madlab", "x.json", MADLAB_OK.replace("200.0", "0.0"), "K_a: the matrix is singular"),
    ("madlab", "x.json", MADLAB_OK.replace('"Ferraris"', "true"), "cal_type: cal_type True is not Ferraris"),
    ("madlab", "x.json", "[" * 100000 + "]" * 100000, "is not valid JSON"),
    ("matrix", "x.json", MATRIX_OK.replace("imucal-affine", "other"), "format: format 'other' is not"),
    ("matrix", "x.json", MATRIX_OK.replace('"offset": [0.0, 0.0, 0.0]', '"offset": [0.0, "a", 0.0]'),
     "offset[1]: offset 'a' must be a number from -1e+12 to 1e+12"),
    ("matrix", "x.csv", "1,0,0,0\n0,1,0,0\n", "expected 3 rows of 4 numbers"),
    ("imutk", "x.calib", "nan " * 21, "calib: nan is not a finite number"),
    ("imutk", "x.calib", "1 " * 20, "expected 21 numbers"),
]


@pytest.mark.parametrize("fmt, name, text, message", BAD, ids=[f"{b[0]}-{i}" for i, b in enumerate(BAD)])
def test_bad_peer_files_exit_2_one_line(xsens_file, run_cli, tmp_path, fmt, name, text, message):
    (tmp_path / name).write_text(text)
    r = run_cli(["compare", xsens_file, tmp_path / name, "--format", fmt, "--data", tmp_path / "never-read.csv"])
    assert r.code == 2 and r.err.count("\n") == 1 and r.err.startswith("imucal: error: "), r.err
    assert message in r.err and str(tmp_path / name) in r.err


def test_good_versions_of_the_bad_files_are_read(tmp_path):
    for fmt, name, text in (("kalibr", "imu.yaml", KALIBR_OK), ("ardupilot", "x.param", AP_OK),
                            ("px4", "x.params", PX4_OK), ("madlab", "x.json", MADLAB_OK),
                            ("matrix", "m.json", MATRIX_OK)):
        (tmp_path / name).write_text(text)
        assert read_peer(tmp_path / name, fmt).M.shape == (3, 3)
        assert read_peer(tmp_path / name).fmt == fmt  # and the name tells the format


def test_unknown_name_needs_format(tmp_path):
    (tmp_path / "x.txt").write_text("1")
    with pytest.raises(ImucalError, match=r"x.txt: --format: cannot tell the calibration format"):
        read_peer(tmp_path / "x.txt")
