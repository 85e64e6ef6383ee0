"""The discovery workflow: fit the base model, add effects while the residual disagrees with the noise,
simplify and check what was found, weigh it against a stochastic bias, decide the verdict."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from imucal.analysis import stochastic as stoch
from imucal.analysis.discover import axes as ax_
from imucal.analysis.discover import backward as bw
from imucal.analysis.discover import stochastic as noise
from imucal.analysis.discover.candidates import candidates, found_effect, testable
from imucal.analysis.discover.problem import EFFECT_ORDER, Effects, Problem, as_dict, canonical, labels, p_noise
from imucal.analysis.discover.changepoint import change_point
from imucal.analysis.hold_steps import Cut, hold_step_words, reading
from imucal.analysis.discover.result import Discovery, FoundEffect, Step
from imucal.analysis.discover.screening import scan
from imucal.analysis.discover.selection import round_
from imucal.analysis.discover.settings import DiscoverSettings
from imucal.analysis.discover.sweep import sweep_discovery
from imucal.analysis.discover.verdict import Shortfall, decide, stochastic_part
from imucal.config.run import EffectSpec, RunConfig
from imucal.errors import ImucalError
from imucal.model.effects import EFFECTS, MIN_DOF, given_names, make_effect
from imucal.model.parameters import BASE_NAMES
from imucal.pipeline import CalibrationRun, calibrate_accelerometer
from imucal.thermal.evidence import SWEEP_SPAN
from imucal.thermal.run import Sweep, sweep_of
from imucal.thermal.select import TEMPERATURE_TERMS
from imucal.solve.fit import FitResult
from imucal.solve.stats import between_excess


#: The note of a stochastic bias withheld because the residual follows temperature.
IN_TEMPERATURE = "a stochastic bias is not named: the shape check found structure in temperature"


@dataclass
class State:
    """Where the search stands: the current fit, its effects, what was found and why it stopped."""

    current: FitResult
    effects: Effects
    steps: list = field(default_factory=list)
    found: list = field(default_factory=list)  #: (name, lr, p, ambiguous labels)
    disagreement: list = field(default_factory=list)
    shortfall: Shortfall | None = None  #: why the search (or a later step) left the residual unexplained
    shape_covariates: tuple[str, ...] = ()  #: covariates the shape check found structure in
    rivals: tuple = ()  #: the terms in time or temperature weighed against a bias random walk (stoch.Rival)


def _next_round(prob: Problem, st: State, names: list[str], settings: DiscoverSettings, notes: list[str],
                consistent: bool) -> Step | None:
    """One forward round, or None (with ``st.shortfall`` set when the residual still disagrees)."""
    iv, base = prob.iv, prob.run
    if len(st.steps) >= settings.max_effects:
        st.shortfall = None if consistent else Shortfall.MAX_EFFECTS
        return None
    cands = candidates(names, st.effects, len(st.current.free_names), iv.n, base.observability.n_distinct)
    if not cands:
        if not consistent:
            notes.append(f"no candidate fits: {iv.n} intervals ({base.observability.n_distinct} distinct "
                         f"orientations) leave too few degrees of freedom for {len(st.current.free_names)} + 1 "
                         "free parameters")
            st.shortfall = Shortfall.TOO_FEW_INTERVALS
        return None
    sc = scan(prob, st.current, st.effects, names, cands)
    if consistent and sc.p >= settings.alpha_scan:
        return None  # the omnibus test passes and no single candidate stands out from the noise
    level = settings.alpha_effect if not consistent else settings.alpha_scan
    step, fits = round_(prob, st.current, st.effects, sc, settings, len(st.steps) + 1, notes, level)
    if step.index == 1:  # where the base model disagrees: single-axis patterns, linearised
        st.disagreement = sorted(((c.label, st.current.chi2 - c.chi2_screen) for c in step.candidates
                                  if len(c.axes) == 1 and c.axes == c.new_axes), key=lambda t: -t[1])
    if step.chosen is not None:
        (st.current,) = fits.values()
    return step


def search(prob: Problem, names: list[str], settings: DiscoverSettings, notes: list[str], p_before: float) -> State:
    """Forward rounds: a round runs while the residual disagrees with the noise or a candidate
    stands out; each adds the most significant candidate (family-wise min-p level)."""
    base = prob.run
    st = State(base.result, as_dict(base.calibration.effect_objects()))
    consistent = p_before >= settings.alpha_noise
    while True:
        step = _next_round(prob, st, names, settings, notes, consistent)
        if step is None or (step.chosen is None and consistent):
            break  # (a candidate that stood out in the screen is not significant when fitted)
        st.steps.append(step)
        if step.chosen is None:
            st.shortfall = Shortfall.NO_CANDIDATE
            break
        c = step.chosen
        st.found.append((c.name, c.lr, c.p_adjusted, tuple(a.label for a in step.ambiguous_with)))
        st.effects = {**st.effects, c.name: c.axes}
        consistent = p_noise(st.current) >= settings.alpha_noise
        st.shortfall = None
    return st


def backward(prob: Problem, st: State, settings: DiscoverSettings, notes: list[str]) -> State:
    """Simplify, prune and shape-check what the forward rounds found."""
    if not st.found:
        return st
    current, effects, kept = bw.simplify(prob, st.current, st.effects, {f[0] for f in st.found}, settings, notes)
    found = [f if f[0] in kept else (EFFECTS[f[0]].simpler, *f[1:]) for f in st.found]
    current, effects = bw.prune(prob, current, effects, {f[0] for f in found}, settings, notes)
    found = [f for f in found if f[0] in effects]
    wrong = bw.shape_check(prob, current, effects, {f[0] for f in found}, settings)
    st = dataclasses.replace(st, current=current, effects=effects, found=found)
    if not wrong:
        return st
    notes.extend(w.note for w in wrong.values())
    effects = {n: ax for n, ax in effects.items() if n not in wrong}
    found = [f for f in found if f[0] not in wrong]
    current = prob.fit(canonical(effects), current.values()) if found else prob.run.result
    return dataclasses.replace(st, current=current, effects=effects, found=found, shortfall=Shortfall.SHAPE,
                               shape_covariates=tuple(sorted({w.covariate for w in wrong.values()})))


def final_config(config: RunConfig, effects: Effects, current: FitResult) -> RunConfig:
    """``config`` with the effects found, every free parameter starting where discovery left it (so the
    calibration's observability check judges the model at the values discovery judged it,
    imucal.pipeline.observability)."""
    specs = tuple(EffectSpec(n, tuple(EFFECTS[n].axis_names[a] for a in ax)) for n, ax in
                  sorted(effects.items(), key=lambda kv: EFFECT_ORDER[kv[0]]))
    names = {n for e in canonical(effects) for n in (*e.coefficient_names, *e.shape_names)}
    start = {n: min(max(p.value, p.lower), p.upper)  # (IPOPT may end a hair outside a bound)
             for n in current.free_names if n not in config.fit.initial and (n in BASE_NAMES or n in names)
             for p in [current.params[n]]}
    start.update({n: current.params[n].value for n in given_names(canonical(effects))})  # a step's time
    return dataclasses.replace(config, fit=dataclasses.replace(config.fit, effects=specs,
                                                               initial={**config.fit.initial, **start}))


def final_run(config: RunConfig, base: CalibrationRun, st: State, notes: list[str]) -> CalibrationRun:
    """The whole pipeline once more with the effects found: the calibration file to keep."""
    if not st.found:
        return base
    final = calibrate_accelerometer(final_config(config, st.effects, st.current))
    if final.result.chi2 > st.current.chi2 * (1 + 1e-6) + 1e-9:
        notes.append(f"the final calibration's chi2 {final.result.chi2:.6g} is above the discovery fit's "
                     f"{st.current.chi2:.6g} (a different local optimum)")
    return final


def _start(config: RunConfig, settings: DiscoverSettings) -> tuple[Sweep | None, CalibrationRun | None]:
    """The recording as a temperature sweep (its rows: imucal.thermal) and, unless it is one, the base
    model's calibration; too few intervals for discovery's rows said in its words."""
    try:
        sweep = sweep_of(config) if set(TEMPERATURE_TERMS) & set(settings.candidates) else None
        if sweep is not None and sweep.rows is not None:  # still poses held over a temperature change
            return sweep, None
        return sweep, calibrate_accelerometer(config, sweep.recording if sweep is not None else None)
    except ImucalError as exc:
        if exc.field != "intervals":
            raise
        raise ImucalError(f"discover fits interval means: {exc.message}", file=exc.file, field=exc.field,
                          fix="record more static orientations (e.g. 18 to 30 holds of 3 s)") from None


def _cut_hold_steps(config: RunConfig, base: CalibrationRun, settings: DiscoverSettings,
                    notes: list[str]) -> tuple[RunConfig, CalibrationRun, tuple[Cut, ...]]:
    """The run file and base calibration with every still interval whose mean moved within it cut there
    (static.split): a step during a hold, which would leave one interval between the two biases."""
    rec, iv = base.recording, base.intervals
    if not settings.scan_holds:
        return config, base, ()
    if getattr(rec, "raw", None) is None:  # read in chunks
        notes.append("steps inside the still intervals not scanned: the recording was read in chunks")
        return config, base, ()
    if not base.hold_steps:  # (the pipeline's scan, at HOLD_ALPHA: discover's default level)
        return config, base, ()
    g, b = base.calibration.gravity, base.guess.b
    cuts = tuple(Cut(s, reading(s, iv, b, g), float(iv.t_start[s.interval]), float(iv.t_end[s.interval]))
                 for s in base.hold_steps)
    notes += [f"{hold_step_words(s, iv, b, g)}: cut there, its two sides are intervals of their own (static.split)"
              for s in base.hold_steps]
    cut = dataclasses.replace(config, static=dataclasses.replace(
        config.static, split=config.static.split + tuple(s.time for s in base.hold_steps)))
    return cut, calibrate_accelerometer(cut, rec), cuts


def _check_room(base: CalibrationRun) -> None:
    iv, src = base.intervals, base.recording.source
    n_free0 = len(base.result.free_names)
    if iv.n - (n_free0 + 1) < MIN_DOF:
        raise ImucalError(f"{iv.n} static intervals are too few to test effects: the base model has {n_free0} free "
                          f"parameters, one effect coefficient more needs at least {n_free0 + 1 + MIN_DOF} intervals",
                          file=src, field="intervals", fix="record more static orientations (e.g. 18 to 30 holds of 3 s)"
                          + (_sweep_words(base) if n_free0 < len(BASE_NAMES) else ""))  # a run file held some: a sweep?


def _sweep_words(base: CalibrationRun) -> str:
    """Why a log of few poses was not taken as a temperature sweep (imucal.thermal.evidence.SWEEP_SPAN), for the
    refusal's fix: no temperature read, or none of its still poses spans the temperature change a sweep needs."""
    rec, iv = base.recording, base.intervals
    temp = getattr(rec, "temp", None)
    if temp is None:
        return ("; a temperature sweep's few poses need its temperature (data.columns.temp in degC, or a netCDF "
                "variable with units degC)")
    span = max((float(np.ptp(temp[a:b])) for a, b in zip(iv.start, iv.end) if b > a), default=0.0)
    return (f"; a temperature sweep needs a still pose that spans {SWEEP_SPAN:g} degC, and this log's span at "
            f"most {span:.3g} degC")


