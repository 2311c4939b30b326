"""The errors of a tetrahedral study's runs (``[body] tet_sizes``) against its one reference per
load case × material: the FEM's P2 field on the finest tetrahedra (:mod:`studies.sweep.tet_runs`).

The reference is sampled where each model's nodes are (:meth:`fem_reference.tet.TetSolution.sample`):
an engine's nodes are the nodes of its own tetrahedra, all in the faceted body; a voxel model's
lattice nodes are scored where they lie in the finest tetrahedra (:func:`hybmss.tetbody.contains`)
and the reference finds their element (:meth:`fem_reference.tet.TetProblem.places`); the others
(the voxel staircase reaches past the inscribed facets) are left out of the field error and
counted (``nodes_outside``).  The columns and scales are those of :mod:`studies.study.metrics`:
``u_rel_l2``/``u_rel_max`` on the field's own magnitude at the scored nodes, a support's force and
torque on the load's force scale (the reference's reactions, ``R_s`` its held vertices' radius),
the volume change (each model's own ΔV/V0 against the reference's ``∫ div u dx / V``) on the
load's strain scale, a named point's displacement (the model's nearest node) on max |u_FEM|."""

from __future__ import annotations

import numpy as np

from studies.study.metrics import _reaction_errors, field_errors, load_scales, nearest_node, published_relative, scaled
from studies.sweep.runner import no_result_because
from studies.sweep.tet_runs import TetEngineScene, TetReferenceScene, reference_solution, support_radius

SAMPLE_TOL = 1e-6
"""Barycentric tolerance of the reference's sampling."""


def _material(task):
    s = task.scene
    return s.material if isinstance(s, (TetEngineScene, TetReferenceScene)) else s.build().material


def reference_config(task) -> tuple:
    m = _material(task)
    return (task.scene.load_case, m.E, m.nu, m.rho)


def references(runs: list[dict]) -> dict:
    """The reference run of each configuration (load case, E, ν, ρ)."""
    return {reference_config(r["task"]): r for r in runs if isinstance(r["task"].scene, TetReferenceScene)}


def scored(study, run: dict, ref: dict, fields: dict):
    """The reference's field (:class:`fem_reference.tet.TetSolution`, cached in ``fields`` by its
    key) and which of the run's nodes are scored (module docstring)."""
    from hybmss.tetbody import contains

    if ref["key"] not in fields:
        fields[ref["key"]] = reference_solution(ref["arrays"], _formulation(ref["row"]))
    sol, X = fields[ref["key"]], run["arrays"]["X"]
    ok = np.ones(len(X), bool) if isinstance(run["task"].scene, TetEngineScene) else contains(study.tet_bodies[-1], X)
    ok[ok] = sol.problem.places(X[ok], SAMPLE_TOL)
    return sol, ok


def reference_at_nodes(study, run: dict, ref: dict, fields: dict) -> np.ndarray:
    """The reference's displacement at the run's nodes (n, 3), NaN at the nodes not scored."""
    sol, ok = scored(study, run, ref, fields)
    X = run["arrays"]["X"]
    u = np.full(X.shape, np.nan)
    u[ok] = sol.sample(X[ok], SAMPLE_TOL)
    return u


def tet_error_rows(study, runs: list[dict], cost) -> list[dict]:
    """One row per model run (``cost(task, row)``: :func:`studies.study.tables._cost`)."""
    from studies.study.tet import tet_notes

    refs, notes, fields = references(runs), tet_notes(study), {}
    out = []
    for r in runs:
        task, s = r["task"], r["task"].scene
        if isinstance(s, TetReferenceScene):
            continue
        on_tets = isinstance(s, TetEngineScene)
        m = _material(task)
        row = {"load_case": s.load_case, "model": s.label, "mesh": "tets" if on_tets else "voxels",
               "cell_size_m": s.cell_size, "cells": s.body.n_tets if on_tets else s.build().body.n_cells,
               "E": m.E, "nu": m.nu, "rho": m.rho, "solver": task.solver.kind,
               "status": (r["row"] or {}).get("status", "missing"), "message": (r["row"] or {}).get("message", ""),
               "note": notes.get(s.label, "")}
        ref = refs[reference_config(task)]
        if r["arrays"] is not None and ref["arrays"] is not None:
            row.update(tet_errors(study, r, ref, *scored(study, r, ref, fields)))
        row.update(cost(task, r["row"] or {}))
        row["failure"] = no_result_because(r["row"])
        if row["failure"]:
            row.update({k: np.nan for k in ("time_s", "time_median_s", "time_spread") if k in row})
        out.append(row)
    return out


