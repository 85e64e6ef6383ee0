"""The magnetometer fit: its rows on the one least-squares path (imucal.solve.least_squares).

Minimise 1/2 sum_k (r_k / sigma_k)^2 over the free parameters, r_k the residual of row k's evidence
(imucal.mag.model: |h| - F, the dip, the SIZE and SKEW constraints) and sigma_k its noise propagated from the readings
(the model's ``noise``), times one factor per kind of evidence: the square root of each kind's own reduced
chi-square, re-estimated between passes (variance components, Helmert), so that a thousand samples of the
field's magnitude and a hundred poses' dip angles weigh as their scatter says, whatever the noise estimate
missed; and of its batch inflation (residuals that move together in time count for less). The row evaluators, IPOPT and the covariance are the accelerometer's: the rows are a RowEvidence whose
evaluators ``row_functions`` generates from the residual, solved by ``solve_scaled`` (imucal.solve.fit), the
covariance from the block-QR R factor by the one routine (imucal.solve.covariance.unscaled_covariance).
"""
from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

import numpy as np

from imucal.errors import ImucalError
from imucal.mag.evidence import MagRows
from imucal.mag.model import DIP, NORM, SIZE, SKEW_KINDS, vectorized
from imucal.model.sensor import SensorModel
from imucal.model.parameters import Parameters
from imucal.solve import ipopt
from imucal.solve import least_squares as lsq
from imucal.solve.f_test import f_sf
from imucal.solve.covariance import unscaled_covariance
from imucal.solve.fit import solve_scaled

#: Kinds of constraint rows: their noise is CONSTRAINT_SIGMA (imucal.mag.model), never floored.
CONSTRAINT_KINDS = (SIZE, *SKEW_KINDS)
#: A measurement row's noise is at least this fraction of its kind's median (a sample on a quantisation step).
NOISE_FLOOR = 1e-3
#: Passes of the fit, the variance components refreshed between them (they settle in two).
PASSES = 3
#: Kinds whose noise is scaled by their own reduced chi-square.
SCALED_KINDS = (NORM, DIP)
#: Batches of the batch-means test of correlated residuals (``batch_inflation``): its estimate has about
#: this many degrees of freedom.
BATCHES = 20


