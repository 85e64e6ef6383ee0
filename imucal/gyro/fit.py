"""The gyroscope's fit: its evidence prepared, then the one fit of every sensor (imucal.solve.fit.fit_evidence).

Preparation: which static intervals are still poses (``still``), the bias and the g-sensitivity from
them (``gsens``, held at those values), the lead-in (``lead_in``), the motion segments between them
(``segments``; a motion with a gap left out), the nominal scale (given by the unit, or searched), the
description's named parameters (imucal.model.gyroscope: the scales and the six entries of M_g free, the
bias too with imu_tk's enableGyroBiasOptimization) and the motions' noise. The evidence
(imucal.gyro.evidence) is imu_tk's residual R_k^T u0 - u1 of every motion, divided by its noise: the
static directions' standard error and the angle random walk of the gyro noise over the motion.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from imucal.errors import ImucalError
from imucal.gyro.attitude import SegmentSteps
from imucal.gyro.evaluate import direction_errors_deg
from imucal.gyro.evidence import MotionEvidence
from imucal.gyro.gsens import StaticFit, fit_static
from imucal.gyro.lead_in import lead_in_for
from imucal.gyro.result import GyroArrays, MotionSummary
from imucal.gyro.segments import GyroData, Segments, motion_segments
from imucal.gyro.still import judge
from imucal.model.gyroscope import (BIAS_NAMES, GSENS_NAMES, MIN_ANGLE_DEG, MIS_NAMES, SCALE_NAMES, gyro_model,
                                    gyro_parameters)
from imucal.model.parameters import Parameters
from imucal.solve.fit import FitResult, fit_evidence
from imucal.solve.stats import median
from imucal.solve.vectorize import apply_values

#: raw units with a known nominal scale [unit per rad/s]
NOMINAL_SCALE = {"rad/s": 1.0, "deg/s": 180.0 / np.pi}


@dataclass(frozen=True)
class GyroOptions:
    """Choices of a gyro fit."""

    gsens: str = "auto"  #: g-sensitivity: "auto" (likelihood-ratio test per axis), "on" or "off"
    free_bias: bool = False  #: also fit a bias correction in the rotation fit
    nominal_scale: float | None = None  #: [unit per rad/s]; None: from the unit, else a 1-D search
    min_angle_deg: float = MIN_ANGLE_DEG
    #: integrate from this far inside the still poses [s] (segments.motion_segments); "auto": by the
    #: data (imucal.gyro.lead_in: when the poses' edges turn and the g-sensitivity found is modelled)
    lead_in_s: float | str = "auto"
    #: which static intervals are still poses: "auto" those the gyro shows still too (imucal.gyro.still),
    #: "off" every interval the accelerometer found
    still: str = "auto"

    def __post_init__(self) -> None:
        if self.gsens not in ("auto", "on", "off"):
            raise ImucalError(f"gsens {self.gsens!r} is not one of auto, on, off", field="gyro.gsens",
                              fix="use auto (test the data), on or off")
        if self.still not in ("auto", "off"):
            raise ImucalError(f"still {self.still!r} is not auto or off", field="gyro.still",
                              fix="use auto (judge stillness on the gyro too) or off")
        if self.lead_in_s != "auto" and not (isinstance(self.lead_in_s, (int, float))
                                             and not isinstance(self.lead_in_s, bool) and 0 <= self.lead_in_s <= 10):
            raise ImucalError(f"lead_in_s {self.lead_in_s!r} is not auto or between 0 and 10 s", field="gyro.lead_in_s",
                              fix="give auto, or the seconds to integrate from inside each still pose, e.g. 0.5")


def _steps(data: GyroData, seg: Segments) -> SegmentSteps:
    """The RK4 steps of the motion segments: raw rates and calibrated acceleration at both ends, dt, directions."""
    return SegmentSteps.of(data.t, data.gyro, data.acc, seg)


def _grid_argmin(steps: SegmentSteps, params: Parameters, grid: np.ndarray) -> float:
    """The grid value of least cost sum_k |r_k|^2, every scale at it and M_g = I, the first of equal ones.

    Exact pruning: the cost is a sum of squares over segments, so a scale whose sum over some
    segments already exceeds a complete cost cannot be the least. The segments are taken in groups
    of growing size; after the first group the most promising scale is completed to give that bound.
    """
    model, free = gyro_model(), params.free_names
    at = np.array([params[n].value for n in free])
    is_scale = np.array([n in SCALE_NAMES for n in free])
    pfix = np.array(params.values(), float)

    def cost(g: SegmentSteps, scales: np.ndarray) -> np.ndarray:
        rows = np.where(is_scale[:, None], scales[None, :], np.where(np.isin(free, MIS_NAMES), 0.0, at)[:, None])
        return g.costs(model, free, rows, pfix)

    cuts = [c for c in (2, 6, 14) if c < steps.n]
    groups = [steps.subset(g) for g in np.split(np.arange(steps.n), cuts)]
    partial = cost(groups[0], grid)
    best = int(np.argmin(partial))
    bound = partial[best] + sum(float(cost(g, grid[[best]])[0]) for g in groups[1:])
    alive = np.ones(grid.size, bool)
    alive[best] = False
    for g in groups[1:]:
        alive &= partial <= bound
        if alive.any():
            partial[alive] += cost(g, grid[alive])
    alive &= partial <= bound
    partial[best] = bound
    cand = np.flatnonzero(alive | (np.arange(grid.size) == best))
    return float(grid[cand[int(np.argmin(partial[cand]))]])


def _search_scale(steps: SegmentSteps, params: Parameters) -> float:
    """Scalar nominal scale [unit per rad/s] minimising the direction mismatch (log grid, then refine)."""
    best = _grid_argmin(steps, params, 10.0 ** np.arange(-2, 6.01, 0.1))
    return _grid_argmin(steps, params, best * np.linspace(0.88, 1.12, 25))


def fit_gyro(data: GyroData, options: GyroOptions = GyroOptions(), segments: np.ndarray | None = None) -> FitResult:
    """Calibrate the gyro from ``data``; ``segments`` (numbers) restricts the fit to some motions.

    The still poses give the bias and the g-sensitivity (imucal.gyro.gsens), held at their values; the
    motions between them are the evidence (imucal.gyro.evidence) of the one fit (imucal.solve.fit.fit_evidence).
    With ``options.still == "auto"`` the intervals the gyro shows turning are no still poses
    (imucal.gyro.still): ``segments`` then numbers the motions between the intervals kept."""
    tic = time.perf_counter()
    still = judge(data, options.gsens) if options.still == "auto" else None
    if still is not None and still.rejected:
        data = data.without(still.keep)
    gm, _, am, _ = data.static_means()
    st = fit_static(gm, am, options.gsens)
    lead_in = lead_in_for(data, options.gsens, options.lead_in_s, st)
    seg = every = motion_segments(data, lead_in)
    _require_motions(every, 12 if options.free_bias else 9, data.source)
    if segments is not None:
        seg = seg.subset(np.asarray(segments, int))
    model, steps = gyro_model(), _steps(data, seg)
    scale0 = options.nominal_scale or NOMINAL_SCALE.get(data.unit)
    if scale0 is None:
        scale0 = _search_scale(steps, _parameters(data, st, np.ones(3), options))
    params = _parameters(data, st, np.full(3, float(scale0)), options)
    evidence = MotionEvidence(model, params.free_names, steps, _segment_sigma(data, seg, np.full(3, float(scale0))),
                              options.min_angle_deg, data.source)
    known = {**dict(zip(BIAS_NAMES, st.bias_std)), **dict(zip(GSENS_NAMES, st.H_std.ravel()))}
    try:
        res = fit_evidence(model, evidence, params, known_std=known)
    except ImucalError as exc:
        if not seg.gapped:
            raise
        raise ImucalError(f"{exc.message} ({_gapped_words(every)})", file=exc.file, field=exc.field,
                          fix=exc.fix) from None
    before = direction_errors_deg(data.t, apply_values(model, params.values(), data.gyro, data.acc), seg)
    after = direction_errors_deg(data.t, res.apply(data.gyro, data.acc), seg)
    scale = GyroArrays.of(res.params, res.std).scale
    return replace(res, summary=MotionSummary(
        unit=data.unit, segments=seg.index, error_before_deg=before, error_deg=after, gsens_selected=st.selected,
        gsens_p_value=st.p_value, seconds=time.perf_counter() - tic, lead_in_s=lead_in, gapped=seg.gapped,
        still=None if still is None else still.with_scale(scale)))


def _parameters(data: GyroData, st: StaticFit, scale: np.ndarray, options: GyroOptions) -> Parameters:
    """The description's parameters at the still poses' bias and g-sensitivity and the nominal ``scale``
    (the "before" calibration: no misalignment)."""
    return gyro_parameters(data.unit, st.bias, scale, gsens=st.H, free_bias=options.free_bias, gsens_free=st.selected,
                           min_angle_deg=options.min_angle_deg)


def _gapped_words(seg: Segments) -> str:
    """How many motions a gap left out (``seg``: every motion's segments, before any subset)."""
    n = len(seg.gapped)
    return (f"{n} of {n + seg.n} motions left out: a gap in the time stamps lies inside "
            f"{'it' if n == 1 else 'each'}, the longest {max(g.longest_gap for g in seg.gapped):.3g} s")


def _require_motions(seg: Segments, nx: int, source: str | None) -> None:
    """Refuse when the motions left after those with a gap (segments.motion_segments) are too few for
    the rotation fit: each gives two residual components, and the fit needs more than its nx unknowns."""
    if not seg.gapped or 2 * seg.n > nx:
        return
    raise ImucalError(f"{seg.n} motions left for the gyro fit's {nx} unknowns (at least {nx // 2 + 1} needed): "
                      f"{_gapped_words(seg)}", file=source, field="t",
                      fix="record again without pauses of the logger during motions (or cut the recording at "
                          "the gaps and calibrate the longest part)")


def _segment_sigma(data: GyroData, seg: Segments, scale0: np.ndarray) -> np.ndarray:
    """Noise of one residual component [rad]: static directions plus the gyro's angle random walk."""
    rate_sd = float(np.sqrt(np.mean((data.static_rate_noise() / scale0) ** 2)))  # [rad/s] per sample
    dur = data.t[seg.last] - data.t[seg.first]
    dt = median(np.diff(data.t))
    return np.sqrt(seg.sigma_u**2 + rate_sd**2 * dt * dur)


def cross_validate(data: GyroData, options: GyroOptions = GyroOptions(), folds: int = 5) -> np.ndarray:
    """Held-out direction error [deg] of every motion segment: fit on the other folds (segment k in fold k % folds).

    The motions are those between the still poses (``options.still``), judged once for all folds."""
    if options.still == "auto":
        data, options = data.without(judge(data, options.gsens).keep), replace(options, still="off")
    options = replace(options, lead_in_s=lead_in_for(data, options.gsens, options.lead_in_s))  # one for all folds
    seg = motion_segments(data, options.lead_in_s)
    out = np.full(seg.n, np.nan)
    for f in range(folds):
        test = np.flatnonzero(seg.index % folds == f)
        train = np.flatnonzero(seg.index % folds != f)
        rate = fit_gyro(data, options, train).apply(data.gyro, data.acc)
        out[test] = direction_errors_deg(data.t, rate, seg.subset(test))
    return out
