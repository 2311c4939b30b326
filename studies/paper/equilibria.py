"""Explicit runs against the static equilibrium of the same scene: where the two are apart, the
scene has more than one equilibrium for that model (a non-unique equilibrium), and neither value
is "the" answer.

An explicit run that reached rest (status ok: force residual and kinetic energy below the rest
test) is an equilibrium too; if it lies more than :data:`NONUNIQUE_PCT` (relative L2 of the nodal
displacements) from the static solver's, the two solvers found two equilibria. The table
``tables/equilibria.csv`` holds every explicit run with its static twin, the difference and the
flag; the report marks the flagged scenes wherever it shows their values.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from studies.sweep.results import Results

NONUNIQUE_PCT = 5.0
"""Relative L2 difference (%) of the nodal displacements of two equilibria of one scene (explicit
at rest, static) above which the scene counts as having non-unique equilibria."""

COLUMNS = ["explicit_key", "static_key", "study", "label", "method", "variant", "experiment", "mesh", "nu",
           "deformation", "angle_deg", "E", "status", "dt", "steps", "damping", "dt_crit", "max_speed",
           "e_explicit_pct", "e_static_pct", "de_pp", "rel_l2_pct", "apart", "message"]


def _cell(v):
    if isinstance(v, (list, tuple, np.ndarray)):
        return tuple(v)
    return None if pd.isna(v) else v  # a missing value matches a missing value


def static_twins(results: Results) -> dict:
    """The first stored static run (status ok) of each scene, keyed by the scene without the
    dynamic solvers' damping."""
    df = results.rows
    keys = [c for c in results.scene_columns() if c not in ("damping", "variant")]
    st = df[(df["solver"] == "mss-static") & (df["status"] == "ok")]
    twins: dict = {}
    for _, t in st.iterrows():
        twins.setdefault(tuple(_cell(t[k]) for k in keys), t)
    return twins, keys


def rel_l2_pct(a: np.ndarray, b: np.ndarray) -> float:
    """‖a − b‖ / ‖b‖ in % (NaN where the shapes differ or b is zero)."""
    if a.shape != b.shape or not np.linalg.norm(b) > 0:
        return np.nan
    return 100 * float(np.linalg.norm(a - b) / np.linalg.norm(b))


def _message(r, ok: bool) -> str:
    """Why an explicit run is no result, in one line ("" for a run at rest)."""
    if ok:
        return ""
    text = " ".join(str(r.get("message") or "").split()) if not pd.isna(r.get("message")) else ""
    info = r.get("info") if isinstance(r.get("info"), dict) else {}
    if not text and r["status"] == "not-converged" and info.get("floor_stop_t") is not None:
        return (f"not at rest: a force residual floor of at least {info['floor_bound']:.2g} "
                f"of the force scale at the end of the budget (stopped at t = {info['floor_stop_t']:.3g} s of "
                f"{int(r['solver_steps']) * float(r['solver_dt']):.3g} s)")
    if not text and r["status"] == "not-converged":
        return f"not at rest after {int(r['solver_steps'])} steps" if pd.notna(r.get("solver_steps")) else "not at rest"
    return text


def equilibria(results: Results) -> pd.DataFrame:
    """Every explicit run beside its static twin (:data:`COLUMNS`); ``apart``: both are equilibria
    (the explicit run at rest) and they differ by more than :data:`NONUNIQUE_PCT`."""
    df = results.rows
    if df.empty or not (df["solver"] == "mss-explicit").any():
        return pd.DataFrame(columns=COLUMNS)
    twins, keys = static_twins(results)
    recs = []
    for _, r in df[df["solver"] == "mss-explicit"].sort_values(["study", "label"]).iterrows():
        twin = twins.get(tuple(_cell(r[k]) for k in keys))
        ok = r["status"] == "ok"
        rel = de = np.nan
        if ok and twin is not None:
            a, b = results.arrays(r["key"]), results.arrays(twin["key"])
            if "u" in a and "u" in b:
                rel = rel_l2_pct(a["u"], b["u"])
            de = 100 * (abs(float(r["volume_change"])) - abs(float(twin["volume_change"])))
        info = r.get("info") if isinstance(r.get("info"), dict) else {}
        recs.append({
            "explicit_key": r["key"], "static_key": twin["key"] if twin is not None else "",
            "study": r.get("study", ""), "label": r["label"], "method": f"{r['variant']} static",
            "variant": r["variant"], "experiment": r["experiment"], "mesh": r["mesh"], "nu": r["nu"],
            "deformation": r.get("deformation", np.nan), "angle_deg": r.get("angle_deg", np.nan),
            "E": r.get("E", np.nan), "status": r["status"], "dt": r.get("solver_dt", np.nan),
            "steps": r.get("solver_steps", np.nan), "damping": r.get("damping", np.nan),
            "dt_crit": info.get("dt_crit", r.get("dt_crit", np.nan)), "max_speed": info.get("max_speed", np.nan),
            "e_explicit_pct": 100 * abs(float(r["volume_change"])) if ok else np.nan,
            "e_static_pct": 100 * abs(float(twin["volume_change"])) if twin is not None else np.nan,
            "de_pp": de, "rel_l2_pct": rel, "apart": bool(ok and rel > NONUNIQUE_PCT),
            "message": _message(r, ok),
        })
    return pd.DataFrame(recs, columns=COLUMNS)
