"""Reading input files safely: regular files only, bounded size, one-line errors.

Every file imucal reads (recordings, run configs, calibrations, plans) may be written by an
attacker: a FIFO would block forever, a device or /dev/zero never ends, a sparse file claims
gigabytes. Inputs are opened without blocking, checked to be regular files on the opened
descriptor (no race with a rename), and refused above a size limit before anything is read.
"""
from __future__ import annotations

import errno
import os
import stat
from pathlib import Path
from typing import Any

from imucal.errors import ImucalError, short

#: Largest text file read whole [bytes]: YAML configs, calibrations, plans.
MAX_TEXT_BYTES = 16 * 1024 * 1024
#: Largest recording read [bytes] (overridable with IMUCAL_MAX_DATA_BYTES).
MAX_DATA_BYTES = 4 * 1024**3


def max_data_bytes() -> int:
    """The recording size limit, from IMUCAL_MAX_DATA_BYTES when set (bytes)."""
    v = os.environ.get("IMUCAL_MAX_DATA_BYTES")
    if v is None:
        return MAX_DATA_BYTES
    try:
        n = int(v)
    except ValueError:
        raise ImucalError(f"IMUCAL_MAX_DATA_BYTES={v[:40]!r} is not an integer", field="environment",
                          fix="unset it or give a size in bytes") from None
    return max(n, 0)


def open_regular(path: str | os.PathLike, *, field: str, fix: str | None = None,
                 max_bytes: int = MAX_TEXT_BYTES) -> tuple[int, int]:
    """Open ``path`` for reading; return (fd, size). Refuses non-regular files and large ones.

    The caller owns the descriptor (``os.fdopen(fd, "rb")``).
    """
    p = str(path)
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ImucalError("file not found", file=p, field=field, fix=fix or "check the path") from None
    except IsADirectoryError:
        raise ImucalError("is a directory, not a file", file=p, field=field,
                          fix=fix or "give the path of a file") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise symlink_loop(p, field) from None
        raise unreadable(p, field, exc) from None
    try:
        st = os.fstat(fd)
        if stat.S_ISDIR(st.st_mode):
            raise ImucalError("is a directory, not a file", file=p, field=field,
                              fix=fix or "give the path of a file")
        if not stat.S_ISREG(st.st_mode):
            kind = ("a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device" if stat.S_ISCHR(st.st_mode)
                    or stat.S_ISBLK(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode) else "not a file")
            raise ImucalError(f"is {kind}, not a regular file", file=p, field=field,
                              fix="save the input to a regular file first")
        if st.st_size > max_bytes:
            raise ImucalError(f"is {st.st_size} bytes, above the limit of {max_bytes} bytes", file=p,
                              field=field, fix=fix or "split the file or check that it is the right one")
        _clear_nonblock(fd)
        return fd, int(st.st_size)
    except BaseException:
        os.close(fd)
        raise


def first_hole(fd: int, size: int) -> int:
    """Offset of the first hole of a sparse file (bytes never written, which read as NUL), or
    ``size`` for a file without one. Asked of the file system (SEEK_HOLE), not read; ``size`` where
    the system cannot tell. The descriptor's offset is left at 0."""
    try:
        return min(os.lseek(fd, 0, os.SEEK_HOLE), size)
    except (AttributeError, OSError):  # no SEEK_HOLE on this system or file system
        return size
    finally:
        os.lseek(fd, 0, os.SEEK_SET)


def _clear_nonblock(fd: int) -> None:
    try:
        import fcntl

        fl = fcntl.fcntl(fd, fcntl.F_GETFL)
        fcntl.fcntl(fd, fcntl.F_SETFL, fl & ~os.O_NONBLOCK)
    except (ImportError, OSError):  # pragma: no cover - non-POSIX
        pass


def read_input_bytes(path: str | os.PathLike, *, field: str, fix: str | None = None,
                     max_bytes: int = MAX_TEXT_BYTES) -> bytes:
    """The whole content of a regular file no larger than ``max_bytes``."""
    fd, size = open_regular(path, field=field, fix=fix, max_bytes=max_bytes)
    try:
        with os.fdopen(fd, "rb") as f:
            data = f.read(max_bytes + 1)
    except OSError as exc:
        raise unreadable(path, field, exc) from None
    if len(data) > max_bytes:  # grew while we read it
        raise ImucalError(f"is above the limit of {max_bytes} bytes", file=str(path), field=field,
                          fix=fix or "let the program writing the file finish first, or split the file")
    return data


