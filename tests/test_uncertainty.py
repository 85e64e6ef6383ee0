"""The standard errors the fit reports are true: a small seeded Monte-Carlo against the CRLB.

The full study (500+ recordings per setting, several schemes and sensors) is
studies/mc_uncertainty.py -> studies/results/uncertainty.md. Here: 80 recordings per setting, bounds wide
enough for that sample size (a std ratio is known to ~ +-0.15, a coverage to ~ +-5 points) but
narrow enough to catch a wrong weight, a missing or doubled chi-square scaling, or a covariance
in the wrong units (each moves the ratios by >= 40 % or the coverage by >= 10 points).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from imucal.analysis import design as D
from imucal.solve.fit import FitData, fit
from imucal.solve.initial import ellipsoid_guess
from imucal.model.sensor import build_model
from imucal.model.parameters import BASE_NAMES, base_parameters
from imucal.analysis.simulate import frame_matrix, si_sensor
from imucal.report.text import t_quantile_975

G = 9.80665
SIGMA_MEAN = 0.003  # m/s^2 per axis per interval mean (0.06 m/s^2 per sample, 400 samples)
N_REC = 80


@dataclass(frozen=True)
class MC:
    z: np.ndarray  #: (estimate - truth) / CRLB std
    err: np.ndarray
    std: np.ndarray  #: reported
    redchi: np.ndarray
    dof: int
    crlb: np.ndarray
    unscaled_vs_crlb_at_estimate: float  #: max relative difference, covariance / redchi vs F^-1
    unscaled_vs_crlb_at_truth: float


def _monte_carlo(scheme: str, seed: int) -> MC:
    sensor = si_sensor(np.random.default_rng(11))
    truth = np.array([sensor.values()[n] for n in BASE_NAMES])
    ds = D.DesignSensor(tuple(sensor.s), tuple(sensor.b), tuple(sensor.angles))
    u = D.scheme_directions(scheme)
    E = frame_matrix(np.asarray(sensor.angles))
    clean = np.asarray(sensor.s) + np.asarray(sensor.b) * (G * u @ E)  # Eq. (theModel), Lemma 1
    sig = D.residual_sigma(u, SIGMA_MEAN, ds, G)
    C = D.crlb(D.fisher(u, sig, ds, G))
    crlb = np.sqrt(np.diag(C))
    rng = np.random.default_rng(seed)
    model = build_model()
    errs, stds, redchi = [], [], []
    d_est = d_truth = 0.0
    for k in range(N_REC):
        means = clean + rng.normal(0, SIGMA_MEAN, clean.shape)
        g0 = ellipsoid_guess(means, G)
        params = base_parameters(g0.s, g0.b, g0.angles, raw_unit="m/s^2", gravity=G)
        data = FitData(raw=means, cov=np.zeros((len(u), 0)), raw_var=np.full(means.shape, SIGMA_MEAN**2),
                       group=np.arange(len(u)), mode="means")
        res = fit(data, params, model, G)
        est = np.array([res.params[n].value for n in BASE_NAMES])
        errs.append(est - truth)
        stds.append([res.std[n] for n in BASE_NAMES])
        redchi.append(res.redchi)
        if k < 5:
            unscaled = res.covariance / res.redchi
            at_est = D.crlb(D.fisher(u, res.sigma, D.DesignSensor.from_values(res.params.value_dict()), G))
            d_est = max(d_est, float(np.max(np.abs(unscaled - at_est) / np.sqrt(np.outer(np.diag(at_est),
                                                                                       np.diag(at_est))))))
            d_truth = max(d_truth, float(np.max(np.abs(np.sqrt(np.diag(unscaled)) / crlb - 1))))
    err = np.array(errs)
    return MC(z=err / crlb, err=err, std=np.array(stds), redchi=np.array(redchi), dof=len(u) - 9, crlb=crlb,
              unscaled_vs_crlb_at_estimate=d_est, unscaled_vs_crlb_at_truth=d_truth)


@pytest.fixture(scope="module")
def wedge() -> MC:
    return _monte_carlo("wedge-24", seed=1)


@pytest.fixture(scope="module")
def edges() -> MC:
    return _monte_carlo("edges", seed=2)


def test_fit_covariance_is_the_inverse_fisher_information(wedge: MC) -> None:
    """Unscaled fit covariance (J^T W J)^-1 == design.crlb at the estimate (up to the design's
    assumption |a| = g at every pose: residuals of ~3e-4 g), and ~ the CRLB at the truth."""
    assert wedge.unscaled_vs_crlb_at_estimate < 5e-3
    assert wedge.unscaled_vs_crlb_at_truth < 0.01


def test_empirical_scatter_matches_the_cramer_rao_bound(wedge: MC) -> None:
    ratio = wedge.z.std(axis=0, ddof=1)
    assert np.all(ratio > 0.75) and np.all(ratio < 1.3), dict(zip(BASE_NAMES, ratio.round(3)))
    assert 0.85 < float(np.sqrt(np.mean(ratio**2))) < 1.15
    bias = wedge.z.mean(axis=0)
    assert np.all(np.abs(bias) < 0.45), dict(zip(BASE_NAMES, bias.round(3)))


def test_reported_std_matches_the_empirical_scatter(wedge: MC) -> None:
    ratio = wedge.std.mean(axis=0) / wedge.err.std(axis=0, ddof=1)
    assert np.all(ratio > 0.75) and np.all(ratio < 1.3), dict(zip(BASE_NAMES, ratio.round(3)))
    # reported = sqrt(redchi) x unscaled: redchi averages to 1 when the weights are right
    assert 0.85 < float(np.mean(wedge.redchi)) < 1.15


def test_95_percent_intervals_cover(wedge: MC) -> None:
    t = t_quantile_975(wedge.dof)  # the quantile the report prints
    cover = np.mean(np.abs(wedge.err) <= t * wedge.std, axis=0)
    assert np.all(cover >= 0.85), dict(zip(BASE_NAMES, cover.round(3)))
    assert 0.91 <= float(cover.mean()) <= 0.985


def test_student_t_quantiles_are_needed_at_few_poses(edges: MC) -> None:
    """12 poses leave dof = 3: 1.96 x the scaled std under-covers; the t quantile (3.18) does not."""
    t = t_quantile_975(edges.dof)
    cov_t = np.mean(np.abs(edges.err) <= t * edges.std)
    cov_z = np.mean(np.abs(edges.err) <= 1.96 * edges.std)
    assert cov_t > cov_z + 0.04
    assert 0.91 <= cov_t <= 0.985
    assert cov_z < 0.93
