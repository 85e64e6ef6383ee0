"""The orders of bias(T) and scale(T) per axis, chosen by the data with the grammar's own test.

The grammar (imucal.model.effects) writes a temperature polynomial as nested orthogonal terms,
bias_temperature, bias_temperature2, bias_temperature3 (and scale_...), so adding an order leaves
the lower coefficients what they were. The selection is discovery's forward test
(imucal.analysis.discover) on the pose-constancy fit (imucal.thermal.fit):

1. candidates: on each axis and target (bias, scale), the next order (1, then 2, then 3); one
   the poses do not determine (its standard error, scaled by the misfit, above the term's
   generous magnitude: imucal.thermal.determine) is not tried, and said so;
2. each is screened by a Gauss-Newton step from the current fit; the best is fitted in full;
3. it is kept when its likelihood-ratio statistic LR = (chi2 - chi2_c) / max(1, chi2_c / dof_c)
   has a family-wise p (Bonferroni over the round's candidates) below ``alpha``: F(1, dof_c)
   when the misfit exceeds the noise (it does on real sensors), chi-square(1) when it does not;
4. repeat until no candidate is significant.

Rows weigh temperature, not time (imucal.thermal.evidence), so a slow drift at one temperature
does not pass for curvature in temperature.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from imucal.model.effects import AXIS_NAMES, EFFECTS, fit_to_data, make_effect
from imucal.model.channels import covariate_matrix
from imucal.model.parameters import BASE_NAMES, Parameters
from imucal.model.sensor import build_model
from imucal.solve.f_test import f_sf
from imucal.solve.fit import unscaled_covariance
from imucal.solve.stats import chi2_sf
from imucal.thermal.evidence import ThermalRows
from imucal.thermal.fit import ThermalFit, accel_rows, fit_rows

#: The grammar's temperature bases by order, and the targets they act on.
BASES = {1: "temperature", 2: "temperature2", 3: "temperature3"}
TARGETS = ("bias", "scale")
MAX_ORDER = 3
#: The grammar's temperature terms: what a sweep's selection can name.
TEMPERATURE_TERMS = tuple(f"{t}_{b}" for t in TARGETS for b in BASES.values())
#: Family-wise level for adding a term (discover's default, imucal.analysis.discover.DiscoverSettings).
ALPHA = 1e-3

Effects = dict[str, tuple[int, ...]]


def term_name(target: str, order: int) -> str:
    return f"{target}_{BASES[order]}"


def orders(effects: Effects) -> dict[tuple[str, int], int]:
    """(target, axis) -> highest temperature order held."""
    out: dict[tuple[str, int], int] = {}
    for name, axes in effects.items():
        target, basis = name.split("_", 1)
        order = next((k for k, b in BASES.items() if b == basis), 0)
        for a in axes:
            out[(target, a)] = max(out.get((target, a), 0), order)
    return out


def label(name: str, axis: int) -> str:
    return f"{name}[{AXIS_NAMES[axis]}]"


@dataclass(frozen=True)
class Trial:
    """One candidate of one round."""

    name: str
    axis: int
    chi2_screen: float  #: linearised chi-square with the candidate
    std: float  #: its coefficient's standard error, scaled by the misfit [its unit]
    typical: float  #: the grammar's generous magnitude of the coefficient (its scale)
    chi2: float = float("nan")  #: of the full fit (nan when only screened)
    dof: int = 0
    lr: float = float("nan")
    p_adjusted: float = float("nan")
    significant: bool = False

    @property
    def label(self) -> str:
        return label(self.name, self.axis)

    @property
    def determined(self) -> bool:
        return self.std <= self.typical


@dataclass(frozen=True)
class Round:
    index: int
    chi2_before: float
    dof_before: int
    trials: tuple[Trial, ...]
    chosen: Trial | None


@dataclass(frozen=True)
class Selection:
    """The terms the data asked for, the rounds that chose them, and the fits before and after."""

    effects: Effects
    rounds: tuple[Round, ...]
    fit: ThermalFit
    none: ThermalFit  #: the fit with no temperature term (each pose's mean)
    model_effects: tuple = field(default=(), repr=False)

    @property
    def undetermined(self) -> tuple[Trial, ...]:
        """Candidates the poses could not determine (the last round that saw each)."""
        seen: dict[str, Trial] = {}
        for r in self.rounds:
            for t in r.trials:
                if not t.determined:
                    seen[t.label] = t
        return tuple(seen.values())


class ThermalProblem:
    """The fixed parts of a selection: rows, the base parameters, and the fits it makes."""

    def __init__(self, rows: ThermalRows, base: Parameters, source: str | None = None,
                 step: Callable[[], None] | None = None) -> None:
        self.rows, self.source, self.step = rows, source, step or (lambda: None)
        self.base = Parameters(base[n] for n in BASE_NAMES).with_fixed(BASE_NAMES)
        self.covariates = {"temp": rows.temp, "time": rows.t}

    def model(self, effects: Effects):
        order = {n: i for i, n in enumerate(EFFECTS)}
        return build_model([make_effect(n, ax) for n, ax in sorted(effects.items(), key=lambda kv: order[kv[0]])])

    def parameters(self, effects: Effects, start: dict[str, float] | None = None):
        model = self.model(effects)
        params = fit_to_data(model.effects, model.parameters(self.base), self.covariates)
        keep = {n: v for n, v in (start or {}).items() if n in params.names and not params[n].fixed}
        return model, params.with_values(keep)

    def cov(self, model) -> np.ndarray:
        return covariate_matrix(model.covariates, self.covariates, self.rows.n)

    def fit(self, effects: Effects, start: dict[str, float] | None = None) -> ThermalFit:
        model, params = self.parameters(effects, start)
        res = fit_rows(model, params, self.rows, self.cov(model), self.source)
        self.step()
        return res


def _screen(prob: ThermalProblem, current: ThermalFit, effects: Effects
            ) -> tuple[np.ndarray, np.ndarray, dict[str, int], int]:
    """r and J (weighted by 1/sigma) at the current fit, over every temperature term of every axis
    (coefficients not in the model at 0) and the pose vectors; the column of each coefficient."""
    every = {term_name(t, k): (0, 1, 2) for t in TARGETS for k in BASES}
    model, params = prob.parameters(every, current.params.value_dict())
    have = set(current.free_names)
    params = params.with_values({n: 0.0 for n in params.free_names if n not in have})
    free = params.free_names
    a, J = accel_rows(model, free)(prob.rows.raw.T, prob.cov(model).T, [params[n].value for n in free],
                                   params.values())
    n, nc = prob.rows.n, len(free)
    index = np.searchsorted(current.poses, prob.rows.pose)
    r = (a.T - current.vectors[index]).ravel()
    Jf = np.zeros((3 * n, nc + 3 * current.poses.size))
    Jf[:, :nc] = J.reshape(nc, 3, n).transpose(2, 1, 0).reshape(3 * n, nc) * np.array([params[c].scale for c in free])
    cols = nc + 3 * index[:, None] + np.arange(3)
    Jf[np.arange(3 * n), cols.ravel()] = -1.0
    return r / current.sigma, Jf / current.sigma, {c: i for i, c in enumerate(free)}, nc


def _trial(rw: np.ndarray, Jw: np.ndarray, cols: list[int], c: int, name: str, axis: int, scale: float,
           typical: float) -> Trial:
    """The linearised chi-square with column ``c`` added to ``cols``, and its coefficient's scaled error."""
    A = Jw[:, cols + [c]]
    sol, *_ = np.linalg.lstsq(A, -rw, rcond=None)
    chi2 = float(np.sum((rw + A @ sol) ** 2))
    dof = A.shape[0] - A.shape[1]
    cov = unscaled_covariance(np.linalg.qr(A, mode="r"))
    std = float(np.sqrt(max(cov[-1, -1], 0.0)) * np.sqrt(max(1.0, chi2 / dof))) * scale
    return Trial(name, axis, chi2, std, typical)


