"""Stochastic biases between interval means: variance components estimated by REML.

The residual of interval mean k, r_k = |a_k| - g at the fit, picks up a bias vector beta_k
(sensor frame, m/s^2) through the model's own derivative: r_k += G_k . beta_k with
G_k,i = (dr_k / draw_i) b_i (~ the direction u_k of gravity in the sensor frame). Two kinds of
beta, each common to the three axes:

* ``bias_instability``: an independent offset per visit of a pose, std tau per axis:
  Cov(r_j, r_k) = tau^2 (G_j . G_k) delta_jk ~ tau^2 delta_jk;
* ``bias_random_walk``: beta(t) = q W(t), W a Wiener process per axis, density q [m/s^2/sqrt(s)]:
  Cov(r_j, r_k) = q^2 (G_j . G_k) min(t_j, t_k), t from the first interval. The origin does not
  matter: a constant bias is a fitted parameter (s_i), so a change of origin adds
  c (G_j . G_k), which lies in the span of the fit's Jacobian and drops out of the REML likelihood.
  Revisits of a pose close in time agree better than revisits far apart: that is what tells the
  walk from per-visit offsets.

V(theta) = diag(sigma_k^2) + tau^2 K_I + q^2 K_W, with sigma_k the noise of each mean. theta is
estimated by restricted (residual) maximum likelihood (Patterson & Thompson 1971; Harville 1977):

    l(theta) = -1/2 [log det V + log det(X^T V^-1 X) + r^T P r],  P = V^-1 - V^-1 X (X^T V^-1 X)^-1 X^T V^-1,

X the Jacobian of the residuals w.r.t. the free parameters (the fit absorbs that much of any
covariance). l is maximised on a log grid and refined by average-information (AI-REML) steps;
standard errors come from the inverse expected information, F_ij = 1/2 tr(P K_i P K_j).

Which components are present is decided by likelihood ratios against the nested models, each
variance at its boundary 0 (p = 1/2 P(chi2(1) > LR), Self & Liang 1987), each at level alpha / 2
(Bonferroni over the two components). A component is then named only if the whitened residuals
have no single outlier (a step in the bias would otherwise pass for a random walk): the largest
standardized one-step innovation must be consistent with N(0, 1) at level alpha (Sidak over rows).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from imucal.constants import STANDARD_GRAVITY
from imucal.solve import least_squares as lsq
from imucal.solve.f_test import f_sf
from imucal.solve.stats import chi2_sf, median

#: The REML test works on dense n x n covariances of the interval means (a Cholesky factor per
#: likelihood evaluation, O(n^3), some 800 evaluations): above this many intervals it is not run, and
#: the between-interval excess is Paule-Mandel's alone. Measured (scripts/bench_memory.py): 380
#: intervals cost 4.5 s of CPU; a 5 M-sample log tiled from Xsens has 3,800 (minutes), and 51 M
#: samples would need 11 GB for one matrix.
MAX_INTERVALS = 300


def feasible(n: int) -> bool:
    """Whether the REML test runs on ``n`` interval means (MAX_INTERVALS)."""
    return n <= MAX_INTERVALS

INSTABILITY, RANDOM_WALK = "bias_instability", "bias_random_walk"
MODELS = ("none", INSTABILITY, RANDOM_WALK, "both")
#: variance components of each model: (instability, random walk) free?
_FREE = {"none": (False, False), INSTABILITY: (True, False), RANDOM_WALK: (False, True), "both": (True, True)}
#: log10 grid of each component relative to its natural scale (median sigma^2, and that per second)
_GRID = np.linspace(-3.0, 3.0, 13)
UNITS = {INSTABILITY: "m/s^2", RANDOM_WALK: "m/s^2/sqrt(s)"}


@dataclass(frozen=True)
class Components:
    """The fixed inputs of the variance-component model of one fit."""

    r: np.ndarray  #: residuals |a| - g of the interval means [m/s^2]
    sigma: np.ndarray  #: noise of each mean [m/s^2]
    X: np.ndarray  #: (n, p) Jacobian of r w.r.t. the free parameters (any column scaling)
    K: tuple[np.ndarray, np.ndarray]  #: (K_I, K_W): covariance per unit tau^2 and per unit q^2
    t: np.ndarray  #: interval times from the first [s]
    G: np.ndarray | None = None  #: (n, 3) how a bias vector [m/s^2] enters each residual
    t0: float = 0.0  #: the first interval's time, which ``t`` counts from [s]

    def covariance(self, tau2: float, q2: float) -> np.ndarray:
        return np.diag(self.sigma**2) + tau2 * self.K[0] + q2 * self.K[1]

    def about_mean(self, tau2: float, q2: float) -> np.ndarray:
        """V with the walk taken about its mean over the intervals, beta(t) - mean_k beta(t_k): the
        covariance of the rows around a calibration whose offsets are the bias averaged over the
        intervals (imucal.solve.fit). Its REML likelihood is ``covariance``'s (the difference is
        X B + B^T X^T when the offsets are free), its fixed effects' meaning is not."""
        GG = self.G @ self.G.T
        return np.diag(self.sigma**2) + tau2 * self.K[0] + q2 * GG * walk_about_mean(self.t)


