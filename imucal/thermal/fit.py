"""The pose-constancy fit: a still sensor's calibrated reading does not change with temperature.

For row k of pose P (imucal.thermal.evidence) the residual is the 3-vector

    r_k = a(raw_k, T_k; p) - v_P

with a the model's own calibrated reading (SensorModel.accel: the Theorem with the effects, Eq.
theModel, built once in CasADi) and v_P the pose's gravity vector in the sensor frame, one free
3-vector per pose. The free parameters are the temperature terms' coefficients; the base
parameters (shifts, scales, angles) are held: a common shift or scale moves every v_P alike and
no pose tells it (|a| = g does: imucal.solve.fit). a and da/dp are numpy code generated from the
CasADi function (imucal.solve.vectorize); IPOPT solves the scaled problem through the one
least-squares solver (imucal.solve.least_squares.solve) with the Gauss-Newton Hessian, and the
covariance is the one routine (imucal.solve.fit.unscaled_covariance) scaled by chi2/dof as
lmfit's scale_covar. Rows weigh alike (the default fit's uniform values): their own scatter
does not say how far a row's mean is off (a settling part, a slow drift).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from imucal.errors import ImucalError
from imucal.model.parameters import Parameters
from imucal.model.sensor import SensorModel
from imucal.solve import least_squares as lsq
from imucal.solve.fit import unscaled_covariance
from imucal.solve.stats import median
from imucal.solve.vectorize import Vectorized
from imucal.thermal.evidence import ThermalRows


@lru_cache(maxsize=64)
def accel_rows(model: SensorModel, free: tuple[str, ...]) -> Vectorized:
    """(raw, cov, pfree, pfix) -> (a [3], da/dpfree [3 x nf]) of one row, from SensorModel.accel."""
    raw, cov = ca.SX.sym("raw", 3), ca.SX.sym("cov", len(model.covariates))
    pf, pfix, p = lsq.split_parameters(model.names, free)  # every evidence's split (one code path)
    a = model.accel(raw, cov, p)
    return Vectorized(ca.Function("thermal_a", [raw, cov, pf, pfix], [a, ca.jacobian(a, pf)]))


@dataclass(frozen=True)
class ThermalFit:
    """The pose-constancy fit: values, standard errors and the residual about each pose."""

    params: Parameters
    std: dict[str, float]  #: standard error of each free coefficient (chi2/dof-scaled)
    covariance: np.ndarray  #: over ``free_names``
    free_names: tuple[str, ...]
    poses: np.ndarray  #: the pose indices, in the order of ``vectors``
    vectors: np.ndarray  #: (P, 3) each pose's calibrated gravity vector [m/s^2]
    residuals: np.ndarray  #: (n, 3) a - v of each row [m/s^2]
    sigma: float  #: the rows' noise (median over rows of the calibrated mean's) [m/s^2]
    chi2: float  #: sum (r / sigma)^2
    dof: int
    status: str
    iterations: int

    @property
    def rss(self) -> float:
        return float(np.sum(self.residuals ** 2))

    @property
    def redchi(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else float("nan")

    @property
    def rms(self) -> float:
        """[m/s^2] RMS of the rows' residual components about their poses."""
        return float(np.sqrt(np.mean(self.residuals ** 2)))


