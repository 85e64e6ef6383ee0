"""The sensor's temperature is not the die's: a lag, or hysteresis, tested for and named only when
the data show it.

Lag: a temperature sensor that lags (or leads) the MEMS by a first-order time constant tau reads
T while the die is at T + tau dT/dt, to first order in tau. Each row's temperature becomes
T_k + tau Tdot_k (Tdot_k the slope of its samples' temperature), and tau enters the pose fit as one
more unknown: its column is da/dT Tdot_k, da/dT taken from the model's own map at the fitted
terms (a central difference of imucal.thermal.fit.accel_rows). Hysteresis: the reading differs
between warming and cooling: one offset h_i per axis times the row's direction of change (+1
warming, -1 cooling, 0 where the temperature moves slower than STEADY_RATE). Each is a
Gauss-Newton step from the selected fit (imucal.thermal.select), tested by a Wald test whose
covariance is the jackknife over episodes (a pose's consecutive rows that warm, cool or hold
alike: ``episodes``), F(k, episodes - 1), Bonferroni over the two tests, and named
only when significant: the value and its standard error are reported either way. One fast
cool-down (the first hour of the real sweep, where the part also settles) is one episode, not
forty rows of evidence.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imucal.data.recording import Recording, RecordingSummary
from imucal.solve.f_test import f_sf
from imucal.solve.fit import unscaled_covariance
from imucal.thermal.fit import accel_rows
from imucal.thermal.select import Selection, ThermalProblem, _screen

#: A row whose temperature moves slower than this [degC/h] is neither warming nor cooling.
STEADY_RATE = 0.5
#: Temperature step of the central difference of da/dT [degC].
DT_PROBE = 0.1


@dataclass(frozen=True)
class LagTest:
    """Both tests' estimates, statistics and verdicts (rendered by imucal.report.thermal)."""

    tau: float  #: [s] first-order lag of the sensor behind the die (> 0) or lead (< 0)
    tau_std: float
    tau_lr: float  #: (tau / std)^2, std the jackknife's over episodes
    tau_p: float  #: Bonferroni-adjusted
    hysteresis: np.ndarray  #: (3,) [m/s^2] half the warming-minus-cooling offset per axis
    hysteresis_std: np.ndarray
    hysteresis_lr: float  #: the largest (h_i / std_i)^2
    hysteresis_p: float
    alpha: float
    n_warming: int  #: rows warming / cooling faster than STEADY_RATE
    n_cooling: int

    @property
    def lag_named(self) -> bool:
        return self.tau_p < self.alpha

    @property
    def hysteresis_named(self) -> bool:
        return self.hysteresis_p < self.alpha


def row_rates(prob: ThermalProblem, rec: Recording) -> np.ndarray:
    """[degC/s] the least-squares slope of each row's temperature against time."""
    rows = prob.rows
    out = np.zeros(rows.n)
    for k, (a, b) in enumerate(zip(rows.start, rows.end)):
        t, T = rec.t[a:b], rec.temp[a:b]
        dt = t - t.mean()
        den = float(dt @ dt)
        out[k] = float(dt @ (T - T.mean())) / den if den > 0 else 0.0
    return out


def _da_dT(prob: ThermalProblem, sel: Selection) -> np.ndarray:
    """(n, 3) the derivative of the calibrated reading with temperature at each row [m/s^2 / degC]."""
    model, _ = prob.parameters(sel.effects)
    fn, p = accel_rows(model, ()), sel.fit.params.values()

    def at(dT: float) -> np.ndarray:
        from imucal.model.channels import covariate_matrix

        cov = covariate_matrix(model.covariates, {"temp": prob.rows.temp + dT, "time": prob.rows.t}, prob.rows.n)
        return fn(prob.rows.raw.T, cov.T, [], p)[0].T

    return (at(DT_PROBE) - at(-DT_PROBE)) / (2 * DT_PROBE)


