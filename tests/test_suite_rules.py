"""Issue 29: the suite's own rules. No test skips because a Python package is missing: every package the
tests import is a dependency or in the test extra, and `importorskip` is not used."""
from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = sorted((ROOT / "tests").glob("*.py"))  # the product's tests


def _calls(path: Path, name: str) -> list[int]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [n.lineno for n in ast.walk(tree) if isinstance(n, ast.Call)
            and getattr(n.func, "attr", getattr(n.func, "id", None)) == name]


def test_no_test_skips_for_a_missing_package():
    found = {p.name: lines for p in TESTS if (lines := _calls(p, "importorskip"))}
    assert found == {}


def _requirements() -> set[str]:
    import tomllib

    meta = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    names = [*meta["dependencies"], *meta["optional-dependencies"]["test"]]
    return {r.split(">")[0].split("[")[0].split("=")[0].strip().replace("-", "_").lower() for r in names}


#: Import names of distributions whose import name differs from the distribution's.
IMPORT_NAMES = {"pyyaml": "yaml", "dask": "distributed"}


def test_every_package_the_tests_import_is_declared():
    """A third-party module a test imports is a dependency or in the test extra (pyproject.toml)."""
    declared = _requirements() | {IMPORT_NAMES.get(n, n) for n in _requirements()} | {"dask"}
    local = {"imucal", "conftest", *(p.stem for p in TESTS)}
    missing = {}
    for p in TESTS:
        for n in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            mods = ([a.name for a in n.names] if isinstance(n, ast.Import)
                    else [n.module] if isinstance(n, ast.ImportFrom) and n.module and n.level == 0 else [])
            for m in mods:
                top = m.split(".")[0]
                if top not in local and top not in sys.stdlib_module_names and top.lower() not in declared:
                    missing.setdefault(top, p.name)
    assert missing == {}
