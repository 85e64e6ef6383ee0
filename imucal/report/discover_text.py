"""Discovery in words and as JSON: the verdict's sentence, the text report, the machine-readable summary.

The only place a Discovery (imucal.analysis.discover) becomes prose; everything it says is read from
the typed result."""
from __future__ import annotations

import dataclasses
import math

from imucal.analysis.discover import Discovery, Outcome, Shortfall, Verdict, Withheld
from imucal.analysis.discover.problem import label
from imucal.analysis.discover.result import FoundEffect
from imucal.analysis.discover.verdict import StochasticPart
from imucal.analysis.stochastic import Preferred
from imucal.constants import STANDARD_GRAVITY
from imucal.errors import printable
from imucal.model.effects import EFFECTS
from imucal.report.thermal import gap_lines, thermal_json, thermal_lines

#: [m/s^2] one milli-g (standard gravity / 1000): the unit a sweep's verdict gives residuals in.
MG = STANDARD_GRAVITY / 1000.0

#: What the shape check's verdict says it found.
SHAPE_FAILED = "a piecewise-constant shape fits significantly better"
_SHORTFALL = {
    Shortfall.NO_CANDIDATE: " and no candidate effect is significant",
    Shortfall.RANDOM_WALK: "; no deterministic term beats a bias random walk",
    Shortfall.REFUSED: "; the model found cannot be calibrated from these poses",
    Shortfall.TOO_FEW_INTERVALS: "; too few intervals to test more effects",
}
_WITHHELD = {
    Withheld.TEMPERATURE: "the residual follows temperature",
    Withheld.JUMP: "one jump between intervals is larger than a Gaussian stochastic bias allows",
}


#: The verdict's headline per outcome (figure titles, tables).
HEADLINE = {
    Outcome.CONSISTENT: "consistent with noise",
    Outcome.EXPLAINED: "explained",
    Outcome.STOCHASTIC: "explained by a stochastic bias",
    Outcome.TERMS_AND_STOCHASTIC: "explained by terms plus a stochastic bias",
    Outcome.PARTLY_EXPLAINED: "partly explained",
    Outcome.UNEXPLAINED: "disagreement not explained by any candidate",
}


def _num(x: float):
    return float(x) if math.isfinite(x) else None


def _weights(v: Verdict) -> str:
    """How the calibration kept counts the excess over the noise (a clause)."""
    if v.weights == "auto":
        return ("the default fit (weights: auto) counts it in its standard errors (its values are the "
                "unweighted fit's)")
    return f"the calibration kept (weights: {v.weights}) does not model it"


def _values(s: StochasticPart) -> str:
    return ", ".join(f"{n} {x:.3g} +/- {sd:.2g} {u}" for n, (x, sd, u) in s.values.items())


def _rest(v: Verdict) -> str:
    """The misfit left by the terms and why no further term explains it."""
    text = f"chi2/dof = {v.redchi:.3g} (p = {v.p:.3g})"
    if v.shortfall is Shortfall.SHAPE:
        return (f"{text}; the residual follows {', '.join(v.shape_covariates)} but not as any term of the grammar "
                f"({SHAPE_FAILED})")
    if v.shortfall is Shortfall.MAX_EFFECTS:
        return f"{text}; stopped after {v.max_effects} effects"
    return text + _SHORTFALL.get(v.shortfall, "")


def _unexplained(v: Verdict) -> str:
    text = f"disagreement not explained by any candidate: {_rest(v)}"
    s = v.stochastic
    if s is not None and s.withheld is not None:
        why = (f"a single step of the bias at t = {s.step_at:.4g} s fits better" if s.withheld is Withheld.STEP
               else _WITHHELD[s.withheld])
        text += f"; a stochastic bias fits the scatter too ({_values(s)}) but is not claimed: {why}; {_weights(v)}"
    elif math.isfinite(v.excess_rms) and v.excess_rms > 0:
        text += (f"; the scatter between intervals fits a random bias per visit of a pose (bias_instability, "
                 f"{v.excess_rms:.3g} m/s^2 rms); {_weights(v)}")
    return text


def _mg(x: float) -> str:
    return f"{x / MG:.3g} mg"


