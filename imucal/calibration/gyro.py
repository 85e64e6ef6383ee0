"""The gyroscope part of a calibration: values, standard errors, its apply map and its file section.

omega = M_g^-1 (B_g^-1 (raw - s_g) - G_s a)     (imucal.gyro.model; a: calibrated acceleration)
      = C raw + c - D a,   C = M_g^-1 B_g^-1,  c = -C s_g,  D = M_g^-1 G_s

in rad/s, in the accelerometer's orthonormal frame (the Theorem's), so both sensors' outputs
share one frame. The file stores the parameters (the source of truth) and, for people and other
tools, the derived C, c and D; on load the derived values must match the parameters.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, Mapping

import numpy as np

from imucal.calibration.fields import GYROSCOPE, check_unit
from imucal.errors import ImucalError, short
from imucal.files.schema import fill, rule
from imucal.model.gyroscope import gyro_model, gyro_parameters, misalignment_entries
from imucal.model.parameters import Parameters
from imucal.solve.vectorize import apply_values
from imucal.gyro.result import arrays, motions, to_dict
from imucal.solve.fit import FitResult

KIND = GYROSCOPE
OUTPUT_UNIT = "rad/s"
EQUATION = "omega = matrix @ raw + offset - acc_matrix @ a  (a: calibrated acceleration [m/s^2])"
#: Relative disagreement between the stored apply map and the parameters' that counts as an edit.
DERIVED_RTOL = 1e-9
_SHAPES = {"bias": (3,), "scale": (3,), "misalignment": (3, 3), "gsens": (3, 3)}


@dataclass(frozen=True)
class GyroCalibration:
    """A calibrated gyroscope (the accelerometer's frame, rad/s)."""

    unit: str  #: raw unit of the gyro readings
    bias: np.ndarray  #: s_g (3,) [unit]
    scale: np.ndarray  #: diag(B_g) (3,) [unit per rad/s]
    misalignment: np.ndarray  #: M_g (3, 3), unit diagonal
    gsens: np.ndarray  #: G_s (3, 3) [(rad/s) per (m/s^2)], zero rows where not selected
    std: Mapping[str, np.ndarray]  #: same keys and shapes as the values
    fit: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_result(cls, res: FitResult) -> "GyroCalibration":
        a, m, d = arrays(res), motions(res), to_dict(res)
        uses = bool(np.any(m.gsens_selected))
        return cls(unit=m.unit, bias=a.bias, scale=a.scale, misalignment=a.misalignment,
                   gsens=a.gsens if uses else np.zeros((3, 3)),
                   std={"bias": a.bias_std, "scale": a.scale_std, "misalignment": a.misalignment_std,
                        "gsens": a.gsens_std if uses else np.zeros((3, 3))},
                   fit={**d["fit"], "rms_direction_error_deg": m.rms_direction_error_deg,
                        "gsens_p_value": [float(v) for v in m.gsens_p_value],
                        **({"not_still": d["not_still"]} if m.still and m.still.rejected else {}),
                        **({"gap_motions": d["gap_motions"]} if m.gapped else {})})

    @property
    def uses_gsens(self) -> bool:
        return bool(np.any(self.gsens != 0))

    def parameters(self) -> Parameters:
        """The gyroscope description's named parameters (imucal.model.gyroscope): H = B_g G_s."""
        return gyro_parameters(self.unit, self.bias, self.scale, misalignment_entries(self.misalignment),
                               (np.asarray(self.scale, float)[:, None] * np.asarray(self.gsens, float)).ravel())

    def rate_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(C, c, D) with omega = C raw + c - D a: the description's map, affine (SensorModel.affine)."""
        C, c, B = (np.asarray(v) for v in gyro_model().affine(self.parameters().values()))
        return C, c.ravel(), -B

    def apply(self, raw: np.ndarray, acc: np.ndarray | None = None) -> np.ndarray:
        """Calibrated rate [rad/s] of raw readings (N, 3) or (3,); ``acc`` [m/s^2] is the
        calibrated acceleration of the same samples (needed when G_s is not zero)."""
        raw = np.asarray(raw, float)
        one = raw.shape == (3,)
        raw = np.atleast_2d(raw)
        if raw.ndim != 2 or raw.shape[1] != 3:
            raise ImucalError(f"gyro data must have shape (N, 3) or (3,), got {raw.shape}", field="raw_gyro")
        if self.uses_gsens and acc is None:
            raise ImucalError("this gyro calibration has a g-sensitivity", field="acc",
                              fix="pass the calibrated acceleration of the same samples")
        a = None if acc is None else np.broadcast_to(np.atleast_2d(np.asarray(acc, float)), raw.shape)
        w = apply_values(gyro_model(), self.parameters().values(), raw, a)
        return w[0] if one else w

    def to_dict(self) -> dict[str, Any]:
        C, c, D = self.rate_map()
        return {
            "kind": KIND,
            "model": "raw = s_g + B_g (M_g omega + G_s a); omega = M_g^-1 (B_g^-1 (raw - s_g) - G_s a)",
            "units": {"input": self.unit, "output": OUTPUT_UNIT, "gsens": "(rad/s)/(m/s^2)"},
            "parameters": {k: np.asarray(getattr(self, k)).tolist() for k in _SHAPES},
            "std": {k: np.asarray(self.std[k]).tolist() for k in _SHAPES},
            "apply": {"matrix": C.tolist(), "offset": c.tolist(), "acc_matrix": D.tolist(), "equation": EQUATION},
            "fit": _plain(dict(self.fit)),
        }

    @classmethod
    def from_dict(cls, d: Any, path: str) -> "GyroCalibration":
        """The ``gyroscope:`` section of a calibration file (GyroSection), with its derived map checked."""
        g = fill(GyroSection, d, path, "gyroscope")
        vals = {k: np.array(getattr(g.parameters, k), float) for k in _SHAPES}
        std = {k: np.array(getattr(g.std, k), float) for k in _SHAPES}
        fix = "restore the file imucal wrote"
        if np.any(vals["scale"] == 0) or np.any(np.diag(vals["misalignment"]) != 1.0):
            raise ImucalError("scales must be non-zero and the misalignment's diagonal 1", file=path,
                              field="gyroscope.parameters", fix=fix)
        if abs(np.linalg.det(vals["misalignment"])) < 1e-6:
            raise ImucalError("the misalignment matrix is singular", file=path, field="gyroscope.parameters", fix=fix)
        out = cls(unit=g.units.input, std=std, fit=dict(g.fit), **vals)
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


def _check_derived(g: GyroCalibration, apply: Any, path: str) -> None:
    if apply is None:
        return
    C, c, D = g.rate_map()
    for key, want in (("matrix", C), ("offset", c), ("acc_matrix", D)):
        try:
            got = np.array(apply.get(key), dtype=float) if isinstance(apply, Mapping) else None
        except (TypeError, ValueError, OverflowError):
            got = None
        if got is None or got.shape != want.shape or not np.allclose(got, want, rtol=DERIVED_RTOL,
                                                                    atol=DERIVED_RTOL * np.abs(want).max(initial=1e-300)):
            raise ImucalError("does not match the parameters (edited by hand?)", file=path,
                              field=f"gyroscope.apply.{key}",
                              fix="edit the parameters, not the derived apply map, or restore the file")


def _plain(x: Any) -> Any:
    """Numbers and containers as YAML's safe dumper writes them."""
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, np.ndarray)):
        return [_plain(v) for v in np.asarray(x, dtype=object).tolist()] if isinstance(x, np.ndarray) else [_plain(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer, bool, int)) and not isinstance(x, bool):
        return int(x)
    return x
