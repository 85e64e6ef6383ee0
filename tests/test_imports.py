"""No import circle in imucal/ (issue 30): every import a module can run (at its top or inside a
function; not the annotations under ``if TYPE_CHECKING:``) points to a module below it.

The walk reads the source (ast), so an import inside a function counts although it runs late: a
circle of late imports is still two modules that each need the other.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "imucal"


def _module_names(root: Path) -> dict[str, Path]:
    """Dotted name -> file of every module under ``root`` (a package folder)."""
    out = {}
    for p in sorted(root.rglob("*.py")):
        parts = p.relative_to(root.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(path: Path, name: str, modules: dict[str, Path]) -> set[str]:
    """The modules of ``modules`` that ``name`` (at ``path``) imports at run time."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def target(base: str, names: list[str]) -> None:
        for n in names:  # `from pkg import mod` imports the module pkg.mod
            found.add(f"{base}.{n}" if f"{base}.{n}" in modules else base)

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child.test):
                for other in child.orelse:
                    visit(other)
                continue
            if isinstance(child, ast.Import):
                found.update(a.name for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                if child.level:  # relative: from the package, up level - 1
                    base = ".".join(package.split(".")[:len(package.split(".")) - child.level + 1])
                    base = f"{base}.{child.module}" if child.module else base
                else:
                    base = child.module or ""
                target(base, [a.name for a in child.names])
            visit(child)

    visit(ast.parse(path.read_text(encoding="utf-8")))
    return {m for m in found if m in modules and m != name}


def import_graph(root: Path) -> dict[str, set[str]]:
    modules = _module_names(root)
    return {name: _imports(path, name, modules) for name, path in modules.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each as a path
    that closes on itself."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def connect(v: str) -> None:  # iterative: no recursion limit on a deep package
        work = [(v, iter(sorted(graph[v])))]
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        while work:
            u, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[u] = min(low[u], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[u])
            if low[u] == index[u]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == u:
                        break
                if len(comp) > 1:
                    found.append(_cycle_in(sorted(comp), graph))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return found


def _cycle_in(comp: list[str], graph: dict[str, set[str]]) -> list[str]:
    """One closed path through a component (breadth first from its first module back to it)."""
    members, start = set(comp), comp[0]
    prev: dict[str, str] = {}
    todo = [start]
    while todo:
        u = todo.pop(0)
        for w in sorted(graph[u] & members):
            if w == start:
                path = [u]
                while path[-1] != start:
                    path.append(prev[path[-1]])
                return [start, *reversed(path[:-1]), start]
            if w not in prev:
                prev[w] = u
                todo.append(w)
    return comp


def _write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return root / "pkg"


def test_imucal_has_no_import_circle() -> None:
    graph = import_graph(ROOT)
    assert len(graph) > 100 and "imucal.data.stream" in graph["imucal.pipeline"] | graph["imucal.data.unit_hint"]
    found = circles(graph)
    assert not found, "import circles: " + "; ".join(" -> ".join(c) for c in found)


@pytest.mark.parametrize("late", ["top", "function"])
def test_a_circle_is_found_at_the_top_or_in_a_function(tmp_path: Path, late: str) -> None:
    """The walk finds a circle closed by an import inside a function as well as at the top, through
    `from pkg import module` and relative imports, and names its path."""
    back = ("from pkg.a import x\n" if late == "top" else "def f():\n    from . import a\n    return a\n")
    pkg = _write(tmp_path, {"pkg/__init__.py": "", "pkg/a.py": "from pkg import b\nx = 1\n",
                            "pkg/sub/__init__.py": "", "pkg/sub/b.py": "", "pkg/b.py": back + "y = 2\n"})
    assert circles(import_graph(pkg)) == [["pkg.a", "pkg.b", "pkg.a"]]


def test_annotations_under_type_checking_are_no_circle(tmp_path: Path) -> None:
    pkg = _write(tmp_path, {"pkg/__init__.py": "", "pkg/a.py": "import pkg.b\n",
                            "pkg/b.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.a import X\n"
                                        "else:\n    import os\n"})
    graph = import_graph(pkg)
    assert graph["pkg.a"] == {"pkg.b"} and graph["pkg.b"] == set() and circles(graph) == []
