"""The one error type imucal raises for bad input: one line naming file, field and fix."""
from __future__ import annotations
import signal


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
        return " ".join(text.split())  # always one line


# Exit statuses of the command line (README "Exit statuses"). One meaning each.
EXIT_OK = 0  #: success
EXIT_NOT_CONVERGED = 1  #: the solver did not converge (outputs written, status "failed")
EXIT_BAD_INPUT = 2  #: bad input, a refused run or a usage error: one line naming file, field, fix
EXIT_INTERNAL = 3  #: an unexpected internal error (a bug): one line; rerun with --debug for the traceback
EXIT_INTERRUPTED = 130  #: SIGINT (Ctrl-C) or SIGTERM: staged outputs removed, nothing published
EXIT_BROKEN_PIPE = 141  #: 128 + SIGPIPE: the reader of stdout left (`| head`); files already written stay


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is, so staged outputs are removed as on Ctrl-C."""


#: Signals received while a command runs, recorded by the command line's handlers. A signal that
#: arrives inside CasADi's C code is caught there and becomes a solver failure status; every
#: solve calls ``raise_if_signalled`` after IPOPT returns, so the run ends as an interruption.
SIGNALS: list[int] = []


def raise_if_signalled() -> None:
    """Raise the interrupt a signal asked for, if one arrived during the last solve."""

    if signal.SIGTERM in SIGNALS:
        raise Terminated()
    if SIGNALS:
        raise KeyboardInterrupt()


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
