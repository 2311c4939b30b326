"""A probe of the command line: invocations of every subcommand, each with the exit status it must
give and the parameter its refusal must name, run in this process (the ``cli_in_process``
fixture of tests/conftest.py) with and without ``--json``.  Every one must be clean: the expected status; for 2 and 3 exactly one
line on stderr (naming the parameter for 2); with ``--json`` exactly one strict-JSON object on
stdout whose status matches; never a traceback.  Fast cases only (meshes of a few cells)."""

from __future__ import annotations

import json

import pytest

from hybmss.experiments import SceneSpec

OK, INVALID, FAILED = 0, 2, 3
STATUS = {OK: "ok", INVALID: "invalid", FAILED: "failed"}

# (arguments, expected exit status, text the stderr line must contain: the parameter for 2)
CASES = [
    # ---------------------------------------------------------------- info
    ("info --mesh 2x2x2", OK, ""),
    ("info --scene torsion --mesh 3x3x3 --le 0.1", OK, ""),
    ("info --mesh 400x400x400", OK, ""),  # closed-form counts: no arrays, no guard needed
    ("info --mesh 0x1x1", INVALID, "--mesh"),
    ("info --mesh abc", INVALID, "--mesh"),
    ("info --mesh 2x2", INVALID, "--mesh"),
    ("info --mesh 2x2x2x2", INVALID, "--mesh"),
    ("info --mesh -2x2x2", INVALID, "--mesh"),
    ("info --le -1", INVALID, "--le"),
    ("info --le 0", INVALID, "--le"),
    ("info --le nan", INVALID, "--le"),
    ("info --le inf", INVALID, "--le"),
    ("info --le x", INVALID, "--le"),
    ("info --scene nope", INVALID, "--scene"),
    ("info --E 5", INVALID, "--E"),
    ("info --bogus", INVALID, "--bogus"),
    ("info --mesh", INVALID, "--mesh"),
    ("study /nonexistent/study.toml", INVALID, "FILE"),
    ("study", INVALID, "FILE"),
    ("study /nonexistent/study.toml --bogus", INVALID, "--bogus"),
    ("nope", INVALID, "nope"),
    ("", INVALID, "COMMAND"),
    # ---------------------------------------------------------------- moduli
    ("moduli --model hybmss --nu 0.3", OK, ""),
    ("moduli --model hybmss-cf --nu 0.45 --E 2e5", OK, ""),
    ("moduli --model hybmss --e-form --nu 0.45", OK, ""),
    ("moduli --model hybmss --e-form --nu -0.5", FAILED, "nu_eff"),  # ν_eff = 0.79: not a material
    ("moduli --model hybmss --e-form --nu -0.9", FAILED, "nu_eff"),
    ("moduli --nu 0.5", INVALID, "--nu"),
    ("moduli --nu -1", INVALID, "--nu"),
    ("moduli --nu 0.7", INVALID, "--nu"),
    ("moduli --nu nan", INVALID, "--nu"),
    ("moduli --E 0", INVALID, "--E"),
    ("moduli --E -1e4", INVALID, "--E"),
    ("moduli --E inf", INVALID, "--E"),
    ("moduli --rho -1", INVALID, "--rho"),
    ("moduli --strain 0", INVALID, "strain"),
    ("moduli --strain 0.5", INVALID, "strain"),
    ("moduli --strain nan", INVALID, "--strain"),
    ("moduli --strain -1e-4", INVALID, "strain"),
    ("moduli --model nope", INVALID, "--model"),
    ("moduli --A -1", INVALID, "A"),
    ("moduli --model baudet2009 --A 1", INVALID, "A"),
    ("moduli --volume-energy cubic", INVALID, "--volume-energy"),
    ("moduli --e-form yes", INVALID, "yes"),
    ("moduli --model xpbd-nh --iterations 1e9", INVALID, "--iterations"),  # the time guard: days
    ("moduli --model xpbd-nh --iterations 0", INVALID, "iterations"),
    ("moduli --model xpbd-nh --iterations 1.5", INVALID, "iterations"),
    ("moduli --model xpbd-nh --substeps -1", INVALID, "substeps"),
    ("moduli --model hybmss --substeps 3", INVALID, "substeps"),
    ("moduli --mesh 2x2x2", INVALID, "--mesh"),
    # ---------------------------------------------------------------- bench
    ("bench --mesh 400x400x400", INVALID, "--mesh"),  # 120 GiB
    ("bench --mesh 400x400x400 --steps 10", INVALID, "--mesh"),
    ("bench --mesh 200x200x200", INVALID, "--mesh"),  # ~160 GiB: 21 kB a particle, measured
    ("bench --steps 1000000000", INVALID, "--steps"),  # days
    ("bench --mesh 10x10x10 --steps 1000000000", INVALID, "--steps"),
    ("bench --steps 0", INVALID, "--steps"),
    ("bench --steps 1e3", INVALID, "--steps"),
    ("bench --threads 0", INVALID, "--threads"),
    ("bench --precision f16", INVALID, "--precision"),
    ("bench --model nope", INVALID, "--model"),
    ("bench --nu 0.5", INVALID, "--nu"),
    ("bench --mesh 0x0x0", INVALID, "--mesh"),
    ("bench --E 1e4", INVALID, "--E"),
    # ---------------------------------------------------------------- fem
    ("fem --mesh 2x2x2 --element hex1", OK, ""),
    ("fem --scene tension --mesh 2x2x2 --element hex1", OK, ""),
    ("fem --scene compression --mesh 2x2x2 --element hex1 --law svk --deformation 0.3", OK, ""),
    ("fem --scene-json {ok}", OK, ""),
    ("fem --refine 0", INVALID, "--refine"),
    ("fem --refine 1.5", INVALID, "--refine"),
    ("fem --convergence 1", INVALID, "--convergence"),
    ("fem --convergence 1,1", INVALID, "--convergence"),
    ("fem --convergence 0,1", INVALID, "--convergence"),
    ("fem --refine 2 --convergence 1,2", INVALID, "--refine"),
    ("fem --law nope", INVALID, "--law"),
    ("fem --element nope", INVALID, "--element"),
    ("fem --mesh 1000x1000x1000", INVALID, "--mesh"),
    ("fem --mesh 10x10x10 --refine 3 --law neo-hookean", INVALID, "--refine"),  # over an hour
    ("fem --mesh 2x2x2 --convergence 1,2,100", INVALID, "--refine 100"),
    ("fem --deformation 1", INVALID, "--deformation"),
    ("fem --deformation -0.1", INVALID, "--deformation"),
    ("fem --deformation nan", INVALID, "--deformation"),
    ("fem --angle-deg 10", INVALID, "--angle-deg"),
    ("fem --scene torsion --angle-deg 180", INVALID, "--angle-deg"),
    ("fem --scene torsion --angle-deg -180", INVALID, "--angle-deg"),
    ("fem --model hybmss", INVALID, "--model"),
    ("fem --A 2", INVALID, "--A"),
    ("fem --load-steps 0", INVALID, "--load-steps"),
    ("fem --linear-solver nope", INVALID, "--linear-solver"),
    ("fem --dt 0.1", INVALID, "--dt"),
    ("fem --nu 0.5", INVALID, "--nu"),
    ("fem --E 0", INVALID, "--E"),
    ("fem --gravity 1", INVALID, "--gravity"),
    ("fem --scene nope", INVALID, "--scene"),
    ("fem --scene-json {missing}", INVALID, "--scene-json"),
    ("fem --scene-json {not_json}", INVALID, "--scene-json"),
    ("fem --scene-json {empty}", INVALID, "--scene-json"),
    ("fem --scene-json {binary}", INVALID, "--scene-json"),
    ("fem --scene-json {nan}", INVALID, "--scene-json"),
    ("fem --scene-json {a_list}", INVALID, "--scene-json"),
    ("fem --scene-json {nested}", INVALID, "--scene-json"),
    ("fem --scene-json {nested_object}", INVALID, "--scene-json"),
    ("fem --scene-json {cross}", INVALID, "--scene-json"),
    ("fem --scene-json {touch}", INVALID, "--scene-json"),
    ("fem --scene-json {string_E}", INVALID, "--scene-json"),
    ("fem --scene-json {bool_damping}", INVALID, "--scene-json"),
    ("fem --scene-json {deep_value}", INVALID, "--scene-json"),
    ("fem --scene-json {unknown_field}", INVALID, "--scene-json"),
    ("fem --scene-json {no_material}", INVALID, "--scene-json"),
    ("fem --scene-json {bad_nu}", INVALID, "--scene-json"),
    ("fem --scene-json {bad_shape}", INVALID, "--scene-json"),
    ("fem --scene-json {bad_motion}", INVALID, "--scene-json"),
    ("fem --scene-json {plates_object}", INVALID, "--scene-json"),
    ("fem --scene-json {ok} --E 5", INVALID, "--scene-json"),
    ("fem --scene-json {ok} --scene torsion", INVALID, "--scene-json"),
    ("fem --scene-json {huge}", INVALID, "--mesh"),
    # ---------------------------------------------------------------- compare
    ("compare compression --mesh 2x2x2 --element hex1", OK, ""),
    ("compare tension --mesh 2x2x2 --element hex1 --model hybmss-cf", OK, ""),
    ("compare nope", INVALID, "scene"),
    ("compare", INVALID, "scene"),
    ("compare compression --dt 0.1", INVALID, "--dt"),
    ("compare compression --steps 10", INVALID, "--steps"),
    ("compare compression --ramp-time 1", INVALID, "--ramp-time"),
    ("compare compression --solver explicit --steps 1000000000", INVALID, "--steps"),
    ("compare compression --solver implicit --steps 1000000000", INVALID, "--steps"),
    ("compare compression --solver explicit --dt 0", INVALID, "--dt"),
    ("compare compression --solver explicit --steps 0", INVALID, "--steps"),
    ("compare compression --solver explicit --ramp-time -1", INVALID, "--ramp-time"),
    ("compare compression --solver nope", INVALID, "--solver"),
    ("compare compression --model xpbd-nh --solver explicit --iterations 1000000", INVALID, "--iterations"),
    ("compare compression --model xpbd-nh --solver explicit --substeps 1000000000000", INVALID, "--substeps"),
    ("compare torsion --angle-deg 180", INVALID, "--angle-deg"),
    ("compare torsion --angle-deg nan", INVALID, "--angle-deg"),
    ("compare compression --nu 0.5", INVALID, "--nu"),
    ("compare compression --deformation 1.2", INVALID, "--deformation"),
    ("compare compression --mesh 1000x1000x1000", INVALID, "--mesh"),
    ("compare compression --mesh 2x2x1", INVALID, "--mesh"),
    ("compare compression --refine 0", INVALID, "--refine"),
    ("compare compression --model baudet2009 --A 2", INVALID, "--A"),
    ("compare compression --element hex3", INVALID, "--element"),
    ("compare compression --angle-deg 5", INVALID, "--angle-deg"),
    ("compare compression --damping -1", INVALID, "--damping"),
    # ---------------------------------------------------------------- modes
    ("modes bending --mesh 1x1x4 -k 3", OK, ""),
    ("modes compression --mesh 2x2x2 --model corot-hex8 -k 2 --element hex1 --mass lumped", OK, ""),
    ("modes", INVALID, "scene"),
    ("modes bending -k 0", INVALID, "-k"),
    ("modes bending -k 101", INVALID, "-k"),
    ("modes bending -k x", INVALID, "-k"),
    ("modes bending --mesh 1x1x2 -k 24", INVALID, "-k"),
    ("modes bending --model xpbd-nh", INVALID, "--model"),
    ("modes bending --model newton-semi", INVALID, "--model"),
    ("modes bending --element mixed --nu 0", INVALID, "--element"),
    ("modes bending --mass nope", INVALID, "--mass"),
    ("modes bending --refine 0", INVALID, "--refine"),
    ("modes bending --nu 0.5", INVALID, "--nu"),
    # ---------------------------------------------------------------- run
    ("run --all --study compression", INVALID, "--all"),
    ("run --out ''", INVALID, "--out"),
    ("run --out {afile}", INVALID, "out"),
    ("run --out {afile}/sub", INVALID, "out"),
    ("run --jobs 0", INVALID, "--jobs"),
    ("run --jobs x", INVALID, "--jobs"),
    ("run --jobs -2", INVALID, "--jobs"),
    ("run --executor nope", INVALID, "--executor"),
    ("run --study nope", INVALID, "--study"),
    ("run --scheduler tcp://h:1", INVALID, "--scheduler"),
    ("run --quick --mesh 2x2x2", INVALID, "--mesh"),
]


