"""Export a calibration to the formats the peers' tools read (issue 14).

The paper's model is an affine map: the Theorem's a = A raw + c (A lower triangular, c = -A s)
is factored into each peer's convention, exactly where the peer holds a full matrix; the
gyroscope's omega = C raw_g + c_g - D a likewise (imucal.export.gyro):

  imutk      imu_tk's .calib text: a = T K (raw - b), T unit-diagonal misalignment, K diagonal
             scale, b bias (imu_tk/calibration.h, CalibratedTriad_::load/save layout: T, K, b).
             The gyroscope goes to a second .calib, as imu_tk writes it (test_imu_calib.cpp:
             acc and gyro files), omega = T_g K_g (raw_g - b_g); imu_tk has no g-sensitivity.
  madlab     mad-lab-fau/imucal's FerrarisCalibrationInfo JSON, format 2.0:
             a = R_a^-1 K_a^-1 (raw - b_a),  gyr = R_g^-1 K_g^-1 (gyr_raw - K_ga a - b_g)
             (ferraris_calibration_info.py, _calibrate_acc, _calibrate_gyr, _calibrate_gyr_offsets),
             gyr in deg/s (FerrarisCalibration.OUT_GYR_UNIT); rows of R_a, R_g unit vectors.
  matrix     plain JSON (or CSV by the file's ending) of the matrices and offsets: a = matrix raw +
             offset; omega = matrix raw_g + offset - acc_matrix a.
  kalibr     Kalibr's imu.yaml with scale-misalignment intrinsics (imucal.export.kalibr): M = A^-1
             exactly, the gyroscope's M, A, C_gyro_i exactly; Kalibr's biases are estimated online.
  ardupilot  ArduPilot parameters, px4 PX4 parameters (imucal.export.autopilot): offset and
             diagonal scale of the accelerometer, the gyroscope's offset only; what they cannot
             hold is measured and stated.

Effects (temperature, drift, nonlinearity) are not affine: every format gets the map at the
effects' reference point, and the export says what it drops (``Exported.notes``).
Text reaches these files through one escaping function per format (imucal.export.escape): the
CSV's comments through hash_comment, JSON through json.dumps; the .calib holds numbers only.
"""
from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from imucal.calibration.frozen import Calibration
from imucal.constants import SI_ACCEL_UNIT, SI_RATE_UNIT
from imucal.export.escape import hash_comment
from imucal.export.gyro import MADLAB_GYR_UNIT, forward, gsens_sentence, imutk_factors, madlab_factors
from imucal.model.sensor import MAGNETOMETER


@dataclass(frozen=True)
class KalibrNoise:
    """Kalibr's noise fields, from a still segment (imucal.analysis.noise); the gyroscope's when
    the calibration and the data have one."""

    accelerometer_noise_density: float  #: [m/s^2/sqrt(Hz)]
    accelerometer_random_walk: float | None  #: [m/s^3/sqrt(Hz)]; None when the curve shows no +1/2 slope
    update_rate: float  #: [Hz]
    segment: str  #: which samples, for the file's comment
    gyroscope_noise_density: float | None = None  #: [rad/s/sqrt(Hz)]; None without gyro data
    gyroscope_random_walk: float | None = None  #: [rad/s^2/sqrt(Hz)]; None without gyro data or +1/2 slope


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
    #: the gyroscope's own file, for formats that keep it apart (imu_tk)
    gyro_text: str | None = None


def affine(cal: Calibration) -> tuple[np.ndarray, np.ndarray]:
    """A and s with a = A (raw - s) (Theorem); with effects, at their reference point."""
    A, _ = cal.linear_map()
    return np.asarray(A, float), np.asarray(cal.values[0:3], float)


def dropped_terms(cal: Calibration) -> tuple[str, ...]:
    """What an affine format loses of the other sensors (the magnetometer) and their terms (the gyroscope's bias(T)):
    one sentence each."""
    out = []
    for s in cal.attached:
        if s.kind == MAGNETOMETER:  # no affine peer format holds one
            out.append("magnetometer not exported: this format holds none (the ArduPilot and PX4 exports and "
                       "`imucal codegen` keep it)")
            continue
        ref = s.reference_inputs()
        if ref:
            names = ", ".join(f"{e.name} ({''.join('xyz'[a] for a in e.axes)})" for e in s.model.effects)
            at = " and ".join(f"{k} = {v:g}" + (" degC" if k == "temp" else " s") for k, v in ref.items())
            out.append(f"{s.kind} terms not exported: {names}; its map written is the calibration's at {at} "
                       "(`imucal codegen` and the ArduPilot and PX4 exports keep them)")
    return tuple(out)


def dropped_effects(cal: Calibration, attached: bool = True) -> tuple[str, ...]:
    """What an affine format loses of a calibration with effects, in one sentence (or nothing); with
    ``attached``, the other sensors' terms too (``dropped_terms``)."""
    if not cal.effects:
        return dropped_terms(cal) if attached else ()
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
            "(`imucal codegen` keeps every effect)",) + (dropped_terms(cal) if attached else ())


