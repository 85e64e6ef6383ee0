"""Loading recordings: CSV with a header, or whitespace text without one (imu_tk's t x y z)."""
from __future__ import annotations

import hashlib
import io
import math
import os
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imucal.calibration.fields import check_raw_unit
from imucal.constants import GYRO_UNIT_CHOICES, TIME_UNIT_CHOICES
from imucal.errors import ImucalError, check_choice, short
from imucal.data.rosbag import is_bag, read_bag
from imucal.files.inputs import first_hole, max_data_bytes, open_regular
from imucal.data.recording import MAX_ABS_VALUE, MAX_RATE_HZ, MIN_RATE_HZ, Recording  # noqa: F401 (re-exported)
from imucal.data.timebase import rate_time_base, stamped_times
from imucal.files.schema import rule

FORMATS = ("auto", "csv", "whitespace")
#: How a recording is read: in chunks (imucal.data.stream) above STREAM_BYTES ("auto"), always, never.
STREAM_CHOICES = ("auto", "always", "never")
#: Column roles: time, acceleration, angular rate, temperature.
ROLES = ("t", "ax", "ay", "az", "gx", "gy", "gz", "temp")
_MAX_SCAN_LINES = 50
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
    #: read in chunks with bounded memory: auto (files above imucal.data.stream.STREAM_BYTES), always, never
    stream: str = "auto"

    def __post_init__(self) -> None:
        if not isinstance(self.path, (str, os.PathLike)) or not str(self.path):
            raise ImucalError(f"path {short(self.path)} must be a file name", field="data.path",
                              fix="give the recording's path as text")
        for name in ("format", "time_unit", "unit", "gyro_unit", "stream"):
            if not isinstance(getattr(self, name), str):
                raise ImucalError(f"{name} {short(getattr(self, name))} must be text", field=f"data.{name}")
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
            raise ImucalError("must map roles to columns", field="data.columns")
        for role, col in self.columns.items():
            if not ((isinstance(col, int) and not isinstance(col, bool) and 0 <= col < 10000)
                    or (isinstance(col, str) and col and len(col) <= 200)):
                raise ImucalError(f"column {short(col)} for {short(role)} must be a header name or a "
                                  "0-based index below 10000", field=f"data.columns.{role if isinstance(role, str) and len(role) <= 20 else short(role, 20)}")
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
                              field="data.skip_rows")
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
        raise ImucalError("the low rail must lie below the high rail on every axis", field=where)
    return out


def _read_bytes(path: Path) -> tuple[bytes, str]:
    """Bytes and SHA-256 of a recording: a regular file, within the size limit, text (no NUL byte,
    no line longer than MAX_LINE_BYTES). A sparse file is read only up to its first hole."""
    fd, size = open_regular(path, field="data.path", max_bytes=max_data_bytes(),
                            fix="check the path (relative paths are relative to the YAML file)")
    hole = first_hole(fd, size)  # a sparse file's NUL tail is never read
    try:
        with os.fdopen(fd, "rb") as f:
            if b"\x00" in f.read(BINARY_PROBE):  # a binary file is refused before it is read whole
                raise binary_file(path)
            f.seek(0)
            blob = f.read(hole)
    except OSError as exc:
        raise ImucalError(f"cannot read: {exc.strerror or exc}", file=str(path), field="data.path") from None
    nul = blob.find(b"\x00")
    if nul >= 0 or hole < size:
        raise binary_file(path, blob.count(b"\n", 0, nul if nul >= 0 else len(blob)) + 1)
    start = long_line(blob)
    if start is not None:
        raise line_too_long(path, blob.count(b"\n", 0, start) + 1)
    return blob, hashlib.sha256(blob).hexdigest()


def _decode(blob: bytes, path: Path) -> str:
    try:
        return blob.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise not_utf8(path) from None


