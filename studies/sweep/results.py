"""Read a stored results folder: run rows, tables, arrays and the publication's values.

Layout (written by the studies): ``runs/<key>.json`` (one row per run), ``runs/<key>.npz``
(``X``, ``u``, ``cells``, ``cell_volumes``), ``tables/<name>.csv``.  Nothing here runs a solver.
The studies judge the publication's claims from it (:mod:`studies.paper.claims`); the report formats
what it reads (:mod:`reports`).
"""

from __future__ import annotations

import re
from collections import Counter
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd

from studies.sweep.outcomes import finding, timing_run
from studies.sweep.store import DamagedRun, Store, table_is_current

#: lattice corner c = di + 2 dj + 4 dk  ->  VTK hexahedron order
VTK_HEX_ORDER = [0, 1, 3, 2, 4, 5, 7, 6]

EXPERIMENT_ORDER = ("compression", "tension", "shear", "torsion", "bending")


#: the columns that say what a run's method is, so that nothing reads a method's name back
METHOD_COLUMNS = ("method", "variant", "model", "solver_kind", "solver_element", "solver_law", "solver_refine",
                  "is_fem", "e_form")


def _from_label(solver: str) -> dict:
    """``solver_kind``, ``solver_element``, ``solver_law``, ``solver_refine`` of a run stored without them, from its
    solver label (``"mss-static"``, ``"fem-hex2-neo-hookean r2"``): the one place a label is read."""
    s, _, refine = str(solver).partition(" r")
    if s.startswith("fem-"):
        element, _, law = s[len("fem-"):].partition("-")
        return {"solver_kind": "fem", "solver_element": element, "solver_law": law,
                "solver_refine": int(refine) if refine.isdigit() else 1}
    return {"solver_kind": s.replace("mss-", "", 1), "solver_element": "", "solver_law": "", "solver_refine": 1}