def scene_files(root) -> dict[str, str]:
    """Scene files, one sound and the others each wrong in one way, by name."""
    good = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.3).build().to_dict()
    good = json.loads(json.dumps(good))
    H = good["body"]["shape"][2] * good["body"]["le"]

    def edited(change):
        d = json.loads(json.dumps(good))
        change(d)
        return json.dumps(d)

    def top(d, dz):
        for p in d["plates"]:
            if p["motion"]["kind"] == "translate":
                p["motion"]["displacement"] = [0.0, 0.0, dz]

    texts = {
        "ok": json.dumps(good),
        "not_json": "{not json",
        "empty": "",
        "nan": json.dumps(good).replace('"damping": 0.0', '"damping": NaN'),
        "a_list": "[1, 2, 3]",
        "nested": "[" * 100_000 + "]" * 100_000,
        "nested_object": '{"body": ' * 5_000 + "1" + "}" * 5_000,
        "cross": edited(lambda d: top(d, -1.2 * H)),  # 120 % compression: through the floor
        "touch": edited(lambda d: top(d, -1.0 * H)),
        "string_E": edited(lambda d: d["material"].update(E="1e4")),
        "bool_damping": edited(lambda d: d.update(damping=True)),
        "deep_value": edited(lambda d: d["material"].update(E=[[[[[1.0]]]]])),
        "unknown_field": edited(lambda d: d.update(colour="red")),
        "no_material": edited(lambda d: d.pop("material")),
        "bad_nu": edited(lambda d: d["material"].update(nu=0.5)),
        "bad_shape": edited(lambda d: d["body"].update(shape=[2, 0, 2])),
        "bad_motion": edited(lambda d: d["plates"][1]["motion"].update(kind="teleport")),
        "plates_object": edited(lambda d: d.update(plates={"top": 1})),
        "huge": edited(lambda d: d["body"].update(shape=[1000, 1000, 1000])),
    }
    paths = {}
    for name, text in texts.items():
        (root / f"{name}.json").write_text(text)
        paths[name] = str(root / f"{name}.json")
    (root / "binary.json").write_bytes(b"\xff\xfe\x00garbage")
    paths["binary"] = str(root / "binary.json")
    paths["missing"] = str(root / "missing.json")
    (root / "afile").write_text("x")
    paths["afile"] = str(root / "afile")
    return paths


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return scene_files(tmp_path_factory.mktemp("probe"))


