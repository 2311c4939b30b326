"""Tables of the reproduction, built from stored runs and written as CSV and Markdown.

- ``runs``: every stored run, one tidy row each (scene parameters, solver, metrics, wall time).
- ``table2_compression`` / ``table3_tension``: relative volume change e (%) per variant and
  reference, next to the publication's values ([G20] Tables 2, 3).
- ``table4_shear`` / ``table5_torsion``: top-plate reaction force F_x (N) and torque T_z (N·m).
- ``bending``: tip deflection (m) against Euler–Bernoulli and the FEM.
- ``differences``: nodal displacement difference of each MSS run against its FEM reference
  (linear at ≤ 5 %, Neo-Hookean above) and the reference's model-form spread (|NH − SVK|).
- ``eform_check``: which spring calibration reproduces the publication's hybmss column (each
  calibration from its own run; failed or missing runs say so).
- ``moduli``: effective E, ν, G per variant (homogeneous static tests).
- ``models``: every registered model's variants with their label and plot style.
- ``reference_laws``: the FEM law each scene load is compared with.
- ``bending_curves`` / ``euler_bernoulli``: centre-line deflection of every bending run and the
  Euler–Bernoulli curve of each beam ([G20] Fig. 5).
- ``study_variants``: the variant names each model is compared in at each stored ν
  (:meth:`hybmss.models.ModelBase.study_variants`): the study's design, which the report shows
  rather than re-derives.
- ``lattice_counts``: volumes, vertices and springs of this lattice on [G20] Table 6's meshes, in
  the publication's convention (:meth:`hybmss.lattice.Lattice.counts`).
- ``published_models``: the models each publication compares, their part in its claims and the
  registered model of each (:func:`studies.paper.publications.published_models`).

Runs are matched with each other by their exact stored parameters; the publication's printed
values are matched with stored ones by :func:`studies.paper.values.printed` only.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hybmss import models
from hybmss.experiments import EXPERIMENTS, SceneSpec
from hybmss.lattice import Lattice
from hybmss.moduli import measure_moduli
from hybmss.scene import Body, Material, Model, admissible_nu
from hybmss.solve import StaticSolveError

from studies.paper import publications as publication
from studies.sweep import roles
from studies.sweep.results import method_frame, printed_match as printed
from studies.sweep.compare import default_law, diff_metrics
from studies.paper.values import load as load_paper
from studies.sweep.store import Store

SCENE_COLS = ["experiment", "mesh", "nu", "E", "deformation", "angle_deg"]


def runs_frame(store: Store, first=None) -> pd.DataFrame:
    """Every stored run, one row each; the runs whose keys are in ``first`` come first, so that
    the columns are in the order their rows give them (not in one that the keys' hashes of other
    runs in the folder decide)."""
    rows = store.rows()
    if first is not None:
        first = set(first)
        rows = [r for r in rows if r.get("key") in first] + [r for r in rows if r.get("key") not in first]
    if not rows:
        return pd.DataFrame()
    df = pd.DataFrame([{k: v for k, v in r.items() if k not in ("info", "traceback", "scene_fields")} for r in rows])
    df["variant"] = [_variant(r) for r in df.to_dict("records")]
    return method_frame(df)


def _variant(row: dict) -> str:
    """The stored variant name of a run; for a run stored without one, its model's name for the
    stored parameters."""
    v = row.get("variant")
    if isinstance(v, str):
        return v
    try:
        spec = models.get(row["model"])
        given = {k: row.get(k) for k in spec.parameter_names()}
        return spec.variant(spec.parameters(**{k: v for k, v in given.items() if v is not None and v == v}))
    except ValueError:
        return str(row["model"])


def _ok(df):
    return df[df["status"] == "ok"]


def _mss(df):
    return df[~df["is_fem"]]


def _fem(df):
    return df[df["is_fem"]]


def volume_table(df: pd.DataFrame, experiment: str, paper_name: str) -> pd.DataFrame:
    """e (%) per (mesh, ν, d) and method; the publication's columns alongside."""
    sub = df[(df["experiment"] == experiment) & (df["study"] == experiment)]
    if sub.empty:
        return pd.DataFrame()
    sub = sub.assign(e_pct=100.0 * sub["volume_change"].abs())
    sub.loc[sub["status"] != "ok", "e_pct"] = np.nan
    wide = sub.pivot_table(index=["mesh", "nu", "deformation"], columns="method",
                           values="e_pct", aggfunc="first").reset_index()
    own = publication.models_of("G20")  # the publication's names of its models -> "paper <model>"
    names = {r.name: f"paper {r.model}" for r in own.itertuples() if r.model}
    paper = load_paper(paper_name).rename(columns={**names, "fem_lsdyna": "paper FEM (LS-Dyna)"})
    return wide.merge(paper, on=["nu", "deformation"], how="left")


