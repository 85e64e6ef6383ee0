"""Monte-Carlo check of the gyro fit's standard errors against known truth.

Simulate hand-held sessions of one sensor (``simulate.hand_held``), fit each, and count how often
the truth lies within 1.96 reported standard errors of the estimate. With honest standard errors
that fraction is 95 %, within the binomial band of the number of estimates. The standard errors
are scaled by the residual scatter (reduced chi-square; the static fit's own), so the exact 95 %
bound is Student-t's with the fit's dof: static intervals minus 4 (bias and G_s row) or minus 1
(bias alone) for the static fit, the rotation fit's dof for scale and misalignment.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imucal.gyro.fit import GyroOptions, fit_gyro
from imucal.gyro.model import MIS_NAMES, misalignment_entries
from imucal.gyro.result import arrays, motions
from imucal.solve.fit import FitResult
from imucal.gyro.simulate import GyroTruth, hand_held
from imucal.report.text import t_quantile_975

#: two-sided 95 % normal quantile
Z95 = 1.959963984540054


def scores(res: FitResult, truth: GyroTruth) -> dict[str, np.ndarray]:
    """(estimate - truth) / reported standard error, per parameter, grouped (G_s: selected rows only)."""
    a = arrays(res)
    out = {"bias": (a.bias - truth.bias) / a.bias_std,
           "scale": (a.scale - truth.scale) / a.scale_std,
           "misalignment": (misalignment_entries(a.misalignment) - truth.mis)
           / misalignment_entries(a.misalignment_std)}
    rows = motions(res).gsens_selected
    out["gsens"] = ((a.gsens[rows] - truth.gsens[rows]) / a.gsens_std[rows]).ravel()
    return out


def names() -> dict[str, list[str]]:
    """Parameter names of each group of ``scores`` (G_s: all nine, row-major)."""
    return {"bias": [f"s_{a}" for a in "xyz"], "scale": [f"b_{a}" for a in "xyz"], "misalignment": list(MIS_NAMES),
            "gsens": [f"G_{a}{b}" for a in "xyz" for b in "xyz"]}


def binomial_band(n: int, p: float = 0.95, alpha: float = 0.05) -> tuple[float, float]:
    """Fractions (lo, hi) of n trials that a two-sided binomial test at level ``alpha`` accepts for ``p``."""
    pmf = [math.exp(math.lgamma(n + 1) - math.lgamma(k + 1) - math.lgamma(n - k + 1) + k * math.log(p)
                    + (n - k) * math.log1p(-p)) for k in range(n + 1)]
    lo, cum = 0, 0.0
    while cum + pmf[lo] <= alpha / 2:
        cum += pmf[lo]
        lo += 1
    hi, cum = n, 0.0
    while cum + pmf[hi] <= alpha / 2:
        cum += pmf[hi]
        hi -= 1
    return lo / n, hi / n


@dataclass(frozen=True)
class Coverage:
    """Standard scores of every seed (rows) per group, and what the fits said."""

    z: dict[str, np.ndarray]  #: group -> (seeds, parameters); G_s: NaN where a row was not selected
    t: dict[str, np.ndarray]  #: Student-t 97.5 % quantile of each estimate's dof, same shapes
    redchi: np.ndarray  #: (seeds,)
    converged: int
    gsens_rows_selected: np.ndarray  #: (3,) how many seeds kept each G_s row

    @staticmethod
    def merge(parts: list["Coverage"]) -> "Coverage":
        """One Coverage of several runs (seeds split over processes)."""
        return Coverage({g: np.concatenate([p.z[g] for p in parts]) for g in parts[0].z},
                        {g: np.concatenate([p.t[g] for p in parts]) for g in parts[0].t},
                        np.concatenate([p.redchi for p in parts]), sum(p.converged for p in parts),
                        np.sum([p.gsens_rows_selected for p in parts], axis=0))

    def fraction(self, group: str, student: bool = False) -> tuple[float, int]:
        """Fraction of |z| < 1.96 (``student``: < the Student-t quantile) over the group's estimates, and their number."""
        ok = np.isfinite(self.z[group])
        z, q = np.abs(self.z[group][ok]), (self.t[group][ok] if student else Z95)
        return float(np.mean(z < q)) if z.size else float("nan"), int(z.size)


def monte_carlo(truth: GyroTruth, seeds: range, options: GyroOptions = GyroOptions(), **session) -> Coverage:
    """Fit ``hand_held(truth, seed=s, **session)`` for every seed and collect standard scores."""
    z: dict[str, list[np.ndarray]] = {g: [] for g in names()}
    t: dict[str, list[np.ndarray]] = {g: [] for g in names()}
    red, conv, rows = [], 0, np.zeros(3, int)
    for s in seeds:
        data = hand_held(truth, seed=s, **session)
        res = fit_gyro(data, options)
        sc = scores(res, truth)
        for g in ("bias", "scale", "misalignment"):
            z[g].append(sc[g])
        G = np.full((3, 3), np.nan)
        selected = motions(res).gsens_selected
        G[selected] = sc["gsens"].reshape(-1, 3)
        z["gsens"].append(G.ravel())
        q_static = np.array([t_quantile_975(data.n_intervals - (4 if k else 1)) for k in selected])
        t["bias"].append(q_static)
        t["gsens"].append(np.repeat(q_static, 3))
        t["scale"].append(np.full(3, t_quantile_975(res.dof)))
        t["misalignment"].append(np.full(6, t_quantile_975(res.dof)))
        red.append(res.redchi)
        conv += res.success
        rows += selected
    return Coverage({g: np.array(v) for g, v in z.items()}, {g: np.array(v) for g, v in t.items()}, np.array(red),
                    conv, rows)
