"""The budget study (studies.paper.pareto with studies.sweep.cost): its lead and ties from known timings, its
error measures against the FEM reference, and hybmss-cf near incompressibility."""

import re

import numpy as np
import pandas as pd
import pytest

from hybmss.experiments import SceneSpec
from studies.paper import pareto
from studies.sweep.runner import SolverSpec, Task, compute
from studies.sweep.store import Store

STATIC = SolverSpec("static")


def _row(t, status="ok", **kw):
    return {"status": status, "wall_time_s": t, **kw}


def test_budget_table_lead_and_ties_from_known_timings():
    """Three methods meet 5 % of field error in one configuration; their stored wall times:
    a: 1.0, 1.3, 1.2 s -> best 1.0, median 1.2, spread 0.2
    b: 1.15, 1.2, 1.6 s -> best 1.15, median 1.2, spread 0.05/1.15 = 0.043
    c: 3.0, 3.1, 3.0 s -> best 3.0, spread 0
    At 5 %: a leads b by 1.15 < 1 + 0.2: a tie.  At 2 % only b and c meet it: b leads c by
    3.0 / 1.15 = 2.61 > 1.043, no tie.  d (error 30 %) meets no budget."""
    samples = {"a": [1.0, 1.3, 1.2], "b": [1.15, 1.2, 1.6], "c": [3.0, 3.1, 3.0], "d": [0.1, 0.1, 0.1]}
    errors = {"a": 0.03, "b": 0.015, "c": 0.001, "d": 0.3}
    recs = []
    for m, ts in samples.items():
        t = pareto.timing_columns(STATIC, _row(ts[0]), [_row(x) for x in ts[1:]])
        recs.append({"config": "c1", "experiment": "shear", "nu": 0.25, "kind": "static", "method": m,
                     "mesh": "4x4x4", **t, "error_field": errors[m], "error_force": np.nan, "error_volume": np.nan})
    df = pd.DataFrame(recs)
    assert df.set_index("method").loc["b", "time_spread"] == pytest.approx(0.05 / 1.15)
    b = pareto.budget_table(df, budgets=(0.02, 0.05))
    assert set(b["cost_kind"]) == {"static"}
    # a measure no run has (no force error here): no method meets any budget
    force = b[b["measure"] == "force"]
    assert (force.loc[force["answer"] == "fastest", "method"] == "none within budget").all()
    b = b[b["measure"] == "field"]
    at = b[b["answer"] == "fastest"].set_index("budget")
    assert (at.loc[0.05, "method"], at.loc[0.05, "runner_up"]) == ("a", "b")
    assert at.loc[0.05, "lead"] == pytest.approx(1.15)
    assert at.loc[0.05, "spread"] == pytest.approx(0.2)
    assert bool(at.loc[0.05, "tie"]) is True  # 1.15 < 1 + max(0.2, 0.043)
    assert (at.loc[0.02, "method"], at.loc[0.02, "runner_up"]) == ("b", "c")
    assert at.loc[0.02, "lead"] == pytest.approx(3.0 / 1.15)
    assert bool(at.loc[0.02, "tie"]) is False
    assert list(b.loc[b["answer"] == "meets no budget", "method"]) == ["d"]


