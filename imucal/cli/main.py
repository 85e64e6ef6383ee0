"""Command line: thin. Parses, calls the library, prints. Bad input exits 2 with one line.

Each subcommand lives in ``imucal/commands/<name>.py`` with ``register(subparsers)`` (argument
definitions only, no heavy imports) and ``run(args) -> int``.
"""
from __future__ import annotations

import argparse
import errno
import importlib
import os
import sys

# One BLAS thread unless the user chose otherwise, set before numpy loads: imucal's matrices have a
# few columns, where the thread pool costs more wall time than it saves (OpenBLAS's pool alone adds
# some 30 ms to every start; scripts/bench_speed.py measures both). The library itself leaves it alone.
for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from imucal import __version__
from imucal.errors import (EXIT_BAD_INPUT, EXIT_BROKEN_PIPE, EXIT_INTERNAL, EXIT_INTERRUPTED, SIGNALS, ImucalError,
                           interrupt_on_signals, interruption_line, restore_signals, short)

#: Subcommand name -> module. Modules import their heavy dependencies inside run().
COMMANDS = {
    "calibrate": "imucal.cli.commands.calibrate",
    "apply": "imucal.cli.commands.apply",
    "codegen": "imucal.cli.commands.codegen",
    "worst-case": "imucal.cli.commands.worst_case",
    "error-map": "imucal.cli.commands.error_map",
    "drift": "imucal.cli.commands.drift",
    "simulate": "imucal.cli.commands.simulate",
    "discover": "imucal.cli.commands.discover",
    "plan-poses": "imucal.cli.commands.plan_poses",
    "export": "imucal.cli.commands.export",
    "noise": "imucal.cli.commands.noise",
    "compare": "imucal.cli.commands.compare",
    "batch": "imucal.cli.commands.batch",
}


def usage_fix(message: str) -> str | None:
    """What to do about one of argparse's own refusals (read from its words), or None when they say it (the
    choices of an invalid choice)."""
    import re  # here: only a refused command line reads it

    if m := re.match(r"argument ([^:/ ]+)[^:]*: invalid (int|float) value", message):
        return f"give {m[1]} a {'whole number' if m[2] == 'int' else 'number, e.g. 0.5'}"
    if m := re.match(r"argument ([^:/ ]+)[^:]*: expected (one|\d+) arguments?", message):
        return f"give {m[1]} {'a value' if m[2] == 'one' else m[2] + ' values'} after it"
    if m := re.match(r"the following arguments are required: (.+)", message):
        return f"add {m[1]}"
    if message.startswith("unrecognized arguments"):
        return "`imucal COMMAND --help` lists the options of each command"
    return None


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse's convention too)
        fix = usage_fix(message)
        sys.stderr.write(f"{self.prog}: error: {message}" + (f" (fix: {fix})" if fix else "") + "\n")
        raise SystemExit(2)


def _named(argv: list[str]) -> list[str]:
    """The subcommands to register: only the one the command line names (each costs its module's
    import and its arguments' set-up, some 10 ms for all), every one for help or an unknown name."""
    for arg in argv:
        if arg == "--debug":
            continue
        return [arg] if arg in COMMANDS else list(COMMANDS)
    return list(COMMANDS)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser for ``argv`` (every subcommand when ``argv`` names none)."""
    parser = _Parser(prog="imucal", description="Calibrate MEMS accelerometers (Nakov & Ivanov model).")
    parser.add_argument("--version", action="version", version=f"imucal {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="on an internal error, print the traceback instead of one line")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in _named(argv or []):
        modname = COMMANDS[name]
        try:
            mod = importlib.import_module(modname)
        except ModuleNotFoundError as exc:
            if exc.name == modname:
                continue  # not built yet
            raise
        mod.register(sub)
    return parser


def _print_traceback() -> None:
    import traceback  # here: only --debug on an internal error prints one (2 ms of every start)

    traceback.print_exc()


_SIGNALLED = SIGNALS  #: signals received by this run (imucal.errors.SIGNALS)


def _interrupted(exc: BaseException) -> bool:
    """An exception caused by a signal: raised inside a C extension (CasADi), KeyboardInterrupt
    can come back wrapped, e.g. as SystemError, with the interrupt in its context."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return bool(_SIGNALLED)


