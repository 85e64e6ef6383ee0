"""The whole-file reader of a text recording: every row in memory, one Recording.

The file is refused as a whole before it is parsed (imucal.data.lines: NUL bytes, an over-long
line, not UTF-8); the common recording (ASCII, every line after the header a row) is parsed by
numpy's C reader from the bytes (fixed-width numbers, as MATLAB writes them, by imucal.data.fixed_width:
the same doubles), anything else line by line, which names the line at fault.
The time base is imucal.data.timebase's, as for every reader.
"""
from __future__ import annotations

import hashlib
import io
import os
import re
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from imucal.data import fixed_width
from imucal.data.counter_wrap import CounterWrap
from imucal.data.layout import MAX_SCAN_LINES, Layout, header_spec, layout, other_instance
from imucal.data.lines import (BINARY_PROBE, binary_file, corrupt_value, decimal_comma, decode, line_too_long,
                               lineno, long_line, no_rows, not_increasing, parse_block, plain_text, split)
from imucal.data.recording import MAX_ABS_VALUE, Recording
from imucal.data.spec import DataSpec, gyro_unit
from imucal.data.timebase import rate_time_base, stamped_times
from imucal.errors import ImucalError
from imucal.files.inputs import first_hole, max_data_bytes, open_regular, unreadable


def _read_bytes(path: Path) -> tuple[bytes, str]:
    """Bytes and SHA-256 of a recording: a regular file, within the size limit, text (no NUL byte,
    no line longer than MAX_LINE_BYTES). A sparse file is read only up to its first hole."""
    fd, size = open_regular(path, field="data.path", max_bytes=max_data_bytes(),
                            fix="check the path (relative paths are relative to the YAML file)")
    hole = first_hole(fd, size)  # a sparse file's NUL tail is never read
    try:
        with os.fdopen(fd, "rb") as f:
            if b"\x00" in (probe := f.read(BINARY_PROBE)):  # a binary file is refused before it is read whole
                raise binary_file(path, head=probe)
            f.seek(0)
            blob = f.read(hole)
    except OSError as exc:
        raise unreadable(path, "data.path", exc) from None
    nul = blob.find(b"\x00")
    if nul >= 0 or hole < size:
        raise binary_file(path, blob.count(b"\n", 0, nul if nul >= 0 else len(blob)) + 1)
    start = long_line(blob)
    if start is not None:
        raise line_too_long(path, blob.count(b"\n", 0, start) + 1)
    return blob, hashlib.sha256(blob).hexdigest()


def _fast_table(blob: bytes, spec: DataSpec, path: Path) -> tuple[Layout, np.ndarray] | None:
    """The common recording read without a Python string per line: ASCII, lines ended by "\n" or
    "\r\n", every line after the header a finite row. None for anything else, which the line by line
    reader (parse_block) reads and, when it is wrong, names the line at fault. Same numbers: the same
    numpy parser reads the same bytes."""
    if not plain_text(blob):
        return None
    n_lines = blob.count(b"\n") + (len(blob) > 0 and not blob.endswith(b"\n"))
    end = -1  # the head: the lines the layout looks at (its first data line and MAX_SCAN_LINES more)
    for _ in range(spec.skip_rows + 2 * MAX_SCAN_LINES):
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
    if (lay.body + MAX_SCAN_LINES >= len(head) and end < len(blob)) or n_lines <= first:
        return None  # the layout may depend on lines past the head; or no row at all
    arr = None
    if lay.delimiter is None:  # fixed-width numbers (MATLAB's save -ascii): read as digits in columns
        start = 0
        for _ in range(first):
            start = blob.find(b"\n", start) + 1
        arr = fixed_width.table(blob, start, lay.usecols)
    if arr is None:
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


