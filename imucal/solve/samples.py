"""Samples mode for the base model: the per-sample objective, vectorised.

A per-sample symbolic expansion (or a CasADi map with exact Hessians) costs minutes at 10^5
samples. For the base model the structure is simple enough to evaluate exactly with array
operations: m = (raw - s) / b (Eq. theModel), q = m^T Tbar m (Proposition 2, Tbar = G^-1 from
the CasADi model), r = sqrt(q) - g. The gradient follows in closed form:
  dq/ds_i = -2 (Tbar m)_i / b_i,  dq/db_i = -2 (Tbar m)_i m_i / b_i,
  dq/dangle = tr(dTbar/dangle  m m^T),   dr/dp = dq/dp / (2 sqrt q).
IPOPT sees a CasADi Callback with this value and gradient, so the fit
stays one IPOPT NLP and each iteration is O(N) array work. The Hessian IPOPT gets is the
Gauss-Newton one, J^T W J, the standard choice for least squares.
"""
from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from imucal.solve import ipopt
from imucal.model.sensor import tbar


@lru_cache(maxsize=1)
def _tbar_and_derivative() -> ca.Function:
    a = ca.SX.sym("a", 3)
    T = tbar(a[0], a[1], a[2])
    dT = [ca.jacobian(ca.vec(T), a[i]) for i in range(3)]
    return ca.Function("tbar_d", [a], [T, *[ca.reshape(d, 3, 3) for d in dT]])


class SampleResiduals:
    """r_k = |a_k| - g and dr_k/dp (N x 9) for the base model, exactly, with numpy.

    Samples are stored axis by axis (3 x N, contiguous): strided column access is several
    times slower at 10^6 samples.
    """

    def __init__(self, raw: np.ndarray, gravity: float) -> None:
        self.X = np.ascontiguousarray(np.asarray(raw, float).T)
        self.g = float(gravity)
        self._last: tuple = (None, None, None)  # IPOPT asks f, grad, Hessian at the same point

    def residuals(self, p: np.ndarray, jac: bool = False):
        key = np.asarray(p, float).tobytes()
        if self._last[0] == key and (not jac or self._last[2] is not None):
            return (self._last[1], self._last[2]) if jac else self._last[1]
        r, J = self._evaluate(np.asarray(p, float), jac)
        self._last = (key, r, J)
        return (r, J) if jac else r

    def _evaluate(self, p: np.ndarray, jac: bool):
        s, b, ang = p[0:3], p[3:6], p[6:9]
        out = _tbar_and_derivative()(ang)
        T = np.asarray(out[0])
        m = [(self.X[i] - s[i]) / b[i] for i in range(3)]  # Eq. (theModel)
        v = [T[i, 0] * m[0] + T[i, 1] * m[1] + T[i, 2] * m[2] for i in range(3)]  # Tbar m
        q = m[0] * v[0] + m[1] * v[1] + m[2] * v[2]  # Proposition 2
        sq = np.sqrt(np.maximum(q, 1e-300))
        r = sq - self.g
        if not jac:
            return r, None
        Jt = np.empty((9, r.size))  # each parameter's column contiguous
        h = 0.5 / sq
        for i in range(3):
            Jt[i] = v[i] * (-2.0 / b[i]) * h
            Jt[3 + i] = Jt[i] * m[i]
        for a in range(3):
            D = np.asarray(out[1 + a])
            Jt[6 + a] = (D[0, 0] * m[0] * m[0] + D[1, 1] * m[1] * m[1] + D[2, 2] * m[2] * m[2]
                         + 2 * (D[0, 1] * m[0] * m[1] + D[0, 2] * m[0] * m[2] + D[1, 2] * m[1] * m[2])) * h
        return r, Jt.T