#: ASCII bytes that end a line for str.splitlines but not for numpy's reader (or not alone: "\r").
_OTHER_BREAKS = (b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e")


def _fast_table(blob: bytes, spec: DataSpec, path: Path) -> tuple[Layout, np.ndarray] | None:
    """The common recording read without a Python string per line: ASCII, lines ended by "\n" or
    "\r\n", every line after the header a finite row. None for anything else, which the line by line
    reader (parse_block) reads and, when it is wrong, names the line at fault. Same numbers: the same
    numpy parser reads the same bytes."""
    if not blob.isascii() or any(b in blob for b in _OTHER_BREAKS) or (
            b"\r" in blob and blob.count(b"\r") != blob.count(b"\r\n")):
        return None
    n_lines = blob.count(b"\n") + (len(blob) > 0 and not blob.endswith(b"\n"))
    end = -1  # the head: the lines the layout looks at (its first data line and _MAX_SCAN_LINES more)
    for _ in range(spec.skip_rows + 2 * _MAX_SCAN_LINES):
        end = blob.find(b"\n", end + 1)
        if end < 0:
            end = len(blob)
            break
    head = blob[:end].decode("ascii").splitlines()[spec.skip_rows:]
    try:
        lay = layout(head, spec, path)
    except ImucalError:
        return None
    first = spec.skip_rows + lay.body  # 0-based line of the first row
    if (lay.body + _MAX_SCAN_LINES >= len(head) and end < len(blob)) or n_lines <= first:
        return None  # the layout may depend on lines past the head; or no row at all
    try:
        with warnings.catch_warnings():  # "input contained no data": blank lines only, read below
            warnings.simplefilter("ignore")
            arr = np.loadtxt(io.BytesIO(blob), delimiter=lay.delimiter, usecols=lay.usecols, ndmin=2,
                             dtype=float, comments="#", skiprows=first)
    except (ValueError, IndexError):
        return None
    if arr.shape[0] != n_lines - first or not np.isfinite(arr).all():
        return None  # a blank or comment line, or a bad value: the line by line reader decides
    return lay, arr


#: Leading bytes searched for NUL (a binary file).
BINARY_PROBE = 1 << 16
#: Longest line a recording may hold [bytes]. A row is a time stamp and a few channels, a few
#: hundred bytes; a line of a mebibyte is no row but a corrupt or binary file, and reading on to
#: its end could take all the memory a huge file claims. Both readers refuse it, naming the line.
MAX_LINE_BYTES = 1 << 20
#: Line ends long_line looks for (str.splitlines' other breaks are rare enough to be refused as
#: one long line when a file uses nothing else).
_LINE_ENDS = (b"\n", b"\r")


def long_line(buf: bytes | bytearray) -> int | None:
    """Offset of the first line of ``buf`` (which starts a line) longer than MAX_LINE_BYTES, or
    None; an unfinished last line counts once it is too long. About len(buf) / MAX_LINE_BYTES
    searches, not one per line."""
    start, n = 0, len(buf)
    while n - start > MAX_LINE_BYTES:
        end = start + MAX_LINE_BYTES + 1
        brk = max(buf.rfind(c, start, end) for c in _LINE_ENDS)
        if brk < 0:
            return start
        start = brk + 1
    return None


def line_too_long(path: Path, line: int) -> ImucalError:
    return ImucalError(f"line {line} is longer than {MAX_LINE_BYTES} bytes (no line end): not a recording's row",
                       file=str(path), field="data",
                       fix="check that the file is a text recording (one row per line) and not cut or corrupt")


def binary_file(path: Path, line: int | None = None) -> ImucalError:
    """NUL bytes: at the head of the file, or (``line``) after text (a sparse or corrupt file)."""
    where = "" if line is None or line <= 1 else f" from line {line} on (a sparse or corrupt file)"
    return ImucalError(f"is a binary file (NUL bytes){where}, not a text recording", file=str(path),
                       field="data.path", fix="export the recording as CSV or whitespace-separated text")


def not_utf8(path: Path) -> ImucalError:
    return ImucalError("is not UTF-8 text", file=str(path), field="data.path",
                       fix="export the recording as CSV or whitespace-separated text")


def _is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.replace(",", " ").replace(";", " ").split()
    return [c.strip() for c in line.split(delimiter)]


def _sniff_delimiter(line: str) -> str | None:
    for d in (",", ";", "\t"):
        if d in line:
            return d
    return None


def parse_block(lines: list[str], first_lineno: int, delimiter: str | None, usecols: list[int],
                 path: Path) -> np.ndarray:
    """Parse numeric rows; on failure, find the offending line and name it."""
    if not any(ln.strip() and not ln.lstrip().startswith("#") for ln in lines):
        raise ImucalError("has no data rows", file=str(path), field="data",
                          fix="record samples after the header")
    try:
        # The lines themselves, not a joined copy in a StringIO: half the time and no second copy.
        arr = np.loadtxt(lines, delimiter=delimiter, usecols=usecols, ndmin=2, dtype=float, comments="#")
        # A row from every line: none was blank or a comment, so all were parsed (no count needed).
        if arr.shape[0] == len(lines) or arr.shape[0] == data_line_count(lines, "\n".join(lines)):
            bad = ~np.isfinite(arr).all(axis=1)
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                raise ImucalError(f"line {lineno(lines, k, first_lineno)} holds NaN or Inf",
                                  file=str(path), field="data",
                                  fix="remove or repair the non-finite rows before calibrating")
            return arr
    except ImucalError:
        raise
    except (ValueError, IndexError):
        pass
    check_lines(lines, first_lineno, delimiter, usecols, path)
    raise unparsed(path)


#: A line of nothing but whitespace (what str.strip removes, which is what \s matches), in lines
#: joined by "\n".
_BLANK_LINE = re.compile(r"\n[^\S\n]*\n")


def data_line_count(lines: list[str], text: str) -> int:
    """How many of ``lines`` (``text`` = the lines joined by "\\n") are neither blank nor comments.

    Without a "#" or a blank line in the text every line counts, found by scans in C rather than
    a Python test of each line.
    """
    if not lines:
        return 0
    if "#" not in text and lines[0].strip() and lines[-1].strip() and not _BLANK_LINE.search(text):
        return len(lines)
    return sum(1 for ln in lines if ln.strip() and not ln.lstrip().startswith("#"))


def unparsed(path: Path) -> ImucalError:
    """Numbers that numpy cannot read although no line is found wrong."""
    return ImucalError("could not be parsed as numeric columns", file=str(path), field="data",
                       fix="use CSV with a header or whitespace-separated numbers")


def check_lines(lines: list[str], first_lineno: int, delimiter: str | None, usecols: list[int], path: Path) -> None:
    """The slow path: raise the message for the first line with too few columns, a non-number or
    a non-finite value."""
    ncol = max(usecols) + 1
    for i, ln in enumerate(lines):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        toks = _split(s, delimiter)
        if len(toks) < ncol:
            raise ImucalError(f"line {first_lineno + i} has {len(toks)} columns, expected at least {ncol}",
                              file=str(path), field="data",
                              fix="make every row hold the same columns as the header")
        for c in usecols:
            if not _is_number(toks[c]):
                raise ImucalError(f"line {first_lineno + i} column {c + 1}: {toks[c][:20]!r} is not a number",
                                  file=str(path), field="data",
                                  fix="remove non-numeric rows or map the right columns")
            if not math.isfinite(float(toks[c])):
                raise ImucalError(f"line {first_lineno + i} holds NaN or Inf", file=str(path),
                                  field="data", fix="remove or repair the non-finite rows before calibrating")


def lineno(lines: list[str], k: int, first: int) -> int:
    seen = -1
    for i, ln in enumerate(lines):
        s = ln.strip()
        if s and not s.startswith("#"):
            seen += 1
            if seen == k:
                return first + i
    return first


_DEFAULT_NAMES = {"t": ("t", "time", "timestamp"), "ax": ("ax", "acc_x", "accx", "x"),
                  "ay": ("ay", "acc_y", "accy", "y"), "az": ("az", "acc_z", "accz", "z"),
                  "gx": ("gx", "gyro_x", "gyrx", "wx"), "gy": ("gy", "gyro_y", "gyry", "wy"),
                  "gz": ("gz", "gyro_z", "gyrz", "wz"), "temp": ("temp", "temperature", "t_c")}


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


def _no_header_layout(ncol: int, path: Path) -> dict[str, int]:
    """Column roles of a file without header and without a mapping."""
    if ncol == 3:
        return {"ax": 0, "ay": 1, "az": 2}
    if ncol == 4:
        return {"t": 0, "ax": 1, "ay": 2, "az": 3}  # imu_tk: t x y z
    if ncol == 5:
        return {"t": 0, "ax": 1, "ay": 2, "az": 3, "temp": 4}  # imucal's simulate layout
    if ncol < 3:
        raise ImucalError(f"has {ncol} column(s): an accelerometer recording needs at least ax ay az",
                          file=str(path), field="data.columns",
                          fix="check the delimiter (data.delimiter) or give the file with its three axes")
    # The likely layout, and a mapping for it that the user can check against the file.
    hint, example = {6: (" (logs like the MPU-6050's hold ax ay az gx gy gz)", "ax=0,ay=1,az=2"),
                     7: (" (imu_tk-style logs hold t gx gy gz ax ay az)", "t=0,ax=4,ay=5,az=6")}.get(
                         ncol, ("", "t=0,ax=1,ay=2,az=3"))
    raise ImucalError(f"has {ncol} columns and no header: the layout is ambiguous{hint}", file=str(path),
                      field="data.columns",
                      fix=f"map the columns, e.g. --columns {example} or data.columns in the YAML")


def _check_bag_spec(spec: DataSpec, path: Path) -> None:
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


@dataclass(frozen=True)
class Layout:
    """Where a recording's numbers are: delimiter, column of each role read, first data line."""

    delimiter: str | None
    columns: dict  #: role -> 0-based column index (every role found)
    roles: list  #: the roles read, in ROLES order
    body: int  #: index (in the lines after skip_rows) of the first line after the header
    body_first: int  #: its 1-based line number in the file
    time_column: str  #: the time column's name in the file ("t" without a header)

    @property
    def usecols(self) -> list[int]:
        return [self.columns[r] for r in self.roles]

    @property
    def has_gyro(self) -> bool:
        return "gx" in self.roles


def resolve_path(spec: DataSpec, base_dir: str | os.PathLike | None) -> Path:
    """The recording's path (relative paths are relative to ``base_dir``, the YAML file's folder)."""
    path = Path(spec.path)
    return Path(base_dir) / path if base_dir is not None and not path.is_absolute() else path


def as_spec(spec: DataSpec | str | os.PathLike) -> DataSpec:
    return spec if isinstance(spec, DataSpec) else DataSpec(path=str(spec))


def _find_header(lines: list[str], k0: int, spec: DataSpec, path: Path) -> int | None:
    """Index of the header line: the first text line with the mapped (or known default) names."""
    if spec.format not in ("auto", "csv"):
        return None
    wanted = [str(v) for r, v in spec.columns.items() if isinstance(v, str)]
    first_text: list[str] | None = None  # the first non-numeric line, for the message
    for i in range(k0, min(len(lines), k0 + _MAX_SCAN_LINES)):
        toks = _split(lines[i], spec.delimiter or _sniff_delimiter(lines[i]))
        if toks and not all(_is_number(t) for t in toks):
            names = [t.strip().strip('"').strip("'") for t in toks]
            first_text = names if first_text is None else first_text
            if wanted and not all(w in names for w in wanted):
                continue
            if not wanted and not any(n.lower() in sum(_DEFAULT_NAMES.values(), ()) for n in names):
                continue
            return i
    if wanted and first_text is not None:
        missing = [w for w in wanted if w not in first_text]
        raise ImucalError(f"mapped column(s) {missing} not in header {first_text[:12]}", file=str(path),
                          field="data.columns", fix="map the roles to the header's names")
    if spec.format == "csv":
        raise ImucalError("no header line with the mapped column names found", file=str(path),
                          field="data.columns",
                          fix="add a header row, or set data.format: whitespace with column indices")
    return None


def _header_columns(names: list[str], spec: DataSpec, path: Path) -> dict[str, int]:
    """Role -> column index from a header: the mapped names (or indices), else the default names."""
    lower = [n.lower() for n in names]
    cols: dict[str, int] = {}
    for role in ROLES:
        if role in spec.columns:
            want = spec.columns[role]
            if isinstance(want, int):
                cols[role] = want
            elif want in names:
                cols[role] = _only_column(names, want, role, path)
            else:
                raise ImucalError(f"column {short(want)} (for {role}) not in header {short(names, 200)}",
                                  file=str(path), field=f"data.columns.{role}",
                                  fix="map the role to one of the header's names")
        else:
            name = next((c for c in _DEFAULT_NAMES[role] if c in lower), None)
            if name is not None:
                cols[role] = _only_column(lower, name, role, path)
    return cols


def _only_column(names: list[str], name: str, role: str, path: Path) -> int:
    """The index of the one header column called ``name`` (read as ``role``); a name the header
    gives twice is refused, naming both positions (1-based), not the first taken silently."""
    at = [i for i, n in enumerate(names) if n == name]
    if len(at) > 1:
        raise ImucalError(f"the header names column {short(name)} (read as {role}) twice: columns "
                          f"{at[0] + 1} and {at[1] + 1}", file=str(path), field=f"data.columns.{role}",
                          fix=f"rename one of them, or map {role} to a 0-based column index "
                              f"(e.g. --columns {role}={at[0]})")
    return at[0]


def _check_roles(cols: dict[str, int], spec: DataSpec, path: Path) -> None:
    for role in ("ax", "ay", "az"):
        if role not in cols:
            raise ImucalError(f"missing column for {role}", file=str(path), field=f"data.columns.{role}",
                              fix=f"add a column named {role} or map it in data.columns")
    if "t" not in cols and spec.sample_rate is None:
        raise ImucalError("no time column and no sample rate", file=str(path), field="data.sample_rate",
                          fix="add a t column or set data.sample_rate in Hz")
    gyro_roles = [r for r in ("gx", "gy", "gz") if r in cols]
    if gyro_roles and len(gyro_roles) != 3:
        raise ImucalError(f"only {', '.join(gyro_roles)} of gx, gy, gz mapped", file=str(path),
                          field="data.columns", fix="map all three gyroscope columns or none")


def layout(lines: list[str], spec: DataSpec, path: Path) -> Layout:
    """Header, delimiter and column roles from the lines after ``spec.skip_rows`` (the whole file,
    or its head: the first data line and _MAX_SCAN_LINES after the first non-comment line)."""
    first_lineno = spec.skip_rows + 1
    # Find the first non-empty, non-comment line.
    k0 = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")), None)
    if k0 is None:
        raise ImucalError("is empty", file=str(path), field="data.path",
                          fix="record samples into the file")
    header_idx = _find_header(lines, k0, spec, path)
    names: list[str] = []
    if header_idx is not None:
        delim = spec.delimiter or _sniff_delimiter(lines[header_idx])
        names = [t.strip().strip('"').strip("'") for t in _split(lines[header_idx], delim)]
        cols = _header_columns(names, spec, path)
        wide = [r for r, c in cols.items() if not 0 <= c < len(names)]
        if wide:
            raise ImucalError(f"column {cols[wide[0]]} of {wide[0]} is beyond the header's {len(names)} columns",
                              file=str(path), field=f"data.columns.{wide[0]}",
                              fix=f"give a 0-based index below {len(names)}, or the column's name")
        body = header_idx + 1
    else:
        if not all(_is_number(t) for t in _split(lines[k0], spec.delimiter)):
            raise ImucalError(f"line {first_lineno + k0} is neither a header with known column names nor numbers",
                              file=str(path), field="data.columns",
                              fix="name columns t, ax, ay, az (temp) or map them in data.columns")
        delim = spec.delimiter or _sniff_delimiter(lines[k0])
        cols = {r: int(v) for r, v in spec.columns.items() if isinstance(v, int)}
        if any(isinstance(v, str) for v in spec.columns.values()):
            raise ImucalError("column names given but the file has no header", file=str(path),
                              field="data.columns", fix="map roles to 0-based column indices")
        if not cols:
            cols = _no_header_layout(len(_split(lines[k0], delim)), path)
        body = k0
    _check_roles(cols, spec, path)
    roles = [r for r in ROLES if r in cols]
    tname = names[cols["t"]] if header_idx is not None and "t" in roles else "t"
    return Layout(delimiter=delim, columns=cols, roles=roles, body=body, body_first=first_lineno + body,
                  time_column=tname)


def no_rows(path: Path) -> ImucalError:
    return ImucalError("has no data rows", file=str(path), field="data", fix="record samples after the header")


def corrupt_value(line: int, path: Path) -> ImucalError:
    """A value beyond MAX_ABS_VALUE on ``line``."""
    return ImucalError(f"line {line} holds a value beyond +-{MAX_ABS_VALUE:g} (corrupt)", file=str(path),
                       field="data", fix="remove or repair the corrupt rows before calibrating")


def not_increasing(line: int, path: Path) -> ImucalError:
    """Time stamps that do not increase at ``line``."""
    return ImucalError(f"time is not strictly increasing at line {line}", file=str(path), field="data.columns.t",
                       fix="sort the rows by time and drop duplicates")


def load_recording(spec: DataSpec | str | os.PathLike, base_dir: str | os.PathLike | None = None
                   ) -> Recording:
    """Read a recording described by ``spec`` (a DataSpec or just a path with defaults)."""
    spec = as_spec(spec)
    path = resolve_path(spec, base_dir)
    if is_bag(path):
        _check_bag_spec(spec, path)
        return read_bag(path, spec.topic, spec.temp_topic)
    for name in ("topic", "temp_topic"):
        if getattr(spec, name) is not None:
            raise ImucalError(f"{name} applies to ROS bags only", file=str(path), field=f"data.{name}",
                              fix="give a .bag file or a ROS 2 bag folder, or drop the topic")
    blob, sha = _read_bytes(path)
    fast = _fast_table(blob, spec, path)
    if fast is not None:  # every line after the header is a row
        (lay, arr), body = fast, None
    else:
        lines = _decode(blob, path).splitlines()[spec.skip_rows:]
        lay = layout(lines, spec, path)
        body = lines[lay.body:]
        arr = parse_block(body, lay.body_first, lay.delimiter, lay.usecols, path)
    del blob
    body_first = lay.body_first

    def line_of(k: int) -> int:  # the file's line number of row k
        return body_first + k if body is None else lineno(body, k, body_first)

    big = np.abs(arr) > MAX_ABS_VALUE
    if big.any():
        raise corrupt_value(line_of(int(np.flatnonzero(big.any(axis=1))[0])), path)
    data = {r: arr[:, i] for i, r in enumerate(lay.roles)}
    n = arr.shape[0]
    stamps = data.get("t")
    if stamps is not None and n > 1:
        d = np.diff(stamps)
        if not (d > 0).all():
            raise not_increasing(line_of(int(np.flatnonzero(~(d > 0))[0]) + 1), path)
    if stamps is None:
        unit, note, tb = rate_time_base(spec.sample_rate)
        t = np.arange(n) / float(spec.sample_rate)
    elif n:  # a given sample rate beside the stamps is checked against them (imucal.data.timebase)
        t, unit, note, tb = stamped_times(stamps, spec.time_unit, spec.sample_rate, lay.time_column, path, line_of)
    else:
        raise no_rows(path)
    raw = np.column_stack([data["ax"], data["ay"], data["az"]])
    gyro = np.column_stack([data["gx"], data["gy"], data["gz"]]) if lay.has_gyro else None
    return Recording(t=t, raw=raw, temp=data.get("temp"), unit=spec.unit, source=str(path), sha256=sha,
                     gyro=gyro, t_source=stamps, time_unit=unit, time_note=note, time_column=lay.time_column,
                     gyro_unit=gyro_unit(spec), time_base=tb)


#: Recordings above this size are read in chunks (imucal.data.stream) when data.stream is "auto" [bytes].
STREAM_BYTES = 64 * 1024**2


def use_stream(spec: DataSpec, base_dir: str | os.PathLike | None = None) -> bool:
    """Whether ``spec`` is read in chunks: data.stream always, or auto and a file above STREAM_BYTES
    without gyroscope data (columns or a second file)."""
    if is_bag(resolve_path(spec, base_dir)):
        return False  # a ROS bag is read message by message (imucal.data.rosbag)
    if spec.stream != "auto":
        return spec.stream == "always"
    if spec.gyro_path is not None:
        return False
    try:
        if os.stat(resolve_path(spec, base_dir)).st_size <= STREAM_BYTES:
            return False
    except OSError:
        return False  # the loader names the problem
    return not has_gyro(spec, base_dir)  # the gyroscope fit needs every sample


def has_gyro(spec: DataSpec, base_dir: str | os.PathLike | None = None) -> bool:
    """Whether a recording comes with gyroscope data: a second file, or gx gy gz columns (read from
    its head by the chunked reader's layout)."""
    if spec.gyro_path is not None:
        return True
    from imucal.data.stream import head_layout  # measured start-up: only for a file read in chunks

    return head_layout(spec, resolve_path(spec, base_dir)).has_gyro
