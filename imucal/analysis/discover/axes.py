"""Which axes a found term may have that the poses cannot rule out, and where to look for them."""
from __future__ import annotations

import numpy as np

from imucal.analysis.discover.problem import Effects, Problem, canonical, label
from imucal.analysis.discover.settings import RESOLVED_POWER
from imucal.model.effects import AXIS_NAMES, EFFECTS, Term, make_effect
from imucal.pipeline import CalibrationRun
from imucal.solve.fit import FitResult, jacobian_rows
from imucal.solve.stats import power_chi2_1


def observable_sum(name: str, axes: tuple[int, ...], res: FitResult) -> tuple[float, float]:
    """The sum of a term's coefficients over its axes and its standard error (the covariance's 1^T C 1):
    what |a| sees of a cross-axis term to first order."""
    names = make_effect(name, axes).coefficient_names
    value = sum(res.params[c].value for c in names)
    idx = [res.free_names.index(c) for c in names if c in res.free_names]
    var = float(np.sum(res.covariance[np.ix_(idx, idx)])) if idx else float("nan")
    return value, float(np.sqrt(max(var, 0.0)))


def axis_notes(effects: Effects, found: set[str], final: CalibrationRun, notes: list[str]) -> None:
    """Effects whose axes static poses tell apart only through second-order terms, if at all: the sum of
    their coefficients is what |a| sees to first order."""
    for n, ax in effects.items():
        if n not in found or EFFECTS[n].axes_observable:
            continue
        v, sd = observable_sum(n, ax, final.result)
        unit = final.result.params[make_effect(n, ax).coefficient_names[0]].unit
        head = (f"{n}: static poses determine to first order only the sum of its coefficients over the axes "
                f"({v:.4g} +/- {sd:.2g} {unit}; |a|^2 changes by 2 (q_x + q_y + q_z) m_x m_y m_z)")
        notes.append(head + (f", not which axis carries it: axis {label(n, ax)[-2]} is a convention" if len(ax) == 1
                             else f"; the split between {EFFECTS[n].axis_label(ax)} comes from the second-order terms "
                                  "q_i^2 (m_j m_k)^2, which large coefficients make visible"))


def unresolved(prob: Problem, res: FitResult, effects: Effects, name: str, penalty: float,
               notes: list[str]) -> dict[int, float]:
    """Axes a found term lacks that these poses cannot rule out: {axis: lambda}.

    lambda = the (misfit-scaled) chi-square a coefficient on that axis as large as the term's largest
    found one would add, linearised at the final fit (the other missing axes left out): its squared
    size over its standard error. The backward step keeps such a coefficient only when it removes
    more than ``penalty``, i.e. with probability P(chi2_1(lambda) > penalty); below
    ``RESOLVED_POWER`` the absence of the axis is not a finding. (A warm-up shows only in the
    first intervals, so their orientations decide which of its axes the data can see.)"""
    have = effects[name]
    if not EFFECTS[name].axes_observable or len(have) == 3:
        return {}
    missing = {a: make_effect(name, (a,)).coefficient_names[0] for a in range(3) if a not in have}
    model, params = prob.parameters(canonical({**effects, name: (0, 1, 2)}), res.values(), check=False)
    params = params.with_values({c: 0.0 for c in missing.values()})
    J = jacobian_rows(prob.data(model), params, model, prob.gravity) / res.sigma[:, None]
    col = {n: i for i, n in enumerate(params.free_names)}
    base = [col[n] for n in res.free_names]
    found = make_effect(name, have).coefficient_names
    ref = max(found, key=lambda c: abs(res.params[c].value))
    out: dict[int, float] = {}
    for a, c in missing.items():
        A = J[:, base + [col[c]]]
        var = float(np.linalg.pinv(A.T @ A)[-1, -1]) * max(1.0, res.redchi)  # scaled units
        lam = (res.params[ref].value / params[c].scale) ** 2 / var if var > 0 else 0.0
        power = power_chi2_1(lam, penalty)
        if power < RESOLVED_POWER:
            out[a] = lam
            ax = EFFECTS[name].axis_names[a]
            notes.append(f"{label(name, have)}: axis {ax} not ruled out: a coefficient there as large as "
                         f"{ref} ({abs(res.params[ref].value):.3g} {res.params[ref].unit}) would add only {lam:.3g} "
                         f"chi-square and be kept in {power:.0%} of such recordings; these poses barely see "
                         f"{name} on {ax}: to test it, {where_to_look(name, a, res)}")
    return out


#: Which holds show a term of each covariate (``where_to_look``).
_WHEN = {"temp": " at the coldest and the warmest times", "temp_rate": " while it warms and while it cools"}


def where_to_look(name: str, axis: int, res: FitResult) -> str:
    """Which holds show a term on an axis: that axis along gravity (a bias or scale change on axis i
    moves |a| by m_i times it, m_i^2 for a scale), or both axes of an angle at 45 degrees to gravity
    (an angle moves |a| by m_i m_j times it), where the term's basis changes most."""
    e = make_effect(name, (axis,))
    if getattr(e, "target", None) == "angle":
        pair = {0: "x and y", 1: "x and z", 2: "y and z"}[axis]
        hold = f"hold the {pair} axes at 45 degrees to gravity, both signs"
    else:
        hold = f"hold the {AXIS_NAMES[axis]} axis up and down"
    if not isinstance(e, Term):  # a term in the specific force: any time
        return hold
    if e.basis.covariate in _WHEN:
        return hold + _WHEN[e.basis.covariate]
    if e.shape_names:  # a warm-up
        return hold + f" within the first {2 * res.params[e.shape_names[0]].value:.3g} s (twice the fitted tau)"
    if e.given_names:  # a step
        return hold + f" before and after {res.params[e.given_names[0]].value:.4g} s"
    return hold + " at the start and at the end of the recording"
