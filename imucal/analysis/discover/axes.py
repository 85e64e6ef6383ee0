"""Which axes a found term may have that the poses cannot rule out, and where to look for them."""
from __future__ import annotations

import numpy as np

from imucal.analysis.discover.problem import Effects, Problem, canonical, label
from imucal.analysis.discover.settings import RESOLVED_POWER
from imucal.model.effects import AXIS_NAMES, EFFECTS, Term, make_effect
from imucal.pipeline import CalibrationRun
from imucal.solve.fit import FitResult, jacobian_rows
from imucal.solve.stats import power_chi2_1


def axis_notes(effects: Effects, found: set[str], final: CalibrationRun, notes: list[str]) -> None:
    """Effects whose axis static poses cannot tell (the sum of their coefficients is determined)."""
    for n, ax in effects.items():
        if n in found and not EFFECTS[n].axes_observable:
            e = make_effect(n, ax)
            v = sum(final.result.params[c].value for c in e.coefficient_names)
            notes.append(f"{n}: static poses determine only the sum of its coefficients over the axes "
                         f"({v:.4g} {final.result.params[e.coefficient_names[0]].unit}; |a|^2 changes by 2 (q_x + q_y "
                         f"+ q_z) m_x m_y m_z), not which axis carries it: axis {label(n, ax)[-2]} is a convention")


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
            notes.append(f"{label(name, have)}: axis {AXIS_NAMES[a]} not ruled out: a coefficient there as large as "
                         f"{ref} ({abs(res.params[ref].value):.3g} {res.params[ref].unit}) would add only {lam:.3g} "
                         f"chi-square and be kept in {power:.0%} of such recordings; these poses barely see "
                         f"{name} on {AXIS_NAMES[a]}: to test it, {where_to_look(name, a, res)}")
    return out


def where_to_look(name: str, axis: int, res: FitResult) -> str:
    """Which holds show a term on an axis: that axis along gravity (a bias or scale change on axis i
    moves |a| by m_i times it, m_i^2 for a scale), where the term's basis changes most."""
    e = make_effect(name, (axis,))
    hold = f"hold the {AXIS_NAMES[axis]} axis up and down"
    if not isinstance(e, Term):  # a term in the specific force: any time
        return hold
    if e.basis.covariate == "temp":
        return hold + " at the coldest and the warmest times"
    if e.shape_names:  # a warm-up
        return hold + f" within the first {2 * res.params[e.shape_names[0]].value:.3g} s (twice the fitted tau)"
    return hold + " at the start and at the end of the recording"
