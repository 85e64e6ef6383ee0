"""Kalibr's imu.yaml with the scale-misalignment intrinsics, written and read back.

Kalibr (ethz-asl/kalibr, aslam_offline_calibration/kalibr/python/kalibr_imu_camera_calibration/
IccSensors.py, class IccScaledMisalignedImu) models the accelerometer as
    measurement = M (C_i_b f) + b_a,      M = M_accel_Dv, lower triangular
(MatrixBasicDv pattern [[1,0,0],[1,1,0],[1,1,1]]), and writes it as ``model: scale-misalignment``,
``accelerometers: {M}``, ``gyroscopes: {M, A, C_gyro_i}`` (ImuParameters.setIntrisicsMatrices).
The Theorem's a = A (raw - s) has A lower triangular too, so M = A^-1 exactly, in the same frame
(first axis along sensor x, second in the x-y plane). Kalibr's bias b_a is a B-spline it
estimates online under ``accelerometer_random_walk`` (IccImu.initBiasSplines), not an intrinsic:
imucal's shift s is written beside it as ``imucal_accelerometer_offset`` (Kalibr reads only the
keys it knows) so the file reads back whole.
The gyroscope (IccScaledMisalignedImu.addGyroscopeErrorTerms):
    measurement = M_gyro (C_gyro_b w_b) + Ma (C_gyro_b a_b) + b_g,   C_gyro_b = C_gyro_i C_i_b,
M_gyro lower triangular (the same MatrixBasicDv pattern), C_gyro_i a rotation (RotationQuaternionDv),
Ma = ``A`` full [(rad/s)/(m/s^2)] (printDetails), a_b the specific force. Like M_accel, M_gyro is
the forward map (reading per true rate), the inverse of an apply map. With omega = C_i_b w_b and
a = C_i_b a_b in the accelerometer's frame (imucal's output frame), imucal's raw - s_g = P omega +
F a factors exactly: P = M_gyro C_gyro_i, A = F C_gyro_i^T (imucal.export.gyro.kalibr_factors);
s_g is written as ``imucal_gyroscope_offset`` (Kalibr estimates b_g online too).
Kalibr writes these intrinsics in its results and starts its own estimate from the identity; it
does not read them as priors.
Noise fields (kalibr_common/ConfigReader.py, getAccelerometerStatistics, getGyroStatistics; Kalibr
refuses values <= 0): accelerometer_noise_density [m/s^2/sqrt(Hz)], accelerometer_random_walk
[m/s^3/sqrt(Hz)], gyroscope_noise_density [rad/s/sqrt(Hz)], gyroscope_random_walk
[rad/s^2/sqrt(Hz)] from imucal.analysis.noise on a still segment, else null with how to get them.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from imucal import __version__
from imucal.analysis.noise import allan_deviation, estimate
from imucal.calibration.frozen import Calibration
from imucal.data.static import detect_static
from imucal.errors import ImucalError, short
from imucal.export.escape import free_text, hash_comment, yaml_flow
from imucal.export.formats import ExportOptions, Exported, KalibrNoise, affine, dropped_effects
from imucal.export.gyro import kalibr_factors
from imucal.export.peers import MAGNITUDE, AffineCalibration, GyroMap, Mat3, Vec3, checked, checked_gyro
from imucal.files.schema import fill, rule
from imucal.files.yamlio import read_yaml

NOISE_FIELDS = ("accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
                "gyroscope_random_walk")
#: How far C_gyro_i may be from a rotation (Kalibr writes it from a unit quaternion).
ROTATION_TOL = 1e-6
MODEL = "scale-misalignment"


def still_noise(cal: Calibration, t: np.ndarray, raw: np.ndarray, rate: float,
                gyro_raw: np.ndarray | None = None) -> KalibrNoise:
    """Kalibr's noise fields from the longest still interval (or the whole log when it is all
    still, as `imucal noise` chooses), calibrated to m/s^2 and, with ``gyro_raw`` (the gyroscope on
    the same samples) and a gyroscope calibration, to rad/s; the worst axis, as Kalibr takes one
    number per sensor."""
    iv = detect_static(t, raw)
    sel, what = slice(None), "the whole log"
    if iv.n and int(iv.n_samples.max()) < 0.9 * raw.shape[0]:
        k = int(np.argmax(iv.n_samples))
        sel = slice(iv.start[k], iv.end[k])
        what = f"the longest still interval, {iv.t_start[k]:.1f}..{iv.t_end[k]:.1f} s"
    A, s = affine(cal)  # the map at the effects' reference point: slow effects do not change the noise
    acc = (raw[sel] - s) @ A.T
    n = acc.shape[0]

    def worst(y: np.ndarray) -> tuple[float, float | None]:
        est = [estimate(allan_deviation(y, rate), j) for j in range(3)]
        rw = [e.random_walk for e in est]
        return max(e.white_density for e in est), (max(rw) if all(np.isfinite(rw)) else None)

    acc_white, acc_rw = worst(acc)
    gyro_white = gyro_rw = None
    if gyro_raw is not None and cal.gyro is not None:
        gyro_white, gyro_rw = worst(cal.gyro.apply(gyro_raw[sel], acc))
        what += ", gyroscope on the same samples"
    return KalibrNoise(accelerometer_noise_density=acc_white, accelerometer_random_walk=acc_rw,
                       update_rate=rate, segment=f"{what} ({n} samples)",
                       gyroscope_noise_density=gyro_white, gyroscope_random_walk=gyro_rw)


_flow = yaml_flow  #: YAML flow text on one line that PyYAML (Kalibr's reader) reads back to the same value


def _kalibr_header(cal: Calibration) -> list[str]:
    """The comment texts that open the file: provenance and Kalibr's model."""
    g = cal.gyro
    out = [f"Kalibr IMU configuration, exported by imucal {__version__} "
           f"from a calibration of {free_text((cal.data or {}).get('file', '?'))} ({cal.created or 'no date'})",
           "Kalibr's scale-misalignment model (kalibr_imu_camera_calibration/IccSensors.py,",
           "IccScaledMisalignedImu): measurement = M (C_i_b f) + b_a, M lower triangular.",
           f"accelerometers.M = imucal's apply matrix inverted, exactly [{cal.raw_unit} per m/s^2];",
           "a = M^-1 (measurement - b_a)."]
    if g is not None:
        out += ["gyroscope: measurement = M C_gyro_i omega + A C_gyro_i a + b_g (addGyroscopeErrorTerms),",
                "omega and a in the accelerometer's frame; M lower triangular, C_gyro_i a rotation,",
                f"A the g-sensitivity [{g.raw_unit} per m/s^2]; gyroscopes.M [{g.raw_unit} per rad/s] (Kalibr's",
                "rad/s when the raw unit is).",
                "omega = (M C_gyro_i)^-1 (measurement - b_g - A C_gyro_i a): imucal's gyroscope, exactly.",
                "Kalibr writes these intrinsics in its results; it does not read them as a starting point."]
    return out


