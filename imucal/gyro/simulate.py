"""Synthetic gyro recordings with known truth: still poses joined by rotations.

``simulate`` joins the poses by given turns (an axis and an angle each); ``hand_held`` draws a
realistic hand-held session: turns of 60 to 180 deg about random axes, each with a tremor about
other axes and a translation of the hand, still poses of random length. The attitude follows the
body rate exactly (Rodrigues steps on a 16 times finer grid than the samples), so the only
mismatch with the fit's RK4 on the samples is its own discretisation, as with a real sensor.
The sensor is the model of ``imucal.gyro.model`` (raw = s_g + B_g (M_g omega + G_s a)) plus white
noise; the accelerometer channel is the specific force in the frame of omega plus white noise.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from imucal.gyro.model import misalignment_matrix
from imucal.gyro.segments import GyroData

#: sub-steps per sample of the attitude integration (a power of 2: multiplied pairwise)
SUBSTEPS = 16


@dataclass(frozen=True)
class GyroTruth:
    bias: np.ndarray  #: [raw]
    scale: np.ndarray  #: [raw per rad/s]
    mis: np.ndarray  #: six off-diagonal entries of M_g
    gsens: np.ndarray  #: (3, 3) [(rad/s) per (m/s^2)]
    noise: float = 0.0  #: white noise per sample [raw]


@dataclass(frozen=True)
class Motion:
    """One rotation between still poses: rate = axis angle (1 - cos 2 pi u) / T plus a tremor."""

    axis: np.ndarray  #: (3,) unit vector, body frame
    angle: float  #: [rad]
    duration: float  #: T [s]
    tremor: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  #: (k, 3) amplitude vectors [rad/s]
    tremor_hz: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: (k,) frequencies [Hz]
    tremor_phase: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: (k,) [rad]
    push: np.ndarray = field(default_factory=lambda: np.zeros(3))  #: hand's acceleration amplitude, world [m/s^2]

    def rate(self, u: np.ndarray) -> np.ndarray:
        """Body rate [rad/s] (m, 3) at normalised times u (m,) in [0, 1]; zero at both ends."""
        u = np.asarray(u, float)[:, None]
        w = self.axis * self.angle * (1 - np.cos(2 * np.pi * u)) / self.duration
        if self.tremor_hz.size:
            s = np.sin(np.pi * u) ** 2 * np.sin(2 * np.pi * self.tremor_hz * self.duration * u + self.tremor_phase)
            w = w + s @ self.tremor
        return w

    def accel(self, u: np.ndarray) -> np.ndarray:
        """Hand's linear acceleration [m/s^2, world] (m, 3): zero net velocity change."""
        return self.push * np.sin(2 * np.pi * np.asarray(u, float)[:, None])


def _exp(v: np.ndarray) -> np.ndarray:
    """Rotation matrices (m, 3, 3) of rotation vectors v (m, 3) (Rodrigues)."""
    a = np.linalg.norm(v, axis=1)[:, None, None]
    z = np.zeros(v.shape[0])
    K = np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                  np.stack([-v[:, 1], v[:, 0], z], 1)], 1)
    small = a < 1e-8
    s = np.where(small, 1.0, np.sin(a) / np.where(small, 1.0, a))
    c = np.where(small, 0.5, (1 - np.cos(a)) / np.where(small, 1.0, a) ** 2)
    return np.eye(3) + s * K + c * K @ K


def _steps(m: "Motion", n: int) -> np.ndarray:
    """Attitude increment (n, 3, 3) over each of the n sample intervals of a motion (product of sub-steps)."""
    u = (np.arange(n * SUBSTEPS) + 0.5) / (n * SUBSTEPS)
    D = _exp(m.rate(u) * m.duration / (n * SUBSTEPS)).reshape(n, SUBSTEPS, 3, 3)
    while D.shape[1] > 1:  # pairwise products in time order
        D = D[:, 0::2] @ D[:, 1::2]
    return D[:, 0]


