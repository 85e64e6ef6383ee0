"""Issue 14: a measured noise model (`imucal noise --json`, a Kalibr imu.yaml) sets the interval
means' noise in the fit (calibrate --noise, fit.noise), validated like every input."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import calibrate_file
from imucal.analysis.noise_model import load_noise_model
from imucal.errors import ImucalError

FS = 100.0
SIGMA = 4.0  # counts per sample, the counts_recording sensor's white noise


def _still_csv(path: Path, n: int = 60_000, seed: int = 3) -> Path:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    raw = np.array([100.0, -50.0, 1670.0]) + rng.normal(0, SIGMA, (n, 3))
    np.savetxt(path, np.column_stack([t, raw]), delimiter=",", header="t,ax,ay,az", comments="")
    return path


@pytest.fixture(scope="module")
def noise_json(tmp_path_factory) -> Path:
    """`imucal noise --json` of a 10 min still log of the counts sensor's white noise."""
    from imucal.cli.main import main

    d = tmp_path_factory.mktemp("noise")
    out = d / "noise.json"
    assert main(["noise", "--data", str(_still_csv(d / "still.csv")), "--json", str(out)]) == 0
    return out


def test_mean_noise_matches_the_scatter_of_simulated_means(noise_json):
    """sigma_mean = N sqrt(fs / n): the spread of 2000 independent 50-sample means agrees to 7 %."""
    model = load_noise_model(noise_json)
    means = np.random.default_rng(9).normal(0, SIGMA, (2000, 50, 3)).mean(axis=1)
    predicted = np.sqrt(model.mean_variance(np.array([50]), FS)[0])
    assert np.all(np.abs(means.std(axis=0, ddof=1) / predicted - 1) < 0.07)
    assert np.all(model.floor == 0)  # white noise: the curve falls to its end, no floor


def test_calibrate_with_the_noise_file(noise_json, counts_recording, run_cli, tmp_path):
    code, out, err = run_cli(["calibrate", "--data", counts_recording.path, "--noise", noise_json,
                              "--out", tmp_path / "o", "--no-figures", "--weights", "noise"])
    assert code == 0, err
    cal = yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())
    assert cal["fit"]["noise"] == "noise.json"
    assert 0.5 < cal["fit"]["redchi"] < 2.0  # the measured noise explains the residuals
    assert "noise of the means = from noise.json" in (tmp_path / "o" / "report.txt").read_text()


def test_noise_model_sets_the_weights(noise_json, counts_recording):
    """Each mean's sigma is N sqrt(fs / n) propagated, not its own scatter."""
    own = calibrate_file(counts_recording.path, fit={"weights": "noise"})
    model = calibrate_file(counts_recording.path, fit={"weights": "noise", "noise": str(noise_json)})
    var = load_noise_model(noise_json).mean_variance(model.intervals.n_samples, FS)
    ratio_model = model.result.sigma / np.sqrt(var.mean(axis=1))
    ratio_own = own.result.sigma / np.sqrt(var.mean(axis=1))
    assert np.ptp(ratio_model) < 0.2 * np.ptp(ratio_own)  # the model's sigmas follow n alone
    assert model.calibration.fit["noise"] == "noise.json" and own.calibration.fit["noise"] == "scatter"


def test_kalibr_density_in_m_s2_converted_by_each_axis_scale(tmp_path):
    p = tmp_path / "imu.yaml"
    p.write_text("accelerometer_noise_density: 0.002\naccelerometer_random_walk: 0.0001\nupdate_rate: 100\n"
                 "rostopic: /imu\n")
    m = load_noise_model(p).in_raw("raw", np.array([1600.0, 1700.0, 1650.0]))
    assert m.white_density.tolist() == pytest.approx([3.2, 3.4, 3.3])
    assert load_noise_model(p).in_raw("m/s^2", np.ones(3)).white_density.tolist() == [0.002] * 3


def test_fit_noise_in_yaml_is_relative_to_the_yaml(noise_json, counts_recording, tmp_path, run_cli):
    (tmp_path / "n.json").write_bytes(noise_json.read_bytes())
    cfg = tmp_path / "run.yaml"
    cfg.write_text(f"data: {{path: {counts_recording.path}}}\nfit: {{noise: n.json}}\n")
    code, out, err = run_cli(["calibrate", cfg, "--out", tmp_path / "o", "--no-figures", "--quiet"])
    assert code == 0, err
    assert yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())["fit"]["noise"] == "n.json"


def _axes(**over):
    ax = {"white_density": 0.4, "white_rel_err": 0.01, "random_walk": None, "random_walk_rel_err": None,
          "bias_instability": 0.01, "bias_instability_rel_err": 0.5, "tau_min": 100.0}
    return {a: {**ax, **over} for a in "xyz"}


@pytest.mark.parametrize("name, content, field, words", [
    ("n.json", {"unit": "raw"}, "axes", "missing"),
    ("n.json", {"unit": "raw", "axes": _axes(white_density=-1)}, "axes.x.white_density", "must be a positive number"),
    ("n.json", {"unit": "raw", "axes": _axes(white_density="a")}, "axes.x.white_density", "'a' must be a positive number"),
    ("n.json", {"unit": "raw", "axes": _axes(), "extra": 1}, "extra", "unknown key"),
    ("n.json", {"unit": "g", "axes": _axes()}, "unit", "neither the recording's raw unit"),
    ("n.json", "[1, 2", "noise", "JSON"),
    ("imu.yaml", {"accelerometer_random_walk": 0.001}, "accelerometer_noise_density", "missing"),
    ("imu.yaml", {"accelerometer_noise_density": 0}, "accelerometer_noise_density", "0 must be a positive number"),
    ("n.txt", "x", "noise", "neither .json"),
])
def test_bad_noise_files_are_one_line_errors(name, content, field, words, tmp_path, counts_recording, run_cli):
    p = tmp_path / name
    text = content if isinstance(content, str) else (json.dumps(content) if name.endswith("json")
                                                     else yaml.safe_dump(content))
    p.write_text(text)
    code, out, err = run_cli(["calibrate", "--data", counts_recording.path, "--noise", p, "--out", tmp_path / "o",
                              "--no-figures"])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert f"{p}: {field}:" in err and words in err


def test_fit_noise_must_be_a_file_name():
    from imucal.config.run import config_from_dict

    with pytest.raises(ImucalError, match="fit.noise") as e:
        config_from_dict({"data": {"path": "x.csv"}, "fit": {"noise": 3}}, "run.yaml")
    assert "must be a file name" in str(e.value)
