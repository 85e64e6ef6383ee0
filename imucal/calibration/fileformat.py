"""The calibration file: YAML, format version 2 (version 1 still read), validated on load.

The file stores the fitted parameters (the source of truth) and, for people and other tools,
values derived from them (the apply map), which must agree with the parameters on load: a hand
edit of a derived value is refused. Every text field that can reach generated C is checked
against imucal.calibration.fields.
"""
from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import replace
from typing import Any, Mapping

import numpy as np
import yaml

import imucal.calibration.frozen as frozen
from imucal.calibration.fields import ACCELEROMETER, NAME_PATTERN, SHA256_PATTERN, UNIT_PATTERN, VERSION_PATTERN
from imucal.calibration.gyro import KIND as GYRO_KIND, GyroCalibration
from imucal.constants import SI_ACCEL_UNIT
from imucal.errors import ImucalError, short
from imucal.files.output import write_text_atomic
from imucal.files.yamlio import read_yaml
from imucal.model.geometry import gram_det_np
from imucal.model.channels import TEMPERATURE, TIME
from imucal.model.parameters import ANGLE_NAMES, BASE_NAMES, Parameter, Parameters, model_label


FORMAT = "imucal-calibration"
FORMAT_VERSION = 2
#: Versions this imucal reads: 1 (accelerometer only, no sensor list) and 2 (``sensors`` lists the
#: kinds the file holds; a ``gyroscope`` section when it has one).
READABLE_VERSIONS = (1, 2)
#: Relative disagreement between apply.matrix/offset and the parameters' map that counts as an
#: edit rather than round-off (the file stores floats with repr, so a true file agrees exactly).
DERIVED_RTOL = 1e-9
OUTPUT_FRAME = ("orthonormal frame f of the Theorem: f1 along sensor axis x, f2 in the plane of "
                "axes x and y, f3 = f1 x f2")


def to_dict(cal: "frozen.Calibration") -> dict[str, Any]:
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
        "parameters": {
            n: {"value": float(p.value), "std": _f(cal.std.get(n, float("nan"))), "unit": p.unit,
                "lower": _f(p.lower), "upper": _f(p.upper), "fixed": bool(p.fixed),
                "solver_scale": float(p.scale)}  # IPOPT's scaling magnitude, not b1..b3
            for n, p in cal.params.items()},
        "apply": {"matrix": A.tolist(), "offset": c.tolist(), "equation": cal.equation},
        "fit": dict(cal.fit),
        "data": dict(cal.data),
        "software": {"name": "imucal", "version": cal.software_version},
        "created": cal.created,
        **({"gyroscope": cal.gyro.to_dict()} if cal.gyro is not None else {}),
    }


def save(cal: "frozen.Calibration", path: str | os.PathLike) -> None:
    """Write ``cal`` atomically (never a partial file)."""
    write_text_atomic(path, yaml.safe_dump(to_dict(cal), sort_keys=False, width=100))


