"""Issue 25, the accelerometer's default weights and samples mode. The default (weights: auto) has the
uniform fit's values, every still interval alike, with standard errors from each mean's noise, the excess
or a walking bias: a bias that walks during a recording leaves the calibration on the recording's still
poses, with offsets of a stated epoch (the bias averaged over the still intervals) and honest errors, and
the report says how far it moved. The samples' own scatter no longer biases a samples fit (E|g + v| > g).
Data are made here with known truth."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import yaml

from conftest import calibrate_file, write_simulation
from imucal.analysis.simulate import PosePlan, cube_directions, si_sensor, simulate
from imucal.calibration.frozen import Calibration
from imucal.constants import STANDARD_GRAVITY
from imucal.model.geometry import frame_np
from imucal.model.parameters import base_parameters
from imucal.model.sensor import build_model
from imucal.solve.fit import FitData, fit

G = STANDARD_GRAVITY
#: A consumer MEMS part at 100 Hz (BMI160-like): white noise per sample [m/s^2] (180 ug/sqrt(Hz) over
#: 50 Hz) and a bias random walk [m/s^2/sqrt(s)] that moves the bias about 1 mg in five minutes.
NOISE, Q_WALK = 0.012, 5e-4
ANGLES = np.array([1.5608, 1.5808, 1.5758])
S, B = np.array([30.0, -12.0, 8.0]), np.array([1670.0, 1660.0, 1675.0])  # counts, counts per m/s^2
NAMES = ("s1", "s2", "s3", "b1", "b2", "b3", "phi", "psi", "theta")


def _walking_recording(tmp_path, seed: int = 0):
    """The cube's 26 poses visited twice in shuffled order, a walking bias on every axis."""
    rng = np.random.default_rng(seed)
    sensor = dataclasses.replace(si_sensor(rng, noise=NOISE), random_walk=(Q_WALK,) * 3)
    d = cube_directions()
    dirs = np.vstack([d, d[::-1]])[rng.permutation(2 * len(d))]
    return write_simulation(tmp_path / "walk.csv", sensor, dirs, seed)


def test_a_walking_bias_leaves_the_default_calibration_on_its_still_poses(run_cli, tmp_path):
    """Before issue 25 the default (GLS with the walk anchored at the first interval) had 1.57 x the
    uniform fit's RMS of |a| - g on this recording; now the uniform fit's values, and the file and report
    say which epoch the offsets are and how far the bias moved."""
    rec = _walking_recording(tmp_path)
    out, js = tmp_path / "out", tmp_path / "s.json"
    r = run_cli(["calibrate", "--data", rec.path, "--unit", "m/s^2", "--out", out, "--no-figures", "--json", js])
    assert r.code == 0, r.err
    assert "the bias moved during the recording (bias_random_walk" in r.err
    assert "the offsets are its mean over the still intervals" in r.err
    cal = Calibration.load(out / "calibration.yaml")
    uniform = calibrate_file(rec.path, data={"unit": "m/s^2"}, fit={"weights": "uniform"})
    assert cal.fit["bias_random_walk"] > 0 and uniform.result.random_walk == 0
    assert cal.fit["rms_residual"] <= 1.02 * uniform.calibration.fit["rms_residual"]
    assert cal.params.value_dict() == uniform.calibration.params.value_dict()
    drift = cal.fit["bias_drift"]
    assert drift["offsets_epoch"] == "mean over the still intervals" and drift["n_intervals"] == 52
    for key in ("moved_mg", "moved_raw", "moved_std_m_s2", "peak_to_peak_mg"):
        assert len(drift[key]) == 3 and all(np.isfinite(drift[key])), key
    assert np.allclose(drift["moved_mg"], np.array(drift["moved_m_s2"]) / G * 1e3)
    assert max(drift["peak_to_peak_mg"]) > 0.3  # a consumer part's walk: tenths of a mg at least
    assert json.loads(js.read_text())["bias_drift"] == drift
    report = (out / "report.txt").read_text()
    assert "bias moved         = per sensor axis" in report
    for axis in "xyz":
        assert f"        {axis}: " in report and " mg); peak to peak " in report
    assert "offsets s1..s3     = the bias averaged over the 52 still intervals" in report
    # the file with its drift section reads back and saves to the same bytes
    cal.save(tmp_path / "again.yaml")
    assert (tmp_path / "again.yaml").read_bytes() == (out / "calibration.yaml").read_bytes()
    assert yaml.safe_load((out / "calibration.yaml").read_text())["fit"]["bias_drift"]["raw_unit"] == "m/s^2"