@dataclass(frozen=True)
class MagFitResult:
    """A fitted magnetometer: values, uncertainties, residuals by kind, the solver's status."""

    model: SensorModel
    params: Parameters
    std: Mapping[str, float]
    covariance: np.ndarray  #: over ``free_names``
    free_names: tuple[str, ...]
    residuals: np.ndarray  #: per row, in the row's unit (field unit or rad)
    sigma: np.ndarray  #: per row, the noise times its kind's factor
    kinds: np.ndarray  #: per row
    factors: Mapping[int, float]  #: per kind: sqrt of its reduced chi-square against the noise alone
    chi2: float
    dof: int
    status: str
    iterations: int

    @property
    def success(self) -> bool:
        return self.status in ipopt.CONVERGED

    @property
    def correlation(self) -> np.ndarray:
        sd = np.sqrt(np.clip(np.diag(self.covariance), 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.covariance / np.outer(sd, sd)

    def values(self) -> dict[str, float]:
        return self.params.value_dict()

    def chi2_of(self, kind: int, sigma: np.ndarray | None = None) -> float:
        m = self.kinds == kind
        s = self.sigma if sigma is None else sigma
        return float(np.sum((self.residuals[m] / s[m]) ** 2))


def _full(params: Parameters, free: tuple[str, ...], p_free: np.ndarray) -> np.ndarray:
    v = dict(zip(params.names, params.values())) | dict(zip(free, p_free))
    return np.array([v[n] for n in params.names], float)


def row_noise(model: SensorModel, rows: MagRows, p: np.ndarray) -> np.ndarray:
    """sigma of every row's residual at the full parameter vector p (the model's ``noise``)."""
    out = np.empty(rows.n)
    f = vectorized(model, "noise")
    for s in range(0, rows.n, lsq.BLOCK):
        sl = slice(s, s + lsq.BLOCK)
        out[sl] = f(rows.raw[sl].T, rows.cov[sl].T, p, rows.target[sl][None, :], rows.var_raw[sl].T,
                    rows.var_acc[sl].T)[0][0]
    # a floor per kind of measurement (a row whose noise vanishes would weigh without bound), in its own unit;
    # the constraint rows keep CONSTRAINT_SIGMA (a floor taken across kinds, in the field's unit, loosened them)
    for k in np.unique(rows.kind):
        m = rows.kind == k
        if int(k) in CONSTRAINT_KINDS:
            continue
        pos = out[m][out[m] > 0]
        out[m] = np.maximum(out[m], max(float(np.median(pos)) * NOISE_FLOOR if pos.size else 1e-12, 1e-12))
    return out


def batch_inflation(z: np.ndarray, batches: int = BATCHES) -> float:
    """Variance of the means of ``batches`` consecutive batches of z (rows in time order) over what
    independent rows give, at least 1: residuals that move together (a field or hard iron that drifts, one
    pose's common error) carry less information than their number says (batch means, as the
    accelerometer's noise_inflation)."""
    m = len(z) // batches
    if m < 2:
        return 1.0
    zz = np.asarray(z[: m * batches], float)
    v = float(np.var(zz))
    return max(1.0, float(np.var(zz.reshape(batches, m).mean(axis=1))) * m / v) if v > 0 else 1.0


def _kind_dof(fns: lsq.RowFunctions, rows: MagRows, sigma: np.ndarray, p_free: np.ndarray, pfix: np.ndarray
              ) -> dict[int, float]:
    """Each kind's degrees of freedom: its rows less the trace of its share of the hat matrix,
    n_k - tr(C H_k) with H_k = R_k^T R_k its rows' J^T W J and C = (sum_k H_k)^-1 (its leverage: the DIP
    rows alone carry the rotation and the dip, so their scatter is that of n_k - 4 degrees of freedom)."""
    R = {}
    for k in np.unique(rows.kind):
        m = rows.kind == k
        R[int(k)] = lsq.weighted_r_factor(fns, lsq.Rows(rows.raw[m], rows.cov[m]), sigma[m], p_free, pfix,
                                          rows.target[m])
    C = unscaled_covariance(np.vstack(list(R.values())))
    return {k: float(np.sum(rows.kind == k)) - float(np.trace(C @ (Rk.T @ Rk))) for k, Rk in R.items()}


def _factors(r: np.ndarray, sigma0: np.ndarray, kinds: np.ndarray, dof: Mapping[int, float]) -> dict[int, float]:
    """Per kind, sqrt(chi2_k / dof_k times its batch inflation), dof_k from its leverage (``_kind_dof``;
    rows of one kind are in time order)."""
    out = {}
    for k in SCALED_KINDS:
        m = kinds == k
        if m.sum() and dof.get(k, 0.0) > 0:
            z = r[m] / sigma0[m]
            out[k] = float(np.sqrt(np.sum(z**2) / dof[k] * batch_inflation(z - z.mean())))
    return out


def _row_factors(kinds: np.ndarray, factors: Mapping[int, float]) -> np.ndarray:
    return np.array([factors.get(k, 1.0) for k in range(int(kinds.max(initial=0)) + 1)])[kinds]


def fit_rows(model: SensorModel, rows: MagRows, params: Parameters, factors: Mapping[int, float] | None = None,
             source: str | None = None) -> MagFitResult:
    """Fit the free parameters of ``params`` to ``rows``; ``factors`` given: held (not re-estimated)."""
    free = params.free_names
    dof = rows.n - len(free)
    if dof < 1:
        raise ImucalError(f"{rows.n} rows cannot determine {len(free)} free parameters", file=source,
                          field="mx, my, mz", fix="record the magnetometer through more orientations")
    fns = lsq.row_functions(model, free)
    evidence = lsq.RowEvidence(fns, lsq.Rows(rows.raw, rows.cov), rows.target)  # the accelerometer's row evidence
    pfix = np.array(params.values(), float)
    scale = np.array([params[n].scale for n in free])
    lo, hi = np.array([params[n].lower for n in free]), np.array([params[n].upper for n in free])
    p_now = np.array([params[n].value for n in free])
    kinds, held = rows.kind, factors is not None
    fac: dict[int, float] = dict(factors or {})
    iters, stats = 0, {}
    for _ in range(1 if held else PASSES):
        sigma = row_noise(model, rows, _full(params, free, p_now)) * _row_factors(kinds, fac)
        p_now, stats = solve_scaled(evidence, pfix, p_now, sigma, scale, lo, hi)
        iters += int(stats.get("iter_count", 0))
        if not held:
            sigma0 = row_noise(model, rows, _full(params, free, p_now))
            fac = _factors(evidence.residuals(p_now, pfix), sigma0, kinds, _kind_dof(fns, rows, sigma0, p_now, pfix))
    r = evidence.residuals(p_now, pfix)
    sigma = row_noise(model, rows, _full(params, free, p_now)) * _row_factors(kinds, fac)
    chi2 = float(np.sum((r / sigma) ** 2))
    cov = unscaled_covariance(evidence.r_factor(p_now, pfix, sigma))  # the factors scale each kind's noise already
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    std = {n: float("nan") for n in params.names}  # held parameters: no standard error
    std.update(dict(zip(free, map(float, sd))))
    return MagFitResult(model, params.with_values(dict(zip(free, p_now))), MappingProxyType(std), cov, free, r,
                        sigma, kinds, MappingProxyType(fac), chi2, dof, str(stats.get("return_status", "unknown")),
                        iters)


@dataclass(frozen=True)
class SoftIronTest:
    """Symmetric soft iron (the SKEW rows: the magnetometer's permuted axes are the accelerometer's) against
    the full 3x3 (without them: a rotation between the two frames).

    The rotation is seen only through the DIP rows, whose noise the fit scaled to their own scatter
    (variance components): F = (chi2_symmetric - chi2_full) / 3 with the full fit's weights, against
    F(3, DIP rows - 4), the degrees of freedom that scale came from; the full form is kept when p < ``level``."""

    f: float
    p: float
    level: float
    full: bool


#: The full soft iron (a rotation to the accelerometer's frame) is kept at this significance.
SOFT_IRON_LEVEL = 1e-3
#: Parameters the DIP rows alone determine: the rotation and the dip.
DIP_PARAMETERS = 4


def soft_iron_test(full: MagFitResult, symmetric: MagFitResult, level: float = SOFT_IRON_LEVEL) -> SoftIronTest:
    """The F test of the three SKEW constraints (``SoftIronTest``); ``symmetric`` fitted to the full fit's
    rows with the SKEW rows appended."""
    keep = ~np.isin(symmetric.kinds, SKEW_KINDS)
    k = int(np.sum(~keep))
    chi2_sym = float(np.sum((symmetric.residuals[keep] / full.sigma) ** 2))
    f = max(chi2_sym - full.chi2, 0.0) / k
    p = f_sf(f, k, max(int(np.sum(full.kinds == DIP)) - DIP_PARAMETERS, 1))
    return SoftIronTest(float(f), float(p), level, p < level)