#: What to do about text in UTF-16 or UTF-32 (a spreadsheet's "Unicode text"): imucal reads UTF-8.
WIDE_TEXT_FIX = ("save it as UTF-8 text (a spreadsheet's \"CSV UTF-8\", or iconv -f UTF-16 -t UTF-8 FILE > NEW) "
                 "and give that")


def wide_text(head: bytes) -> bool:
    """Whether ``head`` (a file's first bytes) is text in UTF-16 or UTF-32: a byte order mark, or ASCII
    characters with the NUL bytes of the wide encoding between them."""
    if head.startswith((b"\xff\xfe", b"\xfe\xff", b"\x00\x00\xfe\xff")):
        return True
    probe = head[:256]
    for width in (2, 4):
        for at in range(width):
            chars = probe[at::width]
            rest = bytes(b for k, b in enumerate(probe) if k % width != at)
            if len(chars) >= 8 and 0 not in chars and not rest.strip(b"\x00") and chars.isascii():
                return True
    return False


def read_input_text(path: str | os.PathLike, *, field: str, fix: str | None = None,
                    max_bytes: int = MAX_TEXT_BYTES) -> str:
    """UTF-8 text of a regular file (BOM allowed); binary content is refused in one line."""
    data = read_input_bytes(path, field=field, fix=fix, max_bytes=max_bytes)
    if b"\x00" in data[:65536]:
        if wide_text(data):
            raise ImucalError("is UTF-16 or UTF-32 text, not UTF-8", file=str(path), field=field, fix=WIDE_TEXT_FIX)
        raise ImucalError("is a binary file (NUL bytes), not text", file=str(path), field=field,
                          fix=fix or "give a text file")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ImucalError("is not UTF-8 text", file=str(path), field=field, fix=fix or "save it as UTF-8") from None


def unreadable(path: str | os.PathLike, field: str, exc: OSError) -> ImucalError:
    """A file the system would not read (an OSError other than not-found), with what to do about its cause."""
    if exc.errno in (errno.EACCES, errno.EPERM):
        fix = "make the file readable for this user (chmod u+r FILE), or copy it somewhere readable"
    elif exc.errno == errno.ENAMETOOLONG:
        fix = "give a shorter path (move the file, or run from its folder)"
    else:
        fix = "check the disk or network share the file is on, or copy the file to a local disk"
    return ImucalError(f"cannot read: {exc.strerror or exc}", file=str(path), field=field, fix=fix)


def symlink_loop(path: str | os.PathLike, field: str) -> ImucalError:
    """A path whose symbolic links lead back to themselves (ELOOP)."""
    return ImucalError("is a loop of symbolic links, not a file", file=str(path), field=field,
                       fix="give the path of the file itself (the links lead back to themselves)")


def resolve(path: str | os.PathLike, *, field: str) -> Path:
    """``path`` made absolute with its symbolic links followed; a loop of links is bad input (one
    line naming ``field``), not the RuntimeError or OSError pathlib raises for it."""
    try:
        return Path(os.path.abspath(path)).resolve()
    except RuntimeError:  # Python < 3.13: "Symlink loop from ..."
        raise symlink_loop(path, field) from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise symlink_loop(path, field) from None
        raise ImucalError(f"cannot resolve: {exc.strerror or exc}", file=str(path), field=field,
                          fix="check the path: each folder on it must exist and be readable") from None


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True when two paths name the same existing file (device and inode), or resolve equal. A
    path that cannot be resolved (a loop of symbolic links) names no file: False (its reader
    refuses it, naming its field)."""
    try:
        sa, sb = os.stat(a), os.stat(b)
        if (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino):
            return True
    except OSError:
        pass
    try:
        return resolve(a, field="path") == resolve(b, field="path")
    except ImucalError:
        return False


def read_json(path: str, field_: str,
              fix: str = "give the JSON file as its tool wrote it (plain JSON: no NaN, each key once)") -> Any:
    """JSON without NaN/Infinity constants (not JSON) and without duplicate keys; ``fix``: what to do about a file
    that is not."""
    def no_constant(name: str) -> None:
        raise ValueError(f"{name} is not a JSON number")

    def no_duplicates(pairs: list) -> dict:
        d: dict = {}
        for k, v in pairs:
            if k in d:
                raise ValueError(f"duplicate key {short(k)}")
            d[k] = v
        return d

    import json  # measured start-up: only a run that reads a JSON file

    try:
        return json.loads(read_input_text(path, field=field_), parse_constant=no_constant,
                          object_pairs_hook=no_duplicates)
    except (ValueError, RecursionError) as exc:
        raise ImucalError(f"is not valid JSON: {' '.join(str(exc).split())[:80]}", file=path, field=field_,
                          fix=fix) from None
