"""The gyro rotation fit: one IPOPT NLP over all motion segments, exact derivatives, Gauss-Newton Hessian.

Unknowns (scaled to be near 1 or 0): relative scale x_s (B_g = B0 (1 + x_s)), the six entries of
M_g, and optionally a bias correction x_b [mrad/s] (imu_tk's enableGyroBiasOptimization). Bias and
g-sensitivity come from the static intervals (``gsens``) and correct the raw rate before the fit.
The residual of segment k is imu_tk's R_k^T u0 - u1, divided by its noise: the static directions'
standard error and the angle random walk of the gyro noise over the segment's duration.
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from imucal.solve import ipopt
from imucal.errors import ImucalError
from imucal.gyro.evaluate import direction_errors_deg
from imucal.gyro.gsens import StaticFit, fit_static
from imucal.gyro.lead_in import lead_in_for
from imucal.gyro.model import AXES, MIS_NAMES, apply_rate, direction_residual, misalignment_matrix, rk4_step
from imucal.gyro.result import GyroResult
from imucal.gyro.segments import GyroData, Segments, motion_segments

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

    def __post_init__(self) -> None:
        if self.gsens not in ("auto", "on", "off"):
            raise ImucalError(f"gsens {self.gsens!r} is not one of auto, on, off", field="gyro.gsens",
                              fix="use auto (test the data), on or off")
        if self.lead_in_s != "auto" and not (isinstance(self.lead_in_s, (int, float))
                                             and not isinstance(self.lead_in_s, bool) and 0 <= self.lead_in_s <= 10):
            raise ImucalError(f"lead_in_s {self.lead_in_s!r} is not auto or between 0 and 10 s", field="gyro.lead_in_s",
                              fix="give auto, or the seconds to integrate from inside each still pose, e.g. 0.5")


@functools.lru_cache(maxsize=16)
def _problem(lengths: tuple[int, ...], free_bias: bool) -> tuple[ca.Function, ca.Function, ca.Function, int]:
    """IPOPT solver and residual/Jacobian function for segments of these step counts (built once)."""
    n, S = len(lengths), int(sum(lengths))
    nx = 12 if free_bias else 9
    x = ca.MX.sym("x", nx)
    P = {"raw0": (3, S), "raw1": (3, S), "dt": (1, S), "u0": (3, n), "u1": (3, n), "w": (1, n), "scale0": (3, 1)}
    syms = {k: ca.MX.sym(k, *s) for k, s in P.items()}
    p = ca.vertcat(*[ca.vec(v) for v in syms.values()])
    scale = syms["scale0"] * (1 + x[0:3])
    db = syms["scale0"] * 1e-3 * x[9:12] if free_bias else ca.DM.zeros(3, 1)
    C = ca.mtimes(ca.inv(misalignment_matrix(x[3:9])), ca.diag(1.0 / scale))
    W0 = ca.mtimes(C, syms["raw0"] - ca.repmat(db, 1, S))
    W1 = ca.mtimes(C, syms["raw1"] - ca.repmat(db, 1, S))
    reset = np.zeros((1, S))
    ends = np.cumsum(lengths) - 1
    reset[0, np.r_[0, ends[:-1] + 1]] = 1.0
    U = ca.vertcat(W0, W1, syms["dt"], ca.DM(reset))
    Q = rk4_step().mapaccum("gyro_path", S)(ca.DM([1, 0, 0, 0]), U)
    r = direction_residual().map(n)(Q[:, ends.tolist()], syms["u0"], syms["u1"])  # 3 x n, imu_tk's residual
    rw = ca.vec(r * ca.repmat(syms["w"], 3, 1))
    rv = ca.vec(r)
    J = ca.jacobian(rv, x)
    res = ca.Function("gyro_res", [x, p], [rv, J])
    cost = ca.Function("gyro_cost", [x, p], [ca.sumsqr(rv)])
    lam = ca.MX.sym("lam")
    Jw = ca.jacobian(rw, x)
    hess = ca.Function("nlp_hess_l", [x, p, lam, ca.MX.sym("lam_g", 0)], [lam * ca.triu(ca.mtimes(Jw.T, Jw))],
                       ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
    opts = {**ipopt.OPTIONS, "hess_lag": hess}  # the one option set of every calibration NLP
    solver = ca.nlpsol("gyro_fit", "ipopt", {"x": x, "p": p, "f": 0.5 * ca.sumsqr(rw)}, opts)
    return solver, res, cost, nx


def _pack(data: GyroData, seg: Segments, corrected: np.ndarray, w: np.ndarray, scale0: np.ndarray) -> np.ndarray:
    """The NLP's parameter vector (data of this fit), in the order of ``_problem``."""
    i0 = np.concatenate([np.arange(f, l) for f, l in zip(seg.first, seg.last)])
    parts = [corrected[i0].T, corrected[i0 + 1].T, (data.t[i0 + 1] - data.t[i0])[None, :],
             seg.u0.T, seg.u1.T, w[None, :], scale0[:, None]]
    return np.concatenate([np.asarray(v, float).ravel(order="F") for v in parts])


