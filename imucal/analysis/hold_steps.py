"""A step inside a still interval: the sensor knocked, or its bias jumping, while it was held still.

The interval's mean then lies between the two biases, which no model of the interval means fits (a step
between intervals, imucal.analysis.discover.changepoint, cannot either). Each hold's samples are scanned
for the cut that best splits them into two means (the sup of the two-mean chi-square, Andrews 1993); the
step is then judged beside a line in time (a drift through the hold is not a step) with the residual's
long-run variance (correlated noise and slow wander are not evidence), and its p is Siegmund's tail of the
sup of a squared Brownian bridge, family-wise over the holds. `imucal calibrate` warns of what it finds;
`imucal discover` cuts the hold there (StaticSettings.split) and names the step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imucal.data.static import Intervals

#: The family-wise level of the scan (discover's alpha_effect by default).
HOLD_ALPHA = 1e-3
#: A long hold is judged in windows of this many minimum durations (StaticSettings.min_duration): a
#: step against its neighbourhood, where a wandering bias (a random walk) moves little.
HOLD_WINDOW = 4
#: The shortest side of a cut inside an interval, as a fraction of its samples (the scan's t0).
HOLD_SIDE = 0.1
#: Fewest samples an interval needs to be scanned for a step inside it.
HOLD_MIN_SAMPLES = 20


@dataclass(frozen=True)
class HoldStep:
    """A still interval whose mean moved within it (a knock, a bias step during the hold)."""

    interval: int
    time: float  #: the first sample after the step [s]
    shift: np.ndarray  #: (3,) mean after minus mean before [raw]
    chi2: float  #: the scan's largest chi-square (3 dof at one cut)
    p: float  #: its p, family-wise over the intervals scanned


def sup_bridge_sf(c: float, dof: int, t0: float) -> float:
    """P(sup over t0 <= u <= 1 - t0 of a standardised squared Brownian bridge in ``dof`` dimensions > c):
    the largest two-mean chi-square over every cut of a series of white noise (Siegmund's approximation,
    as for Andrews' sup-Wald test; conservative for the discrete cuts of a finite series)."""
    if c <= dof:
        return 1.0
    head = math.exp((dof / 2) * math.log(c) - c / 2 - (dof / 2) * math.log(2.0) - math.lgamma(dof / 2))
    return min(1.0, head * ((1 - dof / c) * math.log((1 - t0) ** 2 / t0 ** 2) + 4 / c))


def _scan(x: np.ndarray, floor: float, inflation: float) -> tuple[int, float, np.ndarray]:
    """The cut k (samples before it), its chi-square and shift of the two-mean model of ``x`` (n, 3): each
    axis's mean difference over its standard error, the noise from the residual of the two means at that
    cut (floored by quantisation, times the recording's correlated-noise factor)."""
    n = x.shape[0]
    x = x - x.mean(axis=0)
    k = np.arange(1, n)[:, None]
    left = np.cumsum(x, axis=0)[:-1]  # sums before each cut; the total is 0
    d = -left / (n - k) - left / k  # mean after minus mean before
    between = d ** 2 * k * (n - k) / n
    resid = np.maximum((np.sum(x ** 2, axis=0) - between) / (n - 2), floor) * inflation
    q = np.sum(between / resid, axis=1)
    m = max(1, int(math.ceil(HOLD_SIDE * n)))
    j = m - 1 + int(np.argmax(q[m - 1:n - m]))
    return j + 1, float(q[j]), d[j]


#: Batches of the long-run variance of a scanned interval's residual (its noise at the scale of a mean).
HOLD_BATCHES = 8


def _abrupt(x: np.ndarray, t: np.ndarray, k: int, floor: float, inflation: float) -> tuple[float, np.ndarray]:
    """The chi-square of a step at cut ``k`` beside a line in time, per axis the step's coefficient over
    its standard error with the residual's long-run variance (batch means, at least its variance times the
    recording's pooled correlated-noise factor): slow wander and a drift through the hold are not a step,
    and correlated noise is not evidence."""
    n = x.shape[0]
    u = (t - t.mean()) / max(float(np.ptp(t)), 1e-12)
    A = np.column_stack([np.ones(n), u, (np.arange(n) >= k).astype(float)])
    coef, *_ = np.linalg.lstsq(A, x, rcond=None)
    e = x - A @ coef
    nb = n // HOLD_BATCHES
    bm = e[:nb * HOLD_BATCHES].reshape(HOLD_BATCHES, nb, -1).mean(axis=1)
    lrv = np.maximum(np.maximum(bm.var(axis=0, ddof=1) * nb, e.var(axis=0, ddof=3) * inflation), floor)
    c = float(np.linalg.inv(A.T @ A)[2, 2])
    return float(np.sum(coef[2] ** 2 / (c * lrv))), coef[2]


def _windows(n: int, span: int) -> list[tuple[int, int]]:
    """Rows [a, b) of a hold of ``n`` samples judged one at a time: the whole hold, or windows of ``span``
    samples every span / 2 (a long hold's bias may wander: a step is judged against its neighbourhood)."""
    if n <= span:
        return [(0, n)]
    starts = list(range(0, n - span, span // 2)) + [n - span]
    return [(a, a + span) for a in starts]


def hold_steps(t: np.ndarray, raw: np.ndarray, iv: Intervals, quantum: float, span: int,
               alpha: float = HOLD_ALPHA) -> list[HoldStep]:
    """The still intervals whose mean moved within them, at family-wise level ``alpha`` over the intervals
    and windows scanned (``span``: samples of a window; holds no longer are judged whole): a bias step during
    a hold leaves its interval's mean between the two biases, which no term of the interval means fits (the
    pipeline cuts it there: StaticSettings.split)."""
    span = max(int(span), HOLD_MIN_SAMPLES)
    parts = [(i, a, b) for i in range(iv.n) if iv.end[i] - iv.start[i] >= HOLD_MIN_SAMPLES
             for a, b in _windows(int(iv.end[i] - iv.start[i]), span)]
    floor = quantum ** 2 / 12
    best: dict[int, HoldStep] = {}
    for i, a, b in parts:
        lo, hi = int(iv.start[i]) + a, int(iv.start[i]) + b
        x = np.asarray(raw[lo:hi], float)
        k, _, _ = _scan(x, floor, iv.noise_inflation)
        c, shift = _abrupt(x, np.asarray(t[lo:hi], float), k, floor, iv.noise_inflation)
        p = min(1.0, sup_bridge_sf(c, x.shape[1], HOLD_SIDE) * len(parts))
        if p < alpha and (i not in best or c > best[i].chi2):
            best[i] = HoldStep(i, float(t[lo + k]), shift, c, p)
    return [best[i] for i in sorted(best)]


def hold_step_words(s: HoldStep, iv: Intervals, scale: np.ndarray, gravity: float) -> str:
    """One step in words: where, by how much (``scale``: raw per m/s^2 of each axis), its evidence, and
    what it looks like: a turn keeps |a| (the shift across the reading), a bias step changes it."""
    shift = s.shift / scale
    u = iv.mean[s.interval] / scale  # the reading's direction (offsets neglected: a few % of g)
    u = u / np.linalg.norm(u)
    radial = float(shift @ u)
    across = float(np.linalg.norm(shift - radial * u))
    mg = ", ".join(f"{v:+.3g}" for v in shift * 1e3 / gravity)
    cause = (f"a turn of {math.degrees(across / gravity):.2g} deg the detector did not see (|a| kept)"
             if across > 3 * abs(radial) else
             f"a knock or a bias step while still (|a| moved by {radial * 1e3 / gravity:+.3g} mg)"
             if abs(radial) > 3 * across else "a turn or a bias step while still")
    return (f"the still interval {s.interval} ({iv.t_start[s.interval]:.6g}-{iv.t_end[s.interval]:.6g} s) moved "
            f"within it at {s.time:.6g} s by x, y, z = {mg} mg (chi-square {s.chi2:.3g}, p = {s.p:.2g} over the "
            f"intervals): {cause}")
