"""A study's natural frequencies (``[metrics] modes = k``): per load case, material and resolution
the FEM reference's lowest k modes of the body with the load case's supports, and each model's
paired with them (:mod:`studies.sweep.mode_pairs`), as the table ``modes_<load case>``.

Small vibrations about the rest state, ``K φ = ω² M φ``: the supports hold the components they
constrain at zero; gravity, tractions and plate motions do not enter.  The FEM is the study's
reference element (``auto``: Hex2, mixed u–p for ν ≥ 0.45) with consistent mass, at the
reference's ``refine`` (1 when it is ``"auto"``: the static refinement's error estimate is not a
frequency's); a model is its tangent at rest with its lumped masses
(:func:`hybmss.modes.lattice_modes`), paired by MAC among its lowest 2k modes.  A model without
tangent stiffness (xpbd-nh, the engines) has one row saying it has no modal answer.

``k`` lies in [1, :data:`K_MAX`] and below the free components of every resolution's lattice
(:func:`check_modes`, before any work).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hybmss.lattice import Lattice

from studies.study.errors import StudyError

K_MAX = 100
"""Most modes a study computes (as ``hybmss modes``)."""
COLUMNS = ("model", "model_name", "cell_size_m", "E", "nu", "rho", "mode", "kind", "f_ref_hz", "f_model_hz",
           "model_mode", "error_pct", "mac", "model_time_s", "fem_time_s", "fem_element", "status", "message")


def read_modes(t) -> int:
    """``[metrics] modes``: 0 (no modal table) when absent, otherwise an integer in [1, K_MAX]."""
    if not t.has("modes"):
        return 0
    return t.number("modes", lo=1, hi=K_MAX, integer=True)


def check_modes(study, file: str) -> None:
    """Refuse a ``modes`` that is not below the free components of a lattice (every load case and
    resolution): its eigenproblem has no more modes."""
    k = study.metrics.modes
    if not k:
        return
    for vox in study.voxels:
        X = Lattice.from_body(vox.body).X
        for case in study.load_cases:
            held = np.zeros((len(X), 3), dtype=bool)
            for s in case.supports:
                plate = s.plate(vox.labels)
                sel = plate.region.select(X, vox.body)
                held[np.ix_(sel, list(plate.motion.components))] = True
            n_free = int((~held).sum())
            if k >= n_free:
                raise StudyError("metrics.modes", k, f"an integer in [1, {n_free - 1}]: load case {case.name} at "
                                 f"cell size {vox.le:g} m leaves {n_free} free components", file)


def _configs(study) -> dict:
    """(load case, material, cell size) -> (the FEM reference's scene, [(label, model scene)])."""
    from studies.study.tasks import is_reference

    out: dict = {}
    tasks = study.tasks()
    for task in tasks:
        s = task.scene
        if is_reference(task):
            out.setdefault((s.load_case, s.scene.material, s.cell_size), [None, []])[0] = s.scene
    for task in tasks:
        s = task.scene
        if not is_reference(task):
            out[(s.load_case, s.scene.material, s.cell_size)][1].append((s.label, s.scene))
    return out


def _fem(scene, reference, k: int) -> dict | str:
    """The FEM's ``k`` lowest modes (:func:`studies.sweep.mode_pairs.fem_modes`), or why they failed."""
    from fem_reference.solve import resolve_element

    from studies.sweep.mode_pairs import fem_modes

    element = resolve_element(reference.element, scene.material.nu)
    refine = reference.refine if isinstance(reference.refine, int) else 1
    try:
        return fem_modes(scene, k, element, refine)
    except (ValueError, RuntimeError, ArithmeticError) as exc:
        return f"the FEM's modes failed ({element}, refine {refine}): {' '.join(str(exc).split())}"


def modes_tables(study) -> dict[str, pd.DataFrame]:
    """``modes_<load case>`` of a study with ``[metrics] modes`` (none otherwise)."""
    if study.experiment is not None or not study.metrics.modes:
        return {}
    from studies.sweep.mode_pairs import model_rows

    rows: dict[str, list] = {c.name: [] for c in study.load_cases}
    for (case, mat, le), (fem_scene, runs) in _configs(study).items():
        fem = _fem(fem_scene, study.reference, study.metrics.modes)
        for label, scene in runs:
            head = {"model": label, "model_name": scene.model.name, "cell_size_m": le, "E": mat.E, "nu": mat.nu,
                    "rho": mat.rho}
            if isinstance(fem, str):
                rows[case].append({**head, "status": "failed", "message": fem})
                continue
            for r in model_rows(scene, fem):
                rows[case].append({**head, "fem_element": fem["element"], **r})
    return {f"modes_{case}": pd.DataFrame(r, columns=list(COLUMNS)) for case, r in rows.items()}
