"""Bias and g-sensitivity from the static intervals, selected per gyro axis by a likelihood-ratio test.

At rest omega = 0, so each static gyro mean is  s_g + H a_i  with H = B_g G_s [raw per m/s^2] and
a_i the calibrated gravity vector of interval i. Per axis, the bias-only model (1 parameter) is
tested against bias + H row (4 parameters): LR = n ln(RSS0 / RSS1) ~ chi2(3) under "no
g-sensitivity" (Gaussian scatter of unknown size, which also absorbs bias instability).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.solve.stats import chi2_sf

#: significance level of the per-axis test
ALPHA = 0.01


@dataclass(frozen=True)
class StaticFit:
    """Bias s_g [raw] and H = B_g G_s [raw per m/s^2] from the static means, with standard errors."""

    bias: np.ndarray  #: (3,)
    bias_std: np.ndarray  #: (3,)
    H: np.ndarray  #: (3, 3) zero rows where not selected
    H_std: np.ndarray  #: (3, 3)
    selected: np.ndarray  #: (3,) bool: g-sensitivity kept on this gyro axis
    lr: np.ndarray  #: (3,) likelihood-ratio statistic per axis
    p_value: np.ndarray  #: (3,)
    n_intervals: int


def fit_static(gyro_means: np.ndarray, acc_means: np.ndarray, gsens: str = "auto",
               alpha: float = ALPHA) -> StaticFit:
    """Fit bias (and g-sensitivity when ``gsens`` is "auto" and the test keeps it, or "on")."""
    n = gyro_means.shape[0]
    X0 = np.ones((n, 1))
    X1 = np.column_stack([np.ones(n), acc_means])
    bias, bias_std = np.zeros(3), np.zeros(3)
    H, H_std = np.zeros((3, 3)), np.zeros((3, 3))
    sel, lr, p = np.zeros(3, bool), np.zeros(3), np.ones(3)
    can = n >= 6 and np.linalg.matrix_rank(X1) == 4
    for j in range(3):
        y = gyro_means[:, j]
        c0, rss0 = _ols(X0, y)
        if can:
            c1, rss1 = _ols(X1, y)
            lr[j] = n * np.log(max(rss0, 1e-300) / max(rss1, 1e-300))
            p[j] = chi2_sf(float(lr[j]), 3)
        keep = can and (gsens == "on" or (gsens == "auto" and p[j] < alpha))
        if keep:
            cov = rss1 / (n - 4) * np.linalg.inv(X1.T @ X1)
            bias[j], H[j] = c1[0], c1[1:]
            bias_std[j], H_std[j] = np.sqrt(cov[0, 0]), np.sqrt(np.diag(cov)[1:])
            sel[j] = True
        else:
            bias[j] = c0[0]
            bias_std[j] = np.sqrt(rss0 / max(n - 1, 1) / n)
    return StaticFit(bias, bias_std, H, H_std, sel, lr, p, n)


def _ols(X: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    c, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ c
    return c, float(r @ r)
