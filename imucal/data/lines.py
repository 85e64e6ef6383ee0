"""Lines of a text recording: the bytes refused before any is parsed (NUL, over-long lines, not
UTF-8), tokens, blocks of rows parsed into numbers, and the line-numbered errors every reader gives
for the same bad line (imucal.data.whole reads a file at once, imucal.data.stream in blocks).
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from imucal.data.recording import MAX_ABS_VALUE
from imucal.errors import ImucalError
from imucal.files.inputs import WIDE_TEXT_FIX, wide_text

#: Largest recording read in chunks [bytes] (a file read whole: imucal.files.inputs.max_data_bytes).
MAX_STREAM_BYTES = 1024**4
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


#: Binary files recordings come in, by their first bytes: what the file is, and how to get text imucal reads.
BINARY_FORMATS = (
    (b"ULog\x01\x12\x35", "a PX4 ULog", "write its accelerometer as CSV with pyulog (ulog2csv LOG.ulg -m "
                                       "sensor_accel: before PX4's calibration, with the temperature) and calibrate "
                                       "that CSV"),
    (b"\xa3\x95", "an ArduPilot DataFlash log", "write its IMU as CSV with pymavlink (mavlogdump.py --types IMU "
                                              "--condition 'IMU.I==0' --format csv LOG.bin > imu.csv)"),
    (b"MATLAB 5.0 MAT-file", "a binary MATLAB MAT-file", "save the samples as text in MATLAB (writematrix(X, "
                                                         "'log.csv') with a header row, or save -ascii)"),
    (b"PK\x03\x04", "a zip archive (a spreadsheet's .xlsx, or a compressed log)",
     "save the sheet as CSV, or unzip the recording"),
    (b"\x1f\x8b", "a gzip-compressed file", "decompress it (gunzip) and calibrate the text"),
)


def binary_file(path: Path, line: int | None = None, head: bytes = b"") -> ImucalError:
    """NUL bytes: at the head of the file (``head``: its first bytes, which may name its format), or
    (``line``) after text (a sparse or corrupt file)."""
    where = "" if line is None or line <= 1 else f" from line {line} on (a sparse or corrupt file)"
    known = next(((what, fix) for magic, what, fix in BINARY_FORMATS if head.startswith(magic)), None)
    if known is None and not where and wide_text(head):  # a spreadsheet's "Unicode text": text, not UTF-8
        return ImucalError("is UTF-16 or UTF-32 text, not UTF-8", file=str(path), field="data.path", fix=WIDE_TEXT_FIX)
    if known is not None and not where:
        return ImucalError(f"is {known[0]}, not a text recording", file=str(path), field="data.path", fix=known[1])
    return ImucalError(f"is a binary file (NUL bytes){where}, not a text recording", file=str(path),
                       field="data.path", fix="export the recording as CSV or whitespace-separated text")


#: ASCII bytes that end a line for str.splitlines but not for numpy's or pandas' readers (or not
#: alone: "\r").
OTHER_BREAKS = (b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e")


def plain_text(buf: bytes) -> bool:
    """ASCII with lines ended by "\n" or "\r\n" only: text the fast parsers read as the line by
    line reader does."""
    return buf.isascii() and not any(b in buf for b in OTHER_BREAKS) and (
        b"\r" not in buf or buf.count(b"\r") == buf.count(b"\r\n"))


def check_text(buf: bytes, path: Path, first_line: Callable[[], int]) -> None:
    """The refusals of a text recording for ``buf`` (which starts a line): a NUL byte (a sparse or
    binary file) and a line longer than MAX_LINE_BYTES. ``first_line``: buf's first line number,
    counted only for a message."""
    nul = buf.find(b"\x00")
    if nul >= 0:
        raise binary_file(path, first_line() + buf.count(b"\n", 0, nul))
    start = long_line(buf)
    if start is not None:
        raise line_too_long(path, first_line() + buf.count(b"\n", 0, start))


def not_utf8(path: Path) -> ImucalError:
    return ImucalError("is not UTF-8 text", file=str(path), field="data.path",
                       fix="export the recording as CSV or whitespace-separated text")


def decode(blob: bytes, path: Path) -> str:
    try:
        return blob.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise not_utf8(path) from None


def is_number(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.replace(",", " ").replace(";", " ").split()
    return [c.strip() for c in line.split(delimiter)]


def parse_block(lines: list[str], first_lineno: int, delimiter: str | None, usecols: list[int],
                 path: Path) -> np.ndarray:
    """Parse numeric rows; on failure, find the offending line and name it."""
    if not any(ln.strip() and not ln.lstrip().startswith("#") for ln in lines):
        raise no_rows(path)
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
        toks = split(s, delimiter)
        if len(toks) < ncol:
            raise ImucalError(f"line {first_lineno + i} has {len(toks)} columns, expected at least {ncol}",
                              file=str(path), field="data",
                              fix="make every row hold the same columns as the header")
        for c in usecols:
            if not is_number(toks[c]):
                raise ImucalError(f"line {first_lineno + i} column {c + 1}: {toks[c][:20]!r} is not a number",
                                  file=str(path), field="data", fix=not_a_number_fix(toks[c], delimiter))
            if not math.isfinite(float(toks[c])):
                raise ImucalError(f"line {first_lineno + i} holds NaN or Inf", file=str(path),
                                  field="data", fix="remove or repair the non-finite rows before calibrating")


_DECIMAL_COMMA = re.compile(r"^[+-]?\d+,\d+([eE][+-]?\d+)?$")


def decimal_comma(lines: list[str], delimiter: str | None) -> bool:
    """Whether the rows ``lines`` (a file's first, after its header) write their numbers with a decimal comma (a
    spreadsheet's or phyphox's European export: 0,01;9,81): fields split by ";" or a tab, and a d,d field whose
    comma is followed by other than three digits (1,234 alone could be a thousands separator)."""
    if delimiter not in (";", "\t"):
        return False
    seen = False
    for ln in [x for x in lines if x.strip() and not x.lstrip().startswith("#")][:50]:
        for tok in (t.strip() for t in ln.split(delimiter)):
            if _DECIMAL_COMMA.match(tok):  # another text is left for the parser to name
                seen = seen or len(tok.split(",")[1].split("e")[0].split("E")[0]) != 3
    return seen


def not_a_number_fix(tok: str, delimiter: str | None) -> str:
    """What to do about a field that is not a number: an empty cell (sensors logged apart), a decimal comma
    (a spreadsheet's European locale), or another text."""
    if not tok.strip():
        return ("an empty cell: a logger that writes each sensor's rows apart (at its own rate) leaves the other "
                "sensors' cells empty; write each sensor to its own file, or fill the rows, before calibrating")
    if delimiter != "," and _DECIMAL_COMMA.match(tok.strip()):
        return "the numbers have a decimal comma: write them with a decimal point (a spreadsheet in an English locale)"
    return "remove non-numeric rows or map the right columns"


def lineno(lines: list[str], k: int, first: int) -> int:
    seen = -1
    for i, ln in enumerate(lines):
        s = ln.strip()
        if s and not s.startswith("#"):
            seen += 1
            if seen == k:
                return first + i
    return first


def no_rows(path: Path) -> ImucalError:
    return ImucalError("has no data rows", file=str(path), field="data", fix="record samples after the header")


def corrupt_value(line: int, path: Path) -> ImucalError:
    """A value beyond MAX_ABS_VALUE on ``line``."""
    return ImucalError(f"line {line} holds a value beyond +-{MAX_ABS_VALUE:g} (corrupt)", file=str(path),
                       field="data", fix="remove or repair the corrupt rows before calibrating")


def not_increasing(line: int, path: Path, before: float, after: float) -> ImucalError:
    """Time stamps that do not increase at ``line``: ``after`` follows ``before``."""
    if after == before:
        return ImucalError(f"time stamp {after:.15g} repeats at line {line}", file=str(path), field="data.columns.t",
                           fix="write the stamps with enough digits for each sample to have its own (or drop the time "
                               "column and give --sample-rate HZ); a row written twice: remove it")
    return ImucalError(f"time goes back at line {line} ({after:.15g} after {before:.15g})", file=str(path),
                       field="data.columns.t",
                       fix=f"sort the rows by time (a file merged out of order); a logger that restarted there: split "
                           f"the file at line {line}; or map the right time column")
