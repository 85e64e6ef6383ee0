"""Loading recordings: CSV with a header, or whitespace text without one (imu_tk's t x y z)."""
from __future__ import annotations

import hashlib
import io
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ImucalError

#: Time units accepted for the time column, with their factor to seconds.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
FORMATS = ("auto", "csv", "whitespace")
_MAX_SCAN_LINES = 50


@dataclass(frozen=True)
class DataSpec:
    """How to read one recording (the YAML ``data:`` section).

    ``columns`` maps the roles t, ax, ay, az, temp to column names (CSV with header) or to
    0-based column indices (files without header). Without a time column, give
    ``sample_rate`` [Hz]. ``unit`` labels the raw values ("raw" counts, or "m/s^2").
    """

    path: str
    format: str = "auto"
    columns: dict = field(default_factory=dict)
    delimiter: str | None = None
    skip_rows: int = 0
    sample_rate: float | None = None
    time_unit: str = "s"
    unit: str = "raw"

    def __post_init__(self) -> None:
        if not isinstance(self.path, (str, os.PathLike)) or not str(self.path):
            raise ImucalError(f"path {self.path!r} must be a file name", field="data.path",
                              fix="give the recording's path as text")
        for name in ("format", "time_unit", "unit"):
            if not isinstance(getattr(self, name), str):
                raise ImucalError(f"{name} {getattr(self, name)!r} must be text", field=f"data.{name}")
        if self.delimiter is not None and not (isinstance(self.delimiter, str) and self.delimiter):
            raise ImucalError(f"delimiter {self.delimiter!r} must be a non-empty string", field="data.delimiter",
                              fix='e.g. delimiter: ","  (omit it to detect , ; tab or spaces)')
        if self.sample_rate is not None and (isinstance(self.sample_rate, bool)
                                             or not isinstance(self.sample_rate, (int, float))):
            raise ImucalError(f"sample rate {self.sample_rate!r} must be a positive number of Hz",
                              field="data.sample_rate", fix="give the logging rate in Hz")
        if not isinstance(self.columns, Mapping):
            raise ImucalError("must map roles to columns", field="data.columns")
        for role, col in self.columns.items():
            if not ((isinstance(col, int) and not isinstance(col, bool) and col >= 0)
                    or (isinstance(col, str) and col)):
                raise ImucalError(f"column {col!r} for {role!r} must be a header name or a 0-based index",
                                  field=f"data.columns.{role}")
        if self.format not in FORMATS:
            raise ImucalError(f"unknown format {self.format!r}", field="data.format",
                              fix=f"use one of {', '.join(FORMATS)}")
        if self.time_unit not in TIME_UNITS:
            raise ImucalError(f"unknown time unit {self.time_unit!r}", field="data.time_unit",
                              fix=f"use one of {', '.join(TIME_UNITS)}")
        if self.sample_rate is not None and not (math.isfinite(self.sample_rate)
                                                 and self.sample_rate > 0):
            raise ImucalError(f"sample rate {self.sample_rate} must be a positive number of Hz",
                              field="data.sample_rate", fix="give the logging rate in Hz")
        if not isinstance(self.skip_rows, int) or isinstance(self.skip_rows, bool) or self.skip_rows < 0:
            raise ImucalError(f"skip_rows {self.skip_rows!r} must be a non-negative integer",
                              field="data.skip_rows")
        bad = set(self.columns) - {"t", "ax", "ay", "az", "temp"}
        if bad:
            raise ImucalError(f"unknown column role(s) {sorted(bad)}", field="data.columns",
                              fix="map only t, ax, ay, az, temp")


@dataclass(frozen=True)
class Recording:
    """A loaded recording: time [s], raw readings (N x 3), optional temperature [deg C]."""

    t: np.ndarray
    raw: np.ndarray
    temp: np.ndarray | None
    unit: str
    source: str
    sha256: str

    @property
    def n(self) -> int:
        return self.raw.shape[0]

    @property
    def sample_rate(self) -> float:
        if self.n < 2:
            return float("nan")
        return float((self.n - 1) / (self.t[-1] - self.t[0]))

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.n else 0.0


