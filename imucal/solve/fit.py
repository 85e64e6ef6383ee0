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
from typing import Mapping

import casadi as ca
import numpy as np

from imucal.solve import ipopt
from imucal.solve import least_squares as lsq
from imucal.solve import stochastic
from imucal.solve.covariance import unscaled_covariance
from imucal.solve.evidence import Evidence, EvidenceSummary, FitEvidence
from imucal.solve.observability import determination
from imucal.solve.vectorize import apply_values
from imucal.solve.stats import between_excess, chi2_sf, projected_chi2
from imucal.solve.vectorize import Vectorized
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
#: samples mode: a scatter correction that moved a value by more than this many of its standard errors
#: is a warning (the fit relied on it; interval means do not need it).
SCATTER_NOTABLE_Z = 1.0


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
    """A fitted sensor, whatever the sensor (one result type for every description, issue 26): values,
    uncertainties, goodness of fit and solver status, and what its kind of evidence says beyond them.

    The accelerometer's rows (interval means or samples) fill ``gravity``, ``mode`` and the fields from
    ``excess`` on; any other evidence attaches its own typed ``summary`` (the gyroscope's motions:
    imucal.gyro.result.MotionSummary)."""

    params: Parameters
    initial: Parameters
    std: dict[str, float]  #: every parameter's; NaN where not determined
    covariance: np.ndarray  #: over the free parameters, in ``free_names`` order
    correlation: np.ndarray
    free_names: tuple[str, ...]
    residuals: np.ndarray  #: of the evidence (|a| - g per row [m/s^2]; R^T u0 - u1 per motion [rad])
    sigma: np.ndarray  #: noise of each residual, same unit
    chi2: float
    dof: int
    status: str
    success: bool
    iterations: int
    solve_time: float
    model_name: str
    at_bound: dict[str, str] = field(default_factory=dict)
    #: the sensor's description (its map: ``apply``); None for a result built without one
    model: SensorModel | None = field(default=None, compare=False, repr=False)
    #: the evidence's own summary (typed: imucal.gyro.result.MotionSummary for the gyroscope's motions)
    summary: EvidenceSummary | None = None
    gravity: float = float("nan")  #: the accelerometer's local gravity [m/s^2]
    mode: str = "means"  #: the accelerometer's rows: "means" or "samples"
    #: between-interval excess variance added to every row's sigma^2 in the standard errors [(m/s^2)^2]
    #: (weights="auto": Paule-Mandel's, or REML's beside a named random walk)
    excess: float = 0.0
    chi2_noise: float = float("nan")  #: chi-square against the noise of each row alone
    random_walk: float = 0.0  #: bias random-walk q^2 in the standard errors [(m/s^2)^2 / s] (weights="auto")
    stochastic: "stochastic.StochasticFit | None" = None  #: the REML test that named it
    #: how far the bias moved during the recording, about its mean (the offsets' epoch); with random_walk > 0
    bias_drift: "stochastic.BiasDrift | None" = None
    #: samples mode: per interval, E|a| of its samples minus |a| of their mean, from their own scatter [m/s^2]
    #: (corrected: ``_samples_rows``); None for interval means
    scatter_term: np.ndarray | None = None
    #: samples mode: how far the values would be without that correction (uncorrected minus corrected, to
    #: first order) [each parameter's unit]; None for interval means
    scatter_shift: dict[str, float] | None = None

    @property
    def redchi(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def scatter_z(self) -> tuple[str, float] | None:
        """Samples mode: (parameter, |shift| / std) of the value the scatter correction moved most, in
        its standard errors; None for interval means."""
        if not self.scatter_shift:
            return None
        z = {n: abs(v) / self.std[n] for n, v in self.scatter_shift.items() if self.std.get(n, 0.0) > 0}
        return max(z.items(), key=lambda kv: kv[1]) if z else None

    @property
    def bias_instability(self) -> float:
        """Per-visit bias offsets [m/s^2 rms] (Paule-Mandel's excess, or REML's beside a random walk)."""
        return float(np.sqrt(self.excess))

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

    @property
    def kind(self) -> str:
        """The sensor's kind (its description's)."""
        return self.model.kind if self.model is not None else "accelerometer"

    def apply(self, raw: np.ndarray, inputs: np.ndarray | None = None) -> np.ndarray:
        """The calibrated readings (N, 3) or (3,) of raw ones through the description's map at the fitted
        values; ``inputs`` (N, k) its other inputs (the gyroscope's: the calibrated acceleration)."""
        one = np.ndim(raw) == 1
        if inputs is None and self.model.inputs and _reads_inputs(self.model, self.params.values()):
            raise ImucalError(f"this {self.kind} calibration reads {', '.join(self.model.inputs)}", field="inputs",
                              fix=f"pass them ({', '.join(self.model.inputs)}) for the same samples")
        out = apply_values(self.model, self.params.values(), raw, None if inputs is None else np.atleast_2d(inputs))
        return out[0] if one else out

    def correlations(self, threshold: float = 0.5) -> list[tuple[str, str, float]]:
        """Pairs of free parameters whose correlation exceeds ``threshold`` in size."""
        n, C = self.free_names, self.correlation
        return [(n[i], n[j], float(C[i, j])) for i in range(len(n)) for j in range(i + 1, len(n))
                if abs(C[i, j]) > threshold]

    def values(self) -> dict[str, float]:
        return self.params.value_dict()


def _reads_inputs(model: SensorModel, p: list[float]) -> bool:
    """The map depends on its inputs at these values (an affine map's B is not zero; any other map: yes)."""
    aff = model.affine
    return aff is None or bool(np.any(np.asarray(aff(p)[2])))


def _step_scale(Jw: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Predicted standard error of each free parameter: the solver's unit (x = (p - p0)/d).

    In these units IPOPT sees an objective whose Hessian is near the identity, so its
    tolerances mean "a tiny fraction of a standard error" for every parameter alike.
    """
    with np.errstate(invalid="ignore"):
        d = np.sqrt(np.clip(np.diag(unscaled_covariance(Jw)), 0, None))
    d = np.where(np.isfinite(d) & (d > 0), d, scale)
    return np.clip(d, 1e-9 * scale, scale)


def solve_scaled(evidence: Evidence, pfix: np.ndarray, p_now: np.ndarray, sigma: np.ndarray, scale: np.ndarray,
                 lo: np.ndarray, hi: np.ndarray, exact: bool = False, step=None) -> tuple[np.ndarray, dict]:
    """One IPOPT solve of ``evidence`` weighted by 1/sigma^2, from ``p_now`` within [lo, hi]: the unknowns
    are scaled by each free parameter's predicted standard error (p = p_now + d x, ``_step_scale``), so
    IPOPT sees numbers near one and a Hessian near the identity. Returns (free parameters, IPOPT's stats)."""
    d = _step_scale(evidence.r_factor(p_now, pfix, sigma), scale)
    problem = lsq.Problem(evidence, 1.0 / sigma**2, pfix, p_now, d, exact=exact, step=step)
    x, stats = lsq.solve(problem, (lo - p_now) / d, (hi - p_now) / d)
    return np.clip(p_now + d * x, lo, hi), stats


def fit_evidence(model: SensorModel, evidence: FitEvidence, params: Parameters,
                 known_std: Mapping[str, float] | None = None, summary: EvidenceSummary | None = None) -> FitResult:
    """The one fit of a sensor's evidence (issue 26): the observability check, IPOPT on the residuals
    weighted by their noise, the covariance, one result.

    1. What the evidence determines (imucal.solve.observability.determination on its observability rows,
       each parameter's threshold Parameter.undetermined x scale): the evidence refuses, naming what to record.
    2. IPOPT through imucal.solve.least_squares, unknowns scaled by their predicted standard errors
       (``solve_scaled``), within each parameter's bounds.
    3. The covariance from the R factor of the weighted Jacobian at the solution, scaled by chi2/dof
       (lmfit's scale_covar; the noise-only one without degrees of freedom).
    A fixed parameter's standard error is ``known_std``'s (what the evidence's preparation measured it to,
    NaN otherwise); a free one found there too was corrected by the fit from that value, and the two
    independent errors add in quadrature.
    """
    free = params.free_names
    pfix = np.array(params.values(), float)
    p0 = np.array([params[n].value for n in free])
    scale = np.array([params[n].scale for n in free])
    lo, hi = np.array([params[n].lower for n in free]), np.array([params[n].upper for n in free])
    limits = np.array([params[n].scale * (params[n].undetermined or 1.0) for n in free])
    evidence.require_determined(determination(evidence.observability_rows(p0, pfix), free, limits))
    t0 = time.perf_counter()
    p, stats = solve_scaled(evidence, pfix, p0, evidence.sigma, scale, lo, hi)
    solve_time = time.perf_counter() - t0
    r = evidence.residuals(p, pfix)
    chi2, dof = float(np.sum((r / evidence.sigma) ** 2)), int(evidence.dof)
    cov = unscaled_covariance(evidence.r_factor(p, pfix, evidence.sigma)) * (chi2 / dof if dof > 0 else 1.0)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(sd, sd)
    known = dict(known_std or {})
    std = {n: float(known.get(n, float("nan"))) for n in params.names}
    std.update({n: float(np.hypot(v, known.get(n, 0.0))) for n, v in zip(free, sd)})
    fitted = params.with_values(dict(zip(free, p)))
    status = str(stats.get("return_status", "unknown"))
    return FitResult(params=fitted, initial=params, std=std, covariance=cov, correlation=corr, free_names=free,
                     residuals=r, sigma=evidence.sigma, chi2=chi2, dof=dof, status=status,
                     success=status in _CONVERGED, iterations=int(stats.get("iter_count", 0)), solve_time=solve_time,
                     model_name=model_label(model.name, params),
                     at_bound={n: b for n in free if (b := fitted[n].at_bound()) is not None}, model=model,
                     summary=summary)


def fit(data: FitData, params: Parameters, model: SensorModel, gravity: float,
        source: str | None = None, weights: str = "noise", hessian: str = "gauss-newton") -> FitResult:
    """Fit the free parameters of ``params`` to ``data`` by weighted least squares (IPOPT).

    ``weights="noise"`` weighs each row by 1/sigma^2 (its noise propagated from the raw
    scatter); ``"uniform"`` gives every row the median sigma (imu_tk's unweighted cost);
    ``"auto"`` (interval means) has the uniform fit's values and the noise's standard errors: the
    sandwich (J^T J)^-1 J^T V J (J^T J)^-1 with V each mean's noise, plus, when the residuals exceed
    it at p < EXCESS_P, the between-interval excess (a random bias per visit of a pose, Paule-Mandel),
    or, when the REML test of imucal.solve.stochastic names a bias random walk (rows with times
    ``data.t``), the walk's covariance about its mean (the bias moved: the offsets then estimate the
    bias averaged over the intervals; ``bias_drift`` says how far it moved). Every interval counts
    alike because its own scatter does not tell how far its mean is off (``_sandwich``).
    Samples mode: each row's gravity is g plus the second-order terms of its interval's scatter
    (``_samples_rows``). ``hessian="exact"`` gives IPOPT the exact Hessian instead of Gauss-Newton's
    J^T W J.

    Args:
        data: the rows (interval means or samples), their noise and covariates (pipeline.fit_data).
        params: every parameter, free or held, with its start and bounds.
        model: the sensor model whose residual is fitted.
        gravity: local g [m/s^2].
        source: the recording's name, for messages.
        weights: "noise", "uniform" or "auto", as above.
        hessian: "gauss-newton" or "exact".

    Returns:
        The FitResult: values, standard errors, covariance, chi-square, solver status.
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
    it = _iterate(fns, rows, data, params, model, pfix, gravity, weights, hessian)
    solve_time = time.perf_counter() - t0
    status = str(it.stats.get("return_status", "unknown"))
    dof = n - len(free)
    r = lsq.residuals(fns, rows, it.p, pfix, it.g)
    fitted = params.with_values(dict(zip(free, it.p)))
    sigma, chi2, chi2_noise, cov, drift = _statistics(fns, rows, data, params, it, pfix, gravity, r, dof)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(sd, sd)
    std = {nm: float("nan") for nm in names}
    if dof > 0 or data.mode != "means":  # no residual left to scale by: std not estimable
        std.update({nm: float(v) for nm, v in zip(free, sd)})
    at_bound = {nm: b for nm in free if (b := fitted[nm].at_bound()) is not None}
    return FitResult(params=fitted, initial=params, std=std, covariance=cov, correlation=corr,
                     free_names=free, gravity=gravity, mode=data.mode, residuals=r, sigma=sigma,
                     chi2=chi2, dof=dof, status=status, success=status in _CONVERGED, iterations=it.iterations,
                     solve_time=solve_time, model_name=model_label(model.name, params), at_bound=at_bound, model=model,
                     excess=it.excess, chi2_noise=chi2_noise, random_walk=it.q2,
                     stochastic=it.sto if it.q2 > 0 else None, bias_drift=drift,
                     scatter_term=None if it.samples is None else it.samples.term,
                     scatter_shift=None if it.samples is None else dict(zip(free, it.samples.shift)))


def _statistics(fns, rows, data: FitData, params: Parameters, it: "_Iterated", pfix, gravity: float, r: np.ndarray,
                dof: int) -> tuple[np.ndarray, float, float, np.ndarray, "stochastic.BiasDrift | None"]:
    """(sigma of each row, chi-square, chi-square against the noise alone, covariance of the free
    parameters, how far a walking bias moved)."""
    if it.auto:  # the rows' covariance V and the sandwich; the test of the noise is the noise-weighted fit's
        V, drift = _auto_rows_covariance(fns, rows, data, params, it, pfix, gravity)
        J = lsq.jacobians(fns, rows, it.p, pfix, gravity)[1]
        X = J[:, _movable(params, it.p)]
        sigma = np.sqrt(V if V.ndim == 1 else np.diag(V))
        # V's own chi-square is the V-weighted fit's (projected_chi2: about dof when V is right, whatever
        # weights gave the values): it scales the sandwich as lmfit's scale_covar, except for a walk's V,
        # the residuals' own (REML). The chi-square reported is at the values (a walk's V is full: V's own).
        chi2_v = projected_chi2(r, V if drift is not None else sigma**2, X)
        chi2 = chi2_v if drift is not None else float(np.sum((r / sigma) ** 2))
        k = 1.0 if drift is not None or dof < 1 else chi2_v / dof
        return sigma, chi2, projected_chi2(r, it.sigma0**2, X), _sandwich(J, V, k), drift
    # Covariance from the Jacobian at the solution (via its SVD, symmetric by construction),
    # scaled by the residual variance as lmfit's scale_covar does: (J^T W J)^-1 chi2/dof.
    # With no degrees of freedom left, the noise-only covariance (J^T W J)^-1.
    chi2 = float(np.sum((r / it.sigma) ** 2))
    R = lsq.weighted_r_factor(fns, rows, it.sigma, it.p, pfix, it.g)
    cov = unscaled_covariance(R) * (chi2 / dof if dof > 0 else 1.0)
    return it.sigma, chi2, float(np.sum((r / it.sigma0) ** 2)), cov, None


@dataclass
class _Iterated:
    """Where the fit settled, and the noise, excess and walk its standard errors take."""

    p: np.ndarray  #: free parameters
    sigma0: np.ndarray  #: noise of each row alone
    sigma: np.ndarray  #: with the between-interval excess
    g: float | np.ndarray  #: gravity of every row, or each row's own (samples: ``_samples_rows``) [m/s^2]
    excess: float
    q2: float
    sto: "stochastic.StochasticFit | None"
    iterations: int
    stats: dict
    samples: "_SamplesRows | None" = None  #: samples mode: the scatter correction at the last pass
    auto: bool = False  #: weights="auto" on interval means: uniform values, standard errors from the noise


def _iterate(fns, rows, data: FitData, params: Parameters, model: SensorModel, pfix: np.ndarray, gravity: float,
             weights: str, hessian: str) -> _Iterated:
    """IPOPT on the weighted rows, twice: the weights refreshed from the noise propagated at the first
    solution. weights="auto" on interval means: the uniform fit, then at its solution the noise of each
    mean, the between-interval excess and the walk test (``_excess``) for the standard errors."""
    free = params.free_names
    scale = np.array([params[nm].scale for nm in free])
    lo, hi = np.array([params[nm].lower for nm in free]), np.array([params[nm].upper for nm in free])
    p_now = np.array([params[nm].value for nm in free])
    dof = data.raw.shape[0] - len(free)
    auto = weights == "auto" and data.mode == "means"
    values_weights = "uniform" if auto else weights
    iters = 0
    scatter = _interval_scatter(data) if data.mode == "samples" else None
    srows = None
    shown = None if data.mode == "samples" else False  # samples mode: a bar on a terminal (report.progress)
    with progress(f"samples fit ({data.raw.shape[0]:,} samples)", unit="pass", enabled=shown) as step:
        for _ in range(2):  # once more, with the weights at the solution
            if scatter is None:
                g, sigma0 = gravity, lsq.noise_sigma(fns, rows, data.raw_var, p_now, pfix, gravity, values_weights)
            else:
                srows = _samples_rows(fns, model, free, scatter, p_now, pfix, gravity, values_weights)
                g, sigma0 = srows.g, srows.sigma0
            p_now, stats = solve_scaled(lsq.RowEvidence(fns, rows, g), pfix, p_now, sigma0, scale, lo, hi,
                                        exact=hessian == "exact", step=step)
            iters += int(stats.get("iter_count", 0))
    excess, q2, sto = 0.0, 0.0, None
    if auto:  # the noise at the solution, and what the residuals show beyond it
        sigma0 = lsq.noise_sigma(fns, rows, data.raw_var, p_now, pfix, gravity, "noise")
        if dof >= 1:
            r0, X, _ = lsq.jacobians(fns, rows, p_now, pfix, gravity)
            X = X[:, _movable(params, p_now)]
            excess, q2, sto = _excess(fns, rows, data, params, p_now, pfix, gravity, r0, sigma0, X, dof)
    return _Iterated(p_now, sigma0, np.sqrt(sigma0**2 + excess), g, excess, q2, sto, iters, stats, srows, auto)


def _movable(params: Parameters, p_now: np.ndarray) -> np.ndarray:
    """Which free parameters are off their bounds at p_now: the directions a weighted fit could still take
    out of the residuals (``projected_chi2``); one at a bound cannot."""
    at = params.with_values(dict(zip(params.free_names, p_now)))
    return np.array([at[n].at_bound() is None for n in params.free_names], bool)


def _components(fns, rows, data: FitData, params: Parameters, p_now, pfix, gravity: float,
                sigma0: np.ndarray) -> stochastic.Components:
    """The stochastic-bias components at p_now (G uses the current scales b_i)."""
    b = _scales(params, p_now, pfix)
    return stochastic.components_at(fns, rows, p_now, pfix, gravity, sigma0, b, data.t)


def _scales(params: Parameters, p_now, pfix) -> np.ndarray:
    """The scales b1, b2, b3 at p_now [raw per m/s^2]."""
    values = dict(zip(params.names, pfix)) | dict(zip(params.free_names, p_now))
    return np.array([values[f"b{i}"] for i in (1, 2, 3)])


def _auto_rows_covariance(fns, rows, data: FitData, params: Parameters, it: _Iterated, pfix, gravity: float
                          ) -> tuple[np.ndarray, "stochastic.BiasDrift | None"]:
    """weights="auto": the covariance V of the interval means' residuals (its diagonal, as a vector, when
    the bias does not walk), and how far a walking bias moved.

    V is each mean's noise plus the between-interval excess; with a bias random walk, plus the walk about
    its mean over the intervals (``Components.about_mean``, REML's variances), so that the offsets' errors
    are those of the bias averaged over the intervals: their epoch.
    """
    if it.q2 <= 0:  # diagonal: its variances alone (an n x n matrix would be O(intervals^2) memory)
        return it.sigma**2, None
    c = _components(fns, rows, data, params, it.p, pfix, gravity, it.sigma0)
    tau2, q2 = it.sto.chosen.tau2, it.sto.chosen.q2
    return c.about_mean(tau2, q2), stochastic.bias_drift(c, tau2, q2, _scales(params, it.p, pfix))


def _sandwich(J: np.ndarray, V: np.ndarray, k: float) -> np.ndarray:
    """weights="auto": k (J^T J)^-1 J^T V J (J^T J)^-1, the covariance of the uniform fit's values.

    The values weigh every interval alike: on real recordings an interval's own scatter does not tell
    how far its mean is off (motion, a settling sensor, model error). Weighing by it left the default
    calibration fitting its own still poses up to 1.23 x worse than the uniform fit (the MPU-6050),
    with no better accuracy on the other recordings of the same sensor (ROS data2-4, each applied to
    the others). k scales V as lmfit's scale_covar does (V's own chi-square over dof), or is 1 when V
    is the residuals' own (a walk's, REML). ``V``: n x n, or its diagonal as a vector.
    """
    bread = unscaled_covariance(J)  # (J^T J)^-1
    # V diagonal: J^T diag(V), laid out as the product with the matrix was (C order), then J: the same
    # numbers in O(n) memory
    meat = (np.ascontiguousarray(J.T * V) if V.ndim == 1 else J.T @ V) @ J
    cov = bread @ meat @ bread * k
    return 0.5 * (cov + cov.T)


def _excess(fns, rows, data: FitData, params: Parameters, p_now, pfix, gravity: float, r0: np.ndarray,
            s0: np.ndarray, X: np.ndarray, dof: int) -> tuple[float, float, "stochastic.StochasticFit | None"]:
    """weights="auto": (tau^2, q^2, the test) when the residuals exceed the noise at p < EXCESS_P.

    The test is the noise-weighted fit's chi-square (``projected_chi2``: the columns of the Jacobian X
    taken out of r0, whatever weights gave it). A bias random walk named by the REML test
    (imucal.solve.stochastic), and told apart from per-visit offsets, gives its (tau^2, q^2) and the
    test; otherwise (or above stochastic.MAX_INTERVALS intervals) tau^2 is Paule-Mandel's common
    between-interval variance (iterated with the weighted fit: ``between_excess`` with X) and q^2 is 0.
    """
    chi2 = projected_chi2(r0, s0**2, X)
    if chi2_sf(chi2, dof) >= EXCESS_P:
        return 0.0, 0.0, None
    if data.t is not None and len(params.free_names) + 3 < len(r0) and stochastic.feasible(len(r0)) and (
            chi2 / dof < STOCHASTIC_MAX_REDCHI):
        sto = stochastic.select(_components(fns, rows, data, params, p_now, pfix, gravity, s0))
        if stochastic.RANDOM_WALK in sto.named and not sto.ambiguous:  # undecided: the per-visit excess
            return sto.chosen.tau2, sto.chosen.q2, sto
    return between_excess(r0, s0, dof, X), 0.0, None


@dataclass(frozen=True)
class _Scatter:
    """A samples fit's intervals: what the scatter correction (``_samples_rows``) needs of them."""

    group: np.ndarray  #: (N,) interval of each sample
    n: np.ndarray  #: (k,) samples per interval
    mean: np.ndarray  #: (k, 3) mean raw reading
    cov: np.ndarray  #: (k, c) mean covariates
    var: np.ndarray  #: (k, 3) per-sample variance of the noise model (the weights): data.raw_var's
    S: np.ndarray  #: (k, 3, 3) the samples' own covariance about their mean, ddof 0 [raw^2]


