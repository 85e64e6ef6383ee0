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


def check_destination(path: str | os.PathLike) -> Path:
    """``path`` can be written as a file: it is not a directory, and its nearest existing
    ancestor is a directory. Raises ImucalError (before any work is done) otherwise."""
    path = Path(path)
    if path.is_dir():
        raise ImucalError("is a directory, not a file name", file=str(path), field="output",
                          fix="give a file name for this output")
    for anc in path.parents:
        if anc.exists():
            if not anc.is_dir():
                raise ImucalError("parent is not a directory", file=str(path), field="output",
                                  fix="choose an output path inside a directory")
            break
    return path


def _make_parent(path: Path) -> list[Path]:
    """Create the parent directories of ``path``; return the ones created, outermost first."""
    missing = [a for a in path.parents if not a.exists()][::-1]
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ImucalError(f"cannot create the directory: {exc.strerror}", file=str(path), field="output") from None
    return missing


def _remove_dirs(dirs: list[Path]) -> None:
    """Remove directories we created, innermost first, if they are empty."""
    for d in reversed(dirs):
        try:
            d.rmdir()
        except OSError:
            pass


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> None:
    path = check_destination(path)
    created = _make_parent(path)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
        _remove_dirs(created)
        if isinstance(exc, OSError):
            raise ImucalError(f"cannot write: {exc.strerror or exc}", file=str(path), field="output") from None
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
        self._created: list[Path] = []  #: directories made for this set, removed if it fails

    def _stage(self, dest: str | os.PathLike) -> Path:
        dest = check_destination(dest)
        parent = dest.parent
        if parent not in self._tmpdirs:
            self._created.extend(_make_parent(dest))
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
        published = False
        try:
            if exc_type is None:
                for _, dest in self._staged:  # nothing may have become a directory meanwhile
                    check_destination(dest)
                for tmp, dest in self._staged:
                    try:
                        os.replace(tmp, dest)
                    except OSError as err:
                        raise ImucalError(f"cannot write: {err.strerror or err}", file=str(dest),
                                          field="output") from None
                published = True
        finally:
            for d in self._tmpdirs.values():
                shutil.rmtree(d, ignore_errors=True)
            if not published:
                _remove_dirs(self._created)