def walk_about_mean(t: np.ndarray) -> np.ndarray:
    """Cov(W(t_j) - Wbar, W(t_k) - Wbar) for a unit Wiener process W, Wbar its mean over the times t
    (each counted once): min(t_j, t_k) - m_j - m_k + mean(m), m_j the mean over l of min(t_j, t_l)."""
    T = np.minimum.outer(np.asarray(t, float), np.asarray(t, float))
    m = T.mean(axis=1)
    return T - m[:, None] - m[None, :] + m.mean()


def components(r: np.ndarray, sigma: np.ndarray, X: np.ndarray, G: np.ndarray, t: np.ndarray) -> Components:
    """The kernels of both stochastic biases for residuals ``r`` with directions ``G`` (n, 3) at times ``t``."""
    t0 = float(np.min(t))
    t = np.asarray(t, float) - t0
    GG = G @ G.T
    c = np.linalg.norm(X, axis=0)
    return Components(r=np.asarray(r, float), sigma=np.asarray(sigma, float), X=X / np.where(c > 0, c, 1.0),
                      K=(np.diag(np.diag(GG)), GG * np.minimum.outer(t, t)), t=t, G=np.asarray(G, float), t0=t0)


def components_at(fns: lsq.RowFunctions, rows: lsq.Rows, pfree: np.ndarray, pfix: np.ndarray, gravity: float,
                  sigma: np.ndarray, b: np.ndarray, t: np.ndarray) -> Components:
    """Components at a fit: residuals, Jacobian and G = dr/draw * b from the model's generated row functions."""
    r, J, Jraw = lsq.jacobians(fns, rows, pfree, pfix, gravity)
    return components(r, sigma, J, Jraw * np.asarray(b, float), t)


def reml(c: Components, tau2: float, q2: float, projector: bool = False, ml: bool = False
         ) -> tuple[float, np.ndarray | None]:
    """REML log-likelihood (up to a constant) and, by option, the projector P at (tau^2, q^2).

    ``ml=True``: the profile (full) likelihood instead, without log det(X^T V^-1 X): comparable
    between different X (nested fixed effects); its scoring uses V^-1 for P in the traces."""
    V = c.covariance(tau2, q2)
    L = np.linalg.cholesky(V)
    Xw, rw = np.linalg.solve(L, c.X), np.linalg.solve(L, c.r)
    Q, R = np.linalg.qr(Xw)
    e = rw - Q @ (Q.T @ rw)
    ll = -0.5 * (2 * np.sum(np.log(np.diag(L))) + (0.0 if ml else 2 * np.sum(np.log(np.abs(np.diag(R)))))
                 + float(e @ e))
    if not projector:
        return float(ll), None
    Li = np.linalg.solve(L, np.eye(len(c.r)))
    M = Li - Q @ (Q.T @ Li)
    return float(ll), M.T @ M if not ml else (M.T @ M, Li.T @ Li)


