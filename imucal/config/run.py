"""Run configuration: typed dataclasses, filled from YAML by imucal.files.schema.

Unknown keys are an error that names the key and the allowed ones. A new section is one
dataclass and one line in RunConfig.
"""
from __future__ import annotations

import datetime as dt
import math
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping


from imucal.constants import DEFAULT_ANGLE_TOL
from imucal.data.spec import DataSpec
from imucal.errors import ImucalError, check_choice, short
from imucal.mag.units import ascii_micro, is_sensor_unit
from imucal.model.gravity import normal_gravity
from imucal.model.parameters import BASE_NAMES
from imucal.data.static import StaticSettings
from imucal.constants import STANDARD_GRAVITY
from imucal.files.schema import fill, rule
from imucal.files.yamlio import check_structure, read_yaml

if TYPE_CHECKING:  # the base calibration's type, for annotations (load_base imports it when run)
    from imucal.calibration.frozen import Calibration

FIT_MODES = ("means", "samples")
WEIGHTS = ("auto", "noise", "uniform")


def check_gravity(value: Any, field: str) -> None:
    """Refuse a gravity [m/s^2] that is no local gravity on Earth (the run file's gravity.value, --gravity)."""
    if not (_is_real(value) and math.isfinite(value) and 9.7 < value < 9.9):
        raise ImucalError(f"gravity {short(value)} m/s^2 is not a local gravity on Earth", field=field,
                          fix="give local g in m/s^2 (9.78 .. 9.84)")


@dataclass(frozen=True)
class GravitySpec:
    """Local gravity: a value [m/s^2], or latitude [deg] and height [m] (WGS84 normal gravity)."""

    value: float | None = field(default=None, metadata=rule(
        msg="gravity {value} m/s^2 is not a local gravity on Earth", fix="give local g in m/s^2 (9.78 .. 9.84)"))
    latitude: float | None = field(default=None, metadata=rule(
        msg="latitude {value} is not a number of degrees", fix="latitude in degrees, height in metres"))
    height: float = field(default=0.0, metadata=rule(
        msg="height {value} is not a number of metres", fix="latitude in degrees, height in metres"))

    def __post_init__(self) -> None:
        if self.value is not None and self.latitude is not None:
            raise ImucalError("give either gravity.value or gravity.latitude, not both", field="gravity",
                              fix="keep gravity.value (g in m/s^2) or gravity.latitude (WGS84 normal gravity), "
                                  "drop the other")
        if self.value is not None:
            check_gravity(self.value, "gravity.value")
        for name in ("latitude", "height"):
            v = getattr(self, name)
            if (v is not None or name == "height") and not _is_real(v):
                raise ImucalError(f"{name} {short(v)} is not a number", field=f"gravity.{name}",
                                  fix="latitude in degrees, height in metres")
        if self.latitude is None and self.height != 0.0:
            fix = ("drop gravity.height: gravity.value already sets g" if self.value is not None
                   else "add gravity.latitude (WGS84 normal gravity), or give gravity.value")
            raise ImucalError(f"height {short(self.height)} m is used only with a latitude", field="gravity.height",
                              fix=fix)
        if self.latitude is not None:
            normal_gravity(self.latitude, self.height)  # range checks, at load time

    def resolve(self) -> tuple[float, str]:
        if self.value is not None:
            return float(self.value), "given"
        if self.latitude is not None:
            return normal_gravity(self.latitude, self.height), (
                f"WGS84 normal gravity at latitude {self.latitude} deg, height {self.height} m")

        return STANDARD_GRAVITY, "standard gravity (no local value given)"


