"""Issue 14 (first formats): each export is applied with the peer's OWN formula, written here from
the peer's documentation (not the export code), and must agree with `Calibration.apply`."""
from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import calibrate_file, real_file
from imucal.calibration.frozen import Calibration
from imucal.model.effects import make_effect
from imucal.export.registry import export_text

XSENS = ("xsens-mti-imutk", "xsens_acc.mat")


@pytest.fixture(scope="module")
def xsens():
    cal = calibrate_file(real_file(*XSENS), gravity={"value": 9.81744}).calibration
    raw = np.loadtxt(real_file(*XSENS))[::50, 1:]
    return cal, raw


def imutk_apply(text: str, raw: np.ndarray) -> np.ndarray:
    """imu_tk (calibration.h): T, K, b as written by CalibratedTriad; a = T K (raw - b)."""
    v = np.array(text.split(), float)
    T, K, b = v[:9].reshape(3, 3), v[9:18].reshape(3, 3), v[18:21]
    return (T @ K @ (raw - b).T).T


def madlab_apply(text: str, raw: np.ndarray) -> np.ndarray:
    """mad-lab-fau/imucal FerrarisCalibrationInfo._calibrate_acc: a = R_a^-1 K_a^-1 (raw - b_a)."""
    d = json.loads(text)
    assert d["cal_type"] == "Ferraris" and d["_format_version"] == "2.0"
    R, K, b = (np.array(d[k], float) for k in ("R_a", "K_a", "b_a"))
    return (np.linalg.inv(R) @ np.linalg.inv(K) @ (raw - b).T).T


def matrix_apply(text: str, raw: np.ndarray) -> np.ndarray:
    d = json.loads(text)
    return raw @ np.array(d["matrix"]).T + np.array(d["offset"])


def matrix_csv_apply(text: str, raw: np.ndarray) -> np.ndarray:
    rows = np.array([ln.split(",") for ln in text.splitlines() if not ln.startswith("#")], float)
    return raw @ rows[:, :3].T + rows[:, 3]


@pytest.mark.parametrize("fmt, peer, name", [("imutk", imutk_apply, "x.calib"), ("madlab", madlab_apply, "x.json"),
                                             ("matrix", matrix_apply, "x.json"),
                                             ("matrix", matrix_csv_apply, "x.csv")])
def test_peer_formula_reproduces_our_calibration(xsens, fmt, peer, name):
    cal, raw = xsens
    got = peer(export_text(cal, fmt, name), raw)
    np.testing.assert_allclose(got, cal.apply(raw), rtol=1e-9, atol=1e-9 * 9.81)


def test_madlab_rotation_rows_are_unit_vectors(xsens):
    d = json.loads(export_text(xsens[0], "madlab"))
    np.testing.assert_allclose(np.linalg.norm(d["R_a"], axis=1), 1.0, rtol=1e-12)


def test_imutk_export_reads_back_with_our_imutk_reader(xsens, tmp_path):
    from imucal.export.peers import read_imutk_calib

    cal, raw = xsens
    p = tmp_path / "x.calib"
    p.write_text(export_text(cal, "imutk"))
    np.testing.assert_allclose(read_imutk_calib(p).apply(raw), cal.apply(raw), rtol=1e-9)


def test_cli_export_and_its_refusals(xsens, run_cli, tmp_path, unchanged):
    cal, _ = xsens
    src = tmp_path / "cal.yaml"
    cal.save(src)
    r = run_cli(["export", src, "--format", "imutk", "--out", tmp_path / "x.calib"])
    assert r.code == 0 and (tmp_path / "x.calib").exists()
    with unchanged():
        r = run_cli(["export", src, "--format", "madlab", "--out", src])
    assert r.code == 2 and "would overwrite the input" in r.err
    params = cal.params.extended(make_effect("bias_drift", (0,)).parameters(cal.params))
    eff = Calibration(params=params, std={n: 0.0 for n in params}, gravity=cal.gravity,
                      effects=(("bias_drift", (0,)),), data=cal.data, created=cal.created)
    # effects are not affine: the map at their reference point is written, and the export says so
    from imucal.export.registry import export

    out = export(eff, "imutk")
    assert out.notes == ("effects not exported: bias_drift (x); the map written is the calibration's at t = 0 s "
                         "(the recording's start) (`imucal codegen` keeps every effect)",)
    assert out.text == export_text(cal, "imutk")  # bias_drift_x = 0: the same map
