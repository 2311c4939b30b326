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
