"""The exception of a Newton solve that could not reach equilibrium, with its numbers as fields.

A caller reads the fields, never the message: the message is for people and says the same."""

from __future__ import annotations

CAUSES = ("limit-point", "unstable-path", "indefinite-at-rest", "newton", "residual", "implicit-step",
          "rest-state", "diverged")
"""What a :class:`StaticSolveError` can name as its ``cause``:

- ``limit-point``: a κ < 0 body dilated past a fold of the load path (no equilibrium beyond);
- ``unstable-path``: the constrained Hessian became indefinite (buckling, zero-energy modes);
- ``indefinite-at-rest``: the model is not positive definite even at rest;
- ``newton``: the Hessian stays positive definite but Newton did not converge;
- ``residual``: residual mode (non-conservative forces) lost the path, no stability certificate;
- ``implicit-step``: Newton failed in one step of implicit Euler;
- ``rest-state``: a model's own static solver did not settle to rest;
- ``diverged``: a model's own damped rest run left the physical range at its step."""


class StaticSolveError(RuntimeError):
    """The static (or implicit) solver could not reach equilibrium; the message says where and why.

    Fields (None when they do not apply): ``cause`` (one of :data:`CAUSES`), ``load_factor`` (the
    last load factor s at which an equilibrium was found), ``next_load_factor`` (the one that
    failed), ``smallest_eigenvalue`` (N/m, of the constrained Hessian at ``load_factor``),
    ``next_smallest_eigenvalue`` (N/m, at the state predicted for ``next_load_factor``),
    ``residual`` (N, the free force residual when Newton stopped), ``step`` (1-based step of an
    implicit run) and ``time`` (s, its time)."""

    def __init__(self, message: str, *, cause: str | None = None, load_factor: float | None = None,
                 next_load_factor: float | None = None, smallest_eigenvalue: float | None = None,
                 next_smallest_eigenvalue: float | None = None, residual: float | None = None,
                 step: int | None = None, time: float | None = None):
        super().__init__(message)
        if cause is not None and cause not in CAUSES:
            raise ValueError(f"cause must be one of {', '.join(CAUSES)}; got {cause!r}")
        self.cause = cause
        self.load_factor = load_factor
        self.next_load_factor = next_load_factor
        self.smallest_eigenvalue = smallest_eigenvalue
        self.next_smallest_eigenvalue = next_smallest_eigenvalue
        self.residual = residual
        self.step = step
        self.time = time

    def fields(self) -> dict:
        """The numbers of the failure by name (a stored row's columns)."""
        return {"cause": self.cause, "load_factor": self.load_factor, "next_load_factor": self.next_load_factor,
                "smallest_eigenvalue": self.smallest_eigenvalue,
                "next_smallest_eigenvalue": self.next_smallest_eigenvalue, "residual": self.residual,
                "step": self.step, "time": self.time}
