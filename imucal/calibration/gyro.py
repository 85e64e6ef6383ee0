"""The gyroscope section of a version-2 calibration file (plain arrays), read into the gyroscope's one
calibrated-sensor value (imucal.calibration.sensor.SensorCalibration, the description's named
parameters: imucal.model.gyroscope). Version 3 writes every sensor's section from its Parameters
(imucal.calibration.section); this module only reads the old one.

Version 2 stored, in rad/s and the accelerometer's orthonormal frame,
    omega = M_g^-1 (B_g^-1 (raw - s_g) - G_s a) = C raw + c - D a,   C = M_g^-1 B_g^-1,  c = -C s_g,  D = M_g^-1 G_s
with the parameters (bias, scale, misalignment, G_s [(rad/s) per (m/s^2)]) the source of truth and C, c, D
derived; on load the derived values must match the parameters. G_s becomes the description's
H = B_g G_s [raw per m/s^2] (its standard errors likewise, the scale's own neglected as the fit did).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Mapping

import numpy as np

from imucal.calibration.fields import GYROSCOPE, check_unit
from imucal.calibration.section import check_sensor
from imucal.calibration.sensor import SensorCalibration
from imucal.errors import ImucalError
from imucal.files.schema import fill, rule
from imucal.model.gyroscope import (BIAS_NAMES, GSENS_NAMES, MIS_NAMES, SCALE_NAMES, gyro_model, gyro_parameters,
                                    misalignment_entries)

KIND = GYROSCOPE
OUTPUT_UNIT = "rad/s"
#: Relative disagreement between the stored apply map and the parameters' that counts as an edit.
DERIVED_RTOL = 1e-9
_SHAPES = {"bias": (3,), "scale": (3,), "misalignment": (3, 3), "gsens": (3, 3)}


def from_arrays(unit: str, bias, scale, misalignment, gsens, std: Mapping[str, Any] | None = None,
                fit: Mapping[str, Any] | None = None) -> SensorCalibration:
    """The gyroscope from the model's arrays (version 2's parameters): s_g, diag(B_g), M_g (unit diagonal),
    G_s [(rad/s) per (m/s^2)], and their standard errors by the same keys (zeros when not given)."""
    scale = np.asarray(scale, float)
    G = np.asarray(gsens, float)
    params = gyro_parameters(unit, bias, scale, misalignment_entries(np.asarray(misalignment, float)),
                             (scale[:, None] * G).ravel(), gsens_free=np.any(G != 0, axis=1))
    sd = {k: np.asarray((std or {}).get(k, np.zeros(shape)), float) for k, shape in _SHAPES.items()}
    out = {**dict(zip(BIAS_NAMES, sd["bias"])), **dict(zip(SCALE_NAMES, sd["scale"])),
           **dict(zip(MIS_NAMES, misalignment_entries(sd["misalignment"]))),
           **dict(zip(GSENS_NAMES, (np.abs(scale)[:, None] * sd["gsens"]).ravel()))}
    return SensorCalibration(gyro_model(), params, {n: float(v) for n, v in out.items()}, unit, dict(fit or {}))


def read_v2(d: Any, path: str) -> SensorCalibration:
    """The ``gyroscope:`` section of a version-2 file (GyroSection), with its derived map checked."""
    g = fill(GyroSection, d, path, "gyroscope")
    vals = {k: np.array(getattr(g.parameters, k), float) for k in _SHAPES}
    sd = {k: np.array(getattr(g.std, k), float) for k in _SHAPES}
    fix = "restore the file imucal wrote"
    if np.any(vals["scale"] == 0) or np.any(np.diag(vals["misalignment"]) != 1.0):
        raise ImucalError("scales must be non-zero and the misalignment's diagonal 1", file=path,
                          field="gyroscope.parameters", fix=fix)
    if abs(np.linalg.det(vals["misalignment"])) < 1e-6:
        raise ImucalError("the misalignment matrix is singular", file=path, field="gyroscope.parameters", fix=fix)
    out = from_arrays(g.units.input, std=sd, fit=dict(g.fit), **vals)
    check_sensor(out, path)
    _check_derived(out, g.apply, path)
    return out


#: Values of the file: finite, |x| <= 1e15; standard errors may be NaN (undetermined).
_VALUE = rule(ge=-1e15, le=1e15, fix="restore the file imucal wrote")
_STD = rule(ge=0, le=1e15, allow_nan=True, fix="restore the file imucal wrote")  # a standard error is >= 0
Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]


@dataclass(frozen=True)
class GyroValues:
    bias: Vec3 = field(metadata=_VALUE)
    scale: Vec3 = field(metadata=_VALUE)
    misalignment: Mat3 = field(metadata=_VALUE)
    gsens: Mat3 = field(metadata=_VALUE)


@dataclass(frozen=True)
class GyroStd:
    bias: Vec3 = field(metadata=_STD)
    scale: Vec3 = field(metadata=_STD)
    misalignment: Mat3 = field(metadata=_STD)
    gsens: Mat3 = field(metadata=_STD)


@dataclass(frozen=True)
class GyroUnits:
    input: str = field(metadata=rule(fix="a short unit such as rad/s, deg/s or LSB"))
    output: Literal["rad/s"] = OUTPUT_UNIT
    gsens: str = "(rad/s)/(m/s^2)"

    def __post_init__(self) -> None:
        check_unit(self.input, "gyroscope.units.input", fix="a short unit such as rad/s, deg/s or LSB")


@dataclass(frozen=True)
class GyroSection:
    """The ``gyroscope:`` section as ``to_dict`` writes it."""

    kind: Literal["gyroscope"] = field(metadata=rule(msg=f"kind {{value}} is not {KIND!r}",
                                                     fix="restore the file imucal wrote"))
    units: GyroUnits
    parameters: GyroValues
    std: GyroStd
    model: str | None = None
    apply: Any = None  #: derived from the parameters; checked against them
    fit: Mapping[str, Any] = field(default_factory=dict)


def _check_derived(g: SensorCalibration, apply: Any, path: str) -> None:
    if apply is None:
        return
    a = g.affine()
    for key, want in (("matrix", a.A), ("offset", a.c), ("acc_matrix", -a.B)):
        try:
            got = np.array(apply.get(key), dtype=float) if isinstance(apply, Mapping) else None
        except (TypeError, ValueError, OverflowError):
            got = None
        tol = DERIVED_RTOL * np.abs(want).max(initial=1e-300)
        if got is None or got.shape != want.shape or not np.allclose(got, want, rtol=DERIVED_RTOL, atol=tol):
            raise ImucalError("does not match the parameters (edited by hand?)", file=path,
                              field=f"gyroscope.apply.{key}",
                              fix="edit the parameters, not the derived apply map, or restore the file")