def _sweep_text(v: Verdict) -> str:
    """A temperature sweep's verdict: the terms it holds, and how far they bring the poses together."""
    s = v.sweep
    lo, hi = s.temperature_range
    if not v.terms:
        return (f"no temperature term is significant: the rows of {s.poses} poses over {lo:.1f}..{hi:.1f} degC stay "
                f"within {_mg(s.rms_before)} RMS of their poses")
    return (f"explained by temperature: {', '.join(v.terms)} bring the still poses' readings over {lo:.1f}..{hi:.1f} "
            f"degC from {_mg(s.rms_before)} to {_mg(s.rms_after)} RMS about each pose; the rest (chi2/dof "
            f"{v.redchi:.3g} against the rows' noise) follows no temperature term")


def verdict_text(v: Verdict) -> str:
    """The verdict in one sentence."""
    if v.sweep is not None:
        return _sweep_text(v)
    terms = ", ".join(v.terms)
    s = v.stochastic
    amb = " (the data cannot tell bias_instability from bias_random_walk)" if s is not None and s.ambiguous else ""
    if v.outcome is Outcome.CONSISTENT:
        return f"consistent with noise: chi2/dof = {v.redchi:.3g} (p = {v.p:.3g}); the base model explains the data"
    if v.outcome is Outcome.EXPLAINED:
        return f"explained: after adding {terms} chi2/dof = {v.redchi:.3g} (p = {v.p:.3g}), at noise level"
    if v.outcome is Outcome.STOCHASTIC:
        return f"explained by a stochastic bias: {_values(s)}{amb}; {_weights(v)}; no deterministic term helps ({_rest(v)})"
    if v.outcome is Outcome.TERMS_AND_STOCHASTIC:
        return f"explained by {terms} plus a stochastic bias: {_values(s)}{amb}; {_weights(v)} (without it: {_rest(v)})"
    if v.outcome is Outcome.PARTLY_EXPLAINED:
        return f"partly explained by {terms}; the remaining {_unexplained(v)}"
    return _unexplained(v)


def _gap_lines(d: Discovery) -> list[str]:
    b, f = d.base.result, d.final.result
    return ["[[Gap]]            before          after           (interval means)",
            f"    RMS |a|-g  = {d.rms_before:<15.6g} {d.rms_after:<15.6g} m/s^2 (noise alone: {d.rms_noise:.3g})",
            f"    chi2 / dof = {b.chi2:.4g} / {b.dof:<6d}  {f.chi2:.4g} / {f.dof}",
            f"    chi2/dof   = {b.redchi:<15.4g} {f.redchi:<15.4g} (1 = residual at noise level)",
            f"    p (chi2)   = {d.p_before:<15.3g} {d.p_after:<15.3g} "
            f"(below {d.settings.alpha_noise:g}: disagrees with the noise)",
            f"    model      = {b.model_name}  ->  {f.model_name}"]


#: What tells two terms apart that the data could not: the record a user can make to separate them.
_SEPARATED_BY = {
    frozenset({"scale_nonlinearity", "scale_asymmetry"}):
        "on poses with an axis along or across gravity |m| = m^2 / g, so only poses with the axis between "
        "level and vertical (an edge at 45 deg, a corner at 35 deg) tell an asymmetric scale from a quadratic "
        "one: record more of them",
}


def separation_lines(e: FoundEffect) -> list[str]:
    """For a term ambiguous with a relative the data cannot tell it from, what would (``_SEPARATED_BY``)."""
    rivals = {a.split("[")[0] for a in e.ambiguous_with}
    return [f"        to tell {e.name} from {r}: {_SEPARATED_BY[frozenset({e.name, r})]}"
            for r in sorted(rivals) if frozenset({e.name, r}) in _SEPARATED_BY]


def _effect_lines(d: Discovery) -> list[str]:
    L = ["[[Effects found]]" + ("" if d.effects else "  none")]
    for e in d.effects:
        amb = f"  (ambiguous with {', '.join(e.ambiguous_with)})" if e.ambiguous_with else ""
        L.append(f"    {e.label}: LR = {e.lr:.4g}, p (adjusted) = {e.p_value:.3g}{amb}")
        L += separation_lines(e)
        if e.unresolved_axes:
            L.append(f"        not ruled out on {', '.join(EFFECTS[e.name].axis_names[a] for a in e.unresolved_axes)}: "
                     "these poses barely see the term there (see the notes)")
        for n, v in e.coefficients.items():
            L.append(f"        {n} = {v:.6g} +/- {e.std[n]:.3g} {e.units[n]}")
        L += _change_point_lines(e) + _sum_lines(e)
        for n, v in e.reference.items():
            L.append(f"        {n} = {v:.6g} {e.units.get(n, '')} (fixed reference)")
    L.append("[[Where the base model disagrees]]  chi-square a single-axis effect would remove (linearised)")
    L += [f"    {p:<28s} {v:10.4g}" for p, v in d.disagreement[:8]]
    return L


