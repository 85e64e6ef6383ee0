"""Attitude over the motion segments as products of RK4 increments, with the exact Jacobian.

imu_tk's normalised RK4 step right-multiplies the attitude by a unit quaternion (model.rk4_increment),
so a segment's end attitude is the ordered product P = a_0 (x) a_1 (x) ... (x) a_{L-1} of its steps'
increments. Products are associative: the steps of every segment are cut into blocks of ``BLOCK``
that are multiplied side by side (one numpy operation over all blocks per position), then the block
products of each segment in turn. Every increment is computed at once (numpy code generated from the
CasADi model by imucal.solve.vectorize): no per-sample Python, no graph to build per data shape.

The rate of each step's ends is the sensor description's own map (SensorModel.apply of
imucal.model.gyroscope: raw reading and calibrated acceleration in, rad/s out), with the free and
fixed parameters split as imucal.solve.least_squares.split_parameters does; a rate calibrated by any
other means (a peer's calibration) is integrated by the same increments (``rate_steps``).

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

from imucal.gyro.model import direction_residual, quat_mul, quat_to_rot, rk4_increment, rk4_step
from imucal.model.sensor import SensorModel
from imucal.solve.least_squares import split_parameters
from imucal.solve.vectorize import Vectorized

#: steps per block: about the square root of a long segment's steps (hundreds)
BLOCK = 32
_IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


@dataclass(frozen=True)
class _Generated:
    """Numpy evaluators generated from the CasADi model, for one set of free parameters."""

    increment: Vectorized  #: (pfree, pfix, raw0, raw1, acc0, acc1, dt) -> a (unit quaternion of one step)
    tangent: Vectorized  #: (..., Pre) -> R(Pre) vec(da/dpfree (x) a*)   (3 x nfree)
    product: Vectorized  #: (p, q) -> p (x) q
    end: Vectorized  #: (P, u0, u1) -> r = R(P)^T u0 - u1 (imu_tk's residual)
    end_jac: Vectorized  #: (P, u0, u1, Phi) -> r, dr/dpfree with dP/dpfree = (0, Phi) (x) P


@lru_cache(maxsize=1)
def _shared() -> tuple[Vectorized, Vectorized, Vectorized, Vectorized]:
    """(rate increment (w0, w1, dt) -> a, product, end residual, angle (P, u0, u1) -> deg): what integrating a
    calibrated rate needs, whoever calibrated it."""
    w0, w1, dt = ca.SX.sym("w0", 3), ca.SX.sym("w1", 3), ca.SX.sym("dt")
    p, q = ca.SX.sym("p", 4), ca.SX.sym("q", 4)
    P, u0, u1 = ca.SX.sym("P", 4), ca.SX.sym("u0", 3), ca.SX.sym("u1", 3)
    carried = ca.mtimes(quat_to_rot(P / ca.norm_2(P)).T, u0)  # R^T u0, gravity carried to the end
    angle = ca.atan2(ca.norm_2(ca.cross(carried, u1)), ca.dot(carried, u1)) * (180.0 / np.pi)
    return (Vectorized(ca.Function("gyro_rate_increment", [w0, w1, dt], [rk4_increment()(w0, w1, dt)])),
            Vectorized(ca.Function("gyro_qmul", [p, q], [quat_mul(p, q)])),
            Vectorized(ca.Function("gyro_end", [P, u0, u1], [direction_residual()(P / ca.norm_2(P), u0, u1)])),
            Vectorized(ca.Function("gyro_angle", [P, u0, u1], [angle])))


@lru_cache(maxsize=8)
def _generated(model: SensorModel, free: tuple[str, ...]) -> _Generated:
    pf, pfix, p = split_parameters(model.names, free)
    raw0, raw1, acc0, acc1 = (ca.SX.sym(n, 3) for n in ("raw0", "raw1", "acc0", "acc1"))
    dt = ca.SX.sym("dt")
    a = rk4_increment()(model.apply(raw0, acc0, p), model.apply(raw1, acc1, p), dt)
    conj = a * ca.DM([1, -1, -1, -1])
    da = ca.jacobian(a, pf)
    pre = ca.SX.sym("pre", 4)
    nf = len(free)
    t = ca.horzcat(*[quat_mul(da[:, k], conj)[1:4] for k in range(nf)])
    args = [pf, pfix, raw0, raw1, acc0, acc1, dt]
    P, u0, u1, Phi = ca.SX.sym("P", 4), ca.SX.sym("u0", 3), ca.SX.sym("u1", 3), ca.SX.sym("Phi", 3, nf)
    r = direction_residual()(P / ca.norm_2(P), u0, u1)
    dP = ca.horzcat(*[quat_mul(ca.vertcat(0, Phi[:, k]), P) for k in range(nf)])
    _, product, end, _ = _shared()
    return _Generated(
        increment=Vectorized(ca.Function("gyro_increment", args, [a])),
        tangent=Vectorized(ca.Function("gyro_tangent", args + [pre], [ca.mtimes(quat_to_rot(pre), t)])),
        product=product, end=end,
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


def products(product: Vectorized, a: np.ndarray, layout: Layout, prefixes: bool = False
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
        cur = product(cur, grid[:, :, i])[0]
    n = nb.size
    outer = np.repeat(_IDENTITY[:, None, None], n, 1).repeat(int(nb.max(initial=1)), 2)  # block products of a segment
    outer[:, block_seg, block_pos] = cur
    seg = np.repeat(_IDENTITY[:, None], n, 1)
    before = np.empty((4, block_seg.size)) if prefixes else None  # product of a segment's earlier blocks
    for m in range(int(nb.max(initial=0))):
        if prefixes:
            at = block_pos == m
            before[:, at] = seg[:, block_seg[at]]
        seg = product(seg, outer[:, :, m])[0]
    if not prefixes:
        return seg, None
    return seg, product(before[:, row_block], inner[:, row_block, row_pos])[0]


def _step_rows(first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """The sample index of each RK4 step's start, segment by segment (a step runs from i to i + 1)."""
    return np.concatenate([np.arange(f, l) for f, l in zip(first, last)]) if len(first) else np.zeros(0, int)