def _num(x: float) -> str:
    return repr(float(x))


def _calib_text(T: np.ndarray, K: np.ndarray, b: np.ndarray) -> str:
    rows = [" ".join(_num(v) for v in r) for r in T] + [""] + [" ".join(_num(v) for v in r) for r in K]
    return "\n".join(rows + [""] + [_num(v) for v in b]) + "\n"


def to_imutk(cal: Calibration, opts: ExportOptions) -> Exported:
    """imu_tk's .calib: T (3 lines), blank, K (3 lines), blank, b (3 lines); the gyroscope's in
    its own file (``gyro_text``), the same layout."""
    A, s = affine(cal)
    K = np.diag(np.diag(A))  # T has a unit diagonal, so K takes A's diagonal
    notes = dropped_effects(cal)
    gyro = None
    if cal.gyro is not None:
        gyro = _calib_text(*imutk_factors(cal.gyro))
        if cal.gyro.at_reference().reads_inputs():
            notes += (gsens_sentence("imu_tk", cal.gyro, cal.gravity),)
    return Exported(_calib_text(A @ np.linalg.inv(K), K, s), notes, gyro)


def to_madlab(cal: Calibration, opts: ExportOptions) -> Exported:
    """mad-lab-fau/imucal FerrarisCalibrationInfo JSON (gyroscope identity when the calibration has none)."""
    A, s = affine(cal)
    Minv = np.linalg.inv(A)  # raw - b = K R a
    k = np.linalg.norm(Minv, axis=1)
    notes = eff = dropped_effects(cal)
    if cal.gyro is None:
        gyro = {"from_gyr_unit": "a.u.", "K_g": np.eye(3), "R_g": np.eye(3), "K_ga": np.zeros((3, 3)),
                "b_g": np.zeros(3)}
        what = "no gyroscope calibration (identity)"
        notes += ("gyroscope fields are the identity (this calibration has no gyroscope)",)
    else:
        K_g, R_g, b_g, K_ga = madlab_factors(cal.gyro)
        gyro = {"from_gyr_unit": cal.gyro.raw_unit, "K_g": K_g, "R_g": R_g, "K_ga": K_ga, "b_g": b_g}
        what = f"gyroscope output in {MADLAB_GYR_UNIT}, K_ga [{cal.gyro.raw_unit} per m/s^2]"
    d = {
        "acc_unit": SI_ACCEL_UNIT, "gyr_unit": MADLAB_GYR_UNIT, "from_acc_unit": cal.raw_unit,
        "from_gyr_unit": gyro["from_gyr_unit"], "comment": " ".join((f"exported by imucal; {what}",) + eff),
        "K_a": np.diag(k).tolist(), "R_a": (Minv / k[:, None]).tolist(), "b_a": s.tolist(),
        **{key: np.asarray(gyro[key]).tolist() for key in ("K_g", "R_g", "K_ga", "b_g")},
        "cal_type": "Ferraris", "_format_version": "2.0",
    }
    return Exported(json.dumps(d, indent=4) + "\n", notes)


#: The gyroscope's equation in imucal's matrix format.
MATRIX_GYRO_EQUATION = "omega = matrix @ raw + offset - acc_matrix @ a"


def to_matrix(cal: Calibration, opts: ExportOptions) -> Exported:
    A, s = affine(cal)
    c = -A @ s
    notes = dropped_effects(cal)
    g = None if cal.gyro is None else forward(cal.gyro)
    if opts.filename.lower().endswith(".csv"):
        lines = [hash_comment(t) for t in ["a = matrix @ raw + offset; columns m1,m2,m3,offset; "
                                           f"raw in {cal.raw_unit}, a in {SI_ACCEL_UNIT}", *notes]]
        lines += [",".join(_num(v) for v in (*A[i], c[i])) for i in range(3)]
        if g is not None:
            lines.append(hash_comment(f"gyroscope: {MATRIX_GYRO_EQUATION}; columns m1,m2,m3,offset,acc_m1,acc_m2,"
                                      f"acc_m3; raw in {cal.gyro.raw_unit}, omega in {SI_RATE_UNIT}, a in {SI_ACCEL_UNIT}"))
            cg = -g.C @ g.s
            lines += [",".join(_num(v) for v in (*g.C[i], cg[i], *g.D[i])) for i in range(3)]
        return Exported("\n".join(lines) + "\n", notes)
    d = {"format": "imucal-affine", "equation": "a = matrix @ raw + offset", "input_unit": cal.raw_unit,
         "output_unit": SI_ACCEL_UNIT, "matrix": A.tolist(), "offset": c.tolist()}
    if g is not None:
        d["gyroscope"] = {"equation": MATRIX_GYRO_EQUATION, "input_unit": cal.gyro.raw_unit, "output_unit": SI_RATE_UNIT,
                          "matrix": g.C.tolist(), "offset": (-g.C @ g.s).tolist(), "acc_matrix": g.D.tolist()}
    if notes:
        d["note"] = " ".join(notes)
    return Exported(json.dumps(d, indent=2) + "\n", notes)
