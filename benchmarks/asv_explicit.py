"""asv: the explicit step (generated Numba kernel) by mesh, model and precision.

``time_100_steps`` is 100 steps of 1 ms after a warm-up (kernel compiled or loaded from its
cache); ``track_f32_error`` is the float32 run's largest position difference from the float64 run
after 1,000 steps, relative to the largest displacement: a change that trades accuracy for speed
shows in both.  ``ExplicitTwoThreads`` needs an idle second core to mean anything.
"""

from __future__ import annotations

import numpy as np

from hybmss.explicit import dt_crit, simulate_explicit
from hybmss.system import build

from .asv_common import MESHES, MODELS, scene

NU = 0.499


def _setup(bench, mesh, model, precision):
    bench.scene = scene(mesh, model, NU)
    bench.system = build(bench.scene)
    bench.dc = dt_crit(bench.system)
    bench.dt = 0.5 * bench.dc
    bench.kw = dict(dt=bench.dt, system=bench.system, dt_crit_value=bench.dc, precision=precision,
                    ramp_time=200 * bench.dt, threads=bench.threads)
    try:
        simulate_explicit(bench.scene, steps=2, **bench.kw)
    except ValueError as exc:  # a kernel, precision or thread count this model does not have
        raise NotImplementedError(str(exc)) from exc


class Explicit:
    params = (MESHES, MODELS, ["f64", "f32"])
    param_names = ["mesh", "model", "precision"]
    timeout = 900
    threads = 1

    def setup(self, mesh, model, precision):
        _setup(self, mesh, model, precision)

    def time_100_steps(self, mesh, model, precision):
        simulate_explicit(self.scene, steps=100, check_every=100, **self.kw)

    def track_f32_error(self, mesh, model, precision):
        if precision == "f64":
            raise NotImplementedError("the float64 run is the reference")
        ref = simulate_explicit(self.scene, steps=1000, **{**self.kw, "precision": "f64"})
        r = simulate_explicit(self.scene, steps=1000, **self.kw)
        return float(np.abs(r.u - ref.u).max() / np.abs(ref.u).max())

    track_f32_error.unit = "relative"


class ExplicitTwoThreads:
    """The same 100 steps on two threads (models with a serial kernel are skipped)."""

    params = Explicit.params
    param_names = Explicit.param_names
    timeout = 900
    threads = 2

    def setup(self, mesh, model, precision):
        _setup(self, mesh, model, precision)

    def time_100_steps(self, mesh, model, precision):
        simulate_explicit(self.scene, steps=100, check_every=100, **self.kw)
