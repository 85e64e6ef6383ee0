"""The documentation: the site builds strictly, every inserted number equals its result file, a newcomer's
commands print what the README shows, and the product's tests stand apart from studies/ and scripts/.

scripts/update_docs.py and mkdocs run as programs, as a user runs them; nothing here imports them."""
from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
TOOL = ROOT / "scripts" / "update_docs.py"
README_TEST_COMMAND = 'python -m pip install -c constraints.txt -e ".[test]" && python -m pytest -q'
#: The README stays a front page: what it is, the quick start, one example per job, links.
README_MAX_LINES = 320
#: Absolute paths of one machine, which no script or test may hold.
MACHINE_PATH = re.compile(r"^/(work|home|root|tmp|Users|mnt|opt)/")


def run(*argv: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *argv], cwd=cwd, capture_output=True, text=True,
                          env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})


def test_site_builds_strictly(tmp_path):
    """`mkdocs build --strict`: any broken link or anchor, or a page out of the navigation, fails it."""
    r = run("-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"), "-d", str(tmp_path / "site"))
    assert r.returncode == 0, r.stderr[-3000:]
    site = tmp_path / "site"
    studies = yaml.safe_load((ROOT / "studies" / "studies.yaml").read_text(encoding="utf-8"))
    index = (site / "studies" / "index.html").read_text(encoding="utf-8")
    for s in studies:  # every study has its page, and the overview lists it with what it measures
        assert (site / "studies" / s["page"] / "index.html").exists(), s["page"]
        assert s["title"] in index
    nav = (site / "index.html").read_text(encoding="utf-8")
    assert "Discovery: every pose held twice" in nav  # the revisit variants grouped under one heading
    assert "doc-function" in (site / "reference" / "api" / "index.html").read_text(encoding="utf-8")


def test_the_strict_settings_refuse_a_broken_link(tmp_path):
    """The site's own validation settings, on a two-page site with a link to a page that does not exist."""
    cfg = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "index.md").write_text("# Home\n\nSee [the guide](guide.md) and [this](missing.md).\n")
    (tmp_path / "docs" / "guide.md").write_text("# Guide\n")
    small = {"site_name": "t", "strict": cfg["strict"], "validation": cfg["validation"],
             "nav": [{"Home": "index.md"}, {"Guide": "guide.md"}]}
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(small))
    r = run("-m", "mkdocs", "build", "-f", str(tmp_path / "mkdocs.yml"), "-d", str(tmp_path / "site"))
    assert r.returncode != 0 and "missing.md" in r.stderr
    small["nav"] = [{"Home": "index.md"}]  # a page left out of the navigation fails it too
    (tmp_path / "docs" / "index.md").write_text("# Home\n")
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(small))
    r = run("-m", "mkdocs", "build", "-f", str(tmp_path / "mkdocs.yml"), "-d", str(tmp_path / "site"))
    assert r.returncode != 0 and "guide.md" in r.stderr


def test_a_page_missing_from_mkdocs_yml_is_still_in_the_navigation(tmp_path):
    """A feature's new page under docs/ lands in the `In depth` section until mkdocs.yml places it, so a
    reader finds it and the strict build stays green (scripts/mkdocs_studies.py)."""
    (tmp_path / "docs").mkdir()
    for name, title in (("index.md", "Home"), ("a.md", "Listed"), ("thermal.md", "Thermal calibration")):
        (tmp_path / "docs" / name).write_text(f"# {title}\n")
    cfg = {"site_name": "t", "hooks": [str(ROOT / "scripts" / "mkdocs_studies.py")],
           "nav": [{"Home": "index.md"}, {"In depth": [{"Listed": "a.md"}]}, {"Studies": "studies/index.md"}]}
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(cfg))
    r = run("-m", "mkdocs", "build", "-f", str(tmp_path / "mkdocs.yml"), "-d", str(tmp_path / "site"))
    assert r.returncode == 0, r.stderr[-2000:]
    home = (tmp_path / "site" / "index.html").read_text(encoding="utf-8")
    assert "thermal/" in home and "Thermal calibration" in home


def test_every_inserted_block_equals_its_result_file():
    r = run(str(TOOL), "--check")
    assert r.returncode == 0, r.stdout


def test_a_stale_number_is_named(tmp_path):
    """A number edited by hand in the README (or a result file re-measured) fails the check, naming the block."""
    (tmp_path / "studies" / "results").mkdir(parents=True)
    (tmp_path / "studies" / "results" / "x.md").write_text("# X\n\n<!-- begin:t -->\n| rms | 0.00101 |\n<!-- end:t -->\n")
    block = "<!-- begin:studies/results/x.md#t -->\n| rms | {} |\n<!-- end:studies/results/x.md#t -->\n"
    (tmp_path / "README.md").write_text("# R\n\n" + block.format("0.00101"))
    assert run(str(TOOL), "--check", "--root", str(tmp_path)).returncode == 0
    (tmp_path / "README.md").write_text("# R\n\n" + block.format("0.00099"))
    r = run(str(TOOL), "--check", "--root", str(tmp_path))
    assert r.returncode == 1 and "README.md: block studies/results/x.md#t differs from its source" in r.stdout
    assert run(str(TOOL), "--root", str(tmp_path)).returncode == 0  # the tool puts the measured value back
    assert "0.00101" in (tmp_path / "README.md").read_text()


@pytest.mark.slow
def test_a_newcomers_commands_print_what_the_readme_shows():
    """Every `imucal` command the README shows, run in a fresh folder on the shipped data, prints the
    numbers the README quotes (to the digits shown)."""
    r = run(str(TOOL), "examples", "--check")
    assert r.returncode == 0, r.stdout + r.stderr[-3000:]


def test_the_readme_is_a_front_page_and_ci_runs_its_test_command():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= README_MAX_LINES
    assert not re.search(r"\bissue \d+", readme, re.I)  # no internal issue numbers
    assert README_TEST_COMMAND in readme
    assert README_TEST_COMMAND in (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()


def _sources(*folders: str):
    for folder in folders:
        yield from sorted((ROOT / folder).rglob("*.py"))


def _code_strings(tree: ast.AST):
    """The string constants of a module that are not docstrings."""
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef)) and n.body
                  and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    return [n.value for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docstrings]


def test_the_products_tests_import_nothing_from_studies_or_scripts():
    """Neither by import nor loaded by path; only this file runs the documentation tool, as a program."""
    for path in _sources("tests"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n.split(".")[0] in ("studies", "scripts") for n in names), (path.name, names)
        if path.name != "test_docs.py":
            for text in _code_strings(tree):
                assert text not in ("studies", "scripts") and not re.search(r"\b(studies|scripts)/", text), \
                    (path.name, text)


def test_no_script_study_or_test_holds_a_machine_path():
    for path in _sources("scripts", "studies", "tests"):
        for text in _code_strings(ast.parse(path.read_text(encoding="utf-8"))):
            assert not MACHINE_PATH.match(text), (str(path.relative_to(ROOT)), text)


def test_the_studies_runner_lists_every_result_page():
    r = run("-m", "studies", "list")
    assert r.returncode == 0
    pages = {p.relative_to(ROOT / "studies" / "results").with_suffix("").as_posix()
             for p in (ROOT / "studies" / "results").rglob("*.md")}
    for page in pages:  # one registry entry per result page: none unlisted, none missing
        assert re.search(rf"^  {re.escape(page)} ", r.stdout, re.M), page
    bad = run("-m", "studies", "run", "no_such_study")
    assert bad.returncode == 2 and "no study 'no_such_study'" in bad.stderr