@dataclass(frozen=True)
class SegmentSteps:
    """The RK4 steps of a fit: rows concatenated segment by segment, and each segment's directions."""

    raw0: np.ndarray  #: (3, S) raw reading at each step's start
    raw1: np.ndarray  #: (3, S) ... and end
    acc0: np.ndarray  #: (3, S) calibrated acceleration at each step's start [m/s^2] (the map's inputs)
    acc1: np.ndarray  #: (3, S) ... and end
    dt: np.ndarray  #: (1, S) [s]
    u0: np.ndarray  #: (3, n) gravity direction at the segment's start
    u1: np.ndarray  #: (3, n) ... and end
    layout: Layout

    @classmethod
    def of(cls, t: np.ndarray, raw: np.ndarray, acc: np.ndarray, seg) -> "SegmentSteps":
        """The steps of the segments ``seg`` (imucal.gyro.segments.Segments) of samples (t, raw, acc)."""
        i0 = _step_rows(seg.first, seg.last)
        T = (lambda x: np.ascontiguousarray(x.T))
        return cls(T(raw[i0]), T(raw[i0 + 1]), T(acc[i0]), T(acc[i0 + 1]), (t[i0 + 1] - t[i0])[None, :],
                   T(seg.u0), T(seg.u1), Layout(np.asarray(seg.lengths, int)))

    @property
    def n(self) -> int:
        return int(self.u0.shape[1])

    def _args(self, pfree, pfix) -> list:
        return [pfree, pfix, self.raw0, self.raw1, self.acc0, self.acc1, self.dt]

    def residuals(self, model: SensorModel, free: tuple[str, ...], pfree, pfix) -> np.ndarray:
        """imu_tk's residual R^T u0 - u1 of every segment, (n, 3)."""
        gen = _generated(model, free)
        a = gen.increment(*self._args(pfree, pfix))[0]
        P, _ = products(gen.product, a, self.layout)
        return gen.end(P, self.u0, self.u1)[0].T

    def jacobian(self, model: SensorModel, free: tuple[str, ...], pfree, pfix) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (n, 3) and their Jacobian (3 n, nfree), rows in the order r_0x, r_0y, r_0z, r_1x, ..."""
        gen = _generated(model, free)
        nf = len(free)
        a = gen.increment(*self._args(pfree, pfix))[0]
        P, pre = products(gen.product, a, self.layout, prefixes=True)
        t = gen.tangent(*self._args(pfree, pfix), pre)[0]  # (3 nf, S), column-major 3 x nf
        starts = np.r_[0, np.cumsum(self.layout.lengths)[:-1]]
        Phi = np.add.reduceat(t, starts, axis=1)  # sum over each segment's steps
        r, J = gen.end_jac(P, self.u0, self.u1, Phi)
        return r.T, J.T.reshape(self.n, nf, 3).transpose(0, 2, 1).reshape(3 * self.n, nf)

    def costs(self, model: SensorModel, free: tuple[str, ...], pfree: np.ndarray, pfix) -> np.ndarray:
        """sum |r|^2 over the segments for each column of ``pfree`` (nfree, k), in one pass."""
        k = pfree.shape[1]
        gen = _generated(model, free)
        tile = (lambda v: np.tile(v, (1, k)))
        steps = (lambda v: v[:, None, :])  # (m, 1, S) against the parameters' (nfree, k, 1): the
        # description's instructions on the parameters alone (half the increment's) run k times, not k S
        a = gen.increment(np.asarray(pfree, float)[:, :, None], pfix, steps(self.raw0), steps(self.raw1),
                          steps(self.acc0), steps(self.acc1), steps(self.dt))[0]
        P, _ = products(gen.product, a.reshape(4, -1), self.layout.tiled(k))  # column k S + s, as tiled
        r = gen.end(P, tile(self.u0), tile(self.u1))[0]
        return np.sum(r.reshape(3, k, self.n) ** 2, axis=(0, 2))

    def subset(self, keep: np.ndarray) -> "SegmentSteps":
        """The steps of segments ``keep`` (indices, in order)."""
        L = np.asarray(self.layout.lengths, int)
        starts = np.r_[0, np.cumsum(L)[:-1]]
        rows = np.concatenate([np.arange(starts[s], starts[s] + L[s]) for s in keep])
        return SegmentSteps(self.raw0[:, rows], self.raw1[:, rows], self.acc0[:, rows], self.acc1[:, rows],
                            self.dt[:, rows], self.u0[:, keep], self.u1[:, keep], Layout(L[keep]))


def rate_directions(t: np.ndarray, rate: np.ndarray, seg) -> np.ndarray:
    """Angle [deg] between R^T u0 and u1 of every segment of ``seg``, ``rate`` (N, 3) [rad/s] calibrated by
    anyone: the same RK4 increments and products as the fit, generated from the same CasADi model."""
    if seg.n == 0:
        return np.zeros(0)
    increment, product, _, angle = _shared()
    i0 = _step_rows(seg.first, seg.last)
    a = increment(np.ascontiguousarray(rate[i0].T), np.ascontiguousarray(rate[i0 + 1].T),
                  (t[i0 + 1] - t[i0])[None, :])[0]
    P, _ = products(product, a, Layout(np.asarray(seg.lengths, int)))
    return angle(P, np.ascontiguousarray(seg.u0.T), np.ascontiguousarray(seg.u1.T))[0][0]


def chained_graph(t: np.ndarray, seg, raw: np.ndarray, acc: np.ndarray, model: SensorModel,
                  free: tuple[str, ...], pfix: np.ndarray) -> tuple[ca.MX, ca.MX]:
    """The check's reference: free parameters and residuals (3 n) of imu_tk's normalised RK4 steps chained
    in one CasADi graph (restarted at each segment), exact derivatives by CasADi. Slow to build; for tests and
    scripts/bench_gyro.py, which compare the fast path (and its optimum) with it."""
    pf = ca.MX.sym("pfree", len(free))
    index = {n: i for i, n in enumerate(free)}
    p = ca.vertcat(*[pf[index[n]] if n in index else float(pfix[i]) for i, n in enumerate(model.names)])
    i0 = _step_rows(seg.first, seg.last)
    rates = model.apply.map(i0.size)
    W0 = rates(ca.DM(raw[i0].T), ca.DM(acc[i0].T), ca.repmat(p, 1, i0.size))
    W1 = rates(ca.DM(raw[i0 + 1].T), ca.DM(acc[i0 + 1].T), ca.repmat(p, 1, i0.size))
    ends = np.cumsum(seg.lengths) - 1
    reset = np.zeros((1, i0.size))
    reset[0, np.r_[0, ends[:-1] + 1]] = 1.0
    U = ca.vertcat(W0, W1, ca.DM((t[i0 + 1] - t[i0])[None, :]), ca.DM(reset))
    Q = rk4_step().mapaccum("gyro_path", i0.size)(ca.DM([1, 0, 0, 0]), U)
    r = direction_residual().map(seg.n)(Q[:, ends.tolist()], ca.DM(seg.u0.T), ca.DM(seg.u1.T))
    return pf, ca.vec(r)
