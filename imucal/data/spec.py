"""The data specification: how one recording is read (the YAML ``data:`` section), validated once.

Columns (roles and where they are), units (raw readings, gyroscope, time), the time base given
(sample rate), the rails of the raw readings, and which reader applies (format, chunked reading,
ROS topics). Every reader (imucal.data.whole, imucal.data.stream, imucal.data.rosbag) takes a
DataSpec; nothing here reads a file.
"""
from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imucal.calibration.fields import check_raw_unit
from imucal.constants import GYRO_UNIT_CHOICES, TIME_UNIT_CHOICES
from imucal.data.recording import MAX_ABS_VALUE, MAX_RATE_HZ, MIN_RATE_HZ
from imucal.errors import ImucalError, check_choice, short
from imucal.files.schema import rule

FORMATS = ("auto", "csv", "whitespace")
#: How a recording is read: in chunks (imucal.data.stream) above imucal.data.load.STREAM_BYTES
#: ("auto"), always, never.
STREAM_CHOICES = ("auto", "always", "never")
#: Column roles: time, acceleration, angular rate, temperature, magnetic field.
ROLES = ("t", "ax", "ay", "az", "gx", "gy", "gz", "temp", "mx", "my", "mz")


def gyro_unit(spec: DataSpec, bag: bool = False) -> str:
    """The gyro unit a fit uses: raw (counts, scale searched), deg/s or rad/s; ``bag``: a ROS bag's default."""
    if spec.gyro_unit == "auto":
        return "rad/s" if bag else "raw"
    return "raw" if spec.gyro_unit == "counts" else spec.gyro_unit


