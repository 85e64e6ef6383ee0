"""The magnetometer in the autopilots' parameter files (issue 26): each autopilot's own correction formula,
evaluated on the written numbers, gives imucal's calibrated field (imucal.export.mag_autopilot)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imucal.calibration.frozen import load_calibration
from imucal.export.mag_autopilot import (OFF_DIAGONAL, ROTATIONS, all_permutations_named, rotation_enum,
                                         rotation_matrix)
from test_mag_plugin import FIELD_UT, write_log

#: field units in microtesla: ArduPilot reads milligauss, PX4 gauss
MG_PER_UT, GAUSS_PER_UT = 10.0, 0.01
#: The symmetric fit holds its soft iron symmetric to its constraint rows' 1e-6 (imucal.mag.model.CONSTRAINT_SIGMA):
#: the autopilots' field agrees with imucal's to a few times that, relative to the field
AGREE = 1e-5


@pytest.fixture(scope="module")
def symmetric(tmp_path_factory):
    """A log in g and uT, calibrated with the symmetric soft iron (what both autopilots hold)."""
    from imucal.cli.main import main

    d = tmp_path_factory.mktemp("magexp")
    write_log(d / "log.csv")
    assert main(["calibrate", "--data", str(d / "log.csv"), "--unit", "g", "--mag-unit", "uT", "--mag-field", "48uT",
                 "--mag-soft-iron", "symmetric", "--out", str(d / "out"), "--no-figures", "--quiet"]) == 0
    return d


def _raw_and_imucal(d):
    raw = np.loadtxt(d / "log.csv", delimiter=",", skiprows=1)[::11, 4:7]  # [uT]
    m = load_calibration(d / "out" / "calibration.yaml").sensor("magnetometer")
    return raw, m.apply(raw)  # [uT]


def _symmetric(diag, off) -> np.ndarray:
    S = np.diag(diag)
    for (i, j), v in zip(OFF_DIAGONAL, off):
        S[i, j] = S[j, i] = v
    return S


def test_every_mounting_has_a_rotation_number():
    assert all_permutations_named()
    assert rotation_enum(np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]], float)) == 10  # the AK8963: ROLL_180_YAW_90
    assert np.array_equal(rotation_matrix(ROTATIONS[0]), np.eye(3))


def test_ardupilot_correct_field_on_the_file_gives_imucals_field(symmetric, run_cli):
    out = symmetric / "ap.param"
    r = run_cli(["export", str(symmetric / "out" / "calibration.yaml"), "--format", "ardupilot", "--out", str(out)])
    assert r.code == 0, r.err
    v = dict(ln.split(",") for ln in out.read_text().splitlines() if ln and not ln.startswith("#"))
    ofs = np.array([float(v[f"COMPASS_OFS_{a}"]) for a in "XYZ"])
    M = _symmetric([float(v[f"COMPASS_DIA_{a}"]) for a in "XYZ"], [float(v[f"COMPASS_ODI_{a}"]) for a in "XYZ"])
    R = rotation_matrix(ROTATIONS[int(v["COMPASS_ORIENT"])])
    raw, h = _raw_and_imucal(symmetric)
    # AP_Compass_Backend: rotate_field (mag.rotate(orientation)), then correct_field: mag += offsets; mag = mat * mag
    ap = ((raw * MG_PER_UT) @ R.T + ofs) @ M.T
    assert np.max(np.abs(ap - h * MG_PER_UT)) < AGREE * FIELD_UT * MG_PER_UT
    assert "rotation from the accelerometer's frame" not in r.out  # the symmetric fit: nothing left out


def test_px4_correct_on_the_file_gives_imucals_field(symmetric, run_cli):
    out = symmetric / "px4.params"
    r = run_cli(["export", str(symmetric / "out" / "calibration.yaml"), "--format", "px4", "--out", str(out)])
    assert r.code == 0, r.err
    v = {p[2]: p[3] for p in (ln.split("\t") for ln in out.read_text().splitlines() if ln and not ln.startswith("#"))}
    off = np.array([float(v[f"CAL_MAG0_{a}OFF"]) for a in "XYZ"])
    S = _symmetric([float(v[f"CAL_MAG0_{a}SCALE"]) for a in "XYZ"], [float(v[f"CAL_MAG0_{a}ODIAG"]) for a in "XYZ"])
    R = rotation_matrix(ROTATIONS[int(v["CAL_MAG0_ROT"])])
    raw, h = _raw_and_imucal(symmetric)
    # Magnetometer.hpp Correct(): _rotation * (_scale * (data - _offset))
    px4 = ((raw * GAUSS_PER_UT - off) @ S.T) @ R.T
    assert np.max(np.abs(px4 - h * GAUSS_PER_UT)) < AGREE * FIELD_UT * GAUSS_PER_UT


def test_a_full_soft_iron_is_written_with_its_rotation_stated(tmp_path, run_cli):
    write_log(tmp_path / "log.csv")
    assert run_cli(["calibrate", "--data", str(tmp_path / "log.csv"), "--unit", "g", "--mag-unit", "uT",
                    "--mag-field", "48uT", "--mag-soft-iron", "full", "--out", str(tmp_path / "out"), "--no-figures",
                    "--quiet"]).code == 0
    r = run_cli(["export", str(tmp_path / "out" / "calibration.yaml"), "--format", "ardupilot", "--out",
                 str(tmp_path / "ap.param")])
    assert r.code == 0 and "deg rotation from the accelerometer's frame beyond its mounting is not held" in r.out
    words = r.out.split("magnetometer's ")[1].split(" deg")[0]
    assert float(words) == pytest.approx(math.sqrt(1.0 + 0.25 + 2.25), abs=0.15)  # the simulated 1.87 deg


def test_a_magnetometer_in_counts_is_refused_in_one_line(tmp_path, run_cli, unchanged):
    write_log(tmp_path / "log.csv")
    assert run_cli(["calibrate", "--data", str(tmp_path / "log.csv"), "--unit", "g", "--mag-field", "48uT", "--out",
                    str(tmp_path / "out"), "--no-figures", "--quiet"]).code == 0
    with unchanged(tmp_path):
        r = run_cli(["export", str(tmp_path / "out" / "calibration.yaml"), "--format", "px4", "--out",
                     str(tmp_path / "px4.params")])
    assert r.code == 2 and r.err.count("\n") == 1
    assert "magnetometer.units: the magnetometer's raw unit 'raw' is not a field unit" in r.err
