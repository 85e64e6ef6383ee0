"""Simulated recordings with known truth: the same code serves tests, studies and `imucal simulate`.

Forward model (paper, Section 2): the true specific force a (orthonormal frame f of the
Theorem) is projected on the unit axes, m = E^T a (Lemma 1: m_i = e_i . a), then
raw = s + b * m (Eq. theModel), plus white noise and quantisation to counts.
A pose plan holds the sensor still in a list of gravity directions, with smooth transitions
that carry extra motion and vibration so that static detection is exercised.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .constants import RIGHT_ANGLE, STANDARD_GRAVITY
from .errors import ImucalError


def frame_matrix(angles: np.ndarray) -> np.ndarray:
    """E (columns e_i in frame f), Eq. (eq:125), numerically."""
    phi, psi, th = angles
    cphi, cpsi, cth = np.cos([phi, psi, th])
    sphi = np.sin(phi)
    cxi = (cth - cphi * cpsi) / sphi
    det = 1 - cphi**2 - cpsi**2 - cth**2 + 2 * cphi * cpsi * cth
    if not det > 0:
        raise ImucalError("the angles give no valid frame (Gram determinant <= 0)", field="sensor.angles")
    ceta = np.sqrt(det) / sphi
    return np.array([[1, cphi, cpsi], [0, sphi, cxi], [0, 0, ceta]])


@dataclass(frozen=True)
class SensorSpec:
    """A simulated sensor: the paper's nine parameters plus noise and quantisation."""

    s: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: shifts [raw]
    b: tuple[float, float, float] = (1.0, 1.0, 1.0)  #: scales [raw per m/s^2]
    angles: tuple[float, float, float] = (RIGHT_ANGLE,) * 3  #: phi, psi, theta [rad]
    noise: tuple[float, float, float] = (0.01, 0.01, 0.01)  #: white noise std [raw]
    quantum: float = 0.0  #: quantisation step [raw]; 0 = none
    unit: str = "m/s^2"
    #: extra model terms: effect name -> {parameter name: value}; see imucal.effects
    effects: dict = field(default_factory=dict)

    def values(self) -> dict[str, float]:
        v = {f"s{i+1}": float(self.s[i]) for i in range(3)}
        v.update({f"b{i+1}": float(self.b[i]) for i in range(3)})
        v.update(dict(zip(("phi", "psi", "theta"), map(float, self.angles))))
        for coeffs in self.effects.values():
            v.update({k: float(x) for k, x in coeffs.items()})
        return v

    def forward(self, m: np.ndarray, t: np.ndarray, temp: np.ndarray | None) -> np.ndarray:
        """raw from measured values m (N x 3), noise-free. Effects add their terms."""
        raw = np.asarray(self.s) + np.asarray(self.b) * m
        if self.effects:
            from .effects import simulate_effects

            raw = simulate_effects(self, m, t, temp, raw)
        return raw


def mems_counts_sensor(rng: np.random.Generator, lsb_per_g: float = 16384.0, noise_counts: float = 4.0,
                       bias_counts: float = 300.0, scale_err: float = 0.02, angle_err: float = 0.01
                       ) -> SensorSpec:
    """A random raw-count MEMS sensor (e.g. MPU-6050 +-2 g: 16384 LSB/g)."""
    b = lsb_per_g / STANDARD_GRAVITY * (1 + scale_err * rng.uniform(-1, 1, 3))
    return SensorSpec(s=tuple(rng.uniform(-bias_counts, bias_counts, 3)), b=tuple(b),
                      angles=tuple(RIGHT_ANGLE * (1 + angle_err * rng.uniform(-1, 1, 3))),
                      noise=(noise_counts,) * 3, quantum=1.0, unit="raw")


def si_sensor(rng: np.random.Generator, noise: float = 0.01, bias: float = 0.2, scale_err: float = 0.02,
              angle_err: float = 0.01) -> SensorSpec:
    """A random factory-scaled sensor reporting m/s^2."""
    return SensorSpec(s=tuple(rng.uniform(-bias, bias, 3)), b=tuple(1 + scale_err * rng.uniform(-1, 1, 3)),
                      angles=tuple(RIGHT_ANGLE * (1 + angle_err * rng.uniform(-1, 1, 3))),
                      noise=(noise,) * 3, quantum=0.0, unit="m/s^2")


# --- pose plans -----------------------------------------------------------------------------
def cube_directions(kind: str = "faces+edges+corners") -> np.ndarray:
    """Unit vectors of the 6 faces, 12 edges and/or 8 corners of a cube."""
    out = []
    kinds = kind.split("+")
    for v in np.array(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1])).reshape(3, -1).T:
        nz = int(np.count_nonzero(v))
        if (nz == 1 and "faces" in kinds) or (nz == 2 and "edges" in kinds) or (nz == 3 and "corners" in kinds):
            out.append(v / np.linalg.norm(v))
    return np.array(out, float)


