"""Simulated recordings with known truth: the same code serves tests, studies and `imucal simulate`.

Forward model (paper, Section 2): the true specific force a (orthonormal frame f of the
Theorem) is projected on the unit axes, m = E^T a (Lemma 1: m_i = e_i . a), then
raw = s + b * m (Eq. theModel), plus white noise and quantisation to counts.
A pose plan holds the sensor still in a list of gravity directions, with smooth transitions
that carry extra motion and vibration so that static detection is exercised.
"""
from __future__ import annotations

import io
import itertools
from dataclasses import dataclass, field, replace
from typing import Literal, Mapping, Union

import numpy as np

from imucal.calibration.fields import check_raw_unit
from imucal.constants import RIGHT_ANGLE, STANDARD_GRAVITY
from imucal.errors import ImucalError, short
from imucal.data.recording import MAX_ABS_VALUE
from imucal.model.sensor import frame_np, gram_det_np
from imucal.config.limits import MAX_SIM_POSES, MAX_SIM_SAMPLES, check_seed
from imucal.files.schema import fill, rule
from imucal.files.yamlio import check_structure, read_yaml
from imucal.model.channels import temperature_rate
from imucal.model.effects import (CLASSIC, EFFECTS, STEP_MIN_SIDE, Term, effects_from_coefficients, make_effect,
                                  simulate_effects)


def frame_matrix(angles: np.ndarray) -> np.ndarray:
    """E (columns e_i in frame f), Eq. (eq:125), evaluated from the CasADi model (imucal.model.sensor)."""
    if not gram_det_np(angles) > 0:
        raise ImucalError("the angles give no valid frame (Gram determinant <= 0)", field="sensor.angles",
                          fix="give angles in (0, pi) rad near pi/2 (1.5708), the axes of a real sensor")
    return frame_np(angles)


@dataclass(frozen=True)
class SensorSpec:
    """A simulated sensor: the paper's nine parameters plus noise and quantisation."""

    s: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: shifts [raw]
    b: tuple[float, float, float] = (1.0, 1.0, 1.0)  #: scales [raw per m/s^2]
    angles: tuple[float, float, float] = (RIGHT_ANGLE,) * 3  #: phi, psi, theta [rad]
    noise: tuple[float, float, float] = (0.01, 0.01, 0.01)  #: white noise std [raw]
    quantum: float = 0.0  #: quantisation step [raw]; 0 = none
    unit: str = "m/s^2"
    #: extra model terms: effect name -> {parameter name: value}; see imucal.model.effects
    effects: dict = field(default_factory=dict)
    #: bias random walk density per axis [raw / sqrt(s)]: b_i(t) = q_i W_i(t), W a Wiener process
    random_walk: tuple[float, float, float] = (0.0, 0.0, 0.0)
    #: std of a random bias offset drawn per hold, per axis [raw] (bias_instability: one draw per visit)
    visit_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def values(self) -> dict[str, float]:
        v = {f"s{i+1}": float(self.s[i]) for i in range(3)}
        v.update({f"b{i+1}": float(self.b[i]) for i in range(3)})
        v.update(dict(zip(("phi", "psi", "theta"), map(float, self.angles))))
        for coeffs in self.effects.values():
            v.update({k: float(x) for k, x in coeffs.items()})
        return v

    def forward(self, a: np.ndarray, t: np.ndarray, temp: np.ndarray | None) -> np.ndarray:
        """raw from the true specific force a (N x 3, frame f), noise-free: m = E^T a (Lemma 1),
        raw = s + b m (Eq. theModel); effects add their terms (and may turn the axes)."""
        if self.effects:
            return simulate_effects(self, a, t, temp)
        return np.asarray(self.s) + np.asarray(self.b) * (a @ frame_matrix(np.asarray(self.angles)))


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
            raise ImucalError("directions must be an (n, 3) array", field="plan.directions",
                              fix="give one [x, y, z] direction per pose")
        vals = (self.hold, self.transition, self.rate, self.initial_hold)
        if not all(np.isfinite(vals)) or self.hold <= 0 or self.transition <= 0 or self.rate <= 0 \
                or self.initial_hold < 0:
            raise ImucalError("hold, transition and rate must be positive and finite", field="plan",
                              fix="give hold and transition in seconds and rate in Hz, each above 0 "
                                  "(initial_hold 0 or more)")
        if not 1.0 <= self.rate <= 1.0e5:
            raise ImucalError(f"rate {short(self.rate)} Hz is not an IMU sample rate", field="plan.rate",
                              fix="give 1 to 100000 Hz")
        n = (d.shape[0] * (self.hold + self.transition) + self.initial_hold) * self.rate
        if n > MAX_SIM_SAMPLES:
            raise ImucalError(f"the plan makes {n:.3g} samples, above the limit of {MAX_SIM_SAMPLES:g}",
                              field="plan", fix="shorten the holds or lower the rate")


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
    rng = np.random.default_rng(check_seed(seed))
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
    frame_matrix(np.asarray(sensor.angles))  # (refuses angles with no valid frame)
    raw = sensor.forward(a, t, temp) + rng.normal(0, 1, (n, 3)) * np.asarray(sensor.noise)
    raw = raw + _stochastic_bias(sensor, t, np.array(bounds), rng)
    if sensor.quantum > 0:
        raw = np.round(raw / sensor.quantum) * sensor.quantum
    return Simulation(t=t, raw=raw, temp=temp, accel=a, still=np.concatenate(still), sensor=sensor,
                      gravity=gravity, hold_bounds=np.array(bounds))