def _tested_config(config: RunConfig, notes: list[str]) -> RunConfig:
    """The run file discovery fits with: weights by the noise alone (its tests weigh the residual against
    the noise), on interval means."""
    if config.fit.weights == "auto":
        config = dataclasses.replace(config, fit=dataclasses.replace(config.fit, weights="noise"))
    if config.fit.mode != "means":
        notes.append("discovery works on interval means; fit.mode: samples was ignored")
        config = dataclasses.replace(config, fit=dataclasses.replace(config.fit, mode="means"))
    return config


def _calibrated(config: RunConfig, base: CalibrationRun, st: State, settings: DiscoverSettings,
                notes: list[str]) -> tuple[CalibrationRun, State]:
    """The final calibration of what was found, less what it refuses and what a random walk explains."""
    try:
        final = final_run(config, base, st, notes)
    except ImucalError as exc:  # the calibration refuses the model found (e.g. a parameter undetermined)
        notes.append(f"the calibration with {', '.join(labels([f[0] for f in st.found], st.effects))} was "
                     f"refused: {exc.message}")
        return base, dataclasses.replace(st, found=[], effects={}, shortfall=Shortfall.REFUSED)
    rivals, effects = noise.rivals(final, st.found, st.effects, settings)
    st = dataclasses.replace(st, rivals=rivals)
    if effects == st.effects:
        return final, st
    st = dataclasses.replace(st, found=[f for f in st.found if f[0] in effects], effects=effects,
                             shortfall=Shortfall.RANDOM_WALK)
    return final_run(config, base, st, notes), st