def _noise_fields(cal: Calibration, n: KalibrNoise | None, how: str, notes: list[str]
                  ) -> tuple[list[str], dict[str, Any]]:
    """The comment texts about the noise fields, and their values (None: null); appends to ``notes``."""
    noise: dict[str, Any] = {k: None for k in NOISE_FIELDS}
    if n is None:
        return [f"Noise: no still segment was given: {how}."], noise
    texts = [f"Noise: imucal noise (overlapping Allan deviation, worst axis) on {n.segment}."]
    noise.update(accelerometer_noise_density=n.accelerometer_noise_density,
                 accelerometer_random_walk=n.accelerometer_random_walk,
                 gyroscope_noise_density=n.gyroscope_noise_density, gyroscope_random_walk=n.gyroscope_random_walk)
    for sensor, white, rw in (("accelerometer", n.accelerometer_noise_density, n.accelerometer_random_walk),
                              ("gyroscope", n.gyroscope_noise_density, n.gyroscope_random_walk)):
        if white is None:
            why = ("this calibration has no gyroscope" if cal.gyro is None else
                   "no gyroscope data on the still segment (give --gyro-data, or gx, gy, gz in --data)")
            texts.append(f"{sensor} noise: not estimated: {why}.")
            notes.append(f"{sensor}_noise_density and {sensor}_random_walk are null: {why}; Kalibr refuses null")
        elif rw is None:
            texts.append(f"{sensor}_random_walk: the curve shows no +1/2 slope (record a longer still log).")
            notes.append(f"{sensor}_random_walk is null: the still segment shows no random walk (record a "
                         "longer still log and run `imucal noise`); Kalibr refuses null")
    return texts, noise


