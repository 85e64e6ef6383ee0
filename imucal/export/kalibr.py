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
Noise fields (kalibr_common/ConfigReader.py, ImuParameters.getAccelerometerStatistics; Kalibr
refuses values <= 0): accelerometer_noise_density [m/s^2/sqrt(Hz)] and accelerometer_random_walk
[m/s^3/sqrt(Hz)] from imucal.analysis.noise on a still segment, else null with how to get them.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import yaml

from imucal import __version__
from imucal.calibration.frozen import Calibration
from imucal.errors import ImucalError, short
from imucal.export.formats import ExportOptions, Exported, KalibrNoise, affine, dropped_effects
from imucal.export.peers import AffineCalibration, _keys, checked, number, numbers
from imucal.files.yamlio import read_yaml

NOISE_FIELDS = ("accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
                "gyroscope_random_walk")
#: The keys of Kalibr's IMU configuration (ConfigReader.ImuParameters, IccSensors.py) and imucal's one.
KALIBR_FIELDS = NOISE_FIELDS + ("update_rate", "rostopic", "model", "accelerometers", "gyroscopes", "T_i_b",
                                "time_offset", "imucal_accelerometer_offset")
MODEL = "scale-misalignment"


def still_noise(cal: Calibration, t: np.ndarray, raw: np.ndarray, rate: float) -> KalibrNoise:
    """Kalibr's accelerometer noise fields from the longest still interval (or the whole log when
    it is all still, as `imucal noise` chooses), calibrated to m/s^2; the worst axis, as Kalibr
    takes one number per sensor."""
    from imucal.analysis.noise import allan_deviation, estimate
    from imucal.data.static import detect_static

    iv = detect_static(t, raw)
    y, what = raw, "the whole log"
    if iv.n and int(iv.n_samples.max()) < 0.9 * raw.shape[0]:
        k = int(np.argmax(iv.n_samples))
        y, what = raw[iv.start[k]:iv.end[k]], f"the longest still interval, {iv.t_start[k]:.1f}..{iv.t_end[k]:.1f} s"
    A, s = affine(cal)  # the map at the effects' reference point: slow effects do not change the noise
    curve = allan_deviation((y - s) @ A.T, rate)
    est = [estimate(curve, j) for j in range(3)]
    rw = [e.random_walk for e in est]
    return KalibrNoise(accelerometer_noise_density=max(e.white_density for e in est),
                       accelerometer_random_walk=max(rw) if all(np.isfinite(rw)) else None,
                       update_rate=rate, segment=f"{what} ({y.shape[0]} samples)")


def _flow(x: Any) -> str:
    """YAML flow text PyYAML (Kalibr's reader) reads back to the same floats."""
    return yaml.safe_dump(x, default_flow_style=True, width=1000).strip().removesuffix("...").strip()