def _found_effects(prob: Problem, final: CalibrationRun, st: State, settings: DiscoverSettings,
                   notes: list[str]) -> tuple[FoundEffect, ...]:
    """The effects kept, with their coefficients at the final calibration, the axes not ruled out, a
    step's time and uncertainty, and a cross-axis term's observable sum."""
    last = {n: (lr, p, amb) for n, lr, p, amb in st.found}
    out = []
    for n, ax in sorted(st.effects.items(), key=lambda kv: EFFECT_ORDER[kv[0]]):
        if n not in last:
            continue
        unresolved = ax_.unresolved(prob, final.result, st.effects, n, settings.penalty, notes)
        e = found_effect(n, ax, final.result, *last[n], tuple(unresolved))
        if make_effect(n, ax).given_names:
            e = dataclasses.replace(e, change_point=change_point(prob, final.result, st.effects, n))
        if not EFFECTS[n].axes_observable:
            e = dataclasses.replace(e, observable_sum=ax_.observable_sum(n, ax, final.result))
        out.append(e)
    return tuple(out)


def _kept(asked: RunConfig, config: RunConfig, st: State, p_after: float, settings: DiscoverSettings,
          notes: list[str]) -> CalibrationRun | None:
    """With weights auto asked and the residual above the noise: the calibration with those weights."""
    if asked.fit.weights != "auto" or p_after >= settings.alpha_noise:
        return None
    try:
        auto = dataclasses.replace(config, fit=dataclasses.replace(config.fit, weights="auto"))
        return calibrate_accelerometer(final_config(auto, st.effects, st.current) if st.found else auto)
    except ImucalError as exc:
        notes.append(f"the calibration with weights auto was refused ({exc.message}); the one kept has weights noise")
        return None


