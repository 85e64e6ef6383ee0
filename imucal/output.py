"""Atomic output: every file is written to a temporary sibling and renamed into place.

A failed run leaves no half-written file: ``OutputSet`` stages all files of one run and moves
them in only when the whole run has succeeded.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable

from .errors import ImucalError


def _check_parent(path: Path) -> None:
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise ImucalError("parent is not a directory", file=str(path), field="output",
                          fix="choose an output path inside a directory")


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    path = Path(path)
    _check_parent(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: str | os.PathLike, obj: Any) -> None:
    write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=False, allow_nan=True) + "\n")


class OutputSet:
    """Stage several output files and publish them together.

    >>> with OutputSet() as out:                       # doctest: +SKIP
    ...     out.text("run/report.txt", report)
    ...     out.call("run/fig.png", lambda p: fig.savefig(p))
    Nothing appears at the destinations unless the block completes.
    """

    def __init__(self) -> None:
        self._staged: list[tuple[Path, Path]] = []
        self._tmpdirs: dict[Path, Path] = {}

    def _stage(self, dest: str | os.PathLike) -> Path:
        dest = Path(dest)
        _check_parent(dest)
        parent = dest.parent
        if parent not in self._tmpdirs:
            parent.mkdir(parents=True, exist_ok=True)
            self._tmpdirs[parent] = Path(tempfile.mkdtemp(prefix=".imucal-", dir=parent))
        tmp = self._tmpdirs[parent] / dest.name
        self._staged.append((tmp, dest))
        return tmp

    def text(self, dest: str | os.PathLike, text: str) -> None:
        self._stage(dest).write_text(text, encoding="utf-8")

    def json(self, dest: str | os.PathLike, obj: Any) -> None:
        self.text(dest, json.dumps(obj, indent=2, allow_nan=True) + "\n")

    def call(self, dest: str | os.PathLike, writer: Callable[[Path], None]) -> None:
        """Let ``writer(tmp_path)`` produce the file (e.g. matplotlib's savefig)."""
        writer(self._stage(dest))

    def __enter__(self) -> "OutputSet":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        try:
            if exc_type is None:
                for tmp, dest in self._staged:
                    os.replace(tmp, dest)
        finally:
            for d in self._tmpdirs.values():
                shutil.rmtree(d, ignore_errors=True)