def reaction_table(df: pd.DataFrame, experiment: str, column: str, load_col: str) -> pd.DataFrame:
    sub = df[(df["experiment"] == experiment) & (df["study"] == experiment)]
    if sub.empty or column not in sub:
        return pd.DataFrame()
    sub = sub.copy()
    sub.loc[sub["status"] != "ok", column] = np.nan
    wide = sub.pivot_table(index=["mesh", "nu", load_col], columns="method", values=column,
                           aggfunc="first").reset_index()
    return wide


def bending_table(df: pd.DataFrame) -> pd.DataFrame:
    sub = df[df["experiment"] == "bending"]
    if sub.empty or "tip_deflection" not in sub:
        return pd.DataFrame()
    sub = sub.copy()
    sub.loc[sub["status"] != "ok", "tip_deflection"] = np.nan
    wide = sub.pivot_table(index=["mesh", "E"], columns="method", values="tip_deflection",
                           aggfunc="first").reset_index()
    eb = sub.groupby(["mesh", "E"])["euler_bernoulli_tip"].first().reset_index()
    wide = wide.merge(eb, on=["mesh", "E"])
    return wide


def same(column: pd.Series, value) -> pd.Series:
    """Rows whose stored parameter equals ``value`` exactly (a missing value matches a missing one)."""
    return (column == value) | (column.isna() & pd.isna(value))


GEOMETRY_COLS = ["experiment", "mesh", "nu", "E", "deformation", "angle_deg"]
"""Stored scene parameters that make an MSS run and its FEM reference the same load case."""


def _reference_row(fem: pd.DataFrame, row, law: str):
    m = (fem["solver_law"] == law) & (fem["solver_refine"] == 1)
    for c in GEOMETRY_COLS:
        m &= same(fem[c], row[c])
    m = fem[m]
    return None if m.empty else m.iloc[0]


def differences_table(df: pd.DataFrame, store: Store) -> pd.DataFrame:
    """Nodal displacement difference of every MSS run against its FEM reference."""
    ok = _ok(df)
    fem = _fem(ok)
    out = []
    if fem.empty:
        return pd.DataFrame()
    for _, row in _mss(ok).iterrows():
        if row["experiment"] == "uniaxial":
            continue
        spec = SceneSpec(row["experiment"], deformation=row["deformation"],
                         angle_deg=row["angle_deg"])
        law = default_law(spec)
        ref = _reference_row(fem, row, law)
        if ref is None:
            continue
        a, b = store.arrays(row["key"]), store.arrays(ref["key"])
        if "u" not in a or "u" not in b:
            continue
        d = diff_metrics(a["X"], a["u"], b["u"])
        spread = mid_svk = np.nan
        if law != "linear":
            other = _reference_row(fem, row, "svk" if law == "neo-hookean" else "neo-hookean")
            if other is not None and "u" in store.arrays(other["key"]):
                uo = store.arrays(other["key"])["u"]
                spread = float(np.linalg.norm(uo - b["u"]) / np.linalg.norm(b["u"]))
                if law == "neo-hookean":  # the same layer against the St Venant–Kirchhoff reference
                    mid_svk = diff_metrics(a["X"], a["u"], uo)["mid_layer_mean"]
        out.append({
            "experiment": row["experiment"], "mesh": row["mesh"], "nu": row["nu"],
            "E": row["E"], "deformation": row["deformation"], "angle_deg": row["angle_deg"],
            "method": row["method"], "reference": ref["solver"],
            "mean_m": d["mean"], "max_m": d["max"], "rel_l2": d["rel_l2"], "mid_layer_mean_m": d["mid_layer_mean"],
            "mid_layer_mean_xy_m": d["mid_layer_mean_xy"], "mid_layer_rms_m": d["mid_layer_rms"],
            "mid_layer_n": d["mid_layer_n"], "mid_layer_mean_svk_m": mid_svk,
            "ref_nh_svk_rel_l2": spread,
            "e_mss_pct": 100 * row["volume_change"], "e_fem_pct": 100 * ref["volume_change"],
            "mss_key": row["key"], "fem_key": ref["key"],
        })
    return pd.DataFrame(out)


