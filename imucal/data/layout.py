"""Where a text recording's numbers are: the delimiter (sniffed), the header line and the column
of each role (Layout), found in the lines after ``skip_rows`` or in the head of a file.

imucal.data.lines reads the rows; this module only looks at the head: the first data line and
MAX_SCAN_LINES after the first non-comment line.
"""
from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import BinaryIO

from imucal.data.header_names import bare_axes, is_unit_name, read_name, unit_meaning
from imucal.data.header_units import metadata_rate, spec_with_units, stated_units, units_row
from imucal.data.lines import BINARY_PROBE, MAX_STREAM_BYTES, binary_file, check_text, is_number, not_utf8, split
from imucal.data.spec import ROLES, DataSpec
from imucal.data.timebase import time_column_name
from imucal.errors import ImucalError, short
from imucal.files.inputs import open_regular

#: Lines after the first non-comment line searched for the header (and the lines a layout may
#: depend on).
MAX_SCAN_LINES = 50
#: Largest head of a file searched for the header and the first data line [bytes].
MAX_HEAD_BYTES = 64 * 1024**2


def sniff_delimiter(line: str) -> str | None:
    for d in (",", ";", "\t"):
        if d in line:
            return d
    return None


_DEFAULT_NAMES = {"t": ("t", "time", "timestamp"), "ax": ("ax", "acc_x", "accx", "x"),
                  "ay": ("ay", "acc_y", "accy", "y"), "az": ("az", "acc_z", "accz", "z"),
                  "gx": ("gx", "gyro_x", "gyrx", "wx"), "gy": ("gy", "gyro_y", "gyry", "wy"),
                  "gz": ("gz", "gyro_z", "gyrz", "wz"), "temp": ("temp", "temperature", "t_c"),
                  "mx": ("mx", "mag_x", "magx"), "my": ("my", "mag_y", "magy"), "mz": ("mz", "mag_z", "magz")}


def _known(name: str) -> bool:
    """A header name a role is read from without a mapping (a time column's by time_column_name)."""
    read = read_name(name)  # (an axis alone with its unit, "x (g)", as bare_axes reads it)
    return (name.lower() in sum(_DEFAULT_NAMES.values(), ()) or time_column_name(name)[0]
            or read.role is not None or read.words in (("x",), ("y",), ("z",)))


@dataclass(frozen=True)
class Layout:
    """Where a recording's numbers are: delimiter, column of each role read, first data line."""

    delimiter: str | None
    columns: dict  #: role -> 0-based column index (every role found)
    roles: list  #: the roles read, in ROLES order
    body: int  #: index (in the lines after skip_rows) of the first line after the header
    body_first: int  #: its 1-based line number in the file
    time_column: str  #: the time column's name in the file ("t" without a header)
    #: the units the header's names state: data.unit (acceleration) and data.gyro_unit, in imucal's
    #: spelling (imucal.data.header_names), for header_spec
    units: dict = field(default_factory=dict)
    #: [Hz] a sample rate a metadata line above the header states ("Fs,100"), for header_spec
    sample_rate: float | None = None
    #: role -> the header's name of its column (with a units row's unit), for the record of what was read
    names: dict = field(default_factory=dict)
    #: (column, name, value, its text) of an instance column (ArduPilot's I) that holds one number in the head:
    #: every row is checked to hold it too (other_instance), as interleaved sensors may start past the head
    instance: tuple[int, str, float, str] | None = None

    @property
    def usecols(self) -> list[int]:
        return [self.columns[r] for r in self.roles]

    @property
    def has_gyro(self) -> bool:
        return "gx" in self.roles

    @property
    def has_mag(self) -> bool:
        return "mx" in self.roles


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


def _uncommented(line: str) -> str:
    """A header line without the comment sign EuRoC's and TUM's files put before it (#timestamp [ns],...)."""
    return line.lstrip()[1:] if line.lstrip().startswith("#") else line


def _comment_header(lines: list[str], k0: int) -> list[int]:
    """The comment line just before the first data line when it has as many fields as that line (a
    header written as a comment: EuRoC, Kalibr, TUM); none otherwise."""
    c = next((i for i in range(k0 - 1, -1, -1) if lines[i].strip()), None)
    if c is None or not lines[c].lstrip().startswith("#"):
        return []
    delim = sniff_delimiter(lines[k0])
    return [c] if len(split(_uncommented(lines[c]), delim)) == len(split(lines[k0], delim)) else []


