"""A recording whose gyroscope cannot be calibrated (it turned too little between the poses: a thermal soak, a
bench log) no longer blocks its accelerometer: the refusal says how to calibrate the accelerometer alone,
--no-gyro (gyro.calibrate: false) does it and says so."""
from __future__ import annotations

import numpy as np
import pytest
import yaml


@pytest.fixture()
def still_gyro(tmp_path, si_recording):
    """The SI recording's samples with a gyroscope that never turns."""
    d = np.loadtxt(si_recording.path, delimiter=",", skiprows=1)[:, :4]
    p = tmp_path / "still_gyro.csv"
    gyro = np.tile([0.001, 0.002, -0.001], (d.shape[0], 1))
    np.savetxt(p, np.column_stack([d, gyro]), delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="", fmt="%.10g")
    return p


def test_a_gyroscope_that_cannot_be_calibrated_names_the_accelerometer_alone(run_cli, tmp_path, still_gyro):
    r = run_cli(["calibrate", still_gyro, "--unit", "m/s^2", "--out", tmp_path / "o", "--no-figures", "--quiet"])
    lines = r.err.strip().splitlines()
    assert r.code == 2 and len(lines) == 1 and not (tmp_path / "o").exists(), r.err
    assert lines[0].endswith("; or calibrate the accelerometer alone: --no-gyro (gyro.calibrate: false))"), lines[0]


def test_no_gyro_calibrates_the_accelerometer_alone_and_says_so(run_cli, tmp_path, still_gyro, si_recording):
    r = run_cli(["calibrate", still_gyro, "--unit", "m/s^2", "--no-gyro", "--out", tmp_path / "o", "--no-figures",
                 "--quiet"])
    assert r.code == 0, r.err
    assert "the gyroscope's readings were not calibrated (--no-gyro, gyro.calibrate: false)" in r.err
    cal = yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())
    assert "gyroscope" not in cal and cal["sensors"] == ["accelerometer"]
    r = run_cli(["calibrate", si_recording.path, "--unit", "m/s^2", "--out", tmp_path / "acc", "--no-figures",
                 "--quiet"])
    assert r.code == 0
    alone = yaml.safe_load((tmp_path / "acc" / "calibration.yaml").read_text())
    assert cal["parameters"] == alone["parameters"]  # the same accelerometer as from its columns alone


def test_gyro_calibrate_in_a_run_file_is_true_or_false(run_cli, tmp_path, still_gyro):
    run = tmp_path / "run.yaml"
    run.write_text(f"data: {{path: {still_gyro}, unit: m/s^2}}\ngyro: {{calibrate: sometimes}}\n")
    r = run_cli(["calibrate", run, "--out", tmp_path / "o", "--no-figures", "--quiet"])
    lines = r.err.strip().splitlines()
    assert r.code == 2 and len(lines) == 1 and "gyro.calibrate" in lines[0] and "true or false" in lines[0], r.err
    run.write_text(f"data: {{path: {still_gyro}, unit: m/s^2}}\ngyro: {{calibrate: false}}\n")
    assert run_cli(["calibrate", run, "--out", tmp_path / "o", "--no-figures", "--quiet"]).code == 0


def test_no_mag_leaves_the_magnetometer_and_says_so(run_cli, tmp_path, si_recording):
    """The same for a magnetometer (mx, my, mz): --no-mag calibrates the accelerometer alone and says so; a
    magnetometer fit that is refused names it."""
    d = np.loadtxt(si_recording.path, delimiter=",", skiprows=1)[:, :4]
    p = tmp_path / "with_mag.csv"
    mag = np.tile([20.0, 1.0, -40.0], (d.shape[0], 1))  # a field that never turns: no magnetometer fit
    np.savetxt(p, np.column_stack([d, mag]), delimiter=",", header="t,ax,ay,az,mx,my,mz", comments="", fmt="%.10g")
    r = run_cli(["calibrate", p, "--unit", "m/s^2", "--out", tmp_path / "o", "--no-figures", "--quiet"])
    lines = r.err.strip().splitlines()
    assert r.code == 2 and len(lines) == 1 and lines[0].endswith(
        "; or calibrate without the magnetometer: --no-mag (mag.calibrate: false))"), r.err
    r = run_cli(["calibrate", p, "--unit", "m/s^2", "--no-mag", "--out", tmp_path / "o", "--no-figures", "--quiet"])
    assert r.code == 0 and "the magnetometer's readings were not calibrated (--no-mag" in r.err, r.err
    assert yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())["sensors"] == ["accelerometer"]
