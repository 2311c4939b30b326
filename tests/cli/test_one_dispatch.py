"""``hybmss compare`` and the study runner solve a scene through one dispatch
(:func:`studies.sweep.solving.solve_scene`): an engine's explicit run computes in the engine's own
precision in both (Newton's float32; in float64 the engine refuses the run), so the command and a
stored row of the same scene and solver are the same answer, bit for bit."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hybmss.experiments import SceneSpec
from studies.sweep.runner import SolverSpec, Task, compute

MESH, DAMPING, DT, STEPS, RAMP = (2, 2, 2), 5.0, 0.05, 400, 1.0
"""A damped 2³ compression cube that comes to rest within the steps (about 0.2 s of Newton's
stepping after Warp's start)."""


def test_compare_and_the_runner_run_an_engine_in_its_own_precision(cli_in_process, tmp_path):
    pytest.importorskip("newton")
    pytest.importorskip("warp")
    p = cli_in_process("compare", "compression", "--mesh", "x".join(map(str, MESH)), "--model", "newton-semi",
                       "--damping", DAMPING, "--solver", "explicit", "--dt", DT, "--steps", STEPS,
                       "--ramp-time", RAMP, "--fem", "hex1", "--json", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout)
    assert out["mss"]["converged"] and out["scene"]["model"] == "newton-semi"

    spec = SceneSpec.default("compression", mesh=MESH, model="newton-semi", damping=DAMPING)
    row, _ = compute(Task(spec, SolverSpec("explicit", dt=DT, steps=STEPS, ramp_time=RAMP, kernel="engine")))
    assert row["status"] == "ok", row.get("message")
    force = [row["force_x"], row["force_y"], row["force_z"]]
    assert out["mss"]["reaction_force"] == force
    assert out["mss"]["volume_change"] == row["volume_change"]
    # the plate force is a float32 sum: each component is a float32 number, and it compresses
    assert all(float(np.float32(f)) == f for f in force) and force[2] < 0