def _formulation(ref_row: dict) -> str:
    return str((ref_row.get("info") or {}).get("element", "tet-p2")).removeprefix("tet-")


def tet_errors(study, run: dict, ref: dict, sol, ok: np.ndarray) -> dict:
    """The errors of one run whose nodes ``ok`` are scored (module docstring)."""
    X, u = run["arrays"]["X"], run["arrays"]["u"]
    info_m, info_f = run["row"].get("info", {}) or {}, ref["row"].get("info", {}) or {}
    supports = ref["task"].scene.supports
    radii = {s.name: support_radius(sol, s) for s in supports}
    sc = load_scales(info_f, radii, ref["arrays"]["u"], ref["arrays"]["X"])
    est = info_f.get("reference_error_estimate")
    est = float(est) if est is not None and np.isfinite(float(est)) else float("nan")
    out: dict = {"nodes_scored": int(ok.sum()), "nodes_outside": int((~ok).sum()), "force_scale_N": sc["force_N"],
                 "strain_scale": sc["strain"], "reference_error_estimate": est}
    kinds = {s.name: s.motion.kind for s in supports}
    for name in study.metrics.plate_force:
        if name in kinds:
            out.update(_reaction_errors(name, kinds[name], info_m, info_f, sc["force_N"], radii[name], est))
    if study.metrics.volume_change:
        vm, vf = float(run["row"].get("volume_change", np.nan)), float(ref["row"].get("volume_change", np.nan))
        out.update(volume_change=vm, volume_change_fem=vf, volume_change_err=scaled(vm, vf, sc["strain"]),
                   volume_change_rel=published_relative(vm, vf, sc["strain"], est))
    if study.metrics.displacement and ok.any():
        out.update(field_errors(u[ok], sol.sample(X[ok], SAMPLE_TOL)))
        if np.isfinite(est) and est >= 1.0:  # the reference is below its own error estimate
            out.update(u_rel_l2=float("nan"), u_rel_max=float("nan"))
    for name, p in study.metrics.points:
        i = nearest_node(X, p)
        u_f = sol.sample(X[i:i + 1], SAMPLE_TOL)[0] if ok[i] else np.full(3, np.nan)
        out[f"point_{name}_u_m"] = float(np.linalg.norm(u[i]))
        out[f"point_{name}_fem_u_m"] = float(np.linalg.norm(u_f))
        out[f"point_{name}_err"] = scaled(u[i], u_f, sc["u_m"])
        out[f"point_{name}_rel"] = published_relative(u[i], u_f, sc["u_m"], est)
    return out


def tet_reference_rows(runs: list[dict]) -> list[dict]:
    out = []
    for r in runs:
        s = r["task"].scene
        if not isinstance(s, TetReferenceScene):
            continue
        row = r["row"] or {}
        info = row.get("info", {}) or {}
        m = s.material
        out.append({"load_case": s.load_case, "cell_size_m": s.cell_size, "E": m.E, "nu": m.nu, "rho": m.rho,
                    "solver": row.get("solver"), "element": info.get("element"), "law": "linear",
                    "refine": info.get("reference_refine"), "tets": info.get("tets"),
                    "error_estimate": info.get("reference_error_estimate"),
                    "error_target": info.get("reference_error_target"),
                    "time_s": info.get("time_s"), "status": row.get("status", "missing")})
    return out
