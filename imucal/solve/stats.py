"""Statistics shared by the fit checks, discovery and the gyroscope tests."""
from __future__ import annotations

import math


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
