"""The gyroscope in every export: each peer's formula written HERE from its source (cited), applied
to the Xsens gyro samples with the calibrated acceleration, against Calibration.apply_imu: 1e-9
relative where the format holds imucal's gyroscope, the residual the file states where it cannot
(imu_tk: no g-sensitivity; ArduPilot, PX4: offset only). Round trips through the strict readers."""
from __future__ import annotations

import dataclasses
import json
import math
import re

import numpy as np
import pytest
import yaml

from conftest import real_file
from imucal.calibration.gyro import from_arrays
from imucal.calibration.sensor import SensorCalibration
from imucal.errors import ImucalError
from imucal.export.formats import ExportOptions
from imucal.export.peers import read_imutk_calib
from imucal.export.registry import export, read_peer
from test_export import imutk_apply
from test_export_peers import ardupilot_apply, as_si, best_rotation, px4_apply, sphere, synthetic

ACC = ("xsens-mti-imutk", "xsens_acc.mat")
GYR = ("xsens-mti-imutk", "xsens_gyro.mat")
G_XSENS = 9.81744
FILES = {"imutk": "x.calib", "madlab": "x.json", "matrix": "x.json", "kalibr": "imu.yaml",
         "ardupilot": "x.param", "px4": "x.params"}


@pytest.fixture(scope="module")
def xsens():
    """The Xsens calibration with its gyroscope (G_s selected on every row), and samples of both files."""
    from imucal.config.run import config_from_dict
    from imucal.pipeline import calibrate_imu

    cfg = config_from_dict({"data": {"path": str(real_file(*ACC))}, "gravity": {"value": G_XSENS},
                            "static": {"window": 0.5, "min_duration": 1.5}})
    cal = calibrate_imu(cfg, gyro_file=str(real_file(*GYR))).calibration
    assert cal.gyro is not None and cal.gyro.reads_inputs()
    raw_a = np.loadtxt(real_file(*ACC))[::50, 1:]
    raw_g = np.loadtxt(real_file(*GYR))[::50, 1:]
    return cal, raw_a, raw_g


def _rate_map(g) -> tuple:
    """(C, c, D) with omega = C raw + c - D a: the gyroscope's map through the one accessor (affine)."""
    a = g.affine()
    return a.A, a.c, -a.B


def gyro_part(unit: str = "rad/s", scale=(1.013, 0.987, 1.004), gsens: bool = True) -> SensorCalibration:
    """A misaligned gyroscope with a g-sensitivity, readings in ``unit``."""
    M = np.array([[1.0, 0.012, -0.02], [0.008, 1.0, 0.015], [-0.011, 0.025, 1.0]])
    G = np.array([[2e-4, -1e-4, 3e-4], [1e-4, 4e-4, -2e-4], [-3e-4, 2e-4, 1e-4]]) if gsens else np.zeros((3, 3))
    f = {"rad/s": 1.0, "deg/s": 180 / math.pi}.get(unit, 1000.0)
    vals = {"bias": np.array([0.02, -0.013, 0.007]) * f, "scale": np.array(scale) * f, "misalignment": M, "gsens": G}
    return from_arrays(unit=unit, std={k: np.zeros_like(v) for k, v in vals.items()}, **vals)


def with_gyro(g: SensorCalibration, angles=(1.556, 1.585, 1.562)):
    return dataclasses.replace(synthetic(angles=angles), attached=(g,))


