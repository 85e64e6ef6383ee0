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
from imucal.solve import least_squares as lsq
from imucal.solve import stochastic
from imucal.solve.stats import between_excess, chi2_sf
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
#: weights="auto": at most this many solves while the excess settles.
MAX_PASSES = 8
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
    #: between-interval excess variance added to every row's sigma^2 in the weights [(m/s^2)^2] (weights="auto",
    #: Paule-Mandel; with a bias random walk named, the walk's scatter)
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
        """Per-visit bias offsets [m/s^2 rms]: the excess in the weights, or, with a random walk named (whose
        scatter the weights' excess then holds), REML's own per-visit component (0 unless named too)."""
        if self.random_walk > 0 and self.stochastic is not None:
            return float(np.sqrt(self.stochastic.chosen.tau2))
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
    bias moved during the recording: the values are still those of the weights above (the offsets
    then estimate the bias averaged over the intervals, the constant that fits the still poses), and
    the covariance is the sandwich under the walk's full covariance about that mean (``_walk_covariance``);
    ``bias_drift`` says how far it moved. Samples mode: each row's gravity is g plus the second-order
    terms of its interval's scatter (``_samples_rows``). ``hessian="exact"`` gives IPOPT the exact Hessian
    instead of Gauss-Newton's J^T W J.
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
    R = lsq.weighted_r_factor(fns, rows, it.sigma, it.p, pfix, it.g)
    fitted = params.with_values(dict(zip(free, it.p)))
    chi2 = float(np.sum((r / it.sigma) ** 2))
    redchi = chi2 / dof if dof > 0 else float("nan")
    drift = None
    if it.q2 > 0:  # a bias random walk: the sandwich under its covariance about the mean, and how far it moved
        cov, drift = _walk_covariance(fns, rows, data, params, it, pfix, gravity, R)
    else:
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
                     stochastic=it.sto if it.q2 > 0 else None, bias_drift=drift,
                     scatter_term=None if it.samples is None else it.samples.term,
                     scatter_shift=None if it.samples is None else dict(zip(free, it.samples.shift)))


@dataclass
class _Iterated:
    """Where the weighted fit and its weights settled."""

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


def _iterate(fns, rows, data: FitData, params: Parameters, model: SensorModel, pfix: np.ndarray, gravity: float,
             weights: str, hessian: str) -> _Iterated:
    """IPOPT on the weighted rows, the weights refreshed from the noise propagated at the estimate;
    once at the solution and, with weights="auto", until the between-interval excess (and a named
    bias random walk's variances, which the covariance uses) settles."""
    free = params.free_names
    scale = np.array([params[nm].scale for nm in free])
    lo, hi = np.array([params[nm].lower for nm in free]), np.array([params[nm].upper for nm in free])
    p_now = np.array([params[nm].value for nm in free])
    dof = data.raw.shape[0] - len(free)
    iters, excess, q2, sto, passes = 0, 0.0, 0.0, None, 0
    walk_test = True  # the REML random-walk test (imucal.solve.stochastic) runs until it rejects a walk once
    scatter = _interval_scatter(data) if data.mode == "samples" else None
    srows = None
    shown = None if data.mode == "samples" else False  # samples mode: a bar on a terminal (report.progress)
    with progress(f"samples fit ({data.raw.shape[0]:,} samples)", unit="pass", enabled=shown) as step:
        while True:
            if scatter is None:
                g, sigma0 = gravity, lsq.noise_sigma(fns, rows, data.raw_var, p_now, pfix, gravity, weights)
            else:
                srows = _samples_rows(fns, model, free, scatter, p_now, pfix, gravity, weights)
                g, sigma0 = srows.g, srows.sigma0
            sigma = np.sqrt(sigma0**2 + excess)
            R = lsq.weighted_r_factor(fns, rows, sigma, p_now, pfix, g)
            d = _step_scale(R, scale)  # p = p0 + d * x
            problem = lsq.Problem(fns, rows, 1.0 / sigma**2, pfix, g, p_now, d, exact=hessian == "exact", step=step)
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
    return _Iterated(p_now, sigma0, sigma, g, excess, q2, sto, iters, stats, srows)


def _components(fns, rows, data: FitData, params: Parameters, p_now, pfix, gravity: float,
                sigma0: np.ndarray) -> stochastic.Components:
    """The stochastic-bias components at p_now (G uses the current scales b_i)."""
    b = _scales(params, p_now, pfix)
    return stochastic.components_at(fns, rows, p_now, pfix, gravity, sigma0, b, data.t)


def _scales(params: Parameters, p_now, pfix) -> np.ndarray:
    """The scales b1, b2, b3 at p_now [raw per m/s^2]."""
    values = dict(zip(params.names, pfix)) | dict(zip(params.free_names, p_now))
    return np.array([values[f"b{i}"] for i in (1, 2, 3)])


def _walk_covariance(fns, rows, data: FitData, params: Parameters, it: _Iterated, pfix, gravity: float,
                     R: np.ndarray) -> tuple[np.ndarray, "stochastic.BiasDrift"]:
    """The covariance of the values when the bias walks, and how far it moved.

    The values come from the diagonal weights W (noise plus the excess); under the walk the rows'
    covariance is V, the walk taken about its mean over the intervals (``Components.about_mean``,
    REML's variances), so the sandwich (J^T W J)^-1 J^T W V W J (J^T W J)^-1 is the covariance of the
    values around the scales and angles and the bias averaged over the intervals: the offsets'
    epoch. Not scaled by chi2/dof: V is the residuals' own covariance, estimated from them (REML).
    """
    c = _components(fns, rows, data, params, it.p, pfix, gravity, it.sigma0)
    V = c.about_mean(it.sto.chosen.tau2, it.sto.chosen.q2)
    J = lsq.jacobians(fns, rows, it.p, pfix, gravity)[1] / (it.sigma**2)[:, None]  # W J
    bread = unscaled_covariance(R)  # (J^T W J)^-1
    cov = bread @ (J.T @ V @ J) @ bread
    drift = stochastic.bias_drift(c, it.sto.chosen.tau2, it.sto.chosen.q2, _scales(params, it.p, pfix))
    return 0.5 * (cov + cov.T), drift


def _excess(fns, rows, data: FitData, params: Parameters, p_now, pfix, gravity: float, r0: np.ndarray,
            s0: np.ndarray, dof: int, walk_test: bool = True) -> tuple[float, float, "stochastic.StochasticFit | None"]:
    """weights="auto": (tau^2, q^2, the test) when the residuals exceed the noise at p < EXCESS_P.

    tau^2 is Paule-Mandel's common between-interval variance, the excess in the weights. A bias
    random walk named by the REML test (imucal.solve.stochastic), and told apart from per-visit
    offsets, adds its q^2 (with the test, whose variances the covariance uses); q^2 is 0 otherwise
    (or above stochastic.MAX_INTERVALS intervals).
    """
    if chi2_sf(float(np.sum((r0 / s0) ** 2)), dof) >= EXCESS_P:
        return 0.0, 0.0, None
    tau2 = between_excess(r0, s0, dof)
    if walk_test and data.t is not None and len(params.free_names) + 3 < len(r0) and stochastic.feasible(len(r0)) and (
            float(np.sum((r0 / s0) ** 2)) / dof < STOCHASTIC_MAX_REDCHI):
        sto = stochastic.select(_components(fns, rows, data, params, p_now, pfix, gravity, s0))
        if stochastic.RANDOM_WALK in sto.named and not sto.ambiguous:  # undecided: the per-visit excess
            return tau2, sto.chosen.q2, sto
    return tau2, 0.0, None


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