class _Problem:
    """f = 1/2 |r|^2 / sigma^2 in scaled unknowns x = (coefficients, pose vectors)."""

    def __init__(self, fn: Vectorized, rows: ThermalRows, cov: np.ndarray, pfix: np.ndarray, p0: np.ndarray,
                 d: np.ndarray, sigma: float) -> None:
        self.fn, self.rows, self.cov, self.pfix, self.p0, self.d, self.sigma = fn, rows, cov, pfix, p0, d, sigma
        self.nc = len(p0) - 3 * rows.poses.size
        self.index = np.searchsorted(rows.poses, rows.pose)
        self.n_free = len(p0)

    def unknowns(self, x) -> np.ndarray:
        return self.p0 + self.d * np.asarray(x, float).ravel()

    def residual(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """r (3n,) and dr/du (3n x n_free) at the unknowns u."""
        a, J = self.fn(self.rows.raw.T, self.cov.T, u[:self.nc], self.pfix)
        n, nc = self.rows.n, self.nc
        v = u[nc:].reshape(-1, 3)
        r = (a.T - v[self.index]).ravel()  # row-major: row k's x, y, z
        Jf = np.zeros((3 * n, self.n_free))
        Jf[:, :nc] = J.reshape(nc, 3, n).transpose(2, 1, 0).reshape(3 * n, nc)
        cols = nc + 3 * self.index[:, None] + np.arange(3)
        Jf[np.arange(3 * n), cols.ravel()] = -1.0
        return r, Jf

    def value(self, x) -> float:
        r, _ = self.residual(self.unknowns(x))
        return 0.5 * float(r @ r) / self.sigma ** 2

    def derivatives(self, x) -> tuple[float, np.ndarray, np.ndarray]:
        r, J = self.residual(self.unknowns(x))
        Jx = J * self.d / self.sigma
        rw = r / self.sigma
        return 0.5 * float(rw @ rw), Jx.T @ rw, Jx.T @ Jx


def _r_factor(Jw: np.ndarray) -> np.ndarray:
    """R with R^T R = Jw^T Jw (the covariance routine takes either; R is small)."""
    return np.linalg.qr(Jw, mode="r")


def pose_vectors(model: SensorModel, params: Parameters, rows: ThermalRows, cov: np.ndarray) -> np.ndarray:
    """(P, 3) the mean calibrated reading of each pose at ``params``."""
    a = accel_rows(model, ())(rows.raw.T, cov.T, [], params.values())[0].T
    return np.array([a[rows.pose == p].mean(axis=0) for p in rows.poses])


def row_sigma(model: SensorModel, params: Parameters, rows: ThermalRows) -> float:
    """[m/s^2] the rows' noise: the median over rows and axes of each mean's standard error, through
    the scales (the base map's diagonal, b_i in raw per m/s^2)."""
    b = np.array([params[f"b{i}"].value for i in (1, 2, 3)])
    return max(float(median(np.sqrt(rows.var / b ** 2).ravel())), 1e-12)


def fit_rows(model: SensorModel, params: Parameters, rows: ThermalRows, cov: np.ndarray,
             source: str | None = None) -> ThermalFit:
    """Fit the free parameters of ``params`` (the temperature coefficients) and one gravity vector per
    pose to the rows (module docstring). ``cov``: the rows' covariates in the model's order."""
    free = params.free_names
    if tuple(params.names) != model.names:
        raise ImucalError("parameters do not match the model", field="parameters")
    fn = accel_rows(model, free)
    pfix = np.array(params.values(), float)
    v0 = pose_vectors(model, params, rows, cov)
    p0 = np.concatenate([[params[n].value for n in free], v0.ravel()])
    sigma = row_sigma(model, params, rows)
    n_unknown = p0.size
    if 3 * rows.n <= n_unknown:
        raise ImucalError(f"{rows.n} temperature rows cannot determine {len(free)} coefficients and "
                          f"{rows.poses.size} pose vectors", file=source, field="intervals",
                          fix="hold each pose over a wider temperature range")
    scale = np.concatenate([[params[n].scale for n in free], np.full(v0.size, 1.0)])
    prob = _Problem(fn, rows, cov, pfix, p0, np.ones(n_unknown), sigma)
    _, J = prob.residual(p0)
    d = np.sqrt(np.clip(np.diag(unscaled_covariance(_r_factor(J / sigma))), 0, None))  # predicted standard errors
    prob.d = np.where(np.isfinite(d) & (d > 0), np.minimum(d, scale * 1e3), scale)
    lo = np.concatenate([[params[n].lower for n in free], np.full(v0.size, -np.inf)])
    hi = np.concatenate([[params[n].upper for n in free], np.full(v0.size, np.inf)])
    x, stats = lsq.solve(prob, (lo - p0) / prob.d, (hi - p0) / prob.d)
    u = prob.unknowns(x)
    r, J = prob.residual(u)
    dof = 3 * rows.n - n_unknown
    chi2 = float(r @ r) / sigma ** 2
    cov_u = unscaled_covariance(_r_factor(J / sigma)) * (chi2 / dof)  # lmfit's scale_covar
    nc = len(free)
    std = {n: float(np.sqrt(max(cov_u[i, i], 0.0))) for i, n in enumerate(free)}
    fitted = params.with_values(dict(zip(free, u[:nc])))
    return ThermalFit(params=fitted, std=std, covariance=cov_u[:nc, :nc], free_names=free, poses=rows.poses,
                      vectors=u[nc:].reshape(-1, 3), residuals=r.reshape(-1, 3), sigma=sigma, chi2=chi2, dof=dof,
                      status=str(stats.get("return_status", "unknown")), iterations=int(stats.get("iter_count", 0)))
