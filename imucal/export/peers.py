"""Other tools' calibration files read back, strictly, as one affine map a = M (raw - o).

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
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from imucal.errors import ImucalError, short
from imucal.files.inputs import read_input_text

#: Largest magnitude accepted for any number in a peer's file: far above any offset in counts
#: (2^32) or scale, far below float overflow in the products that follow.
MAX_MAGNITUDE = 1e12
#: Largest condition number of a peer's matrix: beyond it the map loses every digit of a reading.
MAX_CONDITION = 1e12


@dataclass(frozen=True)
class AffineCalibration:
    """a = M (raw - o): a peer's calibration, with the nine parameters it implies."""

    M: np.ndarray
    o: np.ndarray
    source: str = ""
    fmt: str = ""
    #: what the file holds beside the map (noise densities, rate, topic, temperature terms)
    extra: Mapping[str, Any] = field(default_factory=dict)

    def apply(self, raw: np.ndarray) -> np.ndarray:
        return (np.asarray(raw, float) - self.o) @ self.M.T

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
        raise ImucalError(f"{short(v)} is not a number", file=path, field=field_)
    try:
        x = float(v)
    except OverflowError:
        raise ImucalError(f"{short(v)} is too large for a float", file=path, field=field_) from None
    if not math.isfinite(x) or abs(x) > MAX_MAGNITUDE:
        raise ImucalError(f"{short(v)} is not a finite number of magnitude <= {MAX_MAGNITUDE:g}", file=path,
                          field=field_, fix="regenerate the file with the tool that made it")
    return x


def _text_number(tok: str, path: str, field_: str) -> float:
    try:
        return number(float(tok), path, field_)
    except ValueError:
        raise ImucalError(f"{short(tok)} is not a number", file=path, field=field_) from None


def checked(M: np.ndarray, o: np.ndarray, path: str, field_: str, fmt: str,
            extra: Mapping[str, Any] | None = None) -> AffineCalibration:
    """The map, refused when singular or so ill-conditioned that it loses every digit."""
    cond = np.linalg.cond(M)
    if not (np.isfinite(cond) and cond <= MAX_CONDITION):
        raise ImucalError(f"the matrix is singular or ill-conditioned (condition number {cond:.3g})", file=path,
                          field=field_, fix="check the file: a calibration matrix is close to a scaled identity")
    return AffineCalibration(M=M, o=o, source=path, fmt=fmt, extra=dict(extra or {}))


def _keys(d: Any, required: tuple[str, ...], allowed: tuple[str, ...], path: str, what: str) -> Mapping:
    if not isinstance(d, Mapping):
        raise ImucalError(f"is not {what} (top level is not a mapping)", file=path, field="format")
    unknown = [k for k in d if k not in allowed]
    if unknown:
        raise ImucalError(f"unknown field {short(str(unknown[0]))}", file=path, field=str(unknown[0])[:40],
                          fix=f"{what} has only {', '.join(allowed)}")
    missing = [k for k in required if k not in d]
    if missing:
        raise ImucalError("missing", file=path, field=missing[0], fix=f"{what} needs {', '.join(required)}")
    return d


def _json(path: str, field_: str) -> Any:
    """JSON without NaN/Infinity constants (not JSON) and without duplicate keys."""
    def no_constant(name: str) -> None:
        raise ValueError(f"{name} is not a JSON number")

    def no_duplicates(pairs: list) -> dict:
        d: dict = {}
        for k, v in pairs:
            if k in d:
                raise ValueError(f"duplicate key {short(k)}")
            d[k] = v
        return d

    try:
        return json.loads(read_input_text(path, field=field_), parse_constant=no_constant,
                          object_pairs_hook=no_duplicates)
    except (ValueError, RecursionError) as exc:
        raise ImucalError(f"is not valid JSON: {' '.join(str(exc).split())[:80]}", file=path, field=field_) from None


# --- readers --------------------------------------------------------------------------------
def read_imutk_calib(path: str | Path) -> AffineCalibration:
    """imu_tk's .calib text: T (3x3), blank, K (3x3), blank, b (3 lines); a = T K (raw - b)."""
    p = str(path)
    nums = [_text_number(x, p, "calib") for x in read_input_text(path, field="imu_tk calib").split()]
    if len(nums) != 21:
        raise ImucalError(f"expected 21 numbers (T, K, b), found {len(nums)}", file=p, field="calib")
    T = np.array(nums[:9]).reshape(3, 3)
    K = np.array(nums[9:18]).reshape(3, 3)
    return checked(T @ K, np.array(nums[18:]), p, "calib", "imutk")


def read_tomisuarez_params(path: str | Path) -> AffineCalibration:
    """tomisuarez2/ImuCalibration params_acc.csv: a_yz, a_zy, a_zx [rad], K (3) [m/s^2 per count],
    b (3) [counts]; a = T K (raw + b) with T = [[1, -a_yz, a_zy], [0, 1, -a_zx], [0, 0, 1]]."""
    p = str(path)
    try:
        v = np.loadtxt(io.StringIO(read_input_text(path, field="params")), delimiter=",").ravel()
    except ValueError as exc:
        raise ImucalError(f"cannot read: {short(str(exc), 80)}", file=p, field="params") from None
    if v.size != 9:
        raise ImucalError(f"expected 9 numbers, found {v.size}", file=p, field="params")
    v = numbers(v.tolist(), (9,), p, "params")
    a_yz, a_zy, a_zx = v[:3]
    T = np.array([[1, -a_yz, a_zy], [0, 1, -a_zx], [0, 0, 1]])
    return checked(T @ np.diag(v[3:6]), -v[6:9], p, "params", "tomisuarez")  # "+ b": offset is -b


