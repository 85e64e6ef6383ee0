"""Atomic output: every file is written to a temporary sibling and renamed into place.

A failed run leaves no half-written file: ``OutputSet`` stages all files of one run and moves
them in only when the whole run has succeeded. Nothing is lost: an output may not be one of the
run's inputs (same path or same inode), two outputs may not be the same file, and only regular
files are ever replaced. Publishing holds an exclusive lock on each output folder, so two runs
into one folder publish whole sets, one after the other. Staging folders carry the run's pid;
those left by a killed run are removed by the next run into the same folder.
"""
from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import signal
import stat
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, TextIO

from imucal.errors import INTERRUPTING, ImucalError
from imucal.files.inputs import same_file

PathLike = str | os.PathLike
_STAGING = re.compile(r"^\.imucal-(\d+)-")

#: An output named "-" goes to standard output (``--json -``), as in any Unix tool: after the run has
#: succeeded, in one piece, while the words a command prints go to stderr (``data_on_stdout``).
STDOUT = "-"
_data_streams: list[TextIO] = []  #: the standard output of before data_on_stdout, innermost last


def is_stdout(path: PathLike | None) -> bool:
    """``path`` names standard output ("-")."""
    return path is not None and os.fspath(path) == STDOUT


@contextlib.contextmanager
def data_on_stdout(active: bool = True) -> Iterator[None]:
    """While ``active``: print() goes to stderr, and an output named "-" to the standard output of
    before, so ``imucal ... --json - | jq`` reads the JSON alone."""
    if not active:
        yield
        return
    _data_streams.append(sys.stdout)
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        _data_streams.pop()


def write_stdout(text: str) -> None:
    """``text`` onto standard output (data_on_stdout's, when active), flushed."""
    out = _data_streams[-1] if _data_streams else sys.stdout
    out.write(text)
    out.flush()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _not_regular(path: Path) -> str | None:
    """What an existing non-regular file is ("a directory", "a FIFO", ...), or None."""
    try:
        st = os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):  # the parent check reports the latter
        return None
    except OSError as exc:
        return f"unreadable ({exc.strerror})"
    if stat.S_ISLNK(st.st_mode):
        return "a symbolic link"
    if stat.S_ISREG(st.st_mode):
        return None
    if stat.S_ISDIR(st.st_mode):
        return "a directory"
    if stat.S_ISFIFO(st.st_mode):
        return "a FIFO"
    if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode):
        return "a device"
    return "not a regular file"


def check_outputs(inputs: Iterable[PathLike | None], outputs: Iterable[PathLike | None]) -> list[Path]:
    """Refuse, before any work, outputs that would overwrite an input, each other, or anything
    that is not a regular file. Returns the outputs as paths."""
    ins = [Path(p) for p in inputs if p is not None and not is_stdout(p)]
    outs = [Path(p) for p in outputs if p is not None and not is_stdout(p)]
    for i, out in enumerate(outs):
        check_destination(out)
        for inp in ins:
            if same_file(inp, out):
                raise ImucalError(f"would overwrite the input {inp}", file=str(out), field="output",
                                  fix="write the outputs somewhere else (inputs are never replaced)")
        for other in outs[:i]:
            if same_file(other, out):
                raise ImucalError(f"is also the output {other}", file=str(out), field="output",
                                  fix="give every output its own file name")
    return outs


def check_destination(path: str | os.PathLike) -> Path:
    """``path`` can be written as a file: it is not a directory, and its nearest existing
    ancestor is a directory. Raises ImucalError (before any work is done) otherwise."""
    path = Path(path)
    if any(len(part.encode()) > 255 for part in path.parts) or len(os.fsencode(path)) > 4000:
        raise ImucalError("file name too long", file=str(path)[:80] + "...", field="output",
                          fix="choose a shorter output name")
    if path.is_dir():
        raise ImucalError("is a directory, not a file name", file=str(path), field="output",
                          fix="give a file name for this output")
    kind = _not_regular(path)
    if kind is not None:
        raise ImucalError(f"is {kind}: only regular files are replaced", file=str(path), field="output",
                          fix="give the path of a regular file (or a new name)")
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
        raise ImucalError(f"cannot create the directory: {exc.strerror}", file=str(path), field="output",
                          fix="choose an output folder you can write to") from None
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
        with _signals_deferred():  # made and known to the cleanup below as one step
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; outputs follow the user's umask
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
            raise _write_error(Path(path), exc) from None
        raise


#: How text outputs are encoded: UTF-8, and whatever UTF-8 cannot hold escaped (backslashreplace).
#: A file name with bytes that are not UTF-8 (b'log\xff.csv' on Linux) reaches the text as a lone
#: surrogate (Python's surrogateescape): it is written as the escape \udcff, so the file stays UTF-8
#: that every reader (YAML, JSON, HTML, C) takes, and the name stays recognisable.
TEXT_ERRORS = "backslashreplace"