def reml_grid(c: Components, theta: np.ndarray, ml: bool = False) -> np.ndarray:
    """``reml(c, tau2, q2)[0]`` at each row (tau^2, q^2) of ``theta``, by one eigendecomposition per tau^2.

    K_I is diagonal, so D = diag(sigma^2) + tau^2 K_I is too; with D^-1/2 K_W D^-1/2 = U diag(lam) U^T,
    V = D^1/2 U (I + q^2 diag(lam)) U^T D^1/2: log det V and every product with V^-1 are sums over lam,
    and the q^2 of one tau^2 cost a p x p solve each (the likelihood of ``reml``, not an approximation).
    """
    out = np.empty(len(theta))
    kI = np.diag(c.K[0])
    for tau2 in dict.fromkeys(theta[:, 0].tolist()):  # (not np.unique: it loads numpy.ma, 15 ms)
        rows = np.flatnonzero(theta[:, 0] == tau2)
        d = c.sigma**2 + tau2 * kI
        h = 1.0 / np.sqrt(d)
        Xt, rt = c.X * h[:, None], c.r * h
        if theta[rows, 1].any():  # (with q^2 = 0 throughout, V = D: no basis change needed)
            lam, U = np.linalg.eigh(c.K[1] * np.outer(h, h))
            lam = np.clip(lam, 0.0, None)  # K_W is positive semi-definite: rounding only
            Xt, rt = U.T @ Xt, U.T @ rt
        else:
            lam = np.zeros(len(d))
        w = 1.0 / (1.0 + theta[rows, 1, None] * lam)  # (q, n): the eigenvalues of V^-1 in this basis
        A = np.einsum("ki,qk,kj->qij", Xt, w, Xt)  # X^T V^-1 X
        b = (w * rt) @ Xt  # X^T V^-1 r
        quad = (w * rt) @ rt - np.einsum("qi,qi->q", b, np.linalg.solve(A, b[..., None])[..., 0])
        logdet = np.sum(np.log(d)) - np.sum(np.log(w), axis=1)
        out[rows] = -0.5 * (logdet + (0.0 if ml else np.linalg.slogdet(A)[1]) + quad)
    return out


@dataclass(frozen=True)
class ModelFit:
    """One model's REML estimate."""

    name: str
    tau2: float  #: [(m/s^2)^2]
    q2: float  #: [(m/s^2)^2 / s]
    loglik: float
    cov: np.ndarray  #: 2 x 2 covariance of (tau^2, q^2) from the expected information (0 where fixed)