def _search_scale(cost_fn: ca.Function, nx: int, pack) -> float:
    """Scalar nominal scale [unit per rad/s] minimising the direction mismatch (log grid, then refine)."""
    def cost(k: float) -> float:
        return float(cost_fn(np.zeros(nx), pack(np.full(3, k))))
    grid = 10.0 ** np.arange(-2, 6.01, 0.1)
    best = grid[int(np.argmin([cost(k) for k in grid]))]
    fine = best * np.linspace(0.88, 1.12, 25)
    return float(fine[int(np.argmin([cost(k) for k in fine]))])


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
    info = J.T @ J
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
    """Calibrate the gyro from ``data``; ``segments`` (numbers) restricts the fit to some motions."""
    tic = time.perf_counter()
    gm, _, am, _ = data.static_means()
    st = fit_static(gm, am, options.gsens)
    lead_in = lead_in_for(data, options.gsens, options.lead_in_s, st)
    seg = motion_segments(data, lead_in)
    if segments is not None:
        seg = seg.subset(np.asarray(segments, int))
    corrected = data.gyro - st.bias - data.acc @ st.H.T  # raw - s_g - B_g G_s a
    solver, res, cost, nx = _problem(seg.lengths, options.free_bias)
    ones = np.ones(seg.n)
    scale0 = options.nominal_scale or NOMINAL_SCALE.get(data.unit)
    if scale0 is None:
        scale0 = _search_scale(cost, nx, lambda s: _pack(data, seg, corrected, ones, s))
    scale0 = np.full(3, float(scale0))
    w = 1.0 / _segment_sigma(data, seg, scale0)
    p = _pack(data, seg, corrected, w, scale0)
    names = ("x_scale_x", "x_scale_y", "x_scale_z") + MIS_NAMES + (("db_x", "db_y", "db_z") if options.free_bias else ())
    r0, J0 = (np.asarray(v) for v in res(np.zeros(nx), p))
    _require_observable(J0, names, options.min_angle_deg, data.source)
    sol, stats = ipopt.run(solver, x0=np.zeros(nx), p=p)
    x = np.asarray(sol["x"]).ravel()
    r, J = (np.asarray(v) for v in res(x, p))
    wr = np.repeat(w, 3)
    Jw = J * wr[:, None]
    chi2 = float(np.sum((r.ravel() * wr) ** 2))
    dof = 2 * seg.n - nx  # the residual's component along u1 is of second order: 2 per segment
    redchi = chi2 / dof if dof > 0 else float("nan")
    cov = np.linalg.inv(Jw.T @ Jw) * (redchi if dof > 0 else 1.0)
    sd = np.sqrt(np.diag(cov))
    res = _result(data, options, st, seg, x, sd, cov, scale0, corrected, stats, chi2, dof, redchi, names,
                  time.perf_counter() - tic)
    return replace(res, lead_in_s=lead_in)


def _segment_sigma(data: GyroData, seg: Segments, scale0: np.ndarray) -> np.ndarray:
    """Noise of one residual component [rad]: static directions plus the gyro's angle random walk."""
    rate_sd = float(np.sqrt(np.mean((data.static_rate_noise() / scale0) ** 2)))  # [rad/s] per sample
    dur = data.t[seg.last] - data.t[seg.first]
    dt = np.median(np.diff(data.t))
    return np.sqrt(seg.sigma_u**2 + rate_sd**2 * dt * dur)


def _result(data, options, st: StaticFit, seg, x, sd, cov, scale0, corrected, stats, chi2, dof, redchi, names,
            seconds) -> GyroResult:
    scale = scale0 * (1 + x[0:3])
    scale_sd = scale0 * sd[0:3]
    M = misalignment_matrix(x[3:9])
    Msd = misalignment_matrix(sd[3:9]) - np.eye(3)
    bias, bias_sd = st.bias.copy(), st.bias_std.copy()
    if options.free_bias:
        bias = bias + scale0 * 1e-3 * x[9:12]
        bias_sd = np.sqrt(bias_sd**2 + (scale0 * 1e-3 * sd[9:12]) ** 2)
    G = st.H / scale[:, None]  # H = B_g G_s
    G_sd = st.H_std / scale[:, None]
    corr = cov / np.outer(sd, sd)
    rate_before = corrected / scale0  # static bias (and g-sensitivity) removed, nominal scale, no misalignment
    before = direction_errors_deg(data.t, rate_before, seg)
    rate = apply_rate(data.gyro, bias, scale, x[3:9], G if st.selected.any() else None, data.acc)
    after = direction_errors_deg(data.t, rate, seg)
    return GyroResult(unit=data.unit, bias=bias, bias_std=bias_sd, scale=scale, scale_std=scale_sd,
                      misalignment=M, misalignment_std=Msd, gsens=G, gsens_std=G_sd, gsens_selected=st.selected,
                      gsens_p_value=st.p_value, names=names, correlation=corr, segments=seg.index,
                      error_before_deg=before, error_deg=after, status=str(stats["return_status"]),
                      iterations=int(stats["iter_count"]), chi2=chi2, dof=dof, redchi=redchi, seconds=seconds)


def cross_validate(data: GyroData, options: GyroOptions = GyroOptions(), folds: int = 5) -> np.ndarray:
    """Held-out direction error [deg] of every motion segment: fit on the other folds (segment k in fold k % folds)."""
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
