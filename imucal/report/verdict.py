"""The verdict on a calibration: one per sensor the calibration holds, and the page's, as typed values
(report/html.py renders them).

A sensor's verdict is made from its checks and its own warnings, and its headline states the numbers
its checks state (the accelerometer's reduced chi-square is the one against the noise that its
residual check tests, never the weighted fit's 1): PASS when every check passes and nothing is
warned, FAIL when the solver did not converge, CHECK otherwise. The page's level is its worst sensor's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from imucal.pipeline import CalibrationRun, fit_warnings, taken_warnings
from imucal.solve.misfit import POOR_FIT_P, POOR_FIT_REDCHI, excess_residuals
from imucal.solve.stats import chi2_sf

PASS, CHECK, FAIL = "pass", "check", "fail"
LEVEL_WORDS = {PASS: "PASS", CHECK: "CHECK: usable, read the warnings", FAIL: "FAIL: the solver did not converge"}
_ORDER = (PASS, CHECK, FAIL)


@dataclass(frozen=True)
class Check:
    """One line of a verdict: what was checked, whether it passed (None: cannot tell), details."""

    what: str
    ok: bool | None
    detail: str


@dataclass(frozen=True)
class SensorVerdict:
    """One sensor's checks, warnings and level, and the facts its headline states."""

    sensor: str  #: accelerometer, gyroscope
    checks: tuple[Check, ...]
    warnings: tuple[str, ...]
    summary: str  #: the headline's numbers (each is also in a check's detail)
    converged: bool

    @property
    def level(self) -> str:
        if not self.converged:
            return FAIL
        return PASS if all(c.ok is True for c in self.checks) and not self.warnings else CHECK

    @property
    def headline(self) -> str:
        return f"{self.sensor.capitalize()}: {LEVEL_WORDS[self.level].split(':')[0]} ({self.summary})"


@dataclass(frozen=True)
class Verdict:
    """The page's verdict: every sensor's, and the worst level of them."""

    sensors: tuple[SensorVerdict, ...]

    @property
    def level(self) -> str:
        return max((s.level for s in self.sensors), key=_ORDER.index)

    @property
    def headline(self) -> str:
        return LEVEL_WORDS[self.level] + "".join(f"; {s.headline}" for s in self.sensors)

    @property
    def checks(self) -> tuple[Check, ...]:
        return tuple(c for s in self.sensors for c in s.checks)

    @property
    def warnings(self) -> tuple[str, ...]:
        return tuple(w for s in self.sensors for w in s.warnings)


def chi2_consistent(chi2: float, dof: int) -> tuple[bool | None, float]:
    """Whether chi-square on ``dof`` is consistent with the noise (the rule of every fit's warning,
    imucal.solve.misfit: poor when reduced chi-square > POOR_FIT_REDCHI and p < POOR_FIT_P), and its p."""
    if dof <= 0 or not math.isfinite(chi2):
        return None, math.nan
    return excess_residuals(chi2, dof) is None, chi2_sf(chi2, dof)


def _residual_check(chi2: float, dof: int, extra: str = "") -> Check:
    consistent, p = chi2_consistent(chi2, dof)
    return Check("residuals consistent with the noise", consistent,
                 "cannot be tested: 0 degrees of freedom" if consistent is None else
                 f"reduced chi-square {chi2 / dof:.3g} against the noise (chi-square {chi2:.4g} on {dof} dof, "
                 f"p = {p:.3g}; poor when above {POOR_FIT_REDCHI:g} with p < {POOR_FIT_P:g}){extra}")


def _bound_check(at_bound: dict[str, str]) -> Check:
    return Check("no parameter at a bound", not at_bound,
                 "; ".join(f"{n} at its {b} bound" for n, b in at_bound.items()) or "all inside their bounds")


def taken_words(taken: dict) -> tuple[str, str]:
    """Where a taken accelerometer (imucal.pipeline.taken_whole; the file's fit.taken) came from, in words: its
    name, and what was taken with the file's digest, or that the run file stated the values."""
    if "base" in taken:
        return str(taken["base"]), f"its values and standard errors (sha256 {taken.get('sha256', '')})"
    return "the run file's fit.fix values", "as stated (a log its device already corrected), standard errors 0"


def _taken_verdict(run: CalibrationRun) -> SensorVerdict:
    """An accelerometer taken from fit.base or the run file (imucal.pipeline.taken_whole): no fit to judge; this
    log's still intervals, when it has some, check it."""
    cal, iv = run.calibration, run.intervals
    name, what = taken_words(cal.fit["taken"])
    warnings = tuple(taken_warnings(name, cal.fit["chi2"], iv.n, cal.fit["rms_residual"]) if iv.n else ())
    agree = not warnings
    checks = (
        Check(f"taken from {name}", True, what),
        Check("this log's still intervals agree with it", agree,
              f"{iv.n} intervals, reduced chi-square {cal.fit['redchi']:.3g}, RMS |a| − g "
              f"{cal.fit['rms_residual'] * 1e3:.3g} mm/s²" if iv.n else "no still interval in this log: not checked"),
    )
    summary = f"taken from {name}, not fitted" + (f"; checked on {iv.n} still intervals" if iv.n else "")
    return SensorVerdict("accelerometer", checks, warnings, summary, True)