def _walking_means(seed: int, q: float):
    """Means of the 18 faces and edges visited twice, one every 5 s, noise 0.3 counts per mean, a bias
    random walk of q [m/s^2/sqrt(s)] per axis; also the bias of each mean [counts]."""
    rng = np.random.default_rng(seed)
    d = cube_directions("faces+edges")
    u = np.vstack([d[rng.permutation(len(d))] for _ in range(2)])
    t = 2.5 + 5.0 * np.arange(len(u))
    walk = np.cumsum(rng.normal(0, 1, u.shape) * np.sqrt(np.diff(t, prepend=0.0))[:, None], axis=0) * q
    raw = S + B * (G * u @ frame_np(ANGLES)) + walk * B + rng.normal(0, 0.3, u.shape)  # Eq. theModel
    return FitData(raw, np.zeros((len(u), 0)), np.full(u.shape, 0.09), np.arange(len(u)), "means", t=t), walk


def _fit(data: FitData, weights: str):
    return fit(data, base_parameters(S * 1.01, B * 0.99, np.full(3, np.pi / 2), gravity=G), build_model(), G,
               weights=weights)


def test_walk_offsets_are_the_mean_bias_with_honest_errors_and_drift():
    """30 seeds: the offsets estimate the bias averaged over the intervals, scales and angles the truth,
    each within its standard error (z spread about 1); how far the bias moved (last minus first interval)
    within its own; and every default fit within 1.02 x the uniform fit's RMS. (The GLS fit before issue
    25 estimated the walk's origin: its offsets were 5 standard errors from the mean bias.)"""
    z, z_moved, named = [], [], 0
    for seed in range(30):
        data, walk = _walking_means(seed, 3e-4)
        a, u = _fit(data, "auto"), _fit(data, "uniform")
        assert a.rms_residual <= 1.02 * u.rms_residual, seed
        if a.random_walk == 0:
            continue
        named += 1
        s = S + B * walk.mean(axis=0)
        truth = dict(zip(NAMES, (*s, *B, *ANGLES)))
        z += [(a.params[n].value - v) / a.std[n] for n, v in truth.items()]
        d = a.bias_drift
        z_moved += list((d.moved - (walk[-1] - walk[0])) / d.moved_std)
    assert named >= 25
    assert 0.8 < np.std(z) < 1.25, np.std(z)
    assert abs(np.mean(z)) < 0.2, np.mean(z)
    assert 0.75 < np.std(z_moved) < 1.3 and abs(np.mean(z_moved)) < 0.35, (np.std(z_moved), np.mean(z_moved))


def test_uneven_noise_leaves_the_default_on_its_poses_with_honest_errors():
    """Interval means whose noise differs 1 to 6 x between poses (short or shaky holds): the noise-weighted
    fit's RMS of |a| - g on them exceeds the uniform fit's (up to 1.23 x on a real MPU-6050); the default
    keeps the uniform values, and its errors (the sandwich under each mean's noise) cover the truth."""
    z, worse = [], []
    for seed in range(30):
        rng = np.random.default_rng(seed)
        u = cube_directions()
        sig = 0.3 * np.exp(rng.uniform(0, np.log(6), len(u)))  # counts per mean
        raw = S + B * (G * u @ frame_np(ANGLES)) + rng.normal(0, 1, u.shape) * sig[:, None]
        data = FitData(raw, np.zeros((len(u), 0)), np.repeat(sig[:, None] ** 2, 3, axis=1), np.arange(len(u)),
                       "means", t=5.0 * np.arange(len(u)))
        a, n, un = _fit(data, "auto"), _fit(data, "noise"), _fit(data, "uniform")
        assert a.values() == un.values() and a.excess == 0 and a.random_walk == 0
        worse.append(n.rms_residual / un.rms_residual)
        z += [(a.params[k].value - v) / a.std[k] for k, v in zip(NAMES, (*S, *B, *ANGLES))]
    assert max(worse) > 1.05  # what the noise weights would have given
    assert 0.85 < np.std(z) < 1.2 and abs(np.mean(z)) < 0.2, (np.std(z), np.mean(z))


