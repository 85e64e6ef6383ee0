"""The calibration fit: a weighted least-squares IPOPT NLP built from the CasADi model.

Minimise  1/2 sum_k ((|a_k| - g) / sigma_k)^2  over the free parameters, where |a_k| is the
magnitude of Proposition 2 at interval mean (or sample) k and sigma_k its noise propagated
from the raw readings. The paper's condition at rest is g = a_nonorth (end of Section 2).
Unknowns are scaled, p = p0 + d x with d each parameter's predicted standard error, so IPOPT
sees numbers near one and a Hessian near the identity; the solver is built once per problem
shape and reused.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np

from imucal.solve import ipopt
from imucal.errors import ImucalError
from imucal.model.sensor import SensorModel
from imucal.model.parameters import Parameters, model_label

_STATUS_WORDS, _CONVERGED = ipopt.STATUS_WORDS, ipopt.CONVERGED


@dataclass(frozen=True)
class FitData:
    """What the NLP sees: rows of raw readings with covariates and residual noise."""

    raw: np.ndarray  #: (N, 3) raw readings (interval means, or samples)
    cov: np.ndarray  #: (N, k) covariates in the model's order
    raw_var: np.ndarray  #: (N, 3) variance of each raw reading [raw^2]
    group: np.ndarray  #: (N,) interval index of each row
    mode: str  #: "means" or "samples"


@dataclass(frozen=True)
class FitResult:
    """A fitted calibration: values, uncertainties, goodness of fit and solver status."""

    params: Parameters
    initial: Parameters
    std: dict[str, float]
    covariance: np.ndarray  #: over the free parameters, in ``free_names`` order
    correlation: np.ndarray
    free_names: tuple[str, ...]
    gravity: float
    mode: str
    residuals: np.ndarray  #: |a| - g per row [m/s^2]
    sigma: np.ndarray  #: noise of each residual [m/s^2]
    chi2: float
    dof: int
    status: str
    success: bool
    iterations: int
    solve_time: float
    model_name: str
    at_bound: dict[str, str] = field(default_factory=dict)

    @property
    def redchi(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def rms_residual(self) -> float:
        return float(np.sqrt(np.mean(self.residuals**2)))

    @property
    def status_words(self) -> str:
        return _STATUS_WORDS.get(self.status, self.status)

    def values(self) -> dict[str, float]:
        return self.params.value_dict()


def _selection(names: tuple[str, ...], free: tuple[str, ...]) -> np.ndarray:
    S = np.zeros((len(names), len(free)))
    for j, n in enumerate(free):
        S[names.index(n), j] = 1.0
    return S


@lru_cache(maxsize=32)
def _solver(model: SensorModel, n: int, free: tuple[str, ...]) -> tuple[ca.Function, ca.Function]:
    """IPOPT solver and residual/Jacobian function for one problem shape, built once."""
    names, k = model.names, len(model.covariates)
    nf = len(free)
    x = ca.MX.sym("x", nf)
    raw = ca.MX.sym("raw", 3, n)
    cov = ca.MX.sym("cov", k, n)
    w = ca.MX.sym("w", 1, n)
    g = ca.MX.sym("g")
    pfix = ca.MX.sym("pfix", len(names))  # fixed values (free entries ignored)
    off = ca.MX.sym("off", nf)  # free parameters at the start
    step = ca.MX.sym("step", nf)  # their predicted standard errors: x is in those units
    S = ca.DM(_selection(names, free))
    mask = ca.DM(1.0 - S.full().sum(axis=1))
    p = mask * pfix + ca.mtimes(S, off + step * x)
    # Per-row objective term, summed by a reducing map: no per-row symbolic expansion.
    rs, cs, ps, gs, ws = (ca.SX.sym("r", 3), ca.SX.sym("c", k), ca.SX.sym("p", len(names)),
                          ca.SX.sym("g"), ca.SX.sym("w"))
    term = ca.Function("term", [rs, cs, ws, ps, gs], [0.5 * ws * model.residual(rs, cs, ps, gs) ** 2])
    par = "serial"
    fsum = term.map("fsum", par, n, [3, 4], [0]) if n > 1 else term
    obj = fsum(raw, cov, w, p, g)
    P = ca.vertcat(ca.vec(raw), ca.vec(cov), ca.vec(w), g, pfix, off, step)
    nlp = {"x": x, "p": P, "f": obj}
    solver = ca.nlpsol("calib", "ipopt", nlp, ipopt.OPTIONS)
    # Residuals and their Jacobian w.r.t. the free (unscaled) parameters, for the covariance.
    pf = ca.SX.sym("pf", nf)
    pfix_s = ca.SX.sym("pfix", len(names))
    p_s = ca.DM(mask) * pfix_s + ca.mtimes(S, pf)
    r = model.residual(rs, cs, p_s, gs)
    jr_raw = ca.jacobian(r, rs)
    row = ca.Function("row", [rs, cs, pf, pfix_s, gs], [r, ca.jacobian(r, pf), jr_raw])
    rows = row.map(n, par) if n > 1 else row
    return solver, rows


def _row_eval(rows: ca.Function, data: FitData, pfree: np.ndarray, pfix: np.ndarray, g: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r, J, Jraw = rows(data.raw.T, data.cov.T, pfree, pfix, g)
    n = data.raw.shape[0]
    r = np.asarray(r).reshape(n)
    J = np.asarray(J).reshape(len(pfree), n, order="F").T if n > 1 else np.asarray(J).reshape(1, -1)
    Jraw = np.asarray(Jraw).reshape(3, n, order="F").T if n > 1 else np.asarray(Jraw).reshape(1, 3)
    return r, J, Jraw


def _sigma(Jraw: np.ndarray, raw_var: np.ndarray, weights: str = "noise") -> np.ndarray:
    """Noise of |a| - g from the raw noise: first-order propagation."""
    s = np.sqrt(np.sum(Jraw**2 * raw_var, axis=1))
    floor = max(float(np.median(s)) * 1e-3, 1e-12)
    if weights == "uniform":
        return np.full_like(s, max(float(np.median(s)), floor))
    return np.maximum(s, floor)


class _Rows:
    """Residuals, their parameter Jacobian and raw Jacobian at a parameter vector."""

    def __init__(self, data: FitData, model: SensorModel, free: tuple[str, ...], gravity: float,
                 pfix: np.ndarray) -> None:
        self.data, self.g, self.pfix = data, gravity, pfix
        self.free_idx = np.array([model.names.index(nm) for nm in free], int)
        # Base model: the vectorised NLP (imucal.solve.samples), for means and samples alike; with
        # effects, the CasADi map NLP over the extended model.
        self.fast = not model.effects
        if self.fast:
            from imucal.solve.samples import SampleResiduals

            self.sres = SampleResiduals(data.raw, gravity)
            self.solver = None
        else:
            self.solver, self.rows = _solver(model, data.raw.shape[0], free)

    def __call__(self, pfree: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.fast:
            p = self.pfix.copy()
            p[self.free_idx] = pfree
            r, Jp = self.sres.residuals(p, jac=True)
            return r, Jp[:, self.free_idx], -Jp[:, 0:3]  # dr/draw = -dr/ds
        return _row_eval(self.rows, self.data, pfree, self.pfix, self.g)


def unscaled_covariance(Jw: np.ndarray, rcond: float = 1e-12) -> np.ndarray:
    """(Jw^T Jw)^-1 by the SVD of the column-equilibrated Jacobian.

    Columns are divided by their norms first, so the result does not depend on the units of
    the parameters (a shift in counts x 1e12 and an angle in rad differ by 1e15 in scale, and a
    cut relative to the largest singular value would drop the small columns). Directions the
    data do not determine (relative singular value below ``rcond``) get zero variance here and
    are named by imucal.solve.observability before any fit.
    """
    c = np.linalg.norm(Jw, axis=0)
    c = np.where(c > 0, c, 1.0)
    _, sv, Vt = np.linalg.svd(Jw / c, full_matrices=False)
    inv = np.where(sv > sv.max(initial=0) * rcond, 1.0 / np.maximum(sv, 1e-300) ** 2, 0.0)
    return ((Vt.T * inv) @ Vt) / np.outer(c, c)


def _step_scale(Jw: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Predicted standard error of each free parameter: the solver's unit (x = (p - p0)/d).

    In these units IPOPT sees an objective whose Hessian is near the identity, so its
    tolerances mean "a tiny fraction of a standard error" for every parameter alike.
    """
    with np.errstate(invalid="ignore"):
        d = np.sqrt(np.clip(np.diag(unscaled_covariance(Jw)), 0, None))
    d = np.where(np.isfinite(d) & (d > 0), d, scale)
    return np.clip(d, 1e-9 * scale, scale)


