"""The noise of every sensor of a still log: the Allan deviation of each axis (imucal.analysis.noise)
of the accelerometer and, when the recording has one, the gyroscope, on one still segment.

``measure_noise(recording, calibration)`` takes the whole log, or the longest still interval of a
calibration log (static detection with the default settings), and converts the readings to SI
units when a calibration is given (the accelerometer to m/s^2; the gyroscope to rad/s when the
calibration holds one). Its result is typed (StillNoise) and rendered to words in imucal.report.noise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from imucal.analysis.noise import AllanCurve, NoiseEstimate, allan_deviation, estimate
from imucal.constants import SI_ACCEL_UNIT
from imucal.data.recording import Recording
from imucal.data.static import detect_static

if TYPE_CHECKING:
    from imucal.calibration.frozen import Calibration

ACCELEROMETER, GYROSCOPE = "accelerometer", "gyroscope"
#: A log whose longest still interval holds less than this fraction of it is a calibration log: the
#: noise is measured on that interval alone (the poses' changes are not noise).
STILL_FRACTION = 0.9
RAD_PER_DEG = math.pi / 180.0
#: Kalibr's imu.yaml fields of each sensor (noise density, random walk) and the SI unit they are in.
KALIBR_FIELDS = {ACCELEROMETER: ("accelerometer_noise_density", "accelerometer_random_walk", SI_ACCEL_UNIT),
                 GYROSCOPE: ("gyroscope_noise_density", "gyroscope_random_walk", "rad/s")}


@dataclass(frozen=True)
class SensorNoise:
    """One sensor's Allan deviation and its terms per axis, in ``unit``."""

    sensor: str  #: ACCELEROMETER or GYROSCOPE
    unit: str  #: of the readings measured (raw, m/s^2, deg/s, rad/s)
    curve: AllanCurve
    axes: tuple[NoiseEstimate, NoiseEstimate, NoiseEstimate]

    @property
    def random_walk_found(self) -> bool:
        return all(math.isfinite(e.random_walk) for e in self.axes)

    def kalibr(self) -> dict[str, float | None] | None:
        """Kalibr's fields of this sensor (the worst axis, as Kalibr takes one number per sensor), or
        None when the readings are not in SI units (deg/s is converted)."""
        density, walk, si = KALIBR_FIELDS[self.sensor]
        factor = 1.0 if self.unit == si else RAD_PER_DEG if (self.sensor, self.unit) == (GYROSCOPE, "deg/s") else None
        if factor is None:
            return None
        rw = [e.random_walk for e in self.axes if math.isfinite(e.random_walk)]
        return {density: factor * max(e.white_density for e in self.axes),
                walk: factor * max(rw) if len(rw) == 3 else None}

    def to_json(self) -> dict[str, Any]:
        return {"unit": self.unit,
                "axes": {a: {k: (v if math.isfinite(v) else None) for k, v in e.__dict__.items()}
                         for a, e in zip("xyz", self.axes)},
                "allan": {"tau_s": self.curve.tau.tolist(), "adev": self.curve.adev.tolist()}}


@dataclass(frozen=True)
class StillNoise:
    """What `imucal noise` measured: the segment and each sensor's noise."""

    source: str
    segment: str  #: "the whole log" or the still interval measured
    n_samples: int
    rate: float  #: [Hz]
    sensors: tuple[SensorNoise, ...]  #: the accelerometer first, then the gyroscope when there is one

    @property
    def accelerometer(self) -> SensorNoise:
        return self.sensors[0]

    @property
    def gyroscope(self) -> SensorNoise | None:
        return next((s for s in self.sensors if s.sensor == GYROSCOPE), None)

    def kalibr(self) -> dict[str, float | None] | None:
        """Kalibr's imu.yaml noise fields of the sensors in SI units (None: the accelerometer is not)."""
        acc = self.accelerometer.kalibr()
        if acc is None:
            return None
        gyro = None if self.gyroscope is None else self.gyroscope.kalibr()
        return {**acc, **(gyro or {}), "update_rate": self.rate}

    def to_json(self) -> dict[str, Any]:
        """`imucal noise --json`: the accelerometer at the top level (imucal.analysis.noise_model reads
        it as --noise), the gyroscope under "gyro"."""
        out = {"unit": self.accelerometer.unit, "source": self.source, "segment": self.segment,
               "rate_hz": self.rate, **{k: v for k, v in self.accelerometer.to_json().items() if k != "unit"}}
        if self.gyroscope is not None:
            out["gyro"] = self.gyroscope.to_json()
        if (k := self.kalibr()) is not None:
            out["kalibr"] = k
        return out


def still_segment(rec: Recording) -> tuple[slice, str]:
    """The rows measured: the whole log, or a calibration log's longest still interval."""
    iv = detect_static(rec.t, rec.raw)
    if iv.n and int(iv.n_samples.max()) < STILL_FRACTION * rec.n:
        k = int(np.argmax(iv.n_samples))
        return slice(int(iv.start[k]), int(iv.end[k])), (f"the longest still interval, {iv.t_start[k]:.1f}.."
                                                          f"{iv.t_end[k]:.1f} s")
    return slice(0, rec.n), "the whole log"


def _sensor(sensor: str, y: np.ndarray, unit: str, rate: float, source: str) -> SensorNoise:
    curve = allan_deviation(y, rate, source=source)
    return SensorNoise(sensor, unit, curve, (estimate(curve, 0), estimate(curve, 1), estimate(curve, 2)))


def measure_noise(rec: Recording, calibration: Calibration | None = None) -> StillNoise:
    """The noise of each sensor of ``rec`` on its still segment; in SI units with ``calibration``."""
    rows, segment = still_segment(rec)
    acc, acc_unit = rec.raw[rows], rec.unit
    gyro, gyro_unit = (None, "") if rec.gyro is None else (rec.gyro[rows], rec.gyro_unit)
    if calibration is not None:
        acc, acc_unit = calibration.apply(acc), SI_ACCEL_UNIT
        if gyro is not None and calibration.gyro is not None:
            _, gyro = calibration.apply_imu(rec.raw[rows], gyro)
            gyro_unit = "rad/s"
    sensors = [_sensor(ACCELEROMETER, acc, acc_unit, rec.sample_rate, rec.source)]
    if gyro is not None:
        sensors.append(_sensor(GYROSCOPE, gyro, gyro_unit, rec.sample_rate, rec.source))
    return StillNoise(rec.source, segment, int(acc.shape[0]), rec.sample_rate, tuple(sensors))
