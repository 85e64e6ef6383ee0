"""The one least-squares path, in the shape of CasADi's ``sysid.py`` example.

The residual of ONE observation (an interval mean or a sample) is a CasADi function of the
observation and the parameters (``SensorModel.residual``). From it this module generates, once
per model and set of free parameters, the row's value, its Jacobian (free parameters and raw
reading) and, by option, its Hessian (imucal.solve.vectorize turns each into numpy code run over
blocks of rows). The normal equations are accumulated block by block,

    f = 1/2 sum w r^2,   grad = sum w r J,   H = sum w J^T J   (+ sum w r d2r, "exact"),

(or, with a full weight matrix W = V^-1 on interval means, f = 1/2 r^T W r: generalised least
squares for correlated rows, imucal.solve.stochastic), so memory grows with the block, not with the number of rows. IPOPT sees f, grad and H through
CasADi callbacks of an NLP built once per number of free parameters and reused: the data are
swapped in, the solver is not rebuilt. Every fit (base model, effects, means and samples mode)
takes this path with the one option set of imucal.solve.ipopt.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from imucal.model.sensor import SensorModel
from imucal.solve import ipopt
from imucal.solve.stats import median
from imucal.solve.vectorize import Vectorized

#: Rows per block: small enough for the temporaries to stay in the CPU cache (measured fastest
#: at 10^6 rows on this project's benchmark machine), large enough to amortise Python overhead.
BLOCK = 8192


@dataclass(frozen=True)
class RowFunctions:
    """Generated evaluators of one observation's residual r = |a| - g (and its derivatives)."""

    value: Vectorized  #: (raw, cov, pfree, pfix, g) -> r
    derivatives: Vectorized  #: ... -> r, dr/dpfree, dr/draw
    curvature_function: ca.Function  #: ... -> d2r/dpfree2 (the exact Hessian's extra term)
    n_free: int

    @property
    def curvature(self) -> Vectorized:
        """The curvature's numpy evaluator, generated on first use (only hessian="exact" needs it)."""
        return _vectorized(self.curvature_function)


@lru_cache(maxsize=64)
def _vectorized(fn: ca.Function) -> Vectorized:
    return Vectorized(fn)


def split_parameters(names: tuple[str, ...], free: tuple[str, ...]) -> tuple[ca.SX, ca.SX, ca.SX]:
    """(pfree, pfix, p): the symbols of the free parameters and of all parameters' fixed values, and the
    model's parameter vector p taking each free one from pfree and every other from pfix. Every evidence's
    generated evaluators take (pfree, pfix) this way: one set of free parameters, one code path."""
    pf, pfix = ca.SX.sym("pfree", len(free)), ca.SX.sym("pfix", len(names))
    index = {n: k for k, n in enumerate(free)}
    return pf, pfix, ca.vertcat(*[pf[index[n]] if n in index else pfix[i] for i, n in enumerate(names)])


@lru_cache(maxsize=64)
def row_functions(model: SensorModel, free: tuple[str, ...]) -> RowFunctions:
    """The row evaluators for ``model`` with ``free`` parameters, built once and cached."""
    raw, cov = ca.SX.sym("raw", 3), ca.SX.sym("cov", len(model.evidence_covariates))  # the rows' covariates
    pf, pfix, p = split_parameters(model.names, free)
    g = ca.SX.sym("g")
    r = model.residual(raw, cov, p, g)
    args = [raw, cov, pf, pfix, g]
    J = ca.jacobian(r, pf)
    return RowFunctions(
        value=Vectorized(ca.Function("row_r", args, [r])),
        derivatives=Vectorized(ca.Function("row_rj", args, [r, J, ca.jacobian(r, raw)])),
        curvature_function=ca.Function("row_h", args, [ca.hessian(r, pf)[0]]),
        n_free=len(free))


@dataclass(frozen=True)
class Rows:
    """The observations of one fit: raw readings (N, 3) and covariates (N, k)."""

    raw: np.ndarray
    cov: np.ndarray

    @property
    def n(self) -> int:
        return self.raw.shape[0]

    def blocks(self):
        for s in range(0, self.n, BLOCK):
            yield slice(s, s + BLOCK), self.raw[s:s + BLOCK].T, self.cov[s:s + BLOCK].T


