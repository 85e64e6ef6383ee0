#!/usr/bin/env python3
"""The one tool that puts measured numbers into the README and the documentation site.

Every number the README or a guide page quotes sits between two markers naming its source, a result
file that a study, a benchmark or the README's example commands wrote:

    <!-- begin:studies/results/real_accuracy.md#table -->
    ... the text between `<!-- begin:table -->` and `<!-- end:table -->` in that file ...
    <!-- end:studies/results/real_accuracy.md#table -->

A name without `#BLOCK` inserts the whole file (its `# ` title dropped). A marker whose name is no
file path (`<!-- begin:summary -->`) is a source block, written by a script, and is left alone.

    python scripts/update_docs.py            # splice every block (README.md, docs/**/*.md)
    python scripts/update_docs.py --check    # exit 1, naming each stale block, if any differs (CI)
    python scripts/update_docs.py examples   # run the README's example commands, write docs/examples/
    python scripts/update_docs.py examples --check   # run them, compare the numbers they print
    python scripts/update_docs.py screenshots  # docs/images/ from the browser test of report.html

The examples are listed in docs/examples/examples.yaml: each runs its commands in a fresh folder
holding a copy of the repository's configs/ and data/, and keeps the output lines its `show`
patterns match. A number the README shows must then equal the fresh run's to the digits printed.
"""
from __future__ import annotations

import argparse
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
#: Files whose blocks are spliced: the README and every page of the site (studies' own outputs are
#: written whole by their scripts and are sources, not targets).
TARGET_GLOBS = ("README.md", "docs/**/*.md")
EXAMPLES = ROOT / "docs" / "examples" / "examples.yaml"
#: What an example folder gets from the repository: the shipped recordings and run files.
EXAMPLE_INPUTS = ("configs", "data")
#: One example command may not run longer than this [s] (the slowest, a 12-unit batch, takes ~30 s).
EXAMPLE_TIMEOUT_S = 600

BLOCK = re.compile(r"(<!-- begin:([^ >]+) -->\n)(.*?)(<!-- end:\2 -->)", re.S)
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def set_root(root: Path) -> None:
    """Work on another copy of the repository (the tests check the tool on a copy they made)."""
    global ROOT, EXAMPLES
    ROOT, EXAMPLES = root, root / "docs" / "examples" / "examples.yaml"


def is_insertion(name: str) -> bool:
    """A block names a file to insert when its name is a path with a suffix (`dir/file.md#block`)."""
    return bool(Path(name.partition("#")[0]).suffix)


def body(name: str) -> str:
    """The text a block NAME = FILE[#BLOCK] stands for (FILE relative to the repository's root)."""
    fname, _, block = name.partition("#")
    text = (ROOT / fname).read_text(encoding="utf-8")
    if block:
        m = re.search(rf"<!-- begin:{re.escape(block)} -->\n(.*?)<!-- end:{re.escape(block)} -->", text, re.S)
        if not m:
            raise SystemExit(f"update_docs: {fname} has no block {block!r}")
        text = m.group(1)
    lines = [ln for ln in text.splitlines() if not ln.startswith("# ")]  # the page gives its own heading
    return "\n".join(lines).strip() + "\n"


def targets() -> list[Path]:
    found: set[Path] = set()
    for pattern in TARGET_GLOBS:
        found.update(p for p in ROOT.glob(pattern) if p.is_file() and not p.is_symlink()
                     and "studies" not in p.relative_to(ROOT).parts)
    return sorted(found)


def splice(text: str) -> str:
    return BLOCK.sub(lambda m: m.group(0) if not is_insertion(m.group(2))
                     else m.group(1) + body(m.group(2)) + m.group(4), text)


def stale_blocks(path: Path) -> list[str]:
    """Names of the insertion blocks in PATH whose text differs from their source."""
    text = path.read_text(encoding="utf-8")
    return [m.group(2) for m in BLOCK.finditer(text) if is_insertion(m.group(2)) and m.group(3) != body(m.group(2))]


def cmd_splice(check: bool) -> int:
    bad = 0
    for path in targets():
        rel = path.relative_to(ROOT)
        if check:
            for name in stale_blocks(path):
                print(f"{rel}: block {name} differs from its source (run: python scripts/update_docs.py)")
                bad += 1
            continue
        text = path.read_text(encoding="utf-8")
        new = splice(text)
        if new != text:
            path.write_text(new, encoding="utf-8")
            print(f"updated {rel}")
    return 1 if bad else 0


# ---- the README's example commands -------------------------------------------------------------

@dataclass(frozen=True)
class Example:
    name: str          # docs/examples/NAME.md
    commands: list     # shell-free command lines, run in order in one folder
    show: list         # regular expressions: the output lines kept
    head: dict         # files written by the commands: path -> number of first lines shown


