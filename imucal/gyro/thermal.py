"""The gyroscope's bias(T) from still poses over a temperature sweep (issue 27): evidence prepared for
the gyroscope's description (imucal.model.gyroscope), as named Parameters.

A still gyroscope reads its bias plus the Earth's rate projected on its axes, one constant per pose
(0.073 mrad/s at most: a pose's nuisance, with the constant bias). Over a temperature change each
axis's mean reading in the sweep's rows (imucal.thermal.evidence: at most 0.5 degC each) is

    g_i(k) = w_{P(k), i} + sum_j c_{i j} p_j(T_k)

with p_j the grammar's orthogonal polynomials (imucal.model.effects.recurrence: T_ref the rows'
mean, the constants a2, b2, a3, b3 of the rows' temperatures). The model is linear: each axis is one
least-squares problem; the order (0 to 3) is chosen per axis by the grammar's forward test (LR
scaled by the misfit, F(1, dof), Bonferroni over the round's axes, alpha 1e-3); standard errors are
the one covariance routine's (imucal.solve.fit.unscaled_covariance) scaled by chi2/dof.

Time and temperature move together in a sweep (each pose warms for hours): a bias that drifts in
time passes for a temperature term. ``drift`` fits a linear drift per axis beside the terms and
reports it with the correlation of the two estimates, so the report can say how far they are
confounded (the real sweep: x drifts about -0.8 mrad/s per day).
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field

import numpy as np

from imucal.model.effects import AXIS_NAMES, recurrence
from imucal.model.parameters import Parameter, Parameters
from imucal.solve.f_test import f_sf
from imucal.solve.fit import unscaled_covariance
from imucal.thermal.evidence import ThermalRows

MAX_ORDER = 3
ALPHA = 1e-3
#: The grammar's names of the temperature orders (imucal.model.effects.BASES).
TERMS = {1: "bias_temperature", 2: "bias_temperature2", 3: "bias_temperature3"}
#: [s] one day, the unit the drift is reported in.
DAY = 86400.0


@dataclass(frozen=True)
class AxisFit:
    """One axis's least squares: coefficients of the orders 1..order, their errors, the residual."""

    order: int
    coef: np.ndarray  #: (order,) [rad/s per degC^k]
    std: np.ndarray
    rss: float
    dof: int
    residual: np.ndarray  #: (n,) [rad/s]
    offset: float = 0.0  #: [rad/s] the mean of the poses' constants: the bias (with the Earth's rate averaged)
    offset_std: float = float("nan")


@dataclass(frozen=True)
class GyroThermal:
    """bias(T) per axis of the gyroscope, with what chose it and what it leaves."""

    params: Parameters  #: bias_temperature{,2,3}_{x,y,z} [rad/s / degC^k] and their references (fixed)
    std: dict[str, float]
    orders: tuple[int, int, int]
    p_values: tuple[tuple[float, ...], ...]  #: per axis, the adjusted p of each order tried
    before: np.ndarray  #: (n, 3) rows about their poses without terms [rad/s]
    after: np.ndarray  #: (n, 3) with them
    drift: np.ndarray  #: (3,) [rad/s per day] a linear drift fitted beside the terms
    drift_std: np.ndarray
    drift_correlation: np.ndarray  #: (3,) correlation of the drift with the linear temperature coefficient
    tref: float
    #: (3,) [rad/s] the bias at the terms' zero: the mean of the poses' constants (each holds the Earth's rate
    #: projected on the axis in that pose, at most 0.073 mrad/s: not told apart from the bias by still poses)
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    offset_std: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))

    def effects(self) -> list:
        """The grammar's terms this fit holds (bias_temperature{,2,3} on the axes of at least that order), as
        the gyroscope's description takes them (imucal.model.gyroscope.gyro_model)."""
        from imucal.model.effects import make_effect
        return [make_effect(name, [i for i, o in enumerate(self.orders) if o >= k])
                for k, name in TERMS.items() if max(self.orders) >= k]

    def bias(self, temp: np.ndarray) -> np.ndarray:
        """(n, 3) bias(T) - bias(T_ref) [rad/s] at temperatures ``temp``."""
        return temperature_terms(self.params, np.asarray(temp, float))


def _basis(temp: np.ndarray, a: list[float], b: list[float], order: int) -> np.ndarray:
    """(n, order) p_1..p_order of the orthogonal recurrence (imucal.model.effects.Polynomial)."""
    cols, prev, cur = [], np.ones_like(temp), temp - a[0]
    for k in range(1, order + 1):
        if k > 1:
            prev, cur = cur, (temp - a[k - 1]) * cur - b[k - 2] * prev
        cols.append(cur)
    return np.column_stack(cols) if cols else np.zeros((temp.size, 0))


def _poses(pose: np.ndarray) -> np.ndarray:
    return (pose[:, None] == np.unique(pose)[None, :]).astype(float)


def _fit(y: np.ndarray, X: np.ndarray, k: int) -> AxisFit:
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    dof = X.shape[0] - X.shape[1]
    rss = float(r @ r)
    cov = unscaled_covariance(np.linalg.qr(X, mode="r")) * (rss / dof if dof > 0 else 1.0)
    tail = slice(X.shape[1] - k, X.shape[1])
    w = np.zeros(X.shape[1])
    w[:X.shape[1] - k] = 1.0 / (X.shape[1] - k)  # the mean of the poses' constants
    return AxisFit(k, coef[tail], np.sqrt(np.clip(np.diag(cov)[tail], 0, None)), rss, dof, r,
                   float(w @ coef), float(np.sqrt(max(w @ cov @ w, 0.0))))


