"""The model registry and protocol (hybmss/models): every model declared once, listed by the
registry, validated on construction, and the only place that knows its own name."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from hybmss import models
from hybmss.calibrate import hybrid_springs
from hybmss.experiments import SceneSpec
from hybmss.models import ModelBase, NoParameters, Style
from hybmss.scene import Material, Model, Scene
from hybmss.system import build

ROOT = Path(__file__).resolve().parents[1]
IN_TREE = ("hybmss", "hybmss-fd", "hybmss-cf", "baudet2009")


def test_in_tree_models_are_registered_in_order():
    assert models.names()[:4] == IN_TREE
    # one module per model, each defining MODEL
    files = sorted(p.stem for p in (ROOT / "hybmss" / "models").glob("*.py") if not p.stem.startswith("_")
                   and p.stem != "base")
    assert sorted(m.replace("-", "_") for m in IN_TREE) == files


@pytest.mark.parametrize("name", models.names())
def test_every_model_declares_the_protocol(name):
    m = models.get(name)
    m.validate()
    assert m.label and isinstance(m.style, Style)
    assert set(m.solvers) <= set(models.SOLVER_KINDS) and set(m.kernels) <= set(models.KERNELS)
    assert m.conservative or "implicit" not in m.solvers
    model = Model(name)
    assert Scene.from_dict({"body": {"shape": [1, 1, 1], "le": 1.0}, "material": {"E": 1.0, "nu": 0.3},
                            "model": model.to_dict()}).model == model
    c = m.constants(model.params, Material(1e4, 0.3), 0.5)
    assert all(np.isfinite(k) and k >= 0 for k in c.by_family)


def test_unknown_model_and_parameters_name_what_is_allowed():
    with pytest.raises(ValueError, match="model must be one of hybmss, hybmss-fd"):
        Model("hybmss-xyz")
    with pytest.raises(ValueError, match=r"baudet2009 has no parameter 'A' \(its parameters: none\)"):
        Model("baudet2009", A=1.0)
    with pytest.raises(ValueError, match="volume_energy must be one of quadratic, squared"):
        Model("hybmss", volume_energy="cubic")
    with pytest.raises(ValueError, match="A must be 0 for model hybmss-fd"):
        Model("hybmss-fd", A=1.0)


def test_scene_model_records_every_parameter_under_its_own_name():
    m = Model("hybmss-fd")
    assert m.to_dict() == {"name": "hybmss-fd", "A": 0.0, "e_form": False, "volume_energy": "quadratic"}
    assert Model("baudet2009").to_dict() == {"name": "baudet2009"}
    assert m.A == 0.0 and Model("hybmss", e_form=True).variant == "hybmss (E-form)"
    assert m.replace(name="hybmss").to_dict()["A"] == 1.0  # the new model's default, not the old one's
    assert Model("hybmss", A=3.0).replace(volume_energy="squared").A == 3.0
    with pytest.raises(AttributeError):
        Model("baudet2009").A


class _Rods(ModelBase):
    """Edges only, for G (no face or inner diagonals): a test model registered at run time."""

    name = "test-rods"
    label = "edge springs only (test)"
    style = Style("#000000", "+", "--")
    solvers = ("static",)
    studies = ("tables",)

    def constants(self, p, material, le):
        c = hybrid_springs(material.G, 0.0, le, 0.0)
        return dataclasses.replace(c, kc=0.0)


def test_register_a_model_at_run_time():
    models.register(_Rods())
    try:
        assert "test-rods" in models.names() and models.in_role("tables")[-1] == "test-rods"
        assert "test-rods" not in models.in_role("regression")
        spec = SceneSpec.default("compression", mesh=(2, 2, 2), model="test-rods")
        S = build(spec.build())
        assert set(np.unique(S.spring_family)) == {0}  # edges only
        assert spec.to_dict()["variant"] == "test-rods"
        with pytest.raises(ValueError, match="already registered"):
            models.register(type("Other", (_Rods,), {})())
    finally:
        models.unregister("test-rods")
    assert "test-rods" not in models.names()


def test_declarations_that_break_the_protocol_are_refused():
    class NoName(ModelBase):
        name = "Bad Name"

    class ImplicitWithoutEnergy(ModelBase):
        name = "bad-implicit"
        conservative = False

    @dataclasses.dataclass(frozen=True)
    class Clash:
        nu: float = 0.3

    class ClashingParameter(ModelBase):
        name = "bad-clash"
        Parameters = Clash

    with pytest.raises(ValueError, match="model name"):
        models.register(NoName())
    with pytest.raises(ValueError, match="implicit Euler needs a conservative model"):
        models.register(ImplicitWithoutEnergy())
    models.register(ClashingParameter())
    try:
        with pytest.raises(ValueError, match="clashes with a scene field"):
            SceneSpec.default("compression", model="bad-clash", params=(("nu", 0.3),))
    finally:
        models.unregister("bad-clash")
    assert NoParameters in [ModelBase.Parameters]


def test_a_model_without_springs_builds_a_system_with_none():
    class Empty(ModelBase):
        name = "test-empty"

    models.register(Empty())
    try:
        S = build(SceneSpec.default("compression", mesh=(1, 1, 1), model="test-empty").build())
        assert len(S.spring_k) == 0 and not S.has_volume and S.n == 8
    finally:
        models.unregister("test-empty")


PUBLICATION_NAMED = {"studies/performance.py"}
"""[G20] Figs 11-12 give time ratios of HybMSS-CF and HybMSS over HybMSS-FD
(``studies/data/g20_performance.csv``): the study matches those named quantities."""
CHECKED = ("hybmss", "fem_reference", "studies", "benchmarks", "reports/palette.py", "reports/data.py",
           "reports/render.py")
"""Everything that builds, solves, lists or styles models.  The report's findings and claims
(``reports/summary.py``, ``findings.py``, ``tables.py``, ``figures.py``) are statements about the
publication's models and name them."""