#: mad-lab-fau/imucal FerrarisCalibrationInfo / TurnTableCalibrationInfo fields (format 2.0).
MADLAB_FIELDS = ("acc_unit", "gyr_unit", "from_acc_unit", "from_gyr_unit", "comment", "K_a", "R_a", "b_a",
                 "K_g", "R_g", "K_ga", "b_g", "cal_type", "_format_version")


def read_madlab_calibration(path: str | Path) -> AffineCalibration:
    """mad-lab-fau/imucal calibration JSON (accelerometer part): a = R_a^-1 K_a^-1 (raw - b_a)."""
    p = str(path)
    d = _keys(_json(p, "calibration"), ("K_a", "R_a", "b_a", "cal_type"), MADLAB_FIELDS, p,
              "a mad-lab-fau/imucal calibration")
    if d["cal_type"] not in ("Ferraris", "TurnTable"):
        raise ImucalError(f"cal_type {short(d['cal_type'])} is not Ferraris or TurnTable", file=p, field="cal_type")
    K, R = numbers(d["K_a"], (3, 3), p, "K_a"), numbers(d["R_a"], (3, 3), p, "R_a")
    b = numbers(d["b_a"], (3,), p, "b_a")
    for name, m in (("K_a", K), ("R_a", R)):
        checked(m, b, p, name, "madlab")
    return checked(np.linalg.inv(R) @ np.linalg.inv(K), b, p, "K_a/R_a", "madlab")


MATRIX_FIELDS = ("format", "equation", "input_unit", "output_unit", "matrix", "offset", "note")


def read_matrix(path: str | Path) -> AffineCalibration:
    """imucal's plain matrix: JSON {matrix, offset} or CSV rows m1,m2,m3,offset; a = matrix raw + offset."""
    p = str(path)
    if p.lower().endswith(".csv"):
        rows = [ln for ln in read_input_text(p, field="matrix").splitlines()
                if ln.strip() and not ln.lstrip().startswith("#")]
        if len(rows) != 3 or any(len(r.split(",")) != 4 for r in rows):
            raise ImucalError(f"expected 3 rows of 4 numbers (m1,m2,m3,offset), found {len(rows)} row(s)",
                              file=p, field="matrix")
        v = np.array([[_text_number(x, p, "matrix") for x in r.split(",")] for r in rows])
        A, c = v[:, :3], v[:, 3]
    else:
        d = _keys(_json(p, "matrix"), ("format", "matrix", "offset"), MATRIX_FIELDS, p, "an imucal matrix file")
        if d["format"] != "imucal-affine":
            raise ImucalError(f"format {short(d['format'])} is not 'imucal-affine'", file=p, field="format")
        A, c = numbers(d["matrix"], (3, 3), p, "matrix"), numbers(d["offset"], (3,), p, "offset")
    checked(A, c, p, "matrix", "matrix")
    return checked(A, -np.linalg.solve(A, c), p, "matrix", "matrix")  # a = A (raw - o), o = -A^-1 c


def read_kalibr(path: str | Path) -> AffineCalibration:
    """Kalibr imu.yaml with scale-misalignment intrinsics (see imucal.export.kalibr)."""
    from imucal.export.kalibr import read_kalibr_yaml

    return read_kalibr_yaml(path)


def read_ardupilot(path: str | Path) -> AffineCalibration:
    from imucal.export.autopilot import read_ardupilot_params

    return read_ardupilot_params(path)


def read_px4(path: str | Path) -> AffineCalibration:
    from imucal.export.autopilot import read_px4_params

    return read_px4_params(path)


def read_imucal(path: str | Path) -> Any:
    """imucal's own calibration.yaml (a Calibration: applies itself, with its effects)."""
    from imucal.calibration.fileformat import load_calibration

    return load_calibration(path)


#: Format name -> reader. The same names as the export formats, plus imucal's own file.
READERS: dict[str, Callable[[str | Path], Any]] = {
    "imucal": read_imucal, "imutk": read_imutk_calib, "madlab": read_madlab_calibration,
    "matrix": read_matrix, "kalibr": read_kalibr, "ardupilot": read_ardupilot, "px4": read_px4,
    "tomisuarez": read_tomisuarez_params,
}

_IMUCAL_TAG = re.compile(r"^format:\s*imucal-calibration\s*$", re.M)


def guess_format(path: str | Path) -> str:
    """The format of a calibration file from its name (and, for .yaml/.json, a look at its text)."""
    p = str(path).lower()
    for end, fmt in ((".calib", "imutk"), (".param", "ardupilot"), (".parm", "ardupilot"),
                     (".params", "px4"), (".csv", "matrix")):
        if p.endswith(end):
            return fmt
    if p.endswith((".yaml", ".yml")):
        return "imucal" if _IMUCAL_TAG.search(read_input_text(path, field="calibration")) else "kalibr"
    if p.endswith(".json"):
        return "madlab" if '"cal_type"' in read_input_text(path, field="calibration") else "matrix"
    raise ImucalError("cannot tell the calibration format from the file name", file=str(path), field="--format",
                      fix=f"give --format, one of {', '.join(READERS)}")


def read_peer(path: str | Path, fmt: str | None = None) -> Any:
    """Any calibration file: imucal's own (a Calibration) or a peer's (an AffineCalibration)."""
    fmt = fmt or guess_format(path)
    if fmt not in READERS:
        raise ImucalError(f"unknown format {short(fmt)}", field="--format", fix=f"use one of {', '.join(READERS)}")
    return READERS[fmt](path)
