"""Imports flow one way: no import circle between the modules of any package, counting every
import statement (at module level and inside functions), and between packages only
hybmss <- fem_reference <- studies <- reports (benchmarks and tests may use any of them).

The model registry (:mod:`hybmss.models`) loads the model modules and the entry points of other
packages at its first look-up (``importlib``); that is plug-in discovery, not an import
statement, and is not an edge here: a plug-in imports ``hybmss`` by nature."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("hybmss", "fem_reference", "studies", "reports", "benchmarks")
LAYER = {"hybmss": 0, "fem_reference": 1, "studies": 2, "reports": 3, "benchmarks": 4}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def import_graph() -> dict[str, set[str]]:
    """Module -> project modules it imports (every ``import``/``from`` statement)."""
    files = {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in files}
    for mod, path in files.items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = _resolve(mod, is_pkg, node)
                targets = [f"{base}.{a.name}" for a in node.names] + [base]
            for t in targets:
                # the longest project module that the target names (a module, or a name in one)
                while t and t not in files:
                    t = t.rpartition(".")[0]
                if t and t != mod and not mod.startswith(t + "."):  # a parent package is imported first anyway
                    graph[mod].add(t)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_walk_sees_imports():
    g = import_graph()
    assert "hybmss.scene" in g["hybmss.system"]  # from .scene import Scene
    assert "hybmss.models.base" in g["hybmss.models.hybmss"]
    assert "hybmss.experiments" in g["studies.study.experiment"]
    assert "studies.study.experiment" in g["studies.paper.reproduce"]  # from .study.experiment import ...
    # a circle is found when there is one
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_circle(package):
    g = import_graph()
    inside = {m: {t for t in ts if t.split(".")[0] == package} for m, ts in g.items() if m.split(".")[0] == package}
    assert _cycles(inside) == []


def test_packages_import_one_way():
    bad = [(m, t) for m, ts in import_graph().items() for t in ts
           if LAYER[t.split(".")[0]] > LAYER[m.split(".")[0]]]
    assert bad == []


#: the floors of :mod:`studies`: the machinery of a sweep, the study-file format on it, the
#: publication's studies on both, the command line on top (a module at the package's root is the
#: package's own and may import any floor)
STUDIES_FLOOR = {"studies.sweep": 0, "studies.study": 1, "studies.paper": 2, "studies.cli": 3}


def _floor(module: str) -> int | None:
    return next((f for p, f in STUDIES_FLOOR.items() if module == p or module.startswith(p + ".")), None)


def test_studies_floors_import_downwards():
    """The sweep machinery knows no study file, publication or command line; the study-file
    format knows no publication or command line; the publication's studies know no command line."""
    bad = [(m, t) for m, ts in import_graph().items() for t in ts
           if _floor(m) is not None and _floor(t) is not None and _floor(t) > _floor(m)]
    assert bad == []
