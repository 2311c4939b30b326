"""A claim counted over runs counts each state once: a timing repeat of a run (another stored run
of the same scene, ``SolverSpec.repeat`` > 0, as the speed-against-error study makes near ties)
is not another case."""

from __future__ import annotations

from hybmss.experiments import SceneSpec
from studies.paper.claims import _incompressible_claims
from studies.paper.publications import published_models
from studies.paper.stored import StoredResults
from studies.sweep.runner import Runner, SolverSpec, Task, run_tasks
from studies.sweep.store import Store


def test_a_timing_repeat_is_not_another_case(tmp_path):
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.499, deformation=0.05, model="hybmss")
    tasks = [Task(spec, SolverSpec("static", repeat=k), "pareto") for k in range(3)]
    tasks.append(Task(spec.replace(deformation=0.2), SolverSpec("static"), "compression"))
    store = Store(tmp_path)
    rows = run_tasks(tasks, store, runner=Runner(jobs=1, progress=False))
    store.write_table("published_models", published_models())  # as the studies' tables do
    assert [r["status"] for r in rows] == ["ok"] * 4 and len({r["key"] for r in rows}) == 4  # four stored runs
    (claim,) = _incompressible_claims(StoredResults(tmp_path))
    assert claim.counted == 2, claim  # two states: 5 % (stored three times) and 20 %
