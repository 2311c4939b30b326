"""Failures and non-unique equilibria: the runs without a result, and the explicit runs beside
their static twins (``tables/equilibria.csv``)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..data import (NONUNIQUE_PCT, PROTOCOL_FAILURES, Results)
from ..tables import (Table, fmt, frame_table, grade, pp_cell)
from .base import Context, Section, add_tables


FAILURE_CHARS = 120
"""Characters of a failure message printed in the failures table."""


def failures_table(results: Results) -> Table:
    df = results.rows
    bad = df[(df["status"] != "ok") & ~df["timing"]] if not df.empty else df  # a timing run sought no result
    n_timed = int(df["timing"].sum()) if not df.empty else 0
    timing_note = (f" Not listed: {n_timed} timing runs (short explicit runs of a candidate's steps, timed for "
                   "its cost: not at rest, as asked)." if n_timed else "")
    cols = {"label": "scene", "solver": "solver", "study": "study", "status": "status", "counted": "counted as",
            "message": "message"}
    if bad.empty:
        return Table("table_failures", "Runs that did not reach a result",
                     "Every stored run reached status ok." + timing_note, list(cols.values()), [])
    bad = bad.sort_values(["study", "label"]).copy()
    bad["counted"] = ["failure" if not f else f"finding: {f}" for f in bad["finding"]]
    n_failed = int((bad["finding"] == "").sum())
    bad["message"] = [" ".join(str(m).split())[:FAILURE_CHARS] + ("…" if len(" ".join(str(m).split())) > FAILURE_CHARS
                                                                    else "") for m in bad["message"]]
    tab = frame_table(bad, "table_failures", "Runs that did not reach a result",
                      f"{len(bad)} of {len(df)} stored runs have a status other than ok; they are reported, not "
                      "hidden: 'unstable' = the static equilibrium was lost (limit point, Hessian no longer positive "
                      "definite), 'diverged' = explicit integration blew up, 'error' = an exception in a solver. "
                      f"{len(bad) - n_failed} of them are findings of their study: a run not at rest within its step "
                      "budget, an explicit or damped run that left the physical range at its step, a static or "
                      "implicit solve that diagnosed the model's loss of stability (a limit point, an indefinite "
                      f"Hessian, a step too long for Newton); {n_failed} are failures of the program. "
                      f"Messages shortened to {FAILURE_CHARS} characters (the HTML list of runs links every run)."
                      + timing_note,
                      cols, lambda r, c: "fail" if c in ("status", "counted") and not r["finding"] else "")
    other = [i for i, k in enumerate(bad["key"]) if not results.is_publication_run(k)]
    if other:
        tab.row_classes = {i: "screen-only" for i in other}
        tab.caption += (f" {len(other)} of these runs belong to the stress tests of other studies (stability, speed "
                        "against error), whose sections give their outcome; they are listed in the HTML page only.")
    return tab


def equilibria_frame(results: Results) -> pd.DataFrame:
    """The explicit runs beside their static twins as the studies stored them
    (``tables/equilibria.csv``), or computed from the runs for a folder stored without it."""
    t = results.table("equilibria")
    return t if t is not None else pd.DataFrame()


def _explicit_state(r) -> tuple[str, str]:
    if r["status"] != "ok":
        return r["status"], "fail"
    if str(r["apart"]).lower() == "true":
        return "two equilibria ‡", "twofold"
    return "ok", "good"


def explicit_table(results: Results) -> Table | None:
    """Each explicit run (the publication's protocol) against the static equilibrium of the same
    scene; a run that did not come to rest shows no value, a pair apart is flagged."""
    eq = equilibria_frame(results)
    if eq.empty:
        return None
    rows = []
    for _, r in eq.iterrows():
        ok = r["status"] == "ok"
        rows.append([
            (r["label"], ""), (fmt(r["dt"], 3), ""), (fmt(r["steps"]), ""), (fmt(r["damping"], 3), ""),
            (fmt(r["dt_crit"], 3), ""), _explicit_state(r),
            (fmt(r["e_explicit_pct"], 4) if ok else "–", ""),
            (fmt(r["e_static_pct"], 4), "ref") if pd.notna(r["e_static_pct"]) else ("–", ""),
            pp_cell(r["de_pp"] if ok else np.nan, (0.1, 1.0)),
            ((fmt(r["rel_l2_pct"], 3), grade(r["rel_l2_pct"], (1.0, NONUNIQUE_PCT))) if ok else ("–", "")),
            (fmt(r["max_speed"], 3) if ok else "–", ""),
            ("" if ok or pd.isna(r["message"]) else str(r["message"])[:220], ""),
        ])
    other = [i for i, k in enumerate(eq["explicit_key"]) if not results.is_publication_run(k)]
    note = (f" {len(other)} explicit runs of other studies (stability, speed against error) are listed in the HTML "
            "page only." if other else "")
    return Table("table_explicit", "Explicit protocol against the static equilibrium",
                 "The publication's protocol: semi-implicit Euler, dt = 1 ms, 10,000 steps (10 s), plates ramped over "
                 "1 s, mass-proportional damping c (s⁻¹, not stated in [G20]); read at the end, or for xpbd-nh, whose "
                 "rest state is the fixed point of its substep, at that point once the run is at rest (the state the "
                 "rest of its 10 s tends to). A run that did not "
                 "come to rest (status not-converged, diverged) shows no value: it is no result. Compared with the "
                 "static equilibrium of the same scene: e (%) of both, Δe = e_explicit − e_static (pp; green ≤ 0.1, "
                 "amber ≤ 1) and ‖u_explicit − u_static‖ / ‖u_static‖ (%; green ≤ 1, amber ≤ "
                 f"{NONUNIQUE_PCT:g}). Above {NONUNIQUE_PCT:g} % with the explicit run at rest, both are equilibria of "
                 "one scene: 'two equilibria ‡' (non-unique). dt_crit (s) at rest, largest particle speed at the end "
                 "(m/s)." + note,
                 ["run", "dt (s)", "steps", "c (1/s)", "dt_crit (s)", "status", "e explicit (%)", "e static (%)",
                  "Δe (pp)", "‖Δu‖ rel. L2 (%)", "max speed (m/s)", "message"], rows, css="explicit",
                 row_classes={i: "screen-only" for i in other})


def _apart_counts(results: Results, eq: pd.DataFrame) -> str:
    """"k of the n explicit runs at rest …: model: scenes, range" for one group of explicit runs."""
    rest = eq[eq["status"] == "ok"]
    apart = rest[rest["apart"].astype(str).str.lower() == "true"]
    if apart.empty:
        return f"none of the {len(rest)} explicit runs that came to rest"
    per = "; ".join(f"{v} {len(g)} ({g['rel_l2_pct'].min():.3g}–{g['rel_l2_pct'].max():.3g} % apart)"
                    for v, g in apart.groupby("variant"))
    return f"{len(apart)} of the {len(rest)} explicit runs that came to rest ({per})"


def nonunique_sentence(results: Results) -> str:
    """How many explicit runs at rest are apart from their static equilibria, in the publication's
    scenes and in the other studies' stress tests, and which models."""
    eq = equilibria_frame(results)
    if eq.empty:
        return ""
    own = eq["explicit_key"].map(results.is_publication_run).astype(bool)
    parts = []
    if own.any():
        parts.append(f"in the publication's scenes, {_apart_counts(results, eq[own])}")
    if (~own).any():
        parts.append(f"in the other studies (extreme loads, speed against error), {_apart_counts(results, eq[~own])}")
    apart = eq[(eq["status"] == "ok") & (eq["apart"].astype(str).str.lower() == "true")]
    fd = results.published_model("no-face-diagonals")
    hourglass = (f" {fd} has no face diagonals: its cubic lattice has zero-energy (hourglass-like) modes, the zig-zag "
                 "surfaces of its renders." if fd in set(apart["variant"]) else "")
    return ("Non-unique equilibria: an explicit run that came to rest more than "
            f"{NONUNIQUE_PCT:g} % (relative L2 of the nodal displacements) from the static equilibrium of the same "
            "scene found a second equilibrium, and neither value is the model's answer (Tables 2–5 mark such scenes "
            "‡). Found " + "; ".join(parts) + "." + hourglass)


def section(ctx: Context) -> Section:
    """Runs without a result, and explicit equilibria apart from the static ones (non-unique)."""
    results = ctx.results
    s = Section("failures", "Failures and non-unique equilibria",
                " ".join(p for p in (nonunique_sentence(results), PROTOCOL_FAILURES) if p))
    add_tables(s, explicit_table(results), failures_table(results))
    return s
