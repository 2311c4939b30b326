"""Each decision of the harness is written once: the Poisson-ratio range, the nearly
incompressible threshold that picks the mixed FEM element, the speed-against-error budgets, the
strict-JSON walker, and the criteria of the publication's claims (in the studies, not the
report).  Each check below looks for a second copy in the packages' code (docstrings aside) and
then checks that the users of the one home agree with it."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("hybmss", "fem_reference", "studies", "reports", "benchmarks")


def _code(path: Path) -> str:
    """The module's source with its docstrings blanked (string literals elsewhere kept)."""
    src = path.read_text()
    tree = ast.parse(src)
    lines = src.splitlines()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
                for i in range(first.lineno - 1, first.end_lineno):
                    lines[i] = ""
    return "\n".join(lines)


def _hits(pattern: str, root: Path = ROOT) -> list[str]:
    rx = re.compile(pattern)
    out = []
    for pkg in PACKAGES:
        for path in sorted((root / pkg).rglob("*.py")):
            for i, line in enumerate(_code(path).splitlines(), 1):
                if rx.search(line.split("#")[0]):
                    out.append(f"{path.relative_to(root)}:{i}")
    return out


@pytest.mark.parametrize("what, pattern, home", [
    ("the mixed-element threshold", r"(>=|<)\s*0\.45\b|=\s*0\.45\s*$", ["hybmss/scene/material.py"]),
    ("the open Poisson-ratio range", r"-1(\.0)?\s*<[^<]*nu[^<]*<\s*0\.5\b|\(-1(\.0)?, 0\.5\)|Range\(-1(\.0)?,\s*0\.5\b",
     ["hybmss/scene/material.py"]),
    ("the error budgets", r"^\s*BUDGETS\s*=", ["studies/paper/pareto.py"]),
    ("the strict-JSON walker", r"^def strict\(", ["studies/sweep/store.py"]),
    ("the claims' criteria", r"^(E_MODULI_TOL|E_FEM_PP|INCOMPRESSIBLE_E_PCT|PAPER_PP|REL_PCT|MIDDLE_LAYER_TOL)\s*=",
     ["studies/paper/claims.py"]),
])
def test_a_decision_has_one_home(what, pattern, home):
    assert sorted({h.split(":")[0] for h in _hits(pattern)}) == home, what


def test_the_check_finds_a_second_copy(tmp_path):
    """The search above can fail: a copied threshold in a module is found, its docstring is not."""
    pkg = tmp_path / "studies"
    pkg.mkdir()
    (pkg / "copy.py").write_text('"""mixed for nu >= 0.45"""\n\ndef f(nu):\n    return "mixed" if nu >= 0.45 else "hex2"\n')
    assert _hits(r"(>=|<)\s*0\.45\b", tmp_path) == ["studies/copy.py:4"]


def test_the_users_of_each_home_agree_with_it():
    from fem_reference.solve import resolve_element
    from hybmss.experiments import SceneSpec
    from hybmss.scene import NEARLY_INCOMPRESSIBLE_NU, NU_OPEN_RANGE, Material, admissible_nu
    from studies.sweep import sizing
    from studies.cli.parser import build_parser

    lo, hi = NU_OPEN_RANGE
    assert (lo, hi) == (-1.0, 0.5) and not admissible_nu(lo) and not admissible_nu(hi) and admissible_nu(0.499)
    for nu in (lo, hi):
        with pytest.raises(ValueError, match=r"open interval \(-1, 0.5\)"):
            Material(1.0, nu)
        with pytest.raises(ValueError, match="nu"):
            SceneSpec.default("compression", nu=nu).check()
    below = NEARLY_INCOMPRESSIBLE_NU - 1e-9
    assert resolve_element("auto", NEARLY_INCOMPRESSIBLE_NU) == "mixed" and resolve_element("auto", below) == "hex2"
    assert sizing.fem_dofs((2, 2, 2), "auto", 1, NEARLY_INCOMPRESSIBLE_NU) == sizing.fem_dofs((2, 2, 2), "mixed")
    assert sizing.fem_dofs((2, 2, 2), "auto", 1, below) == sizing.fem_dofs((2, 2, 2), "hex2")
    parser, _ = build_parser()
    fem = next(a for a in parser._subparsers._group_actions[0].choices["fem"]._actions if a.dest == "element")
    assert f"mixed for nu >= {NEARLY_INCOMPRESSIBLE_NU:g}" in fem.help


def test_the_command_line_writes_strict_json_with_the_stores_walker():
    import json

    import numpy as np

    from studies.cli import parser as cli

    from studies.sweep import store

    obj = {"a": float("nan"), "b": [np.float32(1.5), 2], "c": (np.int64(3), np.array([np.inf]))}
    assert json.loads(cli.dump(obj)) == store.strict(obj) == {"a": None, "b": [1.5, 2], "c": [3, [None]]}
