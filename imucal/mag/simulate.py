"""Simulated 9-axis logs with known hard and soft iron, axis mounting and misalignment.

The sensor is turned through random orientations C_k (body to world, uniform on the rotations, seeded),
held still at each for ``hold`` samples and turned to the next over ``transition`` samples (a slerp; with
hold 0 the log never stops, like a hand-turned one). In the world frame (z up) the accelerometer's
specific force at rest is (0, 0, g) and the field F (cos dip, 0, sin dip), so the angle of the model,
asin(a . h / |a||h|), is ``dip``. In the body: a = C^T (0, 0, g) (the accelerometer calibrated), and the
magnetometer reads the model's forward map (imucal.mag.model: raw = s + diag(b) E^T P^T R^T h, from
CasADi) of h = C^T h_world, late by ``lag`` samples, plus white noise. ``disturbed`` scales the field
during the holds of chosen poses (a steel desk, a laptop: a field that steps).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from imucal.constants import RIGHT_ANGLE
from imucal.mag.evidence import Poses, shift
from imucal.mag.frame import euler_angles
from imucal.mag.model import IDENTITY, NAMES, build_mag_model, rotation, vectorized


@dataclass(frozen=True)
class MagTruth:
    """The simulated magnetometer: the model's parameters, its noise and its lag."""

    s: tuple[float, float, float] = (0.2, -0.1, 0.05)  #: hard iron [raw]
    b: tuple[float, float, float] = (1.0, 1.0, 1.0)  #: scales [raw per field unit]
    angles: tuple[float, float, float] = (RIGHT_ANGLE,) * 3  #: phi, psi, theta [rad]: soft iron
    axes: tuple[int, ...] = IDENTITY  #: signed permutation P (h_acc = R P h_mag)
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: rx, ry, rz [rad]
    field: float = 0.5  #: F [field unit]
    dip: float = math.radians(-60.0)  #: [rad]
    noise: float = 0.002  #: white noise per axis [raw]
    acc_noise: float = 0.02  #: white noise of the accelerometer per axis [its unit]
    gravity: float = 1.0  #: the accelerometer's reading at rest [its unit]
    lag: float = 0.0  #: the magnetometer's delay [samples]

    def values(self) -> dict[str, float]:
        v = [*self.s, *self.b, *self.angles, *self.rotation, self.field, self.dip]
        return dict(zip(NAMES, map(float, v)))


@dataclass(frozen=True)
class MagSimulation:
    mag: np.ndarray  #: (N, 3) raw magnetometer readings
    acc: np.ndarray  #: (N, 3) calibrated accelerometer readings
    truth: MagTruth
    holds: Poses  #: the still holds (sample ranges)
    orientations: np.ndarray = field(repr=False)  #: (poses, 3, 3) body to world at each hold


def truth_from_soft_iron(M: np.ndarray, s=(0.2, -0.1, 0.05), field: float = 0.5, dip: float = math.radians(-60.0),
                         axes: tuple[int, ...] = IDENTITY, misalignment=(0.0, 0.0, 0.0), **kw) -> MagTruth:
    """The truth whose soft iron, in the magnetometer's own axes, is Q M: M the map from raw - s to the field
    (symmetric: the symmetric soft iron), Q the rotation by the Euler angles ``misalignment`` [rad].

    The paper's scales and angles come from H^-1 = (M^T M)^-1 = diag(b) G diag(b) (imucal.solve.initial),
    their lower-triangular map T from the model, and the model's rotation R = P Q M T^-1 P^T."""
    M = np.asarray(M, float)
    Hinv = np.linalg.inv(M.T @ M)
    b = np.sqrt(np.diag(Hinv))
    cosm = Hinv / np.outer(b, b)
    angles = tuple(float(v) for v in np.arccos([cosm[0, 1], cosm[0, 2], cosm[1, 2]]))
    model = build_mag_model()
    p = np.array(list(MagTruth(s=(0.0, 0.0, 0.0), b=tuple(b), angles=angles).values().values()))
    T = np.column_stack([np.asarray(model.functions["field"](e, p)).ravel() for e in np.eye(3)])
    Q = np.asarray(rotation(*misalignment))
    P = np.array(axes, float).reshape(3, 3)
    R = P @ Q @ M @ np.linalg.inv(T) @ P.T
    return MagTruth(s=tuple(s), b=tuple(map(float, b)), angles=angles, axes=axes, rotation=euler_angles(R),
                    field=field, dip=dip, **kw)