def load_examples() -> list[Example]:
    raw = yaml.safe_load(EXAMPLES.read_text(encoding="utf-8"))
    return [Example(e["name"], list(e.get("commands", [])), list(e.get("show", [])), dict(e.get("head", {})))
            for e in raw]


def run_example(ex: Example, folder: Path) -> str:
    """The example's transcript: each command after `$ `, then the lines of its output it shows."""
    keep = [re.compile(p) for p in ex.show]
    out = []
    for line in ex.commands:
        argv = shlex.split(line)
        if argv[0] == "imucal":  # the installed command, run by the interpreter running this tool
            argv = [sys.executable, "-m", "imucal", *argv[1:]]
        env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        p = subprocess.run(argv, cwd=folder, capture_output=True, text=True, timeout=EXAMPLE_TIMEOUT_S, env=env)
        if p.returncode != 0:
            raise SystemExit(f"update_docs: example {ex.name}: `{line}` exited {p.returncode}:\n{p.stderr}")
        out.append(f"$ {line}")
        out += [ln.rstrip() for ln in (p.stdout + p.stderr).splitlines() if any(k.search(ln) for k in keep)]
    for path, n in ex.head.items():  # the start of a file a command wrote, as `head` shows it
        out.append(f"$ head -n {n} {path}")
        out += (folder / path).read_text(encoding="utf-8").splitlines()[:n]
    return "```console\n" + "\n".join(out) + "\n```\n"


def run_examples() -> dict[str, str]:
    with tempfile.TemporaryDirectory(prefix="imucal-examples-") as tmp:
        folder = Path(tmp)
        for name in EXAMPLE_INPUTS:
            shutil.copytree(ROOT / name, folder / name)
        return {ex.name: run_example(ex, folder) for ex in load_examples()}


def numbers_differ(shown: str, fresh: str) -> str | None:
    """Why two transcripts disagree, or None: same text but for numbers equal to the digits shown."""
    if NUMBER.sub("#", shown) != NUMBER.sub("#", fresh):
        return "the text differs:\n--- shown\n" + shown + "--- fresh\n" + fresh
    for a, b in zip(NUMBER.findall(shown), NUMBER.findall(fresh)):
        mant = a.lower().split("e")[0]
        decimals = len(mant.split(".")[1]) if "." in mant else 0
        exp = int(a.lower().split("e")[1]) if "e" in a.lower() else 0
        last_digit = 10.0 ** (exp - decimals)  # one unit in the last digit shown
        if abs(float(a) - float(b)) > 1.01 * last_digit:
            return f"{a} shown, {b} now"
    return None


def commands_shown(text: str) -> list[str]:
    """Every `imucal ...` command line inside the code blocks of a Markdown text (`$ ` prompts removed)."""
    found = []
    for block in re.findall(r"```[a-z]*\n(.*?)```", text, re.S):
        for line in block.splitlines():
            line = line.removeprefix("$ ").split("  #")[0].strip()
            if line.startswith("imucal "):
                found.append(line)
    return found


def cmd_examples(check: bool) -> int:
    folder = EXAMPLES.parent
    bad = 0
    if check:  # the README shows no command that no example runs
        run = {c for ex in load_examples() for c in ex.commands}
        for line in commands_shown((ROOT / "README.md").read_text(encoding="utf-8")):
            if line not in run:
                print(f"README.md shows `{line}`, which no example in {EXAMPLES.relative_to(ROOT)} runs")
                bad += 1
    fresh = run_examples()
    for name, text in fresh.items():
        path = folder / f"{name}.md"
        if not check:
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path.relative_to(ROOT)}")
            continue
        shown = path.read_text(encoding="utf-8") if path.exists() else ""
        why = numbers_differ(shown, text)
        if why:
            print(f"{path.relative_to(ROOT)}: {why}")
            bad += 1
    return 1 if bad else 0


def cmd_screenshots() -> int:
    """The browser test of report.html (tests/test_html_browser.py) leaves its screenshot in docs/images."""
    images = ROOT / "docs" / "images"
    images.mkdir(exist_ok=True)
    env = dict(os.environ, IMUCAL_DOCS_SCREENSHOTS=str(images),
               PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        str(ROOT / "tests" / "test_html_browser.py"), "-k", "loads_cleanly"], cwd=ROOT, env=env)
    print(f"wrote {(images / 'report-desktop.png').relative_to(ROOT)}" if p.returncode == 0 else "no screenshot")
    return p.returncode


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", nargs="?", choices=["splice", "examples", "screenshots"], default="splice")
    ap.add_argument("--check", action="store_true", help="compare instead of writing; exit 1 on a difference")
    ap.add_argument("--root", type=Path, default=ROOT, help="the repository (default: this script's)")
    a = ap.parse_args(argv)
    set_root(a.root.resolve())
    if a.what == "screenshots":
        return cmd_screenshots()
    return cmd_examples(a.check) if a.what == "examples" else cmd_splice(a.check)


if __name__ == "__main__":
    raise SystemExit(main())
