"""Other tools' calibration files read back, strictly, as one affine map a = M (raw - o), and the
gyroscope part where the file holds one, omega = C (raw_g - o_g) - D a [rad/s] (GyroMap).

Every peer model here is affine, a = M (raw - o). Inverting, raw - o = M^-1 a, and row i of
M^-1 is b_i e_i^T (Eq. theModel with Lemma 1: raw_i = s_i + b_i e_i . a). Hence
  s = o,  b_i = |row_i(M^-1)|,  e_i = row_i / b_i,  cos(angle_ij) = e_i . e_j.
The frame of a peer's output differs from the Theorem's by a rotation, which leaves |a| and
the nine parameters unchanged.

Each reader opens its file through imucal.files.inputs, refuses non-finite, huge or
non-numeric values, missing and unknown fields, and singular maps, in one line. The writers
(imucal.export.formats) cite each peer's formula; the readers invert the same convention.
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal, Mapping

import numpy as np

from imucal.errors import ImucalError, short
from imucal.files.inputs import read_input_text, read_json
from imucal.files.schema import fill, rule

#: Largest magnitude accepted for any number in a peer's file: far above any offset in counts
#: (2^32) or scale, far below float overflow in the products that follow.
MAX_MAGNITUDE = 1e12
#: Largest condition number of a peer's matrix: beyond it the map loses every digit of a reading.
MAX_CONDITION = 1e12
#: A number in a peer's mapping file (imucal.files.schema): finite, |x| <= MAX_MAGNITUDE.
MAGNITUDE = rule(ge=-MAX_MAGNITUDE, le=MAX_MAGNITUDE, fix="regenerate the file with the tool that made it")
Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]


@dataclass(frozen=True)
class GyroMap:
    """omega = C (raw - o) - D a [rad/s], a [m/s^2] the same file's calibrated acceleration."""

    C: np.ndarray  #: [rad/s per raw]
    o: np.ndarray  #: [raw]
    D: np.ndarray  #: [(rad/s) per (m/s^2)]; zero where the format has no g-sensitivity

    def apply(self, raw: np.ndarray, acc: np.ndarray | None = None) -> np.ndarray:
        w = (np.asarray(raw, float) - self.o) @ self.C.T
        if np.any(self.D != 0):
            if acc is None:
                raise ImucalError("this gyroscope calibration has a g-sensitivity", field="acc",
                                  fix="pass the calibrated acceleration of the same samples")
            w = w - np.asarray(acc, float) @ self.D.T
        return w


@dataclass(frozen=True)
class ThermalOffset:
    """An autopilot's temperature offset, subtracted from the reading before its map [raw]:
    q(clamp(T, tmin, tmax) - origin) - q(clamp(t_cal, tmin, tmax) - origin), q(x) = sum_k c_k x^k
    (ArduPilot: origin 35 degC, t_cal INS_ACC1_CALTEMP; PX4: origin TC_A0_TREF, no t_cal term)."""

    coeffs: np.ndarray  #: (4, 3), c_0..c_3 per axis [raw / degC^k]
    origin: float  #: [degC]
    tmin: float  #: [degC]
    tmax: float  #: [degC]
    t_cal: float | None = None  #: [degC]; None: no second term

    def _q(self, temp: np.ndarray) -> np.ndarray:
        x = np.clip(np.asarray(temp, float), self.tmin, self.tmax) - self.origin
        return np.vander(np.atleast_1d(x), 4, increasing=True) @ self.coeffs

    def offset(self, temp: np.ndarray) -> np.ndarray:
        """(n, 3) offset at each temperature [raw]."""
        out = self._q(temp)
        return out if self.t_cal is None else out - self._q(np.array([self.t_cal]))