#: the publication prints e with two decimals: two values closer than this cannot be told apart
PAPER_E_PRECISION_PCT = 0.01


def _run_value(grp: pd.DataFrame) -> tuple[float, str]:
    """(e in %, state) of the single run in ``grp``: state "ok", "missing" or "failed (reason)"."""
    if grp.empty:
        return np.nan, "missing"
    r = grp.iloc[0]
    if r["status"] != "ok":
        reason = " ".join(str(r.get("message") or "").split())[:80]
        return np.nan, f"failed ({r['status']}{': ' + reason if reason else ''})"
    return 100 * abs(float(r["volume_change"])), "ok"


def eform_check(df: pd.DataFrame) -> pd.DataFrame:
    """Distance of the publication's hybmss and hybmss-fd columns to our static equilibria built
    with the G-form (right) and the E-form of [G20] eq. 5.12 (E = 5G/2) spring constants.

    Each calibration's value comes from its own run: a run that failed or was not stored is
    reported as such (``G_form_state``, ``E_form_state``), never replaced by the other's value.
    At ν = 1/4 the two calibrations are the same constants and no E-form run is made
    (``E_form_state`` = "identical to G-form (ν = 1/4)").  ``closer`` names the calibration
    nearer to the published value; "undecided (...)" when a run is missing or failed, or when the
    two values differ by no more than the publication's printed precision (0.01 pp), so that the
    row cannot tell them apart (``decisive`` False)."""
    out = []
    for exp, paper_name in (("compression", "g20_table2_compression"), ("tension", "g20_table3_tension")):
        paper = load_paper(paper_name)
        own = publication.models_of("G20")
        for name, model in [(r.name, r.model) for r in own.itertuples() if r.model and r.name in paper.columns]:
            sub = df[(df["experiment"] == exp) & (df["solver"] == "mss-static")
                     & (df["model"] == model) & (df["study"] == exp)]
            if "e_form" not in sub:  # a model without the E-form parameter: nothing to check
                continue
            for _, p in paper.iterrows():
                sel = sub[printed(sub["nu"], p["nu"])
                          & printed(sub["deformation"], p["deformation"])]
                for mesh, grp in sel.groupby("mesh"):
                    eform = grp["e_form"].fillna(False).astype(bool)
                    gval, gstate = _run_value(grp[~eform])
                    if not eform.any() and len(models.get(model).study_variants(float(grp["nu"].iloc[0]))) == 1:
                        eval_, estate = gval, "identical to G-form (ν = 1/4)"
                    else:
                        eval_, estate = _run_value(grp[eform])
                    ref = float(p[name])
                    if gstate != "ok" or not (estate == "ok" or estate.startswith("identical")):
                        closer = "undecided (" + ("G-form " + gstate if gstate != "ok" else "E-form " + estate) + ")"
                        decisive = False
                    elif abs(gval - eval_) <= PAPER_E_PRECISION_PCT:
                        closer, decisive = "same (differ by ≤ 0.01 pp)", False
                    else:
                        dg, de = abs(gval - ref), abs(eval_ - ref)
                        closer = "E-form" if de < dg else "G-form"
                        decisive = True
                    out.append({"experiment": exp, "model": model, "mesh": mesh, "nu": p["nu"], "deformation": p["deformation"],
                                "paper_pct": ref, "G_form_pct": gval, "G_form_state": gstate,
                                "E_form_pct": eval_, "E_form_state": estate, "closer": closer, "decisive": decisive})
    return pd.DataFrame(out)


MODULI_NUS = (-0.5, 0.0, 0.25, 0.3, 0.45, 0.49, 0.499)


def moduli_variants(nus=MODULI_NUS) -> list[Model]:
    """Every model of the studies (:func:`studies.sweep.roles.studied`) with each parameter set it
    is compared in at any of ``nus``, in the registry's order."""
    variants = []
    studied = roles.studied()
    for m in models.all_models():
        if m.name not in studied or not m.supports("static"):
            continue
        for nu in nus:
            variants += [Model(m.name, **v) for v in m.study_variants(nu)]
    return list(dict.fromkeys(variants))