def _is_real(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


@dataclass(frozen=True)
class EffectSpec:
    name: str
    axes: tuple[str, ...] = field(default=("x", "y", "z"), metadata=rule(fix="e.g. axes: [x, z]"))

    @classmethod
    def schema_input(cls, raw: Any) -> Any:
        """An effect by its name alone, and axes as one word ("xz")."""
        if isinstance(raw, str):
            return {"name": raw}
        if isinstance(raw, Mapping) and isinstance(raw.get("axes"), str):
            return {**raw, "axes": list(raw["axes"])}
        return raw

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise ImucalError(f"effect name {short(self.name)} is not a string", field="fit.effects.name",
                              fix="name the effect as text, e.g. bias_temperature")
        if not isinstance(self.axes, (str, list, tuple)) or not all(isinstance(a, str) for a in self.axes):
            raise ImucalError(f"axes {short(self.axes)} must be a list of x, y, z", field="fit.effects.axes",
                              fix="e.g. axes: [x, z]")


#: An effect parameter a run file may start or give: a coefficient <effect>_x|y|z (an angle term's
#: <effect>_phi|psi|theta), a shape parameter <effect>_tau or a bias step's time <effect>_t (checked
#: against the model's parameters when the model is built).
EFFECT_PARAMETER = re.compile(r"[a-z][a-z0-9_]{0,60}_(x|y|z|phi|psi|theta|tau|t)\Z")


@dataclass(frozen=True)
class FitSettings:
    mode: str = "means"  #: fit interval means (weighted by their noise) or raw samples
    #: "auto": 1/(sigma^2 + excess), the between-interval excess used when the data show one;
    #: "noise": 1/sigma^2 from each interval's scatter; "uniform": as imu_tk
    weights: str = "auto"
    angle_tolerance: float = DEFAULT_ANGLE_TOL  #: angles in pi/2 (1 +- tol)
    fix: tuple[str, ...] = ()  #: parameters held at their initial value
    initial: Mapping[str, float] = field(default_factory=dict, metadata=rule(  #: overrides of the initial guess
        msg="initial value {value} is not a finite number", fix="e.g. initial: {s1: 0.0}"))
    effects: tuple[EffectSpec, ...] = field(default=(), metadata=rule(fix="e.g. effects: [bias_temperature]"))
    #: `imucal noise --json` output or a Kalibr imu.yaml: the interval means' noise from its
    #: white-noise density (imucal.analysis.noise_model) instead of their own scatter
    noise: str | None = field(default=None, metadata=rule(
        min_len=1, msg="noise {value} must be a file name", fix="give the JSON of `imucal noise --json` or a Kalibr imu.yaml"))
    #: a calibration file (a multi-pose log's calibration.yaml): its accelerometer's values start the fit, and
    #: the parameters in ``fix`` are held at them (what a temperature sweep's few poses cannot determine)
    base: str | None = field(default=None, metadata=rule(
        min_len=1, msg="base {value} must be a file name", fix="give the calibration.yaml of a multi-pose log"))

    @classmethod
    def schema_input(cls, raw: Any) -> Any:
        """``fix: {phi: 1.5708}`` holds phi AT the value: the value joins ``initial``."""
        if not isinstance(raw, Mapping) or "fix" not in raw:
            return raw
        raw = dict(raw)
        raw["fix"], held = _fix_shorthand(raw["fix"])
        init = raw.get("initial") or {}
        if held and isinstance(init, Mapping):
            clash = [n for n in held if n in init and init[n] != held[n]]
            if clash:
                raise ImucalError(f"{clash[0]} is given in fit.fix and fit.initial with different values",
                                  field=f"fit.fix.{clash[0]}", fix="give the value once")
            raw["initial"] = {**init, **held}
        return raw

    @property
    def takes_base(self) -> bool:
        """Every accelerometer parameter held at fit.base's and no effect: the accelerometer is taken from the
        base calibration, not fitted (a hand-turned compass log's few still parts; imucal.pipeline)."""
        return self.base is not None and set(BASE_NAMES) <= set(self.fix) and not self.effects

    @property
    def takes_given(self) -> bool:
        """Every accelerometer parameter held at a value the run file gives (fit.fix as a mapping), no effect and
        no base: the accelerometer is taken as stated, not fitted (a log its device already corrected: s 0, b 1,
        right angles; imucal.pipeline)."""
        return (self.base is None and set(BASE_NAMES) <= set(self.fix) and set(BASE_NAMES) <= set(self.initial)
                and not self.effects)

    @property
    def taken_whole(self) -> bool:
        """The accelerometer is taken (from fit.base or the run file's values), not fitted."""
        return self.takes_base or self.takes_given

    def __post_init__(self) -> None:
        if self.noise is not None and (not isinstance(self.noise, str) or not self.noise):
            raise ImucalError(f"noise {short(self.noise)} must be a file name", field="fit.noise",
                              fix="give the JSON of `imucal noise --json` or a Kalibr imu.yaml")
        check_choice(self.mode, FIT_MODES, "fit.mode", "fit mode")
        check_choice(self.weights, WEIGHTS, "fit.weights", "weights")
        if not (isinstance(self.angle_tolerance, (int, float)) and 0 < self.angle_tolerance < 0.5):
            raise ImucalError(f"angle_tolerance {short(self.angle_tolerance)} must lie in (0, 0.5)",
                              field="fit.angle_tolerance", fix="use e.g. 0.02 (90 deg +- 2 %)")
        for n in self.fix:
            if n not in BASE_NAMES:
                raise ImucalError(f"cannot fix {short(n)}", field="fit.fix", fix=f"choose from {', '.join(BASE_NAMES)}")
        if set(BASE_NAMES) <= set(self.fix) and not self.effects and not self.taken_whole:  # no unknown left
            raise ImucalError(f"all {len(BASE_NAMES)} parameters are fixed, so nothing is left to fit",
                              field="fit.fix", fix="drop at least one from fit.fix (e.g. fix: [phi, psi, theta]), "
                                                   "fit an effect beside them (fit.effects), take the accelerometer "
                                                   "from a calibration (fit.base), or give all nine values "
                                                   "(fix: {s1: 0, ..., theta: 1.5707963267948966})")
        if self.taken_whole and (self.mode != "means" or self.noise is not None):  # nothing is fitted to weigh
            key = "fit.mode" if self.mode != "means" else "fit.noise"
            where = "fit.base" if self.takes_base else "fit.fix's values"
            raise ImucalError(f"{key} has no effect: the accelerometer is taken from {where}, not fitted",
                              field=key, fix=f"drop {key}, or leave one parameter out of fit.fix to fit")
        for n, v in self.initial.items():
            if n not in BASE_NAMES and not (isinstance(n, str) and EFFECT_PARAMETER.match(n)):
                raise ImucalError(f"unknown parameter {short(n)}", field="fit.initial",
                                  fix=f"choose from {', '.join(BASE_NAMES)} or a free parameter of fit.effects")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ImucalError(f"initial value {short(v)} is not a finite number", field=f"fit.initial.{n}",
                                  fix=f"give {n} a number, e.g. fit.initial: {{{n}: 0.0}}")


GYRO_GSENS = ("auto", "on", "off")


@dataclass(frozen=True)
class GyroSettings:
    """The gyroscope fit's choices (the YAML ``gyro:`` section; imucal.gyro.fit.GyroOptions)."""

    gsens: str = "auto"  #: g-sensitivity: auto (a likelihood-ratio test per axis), on or off
    lead_in_s: float | str = "auto"  #: [s] integrate from inside the still poses; auto: imucal.gyro.lead_in
    free_bias: bool = False  #: also fit a bias correction in the rotation fit (imu_tk's option)
    #: calibrate the gyroscope when the recording has one (false: the accelerometer alone, e.g. a log whose
    #: gyroscope turned too little between its poses)
    calibrate: bool = True

    @property
    def fit_choices(self) -> dict:
        """The choices of the gyro fit (imucal.gyro.fit.GyroOptions)."""
        return {"gsens": self.gsens, "lead_in_s": self.lead_in_s, "free_bias": self.free_bias}

    def __post_init__(self) -> None:
        check_choice(self.gsens, GYRO_GSENS, "gyro.gsens", "g-sensitivity choice")
        lead_in = self.lead_in_s
        if lead_in != "auto" and not (_is_real(lead_in) and isinstance(lead_in, (int, float)) and 0 <= lead_in <= 10):
            raise ImucalError(f"lead_in_s {short(self.lead_in_s)} is not auto or between 0 and 10 s",
                              field="gyro.lead_in_s", fix="give auto, or seconds such as 0.5")
        if not isinstance(self.free_bias, bool):
            raise ImucalError(f"free_bias {short(self.free_bias)} must be true or false", field="gyro.free_bias",
                              fix="write free_bias: true or free_bias: false")
        if not isinstance(self.calibrate, bool):
            raise ImucalError(f"calibrate {short(self.calibrate)} must be true or false", field="gyro.calibrate",
                              fix="write calibrate: true or calibrate: false")


MAG_SOFT_IRON = ("auto", "symmetric", "full")


@dataclass(frozen=True)
class MagConfig:
    """The magnetometer fit's choices (the YAML ``mag:`` section; imucal.mag.calibrate.MagSettings). The field's
    magnitude from ``field`` (in ``field_unit``, default the sensor's), else from the IGRF at ``latitude``,
    ``longitude``, ``date`` (the optional imucal-nlp[mag] extra), else fitted (the output then in the sensor's
    unit, its overall size held)."""

    field_unit: str | None = field(default=None, metadata=rule(msg="field_unit {value} is not text"))
    dip_deg: float | None = field(default=None, metadata=rule(
        msg="dip_deg {value} is not an angle in degrees", ge=-90, le=90,
        fix="the angle between field and gravity's plane"))
    soft_iron: str = field(default="auto", metadata=rule(msg="soft_iron {value} is not text"))
    #: the readings' unit: raw (counts), or a field unit (uT, gauss, mG, nT: what the autopilots' exports need)
    unit: str = field(default="raw", metadata=rule(msg="unit {value} is not text"))
    window: int = field(default=25, metadata=rule(msg="window {value} is not a count of samples", ge=4, le=100000))
    lag: float | None = field(default=None, metadata=rule(
        msg="lag {value} is not a number of samples", ge=-10000, le=10000, fix="the magnetometer's delay in samples"))
    latitude: float | None = field(default=None, metadata=rule(msg="latitude {value} is not a number of degrees",
                                                               ge=-90, le=90))
    longitude: float | None = field(default=None, metadata=rule(msg="longitude {value} is not a number of degrees",
                                                                ge=-180, le=360))
    height: float = field(default=0.0, metadata=rule(msg="height {value} is not a number of metres"))
    date: str | None = field(default=None, metadata=rule(msg="date {value} is not a date such as 2024-05-17"))
    #: calibrate the magnetometer when the recording has one (false, --no-mag: the other sensors alone)
    calibrate: bool = field(default=True, metadata=rule(msg="calibrate {value} must be true or false"))
    #: last: the name shadows dataclasses.field in the class body
    field: float | None = field(default=None, metadata=rule(
        msg="field {value} is not a field magnitude", gt=0,
        fix="the local field's magnitude, e.g. 48.2 with field_unit: uT"))

    @classmethod
    def schema_input(cls, raw: Any) -> Any:
        """A date as YAML reads it unquoted (date: 2024-05-17 is a date, not text) taken as its ISO text."""
        if isinstance(raw, Mapping) and isinstance(raw.get("date"), dt.date):
            raw = {**raw, "date": raw["date"].isoformat()}
        if isinstance(raw, Mapping):  # unit: µT as uT (the field's units are written with u)
            raw = {**raw, **{k: ascii_micro(raw[k]) for k in ("unit", "field_unit") if k in raw}}
        return raw

    def __post_init__(self) -> None:
        check_choice(self.soft_iron, MAG_SOFT_IRON, "mag.soft_iron", "soft iron choice")
        if self.date is not None:
            try:
                dt.date.fromisoformat(self.date)
            except (TypeError, ValueError):
                raise ImucalError(f"date {short(self.date)} is not a date", field="mag.date",
                                  fix="write it as YYYY-MM-DD, e.g. 2024-05-17") from None
        for name, unit in (("unit", self.unit), ("field_unit", self.field_unit)):
            if unit is not None and not is_sensor_unit(unit):
                raise ImucalError(f"{name} {short(unit)} is not a unit name", field=f"mag.{name}",
                                  fix="e.g. uT, gauss, mG, nT, or raw for counts")
        if self.field is not None and not (_is_real(self.field) and self.field > 0):
            raise ImucalError(f"field {short(self.field)} is not a field magnitude", field="mag.field",
                              fix="the local field's magnitude, e.g. 48.2 with field_unit: uT")
        place = (self.latitude, self.longitude, self.date)
        if any(v is not None for v in place) and any(v is None for v in place):
            raise ImucalError("the field model needs latitude, longitude and date together", field="mag.latitude",
                              fix="give all three, or the field's magnitude (mag.field)")


@dataclass(frozen=True)
class OutputSettings:
    dir: str = field(default="out", metadata=rule(msg="dir {value} must be a directory name", min_len=1))
    figures: bool = field(default=True, metadata=rule(msg="figures {value} must be true or false"))

    def __post_init__(self) -> None:
        if not isinstance(self.dir, str) or not self.dir:
            raise ImucalError(f"dir {short(self.dir)} must be a directory name", field="output.dir",
                              fix="give a folder name, e.g. dir: out")
        if not isinstance(self.figures, bool):
            raise ImucalError(f"figures {short(self.figures)} must be true or false", field="output.figures",
                              fix="write figures: true or figures: false")


@dataclass(frozen=True)
class RunConfig:
    data: DataSpec = field(metadata=rule(fix="add data: {path: RECORDING}"))
    static: StaticSettings = StaticSettings()
    gravity: GravitySpec = GravitySpec()
    fit: FitSettings = FitSettings()
    output: OutputSettings = OutputSettings()
    gyro: GyroSettings = GyroSettings()
    mag: MagConfig = MagConfig()
    #: the YAML file, for messages and relative paths (not a key of the file)
    source: str | None = field(default=None, metadata=rule(internal=True))

    @property
    def base_dir(self) -> Path | None:
        return Path(self.source).parent if self.source else None


def _fix_shorthand(fx: Any) -> tuple[tuple[str, ...], dict[str, float]]:
    """fit.fix as a name, a list of names, or a mapping name -> value held."""
    if fx is None:
        return (), {}
    if isinstance(fx, str):
        return (fx,), {}
    if isinstance(fx, list) and all(isinstance(n, str) for n in fx):
        return tuple(fx), {}
    if isinstance(fx, Mapping) and all(isinstance(n, str) for n in fx):
        for n, v in fx.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ImucalError(f"value {short(v)} to hold {n} at is not a finite number",
                                  field=f"fit.fix.{n}", fix="e.g. fix: {phi: 1.5708} or fix: [phi]")
        return tuple(fx), {n: float(v) for n, v in fx.items()}
    raise ImucalError(f"{short(fx)} is not a parameter name, a list of names or a mapping of names to values",
                      field="fit.fix", fix="e.g. fix: [phi, psi, theta] or fix: {s1: 0.0}")


def config_from_dict(d: Any, path: str | None = None) -> RunConfig:
    """A RunConfig from a YAML mapping (imucal.files.schema: unknown keys, types, one-line errors)."""
    check_structure(d, path, paths=True)
    cfg = replace(fill(RunConfig, d, path), source=path)
    return cfg if cfg.fit.base is None else with_base(cfg, path)


def base_path(cfg: RunConfig) -> Path:
    """fit.base's file (relative to the run file's folder)."""
    assert cfg.fit.base is not None
    p = Path(cfg.fit.base)
    return p if p.is_absolute() or cfg.base_dir is None else cfg.base_dir / p


def load_base(cfg: RunConfig, path: str | None = None) -> Calibration:
    """fit.base's calibration, checked against the run: its raw unit is the data's; a base the run takes
    whole (``FitSettings.takes_base``) has no effect and its values are not overridden."""
    from imucal.calibration.frozen import load_calibration  # only a run file that names a base

    assert cfg.fit.base is not None
    try:
        base = load_calibration(base_path(cfg))
    except ImucalError as exc:
        raise ImucalError(f"fit.base {short(cfg.fit.base)}: {exc.message}", file=path, field="fit.base",
                          fix="give the calibration.yaml that imucal calibrate wrote for a multi-pose log") from None
    if base.raw_unit != cfg.data.unit:
        raise ImucalError(f"the base calibration's raw unit {short(base.raw_unit)} is not the data's "
                          f"{short(cfg.data.unit)}", file=path, field="fit.base",
                          fix="calibrate the base from a recording in the same unit, or set data.unit")
    if cfg.fit.takes_base:
        if base.effects:
            raise ImucalError(f"the base calibration {short(cfg.fit.base)} has effects "
                              f"({', '.join(short(e[0]) for e in base.effects)}), which a run cannot take whole",
                              file=path, field="fit.base",
                              fix="give a base without fit.effects, or leave one parameter out of fit.fix")
        values = base.params.value_dict()
        other = [n for n in BASE_NAMES if n in cfg.fit.initial and cfg.fit.initial[n] != values[n]]
        if other:
            raise ImucalError(f"{other[0]} = {cfg.fit.initial[other[0]]:g} is given, but the accelerometer is taken "
                              f"from fit.base (its {other[0]} = {values[other[0]]:g})", file=path,
                              field=f"fit.fix.{other[0]}", fix="give the held parameters as a list (fix: [s1, ...])")
    return base


def with_base(cfg: RunConfig, path: str | None = None) -> RunConfig:
    """fit.base read: the base calibration's accelerometer values join ``fit.initial`` (the run file's own
    initial values and values held by ``fix: {name: value}`` win), so ``fix`` holds them there."""
    values = load_base(cfg, path).params.value_dict()
    held = {n: float(values[n]) for n in BASE_NAMES if n in values}
    return replace(cfg, fit=replace(cfg.fit, initial={**held, **cfg.fit.initial}))


def load_config(path: str | os.PathLike) -> RunConfig:
    """Read a YAML run file into its typed settings (unknown keys are refused by name).

    Args:
        path: the run file (relative paths in it are relative to its folder).

    Returns:
        The RunConfig that ``imucal calibrate CONFIG`` and ``imucal.calibrate(config)`` run.
    """
    d = read_yaml(path, "config", "pass a YAML run file (see configs/)")
    return config_from_dict(d, str(path))
