"""``imucal discover`` on a temperature sweep: the thermal calibration as a Discovery.

imucal.analysis.discover hands a run whose recording holds still poses over a temperature change
(imucal.thermal.run.is_sweep) here. The rounds of the order selection become discovery's rounds,
the terms its effects (with the pose fit's coefficients, standard errors and references), and
the calibration kept is the base fit with the terms held (imucal.thermal.run). The tests against
the noise are the pose fit's: chi2 of the rows about their poses, before and after.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable

from imucal.analysis.discover import Candidate, Discovery, DiscoverSettings, FoundEffect, Step
from imucal.config.run import RunConfig
from imucal.model.effects import make_effect
from imucal.report.thermal import verdict
from imucal.thermal.run import Sweep, ThermalCalibration, first_added, sweep_of, thermal_calibration  # noqa: F401
from imucal.thermal.select import Round, Trial

#: The grammar's temperature terms: what this path can name.
TEMPERATURE_TERMS = tuple(f"{t}_{b}" for t in ("bias", "scale") for b in ("temperature", "temperature2",
                                                                          "temperature3"))


def _candidate(t: Trial) -> Candidate:
    fitted = t.dof > 0
    return Candidate(name=t.name, axes=(t.axis,), new_axes=(t.axis,), chi2_screen=t.chi2_screen, chi2=t.chi2,
                     dof=t.dof, lr=t.lr, p_value=t.p_adjusted, p_adjusted=t.p_adjusted,
                     score=t.chi2 if fitted else math.nan, fitted=fitted, converged=fitted,
                     significant=t.significant)


def _step(r: Round) -> Step:
    cands = tuple(_candidate(t) for t in r.trials if t.determined)
    chosen = next((c for c in cands if r.chosen is not None and c.label == r.chosen.label), None)
    best = min((c.p_adjusted for c in cands if c.fitted), default=math.nan)
    return Step(index=r.index, chi2_before=r.chi2_before, dof_before=r.dof_before, candidates=cands, chosen=chosen,
                p_scan=best)


def _effects(tc: ThermalCalibration) -> tuple[FoundEffect, ...]:
    fit, added = tc.selection.fit, first_added(tc)
    out = []
    for name, axes in tc.effects.items():
        e = make_effect(name, axes)
        coef = {n: float(fit.params[n].value) for n in e.coefficient_names}
        ref = {n: float(fit.params[n].value) for n in e.reference_names}
        lr, p = added.get(name, (math.nan, math.nan))
        out.append(FoundEffect(name=name, axes=tuple(axes), coefficients=coef,
                               std={n: float(fit.std.get(n, math.nan)) for n in coef},
                               units={n: fit.params[n].unit for n in (*coef, *ref)}, reference=ref, lr=lr, p_value=p))
    return tuple(out)


def sweep_discovery(config: RunConfig, sweep: Sweep, settings: DiscoverSettings,
                    progress: Callable[[], None] | None = None) -> Discovery:
    """The Discovery of a temperature sweep (module docstring); ``config`` as the user gave it."""
    tc = thermal_calibration(replace(sweep, config=config), progress, settings.alpha_effect)
    notes = ["temperature sweep: the terms were chosen on the pose constancy of the still poses' temperature "
             "rows (imucal.thermal; see [[Temperature]]); the calibration kept is |a| - g on the still intervals "
             "with the terms held"]
    if tc.base is None:
        notes.append(f"the base model without temperature terms was refused ({tc.base_refusal}): the 'before' "
                     "column shows the final model")
    alpha = settings.alpha_noise
    return Discovery(base=tc.base or tc.final, final=tc.final, steps=tuple(_step(r) for r in tc.selection.rounds),
                     effects=_effects(tc), verdict=verdict(tc), consistent_before=tc.p_noise(False) >= alpha,
                     consistent_after=tc.p_noise(True) >= alpha, p_before=tc.p_noise(False), p_after=tc.p_noise(True),
                     disagreement=(), notes=tuple(notes), settings=settings, thermal=tc)