def _change_point_lines(e) -> list[str]:
    c = e.change_point
    if c is None:
        return []
    return [f"        step at t = {c.time:.6g} s: between the still intervals ending {c.gap[0]:.6g} s and starting "
            f"{c.gap[1]:.6g} s; 95 % confidence set of change points {c.lower:.6g} .. {c.upper:.6g} s "
            f"({c.gaps} of {c.tried} gaps)"]


def _sum_lines(e) -> list[str]:
    if e.observable_sum is None:
        return []
    v, sd = e.observable_sum
    unit = next(iter(e.units.values()), "")
    return [f"        observable combination (first order): sum over {EFFECTS[e.name].axis_label(e.axes)} = "
            f"{v:.6g} +/- {sd:.3g} {unit}"]


def _round_lines(s) -> list[str]:
    L = [f"[[Round {s.index}]]  chi2 = {s.chi2_before:.6g} on {s.dof_before} dof, {len(s.candidates)} candidates, "
         f"misfit scale {s.scale:.3g}, family-wise p of the best screened {s.p_scan:.3g}"]
    shown = sorted(s.candidates, key=lambda c: (not c.fitted, c.score if c.fitted else c.chi2_screen))
    for c in shown[:10]:
        if c.fitted:
            flag = "significant" if c.significant else "not significant"
            L.append(f"    {c.label:<28s} chi2 {c.chi2:10.5g}  LR {c.lr:9.4g}  p_adj {c.p_adjusted:9.3g}  "
                     f"score {c.score:9.5g}  {flag}")
        else:
            L.append(f"    {c.label:<28s} chi2 ~ {c.chi2_screen:8.5g} (screened out)")
    if s.chosen is None:
        return L + ["    -> no candidate is significant"]
    return L + [f"    -> added {s.chosen.label}"
                + (f" (significant given {s.jointly_with}: the pair explains the data better than any single term, "
                   "and each is significant given the other)" if s.jointly_with else "")
                + (f"; cannot be told apart from {', '.join(c.label for c in s.ambiguous_with)}"
                   if s.ambiguous_with else "")]


def _stochastic_lines(d: Discovery) -> list[str]:
    """The report's stochastic section: the REML estimates and tests, and the Allan view."""
    s = d.stochastic
    if s is None:
        return []
    L = ["[[Stochastic biases]]  REML on interval means, LR tests at level "
         f"{s.alpha:g} (boundary-corrected, Bonferroni over the two)"]
    L += [f"    {n} = {v:.4g} +/- {sd:.2g} {u}" for n, (v, sd, u) in s.values().items()]
    L.append(f"    named: {', '.join(s.named) or 'none'}" + ("  (ambiguous)" if s.ambiguous else ""))
    L += [f"    {n:<18s} p given the other {s.p[n]:9.3g}   p alone {s.p_alone[n]:9.3g}" for n in s.p]
    if d.allan is not None:
        a = d.allan
        L.append(f"    Allan view: interval {a.interval} ({a.duration:.4g} s still); the curve's own +1/2 slope: "
                 + ", ".join(f"{x} {v:.3g}" for x, v in zip("xyz", a.q_allan)) + " m/s^2/sqrt(s)")
    return L


def rival_lines(d: Discovery) -> list[str]:
    """Each term in time or temperature beside the bias random walk that explains the same excess: both
    explanations, which the data prefer, and the test."""
    if not d.rivals:
        return []
    L = ["[[Structure or noise]]  a term and a bias random walk explain the same excess: the likelihood ratio "
         "of the walk with and without the term (per-visit offsets and the walk re-estimated, Bonferroni over the "
         "terms)"]
    for r in d.rivals:
        name = label(r.term, r.axes)
        verdict = {Preferred.TERM: f"the data prefer {name}; the walk alone does not explain its structure",
                   Preferred.WALK: f"the data prefer the walk; {name} is dropped (it adds nothing a walk does not)",
                   Preferred.EITHER: f"the data cannot tell them apart; {name} is kept (it leaves no excess for a "
                                     "walk to explain, and it corrects)"}[r.preferred]
        L.append(f"    {name} or a bias random walk (q = {r.q:.3g} m/s^2/sqrt(s)): LR {r.lr:.3g} on {r.k} "
                 f"parameter(s), p adjusted {r.p_adjusted:.2g}: {verdict}")
    return L


