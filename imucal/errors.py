"""The one error type imucal raises for bad input: one line naming file, field and fix."""
from __future__ import annotations

import signal
from typing import Any


class ImucalError(Exception):
    """Bad input or an impossible request.

    The message is one line: ``FILE: FIELD: what is wrong (fix: what to do)``.
    The command line prints it and exits with status 2, without a traceback.
    """

    def __init__(self, message: str, *, file: str | None = None, field: str | None = None,
                 fix: str | None = None) -> None:
        self.message = message
        self.file = None if file is None else str(file)
        self.field = field
        self.fix = fix
        super().__init__(self.__str__())

    def __str__(self) -> str:
        parts = [p for p in (self.file, self.field) if p]
        text = ": ".join(parts + [self.message])
        if self.fix:
            text += f" (fix: {self.fix})"
        return printable(" ".join(text.split()))  # always one line, and no control character of a file's name


class ImucalWarning(UserWarning):
    """What the user must know about a result that is still given (a poor fit, dropped intervals).

    The library issues it through :mod:`warnings` (a notebook shows it; ``warnings.filterwarnings``
    silences or raises it); the command line prints the same sentence as ``imucal: warning: ...``.
    """


# Exit statuses of the command line (README "Exit statuses"). One meaning each.
EXIT_OK = 0  #: success
EXIT_NOT_CONVERGED = 1  #: the solver did not converge (outputs written, status "failed")
EXIT_BAD_INPUT = 2  #: bad input, a refused run or a usage error: one line naming file, field, fix
EXIT_INTERNAL = 3  #: an unexpected internal error (a bug): one line; rerun with --debug for the traceback
EXIT_INTERRUPTED = 130  #: ended by a signal (INTERRUPTING: Ctrl-C, SIGTERM, SIGHUP, ...): staged outputs removed
EXIT_BROKEN_PIPE = 141  #: 128 + SIGPIPE: the reader of stdout left (`| head`); files already written stay


# --- signals ---------------------------------------------------------------------------------------
# Every signal that would end the process and can be caught ends a run the same way: where the program
# is, as an exception, so staged outputs are removed (or the old set put back while one is placed), one
# line names the signal, and the status is EXIT_INTERRUPTED for all of them: one status means "stopped
# from outside, nothing written", whichever signal it was (the line says which). The shell's 128 + n is
# kept for SIGINT (130, as before) and not spread over a dozen numbers a caller would have to list.
# Python itself ignores SIGPIPE (a reader gone is BrokenPipeError: EXIT_BROKEN_PIPE) and SIGXFSZ (a file
# too large is a write error); a signal ignored when the run starts (nohup's SIGHUP, a job started with &)
# stays ignored, and one with a handler of the calling program is left to it.
_TERMINATING = ("SIGHUP", "SIGINT", "SIGQUIT", "SIGUSR1", "SIGUSR2", "SIGPIPE", "SIGALRM", "SIGTERM", "SIGSTKFLT",
                "SIGXCPU", "SIGXFSZ", "SIGVTALRM", "SIGPROF", "SIGIO", "SIGPWR")


def _interrupting() -> tuple[int, ...]:
    found = {int(getattr(signal, n)) for n in _TERMINATING if hasattr(signal, n)}
    if hasattr(signal, "SIGRTMIN"):  # real-time signals: their default action ends the process too
        found |= set(range(signal.SIGRTMIN, signal.SIGRTMAX + 1))
    return tuple(sorted(found))


#: Signals sent from outside whose default action ends the process (signal(7)). Not the faults the
#: process raises itself (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGSYS, SIGTRAP): no handler resumes
#: from those, and SIGKILL and SIGSTOP cannot be caught.
INTERRUPTING: tuple[int, ...] = _interrupting()