def fit_model(c: Components, name: str, ml: bool = False) -> ModelFit:
    """Maximise the REML (or, ``ml``, the full) likelihood over the model's free components (>= 0):
    log grid, then average-information steps."""
    free = np.array(_FREE[name])
    s2 = median(c.sigma**2)
    scale = np.array([s2, s2 / max(float(np.max(c.t)), 1e-9)])
    if not free.any():
        return ModelFit(name, 0.0, 0.0, reml(c, 0.0, 0.0, ml=ml)[0], np.zeros((2, 2)))
    axes = [scale[j] * 10.0**_GRID if free[j] else np.zeros(1) for j in range(2)]
    grid = np.array([(a, b) for a in axes[0] for b in axes[1]])
    lls = reml_grid(c, grid, ml=ml)
    k = int(np.argmax(lls))  # the first of equal maxima, as max() over the same order
    theta, ll = grid[k].copy(), float(lls[k])
    P, T = _projectors(c, theta, ml)
    for _ in range(50):  # average-information steps with step halving, projected on theta >= 0
        Pr = P @ c.r
        u = [K @ Pr for K in c.K]
        score = np.array([-0.5 * np.sum(T * K) + 0.5 * float(Pr @ ui) for K, ui in zip(c.K, u)])
        # AI_ij = 1/2 r^T P K_i P K_j P r, the mean of the observed and expected information (Gilmour,
        # Thompson & Cullis 1995): Newton-like near the maximum, where expected-information scoring
        # alternates around it when the two components are correlated (Xsens: 21 steps, now 8).
        AI = np.array([[0.5 * float(ui @ P @ uj) for uj in u] for ui in u])
        idx = np.flatnonzero(free)
        step = np.zeros(2)
        step[idx] = np.linalg.lstsq(AI[np.ix_(idx, idx)], score[idx], rcond=None)[0]
        for _ in range(30):  # each trial with its projectors: the accepted one starts the next step
            new = np.maximum(theta + step, 0.0)
            ll_new, proj = reml(c, *new, projector=True, ml=ml)
            if ll_new >= ll - 1e-12:
                break
            step *= 0.5
        if ll_new < ll - 1e-12:  # no ascent along the scoring direction: at the maximum
            break
        done = np.all(np.abs(new - theta) <= 1e-6 * np.maximum(theta, 1e-3 * scale))
        theta, ll = new, max(ll, ll_new)
        P, T = proj if ml else (proj, proj)
        if done:
            break
    PK = [T @ K for K in c.K]
    F = np.array([[0.5 * np.sum(A * B.T) for B in PK] for A in PK])
    idx = np.flatnonzero(free)
    cov = np.zeros((2, 2))
    cov[np.ix_(idx, idx)] = np.linalg.pinv(F[np.ix_(idx, idx)])
    return ModelFit(name, float(theta[0]), float(theta[1]), float(ll), cov)


def _projectors(c: Components, theta: np.ndarray, ml: bool) -> tuple[np.ndarray, np.ndarray]:
    """(P for the quadratic term, the matrix in the traces): P twice for REML, V^-1 in the traces for ML."""
    P = reml(c, *theta, projector=True, ml=ml)[1]
    return P if ml else (P, P)


def innovations(c: Components, tau2: float, q2: float) -> np.ndarray:
    """Standardised one-step innovations in time order: L^-1 (r - X beta_GLS), L the Cholesky factor
    of V in time order. N(0, 1) and independent when V is right (to first order in p / n)."""
    order = np.argsort(c.t, kind="stable")
    V = c.covariance(tau2, q2)[np.ix_(order, order)]
    L = np.linalg.cholesky(V)
    Xw, rw = np.linalg.solve(L, c.X[order]), np.linalg.solve(L, c.r[order])
    Q, _ = np.linalg.qr(Xw)
    e = rw - Q @ (Q.T @ rw)
    return e / math.sqrt(max(1.0 - c.X.shape[1] / len(c.r), 1e-3))


def _p_outlier(e: np.ndarray) -> float:
    """Sidak-adjusted p of the largest |e| among n N(0, 1) values."""
    p1 = math.erfc(float(np.max(np.abs(e))) / math.sqrt(2.0))
    return 1.0 - (1.0 - p1) ** len(e) if p1 > 1e-12 else p1 * len(e)


def step_test(c: Components, tau2: float, q2: float) -> tuple[float, float, int]:
    """Does one step of the bias vector between two intervals in time order (3 coefficients and a
    change point) add to the variances (tau^2, q^2)? The generalised least-squares F test of its
    columns under V(tau^2, q^2) (F, not chi-square: V is estimated, from some 20 to 40 means), at the
    change point that fits best: (p Bonferroni-adjusted over the change points, its time [s, as the
    intervals' times], the number of change points tried). Three intervals at least on each side."""
    L = np.linalg.cholesky(c.covariance(tau2, q2))
    rw = np.linalg.solve(L, c.r)
    n, k = len(c.r), c.X.shape[1]
    dof = n - k - 3
    order = np.argsort(c.t, kind="stable")
    ts = c.t[order]
    Q0 = _left(np.linalg.solve(L, c.X), rw)
    best, tried = (-math.inf, math.nan), 0
    for m in range(3, n - 2) if dof >= 1 else ():
        if ts[m] <= ts[m - 1]:
            continue
        X = np.hstack([c.X, c.G * (c.t >= ts[m]).astype(float)[:, None]])
        X = X / np.linalg.norm(X, axis=0).clip(1e-300)
        sv = np.linalg.svd(X, compute_uv=False)
        if sv[-1] < 1e-8 * sv[0]:  # the poses on one side cannot tell a step from the fit's parameters
            continue
        tried += 1
        Qs = _left(np.linalg.solve(L, X), rw)
        F = ((Q0 - Qs) / 3.0) / max(Qs / dof, 1e-300)
        if F > best[0]:
            best = (F, c.t0 + 0.5 * float(ts[m - 1] + ts[m]))
    if not tried:
        return 1.0, math.nan, 0
    return min(1.0, f_sf(max(best[0], 0.0), 3, dof) * tried), best[1], tried