def _interval_scatter(data: FitData) -> _Scatter:
    """Per interval of a samples fit: counts, means, the weights' variance and the samples' covariance
    (ddof 0: what sum_k r(raw_k) = n (r(mean) + 1/2 tr(H S)) needs)."""
    g = data.group
    k = int(g.max()) + 1 if g.size else 0
    n = np.bincount(g, minlength=k).astype(float)
    n1 = np.maximum(n, 1.0)

    def per_interval(x: np.ndarray) -> np.ndarray:
        return np.stack([np.bincount(g, x[:, j], minlength=k) for j in range(x.shape[1])], axis=1) / n1[:, None] \
            if x.shape[1] else np.zeros((k, 0))

    mean = per_interval(data.raw)
    dev = data.raw - mean[g]
    S = np.empty((k, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            S[:, i, j] = S[:, j, i] = np.bincount(g, dev[:, i] * dev[:, j], minlength=k) / n1
    return _Scatter(g, n, mean, per_interval(data.cov), per_interval(data.raw_var), S)


@dataclass(frozen=True)
class _SamplesRows:
    """Samples mode at one estimate: each row's gravity and noise, and the scatter correction's size."""

    g: np.ndarray  #: (N,) what |a| of each sample averages to at the truth [m/s^2]
    sigma0: np.ndarray  #: (N,) noise of each sample's residual (its interval's, at the mean)
    term: np.ndarray  #: (k,) per interval E|a| of its samples minus |a| of their mean [m/s^2]
    shift: np.ndarray  #: (free,) uncorrected minus corrected values, to first order [parameter units]


def _samples_rows(fns, model: SensorModel, free: tuple[str, ...], sc: _Scatter, p_now, pfix, gravity: float,
                  weights: str) -> _SamplesRows:
    """Samples mode: the fit of every sample to g is biased by their scatter (errors in variables).

    For samples m + v about their interval's mean m with covariance S, to second order in v:
    E r(m + v) = r(m) + c with c = 1/2 tr(H S), H = d2r/draw2 (E|g + v| > g), and the score
    E[r J](m + v) = (r(m) + c) J(m) + d with d = dJ/draw S dr/draw^T (the Jacobian is noisy too: as large
    again). Solving sum w J (r - g_k) = 0 with each row's gravity g_k = g + c + J(m) . delta, where
    N delta = sum W d over intervals (N = sum W J J^T, W its rows' summed weights), removes both; the
    scales otherwise absorb 0.5-1.3 % under vibration. c, d and J come from the model's own residual
    (``_scatter_function``), at the interval's mean and p_now (refreshed with the weights); each sample
    takes its interval's noise at the mean, so no weight correlates with its own sample's noise."""
    mean, cov, S = sc.mean.T, sc.cov.T, sc.S.reshape(len(sc.S), 9).T
    s_iv = lsq.noise_sigma(fns, lsq.Rows(sc.mean, sc.cov), sc.var, p_now, pfix, gravity, weights)
    c, d, J = _scatter_function(model, free)(mean, cov, p_now, pfix, [gravity], S)
    W = sc.n / s_iv**2
    N = (J * W) @ J.T
    delta = np.linalg.lstsq(N, d @ W, rcond=None)[0]
    term = c[0] + delta @ J
    shift = -np.linalg.lstsq(N, J @ (W * c[0]) + d @ W, rcond=None)[0]
    return _SamplesRows(g=gravity + term[sc.group], sigma0=s_iv[sc.group], term=c[0], shift=shift)


@lru_cache(maxsize=64)
def _scatter_function(model: SensorModel, free: tuple[str, ...]) -> Vectorized:
    """(c, d, J) of one row: c = 1/2 tr(d2r/draw2 S), d = dJ/draw S dr/draw^T, J = dr/dpfree, from the
    row's own derivatives (imucal.solve.least_squares.row_functions) differentiated once more by CasADi."""
    f = lsq.row_functions(model, free).derivatives.function
    args = [ca.SX.sym(f"i{k}", f.sparsity_in(k)) for k in range(f.n_in())]
    S = ca.SX.sym("S", 3, 3)
    _, J, Jraw = f(*args)  # 1 x free, 1 x 3
    H = ca.jacobian(Jraw, args[0])  # 3 x 3
    d = ca.mtimes([ca.jacobian(J, args[0]), S, Jraw.T])  # free x 1
    return Vectorized(ca.Function("row_scatter", [*args, S], [0.5 * ca.trace(ca.mtimes(H, S)), d, J.T]))


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
