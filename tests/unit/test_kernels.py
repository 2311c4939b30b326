"""The Numba stencil kernel and the NumPy twin give the same trajectory.

Both evaluate the same forces (same formulas, different summation order), so after one step
they differ by a few ulps; a stable scheme carries such a perturbation over 100 steps with at
most polynomial growth, i.e. to ~1e-13 relative.  1e-10 relative to the largest displacement
leaves three orders of margin and still catches any wrong term (a missing factor or sign changes
the trajectory at the 1e-3 level or more after 100 steps).  A model that takes several substeps
per step (xpbd-nh) is compared over 100 substeps: 100 updates of the state, as for the others.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hybmss import Body, Material, Model, Motion, Plate, Region, Scene
from hybmss._stencil_gen import BLOCK, LOOP1_SHARE, Config, instruction_mix, layout, thread_ranges
from hybmss.explicit import dt_crit, simulate_explicit, stencil
from hybmss import models
from hybmss.scene import Load
from hybmss.system import build

RTOL = 1e-10
STEPS = 100


def _scene(model="hybmss", nu=0.3, body=None, plates="compress", E=1e4, **kw):
    body = body or Body.box(3, 3, 4, 0.5)
    H = body.size[2]
    top_motion = {
        "compress": Motion("translate", (0.0, 0.0, -0.1 * H)),
        "rotate": Motion("rotate", angle=0.4, axis=(0.0, 0.0, 1.0), displacement=(0.0, 0.0, -0.05 * H)),
        "slide": Motion("slide", (0.02, 0.0, -0.1 * H), components=(2,)),
        "affine": Motion("affine", gradient=(0, 0, 0.1, 0, 0, 0, 0, 0, -0.05)),
    }
    if plates is None:
        ps = ()
    elif plates == "clamped":
        ps = (Plate("bottom", Region("z-")),)
    else:
        ps = (Plate("bottom", Region("z-")), Plate("top", Region("z+"), top_motion[plates]))
    return Scene(body, Material(E, nu, 1000.0), Model(model, **kw.pop("model_kw", {})), plates=ps, **kw)


def _l_shape():
    mask = np.ones((4, 2, 4), dtype=bool)
    mask[2:, :, 2:] = False
    return Body.from_mask(mask, 0.5)


CASES = {
    "hybmss": _scene("hybmss", 0.3),
    "hybmss-nu0.499": _scene("hybmss", 0.499),
    "hybmss-negative-kappa": _scene("hybmss", 0.0),
    "hybmss-fd": _scene("hybmss-fd", 0.45),
    "hybmss-cf": _scene("hybmss-cf", 0.3),
    "squared-volume-energy": _scene("hybmss", 0.4, model_kw={"volume_energy": "squared"}),
    "A=3": _scene("hybmss", 0.3, model_kw={"A": 3.0}),
    # E such that ρ g H / E = 2 %: a hanging body, not a collapsing one
    "gravity": _scene("hybmss", 0.3, plates="clamped", E=1e6, gravity=(0.0, -3.0, -10.0)),
    "l-shape": _scene("hybmss", 0.35, body=_l_shape()),
    "rotating-plate": _scene("hybmss", 0.3, plates="rotate"),
    "sliding-plate": _scene("hybmss", 0.3, plates="slide"),
    "affine-plate": _scene("hybmss", 0.3, plates="affine"),
    "damping": _scene("hybmss", 0.3, damping=3.0),
    "free-floating": _scene("hybmss", 0.3, plates=None),
    "baudet2009": _scene("baudet2009", 0.35),
    "baudet2009-l-shape-dead-load": _scene("baudet2009", 0.3, body=_l_shape(), plates="clamped",
                                           loads=(Load(Region("x+"), (0.0, 0.0, -50.0)),)),
    # one cell across: grid offsets that share a flat offset ((1, -1, k) and (0, 1, k); (0, 0, 1)
    # and (0, 1, -1)) share one row of partial sums
    "thin-beam": _scene("hybmss", 0.3, body=Body.box(1, 1, 5, 0.5)),
    "thin-plate": _scene("hybmss-fd", 0.45, body=Body.box(3, 2, 1, 0.5), plates="slide"),
    "dead-load": _scene("hybmss", 0.3, plates="clamped", loads=(Load(Region("x+"), (0.0, 0.0, -50.0)),)),
}
CASES.update({f"model-{m}": _scene(m, 0.3) for m in models.names() if models.get(m).supports("explicit", "numba")})


def _initial(system, seed):
    rng = np.random.default_rng(seed)
    le = system.scene.body.le
    x0 = system.X + 0.02 * le * rng.standard_normal(system.X.shape)
    v0 = 0.01 * rng.standard_normal(system.X.shape)
    return x0, v0


def _run_both(scene, threads=1, seed=0):
    system = build(scene)
    dc = dt_crit(system)
    dt = 0.5 * dc
    x0, v0 = _initial(system, seed)
    kw = dict(dt=dt, ramp_time=30 * dt, system=system, x0=x0, v0=v0, dt_crit_value=dc)
    substeps = simulate_explicit(scene, kernel="numba", threads=threads, steps=1, **kw).info.get("substeps", 1)
    kw["steps"] = max(1, STEPS // substeps)  # STEPS updates of the state
    r_nb = simulate_explicit(scene, kernel="numba", threads=threads, **kw)
    r_np = simulate_explicit(scene, kernel="numpy", **kw)
    return r_nb, r_np


def _assert_same(r_nb, r_np):
    scale = np.abs(r_np.u).max()
    assert scale > 0
    err = np.abs(r_nb.u - r_np.u).max() / scale
    assert err <= RTOL, f"numba vs numpy: relative difference {err:.3g} > {RTOL}"
    assert r_nb.volume == pytest.approx(r_np.volume, rel=RTOL)
    ke = max(r_np.energy["kinetic"], 1e-300)
    assert abs(r_nb.energy["kinetic"] - r_np.energy["kinetic"]) <= 1e-9 * ke


@pytest.mark.parametrize("name", [c if c == "hybmss" else pytest.param(c, marks=pytest.mark.slow) for c in CASES])
def test_numba_and_numpy_give_the_same_trajectory(name):
    r_nb, r_np = _run_both(CASES[name])
    _assert_same(r_nb, r_np)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["gravity-rotate", "l-shape", "baudet2009"])
def test_two_threads_give_the_same_trajectory(name):
    """Each thread recomputes the halo below its node range: the arithmetic per node is the same
    as on one thread, so the trajectories agree bit for bit."""
    scene = {"gravity-rotate": _scene("hybmss", 0.3, body=Body.box(4, 3, 5, 0.5), plates="rotate",
                                      E=1e6, gravity=(0, 0, -10)),
             "l-shape": CASES["l-shape"], "baudet2009": CASES["baudet2009"]}[name]
    r2, r_np = _run_both(scene, threads=2)
    _assert_same(r2, r_np)
    r1, _ = _run_both(scene, threads=1)
    assert np.array_equal(r1.u, r2.u)


@pytest.mark.parametrize("shape, threads", [((11, 11, 11), 2), ((31, 31, 31), 2), ((5, 5, 25), 2),
                                            ((9, 9, 49), 3), ((21, 21, 21), 4), ((3, 3, 3), 2)])
def test_thread_ranges_tile_the_blocks_with_equal_work(shape, threads):
    """The threads' block ranges tile the blocks in order; each halo reaches every base whose
    partial sums land in the thread's nodes (``H = s0 + s1 + 1`` nodes below its first); the
    work of a thread with blocks, its blocks plus LOOP1_SHARE of one per halo block, is within
    one block of the others'; a thread left without blocks has no halo."""
    cfg = Config(shape, ((0, 0, 1),), True, False, False, False, None, "f64", threads, 1.0)
    lay = layout(cfg)
    ranges = thread_ranges(lay)
    assert ranges[0][0] == 0 and ranges[-1][1] == lay.nblocks
    assert [r[0] for r in ranges[1:]] == [r[1] for r in ranges[:-1]]
    reach = -(-(shape[1] * shape[2] + shape[2] + 1) // BLOCK)
    work = []
    for lo, hi, halo in ranges:
        assert lo <= hi
        if hi == lo:
            assert halo == lo
        else:
            assert halo == max(0, lo - reach)
            work.append((hi - lo) + LOOP1_SHARE * (lo - halo))
    assert max(work) - min(work) <= 1.0, ranges


@pytest.mark.parametrize("threads", [1, 2])
def test_warm_up_steps_do_not_change_the_run(threads):
    """``warm_up`` steps a copy of the initial state untimed, then starts again from it: the
    trajectory is the one without, bit for bit, and the warm-up is kept out of the timings."""
    scene = _scene("hybmss", 0.3, body=Body.box(4, 3, 5, 0.5), plates="rotate", E=1e6, gravity=(0, 0, -10))
    system = build(scene)
    kw = dict(dt=0.5 * dt_crit(system), steps=300, threads=threads, system=system, compute_dt_crit=False)
    cold = simulate_explicit(scene, **kw)
    warm = simulate_explicit(scene, warm_up=0.02, **kw)
    assert np.array_equal(cold.u, warm.u)
    assert warm.info["warm_up_s"] >= 0.02 and cold.info["warm_up_s"] == 0.0
    with pytest.raises(ValueError, match="warm_up"):
        simulate_explicit(scene, warm_up=-1.0, **kw)


@pytest.mark.slow
def test_float32_displacements_follow_float64():
    """The 10³ compression cube at ν = 0.499 (volume term on), 10,000 steps of 1 ms: the float32
    kernel (displacements u = x − X) stays within 1e-5 of the largest displacement of float64."""
    from hybmss.bench import compression_scene

    scene = compression_scene("hybmss", 0.499)
    system = build(scene)
    kw = dict(dt=1e-3, steps=10_000, system=system, compute_dt_crit=False, check_every=1000)
    r64 = simulate_explicit(scene, **kw)
    r32 = simulate_explicit(scene, precision="f32", **kw)
    scale = np.abs(r64.u).max()
    assert scale > 0.05 * 0.05 * 5.0 * 0.5  # the plate has moved the top by 5 %
    assert np.abs(r32.u - r64.u).max() <= 1e-5 * scale
    assert r32.info["precision"] == "f32"


@pytest.mark.parametrize("precision, threads", [("f64", 1), pytest.param("f32", 2, marks=pytest.mark.slow)])
def test_generated_kernel_vectorizes_sqrt_and_division(precision, threads):
    """Load-independent evidence of speed: the function that runs the steps (``run`` on one
    thread, ``thread`` on several: a step body per buffer parity) has every square root and
    division of the step packed (ymm or zmm registers): one of each per spring offset, one more
    division for the volume term.  Scalar divisions remain only in the plates' motion."""
    st = stencil(build(_scene("hybmss", 0.499)), 1e-3, 1.0, precision=precision, threads=threads)
    st.load(st.Xg[:, st.flat].T.copy(), np.zeros((len(st.flat), 3)))
    mix = instruction_mix(st.config, st._args(0, 1, 1, 1e30))
    bodies = 1 if threads == 1 else 2
    packed = lambda op: sum(mix[(op, r)] for r in ("ymm", "zmm"))  # noqa: E731
    assert packed("sqrt") == bodies * len(st.offs), mix
    assert packed("div") == bodies * (len(st.offs) + 1), mix
    assert mix[("sqrt", "scalar")] == 0 and mix[("sqrt", "xmm")] == 0, mix


def test_stencil_keeps_only_needed_terms():
    fd = stencil(build(_scene("hybmss-fd", 0.3)), 1e-3, 1.0)
    assert len(fd.offs) == 7 and fd.has_volume  # 3 edge + 4 inner-diagonal offsets
    cf = stencil(build(_scene("hybmss-cf", 0.3)), 1e-3, 1.0)
    assert len(cf.offs) == 13 and not cf.has_volume
    quarter = stencil(build(_scene("hybmss", 0.25)), 1e-3, 1.0)
    assert len(quarter.offs) == 13 and not quarter.has_volume and not quarter.has_gravity


def test_stencil_holds_every_spring_once():
    system = build(CASES["l-shape"])
    st = stencil(system, 1e-3, 1.0)
    assert np.count_nonzero(st.K) == len(system.spring_k)
    assert st.K.sum() == pytest.approx(system.spring_k.sum(), rel=1e-14)
    assert np.count_nonzero(st.kv[0]) == len(system.vol_cells)


class _ZeroTerm:
    """A non-conservative force term of zero force."""

    name, conservative, scaled = "zero", False, False

    def forces(self, x):
        return np.zeros_like(x)


def test_numba_kernel_refuses_unknown_forces():
    scene = CASES["hybmss-cf"]
    system = dataclasses.replace(build(scene), terms=(_ZeroTerm(),))
    with pytest.raises(ValueError, match="kernel='numpy'"):
        simulate_explicit(scene, steps=1, system=system, kernel="numba", compute_dt_crit=False)
    r = simulate_explicit(scene, steps=1, system=system, kernel="numpy", compute_dt_crit=False)
    assert np.all(np.isfinite(r.u))


@pytest.mark.slow
def test_bench_rows_and_table():
    from hybmss.bench import format_bench, run_bench, static_cases

    variants = (("hybmss-fd", 0.499), ("hybmss", 0.499))
    d = run_bench(steps=20, numpy_steps=2, repeats=1, threads=(1,), meshes=((3, 3, 3),), variants=variants)
    assert [set(r) >= {"scene", "mesh", "wall_time_s"} for r in d["static"]] == [True] * len(static_cases())
    assert {r["mesh"] for r in d["static"]} == {"3x3x3"}  # the static rows solve the run's first mesh
    rows = d["explicit"]
    assert {(r["model"], r["precision"], r["kernel"]) for r in rows} == {
        (m, p, "numba") for m, _ in variants for p in ("f64", "f32")} | {(m, "f64", "numpy") for m, _ in variants}
    for r in rows:
        assert {"model", "nu", "mesh", "kernel", "precision", "threads", "steps", "wall_time_s", "load_avg"} <= set(r)
        assert r["mesh"] == "3x3x3" and r["wall_time_s"] > 0
        assert r["steps"] == (20 if r["kernel"] == "numba" else 2)
    text = format_bench(d)
    # each model is compared with the fastest float64 one-thread model of the run (timing decides which)
    f64 = [(r["s_per_10k_steps"], r["model"]) for r in rows if (r["kernel"], r["precision"]) == ("numba", "f64")]
    fastest, other = min(f64)[1], max(f64)[1]
    line = {m: next(ln for ln in text.splitlines() if f" {m} nu=0.499:" in ln) for m, _ in variants}
    assert f"/{fastest}(nu=0.499)" in line[other] and f"/{fastest}(nu=0.499)" not in line[fastest]
    # and every other model over the reference model hybmss at the same nu
    t = {r["model"]: r["s_per_10k_steps"] for r in rows if (r["kernel"], r["precision"]) == ("numba", "f64")}
    assert f"/hybmss(nu=0.499) {t['hybmss-fd'] / t['hybmss']:.2f}" in line["hybmss-fd"]
    assert "/hybmss(nu" not in line["hybmss"]
    assert text.count("f32/f64 (1 thr)") == 2 and text.count("numba/numpy") == 2 and "load average" in text


def test_bench_fits_the_steps_to_the_time_and_says_what_a_model_refuses():
    """Without fixed steps each configuration runs what fits in the target time (the slow NumPy
    twin fewer steps than the kernel); a serial competitor has no two-thread row, and the table
    says so with the model's reason."""
    from hybmss.bench import MAX_STEPS, MIN_STEPS, format_bench, run_bench

    d = run_bench(repeats=1, threads=(1, 2), meshes=((3, 3, 3),), precisions=("f64",), static=False,
                  variants=(("hybmss-cf", 0.3), ("corot-hex8", 0.3)), target_s=0.02)
    rows = {(r["model"], r["kernel"], r["threads"]): r for r in d["explicit"]}
    assert set(rows) == {("hybmss-cf", "numba", 1), ("hybmss-cf", "numba", 2), ("hybmss-cf", "numpy", 1),
                         ("corot-hex8", "numba", 1), ("corot-hex8", "numpy", 1)}
    for r in rows.values():
        assert (MIN_STEPS if r["kernel"] == "numba" else 2) <= r["steps"] <= MAX_STEPS
    assert rows[("hybmss-cf", "numpy", 1)]["steps"] < rows[("hybmss-cf", "numba", 1)]["steps"]
    (refused,) = d["not_run"]
    assert refused["model"] == "corot-hex8" and "serial" in refused["reason"]
    assert "not run: corot-hex8 3x3x3 f64 2 thr" in format_bench(d)


@pytest.mark.slow
def test_bench_times_one_configuration_from_the_command_line():
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "studies.cli.parser", "bench", "--model", "hybmss-cf", "--mesh", "3x3x3",
                          "--precision", "f32", "--threads", "1", "--steps", "10", "--quick", "--json"],
                         capture_output=True, text=True, check=True).stdout
    d = json.loads(out)
    (row,) = d["explicit"]
    assert (row["model"], row["mesh"], row["precision"], row["threads"], row["steps"]) == ("hybmss-cf", "3x3x3", "f32", 1, 10)