def _left(Xw: np.ndarray, rw: np.ndarray) -> float:
    """Squared norm of ``rw`` left after its projection on the columns of ``Xw``."""
    Q, _ = np.linalg.qr(Xw)
    e = rw - Q @ (Q.T @ rw)
    return float(e @ e)


def _p_boundary(lr: float) -> float:
    """p of an LR test of one variance at its boundary 0: 1/2 chi2(0) + 1/2 chi2(1) (Self & Liang 1987)."""
    return 0.5 * chi2_sf(max(lr, 0.0), 1) if lr > 0 else 1.0


@dataclass(frozen=True)
class StochasticFit:
    """Which stochastic biases the residuals show, with their REML estimates and the tests."""

    named: tuple[str, ...]  #: subset of (bias_instability, bias_random_walk), in that order
    chosen: ModelFit  #: the model of the named components ("none" when nothing is named)
    fits: dict[str, ModelFit]  #: every model's REML fit
    p: dict[str, float]  #: each component's LR p against the model without it (given the other)
    p_alone: dict[str, float]  #: each component's LR p against no stochastic bias
    p_outlier: float  #: Sidak p of the largest whitened innovation under the best model
    alpha: float
    ambiguous: bool = False  #: each alone fits, neither adds to the other: the data cannot tell them apart
    notes: tuple[str, ...] = field(default_factory=tuple)
    #: components that fit but are not named: a step fits better (``step_at``), one innovation is an
    #: outlier, or the caller's shape check found structure in temperature (imucal.analysis.discover)
    withheld: tuple[str, ...] = ()
    step_at: float = math.nan  #: time of the step that beats them [s, as the intervals' times] (nan: none)

    @property
    def tau(self) -> float:
        """Per-visit bias std [m/s^2] (0 unless named)."""
        return math.sqrt(self.chosen.tau2)

    @property
    def tau_std(self) -> float:
        return _sqrt_std(self.chosen.tau2, self.chosen.cov[0, 0])

    @property
    def q(self) -> float:
        """Random-walk density [m/s^2/sqrt(s)] (0 unless named)."""
        return math.sqrt(self.chosen.q2)

    @property
    def q_std(self) -> float:
        return _sqrt_std(self.chosen.q2, self.chosen.cov[1, 1])

    def values(self, names: tuple[str, ...] | None = None) -> dict[str, tuple[float, float, str]]:
        """{name: (value, std, unit)} of the named components (or of ``names``, from their model's fit)."""
        names = self.named if names is None else names
        if not names:
            return {}
        f = self.fits["both" if len(names) == 2 else names[0]]
        v = {INSTABILITY: (math.sqrt(f.tau2), _sqrt_std(f.tau2, f.cov[0, 0])),
             RANDOM_WALK: (math.sqrt(f.q2), _sqrt_std(f.q2, f.cov[1, 1]))}
        return {n: (*v[n], UNITS[n]) for n in names}

    def to_json(self) -> dict:
        def num(x: float):
            return float(x) if math.isfinite(x) else None

        return {"named": list(self.named), "withheld": list(self.withheld), "ambiguous": self.ambiguous,
                "alpha": self.alpha, "step_at_s": num(self.step_at),
                "values": {n: {"value": v, "std": num(s), "unit": u} for n, (v, s, u) in self.values().items()},
                "p_given_other": {k: num(v) for k, v in self.p.items()},
                "p_alone": {k: num(v) for k, v in self.p_alone.items()}, "p_outlier": num(self.p_outlier),
                "models": {m: {"tau": math.sqrt(f.tau2), "q": math.sqrt(f.q2), "reml_loglik": f.loglik}
                           for m, f in self.fits.items()},
                "notes": list(self.notes)}


