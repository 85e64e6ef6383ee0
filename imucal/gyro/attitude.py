"""Attitude over the motion segments as products of RK4 increments, with the exact Jacobian.

imu_tk's normalised RK4 step right-multiplies the attitude by a unit quaternion (model.rk4_increment),
so a segment's end attitude is the ordered product P = a_0 (x) a_1 (x) ... (x) a_{L-1} of its steps'
increments. Products are associative: the steps of every segment are cut into blocks of ``BLOCK``
that are multiplied side by side (one numpy operation over all blocks per position), then the block
products of each segment in turn. Every increment is computed at once (numpy code generated from the
CasADi model by imucal.solve.vectorize): no per-sample Python, no graph to build per data shape.

Exact derivatives of the discrete scheme, without approximation: with Pre_j = a_0 (x) ... (x) a_{j-1},
    dP = sum_j Pre_j (x) da_j (x) a_j* (x) Pre_j* (x) P = (0, sum_j R(Pre_j) t_j) (x) P,
t_j = vec(da_j (x) a_j*) (the scalar part is zero for a unit a_j), R(q) the rotation of q
(model.quat_to_rot): the Jacobian of each segment's residual is one sum over its steps.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import casadi as ca
import numpy as np

from imucal.gyro.model import direction_residual, quat_mul, quat_to_rot, rate_map, rk4_increment, rk4_step
from imucal.solve.vectorize import Vectorized

#: steps per block: about the square root of a long segment's steps (hundreds)
BLOCK = 32
_IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def fit_rates(x, scale0, y):
    """Calibrated rate of the fit's unknowns x: C (y - db), B_g = diag(scale0 (1 + x_s)), db = scale0 1e-3 x_b."""
    C, _ = rate_map(scale0 * (1 + x[0:3]), x[3:9])
    db = scale0 * 1e-3 * x[9:12] if x.shape[0] > 9 else ca.DM.zeros(3, 1)
    return ca.mtimes(C, y - db)


@dataclass(frozen=True)
class _Generated:
    """Numpy evaluators generated from the CasADi model, for ``nx`` unknowns."""

    increment: Vectorized  #: (x, scale0, y0, y1, dt) -> a (unit quaternion of one step)
    tangent: Vectorized  #: (x, scale0, y0, y1, dt, Pre) -> R(Pre) vec(da/dx (x) a*)   (3 x nx)
    product: Vectorized  #: (p, q) -> p (x) q
    end: Vectorized  #: (P, u0, u1) -> r = R(P)^T u0 - u1 (imu_tk's residual)
    end_jac: Vectorized  #: (P, u0, u1, Phi) -> r, dr/dx with dP/dx = (0, Phi) (x) P


@lru_cache(maxsize=4)
def _generated(nx: int) -> _Generated:
    x, s0, y0, y1, dt = (ca.SX.sym(n, k) for n, k in (("x", nx), ("scale0", 3), ("y0", 3), ("y1", 3), ("dt", 1)))
    a = rk4_increment()(fit_rates(x, s0, y0), fit_rates(x, s0, y1), dt)
    conj = a * ca.DM([1, -1, -1, -1])
    da = ca.jacobian(a, x)
    pre = ca.SX.sym("pre", 4)
    t = ca.horzcat(*[quat_mul(da[:, k], conj)[1:4] for k in range(nx)])
    args = [x, s0, y0, y1, dt]
    p, q = ca.SX.sym("p", 4), ca.SX.sym("q", 4)
    P, u0, u1, Phi = ca.SX.sym("P", 4), ca.SX.sym("u0", 3), ca.SX.sym("u1", 3), ca.SX.sym("Phi", 3, nx)
    r = direction_residual()(P / ca.norm_2(P), u0, u1)
    dP = ca.horzcat(*[quat_mul(ca.vertcat(0, Phi[:, k]), P) for k in range(nx)])
    return _Generated(
        increment=Vectorized(ca.Function("gyro_increment", args, [a])),
        tangent=Vectorized(ca.Function("gyro_tangent", args + [pre], [ca.mtimes(quat_to_rot(pre), t)])),
        product=Vectorized(ca.Function("gyro_qmul", [p, q], [quat_mul(p, q)])),
        end=Vectorized(ca.Function("gyro_end", [P, u0, u1], [r])),
        end_jac=Vectorized(ca.Function("gyro_end_jac", [P, u0, u1, Phi], [r, ca.mtimes(ca.jacobian(r, P), dP)])))


