"""Bad and extreme invocations of the real ``hybmss`` command, each held to the contract.

exit 0: a result (``--json``: one strict JSON object); exit 2: input not allowed, one line on
stderr naming the parameter, its value and the allowed range, refused before any work; exit 3: a
valid simulation that failed, one line (and with ``--json`` one object with ``status`` and
``message``).  Never a traceback.

Every refused invocation is run through :func:`studies.cli.parser.main` (the ``hybmss`` console
script's entry point) in this process, in a working folder of its own, with stdout and stderr
captured; a representative subset (every subcommand and every kind of refusal) is run again
through the real ``hybmss`` script in a fresh interpreter.  The invocations that solve go through
the real script and use meshes of 2³ cells or fewer.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from studies.paper import reproduce

HYBMSS = str(Path(sys.executable).with_name("hybmss"))

INVOCATIONS: list[tuple] = []


def _reject_constant(name):
    raise ValueError(f"non-strict JSON constant {name}")


def hybmss(*argv, cwd=None, timeout=300):
    env = dict(os.environ, MPLBACKEND="Agg", OMP_NUM_THREADS="1")
    proc = subprocess.run([HYBMSS, *argv], capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout)
    INVOCATIONS.append((argv, proc.returncode))
    return proc


def check(proc, status: int, fragment: str | None = None):
    """The contract for one invocation; returns the JSON object printed, if any."""
    argv = proc.args[1:]
    assert proc.returncode == status, (argv, proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr and "Traceback" not in proc.stdout, (argv, proc.stderr)
    lines = proc.stderr.splitlines()
    if status == 0:
        assert len(lines) <= 1, (argv, proc.stderr)  # at most one note about the solvers' warnings
    else:
        assert len(lines) == 1, (argv, proc.stderr)
        assert lines[0].startswith("hybmss: "), lines
    if fragment is not None:
        assert fragment in proc.stderr, (argv, proc.stderr)
    obj = None
    if "--json" in argv and not (status == 0 and "--help" in argv):
        obj = json.loads(proc.stdout, parse_constant=_reject_constant)
        assert isinstance(obj, dict), proc.stdout[:200]
        if status == 0:
            assert obj["status"] == "ok"
        else:
            assert obj["status"] == ("invalid" if status == 2 else "failed")
            assert obj["message"] and "\n" not in obj["message"]
    return obj


# ------------------------------------------------------------------------ refused before any work
REFUSED = [
    # negative numbers are read as values, and refused by range
    (["compare", "compression", "--E", "-1e4"], "--E = -10000"),
    (["fem", "--E", "-1e4", "--json"], "allowed: (0, inf) Pa"),
    (["moduli", "--E", "-1", "--json"], "E (Young's modulus) must be > 0"),
    (["fem", "--mesh", "-1x2x2"], "--mesh"),
    (["compare", "torsion", "--mesh", "-2x2x2", "--json"], "got '-2x2x2'"),
    (["info", "--mesh", "0x2x2"], "--mesh"),
    (["fem", "--rho", "-1"], "--rho = -1"),
    (["compare", "compression", "--damping", "-1", "--solver", "explicit"], "--damping = -1"),
    (["compare", "compression", "--A", "-0.5"], "must be >= 0, got -0.5"),
    (["compare", "compression", "--model", "hybmss-fd", "--A", "2"], "A must be 0 for model hybmss-fd"),
    (["compare", "compression", "--model", "baudet2009", "--A", "2"], "model baudet2009 has no parameter 'A'"),
    (["moduli", "--volume-energy", "cubic", "--json"], "invalid choice: 'cubic'"),
    (["fem", "--le", "-0.5"], "--le = -0.5"),
    # nu outside (-1, 1/2) and other non-numbers
    (["compare", "compression", "--nu", "0.5", "--json"], "--nu = 0.5"),
    (["fem", "--nu", "-1"], "--nu = -1"),
    (["moduli", "--nu", "0.7"], "nu (Poisson ratio)"),
    (["compare", "compression", "--E", "abc"], "expected a number, got 'abc'"),
    (["compare", "compression", "--E", "nan", "--json"], "expected a finite number"),
    (["fem", "--deformation", "inf"], "expected a finite number"),
    (["moduli", "--strain", "0"], "strain=0"),
    (["moduli", "--strain", "-0.5", "--json"], "outside [1e-06, 0.01]"),
    (["moduli", "--nu", "-0.999999"], "outside [-0.99, 0.49999]"),
    (["compare", "compression", "--nu", "0.4999999", "--json"], "outside [-0.99, 0.49999]"),
    # compression by d >= 1 (the plate at or below the floor), negative compressions and tensions
    (["fem", "--deformation", "1.5"], "--deformation = 1.5"),
    (["fem", "--deformation", "5", "--json"], "allowed: [0, 1)"),
    (["compare", "compression", "-d", "1"], "--deformation = 1"),
    (["compare", "compression", "-d", "-0.1"], "allowed: [0, 1)"),
    (["fem", "--scene", "tension", "-d", "-0.2"], "allowed: [0, inf)"),
    # torsion by half a turn or more: theta and theta - 360 deg are the same plate position
    (["compare", "torsion", "--angle", "360", "--json"], "--angle-deg = 360"),
    (["fem", "--scene", "torsion", "--angle", "720"], "(-180, 180) degrees"),
    (["fem", "--scene", "torsion", "--angle-deg", "-180"], "--angle-deg = -180"),
    # options a scene or solver does not use are refused, not ignored
    (["compare", "compression", "--angle", "30"], "compression does not use it"),
    (["fem", "--scene", "torsion", "-d", "0.1", "--json"], "torsion does not use it"),
    (["compare", "bending", "--deformation", "0.1"], "bending does not use it"),
    (["compare", "shear", "--gravity", "9.81"], "--gravity = 9.81"),
    (["fem", "--model", "baudet2009"], "the fem solver does not use it"),
    (["fem", "--e-form", "--json"], "--e-form"),
    (["fem", "--damping", "2"], "--damping = 2"),
    (["compare", "compression", "--damping", "2"], "static and fem solvers do not use it"),
    (["compare", "compression", "--dt", "0.01"], "the static solver does not use it"),
    (["compare", "compression", "--steps", "100", "--json"], "--steps = 100"),
    (["fem", "--convergence", "1,2", "--refine", "2"], "--refine = 2 is not allowed with --convergence"),
    # one cell layer between two plates leaves nothing to solve
    # a solver kind the model does not support (its `solvers`)
    (["compare", "compression", "--mesh", "2x2x2", "--model", "corot-hex8", "--solver", "implicit"],
     "--solver = implicit is not allowed: model corot-hex8 does not support it; allowed: static, explicit"),
    (["compare", "compression", "--mesh", "2x2x2", "--model", "corot-hex8-sri", "--solver", "implicit", "--json"],
     "--solver = implicit is not allowed: model corot-hex8-sri"),
    (["compare", "compression", "--mesh", "2x2x2", "--model", "baudet2009", "--solver", "implicit"],
     "--solver = implicit is not allowed: model baudet2009"),
    (["compare", "compression", "--mesh", "2x2x2", "--model", "xpbd-nh", "--solver", "implicit"],
     "--solver = implicit is not allowed: model xpbd-nh"),
    (["compare", "compression", "--mesh", "1x1x1"], "--mesh = 1x1x1"),
    (["fem", "--scene", "shear", "--mesh", "3x3x1", "--json"], "NZ >= 2"),
    # size guard: memory estimated from mesh and refinement, refused with what it would need
    (["compare", "compression", "--mesh", "1000x1000x1000"], "would need about"),
    (["fem", "--mesh", "1000x1000x1000", "--json"], "TiB of memory"),
    (["fem", "--mesh", "200x200x200"], "--mesh 200x200x200 is too large"),
    (["fem", "--refine", "40"], "--refine 40 is too large"),
    (["compare", "torsion", "--refine", "100", "--json"], "allowed: up to"),
    (["fem", "--convergence", "1,2,40"], "--refine 40 is too large"),
    (["compare", "compression", "--mesh", "300x300x300", "--solver", "explicit"], "explicit run would need"),
    # stored scenes that are not scenes
    (["fem", "--scene-json", "/nonexistent/scene.json"], "cannot read it"),
    (["fem", "--scene-json", "{list}", "--json"], "it holds a JSON list"),
    (["fem", "--scene-json", "{empty}"], "missing key 'body'"),
    (["fem", "--scene-json", "{text}"], "not JSON"),
    (["fem", "--scene-json", "{list}", "--mesh", "2x2x2"], "--scene-json is not allowed with --mesh"),
    # run: folders, jobs, studies
    (["run", "--all", "--study", "bending"], "--all and --study bending together are not allowed"),
    (["run", "--jobs", "0"], "jobs 0 is not allowed"),
    (["run", "--jobs", "-1", "--study", "bending", "--json"], "jobs -1 is not allowed: an integer >= 1"),
    (["run", "--jobs", "two"], "expected an integer, got 'two'"),
    (["run", "--out", ""], "--out '' is not allowed"),
    (["run", "--out", "/dev/null"], "is a file"),
    (["run", "--out", "/dev/null/results"], "which is not a folder"),
    (["run", "--out", "{file}", "--study", "bending"], "is a file"),
    (["run", "--scheduler", "tcp://h:1"], "needs executor dask"),
    (["run", "--executor", "slurm"], "invalid choice: 'slurm'"),
    (["run", "--study", "nosuch"], "invalid choice: 'nosuch'"),
    # bench, info and the parser itself
    (["bench", "--steps", "0"], "--steps"),
    (["bench", "--steps", "-5", "--json"], "got '-5'"),
    (["info", "--scene", "cylinder"], "invalid choice: 'cylinder'"),
    (["info", "--mesh", "3x3"], "--mesh"),
    (["info", "--le", "0"], "--le = 0"),
    (["compare"], "compare needs an experiment (compression"),
    (["compare", "uniaxial"], "invalid choice: 'uniaxial'"),
    (["compare", "compression", "--element", "hex3"], "invalid choice: 'hex3'"),
    (["fem", "--law", "hooke", "--json"], "invalid choice: 'hooke'"),
    (["fem", "--refine", "0"], "--refine"),
    (["fem", "--convergence", "1"], "at least two distinct factors"),
    (["moduli", "--model", "nosuch"], "invalid choice: 'nosuch'"),
    (["compare", "compression", "--no-such-option"], "unrecognized arguments"),
    (["compare", "compression", "--E"], "expected one argument"),
    ([], "required: COMMAND"),
    (["nosuch"], "invalid choice: 'nosuch'"),
]


BY_THE_SCRIPT = [
    ["compare", "compression", "--E", "-1e4"],                  # a negative value, by range
    ["fem", "--E", "-1e4", "--json"],                           # the same with --json
    ["moduli", "--nu", "0.7"],                                  # the model's own check
    ["info", "--mesh", "0x2x2"],                                # a value type
    ["bench", "--steps", "-5", "--json"],                       # bench
    ["fem", "--mesh", "1000x1000x1000", "--json"],              # the size guard
    ["fem", "--scene-json", "{text}"],                          # a stored scene that is not one
    ["run", "--out", "{file}", "--study", "bending"],           # run: the results folder
    ["compare", "compression", "--no-such-option"],             # the parser itself
    [],                                                         # no command
]
"""The refusals run again through the real ``hybmss`` script (indices into :data:`REFUSED`)."""
SCRIPT_SUBSET = [[a for a, _ in REFUSED].index(argv) for argv in BY_THE_SCRIPT]


@pytest.fixture(scope="module")
def refusal_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    files = {"list": d / "list.json", "empty": d / "empty.json", "text": d / "text.json", "file": d / "afile"}
    files["list"].write_text("[]")
    files["empty"].write_text("{}")
    files["text"].write_text("not json {")
    files["file"].write_text("x")
    return d, files


def _argv(i, files):
    return [a.format(**files) if a.startswith("{") else a for a in REFUSED[i][0]]


@pytest.fixture(scope="module")
def refused_runs(refusal_files, cli_in_process):
    """Every refused invocation through ``studies.cli.parser.main`` in this process, each in its own
    empty working folder."""
    d, files = refusal_files
    runs = []
    for i in range(len(REFUSED)):
        cwd = d / f"cwd{i}"
        cwd.mkdir()
        proc = cli_in_process(*_argv(i, files), cwd=cwd)
        INVOCATIONS.append((REFUSED[i][0], proc.returncode))
        runs.append((proc, cwd))
    return runs


@pytest.fixture(scope="module")
def scripted_runs(refusal_files):
    """The subset :data:`SCRIPT_SUBSET` through the real ``hybmss`` script, four at a time (each is
    one interpreter start), each in its own empty working folder."""
    d, files = refusal_files

    def one(i):
        cwd = d / f"script{i}"
        cwd.mkdir()
        return hybmss(*_argv(i, files), cwd=cwd), cwd

    with ThreadPoolExecutor(max_workers=4) as pool:
        return dict(zip(SCRIPT_SUBSET, pool.map(one, SCRIPT_SUBSET)))


@pytest.mark.parametrize("i", range(len(REFUSED)), ids=[" ".join(a) or "(none)" for a, _ in REFUSED])
def test_refused_before_work(i, refused_runs):
    proc, cwd = refused_runs[i]
    check(proc, 2, REFUSED[i][1])
    assert list(cwd.iterdir()) == []  # nothing written: refused before any work


@pytest.mark.slow
@pytest.mark.parametrize("i", SCRIPT_SUBSET, ids=[" ".join(REFUSED[i][0]) or "(none)" for i in SCRIPT_SUBSET])
def test_refused_by_the_real_command(i, scripted_runs, refused_runs):
    proc, cwd = scripted_runs[i]
    check(proc, 2, REFUSED[i][1])
    assert list(cwd.iterdir()) == []
    inproc = refused_runs[i][0]  # the same refusal as through the entry point in this process
    assert (proc.stdout, proc.stderr) == (inproc.stdout, inproc.stderr)


def test_debug_shows_the_traceback():
    proc = hybmss("compare", "compression", "--E", "-1", "--debug")
    assert proc.returncode == 2
    assert "Traceback" in proc.stderr and proc.stderr.rstrip().splitlines()[-1].startswith("hybmss: error:")


def test_help_states_the_contract(cli_in_process, tmp_path):
    # the script once, the subcommands' help through its entry point in this process
    for argv in (["--help"], ["compare", "--help"], ["fem", "-h"]):
        proc = hybmss(*argv) if argv == ["--help"] else cli_in_process(*argv, cwd=tmp_path)
        check(proc, 0)
        assert "exit status and output" in proc.stdout and "strict JSON" in proc.stdout
    assert "allowed (-180, 180)" in " ".join(proc.stdout.split())  # ranges from the scene specification


# ------------------------------------------------------------------------ results (tiny solves)
CUBE, BEAM = "2x2x2", "1x1x2"
DIGEST_CASES = {
    "compression": ["--mesh", CUBE, "-d", "0.2"],
    "tension": ["--mesh", BEAM, "--deformation", "0.01", "--nu", "0.3"],
    "shear": ["--mesh", CUBE, "-d", "-0.03", "--E", "2e4"],
    "torsion": ["--mesh", CUBE, "--angle", "-30"],
    "bending": ["--mesh", BEAM, "--gravity", "-10", "--rho", "500"],
}


@pytest.mark.parametrize("experiment", [e if e == "compression" else pytest.param(e, marks=pytest.mark.slow)
                                        for e in DIGEST_CASES])
def test_fem_and_compare_solve_the_same_scene(experiment):
    args = DIGEST_CASES[experiment]
    fem = check(hybmss("fem", "--scene", experiment, *args, "--json"), 0)
    cmp = check(hybmss("compare", experiment, *args, "--json"), 0)
    assert fem["scene_digest"] == cmp["scene_digest"]
    assert fem["solver"] == cmp["fem"]["solver"]  # the same law and element by default
    if experiment in ("compression", "torsion", "bending"):  # 20 %, |-30 deg|, bending: finite strain
        assert fem["solver"].endswith("neo-hookean")
    else:  # |d| <= 5 %: linear, whatever the sign
        assert fem["solver"].endswith("linear")
    u = fem["max_displacement"]
    if experiment == "compression":
        assert u == pytest.approx(0.2 * 5.0)  # the top plate moves by d H
    if experiment == "shear":
        assert u == pytest.approx(0.03 * 5.0)


@pytest.mark.slow
def test_scene_json_solves_the_stored_scene(tmp_path):
    from studies.sweep.scenes import SceneSpec

    scene = SceneSpec.default("torsion", mesh=(2, 2, 2), angle_deg=2.0).build()
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene.to_dict()))
    out = check(hybmss("fem", "--scene-json", str(path), "--element", "hex1", "--json"), 0)
    assert out["scene_digest"] == scene.digest() and out["solver"] == "fem-hex1-linear"


@pytest.mark.slow
def test_fem_convergence_and_text_output():
    out = check(hybmss("fem", "--scene", "tension", "--mesh", "1x1x2", "--element", "hex1",
                       "--convergence", "1,2", "--json"), 0)
    assert out["refinements"] == [1, 2] and out["finest"]["solver"] == "fem-hex1-linear"
    proc = hybmss("compare", "bending", "--mesh", "1x1x1")  # one layer is fine with one plate
    check(proc, 0)
    assert "Euler-Bernoulli" in proc.stdout and "scene digest" in proc.stdout


def test_info_counts_without_building_arrays():
    out = check(hybmss("info", "--mesh", "1000x1000x1000", "--json"), 0)
    assert set(out) == {"status", "mesh", "le", "volumes", "vertices", "springs", "paper_springs_no_fd",
                        "paper_springs_with_fd"}
    assert set(out["springs"]) == {"edge", "face_diagonal", "inner_diagonal", "total"}
    n = 1000
    assert out["vertices"] == (n + 1) ** 3 and out["volumes"] == n**3
    assert out["springs"]["inner_diagonal"] == 4 * n**3


@pytest.mark.slow
def test_moduli_of_the_default_model():
    out = check(hybmss("moduli", "--nu", "0.3", "--json"), 0)
    # the calibration reproduces the input moduli exactly for every nu (README "Models")
    assert out["E_eff"] == pytest.approx(1e4, rel=1e-5) and out["nu_eff"] == pytest.approx(0.3, abs=1e-5)
    assert out["G_eff"] == pytest.approx(1e4 / 2.6, rel=1e-5)


def test_implicit_run_that_ends_before_rest_exits_3():
    # five steps of 1 ms end long before the 1 s load ramp does: not at rest, never converged
    out = check(hybmss("compare", "compression", "--mesh", CUBE, "--solver", "implicit", "--steps", "5",
                       "--json"), 3, "not at rest after 5 steps: raise --steps or --damping")
    assert out["status"] == "failed" and "load ramp is at s = " in out["message"]


def test_failed_simulation_exits_3():
    # an explicit step 25x above the stability limit diverges: valid input, failed simulation
    out = check(hybmss("compare", "compression", "--mesh", CUBE, "--solver", "explicit", "--dt", "20",
                       "--steps", "100", "--json"), 3)
    assert "diverged" in out["message"]


@pytest.mark.slow
def test_bench_quick():
    out = check(hybmss("bench", "--quick", "--steps", "10", "--json"), 0)
    assert {r["kernel"] for r in out["explicit"]} == {"numba", "numpy"} and out["static"]
    assert {r["mesh"] for r in out["explicit"] + out["static"]} == {"3x3x3"}  # a smoke run: the small cube


@pytest.mark.slow
def test_run_a_quick_study(tmp_path):
    out = check(hybmss("run", "--study", "bending", "--quick", "--jobs", "2", "--no-progress",
                       "--out", str(tmp_path / "res"), "--json"), 0)
    assert out["runs"] == out["computed"] == len(reproduce.STUDIES["bending"](quick=True)) and out["failed"] == 0
    again = check(hybmss("run", "--study", "bending", "--quick", "--no-progress", "--out", str(tmp_path / "res"),
                         "--json"), 0)  # resumed: every run stored
    assert again["runs"] == again["stored"] == out["runs"] and again["computed"] == 0


def test_invocation_count():
    """At least 60 bad or extreme invocations are held to the contract (counted when run in order)."""
    assert len(REFUSED) >= 60


# ------------------------------------------------------------------------ failures inside the work
def _raise_value_error(*args, **kwargs):
    raise ValueError("array must not contain infs or NaNs")  # as SciPy says it of a state it cannot take


@pytest.mark.parametrize("argv, module, name", [
    (["fem", "--mesh", CUBE, "--json"], "fem_reference.solve", "solve"),
    (["compare", "compression", "--mesh", CUBE, "--json"], "studies.cli.compare", "solve_scene"),
    (["modes", "compression", "--mesh", CUBE, "-k", "2", "--json"], "hybmss.modes", "lattice_modes"),
])
def test_a_value_error_inside_the_work_is_a_failed_simulation(argv, module, name, monkeypatch, cli_in_process,
                                                               tmp_path):
    # exit 2 is for input refused before any work; valid input whose solve raises is exit 3
    import importlib

    monkeypatch.setattr(importlib.import_module(module), name, _raise_value_error)
    out = check(cli_in_process(*argv, cwd=tmp_path), 3, "ValueError during the solve: array must not contain")
    assert out["status"] == "failed"