def accelerometer_verdict(run: CalibrationRun) -> SensorVerdict:
    res, cal, obs = run.result, run.calibration, run.observability
    if "taken" in cal.fit:
        return _taken_verdict(run)
    dropped = list(cal.data.get("dropped_intervals", []))
    held = (f"; the standard errors include a between-interval excess of {res.excess ** 0.5:.3g} m/s^2 rms "
            "(bias_instability)" if res.excess > 0 else "")
    checks = (
        Check("IPOPT converged", res.success, f"{res.status_words}; {res.iterations} iterations"),
        _residual_check(res.chi2_noise, res.dof, held),
        Check("every parameter determined by the poses", not obs.poorly_determined,
              f"{obs.n_distinct} distinct orientations; Jacobian condition {obs.condition:.3g}"
              + ("; poorly determined: " + ", ".join(obs.poorly_determined) if obs.poorly_determined else "")),
        _bound_check(res.at_bound),
        Check("no static interval dropped", not dropped,
              f"{len(dropped)} dropped because an axis was clipped" if dropped else
              f"{run.intervals.n} static intervals used"),
    )
    red = f"reduced chi-square {res.redchi_noise:.3g} against the noise" if res.dof > 0 else "0 degrees of freedom"
    summary = f"RMS |a| − g {cal.fit['rms_residual'] * 1e3:.3g} mm/s² on {run.intervals.n} interval means, {red}"
    warnings = tuple(fit_warnings(res, run.config, run.recording, dropped))
    return SensorVerdict("accelerometer", checks, warnings, summary, res.success)


def gyroscope_verdict(run: CalibrationRun) -> SensorVerdict:
    from imucal.gyro.result import motions  # only a run with a gyroscope
    from imucal.report.gyro import gyro_warnings

    res = run.gyro
    assert res is not None
    m = motions(res)
    r = m.rms_direction_error_deg
    rejected = 0 if m.still is None else len(m.still.rejected)
    checks = (
        Check("IPOPT converged", res.success, f"{res.status_words}; {res.iterations} iterations"),
        _residual_check(res.chi2, res.dof),
        Check("the calibration aligns the motions", r["after"] < r["before"],
              f"gravity-direction error {r['before']:.3f}° rms before, {r['after']:.3f}° after, over "
              f"{m.segments.size} motions"),
        _bound_check(res.at_bound),
        Check("every motion integrated", not m.gapped,
              f"{len(m.gapped)} motion(s) left out: a gap in the time stamps inside each" if m.gapped else
              f"{m.segments.size} motions" + (f"; {rejected} static interval(s) turning for the gyro, not used as "
                                                "still poses" if rejected else "")),
    )
    summary = (f"gravity-direction error {r['after']:.3f}° rms over {m.segments.size} motions "
               f"({r['before']:.3f}° before), reduced chi-square {res.redchi:.3g} against the noise")
    return SensorVerdict("gyroscope", checks, tuple(gyro_warnings(res)), summary, res.success)


#: The field-norm residual after calibration passes when within this factor of its noise floor (the readings'
#: noise propagated to |h|): more is soft iron or a disturbance the model does not hold.
NORM_FLOOR_FACTOR = 2.0


def magnetometer_verdict(run: CalibrationRun) -> SensorVerdict:
    from imucal.report.mag import mag_warnings  # only a run with a magnetometer

    cal = run.mag
    assert cal is not None
    n, d = cal.report.norm_pct, cal.report.dip_deg
    steps = cal.steps
    checks = [
        Check("IPOPT converged", cal.fit.success, f"{cal.fit.status}; {cal.fit.iterations} iterations"),
        Check("field-norm residual near the noise floor", n.after <= NORM_FLOOR_FACTOR * n.floor,
              f"{n.after:.3g} % of the field rms after ({n.before:.3g} % before), noise floor {n.floor:.2g} %"),
        Check("the field's magnitude steady between poses", None if steps is None else not steps.disturbed,
              "not tested" if steps is None else
              f"step test p = {steps.p:.3g}; {len(steps.outliers)} pose(s) standing out"),
    ]
    if d is not None:
        checks.append(Check("the calibration steadies the dip angle", d.after <= d.before,
                            f"dip scatter {d.after:.3g}° after, {d.before:.3g}° before (floor {d.floor:.2g}°)"))
    summary = f"field-norm residual {n.after:.3g} % ({n.before:.3g} % before)" + (
        f", dip scatter {d.after:.3g}° ({d.before:.3g}° before)" if d is not None else "")
    return SensorVerdict("magnetometer", tuple(checks), tuple(mag_warnings(cal)), summary, cal.fit.success)


def verdict(run: CalibrationRun) -> Verdict:
    """The verdict of every sensor the run calibrated."""
    sensors = [accelerometer_verdict(run)]
    if run.gyro is not None:
        sensors.append(gyroscope_verdict(run))
    if run.mag is not None:
        sensors.append(magnetometer_verdict(run))
    return Verdict(tuple(sensors))