def discovery_report(d: Discovery) -> str:
    """A text report: verdict, gap before/after, effects with coefficients, the rounds."""
    gap = _gap_lines(d)
    if d.thermal is not None:  # a sweep's gap is its poses' constancy (imucal.report.thermal)
        gap = gap_lines(d.thermal, d.settings.alpha_noise) + [f"    model      = {d.final.result.model_name}"]
    L = ["[[Discovery]]", f"    data      = {printable(d.base.recording.source)} ({d.base.intervals.n} static intervals)",
         f"    verdict   = {verdict_text(d.verdict)}", *gap, *_effect_lines(d)]
    for s in d.steps:
        L += _round_lines(s)
    if d.thermal is not None:
        L += thermal_lines(d.thermal)
    L += rival_lines(d) + _stochastic_lines(d)
    if d.notes:
        L.append("[[Notes]]")
        L.extend(f"    - {n}" for n in d.notes)
    return "\n".join(L) + "\n"


def _effects_json(d: Discovery) -> list[dict]:
    return [{"name": e.name, "axes": list(e.axis_names), "label": e.label,
             "coefficients": e.coefficients, "std": {k: _num(v) for k, v in e.std.items()},
             "units": e.units, "reference": e.reference, "lr": _num(e.lr), "p_value": _num(e.p_value),
             "ambiguous_with": list(e.ambiguous_with),
             "unresolved_axes": [EFFECTS[e.name].axis_names[a] for a in e.unresolved_axes],
             "change_point": e.change_point.to_json() if e.change_point is not None else None,
             "observable_sum": None if e.observable_sum is None else
             {"value": _num(e.observable_sum[0]), "std": _num(e.observable_sum[1])}}
            for e in d.effects]


def _steps_json(d: Discovery) -> list[dict]:
    return [{"round": s.index, "chi2_before": s.chi2_before, "dof_before": s.dof_before, "scale": s.scale,
             "p_scan": _num(s.p_scan), "chosen": s.chosen.label if s.chosen else None, "jointly_with": s.jointly_with,
             "ambiguous_with": [c.label for c in s.ambiguous_with],
             "candidates": [{"effect": c.label, "new_axes": [EFFECTS[c.name].axis_names[a] for a in c.new_axes],
                             "chi2_screen": _num(c.chi2_screen), "chi2": _num(c.chi2), "dof": c.dof, "lr": _num(c.lr),
                             "p_adjusted": _num(c.p_adjusted), "fitted": c.fitted, "significant": c.significant}
                            for c in s.candidates]}
            for s in d.steps]


def discovery_json(d: Discovery) -> dict:
    """The machine-readable summary (``imucal discover --json``)."""
    b, f = d.base.result, d.final.result
    return {
        "format": "imucal-discover", "format_version": 2,
        "data": dict(d.final.calibration.data),
        "verdict": verdict_text(d.verdict), "outcome": d.verdict.to_json(),
        "effects": _effects_json(d),
        "rms_before": d.rms_before, "rms_after": d.rms_after, "rms_noise": d.rms_noise, "rms_unit": "m/s^2",
        "chi2_before": d.chi2_before, "chi2_after": d.chi2_after,
        "dof": int(f.dof), "dof_before": int(b.dof), "dof_after": int(f.dof),
        "redchi_before": _num(b.redchi), "redchi_after": _num(f.redchi),
        "p_before": d.p_before, "p_after": d.p_after,
        "consistent_before": d.consistent_before, "consistent_after": d.consistent_after,
        "n_intervals": int(d.base.intervals.n), "model_before": b.model_name, "model_after": f.model_name,
        "calibration_weights": d.calibration_run.calibration.fit.get("weights"),  # of the one --out writes
        "disagreement": [{"pattern": p, "chi2_removed": _num(v)} for p, v in d.disagreement],
        "steps": _steps_json(d),
        "notes": list(d.notes),
        "holds_cut": [c.to_json() for c in d.holds_cut],
        "settings": dataclasses.asdict(d.settings),
        "stochastic": d.stochastic.to_json() if d.stochastic is not None else None,
        "structure_or_noise": [r.to_json() for r in d.rivals],
        "allan": d.allan.to_json() if d.allan is not None else None,
        "thermal": thermal_json(d.thermal) if d.thermal is not None else None,
    }
