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
from enum import Enum

import numpy as np

from imucal.data.static import Intervals

#: The family-wise level of the scan, calibrate's and discover's alike (discover --alpha leaves it).
HOLD_ALPHA = 1e-3
#: A long hold is judged in windows of this many minimum durations (StaticSettings.min_duration): a
#: step against its neighbourhood, where a wandering bias (a random walk) moves little.
HOLD_WINDOW = 4
#: The shortest side of a cut inside an interval, as a fraction of its samples (the scan's t0).
HOLD_SIDE = 0.1
#: Block means a window is judged on (fewer when it has fewer samples).
HOLD_BLOCKS = 64
#: Fewest samples an interval needs to be scanned for a step inside it.
HOLD_MIN_SAMPLES = 20


@dataclass(frozen=True)
class HoldStep:
    """A still interval whose mean moved within it (a knock, a bias step during the hold)."""

    interval: int
    time: float  #: the first sample after the step [s]
    shift: np.ndarray  #: (3,) mean after minus mean before [raw]
    chi2: float  #: the step's chi-square beside a line in time (3 dof, at the best cut)
    p: float  #: its p, family-wise over the intervals and windows scanned


def sup_bridge_sf(c: float, dof: int, t0: float) -> float:
    """P(sup over t0 <= u <= 1 - t0 of a standardised squared Brownian bridge in ``dof`` dimensions > c):
    the largest two-mean chi-square over every cut of a series of white noise (Siegmund's approximation,
    as for Andrews' sup-Wald test; conservative for the discrete cuts of a finite series)."""
    if c <= dof:
        return 1.0
    head = math.exp((dof / 2) * math.log(c) - c / 2 - (dof / 2) * math.log(2.0) - math.lgamma(dof / 2))
    return min(1.0, head * ((1 - dof / c) * math.log((1 - t0) ** 2 / t0 ** 2) + 4 / c))


#: Batches of the long-run variance of a scanned interval's residual (its noise at the scale of a mean).
HOLD_BATCHES = 8


