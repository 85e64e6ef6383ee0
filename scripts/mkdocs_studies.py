"""mkdocs hook: the Studies section of the site, from the studies' registry (studies/studies.yaml), and a
place in the navigation for every page.

A study is listed once, in the registry; this hook puts every result page into the navigation under
its group and writes the section's overview page (studies/index.md) with one line per study. The
pages themselves are studies/results/*.md, which the site reads through the link docs/studies.
A page under docs/ that mkdocs.yml does not list yet (a feature's new page) is added to the
`In depth` section, so a reader finds it from the navigation; listing it in mkdocs.yml places it.
"""
from __future__ import annotations

from pathlib import Path

import yaml
from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]
REGISTRY = ROOT / "studies" / "studies.yaml"
#: The nav entry mkdocs.yml leaves for this hook to fill.
PLACEHOLDER = "Studies"
#: The section that receives the pages mkdocs.yml does not list.
UNLISTED_SECTION = "In depth"
INDEX = "studies/index.md"


def _studies() -> list[dict]:
    return yaml.safe_load(REGISTRY.read_text(encoding="utf-8"))


def _groups() -> dict[str, list[dict]]:
    groups: dict[str, list[dict]] = {}
    for s in _studies():
        groups.setdefault(s["group"], []).append(s)
    return groups


def on_config(config, **kwargs):
    """Replace the nav's `Studies` entry by the overview and one sub-section per group."""
    section = [{"Overview": INDEX}] + [
        {group: [{s["title"]: f"studies/{s['page']}.md"} for s in items]} for group, items in _groups().items()]
    for i, item in enumerate(config["nav"]):
        if isinstance(item, dict) and PLACEHOLDER in item:
            config["nav"][i] = {PLACEHOLDER: section}
            return config
    raise SystemExit(f"mkdocs.yml: the nav has no `{PLACEHOLDER}` entry for the studies")


def overview() -> str:
    lines = ["# Studies", "",
             "The measurements behind the numbers in the README and the guide, apart from the product: each page "
             "is written by a program in `studies/` (`python -m studies run PAGE`; `python -m studies list` "
             "prints this list). The README and the guide insert their numbers from these pages "
             "(`python scripts/update_docs.py`), and CI checks that they match.", ""]
    for group, items in _groups().items():
        lines += [f"## {group}", ""]
        lines += [f"- [{s['title']}]({s['page']}.md): {s['measures']} (`python -m studies run {s['page']}`)"
                  for s in items]
        lines.append("")
    return "\n".join(lines)


def _listed(nav) -> set[str]:
    """Every page path the navigation names."""
    if isinstance(nav, str):
        return {nav}
    if isinstance(nav, dict):
        return set().union(*(_listed(v) for v in nav.values()))
    if isinstance(nav, list):
        return set().union(*(_listed(v) for v in nav)) if nav else set()
    return set()


def _place_unlisted(files: Files, config) -> None:
    listed = _listed(config["nav"])
    unlisted = sorted(f.src_uri for f in files.documentation_pages() if f.src_uri not in listed)
    if not unlisted:
        return
    for item in config["nav"]:
        if isinstance(item, dict) and UNLISTED_SECTION in item:
            item[UNLISTED_SECTION] = list(item[UNLISTED_SECTION]) + unlisted
            return
    config["nav"].append({UNLISTED_SECTION: unlisted})


def on_files(files: Files, config, **kwargs) -> Files:
    files.append(File.generated(config, INDEX, content=overview()))
    _place_unlisted(files, config)
    return files