def _sensors_left(recording) -> list[str]:
    """The note that the gyroscope's and magnetometer's columns a recording has are not in discover's result."""
    left = [f"the {n} ({c})" for n, c, a in (("gyroscope", "gx, gy, gz", "gyro"), ("magnetometer", "mx, my, mz", "mag"))
            if getattr(recording, a, None) is not None]
    return [f"{' and '.join(left)} not searched and not in the calibration written: discover looks at the "
            "accelerometer; give the effects it names to `imucal calibrate` (fit.effects in the run file) for a "
            "calibration of every sensor"] if left else []


def discover(config: RunConfig, settings: DiscoverSettings = DiscoverSettings(),
             progress: Callable[[], None] | None = None) -> Discovery:
    """Fit the base model, test its residual against the noise, add effects while they are needed.

    ``progress`` is called after every candidate fit (imucal.report.progress)."""
    notes: list[str] = []
    asked, config = config, _tested_config(config, notes)
    sweep, base = _start(config, settings)
    if base is None:
        return sweep_discovery(asked, sweep, settings, progress)
    config, base, cuts = _cut_hold_steps(config, base, settings, notes)
    prob = Problem(config, base, progress)
    notes += _sensors_left(base.recording)
    names = testable(list(settings.candidates), base.intervals, base.recording.source, notes)
    _check_room(base)
    p_before = p_noise(base.result)
    st = backward(prob, search(prob, names, settings, notes, p_before), settings, notes)
    final, st = _calibrated(config, base, st, settings, notes)
    found = {f[0] for f in st.found}
    ax_.axis_notes(st.effects, found, final, notes)
    last = {n: (lr, p, amb) for n, lr, p, amb in st.found}
    effects = _found_effects(prob, final, st, settings, notes)
    p_after = p_noise(final.result)
    sto = noise.assess(final, settings)
    in_temp = st.shortfall is Shortfall.SHAPE and "temp" in st.shape_covariates
    if sto is not None and sto.named and in_temp:  # structure in temperature no stochastic bias of time explains
        sto = dataclasses.replace(sto, named=(), withheld=sto.named, chosen=sto.fits["none"], ambiguous=False,
                                  notes=sto.notes + (IN_TEMPERATURE,))
    kept = _kept(asked, config, st, p_after, settings, notes)
    res = final.result
    verdict = decide(p_before >= settings.alpha_noise, p_after >= settings.alpha_noise,
                     tuple(e.label for e in effects), st.shortfall, res.redchi, p_after,
                     shape_covariates=st.shape_covariates, max_effects=settings.max_effects,
                     excess_rms=math.sqrt(between_excess(res.residuals, res.sigma, res.dof)) if sto is None else math.nan,
                     stochastic=stochastic_part(sto, in_temp),
                     weights=str((kept or final).calibration.fit.get("weights", config.fit.weights)))
    return Discovery(base=base, final=final, steps=tuple(st.steps), effects=effects, verdict=verdict, kept=kept,
                     consistent_before=p_before >= settings.alpha_noise,
                     consistent_after=p_after >= settings.alpha_noise, p_before=p_before, p_after=p_after,
                     disagreement=tuple(st.disagreement), notes=tuple(notes) + (sto.notes if sto else ()),
                     settings=settings, stochastic=sto, allan=stoch.allan_view(final, sto), rivals=st.rivals,
                     holds_cut=cuts)
