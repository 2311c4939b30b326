"""The model registry and protocol (hybmss/models): every model declared once, listed by the
registry, validated on construction, and the only place that knows its own name."""

from __future__ import annotations

import ast
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

ROOT = Path(__file__).resolve().parents[2]
PUBLICATION_MODELS = ("hybmss", "hybmss-fd", "hybmss-cf", "baudet2009")
COMPETITORS = ("corot-hex8", "corot-hex8-sri", "xpbd-nh")
"""What a user would pick instead of an MSS (SPEC §10), listed after the publications' models."""
IN_TREE = PUBLICATION_MODELS + COMPETITORS


def test_in_tree_models_are_registered_in_order():
    assert models.names()[:len(IN_TREE)] == IN_TREE
    # a module or a folder per model (a family of variants in one folder: MODELS), none defined twice
    import importlib

    here = ROOT / "hybmss" / "models"
    places = sorted([p.stem for p in here.glob("*.py")] + [p.parent.name for p in here.glob("*/__init__.py")])
    places = [p for p in places if not p.startswith("_") and p != "base"]
    assert places == ["baudet2009", "corot_hex8", "hybmss", "hybmss_cf", "hybmss_fd", "mujoco", "newton", "pbd", "xpbd_nh"]
    declared = []
    for place in places:
        module = importlib.import_module(f"hybmss.models.{place}")
        declared += [m.name for m in getattr(module, "MODELS", None) or (module.MODEL,)]
    assert set(IN_TREE) <= set(declared) and len(declared) == len(set(declared))
    assert set(declared) <= set(models.names())


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

    def constants(self, p, material, le):
        c = hybrid_springs(material.G, 0.0, le, 0.0)
        return dataclasses.replace(c, kc=0.0)


def test_register_a_model_at_run_time():
    from studies.sweep import roles

    models.register(_Rods())
    try:
        # undeclared, it takes every study role its solvers allow (static only: no explicit rows)
        assert "test-rods" in models.names() and roles.in_role("tables")[-1] == "test-rods"
        assert "test-rods" in roles.in_role("regression") and "test-rods" not in roles.in_role("explicit-tables")
        assert roles.published("test-rods") == {} and roles.run_cost(
            SceneSpec.default("compression", model="test-rods", deformation=0.2), "static") == 16.0
        roles.declare("test-rods", roles.Part(roles=("tables",)))
        assert roles.in_role("tables")[-1] == "test-rods" and "test-rods" not in roles.in_role("regression")
        spec = SceneSpec.default("compression", mesh=(2, 2, 2), model="test-rods")
        S = build(spec.build())
        assert set(np.unique(S.spring_family)) == {0}  # edges only
        assert spec.to_dict()["variant"] == "test-rods"
        with pytest.raises(ValueError, match="already registered"):
            models.register(type("Other", (_Rods,), {})())
    finally:
        models.unregister("test-rods")
        roles.withdraw("test-rods")
    assert "test-rods" not in models.names()


def test_study_roles_publications_and_costs_are_the_studies_own():
    """The core declares no study role, publication name or run cost; the studies' table gives
    each in-tree model the roles it had, and a model's roles stop where its solvers do."""
    from studies.sweep import roles

    for path in (ROOT / "hybmss").rglob("*.py"):
        text = path.read_text()
        for word in ("STUDY_ROLES", "in_role", "takes_part", "run_cost", ".published", "published ="):
            assert word not in text, f"{path.relative_to(ROOT)} names {word}"
    everything = set(roles.STUDY_ROLES)
    want = {"hybmss": everything, "hybmss-fd": everything - {"b09"},
            "hybmss-cf": {"tables", "regression", "stability", "pareto", "performance"},
            "baudet2009": {"tables", "b09"}, "corot-hex8": everything - {"regression"},
            "corot-hex8-sri": everything - {"regression"}, "xpbd-nh": everything - {"regression"}}
    assert {m: {r for r in roles.STUDY_ROLES if roles.takes_part(m, r)} for m in IN_TREE} == want
    assert {m: roles.published(m) for m in PUBLICATION_MODELS} == {
        "hybmss": {"G20": "hybmss"}, "hybmss-fd": {"G20": "hybmss-fd"}, "hybmss-cf": {"G20": "hybmss-cf"},
        "baudet2009": {"B09": "baudet2009"}}
    assert all(roles.published(m) == {} for m in COMPETITORS)
    with pytest.raises(ValueError, match="study roles must be among tables"):
        roles.Part(roles=("tables", "paper"))
    with pytest.raises(ValueError, match="study role must be one of"):
        roles.in_role("paper")