def test_budget_answers_kept_across_calls_follow_a_changed_time():
    """The driver keeps the budget answers of its earlier calls (``answers``): a call after repeats
    must answer anew where a time changed (b becomes the fastest at 5 %) and equal a fresh call
    everywhere, NaN errors included."""
    recs = [{"config": "c1", "experiment": "shear", "nu": 0.25, "kind": "static", "method": m, "mesh": "4x4x4",
             "time_s": t, "time_spread": 0.01, "error_field": e, "error_force": np.nan, "error_volume": np.nan,
             "failure": ""}
            for m, t, e in (("a", 1.0, 0.03), ("b", 1.5, 0.015), ("c", 3.0, 0.001))]
    df = pd.DataFrame(recs)
    answers = {}
    first = pareto.budget_table(df, budgets=(0.02, 0.05), answers=answers)
    pd.testing.assert_frame_equal(first, pareto.budget_table(df, budgets=(0.02, 0.05)))
    assert len(answers) == 3  # one per measure; a second call with the same rows adds none
    pd.testing.assert_frame_equal(pareto.budget_table(df, budgets=(0.02, 0.05), answers=answers), first)
    assert len(answers) == 3
    faster = df.assign(time_s=np.where(df["method"] == "b", 0.5, df["time_s"]))
    kept = pareto.budget_table(faster, budgets=(0.02, 0.05), answers=answers)
    pd.testing.assert_frame_equal(kept, pareto.budget_table(faster, budgets=(0.02, 0.05)))
    at = kept[(kept["measure"] == "field") & (kept["answer"] == "fastest")].set_index("budget")
    assert at.loc[0.05, "method"] == "b" and at.loc[0.05, "runner_up"] == "a"


def test_explicit_cost_at_the_stable_step_from_known_timings():
    """Three short runs of 100 steps took 2.0, 2.4, 2.2 ms: 20 µs per step at best, spread
    (22 − 20)/20 = 0.1; dt_crit = 4 ms -> dt = 2 ms -> 500 steps per simulated second = 10 ms."""
    proto = SolverSpec("explicit", dt=1e-3, steps=10_000)
    row = _row(0.3, dt_crit=4e-3, model="hybmss", steps=10_000)
    reps = [_row(t, status="not-converged", steps=100, model="hybmss") for t in (2.0e-3, 2.4e-3, 2.2e-3)]
    t = pareto.timing_columns(proto, row, reps)
    assert t["us_per_step"] == pytest.approx(20.0)
    assert t["step_spread"] == pytest.approx(0.1)
    assert t["dt_stable"] == pytest.approx(2e-3)
    assert t["cost_explicit_s"] == pytest.approx(0.01)
    # xpbd-nh has no explicit limit: its short runs took 2 substeps a step (10 µs a substep at
    # best); its frame of 2 ms (½ dt_crit) in 10 substeps is 5,000 substeps a second = 50 ms
    xp = [{**r, "model": "xpbd-nh", "info": {"substeps": 2}} for r in reps]
    t = pareto.timing_columns(proto, {**row, "model": "xpbd-nh", "dt_crit": None}, xp, frame=(4e-3, 2e-3, 10))
    assert t["us_per_step"] == pytest.approx(10.0)
    assert t["dt_stable"] == pytest.approx(2e-4) and t["cost_explicit_s"] == pytest.approx(0.05)
    assert np.isnan(pareto.timing_columns(proto, {**row, "model": "xpbd-nh"}, xp)["cost_explicit_s"])


def test_the_frame_of_a_model_without_explicit_limit():
    """xpbd-nh's frame ½ dt_crit = 1/ω_max takes ceil(1/0.1) = 10 substeps of its accuracy rule."""
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, model="xpbd-nh")
    dc, frame, substeps = pareto.unlimited_frame(spec)
    assert frame == pytest.approx(dc / 2) and substeps == 10


def test_frames_computed_on_the_session_workers_equal_those_computed_here():
    """:func:`pareto.unlimited_frames` (the session's workers) gives each xpbd-nh explicit
    candidate the frame :func:`pareto.unlimited_frame` computes in this process, and none to a
    model with an explicit limit or a static candidate; without a session's workers, none."""
    from studies.sweep.runner import Runner

    explicit = SolverSpec("explicit", dt=1e-3, steps=100)
    scenes = [SceneSpec.default("compression", mesh=(2, 2, 2), nu=nu, model="xpbd-nh") for nu in (0.0, 0.499)]
    scenes.append(SceneSpec.default("tension", mesh=(1, 1, 6), nu=0.25, model="xpbd-nh"))
    pairs = [({"role": "candidate"}, Task(s, explicit)) for s in scenes]
    pairs += [({"role": "candidate"}, Task(scenes[0], STATIC)), ({"role": "reference"}, Task(scenes[1], explicit)),
              ({"role": "candidate"}, Task(SceneSpec.default("compression", mesh=(2, 2, 2), model="hybmss"), explicit))]
    assert pareto.unlimited_frames(pairs) == {}
    with Runner("local", 2, progress=False) as runner:
        frames = pareto.unlimited_frames(pairs, runner)
    assert list(frames) == scenes
    for s in scenes:
        assert frames[s] == pareto.unlimited_frame(s)
    assert frames[scenes[0]][0] != frames[scenes[1]][0]  # each scene its own dt_crit


