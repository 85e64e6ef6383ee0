"""After the forward rounds: replace a term by its simpler relative, drop coefficients the final model no
longer needs, and check that each term in time or temperature has the right shape."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.analysis.discover.problem import EFFECT_ORDER, Effects, Problem, canonical, label
from imucal.analysis.discover.settings import DiscoverSettings
from imucal.errors import ImucalError
from imucal.model.effects import EFFECTS, MIN_DOF, Term, make_effect
from imucal.solve.f_test import f_sf
from imucal.solve.fit import FitResult, jacobian_rows
from imucal.solve.stats import chi2_sf

#: Bins of the piecewise-constant alternative in the shape check (quantiles of the covariate).
SHAPE_BINS = 6


def prune(prob: Problem, current: FitResult, effects: Effects, found_names: set[str],
          settings: DiscoverSettings, notes: list[str]) -> tuple[FitResult, Effects]:
    """Backward step: drop a coefficient (effect, axis) added earlier that the final model no
    longer needs, i.e. whose removal costs less than ``penalty`` in scaled chi-square. A greedy
    forward search can pick an extra axis early that a later effect explains better."""
    while True:
        scale = max(1.0, current.redchi)
        trials = []
        for n in sorted(found_names & set(effects), key=EFFECT_ORDER.get):
            for a in effects[n]:
                reduced = dict(effects)
                rest = tuple(x for x in effects[n] if x != a)
                if rest:
                    reduced[n] = rest
                else:
                    del reduced[n]
                try:
                    res = prob.fit(canonical(reduced), current.values())
                except ImucalError:
                    continue
                e = make_effect(n, (0,))
                k = 1 + (0 if rest else len(e.shape_names) + len(e.given_names))
                trials.append(((res.chi2 - current.chi2) / scale / k, n, a, res, reduced))
        if not trials:
            return current, effects
        cost, n, a, res, reduced = min(trials, key=lambda t: t[0])
        if cost >= settings.penalty:
            return current, effects
        notes.append(f"dropped {n} on axis {EFFECTS[n].axis_names[a]} after the later effects: it removed only "
                     f"{max(cost, 0.0):.3g} of scaled chi-square (< {settings.penalty:.3g} per coefficient)")
        current, effects = res, reduced


def simplify(prob: Problem, current: FitResult, effects: Effects, found_names: set[str],
             settings: DiscoverSettings, notes: list[str]) -> tuple[FitResult, Effects, set[str]]:
    """Replace a term by its nested simpler relative (a warm-up by the drift it tends to) when the
    simpler one explains the data within ``penalty`` per parameter saved."""
    for n in sorted(found_names & set(effects), key=EFFECT_ORDER.get):
        simple = EFFECTS[n].simpler
        if simple is None or simple not in settings.candidates:
            continue
        reduced = {k: v for k, v in effects.items() if k != n}
        reduced[simple] = tuple(sorted(set(reduced.get(simple, ())) | set(effects[n])))
        try:
            res = prob.fit(canonical(reduced), current.values())
        except ImucalError:
            continue
        saved = len(current.free_names) - len(res.free_names)
        cost = (res.chi2 - current.chi2) / max(1.0, current.redchi)
        if saved > 0 and cost < settings.penalty * saved:
            notes.append(f"{label(n, effects[n])} replaced by the simpler {label(simple, reduced[simple])}: "
                         f"it explains the data within {max(cost, 0.0):.3g} of scaled chi-square")
            current, effects = res, reduced
            found_names = (found_names - {n}) | {simple}
    return current, effects, found_names


@dataclass(frozen=True)
class ShapeFailure:
    """A term whose covariate the residual follows in another shape (``shape_check``)."""

    name: str
    covariate: str  #: temp or time
    note: str


def shape_check(prob: Problem, current: FitResult, effects: Effects, found_names: set[str],
                settings: DiscoverSettings) -> dict[str, ShapeFailure]:
    """Is each term found in time or temperature the right *shape*? Its alternative is a
    piecewise-constant bias or scale in the same covariate on the same axes (``SHAPE_BINS``
    quantile bins), added to the final model in a Gauss-Newton step. When that removes
    significantly more (scaled LR, Bonferroni over the checks), the data follow the covariate in
    a way no term of the grammar describes (a step, say): the term is dropped and the verdict says
    so. Returns {effect name: failure} of the terms that fail."""
    terms = [n for n in sorted(found_names & set(effects), key=EFFECT_ORDER.get)
             if isinstance(make_effect(n, (0,)), Term)]
    if not terms:
        return {}
    model, params = prob.parameters(canonical(effects), current.values(), check=False)
    J = jacobian_rows(prob.data(model), params, model, prob.gravity) * (1.0 / current.sigma)[:, None]
    rw = current.residuals / current.sigma
    col = {n: i for i, n in enumerate(params.free_names)}
    base_cols = [col[n] for n in current.free_names]
    out: dict[str, ShapeFailure] = {}
    for n in terms:
        e = make_effect(n, effects[n])
        if any(e.base_parameter(a) not in col for a in e.axes):
            continue  # (the shift, scale or angle it modulates is held by the run file)
        x = np.asarray(prob.cov[e.basis.covariate], float)
        edges = np.quantile(x, np.linspace(0, 1, SHAPE_BINS + 1)[1:-1])
        ind = np.eye(SHAPE_BINS)[np.searchsorted(edges, x, side="right")]  # one-hot bin of each row
        extra = np.hstack([J[:, [col[e.base_parameter(a)]]] * ind for a in e.axes])
        A = np.hstack([J[:, base_cols], extra])
        sol, *_ = np.linalg.lstsq(A, -rw, rcond=None)
        chi2_bins = float(np.sum((rw + A @ sol) ** 2))
        k = (SHAPE_BINS - 1) * len(e.axes)  # one bin per axis is the shift or scale itself
        dof = current.dof - k
        if dof < MIN_DOF:
            continue
        scale = chi2_bins / dof
        lr = max(0.0, (current.chi2 - chi2_bins) / max(1.0, scale))
        p = (f_sf(lr / k, k, dof) if scale > 1 and chi2_sf(chi2_bins, dof) < settings.alpha_noise else chi2_sf(lr, k))
        if p * len(terms) < settings.alpha_effect:
            out[n] = ShapeFailure(n, e.basis.covariate, (
                f"{label(n, effects[n])} dropped: a piecewise-constant {e.target} in "
                f"{e.basis.covariate} ({SHAPE_BINS} bins) removes {current.chi2 - chi2_bins:.4g} more chi-square "
                f"(LR {lr:.3g} on {k} parameters, p adjusted {min(1.0, p * len(terms)):.2g}): not its shape"))
    return out
