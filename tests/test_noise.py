"""Issue 14 (noise): the Allan-deviation terms recover a simulated still log's known noise within
their stated uncertainty; the vectorised curve equals the textbook sum."""
from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import real_file
from imucal.analysis.noise import FLICKER_FACTOR, allan_deviation, estimate

FS = 100.0


def still_log(n: int, white: float, walk: float, seed: int) -> np.ndarray:
    """White noise of density ``white`` [unit/sqrt(Hz)] plus a random walk of ``walk`` [unit/s/sqrt(Hz)]."""
    rng = np.random.default_rng(seed)
    return (rng.normal(0, white * np.sqrt(FS), (n, 3))
            + np.cumsum(rng.normal(0, walk / np.sqrt(FS), (n, 3)), axis=0))


def test_overlapping_adev_equals_the_textbook_sum():
    y = still_log(2000, 0.01, 0.0, 1)[:, 0]
    c = allan_deviation(y, FS)
    for m, s in zip(np.round(c.tau * FS).astype(int)[:6], c.adev[:6, 0]):
        # IEEE 952: sigma^2 = 1/(2 m^2 (N - 2m + 1)) sum_j (sum_{i=j}^{j+m-1} (y_{i+m} - y_i))^2
        terms = [np.sum(y[j + m:j + 2 * m]) - np.sum(y[j:j + m]) for j in range(len(y) - 2 * m + 1)]
        assert s == pytest.approx(np.sqrt(np.mean(np.square(terms)) / (2 * m**2)), rel=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_white_noise_and_random_walk_within_stated_uncertainty(seed):
    white, walk = 0.002, 5e-5
    c = allan_deviation(still_log(360_000, white, walk, seed), FS)
    for j in range(3):
        e = estimate(c, j)
        assert abs(e.white_density / white - 1) < 4 * e.white_rel_err + 0.01
        assert abs(e.random_walk / walk - 1) < 3 * e.random_walk_rel_err


def test_white_noise_only_has_no_random_walk_and_a_falling_curve():
    c = allan_deviation(still_log(50_000, 0.01, 0.0, 3), FS)
    e = estimate(c, 0)
    assert np.isnan(e.random_walk)
    assert e.bias_instability == pytest.approx(c.adev[:, 0].min() / FLICKER_FACTOR)


def test_cli_on_the_xsens_still_start(run_cli, tmp_path):
    cal = tmp_path / "cal"
    assert run_cli(["calibrate", "--data", real_file("xsens-mti-imutk", "xsens_acc.mat"), "--gravity", "9.81744",
                    "--out", cal, "--no-figures", "--quiet"]).code == 0
    js = tmp_path / "n.json"
    r = run_cli(["noise", "--data", real_file("xsens-mti-imutk", "xsens_acc.mat"), "--calibration",
                 cal / "calibration.yaml", "--json", js])
    assert r.code == 0, r.err
    d = json.loads(js.read_text())
    assert d["segment"].startswith("the longest still interval") and d["unit"] == "m/s^2"
    assert 1e-4 < d["kalibr"]["accelerometer_noise_density"] < 1e-2
    assert d["kalibr"]["accelerometer_random_walk"] is None and "random walk n/a" in r.out


def _imu_still_log(path, white_acc: float, white_gyro: float, n: int = 20_000, seed: int = 5):
    """A still log with accelerometer [m/s^2] and gyroscope [rad/s] columns of known white noise."""
    rng = np.random.default_rng(seed)
    acc = np.array([0.1, -0.2, 9.81]) + rng.normal(0, white_acc * np.sqrt(FS), (n, 3))
    gyr = np.array([0.01, 0.0, -0.02]) + rng.normal(0, white_gyro * np.sqrt(FS), (n, 3))
    np.savetxt(path, np.column_stack([np.arange(n) / FS, acc, gyr]), delimiter=",", fmt="%.9g",
               header="t,ax,ay,az,gx,gy,gz", comments="")
    return path


def test_noise_covers_the_gyroscope_and_draws_the_allan_plot(run_cli, tmp_path):
    """Issue 29: the gyroscope's columns get their own table, JSON section and Kalibr fields, and --plot
    draws both sensors' Allan deviation; the JSON still reads as a --noise file."""
    from imucal.analysis.noise_model import load_noise_model

    log = _imu_still_log(tmp_path / "still.csv", 2e-3, 1e-4)
    js, png = tmp_path / "n.json", tmp_path / "allan.png"
    r = run_cli(["noise", "--data", log, "--unit", "m/s^2", "--gyro-unit", "rad/s", "--json", js, "--plot", png])
    assert r.code == 0, r.err
    assert "[accelerometer] unit m/s^2" in r.out and "[gyroscope] unit rad/s" in r.out
    d = json.loads(js.read_text())
    for sensor, want in ((d, 2e-3), (d["gyro"], 1e-4)):
        for a in "xyz":
            e = sensor["axes"][a]
            assert abs(e["white_density"] / want - 1) < 4 * e["white_rel_err"] + 0.02, (a, e)
    k = d["kalibr"]
    assert k["gyroscope_noise_density"] == max(d["gyro"]["axes"][a]["white_density"] for a in "xyz")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert load_noise_model(js).white_density == pytest.approx([d["axes"][a]["white_density"] for a in "xyz"])


def test_noise_json_to_stdout_is_the_json_alone(run_cli, tmp_path):
    """`--json -`: stdout holds the JSON alone (the tables go to stderr), no file named '-'."""
    log = _imu_still_log(tmp_path / "still.csv", 2e-3, 1e-4, n=5000)
    r = run_cli(["noise", "--data", log, "--json", "-"])
    assert r.code == 0, r.err
    assert json.loads(r.out)["gyro"]["unit"] == "raw" and "[gyroscope]" in r.err
    assert not (tmp_path / "-").exists() and not __import__("pathlib").Path("-").exists()
