"""Export a calibration to the formats the peers' tools read (issue 14).

The paper's model is an affine map: the Theorem's a = A raw + c (A lower triangular, c = -A s)
is factored into each peer's convention, exactly where the peer holds a full matrix:

  imutk      imu_tk's .calib text: a = T K (raw - b), T unit-diagonal misalignment, K diagonal
             scale, b bias (imu_tk/calibration.h, CalibratedTriad_::load/save layout: T, K, b).
  madlab     mad-lab-fau/imucal's FerrarisCalibrationInfo JSON, format 2.0:
             a = R_a^-1 K_a^-1 (raw - b_a), K_a diagonal sensitivities, R_a rows unit vectors.
             The gyroscope fields hold the identity (imucal's file holds no gyroscope yet).
  matrix     plain JSON (or CSV by the file's ending) of the matrix and offset: a = matrix raw + offset.
  kalibr     Kalibr's imu.yaml with scale-misalignment intrinsics (imucal.export.kalibr): M = A^-1
             exactly; Kalibr's bias is estimated online, not an intrinsic.
  ardupilot  ArduPilot parameters, px4 PX4 parameters (imucal.export.autopilot): offset and
             diagonal scale only; the misalignment they cannot hold is measured and stated.

Effects (temperature, drift, nonlinearity) are not affine: every format gets the map at the
effects' reference point, and the export says what it drops (``Exported.notes``).
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Callable

import numpy as np

from imucal.calibration.frozen import Calibration
from imucal.constants import SI_ACCEL_UNIT
from imucal.errors import ImucalError


@dataclass(frozen=True)
class KalibrNoise:
    """Kalibr's accelerometer noise fields, from a still segment (imucal.analysis.noise)."""

    accelerometer_noise_density: float  #: [m/s^2/sqrt(Hz)]
    accelerometer_random_walk: float | None  #: [m/s^3/sqrt(Hz)]; None when the curve shows no +1/2 slope
    update_rate: float  #: [Hz]
    segment: str  #: which samples, for the file's comment


@dataclass(frozen=True)
class ExportOptions:
    filename: str = ""  #: the output's name (matrix: .csv or JSON)
    noise: KalibrNoise | None = None  #: kalibr: noise fields, when a still segment was given
    rostopic: str = "/imu0"  #: kalibr: the IMU topic


@dataclass(frozen=True)
class Exported:
    text: str
    #: what the format cannot hold, with the error that leaves (printed by `imucal export`)
    notes: tuple[str, ...] = ()


