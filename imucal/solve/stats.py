"""Statistics shared by the fit checks, discovery and the gyroscope tests."""
from __future__ import annotations

import math
import numpy as np


def median(x) -> float:
    """``float(np.median(x))``, bit for bit, without numpy.ma.

    np.median's NaN check imports numpy.ma on its first call: about 9 ms of CPU, a twentieth of
    `imucal calibrate`'s own start-up (python -X importtime). The same middle order statistics,
    by np.partition in the input's float type (the mean of the two middle values of an even
    count summed in that type, as np.mean does); NaN when any value is NaN or there is none.
    """
    a = np.asarray(x)
    a = (a if a.dtype.kind == "f" else a.astype(float)).ravel()
    n = a.size
    if n == 0 or np.isnan(a).any():
        return float("nan")
    k = n // 2
    if n % 2:
        return float(np.partition(a, k)[k])
    p = np.partition(a, (k - 1, k))
    return float((p[k - 1] + p[k]) / 2)


def chi2_sf(x: float, k: int) -> float:
    """P(chi-square(k) > x) for integer k >= 1, in closed form (log-space sums)."""
    if k < 1:
        raise ValueError("k must be >= 1")
    if not x > 0:
        return 1.0
    if not math.isfinite(x):
        return 0.0
    h = x / 2.0
    if k % 2 == 0:
        logs = [-h + j * math.log(h) - math.lgamma(j + 1) for j in range(k // 2)]
        head = 0.0
    else:
        logs = [-h + (j - 0.5) * math.log(h) - math.lgamma(j + 0.5) for j in range(1, (k - 1) // 2 + 1)]
        head = math.erfc(math.sqrt(h))
    if logs:
        m = max(logs)
        head += math.exp(m) * sum(math.exp(v - m) for v in logs)
    return min(1.0, head)


def power_chi2_1(lam: float, crit: float) -> float:
    """P(chi-square(1, non-centrality lam) > crit): the power of a 1-dof test whose statistic the
    effect shifts by lam (a coefficient lam standard errors squared from zero)."""
    s, m = math.sqrt(crit), math.sqrt(max(lam, 0.0))
    return 0.5 * math.erfc((s - m) / math.sqrt(2)) + 0.5 * math.erfc((s + m) / math.sqrt(2))


_ERFC = np.frompyfunc(math.erfc, 1, 1)


def chi2_sf_array(x: np.ndarray, k: int) -> np.ndarray:
    """``chi2_sf`` over an array (same closed form: erfc head for odd k plus the Poisson-type sum)."""
    if k < 1:
        raise ValueError("k must be >= 1")
    x = np.maximum(np.asarray(x, float), 0.0)
    h = x / 2.0
    with np.errstate(divide="ignore"):
        logh = np.log(h)
    if k % 2 == 0:
        head, terms = np.zeros_like(h), [(j, math.lgamma(j + 1)) for j in range(k // 2)]
    else:
        head = _ERFC(np.sqrt(h)).astype(float)
        terms = [(j - 0.5, math.lgamma(j + 0.5)) for j in range(1, (k - 1) // 2 + 1)]
    for power, lg in terms:  # exp(-h) h^power / Gamma(power + 1)
        with np.errstate(invalid="ignore"):
            head = head + np.where(h > 0, np.exp(-h + power * logh - lg), 1.0 if power == 0 else 0.0)
    return np.minimum(1.0, head)

def projected_chi2(r, var, X) -> float:
    """min over d of (r - X d)^T V^-1 (r - X d), V = diag(var) or ``var`` itself (n x n): the chi-square
    of residuals r against V with the columns of X (the fit's parameters) taken out, to first order:
    the weighted fit's own chi-square whatever weights gave r (imucal.solve.fit, weights="auto")."""
    r, V, X = np.asarray(r, float), np.asarray(var, float), np.asarray(X, float)
    if V.ndim == 1:
        w = 1.0 / np.sqrt(V)
        rw, Xw = r * w, X * w[:, None]
    else:
        L = np.linalg.cholesky(V)
        rw, Xw = np.linalg.solve(L, r), np.linalg.solve(L, X)
    c = np.linalg.norm(Xw, axis=0)
    U, sv, _ = np.linalg.svd(Xw / np.where(c > 0, c, 1.0), full_matrices=False)
    U = U[:, sv > sv.max(initial=0.0) * 1e-12]  # (directions the rows do not determine take nothing out)
    e = rw - U @ (U.T @ rw)
    return float(e @ e)


def between_excess(r, sigma, dof: int, X=None) -> float:
    """Paule-Mandel estimate of a common excess variance s^2 between rows: the s^2 >= 0 with
    sum r_k^2 / (sigma_k^2 + s^2) = dof (the random-effects moment equation that REML solves
    approximately; Paule & Mandel 1982, DerSimonian & Kacker 2007). 0 when the residuals are
    within their noise. With ``X`` (the fit's Jacobian), the left side is ``projected_chi2``: the
    weighted fit's own residuals at that s^2, whatever weights gave r (the iterated estimate)."""

    r2, s2 = np.asarray(r, float) ** 2, np.asarray(sigma, float) ** 2

    def chi2(extra: float) -> float:  # decreasing in the excess
        return float(np.sum(r2 / (s2 + extra))) if X is None else projected_chi2(r, s2 + extra, X)

    if dof < 1 or chi2(0.0) <= dof:
        return 0.0
    lo, hi = 0.0, float(np.sum(r2)) / dof
    while chi2(hi) > dof:  # bracket (guards against degenerate sigma)
        hi *= 2.0
    for _ in range(200):  # bisection on a monotone function: robust, 1e-15 relative
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2(mid) > dof else (lo, mid)
        if hi - lo <= 1e-15 * hi:
            break
    return 0.5 * (lo + hi)
