"""The engines as optional extras and their versions.

- ``pip install hybmss[engines]`` installs the engines (pyproject's ``engines`` extra equals the
  engine folders' ``REQUIRES``, each with an upper bound; no engine among the dependencies; the
  Makefile's environment installs the extra).
- An engine that is missing (a blocking import hook, not an uninstall) or installed at a version
  outside the range its models' laws were read and measured at leaves its models unavailable with
  the reason and the install command: not among the registry's names, refused by name (exit 2 of
  ``hybmss compare --model mujoco-tet``, one stderr line, no traceback), named in a study file's
  refusal.
"""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from hybmss.models import _engine_model as em

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("mujoco", "newton", "pbd")


def _requires():
    import importlib

    return {f: importlib.import_module(f"hybmss.models.{f}").REQUIRES for f in FOLDERS}


def test_engines_extra_is_the_models_requirements():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extra = meta["optional-dependencies"]["engines"]
    lines = [line for req in _requires().values() for line in em.requirement_lines(req)]
    assert sorted(extra) == sorted(lines)
    assert all("<" in line for line in extra)  # every engine has an upper bound
    deps = " ".join(meta["dependencies"])
    assert not any(d in deps for d in ("mujoco", "newton", "warp", "pypbd"))
    assert "'.[test,engines]'" in (ROOT / "Makefile").read_text()


@pytest.mark.parametrize("version, spec, ok", [("4.0.1", ">=4.0,<4.1", True), ("4.1.0", ">=4.0,<4.1", False),
                                               ("3.9", ">=4.0,<4.1", False), ("1.19.0", ">=1.19,<2", True),
                                               ("2.0.0rc1", ">=1.19,<2", False), ("1.18.9", ">=1.19,<2", False)])
def test_version_range(version, spec, ok):
    assert em.in_range(version, spec) is ok


def test_unsupported_version_makes_models_unavailable(monkeypatch):
    """newton 1.9.0 reported by the package metadata (its private kernels may have changed): the
    newton-* models are unavailable with the installed and the measured versions and the install
    command; at the installed version nothing is missing."""
    import hybmss.models.newton as nw

    if em.missing_engine(nw.REQUIRES) is not None:
        pytest.skip("newton is not installed at a supported version here")
    real = importlib.metadata.version
    monkeypatch.setattr(importlib.metadata, "version", lambda d: "1.9.0" if d == "newton" else real(d))
    models, unavailable = em.engine_models(nw.REQUIRES, (nw.NewtonSemi(), nw.NewtonVBD()))
    assert models == ()
    why = unavailable["newton-semi"]
    assert "newton 1.9.0 is installed" in why and ">=1.8,<1.9" in why and "pip install 'hybmss[engines]'" in why


BLOCK = ("import sys\n"
         "class Block:\n"
         "    def find_spec(self, name, path=None, target=None):\n"
         "        if name.split('.')[0] == 'mujoco':\n"
         "            raise ModuleNotFoundError(name)\n"
         "sys.meta_path.insert(0, Block())\n")


def _run(code: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", BLOCK + code], capture_output=True, text=True, timeout=120,
                          cwd=cwd, env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})


def test_missing_engine_compare_exits_2_with_install_command():
    p = _run("from studies.cli.parser import main; sys.exit(main(['compare', 'compression', '--model', 'mujoco-tet']))")
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr
    assert "mujoco-tet is unavailable" in lines[0] and "pip install 'hybmss[engines]'" in lines[0]
    p = _run("import hybmss.models as m\n"
             "try:\n    m.get('mujoco-trilinear')\nexcept ValueError as e:\n    print(e)\n"
             "print(sorted(m.unavailable()), 'mujoco-tet' in m.names())")
    assert p.returncode == 0 and p.stderr == "", p.stderr
    assert "mujoco-trilinear is unavailable: the mujoco package is not installed" in p.stdout
    assert "['mujoco-quadratic', 'mujoco-tet', 'mujoco-trilinear'] False" in p.stdout


