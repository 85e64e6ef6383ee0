"""The calibration file: YAML, format version 3 (versions 1 and 2 still read), validated on load.

Version 3 (issue 26): the accelerometer at the top level as before, and one section per other sensor
(``gyroscope:``), written and read by the one generic section of imucal.calibration.section from the
sensor's Parameters; version 2's gyroscope section (plain arrays) is read by imucal.calibration.gyro.

Below the Calibration it stores (imucal.calibration.frozen builds, saves and loads one through
this module): ``to_dict``/``save`` read a calibration's fields, ``read_mapping`` validates a file's
mapping into the Calibration's values, and ``check_built`` checks the built calibration against
what the file derived from them.

The file stores the fitted parameters (the source of truth) and, for people and other tools,
values derived from them (the apply map), which must agree with the parameters on load: a hand
edit of a derived value is refused. Every text field that can reach generated C is checked
against imucal.calibration.fields.
"""
from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass, field
from typing import Any, Literal, Mapping

import numpy as np

from imucal.calibration.fields import (ACCELEROMETER, DATE_PATTERN, GYROSCOPE, NAME_PATTERN, SHA256_PATTERN,
                                      VERSION_PATTERN, check_raw_unit, check_unit)
from imucal.calibration.section import (ParameterEntry, check_parameter_units, from_section, parameter_entries,
                                       read_parameters, to_section)
from imucal.calibration.sensor import SensorCalibration
from imucal.model.registry import DESCRIPTIONS, KINDS
from imucal.constants import SI_ACCEL_UNIT
from imucal.errors import ImucalError, short
from imucal.files.output import write_text_atomic
from imucal.files.schema import fill, rule
from imucal.files.yamlio import dump_yaml, read_yaml
from imucal.model.geometry import gram_det_np
from imucal.model.channels import TEMPERATURE, TIME
from imucal.model.parameters import ANGLE_NAMES, BASE_NAMES, Parameter, Parameters, base_parameters, model_label

#: imucal.calibration.frozen.Calibration, which builds, saves and loads itself through this module: named here,
#: not imported, so the two modules import in one direction only (tests/test_imports.py)
Calibration = Any


FORMAT = "imucal-calibration"
FORMAT_VERSION = 3
#: Versions this imucal reads: 1 (accelerometer only, no sensor list), 2 (``sensors`` lists the
#: kinds the file holds; a ``gyroscope`` section of plain arrays when it has one) and 3 (one section per
#: sensor beside the accelerometer, from its Parameters: imucal.calibration.section).
READABLE_VERSIONS = (1, 2, 3)
#: Relative disagreement between apply.matrix/offset and the parameters' map that counts as an
#: edit rather than round-off (the file stores floats with repr, so a true file agrees exactly).
DERIVED_RTOL = 1e-9
#: Local gravity a calibration file may hold [m/s^2]: every g imucal calibrates with, and no other
#: (588, YAML 1.1's reading of 9:48, is not a gravity). Above: the largest g a run accepts
#: (imucal.config.run.GravitySpec: 9.7 to 9.9, the range of g on Earth's surface with margin). Below:
#: WGS84 normal gravity at the equator at the greatest height imucal.model.gravity takes (100 km),
#: 9.47, with margin. tests/test_trust_export.py checks that both admit what calibrate can write.
GRAVITY_MIN, GRAVITY_MAX = 9.4, 9.9
OUTPUT_FRAME = ("orthonormal frame f of the Theorem: f1 along sensor axis x, f2 in the plane of "
                "axes x and y, f3 = f1 x f2")


def to_dict(cal: Calibration) -> dict[str, Any]:
    """The file's mapping for ``cal`` (what ``save`` writes)."""
    A, c = cal.linear_map()
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "sensors": list(cal.sensors),
        "model": model_label(cal.model_name, cal.params),
        "effects": [{"name": n, "axes": ["xyz"[a] for a in ax]} for n, ax in cal.effects],
        "units": {"input": cal.raw_unit, "output": SI_ACCEL_UNIT, "angles": "rad",
                  "time": TIME.unit, "temperature": TEMPERATURE.unit, "gravity": SI_ACCEL_UNIT},
        "output_frame": OUTPUT_FRAME,
        "gravity": float(cal.gravity),
        "parameters": parameter_entries(cal.params, cal.std),
        "apply": {"matrix": A.tolist(), "offset": c.tolist(), "equation": cal.equation},
        "fit": dict(cal.fit),
        "data": dict(cal.data),
        "software": {"name": "imucal", "version": cal.software_version},
        "created": cal.created,
        **{s.kind: to_section(s) for s in cal.attached},
    }


