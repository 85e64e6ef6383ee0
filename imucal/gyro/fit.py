"""The gyro rotation fit: one IPOPT NLP over all motion segments, exact derivatives, Gauss-Newton Hessian.

Unknowns: the gyroscope description's named parameters (imucal.model.gyroscope): the scales and the six
entries of M_g, and optionally the bias (imu_tk's enableGyroBiasOptimization), scaled p = p0 + d x with d
each parameter's solver scale (the nominal scale, 1, a milli-rad/s of reading). Bias and g-sensitivity
come from the static intervals (``gsens``) and are held at their values there.
The residual of segment k is imu_tk's R_k^T u0 - u1, divided by its noise: the static directions'
standard error and the angle random walk of the gyro noise over the segment's duration.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from imucal.solve import least_squares
from imucal.errors import ImucalError
from imucal.gyro.evaluate import direction_errors_deg
from imucal.gyro.gsens import StaticFit, fit_static
from imucal.gyro.attitude import SegmentSteps
from imucal.gyro.lead_in import lead_in_for
from imucal.model.gyroscope import (AXES, BIAS_NAMES, MIS_NAMES, SCALE_NAMES, gyro_model, gyro_parameters, values)
from imucal.model.parameters import Parameters
from imucal.model.sensor import SensorModel
from imucal.gyro.result import GyroResult
from imucal.gyro.segments import GyroData, Segments, motion_segments
from imucal.model.gyroscope import misalignment_matrix
from imucal.solve.vectorize import apply_values
from imucal.gyro.still import judge

#: raw units with a known nominal scale [unit per rad/s]
NOMINAL_SCALE = {"rad/s": 1.0, "deg/s": 180.0 / np.pi}
#: smallest effective rotation [deg] that moves gravity about an axis for its scale to count as determined
MIN_ANGLE_DEG = 45.0


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


class _Problem:
    """1/2 sum_k w_k^2 |r_k|^2 over the segments, for IPOPT through imucal.solve.least_squares, in scaled
    unknowns x: the free parameters are p0 + d x (d each one's solver scale).

    Gradient J^T W r and Gauss-Newton Hessian J^T W J from one Jacobian per point (cached).
    """

    def __init__(self, steps: SegmentSteps, model: SensorModel, params: Parameters, w: np.ndarray) -> None:
        self.steps, self.model, self.wr = steps, model, np.repeat(w, 3)
        self.free = params.free_names
        self.n_free = len(self.free)
        self.pfix = np.array(params.values(), float)
        self.p0 = np.array([params[n].value for n in self.free])
        self.d = np.array([params[n].scale for n in self.free])
        self._key: bytes | None = None
        self._rj: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros(0))

    def p_of(self, x) -> np.ndarray:
        return self.p0 + self.d * np.asarray(x, float).ravel()

    def jacobian(self, x) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (3 n,) and Jacobian (3 n, nx) in the scaled unknowns, unweighted."""
        x = np.asarray(x, float).ravel()
        if self._key != x.tobytes():
            r, J = self.steps.jacobian(self.model, self.free, self.p_of(x), self.pfix)
            self._key, self._rj = x.tobytes(), (r.ravel(), J * self.d)
        return self._rj

    def value(self, x) -> float:
        x = np.asarray(x, float).ravel()
        r = self._rj[0] if self._key == x.tobytes() else self.steps.residuals(self.model, self.free, self.p_of(x),
                                                                              self.pfix).ravel()
        return 0.5 * float(np.sum((self.wr * r) ** 2))

    def derivatives(self, x) -> tuple[float, np.ndarray, np.ndarray]:
        r, J = self.jacobian(x)
        Jw = J * self.wr[:, None]
        return 0.5 * float(np.sum((self.wr * r) ** 2)), Jw.T @ (self.wr * r), Jw.T @ Jw


def _refuse_scales(axes: list[int], eff: np.ndarray, min_deg: float, source: str | None) -> None:
    """The refusal naming every gyro axis in ``axes`` and the rotations to add."""
    ax = [AXES[k] for k in axes]
    which = ax[0] if len(ax) == 1 else ", ".join(ax[:-1]) + " and " + ax[-1]
    turned = "; ".join(f"about {AXES[k]} by an effective {eff[k]:.3g} deg" for k in axes)
    if len(ax) == 1:
        msg, fix = (f"the gyro {which} scale is not determined", f"add rotations about the {which} axis between "
                    f"still poses, with the {which} axis horizontal (e.g. 90 deg turns about {which})")
    else:
        msg, fix = (f"the gyro scale is not determined for the {which} axes", f"add rotations about the {which} "
                    f"axes between still poses, each with its axis horizontal (e.g. 90 deg turns about "
                    f"{', then '.join(ax)})")
    raise ImucalError(f"{msg}: the motions turn the gravity direction {turned} (need at least {min_deg:g} deg)",
                      file=source, field="gyro.scale", fix=fix)


def _require_observable(J: np.ndarray, names: tuple[str, ...], min_deg: float, source: str | None) -> None:
    """Refuse, naming the axes, when the motions hardly turn gravity about some gyro axis.

    First every axis about which the motions turn gravity by less than ``min_deg`` in all (root
    sum square over motions: sqrt of the information of its relative scale, in degrees); then,
    with correlations, a null direction of J^T J or a scale whose standard error, as an angle,
    is below ``min_deg``.
    """
    order = [names.index(n) for n in SCALE_NAMES] + [k for k, n in enumerate(names) if n not in SCALE_NAMES]
    info = (J.T @ J)[np.ix_(order, order)]  # the scales first
    alone = np.degrees(np.sqrt(np.diag(info)[0:3]))
    weak = [k for k in range(3) if not alone[k] >= min_deg]
    if weak:
        _refuse_scales(weak, alone, min_deg, source)
    lam, V = np.linalg.eigh(info)
    null = lam <= 1e-9 * max(lam[-1], 1e-300)
    weak = [int(np.argmax(np.abs(V[0:3, i]))) for i in np.flatnonzero(null) if np.abs(V[0:3, i]).max() > 0.1]
    if null.any() and not weak:
        raise ImucalError("the gyro misalignment is not determined by these motions", file=source,
                          field="gyro.misalignment", fix="rotate about all three axes, each in several poses")
    eff = np.zeros(3)
    if not null.any():
        eff = np.degrees(1.0 / np.sqrt(np.diag(np.linalg.inv(info))[0:3]))
    k = weak[0] if weak else int(np.argmin(eff))
    if weak or not eff[k] >= min_deg:
        _refuse_scales([k], eff, min_deg, source)


def fit_gyro(data: GyroData, options: GyroOptions = GyroOptions(), segments: np.ndarray | None = None) -> GyroResult:
    """Calibrate the gyro from ``data``; ``segments`` (numbers) restricts the fit to some motions.

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
    nx = 12 if options.free_bias else 9
    _require_motions(every, nx, data.source)
    if segments is not None:
        seg = seg.subset(np.asarray(segments, int))
    model = gyro_model()
    steps = _steps(data, seg)
    start = gyro_parameters(data.unit, st.bias, np.ones(3), gsens=st.H, free_bias=options.free_bias,
                            gsens_free=st.selected)
    scale0 = options.nominal_scale or NOMINAL_SCALE.get(data.unit)
    if scale0 is None:
        scale0 = _search_scale(steps, start)
    scale0 = np.full(3, float(scale0))
    params = gyro_parameters(data.unit, st.bias, scale0, gsens=st.H, free_bias=options.free_bias,
                             gsens_free=st.selected)
    w = 1.0 / _segment_sigma(data, seg, scale0)
    problem = _Problem(steps, model, params, w)
    names = params.free_names
    try:
        _require_observable(problem.jacobian(np.zeros(problem.n_free))[1], names, options.min_angle_deg, data.source)
    except ImucalError as exc:
        if not seg.gapped:
            raise
        raise ImucalError(f"{exc.message} ({_gapped_words(every)})", file=exc.file, field=exc.field,
                          fix=exc.fix) from None
    lo = np.array([(params[n].lower - params[n].value) / params[n].scale for n in names])
    x, stats = least_squares.solve(problem, lo, np.full(len(names), np.inf))
    r, J = problem.jacobian(x)
    wr = np.repeat(w, 3)
    Jw = J * wr[:, None]
    chi2 = float(np.sum((r.ravel() * wr) ** 2))
    dof = 2 * seg.n - len(names)  # the residual's component along u1 is of second order: 2 per segment
    redchi = chi2 / dof if dof > 0 else float("nan")
    cov = np.linalg.inv(Jw.T @ Jw) * (redchi if dof > 0 else 1.0)
    sd = np.sqrt(np.diag(cov))
    fitted = params.with_values(dict(zip(names, problem.p_of(x))))
    res = _result(data, st, seg, params, fitted, problem.d * sd, cov, stats, chi2, dof, redchi,
                  time.perf_counter() - tic)
    return replace(res, lead_in_s=lead_in, still=None if still is None else still.with_scale(res.scale),
                   gapped=seg.gapped)


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
    dt = np.median(np.diff(data.t))
    return np.sqrt(seg.sigma_u**2 + rate_sd**2 * dt * dur)


def _result(data: GyroData, st: StaticFit, seg: Segments, start: Parameters, fitted: Parameters, sd: np.ndarray,
            cov: np.ndarray, stats: dict, chi2: float, dof: int, redchi: float, seconds: float) -> GyroResult:
    names = fitted.free_names
    v, std = values(fitted), dict(zip(names, sd))
    scale = v["scale"]
    scale_sd = np.array([std[n] for n in SCALE_NAMES])
    Msd = misalignment_matrix(np.array([std[n] for n in MIS_NAMES])) - np.eye(3)
    bias, bias_sd = v["bias"], st.bias_std.copy()
    if BIAS_NAMES[0] in std:  # the static fit's error and the rotation fit's correction's
        bias_sd = np.sqrt(bias_sd**2 + np.array([std[n] for n in BIAS_NAMES]) ** 2)
    G = st.H / scale[:, None]  # H = B_g G_s
    G_sd = st.H_std / scale[:, None]
    d = np.sqrt(np.diag(cov))
    corr = cov / np.outer(d, d)
    model = gyro_model()
    # before: static bias (and g-sensitivity) removed, nominal scale, no misalignment
    before = direction_errors_deg(data.t, apply_values(model, start.values(), data.gyro, data.acc), seg)
    after = direction_errors_deg(data.t, apply_values(model, fitted.values(), data.gyro, data.acc), seg)
    return GyroResult(unit=data.unit, bias=bias, bias_std=bias_sd, scale=scale, scale_std=scale_sd,
                      misalignment=v["misalignment"], misalignment_std=Msd, gsens=G, gsens_std=G_sd,
                      gsens_selected=st.selected, gsens_p_value=st.p_value, names=names, correlation=corr,
                      segments=seg.index, error_before_deg=before, error_deg=after,
                      status=str(stats["return_status"]), iterations=int(stats["iter_count"]), chi2=chi2, dof=dof,
                      redchi=redchi, seconds=seconds, params=fitted)


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
        r = fit_gyro(data, options, train)
        rate = r.apply(data.gyro, data.acc)
        out[test] = direction_errors_deg(data.t, rate, seg.subset(test))
    return out
