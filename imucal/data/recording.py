"""A loaded recording and the limits every reader applies (text read whole in data/whole.py, bags in
data/rosbag.py, text in chunks in data/stream.py)."""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from imucal.errors import ImucalError
from imucal.model.channels import (ACCELERATION, ANGULAR_RATE, MAGNETIC_FIELD, MAX_OPERATING_TEMPERATURE, TEMPERATURE,
                                   TEMPERATURE_RANGE, TIME, Channel)

#: Plausible IMU sample rates [Hz]: anything outside is a wrong time unit or a wrong rate.
MIN_RATE_HZ, MAX_RATE_HZ = 1.0, 1.0e5
#: Largest magnitude accepted in a data column: beyond it a value is corrupt, not a reading
#: (squares of it would overflow double precision in the fit).
MAX_ABS_VALUE = 1.0e30


class TimeSource(str, Enum):
    """Where a recording's times come from."""

    STAMPS = "stamps"  #: the time column, as read (in its unit, from its first stamp)
    CLOCK = "clock"  #: a clock fitted to jittered stamps: sample index x step, gaps kept
    RATE = "rate"  #: no time column: sample index / the given sample rate


@dataclass(frozen=True, eq=False)
class TimeBase:
    """How a recording's times were made (imucal.data.timebase), and the one sample rate they give.

    Rendered to words by imucal.report; decided where the stamps are read."""

    source: TimeSource
    rate: float  #: [Hz] the one sample rate of the recording: 1 / its sample step
    #: samples that follow a gap (samples missing: imucal.data.timebase), in order
    gap_index: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    gap_seconds: np.ndarray = field(default_factory=lambda: np.empty(0))  #: [s] each gap's step
    longest_gap_line: int = 0  #: the file's line of the sample after the longest gap (0: none, or arrays)
    #: the stamps' evidence of jitter: the fraction of their steps shorter than timebase.SHORT_STEP
    #: sample steps, and their median step [s] (which a clock's step replaces)
    short_fraction: float = 0.0
    median_step: float = float("nan")
    rate_given: float | None = None  #: [Hz] a sample rate given beside the time column, checked against it
    wraps: int = 0  #: times the time column wrapped as an unsigned counter, unwrapped (imucal.data.counter_wrap)

    @property
    def step(self) -> float:
        """[s] the sample step."""
        return 1.0 / self.rate

    @property
    def n_gaps(self) -> int:
        return int(self.gap_index.size)

    @property
    def longest_gap(self) -> float:
        """[s] the longest gap's step (0 without gaps)."""
        return float(self.gap_seconds.max()) if self.gap_seconds.size else 0.0


@dataclass(frozen=True)
class Recording:
    """A loaded recording: time [s], raw readings (N x 3), optional temperature [deg C]."""

    t: np.ndarray  #: [s], from 0
    raw: np.ndarray  #: (N, 3) accelerometer readings [unit]
    temp: np.ndarray | None
    unit: str
    source: str
    sha256: str
    gyro: np.ndarray | None = None  #: (N, 3) angular-rate readings when mapped (gx, gy, gz)
    t_source: np.ndarray | None = None  #: the time column exactly as read (unit and origin kept)
    time_unit: str = "s"  #: unit of t_source
    time_note: str = ""  #: how the time base was obtained (given, inferred, or from the rate)
    time_column: str = "t"  #: the time column's name in the file
    gyro_unit: str = "raw"  #: unit of ``gyro`` (and of a second gyro file): raw (counts), deg/s or rad/s
    #: how ``t`` was made and the recording's one sample rate (None: built without one; the rate
    #: is then that of t's span)
    time_base: TimeBase | None = None
    mag: np.ndarray | None = None  #: (N, 3) magnetometer readings when mapped (mx, my, mz), in their own unit
    #: the magnetometer's unit when the file states it (a netCDF variable's units), else raw (the run file's mag.unit)
    mag_unit: str = "raw"
    #: a magnetometer the file holds but was not asked to read (a netCDF field variable not mapped): "NAME (UNITS)"
    mag_unread: str = ""
    #: role -> the file's name of the column read for it (a text file's header; empty without one)
    columns: dict = field(default_factory=dict)
    unit_stated_by: str = ""  #: the header's column whose name stated ``unit`` (acc_x [g]); "" when none did

    def __post_init__(self) -> None:
        """A temperature no sensor reads (below absolute zero, or above TEMPERATURE_RANGE) is refused: the fit
        took it and wrote a calibration the exports refuse."""
        if self.temp is not None and (err := temperature_error(self.temp, self.source)) is not None:
            raise err

    @property
    def n(self) -> int:
        return self.raw.shape[0]

    @property
    def channels(self) -> tuple[Channel, ...]:
        """The channels this recording carries, with their units (a sensor is data)."""
        out = [TIME, ACCELERATION.with_unit(self.unit)]
        if self.gyro is not None:
            out.append(ANGULAR_RATE.with_unit(self.gyro_unit))
        if self.temp is not None:
            out.append(TEMPERATURE)
        if self.mag is not None:
            out.append(MAGNETIC_FIELD.with_unit(self.mag_unit))
        return tuple(out)

    @property
    def sample_rate(self) -> float:
        """[Hz] the one rate of the time base (not of the span, which gaps lengthen)."""
        if self.time_base is not None:
            return self.time_base.rate
        if self.n < 2:
            return float("nan")
        return float((self.n - 1) / (self.t[-1] - self.t[0]))

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.n else 0.0