def _find_header(lines: list[str], k0: int, spec: DataSpec, path: Path) -> int | None:
    """Index of the header line: the last text line with the mapped (or known default) names above the first
    row of numbers (a title line above the header may hold a known word: "... Z up.")."""
    if spec.format not in ("auto", "csv"):
        return None
    wanted = [str(v) for r, v in spec.columns.items() if isinstance(v, str)]
    first_text: list[str] | None = None  # the first non-numeric line, for the message
    found = None  # the last line with the names above the first row of numbers: a title above it is no header
    for i in [*_comment_header(lines, k0), *range(k0, min(len(lines), k0 + MAX_SCAN_LINES))]:
        toks = split(_uncommented(lines[i]), spec.delimiter or sniff_delimiter(lines[i]))
        if toks and not all(is_number(t) for t in toks):
            names = [t.strip().strip('"').strip("'") for t in toks]
            first_text = names if first_text is None else first_text
            if wanted and not all(w in names for w in wanted):
                continue
            if not wanted and not any(_known(n) for n in names):
                continue
            found = i
        elif toks and found is not None:
            break
    if found is not None:
        return found
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
    """Role -> column index from a header: the mapped names (or indices), else the default names, else
    the role an exporter's name states (imucal.data.header_names: PX4, ArduPilot, EuRoC, ROS, ...)."""
    lower = [n.lower() for n in names]
    read = [read_name(n) for n in names]
    # ArduPilot's IMU message names its temperature T beside its time columns (TimeUS): a bare capital T
    # beside another time column is not the time (imucal's own t, lower case, is)
    capital_t = "T" in names and any(r.role == "t" and n != "T" for n, r in zip(names, read))
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
            continue
        lowered = [n for n, orig in zip(lower, names) if not (capital_t and orig == "T")]
        name = next((c for c in _DEFAULT_NAMES[role] if c in lowered), None)
        if name is None and role == "t":  # timestamp_ms, time_s, stamp: the unit is read from the name
            name = next((n for n in lowered if time_column_name(n)[0]), None)
        if name is not None:
            cols[role] = _only_column(lower, name, role, path)
    for role in ROLES:  # an exporter's names (acc_x [g], AccX, accelerometer_m_s2[0], w_RS_S_x [rad s^-1])
        if role not in cols:
            at = [i for i, r in enumerate(read) if r.role == role and i not in cols.values()]
            if role == "temp" and not at and capital_t and "timeus" in lower:
                at = [names.index("T")]  # ArduPilot's IMU message: TimeUS the time, T the temperature [degC]
            if len(at) > 1:
                raise ImucalError(f"columns {short(names[at[0]])} and {short(names[at[1]])} both name {role}",
                                  file=str(path), field=f"data.columns.{role}",
                                  fix=f"map {role} to one of them, e.g. --columns {role}={at[0]}")
            if at:
                cols[role] = at[0]
    if not any(r in cols for r in ("ax", "ay", "az")):  # x, y, z (g): an accelerometer's axes alone
        cols.update({r: i for r, i in bare_axes(names).items() if i not in cols.values()})
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


def _check_roles(cols: dict[str, int], spec: DataSpec, path: Path, meta_rate: float | None = None) -> None:
    for role in ("ax", "ay", "az"):
        if role not in cols:
            raise ImucalError(f"missing column for {role}", file=str(path), field=f"data.columns.{role}",
                              fix=f"add a column named {role} or map it in data.columns")
    if "t" not in cols and spec.sample_rate is None and meta_rate is None:
        raise ImucalError("no time column and no sample rate", file=str(path), field="data.sample_rate",
                          fix="add a t column or set data.sample_rate in Hz")
    for axes, what in ((("gx", "gy", "gz"), "gyroscope"), (("mx", "my", "mz"), "magnetometer")):
        given = [r for r in axes if r in cols]
        if given and len(given) != 3:
            raise ImucalError(f"only {', '.join(given)} of {', '.join(axes)} mapped", file=str(path),
                              field="data.columns", fix=f"map all three {what} columns or none")