# ------------------------------------------------------------------------------ quick study at ν = 0.499
QUICK_0499 = dict(experiments=("compression",), nus=(0.499,))


@pytest.fixture(scope="module")
def incompressible_store(tmp_path_factory):
    store = Store(tmp_path_factory.mktemp("pareto-0.499"))
    return store, pareto.run(store, quick=True, jobs=2, progress=False, **QUICK_0499)


@pytest.fixture(scope="module")
def incompressible(incompressible_store):
    return incompressible_store[1]


@pytest.mark.slow
def test_errors_kept_across_calls_are_those_read_afresh(incompressible_store):
    """The driver keeps each run's errors across its calls (``measured``): a second call with them
    gives the table a call without them gives, every candidate its own errors."""
    from studies.sweep.runner import run_tasks

    store, tables = incompressible_store
    pairs = pareto.all_tasks(True, **QUICK_0499)
    rows = run_tasks([t for _, t in pairs], store, jobs=1, progress=False)
    measured = {}
    first, _ = pareto.pareto_frame(store, pairs, rows, True, measured=measured)
    again, _ = pareto.pareto_frame(store, pairs, rows, True, measured=measured)
    fresh, _ = pareto.pareto_frame(store, pairs, rows, True)
    pd.testing.assert_frame_equal(again, fresh)
    pd.testing.assert_frame_equal(first, fresh)
    assert fresh["error_field"].nunique() > 3


@pytest.mark.slow
def test_quick_pareto_has_force_volume_and_field_errors(incompressible):
    refs, df = incompressible["pareto_references"], incompressible["pareto"]
    (ref,) = refs.to_dict("records")
    assert ref["reference"].startswith("fem-") and ref["reference_status"] == "ok"
    assert ref["force_quantity"] == "force_z" and ref["force_reference"] < 0  # the top plate pushes down
    # near incompressibility the reference keeps its volume: |e*| within 1 % of the imposed 5 %
    assert abs(ref["volume_change_reference"]) < 0.01 * 0.05
    ok = df[df["status"] == "ok"]
    assert len(ok) == len(df) and ok["method"].str.startswith("fem-").any()
    for m in pareto.MEASURES:
        assert np.isfinite(ok[f"error_{m}"]).all(), m
    # repeats only where two candidates are within the timing noise: both then have a spread, and
    # every budget answer with a runner-up says whether it is a tie
    budget = incompressible["budget"]
    fast = budget[(budget["answer"] == "fastest") & (budget["runner_up"] != "")]
    close = fast[fast["lead"] < 1 + pareto.NOISE]
    assert np.isfinite(close[["spread", "runner_up_spread"]].astype(float)).all().all()
    assert fast["tie"].notna().all()
    assert np.isfinite(ok.loc[ok["kind"] == "explicit", "cost_explicit_s"]).all()
    # hybmss-cf keeps ν = ¼: bonded plates only add to the volume loss (1 − 2ν) d of a free
    # uniaxial compression, so its volume error is at least about ½ d
    cf = ok[ok["variant"] == "hybmss-cf"]
    assert (cf["error_volume"] > 0.45).all()
    budget = incompressible["budget"]
    assert set(budget["measure"]) == set(pareto.MEASURES)
    assert set(budget["cost_kind"]) == {"static", "explicit"}