@dataclass(frozen=True)
class AffineCalibration:
    """a = M (raw - o - thermal(T)): a peer's calibration, with the nine parameters it implies."""

    M: np.ndarray
    o: np.ndarray
    source: str = ""
    fmt: str = ""
    #: what the file holds beside the map (noise densities, rate, topic, temperature terms)
    extra: Mapping[str, Any] = field(default_factory=dict)
    gyro: GyroMap | None = None  #: the gyroscope part, when the file holds one
    thermal: ThermalOffset | None = None  #: ArduPilot's INS_TCAL1_*, PX4's TC_A0_*, when enabled

    @property
    def covariates(self) -> tuple[str, ...]:
        return ("temp",) if self.thermal is not None else ()

    def apply(self, raw: np.ndarray, covariates: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        raw = np.asarray(raw, float)
        if self.thermal is not None:
            if not covariates or "temp" not in covariates:
                raise ImucalError("this calibration has temperature terms", field="covariates",
                                  fix="pass the temperature of the samples (temp in deg C)")
            raw = raw - self.thermal.offset(np.broadcast_to(covariates["temp"], raw.shape[:1]))
        return (raw - self.o) @ self.M.T

    def nine_parameters(self) -> dict[str, float]:
        Minv = np.linalg.inv(self.M)
        b = np.linalg.norm(Minv, axis=1)
        e = Minv / b[:, None]
        ang = np.arccos(np.clip([e[0] @ e[1], e[0] @ e[2], e[1] @ e[2]], -1, 1))
        out = {f"s{i+1}": float(self.o[i]) for i in range(3)}
        out.update({f"b{i+1}": float(b[i]) for i in range(3)})
        out.update(dict(zip(("phi", "psi", "theta"), map(float, ang))))
        return out


# --- strict values -------------------------------------------------------------------------
def numbers(value: Any, shape: tuple[int, ...], path: str, field_: str) -> np.ndarray:
    """A float array of ``shape`` from nested lists of numbers: finite, |x| <= MAX_MAGNITUDE."""
    def flat(v: Any, depth: int) -> list[float]:
        if depth < len(shape):
            if not isinstance(v, (list, tuple)) or len(v) != shape[depth]:
                raise ImucalError(f"{short(v)} is not a list of {shape[depth]}", file=path, field=field_,
                                  fix=f"give a {'x'.join(map(str, shape))} array of numbers")
            return [x for item in v for x in flat(item, depth + 1)]
        return [number(v, path, field_)]

    return np.array(flat(value, 0), float).reshape(shape)


def number(v: Any, path: str, field_: str) -> float:
    """One finite number no larger than MAX_MAGNITUDE (bools and text refused)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ImucalError(f"{short(v)} is not a number", file=path, field=field_,
                          fix="write a plain number there, as the tool that made the file does")
    try:
        x = float(v)
    except OverflowError:
        raise ImucalError(f"{short(v)} is too large for a float", file=path, field=field_,
                          fix="regenerate the file with the tool that made it") from None
    if not math.isfinite(x) or abs(x) > MAX_MAGNITUDE:
        raise ImucalError(f"{short(v)} is not a finite number of magnitude <= {MAX_MAGNITUDE:g}", file=path,
                          field=field_, fix="regenerate the file with the tool that made it")
    return x


def _text_number(tok: str, path: str, field_: str) -> float:
    try:
        return number(float(tok), path, field_)
    except ValueError:
        raise ImucalError(f"{short(tok)} is not a number", file=path, field=field_,
                          fix="the file holds numbers only: regenerate it with the tool that made it") from None


def checked(M: np.ndarray, o: np.ndarray, path: str, field_: str, fmt: str,
            extra: Mapping[str, Any] | None = None) -> AffineCalibration:
    """The map, refused when singular or so ill-conditioned that it loses every digit."""
    cond = np.linalg.cond(M)
    if not (np.isfinite(cond) and cond <= MAX_CONDITION):
        raise ImucalError(f"the matrix is singular or ill-conditioned (condition number {cond:.3g})", file=path,
                          field=field_, fix="check the file: a calibration matrix is close to a scaled identity")
    return AffineCalibration(M=M, o=o, source=path, fmt=fmt, extra=dict(extra or {}))


def checked_gyro(C: np.ndarray, o: np.ndarray, D: np.ndarray, path: str, field_: str) -> GyroMap:
    """A gyroscope map, refused when its matrix is singular or ill-conditioned."""
    checked(C, o, path, field_, "")
    return GyroMap(C=C, o=o, D=D)


# --- readers --------------------------------------------------------------------------------
def _imutk_triad(path: str) -> tuple[np.ndarray, np.ndarray]:
    """T K and b of one imu_tk .calib text: T (3x3), blank, K (3x3), blank, b (3 lines)."""
    nums = [_text_number(x, path, "calib") for x in read_input_text(path, field="imu_tk calib").split()]
    if len(nums) != 21:
        raise ImucalError(f"expected 21 numbers (T, K, b), found {len(nums)}", file=path, field="calib",
                          fix="give imu_tk's .calib file as it wrote it: T (3x3), K (3x3), b (3)")
    T = np.array(nums[:9]).reshape(3, 3)
    K = np.array(nums[9:18]).reshape(3, 3)
    return T @ K, np.array(nums[18:])


def read_imutk_calib(path: str | Path, gyro_path: str | Path | None = None) -> AffineCalibration:
    """imu_tk's .calib text: a = T K (raw - b); with ``gyro_path``, its gyroscope .calib (imu_tk
    keeps it in a second file): omega = T_g K_g (raw_g - b_g), no g-sensitivity."""
    p = str(path)
    TK, b = _imutk_triad(p)
    out = checked(TK, b, p, "calib", "imutk")
    if gyro_path is None:
        return out
    C, o = _imutk_triad(str(gyro_path))
    return replace(out, gyro=checked_gyro(C, o, np.zeros((3, 3)), str(gyro_path), "calib"))


def read_tomisuarez_params(path: str | Path) -> AffineCalibration:
    """tomisuarez2/ImuCalibration params_acc.csv: a_yz, a_zy, a_zx [rad], K (3) [m/s^2 per count],
    b (3) [counts]; a = T K (raw + b) with T = [[1, -a_yz, a_zy], [0, 1, -a_zx], [0, 0, 1]]."""
    p = str(path)
    try:
        v = np.loadtxt(io.StringIO(read_input_text(path, field="params")), delimiter=",").ravel()
    except ValueError as exc:
        raise ImucalError(f"cannot read: {short(str(exc), 80)}", file=p, field="params",
                          fix="give params_acc.csv as ImuCalibration wrote it: 9 comma-separated numbers") from None
    if v.size != 9:
        raise ImucalError(f"expected 9 numbers, found {v.size}", file=p, field="params",
                          fix="give a_yz, a_zy, a_zx, K (3), b (3) as ImuCalibration writes them")
    v = numbers(v.tolist(), (9,), p, "params")
    a_yz, a_zy, a_zx = v[:3]
    T = np.array([[1, -a_yz, a_zy], [0, 1, -a_zx], [0, 0, 1]])
    return checked(T @ np.diag(v[3:6]), -v[6:9], p, "params", "tomisuarez")  # "+ b": offset is -b


#: The gyroscope's fields of a mad-lab-fau/imucal Ferraris file, and the output units imucal converts.
MADLAB_GYRO = ("K_g", "R_g", "b_g", "K_ga")
MADLAB_RATE_UNITS = {"deg/s": math.pi / 180.0, "rad/s": 1.0}


@dataclass(frozen=True, kw_only=True)
class MadlabFile:
    """mad-lab-fau/imucal FerrarisCalibrationInfo / TurnTableCalibrationInfo fields (format 2.0)."""

    cal_type: Literal["Ferraris", "Turntable"] = field(metadata=rule(  # CalibrationInfo.CAL_TYPE
        msg="cal_type {value} is not Ferraris or Turntable"))
    K_a: Mat3 = field(metadata=MAGNITUDE)
    R_a: Mat3 = field(metadata=MAGNITUDE)
    b_a: Vec3 = field(metadata=MAGNITUDE)
    K_g: Mat3 | None = field(default=None, metadata=MAGNITUDE)
    R_g: Mat3 | None = field(default=None, metadata=MAGNITUDE)
    K_ga: Mat3 | None = field(default=None, metadata=MAGNITUDE)
    b_g: Vec3 | None = field(default=None, metadata=MAGNITUDE)
    acc_unit: Any = None
    gyr_unit: str = "deg/s"  #: FerrarisCalibrationInfo's default
    from_acc_unit: Any = None
    from_gyr_unit: Any = None
    comment: Any = None
    _format_version: Any = None

    def __post_init__(self) -> None:
        held = [k for k in MADLAB_GYRO if getattr(self, k) is not None]
        if held and len(held) != len(MADLAB_GYRO):
            raise ImucalError("missing", field=next(k for k in MADLAB_GYRO if getattr(self, k) is None),
                              fix=f"a gyroscope part needs {', '.join(MADLAB_GYRO)}")
        if held and self.gyr_unit not in MADLAB_RATE_UNITS:
            raise ImucalError(f"gyr_unit {short(self.gyr_unit)} is not one of {', '.join(MADLAB_RATE_UNITS)}",
                              field="gyr_unit", fix="the calibrated rate's unit: deg/s (Ferraris) or rad/s")


def read_madlab_calibration(path: str | Path) -> AffineCalibration:
    """mad-lab-fau/imucal calibration JSON: a = R_a^-1 K_a^-1 (raw - b_a) and, when the file has
    them, gyr = R_g^-1 K_g^-1 (gyr_raw - K_ga a - b_g) in ``gyr_unit`` (ferraris_calibration_info.py)."""
    p = str(path)
    d = fill(MadlabFile, read_json(p, "calibration"), p)
    K, R, b = (np.array(x, float) for x in (d.K_a, d.R_a, d.b_a))
    for name, m in (("K_a", K), ("R_a", R)):
        checked(m, b, p, name, "madlab")
    out = checked(np.linalg.inv(R) @ np.linalg.inv(K), b, p, "K_a/R_a", "madlab")
    if d.K_g is None:
        return out
    Kg, Rg, bg, Kga = (np.array(x, float) for x in (d.K_g, d.R_g, d.b_g, d.K_ga))
    for name, m in (("K_g", Kg), ("R_g", Rg)):
        checked(m, bg, p, name, "madlab")
    C = MADLAB_RATE_UNITS[d.gyr_unit] * np.linalg.inv(Rg) @ np.linalg.inv(Kg)  # to rad/s
    return replace(out, gyro=checked_gyro(C, bg, C @ Kga, p, "K_g/R_g"))


@dataclass(frozen=True)
class MatrixGyro:
    """The gyroscope section of imucal's plain matrix file: omega = matrix raw + offset - acc_matrix a."""

    matrix: Mat3 = field(metadata=MAGNITUDE)
    offset: Vec3 = field(metadata=MAGNITUDE)
    acc_matrix: Mat3 = field(metadata=MAGNITUDE)
    equation: Any = None
    input_unit: Any = None
    output_unit: Literal["rad/s"] = field(default="rad/s", metadata=rule(msg="{value} is not rad/s"))