def _judge(x: np.ndarray, t: np.ndarray, floor: float, inflation: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each of W windows of n samples (``x``: (W, n, 3), ``t``: (W, n)): the cut k (samples before it) that
    best splits it into two means, and the chi-square and shift (W, 3) of a step there beside a line in time.

    The cut: each axis's mean difference over its standard error, the noise from the residual of the two
    means (floored by quantisation, times the recording's correlated-noise factor). The step's chi-square:
    per axis its coefficient beside the line over its standard error with the residual's long-run variance
    (batch means, at least its variance times that factor): slow wander and a drift through the hold are
    not a step, and correlated noise is not evidence."""
    w, n, _ = x.shape
    x = x - x.mean(axis=1, keepdims=True)
    ks = np.arange(1, n)[None, :, None]
    left = np.cumsum(x, axis=1)[:, :-1]  # sums before each cut; the total is 0
    d = -left / (n - ks) - left / ks  # mean after minus mean before
    between = d ** 2 * ks * (n - ks) / n
    resid = np.maximum((np.sum(x ** 2, axis=1, keepdims=True) - between) / (n - 2), floor) * inflation
    m = max(1, int(math.ceil(HOLD_SIDE * n)))
    k = m + np.argmax(np.sum(between / resid, axis=2)[:, m - 1:n - m], axis=1)
    u = t - t.mean(axis=1, keepdims=True)
    u = u / np.maximum(np.ptp(t, axis=1, keepdims=True), 1e-12)
    h = (np.arange(n)[None, :] >= k[:, None]).astype(float)
    cols = np.stack([np.ones_like(u), u, h], axis=2)  # (W, n, 3): 1, t, the step
    colt = cols.transpose(0, 2, 1)
    gram = colt @ cols
    coef = np.linalg.solve(gram, colt @ x)  # (W, 3 columns, 3 axes)
    e = x - cols @ coef
    nb = n // HOLD_BATCHES
    bm = e[:, :nb * HOLD_BATCHES].reshape(w, HOLD_BATCHES, nb, 3).mean(axis=2)
    lrv = np.maximum(np.maximum(bm.var(axis=1, ddof=1) * nb, np.sum(e ** 2, axis=1) / (n - 3) * inflation), floor)
    c = np.linalg.inv(gram)[:, 2, 2]
    return k, np.sum(coef[:, 2] ** 2 / (c[:, None] * lrv), axis=1), coef[:, 2]


def _windows(n: int, span: int) -> list[tuple[int, int]]:
    """Rows [a, b) of a hold of ``n`` rows judged one at a time: the whole hold, or windows of ``span``
    rows every span / 2 (a long hold's bias may wander: a step is judged against its neighbourhood)."""
    if n <= span:
        return [(0, n)]
    starts = list(range(0, n - span, span // 2)) + [n - span]
    return [(a, a + span) for a in starts]


def _block_means(raw: np.ndarray, iv: Intervals, sizes: dict[int, int]) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """{interval: (means of its consecutive blocks of sizes[interval] samples (the last few left out), the
    first sample of each)}, in one pass over the samples: a step moves a block mean as it moves the samples."""
    firsts, keep = [], []
    for i, size in sizes.items():
        lo, m = int(iv.start[i]), int(iv.end[i] - iv.start[i]) // size
        firsts.append(lo + size * np.arange(m + 1))  # (the block after the last one only ends it)
        keep.append(np.arange(m))
    if not firsts:
        return {}
    idx = np.concatenate(firsts)
    ends = idx < raw.shape[0]
    sums = np.add.reduceat(np.asarray(raw, float), idx[ends], axis=0)
    out, at = {}, 0
    for (i, size), f in zip(sizes.items(), firsts):
        out[i] = (sums[at:at + f.size - 1] / size, f[:-1])
        at += f.size if ends[at + f.size - 1] else f.size - 1
    return out


def hold_steps(t: np.ndarray, raw: np.ndarray, iv: Intervals, quantum: float, span: int,
               alpha: float = HOLD_ALPHA) -> list[HoldStep]:
    """The still intervals whose mean moved within them, at family-wise level ``alpha`` over the intervals
    and windows scanned (``span``: samples of a window; holds no longer are judged whole): a bias step during
    a hold leaves its interval's mean between the two biases, which no term of the interval means fits (the
    pipeline cuts it there: StaticSettings.split). Judged on means of blocks of samples, HOLD_BLOCKS to a
    window: the same evidence of a step at a fraction of the work."""
    span = max(int(span), HOLD_MIN_SAMPLES)
    n = iv.end - iv.start
    sizes = {i: max(1, min(int(n[i]), span) // HOLD_BLOCKS) for i in range(iv.n) if n[i] >= HOLD_MIN_SAMPLES}
    parts = []  # (interval, block means, their times, block size)
    for i, (x, first) in _block_means(raw, iv, sizes).items():
        tb = np.asarray(t[first], float)
        parts += [(i, x[a:b], tb[a:b], sizes[i]) for a, b in _windows(x.shape[0], max(span // sizes[i], 1))]
    best: dict[int, HoldStep] = {}
    for n in sorted({len(p[1]) for p in parts}):  # windows of one length judged together
        group = [p for p in parts if len(p[1]) == n]
        for size in sorted({p[3] for p in group}):
            same = [p for p in group if p[3] == size]
            k, chi2, shift = _judge(np.stack([p[1] for p in same]), np.stack([p[2] for p in same]),
                                    quantum ** 2 / 12 / size, iv.noise_inflation)
            for (i, _, tb, _), kk, c, sh in zip(same, k, chi2, shift):
                p = min(1.0, sup_bridge_sf(float(c), 3, HOLD_SIDE) * len(parts))
                if p < alpha and (i not in best or c > best[i].chi2):
                    best[i] = HoldStep(i, float(tb[kk]), sh, float(c), p)
    return [best[i] for i in sorted(best)]


class Kind(str, Enum):
    """What a hold's step looks like from the reading's direction."""

    TURN = "turn"  #: the shift lies across the reading: |a| kept (a turn the detector did not see)
    BIAS_STEP = "bias_step"  #: the shift lies along the reading: |a| changed (a knock, a bias step)
    EITHER = "turn_or_bias_step"  #: neither dominates (3x)


@dataclass(frozen=True)
class Reading:
    """A hold's step in the calibrated units: its shift [mg], the part along gravity [mg] and the angle across it."""

    kind: Kind
    shift_mg: tuple[float, float, float]
    along_mg: float  #: the change of |a|
    turn_deg: float  #: the angle of the part across the reading

    def to_json(self) -> dict:
        return {"kind": self.kind.value, "shift_mg": list(self.shift_mg), "along_mg": self.along_mg,
                "turn_deg": self.turn_deg}


def reading(s: HoldStep, iv: Intervals, scale: np.ndarray, gravity: float) -> Reading:
    """What ``s`` looks like (``scale``: raw per m/s^2 of each axis): a turn keeps |a| (the shift across the
    reading), a bias step changes it (the shift along it)."""
    shift = s.shift / scale
    u = iv.mean[s.interval] / scale  # the reading's direction (offsets neglected: a few % of g)
    u = u / np.linalg.norm(u)
    along = float(shift @ u)
    across = float(np.linalg.norm(shift - along * u))
    kind = Kind.TURN if across > 3 * abs(along) else Kind.BIAS_STEP if abs(along) > 3 * across else Kind.EITHER
    mg = shift * 1e3 / gravity
    return Reading(kind, (float(mg[0]), float(mg[1]), float(mg[2])), along * 1e3 / gravity,
                   math.degrees(across / gravity))


@dataclass(frozen=True)
class Cut:
    """A hold cut where its mean moved (imucal discover): the step, what it looks like, the hold's span [s]."""

    step: HoldStep
    reading: Reading
    t_start: float
    t_end: float

    def to_json(self) -> dict:
        s = self.step
        return {"interval": s.interval, "t_start_s": self.t_start, "t_end_s": self.t_end, "time_s": s.time,
                "chi2": s.chi2, "p": s.p, **self.reading.to_json()}


def hold_step_words(s: HoldStep, iv: Intervals, scale: np.ndarray, gravity: float) -> str:
    """One step in words: where, by how much, its evidence, and what it looks like (``reading``)."""
    r = reading(s, iv, scale, gravity)
    cause = {Kind.TURN: f"a turn of {r.turn_deg:.2g} deg the detector did not see (|a| kept)",
             Kind.BIAS_STEP: f"a knock or a bias step while still (|a| moved by {r.along_mg:+.3g} mg)",
             Kind.EITHER: "a turn or a bias step while still"}[r.kind]
    mg = ", ".join(f"{v:+.3g}" for v in r.shift_mg)
    return (f"the still interval {s.interval} ({iv.t_start[s.interval]:.6g}-{iv.t_end[s.interval]:.6g} s) moved "
            f"within it at {s.time:.6g} s by x, y, z = {mg} mg (chi-square {s.chi2:.3g}, p = {s.p:.2g} over the "
            f"intervals): {cause}")