def to_kalibr(cal: Calibration, opts: ExportOptions) -> Exported:
    """Kalibr's imu.yaml (module docstring): every comment through hash_comment, every value through
    yaml_flow (imucal.export.escape)."""
    A, s = affine(cal)
    M = np.linalg.inv(A)  # lower triangular, as Kalibr's M_accel
    M[np.triu_indices(3, 1)] = 0.0  # structural zeros (the inverse of a triangular matrix), not round-off
    n, g = opts.noise, cal.gyro
    notes = list(dropped_effects(cal))
    notes.append("Kalibr estimates the biases online; imucal's shifts are written as imucal_accelerometer_offset"
                 + ("" if g is None else " and imucal_gyroscope_offset") + ", which Kalibr does not read")
    if g is None:
        notes.append("gyroscopes: identity (this calibration has no gyroscope)")
    how = ("run `imucal noise --data STILL_LOG --calibration CAL` (or `imucal export ... --data LOG`) and copy "
           "its kalibr fields; Kalibr refuses null")
    texts = _kalibr_header(cal) + [f"NOTE: {x}." for x in notes]
    noise_texts, noise = _noise_fields(cal, n, how, notes)
    lines = [hash_comment(t) for t in texts + noise_texts]
    lines += [f"{k}: {_flow(noise[k])}" for k in NOISE_FIELDS]
    lines.append(f"rostopic: {_flow(opts.rostopic)}")
    rate = None if n is None else n.update_rate
    lines.append(f"update_rate: {_flow(rate)}  " + hash_comment("Hz: give --data LOG, or write your IMU's rate"
                                                                if rate is None else "Hz"))
    Mg, Cg, Ag = (np.eye(3), np.eye(3), np.zeros((3, 3))) if g is None else kalibr_factors(g)
    lines += [f"model: {MODEL}", "accelerometers:", f"  M: {_flow(M.tolist())}", "gyroscopes:",
              f"  M: {_flow(Mg.tolist())}", f"  A: {_flow(Ag.tolist())}", f"  C_gyro_i: {_flow(Cg.tolist())}",
              f"imucal_accelerometer_offset: {_flow(s.tolist())}  "
              + hash_comment(f"b_a = s [{cal.raw_unit}], not a Kalibr key")]
    if g is not None:
        lines.append(f"imucal_gyroscope_offset: {_flow(g.at_reference().forward().s.tolist())}  "
                     + hash_comment(f"b_g = s_g [{g.raw_unit}], not a Kalibr key"))
    if n is None:
        notes.append(f"noise fields are null: {how}")
    return Exported("\n".join(lines) + "\n", tuple(notes))


_MAGNITUDE = MAGNITUDE  #: Kalibr's matrices and imucal's offsets: finite, |x| <= MAX_MAGNITUDE
_NOISE = rule(gt=0, fix="Kalibr refuses values <= 0; give the value, or null")


@dataclass(frozen=True)
class KalibrAccelerometers:
    M: Mat3 = field(metadata=_MAGNITUDE)


@dataclass(frozen=True)
class KalibrGyroscopes:
    M: Mat3 = field(metadata=_MAGNITUDE)
    A: Mat3 = field(metadata=_MAGNITUDE)
    C_gyro_i: Mat3 = field(metadata=_MAGNITUDE)


