"""A model from another package: the README's "Add a model" example, installed in a temporary
folder and registered through the entry-point group ``hybmss.models``, goes through the real
``hybmss`` command (moduli, compare, a small study) and the report, with no project file changed.

The effective moduli are checked against the closed form of a spring-only cubic lattice
calibrated for G (SPEC §2): G_eff = G, ν_eff = 1/4 (Cauchy relation), E_eff = 2 G (1 + 1/4)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _readme_example() -> tuple[str, str]:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Add a model"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    entry = re.search(r'\[project\.entry-points\."hybmss\.models"\]\n(.*?)\n', section).group(1)
    return code, entry


def _project_state() -> str:
    out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                         capture_output=True, text=True)
    return out.stdout if out.returncode == 0 else ""


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    """A site folder holding the package ``shearsprings`` and its distribution metadata."""
    code, entry = _readme_example()
    site = tmp_path_factory.mktemp("site")
    (site / "shearsprings").mkdir()
    (site / "shearsprings" / "__init__.py").write_text(code)
    dist = site / "shearsprings-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: shearsprings\nVersion: 0.1\n")
    name, value = (t.strip().strip('"') for t in entry.split("=", 1))  # TOML -> entry_points.txt
    (dist / "entry_points.txt").write_text(f"[hybmss.models]\n{name} = {value}\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), str(site)]), MPLBACKEND="Agg",
               PYVISTA_OFF_SCREEN="true")
    return env


def _hybmss(env, *args, timeout=300):
    script = Path(sys.executable).with_name("hybmss")
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "studies"]
    p = subprocess.run(cmd + list(args), env=env, capture_output=True, text=True, timeout=timeout)
    assert p.returncode == 0, p.stderr[-2000:]
    return p.stdout


def test_plugin_moduli_match_the_closed_form(plugin):
    before = _project_state()
    E, nu = 1e4, 0.3
    out = json.loads(_hybmss(plugin, "moduli", "--model", "shear-springs", "--E", str(E), "--nu", str(nu), "--json"))
    G = E / (2 * (1 + nu))
    assert out["G_eff"] == pytest.approx(G, rel=1e-6)
    assert out["nu_eff"] == pytest.approx(0.25, abs=1e-6)
    assert out["E_eff"] == pytest.approx(2.5 * G, rel=1e-6)
    assert _project_state() == before


@pytest.mark.slow
def test_plugin_in_compare_and_in_a_report(plugin, tmp_path):
    before = _project_state()
    out = json.loads(_hybmss(plugin, "compare", "compression", "--mesh", "2x2x2", "--model", "shear-springs",
                             "--A", "2", "--fem", "hex1", "--json"))
    assert out["scene"]["model"] == "shear-springs" and out["scene"]["A"] == 2.0
    assert out["mss"]["converged"] and out["mss"]["volume_change"] < 0

    # a small study: compression of a 2x2x2 cube, every registered model, and the report of it
    results, report = tmp_path / "results", tmp_path / "report"
    study = (
        "import sys, functools\n"
        "from hybmss.experiments import SceneSpec\n"
        "from studies.sweep import roles\n"
        "from studies.sweep.runner import SolverSpec, Task, run_tasks\n"
        "from studies.sweep.store import Store\n"
        "import studies.paper.tables as t\n"
        "store = Store(sys.argv[1])\n"
        "spec = SceneSpec.default('compression', mesh=(2, 2, 2), nu=0.3)\n"
        "tasks = [Task(spec.replace(model=m), SolverSpec('static'), 'compression') for m in roles.in_role('tables')]\n"
        "tasks.append(Task(spec, SolverSpec('fem', element='hex1', law='linear'), 'compression'))\n"
        "rows = run_tasks(tasks, store, jobs=1, progress=False)\n"
        "assert all(r['status'] == 'ok' for r in rows), rows\n"
        "t.moduli_table = functools.partial(t.moduli_table, nus=(0.3,))\n"
        "t.write_tables(store)\n"
    )
    p = subprocess.run([sys.executable, "-c", study, str(results)], env=plugin, capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    runs = (results / "tables" / "runs.csv").read_text()
    assert "shear-springs" in runs
    styles = (results / "tables" / "models.csv").read_text()
    assert "shear-springs,shear-springs" in styles and "#17becf" in styles
    p = subprocess.run([sys.executable, "-m", "reports", "build", "--results", str(results), "--out", str(report),
                        "--no-pdf", "--quiet"], env=plugin, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    html = (report / "index.html").read_text()
    assert "shear-springs" in html
    assert _project_state() == before