def _run(args: argparse.Namespace) -> int:
    """The command; with ``--json -`` its words go to stderr and stdout holds the JSON alone."""
    if getattr(args, "json", None) != "-":
        return args.run(args)
    from imucal.files.output import data_on_stdout

    with data_on_stdout():
        return args.run(args)


def as_typed(exc: ImucalError, argv: list[str]) -> ImucalError:
    """``exc`` naming the option the user typed (``--range-g``) where the library names its field without the
    dashes (``range-g``, ``range_g``): a refusal of no file whose field is an option given on this command line."""
    if exc.file is not None or not exc.field or exc.field.startswith("-"):
        return exc
    option = "--" + exc.field.replace("_", "-")
    if not any(a == option or a.startswith(option + "=") for a in argv):
        return exc
    return ImucalError(exc.message, field=option, fix=exc.fix)


def _interrupted_exit(as_program: bool) -> int:
    """EXIT_INTERRUPTED; as the program itself, at once: the staged outputs are gone (files.output) and the
    line is out, and an interpreter's teardown after a signal inside CasADi's C code has aborted (a fatal
    'PyThreadState_Get' error, exit -6: seen once under a full test suite's load)."""
    if as_program:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(EXIT_INTERRUPTED)
    return EXIT_INTERRUPTED


def main(argv: list[str] | None = None) -> int:
    """Run one command. Exit statuses: imucal.errors.EXIT_* (README, "Exit status")."""
    as_program = argv is None  # the console script or python -m imucal, not a caller's code
    if as_program:  # its main module is safe to import again: long logs may use worker processes
        from imucal.data.run_pool import allow_workers

        allow_workers()
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    if not getattr(args, "run", None):
        parser.print_help()
        return EXIT_BAD_INPUT
    if getattr(sys.stdout, "errors", None) == "strict" and hasattr(sys.stdout, "reconfigure"):
        # a file name that is not UTF-8 (b'log\xff.csv') prints escaped, as files.output writes it
        sys.stdout.reconfigure(errors="backslashreplace")
    replaced: dict = {}
    _SIGNALLED.clear()
    try:  # SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGUSR1, ... end the run as an interruption (imucal.errors)
        replaced = interrupt_on_signals()
    except ValueError:  # not the main thread (e.g. a test runner's worker): leave it alone
        pass
    try:
        code = int(_run(args) or 0)
        sys.stdout.flush()  # a reader gone shows here, not in the interpreter's last flush
        return code
    except ImucalError as exc:
        sys.stderr.write(f"imucal: error: {as_typed(exc, argv)}\n")
        return EXIT_BAD_INPUT
    except KeyboardInterrupt as exc:
        sys.stderr.write(interruption_line(exc) + "\n")
        return _interrupted_exit(as_program)
    except BrokenPipeError:  # the reader of stdout left (e.g. `| head`): as a pipe tool, end quietly
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        except (OSError, ValueError):
            pass
        return EXIT_BROKEN_PIPE
    except MemoryError:
        if args.debug:
            _print_traceback()
        sys.stderr.write("imucal: error: out of memory (the input is too large for this machine; "
                         "rerun with --debug for the traceback)\n")
        return EXIT_INTERNAL
    except Exception as exc:  # noqa: BLE001 - the last line of defence: one line, never a traceback
        if _interrupted(exc):
            sys.stderr.write(interruption_line(None) + "\n")
            return _interrupted_exit(as_program)
        if isinstance(exc, OSError) and exc.errno in (errno.ENAMETOOLONG, errno.ELOOP):
            # a path the system cannot look up (too long, a symbolic-link loop): bad input, not a bug
            name = short(str(exc.filename), 80) if exc.filename is not None else "a path given"
            sys.stderr.write(f"imucal: error: {name}: path: {str(exc.strerror).lower()} (fix: give a shorter "
                             "path, without a symbolic-link loop)\n")
            return EXIT_BAD_INPUT
        if args.debug:
            _print_traceback()
        sys.stderr.write(f"imucal: internal error: {type(exc).__name__}: {short(str(exc), 200)} "
                         "(rerun with --debug for the traceback)\n")
        return EXIT_INTERNAL
    finally:
        # Called from code (argv given): give the caller its handlers back. As the program itself
        # (argv None: the console script, python -m imucal) the run is over and its outputs are
        # complete: a signal in the last milliseconds of the exit is ignored, not allowed to kill
        # the finished run (exit -15) by the default action restored here.
        restore_signals(replaced, ignore=as_program)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
