"""A study's model run is timed once (studies.study.tasks._single: after an untimed run where the
process has not solved that model yet); a near tie's re-timing up to ``repeats`` times after an
untimed run, the timed runs stopped once they took TIMING_BUDGET_S together (_timed); the time
estimate of the study's checks (studies.study.checks) counts the same number (timed_repeats),
checked against a scripted clock."""

from types import SimpleNamespace

import pytest

from hybmss import timing
from studies.study import tasks


def scripted(monkeypatch, seconds: float, info: dict | None = None, modules=(timing, tasks)) -> list:
    """A scripted clock of ``seconds`` a solve (the clock of ``modules``: ``hybmss.timing``'s and
    the tasks' own) and a solve returning ``info``; returns the list of its calls."""
    clock = iter(k * seconds for k in range(100))
    fake = SimpleNamespace(perf_counter=lambda: next(clock))
    for module in modules:
        monkeypatch.setattr(module, "time", fake)
    calls = []

    def solve(scene, solver):
        calls.append(1)
        return SimpleNamespace(info=dict(info or {}))

    monkeypatch.setattr(tasks, "solve_scene", solve)
    return calls


@pytest.mark.parametrize("seconds", (0.5, 3.0, 4.0, 9.9, 10.0, 30.0))
def test_timed_runs_stop_at_the_budget_and_the_estimate_counts_them(monkeypatch, seconds):
    calls = scripted(monkeypatch, seconds, modules=(timing,))
    res = tasks._timed(None, None, repeats=5)
    timed = res.info["time_repeats"]
    assert len(calls) == 1 + timed  # the untimed run and the timed ones
    assert timed == tasks.timed_repeats(seconds, 5)
    expected = min(5, max(1, -(-tasks.TIMING_BUDGET_S // seconds)))  # k runs until k·seconds >= budget
    assert timed == expected and res.info["time_s"] == seconds


@pytest.mark.parametrize("seconds, info, again", [
    (30.0, {"compile_time_s": 0.02, "warm_up_s": 0.0}, False),  # an engine's long run: its own timing
    (30.0, {"compile_time_s": 0.5}, True),                      # compile 1.7 % of it: timed again
    (30.0, {"compile_time_s": 0.0, "warm_up_s": 0.4}, True),    # the loop's warm-up call 1.3 %
    (30.0, {}, True),                                           # one-time cost not reported (Numba)
    (9.0, {"compile_time_s": 0.0}, True),                       # short: timed runs for its spread
])
def test_a_long_first_run_with_a_negligible_reported_one_time_cost_is_its_own_timing(monkeypatch, seconds, info,
                                                                                      again):
    calls = scripted(monkeypatch, seconds, info)
    res = tasks._timed(None, None, repeats=5)
    assert (len(calls) > 1) == again
    assert res.info["time_first_run"] == (not again)
    assert res.info["time_s"] == seconds and res.info["time_repeats"] == (1 if not again else
                                                                           tasks.timed_repeats(seconds, 5))


@pytest.fixture
def cold(monkeypatch):
    """A process that has solved nothing yet (tasks.WARM empty), a scripted clock of 2 s a solve."""
    monkeypatch.setattr(tasks, "WARM", set())
    return scripted(monkeypatch, 2.0)


def scene_of(model: str):
    return SimpleNamespace(model=model)


def test_a_models_first_run_in_a_process_is_timed_again_later_runs_are_their_own_timing(cold):
    """The first solve of a (model, solver) pays its one-time costs and is not timed; every later
    run of the pair in the process is timed once, and so is another model's first run again."""
    static = SimpleNamespace(kind="static", kernel="numba")
    res = tasks._single(scene_of("hybmss"), static)
    assert len(cold) == 2 and res.info["time_first_run"] is False
    assert res.info["time_s"] == 2.0 and res.info["time_repeats"] == 1 and res.info["time_spread"] != res.info["time_spread"]
    res = tasks._single(scene_of("hybmss"), static)
    assert len(cold) == 3 and res.info["time_first_run"] is True and res.info["time_s"] == 2.0
    tasks._single(scene_of("corot-hex8"), static)
    assert len(cold) == 5
    tasks._single(scene_of("hybmss"), SimpleNamespace(kind="explicit", kernel="numba"))
    assert len(cold) == 7


def _budget(lead: float):
    import pandas as pd

    return pd.DataFrame([{"load_case": "press", "E": 1e4, "nu": 0.3, "rho": 1000.0, "answer": "fastest",
                          "method": "hybmss", "cell_size_m": 0.01, "runner_up": "corot-hex8",
                          "runner_up_cell_size_m": 0.02, "lead": lead}])


def _study_tasks():
    from hybmss import Body, Material, Model, Plate, Region, Scene
    from studies.sweep.runner import SolverSpec, Task

    out = []
    for le in (0.01, 0.02):
        body = Body.box(2, 2, 2, le=le)
        for model in ("hybmss", "corot-hex8"):
            scene = Scene(body=body, material=Material(E=1e4, nu=0.3, rho=1000.0), model=Model(model),
                          plates=(Plate("bottom", Region("z-")),))
            out.append(Task(tasks.StudyScene(scene, "s", "press", le, model, 3), SolverSpec("static"), "s"))
    return out


def test_near_ties_are_timed_again_and_only_once():
    """A lead within RETIME_NOISE asks for the re-timing of the winner at its cell size and of the
    runner-up at its own; a lead beyond it, or runs already re-timed, for none."""
    all_tasks = _study_tasks()
    again = tasks.near_ties(all_tasks, [_budget(1.0 + 0.9 * tasks.RETIME_NOISE)])
    assert sorted((t.scene.label, t.scene.cell_size) for t in again) == [("corot-hex8", 0.02), ("hybmss", 0.01)]
    assert all(t.scene.retime and t.scene.repeats == 3 for t in again)
    assert len({t.key() for t in again} | {t.key() for t in all_tasks}) == len(all_tasks) + 2  # keys of their own
    assert tasks.near_ties(all_tasks, [_budget(1.0 + 1.1 * tasks.RETIME_NOISE)]) == []
    assert tasks.near_ties(all_tasks, [_budget(1.1)], {t.key() for t in again}) == []


@pytest.mark.slow
def test_a_studys_near_tie_is_timed_again_and_decided_on_its_spreads(tmp_path, monkeypatch):
    """The same model under two labels ties (its two runs do the same work): the study times both
    again ``repeats`` times, and the budget answer reads the spreads of those timings.  Their single
    timings (milliseconds, on a machine the other tests load) may differ by more than the noise the
    study assumes: here any lead counts as near."""
    import math

    monkeypatch.setattr(tasks, "RETIME_NOISE", 1e6)

    from study_files import small_study, write
    from studies.study import Study
    from studies.sweep.store import Store

    doc = small_study()
    doc["study"]["repeats"] = 3
    doc["model"] = [{"name": "hybmss", "label": "a"}, {"name": "hybmss", "label": "b"}]
    study = Study.from_toml(write(doc, tmp_path / "tie.toml"))
    study.run(tmp_path / "out", jobs=1, progress=False)
    store = Store(tmp_path / "out")
    again = [t for t in study.tasks() if not tasks.is_reference(t)]
    rows = [store.row(tasks.near_ties(again, [_tie(study, tmp_path)])[i].key()) for i in range(2)]
    assert all(r["status"] == "ok" and r["info"]["time_repeats"] >= 2 for r in rows)
    budget = study.tables(tmp_path / "out")["budget_press"]
    win = budget[budget["answer"] == "fastest"].iloc[0]
    assert {win["method"], win["runner_up"]} == {"a", "b"}
    assert math.isfinite(win["spread"]) and math.isfinite(win["runner_up_spread"])
    best = {r["variant"]: r["info"]["time_s"] for r in rows}
    assert win["cost"] == best[win["method"]] and win["runner_up_cost"] == best[win["runner_up"]]


def _tie(study, tmp_path):
    """A budget answer of the study's two labels tied (lead 1)."""
    import pandas as pd

    m = study.materials[0]
    return pd.DataFrame([{"load_case": "press", "E": m.E, "nu": m.nu, "rho": m.rho, "answer": "fastest",
                          "method": "a", "cell_size_m": study.voxels[0].le, "runner_up": "b",
                          "runner_up_cell_size_m": study.voxels[0].le, "lead": 1.0}])


def test_a_cold_process_warms_up_on_the_coarsest_body_and_times_the_run_itself(monkeypatch):
    """A model's first run in a process with a warm-up scene (the same run on the coarsest body):
    the warm-up is solved untimed, the run itself once and timed; a warm-up that fails leaves the
    untimed first run and a timed second one."""
    monkeypatch.setattr(tasks, "WARM", set())
    clock = iter(k * 2.0 for k in range(100))
    monkeypatch.setattr(tasks, "time", SimpleNamespace(perf_counter=lambda: next(clock)))
    solved = []

    def solve(scene, solver):
        solved.append(scene.name)
        if scene.name == "bad":
            raise FloatingPointError("diverged")
        return SimpleNamespace(info={})

    monkeypatch.setattr(tasks, "solve_scene", solve)
    static = SimpleNamespace(kind="static", kernel="numba")
    fine = SimpleNamespace(model="hybmss", name="fine")
    res = tasks._single(fine, static, SimpleNamespace(model="hybmss", name="coarse"))
    assert solved == ["coarse", "fine"] and res.info["time_first_run"] is True and res.info["time_s"] == 2.0
    solved.clear()
    tasks._single(fine, static, SimpleNamespace(model="hybmss", name="coarse"))
    assert solved == ["fine"]  # warm: no warm-up
    solved.clear()
    res = tasks._single(SimpleNamespace(model="corot-hex8", name="fine"), static,
                        SimpleNamespace(model="corot-hex8", name="bad"))
    assert solved == ["bad", "fine", "fine"] and res.info["time_first_run"] is False


def test_the_finer_runs_of_a_study_warm_up_on_its_coarsest_body():
    """Each model run at a cell size finer than the coarsest holds the coarsest run's scene, which
    does not change its key."""
    from dataclasses import replace

    all_tasks = tasks.with_warm_ups(_study_tasks())
    warm = {(t.scene.label, t.scene.cell_size): t.scene.warm_up for t in all_tasks}
    assert warm[("hybmss", 0.02)] is None and warm[("corot-hex8", 0.02)] is None
    coarse = {t.scene.label: t.scene.scene for t in all_tasks if t.scene.cell_size == 0.02}
    assert warm[("hybmss", 0.01)] is coarse["hybmss"] and warm[("corot-hex8", 0.01)] is coarse["corot-hex8"]
    assert all(t.key() == replace(t, scene=replace(t.scene, warm_up=None)).key() for t in all_tasks)