@dataclass(frozen=True, kw_only=True)
class MatrixFile:
    """imucal's plain matrix file (JSON): a = matrix raw + offset."""

    format: Literal["imucal-affine"] = field(metadata=rule(msg="format {value} is not 'imucal-affine'"))
    matrix: Mat3 = field(metadata=MAGNITUDE)
    offset: Vec3 = field(metadata=MAGNITUDE)
    gyroscope: MatrixGyro | None = None
    equation: Any = None
    input_unit: Any = None
    output_unit: Any = None
    note: Any = None


def _matrix_gyro(C: np.ndarray, c: np.ndarray, D: np.ndarray, p: str, field_: str) -> GyroMap:
    checked(C, c, p, field_, "matrix")
    return checked_gyro(C, -np.linalg.solve(C, c), D, p, field_)  # omega = C raw + c - D a


def read_matrix(path: str | Path) -> AffineCalibration:
    """imucal's plain matrix: JSON {matrix, offset[, gyroscope]} or CSV rows m1,m2,m3,offset (then,
    for the gyroscope, m1,m2,m3,offset,acc_m1,acc_m2,acc_m3); a = matrix raw + offset,
    omega = matrix raw_g + offset - acc_matrix a."""
    p = str(path)
    gyro = None
    if p.lower().endswith(".csv"):
        rows = [ln for ln in read_input_text(p, field="matrix").splitlines()
                if ln.strip() and not ln.lstrip().startswith("#")]
        widths = [len(r.split(",")) for r in rows]
        if widths not in ([4] * 3, [4] * 3 + [7] * 3):
            raise ImucalError(f"expected 3 rows of 4 numbers (m1,m2,m3,offset), then optionally 3 rows of 7 "
                              f"(the gyroscope), found rows of {short(widths)} numbers", file=p, field="matrix",
                              fix="write m1,m2,m3,offset on each of 3 lines (a = matrix raw + offset)")
        v = [[_text_number(x, p, "matrix") for x in r.split(",")] for r in rows]
        a = np.array(v[:3])
        A, c = a[:, :3], a[:, 3]
        if len(v) == 6:
            g = np.array(v[3:])
            gyro = _matrix_gyro(g[:, :3], g[:, 3], g[:, 4:], p, "matrix")
    else:
        d = fill(MatrixFile, read_json(p, "matrix"), p)
        A, c = np.array(d.matrix, float), np.array(d.offset, float)
        if d.gyroscope is not None:
            g = d.gyroscope
            gyro = _matrix_gyro(*(np.array(x, float) for x in (g.matrix, g.offset, g.acc_matrix)), p,
                                "gyroscope.matrix")
    checked(A, c, p, "matrix", "matrix")
    return replace(checked(A, -np.linalg.solve(A, c), p, "matrix", "matrix"), gyro=gyro)  # a = A (raw - o)
