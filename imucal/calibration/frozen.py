"""A frozen calibration: applies itself, saves itself (self-describing YAML) and loads back.

The apply map is the Theorem: a_orth = E^-T diag(1/b) (raw - s) = A raw + c, with A lower
triangular (structural zeros above the diagonal). Effects, when present, make A and c depend
on covariates (temperature, time) and the map is evaluated through the CasADi model.
"""
from __future__ import annotations

import datetime as _dt
import math
import os
from dataclasses import dataclass, field, replace
from typing import Any, Mapping

import numpy as np
import yaml

from imucal import __version__
from imucal.calibration.fields import NAME_PATTERN, SHA256_PATTERN, UNIT_PATTERN, VERSION_PATTERN
from imucal.calibration.gyro import KIND as GYRO_KIND, GyroCalibration
from imucal.constants import SI_ACCEL_UNIT
from imucal.errors import ImucalError, short
from imucal.model.sensor import gram_det_np
from imucal.model.parameters import ANGLE_NAMES, BASE_NAMES, Parameter, Parameters, model_label

FORMAT = "imucal-calibration"
FORMAT_VERSION = 2
#: Versions this imucal reads: 1 (accelerometer only, no sensor list) and 2 (``sensors`` lists the
#: kinds the file holds; a ``gyroscope`` section when it has one).
READABLE_VERSIONS = (1, 2)
ACCELEROMETER = "accelerometer"
#: Relative disagreement between apply.matrix/offset and the parameters' map that counts as an
#: edit rather than round-off (the file stores floats with repr, so a true file agrees exactly).
DERIVED_RTOL = 1e-9
OUTPUT_FRAME = ("orthonormal frame f of the Theorem: f1 along sensor axis x, f2 in the plane of "
                "axes x and y, f3 = f1 x f2")


