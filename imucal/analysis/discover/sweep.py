"""A temperature sweep's discovery: still poses held while the temperature changes have their own evidence
(imucal.thermal: the rows of each pose about the pose), so the terms are chosen there and shown as a
Discovery's rounds and effects."""
from __future__ import annotations

import dataclasses
import math
from typing import Callable

from imucal.analysis.discover.candidates import found_effect
from imucal.analysis.discover.problem import EFFECT_ORDER, labels
from imucal.analysis.discover.result import Candidate, Discovery, Step
from imucal.analysis.discover.settings import DiscoverSettings
from imucal.analysis.discover.verdict import Outcome, Shortfall, SweepVerdict, Verdict
from imucal.config.run import RunConfig
from imucal.thermal.run import Sweep, ThermalCalibration, first_added, thermal_calibration


def _steps(tc: ThermalCalibration) -> tuple[Step, ...]:
    """The order selection's rounds as discovery's rounds."""
    steps = []
    for r in tc.selection.rounds:
        cands = tuple(Candidate(t.name, (t.axis,), (t.axis,), t.chi2_screen, chi2=t.chi2, dof=t.dof, lr=t.lr,
                                p_value=t.p_adjusted, p_adjusted=t.p_adjusted, score=t.chi2, fitted=t.dof > 0,
                                converged=t.dof > 0, significant=t.significant) for t in r.trials if t.determined)
        chosen = next((c for c in cands if r.chosen is not None and c.label == r.chosen.label), None)
        steps.append(Step(r.index, r.chi2_before, r.dof_before, cands, chosen,
                          p_scan=min((c.p_adjusted for c in cands if c.fitted), default=math.nan)))
    return tuple(steps)


def _verdict(tc: ThermalCalibration, alpha: float) -> Verdict:
    """The sweep's verdict: the terms, and how far they bring the poses' rows together."""
    fit = tc.selection.fit
    terms = labels(sorted(tc.effects, key=EFFECT_ORDER.get), tc.effects)
    sweep = SweepVerdict(poses=int(tc.rows.poses.size), temperature_range=tc.temperature_range,
                         rms_before=tc.rms_before, rms_after=tc.rms_after)
    p = tc.p_noise(True)
    outcome = Outcome.EXPLAINED if terms else Outcome.CONSISTENT if p >= alpha else Outcome.UNEXPLAINED
    return Verdict(outcome, fit.redchi, p, terms, None if outcome is not Outcome.UNEXPLAINED else Shortfall.NO_CANDIDATE,
                   sweep=sweep)


def sweep_discovery(config: RunConfig, sweep: Sweep, settings: DiscoverSettings,
                    progress: Callable[[], None] | None) -> Discovery:
    """A temperature sweep's Discovery: its thermal calibration (imucal.thermal.run), the order selection's
    rounds as rounds, the terms as effects, the tests against the noise those of the rows about their poses."""
    tc = thermal_calibration(dataclasses.replace(sweep, config=config), progress, settings.alpha_effect)
    fit, added = tc.selection.fit, first_added(tc)
    res = dataclasses.replace(tc.final.result, params=fit.params, std=fit.std)
    effects = tuple(found_effect(n, ax, res, *added[n], ()) for n, ax in
                    sorted(tc.effects.items(), key=lambda kv: EFFECT_ORDER[kv[0]]))
    notes = ["temperature sweep: the terms were chosen on the pose constancy of the still poses' temperature rows "
             "(imucal.thermal; see [[Temperature]]); the calibration kept is |a| - g on the still intervals with "
             "the terms held"]
    if tc.base is None:
        notes.append(f"the base model without temperature terms was refused ({tc.base_refusal}): the base run "
                     "shown is the final one")
    if tc.gyro_note:
        notes.append(tc.gyro_note)
    a = settings.alpha_noise
    return Discovery(base=tc.base or tc.final, final=tc.final, steps=_steps(tc), effects=effects,
                     verdict=_verdict(tc, a), consistent_before=tc.p_noise(False) >= a,
                     consistent_after=tc.p_noise(True) >= a, p_before=tc.p_noise(False), p_after=tc.p_noise(True),
                     disagreement=(), notes=tuple(notes), settings=settings, thermal=tc)
