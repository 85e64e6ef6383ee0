"""One evaluation formula for every tool: the gravity-direction error of each motion segment.

Given calibrated rates [rad/s] (whoever calibrated them) and the gravity directions measured at
the two ends of each segment, integrate the rate with imu_tk's quaternion RK4 step and report the
angle between the carried start direction R^T u0 and the measured end direction u1 [deg].
Written in numpy, independently of the CasADi graph of the fit (a test pins the two together).
"""
from __future__ import annotations

import numpy as np

from imucal.gyro.segments import Segments


def _omega(w: np.ndarray) -> np.ndarray:
    """(n, 4, 4) matrices of q' = 0.5 Omega(w) q, q = (w, x, y, z)."""
    x, y, c = w[:, 0], w[:, 1], w[:, 2]
    O = np.zeros((w.shape[0], 4, 4))
    O[:, 0, 1:], O[:, 1:, 0] = -w, w
    O[:, 1, 2], O[:, 1, 3], O[:, 2, 1], O[:, 2, 3], O[:, 3, 1], O[:, 3, 2] = c, -y, -c, x, y, -x
    return O


def integrate(t: np.ndarray, rate: np.ndarray, segments: Segments) -> np.ndarray:
    """End quaternion (n, 4) of every segment, all segments stepped together."""
    n = segments.n
    steps = segments.last - segments.first
    q = np.tile([1.0, 0, 0, 0], (n, 1))
    for j in range(int(steps.max(initial=0))):
        act = j < steps
        i = np.minimum(segments.first + j, segments.last - 1)
        dt = np.where(act, t[i + 1] - t[i], 0.0)[:, None]
        w0, w1 = rate[i], rate[i + 1]
        O0, Om, O1 = _omega(w0), _omega(0.5 * (w0 + w1)), _omega(w1)
        k1 = 0.5 * np.einsum("nij,nj->ni", O0, q)
        k2 = 0.5 * np.einsum("nij,nj->ni", Om, q + 0.5 * dt * k1)
        k3 = 0.5 * np.einsum("nij,nj->ni", Om, q + 0.5 * dt * k2)
        k4 = 0.5 * np.einsum("nij,nj->ni", O1, q + dt * k3)
        qn = q + dt * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        q = qn / np.linalg.norm(qn, axis=1, keepdims=True)
    return q


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices of unit quaternions (w, x, y, z)."""
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], 1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], 1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1)], 1)


def direction_errors_deg(t: np.ndarray, rate: np.ndarray, segments: Segments) -> np.ndarray:
    """Angle [deg] between R^T u0 and u1 for every segment (rate in rad/s, any calibration)."""
    R = rotation_matrices(integrate(t, rate, segments))
    carried = np.einsum("nji,nj->ni", R, segments.u0)
    c = np.sum(carried * segments.u1, axis=1) / np.linalg.norm(carried, axis=1) / np.linalg.norm(segments.u1, axis=1)
    s = np.linalg.norm(np.cross(carried, segments.u1), axis=1) / np.linalg.norm(carried, axis=1) / np.linalg.norm(segments.u1, axis=1)
    return np.degrees(np.arctan2(s, c))


def rms(x: np.ndarray) -> float:
    """Root mean square of per-segment errors."""
    return float(np.sqrt(np.mean(np.square(x))))
