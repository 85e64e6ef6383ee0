"""Calibrate a magnetometer from a log turned through many orientations (still or moving).

  1. noise of both sensors from the log (imucal.mag.evidence.sample_variance)
  2. initial guess: the accelerometer's linear ellipsoid fit (imucal.solve.initial) on the readings
  3. coverage: refuse directions that leave the hard and soft iron undetermined (imucal.mag.checks)
  4. with an accelerometer: the lag, the poses (still intervals and the quiet windows between them, or the
     quiet windows alone when fewer than MIN_STILL_POSES are still), the mounting
     (imucal.mag.frame: the 24 signed permutations, refined in closed form)
  5. the fit of every row (imucal.mag.fit), with and without the rotation, and the F test between them
  6. the field's steps between poses, and the figures before and after (imucal.mag.result)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imucal.errors import ImucalError
from imucal.mag import evidence as ev
from imucal.mag.checks import PoseOffset, coverage_error, field_steps, require_coverage, require_span
from imucal.mag.fit import MagFitResult, SoftIronTest, fit_rows, soft_iron_test
from imucal.mag.frame import AxesSearch, dip_angles, euler_angles, search_axes
from imucal.mag.model import (DIP, IDENTITY, NORM, ROTATION_BOUND, ROTATION_NAMES, build_mag_model,
                              mag_parameters, vectorized)
from imucal.mag.result import MagCalibration, MagReport, PoseFigures, Scatter
from imucal.mag.field_model import EarthField, Place
from imucal.mag.units import field_magnitude, field_ratio_error, is_field_unit
from imucal.model.parameters import BASE_NAMES, Parameters
from imucal.model.sensor import SensorModel
from imucal.solve.initial import ellipsoid_guess

SOFT_IRON_CHOICES = ("auto", "symmetric", "full")
#: Samples the initial ellipsoid fit looks at (evenly spaced): a linear fit, its cost linear in them.
GUESS_ROWS = 20000
#: Still intervals used for the dip (beside the quiet windows between them) when there are at least this many;
#: else the quiet windows of a moving log alone.
MIN_STILL_POSES = 6
#: A pose whose accelerometer magnitude is off the poses' median by more than this fraction is moving
#: (linear acceleration tilts the apparent gravity): not a DIP row.
MAX_ACC_DEVIATION = 0.05
#: Poses whose field stands out that are left out of the fit, the worst first, one a round.
MAX_EXCLUDED = 3
#: DIP rows needed for the rotation and the dip (4 unknowns, and the scatter that weighs them).
MIN_DIP_ROWS = 8


@dataclass(frozen=True)
class MagSettings:
    """How to calibrate (the run file's ``mag:`` section fills it)."""

    field: float | None = None  #: the field's magnitude F (None: fitted, the scales' overall size held)
    field_unit: str | None = None  #: F's unit (None: the sensor's); uT, nT, gauss, mG ...
    dip_deg: float | None = None  #: the dip angle asin(a . h / |a||h|) held [deg] (None: fitted)
    size: float = 1.0  #: the scales' geometric mean held when F is fitted [raw per field unit]
    soft_iron: str = "auto"  #: auto (the F test), symmetric or full
    window: int = 25  #: samples per window of a moving log (the dip's poses)
    lag: float | None = None  #: the magnetometer's delay [samples] (None: estimated)
    place: Place | None = None  #: where and when: F from the IGRF when ``field`` is not given (optional extra)

    def __post_init__(self) -> None:
        if self.soft_iron not in SOFT_IRON_CHOICES:
            raise ImucalError(f"soft_iron {self.soft_iron!r} is not a choice", field="mag.soft_iron",
                              fix=f"use one of {', '.join(SOFT_IRON_CHOICES)}")
        if not (isinstance(self.window, int) and self.window >= 4):
            raise ImucalError(f"window {self.window!r} must be at least 4 samples", field="mag.window",
                              fix="give a whole number of samples, 4 or more")
        if not (self.size > 0 and math.isfinite(self.size)):
            raise ImucalError(f"size {self.size!r} must be positive", field="mag.size",
                              fix="give a positive, finite number")


def _guess(mag: np.ndarray, F: float | None, size: float, source: str | None):
    """(s, b, angles, F) from the linear ellipsoid fit; F fitted: the scales' geometric mean at ``size``."""
    pick = np.linspace(0, len(mag) - 1, min(len(mag), GUESS_ROWS)).astype(int)
    try:
        g = ellipsoid_guess(mag[pick], 1.0 if F is None else F, source=source)
    except ImucalError:  # no ellipsoid at all: name the directions (about the readings' mid-range)
        mid = 0.5 * (mag.min(axis=0) + mag.max(axis=0))
        raise coverage_error(mag[pick] - mid, "leave the hard and soft iron", source) from None
    b = np.asarray(g.b, float)
    if F is None:  # |h| = 1 with b: with b k, |h| = 1 / k
        k = size / float(np.prod(b)) ** (1 / 3)
        return g.s, b * k, g.angles, 1.0 / k
    return g.s, b, g.angles, F


def _held(params: Parameters, names) -> Parameters:
    return params.with_fixed([n for n in names if n in params])


@dataclass(frozen=True)
class _DipSetup:
    """What the dip needs: the lag, the poses and their DIP rows, the mounting, the start of the rotation."""

    lag: ev.Lag
    poses: ev.Poses
    rows: ev.MagRows
    search: AxesSearch
    params: Parameters  #: with the rotation and dip started from the closed form
    steps: ev.Poses  #: the poses the report and the field's step test go by: the still ones when used, else all


def _dip_setup(mag: np.ndarray, acc: np.ndarray, still: ev.Poses | None, params: Parameters, settings: MagSettings,
               var_m: np.ndarray, use: np.ndarray, source: str | None) -> _DipSetup:
    """The lag, the poses (``dip_poses``), their DIP rows and the mounting."""
    p0 = np.array(params.values(), float)
    lag = ev.Lag(float(settings.lag), 0.0, False) if settings.lag is not None else ev.estimate_lag(mag - p0[:3], acc)
    mag_d = ev.shift(mag, lag.samples)
    poses, from_still = dip_poses(ev.quiet_windows(mag_d - p0[:3], settings.window), still)
    keep = poses.inside(use)
    an = np.linalg.norm(poses.means(acc), axis=1)
    keep &= np.abs(an / np.median(an[keep] if keep.any() else an) - 1) <= MAX_ACC_DEVIATION
    poses, from_still = poses.subset(keep), from_still[keep]
    if poses.n < MIN_DIP_ROWS:
        raise ImucalError(f"only {poses.n} poses for the dip angle", file=source, field="ax, ay, az",
                          fix=f"hold the sensor still in at least {MIN_DIP_ROWS} orientations, or turn it slowly")
    rows = ev.dip_rows(mag_d, acc, poses, var_m, ev.sample_variance(acc))
    h0 = np.asarray(vectorized(build_mag_model(), "field")(rows.raw.T, p0)[0]).T
    search = search_axes(rows.cov[:, 1:], h0)
    P = np.array(search.best.axes, float).reshape(3, 3)
    r0 = euler_angles(search.closed_form.rotation @ P.T) if search.agrees else (0.0, 0.0, 0.0)
    start = dict(zip(ROTATION_NAMES, (float(np.clip(v, -ROTATION_BOUND, ROTATION_BOUND)) for v in r0)))
    if params["dip"].free:  # the poses' mean dip in the found frame
        start["dip"] = float(np.mean(dip_angles(rows.cov[:, 1:], h0 @ P.T)))
    return _DipSetup(lag, poses, rows, search, params.with_values(start),
                     poses.subset(from_still) if from_still.any() else poses)


def dip_poses(quiet: ev.Poses, still: ev.Poses | None) -> tuple[ev.Poses, np.ndarray]:
    """The dip's poses, and which of them are still intervals: the still intervals (when at least
    MIN_STILL_POSES) and the quiet windows that overlap none of them, in time order. A hand-turned log is rarely
    still: most of its dip evidence is in the windows between its few still parts (CK-Explorer's log: 19 still
    intervals, some 300 quiet windows)."""
    if still is None or still.n < MIN_STILL_POSES:
        return quiet, np.zeros(quiet.n, bool)
    hit = (quiet.start[:, None] < still.end[None, :]) & (quiet.end[:, None] > still.start[None, :])
    apart = quiet.subset(~hit.any(axis=1))
    start, end = np.concatenate([still.start, apart.start]), np.concatenate([still.end, apart.end])
    order = np.argsort(start, kind="stable")
    source = still.source if not apart.n else f"{still.source} and {apart.n} {quiet.source} between them"
    return ev.Poses(start[order], end[order], source), np.arange(start.size)[order] < still.n


def _fits(model: SensorModel, rows: ev.MagRows, params: Parameters, settings: MagSettings, dip: bool,
          source: str | None) -> tuple[MagFitResult, MagFitResult | None, SoftIronTest | None]:
    """The full and the symmetric fit, the test between them, and the chosen one (without DIP rows: the
    ellipsoid alone, its rotation and dip held)."""
    if not dip:
        return fit_rows(model, rows, _held(params, [*ROTATION_NAMES, "dip"]), source=source), None, None
    full = fit_rows(model, rows, params, source=source)
    sym = fit_rows(model, ev.MagRows.stack(rows, ev.skew_rows()), full.params, factors=full.factors, source=source)
    test = soft_iron_test(full, sym)
    use_full = test.full if settings.soft_iron == "auto" else settings.soft_iron == "full"
    return (full if use_full else sym), sym, test


def _start(mag: np.ndarray, settings: MagSettings, earth: EarthField | None, raw_unit: str, source: str | None
           ) -> tuple[Parameters, str]:
    """The initial parameters (F held when given, or from the field model) and the calibrated field's unit."""
    value, unit = ((settings.field, settings.field_unit) if settings.field is not None else
                   (earth.intensity_uT, "uT") if earth is not None else (None, None))
    given = value is not None
    F, field_unit = field_magnitude(value, unit, raw_unit, source) if given else (None, raw_unit)
    if given and not is_field_unit(field_unit):  # F in the readings' own unit: near their field's size
        err = field_ratio_error(F, field_unit, _guess(mag, None, 1.0, source)[3], source)
        if err is not None:
            raise err
    s0, b0, ang0, F0 = _guess(mag, F, settings.size, source)
    dip0 = 0.0 if settings.dip_deg is None else math.radians(settings.dip_deg)
    params = mag_parameters(s0, b0, ang0, F0, dip0=dip0, raw_unit=raw_unit, field_unit=field_unit)
    return _held(params, (["F"] if given else []) + (["dip"] if settings.dip_deg is not None else [])), field_unit


def calibrate_mag(mag: np.ndarray, acc: np.ndarray | None = None, *, still: ev.Poses | None = None,
                  settings: MagSettings = MagSettings(), raw_unit: str = "raw", source: str | None = None,
                  use: np.ndarray | None = None) -> MagCalibration:
    """Hard and soft iron, the field, and (with the calibrated accelerometer ``acc``) the rotation to the
    accelerometer's frame and the dip. ``still``: the accelerometer's still intervals, if any; ``use``: the
    samples the fit may use (a mask; the rest can judge it: cross-validation), default all.

    Poses whose field stands out from the rest (``FieldSteps.outliers``: a magnet passing by) are left out,
    the worst first, and the fit repeated (up to MAX_EXCLUDED); they are named in ``excluded``. A step of
    the field (``FieldSteps.step_after``) is named, not undone: which side is the true field is unknown."""
    mag = np.asarray(mag, float)
    acc = None if acc is None else np.asarray(acc, float)
    ev.check_lengths(mag, acc, source)
    require_span(mag, source)
    use = np.ones(len(mag), bool) if use is None else np.asarray(use, bool)
    earth = settings.place.field() if settings.place is not None else None
    params, field_unit = _start(mag[use], settings, earth, raw_unit, source)
    var_m = ev.sample_variance(mag)
    nrows = ev.norm_rows(mag, var_m).subset(use)
    require_coverage(build_mag_model(), nrows, _held(params, [n for n in params.names if n not in BASE_NAMES]),
                     source)
    extra = [] if params["F"].fixed else [ev.size_row(settings.size)]
    setup = None if acc is None else _dip_setup(mag, acc, still, params, settings, var_m, use, source)
    model = build_mag_model(IDENTITY if setup is None else setup.search.best.axes, field_unit)
    params = params if setup is None else setup.params
    rows = ev.MagRows.stack(nrows, *([] if setup is None else [setup.rows]), *extra)
    step_poses = setup.steps if setup is not None else (still if still is not None and still.n >= MIN_STILL_POSES
                                                        else ev.windows(len(mag), settings.window))
    fits = _fits(model, rows, params, settings, setup is not None, source)
    steps = field_steps(step_poses.means(_norm_pct(fits[0], mag)[:, None])[:, 0] / 100.0, step_poses)
    excluded: tuple[PoseOffset, ...] = ()
    for _ in range(MAX_EXCLUDED):  # the worst pose out, the fit again (a pose far off pulls its neighbours)
        new = [o for o in steps.outliers if o.pose not in {e.pose for e in excluded}]
        if not new:
            break
        excluded += (max(new, key=lambda o: abs(o.offset)),)
        keep = _outside(rows, excluded, None if setup is None else setup.poses)
        fits = _fits(model, rows.subset(keep), params, settings, setup is not None, source)
        steps = field_steps(step_poses.means(_norm_pct(fits[0], mag)[:, None])[:, 0] / 100.0, step_poses)
    return _result(*fits, setup, steps, excluded, step_poses, mag, acc, raw_unit, field_unit,
                   not params["F"].free, earth)


def _outside(rows: ev.MagRows, offsets, dip_poses: ev.Poses | None) -> np.ndarray:
    """Rows whose samples lie outside the poses ``offsets`` (NORM rows by sample, DIP rows by overlap)."""
    keep = np.ones(rows.n, bool)
    for o in offsets:
        keep &= ~((rows.kind == NORM) & (rows.pose >= o.start) & (rows.pose < o.end))
        if dip_poses is not None:
            hit = np.flatnonzero((dip_poses.start < o.end) & (dip_poses.end > o.start))
            keep &= ~((rows.kind == DIP) & np.isin(rows.pose, hit))
    return keep


def _norm_pct(fit: MagFitResult, raw: np.ndarray) -> np.ndarray:
    p = np.array(fit.params.values(), float)
    F = fit.params["F"].value
    return 100.0 * (vectorized(fit.model, "norm")(raw.T, p)[0][0] - F) / F


def _dips(fit: MagFitResult, raw: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """Each pose's dip minus the fitted dip [deg]."""
    p = np.array(fit.params.values(), float)
    return np.degrees(vectorized(fit.model, "dip")(raw.T, acc.T, p)[0][0] - fit.params["dip"].value)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(x, float) ** 2)))


