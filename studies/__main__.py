"""The studies' runner: the measurements behind the documentation, apart from the product.

    python -m studies list                 # every result page, grouped, with what it measures
    python -m studies run PAGE [ARGS...]   # run the program that writes studies/results/PAGE.md
    python -m studies check [PYTEST ARGS]  # the studies' own checks (studies/tests)

The product (imucal/ and tests/) imports nothing from here. After a run, `python scripts/update_docs.py`
splices the new numbers into the README and the guide.
"""
from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
REGISTRY = HERE / "studies.yaml"


@dataclass(frozen=True)
class Study:
    page: str      # studies/results/PAGE.md
    title: str
    run: str       # program in studies/ and its arguments
    group: str
    measures: str

    @property
    def result(self) -> Path:
        return HERE / "results" / f"{self.page}.md"

    def argv(self, extra: list[str]) -> list[str]:
        program, *args = shlex.split(self.run)
        return [sys.executable, str(HERE / program), *args, *extra]


def registry() -> list[Study]:
    return [Study(**entry) for entry in yaml.safe_load(REGISTRY.read_text(encoding="utf-8"))]


def cmd_list() -> int:
    group = None
    for s in registry():
        if s.group != group:
            group = s.group
            print(f"\n{group}")
        print(f"  {s.page:<52} {s.measures}")
    return 0


def cmd_run(page: str, extra: list[str]) -> int:
    found = {s.page: s for s in registry()}
    if page not in found:
        print(f"studies: no study {page!r}; `python -m studies list` names them", file=sys.stderr)
        return 2
    argv = found[page].argv(extra)
    print("$", shlex.join(argv[1:]), file=sys.stderr)
    return subprocess.run(argv, cwd=ROOT).returncode


def cmd_check(extra: list[str]) -> int:
    return subprocess.run([sys.executable, "-m", "pytest", "-q", str(HERE / "tests"), *extra], cwd=ROOT).returncode


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list", help="every result page, grouped")
    run = sub.add_parser("run", help="run one study")
    run.add_argument("page")
    check = sub.add_parser("check", help="the studies' own checks")
    for p in (run, check):
        p.add_argument("extra", nargs=argparse.REMAINDER, help="passed on")
    a, unknown = ap.parse_known_args(argv)  # options meant for the study or pytest pass through
    if unknown and a.cmd == "list":
        ap.error(f"unrecognized arguments: {' '.join(unknown)}")
    a.extra = [*unknown, *getattr(a, "extra", [])]
    if a.cmd == "list":
        return cmd_list()
    if a.cmd == "run":
        return cmd_run(a.page, a.extra)
    return cmd_check(a.extra)


if __name__ == "__main__":
    raise SystemExit(main())