def read_text(spec: DataSpec, path: Path) -> Recording:
    """Every row of the text recording at ``path`` (read as ``spec`` says), in memory."""
    blob, sha = _read_bytes(path)
    fast = _fast_table(blob, spec, path)
    if fast is not None:  # every line after the header is a row
        (lay, arr), body = fast, None
    else:
        lines = decode(blob, path).splitlines()[spec.skip_rows:]
        lay = layout(lines, spec, path)
        body = lines[lay.body:]
        if decimal_comma(body, lay.delimiter):  # 0,01;9,81: read as 0.01 and 9.81
            body = [ln.replace(",", ".") for ln in body]
        arr = parse_block(body, lay.body_first, lay.delimiter, lay.usecols, path)
    rate_source = "given" if spec.sample_rate is not None else "stated above the header"
    spec = header_spec(spec, lay, path)  # the units the header's names state, a rate its metadata lines state
    body_first = lay.body_first

    def line_of(k: int) -> int:  # the file's line number of row k
        return body_first + k if body is None else lineno(body, k, body_first)

    if lay.instance is not None:  # an instance column: every row's, not only the head's (one sensor)
        rows = decode(blob, path).splitlines()[spec.skip_rows + lay.body:] if body is None else body
        other_instance(rows, lay, path, line_of)

    del blob
    big = np.abs(arr) > MAX_ABS_VALUE
    if big.any():
        raise corrupt_value(line_of(int(np.flatnonzero(big.any(axis=1))[0])), path)
    data = {r: arr[:, i] for i, r in enumerate(lay.roles)}
    n = arr.shape[0]
    stamps, wrap = data.get("t"), CounterWrap()
    if stamps is not None and n > 1:
        stamps = wrap.feed(stamps)  # a counter that wrapped (micros()), unwrapped
        d = np.diff(stamps)
        if not (d > 0).all():
            k = int(np.flatnonzero(~(d > 0))[0])
            raise not_increasing(line_of(k + 1), path, float(stamps[k]), float(stamps[k + 1]))
    if stamps is None:
        unit, note, tb = rate_time_base(spec.sample_rate, rate_source)
        t = np.arange(n) / float(spec.sample_rate)
    elif n:  # a given sample rate beside the stamps is checked against them (imucal.data.timebase)
        t, unit, note, tb = stamped_times(stamps, spec.time_unit, spec.sample_rate, lay.time_column, path, line_of)
        note, tb = "; ".join(x for x in (note, wrap.note) if x), replace(tb, wraps=wrap.wraps)
    else:
        raise no_rows(path)
    raw = np.column_stack([data["ax"], data["ay"], data["az"]])
    gyro = np.column_stack([data["gx"], data["gy"], data["gz"]]) if lay.has_gyro else None
    mag = np.column_stack([data["mx"], data["my"], data["mz"]]) if "mx" in lay.roles else None
    return Recording(t=t, raw=raw, temp=data.get("temp"), unit=spec.unit, source=str(path), sha256=sha,
                     gyro=gyro, mag=mag, t_source=stamps, time_unit=unit, time_note=note, time_column=lay.time_column,
                     gyro_unit=gyro_unit(spec), time_base=tb, mag_unit=lay.units.get("mag_unit", "raw"),
                     columns=lay.names, unit_stated_by=lay.names.get("ax", "") if "unit" in lay.units else "")


def stamp_texts(spec: DataSpec, path: Path, n: int) -> list[str] | None:
    """The time column's own text in each of the ``n`` rows of a text recording, when every one is an integer:
    stamps beyond 2**53 (EuRoC's nanoseconds since 1970) that a double rounds (by up to 128 ns) are written back
    as the file holds them. None for another file (binary, no time column) or rows that differ in count."""
    try:
        blob, _ = _read_bytes(path)
        lines = decode(blob, path).splitlines()[spec.skip_rows:]
        lay = layout(lines, spec, path)
    except ImucalError:  # a netCDF file or a ROS bag: its stamps as read
        return None
    if "t" not in lay.columns:
        return None
    col = lay.columns["t"]
    texts = [toks[col] if len(toks := split(ln, lay.delimiter)) > col else "" for ln in lines[lay.body:]
             if ln.strip() and not ln.lstrip().startswith("#")]
    return texts if len(texts) == n and all(_INTEGER.fullmatch(t) for t in texts) else None


_INTEGER = re.compile(r"[-+]?[0-9]+")

