"""A text recording's body in blocks of whole lines: their byte offsets, the file's SHA-256, the
numbers of each block (pandas' C parser, or line by line for anything unusual, which names the bad
line), and line numbers counted only when a message needs one. The file is refused if it changes
between reads.
"""
from __future__ import annotations

import csv
import hashlib
import io
import os
import queue
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from imucal.data.layout import Layout, file_head
from imucal.data.lines import (MAX_STREAM_BYTES, check_lines, check_text, decimal_comma, lineno, not_utf8, parse_block,
                               plain_text, unparsed)
from imucal.data.spec import DataSpec
from imucal.errors import ImucalError
from imucal.files.inputs import open_regular
from imucal.report.progress import progress

#: Bytes parsed at a time (whole lines): a block's text and numbers are what a long log's reading
#: holds in memory (about 16 MB of text and 10 MB of numbers), and pandas reads this much in one call
#: at its full speed.
CHUNK_BYTES = 16 * 1024**2
#: Blocks read and parsed ahead of the one being used (each about CHUNK_BYTES of text and its numbers).
READ_AHEAD = 2
#: Bytes of the first rows looked at for a decimal comma.
DECIMAL_PROBE = 64 * 1024


class TextBlocks:
    """A recording's body in blocks of whole lines (with their byte offsets and parsed rows); the
    file is refused if it changes between passes."""

    def __init__(self, spec: DataSpec, path: Path) -> None:
        self.spec, self.path = spec, path
        fd, self.size = open_regular(path, field="data.path", max_bytes=MAX_STREAM_BYTES,
                                     fix="check the path (relative paths are relative to the YAML file)")
        st = os.fstat(fd)
        self.stamp = (st.st_size, st.st_mtime_ns, st.st_ino)
        os.close(fd)
        self.sha = ""
        #: numbers numpy could not read in an earlier block, no line found wrong there: later
        #: lines are checked one by one for a message naming one (as the loader does), else this
        self.unparsed: ImucalError | None = None
        self.lay, self.offset = self._head()
        self._counted = (self.offset, self.lay.body_first)
        self._lock = threading.Lock()
        with self._open() as f:  # 0,01;9,81: read as the whole-file reader reads it, from the first rows
            f.seek(self.offset)
            first = f.read(DECIMAL_PROBE).decode("utf-8", errors="replace").splitlines()[:-1]
        #: the rows write their numbers with a decimal comma (imucal.data.lines.decimal_comma)
        self.comma = decimal_comma(first, self.lay.delimiter)

    def _open(self) -> io.BufferedReader:
        fd, _ = open_regular(self.path, field="data.path", max_bytes=MAX_STREAM_BYTES)
        st = os.fstat(fd)
        if (st.st_size, st.st_mtime_ns, st.st_ino) != self.stamp:
            os.close(fd)
            raise ImucalError("changed while it was being read", file=str(self.path), field="data.path",
                              fix="calibrate a copy that no program is writing to")
        return os.fdopen(fd, "rb")

    def _head(self) -> tuple[Layout, int]:
        """Header and layout from the head of the file; byte offset of the body."""
        with self._open() as f:
            return file_head(f, self.spec, self.path)

    def line_at(self, offset: int) -> int:
        """Line number of the line starting at byte ``offset`` of the body (counted when a message
        needs it, from the last one counted)."""
        with self._lock:  # the reading thread (rows) and its caller may both need one
            return self._line_at(offset)

    def _line_at(self, offset: int) -> int:
        at, line = self._counted
        if offset < at:
            at, line = self.offset, self.lay.body_first
        with self._open() as f:
            f.seek(at)
            while at < offset:
                data = f.read(min(CHUNK_BYTES, offset - at))
                if not data:
                    break
                line += data.count(b"\n")
                at += len(data)
        self._counted = (offset, line)
        return line

    def blocks(self, hash_it: bool = False) -> Iterator[tuple[int, bytes]]:
        """(byte offset, bytes of whole lines) from the body on; the SHA-256 of the whole file is
        left in ``self.sha`` when ``hash_it``."""
        h = hashlib.sha256() if hash_it else None
        at = self.offset
        shown = progress(f"reading {self.path.name}", total=self.stamp[0], unit="B", scale=True)
        with self._open() as f, shown as step:
            if h is not None:
                h.update(f.read(self.offset))
            else:
                f.seek(self.offset)
            carry = b""
            while True:
                data = f.read(CHUNK_BYTES)
                step(len(data))  # a bar on a terminal (imucal.report.progress)
                if h is not None:
                    h.update(data)
                if not data:
                    if carry.strip():
                        yield at, carry
                    break
                buf = carry + data
                check_text(buf, self.path, lambda: self.line_at(at))  # a sparse tail or a line without end stops here
                cut = buf.rfind(b"\n") + 1
                if cut == 0:
                    carry = buf
                    continue
                block, carry = buf[:cut], buf[cut:]
                yield at, block
                at += cut
            if f.tell() != self.stamp[0]:
                raise ImucalError("changed while it was being read", file=str(self.path), field="data.path",
                                  fix="calibrate a copy that no program is writing to")
        if h is not None:
            self.sha = h.hexdigest()

    def parse(self, block: bytes, offset: int) -> np.ndarray:
        """The used columns of a block's rows (roles order), or the loader's message for its first bad line."""
        lay = self.lay
        if self.unparsed is not None:
            check_lines(self._lines(block), self.line_at(offset), lay.delimiter, lay.usecols, self.path)
            return np.empty((0, len(lay.usecols)))
        if plain_text(block):
            # imported here: pandas adds about 0.3 s to start-up, which a short recording read whole
            # never pays (the measured start-up of `imucal calibrate` in docs/benchmarks.md)
            import pandas as pd

            try:
                df = pd.read_csv(io.BytesIO(block), sep=lay.delimiter or r"\s+", header=None, usecols=lay.usecols,
                                 dtype=np.float64, comment="#", skip_blank_lines=True, quoting=csv.QUOTE_NONE,
                                 engine="c", decimal="," if self.comma else ".")
                arr = df[lay.usecols].to_numpy(dtype=np.float64)
                # NaN and infinity carry into the sum; so may huge finite values, which the line by
                # line reader below then reads (and the caller refuses as corrupt)
                if np.isfinite(np.add.reduce(arr, axis=None)):
                    return arr
            except (ValueError, IndexError, pd.errors.ParserError, pd.errors.EmptyDataError):
                pass
        lines = self._lines(block)
        if not any(ln.strip() and not ln.lstrip().startswith("#") for ln in lines):
            return np.empty((0, len(lay.usecols)))
        try:
            return parse_block(lines, self.line_at(offset), lay.delimiter, lay.usecols, self.path)
        except ImucalError as exc:
            if exc.message != unparsed(self.path).message:
                raise
            self.unparsed = exc
            return np.empty((0, len(lay.usecols)))

    def _lines(self, block: bytes) -> list[str]:
        try:
            lines = block.decode("utf-8").splitlines()
        except UnicodeDecodeError:
            raise not_utf8(self.path) from None
        return [ln.replace(",", ".") for ln in lines] if self.comma else lines

    def rows(self, hash_it: bool = False) -> Iterator[tuple[int, bytes, np.ndarray]]:
        """(byte offset, block, its rows) of every block, read, hashed and parsed up to READ_AHEAD
        blocks ahead in a thread: reading, hashing and pandas' tokenizer release the GIL, so the
        caller's work on one block runs beside the parsing of the next. An error in the thread is
        raised here; the thread stops when the caller does."""
        ahead: queue.Queue = queue.Queue(maxsize=READ_AHEAD)
        stop = threading.Event()

        def put(item: object) -> bool:
            while not stop.is_set():
                try:
                    ahead.put(item, timeout=0.05)
                    return True
                except queue.Full:
                    continue
            return False

        def work() -> None:
            try:
                for offset, block in self.blocks(hash_it):
                    if not put((offset, block, self.parse(block, offset))):
                        return
                put(None)
            except BaseException as exc:  # noqa: B036 - handed to the caller, which raises it
                put(exc)

        reader = threading.Thread(target=work, name="imucal-read", daemon=True)
        reader.start()
        try:
            while (item := ahead.get()) is not None:
                if isinstance(item, BaseException):
                    raise item
                yield item
        finally:
            stop.set()
            reader.join()

    def line_of(self, block: bytes, offset: int, k: int) -> int:
        """File line of data row ``k`` of the block at ``offset``."""
        return lineno(block.decode("utf-8").splitlines(), k, self.line_at(offset))