def to_kalibr(cal: Calibration, opts: ExportOptions) -> Exported:
    A, s = affine(cal)
    M = np.linalg.inv(A)  # lower triangular, as Kalibr's M_accel
    M[np.triu_indices(3, 1)] = 0.0  # structural zeros (the inverse of a triangular matrix), not round-off
    n = opts.noise
    notes = list(dropped_effects(cal))
    notes.append("Kalibr estimates the accelerometer bias online; imucal's shift is written as "
                 "imucal_accelerometer_offset, which Kalibr does not read")
    notes.append("gyroscopes: identity (imucal's calibration file holds no gyroscope)")
    how = ("run `imucal noise --data STILL_LOG --calibration CAL` (or `imucal export ... --data LOG`) and copy "
           "its kalibr fields; Kalibr refuses null")
    lines = [f"# Kalibr IMU configuration, exported by imucal {__version__} "
             f"from a calibration of {(cal.data or {}).get('file', '?')} ({cal.created or 'no date'})",
             "# Kalibr's scale-misalignment model (kalibr_imu_camera_calibration/IccSensors.py,",
             "# IccScaledMisalignedImu): measurement = M (C_i_b f) + b_a, M lower triangular.",
             f"# accelerometers.M = imucal's apply matrix inverted, exactly [{cal.raw_unit} per m/s^2];",
             "# a = M^-1 (measurement - b_a).", *[f"# NOTE: {x}." for x in notes]]
    if n is None:
        lines.append(f"# Noise: no still segment was given: {how}.")
        noise = {k: None for k in NOISE_FIELDS}
    else:
        lines.append(f"# Noise: imucal noise (overlapping Allan deviation, worst axis) on {n.segment}.")
        noise = {"accelerometer_noise_density": n.accelerometer_noise_density,
                 "accelerometer_random_walk": n.accelerometer_random_walk,
                 "gyroscope_noise_density": None, "gyroscope_random_walk": None}
        if n.accelerometer_random_walk is None:
            lines.append("# accelerometer_random_walk: the curve shows no +1/2 slope (record a longer still log).")
            notes.append("accelerometer_random_walk is null: the still segment shows no random walk (record a "
                         "longer still log and run `imucal noise`); Kalibr refuses null")
        lines.append("# gyroscope noise: not estimated by this export (imucal's calibration holds no gyroscope).")
    for k in NOISE_FIELDS:
        lines.append(f"{k}: {_flow(noise[k])}")
    lines.append(f"rostopic: {_flow(opts.rostopic)}")
    rate = None if n is None else n.update_rate
    lines.append(f"update_rate: {_flow(rate)}" + ("  # Hz: give --data LOG, or write your IMU's rate" if rate is None
                                                  else "  # Hz"))
    lines += [f"model: {MODEL}", "accelerometers:", f"  M: {_flow(M.tolist())}", "gyroscopes:",
              f"  M: {_flow(np.eye(3).tolist())}", f"  A: {_flow(np.zeros((3, 3)).tolist())}",
              f"  C_gyro_i: {_flow(np.eye(3).tolist())}",
              f"imucal_accelerometer_offset: {_flow(s.tolist())}  # b_a = s [{cal.raw_unit}], not a Kalibr key"]
    if n is None:
        notes.append(f"noise fields are null: {how}")
    return Exported("\n".join(lines) + "\n", tuple(notes))


def _positive_or_null(v: Any, path: str, key: str) -> float | None:
    if v is None:
        return None
    x = number(v, path, key)
    if not x > 0:
        raise ImucalError(f"{short(v)} must be positive (Kalibr refuses values <= 0)", file=path, field=key)
    return x


def read_kalibr_yaml(path: str | Path) -> AffineCalibration:
    """Kalibr's imu.yaml (flat, or nested under imu0 as in its results) with model scale-misalignment.

    The bias is imucal_accelerometer_offset when present, else zero (Kalibr estimates it online;
    ``extra['offset_held']`` says which)."""
    p = str(path)
    d = read_yaml(p, "kalibr imu.yaml", "pass an imu.yaml with model: scale-misalignment")
    if isinstance(d, dict) and len(d) == 1 and isinstance(next(iter(d)), str) and next(iter(d)).startswith("imu"):
        d = next(iter(d.values()))  # Kalibr's result files nest the IMU under imu0
    d = _keys(d, ("model", "accelerometers"), KALIBR_FIELDS, p, "a Kalibr imu.yaml")
    if d["model"] != MODEL:
        raise ImucalError(f"model {short(d['model'])} is not {MODEL!r}", file=p, field="model",
                          fix="only the scale-misalignment intrinsics hold an accelerometer matrix")
    acc = _keys(d["accelerometers"], ("M",), ("M",), p, "Kalibr's accelerometers section")
    M = numbers(acc["M"], (3, 3), p, "accelerometers.M")
    if np.any(M[np.triu_indices(3, 1)] != 0):
        raise ImucalError("is not lower triangular (Kalibr's M_accel is)", file=p, field="accelerometers.M")
    held = "imucal_accelerometer_offset" in d
    o = numbers(d["imucal_accelerometer_offset"], (3,), p, "imucal_accelerometer_offset") if held else np.zeros(3)
    extra: dict[str, Any] = {k: _positive_or_null(d.get(k), p, k) for k in NOISE_FIELDS}
    extra["update_rate"] = _positive_or_null(d.get("update_rate"), p, "update_rate")
    topic = d.get("rostopic")
    if topic is not None and not isinstance(topic, str):
        raise ImucalError(f"{short(topic)} is not a topic name", file=p, field="rostopic")
    extra.update(rostopic=topic, offset_held=held)
    checked(M, o, p, "accelerometers.M", "kalibr")
    return checked(np.linalg.inv(M), o, p, "accelerometers.M", "kalibr", extra)