def _sqrt_std(v2: float, var: float) -> float:
    """std of sqrt(v2) by the delta method, from the variance of v2."""
    return math.sqrt(max(var, 0.0)) / (2.0 * math.sqrt(v2)) if v2 > 0 else float("nan")


def select(c: Components, alpha: float = 1e-3) -> StochasticFit:
    """Fit the four models and name the components the data ask for (module docstring)."""
    fits = {m: fit_model(c, m) for m in MODELS}
    lr = lambda a, b: 2.0 * (fits[a].loglik - fits[b].loglik)  # noqa: E731
    p = {INSTABILITY: _p_boundary(lr("both", RANDOM_WALK)), RANDOM_WALK: _p_boundary(lr("both", INSTABILITY))}
    alone = {n: _p_boundary(lr(n, "none")) for n in (INSTABILITY, RANDOM_WALK)}
    level = alpha / 2.0
    named = tuple(n for n in (INSTABILITY, RANDOM_WALK) if p[n] < level and alone[n] < level)
    ambiguous = False
    if len(named) == 2:
        model = "both"
    elif named:
        model = named[0]
    elif min(alone.values()) < level:  # each explains the excess alone, neither adds to the other
        model = max((INSTABILITY, RANDOM_WALK), key=lambda n: fits[n].loglik)
        named, ambiguous = (model,), alone[INSTABILITY] < level and alone[RANDOM_WALK] < level
    else:
        model = "none"
    notes = []
    e = innovations(c, fits[model].tau2, fits[model].q2)
    p_out = _p_outlier(e)
    withheld, step_at = (), math.nan
    if named and p_out < alpha:
        notes.append(f"{' and '.join(named)} not named: one whitened innovation is {np.max(np.abs(e)):.3g} sigma "
                     f"(p adjusted {p_out:.2g} < {alpha:g}), a jump no Gaussian stochastic bias explains")
        withheld, named, model, ambiguous = named, (), "none", False
    if named and c.G is not None:
        # One step of the bias on top of the named variances, at the change point that fits best: a jump
        # the outlier test misses when the walk's own estimate absorbs it. A true walk or per-visit
        # offsets gain no more than chance from one step: their covariance already allows one.
        p_step, at, tried = step_test(c, fits[model].tau2, fits[model].q2)
        if p_step < alpha:
            notes.append(f"{' and '.join(named)} not named: a single step of the bias at t = {at:.4g} s adds to them "
                         f"(F test on 3 coefficients, p adjusted over {tried} change points {p_step:.2g} < {alpha:g}), "
                         "a jump no Gaussian stochastic bias explains")
            withheld, step_at, named, model, ambiguous = named, at, (), "none", False
    return StochasticFit(named=named, chosen=fits[model], fits=fits, p=p, p_alone=alone, p_outlier=p_out,
                         alpha=alpha, ambiguous=ambiguous, notes=tuple(notes), withheld=withheld, step_at=step_at)


