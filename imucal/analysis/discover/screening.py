"""The round's screen: every candidate's Gauss-Newton chi-square from the current fit, and the joint null
of those statistics (imucal.analysis.min_p), which is the round's multiple-testing correction.

Candidates not in the model enter with coefficient 0 (the current fit): the whitened Jacobian of the
residuals with respect to the base and every candidate coefficient gives each candidate's linearised
chi-square (the score, or Lagrange-multiplier, approximation), exact for a linear model. A new
warm-up's tau does not enter at amplitude 0, so the Jacobian is taken once per tau of the grid; a new
bias step's time is profiled the same way, once per gap between two still intervals (its column is
the shift's, zero before the step).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from imucal.analysis.discover.candidates import extra
from imucal.analysis.discover.problem import Effects, Problem, canonical
from imucal.analysis.discover.result import Candidate
from imucal.analysis.discover.settings import TAU_GRID
from imucal.analysis.min_p import MinPNull, min_p_null, search_gain
from imucal.model.effects import make_effect
from imucal.solve.fit import FitResult, jacobian_rows
from imucal.solve.stats import chi2_sf


@dataclass(frozen=True)
class Screen:
    """The whitened Jacobian at one set of shape values (``values``); ``varies``: the names profiled here."""

    J: np.ndarray
    values: dict[str, float]
    varies: frozenset[str]


def _grid(prob: Problem, model, have: set[str], tau_grid: Sequence[float]) -> list[tuple[dict, frozenset]]:
    """The shape values of each screen: the warm-ups' tau on ``tau_grid`` (fractions of the last interval's
    time) and each new given parameter (a step's time) on its effect's own grid; the others at a default."""
    t_end = float(np.max(prob.iv.t_mid)) if prob.iv.n else 1.0
    shapes = [n for e in model.effects for n in e.shape_names if n not in have]
    profiled = {e.name: e.profile_grid(prob.cov) for e in model.effects
                if e.given_names and not set(e.given_names) & have}
    default = {n: tau_grid[len(tau_grid) // 2] * t_end for n in shapes}
    for grid in profiled.values():
        if grid:
            default.update(grid[len(grid) // 2])
    out = [({**default, **{n: f * t_end for n in shapes}}, frozenset(shapes)) for f in tau_grid] if shapes else []
    for grid in profiled.values():
        out += [({**default, **g}, frozenset(g)) for g in grid]
    return out or [(default, frozenset())]


def screen(prob: Problem, current: FitResult, effects: Effects, names: Sequence[str],
           tau_grid: Sequence[float] = TAU_GRID) -> tuple[list[Screen], np.ndarray, dict[str, int], list[str]]:
    """Column-scaled Jacobians of the residuals w.r.t. base + every candidate coefficient, at the fit.

    Returns ([Screen] one per profiled value, r / sigma, column index by parameter name, current free names)."""
    every = {n: (0, 1, 2) for n in names}
    for n in effects:
        every[n] = (0, 1, 2)
    model, params = prob.parameters(canonical(every), current.values(), check=False)
    have = set(current.params.names)
    params = params.with_values({n: 0.0 for e in model.effects for n in e.coefficient_names if n not in have})
    w = 1.0 / current.sigma
    data = prob.data(model)
    screens = [Screen(jacobian_rows(data, params.with_values(g), model, prob.gravity) * w[:, None], g, v)
               for g, v in _grid(prob, model, have, tau_grid)]
    cols = {n: i for i, n in enumerate(params.free_names)}
    return screens, current.residuals * w, cols, list(current.free_names)


def own_screens(screens: Sequence[Screen], name: str, new: tuple[int, ...]) -> list[int]:
    """The screens a candidate is profiled over: those that vary its shape or given parameters (all of them
    for a new warm-up or step), or the first alone (every screen gives the others the same columns)."""
    e = make_effect(name, new)
    mine = set(e.shape_names) | set(e.given_names)
    ids = [i for i, s in enumerate(screens) if mine and mine & s.varies]
    return ids or [0]


def linear_chi2(Jw: np.ndarray, rw: np.ndarray, cols: list[int]) -> float:
    """min_x |rw + Jw[:, cols] x|^2: the Gauss-Newton chi-square (exact for a linear model)."""
    A = Jw[:, cols]
    x, *_ = np.linalg.lstsq(A, -rw, rcond=None)
    return float(np.sum((rw + A @ x) ** 2))


def screen_candidate(screens: list[Screen], rw: np.ndarray, base_cols: list[int], col: dict[str, int], name: str,
                     new: tuple[int, ...]) -> tuple[float, tuple[tuple[str, float], ...]]:
    """Gauss-Newton chi-square of one candidate, profiled over its screens, and the shape values it
    starts its full fit from."""
    eff = make_effect(name, new)
    cols = base_cols + [col[c] for c in eff.coefficient_names]
    named = (*eff.shape_names, *eff.given_names)
    best = None
    for i in own_screens(screens, name, new):
        s = screens[i]
        chi2 = linear_chi2(s.J, rw, cols)
        if best is None or chi2 < best[0]:
            best = (chi2, tuple((n, s.values[n]) for n in named if n in s.values))
    return best


def _priced(screened: list[Candidate], Js: list[np.ndarray], base_cols: list[int], family: list) -> list[Candidate]:
    """Each candidate searched over several screens priced at what its search gains on noise beyond its
    columns (``search_gain``), at least one parameter per shape or given value (as ``k`` counts them)."""
    searched = [i for i, (_, _, ids) in enumerate(family) if len(ids) > 1]
    if not searched:
        return screened
    gain = search_gain(Js, base_cols, [(family[i][0], family[i][2]) for i in searched])
    out = list(screened)
    for g, i in zip(gain, searched):
        c = out[i]
        out[i] = dataclasses.replace(c, priced=len(c.new_axes) + max(float(c.extra), g - len(c.new_axes)))
    return out


@dataclass(frozen=True)
class Scan:
    """A round's screen: every candidate's linearised chi-square, and the min-p null over them."""

    screened: list[Candidate]
    null: MinPNull
    p: float  #: family-wise p of the best screened candidate (linearised, unscaled)
    screens: list[np.ndarray]  #: whitened Jacobians, one per screened shape value (``screen``)
    rw: np.ndarray  #: whitened residual of the current fit
    col: dict[str, int]  #: column of each parameter in ``screens``
    base_cols: list[int]  #: columns of the current model's free parameters
    ids: list[list[int]]  #: the screens of each screened candidate (``own_screens``)
    values: list[dict[str, float]]  #: the shape values of each screen


def scan(prob: Problem, current: FitResult, effects: Effects, names: Sequence[str], cands: list) -> Scan:
    """Gauss-Newton chi-square of each candidate from the current fit, and the joint null of
    their statistics (``imucal.analysis.min_p``): the round's multiple-testing correction."""
    screens, rw, col, cur_free = screen(prob, current, effects, names)
    base_cols = [col[n] for n in cur_free]
    screened, family, ids = [], [], []
    for n, merged, new in cands:
        chi2, start = screen_candidate(screens, rw, base_cols, col, n, new)
        c = Candidate(n, merged, new, chi2_screen=chi2, extra=extra(n, effects), start=start)
        screened.append(c)
        ids.append(own_screens(screens, n, new))
        family.append(([col[x] for x in make_effect(n, new).coefficient_names], c.k, ids[-1]))
    Js = [s.J for s in screens]
    null = min_p_null(Js, base_cols, family)
    screened = _priced(screened, Js, base_cols, family)
    p_best = min((chi2_sf(max(0.0, current.chi2 - c.chi2_screen), c.k) for c in screened), default=1.0)
    return Scan(screened, null, null.adjust(p_best), Js, rw, col, base_cols, ids, [s.values for s in screens])