@dataclass(frozen=True)
class DataSpec:
    """How to read one recording (the YAML ``data:`` section).

    ``columns`` maps the roles t, ax, ay, az, temp to column names (CSV with header) or to
    0-based column indices (files without header). Without a time column, give
    ``sample_rate`` [Hz]; beside one it is checked against the stamps (imucal.data.timebase).
    ``unit`` labels the raw values ("raw" counts, or "m/s^2").
    ``gyro_unit`` is the gyroscope's raw unit (GYRO_UNIT_CHOICES): counts start the gyro fit with a
    search for the scale, deg/s and rad/s with the nominal scale; "auto" is rad/s for a ROS bag
    (REP 103) and counts otherwise.
    """

    path: str = field(metadata=rule(fix="add data.path: RECORDING", msg="path {value} must be a file name"))
    format: str = "auto"
    columns: dict = field(default_factory=dict, metadata=rule(msg="must map roles to columns",
                                                              fix="e.g. columns: {t: time, ax: x}"))
    delimiter: str | None = field(default=None, metadata=rule(
        msg="delimiter {value} must be one character",
        fix='e.g. delimiter: ","  (omit it to detect , ; tab or spaces)'))
    skip_rows: int = 0
    sample_rate: float | None = field(default=None, metadata=rule(
        msg="sample rate {value} is not an IMU rate (not a number)", fix="give the logging rate in Hz"))
    time_unit: str = "auto"
    unit: str = "raw"
    gyro_unit: str = "auto"  #: the gyroscope's raw unit, one of GYRO_UNIT_CHOICES
    #: rails of the raw readings: {"low": v, "high": v}, each a number or [x, y, z]
    saturation: dict | None = None
    #: a gyroscope recording on the same time base (imu_tk's second file), calibrated beside
    gyro_path: str | None = None
    #: ROS bags: the sensor_msgs/msg/Imu topic, and optionally a sensor_msgs/msg/Temperature one
    topic: str | None = None
    temp_topic: str | None = None
    #: read in chunks with bounded memory: auto (files above imucal.data.load.STREAM_BYTES), always, never
    stream: str = "auto"

    def __post_init__(self) -> None:
        if not isinstance(self.path, (str, os.PathLike)) or not str(self.path):
            raise ImucalError(f"path {short(self.path)} must be a file name", field="data.path",
                              fix="give the recording's path as text")
        for name in ("format", "time_unit", "unit", "gyro_unit", "stream"):
            if not isinstance(getattr(self, name), str):
                raise ImucalError(f"{name} {short(getattr(self, name))} must be text", field=f"data.{name}",
                                  fix=f"give data.{name} as a word, e.g. {name}: {'raw' if name == 'unit' else 'auto'}")
        check_raw_unit(self.unit, "data.unit")  # the calibration file's rule: what calibrate writes reads back
        if self.delimiter is not None and not (isinstance(self.delimiter, str) and len(self.delimiter) == 1
                                               and self.delimiter not in "\r\n"):
            raise ImucalError(f"delimiter {short(self.delimiter)} must be one character", field="data.delimiter",
                              fix='e.g. delimiter: ","  (omit it to detect , ; tab or spaces)')
        if self.sample_rate is not None and (isinstance(self.sample_rate, bool)
                                             or not isinstance(self.sample_rate, (int, float))):
            raise ImucalError(f"sample rate {short(self.sample_rate)} is not an IMU rate (not a number)",
                              field="data.sample_rate", fix="give the logging rate in Hz")
        if not isinstance(self.columns, Mapping):
            raise ImucalError("must map roles to columns", field="data.columns",
                              fix="e.g. columns: {t: 0, ax: 1, ay: 2, az: 3} (--columns t=0,ax=1,ay=2,az=3)")
        for role, col in self.columns.items():
            if not ((isinstance(col, int) and not isinstance(col, bool) and 0 <= col < 10000)
                    or (isinstance(col, str) and col and len(col) <= 200)):
                raise ImucalError(f"column {short(col)} for {short(role)} must be a header name or a "
                                  "0-based index below 10000", field=f"data.columns.{role if isinstance(role, str) and len(role) <= 20 else short(role, 20)}",
                                  fix="give the column's header name or its 0-based position, e.g. ax=4 or ax=acc_x")
        check_choice(self.format, FORMATS, "data.format", "format")
        check_choice(self.stream, STREAM_CHOICES, "data.stream", "stream setting")
        check_choice(self.gyro_unit, GYRO_UNIT_CHOICES, "data.gyro_unit", "gyro unit",
                     "raw and counts: the scale is searched")
        check_choice(self.time_unit, TIME_UNIT_CHOICES, "data.time_unit", "time unit")
        if self.sample_rate is not None and not (_finite(self.sample_rate)
                                                 and MIN_RATE_HZ <= self.sample_rate <= MAX_RATE_HZ):
            raise ImucalError(f"sample rate {short(self.sample_rate)} Hz is not an IMU rate",
                              field="data.sample_rate",
                              fix=f"give the logging rate in Hz ({MIN_RATE_HZ:g} to {MAX_RATE_HZ:g})")
        if not isinstance(self.skip_rows, int) or isinstance(self.skip_rows, bool) or not 0 <= self.skip_rows < 10**9:
            raise ImucalError(f"skip_rows {short(self.skip_rows)} must be a non-negative integer below 1e9",
                              field="data.skip_rows",
                              fix="give the number of lines above the header (or the data) as a whole number, e.g. 0")
        bad = set(self.columns) - set(ROLES)
        if bad:
            raise ImucalError(f"unknown column role(s) {short(sorted(map(str, bad)))}", field="data.columns",
                              fix=f"map only {', '.join(ROLES)}")
        cols = [c for c in self.columns.values()]
        if len(set(map(str, cols))) != len(cols):
            raise ImucalError("two roles map to the same column", field="data.columns",
                              fix="give each role its own column")
        if self.saturation is not None:
            rails(self.saturation)  # validated here, used by static detection
        for name in ("topic", "temp_topic"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, str) and v and len(v) <= 1000):
                raise ImucalError(f"{name} {short(v)} must be a ROS topic name", field=f"data.{name}",
                                  fix="e.g. topic: /imu")
        if self.gyro_path is not None and not (isinstance(self.gyro_path, str) and self.gyro_path):
            raise ImucalError(f"gyro_path {short(self.gyro_path)} must be a file name", field="data.gyro_path",
                              fix="give the gyroscope recording's path as text")


    @property
    def declared_rails(self) -> dict[str, np.ndarray | None] | None:
        """The rails of ``saturation`` as arrays (validated on construction), or None."""
        return None if self.saturation is None else rails(self.saturation)


def _finite(x: int | float) -> bool:
    """math.isfinite without OverflowError for integers beyond double range (YAML's 10**400)."""
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


