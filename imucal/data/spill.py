"""Numbers parsed once, read back many times: a binary spill in an unnamed temporary file.

A long recording's text is parsed once (imucal.data.stream); the passes after it (the time base's
gaps, a moving variance redone with the right window, each still interval's statistics, the
residual of every static sample) read the rows back from here, as float64 exactly as parsed, a
block at a time: memory a block, whatever the length. The file has no name (it is unlinked when
made), so nothing is left behind whatever ends the run; the operating system's page cache keeps
it in memory while it fits there.
"""
from __future__ import annotations

import tempfile
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np

from imucal.errors import ImucalError

#: Rows read back at a time: 2^18 rows of 4 to 8 columns are 8 to 16 MB.
SPILL_ROWS = 1 << 18


def temporary_file(what: str) -> BinaryIO:
    """An unnamed temporary file (in TMPDIR) for ``what``; its failure in one line."""
    try:
        return tempfile.TemporaryFile(prefix="imucal-")
    except OSError as exc:
        raise spill_error(what, exc) from None


def spill_error(what: str, exc: OSError) -> ImucalError:
    """A spill that cannot be made or written (no space, no temporary folder)."""
    return ImucalError(f"cannot write {what} to a temporary file in {tempfile.gettempdir()}: "
                       f"{exc.strerror or exc}", field="data.stream",
                       fix="free space there or point TMPDIR to a folder with room for about 40 bytes a sample "
                           "(or give --stream never to read the file whole in memory)")


class RowSpill:
    """Rows of ``ncol`` float64 columns, appended in blocks, read back in blocks of SPILL_ROWS."""

    def __init__(self, ncol: int) -> None:
        self.ncol, self.n = ncol, 0
        self._f = temporary_file("the parsed rows")

    def add(self, arr: np.ndarray) -> None:
        arr = np.ascontiguousarray(arr, np.float64)
        try:
            self._f.write(memoryview(arr).cast("B"))
        except OSError as exc:
            raise spill_error("the parsed rows", exc) from None
        self.n += arr.shape[0]

    def blocks(self) -> Iterator[tuple[int, np.ndarray]]:
        """(first row, rows) of every block (SPILL_ROWS rows), in order."""
        rows = SPILL_ROWS
        self._f.flush()
        self._f.seek(0)
        row0 = 0
        while row0 < self.n:
            arr = np.empty((min(rows, self.n - row0), self.ncol))
            if self._f.readinto(memoryview(arr).cast("B")) != arr.nbytes:  # pragma: no cover - the file is ours
                raise OSError("the spill of parsed rows ended early")
            yield row0, arr
            row0 += arr.shape[0]

    def column_blocks(self, j: int) -> Iterator[np.ndarray]:
        """Column ``j`` of every block, in order."""
        for _, arr in self.blocks():
            yield arr[:, j].copy()

    def close(self) -> None:
        self._f.close()

    @property
    def nbytes(self) -> int:
        return self.n * self.ncol * 8