def file_sha256(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _read_text(path: Path) -> tuple[str, str]:
    try:
        blob = path.read_bytes()
    except FileNotFoundError:
        raise ImucalError("file not found", file=str(path), field="data.path",
                          fix="check the path (relative paths are relative to the YAML file)") from None
    except IsADirectoryError:
        raise ImucalError("is a directory, not a data file", file=str(path), field="data.path",
                          fix="point data.path at the recording file") from None
    except OSError as exc:
        raise ImucalError(f"cannot read: {exc.strerror}", file=str(path), field="data.path") from None
    try:
        text = blob.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ImucalError("is not UTF-8 text", file=str(path), field="data.path",
                          fix="export the recording as CSV or whitespace-separated text") from None
    return text, hashlib.sha256(blob).hexdigest()


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


def _parse_block(lines: list[str], first_lineno: int, delimiter: str | None, usecols: list[int],
                 path: Path) -> np.ndarray:
    """Parse numeric rows; on failure, find the offending line and name it."""
    if not any(ln.strip() and not ln.lstrip().startswith("#") for ln in lines):
        raise ImucalError("has no data rows", file=str(path), field="data",
                          fix="record samples after the header")
    ncol = max(usecols) + 1
    try:
        arr = np.loadtxt(io.StringIO("\n".join(lines)), delimiter=delimiter, usecols=usecols,
                         ndmin=2, dtype=float, comments="#")
        if arr.shape[0] == len([ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")]):
            bad = ~np.isfinite(arr).all(axis=1)
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                raise ImucalError(f"line {_lineno(lines, k, first_lineno)} holds NaN or Inf",
                                  file=str(path), field="data",
                                  fix="remove or repair the non-finite rows before calibrating")
            return arr
    except ImucalError:
        raise
    except (ValueError, IndexError):
        pass
    # Slow path: locate the first bad line for the message.
    k = 0
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
        k += 1
    raise ImucalError("could not be parsed as numeric columns", file=str(path), field="data",
                      fix="use CSV with a header or whitespace-separated numbers")


def _lineno(lines: list[str], k: int, first: int) -> int:
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
                  "temp": ("temp", "temperature", "t_c")}


def load_recording(spec: DataSpec | str | os.PathLike, base_dir: str | os.PathLike | None = None
                   ) -> Recording:
    """Read a recording described by ``spec`` (a DataSpec or just a path with defaults)."""
    if not isinstance(spec, DataSpec):
        spec = DataSpec(path=str(spec))
    path = Path(spec.path)
    if base_dir is not None and not path.is_absolute():
        path = Path(base_dir) / path
    text, sha = _read_text(path)
    lines = text.splitlines()[spec.skip_rows:]
    first_lineno = spec.skip_rows + 1
    # Find the first non-empty, non-comment line.
    k0 = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")), None)
    if k0 is None:
        raise ImucalError("is empty", file=str(path), field="data.path",
                          fix="record samples into the file")
    fmt = spec.format
    header_idx = None
    if fmt in ("auto", "csv"):
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
                header_idx = i
                break
        if wanted and header_idx is None and first_text is not None:
            missing = [w for w in wanted if w not in first_text]
            raise ImucalError(f"mapped column(s) {missing} not in header {first_text[:12]}", file=str(path),
                              field="data.columns", fix="map the roles to the header's names")
        if fmt == "csv" and header_idx is None:
            raise ImucalError("no header line with the mapped column names found", file=str(path),
                              field="data.columns",
                              fix="add a header row, or set data.format: whitespace with column indices")
    if header_idx is not None:
        hdr_line = lines[header_idx]
        delim = spec.delimiter or _sniff_delimiter(hdr_line)
        names = [t.strip().strip('"').strip("'") for t in _split(hdr_line, delim)]
        lower = [n.lower() for n in names]
        cols: dict[str, int] = {}
        for role in ("t", "ax", "ay", "az", "temp"):
            if role in spec.columns:
                want = spec.columns[role]
                if isinstance(want, int):
                    cols[role] = want
                elif want in names:
                    cols[role] = names.index(want)
                else:
                    raise ImucalError(f"column {want!r} (for {role}) not in header {names}",
                                      file=str(path), field=f"data.columns.{role}",
                                      fix="map the role to one of the header's names")
            else:
                hit = next((lower.index(c) for c in _DEFAULT_NAMES[role] if c in lower), None)
                if hit is not None:
                    cols[role] = hit
        body = lines[header_idx + 1:]
        body_first = first_lineno + header_idx + 1
    else:
        if k0 is not None and not all(_is_number(t) for t in _split(lines[k0], spec.delimiter)):
            raise ImucalError(f"line {first_lineno + k0} is neither a header with known column names nor numbers",
                              file=str(path), field="data.columns",
                              fix="name columns t, ax, ay, az (temp) or map them in data.columns")
        delim = spec.delimiter or _sniff_delimiter(lines[k0])
        ncol = len(_split(lines[k0], delim))
        cols = {r: int(v) for r, v in spec.columns.items() if isinstance(v, int)}
        if any(isinstance(v, str) for v in spec.columns.values()):
            raise ImucalError("column names given but the file has no header", file=str(path),
                              field="data.columns", fix="map roles to 0-based column indices")
        if not cols:
            if ncol >= 5:
                cols = {"t": 0, "ax": 1, "ay": 2, "az": 3, "temp": 4}
            elif ncol == 4:
                cols = {"t": 0, "ax": 1, "ay": 2, "az": 3}  # imu_tk: t x y z
            elif ncol == 3:
                cols = {"ax": 0, "ay": 1, "az": 2}
            else:
                raise ImucalError(f"has {ncol} numeric columns; cannot guess the layout", file=str(path),
                                  field="data.columns", fix="map t, ax, ay, az to column indices")
        body = lines[k0:]
        body_first = first_lineno + k0
    for role in ("ax", "ay", "az"):
        if role not in cols:
            raise ImucalError(f"missing column for {role}", file=str(path), field=f"data.columns.{role}",
                              fix=f"add a column named {role} or map it in data.columns")
    if "t" not in cols and spec.sample_rate is None:
        raise ImucalError("no time column and no sample rate", file=str(path), field="data.sample_rate",
                          fix="add a t column or set data.sample_rate in Hz")
    roles = [r for r in ("t", "ax", "ay", "az", "temp") if r in cols]
    if spec.sample_rate is not None and "t" in cols and "t" not in spec.columns:
        roles.remove("t")  # an explicit rate overrides a guessed time column
    arr = _parse_block(body, body_first, delim, [cols[r] for r in roles], path)
    data = {r: arr[:, i] for i, r in enumerate(roles)}
    n = arr.shape[0]
    if "t" in data:
        t = data["t"] * TIME_UNITS[spec.time_unit]
        dt = np.diff(t)
        if n > 1 and not (dt > 0).all():
            k = int(np.flatnonzero(dt <= 0)[0])
            raise ImucalError(f"time is not strictly increasing at line {_lineno(body, k + 1, body_first)}",
                              file=str(path),
                              field="data.columns.t", fix="sort the rows by time and drop duplicates")
        t = t - t[0]
    else:
        t = np.arange(n) / float(spec.sample_rate)
    raw = np.column_stack([data["ax"], data["ay"], data["az"]])
    return Recording(t=t, raw=raw, temp=data.get("temp"), unit=spec.unit, source=str(path), sha256=sha)
