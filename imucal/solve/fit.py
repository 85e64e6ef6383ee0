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

import numpy as np

from imucal.solve import ipopt
from imucal.solve import least_squares as lsq
from imucal.solve import stochastic
from imucal.solve.stats import between_excess, chi2_sf
from imucal.errors import ImucalError
from imucal.model.sensor import SensorModel
from imucal.model.parameters import Parameters, model_label
from imucal.report.progress import progress

_STATUS_WORDS, _CONVERGED = ipopt.STATUS_WORDS, ipopt.CONVERGED
#: weights="auto": the noise-only chi-square test at which a between-interval excess is used.
EXCESS_P = 1e-3
#: weights="auto": no stochastic-bias test above this reduced chi-square against the noise: that is a
#: model error (the pipeline refuses such a fit), which a random walk would otherwise absorb.
STOCHASTIC_MAX_REDCHI = 1.0e4
#: weights="auto": at most this many solves while the excess settles.
MAX_PASSES = 8


@dataclass(frozen=True)
class FitData:
    """What the NLP sees: rows of raw readings with covariates and residual noise."""

    raw: np.ndarray  #: (N, 3) raw readings (interval means, or samples)
    cov: np.ndarray  #: (N, k) covariates in the model's order
    raw_var: np.ndarray  #: (N, 3) variance of each raw reading [raw^2]
    group: np.ndarray  #: (N,) interval index of each row
    mode: str  #: "means" or "samples"
    t: np.ndarray | None = None  #: (N,) time of each interval mean [s] (the random-walk test needs it)
    #: where raw_var comes from: "scatter" (each interval's own) or a noise model's file
    #: (imucal.analysis.noise_model: white-noise density and bias-instability floor)
    noise_source: str = "scatter"


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
    excess: float = 0.0  #: between-interval excess variance in the weights [(m/s^2)^2] (weights="auto")
    chi2_noise: float = float("nan")  #: chi-square against the noise of each row alone
    random_walk: float = 0.0  #: bias random-walk q^2 in the weights [(m/s^2)^2 / s] (weights="auto")
    stochastic: "stochastic.StochasticFit | None" = None  #: the REML test that named it

    @property
    def redchi(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def redchi_noise(self) -> float:
        """Reduced chi-square against the noise alone (the test of the model, excess or not)."""
        return self.chi2_noise / self.dof if self.dof > 0 else float("nan")

    @property
    def noise_std(self) -> dict[str, float]:
        """``std`` before the scaling by chi2/dof (what the weights alone predict; ``fit`` scales
        the covariance by it when degrees of freedom are left)."""
        k = 1.0 / np.sqrt(self.redchi) if self.dof > 0 and self.redchi > 0 else 1.0
        return {n: v * k for n, v in self.std.items()}

    @property
    def rms_residual(self) -> float:
        return float(np.sqrt(np.mean(self.residuals**2)))

    @property
    def status_words(self) -> str:
        return _STATUS_WORDS.get(self.status, self.status)

    def values(self) -> dict[str, float]:
        return self.params.value_dict()


def unscaled_covariance(Jw: np.ndarray, rcond: float = 1e-12) -> np.ndarray:
    """(Jw^T Jw)^-1 by the SVD of the column-equilibrated Jacobian.

    ``Jw`` may be the weighted Jacobian itself or any R with R^T R = Jw^T Jw (the block QR of
    imucal.solve.least_squares): both have the same column norms and singular values.

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
        source: str | None = None, weights: str = "noise", hessian: str = "gauss-newton") -> FitResult:
    """Fit the free parameters of ``params`` to ``data`` by weighted least squares (IPOPT).

    ``weights="noise"`` weighs each row by 1/sigma^2 (its noise propagated from the raw
    scatter); ``"uniform"`` gives every row the median sigma (imu_tk's unweighted cost);
    ``"auto"`` (interval means) adds to every sigma^2 the between-interval excess (a random bias
    offset per visit of a pose) when the residuals exceed the noise at p < EXCESS_P, estimated by
    Paule-Mandel and iterated with the fit: with no excess it is the noise-weighted fit. When the
    REML test of imucal.solve.stochastic names a bias random walk (rows with times ``data.t``), the
    weights are its full covariance (generalised least squares) and the standard errors follow.
    ``hessian="exact"`` gives IPOPT the exact Hessian instead of Gauss-Newton's J^T W J.
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
    fns, rows = lsq.row_functions(model, free), lsq.Rows(data.raw, data.cov)
    t0 = time.perf_counter()
    it = _iterate(fns, rows, data, params, pfix, gravity, weights, hessian)
    solve_time = time.perf_counter() - t0
    status = str(it.stats.get("return_status", "unknown"))
    dof = n - len(free)
    r = lsq.residuals(fns, rows, it.p, pfix, gravity)
    R = lsq.weighted_r_factor(fns, rows, it.sigma if it.white is None else it.white, it.p, pfix, gravity)
    fitted = params.with_values(dict(zip(free, it.p)))
    chi2 = float(np.sum((r / it.sigma) ** 2)) if it.white is None else float(np.sum((it.white @ r) ** 2))
    redchi = chi2 / dof if dof > 0 else float("nan")
    # Covariance from the Jacobian at the solution (via its SVD, symmetric by construction),
    # scaled by the residual variance as lmfit's scale_covar does: (J^T W J)^-1 chi2/dof.
    # With no degrees of freedom left, the noise-only covariance (J^T W J)^-1.
    cov = unscaled_covariance(R) * (redchi if dof > 0 else 1.0)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(sd, sd)
    std = {nm: float("nan") for nm in names}
    if dof > 0 or data.mode != "means":  # no residual left to scale by: std not estimable
        std.update({nm: float(v) for nm, v in zip(free, sd)})
    at_bound = {nm: b for nm in free if (b := fitted[nm].at_bound()) is not None}
    return FitResult(params=fitted, initial=params, std=std, covariance=cov, correlation=corr,
                     free_names=free, gravity=gravity, mode=data.mode, residuals=r, sigma=it.sigma,
                     chi2=chi2, dof=dof, status=status, success=status in _CONVERGED, iterations=it.iterations,
                     solve_time=solve_time, model_name=model_label(model.name, params), at_bound=at_bound,
                     excess=it.excess, chi2_noise=float(np.sum((r / it.sigma0) ** 2)), random_walk=it.q2,
                     stochastic=it.sto if it.q2 > 0 else None)


@dataclass
class _Iterated:
    """Where the weighted fit and its weights settled."""

    p: np.ndarray  #: free parameters
    sigma0: np.ndarray  #: noise of each row alone
    sigma: np.ndarray  #: with the between-interval excess
    white: np.ndarray | None  #: L^-1 of the rows' covariance (a bias random walk), else None
    excess: float
    q2: float
    sto: "stochastic.StochasticFit | None"
    iterations: int
    stats: dict


def _iterate(fns, rows, data: FitData, params: Parameters, pfix: np.ndarray, gravity: float, weights: str,
             hessian: str) -> _Iterated:
    """IPOPT on the weighted rows, the weights refreshed from the noise propagated at the estimate;
    once at the solution and, with weights="auto", until the between-interval excess settles. With a
    bias random walk the rows are correlated: V = diag(sigma0^2 + excess) + q^2 K_W, and the fit is
    generalised least squares (rows whitened by L^-1, V = L L^T)."""
    free = params.free_names
    scale = np.array([params[nm].scale for nm in free])
    lo, hi = np.array([params[nm].lower for nm in free]), np.array([params[nm].upper for nm in free])
    p_now = np.array([params[nm].value for nm in free])
    dof = data.raw.shape[0] - len(free)
    iters, excess, q2, sto, passes = 0, 0.0, 0.0, None, 0
    walk_test = True  # the REML random-walk test (imucal.solve.stochastic) runs until it rejects a walk once
    shown = None if data.mode == "samples" else False  # samples mode: a bar on a terminal (report.progress)
    with progress(f"samples fit ({data.raw.shape[0]:,} samples)", unit="pass", enabled=shown) as step:
        while True:
            sigma0 = lsq.noise_sigma(fns, rows, data.raw_var, p_now, pfix, gravity, weights)
            sigma, W, white = _weights(fns, rows, data, params, p_now, pfix, gravity, sigma0, excess, q2)
            R = lsq.weighted_r_factor(fns, rows, sigma if white is None else white, p_now, pfix, gravity)
            d = _step_scale(R, scale)  # p = p0 + d * x
            problem = lsq.Problem(fns, rows, W, pfix, gravity, p_now, d, exact=hessian == "exact", step=step)
            x, stats = lsq.solve(problem, (lo - p_now) / d, (hi - p_now) / d)
            iters += int(stats.get("iter_count", 0))
            p_now = np.clip(p_now + d * x, lo, hi)
            passes += 1
            if weights != "auto" or data.mode != "means" or dof < 1:
                if passes < 2:
                    continue  # once more, with the weights at the solution
                break
            if passes >= MAX_PASSES:
                break
            # The excess at this solution; the next pass refreshes the noise weights and the excess together.
            r0 = lsq.residuals(fns, rows, p_now, pfix, gravity)
            s0 = lsq.noise_sigma(fns, rows, data.raw_var, p_now, pfix, gravity, weights)
            new, new_q2, sto = _excess(fns, rows, data, params, p_now, pfix, gravity, r0, s0, dof, walk_test)
            walk_test = sto is not None  # the REML test rejected a walk once: later passes only re-estimate tau^2
            settled = (abs(new - excess) <= 1e-4 * max(new, excess) and abs(new_q2 - q2) <= 1e-4 * max(new_q2, q2)
                       ) or (new == 0.0 and excess == 0.0 and new_q2 == 0.0 and q2 == 0.0)
            if settled and passes >= 2:  # (no excess after the first pass: one refresh of the noise weights)
                break
            excess, q2 = new, new_q2
    return _Iterated(p_now, sigma0, sigma, white, excess, q2, sto, iters, stats)


def _components(fns, rows, data: FitData, params: Parameters, p_now, pfix, gravity: float,
                sigma0: np.ndarray) -> stochastic.Components:
    """The stochastic-bias components at p_now (G uses the current scales b_i)."""
    values = dict(zip(params.names, pfix)) | dict(zip(params.free_names, p_now))
    b = np.array([values[f"b{i}"] for i in (1, 2, 3)])
    return stochastic.components_at(fns, rows, p_now, pfix, gravity, sigma0, b, data.t)


def _weights(fns, rows, data: FitData, params: Parameters, p_now, pfix, gravity: float, sigma0: np.ndarray,
             excess: float, q2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(sigma of each row, weights for the NLP, whitening L^-1 or None): diagonal unless q2 > 0."""
    if q2 <= 0:
        sigma = np.sqrt(sigma0**2 + excess)
        return sigma, 1.0 / sigma**2, None
    V = _components(fns, rows, data, params, p_now, pfix, gravity, sigma0).covariance(excess, q2)
    white = np.linalg.inv(np.linalg.cholesky(V))
    return np.sqrt(np.diag(V)), white.T @ white, white


def _excess(fns, rows, data: FitData, params: Parameters, p_now, pfix, gravity: float, r0: np.ndarray,
            s0: np.ndarray, dof: int, walk_test: bool = True) -> tuple[float, float, "stochastic.StochasticFit | None"]:
    """weights="auto": (tau^2, q^2, the test) when the residuals exceed the noise at p < EXCESS_P.

    A bias random walk named by the REML test (imucal.solve.stochastic), and told apart from
    per-visit offsets, gives its (tau^2, q^2); otherwise (or above stochastic.MAX_INTERVALS intervals)
    the excess is Paule-Mandel's common between-interval variance, as before the test.
    """
    if chi2_sf(float(np.sum((r0 / s0) ** 2)), dof) >= EXCESS_P:
        return 0.0, 0.0, None
    if walk_test and data.t is not None and len(params.free_names) + 3 < len(r0) and stochastic.feasible(len(r0)) and (
            float(np.sum((r0 / s0) ** 2)) / dof < STOCHASTIC_MAX_REDCHI):
        sto = stochastic.select(_components(fns, rows, data, params, p_now, pfix, gravity, s0))
        if stochastic.RANDOM_WALK in sto.named and not sto.ambiguous:  # undecided: the per-visit excess
            return sto.chosen.tau2, sto.chosen.q2, sto
    return between_excess(r0, s0, dof), 0.0, None


def jacobian_rows(data: FitData, params: Parameters, model: SensorModel, gravity: float,
                  residuals: bool = False, weighted: bool = False):
    """Residual Jacobian w.r.t. the free parameters, each column times the parameter's scale.

    ``weighted=True`` returns ``(J, J / sigma)``: also each row divided by its noise (so the
    second's J^T J is the Fisher information in scaled units); ``residuals=True`` returns the
    residuals |a| - g instead.
    """
    free = params.free_names
    fns, rows = lsq.row_functions(model, free), lsq.Rows(data.raw, data.cov)
    pfix, pfree = np.array(params.values(), float), np.array([params[n].value for n in free])
    if residuals:
        return lsq.residuals(fns, rows, pfree, pfix, gravity)
    _, J, _ = lsq.jacobians(fns, rows, pfree, pfix, gravity)
    J = J * np.array([params[n].scale for n in free])
    if weighted:
        return J, J / lsq.noise_sigma(fns, rows, data.raw_var, pfree, pfix, gravity)[:, None]
    return J