def layout(lines: list[str], spec: DataSpec, path: Path) -> Layout:
    """Header, delimiter and column roles from the lines after ``spec.skip_rows`` (the whole file,
    or its head: the first data line and MAX_SCAN_LINES after the first non-comment line)."""
    first_lineno = spec.skip_rows + 1
    # Find the first non-empty, non-comment line.
    k0 = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")), None)
    if k0 is None:
        raise ImucalError("is empty", file=str(path), field="data.path",
                          fix="record samples into the file")
    header_idx = _find_header(lines, k0, spec, path)
    names: list[str] = []
    if header_idx is not None:
        delim = spec.delimiter or sniff_delimiter(lines[header_idx])
        names = [t.strip().strip('"').strip("'") for t in split(_uncommented(lines[header_idx]), delim)]
        if units_row(lines[header_idx + 1] if header_idx + 1 < len(lines) else "", delim, len(names)) is None:
            # rows with more fields than names: said before any name is missed ("time (s)x (g),y (g),z (g)")
            _fields_named(names, lines[header_idx + 1:header_idx + 1 + MAX_SCAN_LINES], delim,
                          first_lineno + header_idx + 1, path)
            checked = True
        else:
            checked = False
        cols = _header_columns(names, spec, path)
        wide = [r for r, c in cols.items() if not 0 <= c < len(names)]
        if wide:
            raise ImucalError(f"column {cols[wide[0]]} of {wide[0]} is beyond the header's {len(names)} columns",
                              file=str(path), field=f"data.columns.{wide[0]}",
                              fix=f"give a 0-based index below {len(names)}, or the column's name")
        body = max(header_idx + 1, k0)
        below = units_row(lines[body] if body < len(lines) else "", delim, len(names))
        if below is not None:  # a line of units under the names (s, m/s^2, deg/s, degC): read as theirs
            _one_unit_each(names, below, path)
            names = [f"{n} [{u}]" if u and read_name(n).unit is None else n for n, u in zip(names, below)]
            body += 1
        instance = _one_instance(names, lines[body:body + MAX_SCAN_LINES], delim, path, first_lineno + body)
        if not checked or below is not None:  # (the rows below a line of units, checked once)
            _fields_named(names, lines[body:body + MAX_SCAN_LINES], delim, first_lineno + body, path)
    else:
        if not all(is_number(t) for t in split(lines[k0], spec.delimiter)):
            raise ImucalError(f"line {first_lineno + k0} is neither a header with known column names nor numbers",
                              file=str(path), field="data.columns",
                              fix="name columns t, ax, ay, az (temp) or map them in data.columns")
        delim = spec.delimiter or sniff_delimiter(lines[k0])
        cols = {r: int(v) for r, v in spec.columns.items() if isinstance(v, int)}
        if any(isinstance(v, str) for v in spec.columns.values()):
            raise ImucalError("column names given but the file has no header", file=str(path),
                              field="data.columns", fix="map roles to 0-based column indices")
        if not cols:
            cols = _no_header_layout(len(split(lines[k0], delim)), path)
        body = k0
        instance = None
    meta_rate = metadata_rate(lines[k0:header_idx], delim) if header_idx is not None else None
    _check_roles(cols, spec, path, meta_rate)
    roles = [r for r in ROLES if r in cols]
    tname = names[cols["t"]] if header_idx is not None and "t" in roles else "t"
    return Layout(delimiter=delim, columns=cols, roles=roles, body=body, body_first=first_lineno + body,
                  time_column=tname, units=stated_units(names, cols, path) if names else {},
                  sample_rate=meta_rate, names={r: names[cols[r]] for r in roles} if names else {},
                  instance=instance)


def _one_unit_each(names: list[str], below: list[str], path: Path) -> None:
    """Refuse a column whose name states one unit and the line of units under the header another (acc_x [g] over
    m/s^2): which one the numbers are in, the file does not say."""
    for n, u in zip(names, below):
        stated = read_name(n).unit
        if u and stated is not None and is_unit_name(u) and is_unit_name(stated) and (
                unit_meaning(u) != unit_meaning(stated)):
            raise ImucalError(f"column {short(n)} states {short(stated)} in its name and {short(u)} in the line of "
                              "units under the header", file=str(path), field="data.columns",
                              fix="give each column's unit once (in its name or in the line of units), or make the two "
                                  "agree")


