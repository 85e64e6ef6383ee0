"""The thermal calibration of a recording that holds still poses over a temperature sweep.

``thermal_calibration(config, base)``: the base fit (|a| = g on the still intervals, with what the
run file holds: imucal.pipeline.calibrate_accelerometer) gives the parameters at the reference temperature; the
pose-constancy rows (imucal.thermal.evidence) give the temperature terms, their orders chosen by
the grammar's test (imucal.thermal.select); the lag and hysteresis of the temperature sensor are
tested (imucal.thermal.lag). The calibration kept is the base fit once more with the terms held
at their values (``pipeline.calibrate_accelerometer(held=...)``), so the file, ``apply``, the generated C and the
autopilot exports carry them, with the pose fit's standard errors. The gyroscope's bias(T), from the
same rows (imucal.thermal.gyro), is attached as the calibration's gyroscope (on fit.base's), so they
carry it too.

``imucal discover`` takes this path when the recording is such a sweep (``sweep_of``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from imucal.config.run import EffectSpec, RunConfig
from imucal.data.load import use_stream
from imucal.data.recording import Recording
from imucal.data.static import Intervals
from imucal.errors import ImucalError
from imucal.gyro.thermal import GyroThermal
from imucal.model.effects import AXIS_NAMES, EFFECTS, make_effect
from imucal.model.parameters import ANGLE_NAMES, BASE_NAMES, Parameters
from imucal.model.sensor import build_model
from imucal.pipeline import CalibrationRun, calibrate_accelerometer, initial_guess, make_parameters, read_intervals
from imucal.solve.stats import chi2_sf
from imucal.thermal.determine import PoseSupport, one_sided
from imucal.thermal.evidence import ThermalRows, thermal_rows
from imucal.thermal.gyro import gyro_base, sweep_gyro
from imucal.thermal.lag import LagTest, lag_and_hysteresis
from imucal.thermal.select import Selection, ThermalProblem, select


@dataclass(frozen=True)
class Sweep:
    """A recording read for a run, its still intervals, and their temperature rows (None: no sweep)."""

    config: RunConfig
    recording: Recording
    intervals: Intervals
    rows: ThermalRows | None


def sweep_of(config: RunConfig) -> Sweep | None:
    """The run's recording and intervals, with rows when it is a temperature sweep: a still pose spans a
    temperature change (at least imucal.thermal.evidence.SWEEP_SPAN) and the poses are too few for
    |a| = g to determine the model (fewer distinct orientations than its nine parameters: the run file
    holds what they cannot). A multi-pose log keeps discovery's |a| = g path, its temperature changing
    across the poses. None for a file read in chunks (no samples kept)."""
    if use_stream(config.data, config.base_dir):
        return None
    rec, iv, _ = read_intervals(config)
    rows = thermal_rows(rec, iv)
    if rows is None or not rows.is_sweep:
        return Sweep(config, rec, iv, None)
    gravity, _ = config.gravity.resolve()
    _, _, n_distinct = initial_guess(iv, gravity, False, rec.source)
    return Sweep(config, rec, iv, rows if n_distinct < len(BASE_NAMES) else None)


@dataclass(frozen=True)
class ThermalCalibration:
    """What the temperature sweep determined, and the calibration that carries it."""

    rows: ThermalRows
    selection: Selection
    support: PoseSupport
    lag: LagTest
    final: CalibrationRun
    base: CalibrationRun | None  #: the fit without temperature terms (None: refused, the terms are needed)
    base_refusal: str  #: why it was refused
    one_sided: tuple[int, ...]  #: axes that meet gravity one way only: s_i and b_i at T_ref not told apart
    held: tuple[str, ...]  #: base parameters the run file held
    #: the gyroscope's bias(T) from the same rows (imucal.gyro.thermal) [rad/s], when the recording has one in
    #: a rate unit or fit.base has a gyroscope; the calibration's gyroscope section carries it (imucal.thermal.gyro)
    gyro: GyroThermal | None = None
    gyro_note: str = ""  #: why a recorded gyroscope got no section (counts without a base), else ""

    @property
    def effects(self) -> dict[str, tuple[int, ...]]:
        return self.selection.effects

    @property
    def rms_before(self) -> float:
        """[m/s^2] RMS of the rows about their poses without temperature terms."""
        return self.selection.none.rms

    @property
    def rms_after(self) -> float:
        return self.selection.fit.rms

    @property
    def temperature_range(self) -> tuple[float, float]:
        return float(self.rows.temp.min()), float(self.rows.temp.max())

    def p_noise(self, after: bool = True) -> float:
        f = self.selection.fit if after else self.selection.none
        return chi2_sf(f.chi2, f.dof) if f.dof > 0 else 1.0


def _held_values(sel: Selection, prob: ThermalProblem) -> dict[str, float]:
    """The terms' coefficients and their references (T_ref and the orthogonal-polynomial constants)."""
    _, params = prob.parameters(sel.effects)
    out = {}
    for e in prob.model(sel.effects).effects:
        for n in (*e.coefficient_names, *e.reference_names):
            out[n] = float(sel.fit.params[n].value) if n in sel.fit.params.names else float(params[n].value)
    return out