@dataclass(frozen=True, kw_only=True)
class KalibrImu:
    """Kalibr's IMU configuration (ConfigReader.ImuParameters, IccSensors.py) and imucal's two offsets."""

    model: str = field(metadata=rule(fix="only the scale-misalignment intrinsics hold an accelerometer matrix"))
    accelerometers: KalibrAccelerometers
    gyroscopes: KalibrGyroscopes | None = None
    accelerometer_noise_density: float | None = field(default=None, metadata=_NOISE)
    accelerometer_random_walk: float | None = field(default=None, metadata=_NOISE)
    gyroscope_noise_density: float | None = field(default=None, metadata=_NOISE)
    gyroscope_random_walk: float | None = field(default=None, metadata=_NOISE)
    update_rate: float | None = field(default=None, metadata=_NOISE)
    rostopic: str | None = field(default=None, metadata=rule(msg="{value} is not a topic name"))
    T_i_b: Any = None
    time_offset: Any = None
    imucal_accelerometer_offset: Vec3 | None = field(default=None, metadata=_MAGNITUDE)
    imucal_gyroscope_offset: Vec3 | None = field(default=None, metadata=_MAGNITUDE)

    def __post_init__(self) -> None:
        if self.model != MODEL:
            raise ImucalError(f"model {short(self.model)} is not {MODEL!r}", field="model",
                              fix="only the scale-misalignment intrinsics hold an accelerometer matrix")
        if self.gyroscopes is None and self.imucal_gyroscope_offset is not None:
            raise ImucalError("is given without a gyroscopes section", field="imucal_gyroscope_offset",
                              fix="add gyroscopes: {M, A, C_gyro_i} or drop the offset")


def read_kalibr_yaml(path: str | Path) -> AffineCalibration:
    """Kalibr's imu.yaml (flat, or nested under imu0 as in its results) with model scale-misalignment.

    The bias is imucal_accelerometer_offset when present, else zero (Kalibr estimates it online;
    ``extra['offset_held']`` says which)."""
    p = str(path)
    d = read_yaml(p, "kalibr imu.yaml", "pass an imu.yaml with model: scale-misalignment")
    if isinstance(d, dict) and len(d) == 1 and isinstance(next(iter(d)), str) and next(iter(d)).startswith("imu"):
        d = next(iter(d.values()))  # Kalibr's result files nest the IMU under imu0
    k = fill(KalibrImu, d, p)
    M = np.array(k.accelerometers.M, float)
    if np.any(M[np.triu_indices(3, 1)] != 0):
        raise ImucalError("is not lower triangular (Kalibr's M_accel is)", file=p, field="accelerometers.M",
                          fix="give Kalibr's own result file (the entries above M's diagonal are 0)")
    held = k.imucal_accelerometer_offset is not None
    o = np.array(k.imucal_accelerometer_offset, float) if held else np.zeros(3)
    extra: dict[str, Any] = {n: None if getattr(k, n) is None else float(getattr(k, n))
                             for n in NOISE_FIELDS + ("update_rate",)}
    extra.update(rostopic=k.rostopic, offset_held=held)
    checked(M, o, p, "accelerometers.M", "kalibr")
    gyro = _kalibr_gyro(k, p, extra) if k.gyroscopes is not None else None
    return replace(checked(np.linalg.inv(M), o, p, "accelerometers.M", "kalibr", extra), gyro=gyro)


def _kalibr_gyro(k: KalibrImu, p: str, extra: dict[str, Any]) -> GyroMap:
    """omega = (M C)^-1 (measurement - b_g) - (M C)^-1 A C a (module docstring); b_g is
    imucal_gyroscope_offset when present, else zero (``extra['gyro_offset_held']``)."""
    gy = k.gyroscopes
    M, A, R = (np.array(x, float) for x in (gy.M, gy.A, gy.C_gyro_i))
    if np.any(M[np.triu_indices(3, 1)] != 0):
        raise ImucalError("is not lower triangular (Kalibr's M_gyro is)", file=p, field="gyroscopes.M",
                          fix="give Kalibr's own result file (the entries above M's diagonal are 0)")
    dev = float(np.abs(R @ R.T - np.eye(3)).max())
    if not (dev <= ROTATION_TOL and np.linalg.det(R) > 0):
        raise ImucalError(f"is not a rotation (|C C^T - I| = {dev:.3g}, det {np.linalg.det(R):.3g})", file=p,
                          field="gyroscopes.C_gyro_i", fix="Kalibr writes a rotation matrix here")
    held = k.imucal_gyroscope_offset is not None
    b = np.array(k.imucal_gyroscope_offset, float) if held else np.zeros(3)
    extra["gyro_offset_held"] = held
    checked(M, b, p, "gyroscopes.M", "kalibr")
    C = np.linalg.inv(M @ R)
    return checked_gyro(C, b, C @ A @ R, p, "gyroscopes.M")