def signal_name(signum: int) -> str:
    """A signal's name: "SIGHUP", "SIGRTMIN+3", or "signal 99" for a number the platform does not name."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        if hasattr(signal, "SIGRTMIN") and signal.SIGRTMIN < signum <= signal.SIGRTMAX:
            return f"SIGRTMIN+{signum - signal.SIGRTMIN}"
        return f"signal {signum}"


class Terminated(KeyboardInterrupt):
    """A signal other than SIGINT, raised where the program is, so staged outputs are removed as on Ctrl-C."""

    def __init__(self, signum: int = signal.SIGTERM) -> None:
        super().__init__(signum)
        self.signum = signum


#: Signals received while a command runs, recorded by the handlers of ``interrupt_on_signals``. A
#: signal that arrives inside CasADi's C code is caught there and becomes a solver failure status; every
#: solve calls ``raise_if_signalled`` after IPOPT returns, so the run ends as an interruption.
SIGNALS: list[int] = []
_TAKEN: set[int] = set()  #: signals whose handler is ``_on_signal`` (set by ``interrupt_on_signals``)


def _raise_for(signum: int) -> None:
    if signum == signal.SIGINT:
        raise KeyboardInterrupt()
    raise Terminated(signum)


def _on_signal(signum: int, frame: object) -> None:  # noqa: ARG001 - signal handler signature
    SIGNALS.append(signum)
    if signum != signal.SIGINT:  # once: the cleanup is not interrupted again (a second Ctrl-C still is)
        for s in _TAKEN - {signal.SIGINT}:
            signal.signal(s, signal.SIG_IGN)
    _raise_for(signum)


def interrupt_on_signals() -> dict[int, Any]:
    """Make every INTERRUPTING signal with its default action (Python's own handler for SIGINT) raise
    KeyboardInterrupt (SIGINT) or Terminated (the others) where the program is. Ignored signals and
    handlers of the calling program are left alone. Returns the handlers replaced, for
    ``restore_signals``. Raises ValueError outside the main thread."""
    replaced = {}
    for s in INTERRUPTING:
        h = signal.getsignal(s)
        if h is signal.SIG_DFL or (s == signal.SIGINT and h is signal.default_int_handler):
            replaced[s] = signal.signal(s, _on_signal)
            _TAKEN.add(s)
    return replaced


def restore_signals(replaced: dict[int, Any], ignore: bool = False) -> None:
    """Give back the handlers ``interrupt_on_signals`` replaced, or (``ignore``) ignore those signals:
    a program whose run is over is not killed by a signal during its exit."""
    for s, h in replaced.items():
        signal.signal(s, signal.SIG_IGN if ignore else h)
        _TAKEN.discard(s)


def raise_if_signalled() -> None:
    """Raise the interrupt a signal asked for, if one arrived during the last solve."""
    if SIGNALS:
        _raise_for(next((s for s in SIGNALS if s != signal.SIGINT), SIGNALS[0]))


def interruption_line(exc: BaseException | None, kept: str = "nothing was written") -> str:
    """The one line an interrupted run ends with, naming the signal: "imucal: terminated by SIGHUP;
    nothing was written" (``kept``: what stays, for a command that keeps finished work)."""
    signum = getattr(exc, "signum", None) or next((s for s in SIGNALS if s != signal.SIGINT), None)
    what = "interrupted" if signum is None else f"terminated by {signal_name(signum)}"
    return f"imucal: {what}; {kept}"


def printable(text: str, keep: str = "") -> str:
    """``text`` with each character no terminal or page shows as itself written as its escape (ESC as \\x1b, a
    bidi override as \\u202e, a line separator, a lone surrogate as \\udcff), but those in ``keep``: a file's or
    a column's name (an attacker's text) then cannot move the cursor, retitle the terminal or reorder a line."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() or c in keep else c.encode("unicode_escape").decode("ascii") for c in text)


def short(value: object, limit: int = 40) -> str:
    """repr of a value for a message, cut to ``limit`` characters (never repr an unbounded value)."""
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a hostile __repr__ must not escape
        text = f"<{type(value).__name__}>"
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def key_text(key: object) -> str:
    """A mapping key as a field name in a message: plain when short and printable, else cut."""
    if isinstance(key, str) and 0 < len(key) <= 40 and key.isprintable():
        return key
    return short(key, 40)


def check_choice(value: object, choices: tuple, field: str, what: str, note: str = "") -> None:
    """Refuse ``value`` outside ``choices``: "unknown WHAT VALUE" with the choices as the fix."""
    if value not in choices:
        raise ImucalError(f"unknown {what} {short(value)}", field=field,
                          fix=f"use one of {', '.join(choices)}" + (f" ({note})" if note else ""))