def _random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform rotations from uniform unit quaternions (Shoemake)."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return _quat_to_matrix(q)


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)


def _matrix_to_quat(C: np.ndarray) -> np.ndarray:
    w = np.sqrt(max(1e-12, 1 + np.trace(C))) / 2
    q = np.array([w, (C[2, 1] - C[1, 2]) / (4 * w), (C[0, 2] - C[2, 0]) / (4 * w), (C[1, 0] - C[0, 1]) / (4 * w)])
    if 1 + np.trace(C) < 1e-6:  # near 180 deg: the largest diagonal element's branch
        i = int(np.argmax(np.diag(C)))
        j, k = (i + 1) % 3, (i + 2) % 3
        v = np.sqrt(max(1e-12, 1 + C[i, i] - C[j, j] - C[k, k])) / 2
        q = np.empty(4)
        q[0], q[1 + i] = (C[k, j] - C[j, k]) / (4 * v), v
        q[1 + j], q[1 + k] = (C[j, i] + C[i, j]) / (4 * v), (C[k, i] + C[i, k]) / (4 * v)
    return q / np.linalg.norm(q)


def _slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    d = float(q0 @ q1)
    if d < 0:
        q1, d = -q1, -d
    th = math.acos(min(1.0, d))
    if th < 1e-9:
        return np.tile(q0, (len(u), 1))
    return (np.sin((1 - u) * th)[:, None] * q0 + np.sin(u * th)[:, None] * q1) / math.sin(th)


def _path(C: np.ndarray, hold: int, transition: int) -> tuple[np.ndarray, Poses]:
    """Body-to-world rotation of every sample, and the holds."""
    qs = [_matrix_to_quat(c) for c in C]
    parts, start, end, k = [], [], [], 0
    for i, q in enumerate(qs):
        parts.append(np.tile(q, (hold, 1)))
        start.append(k)
        end.append(k + hold)
        k += hold
        if i + 1 < len(qs) and transition:
            u = (np.arange(transition) + 1) / (transition + 1)
            u = 0.5 - 0.5 * np.cos(np.pi * u)  # smooth start and stop
            parts.append(_slerp(q, qs[i + 1], u))
            k += transition
    return _quat_to_matrix(np.vstack(parts)), Poses(np.array(start), np.array(end), "holds")


def simulate_mag(truth: MagTruth = MagTruth(), n_poses: int = 24, hold: int = 100, transition: int = 50,
                 seed: int = 0, disturbed: Mapping[int, float] | None = None,
                 orientations: np.ndarray | None = None) -> MagSimulation:
    """A log of ``n_poses`` random orientations (or the given ones), see the module docstring."""
    rng = np.random.default_rng(seed)
    C = _random_rotations(rng, n_poses) if orientations is None else np.asarray(orientations, float)
    Cs, holds = _path(C, hold, transition)
    g_w = np.array([0.0, 0.0, truth.gravity])
    h_w = truth.field * np.array([math.cos(truth.dip), 0.0, math.sin(truth.dip)])
    acc = np.einsum("kji,j->ki", Cs, g_w)
    scale = np.ones(len(Cs))
    for pose, f in (disturbed or {}).items():
        scale[holds.start[pose]:holds.end[pose]] = f
    h = np.einsum("kji,j->ki", Cs, h_w) * scale[:, None]
    h = shift(h, -truth.lag)  # late by lag: h'[k] = h(k - lag)
    model = build_mag_model(truth.axes)
    p = np.array(list(truth.values().values()), float)
    mag = np.asarray(vectorized(model, "forward")(h.T, p)[0]).T
    mag = mag + rng.normal(0.0, truth.noise, mag.shape)
    acc = acc + rng.normal(0.0, truth.acc_noise, acc.shape)
    return MagSimulation(mag, acc, truth, holds, C)