def _report(fit: MagFitResult, sym: MagFitResult | None, setup: "_DipSetup | None", poses: ev.Poses,
            mag: np.ndarray, acc: np.ndarray | None) -> MagReport:
    """The figures before and after, over the log and per pose."""
    after = _norm_pct(fit, mag)
    before = 100.0 * (np.linalg.norm(mag, axis=1) / np.mean(np.linalg.norm(mag, axis=1)) - 1.0)
    noise_only = fit.sigma / np.array([fit.factors.get(int(k), 1.0) for k in fit.kinds])
    norm = Scatter(_rms(before), _rms(after), 100.0 * _rms(noise_only[fit.kinds == NORM]) / fit.params["F"].value)
    nb, na = poses.means(before[:, None])[:, 0], poses.means(after[:, None])[:, 0]
    if setup is None or sym is None or acc is None:
        return MagReport(norm, None, tuple(PoseFigures(int(a), int(b), float(x), float(y), None, None, None)
                                           for a, b, x, y in zip(poses.start, poses.end, nb, na)))
    mp, ap = poses.means(ev.shift(mag, setup.lag.samples)), poses.means(acc)
    d_before = np.degrees(dip_angles(ap, mp))
    d_before -= d_before.mean()
    d_sym, d_after = _dips(sym, mp, ap), _dips(fit, mp, ap)
    dip = Scatter(float(np.std(d_before)), float(np.std(d_after)),
                  float(np.degrees(_rms(noise_only[fit.kinds == DIP]))), float(np.std(d_sym)))
    return MagReport(norm, dip, tuple(PoseFigures(int(poses.start[j]), int(poses.end[j]), float(nb[j]), float(na[j]),
                                                  float(d_before[j]), float(d_sym[j]), float(d_after[j]))
                                      for j in range(poses.n)))


def _result(fit, sym, test, setup, steps, excluded, poses, mag, acc, raw_unit, field_unit, given, earth
            ) -> MagCalibration:
    return MagCalibration(fit, sym, test, None if setup is None else setup.search, None if setup is None else setup.lag,
                          None if setup is None else setup.poses, steps, _report(fit, sym, setup, poses, mag, acc),
                          raw_unit, field_unit, given, excluded, earth)
