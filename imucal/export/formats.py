"""Export a calibration to the formats the peers' tools read (issue 14, first formats).

Every format here holds an affine map, so the paper's model exports exactly: the Theorem's map
a = A raw + c (A lower triangular, c = -A s) is factored into each peer's convention.

  imutk    imu_tk's .calib text: a = T K (raw - b), T unit-diagonal misalignment, K diagonal
           scale, b bias (imu_tk/calibration.h, CalibratedTriad_::load/save layout: T, K, b).
  madlab   mad-lab-fau/imucal's FerrarisCalibrationInfo JSON, format 2.0:
           a = R_a^-1 K_a^-1 (raw - b_a), K_a diagonal sensitivities, R_a rows unit vectors.
           The gyroscope fields hold the identity (imucal's file holds no gyroscope yet).
  matrix   plain JSON (or CSV by the file's ending) of the matrix and offset: a = matrix raw + offset.

A calibration with effects (temperature, drift, nonlinearity) is not an affine map: it is refused,
since no format here can hold it (the generated C can).
"""
from __future__ import annotations

import json
from typing import Callable

import numpy as np

from imucal.calibration.frozen import Calibration
from imucal.constants import SI_ACCEL_UNIT
from imucal.errors import ImucalError


def _affine(cal: Calibration, fmt: str) -> tuple[np.ndarray, np.ndarray]:
    """A and s with a = A (raw - s) (Theorem)."""
    if cal.effects:
        names = ", ".join(n for n, _ in cal.effects)
        raise ImucalError(f"the calibration has effects ({names}): format {fmt} holds only an affine map",
                          field="--format", fix="export a calibration without effects, or use `imucal codegen`")
    A, _ = cal.linear_map()
    return np.asarray(A, float), np.asarray(cal.values[0:3], float)


def _num(x: float) -> str:
    return repr(float(x))


def to_imutk(cal: Calibration) -> str:
    """imu_tk's .calib: T (3 lines), blank, K (3 lines), blank, b (3 lines)."""
    A, s = _affine(cal, "imutk")
    K = np.diag(np.diag(A))  # T has a unit diagonal, so K takes A's diagonal
    T = A @ np.linalg.inv(K)
    rows = [" ".join(_num(v) for v in r) for r in T] + [""] + [" ".join(_num(v) for v in r) for r in K]
    return "\n".join(rows + [""] + [_num(v) for v in s]) + "\n"


def to_madlab(cal: Calibration) -> str:
    """mad-lab-fau/imucal FerrarisCalibrationInfo JSON (accelerometer; gyroscope identity)."""
    A, s = _affine(cal, "madlab")
    Minv = np.linalg.inv(A)  # raw - b = K R a
    k = np.linalg.norm(Minv, axis=1)
    d = {
        "acc_unit": SI_ACCEL_UNIT, "gyr_unit": "deg/s", "from_acc_unit": cal.raw_unit, "from_gyr_unit": "a.u.",
        "comment": "exported by imucal; no gyroscope calibration (identity)",
        "K_a": np.diag(k).tolist(), "R_a": (Minv / k[:, None]).tolist(), "b_a": s.tolist(),
        "K_g": np.eye(3).tolist(), "R_g": np.eye(3).tolist(), "K_ga": np.zeros((3, 3)).tolist(),
        "b_g": [0.0, 0.0, 0.0], "cal_type": "Ferraris", "_format_version": "2.0",
    }
    return json.dumps(d, indent=4) + "\n"


def to_matrix_json(cal: Calibration) -> str:
    A, s = _affine(cal, "matrix")
    return json.dumps({"format": "imucal-affine", "equation": "a = matrix @ raw + offset",
                       "input_unit": cal.raw_unit, "output_unit": SI_ACCEL_UNIT,
                       "matrix": A.tolist(), "offset": (-A @ s).tolist()}, indent=2) + "\n"


def to_matrix_csv(cal: Calibration) -> str:
    A, s = _affine(cal, "matrix")
    c = -A @ s
    lines = ["# a = matrix @ raw + offset; columns m1,m2,m3,offset; "
             f"raw in {cal.raw_unit}, a in {SI_ACCEL_UNIT}"]
    lines += [",".join(_num(v) for v in (*A[i], c[i])) for i in range(3)]
    return "\n".join(lines) + "\n"


#: Format name -> (writer, what it is).
FORMATS: dict[str, tuple[Callable[[Calibration], str], str]] = {
    "imutk": (to_imutk, "imu_tk .calib text (a = T K (raw - b))"),
    "madlab": (to_madlab, "mad-lab-fau/imucal Ferraris JSON 2.0 (a = R_a^-1 K_a^-1 (raw - b_a))"),
    "matrix": (to_matrix_json, "JSON matrix and offset (a = matrix raw + offset); CSV when the file ends in .csv"),
}


def export_text(cal: Calibration, fmt: str, filename: str = "") -> str:
    """The calibration in format ``fmt``."""
    if fmt not in FORMATS:
        raise ImucalError(f"unknown format {fmt!r}", field="--format", fix=f"use one of {', '.join(FORMATS)}")
    if fmt == "matrix" and filename.lower().endswith(".csv"):
        return to_matrix_csv(cal)
    return FORMATS[fmt][0](cal)