def encode_text(text: str) -> bytes:
    """``text`` as every text output is written (TEXT_ERRORS)."""
    return text.encode("utf-8", errors=TEXT_ERRORS)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    write_bytes_atomic(path, encode_text(text))


def json_text(obj: Any) -> str:
    """The JSON of every JSON output (indented, NaN kept as JavaScript's NaN)."""
    import json  # measured start-up: only a run that writes JSON (--json)

    return json.dumps(obj, indent=2, sort_keys=False, allow_nan=True) + "\n"


def write_json_atomic(path: str | os.PathLike, obj: Any) -> None:
    """``obj`` as JSON into ``path`` atomically, or onto standard output when ``path`` is "-"."""
    if is_stdout(path):
        write_stdout(json_text(obj))
    else:
        write_text_atomic(path, json_text(obj))


def _pid_alive(pid: int) -> bool:
    """Whether process ``pid`` runs. A zombie (ended, not yet reaped by its parent: a batch's or a
    cluster's worker just killed) does not."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:  # Linux: the state follows the command name in parentheses, which may hold any character
        return Path(f"/proc/{pid}/stat").read_bytes().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):
        return True


def remove_stale_staging(folder: Path) -> None:
    """Remove staging folders of runs that no longer exist (killed with SIGKILL, power loss)."""
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return
    for e in entries:
        m = _STAGING.match(e.name)
        if m and e.is_dir(follow_symlinks=False) and not _pid_alive(int(m.group(1))):
            shutil.rmtree(e.path, ignore_errors=True)


@contextlib.contextmanager
def _locked(folders: Iterable[Path]) -> Iterator[None]:
    """Exclusive flock on each folder (sorted, so two runs cannot deadlock)."""
    fds = []
    try:
        for d in sorted({f.resolve() for f in folders}):
            fd = os.open(d, os.O_RDONLY)
            fds.append(fd)
            try:
                import fcntl

                fcntl.flock(fd, fcntl.LOCK_EX)
            except (ImportError, OSError):  # pragma: no cover - no flock: publish unlocked
                pass
        yield
    finally:
        for fd in fds:
            os.close(fd)  # closing releases the lock


def _write_error(dest: Path, exc: OSError) -> ImucalError:
    why = {errno.ENOSPC: "disk full", errno.EROFS: "read-only file system", errno.EACCES: "permission denied",
           errno.ENAMETOOLONG: "file name too long", errno.EDQUOT: "disk quota exceeded"}.get(
        exc.errno, exc.strerror or type(exc).__name__)
    return ImucalError(f"cannot write: {why}", file=str(dest), field="output",
                       fix="free space or choose another output folder; nothing was written")


class _Deferred:
    """The signals noted while deferred (``_signals_deferred``)."""

    def __init__(self) -> None:
        self.got: list[int] = []

    def pending(self) -> bool:
        return bool(self.got)

    def forget(self) -> None:
        """Drop what arrived: the work it would have interrupted is complete (the program then ends, or
        goes on to its next step, within milliseconds; main ignores a signal during its exit alike)."""
        self.got.clear()


@contextlib.contextmanager
def _signals_deferred() -> Iterator[_Deferred]:
    """Hold the signals that end a run (imucal.errors.INTERRUPTING: SIGINT, SIGTERM, SIGHUP, SIGQUIT,
    SIGUSR1, ...) until the block ends, then act on the first as its handler would (raising as usual,
    or the default action: the process ends, as if the signal came now); yields what arrived meanwhile.
    An ignored signal (SIG_IGN) stays ignored, and a handler installed from C (None: faulthandler's,
    say) is left alone, as Python could not put it back.

    The Python handlers are swapped for a note, not the signals masked: a process-directed signal goes
    to any thread that does not block it (BLAS, a test runner), and Python runs its handler in the main
    thread all the same. A signal between mkdtemp's mkdir and the registration of the new folder would
    leave a staging folder that no cleanup knows about; one while a set is placed, half a set.
    """
    d = _Deferred()
    try:
        old = {s: signal.getsignal(s) for s in INTERRUPTING}
        old = {s: h for s, h in old.items() if h is not None and h != signal.SIG_IGN}
        for s in old:
            signal.signal(s, lambda signum, frame: d.got.append(signum))
    except (ValueError, OSError):  # not the main thread: no handler to swap (none runs here either)
        yield d
        return
    try:
        yield d
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if d.got:
            h = old[d.got[0]]
            if callable(h):
                h(d.got[0], None)
            else:  # the default action (terminate), as if it came now
                os.kill(os.getpid(), d.got[0])


def _roll_back(done: list[tuple[Path, Path | None]]) -> None:
    """Undo a publication: each backup back in place, each new file removed (last placed first)."""
    for placed, backup in reversed(done):
        with contextlib.suppress(OSError):
            if backup is not None:
                os.replace(backup, placed)
            elif placed.exists():
                os.unlink(placed)


class OutputSet:
    """Stage several output files and publish them together.

    >>> with OutputSet() as out:                       # doctest: +SKIP
    ...     out.text("run/report.txt", report)
    ...     out.call("run/fig.png", lambda p: fig.savefig(p))
    Nothing appears at the destinations unless the block completes.
    """

    def __init__(self, inputs: Iterable[PathLike | None] = ()) -> None:
        self._inputs = [Path(p) for p in inputs if p is not None]
        self._staged: list[tuple[Path, Path]] = []
        self._tmpdirs: dict[Path, Path] = {}
        self._created: list[Path] = []  #: directories made for this set, removed if it fails
        self._stdout: list[str] = []  #: texts for standard output ("-"), written once the set is published

    def _stage(self, dest: str | os.PathLike) -> Path:
        dest = Path(dest)
        check_outputs(self._inputs, [*(d for _, d in self._staged), dest])
        parent = dest.parent
        if parent not in self._tmpdirs:
            self._created.extend(_make_parent(dest))
            remove_stale_staging(parent)
            try:
                with _signals_deferred():  # made and registered for cleanup as one step
                    self._tmpdirs[parent] = Path(tempfile.mkdtemp(prefix=f".imucal-{os.getpid()}-", dir=parent))
            except OSError as exc:
                raise _write_error(dest, exc) from None
        tmp = self._tmpdirs[parent] / dest.name
        self._staged.append((tmp, dest))
        return tmp

    def text(self, dest: str | os.PathLike, text: str) -> None:
        tmp = self._stage(dest)
        try:
            tmp.write_bytes(encode_text(text))
        except OSError as exc:
            raise _write_error(Path(dest), exc) from None

    def bytes(self, dest: str | os.PathLike, data: bytes) -> None:
        tmp = self._stage(dest)
        try:
            tmp.write_bytes(data)
        except OSError as exc:
            raise _write_error(Path(dest), exc) from None

    def json(self, dest: str | os.PathLike, obj: Any) -> None:
        """``obj`` as JSON into ``dest``; "-": onto standard output once the set is published."""
        if is_stdout(dest):
            self._stdout.append(json_text(obj))
        else:
            self.text(dest, json_text(obj))

    def call(self, dest: str | os.PathLike, writer: Callable[[Path], None]) -> None:
        """Let ``writer(tmp_path)`` produce the file (e.g. matplotlib's savefig)."""
        tmp = self._stage(dest)
        try:
            writer(tmp)
        except ImucalError as exc:  # the writer's own one-line error names the staging file
            raise ImucalError(exc.message, file=str(dest), field=exc.field, fix=exc.fix) from None
        except OSError as exc:
            raise _write_error(Path(dest), exc) from None
        if tmp.exists():
            os.chmod(tmp, 0o666 & ~_umask())

    def _publish(self) -> list[tuple[Path, Path | None]]:
        """Move every staged file into place; on any failure put back what was there before.
        Returns (destination, backup of what it replaced or None) per file placed."""
        done: list[tuple[Path, Path | None]] = []
        try:
            for tmp, dest in self._staged:
                backup = None
                if dest.exists():
                    backup = tmp.with_name(f".previous-{tmp.name}")
                    os.replace(dest, backup)
                done.append((dest, backup))
                os.replace(tmp, dest)
        except OSError as err:
            _roll_back(done)
            raise _write_error(dest, err) from None
        return done

    def __enter__(self) -> "OutputSet":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        published = False
        try:
            # Whole sets, one run after the other: a signal while waiting for another run's lock
            # interrupts as usual. The signals that end a run then wait while the set is placed and
            # the staging removed (an interrupt in the middle left half a set, or deleted the old files
            # with the staging): one that arrived while the set was placed puts the old set back and
            # interrupts the run, which has then written nothing; one after the set is complete is dropped.
            with _locked(self._tmpdirs) if exc_type is None else contextlib.nullcontext():
                with _signals_deferred() as sig:
                    try:
                        if exc_type is None:
                            check_outputs(self._inputs, [d for _, d in self._staged])  # nothing changed meanwhile
                            done = self._publish()
                            if sig.pending():
                                _roll_back(done)
                            else:
                                published = True
                    finally:
                        self._clean(published)
                        if published:
                            sig.forget()
        finally:
            self._clean(published)  # (again, when the wait for the lock was interrupted)
        if published:
            for text in self._stdout:
                write_stdout(text)

    def _clean(self, published: bool) -> None:
        for d in self._tmpdirs.values():
            shutil.rmtree(d, ignore_errors=True)
        if not published:
            _remove_dirs(self._created)