def _fields_named(names: list[str], head: list[str], delim: str | None, first: int, path: Path) -> None:
    """Refuse a first row with more filled fields than the header has names: the names do not describe the rows
    (0,01,9,81 with a comma for both the decimal point and the delimiter; a header from another table)."""
    k = next((i for i, ln in enumerate(head) if ln.strip() and not ln.lstrip().startswith("#")), None)
    if k is None or delim is None:
        return
    toks = split(head[k], delim)
    filled = len(toks) - next((i for i, t in enumerate(reversed(toks)) if t), len(toks))  # a trailing empty field
    if filled > len(names):
        decimal_comma = delim == "," and not any("." in t for t in toks)  # 0,01,9,81: no decimal point left
        comma = " (numbers with a decimal comma, and commas between them?)" if decimal_comma else ""
        raise ImucalError(f"line {first + k} has {filled} fields, the header names {len(names)}{comma}",
                          file=str(path), field="data.columns",
                          fix="give the header one name per column" + (", and write the numbers with a decimal point "
                                                                        "or split the fields by ;" if comma else ""))


#: Column names that number the sensor a row comes from (ArduPilot's IMU message: I).
INSTANCE_NAMES = ("i", "instance")


def _one_instance(names: list[str], head: list[str], delim: str | None, path: Path,
                  first_line: int) -> tuple[int, str, float, str] | None:
    """Refuse rows of several sensors interleaved in one file (an instance column that changes in the
    head's rows): read as one sensor, they would be calibrated as one. The (column, name, value, text) of the
    instance column that holds one number in the head, for other_instance to check every row against; None without one.
    ``first_line``: the file's line of ``head[0]``."""
    for k, name in enumerate(names):
        if name.lower() in INSTANCE_NAMES:
            seen: dict[float, str] = {}  # compared as numbers: 0 and 0.0 are one IMU
            for i, ln in enumerate(head):
                if ln.strip() and not ln.lstrip().startswith("#") and len(toks := split(ln, delim)) > k:
                    seen.setdefault(instance_number(toks[k], name, path, first_line + i), toks[k])
            if len(seen) > 1:
                raise interleaved(path, name, set(seen.values()))
            if seen:
                value, text = next(iter(seen.items()))
                return k, name, value, text
    return None


def instance_number(tok: str, name: str, path: Path, line: int) -> float:
    """The IMU number an instance column's cell holds (its text as a number: 0, 0.0 and 0e0 are one IMU);
    a cell that is no number is refused naming its line."""
    try:
        x = float(tok.strip().strip('"').strip("'"))
    except ValueError:
        x = math.nan
    if not math.isfinite(x):
        raise ImucalError(f"column {short(name)} holds {short(tok, 20)} at line {line}, not an IMU instance number",
                          file=str(path), field="data.path",
                          fix=f"give every row's IMU number (0, 1, ...) in column {short(name)}, or remove that column")
    return x


def interleaved(path: Path, name: str, seen: set[str], line: int | None = None) -> ImucalError:
    """The refusal of rows of several sensors (column ``name`` holds the values ``seen``; from ``line`` on)."""
    shown = ", ".join(sorted(short(v, 20) for v in seen)[:4])
    where = "" if line is None else f" from line {line} on"
    return ImucalError(f"rows of {len(seen)} sensors are interleaved{where} (column {short(name)} holds {shown})",
                       file=str(path), field="data.path",
                       fix="write one sensor's rows to a file (ArduPilot: mavlogdump.py --types IMU "
                           "--condition 'IMU.I==0' --format csv) and calibrate each")


def other_instance(lines: list[str], lay: Layout, path: Path, line_of: Callable[[int], int]) -> None:
    """Refuse the first data row of ``lines`` whose instance column (Layout.instance) holds another value than
    the head's (``line_of``: the file's line of data row k)."""
    if lay.instance is None:
        return
    col, name, value, text = lay.instance
    k = -1
    for ln in lines:
        if not ln.strip() or ln.lstrip().startswith("#"):
            continue
        k += 1
        toks = split(ln, lay.delimiter)
        if len(toks) > col and toks[col] != text and instance_number(toks[col], name, path, line_of(k)) != value:
            raise interleaved(path, name, {text, toks[col]}, line_of(k))


