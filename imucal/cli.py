"""Command line: thin. Parses, calls the library, prints. Bad input exits 2 with one line.

Each subcommand lives in ``imucal/commands/<name>.py`` with ``register(subparsers)`` (argument
definitions only, no heavy imports) and ``run(args) -> int``.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from . import __version__
from .errors import ImucalError

#: Subcommand name -> module. Modules import their heavy dependencies inside run().
COMMANDS = {
    "calibrate": "imucal.commands.calibrate",
    "apply": "imucal.commands.apply",
    "codegen": "imucal.commands.codegen",
    "worst-case": "imucal.commands.worst_case",
    "error-map": "imucal.commands.error_map",
    "drift": "imucal.commands.drift",
    "simulate": "imucal.commands.simulate",
    "discover": "imucal.commands.discover",
    "plan-poses": "imucal.commands.plan_poses",
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse's convention too)
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="imucal", description="Calibrate MEMS accelerometers (Nakov & Ivanov model).")
    parser.add_argument("--version", action="version", version=f"imucal {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name, modname in COMMANDS.items():
        try:
            mod = importlib.import_module(modname)
        except ModuleNotFoundError as exc:
            if exc.name == modname:
                continue  # not built yet
            raise
        mod.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "run", None):
        parser.print_help()
        return 2
    try:
        return int(args.run(args) or 0)
    except ImucalError as exc:
        sys.stderr.write(f"imucal: error: {exc}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("imucal: interrupted\n")
        return 130


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