def test_no_code_outside_a_model_module_compares_a_model_name():
    """Comparisons (==, !=, in) against a literal registered name, in the packages' code."""
    names = "|".join(re.escape(n) for n in IN_TREE)
    pattern = re.compile(rf"""(==|!=|\bin)\s*\(?\s*["']({names})["']|["']({names})["']\s*(==|!=)""")
    hits = []
    for part in CHECKED:
        for path in ([ROOT / part] if part.endswith(".py") else (ROOT / part).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel.startswith("hybmss/models/") or rel in PUBLICATION_NAMED:
                continue
            for i, line in enumerate(path.read_text().splitlines(), 1):
                if pattern.search(line):
                    hits.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert hits == []


def test_a_model_with_its_own_solvers_and_time_step_gets_the_scene():
    """``solve_static``, ``simulate_explicit`` and ``dt_crit`` of a model replace the harness's."""
    from hybmss.explicit import dt_crit, simulate_explicit
    from hybmss.solvers import solve_static

    seen = []

    class Own(ModelBase):
        name = "test-own"
        solvers = ("static", "explicit")
        kernels = ("numpy",)

        def solve_static(self, scene, options=None, system=None):
            seen.append(("static", scene.model.name))
            return "static answer"

        def simulate_explicit(self, scene, **kw):
            seen.append(("explicit", kw["dt"], kw["steps"]))
            return "explicit answer"

        def dt_crit(self, system):
            return 0.125

    models.register(Own())
    try:
        scene = SceneSpec.default("compression", mesh=(1, 1, 1), model="test-own").build()
        assert solve_static(scene) == "static answer"
        assert simulate_explicit(scene, dt=1e-3, steps=7, kernel="numpy") == "explicit answer"
        assert dt_crit(scene) == 0.125
        with pytest.raises(ValueError, match="no numba kernel"):
            simulate_explicit(scene, kernel="numba")
        assert seen == [("static", "test-own"), ("explicit", 1e-3, 7)]
    finally:
        models.unregister("test-own")
    rods = _Rods()
    rods.solvers = ("explicit",)
    models.register(rods)
    try:
        with pytest.raises(ValueError, match="has no static solver"):
            solve_static(SceneSpec.default("compression", mesh=(1, 1, 1), model="test-rods").build())
    finally:
        models.unregister("test-rods")


def test_parameter_fields_give_each_parameter_once_with_its_help():
    f = models.parameter_fields()
    assert {"A", "e_form", "volume_energy"} <= set(f)
    assert f["A"].default == 1.0 and f["volume_energy"].metadata["choices"] == ("quadratic", "squared")
    assert all(fl.metadata.get("help") for k, fl in f.items() if k in ("A", "e_form", "volume_energy"))