def test_run_costs_order_a_sweep():
    """The default cost is (d / 5 %)² above 5 % for a static solve and 0.5 for the explicit
    protocol; hybmss-fd's static solves cost 16 times that, xpbd-nh's grow as its volumetric wave
    speed √(2(1 − ν)/(1 − 2ν)) (√3 at ν = 1/4)."""
    from studies.sweep import roles

    spec = SceneSpec.default("compression", deformation=0.2)
    assert roles.run_cost(spec, "static") == 16.0 and roles.run_cost(spec, "explicit") == 0.5
    assert roles.run_cost(spec.replace(deformation=0.05), "static") == 1.0
    assert roles.run_cost(spec.replace(model="hybmss-fd"), "static") == 256.0
    assert roles.run_cost(spec.replace(model="hybmss-fd"), "explicit") == 0.5
    x = spec.replace(model="xpbd-nh", nu=0.25)
    assert roles.run_cost(x, "explicit") == pytest.approx(8 * 3 ** 0.5)
    assert roles.run_cost(x, "static") == pytest.approx(2.5 * 3 ** 0.5)


def test_a_package_declares_its_models_part_through_an_entry_point(monkeypatch):
    """``[project.entry-points."hybmss.studies"] my-model = "mypkg:PART"``: the studies read it at
    their first look-up; an entry point that is not a Part is refused with its name."""
    import importlib.metadata

    from studies.sweep import roles

    class EP:
        def __init__(self, name, obj):
            self.name, self.value, self._obj = name, f"pkg:{name}", obj

        def load(self):
            return self._obj

    part = roles.Part(roles=("pareto",), published={"G20": "x"})
    monkeypatch.setattr(importlib.metadata, "entry_points",
                        lambda group: [EP("test-ep", part)] if group == roles.ENTRY_POINT_GROUP else [])
    parts = roles.Parts(roles.IN_TREE)
    assert parts.get("test-ep") is part and parts.get("hybmss") is roles.IN_TREE["hybmss"]
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: [EP("test-bad", {"roles": ()})])
    with pytest.raises(RuntimeError, match="study part 'test-bad'.*must be a studies.sweep.roles.Part"):
        roles.Parts({}).get("test-bad")


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


CHECKED = ("hybmss", "fem_reference", "studies", "benchmarks", "reports")
"""Everything that builds, solves, lists, studies, styles or reports models (a model's own module
in ``hybmss/models/`` excepted)."""
OWN_TABLES = ("studies/sweep/roles.py",)
"""The studies' one table of each model's part (roles, publication names, run cost): it names models."""
NOT_A_MODEL = {("studies/cli/parser.py", "hybmss"): "the command's name (prog), which is the project's",
               ("hybmss/_stencil_gen.py", "hybmss"): "the project's folder of the kernel cache"}
"""String literals that equal a model's name but do not name the model, with the reason."""


def _sources():
    for part in CHECKED:
        for path in sorted((ROOT / part).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if not rel.startswith("hybmss/models/") and rel not in OWN_TABLES:
                yield rel, path


def test_no_code_outside_a_model_module_compares_a_model_name():
    """Comparisons (==, !=, in) against a literal registered name, in the packages' code."""
    names = "|".join(re.escape(n) for n in models.names())
    pattern = re.compile(rf"""(==|!=|\bin)\s*\(?\s*["']({names})["']|["']({names})["']\s*(==|!=)""")
    hits = []
    for rel, path in _sources():
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line):
                hits.append(f"{rel}:{i}: {line.strip()}")
    assert hits == []


def _literals(tree: ast.AST):
    """(line, text) of every string constant of a module that is not a docstring."""
    docs = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                docs.add(id(first.value))
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs:
            yield node.lineno, node.value


