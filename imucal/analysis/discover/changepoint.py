"""Where a bias step is: its time and the change points the data cannot tell from it.

A step's time t_s is not fitted (the data hold no gradient in it between two still intervals): the
screen profiles it over the gaps between consecutive intervals and the full fit holds the best one.
Its uncertainty has two parts: within a gap the data cannot place it at all (the sensor moved), and
other gaps may fit nearly as well. The profile chi-square of each gap is the final model's, refitted
by a Gauss-Newton step with the step moved there; the gaps within chi-square(1) at 95 % (scaled by the
misfit) of the best form the confidence set (Hinkley 1970: the likelihood-ratio set of a change point).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imucal.analysis.discover.problem import Effects, Problem, canonical
from imucal.model.effects import make_effect
from imucal.solve.fit import FitResult, jacobian_rows

#: chi-square(1) at 95 %: the profile likelihood's confidence set of the change point.
CHI2_1_95 = 3.841


@dataclass(frozen=True)
class ChangePoint:
    """A step's time [s from the recording's start] and what the data can say of it."""

    time: float  #: the time the calibration holds (the middle of its gap)
    gap: tuple[float, float]  #: the still intervals on either side of it end and start here [s]
    lower: float  #: the earliest and latest time of the 95 % confidence set of gaps [s]
    upper: float
    gaps: int  #: gaps in the confidence set
    tried: int  #: gaps profiled

    def to_json(self) -> dict:
        return {"time_s": self.time, "gap_s": list(self.gap), "lower_s": self.lower, "upper_s": self.upper,
                "gaps_in_set": self.gaps, "gaps_tried": self.tried}


def _gap(prob: Problem, t: float) -> tuple[float, float]:
    """The end of the last still interval before ``t`` and the start of the first after it [s]."""
    iv = prob.iv
    before, after = iv.t_mid < t, iv.t_mid >= t
    return (float(np.max(iv.t_end[before])) if before.any() else float(np.min(iv.t_start)),
            float(np.min(iv.t_start[after])) if after.any() else float(np.max(iv.t_end)))


def _profile(prob: Problem, res: FitResult, effects: Effects, name: str) -> tuple[list[float], np.ndarray]:
    """The step's candidate times and the linearised chi-square of the final model at each."""
    e = make_effect(name, effects[name])
    (tname,) = e.given_names
    grid = [g[tname] for g in e.profile_grid(prob.cov)]
    model, params = prob.parameters(canonical(effects), res.values(), check=False)
    params = params.with_values({tname: res.params[tname].value})
    data = prob.data(model)
    w = 1.0 / res.sigma
    out = []
    for t in grid:
        at = params.with_values({tname: t})
        r = jacobian_rows(data, at, model, prob.gravity, residuals=True) * w
        A = jacobian_rows(data, at, model, prob.gravity) * w[:, None]
        x, *_ = np.linalg.lstsq(A, -r, rcond=None)
        out.append(float(np.sum((r + A @ x) ** 2)))
    return grid, np.array(out)


def change_point(prob: Problem, res: FitResult, effects: Effects, name: str) -> ChangePoint:
    """The step of ``name`` in the final fit ``res``: its time, its gap and the 95 % set of gaps."""
    t = float(res.params[make_effect(name, effects[name]).given_names[0]].value)
    grid, chi2 = _profile(prob, res, effects, name)
    if not grid:
        return ChangePoint(t, _gap(prob, t), t, t, 1, 0)
    near = chi2 - chi2.min() <= CHI2_1_95 * max(1.0, res.redchi)
    inside = [g for g, ok in zip(grid, near) if ok] or [t]
    lo, hi = _gap(prob, min(inside)), _gap(prob, max(inside))
    return ChangePoint(t, _gap(prob, t), min(lo[0], t), max(hi[1], t), len(inside), len(grid))


# --- a step inside a still interval -------------------------------------------------------------
#: The shortest side of a cut inside an interval, as a fraction of its samples (the scan's t0).
INNER_SIDE = 0.1
#: Fewest samples an interval needs to be scanned for a step inside it.
INNER_MIN_SAMPLES = 20


@dataclass(frozen=True)
class InnerStep:
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
    m = max(1, int(math.ceil(INNER_SIDE * n)))
    j = m - 1 + int(np.argmax(q[m - 1:n - m]))
    return j + 1, float(q[j]), d[j]


#: Batches of the long-run variance of a scanned interval's residual (its noise at the scale of a mean).
INNER_BATCHES = 8


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
    nb = n // INNER_BATCHES
    bm = e[:nb * INNER_BATCHES].reshape(INNER_BATCHES, nb, -1).mean(axis=1)
    lrv = np.maximum(np.maximum(bm.var(axis=0, ddof=1) * nb, e.var(axis=0, ddof=3) * inflation), floor)
    c = float(np.linalg.inv(A.T @ A)[2, 2])
    return float(np.sum(coef[2] ** 2 / (c * lrv))), coef[2]


def inner_steps(t: np.ndarray, raw: np.ndarray, iv, quantum: float, alpha: float) -> list[InnerStep]:
    """The still intervals whose mean moved within them, at family-wise level ``alpha`` over the intervals
    scanned: a bias step during a hold leaves its interval's mean between the two biases, which no term
    of the interval means fits (the pipeline cuts it there: StaticSettings.split)."""
    scanned = [i for i in range(iv.n) if iv.end[i] - iv.start[i] >= INNER_MIN_SAMPLES]
    floor = quantum ** 2 / 12
    out = []
    for i in scanned:
        x = np.asarray(raw[iv.start[i]:iv.end[i]], float)
        k, _, _ = _scan(x, floor, iv.noise_inflation)
        c, shift = _abrupt(x, np.asarray(t[iv.start[i]:iv.end[i]], float), k, floor, iv.noise_inflation)
        p = min(1.0, sup_bridge_sf(c, x.shape[1], INNER_SIDE) * len(scanned))
        if p < alpha:
            out.append(InnerStep(i, float(t[iv.start[i] + k]), shift, c, p))
    return out
