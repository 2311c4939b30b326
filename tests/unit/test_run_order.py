"""The order a sweep hands its runs to the workers (studies.sweep.runner.run_order): each model's
longest run first, then the others longest first."""

from types import SimpleNamespace

from studies.sweep.runner import SolverSpec, run_order


def _task(model: str, cost: float, kind: str = "static"):
    scene = SimpleNamespace(model=model, expected_cost=lambda solver, c=cost: c)
    solver = SolverSpec(kind) if kind != "fem" else SolverSpec("fem", element="hex2", law="linear")
    return (f"{model}-{kind}-{cost}", SimpleNamespace(scene=scene, solver=solver))


def test_each_models_longest_run_comes_first_then_longest_first():
    todo = [_task("a", 10.0), _task("a", 9.0), _task("b", 5.0), _task("c", 7.0), _task("c", 1.0),
            _task("a", 8.0, "explicit"), _task("hybmss", 6.0, "fem"), _task("hybmss", 0.5, "fem")]
    order = [k for k, _ in run_order(todo)]
    # a's explicit run shares a's kernels: it waits with the rest, not beside a's longest run
    assert order == ["a-static-10.0", "c-static-7.0", "hybmss-fem-6.0", "b-static-5.0",
                     "a-static-9.0", "a-explicit-8.0", "c-static-1.0", "hybmss-fem-0.5"]


def test_a_run_waits_while_the_first_run_of_its_code_compiles_unless_nothing_else_fits():
    from collections import deque

    from studies.sweep.runner import _code_of, next_fitting

    pending = deque([_task("xpbd-nh", 9.0, "explicit"), _task("xpbd-nh", 8.0), _task("b", 1.0)])
    warming = frozenset({_code_of(pending[0][1])})
    assert next_fitting(pending, [1.0], {}, 10.0, warming)[0] == "b-static-1.0"
    assert next_fitting(pending, [1.0], {}, 10.0, warming)[0] == "xpbd-nh-explicit-9.0"  # nothing else
    assert next_fitting(deque([_task("c", 2.0)]), [], {}, 10.0, warming)[0] == "c-static-2.0"


def test_a_sweep_holds_a_models_second_run_back_while_its_first_runs(tmp_path):
    """Two workers, a's two runs first in line: the second worker takes b's run instead of a's
    second while a's first is running (on a cold cache it would compile a's kernels twice)."""
    from studies.sweep.runner import Runner, Summary
    from studies.sweep.store import Store, code_version

    class Pool:
        shares_memory = False

        def __init__(self):
            self.running, self.log = [], []

        def capacity(self):
            return 2

        def submit(self, key, task):
            self.running.append(key)
            self.log.append(tuple(self.running))

        def wait_one(self):
            key = self.running.pop(0)
            return key, ({"status": "ok", "label": key, "env_code_version": code_version()}, None)

    todo = [_task("a", 9.0), _task("a", 8.0, "explicit"), _task("b", 1.0)]
    pool = Pool()
    bar = SimpleNamespace(update=lambda n: None, set_postfix_str=lambda *a, **k: None)
    Runner(jobs=2, progress=False)._sweep(pool, todo, Store(tmp_path), Summary(), bar, {}, {})
    assert pool.log[:2] == [("a-static-9.0",), ("a-static-9.0", "b-static-1.0")]
    assert {k for r in pool.log for k in r} == {k for k, _ in todo}