def _vibrating_samples(seed: int, sigma: float, n: int = 300) -> tuple[FitData, dict[str, float]]:
    """n samples in each of the cube's 26 poses [m/s^2, scales near 1], white per-sample scatter sigma
    [m/s^2] per axis (vibration): the samples fit's rows, and the truth."""
    rng = np.random.default_rng(seed)
    s, b = rng.uniform(-0.2, 0.2, 3), 1 + 0.02 * rng.uniform(-1, 1, 3)
    u = np.repeat(cube_directions(), n, axis=0)
    raw = s + b * (G * u @ frame_np(ANGLES)) + rng.normal(0, sigma, u.shape)
    group = np.repeat(np.arange(26), n)
    data = FitData(raw, np.zeros((len(u), 0)), np.full(u.shape, sigma**2), group, "samples")
    return data, dict(zip(NAMES, (*s, *b, *ANGLES)))


def test_samples_mode_under_vibration_leaves_the_scales_unbiased_and_says_so():
    """1 m/s^2 of scatter per axis: averaging |g + v| put the scales 4-8 standard errors high (0.7-1.1 %);
    with the scatter's own second-order terms in the rows' gravity the scales are within their standard
    errors, and the fit says how far the correction moved them."""
    z, moved = [], []
    for seed in range(8):
        data, truth = _vibrating_samples(seed, 1.0)
        res = fit(data, base_parameters(np.zeros(3), np.ones(3), np.full(3, np.pi / 2), gravity=G), build_model(), G)
        assert res.success
        z += [(res.params[n].value - truth[n]) / res.std[n] for n in ("b1", "b2", "b3")]
        moved.append(res.scatter_z[1])
        # E|g + v| - g = (tr S - u^T S u) / (2 g) = sigma^2 / g for isotropic scatter, at unit scales
        # (each interval's from its own 300 samples: their covariance is within some 10 % of sigma^2)
        assert np.median(res.scatter_term) == pytest.approx(1.0 / G, rel=0.05)
        assert res.scatter_term == pytest.approx(np.full(26, 1.0 / G), rel=0.3)
        assert res.scatter_shift["b1"] > 0  # uncorrected, the scales come out high
    assert abs(np.mean(z)) < 0.6 and np.max(np.abs(z)) < 3.5, z
    assert min(moved) > 3.0, moved


def test_samples_mode_of_a_vibrating_recording_warns_and_reports(run_cli, tmp_path):
    """A recording with 0.7 m/s^2 of scatter per sample, through static detection: the scales within
    their standard errors of the truth (uncorrected, about 4.5 standard errors high), and the run says
    the correction mattered."""
    rng = np.random.default_rng(3)
    sensor = si_sensor(rng, noise=0.7)
    sim = simulate(sensor, PosePlan(cube_directions(), hold=3.0, transition=1.5, vibration=3.5), seed=3)
    (tmp_path / "vib.csv").write_text(sim.to_csv_text())
    out = tmp_path / "out"
    r = run_cli(["calibrate", "--data", tmp_path / "vib.csv", "--unit", "m/s^2", "--mode", "samples",
                 "--out", out, "--no-figures"])
    assert r.code == 0, r.err
    assert "imucal: warning: samples mode: the samples' scatter about their interval means" in r.err
    assert "standard errors; corrected to second order (fit.mode: means does not need it)" in r.err
    assert "    scatter correction = |a| of a sample exceeds |a| of its interval's mean by up to" in \
        (out / "report.txt").read_text()
    cal, truth = Calibration.load(out / "calibration.yaml"), sensor.values()
    for k in ("b1", "b2", "b3"):
        assert abs(cal.params[k].value - truth[k]) < 2.5 * cal.std[k], k


def test_interval_means_carry_no_scatter_correction(si_run):
    """Interval means: the scatter's term is divided by the samples per interval, so none is applied."""
    assert si_run.result.scatter_term is None and si_run.result.scatter_shift is None
    assert not any("samples mode" in w for w in si_run.calibration.fit["warnings"])