def _select(y: np.ndarray, P: np.ndarray, B: np.ndarray, alpha: float) -> tuple[AxisFit, tuple[float, ...]]:
    """Orders 1, 2, 3 added while significant (LR = drop in RSS over the misfit scale, F(1, dof))."""
    cur, ps = _fit(y, P, 0), []
    for k in range(1, MAX_ORDER + 1):
        new = _fit(y, np.hstack([P, B[:, :k]]), k)
        if new.dof < 1:
            break
        if new.rss > 0:
            lr = (cur.rss - new.rss) / (new.rss / new.dof)
        else:  # an exact fit (a constant channel, or readings the order explains wholly): a drop is decisive
            lr = math.inf if cur.rss > 0 else 0.0
        p = min(1.0, 3 * f_sf(max(lr, 0.0), 1, new.dof))  # Bonferroni over the three axes
        ps.append(p)
        if p >= alpha:
            break
        cur = new
    return cur, tuple(ps)


def gyro_bias_temperature(rows: ThermalRows, alpha: float = ALPHA) -> GyroThermal:
    """bias(T) of each gyroscope axis from the sweep's rows (module docstring); rows need ``gyro``."""
    if rows.gyro is None:
        raise ValueError("the rows have no gyroscope readings")
    a, b = recurrence(rows.temp, MAX_ORDER, float(np.round(np.mean(rows.temp), 3)))
    B, P = _basis(rows.temp, a, b, MAX_ORDER), _poses(rows.pose)
    fits, pvals = [], []
    for i in range(3):
        f, ps = _select(rows.gyro[:, i], P, B, alpha)
        fits.append(f)
        pvals.append(ps)
    params, std = _parameters(fits, a, b)
    before = np.column_stack([_fit(rows.gyro[:, i], P, 0).residual for i in range(3)])
    after = np.column_stack([f.residual for f in fits])
    drift, dstd, corr = _drift(rows, P, B, fits)
    return GyroThermal(params=params, std=std, orders=tuple(f.order for f in fits), p_values=tuple(pvals),
                       before=before, after=after, drift=drift, drift_std=dstd, drift_correlation=corr, tref=a[0],
                       offset=np.array([f.offset for f in fits]), offset_std=np.array([f.offset_std for f in fits]))


def _parameters(fits: list[AxisFit], a: list[float], b: list[float]) -> tuple[Parameters, dict[str, float]]:
    """The grammar's names: coefficients per axis, and each term's references (fixed)."""
    out, std = [], {}
    top = max((f.order for f in fits), default=0)
    for k in range(1, top + 1):
        name = TERMS[k]
        for i, f in enumerate(fits):
            if f.order >= k:
                n = f"{name}_{AXIS_NAMES[i]}"
                out.append(Parameter(n, float(f.coef[k - 1]), unit=f"rad/s/degC{'' if k == 1 else f'^{k}'}",
                                     scale=1e-4, description=f"gyroscope bias, order {k} in temperature"))
                std[n] = float(f.std[k - 1])
        out.append(Parameter(f"{name}_tref", a[0], unit="degC", fixed=True, description="reference temperature"))
        for j in range(2, k + 1):
            out += [Parameter(f"{name}_a{j}", a[j - 1], unit="degC", fixed=True),
                    Parameter(f"{name}_b{j}", b[j - 2], unit="degC^2", fixed=True)]
    return Parameters(out), std


def temperature_terms(params: Parameters, temp: np.ndarray) -> np.ndarray:
    """(n, 3) the sum of the bias terms in ``params`` at ``temp`` [rad/s]."""
    out = np.zeros((temp.size, 3))
    for k, name in TERMS.items():
        if f"{name}_tref" not in params.names:
            continue
        a = [params[f"{name}_tref"].value] + [params[f"{name}_a{j}"].value for j in range(2, k + 1)]
        b = [params[f"{name}_b{j}"].value for j in range(2, k + 1)]
        p = _basis(temp, a, b, k)[:, -1]
        for i, ax in enumerate(AXIS_NAMES):
            if f"{name}_{ax}" in params.names:
                out[:, i] += params[f"{name}_{ax}"].value * p
    return out


def _drift(rows: ThermalRows, P: np.ndarray, B: np.ndarray, fits: list[AxisFit]
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A linear drift in time beside each axis's terms [rad/s per day], its error, and its correlation
    with the linear temperature coefficient (nan where the axis has none)."""
    t = (rows.t - rows.t.mean()) / DAY
    d, s, c = np.zeros(3), np.zeros(3), np.full(3, np.nan)
    for i, f in enumerate(fits):
        X = np.hstack([P, B[:, :f.order], t[:, None]])
        coef, *_ = np.linalg.lstsq(X, rows.gyro[:, i], rcond=None)
        r = rows.gyro[:, i] - X @ coef
        dof = X.shape[0] - X.shape[1]
        cov = unscaled_covariance(np.linalg.qr(X, mode="r")) * (float(r @ r) / max(dof, 1))
        d[i], s[i] = coef[-1], np.sqrt(max(cov[-1, -1], 0.0))
        if f.order:
            j = P.shape[1]  # the first temperature column
            c[i] = cov[j, -1] / np.sqrt(cov[j, j] * cov[-1, -1])
    return d, s, c