@dataclass(frozen=True)
class Calibration:
    """Parameters of a fitted sensor model and everything needed to apply and trace them."""

    params: Parameters
    std: Mapping[str, float]
    gravity: float
    raw_unit: str = "raw"
    effects: tuple[tuple[str, tuple[int, ...]], ...] = ()
    fit: Mapping[str, Any] = field(default_factory=dict)  #: rms, chi2, dof, status, ...
    data: Mapping[str, Any] = field(default_factory=dict)  #: file name, sha256
    created: str = ""
    software_version: str = __version__
    gyro: GyroCalibration | None = None  #: the gyroscope part, in the same output frame

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensor kinds this calibration holds."""
        return (ACCELEROMETER,) + ((GYRO_KIND,) if self.gyro is not None else ())

    # --- the model -------------------------------------------------------------------------
    @property
    def model(self):
        from imucal.model.sensor import build_model

        return build_model(self.effect_objects())

    def effect_objects(self) -> list:
        if not self.effects:
            return []
        from imucal.model.effects import make_effect

        return [make_effect(name, axes) for name, axes in self.effects]

    @property
    def covariates(self) -> tuple[str, ...]:
        return self.model.covariates if self.effects else ()

    @property
    def model_name(self) -> str:
        return self.model.name

    @property
    def values(self) -> np.ndarray:
        return np.array(self.params.values(), float)

    def linear_map(self) -> tuple[np.ndarray, np.ndarray]:
        """A (3x3, lower triangular) and c (3) with a_orth = A raw + c (Theorem).

        With effects, the map at covariates zero (reference temperature, t = 0).
        """
        from imucal.model.sensor import build_model

        base = build_model()
        A, c = base.linear_map(self.values[: len(BASE_NAMES)])
        return np.asarray(A), np.asarray(c).ravel()

    @property
    def rms_residual(self) -> float:
        return float(self.fit.get("rms_residual", float("nan")))

    # --- apply -------------------------------------------------------------------------------
    def apply(self, raw: np.ndarray, covariates: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        """Calibrated acceleration [m/s^2] in the Theorem's orthonormal frame, one row per sample."""
        raw = np.asarray(raw, float)
        if raw.shape == (3,):  # one sample
            return self.apply(raw[None, :], covariates)[0]
        if raw.ndim != 2 or raw.shape[1] != 3:
            raise ImucalError(f"raw data must have shape (N, 3) or (3,), got {raw.shape}", field="raw")
        if not self.effects:
            A, c = self.linear_map()
            out = (A @ raw.T).T  # one BLAS call; half the peak memory of raw @ A.T + c
            out += c
            return out
        covs = self.covariates
        covariates = covariates or {}
        missing = [c for c in covs if c not in covariates]
        if missing:
            raise ImucalError(f"this calibration needs covariate(s) {missing}", field="covariates",
                              fix="load a recording with those columns (temp in deg C, time in s)")
        n = raw.shape[0]
        C = np.column_stack([np.broadcast_to(np.asarray(covariates[c], float), (n,)) for c in covs]) if covs \
            else np.zeros((n, 0))  # effects without covariates (scale_nonlinearity)
        # Serial map: CasADi's "thread" map aborts the process for large n (one thread per call).
        f = self.model.accel.map(n, "serial")
        return np.asarray(f(raw.T, C.T, self.values)).T

    def apply_imu(self, raw_acc: np.ndarray, raw_gyro: np.ndarray,
                  covariates: Mapping[str, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(acceleration [m/s^2], angular rate [rad/s]) of the same samples, in one frame."""
        if self.gyro is None:
            raise ImucalError("this calibration has no gyroscope part", field="gyroscope",
                              fix="calibrate with gyro columns (gx, gy, gz) or --gyro-data")
        acc = self.apply(raw_acc, covariates)
        return acc, self.gyro.apply(raw_gyro, acc)

    @property
    def equation(self) -> str:
        """The accelerometer's apply equation as actually applied."""
        if not self.effects:
            return "a = matrix @ raw + offset (matrix lower triangular)"
        covs = ", ".join(self.covariates)
        terms = ", ".join(f"{n}[{''.join('xyz'[i] for i in ax)}]" for n, ax in self.effects)
        return (f"a = E^-T m with m_i = (raw_i - s_i) / b_i (Eq. theModel) extended by {terms}"
                + (f", evaluated at each sample's {covs}" if covs else "")
                + "; matrix and offset are the map with every effect term at zero"
                + (f" ({covs} at their reference)" if covs else ""))

    def generate_c(self, prefix: str = "imucal", precision: str = "float"):
        """C source applying this calibration (see imucal.export.codegen.generate_c)."""
        from imucal.export.codegen import generate_c

        return generate_c(self, prefix=prefix, precision=precision)

    # --- files -------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | os.PathLike) -> "Calibration":
        """Read a calibration file written by :meth:`save` (refuses unknown versions)."""
        return load_calibration(path)

    def to_dict(self) -> dict[str, Any]:
        A, c = self.linear_map()
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "sensors": list(self.sensors),
            "model": model_label(self.model_name, self.params),
            "effects": [{"name": n, "axes": ["xyz"[a] for a in ax]} for n, ax in self.effects],
            "units": {"input": self.raw_unit, "output": SI_ACCEL_UNIT, "angles": "rad",
                      "time": "s", "temperature": "degC", "gravity": SI_ACCEL_UNIT},
            "output_frame": OUTPUT_FRAME,
            "gravity": float(self.gravity),
            "parameters": {
                n: {"value": float(p.value), "std": _f(self.std.get(n, float("nan"))), "unit": p.unit,
                    "lower": _f(p.lower), "upper": _f(p.upper), "fixed": bool(p.fixed),
                    "solver_scale": float(p.scale)}  # IPOPT's scaling magnitude, not b1..b3
                for n, p in self.params.items()},
            "apply": {"matrix": A.tolist(), "offset": c.tolist(), "equation": self.equation},
            "fit": dict(self.fit),
            "data": dict(self.data),
            "software": {"name": "imucal", "version": self.software_version},
            "created": self.created,
            **({"gyroscope": self.gyro.to_dict()} if self.gyro is not None else {}),
        }

    def save(self, path: str | os.PathLike) -> None:
        from imucal.files.output import write_text_atomic

        write_text_atomic(path, yaml.safe_dump(self.to_dict(), sort_keys=False, width=100))


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


def from_dict(d: Mapping[str, Any], path: str = "<calibration>") -> Calibration:
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
    cal = Calibration(params=params, std=std, gravity=g, raw_unit=_text(units.get("input", "raw"), path, "units.input"),
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


def check_text_fields(cal: Calibration, path: str = "<calibration>") -> None:
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


def load_calibration(path: str | os.PathLike) -> Calibration:
    """Read a calibration YAML written by :meth:`Calibration.save`; refuses unknown versions."""
    from imucal.files.yamlio import read_yaml

    d = read_yaml(path, "calibration", "pass the calibration.yaml written by `imucal calibrate`")
    return from_dict(d, str(path))


def now_utc() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
