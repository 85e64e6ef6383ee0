"""weights: auto (the default) = the uniform fit's values (issue 25: every interval alike), with standard
errors from the noise of each mean, plus a between-interval excess when the residuals exceed the noise
(issue 12's honest errors). Checked against data made here with a known excess."""
from __future__ import annotations

import numpy as np
import pytest

from imucal.model.geometry import frame_np
from imucal.model.parameters import base_parameters
from imucal.model.sensor import build_model
from imucal.solve.fit import FitData, fit
from imucal.solve.stats import between_excess

G = 9.80665
ANGLES = np.array([1.5608, 1.5808, 1.5758])
S, B = np.array([30.0, -12.0, 8.0]), np.array([1670.0, 1660.0, 1675.0])  # counts, counts per m/s^2


def _means(n: int, sigma: float, tau: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """n interval means [counts] of random directions: noise sigma per mean plus a random
    offset of tau per visit (the same draw on every axis's reading, in counts)."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    clean = S + B * (G * u @ frame_np(ANGLES))  # raw_i = s_i + b_i e_i . a (Eq. theModel)
    return clean + rng.normal(0, sigma, clean.shape) + rng.normal(0, tau, clean.shape), np.full(clean.shape, sigma**2)


def _fit(raw, var, weights):
    data = FitData(raw, np.zeros((len(raw), 0)), var, np.arange(len(raw)), "means")
    p = base_parameters(S * 1.01, B * 0.99, np.full(3, np.pi / 2), gravity=G)
    return fit(data, p, build_model(), G, weights=weights)


def test_without_excess_auto_has_the_uniform_values_and_the_noise_errors():
    raw, var = _means(40, 0.5, 0.0, seed=1)
    a, n, u = _fit(raw, var, "auto"), _fit(raw, var, "noise"), _fit(raw, var, "uniform")
    assert a.excess == 0.0 and a.random_walk == 0.0
    assert a.values() == u.values()  # every interval alike
    assert a.chi2 == pytest.approx(n.chi2, rel=1e-3)  # the test of the noise is the noise-weighted fit's
    for k in a.free_names:  # equal noise here: the noise-weighted fit's errors
        assert a.std[k] == pytest.approx(n.std[k], rel=0.02), k


def test_a_between_visit_excess_is_estimated_and_carried_into_the_errors():
    sig, tau = 0.3, 3.0  # counts: the visits scatter ten times more than each mean's noise
    taus, z_auto, z_noise = [], [], []
    for seed in range(12):
        raw, var = _means(60, sig, tau, seed)
        a, n = _fit(raw, var, "auto"), _fit(raw, var, "noise")
        assert a.success and a.excess > 0 and n.excess == 0
        assert a.redchi == pytest.approx(1.0, rel=0.05)  # the excess absorbs the scatter
        assert a.redchi_noise > 10
        taus.append(np.sqrt(a.excess))
        truth = {"s1": S[0], "s2": S[1], "s3": S[2], "b1": B[0], "b2": B[1], "b3": B[2],
                 "phi": ANGLES[0], "psi": ANGLES[1], "theta": ANGLES[2]}
        z_auto += [(a.params[k].value - v) / a.std[k] for k, v in truth.items()]
        z_noise += [(n.params[k].value - v) / n.std[k] for k, v in truth.items()]
    # tau is in m/s^2 of |a|: a visit's offset of 3 counts on each axis is 3/1670 m/s^2 along g
    assert np.median(taus) == pytest.approx(tau / B.mean(), rel=0.3)
    # errors scaled to the truth: about unit variance with the excess in the weights
    assert 0.6 < np.std(z_auto) < 1.5, np.std(z_auto)


def test_paule_mandel_solves_its_moment_equation():
    rng = np.random.default_rng(3)
    s = rng.uniform(0.5, 2.0, 200)
    r = rng.normal(0, np.sqrt(s**2 + 4.0))
    e = between_excess(r, s, 190)
    assert np.sum(r**2 / (s**2 + e)) == pytest.approx(190, rel=1e-9)
    assert between_excess(rng.normal(0, s * 0.5), s, 190) == 0.0


def test_xsens_default_fit_is_as_good_as_the_uniform_one_and_better_than_imu_tk():
    """Issue 12: on Xsens (chi2/dof 8.1 against the noise) the default fit's RMS of |a| - g on
    interval means is at most 0.95 times imu_tk's 0.001122 m/s^2, near the uniform fit's."""
    from conftest import real_file
    from imucal.config.run import load_config
    from imucal.pipeline import calibrate_accelerometer
    import dataclasses
    from pathlib import Path

    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "xsens-mti-imutk.yaml")
    real_file("xsens-mti-imutk", "xsens_acc.mat")  # skips without ../shared
    runs = {w: calibrate_accelerometer(dataclasses.replace(cfg, fit=dataclasses.replace(cfg.fit, weights=w)))
            for w in ("auto", "noise", "uniform")}
    rms = {w: r.calibration.fit["rms_residual"] for w, r in runs.items()}
    assert rms["auto"] <= 0.95 * 0.001122
    assert rms["auto"] <= 1.01 * rms["uniform"] and rms["auto"] < rms["noise"]
    a, u = runs["auto"].result, runs["uniform"].result
    for k in a.free_names:  # errors like the uniform fit's, whose weights do not over-trust quiet poses
        assert a.std[k] == pytest.approx(u.std[k], rel=0.25), k