def _final(config: RunConfig, rec: Recording, sel: Selection, prob: ThermalProblem) -> CalibrationRun:
    """The base fit with the terms held at the pose fit's values; the coefficients then carry the pose
    fit's standard errors and are marked free (they were fitted, to the poses)."""
    order = {n: i for i, n in enumerate(EFFECTS)}
    specs = tuple(EffectSpec(n, tuple(AXIS_NAMES[a] for a in ax))
                  for n, ax in sorted(sel.effects.items(), key=lambda kv: order[kv[0]]))
    run = calibrate_accelerometer(replace(config, fit=replace(config.fit, effects=specs)), rec,
                                  held=_held_values(sel, prob))
    if not sel.effects:
        return run
    coef = set(sel.fit.free_names)
    params = Parameters(replace(p, fixed=False) if n in coef else p for n, p in run.result.params.items())
    std = {**run.result.std, **{n: sel.fit.std[n] for n in coef}}
    fit = {**run.calibration.fit, "temperature_terms": "pose constancy over the temperature sweep "
                                                      "(imucal.thermal), standard errors scaled by chi2/dof",
           # the range the terms were fitted over (the exports write it: INS_TCAL1_TMIN ...), the rows' own
           "temperature_range": fit_range(prob.rows)}
    cal = replace(run.calibration, params=params, std=std, fit=fit)
    return replace(run, result=replace(run.result, params=params, std=std), calibration=cal)


def start_parameters(config: RunConfig, iv: Intervals, source: str, unit: str) -> Parameters:
    """The base parameters the pose fit holds before |a| = g has been fitted: the pipeline's own start
    (the ellipsoid guess, or the run file's fix and initial values)."""
    gravity, _ = config.gravity.resolve()
    angles_free = not set(ANGLE_NAMES) <= set(config.fit.fix)
    guess, _, _ = initial_guess(iv, gravity, angles_free, source)
    return make_parameters(guess, config, gravity, build_model(()), unit)


def thermal_calibration(sweep: Sweep, progress: Callable[[], None] | None = None,
                        alpha: float = 1e-3) -> ThermalCalibration:
    """The temperature terms of a sweep (module docstring) and the calibration that holds them: the
    terms chosen at the pipeline's start, then the pose fit repeated once at the base fit's values."""
    config, rec, rows = sweep.config, sweep.recording, sweep.rows
    prob = ThermalProblem(rows, start_parameters(config, sweep.intervals, rec.source, rec.unit), rec.source, progress)
    sel = select(prob, alpha=alpha)
    final = _final(config, rec, sel, prob)
    prob = ThermalProblem(rows, final.result.params, rec.source, progress)  # at the fitted shifts
    sel = replace(sel, fit=prob.fit(sel.effects, sel.fit.params.value_dict()), none=prob.fit({}))
    final = _final(config, rec, sel, prob)
    try:
        base, refusal = calibrate_accelerometer(config, rec), ""
    except ImucalError as exc:
        base, refusal = None, exc.message
    support = PoseSupport.of(rows, sel.fit.vectors, sel.fit.poses)
    held = tuple(n for n in BASE_NAMES if n in config.fit.fix)
    acc = final.calibration.apply(rows.raw, {"temp": rows.temp, "time": rows.t})
    gyro = sweep_gyro(rows, rec.gyro_unit, acc, gyro_base(config, rec.gyro_unit), fit_range(rows), alpha)
    if gyro.section is not None:
        final = replace(final, calibration=replace(final.calibration, attached=(gyro.section,)))
    return ThermalCalibration(rows=rows, selection=sel, support=support, lag=lag_and_hysteresis(prob, sel, rec, alpha),
                              final=final, base=base, base_refusal=refusal,
                              one_sided=tuple(one_sided(final.directions)), held=held, gyro=gyro.fit,
                              gyro_note=gyro.note)


def fit_range(rows: ThermalRows) -> list[float]:
    """[degC] the rows' temperature range: the terms' (the autopilots' TMIN, TMAX)."""
    return [float(rows.temp.min()), float(rows.temp.max())]


def found_label(effects: dict[str, tuple[int, ...]]) -> str:
    order = {n: i for i, n in enumerate(EFFECTS)}
    return ", ".join(f"{n}[{''.join(AXIS_NAMES[a] for a in ax)}]"
                     for n, ax in sorted(effects.items(), key=lambda kv: order[kv[0]]))


def coefficient_std(tc: ThermalCalibration, name: str, axes: tuple[int, ...]) -> dict[str, float]:
    e = make_effect(name, axes)
    return {n: float(tc.selection.fit.std.get(n, math.nan)) for n in e.coefficient_names}


def first_added(tc: ThermalCalibration) -> dict[str, tuple[float, float]]:
    """term name -> (LR, adjusted p) of the round that first added it."""
    out: dict[str, tuple[float, float]] = {}
    for r in tc.selection.rounds:
        if r.chosen is not None and r.chosen.name not in out:
            out[r.chosen.name] = (r.chosen.lr, r.chosen.p_adjusted)
    return out


def axis_rms(tc: ThermalCalibration, after: bool = True) -> np.ndarray:
    """[m/s^2] per axis, RMS of the rows about their poses."""
    f = tc.selection.fit if after else tc.selection.none
    return np.sqrt(np.mean(f.residuals ** 2, axis=0))
