#!/usr/bin/env python3
"""Splice the generated result tables from docs/ into README.md.

Each README block between `<!-- begin:NAME -->` and `<!-- end:NAME -->` is replaced by the
file docs/NAME.md, or, for NAME = FILE#BLOCK, by the part of docs/FILE.md between that block's
markers. The docs are
written by the scripts named in each of them; run those first, then:

    python scripts/update_readme.py
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.files.output import write_text_atomic  # noqa: E402

BLOCK = re.compile(r"(<!-- begin:([\w/.#-]+) -->\n)(.*?)(<!-- end:\2 -->)", re.S)


def body(name: str) -> str:
    """docs/NAME.md, or with NAME = FILE#BLOCK the part of docs/FILE.md between BLOCK's markers."""
    fname, _, block = name.partition("#")
    text = (ROOT / "docs" / f"{fname}.md").read_text(encoding="utf-8")
    if block:
        m = re.search(rf"<!-- begin:{re.escape(block)} -->\n(.*?)<!-- end:{re.escape(block)} -->", text, re.S)
        if not m:
            raise SystemExit(f"docs/{fname}.md has no block {block!r}")
        text = m.group(1)
    # Drop the doc's own top-level title; the README gives the section heading.
    lines = [ln for ln in text.splitlines() if not ln.startswith("# ")]
    return "\n".join(lines).strip() + "\n"


def main() -> int:
    readme = ROOT / "README.md"
    text = readme.read_text(encoding="utf-8")
    new = BLOCK.sub(lambda m: m.group(1) + body(m.group(2)) + m.group(4), text)
    if new != text:
        write_text_atomic(readme, new)
        print("README.md updated")
    else:
        print("README.md already up to date")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