@dataclass(frozen=True)
class BiasDrift:
    """How far the bias moved during a recording: the walk's smoothed estimate at each interval (the
    best linear unbiased predictor given the residuals and the REML variances), per sensor axis, about
    its mean over the intervals, which is what the calibration's offsets are (imucal.solve.fit)."""

    t: np.ndarray  #: (n,) interval times in time order [s, as the recording's]
    walk: np.ndarray  #: (n, 3) smoothed bias minus its mean over the intervals [m/s^2 along each sensor axis]
    walk_std: np.ndarray  #: (n, 3) prediction standard error of ``walk`` [m/s^2]
    moved: np.ndarray  #: (3,) smoothed bias at the last interval minus at the first [m/s^2]
    moved_std: np.ndarray  #: (3,) prediction standard error of ``moved`` [m/s^2]
    b: np.ndarray  #: (3,) the scales [raw per m/s^2]: a bias of x m/s^2 along axis i reads b_i x

    @property
    def peak_to_peak(self) -> np.ndarray:
        """(3,) largest minus smallest smoothed bias over the intervals [m/s^2]."""
        return np.ptp(self.walk, axis=0)

    def in_raw(self, x: np.ndarray) -> np.ndarray:
        """Per-axis values [m/s^2] in the sensor's units (raw)."""
        return np.asarray(x, float) * self.b

    @staticmethod
    def in_mg(x: np.ndarray) -> np.ndarray:
        """Per-axis values [m/s^2] in mg (thousandths of standard gravity)."""
        return np.asarray(x, float) / STANDARD_GRAVITY * 1e3

    def to_json(self, raw_unit: str) -> dict:
        """Plain numbers, per axis x, y, z: in m/s^2, in the sensor's unit and in mg."""
        def axes(v: np.ndarray) -> list[float]:
            return [float(x) for x in v]

        return {"offsets_epoch": "mean over the still intervals", "t_first_s": float(self.t[0]),
                "t_last_s": float(self.t[-1]), "n_intervals": int(self.t.size), "raw_unit": raw_unit,
                "moved_m_s2": axes(self.moved), "moved_std_m_s2": axes(self.moved_std),
                "moved_raw": axes(self.in_raw(self.moved)), "moved_mg": axes(self.in_mg(self.moved)),
                "peak_to_peak_m_s2": axes(self.peak_to_peak), "peak_to_peak_raw": axes(self.in_raw(self.peak_to_peak)),
                "peak_to_peak_mg": axes(self.in_mg(self.peak_to_peak))}


def bias_drift(c: Components, tau2: float, q2: float, b: np.ndarray) -> BiasDrift:
    """The walk's smoothed estimate about its mean over the intervals (BiasDrift), with V about that
    mean (``Components.about_mean``): beta_i = C_i P r, its error covariance q^2 K - C_i P C_i^T
    (Henderson's prediction error), C_i = Cov(beta_i, r) = q^2 K diag(G_i), K = walk_about_mean(t),
    P the REML projector (the fitted parameters' share of r taken out)."""
    order = np.argsort(c.t, kind="stable")
    K = walk_about_mean(c.t)
    L = np.linalg.cholesky(c.about_mean(tau2, q2))
    Xw = np.linalg.solve(L, c.X)
    Q, _ = np.linalg.qr(Xw)
    Li = np.linalg.solve(L, np.eye(len(c.r)))
    M = Li - Q @ (Q.T @ Li)
    P = M.T @ M  # V^-1 - V^-1 X (X^T V^-1 X)^-1 X^T V^-1
    Pr = P @ c.r
    walk, std = np.empty((len(c.r), 3)), np.empty((len(c.r), 3))
    moved, moved_std = np.empty(3), np.empty(3)
    first, last = order[0], order[-1]
    for i in range(3):
        C = q2 * K * c.G[:, i][None, :]
        walk[:, i] = C @ Pr
        E = q2 * K - C @ P @ C.T
        std[:, i] = np.sqrt(np.clip(np.diag(E), 0.0, None))
        moved[i] = walk[last, i] - walk[first, i]
        moved_std[i] = math.sqrt(max(E[last, last] + E[first, first] - 2.0 * E[last, first], 0.0))
    return BiasDrift(t=c.t0 + c.t[order], walk=walk[order], walk_std=std[order], moved=moved, moved_std=moved_std,
                     b=np.asarray(b, float))