def test_missing_engine_in_a_study_file():
    """A study file naming a model whose engine is missing is refused at its dotted key with the
    reason (the study spec's reader)."""
    p = _run("from studies.study import spec\nfrom studies.study.keys import Table\n"
             "from hybmss import models\n"
             "t = Table({'name': 'mujoco-tet'}, 'models[0]', 'study.toml')\n"
             "try:\n    spec._read_model(t)\nexcept Exception as e:\n    print(type(e).__name__, e)\n")
    assert p.returncode == 0, p.stderr
    assert "models[0].name" in p.stdout and "mujoco-tet is unavailable" in p.stdout and "hybmss[engines]" in p.stdout


def test_pbd_forces_said_to_be_the_harness_s():
    """pbd-xpbd-fem's forces are svk_forces, the harness's re-implementation: its label and
    docstring, and the report's engines section, say so."""
    pbd = pytest.importorskip("hybmss.models.pbd")
    from reports.engines import findings

    assert "re-implemented" in pbd.PbdXpbdFem.label
    assert "svk_forces" in pbd.PbdXpbdFem.__doc__ and "re-implementation" in pbd.__doc__
    text = findings(None, None)
    assert "pbd-xpbd-fem's forces" in text and "re-implementation" in text and "svk_forces" in text


# ---------------------------------------------------------------------------- the law check per engine version
def test_law_check_measured_once_per_version(tmp_path, monkeypatch):
    """mujoco-trilinear's law check (its own forces on one cell against (λ + 2μ) ε and μ γ) runs
    once per installed version: cached under the version's key, measured again for another."""
    pytest.importorskip("mujoco")
    from hybmss import models

    cache = tmp_path / "laws.json"
    monkeypatch.setenv("HYBMSS_ENGINE_CACHE", str(cache))
    model = models.get("mujoco-trilinear")
    calls = []
    real = type(model).law_errors
    monkeypatch.setattr(type(model), "law_errors", lambda self: calls.append(1) or real(self))
    model.check_law()
    model.check_law()
    assert len(calls) == 1
    key = f"mujoco-trilinear | mujoco {importlib.metadata.version('mujoco')}"
    import json

    stored = json.loads(cache.read_text())[key]
    assert stored["uniaxial"] < 1e-9 and stored["shear"] < 1e-5  # corotational linear: exact at small strain
    version = importlib.metadata.version
    monkeypatch.setattr(importlib.metadata, "version", lambda d: "4.0.99" if d == "mujoco" else version(d))
    model.check_law()
    assert len(calls) == 2 and "mujoco-trilinear | mujoco 4.0.99" in json.loads(cache.read_text())


def test_changed_law_makes_the_model_unavailable(tmp_path, monkeypatch):
    """newton-semi with the builder's Lamé parameters taken as they are (k_mu = μ, k_lambda = λ,
    the law its docstring derives against: μ 25 % low): the law check finds the shear stress 25 %
    off, and a run is refused (a ValueError: exit 2) naming the version and the install command."""
    pytest.importorskip("newton")
    from hybmss import Material, Model
    from hybmss.models import _engine_model as em
    from hybmss.models.newton import engine
    from hybmss.moduli import measure_moduli

    monkeypatch.setenv("HYBMSS_ENGINE_CACHE", str(tmp_path / "laws.json"))
    monkeypatch.setattr(engine, "lame", lambda m: (float(m.G), float(m.lam)))
    with pytest.raises(ValueError, match="newton-semi is unavailable") as e:
        measure_moduli(Model("newton-semi"), Material(1e4, 0.3, 1000.0), strain=3e-3)
    assert isinstance(e.value, em.EngineUnavailable)
    assert "the shear stress 25 % off" in str(e.value) and "newton 1.8" in str(e.value)
    assert "pip install 'hybmss[engines]'" in str(e.value)