def test_no_code_outside_a_model_module_names_a_model():
    """No string literal outside a model's module is a registered model's name, one of its
    methods ("<name> static", "<name> (E-form) explicit") or a published column of it
    ("paper <name>"): studies and reports take models from the registry, by study role or by
    their part in a publication (``published``, ``studies/data/*_models.csv``)."""
    names = "|".join(re.escape(n) for n in models.names())
    named = re.compile(rf"^(paper )?({names})( \([^)]*\))?( (static|explicit|implicit|mss-[a-z]+))?$")
    hits = []
    for rel, path in _sources():
        for line, text in _literals(ast.parse(path.read_text(), rel)):
            if named.match(text.strip()) and (rel, text) not in NOT_A_MODEL:
                hits.append(f"{rel}:{line}: {text!r}")
    assert hits == []


def test_the_name_check_finds_a_literal_model_name(tmp_path):
    """The check above can fail: it finds the names it looks for, and skips docstrings."""
    src = 'def f(df):\n    """hybmss"""\n    return df[df["method"] == "hybmss-fd static"], "paper hybmss", "hybmss-cf"\n'
    found = [t for _, t in _literals(ast.parse(src))]
    names = "|".join(re.escape(n) for n in models.names())
    named = re.compile(rf"^(paper )?({names})( \([^)]*\))?( (static|explicit|implicit|mss-[a-z]+))?$")
    assert sorted(t for t in found if named.match(t)) == ["hybmss-cf", "hybmss-fd static", "paper hybmss"]


def test_a_publication_names_its_models_through_their_declarations():
    """[G20]'s and [B09]'s tables name their models; each registered model that a publication
    reports declares that name (``published``), and the publication's data file of models
    gives its part in the claims."""
    from studies.paper import values as paper
    from studies.paper import publications

    t = publications.published_models()
    own = dict(zip(zip(t["publication"], t["role"]), t["model"]))
    assert own == {("G20", "proposed"): "hybmss", ("G20", "no-face-diagonals"): "hybmss-fd",
                   ("G20", "springs-only"): "hybmss-cf", ("B09", "proposed"): "baudet2009"}
    for pub, name in (("G20", "hybmss-fd"), ("B09", "baudet2009")):
        assert publications.model_named(pub, name) == name and publications.published_name(name, pub) == name
    # every published column of [G20]'s tables 2-5 is a declared name (or the FEM's)
    declared = set(t["name"])
    for table in ("g20_table2_compression", "g20_table3_tension", "g20_table4_shear", "g20_table5_torsion"):
        cols = set(paper.load(table).columns) - {"nu", "deformation", "angle_deg", "fem_lsdyna"}
        assert cols <= declared, table
    assert set(paper.load("b09_errors")["model"]) <= declared
    # a plug-in model that declares no publication is in none
    assert publications.model_named("G20", "test-nothing") is None


def test_the_default_model_comes_from_the_registry():
    assert models.default_name() == models.names()[0]
    assert Model().name == models.default_name() == SceneSpec.default("compression").model


def test_a_model_with_its_own_solvers_and_time_step_gets_the_scene():
    """``solve_static``, ``stepper`` and ``dt_crit`` of a model replace the harness's; the one
    explicit loop runs the model's stepper."""
    from hybmss.explicit import LatticeStepper, dt_crit, simulate_explicit
    from hybmss.solve import solve_static

    seen = []

    class Own(ModelBase):
        name = "test-own"
        solvers = ("static", "explicit")
        kernels = ("numpy",)

        def solve_static(self, scene, options=None, system=None):
            seen.append(("static", scene.model.name))
            return "static answer"

        def stepper(self, system, dt, **kw):
            seen.append(("explicit", dt, kw["kernel"]))
            return LatticeStepper(system, dt, **kw)

        def dt_crit(self, system):
            return 0.125

    models.register(Own())
    try:
        scene = SceneSpec.default("compression", mesh=(1, 1, 1), model="test-own").build()
        assert solve_static(scene) == "static answer"
        r = simulate_explicit(scene, dt=1e-3, steps=7, kernel="numpy")
        assert r.iterations == 7 and r.info["dt_crit"] == 0.125
        assert dt_crit(scene) == 0.125
        with pytest.raises(ValueError, match="no numba kernel"):
            simulate_explicit(scene, kernel="numba")
        assert seen == [("static", "test-own"), ("explicit", 1e-3, "numpy")]
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