def random_directions(n: int, rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@dataclass(frozen=True)
class PosePlan:
    """Still holds in given gravity directions (frame f), joined by smooth moving transitions."""

    directions: np.ndarray  #: (n, 3) unit vectors
    hold: float = 4.0  #: seconds still per pose
    transition: float = 2.0  #: seconds of motion between poses
    initial_hold: float = 0.0  #: extra still time at the start [s]
    vibration: float = 1.0  #: std of extra acceleration during transitions [m/s^2]
    rate: float = 100.0  #: sample rate [Hz]

    def __post_init__(self) -> None:
        d = np.asarray(self.directions, float)
        if d.ndim != 2 or d.shape[1] != 3 or d.shape[0] < 1:
            raise ImucalError("directions must be an (n, 3) array", field="plan.directions")
        if self.hold <= 0 or self.transition <= 0 or self.rate <= 0:
            raise ImucalError("hold, transition and rate must be positive", field="plan")


@dataclass(frozen=True)
class Simulation:
    t: np.ndarray  #: [s]
    raw: np.ndarray  #: (N, 3) [raw]
    temp: np.ndarray | None  #: [deg C]
    accel: np.ndarray  #: (N, 3) true specific force in frame f [m/s^2]
    still: np.ndarray  #: (N,) bool, true holds
    sensor: SensorSpec
    gravity: float
    hold_bounds: np.ndarray  #: (n, 2) sample index ranges of the holds

    def to_csv_text(self) -> str:
        import io

        cols = [self.t, *self.raw.T] + ([self.temp] if self.temp is not None else [])
        head = "t,ax,ay,az" + (",temp" if self.temp is not None else "")
        buf = io.StringIO()
        buf.write(head + "\n")
        fmt = ["%.6f"] + (["%.0f"] * 3 if self.sensor.quantum == 1.0 else ["%.9g"] * 3)
        fmt += ["%.4f"] if self.temp is not None else []
        np.savetxt(buf, np.column_stack(cols), delimiter=",", fmt=fmt)
        return buf.getvalue()


def _slerp(u: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    cosang = np.clip(u @ v, -1, 1)
    ang = np.arccos(cosang)
    if ang < 1e-9:
        return np.repeat(u[None], w.size, axis=0)
    if np.pi - ang < 1e-6:  # antipodal: go through any perpendicular direction
        perp = np.cross(u, [1, 0, 0] if abs(u[0]) < 0.9 else [0, 1, 0])
        perp /= np.linalg.norm(perp)
        half = np.minimum(w * 2, 1)[:, None], np.maximum(w * 2 - 1, 0)[:, None]
        a = _slerp(u, perp, half[0].ravel())
        b = _slerp(perp, v, half[1].ravel())
        return np.where((w < 0.5)[:, None], a, b)
    s = np.sin(ang)
    return (np.sin((1 - w) * ang)[:, None] * u + np.sin(w * ang)[:, None] * v) / s


def simulate(sensor: SensorSpec, plan: PosePlan, gravity: float = STANDARD_GRAVITY, seed: int = 0,
             temperature: "TemperatureProfile | None" = None) -> Simulation:
    """Simulate a multi-pose recording; reproducible for a given seed."""
    rng = np.random.default_rng(seed)
    dirs = np.asarray(plan.directions, float)
    dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    nh, nt = int(round(plan.hold * plan.rate)), int(round(plan.transition * plan.rate))
    n0 = int(round(plan.initial_hold * plan.rate))
    acc, still, bounds = [], [], []
    pos = 0
    for k, d in enumerate(dirs):
        h = nh + (n0 if k == 0 else 0)
        acc.append(np.repeat(d[None] * gravity, h, axis=0))
        still.append(np.ones(h, bool))
        bounds.append((pos, pos + h))
        pos += h
        if k + 1 < len(dirs):
            w = 0.5 - 0.5 * np.cos(np.linspace(0, np.pi, nt))  # smooth rotation profile
            path = _slerp(d, dirs[k + 1], w) * gravity
            bump = np.sin(np.linspace(0, np.pi, nt))[:, None]
            motion = bump * (rng.normal(0, plan.vibration, (nt, 3)) + rng.normal(0, 2 * plan.vibration, 3))
            acc.append(path + motion)
            still.append(np.zeros(nt, bool))
            pos += nt
    a = np.vstack(acc)
    n = a.shape[0]
    t = np.arange(n) / plan.rate
    temp = temperature.sample(t, rng) if temperature is not None else None
    E = frame_matrix(np.asarray(sensor.angles))
    m = a @ E  # m_i = e_i . a (Lemma 1), E's columns are e_i
    raw = sensor.forward(m, t, temp) + rng.normal(0, 1, (n, 3)) * np.asarray(sensor.noise)
    if sensor.quantum > 0:
        raw = np.round(raw / sensor.quantum) * sensor.quantum
    return Simulation(t=t, raw=raw, temp=temp, accel=a, still=np.concatenate(still), sensor=sensor,
                      gravity=gravity, hold_bounds=np.array(bounds))


@dataclass(frozen=True)
class TemperatureProfile:
    """Warm-up towards a plateau plus a slow non-monotonic swing and a little noise [deg C]."""

    start: float = 20.0
    plateau: float = 35.0
    tau: float = 60.0  #: warm-up time constant [s]
    swing: float = 3.0  #: amplitude of the slow swing [deg C]
    period: float = 300.0  #: period of the swing [s]
    noise: float = 0.02

    def sample(self, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        warm = self.plateau + (self.start - self.plateau) * np.exp(-t / self.tau)
        return warm + self.swing * np.sin(2 * np.pi * t / self.period) + rng.normal(0, self.noise, t.size)