def row_g(g: float | np.ndarray, sl: slice) -> list[float] | np.ndarray:
    """The gravity argument of one block: one value for every row, or each row's own (an (N,) array:
    what |a| of a noisy sample averages to, imucal.solve.fit)."""
    return [g] if np.ndim(g) == 0 else np.asarray(g, float)[sl][None, :]


def residuals(fns: RowFunctions, rows: Rows, pfree, pfix, g: float | np.ndarray) -> np.ndarray:
    """r = |a| - g for every row (g one value, or one per row)."""
    out = np.empty(rows.n)
    for sl, raw, cov in rows.blocks():
        out[sl] = fns.value(raw, cov, pfree, pfix, row_g(g, sl))[0][0]
    return out


def jacobians(fns: RowFunctions, rows: Rows, pfree, pfix, g: float | np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """r (N,), dr/dpfree (N, nf) and dr/draw (N, 3): whole arrays, for small N (interval means)."""
    r, J, Jraw = np.empty(rows.n), np.empty((rows.n, fns.n_free)), np.empty((rows.n, 3))
    for sl, raw, cov in rows.blocks():
        rb, Jb, Jrb = fns.derivatives(raw, cov, pfree, pfix, row_g(g, sl))
        r[sl], J[sl], Jraw[sl] = rb[0], Jb.T, Jrb.T
    return r, J, Jraw


def noise_sigma(fns: RowFunctions, rows: Rows, raw_var: np.ndarray, pfree, pfix, g: float | np.ndarray,
                weights: str = "noise") -> np.ndarray:
    """Noise of each residual, propagated to first order from the raw readings' variance.

    ``weights="uniform"`` gives every row the median (imu_tk's unweighted cost).
    """
    s = np.empty(rows.n)
    for sl, raw, cov in rows.blocks():
        Jraw = fns.derivatives(raw, cov, pfree, pfix, row_g(g, sl))[2]
        s[sl] = np.sqrt(np.sum(Jraw**2 * raw_var[sl].T, axis=0))
    floor = max(median(s) * 1e-3, 1e-12)
    if weights == "uniform":
        return np.full_like(s, max(median(s), floor))
    return np.maximum(s, floor)


def weighted_r_factor(fns: RowFunctions, rows: Rows, sigma: np.ndarray, pfree, pfix, g: float | np.ndarray
                      ) -> np.ndarray:
    """R (nf x nf) with R^T R = J^T W J, by a QR of the weighted Jacobian taken block by block.

    R has the singular values and right singular vectors of J / sigma, so the covariance from
    it equals the one from the whole Jacobian, without holding an N x nf array. ``sigma`` (N, N)
    is a whitening matrix L^-1 (V = L L^T, generalised least squares): R from L^-1 J.
    """
    if sigma.ndim == 2:
        return np.linalg.qr(sigma @ jacobians(fns, rows, pfree, pfix, g)[1], mode="r")
    R = np.zeros((0, fns.n_free))
    for sl, raw, cov in rows.blocks():
        Jb = fns.derivatives(raw, cov, pfree, pfix, row_g(g, sl))[1].T / sigma[sl, None]
        R = np.linalg.qr(np.vstack([R, Jb]), mode="r")
    return R


def normal_equations(fns: RowFunctions, rows: Rows, w: np.ndarray, pfree, pfix, g: float | np.ndarray,
                     exact: bool = False) -> tuple[float, np.ndarray, np.ndarray]:
    """f, grad and Hessian (Gauss-Newton, or exact) of 1/2 sum w r^2, accumulated by blocks.

    ``w`` (N, N) is a full weight matrix V^-1 (generalised least squares, interval means only):
    f = 1/2 r^T W r, grad = J^T W r, H = J^T W J, on whole arrays.
    """
    nf = fns.n_free
    if w.ndim == 2:
        r, J, _ = jacobians(fns, rows, pfree, pfix, g)
        wr_all = w @ r
        H = J.T @ w @ J
        if exact:
            for sl, raw, cov in rows.blocks():
                H += (fns.curvature(raw, cov, pfree, pfix, row_g(g, sl))[0] @ wr_all[sl]).reshape(nf, nf)
        return 0.5 * float(r @ wr_all), J.T @ wr_all, H
    f, grad, H = 0.0, np.zeros(nf), np.zeros((nf, nf))
    for sl, raw, cov in rows.blocks():
        rb, Jb, _ = fns.derivatives(raw, cov, pfree, pfix, row_g(g, sl))
        wr = w[sl] * rb[0]
        f += 0.5 * float(np.dot(wr, rb[0]))
        grad += Jb @ wr
        H += (Jb * w[sl]) @ Jb.T
        if exact:
            H += (fns.curvature(raw, cov, pfree, pfix, row_g(g, sl))[0] @ wr).reshape(nf, nf)
    return f, grad, H


@dataclass(frozen=True)
class RowEvidence:
    """The accelerometer's evidence as the one fit sees it: rows (interval means or samples), each residual
    r = |a| - g from ``fns`` (imucal.solve.evidence.Evidence, accumulated block by block)."""

    fns: RowFunctions
    rows: Rows
    g: float | np.ndarray  #: gravity of every row, or each row's own [m/s^2]

    @property
    def n_free(self) -> int:
        return self.fns.n_free

    def residuals(self, pfree, pfix) -> np.ndarray:
        return residuals(self.fns, self.rows, pfree, pfix, self.g)

    def normal_equations(self, pfree, pfix, w: np.ndarray, exact: bool = False) -> tuple[float, np.ndarray, np.ndarray]:
        return normal_equations(self.fns, self.rows, w, pfree, pfix, self.g, exact)

    def r_factor(self, pfree, pfix, sigma: np.ndarray) -> np.ndarray:
        return weighted_r_factor(self.fns, self.rows, sigma, pfree, pfix, self.g)


class Problem:
    """One weighted least-squares problem in scaled unknowns x: pfree = off + scale * x, over any evidence
    (imucal.solve.evidence.Evidence: the accelerometer's rows, the gyroscope's motion segments)."""

    def __init__(self, evidence, w: np.ndarray, pfix: np.ndarray, off: np.ndarray, scale: np.ndarray,
                 exact: bool = False, step: Callable[[], None] | None = None) -> None:
        self.evidence, self.w, self.pfix = evidence, w, pfix
        self.off, self.scale, self.exact = off, scale, exact
        self.step = step  #: called after every pass over the rows (a progress bar, imucal.report.progress)
        self._key: bytes | None = None
        self._val: tuple = ()

    @property
    def n_free(self) -> int:
        return self.evidence.n_free

    def p_of(self, x) -> np.ndarray:
        return self.off + self.scale * np.asarray(x, float).ravel()

    def value(self, x) -> float:
        x = np.asarray(x, float)  # IPOPT's point arrives as a CasADi DM: converted once
        if self._key == x.tobytes():
            return self._val[0]
        r = self.evidence.residuals(self.p_of(x), self.pfix)
        if self.step is not None:
            self.step()
        return 0.5 * float(r @ (self.w @ r if self.w.ndim == 2 else self.w * r))

    def derivatives(self, x) -> tuple[float, np.ndarray, np.ndarray]:
        """f, grad and Hessian in x; IPOPT asks them at the same point: computed once."""
        x = np.asarray(x, float)
        key = x.tobytes()
        if self._key != key:
            f, g, H = self.evidence.normal_equations(self.p_of(x), self.pfix, self.w, self.exact)
            if self.step is not None:
                self.step()
            self._key, self._val = key, (f, g * self.scale, H * np.outer(self.scale, self.scale))
        return self._val


class _Slot:
    """The problem the cached solver currently works on (swapped in by ``solve``).

    An interrupt (Ctrl-C, SIGTERM) raised inside a callback is caught by CasADi and becomes an
    IPOPT failure status; it is recorded here and raised again once IPOPT has returned.
    """

    problem: Problem | None = None
    interrupt: BaseException | None = None

    def call(self, fn, *args):
        try:
            return fn(*args)
        except KeyboardInterrupt as e:
            self.interrupt = e
            raise


class _Objective(ca.Callback):
    def __init__(self, slot: _Slot, nf: int) -> None:
        ca.Callback.__init__(self)
        self.slot, self.nf, self._keep = slot, nf, []
        self.construct("lsq_f", {})

    def get_n_in(self): return 1
    def get_n_out(self): return 1
    def get_sparsity_in(self, i): return ca.Sparsity.dense(self.nf, 1)
    def get_sparsity_out(self, i): return ca.Sparsity.dense(1, 1)
    def eval(self, arg): return [self.slot.call(lambda x: self.slot.problem.value(x), arg[0])]
    def has_jacobian(self): return True

    def get_jacobian(self, name, inames, onames, opts):
        cb = _Gradient(self)
        self._keep.append(cb)  # CasADi holds raw pointers: keep derived callbacks alive
        return cb


class _Gradient(ca.Callback):
    def __init__(self, obj: _Objective) -> None:
        ca.Callback.__init__(self)
        self.obj = obj
        self.construct("lsq_grad", {})

    def get_n_in(self): return 2  # x, nominal f
    def get_n_out(self): return 1

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(self.obj.nf, 1) if i == 0 else ca.Sparsity.dense(1, 1)

    def get_sparsity_out(self, i): return ca.Sparsity.dense(1, self.obj.nf)
    def eval(self, arg): return [ca.DM(self.obj.slot.call(self.obj.slot.problem.derivatives, arg[0])[1]).T]
    def has_jacobian(self): return True

    def get_jacobian(self, name, inames, onames, opts):
        cb = _Hessian(self.obj)
        self.obj._keep.append(cb)
        return cb


class _Hessian(ca.Callback):
    def __init__(self, obj: _Objective) -> None:
        ca.Callback.__init__(self)
        self.obj = obj
        self.construct("lsq_hess", {})

    def get_n_in(self): return 3  # x, nominal f, nominal gradient
    def get_n_out(self): return 2  # d grad/dx, d grad/df (structurally zero)

    def get_sparsity_in(self, i):
        nf = self.obj.nf
        return [ca.Sparsity.dense(nf, 1), ca.Sparsity.dense(1, 1), ca.Sparsity.dense(1, nf)][i]

    def get_sparsity_out(self, i):
        nf = self.obj.nf
        return ca.Sparsity.dense(nf, nf) if i == 0 else ca.Sparsity(nf, 1)

    def eval(self, arg):
        H = self.obj.slot.call(self.obj.slot.problem.derivatives, arg[0])[2]
        return [ca.DM(H), ca.DM(ca.Sparsity(self.obj.nf, 1))]


@lru_cache(maxsize=32)
def _solver(nf: int) -> tuple[ca.Function, _Slot, _Objective]:
    """IPOPT over nf scaled unknowns with simple bounds, built once per nf."""
    slot = _Slot()
    obj = _Objective(slot, nf)
    x = ca.MX.sym("x", nf)
    return ca.nlpsol("imucal_lsq", "ipopt", {"x": x, "f": obj(x)}, ipopt.LEAST_SQUARES), slot, obj


def solve(problem: Problem, lb: np.ndarray, ub: np.ndarray) -> tuple[np.ndarray, dict]:
    """Minimise the problem from x = 0 within [lb, ub]; returns (x, IPOPT's stats).

    ``problem`` has ``n_free``, ``value(x)`` and ``derivatives(x)`` -> (f, gradient, Hessian), as
    ``Problem`` over any evidence.
    """
    nf = problem.n_free
    solver, slot, _ = _solver(nf)
    slot.problem, slot.interrupt = problem, None
    try:
        sol, stats = ipopt.run(solver, x0=np.zeros(nf), lbx=lb, ubx=ub)
        if slot.interrupt is not None:
            raise slot.interrupt
        return np.asarray(sol["x"]).ravel(), stats
    finally:
        slot.problem, slot.interrupt = None, None