def record(truth: GyroTruth, motions: list[Motion], stills: list[float], fs: float = 100.0, gravity: float = 9.81,
           seed: int = 0, acc_noise: float = 0.0, unit: str = "raw", R0: np.ndarray | None = None,
           still_turns: dict[int, float] | None = None) -> GyroData:
    """Still ``stills[0]`` s, motion 0, still ``stills[1]`` s, ...; ``len(stills) == len(motions) + 1``.

    ``still_turns`` {pose: rate [rad/s]}: during those still poses the sensor turns slowly about the
    vertical (a turntable, or a hand): the specific force stays the same, the gyro sees the rate."""
    rng = np.random.default_rng(seed)
    g_world = np.array([0, 0, gravity])  # specific force at rest points up
    R = np.eye(3) if R0 is None else np.asarray(R0, float)
    ws, accs, start, end = [], [], [], []
    k = 0
    for step, still in enumerate(stills):
        n = max(int(round(still * fs)), 2)
        start.append(k)
        w = (still_turns or {}).get(step, 0.0) * (R.T @ [0.0, 0.0, 1.0])  # about the vertical: constant in the body
        ws += [w] * n
        accs += [R.T @ g_world] * n
        R = R @ _exp((w * n / fs)[None])[0]  # the pose's n sample steps of the constant rate
        k += n
        end.append(k)
        if step == len(motions):
            break
        n = max(int(round(motions[step].duration * fs)), 2)
        m = replace(motions[step], duration=n / fs)  # on the sample grid
        u = np.arange(1, n + 1) / n
        f = g_world + m.accel(u)
        for i, D in enumerate(_steps(m, n)):
            R = R @ D
            accs.append(R.T @ f[i])
        ws += list(m.rate(u))
        k += n
    t = np.arange(k) / fs
    omega, acc = np.array(ws), np.array(accs)
    M = misalignment_matrix(np.asarray(truth.mis, float))
    raw = truth.bias + (omega @ M.T + acc @ truth.gsens.T) * truth.scale + truth.noise * rng.standard_normal((k, 3))
    acc = acc + acc_noise * rng.standard_normal((k, 3))
    return GyroData(t=t, gyro=raw, acc=acc, start=np.array(start), end=np.array(end), unit=unit, source="<simulated>")


def simulate(truth: GyroTruth, turns: list[tuple[int | np.ndarray, float]], fs: float = 100.0, still: float = 2.0,
             move: float = 1.0, gravity: float = 9.81, seed: int = 0, acc_noise: float = 0.0,
             unit: str = "raw", still_turns: dict[int, float] | None = None) -> GyroData:
    """Still ``still`` s, then each (axis, angle [rad]) turn over ``move`` s, still again.

    An axis is a body axis number (0, 1, 2) or a vector."""
    motions = []
    for axis, angle in turns:
        v = np.eye(3)[axis] if np.ndim(axis) == 0 else np.asarray(axis, float) / np.linalg.norm(axis)
        motions.append(Motion(v, float(angle), move))
    return record(truth, motions, [still] * (len(turns) + 1), fs, gravity, seed, acc_noise, unit,
                  still_turns=still_turns)


def hand_held(truth: GyroTruth, n_poses: int = 24, seed: int = 0, fs: float = 100.0, gravity: float = 9.81,
              acc_noise: float = 0.02, unit: str = "raw", tremor: float = 0.15, push: float = 1.0,
              durations: tuple[float, float] | None = (1.0, 2.0), still: tuple[float, float] = (1.5, 3.0),
              still_turns: dict[int, float] | None = None) -> GyroData:
    """A hand-held session of ``n_poses`` still poses: turns of 60-180 deg about random axes.

    Each turn carries a tremor of three sinusoids (0.5 to 3 Hz, ``tremor`` [rad/s] rms amplitude
    per component, about random axes) and a hand translation of ``push`` [m/s^2]; the start
    attitude is random. ``durations`` (min, max) [s] of the turns, None for 1.5 s each (then
    recordings of every seed have the same shape, so the fit reuses its solver).
    """
    rng = np.random.default_rng(seed)
    motions = []
    for _ in range(n_poses - 1):
        axis = rng.normal(size=3)
        T = 1.5 if durations is None else float(rng.uniform(*durations))
        motions.append(Motion(axis / np.linalg.norm(axis), float(np.radians(rng.uniform(60, 180)) * rng.choice([-1, 1])),
                              T, tremor * rng.normal(size=(3, 3)), rng.uniform(0.5, 3.0, 3),
                              rng.uniform(0, 2 * np.pi, 3), push * rng.normal(size=3)))
    stills = [2.0] * n_poses if durations is None else list(rng.uniform(*still, n_poses))
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    R0 = _exp((2 * np.arccos(np.clip(q[0], -1, 1)) * q[1:] / max(np.linalg.norm(q[1:]), 1e-12))[None])[0]
    return record(truth, motions, stills, fs, gravity, int(rng.integers(2**31)), acc_noise, unit, R0, still_turns)