class _Objective(ca.Callback):
    """f(x) = 1/2 sum w r^2, free parameters p = off + scale * x; gradient via get_jacobian."""

    def __init__(self, res: SampleResiduals, w: np.ndarray, pfix: np.ndarray, free_idx: np.ndarray,
                 off: np.ndarray, scale: np.ndarray) -> None:
        ca.Callback.__init__(self)
        self.res, self.w, self.pfix, self.free_idx = res, w, pfix, free_idx
        self.off, self.scale = off, scale
        self._keep: list = []  # CasADi holds raw pointers: keep every derived callback alive
        self.construct("samples_objective", {})

    def p_of(self, x: np.ndarray) -> np.ndarray:
        p = self.pfix.copy()
        p[self.free_idx] = self.off + self.scale * np.asarray(x).ravel()
        return p

    def get_n_in(self): return 1
    def get_n_out(self): return 1
    def get_sparsity_in(self, i): return ca.Sparsity.dense(len(self.free_idx), 1)
    def get_sparsity_out(self, i): return ca.Sparsity.dense(1, 1)

    def eval(self, arg):
        r = self.res.residuals(self.p_of(arg[0]))
        return [0.5 * float(np.sum(self.w * r * r))]

    def has_jacobian(self): return True

    def get_jacobian(self, name, inames, onames, opts):
        jac = _Gradient(self)
        self._keep.append(jac)
        return jac


class _Gradient(ca.Callback):
    def __init__(self, obj: _Objective) -> None:
        ca.Callback.__init__(self)
        self.obj = obj
        self.construct("samples_gradient", {})

    def get_n_in(self): return 2
    def get_n_out(self): return 1

    def get_sparsity_in(self, i):
        return ca.Sparsity.dense(len(self.obj.free_idx), 1) if i == 0 else ca.Sparsity.dense(1, 1)

    def get_sparsity_out(self, i): return ca.Sparsity.dense(1, len(self.obj.free_idx))

    def eval(self, arg):
        o = self.obj
        r, J = o.res.residuals(o.p_of(arg[0]), jac=True)
        g = (J.T[o.free_idx] @ (o.w * r)) * o.scale
        return [ca.DM(g).T]

    def has_jacobian(self): return True

    def get_jacobian(self, name, inames, onames, opts):
        hess = _GaussNewtonHessian(self.obj)
        self.obj._keep.append(hess)
        return hess


class _GaussNewtonHessian(ca.Callback):
    """Gauss-Newton Hessian J^T W J (positive semi-definite; exact at zero residual)."""

    def __init__(self, obj: _Objective) -> None:
        ca.Callback.__init__(self)
        self.obj = obj
        self.construct("samples_hessian", {})

    def get_n_in(self): return 3  # x, nominal f, nominal gradient
    def get_n_out(self): return 2  # d grad/dx, d grad/d f (structurally zero)

    def get_sparsity_in(self, i):
        nf = len(self.obj.free_idx)
        return [ca.Sparsity.dense(nf, 1), ca.Sparsity.dense(1, 1), ca.Sparsity.dense(1, nf)][i]

    def get_sparsity_out(self, i):
        nf = len(self.obj.free_idx)
        return ca.Sparsity.dense(nf, nf) if i == 0 else ca.Sparsity(nf, 1)

    def eval(self, arg):
        o = self.obj
        _, J = o.res.residuals(o.p_of(arg[0]), jac=True)
        Jt = J.T[o.free_idx] * o.scale[:, None]
        H = (Jt * o.w) @ Jt.T
        return [ca.DM(H), ca.DM(ca.Sparsity(len(o.free_idx), 1))]


def solve_samples(raw: np.ndarray, w: np.ndarray, gravity: float, pfix: np.ndarray, free_idx: np.ndarray,
                  off: np.ndarray, scale: np.ndarray, x0: np.ndarray, lb: np.ndarray, ub: np.ndarray):
    """One IPOPT solve of the samples-mode NLP; returns (x, stats)."""
    res = SampleResiduals(raw, gravity)
    obj = _Objective(res, w, pfix, free_idx, off, scale)
    x = ca.MX.sym("x", len(free_idx))
    solver = ca.nlpsol("calib_samples", "ipopt", {"x": x, "f": obj(x)},
                       ipopt.OPTIONS)
    sol = solver(x0=x0, lbx=lb, ubx=ub)
    stats = solver.stats()
    del solver  # before the callbacks it points to
    return np.asarray(sol["x"]).ravel(), stats