# --- the peers' formulas, from their sources ---------------------------------------------------
def kalibr_gyro_apply(text: str, raw: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """Kalibr IccSensors.py, IccScaledMisalignedImu.addGyroscopeErrorTerms:
    measurement = M (C_gyro_i w) + A (C_gyro_i a) + b; b is imucal's offset (Kalibr's is online)."""
    d = yaml.safe_load(text)
    M, A, C = (np.array(d["gyroscopes"][k]) for k in ("M", "A", "C_gyro_i"))
    assert np.all(np.triu(M, 1) == 0)  # MatrixBasicDv pattern [[1,0,0],[1,1,0],[1,1,1]]
    np.testing.assert_allclose(C @ C.T, np.eye(3), atol=1e-12)  # a rotation (RotationQuaternionDv)
    assert np.linalg.det(C) > 0
    b = np.array(d["imucal_gyroscope_offset"])
    return np.linalg.solve(M @ C, (raw - b - acc @ (A @ C).T).T).T


def madlab_gyro_apply(text: str, raw: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """mad-lab-fau/imucal FerrarisCalibrationInfo._calibrate_gyr and _calibrate_gyr_offsets:
    gyr = R_g^-1 K_g^-1 (gyr - (K_ga acc + b_g)), in gyr_unit."""
    d = json.loads(text)
    R, K, Kga, b = (np.array(d[k], float) for k in ("R_g", "K_g", "K_ga", "b_g"))
    return (np.linalg.inv(R) @ np.linalg.inv(K) @ (raw - ((Kga @ acc.T).T + b)).T).T


def matrix_gyro_apply(text: str, raw: np.ndarray, acc: np.ndarray) -> np.ndarray:
    g = json.loads(text)["gyroscope"]
    return raw @ np.array(g["matrix"]).T + np.array(g["offset"]) - acc @ np.array(g["acc_matrix"]).T


def matrix_csv_gyro_apply(text: str, raw: np.ndarray, acc: np.ndarray) -> np.ndarray:
    rows = np.array([ln.split(",") for ln in text.splitlines() if not ln.startswith("#")][3:], float)
    return raw @ rows[:, :3].T + rows[:, 3] - acc @ rows[:, 4:].T


def stated_sensitivity(text: str) -> float:
    """The driver's sensitivity k the file states (its comments joined: ArduPilot's wrap)."""
    text = " ".join(ln[2:] for ln in text.splitlines() if ln.startswith("# "))
    return float(re.search(r"sensitivity k = ([0-9.e+-]+) ", text).group(1))


def autopilot_gyro_apply(text: str, raw: np.ndarray, fmt: str) -> np.ndarray:
    """ArduPilot _rotate_and_correct_gyro: gyro -= _gyro_offset; PX4 Gyroscope::Correct(): data - _offset.
    The reading [rad/s] is the driver's raw / k, k as the file states it."""
    k = stated_sensitivity(text)
    if fmt == "ardupilot":
        p = dict(ln.split(",") for ln in text.splitlines() if ln and not ln.startswith("#"))
        off = np.array([float(p[f"INS_GYROFFS_{a}"]) for a in "XYZ"])
    else:
        p = {f[2]: float(f[3]) for f in (ln.split("\t") for ln in text.splitlines() if ln and not ln.startswith("#"))}
        off = np.array([p[f"CAL_GYRO0_{a}OFF"] for a in "XYZ"])
    return raw / k - off


def stated_gyro(text: str) -> tuple[float, float, float, float]:
    """(rate max, rate RMS, at-rest max, at-rest RMS) [deg/s] as the file states them."""
    num = r"([0-9.e+-]+)"
    text = " ".join(ln[2:] for ln in text.splitlines() if ln.startswith("# "))  # ArduPilot's comments wrap
    m = re.search(rf"\|omega\| = 1 rad/s over all directions is max {num} deg/s, RMS {num} deg/s, "
                  rf"and at rest with \|a\| = g over all directions max {num} deg/s, RMS {num} deg/s", text)
    assert m, "the file states the gyroscope residual"
    return tuple(float(x) for x in m.groups())


def stated_gsens(text: str) -> tuple[float, float]:
    m = re.search(r"no gyroscope g-sensitivity term: imucal's G_s leaves a rate error at \|a\| = g over all "
                  r"directions of max ([0-9.e+-]+) deg/s, RMS ([0-9.e+-]+) deg/s", text)
    assert m, "the export states the g-sensitivity residual"
    return float(m.group(1)), float(m.group(2))


def raw_gyro(cal, omega: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """Raw gyro readings that imucal calibrates to ``omega`` given the acceleration ``acc``."""
    C, c, D = _rate_map(cal.gyro)
    return np.linalg.solve(C, (omega - c + acc @ D.T).T).T


def unit_vectors(n: int, seed: int) -> np.ndarray:
    u = np.random.default_rng(seed).normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


# --- exact formats on the real samples -------------------------------------------------------------
EXACT = [("kalibr", "imu.yaml", kalibr_gyro_apply, 1.0), ("madlab", "x.json", madlab_gyro_apply, 180 / math.pi),
         ("matrix", "x.json", matrix_gyro_apply, 1.0), ("matrix", "x.csv", matrix_csv_gyro_apply, 1.0)]


@pytest.mark.parametrize("fmt, name, peer, to_unit", EXACT, ids=[f"{e[0]}-{e[1]}" for e in EXACT])
def test_exact_formats_reproduce_apply_imu(xsens, fmt, name, peer, to_unit):
    cal, raw_a, raw_g = xsens
    acc, omega = cal.apply_imu(raw_a, raw_g)
    out = export(cal, fmt, ExportOptions(filename=name))
    got = peer(out.text, raw_g, acc) / to_unit  # madlab: deg/s, its Ferraris output unit
    scale = np.abs(omega).max()
    np.testing.assert_allclose(got, omega, rtol=1e-9, atol=1e-9 * scale)
    assert not any(w in n for n in out.notes for w in ("g-sensitivity", "identity", "lost"))  # nothing lost


def test_madlab_gyro_fields_follow_their_convention(xsens):
    d = json.loads(export(xsens[0], "madlab").text)
    np.testing.assert_allclose(np.linalg.norm(d["R_g"], axis=1), 1.0, rtol=1e-12)  # unit rows, as Eq. 12 gives
    assert np.count_nonzero(np.array(d["K_g"]) - np.diag(np.diag(d["K_g"]))) == 0
    assert d["gyr_unit"] == "deg/s" and d["from_gyr_unit"] == "raw" and d["from_acc_unit"] == "raw"
    np.testing.assert_array_equal(d["b_g"], xsens[0].gyro.forward().s)


@pytest.mark.parametrize("scale", [(1.013, 0.987, 1.004), (1.013, 0.987, -1.004), (-1.0, 1.0, 1.0)])
def test_kalibr_factoring_is_exact_for_any_sign(scale):
    """P = M C_gyro_i with C_gyro_i a rotation even when det P < 0 (a negative scale)."""
    cal = with_gyro(gyro_part(scale=scale))
    raw_a, a = sphere(cal, 300)
    omega = unit_vectors(300, 3) * 2.0
    raw_g = raw_gyro(cal, omega, a)
    got = kalibr_gyro_apply(export(cal, "kalibr").text, raw_g, cal.apply(raw_a))
    np.testing.assert_allclose(got, cal.gyro.apply(raw_g, cal.apply(raw_a)), rtol=1e-9, atol=1e-9)


# --- imu_tk: exact but for the g-sensitivity it has no term for ----------------------------------
def test_imutk_gyro_leaves_exactly_the_stated_g_sensitivity(xsens):
    cal, raw_a, raw_g = xsens
    out = export(cal, "imutk")
    mx, rms = stated_gsens(" ".join(out.notes))
    acc, omega = cal.apply_imu(raw_a, raw_g)
    tk = imutk_apply(out.gyro_text, raw_g)  # imu_tk: omega = T K (raw - b), the same layout as the acc file
    err = np.degrees(np.linalg.norm(tk - omega, axis=1))
    assert np.all(err <= mx * np.linalg.norm(acc, axis=1) / cal.gravity * (1 + 1e-9))
    # with no acceleration imu_tk's map is imucal's, exactly
    np.testing.assert_allclose(tk, cal.gyro.apply(raw_g, np.zeros_like(acc)), rtol=1e-9, atol=1e-9)
    # over all directions at |a| = g: the stated max and RMS
    a = cal.gravity * unit_vectors(20000, 5)
    rg = raw_gyro(cal, np.zeros_like(a), a)
    e = np.degrees(np.linalg.norm(imutk_apply(out.gyro_text, rg), axis=1))
    half_digit = 0.5 * 10.0 ** (np.floor(np.log10(mx)) - 2)  # the note states 3 significant digits
    assert (mx - half_digit) * 0.97 <= e.max() <= mx + half_digit
    assert np.sqrt(np.mean(e**2)) == pytest.approx(rms, rel=0.02)
    assert 0.1 < mx < 1.0  # the Xsens G_s: 0.2 deg/s at rest, not negligible


def test_imutk_without_g_sensitivity_is_exact():
    cal = with_gyro(gyro_part(gsens=False))
    out = export(cal, "imutk")
    raw_g = raw_gyro(cal, unit_vectors(200, 1), np.zeros((200, 3)))
    np.testing.assert_allclose(imutk_apply(out.gyro_text, raw_g), cal.gyro.apply(raw_g), rtol=1e-9, atol=1e-12)
    assert out.notes == ()


# --- ArduPilot and PX4: the offset, and the stated loss -----------------------------------------
ACC_PEERS = {"ardupilot": ardupilot_apply, "px4": px4_apply}


@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
@pytest.mark.parametrize("which", ["xsens", "rad/s", "deg/s"])
def test_autopilot_gyro_error_is_the_stated_residual(xsens, fmt, which):
    cal = as_si(xsens[0])[0] if which == "xsens" else with_gyro(gyro_part(which))  # autopilots hold m/s^2
    out = export(cal, fmt)
    rmax, rrms, gmax, grms = stated_gyro(out.text)
    assert any(f"max {rmax:.3g} deg/s, RMS {rrms:.3g} deg/s" in n for n in out.notes)  # the command prints it
    raw_a, a = sphere(cal)
    R = best_rotation(ACC_PEERS[fmt](out.text, raw_a), a)  # the accelerometer's best-aligned frame
    for w, acc, mx, rms in ((unit_vectors(20000, 2), np.zeros((20000, 3)), rmax, rrms),
                            (np.zeros((20000, 3)), cal.gravity * unit_vectors(20000, 4), gmax, grms)):
        peer = autopilot_gyro_apply(out.text, raw_gyro(cal, w, acc), fmt)
        e = np.degrees(np.linalg.norm(peer @ R - w, axis=1))
        assert mx * 0.97 <= e.max() <= mx * 1.005
        assert np.sqrt(np.mean(e**2)) == pytest.approx(rms, rel=0.02)
    if which == "xsens":
        assert rmax > 1.0 and gmax > 0.1  # 2.5 deg/s at 1 rad/s, 0.21 deg/s at rest: not negligible


@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
def test_autopilot_gyro_offset_in_rad_per_s(fmt):
    """Readings already in rad/s or deg/s: k is exact, the offset is s_g in rad/s; an ideal gyro is held exactly."""
    for unit, k in (("rad/s", 1.0), ("deg/s", 180 / math.pi)):
        g = from_arrays(unit, bias=np.array([0.02, -0.013, 0.007]) * k, scale=np.full(3, k), misalignment=np.eye(3),
                        gsens=np.zeros((3, 3)))
        cal = with_gyro(g, angles=(math.pi / 2,) * 3)  # orthogonal accelerometer axes: its frame is imucal's
        out = export(cal, fmt)
        w = unit_vectors(100, 6)
        np.testing.assert_allclose(autopilot_gyro_apply(out.text, raw_gyro(cal, w, np.zeros((100, 3))), fmt), w,
                                   rtol=1e-9, atol=1e-12)
        assert stated_gyro(out.text)[0] < 1e-9 and "(assumed" not in out.text


def test_xsens_gyro_residual_on_the_real_samples_is_bounded_by_the_stated_one(xsens):
    (cal, raw_a), raw_g = as_si(*xsens[:2]), xsens[2]  # ArduPilot holds m/s^2
    out = export(cal, "ardupilot")
    rmax, _, gmax, _ = stated_gyro(out.text)
    sa, s_ours = sphere(cal)
    R = best_rotation(ardupilot_apply(out.text, sa), s_ours)
    acc, omega = cal.apply_imu(raw_a, raw_g)
    err = np.degrees(np.linalg.norm(autopilot_gyro_apply(out.text, raw_g, "ardupilot") @ R - omega, axis=1))
    bound = rmax * np.linalg.norm(omega, axis=1) + gmax * np.linalg.norm(acc, axis=1) / cal.gravity
    assert np.all(err <= 1.001 * bound + 1e-9) and np.abs(omega).max() > 1.0  # the log turns faster than 1 rad/s


# --- round trips ------------------------------------------------------------------------------
CASES = [(f, n) for f, n in FILES.items()] + [("matrix", "x.csv")]


@pytest.mark.parametrize("fmt, name", CASES)
def test_gyro_round_trip(xsens, tmp_path, fmt, name):
    cal, raw_a, raw_g = xsens
    if fmt in ("ardupilot", "px4"):  # they hold m/s^2
        cal, raw_a = as_si(cal, raw_a)
    out = export(cal, fmt, ExportOptions(filename=name))
    (tmp_path / name).write_text(out.text)
    if fmt == "imutk":
        (tmp_path / "g.calib").write_text(out.gyro_text)
        back = read_imutk_calib(tmp_path / name, tmp_path / "g.calib")
    else:
        back = read_peer(tmp_path / name, fmt)
    acc, omega = cal.apply_imu(raw_a, raw_g)
    got = back.gyro.apply(raw_g, back.apply(raw_a))
    if fmt in ("ardupilot", "px4"):  # the offset s_g / k, exactly; nothing else
        k = stated_sensitivity(out.text)
        np.testing.assert_allclose(back.gyro.o, cal.gyro.forward().s / k, rtol=1e-12)
        assert np.all(back.gyro.C == np.eye(3)) and np.all(back.gyro.D == 0)
    elif fmt == "imutk":  # all but G_s
        np.testing.assert_allclose(got, cal.gyro.apply(raw_g, np.zeros_like(acc)), rtol=1e-9, atol=1e-9)
    else:
        np.testing.assert_allclose(got, omega, rtol=1e-9, atol=1e-9 * np.abs(omega).max())
    if fmt == "kalibr":
        assert back.extra["gyro_offset_held"] is True


def test_accelerometer_only_calibrations_write_no_gyro_values(tmp_path):
    cal = synthetic()
    assert "INS_GYROFFS" not in export(cal, "ardupilot").text and "CAL_GYRO0" not in export(cal, "px4").text
    assert export(cal, "imutk").gyro_text is None and "gyroscope" not in json.loads(export(cal, "matrix").text)
    assert any("identity" in n for n in export(cal, "kalibr").notes)
    (tmp_path / "x.csv").write_text(export(cal, "matrix", ExportOptions(filename="x.csv")).text)
    assert read_peer(tmp_path / "x.csv").gyro is None


# --- the command line -------------------------------------------------------------------------
@pytest.fixture
def xsens_file(xsens, tmp_path):
    p = tmp_path / "cal.yaml"
    xsens[0].save(p)
    return p


def test_cli_imutk_writes_both_files(xsens, xsens_file, run_cli, tmp_path, unchanged):
    r = run_cli(["export", xsens_file, "--format", "imutk", "--out", tmp_path / "acc.calib"])
    assert r.code == 0, r.err
    assert f"wrote {tmp_path / 'acc_gyro.calib'}" in r.out and "G_s leaves a rate error" in r.out
    back = read_imutk_calib(tmp_path / "acc.calib", tmp_path / "acc_gyro.calib")
    np.testing.assert_allclose(back.gyro.o, xsens[0].gyro.forward().s, rtol=1e-12)
    with unchanged():  # the gyro file would overwrite the calibration: nothing is written
        r = run_cli(["export", xsens_file, "--format", "imutk", "--out", tmp_path / "new.calib",
                     "--gyro-out", xsens_file])
    assert r.code == 2 and "would overwrite the input" in r.err and not (tmp_path / "new.calib").exists()
    r = run_cli(["export", xsens_file, "--format", "px4", "--out", tmp_path / "p.params", "--gyro-out", "g.calib"])
    assert r.code == 2 and "--gyro-out: only imu_tk keeps the gyroscope in a second file" in r.err


def test_cli_kalibr_gyro_noise_is_imucal_noise_on_the_gyro_channel(xsens, xsens_file, run_cli, tmp_path):
    from imucal.analysis.noise import allan_deviation, estimate
    from imucal.data.static import detect_static

    cal, _, _ = xsens
    r = run_cli(["export", xsens_file, "--format", "kalibr", "--out", tmp_path / "imu.yaml",
                 "--data", real_file(*ACC), "--gyro-data", real_file(*GYR)])
    assert r.code == 0, r.err
    d = yaml.safe_load((tmp_path / "imu.yaml").read_text())
    acc_log, gyr_log = np.loadtxt(real_file(*ACC)), np.loadtxt(real_file(*GYR))
    t = acc_log[:, 0] - acc_log[0, 0]
    iv = detect_static(t, acc_log[:, 1:])
    k = int(np.argmax(iv.n_samples))
    sel = slice(iv.start[k], iv.end[k])
    acc, w = cal.apply_imu(acc_log[sel, 1:], gyr_log[sel, 1:])
    rate = (len(t) - 1) / (t[-1] - t[0])
    curve = allan_deviation(w, rate)
    white = max(estimate(curve, j).white_density for j in range(3))
    assert d["gyroscope_noise_density"] == pytest.approx(white, rel=1e-6)
    assert 1e-4 < d["gyroscope_noise_density"] < 1e-2  # rad/s/sqrt(Hz): an MTi's 0.05 deg/s/sqrt(Hz) order
    assert d["gyroscope_random_walk"] is None and "gyroscope_random_walk is null" in r.out  # 52 s: no +1/2 slope
    r = run_cli(["export", xsens_file, "--format", "kalibr", "--out", tmp_path / "i2.yaml", "--data", real_file(*ACC)])
    assert r.code == 0 and yaml.safe_load((tmp_path / "i2.yaml").read_text())["gyroscope_noise_density"] is None
    assert "no gyroscope data on the still segment" in r.out
    r = run_cli(["export", xsens_file, "--format", "kalibr", "--out", tmp_path / "i3.yaml", "--gyro-data", "g.mat"])
    assert r.code == 2 and "--gyro-data: needs the accelerometer's recording" in r.err


# --- malicious gyro fields: exit 2, one line ------------------------------------------------------
def _kalibr_ok() -> str:
    return ("model: scale-misalignment\naccelerometers:\n  M: [[400.0, 0.0, 0.0], [1.0, 410.0, 0.0], "
            "[2.0, 3.0, 405.0]]\ngyroscopes:\n  M: [[1.0, 0.0, 0.0], [0.01, 1.0, 0.0], [0.0, 0.02, 1.0]]\n"
            "  A: [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]\n"
            "  C_gyro_i: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\n"
            "imucal_gyroscope_offset: [0.1, 0.2, 0.3]\n")


MADLAB_G = {"K_a": np.diag([200.0] * 3).tolist(), "R_a": np.eye(3).tolist(), "b_a": [1.0, 2.0, 3.0],
            "K_g": np.diag([16.4] * 3).tolist(), "R_g": np.eye(3).tolist(), "b_g": [1.0, 2.0, 3.0],
            "K_ga": np.zeros((3, 3)).tolist(), "gyr_unit": "deg/s", "cal_type": "Ferraris", "_format_version": "2.0"}
AP_G = "".join(f"INS_ACCOFFS_{a},0.1\nINS_ACCSCAL_{a},1.01\nINS_GYROFFS_{a},0.01\n" for a in "XYZ")
MATRIX_G = json.dumps({"format": "imucal-affine", "matrix": np.eye(3).tolist(), "offset": [0.0] * 3,
                       "gyroscope": {"matrix": np.eye(3).tolist(), "offset": [0.0] * 3,
                                     "acc_matrix": np.zeros((3, 3)).tolist()}})

BAD = [
    ("kalibr", "imu.yaml", _kalibr_ok().replace("C_gyro_i: [[1.0", "C_gyro_i: [[1.1"),
     "gyroscopes.C_gyro_i: is not a rotation"),
    ("kalibr", "imu.yaml", _kalibr_ok().replace("[[1.0, 0.0, 0.0], [0.01", "[[1.0, 0.3, 0.0], [0.01"),
     "gyroscopes.M: is not lower triangular"),
    ("kalibr", "imu.yaml", _kalibr_ok().replace("  A: [[0.0, 0.0, 0.0], ", "  A: [[.nan, 0.0, 0.0], "),
     "gyroscopes.A[0][0]: A is not finite (nan)"),
    ("kalibr", "imu.yaml", _kalibr_ok().replace("  A: [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]\n", ""),
     "A: missing"),
    ("kalibr", "imu.yaml", _kalibr_ok().replace("  C_gyro_i:", "  C_gyro: [[1.0]]\n  C_gyro_i:"),
     "gyroscopes.C_gyro: unknown key 'C_gyro'"),
    ("kalibr", "imu.yaml", _kalibr_ok().split("gyroscopes:")[0] + "imucal_gyroscope_offset: [0.1, 0.2, 0.3]\n",
     "imucal_gyroscope_offset: is given without a gyroscopes section"),
    ("kalibr", "imu.yaml", _kalibr_ok().split("gyroscopes:")[0] + "gyroscopes: 5\n",
     "gyroscopes: gyroscopes 5 must be a mapping (or null)"),
    ("matrix", "x.json", MATRIX_G.replace('"gyroscope": {', '"gyroscope": [{').replace("]]}}", "]]}]}"),
     "must be a mapping (or null)"),
    ("madlab", "x.json", json.dumps({k: v for k, v in MADLAB_G.items() if k != "K_ga"}), "K_ga: missing"),
    ("madlab", "x.json", json.dumps({**MADLAB_G, "gyr_unit": "rpm"}), "gyr_unit: gyr_unit 'rpm' is not one of"),
    ("madlab", "x.json", json.dumps({**MADLAB_G, "K_g": np.zeros((3, 3)).tolist()}), "K_g: the matrix is singular"),
    ("madlab", "x.json", json.dumps({**MADLAB_G, "cal_type": "TurnTable"}), "cal_type 'TurnTable' is not Ferraris"),
    ("ardupilot", "x.param", AP_G.replace("INS_GYROFFS_Y,0.01\n", ""), "INS_GYROFFS_Y: missing"),
    ("ardupilot", "x.param", AP_G.replace("INS_GYROFFS_Y,0.01", "INS_GYROFFS_Y,inf"), "INS_GYROFFS_Y: inf is not"),
    ("px4", "x.params", "".join(f"1\t1\tCAL_ACC0_{a}OFF\t0.1\t9\n1\t1\tCAL_ACC0_{a}SCALE\t1.01\t9\n" for a in "XYZ")
     + "1\t1\tCAL_GYRO0_XOFF\t0.1\t9\n", "CAL_GYRO0_YOFF: missing"),
    ("matrix", "x.json", MATRIX_G.replace('"acc_matrix"', '"acc_matrx"'), "gyroscope.acc_matrx: unknown key 'acc_matrx'"),
    ("matrix", "x.json", MATRIX_G.replace('"offset": [0.0, 0.0, 0.0], "acc', '"offset": [0.0, "a", 0.0], "acc'),
     "gyroscope.offset[1]: offset 'a' must be a number from"),
    ("matrix", "x.csv", "1,0,0,0\n0,1,0,0\n0,0,1,0\n1,0,0,0,0,0,0\n0,1,0,0,0,0,0\n",
     "then optionally 3 rows of 7 (the gyroscope), found rows of [4, 4, 4, 7, 7] numbers"),
    ("matrix", "x.csv", "1,0,0,0\n0,1,0,0\n0,0,1,0\n" + "0,0,0,0,0,0,0\n" * 3, "matrix: the matrix is singular"),
]


@pytest.mark.parametrize("fmt, name, text, message", BAD, ids=[f"{b[0]}-{i}" for i, b in enumerate(BAD)])
def test_bad_gyro_fields_exit_2_one_line(xsens_file, run_cli, tmp_path, fmt, name, text, message):
    (tmp_path / name).write_text(text)
    r = run_cli(["compare", xsens_file, tmp_path / name, "--format", fmt, "--data", tmp_path / "never-read.csv"])
    assert r.code == 2 and r.err.count("\n") == 1 and r.err.startswith("imucal: error: "), r.err
    assert message in r.err and str(tmp_path / name) in r.err


def test_good_gyro_files_are_read(tmp_path):
    for fmt, name, text in (("kalibr", "imu.yaml", _kalibr_ok()), ("madlab", "x.json", json.dumps(MADLAB_G)),
                            ("ardupilot", "x.param", AP_G), ("matrix", "m.json", MATRIX_G),
                            ("madlab", "t.json", json.dumps({**MADLAB_G, "cal_type": "Turntable"}))):
        (tmp_path / name).write_text(text)
        g = read_peer(tmp_path / name, fmt).gyro
        assert g is not None and g.C.shape == (3, 3)
    # madlab's deg/s output converted to rad/s: K_g = 16.4 raw per deg/s
    g = read_peer(tmp_path / "x.json", "madlab").gyro
    np.testing.assert_allclose(g.apply(np.array([[17.4, 2.0, 3.0]]), np.zeros((1, 3))), [[math.radians(1.0), 0, 0]],
                               rtol=1e-12, atol=1e-15)
    with pytest.raises(ImucalError, match="g-sensitivity"):
        dataclasses.replace(g, D=np.ones((3, 3))).apply(np.zeros((1, 3)))
