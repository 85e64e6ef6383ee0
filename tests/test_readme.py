"""The README's result blocks are exactly what the scripts wrote into docs/ (no hand edits),
and the quick start's test command is what CI runs."""
from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("update_readme", ROOT / "scripts" / "update_readme.py")
update_readme = importlib.util.module_from_spec(spec)
spec.loader.exec_module(update_readme)


def test_readme_blocks_match_generated_docs():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    blocks = list(update_readme.BLOCK.finditer(text))
    assert len(blocks) >= 5
    for m in blocks:
        assert m.group(3) == update_readme.body(m.group(2)), (
            f"README block {m.group(2)} differs from docs/: run python scripts/update_readme.py")


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    cmd = 'python -m pip install -c constraints.txt -e ".[test]" && python -m pytest -q'
    assert cmd in readme
    assert cmd in ci.splitlines()