def episodes(prob: ThermalProblem, direction: np.ndarray) -> np.ndarray:
    """(n,) an episode number per row: a pose's consecutive rows that warm, cool or hold steady alike.
    The slow drift makes neighbouring rows' misfits alike (measured lag-1 correlation 0.8-0.9 on the
    real sweep), so an episode, not a row, is one piece of evidence about a lag or hysteresis."""
    pose = prob.rows.pose
    new = np.ones(pose.size, bool)
    new[1:] = (pose[1:] != pose[:-1]) | (direction[1:] != direction[:-1])
    return np.cumsum(new) - 1


def _extra_test(rw: np.ndarray, Jw: np.ndarray, X: np.ndarray, cluster: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Values, standard errors, Wald statistic and p of the columns X added to Jw (a Gauss-Newton step).
    The covariance is the jackknife over clusters (``cluster``: per row; a row holds 3 components):
    each episode left out in turn, (C - 1) / C sum (beta_-c - mean)^2, so an effect that one episode
    alone carries (a settling after the first cool-down) has the spread of that episode's weight;
    W = the largest (beta_j / std_j)^2, p = k P(F(1, C - 1) > W)."""
    A = np.hstack([Jw, X])
    k = X.shape[1]
    beta = np.linalg.lstsq(A, -rw, rcond=None)[0][-k:]
    groups = np.repeat(cluster, 3)
    labels = np.unique(groups)
    C = labels.size
    if C < 3:
        return beta, np.full(k, math.nan), 0.0, 1.0
    reps = np.array([np.linalg.lstsq(A[groups != c], -rw[groups != c], rcond=None)[0][-k:] for c in labels])
    d = reps - reps.mean(axis=0)
    std = np.sqrt(np.sum(d ** 2, axis=0) * (C - 1) / C)
    with np.errstate(divide="ignore", invalid="ignore"):
        z2 = np.where(std > 0, (beta / std) ** 2, 0.0)
    W = float(np.max(z2))  # per column (a jackknife over few episodes has no stable joint covariance)
    p = min(1.0, k * f_sf(W, 1, C - 1)) if np.isfinite(W) and W > 0 else 1.0
    return beta, std, W, p


def lag_and_hysteresis(prob: ThermalProblem, sel: Selection, rec: Recording | RecordingSummary,
                       alpha: float) -> LagTest:
    """Both tests at the selected fit (module docstring)."""
    rows, fit = prob.rows, sel.fit
    rate = row_rates(prob, rec) if isinstance(rec, Recording) else np.zeros(rows.n)
    rw, Jw, col, nc = _screen(prob, fit, sel.effects)
    keep = [col[n] for n in fit.free_names] + list(range(nc, Jw.shape[1]))
    J = Jw[:, keep]
    direction = np.where(rate > STEADY_RATE / 3600, 1.0, np.where(rate < -STEADY_RATE / 3600, -1.0, 0.0))
    cluster = episodes(prob, direction)
    X_tau = (_da_dT(prob, sel) * rate[:, None]).ravel()[:, None] / fit.sigma  # d r / d tau
    tau, tau_std, tau_lr, tau_p = _extra_test(rw, J, X_tau, cluster)
    X_h = np.zeros((3 * rows.n, 3))
    for i in range(3):
        X_h[i::3, i] = -direction  # r = a - v - h d: warming rows (d = +1) read v + h, cooling ones v - h
    X_h /= fit.sigma
    if not (np.any(direction > 0) and np.any(direction < 0)):
        h, h_std, h_lr, h_p = np.zeros(3), np.full(3, math.nan), 0.0, 1.0
    else:
        h, h_std, h_lr, h_p = _extra_test(rw, J, X_h, cluster)
    return LagTest(tau=float(tau[0]), tau_std=float(tau_std[0]), tau_lr=tau_lr, tau_p=min(1.0, 2 * tau_p),
                   hysteresis=np.asarray(h, float), hysteresis_std=np.asarray(h_std, float), hysteresis_lr=h_lr,
                   hysteresis_p=min(1.0, 2 * h_p), alpha=alpha, n_warming=int(np.sum(direction > 0)),
                   n_cooling=int(np.sum(direction < 0)))