def _moduli_row(job: tuple) -> dict:
    """The ``moduli`` row of one model variant (``Model.to_dict()``) at one ν (a worker's share)."""
    spec, nu = job
    model = Model(**spec)
    mat = Material(1e4, nu)
    try:
        m = measure_moduli(model, mat)
        # a stationary homogeneous state exists even for a non-positive-definite material;
        # it is stable only if -1 < nu_eff < 1/2 and G_eff > 0
        stable = admissible_nu(m["nu_eff"]) and m["G_eff"] > 0 and m["E_eff"] > 0
        status = "ok" if stable else "unstable material (nu_eff outside (-1, 1/2))"
    except StaticSolveError as exc:  # a scene an engine cannot represent says so
        why = getattr(exc, "row_status", None) or "unstable"
        m, status = {"E_eff": np.nan, "nu_eff": np.nan, "G_eff": np.nan}, f"{why}: {exc}"[:160]
    return {"variant": model.variant, "nu": nu, "E_eff_over_E": float(m["E_eff"]) / mat.E,
            "nu_eff": float(m["nu_eff"]), "G_eff_over_G": float(m["G_eff"]) / mat.G, "status": status,
            "model": model.name, **{k: v for k, v in model.to_dict().items() if k != "name"}}


def moduli_table(nus=MODULI_NUS, store: Store | None = None, workers: int | None = None,
                 runner=None) -> pd.DataFrame:
    """Effective moduli of every model of the studies with each parameter set it is compared in
    (:func:`moduli_variants`), rows by ν then variant; measured on ``workers`` processes, each
    row kept in ``store`` as computation ``moduli`` (:func:`studies.sweep.executors.map_stored`:
    not measured again while the code is the same; ``None``: measured each time; ``runner``: whose
    session's workers measure)."""
    from studies.sweep.executors import map_stored

    return pd.DataFrame(map_stored(store, "moduli", _moduli_row, moduli_jobs(nus), workers, runner))


def moduli_jobs(nus=MODULI_NUS) -> list[tuple]:
    """The measurements of :func:`moduli_table`: (the model's parameters, ν)."""
    variants = moduli_variants(nus)
    return [(model.to_dict(), float(nu)) for nu in nus for model in variants]


def calls() -> list:
    """The moduli :func:`write_tables` measures, as the sweep's calls
    (:class:`studies.sweep.executors.Call`), which it then finds stored."""
    from studies.sweep.executors import Call

    return [Call("moduli", _moduli_row, job) for job in moduli_jobs()]


def reference_laws_table(df: pd.DataFrame) -> pd.DataFrame:
    """The FEM law each stored scene load is compared with (:func:`studies.sweep.compare.default_law`),
    one row per (experiment, d, torsion angle): the decision the report shows, made here once."""
    keys = df[["experiment", "deformation", "angle_deg"]].fillna(0.0).drop_duplicates()
    rows = [{"experiment": e, "deformation": float(d), "angle_deg": float(a),
             "law": default_law(SceneSpec(e, deformation=float(d), angle_deg=float(a)))}
            for e, d, a in keys.itertuples(index=False) if e != "uniaxial"]
    return pd.DataFrame(rows)


def spec_of(row: dict) -> SceneSpec:
    """The :class:`SceneSpec` a stored run recorded (its scene fields and model parameters)."""
    fields = {f: row[f] for f in ("mesh", "E", "nu", "rho", "model", "deformation", "angle_deg",
                                  "gravity", "damping", "le") if f in row}
    fields = {k: v for k, v in fields.items() if not (isinstance(v, float) and v != v)}
    fields["mesh"] = tuple(int(n) for n in str(fields["mesh"]).split("x"))
    names = models.get(fields["model"]).parameter_names()
    params = {k: row[k] for k in names if k in row and row[k] == row[k]}
    return SceneSpec.default(row["experiment"], **fields, **params)


