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


class _Steps:
    """100 explicit steps of one (mesh, model, precision) on ``threads`` threads (a model that does
    not have the kernel, precision or thread count is skipped)."""

    params = (MESHES, MODELS, ["f64", "f32"])
    param_names = ["mesh", "model", "precision"]
    timeout = 900
    threads = 1

    def setup(self, mesh, model, precision):
        self.scene = scene(mesh, model, NU)
        self.system = build(self.scene)
        self.dc = dt_crit(self.system)
        self.dt = 0.5 * self.dc
        self.kw = dict(dt=self.dt, system=self.system, dt_crit_value=self.dc, precision=precision,
                       ramp_time=200 * self.dt, threads=self.threads)
        try:
            simulate_explicit(self.scene, steps=2, **self.kw)
        except ValueError as exc:  # a kernel, precision or thread count this model does not have
            raise NotImplementedError(str(exc)) from exc

    def time_100_steps(self, mesh, model, precision):
        simulate_explicit(self.scene, steps=100, check_every=100, **self.kw)


class Explicit(_Steps):
    def track_f32_error(self, mesh, model, precision):
        if precision == "f64":
            raise NotImplementedError("the float64 run is the reference")
        ref = simulate_explicit(self.scene, steps=1000, **{**self.kw, "precision": "f64"})
        r = simulate_explicit(self.scene, steps=1000, **self.kw)
        return float(np.abs(r.u - ref.u).max() / np.abs(ref.u).max())

    track_f32_error.unit = "relative"


class ExplicitTwoThreads(_Steps):
    """The same 100 steps on two threads (models with a serial kernel are skipped)."""

    threads = 2