@pytest.mark.slow
def test_hybmss_cf_does_not_win_a_force_budget_at_nu_0499(incompressible):
    """hybmss-cf has no volume energy: its springs give ν = ¼ whatever ν is asked, so its answer
    at ν = 0.499 is its answer at ν = ¼.  Its force error is then bounded below by the triangle
    inequality:

        |F_cf − F*| ≥ |F(¼) − F*| − |F_cf − F(¼)|,

    F* the reference at ν = 0.499, F(¼) the same FEM at ν = ¼ (both independent of the model),
    |F_cf − F(¼)| the lattice's own error at ν = ¼.  Between bonded plates a cube's lateral
    expansion is restrained near them, where the confined modulus (1 − ν)/((1 + ν)(1 − 2ν)) E
    acts (1.2 E at ¼, 167 E at 0.499): at fixed E the force grows with ν, by 16 % on this
    cube, and the lattice cannot follow.  The bound exceeds the largest budget (10 %)."""
    df = incompressible["pareto"]
    ref = incompressible["pareto_references"].iloc[0]
    spec = SceneSpec.default("compression", mesh=tuple(int(n) for n in ref["reference_mesh"].split("x")),
                             nu=0.25, deformation=0.05)
    f_quarter = compute(Task(spec, SolverSpec("fem", element="auto", law="linear")))[0]["force_z"]
    f_star = ref["force_reference"]
    cf = df[(df["variant"] == "hybmss-cf") & (df["kind"] == "static")]
    assert len(cf) == 2
    for r in cf.to_dict("records"):
        mesh = tuple(int(n) for n in r["mesh"].split("x"))
        quarter = compute(Task(spec.replace(model="hybmss-cf", mesh=mesh), STATIC))[0]["force_z"]
        assert quarter == pytest.approx(r["force_value"], rel=1e-9)  # ν is ignored
        bound = (abs(f_quarter - f_star) - abs(quarter - f_quarter)) / abs(f_star)
        assert bound > max(pareto.BUDGETS)
        assert r["error_force"] >= bound - 1e-12
    budget = incompressible["budget"]
    force = budget[(budget["measure"] == "force") & (budget["answer"] == "fastest")]
    assert len(force) == 2 * len(pareto.BUDGETS)
    assert not force["method"].str.startswith("hybmss-cf").any()
    assert not force["runner_up"].str.startswith("hybmss-cf").any()


def test_a_run_that_reached_no_result_neither_wins_nor_is_runner_up():
    """Four methods in one configuration.  'a' is the fastest (0.1 s) and its error (0.1 %) is the
    smallest, but its run is not at rest: whatever numbers its row holds, it is no candidate.
    So b (0.5 s, 2 %) wins 5 % and 10 % with c (2.0 s, 0.4 %) the runner-up, lead 2.0 / 0.5 = 4;
    at 1 % only c.  'a' is listed once as 'no result' with its reason, and so is 'd', whose run
    failed (no error at all); neither is listed as meeting no budget."""
    from studies.sweep import cost

    df = pd.DataFrame({
        "method": ["a", "b", "c", "d"], "mesh": "2x2x2",
        "error": [0.001, 0.02, 0.004, np.nan], "cost": [0.1, 0.5, 2.0, 0.05], "spread": [0.0, 0.01, 0.01, 0.0],
        "failure": ["not-converged: not at rest after 200 steps", "", None, "diverged: |v| > 1e6 m/s"]})
    ans = cost.budget_answer(df, (0.01, 0.05, 0.10), keep=("mesh",), failure="failure")
    fastest = ans[ans["answer"] == "fastest"].set_index("budget")
    assert list(fastest["method"]) == ["c", "b", "b"]
    assert "a" not in set(fastest["runner_up"]) and "d" not in set(fastest["runner_up"])
    assert list(fastest["runner_up"]) == ["", "c", "c"]
    assert fastest.loc[0.05, "lead"] == pytest.approx(4.0)
    assert (fastest["failure"] == "").all()
    none = ans[ans["answer"] == cost.NO_RESULT].set_index("method")
    assert set(none.index) == {"a", "d"}
    assert none.loc["a", "failure"].startswith("not-converged: not at rest")
    assert none[["error", "cost", "budget"]].isna().all().all()  # no number for a failure
    assert (ans["answer"] != cost.NO_BUDGET).all()
    # without the reasons the same table lets the run not at rest win every budget: the reason decides
    plain = cost.budget_answer(df, (0.01, 0.05, 0.10), keep=("mesh",))
    assert (plain.loc[plain["answer"] == "fastest", "method"] == "a").all()
    assert "failure" not in plain