def _stochastic_bias(sensor: SensorSpec, t: np.ndarray, bounds: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The stochastic bias [raw], (N, 3): a random walk q_i W_i(t) (increments N(0, q_i^2 dt), W(0) = 0)
    plus one offset per hold, held from the hold's start to the next hold's. Draws nothing when both
    are zero, so recordings without them are unchanged (byte-identical CSV)."""
    out = np.zeros((t.size, 3))
    q, v = np.asarray(sensor.random_walk, float), np.asarray(sensor.visit_offset, float)
    if np.any(q > 0):
        dt = np.diff(t, prepend=t[0])
        out += np.cumsum(rng.normal(0, 1, (t.size, 3)) * np.sqrt(dt)[:, None], axis=0) * q
    if np.any(v > 0):
        hold = np.searchsorted(bounds[:, 0], np.arange(t.size), side="right") - 1
        out += (rng.normal(0, 1, (len(bounds), 3)) * v)[np.maximum(hold, 0)]
    return out


@dataclass(frozen=True)
class TemperatureProfile:
    """Warm-up towards a plateau plus a slow non-monotonic swing and a little noise [deg C]."""

    start: float = 20.0
    plateau: float = 35.0
    tau: float = field(default=60.0, metadata=rule(gt=0, unit="seconds"))  #: warm-up time constant [s]
    swing: float = 3.0  #: amplitude of the slow swing [deg C]
    period: float = field(default=300.0, metadata=rule(gt=0, unit="seconds"))  #: period of the swing [s]
    noise: float = field(default=0.02, metadata=rule(ge=0, unit="degC"))

    def sample(self, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        warm = self.plateau + (self.start - self.plateau) * np.exp(-t / self.tau)
        return warm + self.swing * np.sin(2 * np.pi * t / self.period) + rng.normal(0, self.noise, t.size)


# --- configuration (YAML -> typed dataclasses) and fitted-sensor replay ---------------------
#: Named direction sets for ``plan.directions`` in a simulation config.
DIRECTION_SETS = ("faces", "edges", "corners", "faces+edges", "faces+corners", "edges+corners",
                  "faces+edges+corners", "random")
SENSOR_PRESETS = ("mems_counts", "si", "none")


@dataclass(frozen=True)
class SimulationConfig:
    """Everything one simulated recording needs; ``simulation_from_dict`` fills it from YAML."""

    sensor: SensorSpec
    plan: PosePlan
    temperature: "TemperatureProfile | None" = None  #: None: the recording has no temp column
    gravity: float = STANDARD_GRAVITY  #: [m/s^2]
    seed: int = 0
    source: str | None = None  #: the YAML file, for messages

    def run(self) -> Simulation:
        """The recording; refused when its readings leave what imucal reads back (finite, within
        +-MAX_ABS_VALUE): a simulation file with absurd sizes wrote -inf or 1e300 columns."""
        with np.errstate(all="ignore"):
            sim = simulate(self.sensor, self.plan, gravity=self.gravity, seed=self.seed,
                           temperature=self.temperature)
        peak = float(np.max(np.abs(sim.raw))) if sim.raw.size else 0.0
        if not peak <= MAX_ABS_VALUE:  # (NaN fails too)
            raise ImucalError(f"the simulated readings reach {peak:.3g}, beyond the +-{MAX_ABS_VALUE:g} imucal reads",
                              file=self.source, field="sensor",
                              fix="give the sensor sizes a sensor has (effects, random_walk, visit_offset, noise, s, b)")
        return sim


#: Three numbers, or one for all three axes.
Vec3 = Union[float, tuple[float, float, float], None]
_VEC3 = rule(msg="{value} must be three finite numbers (or one for all axes)")


@dataclass(frozen=True)
class SensorSection:
    """``sensor:`` of a simulation file: a preset drawn from the seed, explicit values override it."""

    preset: Literal["mems_counts", "si", "none"] = field(default="mems_counts", metadata=rule(
        msg="unknown preset {value}", fix=f"use one of {', '.join(SENSOR_PRESETS)}"))
    s: Vec3 = field(default=None, metadata=_VEC3)
    b: Vec3 = field(default=None, metadata=_VEC3)
    angles_deg: Vec3 = field(default=None, metadata=_VEC3)
    noise: Vec3 = field(default=None, metadata=_VEC3)
    #: a bias random walk [raw / sqrt(s)] and one random bias offset per visit of a pose [raw] (stochastic effects)
    random_walk: Vec3 = field(default=None, metadata=_VEC3)
    visit_offset: Vec3 = field(default=None, metadata=_VEC3)
    quantum: float | None = field(default=None, metadata=rule(ge=0))
    unit: str | None = field(default=None, metadata=rule(min_len=1, max_len=20, msg="unit {value} must be a short name",
                                                         fix="e.g. unit: raw or unit: m/s^2"))
    effects: Mapping[str, Mapping[str, float]] = field(default_factory=dict, metadata=rule(
        fix="e.g. effects: {bias_temperature: {bias_temperature_x: 2.0}}"))

    def __post_init__(self) -> None:
        if self.b is not None and not all(x > 0 for x in _three(self.b)):
            raise ImucalError("scales must be positive", field="sensor.b",
                              fix="give each scale b as a positive number of raw units per m/s^2")
        if self.noise is not None and not all(x >= 0 for x in _three(self.noise)):
            raise ImucalError("noise must be non-negative", field="sensor.noise",
                              fix="give the noise standard deviation in raw units, 0 or more")
        for key, unit in (("random_walk", "raw / sqrt(s)"), ("visit_offset", "raw")):
            v = getattr(self, key)
            if v is not None and not all(x >= 0 for x in _three(v)):
                raise ImucalError(f"{key} must be non-negative [{unit}]", field=f"sensor.{key}",
                                  fix=f"give {key} as 0 or more [{unit}], one number or one per axis")
        if self.unit is not None:  # the rule calibrate and the calibration file apply: the readings calibrate
            check_raw_unit(self.unit, "sensor.unit", fix="e.g. unit: raw or unit: m/s^2")


@dataclass(frozen=True)
class PlanSection:
    """``plan:`` of a simulation file: a named direction set or a list of [x, y, z], plus random ones."""

    directions: str | tuple[tuple[float, float, float], ...] = field(default="faces+edges", metadata=rule(
        max_len=MAX_SIM_POSES, msg=f"directions must be a set name or a list of at most {MAX_SIM_POSES} [x, y, z]",
        fix=f"use one of {', '.join(DIRECTION_SETS)} or a list of [x, y, z]"))
    n_random: int = field(default=0, metadata=rule(ge=0, le=MAX_SIM_POSES, fix="a calibration needs tens of poses"))
    hold: float | None = field(default=None, metadata=rule(ge=0, unit="seconds"))
    transition: float | None = field(default=None, metadata=rule(ge=0, unit="seconds"))
    initial_hold: float | None = field(default=None, metadata=rule(ge=0, unit="seconds"))
    vibration: float | None = field(default=None, metadata=rule(ge=0, unit="m/s^2"))
    rate: float | None = field(default=None, metadata=rule(ge=0, unit="Hz"))

    def __post_init__(self) -> None:
        if isinstance(self.directions, str) and self.directions not in DIRECTION_SETS:
            raise ImucalError(f"unknown direction set {short(self.directions)}", field="plan.directions",
                              fix=f"use one of {', '.join(DIRECTION_SETS)} or a list of [x, y, z]")


@dataclass(frozen=True)
class SimulationFile:
    """A simulation YAML as written (configs/simulate_example.yaml); ``simulation_from_dict`` builds it."""

    seed: int = 0
    gravity: float = field(default=STANDARD_GRAVITY, metadata=rule(gt=0, unit="m/s^2"))
    sensor: SensorSection = SensorSection()
    plan: PlanSection = PlanSection()
    temperature: TemperatureProfile | None = None  #: omit or null: no temp column


def _three(v: float | tuple[float, ...]) -> tuple[float, float, float]:
    return (float(v),) * 3 if isinstance(v, (int, float)) else tuple(float(x) for x in v)  # type: ignore[return-value]


def _sensor(sd: SensorSection, rng: np.random.Generator) -> SensorSpec:
    base = {"mems_counts": lambda: mems_counts_sensor(rng), "si": lambda: si_sensor(rng),
            "none": SensorSpec}[sd.preset]()
    kw: dict = {k: _three(getattr(sd, k)) for k in ("s", "b", "noise", "random_walk", "visit_offset")
                if getattr(sd, k) is not None}
    if sd.angles_deg is not None:
        kw["angles"] = tuple(np.radians(_three(sd.angles_deg)))
    kw.update({k: getattr(sd, k) for k in ("quantum", "unit") if getattr(sd, k) is not None})
    kw["effects"] = {str(n): {str(k): float(v) for k, v in c.items()} for n, c in sd.effects.items()}
    sensor = replace(base, **kw)
    frame_matrix(np.asarray(sensor.angles))
    if sensor.effects:
        effects_from_coefficients(sensor.effects)
    return sensor


def _plan(pd: PlanSection, rng: np.random.Generator) -> PosePlan:
    if isinstance(pd.directions, str):
        parts = [] if pd.directions == "random" else [cube_directions(pd.directions)]
    else:
        arr = np.asarray(pd.directions, float)
        largest = np.max(np.abs(arr), axis=1, keepdims=True) if arr.size else np.zeros((0, 1))
        if arr.size == 0 or np.any(largest == 0):
            raise ImucalError("directions must be a set name or a list of non-zero [x, y, z]",
                              field="plan.directions", fix="name a set (e.g. faces+edges+corners) or list [x, y, z] "
                                                            "directions with at least one non-zero entry each")
        arr = arr / largest  # scaled first: the norm of [1e308, 1e308, 0] overflows
        parts = [arr / np.linalg.norm(arr, axis=1, keepdims=True)]
    if pd.n_random:
        parts.append(random_directions(pd.n_random, rng))
    if not parts:
        raise ImucalError("no directions: 'random' needs n_random > 0", field="plan.n_random",
                          fix="give n_random, the number of random directions, above 0")
    order = np.vstack(parts)
    order = order[rng.permutation(len(order))]  # poses in a shuffled order, as a person would
    pkw = {k: float(getattr(pd, k)) for k in ("hold", "transition", "initial_hold", "vibration", "rate")
           if getattr(pd, k) is not None}
    return PosePlan(order, **pkw)


def simulation_from_dict(d: object, path: str | None = None) -> SimulationConfig:
    """Typed simulation config from a YAML mapping (imucal.files.schema: unknown keys are an error
    naming the allowed ones). Top level: ``seed``, ``gravity`` [m/s^2], ``sensor``, ``plan``,
    ``temperature`` (omit or null for a recording without a temp column). See
    configs/simulate_example.yaml.
    """
    check_structure(d, path, paths=True)
    f = fill(SimulationFile, d, path)
    try:
        seed = check_seed(f.seed, "seed")
        rng = np.random.default_rng(seed)
        sensor, plan = _sensor(f.sensor, rng), _plan(f.plan, rng)
        if sensor.effects and f.temperature is None and any(
                "temp" in e.covariates for e in effects_from_coefficients(sensor.effects)):
            raise ImucalError("the sensor has a temperature effect but there is no temperature: section",
                              field="temperature", fix="add temperature: {start: 20, plateau: 35}")
    except ImucalError as exc:
        raise ImucalError(exc.message, file=path, field=exc.field, fix=exc.fix) from None
    return SimulationConfig(sensor=sensor, plan=plan, temperature=f.temperature, gravity=float(f.gravity),
                            seed=seed, source=path)


def load_simulation_config(path: str) -> SimulationConfig:
    """Read a simulation YAML (``yaml.safe_load``) into a SimulationConfig."""
    d = read_yaml(path, "config", "pass a simulation YAML (see configs/simulate_example.yaml)")
    return simulation_from_dict(d, str(path))


def sensor_from_values(values: dict, effects: tuple = (), noise: tuple[float, float, float] = (0.0, 0.0, 0.0),
                       unit: str = "raw") -> SensorSpec:
    """A SensorSpec from fitted parameter values (e.g. ``Calibration.params.value_dict()``).

    ``effects`` are the model's effect objects; their coefficients (and fixed references) are
    taken from ``values``. Used to replay what a recording should look like under a fitted model.
    """
    eff: dict[str, dict[str, float]] = {}
    for e in effects:
        names = [*e.coefficient_names, *e.reference_names, *e.shape_names]
        eff[e.name] = {n: float(values[n]) for n in names}
    return SensorSpec(s=tuple(float(values[f"s{i}"]) for i in (1, 2, 3)),
                      b=tuple(float(values[f"b{i}"]) for i in (1, 2, 3)),
                      angles=tuple(float(values[a]) for a in ("phi", "psi", "theta")),
                      noise=tuple(noise), quantum=0.0, unit=unit, effects=eff)


# --- seeded cases with one hidden effect (tests and studies/discover_study.py) ---------------
@dataclass(frozen=True)
class EffectCase:
    """A simulated recording with at most one hidden effect, drawn from a seed."""

    seed: int
    effect: str | None  #: None: a clean sensor
    axes: tuple[int, ...]
    size: float  #: largest change of a reading at 1 g over the recording [m/s^2]
    sigma_mean: float  #: noise of one interval mean [m/s^2], for the signal-to-noise ratio
    config: SimulationConfig

    @property
    def snr(self) -> float:
        return self.size / self.sigma_mean if self.sigma_mean > 0 else float("inf")

    @property
    def label(self) -> str:
        if self.effect is None:
            return "clean"
        return f"{self.effect}[{EFFECTS[self.effect].axis_label(self.axes)}]"


def _axis_subsets() -> list[tuple[int, ...]]:
    return [c for r in (1, 2, 3) for c in itertools.combinations(range(3), r)]


def draw_effect_case(seed: int, effect: str | None = "random", axes: tuple[int, ...] | None = None,
                     snr: float | tuple[float, float] = (15.0, 60.0), noise_mg: float | None = None,
                     counts: bool | None = None, with_temperature: bool = True,
                     candidates: tuple[str, ...] | None = None, revisit: bool = False,
                     step_anywhere: bool = False, hold: float = 3.0, rate: float = 100.0) -> EffectCase:
    """Draw sensor, pose plan, temperature profile and (unless ``effect`` is None) one effect.

    ``effect``: "random" (drawn from ``candidates``, default the five classic effects), a name from
    imucal.model.effects.EFFECTS, or None for a clean sensor. A term's basis constants are those of
    the planned hold centres (what discovery computes from the interval means), a warm-up's tau is
    drawn in 5-30 % of the recording's length.
    ``snr``: effect size in units of the noise of one interval mean (a number or a log-uniform
    range). ``noise_mg``: white noise per sample [mg]; default drawn in 0.1 .. 1 mg.
    ``counts``: raw counts with quantisation (True) or factory-scaled m/s^2 (False); default random.
    18 to 26 poses of ``hold`` s at ``rate`` Hz (default 3 s at 100 Hz: a case simulates in milliseconds and fits
    in well under a second; other designs show how far the results carry to other recordings).
    ``revisit``: every pose held twice, the second pass in reverse order (36 to 52 holds; the other
    draws unchanged): a plan that sees time and temperature terms on every axis early and late.
    ``step_anywhere``: a bias step's time drawn uniformly over the holds and the moves between them
    (within a hold the sensor's bias jumps while it is still; by default it jumps while it is moved).
    """

    rng = np.random.default_rng([seed, 20240611])
    counts = bool(rng.integers(2)) if counts is None else counts
    noise_mg = float(np.exp(rng.uniform(np.log(0.1), np.log(1.0)))) if noise_mg is None else float(noise_mg)
    g = STANDARD_GRAVITY
    if counts:
        lsb_per_g = float(rng.choice([4096.0, 8192.0, 16384.0]))
        sensor = mems_counts_sensor(rng, lsb_per_g=lsb_per_g, noise_counts=noise_mg * 1e-3 * lsb_per_g)
    else:
        sensor = si_sensor(rng, noise=noise_mg * 1e-3 * g)
    kind = ["faces+edges", "faces+corners", "faces+edges+corners"][int(rng.integers(3))]
    dirs = cube_directions(kind)
    n_extra = {"faces+edges": int(rng.integers(0, 9)), "faces+corners": int(rng.integers(4, 9)),
               "faces+edges+corners": 0}[kind]  # 18 to 26 poses
    if n_extra:
        dirs = np.vstack([dirs, random_directions(n_extra, rng)])
    dirs = dirs[rng.permutation(len(dirs))]
    if revisit:
        dirs = np.vstack([dirs, dirs[::-1]])
    plan = PosePlan(dirs, hold=float(hold), transition=float(rng.uniform(1.5, 2.5)), initial_hold=0.0,
                    vibration=float(rng.uniform(0.5, 1.5)), rate=float(rate))
    temperature = None
    if with_temperature:
        start = float(rng.uniform(15, 25))
        temperature = TemperatureProfile(start=start, plateau=start + float(rng.uniform(8, 15)),
                                         tau=float(rng.uniform(30, 90)), swing=float(rng.uniform(2, 4)),
                                         period=float(rng.uniform(80, 150)), noise=0.02)
    duration = len(dirs) * plan.hold + (len(dirs) - 1) * plan.transition
    t = np.linspace(0, duration, 1000)
    t_mid = np.arange(len(dirs)) * (plan.hold + plan.transition) + plan.hold / 2  # hold centres
    clean = TemperatureProfile(**{**temperature.__dict__, "noise": 0.0}) if temperature is not None else None
    temp_clean = clean.sample(t, rng) if clean is not None else None
    b_mean = float(np.mean(sensor.b))
    n_hold = 0.8 * plan.hold * plan.rate  # samples an interval keeps after trimming
    sigma_mean = float(np.mean(sensor.noise)) / b_mean / np.sqrt(n_hold)
    name, ax, size = None, (), 0.0
    if effect is not None:
        pool = [n for n in (candidates or CLASSIC)
                if temperature is not None or "temp" not in EFFECTS[n].covariates]
        name = pool[int(rng.integers(len(pool)))] if effect == "random" else effect
        if name not in EFFECTS:
            raise ImucalError(f"unknown effect {short(name)}", field="effect", fix=f"choose from {', '.join(EFFECTS)}")
        subsets = _axis_subsets()
        ax = tuple(axes) if axes is not None else subsets[int(rng.integers(len(subsets)))]
        if not EFFECTS[name].axes_observable and axes is None:  # only the sum over axes reaches |a| (to
            ax = ax[:1]  # first order): hide it on one axis unless told otherwise
        lo, hi = (snr, snr) if isinstance(snr, (int, float)) else snr
        size = float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) * sigma_mean
        e = make_effect(name, ax)
        signs = [1.0 if rng.integers(2) else -1.0 for _ in e.axes]
        refs: dict[str, float] = {}
        if name in CLASSIC and e.uses_tref:  # a reference of its own: the fit's shift absorbs the difference
            refs[e.tref_name] = float(np.round(rng.uniform(20, 30), 1))
        elif isinstance(e, Term):  # the basis as discovery will build it from the interval means
            hold_cov = {"time": t_mid, "temp": clean.sample(t_mid, rng) if clean is not None else None}
            refs = {n: v for n, v in e.data_values(hold_cov).items() if n in e.reference_names}
            refs.update({n: float(rng.uniform(0.05, 0.3)) * duration for n in e.shape_names})
            refs.update({n: _step_time(len(dirs), plan, rng, step_anywhere) for n in e.given_names})
        span = 0.0
        if isinstance(e, Term):
            cov = {"time": t, "temp": temp_clean,
                   "temp_rate": None if temp_clean is None else temperature_rate(t, temp_clean)}
            span = float(np.ptp(e.basis.value(cov[e.basis.covariate], {**e.default_values(), **refs}, e.name)))
        coeffs = {e.coefficient(a): sign * e.coefficient_for_size(size, float(sensor.b[a]), span, g)
                  for a, sign in zip(e.axes, signs)}
        coeffs.update(refs)
        sensor = replace(sensor, effects={name: coeffs})
    cfg = SimulationConfig(sensor=sensor, plan=plan, temperature=temperature, gravity=g, seed=int(seed))
    return EffectCase(seed=int(seed), effect=name, axes=tuple(ax), size=size, sigma_mean=sigma_mean, config=cfg)


def _step_time(n_holds: int, plan: PosePlan, rng: np.random.Generator, anywhere: bool = False) -> float:
    """A bias step's time: in the middle of a transition between holds, with at least
    imucal.model.effects.STEP_MIN_SIDE holds on each side (the sensor knocked while it was moved);
    ``anywhere``: uniform from the start of hold STEP_MIN_SIDE to the end of the STEP_MIN_SIDE-th last."""
    if anywhere:
        cycle = plan.hold + plan.transition
        lo, hi = STEP_MIN_SIDE * cycle, (n_holds - STEP_MIN_SIDE) * cycle - plan.transition
        return float(rng.uniform(lo, hi)) + (plan.initial_hold or 0.0)
    k = int(rng.integers(STEP_MIN_SIDE, n_holds - STEP_MIN_SIDE + 1))  # holds before the step
    return k * plan.hold + (k - 0.5) * plan.transition + (plan.initial_hold or 0.0)


def draw_pair_case(seed: int, snr: float = 40.0, noise_mg: float | None = None,
                   candidates: tuple[str, ...] | None = None) -> tuple[EffectCase, EffectCase]:
    """Two different effects, each on one random axis and of the same SNR, in one recording.

    The effects are drawn from ``candidates`` (default: the five classic effects). Returns the two
    single-effect cases; the recording is ``pair_config(...)`` of them (the first case's sensor,
    plan and temperature with both effects).
    """

    rng = np.random.default_rng([seed, 977])
    names = list(candidates or CLASSIC)
    a, b = rng.choice(len(names), 2, replace=False)
    c1 = draw_effect_case(seed, effect=names[a], axes=(int(rng.integers(3)),), snr=snr, noise_mg=noise_mg)
    c2 = draw_effect_case(seed, effect=names[b], axes=(int(rng.integers(3)),), snr=snr, noise_mg=noise_mg)
    return c1, c2


def pair_config(c1: EffectCase, c2: EffectCase) -> SimulationConfig:
    """The simulation of ``c1`` with the effects of both cases (same seed: same sensor and plan)."""
    sensor = replace(c1.config.sensor, effects={**c1.config.sensor.effects, **c2.config.sensor.effects})
    return replace(c1.config, sensor=sensor)