@pytest.mark.slow
def test_two_threads_in_float32_equal_one_thread_bit_for_bit():
    scene = _scene("hybmss", 0.45, body=Body.box(4, 3, 5, 0.5), plates="rotate", E=1e6, gravity=(0, 0, -10))
    system = build(scene)
    dc = dt_crit(system)
    x0, v0 = _initial(system, 2)
    kw = dict(dt=0.5 * dc, ramp_time=30 * dc, system=system, x0=x0, v0=v0, dt_crit_value=dc, steps=STEPS,
              precision="f32", check_every=7)
    r1 = simulate_explicit(scene, threads=1, **kw)
    r2 = simulate_explicit(scene, threads=2, **kw)
    assert np.abs(r1.u).max() > 0 and np.array_equal(r1.u, r2.u)


@pytest.mark.slow
def test_threads_that_cannot_run_at_once_give_up_and_restore_the_state():
    """A thread whose partner never comes gives up at the barrier after its spin limit, the state
    is restored and the run goes on one parallel region per step, to the same positions."""
    scene = CASES["rotating-plate"]
    system = build(scene)
    st = stencil(system, 0.5 * dt_crit(system), 0.01, threads=2)
    x0, v0 = _initial(system, 1)
    st.load(x0, v0)
    before = st.W.copy()
    assert st._run_threads(st.module(), st._args(0, 20, 5, 1e30), absent=(1,)) == (None, None)
    assert np.array_equal(st.W, before)
    assert st.advance(0, 20, 5, 1e30) == (20, -1)
    one = stencil(system, 0.5 * dt_crit(system), 0.01, threads=1)
    one.load(x0, v0)
    one.advance(0, 20, 5, 1e30)
    assert np.array_equal(st.state()[0], one.state()[0])


@pytest.mark.slow
@pytest.mark.parametrize("threads", [1, 2])
def test_shared_helpers_compile_once_for_every_lattice(threads, tmp_path, monkeypatch):
    """The generated kernels pass their lattice's constants to the shared helpers (plates,
    divergence check) as run-time integers: a second lattice size adds no compiled version of
    them (each was about 2 s of compiling per kernel when typed by value).  The kernels are
    compiled afresh (an empty kernel cache), so that each resolves its calls to the helpers."""
    from hybmss import _kernels

    monkeypatch.setenv("HYBMSS_KERNEL_CACHE", str(tmp_path))
    helpers = (_kernels.end_of_step, _kernels.prescribe, _kernels.apply_plates, _kernels.find_bad)
    before = None
    for shape in ((3, 4, 3), (5, 3, 3)):  # sizes no other test compiles (kept in memory once loaded)
        scene = _scene("hybmss", 0.3, body=Body.box(*shape, 0.5), plates="rotate")
        simulate_explicit(scene, dt=1e-4, steps=3, threads=threads)
        now = [set(h.signatures) for h in helpers]
        if before is not None:
            assert now == before, [h.py_func.__name__ for h, a, b in zip(helpers, now, before) if a != b]
        before = now