def fit(data: FitData, params: Parameters, model: SensorModel, gravity: float,
        source: str | None = None, weights: str = "noise") -> FitResult:
    """Fit the free parameters of ``params`` to ``data`` by weighted least squares (IPOPT).

    ``weights="noise"`` weighs each row by 1/sigma^2 (its noise propagated from the raw
    scatter); ``"uniform"`` gives every row the median sigma (imu_tk's unweighted cost).
    """
    names = model.names
    if tuple(params.names) != names:
        raise ImucalError(f"parameters {params.names} do not match the model's {names}",
                          field="parameters")
    free = params.free_names
    n = data.raw.shape[0]
    if n < len(free):
        raise ImucalError(f"{n} rows cannot determine {len(free)} free parameters", file=source,
                          field="intervals",
                          fix="hold the sensor still in more orientations, or fit samples (fit.mode: samples)")
    pfix = np.array(params.values(), float)
    scale = np.array([params[nm].scale for nm in free])
    lo = np.array([params[nm].lower for nm in free])
    hi = np.array([params[nm].upper for nm in free])
    p_now = np.array([params[nm].value for nm in free])
    rows = _Rows(data, model, free, gravity, pfix)
    t0 = time.perf_counter()
    iters = 0
    # Weights from the noise propagated at the current estimate; refresh once at the solution.
    for _ in range(2):
        r0, J0, Jraw = rows(p_now)
        sigma = _sigma(Jraw, data.raw_var, weights)
        d = _step_scale(J0 / sigma[:, None], scale)  # p = p0 + d * x
        lb, ub = (lo - p_now) / d, (hi - p_now) / d
        x0 = np.zeros(len(free))
        if rows.fast:
            from imucal.solve.samples import solve_samples

            x, stats = solve_samples(data.raw, 1.0 / sigma**2, gravity, pfix, rows.free_idx, p_now, d,
                                     x0, lb, ub)
        else:
            P = np.concatenate([data.raw.T.ravel(order="F"), data.cov.T.ravel(order="F"),
                                1.0 / sigma**2, [gravity], pfix, p_now, d])
            sol = rows.solver(x0=x0, p=P, lbx=lb, ubx=ub)
            stats = rows.solver.stats()
            x = np.asarray(sol["x"]).ravel()
        iters += int(stats.get("iter_count", 0))
        p_now = np.clip(p_now + d * x, lo, hi)
    solve_time = time.perf_counter() - t0
    status = str(stats.get("return_status", "unknown"))
    pfree = p_now
    r, J, _ = rows(pfree)
    fitted = params.with_values(dict(zip(free, pfree)))
    Jw = J / sigma[:, None]
    chi2 = float(np.sum((r / sigma) ** 2))
    dof = n - len(free)
    redchi = chi2 / dof if dof > 0 else float("nan")
    # Covariance from the Jacobian at the solution (via its SVD, symmetric by construction),
    # scaled by the residual variance as lmfit's scale_covar does: (J^T W J)^-1 chi2/dof.
    # With no degrees of freedom left, the noise-only covariance (J^T W J)^-1.
    cov = unscaled_covariance(Jw) * (redchi if dof > 0 else 1.0)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(sd, sd)
    std = {nm: float("nan") for nm in names}
    if dof > 0 or data.mode != "means":  # no residual left to scale by: std not estimable
        std.update({nm: float(v) for nm, v in zip(free, sd)})
    at_bound = {nm: b for nm in free if (b := fitted[nm].at_bound()) is not None}
    success = status in _CONVERGED
    return FitResult(params=fitted, initial=params, std=std, covariance=cov, correlation=corr,
                     free_names=free, gravity=gravity, mode=data.mode, residuals=r, sigma=sigma,
                     chi2=chi2, dof=dof, status=status, success=success, iterations=iters,
                     solve_time=solve_time, model_name=model_label(model.name, params), at_bound=at_bound)


def jacobian_rows(data: FitData, params: Parameters, model: SensorModel, gravity: float,
                  residuals: bool = False, weighted: bool = False):
    """Residual Jacobian w.r.t. the free parameters, each column times the parameter's scale.

    ``weighted=True`` returns ``(J, J / sigma)``: also each row divided by its noise (so the
    second's J^T J is the Fisher information in scaled units); ``residuals=True`` returns the
    residuals |a| - g instead.
    """
    free = params.free_names
    rows = _Rows(data, model, free, gravity, np.array(params.values(), float))
    r, J, Jraw = rows(np.array([params[n].value for n in free]))
    if residuals:
        return r
    J = J * np.array([params[n].scale for n in free])
    if weighted:
        return J, J / _sigma(Jraw, data.raw_var)[:, None]
    return J