def save(cal: Calibration, path: str | os.PathLike) -> None:
    """Write ``cal`` atomically (never a partial file)."""
    write_text_atomic(path, dump_yaml(to_dict(cal), sort_keys=False, width=100))


def _f(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else (None if math.isnan(x) else x)


REGEN = "regenerate the file with `imucal calibrate`"
_NUMBER = rule(msg="{value} is not a number", fix=REGEN)
_BOUND = rule(msg="{value} is not a number", allow_inf=True, fix=REGEN)
#: A standard error: not negative (null when undetermined, .inf when unbounded).
_STD = rule(ge=0, allow_inf=True, msg="{value} is not a standard error (a number >= 0, or null)", fix=REGEN)


@dataclass(frozen=True)
class EffectEntry:
    name: str = field(metadata=rule(msg="effect name {value} is not text", fix=REGEN))
    axes: tuple[Literal["x", "y", "z"], ...] = field(metadata=rule(
        min_len=1, msg="axis {value} is not x, y or z", fix=REGEN))

    @classmethod
    def schema_input(cls, raw: Any) -> Any:
        """Axes as one word ("xz")."""
        return {**raw, "axes": list(raw["axes"])} if isinstance(raw, Mapping) and isinstance(
            raw.get("axes"), str) else raw


@dataclass(frozen=True)
class UnitsSection:
    input: str = field(default="raw", metadata=rule(msg="{value} is not text", fix=REGEN))
    #: what the maps read and give, as this imucal writes them: a file stating another unit is refused, not
    #: applied in these (a temperature in degF read as degC)
    output: Literal["m/s^2"] = field(default=SI_ACCEL_UNIT, metadata=rule(
        msg=f"output unit {{value}} is not {SI_ACCEL_UNIT}", fix=REGEN))
    angles: Literal["rad"] = field(default="rad", metadata=rule(msg="angle unit {value} is not rad", fix=REGEN))
    time: Literal["s"] = field(default="s", metadata=rule(msg=f"time unit {{value}} is not {TIME.unit}", fix=REGEN))
    temperature: Literal["degC"] = field(default="degC", metadata=rule(
        msg=f"temperature unit {{value}} is not {TEMPERATURE.unit}", fix=REGEN))
    gravity: Literal["m/s^2"] = field(default=SI_ACCEL_UNIT, metadata=rule(
        msg=f"gravity unit {{value}} is not {SI_ACCEL_UNIT}", fix=f"give gravity in {SI_ACCEL_UNIT}"))


@dataclass(frozen=True)
class SoftwareSection:
    name: str = "imucal"
    version: str = field(default="", metadata=rule(msg="{value} is not text", fix=REGEN))


@dataclass(frozen=True, kw_only=True)
class CalibrationFile:
    """The calibration file as ``to_dict`` writes it (version 2; version 1 has no sensors or gyroscope),
    checked in this order. ``apply`` is derived from the parameters and checked against them."""

    format: Literal["imucal-calibration"] = field(metadata=rule(
        msg=f"format {{value}} is not {FORMAT!r}", fix="pass a calibration.yaml written by `imucal calibrate`"))
    format_version: Literal[1, 2, 3] = field(metadata=rule(
        msg="unknown format version {value} (this imucal reads versions "
            f"{', '.join(map(str, READABLE_VERSIONS))})", fix="regenerate the file with this imucal or upgrade imucal"))
    parameters: Mapping[str, ParameterEntry] = field(metadata=rule(fix=REGEN))
    effects: tuple[EffectEntry, ...] = field(default=(), metadata=rule(fix=REGEN))
    gravity: float = field(metadata=rule(ge=GRAVITY_MIN, le=GRAVITY_MAX, msg="gravity {value} is not a local gravity "
                                         f"on Earth in m/s^2 ({GRAVITY_MIN:g} to {GRAVITY_MAX:g})", fix=REGEN))
    units: UnitsSection = UnitsSection()
    software: SoftwareSection = SoftwareSection()
    created: str = field(default="", metadata=rule(msg="{value} is not text", fix=REGEN))
    sensors: tuple[str, ...] | None = field(default=None, metadata=rule(fix=REGEN))
    model: Any = None  #: checked against the parameters (_check_model_name)
    output_frame: str | None = None
    apply: Any = None
    fit: Mapping[str, Any] = field(default_factory=dict, metadata=rule(fix=REGEN))
    data: Mapping[str, Any] = field(default_factory=dict, metadata=rule(fix=REGEN))
    #: the other sensors' sections by kind (imucal.model.registry), read by imucal.calibration.section
    #: (version 3) or imucal.calibration.gyro (version 2)
    sections: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def schema_input(cls, raw: Any) -> Any:
        """YAML reads an unquoted timestamp as a datetime: the text it was. The sensors' sections, each
        under its kind's name, are gathered into ``sections``."""
        if not isinstance(raw, Mapping):
            return raw
        out = {k: v for k, v in raw.items() if k not in DESCRIPTIONS and k != "sections"}
        if isinstance(raw.get("created"), _dt.datetime):
            out["created"] = raw["created"].isoformat()
        kinds = {k: v for k, v in raw.items() if k in DESCRIPTIONS}
        return {**out, "sections": kinds} if kinds or "sections" in raw else out


def _parameters(entries: Mapping[str, ParameterEntry], path: str) -> tuple[Parameters, dict[str, float]]:
    """The base parameters first, then each effect's in file order."""
    return read_parameters(entries, tuple(BASE_NAMES) + tuple(n for n in entries if n not in BASE_NAMES), path)


@dataclass(frozen=True)
class FileContent:
    """A calibration file's mapping, validated field by field: the Calibration's values, and the
    values the file derived from them (model label, apply map), checked against the built one."""

    values: dict[str, Any]  #: imucal.calibration.frozen.Calibration's keyword arguments
    model: Any  #: the file's model label
    apply: Any  #: the file's apply map


def read_mapping(d: Mapping[str, Any], path: str = "<calibration>") -> FileContent:
    """Validate a calibration mapping (CalibrationFile) into the Calibration's values."""
    if not isinstance(d, Mapping):
        raise ImucalError("is not a calibration file (top level is not a mapping)", file=path,
                          field="format", fix="pass a calibration.yaml written by `imucal calibrate`")
    f = fill(CalibrationFile, d, path)
    params, std = _parameters(f.parameters, path)
    validate_parameters(params, path)
    effects = tuple((e.name, tuple("xyz".index(a) for a in e.axes)) for e in f.effects)
    values = dict(params=params, std=std, gravity=float(f.gravity), raw_unit=f.units.input, effects=effects,
                  fit=dict(f.fit), data=dict(f.data), created=f.created, software_version=f.software.version,
                  attached=_attached(f, path))
    return FileContent(values, f.model, f.apply)


def check_built(cal: Calibration, content: FileContent, path: str = "<calibration>") -> None:
    """The checks of a calibration built from a file: its text fields, parameter names, bounds and
    fit numbers, and the model label and apply map the file derived (a hand edit is refused)."""
    check_text_fields(cal, path)
    _check_parameter_names(cal, path)
    _check_parameter_units(cal, path)
    _check_bounds(cal, path)
    _check_fit_numbers(cal.fit, path)
    _check_model_name(content.model, cal, path)
    _check_derived(content.apply, cal, path)


def read_file(path: str | os.PathLike) -> Any:
    """The mapping of a calibration YAML file (read safely; validated by ``read_mapping``)."""
    return read_yaml(path, "calibration", "pass the calibration.yaml written by `imucal calibrate`")


def _check_parameter_names(cal: Calibration, path: str) -> None:
    """The parameters must be exactly the model's (base + each effect's)."""
    names = tuple(cal.params.names)
    if cal.effects:
        try:
            model_names = tuple(cal.model.names)
        except ImucalError as exc:
            raise ImucalError(exc.message, file=path, field=exc.field or "effects", fix=exc.fix) from None
        if names != model_names:
            raise ImucalError(f"parameters {short(list(names), 200)} do not match the model's "
                              f"{short(list(model_names), 200)}", file=path, field="parameters", fix=REGEN)
    elif len(names) != len(BASE_NAMES):
        extra = [n for n in names if n not in BASE_NAMES]
        raise ImucalError(f"parameter(s) {short(extra)} belong to no effect of this calibration", file=path,
                          field="parameters", fix=REGEN)


def _check_parameter_units(cal: Calibration, path: str) -> None:
    """The accelerometer's unit labels must be the model's for the file's input unit (base_parameters and each
    effect's parameters, as calibrate writes them)."""
    try:
        want = cal.model.parameters(base_parameters((0.0,) * 3, (1.0,) * 3, raw_unit=cal.raw_unit))
    except ImucalError as exc:
        raise ImucalError(exc.message, file=path, field=exc.field or "effects", fix=exc.fix) from None
    check_parameter_units(cal.params, {n: p.unit for n, p in want.items()}, cal.raw_unit, path, "parameters")


def _attached(f: CalibrationFile, path: str) -> tuple[SensorCalibration, ...]:
    """The sensors beside the accelerometer: version 3's sections (imucal.calibration.section), version 2's
    gyroscope section (imucal.calibration.gyro); ``sensors`` must list exactly what the file holds."""
    if f.format_version == 1:
        if f.sections or f.sensors is not None:
            raise ImucalError("version 1 files hold an accelerometer only", file=path, field="format_version",
                              fix="write format_version: 3 for a file with sensors and their sections")
        return ()
    want = tuple(k for k in KINDS if k == ACCELEROMETER or k in f.sections)
    if f.sensors != want:
        raise ImucalError(f"{short(list(f.sensors or ()))} does not list the file's sensors {list(want)}", file=path,
                          field="sensors", fix=REGEN)
    if f.format_version == 2:
        if set(f.sections) - {GYROSCOPE}:
            raise ImucalError(f"version 2 files hold no {sorted(set(f.sections) - {GYROSCOPE})[0]}", file=path,
                              field="format_version", fix="write format_version: 3")
        if GYROSCOPE not in f.sections:
            return ()
        from imucal.calibration.gyro import read_v2  # only a version-2 file with a gyroscope

        return (read_v2(f.sections[GYROSCOPE], path),)
    return tuple(from_section(k, f.sections[k], path) for k in want[1:])


def check_text_fields(cal: Calibration, path: str = "<calibration>") -> None:
    """Refuse text that does not look like what it claims to be (dates as ISO 8601 dates, units,
    versions, names, SHA-256 digests). These fields reach generated C and reports."""
    def bad(field_: str, value: Any, what: str, fix: str) -> ImucalError:
        return ImucalError(f"{short(value)} is not {what}", file=path, field=field_, fix=fix)

    regen = "regenerate the file with `imucal calibrate`"
    if cal.created:
        try:
            if not (isinstance(cal.created, str) and DATE_PATTERN.match(cal.created)):
                raise ValueError
            _dt.datetime.fromisoformat(cal.created)
        except (TypeError, ValueError):
            raise bad("created", cal.created, "an ISO 8601 date", "write e.g. 2024-05-01T12:00:00+00:00") from None
    if cal.software_version and not VERSION_PATTERN.match(cal.software_version):
        raise bad("software.version", cal.software_version, "a version number", regen)
    check_raw_unit(cal.raw_unit, "units.input", path)
    for n, p in cal.params.items():
        if not NAME_PATTERN.match(n):
            raise bad("parameters", n, "a parameter name", regen)
        check_unit(p.unit, f"parameters.{n}.unit", path, regen)
    for other in cal.attached:
        check_raw_unit(other.raw_unit, f"{other.kind}.units.input", path, "write e.g. rad/s, deg/s or counts")
    for name, _ in cal.effects:
        if not NAME_PATTERN.match(name):
            raise bad("effects", name, "an effect name", regen)
    sha = (cal.data or {}).get("sha256")
    if sha is not None and not (isinstance(sha, str) and SHA256_PATTERN.match(sha)):
        raise bad("data.sha256", sha, "a SHA-256 digest (64 hex digits)", regen)
    name = (cal.data or {}).get("file")
    if name is not None and not isinstance(name, str):
        raise bad("data.file", name, "a file name", regen)


def _check_model_name(model: Any, cal: Calibration, path: str) -> None:
    """``model:`` must name this model: the label (nakov-ivanov-6 ...) or the plain model name."""
    if model is None:
        return
    try:
        names = {cal.model_name, model_label(cal.model_name, cal.params)}
    except ImucalError as exc:
        raise ImucalError(exc.message, file=path, field=exc.field or "effects", fix=exc.fix) from None
    if not isinstance(model, str) or model not in names:
        raise ImucalError(f"model {short(model)} is not this file's model {short(sorted(names))}", file=path,
                          field="model", fix="regenerate the file with `imucal calibrate`")


def _check_derived(apply: Any, cal: Calibration, path: str) -> None:
    """apply.matrix / apply.offset are derived from the parameters: an edit of either is refused
    (the parameters are what imucal applies, so a disagreement means the file was altered)."""
    if apply is None:
        return
    fix = "do not edit apply.matrix or apply.offset; regenerate the file with `imucal calibrate`"
    if not isinstance(apply, Mapping):
        raise ImucalError("must be a mapping", file=path, field="apply", fix=fix)
    A, c = cal.linear_map()
    for key, want in (("matrix", A), ("offset", c)):
        got = apply.get(key)
        if got is None:
            continue
        try:
            arr = np.array(got, dtype=float)
        except (TypeError, ValueError, OverflowError):
            arr = None
        if arr is None or arr.shape != want.shape:
            raise ImucalError(f"is not a {'3x3 matrix' if key == 'matrix' else '3-vector'} of numbers",
                              file=path, field=f"apply.{key}", fix=fix)
        # offset = -matrix @ s: its round-off scales with |matrix| |s|, not with |offset|
        ref = np.abs(A).max() if key == "matrix" else (np.abs(A) @ np.abs(cal.values[0:3])).max()
        dev = np.abs(arr - want).max() if np.all(np.isfinite(arr)) else math.inf
        if not dev <= DERIVED_RTOL * ref:
            raise ImucalError(f"disagrees with the parameters (max difference {dev:.3g}, relative "
                              f"{dev / ref if ref else math.inf:.3g})", file=path, field=f"apply.{key}", fix=fix)


def _check_bounds(cal: Calibration, path: str) -> None:
    """Every value within the file's own bounds, and an effect's within the model's (a warm-up's tau
    in [1, 1e5] s, a scale coefficient that keeps the scale positive): a value outside them was never
    fitted, and the apply map or the generated C would return NaN or inf with it."""
    model = {}
    for e in cal.model.effects if cal.effects else ():
        model.update({p.name: (p.lower, p.upper) for p in e.parameters(cal.params)})
    for n in cal.params.names:
        p = cal.params[n]
        for lo, hi, whose in ((p.lower, p.upper, "the file's"), (*model.get(n, (-math.inf, math.inf)), "the model's")):
            if not p.admits(p.value, lo, hi):
                raise ImucalError(f"{n} = {p.value:.6g} {p.unit} is outside {whose} bounds [{lo:.6g}, {hi:.6g}]",
                                  file=path, field=f"parameters.{n}.value", fix=REGEN)


def _check_fit_numbers(fit: Mapping[str, Any], path: str) -> None:
    """The numbers of the fit section that commands compute with (``drift`` the RMS residual, the
    exports the temperature range): finite, the RMS not negative, the range [min, max] in order."""
    def number(x: Any) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

    if "rms_residual" in fit and not (number(fit["rms_residual"]) and fit["rms_residual"] >= 0):
        raise ImucalError(f"{short(repr(fit['rms_residual']), 40)} is not an RMS (a finite number >= 0)", file=path,
                          field="fit.rms_residual", fix=REGEN)
    if "temperature_range" in fit:
        r = fit["temperature_range"]
        if not (isinstance(r, list) and len(r) == 2 and all(number(x) for x in r) and r[0] <= r[1]):
            raise ImucalError(f"{short(repr(r), 60)} is not a temperature range [min, max] of finite numbers, "
                              "min <= max", file=path, field="fit.temperature_range", fix=REGEN)


def validate_parameters(params: Parameters, path: str = "<calibration>") -> None:
    """Positive scales and angles that span a right-handed frame (det G > 0)."""
    for i in (1, 2, 3):
        if not params[f"b{i}"].value > 0:
            raise ImucalError(f"scale b{i} = {params[f'b{i}'].value} must be positive", file=path,
                              field=f"parameters.b{i}.value", fix=REGEN)
    ang = [params[a].value for a in ANGLE_NAMES]
    for a, v in zip(ANGLE_NAMES, ang):
        if not 0 < v < math.pi:
            raise ImucalError(f"angle {a} = {v} rad is outside (0, pi)", file=path,
                              field=f"parameters.{a}.value", fix=REGEN)
    det = float(gram_det_np(ang))  # Eq. (eq:12), from the CasADi model
    if not det > 1e-12:
        raise ImucalError("the angles phi, psi, theta give no valid frame (Gram determinant <= 0)",
                          file=path, field="parameters", fix="check the angles; they must be near pi/2")