def _f(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else (None if math.isnan(x) else x)


def _get(d: Mapping, key: str, path: str, where: str) -> Any:
    if not isinstance(d, Mapping) or key not in d:
        raise ImucalError(f"missing field {where + key!r}", file=path, field=where + key,
                          fix="regenerate the file with `imucal calibrate`")
    return d[key]


def _num(x: Any, path: str, field_: str) -> float:
    if x is None:
        return float("nan")
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise ImucalError(f"{short(x)} is not a number", file=path, field=field_)
    try:
        return float(x)
    except OverflowError:  # an integer beyond the float range
        raise ImucalError(f"{short(x)} is too large for a float", file=path, field=field_) from None


def from_dict(d: Mapping[str, Any], path: str = "<calibration>") -> "frozen.Calibration":
    """Validate a calibration mapping and rebuild the Calibration."""
    if not isinstance(d, Mapping):
        raise ImucalError("is not a calibration file (top level is not a mapping)", file=path,
                          field="format", fix="pass a calibration.yaml written by `imucal calibrate`")
    fmt = _get(d, "format", path, "")
    if fmt != FORMAT:
        raise ImucalError(f"format {fmt!r} is not {FORMAT!r}", file=path, field="format",
                          fix="pass a calibration.yaml written by `imucal calibrate`")
    ver = _get(d, "format_version", path, "")
    if ver not in READABLE_VERSIONS or isinstance(ver, bool):
        raise ImucalError(f"unknown format version {short(ver)} (this imucal reads versions "
                          f"{', '.join(map(str, READABLE_VERSIONS))})",
                          file=path, field="format_version",
                          fix="regenerate the file with this imucal or upgrade imucal")
    pd = _get(d, "parameters", path, "")
    if not isinstance(pd, Mapping) or not all(isinstance(n, str) for n in pd):
        raise ImucalError("must map parameter names to entries", file=path, field="parameters",
                          fix="regenerate the file with `imucal calibrate`")
    effects_in = _section(d, "effects", path, list)
    effects: list[tuple[str, tuple[int, ...]]] = []
    for e in effects_in:
        name = _get(e, "name", path, "effects[].")
        axes = _get(e, "axes", path, "effects[].")
        if not isinstance(name, str) or not isinstance(axes, (list, str)) or not axes \
                or not all(isinstance(a, str) and a in ("x", "y", "z") for a in axes):
            raise ImucalError(f"effect {name!r} on axes {axes!r} is not a named effect on x, y, z", file=path,
                              field="effects", fix="regenerate the file with `imucal calibrate`")
        effects.append((name, tuple("xyz".index(a) for a in axes)))
    plist: list[Parameter] = []
    names = list(BASE_NAMES) + [n for n in pd if n not in BASE_NAMES]
    std: dict[str, float] = {}
    for n in names:
        e = _get(pd, n, path, "parameters.")
        where = f"parameters.{n}."
        val = _num(_get(e, "value", path, where), path, where + "value")
        if not math.isfinite(val):
            raise ImucalError("value is not finite", file=path, field=where + "value")
        lo = _num(e.get("lower", -math.inf), path, where + "lower")
        hi = _num(e.get("upper", math.inf), path, where + "upper")
        if "solver_scale" in e and "scale" in e:
            raise ImucalError("has both solver_scale and its old name scale", file=path, field=where + "scale",
                              fix="keep only solver_scale")
        key = "scale" if "scale" in e else "solver_scale"  # "scale" in files before the rename
        scale = _num(e.get(key, 1.0), path, where + key)
        fixed = e.get("fixed", False)
        if not isinstance(fixed, bool):
            raise ImucalError(f"{fixed!r} is not true or false", file=path, field=where + "fixed")
        try:
            plist.append(Parameter(n, val, lower=-math.inf if math.isnan(lo) else lo,
                                   upper=math.inf if math.isnan(hi) else hi, unit=str(e.get("unit", "")),
                                   fixed=fixed, scale=scale))
        except ImucalError as exc:
            field_ = where + key if exc.field and exc.field.endswith(".scale") else exc.field
            raise ImucalError(exc.message, file=path, field=field_, fix=exc.fix) from None
        std[n] = _num(e.get("std"), path, where + "std")
    params = Parameters(plist)
    validate_parameters(params, path)
    g = _num(_get(d, "gravity", path, ""), path, "gravity")
    if not (math.isfinite(g) and g > 0):
        raise ImucalError(f"gravity {g} must be positive", file=path, field="gravity")
    units = _section(d, "units", path, Mapping)
    sw = _section(d, "software", path, Mapping)
    if units.get("gravity", SI_ACCEL_UNIT) != SI_ACCEL_UNIT:
        raise ImucalError(f"gravity unit {short(units.get('gravity'))} is not {SI_ACCEL_UNIT}", file=path,
                          field="units.gravity", fix=f"give gravity in {SI_ACCEL_UNIT}")
    created = d.get("created", "")
    if isinstance(created, _dt.datetime):  # YAML reads an unquoted timestamp as a datetime
        created = created.isoformat()
    cal = frozen.Calibration(params=params, std=std, gravity=g, raw_unit=_text(units.get("input", "raw"), path, "units.input"),
                      effects=tuple(effects), fit=dict(_section(d, "fit", path, Mapping)),
                      data=dict(_section(d, "data", path, Mapping)),
                      created=_text(created, path, "created"),
                      software_version=_text(sw.get("version", ""), path, "software.version"))
    gyro = _gyro_section(d, ver, path)
    if gyro is not None:
        cal = replace(cal, gyro=gyro)
    check_text_fields(cal, path)
    if effects:  # the parameters must be exactly the model's (base + each effect's)
        try:
            model_names = cal.model.names
        except ImucalError as exc:
            raise ImucalError(exc.message, file=path, field=exc.field or "effects", fix=exc.fix) from None
        if tuple(params.names) != tuple(model_names):
            raise ImucalError(f"parameters {list(params.names)} do not match the model's {list(model_names)}",
                              file=path, field="parameters", fix="regenerate the file with `imucal calibrate`")
    elif len(params) != len(BASE_NAMES):
        extra = [n for n in params.names if n not in BASE_NAMES]
        raise ImucalError(f"parameter(s) {short(extra)} belong to no effect of this calibration", file=path,
                          field="parameters", fix="regenerate the file with `imucal calibrate`")
    _check_model_name(d.get("model"), cal, path)
    _check_derived(d.get("apply"), cal, path)
    return cal


def _gyro_section(d: Mapping, version: int, path: str) -> GyroCalibration | None:
    """The gyroscope part of a version-2 file; ``sensors`` must list exactly what the file holds."""
    if version == 1:
        if "gyroscope" in d or "sensors" in d:
            raise ImucalError("version 1 files hold an accelerometer only", file=path, field="format_version",
                              fix="write format_version: 2 for a file with sensors and a gyroscope section")
        return None
    sensors = d.get("sensors")
    want = [ACCELEROMETER] + ([GYRO_KIND] if "gyroscope" in d else [])
    if sensors != want:
        raise ImucalError(f"{short(sensors)} does not list the file's sensors {want}", file=path, field="sensors",
                          fix="regenerate the file with `imucal calibrate`")
    return GyroCalibration.from_dict(d["gyroscope"], path) if "gyroscope" in d else None


def _text(x: Any, path: str, field_: str) -> str:
    if not isinstance(x, str):
        raise ImucalError(f"{short(x)} is not text", file=path, field=field_,
                          fix="regenerate the file with `imucal calibrate`")
    return x


def check_text_fields(cal: "frozen.Calibration", path: str = "<calibration>") -> None:
    """Refuse text that does not look like what it claims to be (dates as ISO 8601 dates, units,
    versions, names, SHA-256 digests). These fields reach generated C and reports."""
    def bad(field_: str, value: Any, what: str, fix: str) -> ImucalError:
        return ImucalError(f"{short(value)} is not {what}", file=path, field=field_, fix=fix)

    regen = "regenerate the file with `imucal calibrate`"
    if cal.created:
        try:
            _dt.datetime.fromisoformat(cal.created)
        except (TypeError, ValueError):
            raise bad("created", cal.created, "an ISO 8601 date", "write e.g. 2024-05-01T12:00:00+00:00") from None
    if cal.software_version and not VERSION_PATTERN.match(cal.software_version):
        raise bad("software.version", cal.software_version, "a version number", regen)
    if not UNIT_PATTERN.match(cal.raw_unit) or "//" in cal.raw_unit:
        raise bad("units.input", cal.raw_unit, "a unit (letters, digits, ^ . % ( ) / - space; at most 40)", "write e.g. counts")
    for n, p in cal.params.items():
        if not NAME_PATTERN.match(n):
            raise bad("parameters", n, "a parameter name", regen)
        if not UNIT_PATTERN.match(p.unit) or "//" in p.unit:
            raise bad(f"parameters.{n}.unit", p.unit, "a unit", regen)
    for name, _ in cal.effects:
        if not NAME_PATTERN.match(name):
            raise bad("effects", name, "an effect name", regen)
    sha = (cal.data or {}).get("sha256")
    if sha is not None and not (isinstance(sha, str) and SHA256_PATTERN.match(sha)):
        raise bad("data.sha256", sha, "a SHA-256 digest (64 hex digits)", regen)
    name = (cal.data or {}).get("file")
    if name is not None and not isinstance(name, str):
        raise bad("data.file", name, "a file name", regen)


def _check_model_name(model: Any, cal: "frozen.Calibration", path: str) -> None:
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


def _check_derived(apply: Any, cal: "frozen.Calibration", path: str) -> None:
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


def _section(d: Mapping, key: str, path: str, kind: type) -> Any:
    """An optional section that must have the given kind (Mapping or list) when present."""
    v = d.get(key)
    if v is None:
        return [] if kind is list else {}
    if not isinstance(v, kind):
        raise ImucalError(f"must be a {'list' if kind is list else 'mapping'}, got {type(v).__name__}",
                          file=path, field=key, fix="regenerate the file with `imucal calibrate`")
    return v


def validate_parameters(params: Parameters, path: str = "<calibration>") -> None:
    """Positive scales and angles that span a right-handed frame (det G > 0)."""
    for i in (1, 2, 3):
        if not params[f"b{i}"].value > 0:
            raise ImucalError(f"scale b{i} = {params[f'b{i}'].value} must be positive", file=path,
                              field=f"parameters.b{i}.value")
    ang = [params[a].value for a in ANGLE_NAMES]
    for a, v in zip(ANGLE_NAMES, ang):
        if not 0 < v < math.pi:
            raise ImucalError(f"angle {a} = {v} rad is outside (0, pi)", file=path,
                              field=f"parameters.{a}.value")
    det = float(gram_det_np(ang))  # Eq. (eq:12), from the CasADi model
    if not det > 1e-12:
        raise ImucalError("the angles phi, psi, theta give no valid frame (Gram determinant <= 0)",
                          file=path, field="parameters", fix="check the angles; they must be near pi/2")


def load_calibration(path: str | os.PathLike) -> "frozen.Calibration":
    """Read a calibration YAML written by :meth:`Calibration.save`; refuses unknown versions."""
    d = read_yaml(path, "calibration", "pass the calibration.yaml written by `imucal calibrate`")
    return from_dict(d, str(path))