def header_spec(spec: DataSpec, lay: Layout, path: Path) -> DataSpec:
    """``spec`` with what the file's head states (imucal.data.header_units.spec_with_units): its units, and a
    rate above the header for a file without a time column."""
    return spec_with_units(spec, lay.units, lay.sample_rate, "t" in lay.roles, path)


def file_head(f: BinaryIO, spec: DataSpec, path: Path) -> tuple[Layout, int]:
    """The layout from the head of an open file (read from its start) and the byte offset of its body."""
    skip = spec.skip_rows
    head = f.read(BINARY_PROBE)
    if b"\x00" in head:
        raise binary_file(path, head=head)
    size = 1 << 20
    while True:
        head += f.read(size - len(head))
        check_text(head, path, lambda: 1)
        eof = len(head) < size
        cut = len(head) if eof else head.rfind(b"\n") + 1
        try:
            text = head[:cut].decode("utf-8-sig")
        except UnicodeDecodeError:
            raise not_utf8(path) from None
        rest = text.splitlines()[skip:]
        k0 = next((i for i, ln in enumerate(rest) if ln.strip() and not ln.lstrip().startswith("#")), None)
        if eof or (k0 is not None and len(rest) > k0 + MAX_SCAN_LINES + 1):
            break
        if size >= MAX_HEAD_BYTES:
            raise ImucalError(f"no header or data line in the first {MAX_HEAD_BYTES} bytes", file=str(path),
                              field="data.path", fix="remove the leading text, or give data.stream: never")
        size *= 4
    lay = layout(rest, spec, path)
    bom = 3 if head.startswith(b"\xef\xbb\xbf") else 0
    kept = text.splitlines(keepends=True)  # the same lines with their line breaks
    return lay, bom + sum(len(ln.encode("utf-8")) for ln in kept[:skip + lay.body])


def head_layout(spec: DataSpec, path: Path) -> Layout:
    """The layout of a recording's head (whether it has gyroscope columns, before it is read)."""
    fd, _ = open_regular(path, field="data.path", max_bytes=MAX_STREAM_BYTES,
                         fix="check the path (relative paths are relative to the YAML file)")
    with os.fdopen(fd, "rb") as f:
        return file_head(f, spec, path)[0]


#: The head of a second (gyroscope) file searched for its header [bytes]: a header further down is not looked
#: for (the file is then read with the loader's defaults, imu_tk's t x y z).
GYRO_HEAD_BYTES = 64 * 1024


def gyro_file_spec(spec: DataSpec, path: Path) -> DataSpec:
    """The spec a second file is read with for its gyroscope (``--gyro-data``): its gyroscope columns as the three
    axes when its header names them (gx.., gyro_x [rad/s], w_RS_S_x, Gyroscope x (rad/s)), also beside an
    accelerometer's; else ``spec`` (imu_tk's t x y z)."""
    if spec.columns:
        return spec
    fd, _ = open_regular(path, field="--gyro-data", max_bytes=MAX_STREAM_BYTES,
                         fix="check the path of the gyroscope's file")
    with os.fdopen(fd, "rb") as f:
        head = f.read(GYRO_HEAD_BYTES)
    if b"\x00" in head:
        raise binary_file(path, head=head)
    lines = head.decode("utf-8-sig", errors="replace").splitlines()[spec.skip_rows:]
    if len(head) == GYRO_HEAD_BYTES:
        lines = lines[:-1]  # whole lines only
    k0 = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")), None)
    at = None if k0 is None else _find_header(lines, k0, spec, path)
    if at is None:
        return spec
    names = [t.strip().strip('"').strip("'") for t in split(_uncommented(lines[at]), spec.delimiter
                                                                   or sniff_delimiter(lines[at]))]
    cols = _header_columns(names, spec, path)
    if not {"gx", "gy", "gz"} <= cols.keys():  # (a file with both sensors gives its gyroscope's, not its ax..)
        return spec
    roles = {"ax": "gx", "ay": "gy", "az": "gz", **({"t": "t"} if "t" in cols else {})}
    return replace(spec, columns={r: names[cols[g]] for r, g in roles.items()})
