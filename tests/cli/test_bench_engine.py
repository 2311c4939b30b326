"""``hybmss bench --model <engine>``: the engine's time per explicit step as a ratio to hybmss's on
the same cube, both static answers' wall times, the load average; one strict-JSON object with
``--json``; what the engine cannot represent refused before any work (exit 2, one line)."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys

import pytest

pytest.importorskip("mujoco")

HYBMSS = shutil.which("hybmss") or os.path.join(os.path.dirname(sys.executable), "hybmss")


def hybmss(*argv, timeout=600):
    env = dict(os.environ, MPLBACKEND="Agg", OMP_NUM_THREADS="1")
    return subprocess.run([HYBMSS, *argv], capture_output=True, text=True, env=env, timeout=timeout)


@pytest.mark.slow
def test_engine_bench_is_one_json_object_with_the_ratio():
    p = hybmss("bench", "--model", "mujoco-tet", "--quick", "--steps", "20", "--json")
    assert p.returncode == 0, p.stderr[-2000:]
    assert "Traceback" not in p.stderr and len(p.stderr.splitlines()) <= 1, p.stderr
    d = json.loads(p.stdout, parse_constant=lambda c: pytest.fail(f"non-strict JSON constant {c}"))
    assert d["model"] == "mujoco-tet" and d["mesh"] == "3x3x3" and d["nu"] == 0.25
    base, eng = d["explicit"]
    assert (base["model"], eng["model"]) == ("hybmss", "mujoco-tet") and base["steps"] == eng["steps"] == 20
    # the ratio is the two times per step measured in this run
    assert eng["ratio_to_hybmss"] == pytest.approx(eng["s_per_step"] / base["s_per_step"], rel=1e-12)
    assert d["step_ratio_to_hybmss"] == eng["ratio_to_hybmss"] and base["ratio_to_hybmss"] == 1.0
    # the engine's own calls are part of its step, which also sets the plates and the damping
    assert 0 < eng["engine_calls_s_per_step"] <= eng["s_per_step"]
    assert eng["device"] == "cpu" and eng["engine_version"]
    assert all(r["load_avg"] is None or r["load_avg"] >= 0 for r in d["explicit"] + d["static"])
    hyb, own = d["static"]
    assert own["solver"] == "mujoco-tet-rest" and own["steps_or_iterations"] > 0 and own["wall_time_s"] > 0
    assert d["static_ratio_to_hybmss"] == pytest.approx(own["wall_time_s"] / hyb["wall_time_s"], rel=1e-12)
    assert all(math.isfinite(r["s_per_step"]) for r in d["explicit"])


@pytest.mark.parametrize("argv, fragment", [
    (["--model", "newton-xpbd"], "shear modulus"),
    (["--model", "pbd-xpbd-fem", "--nu", "0.499"], "nu must lie in [0, 0.49]"),
    (["--model", "mujoco-tet", "--threads", "2"], "threads must be 1"),
    (["--model", "mujoco-tet", "--precision", "f32"], "precision must be f64"),
])
def test_engine_bench_refuses_what_the_engine_cannot_do(argv, fragment):
    if "newton" in argv[1]:
        pytest.importorskip("newton")
    if "pbd" in argv[1]:
        pytest.importorskip("pypbd")
    p = hybmss("bench", *argv, "--json", timeout=300)
    assert p.returncode == 2, (p.returncode, p.stderr[-2000:])
    lines = p.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hybmss: ") and fragment in lines[0], p.stderr
    assert "Traceback" not in p.stderr