def rails(spec: object, where: str = "data.saturation") -> dict[str, np.ndarray | None]:
    """Declared rails of the raw readings: {"low": [x, y, z] or None, "high": ...}.

    YAML: ``saturation: {low: -16000, high: 16000}`` (one value for all axes, or [x, y, z]).
    A reading at or beyond a rail is clipped (the sensor's range was exceeded).
    """
    if not isinstance(spec, Mapping) or not spec or set(spec) - {"low", "high"}:
        raise ImucalError(f"{short(spec)} must map low and/or high to rail values", field=where,
                          fix="e.g. saturation: {low: -32768, high: 32767}")
    out: dict[str, np.ndarray | None] = {"low": None, "high": None}
    for k, v in spec.items():
        vals = v if isinstance(v, (list, tuple)) else [v] * 3
        if len(vals) != 3 or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                     and _finite(x) and abs(x) <= MAX_ABS_VALUE for x in vals):
            raise ImucalError(f"{k} rail {short(v)} must be a finite number or [x, y, z]", field=f"{where}.{k}",
                              fix="give the raw value at which the sensor clips")
        out[k] = np.array(vals, float)
    if out["low"] is not None and out["high"] is not None and not np.all(out["low"] < out["high"]):
        raise ImucalError("the low rail must lie below the high rail on every axis", field=where,
                          fix="give low as the most negative raw value the sensor reports, high as the most positive")
    return out


def resolve_path(spec: DataSpec, base_dir: str | os.PathLike | None) -> Path:
    """The recording's path (relative paths are relative to ``base_dir``, the YAML file's folder)."""
    path = Path(spec.path)
    return Path(base_dir) / path if base_dir is not None and not path.is_absolute() else path


def as_spec(spec: DataSpec | str | os.PathLike) -> DataSpec:
    return spec if isinstance(spec, DataSpec) else DataSpec(path=str(spec))


def parse_columns(text: str, where: str = "--columns") -> dict[str, int | str]:
    """``"t=0,ax=4,ay=5,az=6"`` (0-based indices) or ``"t=time,ax=acc_x"`` (header names)."""
    if not isinstance(text, str) or not text.strip() or len(text) > 2000:
        raise ImucalError("give ROLE=COLUMN pairs separated by commas", field=where,
                          fix="e.g. --columns t=0,ax=4,ay=5,az=6")
    out: dict[str, int | str] = {}
    for item in text.split(","):
        role, sep, col = (x.strip() for x in item.partition("="))
        if not sep or not role or not col:
            raise ImucalError(f"{short(item)} is not ROLE=COLUMN", field=where,
                              fix="e.g. --columns t=0,ax=4,ay=5,az=6")
        if role not in ROLES:
            raise ImucalError(f"unknown role {short(role)}", field=where, fix=f"roles: {', '.join(ROLES)}")
        if role in out:
            raise ImucalError(f"role {role} given twice", field=where, fix="give each role once")
        index = col.isascii() and col.isdigit()  # not "²" or other Unicode digits
        if index and len(col) > 4:
            raise ImucalError(f"column index {short(col)} for {role} is out of range", field=where,
                              fix="give a 0-based index below 10000")
        value: int | str = int(col) if index else col
        if value in out.values():
            other = next(r for r, v in out.items() if v == value)
            raise ImucalError(f"roles {other} and {role} both map to column {short(col)}", field=where,
                              fix="give each role its own column")
        out[role] = value
    return out


def check_bag_spec(spec: DataSpec, path: Path) -> None:
    """Options of text files are refused for a bag (its messages name their fields and units)."""
    given = [n for n, v in (("columns", spec.columns), ("sample_rate", spec.sample_rate),
                            ("delimiter", spec.delimiter), ("skip_rows", spec.skip_rows),
                            ("gyro_path", spec.gyro_path)) if v]
    given += [n for n, v, d in (("format", spec.format, "auto"), ("time_unit", spec.time_unit, "auto")) if v != d]
    if spec.unit not in ("raw", "m/s^2"):
        given.append("unit")
    if spec.gyro_unit not in ("auto", "rad/s"):
        given.append("gyro_unit")
    if given:
        raise ImucalError(f"{given[0]} does not apply to a ROS bag", file=str(path), field=f"data.{given[0]}",
                          fix="drop it: the Imu messages give time [s], acceleration [m/s^2] and rate [rad/s]")
