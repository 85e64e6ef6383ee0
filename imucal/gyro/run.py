"""The gyroscope beside an accelerometer run: from the recording's gyro columns, or from a second
file on the same time base (imu_tk's two files)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from imucal.constants import TIME_UNITS
from imucal.data.load import load_gyro_file
from imucal.data.recording import Recording
from imucal.errors import ImucalError
from imucal.gyro.fit import GyroOptions, fit_gyro
from imucal.gyro.result import motions
from imucal.solve.fit import FitResult
from imucal.gyro.segments import GyroData, gyro_data_from_run


#: A second file with as many samples is taken sample by sample when each stamp lies within this fraction of a
#: sample period of the accelerometer's (the clock's rounding), not when they name other instants.
SAME_SAMPLE_FRACTION = 0.5


@dataclass(frozen=True)
class GyroChannel:
    """The gyroscope's readings beside an accelerometer recording."""

    t: np.ndarray  #: time stamps [s]
    raw: np.ndarray  #: (N, 3) raw rates
    source: str
    acc_t0: float | None  #: the accelerometer's start in the gyro's clock (None: the recording's own columns)
    gaps: np.ndarray | None  #: a second file's samples after a gap (None: the recording's own columns)
    unit: str | None = None  #: the unit a second file's header states (rad/s, deg/s), None: none stated


def gyro_channel(rec: Recording, gyro_file: str | None = None) -> GyroChannel | None:
    """The gyroscope's readings: the recording's own columns, or a second file's, or None.

    A second file is read with the loader's defaults (imu_tk: t x y z), or its gyroscope columns when its
    header names them (imucal.data.layout.gyro_file_spec), in the unit the header states; its time stamps and
    the accelerometer's share one clock, so both keep their original origin.
    """
    if gyro_file is None:
        if rec.gyro is None:
            return None
        return GyroChannel(rec.t, rec.gyro, rec.source, None, None)
    path = Path(gyro_file)
    spec, g = load_gyro_file(path)
    if g.t_source is None or rec.t_source is None:
        raise ImucalError("both files need time stamps to share one time base", file=str(gyro_file),
                          field="--gyro-data", fix="record t in both files (imu_tk: t x y z)")
    t_g = g.t_source * TIME_UNITS[g.time_unit]
    acc_t0 = float(rec.t_source[0]) * TIME_UNITS[rec.time_unit]
    if g.n == rec.n:  # taken sample by sample: the stamps must say they are the same samples
        off = np.abs(t_g - rec.t_source * TIME_UNITS[rec.time_unit])
        if not off.max() <= SAME_SAMPLE_FRACTION / rec.sample_rate:
            k = int(np.argmax(off))
            raise ImucalError(f"as many samples as the accelerometer, but sample {k} is stamped {off[k]:.6g} s apart "
                              f"from the accelerometer's ({off[k] * rec.sample_rate:.3g} samples): not the same "
                              "samples on one clock", file=g.source, field="t",
                              fix="give the gyroscope's stamps on the accelerometer's clock (the same t for the same "
                                  "sample), in one unit")
    stated = g.unit if spec.columns and g.unit in ("rad/s", "deg/s") else None  # named gyro columns' unit
    return GyroChannel(t_g, g.raw, g.source, acc_t0, None if g.time_base is None else g.time_base.gap_index, stated)


#: A calibrated gyroscope that leaves the gravity direction this far off [deg rms] over the
#: motions does not describe them: wrong columns, wrong file or no gyroscope signal. Refused.
MAX_DIRECTION_ERROR_DEG = 10.0


def gyro_data(run, gyro_file: str | None = None, unit: str | None = None) -> tuple[GyroData, str] | None:
    """The gyro fit's data of ``run`` (imucal.pipeline.CalibrationRun) and the gyro's source; None without a gyro.

    ``unit``: the gyro's raw unit (rad/s, deg/s or raw); default the recording's ``gyro_unit``
    (data.gyro_unit), never the accelerometer's unit."""
    ch = gyro_channel(run.recording, gyro_file)
    if ch is None:
        return None
    acc_t0 = None if gyro_file is not None and ch.raw.shape[0] == run.recording.n else ch.acc_t0  # same samples
    unit = unit or _second_file_unit(run.recording.gyro_unit, ch)
    try:
        return gyro_data_from_run(run, ch.t, ch.raw, unit=unit, acc_t0=acc_t0, gyro_gaps=ch.gaps), ch.source
    except ImucalError as exc:
        raise ImucalError(exc.message, file=exc.file or ch.source, field=exc.field, fix=exc.fix) from None


def _second_file_unit(given: str, ch: GyroChannel) -> str:
    """The gyro's unit: the one a second file's header states unless the run gave another (refused: one line),
    else the run's (data.gyro_unit)."""
    if ch.unit is None or given == ch.unit:
        return given
    if given != "raw":  # the run's data.gyro_unit given (raw: not given, or counts)
        raise ImucalError(f"data.gyro_unit {given} given, but the gyroscope file's header states {ch.unit}",
                          file=ch.source, field="data.gyro_unit", fix=f"give {ch.unit} (or leave it out)")
    return ch.unit


def calibrate_gyro(run, gyro_file: str | None = None, options: GyroOptions = GyroOptions()) -> FitResult | None:
    """Fit the gyroscope of ``run`` (imucal.pipeline.CalibrationRun); None when it has none."""
    got = gyro_data(run, gyro_file)
    if got is None:
        return None
    data, source = got
    res = fit_gyro(data, options)
    after = motions(res).rms_direction_error_deg["after"]
    if not after <= MAX_DIRECTION_ERROR_DEG:
        raise ImucalError(f"the calibrated gyroscope leaves the gravity direction {after:.3g} deg rms off over "
                          f"{motions(res).segments.size} motions: it does not describe them", file=source, field="gyro",
                          fix="check the gyroscope columns (gx, gy, gz) or file, and that it shares the time base")
    return res


def gyro_on_accel_samples(rec: Recording, gyro_file: str | None = None) -> np.ndarray | None:
    """Raw gyro readings (N, 3) at the accelerometer's samples, or None without a gyroscope.

    A second file with as many samples is taken sample by sample; one at another rate is
    interpolated linearly onto the accelerometer's time stamps (same clock), never extrapolated.
    """
    ch = gyro_channel(rec, gyro_file)
    if ch is None:
        return None
    t_g, raw, source, acc_t0 = ch.t, ch.raw, ch.source, ch.acc_t0
    if acc_t0 is None or raw.shape[0] == rec.n:
        return raw
    t_a = rec.t_source * TIME_UNITS[rec.time_unit]
    if t_a[0] < t_g[0] or t_a[-1] > t_g[-1]:
        raise ImucalError(f"the gyroscope covers {t_g[0]:.6g}..{t_g[-1]:.6g} s, the accelerometer "
                          f"{t_a[0]:.6g}..{t_a[-1]:.6g} s on their shared clock", file=source, field="t",
                          fix="give a gyroscope recording that spans the accelerometer's")
    return np.column_stack([np.interp(t_a, t_g, raw[:, j]) for j in range(3)])