def method_frame(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` (stored rows with ``solver``, ``model`` and ``variant``) with the structured columns
    of :data:`METHOD_COLUMNS`: a run's solver kind, FEM element and law as stored (derived from
    its solver label where a row stored none), and its method's name, ``"<variant> <kind>"`` for a
    model's run, the solver label for the FEM's."""
    df = df.copy()
    derived = pd.DataFrame([_from_label(s) for s in df["solver"]], index=df.index)
    for col in ("solver_kind", "solver_element", "solver_law"):
        stored = df[col] if col in df else pd.Series(np.nan, index=df.index, dtype=object)
        stored = stored.where(stored.notna() & (stored.astype(str) != ""), derived[col])
        df[col] = stored.fillna("").astype(str)
    refine = df["solver_refine"] if "solver_refine" in df else pd.Series(np.nan, index=df.index)
    df["solver_refine"] = refine.where(refine.notna(), derived["solver_refine"]).astype(int)
    df["e_form"] = df["e_form"].fillna(False).astype(bool) if "e_form" in df else False
    fem = df["solver_kind"] == "fem"
    df["is_fem"] = fem
    df["method"] = np.where(fem, df["solver"].astype(str),
                            df["variant"].astype(str) + " " + df["solver"].astype(str).str.replace("mss-", "", regex=False))
    return df


class Results:
    """A results folder, read lazily.  Only runs and tables of the current code version are read
    (:func:`studies.sweep.store.is_current`, :func:`studies.sweep.store.table_is_current`), so a report never
    mixes results of two versions; ``all_versions`` reads every stored run and table."""

    def __init__(self, root, all_versions: bool = False):
        self.root = Path(root)
        self.all_versions = bool(all_versions)
        self.runs_dir = self.root / "runs"
        self.tables_dir = self.root / "tables"
        self._arrays: dict[str, dict] = {}
        self._damaged: list[DamagedRun] = []
        if not self.runs_dir.is_dir() and not self.tables_dir.is_dir():
            raise FileNotFoundError(f"no results in {self.root}: expected runs/ and tables/ (run "
                                    f"'python -m studies run --all --out {self.root}' first)")

    # ----------------------------------------------------------------- rows
    @cached_property
    def rows(self) -> pd.DataFrame:
        """Every stored run, one row each, with ``variant``, ``method`` and ``load`` columns, and
        ``finding``: why a run without result is a finding of the publication's studies, ``""`` for a
        result or a failure (:func:`studies.sweep.outcomes.finding`); ``timing``: a timing run not at
        rest, as asked (:func:`studies.sweep.outcomes.timing_run`), neither."""
        recs, self._damaged = Store(self.root).scan(all_versions=self.all_versions)
        if not recs:
            return pd.DataFrame()
        df = pd.DataFrame(recs)
        df["finding"] = [finding(r) for r in recs]
        df["timing"] = [timing_run(r) for r in recs]
        for col, default in (("e_form", False), ("status", "ok"), ("message", ""),
                             ("angle_deg", 0.0), ("deformation", 0.0), ("elapsed_s", np.nan),
                             ("model", "")):
            if col not in df:
                df[col] = default
        df["e_form"] = df["e_form"].fillna(False).astype(bool)
        df["message"] = df["message"].fillna("")
        # the variant name the study stored with the run (its model's name for its parameters)
        stored = df["variant"] if "variant" in df else pd.Series(np.nan, index=df.index)
        df["variant"] = stored.where(stored.notna(), df["model"])
        return method_frame(df)

    @cached_property
    def methods(self) -> pd.DataFrame:
        """One row per method of the stored runs, indexed by its name, with its variant, model,
        solver kind, FEM element and law (:data:`METHOD_COLUMNS`): what a table whose columns are
        methods is read by."""
        df = self.rows
        if df.empty:
            return pd.DataFrame(columns=list(METHOD_COLUMNS)).set_index("method")
        return df[list(METHOD_COLUMNS)].drop_duplicates("method").set_index("method")

    def method(self, name: str) -> dict:
        """The structured columns of a method (:attr:`methods`); for a name no stored run has, its
        solver kind only: ``"fem"`` for FEM labels, ``""`` otherwise."""
        t = self.methods
        if name in t.index:
            return {"method": name, **t.loc[name].to_dict()}
        return {"method": name, "variant": "", "model": "", "solver_kind": "", "solver_element": "",
                "solver_law": "", "solver_refine": 1, "is_fem": False, "e_form": False}

    def is_fem(self, name: str) -> bool:
        return bool(self.method(name)["is_fem"])

    def variant(self, name: str) -> str:
        return str(self.method(name)["variant"])

    def law(self, name: str) -> str:
        return str(self.method(name)["solver_law"])

    def fem_with_law(self, columns, law: str | None) -> str | None:
        """The first of ``columns`` that is the FEM with ``law`` on the scene's own mesh (refine 1)."""
        for c in columns:
            i = self.method(c)
            if law and i["is_fem"] and i["solver_law"] == law and int(i["solver_refine"]) == 1:
                return c
        return None

    @property
    def damaged(self) -> list[DamagedRun]:
        """Stored runs left out of :attr:`rows` (unreadable, incomplete, arrays not their own),
        each with its file and reason."""
        self.rows  # noqa: B018 - reading the rows finds them
        return self._damaged

    def ok(self) -> pd.DataFrame:
        df = self.rows
        return df[df["status"] == "ok"] if not df.empty else df

    def is_publication_run(self, key: str) -> bool:
        """True if the run belongs to one of the publication's studies (not a sweep or stress test)."""
        df = self.rows
        if df.empty or "study" not in df:
            return True
        s = df.loc[df["key"] == key, "study"]
        return s.empty or str(s.iloc[0]) in EXPERIMENT_ORDER

    def scene_columns(self) -> list[str]:
        """The columns of :attr:`rows` that are a run's scene (the ``scene_fields`` each row lists),
        in the order of the columns."""
        df = self.rows
        if df.empty or "scene_fields" not in df:
            return []
        named = {f for v in df["scene_fields"].dropna() for f in str(v).split()}
        return [c for c in df.columns if c in named]

    def row(self, key: str) -> pd.Series:
        return self.rows.set_index("key").loc[key]

    # ----------------------------------------------------------------- environment
    @cached_property
    def environment(self) -> dict:
        """Most frequent value of every ``env_*`` field, and every git revision seen."""
        df = self.rows
        out: dict = {}
        if df.empty:
            return out
        for c in sorted(c for c in df.columns if c.startswith("env_")):
            vals = [str(v) for v in df[c].dropna()]
            if vals:
                out[c[4:]] = Counter(vals).most_common(1)[0][0]
        if "env_git_revision" in df:
            out["git_revisions"] = sorted({str(v) for v in df["env_git_revision"].dropna()})
        if "env_code_version" in df:
            out["code_versions"] = sorted({str(v) for v in df["env_code_version"].dropna()})
        return out

    # ----------------------------------------------------------------- tables
    def table_names(self) -> list[str]:
        """The stored tables of the current code version (every one with ``all_versions``)."""
        if not self.tables_dir.is_dir():
            return []
        return sorted(p.stem for p in self.tables_dir.glob("*.csv") if self.all_versions or table_is_current(p))

    @property
    def other_version_tables(self) -> list[str]:
        """Stored tables written by another code version (left out of the report)."""
        if self.all_versions or not self.tables_dir.is_dir():
            return []
        return sorted(p.stem for p in self.tables_dir.glob("*.csv") if not table_is_current(p))

    def table(self, name: str) -> pd.DataFrame | None:
        path = self.tables_dir / f"{name}.csv"
        if not path.exists():
            return None
        if not (self.all_versions or table_is_current(path)):
            return None
        try:
            df = pd.read_csv(path)
        except (pd.errors.EmptyDataError, OSError):
            return None
        return df if not df.empty else None

    # ----------------------------------------------------------------- arrays
    def arrays(self, key: str) -> dict:
        """``X``, ``u``, ``cells`` (and ``cell_volumes``) of a run; empty if not stored."""
        if key not in self._arrays:
            path = self.runs_dir / f"{key}.npz"
            if path.exists():
                with np.load(path) as z:
                    self._arrays[key] = {k: z[k] for k in z.files}
            else:
                self._arrays[key] = {}
        return self._arrays[key]

    def npz_mtime(self, key: str) -> float:
        path = self.runs_dir / f"{key}.npz"
        return path.stat().st_mtime if path.exists() else 0.0

    # ----------------------------------------------------------------- lookup
    def find(self, experiment: str, *, nu=None, mesh=None, deformation=None, angle_deg=None, E=None,
             method=None, law=None, fem=None, study=None, ok_only=True, printed=False) -> pd.DataFrame:
        """Rows matching the given scene parameters: their exact stored values, or with
        ``printed`` values printed by a publication (:func:`printed_match`)."""
        df = self.ok() if ok_only else self.rows
        if df.empty:
            return df
        m = df["experiment"] == experiment
        for col, val in (("nu", nu), ("deformation", deformation), ("angle_deg", angle_deg),
                         ("E", E)):
            if val is not None:
                m &= printed_match(df[col], val) if printed else df[col].astype(float) == float(val)
        if mesh is not None:
            m &= df["mesh"] == mesh
        if method is not None:
            m &= df["method"] == method
        if law is not None:
            m &= df["solver_law"] == law
        if fem is not None:
            m &= df["is_fem"] == bool(fem)
        if study is not None and "study" in df:
            m &= df["study"] == study
        return df[m]

    def reference_law(self, experiment: str, deformation: float = 0.0, angle_deg: float = 0.0) -> str | None:
        """The FEM law the studies compare a scene load with (``tables/reference_laws.csv``)."""
        t = self.table("reference_laws")
        if t is None:
            return None
        m = t[(t["experiment"] == experiment) & (t["deformation"] == float(deformation or 0.0))
              & (t["angle_deg"] == float(angle_deg or 0.0))]
        return None if m.empty else str(m["law"].iloc[0])

    def nus(self, experiment: str | None = None) -> tuple[float, ...]:
        """The Poisson ratios of the stored runs (of an experiment's own study, if given)."""
        df = self.rows
        if df.empty:
            return ()
        if experiment is not None:
            df = df[df["experiment"] == experiment]
            if "study" in df and (df["study"] == experiment).any():
                df = df[df["study"] == experiment]
        return tuple(sorted(float(v) for v in df["nu"].dropna().unique()))

    def reference(self, experiment: str, printed: bool = False, **scene) -> pd.Series | None:
        """The FEM reference run of a scene (law of :meth:`reference_law`, refine 1; ``printed``
        as for :meth:`find`): the experiment's own study's (:func:`own_study_first`) where another
        study solved the scene with another element too."""
        law = self.reference_law(experiment, scene.get("deformation") or 0.0, scene.get("angle_deg") or 0.0)
        if law is None:
            return None
        sub = self.find(experiment, fem=True, law=law, printed=printed, **scene)
        if "solver_refine" in sub:
            sub = sub[sub["solver_refine"].fillna(1).astype(int) == 1]
        sub = own_study_first(sub, experiment)
        return None if sub.empty else sub.iloc[0]

    # ----------------------------------------------------------------- the publications' models
    def published(self, publication: str = "G20") -> pd.DataFrame:
        """The models ``publication`` compares that are registered, as the studies stored them
        (``tables/published_models.csv``: ``name`` in its tables, ``role``, ``model``), in the
        registry's order (``tables/models.csv``)."""
        t = self.table("published_models")
        if t is None:
            return pd.DataFrame(columns=["publication", "name", "role", "description", "model"])
        t = t[(t["publication"] == publication) & t["model"].notna() & (t["model"].astype(str) != "")]
        order = self.model_order()
        return t.assign(_o=t["model"].map(lambda m: order.get(m, 99))).sort_values("_o", kind="stable").drop(
            columns="_o").reset_index(drop=True)

    def published_model(self, role: str, publication: str = "G20") -> str | None:
        """The registered model that plays ``role`` in ``publication`` (None if none)."""
        t = self.published(publication)
        hit = t[t["role"] == role]
        return None if hit.empty else str(hit["model"].iloc[0])

    def published_name(self, model: str | None, publication: str = "G20") -> str | None:
        """The name ``publication``'s tables give ``model`` (None if it reports none)."""
        t = self.published(publication)
        hit = t[t["model"] == model]
        return None if hit.empty else str(hit["name"].iloc[0])

    def in_design(self, variant: str, nu) -> bool:
        """Whether the studies compare ``variant`` at Poisson ratio ``nu`` (``tables/study_variants.csv``;
        True where that table or the variant's model is not listed)."""
        t = self.table("study_variants")
        if t is None or variant not in set(t["variant"]):
            return True
        return bool(((t["variant"] == variant) & (t["nu"] == float(nu))).any())

    def model_order(self) -> dict:
        """Variant name -> listing position of its model (``tables/models.csv``); the variant
        with its model's defaults (named as the model) first."""
        t = self.table("models")
        if t is None:
            return {}
        return {r.variant: (r.variant != r.model, int(r.order)) for r in t.itertuples()}

    def method_order(self, methods) -> list[str]:
        """``methods`` ("<variant> <solver>" and FEM methods): the models' in registry order
        (:meth:`model_order`), then any other, then the FEM's, each sorted."""
        order = self.model_order()

        def key(m: str):
            variant = self.variant(m)
            if self.is_fem(m):
                return (2, (False, 0), m)
            return (0, order[variant], m) if variant in order else (1, (False, 0), m)

        return sorted(methods, key=key)

    def primary_mesh(self, experiment: str) -> str | None:
        """The finest mesh of an experiment's own study in the results (the one the figures show)."""
        sub = self.ok()
        if sub.empty:
            return None
        sub = sub[sub["experiment"] == experiment]
        if "study" in sub and (sub["study"] == experiment).any():
            sub = sub[sub["study"] == experiment]
        if sub.empty:
            return None
        meshes = sorted(sub["mesh"].astype(str).unique(), key=mesh_size)
        return meshes[-1]


def own_study_first(rows: pd.DataFrame, experiment: str) -> pd.DataFrame:
    """``rows`` with those of the experiment's own study first, each part in its stored order, so
    that a pick among runs of one scene from several studies does not depend on the order of
    the stored keys (which hash the code version)."""
    if rows.empty or "study" not in rows:
        return rows
    own = rows["study"] == experiment
    return pd.concat([rows[own], rows[~own]])


def mesh_size(mesh: str) -> int:
    """Number of cells of a mesh label ``"NXxNYxNZ"`` (0 if it is not one)."""
    try:
        return int(np.prod([int(v) for v in str(mesh).split("x")]))
    except ValueError:
        return 0


def run_state(results: Results, experiment: str, method: str, printed: bool = False, **scene) -> str:
    """What a reader sees instead of a number: "missing" if no run of ``method`` is stored for the
    scene, "failed (status, exception)" if every stored one failed (the message is in the failures
    table), "" if one reached a result (``printed``: the scene's values are a publication's, as
    for :meth:`Results.find`); a variant the studies do not compare at the scene's ν
    (``tables/study_variants.csv``, e.g. the E-form at ν = 1/4, the G-form's constants) says so."""
    sub = results.find(experiment, method=method, ok_only=False, printed=printed, **scene)
    if sub.empty and scene.get("nu") is not None and not results.is_fem(method) and \
            not results.in_design(results.variant(method), scene["nu"]):
        return "not in the study at this ν"  # e.g. the E-form at ν = 1/4: the G-form's constants
    if sub.empty:
        return "missing"
    if (sub["status"] == "ok").any():
        return ""
    r = sub.iloc[0]
    exc = re.match(r"^([A-Za-z_]+(?:Error|Exception))\b", str(r.get("message") or "").strip())
    return f"failed ({r['status']}{', ' + exc.group(1) if exc else ''})"


def printed_match(values, value) -> np.ndarray | bool:
    """Whether stored parameter ``values`` are the publication's printed ``value``.

    The publications print rounded parameters (ν = 0.499, d = 0.05, θ = 45°): a stored value
    matches a printed one within ``numpy.isclose``'s default tolerance (relative 1e-5, absolute
    1e-8).  This is the harness's one tolerant match; stored runs are matched with each other by
    their exact stored values."""
    return np.isclose(np.asarray(values, dtype=float), float(value))
