"""The F distribution's upper tail (no scipy): the quasi-likelihood test when the misfit scale is estimated.

When the residual variance is estimated from the fit (chi2_c / dof_c > 1), the scaled
likelihood-ratio statistic LR / k = (delta chi2 / k) / (chi2_c / dof_c) follows F(k, dof_c), not
chi-square(k) / k: with tens of degrees of freedom the chi-square p-value is too small by orders
of magnitude.
"""
from __future__ import annotations

import math

_EPS, _TINY, _MAX_ITER = 1e-15, 1e-300, 500


def _betacf(a: float, b: float, x: float) -> float:
    """Continued fraction of the incomplete beta function (modified Lentz)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > _TINY else _TINY)
    h = d
    for m in range(1, _MAX_ITER + 1):
        m2 = 2 * m
        for aa in (m * (b - m) * x / ((qam + m2) * (a + m2)), -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))):
            d = 1.0 + aa * d
            d = 1.0 / (d if abs(d) > _TINY else _TINY)
            c = 1.0 + aa / c
            c = c if abs(c) > _TINY else _TINY
            h *= d * c
        if abs(d * c - 1.0) < _EPS:
            break
    return h


def betainc(a: float, b: float, x: float) -> float:
    """Regularised incomplete beta function I_x(a, b)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    lbt = math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(lbt) * _betacf(a, b, x) / a
    return 1.0 - math.exp(lbt) * _betacf(b, a, 1.0 - x) / b


def f_sf(x: float, d1: float, d2: float) -> float:
    """P(F > x) for F ~ F(d1, d2): I_{d2 / (d2 + d1 x)}(d2 / 2, d1 / 2)."""
    if not x > 0:
        return 1.0
    if math.isinf(x):
        return 0.0
    return betainc(d2 / 2.0, d1 / 2.0, d2 / (d2 + d1 * x))