@pytest.mark.slow
def test_a_candidate_not_at_rest_has_no_error_and_wins_nothing(tmp_path, monkeypatch):
    """The quick study with the explicit protocol cut at 200 steps of 1 ms: the load ramp takes
    1 s, so after 0.2 s the plates are at a fifth of their motion and no explicit run can be at
    rest (the first condition of the rest test).  Each explicit candidate then has no error and
    no time (NaN, also in the CSV), says why, is on no front, neither wins nor is runner-up in any
    budget, is listed as 'no result' and counted by the report's caption; the static candidates
    still answer (the test is not vacuous)."""
    import dataclasses

    from reports.study_figures import no_result_count
    from studies.sweep import cost

    monkeypatch.setattr(pareto, "PROTOCOL", dataclasses.replace(pareto.PROTOCOL, steps=200))
    monkeypatch.setattr(pareto, "pareto_models", lambda: ("hybmss", "hybmss-cf"))
    store = Store(tmp_path)
    t = pareto.run(store, quick=True, jobs=1, progress=False, experiments=("compression",))
    df = t["pareto"]
    ex = df[df["kind"] == "explicit"]
    assert len(ex) == 4  # two models on two meshes
    assert not ex["at_rest"].any()
    # not run: the ramp alone needs 1,000 steps (studies.sweep.rest_bound), said with the budget
    assert ex["failure"].str.fullmatch(r"not-converged: not at rest after 200 steps: not run, it needs at least "
                                       r"1000 steps .* and its budget is 200").all()
    for m in pareto.MEASURES:
        assert ex[f"error_{m}"].isna().all(), m
    assert ex["error_u"].isna().all() and ex["time_s"].isna().all() and not ex["pareto"].any()
    assert ex[list(pareto.NO_RESULT_COSTS)].isna().all().all()  # nor a cost: a cost of no result
    assert np.isfinite(ex["dt_crit"]).all()  # the lattice's limit is no result of the run
    static = df[df["kind"] == "static"]
    assert static["at_rest"].all() and (static["failure"] == "").all()
    assert np.isfinite(static["error_field"]).all() and static["pareto"].any()
    csv = pd.read_csv(tmp_path / "tables" / "pareto.csv")
    cut = csv[csv["kind"] == "explicit"]
    assert cut[[f"error_{m}" for m in pareto.MEASURES] + ["time_s"]].isna().all().all()
    budget = t["budget"]
    fastest = budget[budget["answer"] == "fastest"]
    named = set(fastest["method"]) | set(fastest["runner_up"])
    assert not named & set(ex["method"])
    assert (fastest.loc[fastest["cost_kind"] == "static", "method"] != cost.NONE_WITHIN).any()
    assert (fastest.loc[fastest["cost_kind"] == "explicit", "method"] == cost.NONE_WITHIN).all()
    none = budget[budget["answer"] == cost.NO_RESULT]
    for m in pareto.MEASURES:
        assert set(none.loc[(none["measure"] == m) & (none["cost_kind"] == "explicit"), "method"]) == set(ex["method"])
    assert none["failure"].str.contains("not at rest").all() and none["error"].isna().all()
    assert no_result_count(df) == (4, len(df))
    # the report of these tables: no number of a run without result, and the count said
    from test_reports import _visible_text, values_of_no_result

    from reports.build import build

    res = build(tmp_path, tmp_path / "report")
    assert values_of_no_result(res.tables) == []
    assert "table_pareto" in res.tables and "table_budget" in res.tables
    text = _visible_text(res.html.read_text(encoding="utf-8"))
    assert f"4 of {len(df)} candidate runs reached no result" in text
    assert not re.search(r"\bnan\b", text, re.I)