def bending_curves(df: pd.DataFrame, store: Store) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The centre line of every bending run, ``(key, method, mesh, E, z, u_y)`` with z from the
    clamp ([G20] Fig. 5), and the Euler–Bernoulli deflection of each (mesh, E) on 101 points."""
    from studies.sweep.solving import neutral_axis

    sub = _ok(df[df["experiment"] == "bending"])
    curves, theory = [], []
    for r in sub.to_dict("records"):
        a = store.arrays(r["key"])
        if "u" not in a:
            continue
        z, uy = neutral_axis(a["X"], a["u"])
        z0 = float(a["X"][:, 2].min())
        curves += [{"key": r["key"], "method": r["method"], "mesh": r["mesh"], "E": r["E"],
                    "z": float(zi - z0), "u_y": float(u)} for zi, u in zip(z, uy)]
    for (mesh, E), grp in sub.groupby(["mesh", "E"]):
        spec = spec_of(grp.iloc[0].to_dict())
        L = spec.beam_section()[2]
        zz = np.linspace(0.0, L, 101)
        theory += [{"mesh": mesh, "E": E, "z": float(z), "u_y": float(y)}
                   for z, y in zip(zz, spec.euler_bernoulli(zz))]
    return pd.DataFrame(curves), pd.DataFrame(theory)


def study_variants_table(df: pd.DataFrame) -> pd.DataFrame:
    """``model, variant, nu``: every parameter set each registered model is compared in at every
    Poisson ratio of the stored runs."""
    rows = []
    for nu in sorted(float(v) for v in df["nu"].dropna().unique()):
        for m in models.all_models():
            for v in m.study_variants(nu):
                rows.append({"model": m.name, "variant": Model(m.name, **v).variant, "nu": nu})
    return pd.DataFrame(rows).drop_duplicates()


def lattice_counts_table() -> pd.DataFrame:
    """Counts of this lattice on every mesh of [G20] Table 6, in the publication's convention."""
    rows = []
    for mesh in load_paper("g20_table6_meshes")["mesh"]:
        c = Lattice.from_body(Body.box(*(int(v) for v in str(mesh).split("x")), 1.0)).counts()
        rows.append({"mesh": mesh, "volumes": c["volumes"], "vertices": c["vertices"],
                     "springs_no_fd": c["paper_springs_no_fd"], "springs_with_fd": c["paper_springs_with_fd"]})
    return pd.DataFrame(rows)


def models_table() -> pd.DataFrame:
    """One row per variant name of every registered model: its model, label, plot style and
    capabilities (what the report's palette and legends use)."""
    rows = []
    for m in models.all_models():
        for variant, st in m.styles().items():
            rows.append({"variant": variant, "model": m.name, "label": m.label, "color": st.color,
                         "marker": st.marker, "linestyle": st.linestyle, "order": m.order,
                         "conservative": m.conservative, "solvers": " ".join(m.solvers),
                         "kernels": " ".join(m.kernels)})
    return pd.DataFrame(rows)


def write_tables(store: Store, keys=None, runner=None) -> dict:
    """Build every table from the stored runs (and the cheap moduli tests, on ``runner``'s workers
    when it has a session's, :func:`moduli_table`); returns them.
    ``keys``: only the runs of these keys (the studies' tasks; None: every stored run of an
    equilibrium experiment), so that the tables do not change with what other studies stored in
    the same folder."""
    df = runs_frame(store, keys)
    if keys is not None and not df.empty:
        df = df[df["key"].isin(set(keys))].reset_index(drop=True)
    if "experiment" in df:  # equilibria only: a released transient (the dynamics study's) is not one
        df = df[df["experiment"].isin(EXPERIMENTS)].reset_index(drop=True)
    if "solver_repeat" in df:  # a repeat of a run times it again: the same answer, not another row
        df = df[df["solver_repeat"].fillna(0) == 0].reset_index(drop=True)
    tables = {"models": models_table()}
    if not df.empty:
        keep = [c for c in df.columns if not c.startswith("env_")] + ["env_git_revision", "env_code_version"]
        tables["runs"] = df[[c for c in keep if c in df.columns]]
        tables["table2_compression"] = volume_table(df, "compression", "g20_table2_compression")
        tables["table3_tension"] = volume_table(df, "tension", "g20_table3_tension")
        tables["table4_shear"] = reaction_table(df, "shear", "force_x", "deformation")
        tables["table5_torsion"] = reaction_table(df, "torsion", "torque_z", "angle_deg")
        tables["bending"] = bending_table(df)
        tables["differences"] = differences_table(df, store)
        tables["eform_check"] = eform_check(df)
        tables["reference_laws"] = reference_laws_table(df)
        tables["study_variants"] = study_variants_table(df)
        tables["bending_curves"], tables["euler_bernoulli"] = bending_curves(df, store)
    tables["moduli"] = moduli_table(store=store, runner=runner)
    tables["published_models"] = publication.published_models()
    tables["lattice_counts"] = lattice_counts_table()
    for name, t in tables.items():
        if t is not None and not t.empty:
            store.write_table(name, t)
    return tables
