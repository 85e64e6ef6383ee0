"""Where a bias step is: its time and the change points the data cannot tell from it.

A step's time t_s is not fitted (the data hold no gradient in it between two still intervals): the
screen profiles it over the gaps between consecutive intervals and the full fit holds the best one.
Its uncertainty has two parts: within a gap the data cannot place it at all (the sensor moved), and
other gaps may fit nearly as well. The profile chi-square of each gap is the final model's, refitted
by a Gauss-Newton step with the step moved there; the gaps within chi-square(1) at 95 % (scaled by the
misfit) of the best form the confidence set (Hinkley 1970: the likelihood-ratio set of a change point).
A step in the first or last samples of a hold, which the scan of imucal.analysis.hold_steps does not cut,
looks like one in the gap beside them: the set reaches into those edges.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.analysis.discover.problem import Effects, Problem, canonical
from imucal.analysis.hold_steps import HOLD_SIDE
from imucal.model.effects import make_effect
from imucal.solve.fit import FitResult, jacobian_rows

#: chi-square(1) at 95 %: the profile likelihood's confidence set of the change point.
CHI2_1_95 = 3.841


@dataclass(frozen=True)
class ChangePoint:
    """A step's time [s from the recording's start] and what the data can say of it."""

    time: float  #: the time the calibration holds (the middle of its gap)
    gap: tuple[float, float]  #: the still intervals on either side of it end and start here [s]
    #: the earliest and latest time of the 95 % confidence set of gaps [s], each gap widened into the edges of
    #: its intervals that the scan for a step inside a hold leaves (imucal.analysis.hold_steps.HOLD_SIDE)
    lower: float
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


def _reach(prob: Problem, t: float) -> tuple[float, float]:
    """The gap of ``t`` widened into the edges of its two intervals that the scan for a step inside a hold
    does not cut (imucal.analysis.hold_steps.HOLD_SIDE of each): a step there looks like one in the gap."""
    iv = prob.iv
    before, after = iv.t_mid < t, iv.t_mid >= t
    lo, hi = _gap(prob, t)
    if before.any():
        k = int(np.flatnonzero(before)[-1])
        lo -= HOLD_SIDE * float(iv.t_end[k] - iv.t_start[k])
    if after.any():
        k = int(np.flatnonzero(after)[0])
        hi += HOLD_SIDE * float(iv.t_end[k] - iv.t_start[k])
    return lo, hi


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
    lo, hi = _reach(prob, min(inside)), _reach(prob, max(inside))
    return ChangePoint(t, _gap(prob, t), min(lo[0], t), max(hi[1], t), len(inside), len(grid))