def _round(prob: ThermalProblem, current: ThermalFit, effects: Effects, index: int, alpha: float
           ) -> tuple[Round, ThermalFit | None, Effects]:
    rw, Jw, col, nc = _screen(prob, current, effects)
    v_cols = list(range(nc, Jw.shape[1]))
    base_cols = [col[n] for n in current.free_names] + v_cols
    _, every = prob.parameters({term_name(t, k): (0, 1, 2) for t in TARGETS for k in BASES})
    have = orders(effects)
    trials = []
    for target in TARGETS:
        for axis in range(3):
            order = have.get((target, axis), 0)
            if order >= MAX_ORDER:
                continue
            name = term_name(target, order + 1)
            c = make_effect(name, (axis,)).coefficient(axis)
            trials.append(_trial(rw, Jw, base_cols, col[c], name, axis, every[c].scale, every[c].scale))
    tried = [t for t in trials if t.determined]
    chosen, fitted, new = None, None, effects
    if tried:
        best = min(tried, key=lambda t: t.chi2_screen)
        new = {**effects, best.name: tuple(sorted(set(effects.get(best.name, ())) | {best.axis}))}
        fitted = prob.fit(new, current.params.value_dict())
        scale = max(1.0, fitted.redchi)
        lr = max(0.0, (current.chi2 - fitted.chi2) / scale)
        misfit = current.redchi > 1.0 and chi2_sf(current.chi2, current.dof) < alpha
        p = f_sf(lr, 1, fitted.dof) if misfit else chi2_sf(lr, 1)
        p_adj = min(1.0, p * len(tried))
        full = Trial(best.name, best.axis, best.chi2_screen, best.std, best.typical, fitted.chi2, fitted.dof, lr,
                     p_adj, p_adj < alpha)
        trials = [full if t is best else t for t in trials]
        chosen = full if full.significant else None
    rnd = Round(index, current.chi2, current.dof, tuple(trials), chosen)
    return rnd, (fitted if chosen is not None else None), (new if chosen is not None else effects)


def select(prob: ThermalProblem, alpha: float = ALPHA, max_terms: int = 2 * 3 * MAX_ORDER) -> Selection:
    """Forward selection of the temperature terms (module docstring)."""
    none = prob.fit({})
    current, effects, rounds = none, {}, []
    while len(rounds) < max_terms:
        rnd, fitted, effects = _round(prob, current, effects, len(rounds) + 1, alpha)
        rounds.append(rnd)
        if fitted is None:
            break
        current = fitted
    return Selection(effects=effects, rounds=tuple(rounds), fit=current, none=none)
