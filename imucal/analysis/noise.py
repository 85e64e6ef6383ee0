"""Noise characterisation from a still log: overlapping Allan deviation (IEEE Std 952, Annex C).

For a rate or acceleration y sampled at tau0, with its integral x_k = tau0 sum_{j<k} y_j,

    sigma^2(tau = m tau0) = sum_k (x_{k+2m} - 2 x_{k+m} + x_k)^2 / (2 tau^2 (N - 2m)),

evaluated for every m on a log grid with one vectorised pass per m. From the curve, by a weighted fit of sigma^2(tau) = N^2 / tau + B0^2 + K^2 tau / 3:
  white-noise density N   (the -1/2 slope)                          [unit/sqrt(Hz)]
  random walk K           (the +1/2 slope)                          [unit/s/sqrt(Hz)]
  bias instability B      at the flat minimum: B = sigma_min / sqrt(2 ln 2 / pi) = sigma_min / 0.664
with uncertainties from the fit (weights from the number of independent clusters, Lesage &
Audoin: var(sigma^2) / sigma^4 = 2 / clusters). A term the curve does not show is n/a. The accelerometer values are Kalibr's
``accelerometer_noise_density`` and ``accelerometer_random_walk``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imucal.errors import ImucalError

#: sqrt(2 ln 2 / pi): sigma_min of a flicker floor over the bias instability B.
FLICKER_FACTOR = math.sqrt(2 * math.log(2) / math.pi)
#: A curve peaking after its first tau is fitted from this many times the peak's tau on.
LOWPASS_MARGIN = 10.0


@dataclass(frozen=True)
class AllanCurve:
    tau: np.ndarray  #: [s]
    adev: np.ndarray  #: (k, axes) [unit]
    clusters: np.ndarray  #: independent clusters per tau (N/m)


@dataclass(frozen=True)
class NoiseEstimate:
    """One axis: value and relative uncertainty of each term (nan when the curve lacks the slope)."""

    white_density: float
    white_rel_err: float
    random_walk: float
    random_walk_rel_err: float
    bias_instability: float
    bias_instability_rel_err: float
    tau_min: float  #: [s] where the curve is lowest


def allan_deviation(y: np.ndarray, rate: float, points_per_decade: int = 10, source: str | None = None,
                    axes: str = "xyz") -> AllanCurve:
    """Overlapping Allan deviation of each column of ``y`` (N, axes) sampled at ``rate`` Hz.

    Each column is computed in units of its own range and scaled back, so the curve of readings of
    any size (1e-200 or 1e200) is that of the same readings scaled to one. A column that never
    changes has no noise to measure: refused, naming ``source`` and the axis (``axes``: their names).
    """
    y = np.asarray(y, float)
    if y.ndim == 1:
        y = y[:, None]
    n = y.shape[0]
    if n < 100:
        raise ImucalError(f"only {n} still samples; the Allan deviation needs at least 100", file=source,
                          field="data", fix="record a longer still log (minutes to hours)")
    span = np.ptp(y, axis=0)
    for j in np.flatnonzero(~(span > 0)):
        name = axes[j] if j < len(axes) else str(j)
        raise ImucalError(f"axis {name} reads {y[0, j]:.6g} in all {n} still samples: it never changes, so it "
                          "has no noise to measure (a stuck or clipped axis, or readings rounded coarser than "
                          "the noise)", file=source, field="data",
                          fix=f"check axis {name} of the sensor, or record it at its full resolution")
    tau0 = 1.0 / rate
    x = np.vstack([np.zeros((1, y.shape[1])), np.cumsum((y - y.mean(axis=0)) / span, axis=0) * tau0])
    ms = np.unique(np.round(np.logspace(0, math.log10((n - 1) // 3), points_per_decade
                                        * max(1, int(math.log10(n)))).astype(int)))
    out = np.empty((ms.size, y.shape[1]))
    for i, m in enumerate(ms):
        d = x[2 * m:] - 2 * x[m:-m] + x[:-2 * m]
        out[i] = np.sqrt(np.mean(d * d, axis=0) / (2 * (m * tau0) ** 2))
    return AllanCurve(tau=ms * tau0, adev=out * span, clusters=n / ms)


def _rel_err(clusters: float) -> float:
    return 1.0 / math.sqrt(max(2.0 * (clusters - 1.0), 1.0))


def _fit_terms(t: np.ndarray, s: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sigma^2(tau) = q0 / tau + q1 + q2 tau / 3 with q >= 0 (white, flicker floor, random walk).

    Weighted least squares (var(sigma^2) / sigma^4 = 2 / clusters) over every subset of the
    three terms; the best subset with non-negative coefficients wins. Returns q and its std
    (inflated by the points per independent cluster, as neighbouring taus are correlated).
    """
    A = np.column_stack([1.0 / t, np.ones_like(t), t / 3.0])
    w = np.sqrt(c / 2.0) / s**2
    best = (np.inf, np.zeros(3), np.full(3, np.nan))
    for mask in ((1, 0, 1), (1, 1, 1), (1, 0, 0), (1, 1, 0), (0, 1, 1), (0, 0, 1), (0, 1, 0)):
        cols = [j for j in range(3) if mask[j]]
        Aw = A[:, cols] * w[:, None]
        q, *_ = np.linalg.lstsq(Aw, s**2 * w, rcond=None)
        if np.any(q < 0):
            continue
        res = float(np.sum((Aw @ q - s**2 * w) ** 2))
        dof = max(len(t) - len(cols), 1)
        if res / dof < best[0] * 0.9 or (best[0] == np.inf):
            cov = np.linalg.pinv(Aw.T @ Aw) * max(res / dof, 1.0) * 5.0  # ~5 taus per cluster scale
            qq, sd = np.zeros(3), np.full(3, np.nan)
            qq[cols], sd[cols] = q, np.sqrt(np.diag(cov))
            best = (res / dof, qq, sd)
    return best[1], best[2]


def estimate(curve: AllanCurve, axis: int = 0) -> NoiseEstimate:
    """White-noise density, random walk and bias instability of one axis of ``curve``."""
    t, s, c = curve.tau, curve.adev[:, axis], curve.clusters
    # A curve that rises first is low-pass filtered noise, correlated over about its peak's tau: the
    # -1/2 slope of white noise holds from well beyond it (LOWPASS_MARGIN x the peak's tau) on.
    k0 = int(np.argmax(s))
    if k0 > 0:
        keep = t >= LOWPASS_MARGIN * t[k0]
        if np.count_nonzero(keep) >= 4:
            t, s, c = t[keep], s[keep], c[keep]
    unit = float(s.max())  # fitted in units of the curve's largest value: no under- or overflow of s^2
    if not (np.isfinite(unit) and unit > 0):
        raise ImucalError(f"axis {axis}: the Allan deviation is {unit:g} at every tau: no noise to measure",
                          field="data", fix="give a still log whose readings change")
    q, sd = _fit_terms(t, s / unit, c)

    def term(j: int) -> tuple[float, float]:  # value = sqrt(q_j); relative error = sd / (2 q)
        if not q[j] > 0:
            return float("nan"), float("nan")
        return math.sqrt(q[j]) * unit, float(sd[j] / (2 * q[j]))

    white, we = term(0)
    rw, re = term(2)
    k = int(np.argmin(s))
    return NoiseEstimate(white, we, rw, re, float(s[k] / FLICKER_FACTOR), _rel_err(c[k]), float(t[k]))