def _argv(text: str, files: dict) -> list[str]:
    import shlex

    return [a.format(**files) for a in shlex.split(text)]


def _strict(name):
    raise ValueError(f"{name} in JSON output")


@pytest.mark.parametrize("as_json", [False, True], ids=["text", "json"])
@pytest.mark.parametrize("text, status, names", CASES, ids=[c[0] or "(none)" for c in CASES])
def test_probe(text, status, names, as_json, files, tmp_path, cli_in_process):
    run_cli = cli_in_process
    argv = _argv(text, files) + (["--json"] if as_json else [])
    res = run_cli(*argv, cwd=tmp_path)
    assert "Traceback" not in res.stderr + res.stdout, res.stderr
    assert res.returncode == status, (res.returncode, res.stderr[-600:])
    if status != OK:
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1, res.stderr
        assert names in lines[0], lines[0]
    if as_json:
        lines = res.stdout.strip().splitlines()
        assert len(lines) == 1, res.stdout
        obj = json.loads(lines[0], parse_constant=_strict)
        assert isinstance(obj, dict) and obj["status"] == STATUS[status]
        if status != OK:
            assert obj["message"] and obj["message"] in res.stderr
    elif status == OK:
        assert res.stdout.strip()


def test_the_probe_covers_every_subcommand_and_status():
    from studies.cli.parser import build_parser

    parser, _ = build_parser()
    commands = set(parser._subparsers._group_actions[0].choices)
    first = {c[0].split()[0] for c in CASES if c[0]}
    assert commands <= first, commands - first
    assert {c[1] for c in CASES} == {OK, INVALID, FAILED}
    assert 2 * len(CASES) >= 200
