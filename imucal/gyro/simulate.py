"""Synthetic gyro recordings with known truth: still poses joined by single-axis turns."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.gyro.model import misalignment_matrix
from imucal.gyro.segments import GyroData


@dataclass(frozen=True)
class GyroTruth:
    bias: np.ndarray  #: [raw]
    scale: np.ndarray  #: [raw per rad/s]
    mis: np.ndarray  #: six off-diagonal entries of M_g
    gsens: np.ndarray  #: (3, 3) [(rad/s) per (m/s^2)]
    noise: float = 0.0  #: white noise per sample [raw]


def _rot(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def simulate(truth: GyroTruth, turns: list[tuple[int, float]], fs: float = 100.0, still: float = 2.0,
             move: float = 1.0, gravity: float = 9.81, seed: int = 0) -> GyroData:
    """Still ``still`` s, then each (axis, angle [rad]) turn over ``move`` s (smooth profile), still again."""
    rng = np.random.default_rng(seed)
    g_world = np.array([0, 0, gravity])
    R = np.eye(3)
    ts, ws, accs, start, end = [], [], [], [], []
    n_still, n_move = int(still * fs), int(move * fs)
    k = 0
    for step in range(len(turns) + 1):
        start.append(k)
        for _ in range(n_still):
            ws.append(np.zeros(3))
            accs.append(R.T @ g_world)
            k += 1
        end.append(k)
        if step == len(turns):
            break
        axis, ang = turns[step]
        R0 = R
        for i in range(1, n_move + 1):
            u = i / n_move
            theta = ang * (u - np.sin(2 * np.pi * u) / (2 * np.pi))
            rate = ang * (1 - np.cos(2 * np.pi * u)) / move
            R = R0 @ _rot(axis, theta)
            w = np.zeros(3)
            w[axis] = rate
            ws.append(w)
            accs.append(R.T @ g_world)
            k += 1
    t = np.arange(k) / fs
    omega, acc = np.array(ws), np.array(accs)
    M = misalignment_matrix(np.asarray(truth.mis, float))
    raw = truth.bias + (omega @ M.T + acc @ truth.gsens.T) * truth.scale + truth.noise * rng.standard_normal((k, 3))
    return GyroData(t=t, gyro=raw, acc=acc, start=np.array(start), end=np.array(end), unit="raw", source="<simulated>")