@dataclass(frozen=True)
class StaticSamples:
    """The samples inside static intervals, in order: what samples mode and the residuals read."""

    raw: np.ndarray  #: (m, 3)
    t: np.ndarray  #: (m,) [s]
    temp: np.ndarray | None

    def rows(self, a: int, b: int) -> "StaticSamples":
        """Samples a to b - 1."""
        return StaticSamples(self.raw[a:b], self.t[a:b], None if self.temp is None else self.temp[a:b])


@dataclass(frozen=True)
class RecordingSummary:
    """What a run reports of a recording read in chunks (Recording's fields, without samples)."""

    n: int
    t_last: float  #: [s] from the first sample
    unit: str
    source: str
    sha256: str
    time_unit: str
    time_note: str
    time_column: str
    time_base: TimeBase | None = None
    columns: dict = field(default_factory=dict)  #: as Recording.columns
    unit_stated_by: str = ""  #: as Recording.unit_stated_by
    raw: None = None
    t: None = None
    temp: None = None
    gyro: None = None
    t_source: None = None

    @property
    def sample_rate(self) -> float:
        if self.time_base is not None:
            return self.time_base.rate
        return float((self.n - 1) / self.t_last) if self.n > 1 else float("nan")

    @property
    def duration(self) -> float:
        return float(self.t_last)


def temperature_error(temp: np.ndarray, source: str, first: int = 0) -> ImucalError | None:
    """The refusal of a temperature no sensor reads (below absolute zero, or above TEMPERATURE_RANGE: the fit took
    it and wrote a calibration the exports refuse), naming its sample (``first``: the index of ``temp[0]``);
    None when every one is a sensor's."""
    lo, hi = TEMPERATURE_RANGE
    bad = ~((temp >= lo) & (temp <= hi))
    if not bad.any():
        mid = float(np.median(temp)) if temp.size else 0.0
        if mid <= MAX_OPERATING_TEMPERATURE:
            return None
        return ImucalError(f"the temperature's median is {mid:.5g} degC, above any MEMS sensor's operating range "
                           f"(at most {MAX_OPERATING_TEMPERATURE:g} degC): kelvin ({mid:.5g} K is {mid - 273.15:.3g} "
                           "degC)?", file=source, field="data.columns.temp",
                           fix="give the temperature in degC (kelvin less 273.15)")
    k = int(np.flatnonzero(bad)[0])
    return ImucalError(f"sample {first + k} holds temperature {temp[k]:g} degC, not a sensor's temperature "
                       f"({lo:g} to {hi:g} degC)", file=source, field="data.columns.temp",
                       fix="give the temperature in degC (kelvin less 273.15), or repair the corrupt samples")


def named_columns(columns: dict) -> dict:
    """The columns read, role -> the file's name, when a name is not its role's own (AccX for ax): what a
    calibration records of a header imucal read by an exporter's names; empty for imucal's own names."""
    return dict(columns) if any(name != role for role, name in columns.items()) else {}