@dataclass(frozen=True)
class Layout:
    """Where each step (row) sits: segments of ``lengths`` steps, cut into blocks of BLOCK."""

    lengths: np.ndarray

    @cached_property
    def index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per row: block and position in it; per block: segment and position among the segment's blocks."""
        L = np.asarray(self.lengths, int)
        nb = -(-L // BLOCK)
        first_block = np.r_[0, np.cumsum(nb)[:-1]]
        step = np.arange(int(L.sum())) - np.repeat(np.r_[0, np.cumsum(L)[:-1]], L)  # step within its segment
        row_block = np.repeat(first_block, L) + step // BLOCK
        block_seg = np.repeat(np.arange(L.size), nb)
        block_pos = np.arange(int(nb.sum())) - np.repeat(first_block, nb)
        return row_block, step % BLOCK, block_seg, block_pos, nb

    def tiled(self, times: int) -> "Layout":
        return Layout(np.tile(np.asarray(self.lengths, int), times))


def products(gen: _Generated, a: np.ndarray, layout: Layout, prefixes: bool = False
             ) -> tuple[np.ndarray, np.ndarray | None]:
    """Each segment's product P (4, n) of the row increments a (4, S); with ``prefixes`` also Pre_j (4, S)."""
    row_block, row_pos, block_seg, block_pos, nb = layout.index
    grid = np.repeat(_IDENTITY[:, None, None], nb.sum(), 1).repeat(BLOCK, 2)
    grid[:, row_block, row_pos] = a
    inner = np.empty((4, grid.shape[1], BLOCK + 1)) if prefixes else None  # exclusive prefixes within blocks
    cur = np.repeat(_IDENTITY[:, None], grid.shape[1], 1)
    for i in range(BLOCK):
        if prefixes:
            inner[:, :, i] = cur
        cur = gen.product(cur, grid[:, :, i])[0]
    n = nb.size
    outer = np.repeat(_IDENTITY[:, None, None], n, 1).repeat(int(nb.max()), 2)  # block products of a segment
    outer[:, block_seg, block_pos] = cur
    seg = np.repeat(_IDENTITY[:, None], n, 1)
    before = np.empty((4, block_seg.size)) if prefixes else None  # product of a segment's earlier blocks
    for m in range(int(nb.max())):
        if prefixes:
            at = block_pos == m
            before[:, at] = seg[:, block_seg[at]]
        seg = gen.product(seg, outer[:, :, m])[0]
    if not prefixes:
        return seg, None
    return seg, gen.product(before[:, row_block], inner[:, row_block, row_pos])[0]


@dataclass(frozen=True)
class SegmentSteps:
    """The RK4 steps of a fit: rows concatenated segment by segment, and each segment's directions."""

    y0: np.ndarray  #: (3, S) corrected raw rate at each step's start
    y1: np.ndarray  #: (3, S) ... and end
    dt: np.ndarray  #: (1, S) [s]
    u0: np.ndarray  #: (3, n) gravity direction at the segment's start
    u1: np.ndarray  #: (3, n) ... and end
    layout: Layout

    @property
    def n(self) -> int:
        return int(self.u0.shape[1])

    def residuals(self, x: np.ndarray, scale0: np.ndarray) -> np.ndarray:
        """imu_tk's residual R^T u0 - u1 of every segment, (n, 3)."""
        gen = _generated(x.size)
        a = gen.increment(x, scale0, self.y0, self.y1, self.dt)[0]
        P, _ = products(gen, a, self.layout)
        return gen.end(P, self.u0, self.u1)[0].T

    def jacobian(self, x: np.ndarray, scale0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (n, 3) and their Jacobian (3 n, nx), rows in the order r_0x, r_0y, r_0z, r_1x, ..."""
        gen = _generated(x.size)
        a = gen.increment(x, scale0, self.y0, self.y1, self.dt)[0]
        P, pre = products(gen, a, self.layout, prefixes=True)
        t = gen.tangent(x, scale0, self.y0, self.y1, self.dt, pre)[0]  # (3 nx, S), column-major 3 x nx
        starts = np.r_[0, np.cumsum(self.layout.lengths)[:-1]]
        Phi = np.add.reduceat(t, starts, axis=1)  # sum over each segment's steps
        r, J = gen.end_jac(P, self.u0, self.u1, Phi)
        return r.T, J.T.reshape(self.n, x.size, 3).transpose(0, 2, 1).reshape(3 * self.n, x.size)

    def costs(self, scales: np.ndarray, nx: int) -> np.ndarray:
        """sum |r|^2 over the segments at x = 0, for each scalar nominal scale in ``scales`` (one pass)."""
        k = len(scales)
        gen = _generated(nx)
        s0 = np.repeat(np.asarray(scales, float), self.dt.shape[1])[None, :].repeat(3, 0)
        tile = (lambda v: np.tile(v, (1, k)))
        a = gen.increment(np.zeros(nx), s0, tile(self.y0), tile(self.y1), tile(self.dt))[0]
        P, _ = products(gen, a, self.layout.tiled(k))
        r = gen.end(P, tile(self.u0), tile(self.u1))[0]
        return np.sum(r.reshape(3, k, self.n) ** 2, axis=(0, 2))

    def subset(self, keep: np.ndarray) -> "SegmentSteps":
        """The steps of segments ``keep`` (indices, in order)."""
        L = np.asarray(self.layout.lengths, int)
        starts = np.r_[0, np.cumsum(L)[:-1]]
        rows = np.concatenate([np.arange(starts[s], starts[s] + L[s]) for s in keep])
        return SegmentSteps(self.y0[:, rows], self.y1[:, rows], self.dt[:, rows], self.u0[:, keep],
                            self.u1[:, keep], Layout(L[keep]))


def chained_graph(t: np.ndarray, seg, corrected: np.ndarray, nx: int, scale0: np.ndarray) -> tuple[ca.MX, ca.MX]:
    """The check's reference: unknowns x and residuals (3 n) of imu_tk's normalised RK4 steps chained in one
    CasADi graph (restarted at each segment), exact derivatives by CasADi. Slow to build; for tests and
    scripts/bench_gyro.py, which compare the fast path (and its optimum) with it."""
    x = ca.MX.sym("x", nx)
    i0 = np.concatenate([np.arange(f, l) for f, l in zip(seg.first, seg.last)])
    W0 = fit_rates(x, ca.DM(scale0), ca.DM(corrected[i0].T))
    W1 = fit_rates(x, ca.DM(scale0), ca.DM(corrected[i0 + 1].T))
    ends = np.cumsum(seg.lengths) - 1
    reset = np.zeros((1, i0.size))
    reset[0, np.r_[0, ends[:-1] + 1]] = 1.0
    U = ca.vertcat(W0, W1, ca.DM((t[i0 + 1] - t[i0])[None, :]), ca.DM(reset))
    Q = rk4_step().mapaccum("gyro_path", i0.size)(ca.DM([1, 0, 0, 0]), U)
    r = direction_residual().map(seg.n)(Q[:, ends.tolist()], ca.DM(seg.u0.T), ca.DM(seg.u1.T))
    return x, ca.vec(r)