def affine(cal: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """A and s with a = A (raw - s) (Theorem); with effects, at their reference point."""
    A, _ = cal.linear_map()
    return np.asarray(A, float), np.asarray(cal.values[0:3], float)


def dropped_effects(cal: Calibration) -> tuple[str, ...]:
    """What an affine format loses of a calibration with effects, in one sentence (or nothing)."""
    if not cal.effects:
        return ()
    names = ", ".join(f"{n} ({''.join('xyz'[a] for a in ax)})" for n, ax in cal.effects)
    where = []
    tref = sorted({p.value for n, p in cal.params.items() if n.endswith("_tref")})
    if tref:
        where.append(f"at the reference temperature {', '.join(f'{t:g}' for t in tref)} degC")
    if "time" in cal.covariates:
        where.append("at t = 0 s (the recording's start)")
    if any(n == "scale_nonlinearity" for n, _ in cal.effects):
        where.append("without the quadratic term")
    return (f"effects not exported: {names}; the map written is the calibration's {' and '.join(where)} "
            "(`imucal codegen` keeps every effect)",)


def _num(x: float) -> str:
    return repr(float(x))


def to_imutk(cal: Calibration, opts: ExportOptions) -> Exported:
    """imu_tk's .calib: T (3 lines), blank, K (3 lines), blank, b (3 lines)."""
    A, s = affine(cal)
    K = np.diag(np.diag(A))  # T has a unit diagonal, so K takes A's diagonal
    T = A @ np.linalg.inv(K)
    rows = [" ".join(_num(v) for v in r) for r in T] + [""] + [" ".join(_num(v) for v in r) for r in K]
    return Exported("\n".join(rows + [""] + [_num(v) for v in s]) + "\n", dropped_effects(cal))


def to_madlab(cal: Calibration, opts: ExportOptions) -> Exported:
    """mad-lab-fau/imucal FerrarisCalibrationInfo JSON (accelerometer; gyroscope identity)."""
    A, s = affine(cal)
    Minv = np.linalg.inv(A)  # raw - b = K R a
    k = np.linalg.norm(Minv, axis=1)
    notes = dropped_effects(cal)
    d = {
        "acc_unit": SI_ACCEL_UNIT, "gyr_unit": "deg/s", "from_acc_unit": cal.raw_unit, "from_gyr_unit": "a.u.",
        "comment": " ".join(("exported by imucal; no gyroscope calibration (identity)",) + notes),
        "K_a": np.diag(k).tolist(), "R_a": (Minv / k[:, None]).tolist(), "b_a": s.tolist(),
        "K_g": np.eye(3).tolist(), "R_g": np.eye(3).tolist(), "K_ga": np.zeros((3, 3)).tolist(),
        "b_g": [0.0, 0.0, 0.0], "cal_type": "Ferraris", "_format_version": "2.0",
    }
    return Exported(json.dumps(d, indent=4) + "\n", notes + ("gyroscope fields are the identity",))


def to_matrix(cal: Calibration, opts: ExportOptions) -> Exported:
    A, s = affine(cal)
    c = -A @ s
    notes = dropped_effects(cal)
    if opts.filename.lower().endswith(".csv"):
        lines = ["# a = matrix @ raw + offset; columns m1,m2,m3,offset; "
                 f"raw in {cal.raw_unit}, a in {SI_ACCEL_UNIT}"] + [f"# {n}" for n in notes]
        lines += [",".join(_num(v) for v in (*A[i], c[i])) for i in range(3)]
        return Exported("\n".join(lines) + "\n", notes)
    d = {"format": "imucal-affine", "equation": "a = matrix @ raw + offset", "input_unit": cal.raw_unit,
         "output_unit": SI_ACCEL_UNIT, "matrix": A.tolist(), "offset": c.tolist()}
    if notes:
        d["note"] = " ".join(notes)
    return Exported(json.dumps(d, indent=2) + "\n", notes)


def _kalibr(cal: Calibration, opts: ExportOptions) -> Exported:
    from imucal.export.kalibr import to_kalibr

    return to_kalibr(cal, opts)


def _ardupilot(cal: Calibration, opts: ExportOptions) -> Exported:
    from imucal.export.autopilot import to_ardupilot

    return to_ardupilot(cal, opts)


def _px4(cal: Calibration, opts: ExportOptions) -> Exported:
    from imucal.export.autopilot import to_px4

    return to_px4(cal, opts)


#: Format name -> (writer, what it is).
FORMATS: dict[str, tuple[Callable[[Calibration, ExportOptions], Exported], str]] = {
    "imutk": (to_imutk, "imu_tk .calib text (a = T K (raw - b))"),
    "madlab": (to_madlab, "mad-lab-fau/imucal Ferraris JSON 2.0 (a = R_a^-1 K_a^-1 (raw - b_a))"),
    "matrix": (to_matrix, "JSON matrix and offset (a = matrix raw + offset); CSV when the file ends in .csv"),
    "kalibr": (_kalibr, "Kalibr imu.yaml, scale-misalignment intrinsics (raw = M a + bias)"),
    "ardupilot": (_ardupilot, "ArduPilot parameters INS_ACCOFFS/INS_ACCSCAL (a = (raw - offset) * scale)"),
    "px4": (_px4, "PX4 parameters CAL_ACC0_*OFF/*SCALE (a = (raw - offset) * scale)"),
}


def export(cal: Calibration, fmt: str, opts: ExportOptions = ExportOptions()) -> Exported:
    """The calibration in format ``fmt``, with what the format could not hold."""
    if fmt not in FORMATS:
        raise ImucalError(f"unknown format {fmt!r}", field="--format", fix=f"use one of {', '.join(FORMATS)}")
    return FORMATS[fmt][0](cal, opts)


def export_text(cal: Calibration, fmt: str, filename: str = "") -> str:
    """The calibration's text in format ``fmt`` (see :func:`export` for the notes)."""
    return export(cal, fmt, ExportOptions(filename=filename)).text
