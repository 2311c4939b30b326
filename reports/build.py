"""Assemble the report: figures, renders, tables and VTU files into ``index.html`` (self-contained,
images embedded as base64) and ``report.pdf`` (weasyprint), from a stored results folder.

Figures and renders are cached under ``<out>/.cache`` by a fingerprint of the stored files they
read and of the code that draws them, so restyling the report does not redraw what did not change
and a rebuild from unchanged results takes a few seconds.
"""

from __future__ import annotations

import base64
import datetime as _dt
import hashlib
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from studies.paper.claims import PROTOCOL_FAILURES

from . import figures as figmod
from . import palette
from . import render as rendermod
from . import engines as enginemod
from . import modes as modesmod
from . import dynamics as dynmod
from . import findings, layout, summary, tables, vtu
from .data import Results

TEMPLATES = Path(__file__).parent / "templates"
#: study sections: (id, title, figures, stored tables kept in the HTML only, collapsed)
STUDY_SECTIONS = (
    ("pareto", "Speed against error: which method for which error budget", ("study_budget", "study_budget_explicit", "study_pareto"),
     ("budget", "pareto_front", "pareto_references", "pareto")),
    ("performance", "Performance against the number of volumes (Figs 11, 12)", ("study_performance",),
     ("performance_summary", "performance", "bandwidth")),
    ("stability", "Stability: time step and extreme loads", ("study_stability_map", "study_dt_stability"),
     ("dt_stability", "stability_extreme", "stability", "stability_irregular", "stability_engines")),
    ("damping", "Damping: steps the explicit protocol needs", ("study_damping",), ("damping_steps",)),
    ("limit", "Limit stretch", ("study_limit_stretch",), ("limit_stretch",)),
    ("baudet", "[B09]'s experiments at [B09]'s parameters", ("study_b09",),
     ("baudet_cantilever", "baudet_lshape", "baudet_moduli", "baudet_volume")),
)
#: study figures printed at a third of the page height, so that a section's figures and short table share a page
HALF_FIGURES = {"study_performance", "study_stability_map", "study_dt_stability", "study_damping",
                "study_limit_stretch", "study_b09"}
OPTIONAL_TABLES = tuple(t for *_, names in STUDY_SECTIONS for t in names)
KNOWN_TABLES = {"runs", "table2_compression", "table3_tension", "table4_shear", "table5_torsion", "bending",
                "differences", "eform_check", "moduli", "headline", "claims", *OPTIONAL_TABLES, *enginemod.TABLES,
                *modesmod.TABLES, *dynmod.TABLES}


@dataclass
class Section:
    id: str
    title: str
    intro: str = ""
    items: list = field(default_factory=list)  # ("table", Table) | ("figure", dict)
    screen_only: bool = False


@dataclass
class BuildResult:
    html: Path
    pdf: Path | None
    pages: int
    seconds: float
    figures: int
    tables: dict
    vtu: int
    warnings: list = field(default_factory=list)
    page_text: list = field(default_factory=list)  # text laid out on each PDF page
    page_anchors: list = field(default_factory=list)  # element ids on each PDF page


def _b64(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")


def _fingerprint(results: Results, *modules) -> str:
    """Hash of the stored files (name, size, mtime) and of the given modules' source."""
    h = hashlib.sha256()
    for d in (results.runs_dir, results.tables_dir):
        if d.is_dir():
            for p in sorted(d.iterdir()):
                st = p.stat()
                h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    for m in modules:
        h.update(Path(m.__file__).read_bytes())
    return h.hexdigest()[:20]


def _cached_figures(results: Results, fig_dir: Path, cache: Path, warnings: list) -> dict:
    """matplotlib figures, reused when neither the results nor the drawing code changed."""
    key = _fingerprint(results, figmod, palette)
    manifest = cache / f"figures-{key}.json"
    if manifest.exists():
        data = json.loads(manifest.read_text())
        if all((cache / "figures" / Path(f["path"]).name).exists() for f in data.values()):
            out = {}
            for fid, f in data.items():
                dst = fig_dir / Path(f["path"]).name
                shutil.copyfile(cache / "figures" / dst.name, dst)
                out[fid] = figmod.Figure(fid, f["title"], dst, f["caption"])
            return out
    n_warn = len(warnings)
    figs = figmod.all_figures(results, fig_dir, warnings)
    for name, plot in figmod.STUDY_PLOTS.items():
        t = results.table(name)
        if t is not None:
            try:
                f = plot(t, fig_dir / f"{name}.png")
            except Exception as exc:  # noqa: BLE001 - a table of unexpected shape: table only
                warnings.append(f"no plot of tables/{name}.csv: {type(exc).__name__}: {exc}")
                f = None
            if f is not None:
                figs[f"study_{name}"] = f
    if len(warnings) > n_warn:  # do not cache a partial set
        return figs
    (cache / "figures").mkdir(parents=True, exist_ok=True)
    for f in figs.values():
        shutil.copyfile(f.path, cache / "figures" / f.path.name)
    manifest.write_text(json.dumps({k: {"title": f.title, "path": f.path.name, "caption": f.caption}
                                    for k, f in figs.items()}))
    return figs


def _fig(f, number: str = "") -> dict:
    return {"id": f.id if hasattr(f, "id") else f.path.stem, "title": f.title if hasattr(f, "title") else "",
            "src": _b64(f.path), "caption": f.caption, "number": number, "file": f"figures/{f.path.name}"}


class _Exports:
    """The VTU files of every run and the 3D renders (:func:`reports.render.render_figures`):
    ``start`` forks a process that makes them (``None`` where processes cannot be forked), ``join``
    returns ``(vtu files, renders, warnings)``, made here if no process did (or it failed)."""

    def __init__(self, results: Results, out: Path, fig_dir: Path, render_cache: Path):
        self.results, self.out, self.fig_dir, self.render_cache = results, out, fig_dir, render_cache

    def make(self) -> tuple[list, list, list[str]]:
        vtu_files = vtu.export_all(self.results, self.out / "vtu")
        with palette.models(self.results.table("models")):
            try:
                renders = rendermod.render_figures(self.results, self.fig_dir, self.render_cache)
                return vtu_files, renders, []
            except Exception as exc:  # noqa: BLE001 - e.g. no OpenGL context: the report without renders
                return vtu_files, [], [f"3D renders not made: {type(exc).__name__}: {exc}"]

    def _child(self, conn) -> None:
        try:  # nothing is sent on failure: the parent then makes them itself
            conn.send(self.make())
        finally:
            conn.close()

    def start(self):
        import multiprocessing as mp

        if "fork" not in mp.get_all_start_methods():
            return None
        ctx = mp.get_context("fork")
        recv, send = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=self._child, args=(send,), daemon=True)
        proc.start()
        send.close()
        return proc, recv

    def join(self, side) -> tuple[list, list, list[str]]:
        if side is not None:
            proc, recv = side
            try:
                return recv.recv()
            except EOFError:  # the process failed or died (a crash in VTK): made here instead
                pass
            finally:
                recv.close()
                proc.join()
        return self.make()


def check_out(out_dir) -> None:
    """Raise ``NotADirectoryError``/``PermissionError`` (naming the folder) unless ``out_dir`` is,
    or can be created as, a writable folder with writable ``figures/`` and ``.cache/``: checked
    before any work."""
    p = Path(out_dir).absolute()
    for sub in (p, p / "figures", p / ".cache", p / "vtu"):
        if sub.exists() and not sub.is_dir():
            raise NotADirectoryError(f"--out {out_dir}: {sub} is a file; allowed: a writable folder")
    probe = p
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    if not probe.is_dir():
        raise NotADirectoryError(f"--out {out_dir}: {probe} is not a folder; allowed: a writable folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise PermissionError(f"--out {out_dir}: {probe} is not writable; allowed: a writable folder")


def summary_section(results: Results, head, claims) -> Section:
    """§1: the verdict first (where each method wins, in sentences and one table), the caveats of the
    reproduction, then the claims of the publication and the headline comparison."""
    v = summary.verdict(results)
    subject = results.published_model("proposed")
    paras = summary.verdict_sentences(v, subject) if not v.empty else []
    notes = summary.caveats(results, claims, head)
    intro = "".join(f"<p>{p}</p>" for p in paras)
    if notes:
        intro += "<p><b>Caveats.</b></p><ul class='caveats'>" + "".join(f"<li>{_escape(n)}</li>" for n in notes) + "</ul>"
    s = Section("summary", "Summary: where each method wins", intro)
    if not v.empty:
        s.items.append(("table", summary.verdict_table(v, results.published_model("springs-only"))))
    if not claims.empty:
        s.items += [("table", t) for t in summary.claims_tables(claims)]
    if not head.empty:
        s.items.append(("table", summary.headline_table(head)))
    return s


def _escape(text: str) -> str:
    import html

    return html.escape(str(text), quote=False)


def failures_section(results: Results) -> Section:
    """Runs without a result, and explicit equilibria apart from the static ones (non-unique)."""
    s = Section("failures", "Failures and non-unique equilibria",
                " ".join(p for p in (tables.nonunique_sentence(results), PROTOCOL_FAILURES) if p))
    t = tables.explicit_table(results)
    if t is not None:
        s.items.append(("table", t))
    s.items.append(("table", tables.failures_table(results)))
    return s


def publication_tables_section(results: Results, figs: dict, claims) -> Section:
    """Tables 2–6: each "[G20] beside ours" (at most :data:`reports.tables.MAX_COLUMNS` columns),
    the models [G20] does not list in tables of their own, and their figures; opened by the claims
    they decide."""
    s = Section("tables", "Tables 2–6 of the publication, reproduced",
                summary.claim_findings(claims, "Tables 2, 3", "(Table 4", "(Table 5", "FEM shear force",
                                       "FEM torsion torque", "FEM volume change"))
    for name, exp, number in (("table2_compression", "compression", 2), ("table3_tension", "tension", 3)):
        t = tables.volume_table(results, name, exp, number)
        if t is not None:
            s.items.append(("table", t))
        s.items += [("table", c) for c in tables.competitors_volume_tables(results, name, exp, number)]
    if "fig_e" in figs:
        s.items.append(("figure", _fig(figs["fig_e"])))
    for name, exp, number, load, unit, q in (
            ("table4_shear", "shear", 4, "deformation", "N", "reaction force F_x"),
            ("table5_torsion", "torsion", 5, "angle_deg", "N·m", "reaction torque T_z")):
        t = tables.reaction_table(results, name, exp, number, load, unit, q)
        if t is not None:
            s.items.append(("table", t))
        t = tables.published_reaction_table(results, number)
        if t is not None:
            s.items.append(("table", t))
        s.items += [("table", c) for c in tables.competitors_reaction_tables(results, name, exp, number, load, unit, q)]
    for fid in ("fig_reactions", "fig_torsion_sweep"):
        if fid in figs:
            s.items.append(("figure", _fig(figs[fid])))
    for t in (tables.meshes_table(results), tables.bending_table(results)):
        if t is not None:
            s.items.append(("table", t))
    s.items += [("table", t) for t in tables.bending_others_tables(results)]
    return s


def build(results_dir, out_dir, pdf: bool = True, verbose: bool = False) -> BuildResult:
    t0 = time.perf_counter()
    check_out(out_dir)
    results = Results(results_dir)
    out = Path(out_dir)
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    cache = out / ".cache"
    cache.mkdir(exist_ok=True)

    def log(msg):
        if verbose:
            print(f"[{time.perf_counter() - t0:6.2f} s] {msg}", flush=True)

    warnings: list[str] = []
    warnings += [f"damaged run left out: {d} (run 'hybmss run' again to recompute it)"
                 for d in results.damaged]
    warnings += [f"table {n} was written by another code version and is left out (run the studies again)"
                 for n in results.other_version_tables]
    # the VTU files and the 3D renders are made by a second process while this one draws the
    # matplotlib figures (where processes can be forked; otherwise one after the other)
    job = _Exports(results, out, fig_dir, cache / "renders" / _fingerprint(results, rendermod)[:8])
    side = job.start()
    with palette.models(results.table("models")):  # the models' own plot styles, as stored
        figs = _cached_figures(results, fig_dir, cache, warnings)
    log(f"{len(figs)} figures")
    vtu_files, renders, render_warnings = job.join(side)
    warnings += render_warnings
    log(f"{len(vtu_files)} VTU files")
    log(f"{len(renders)} renders")
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr, flush=True)

    ov = summary.overview(results)
    head = summary.headline(results)
    claims = summary.claims(results)
    sections: list[Section] = []

    sections.append(summary_section(results, head, claims))

    sections.append(publication_tables_section(results, figs, claims))

    if renders:
        s = Section("shapes", "Deformed shapes (Figs 3, 4, 7, 9): where the MSS departs from the FEM",
                    rendermod.largest_differences_sentence(renders))
        for r in renders:
            n = rendermod.FIGURE_NUMBERS.get(r.experiment, "")
            s.items.append(("figure", {"id": r.path.stem, "title": f"{r.experiment.capitalize()}, {r.load} (cf. Fig. {n})",
                                       "src": _b64(r.path), "caption": r.caption, "number": str(n),
                                       "file": f"figures/{r.path.name}"}))
        sections.append(s)

    s = Section("curves", "Cross sections, beam deflection and nodal differences (Figs 5, 8, 10)",
                summary.claim_findings(claims, "middle-layer", "beam deflection", "closer to FEM than"))
    for fid in ("fig8", "fig10"):
        if fid in figs:
            s.items.append(("figure", _fig(figs[fid])))
    t = tables.middle_layer_table(results)
    if t is not None:
        s.items.append(("table", t))
    for fid in ("fig5", "fig_diff"):
        if fid in figs:
            s.items.append(("figure", _fig(figs[fid])))
    t = tables.differences_table(results)
    if t is not None:
        s.items.append(("table", t))
    if s.items:
        sections.append(s)

    present = set(results.table_names())
    for sid, title, fig_ids, names in STUDY_SECTIONS:
        if not present & set(names):
            continue
        intro, short = _finding(sid, results)
        s = Section(f"study_{sid}", title, intro)
        for fid in fig_ids:
            if fid in figs:
                item = _fig(figs[fid])
                if fid in HALF_FIGURES:
                    item["css"] = "study"
                s.items.append(("figure", item))
        if short is not None:
            s.items.append(("table", short))
        if sid == "baudet":
            t = tables.b09_published_table(results)
            if t is not None:
                s.items.append(("table", t))
        for name in names:
            t = tables.stored_table(results, name)
            if t is not None:
                s.items.append(("table", t))
        sections.append(s)
    others = [n for n in results.table_names() if n not in KNOWN_TABLES]
    if others:
        s = Section("study_other", "Other study tables",
                    "Tables written by further studies, as stored (HTML only).", screen_only=True)
        for name in others:
            t = tables.stored_table(results, name)
            if t is not None:
                s.items.append(("table", t))
        sections.append(s)

    sections.append(failures_section(results))

    s = Section("moduli", "Effective moduli and the E-form check",
                summary.claim_findings(claims, "input Young's modulus", "limited to ν = 1/4", "E-form"))
    for t in (tables.moduli_table(results), tables.eform_table(results)):
        if t is not None:
            s.items.append(("table", t))
    if s.items:
        sections.append(s)

    mod = modesmod.section(results, fig_dir)  # natural frequencies (reports/modes.py)
    if mod is not None:
        sections.append(Section("modes", mod[0], mod[1], [(k, _fig(i) if k == "figure" else i) for k, i in mod[2]]))

    dyn = dynmod.section(results, fig_dir)  # released transients (reports/dynamics.py)
    if dyn is not None:
        sections.append(Section("dynamics", dyn[0], dyn[1], [(k, _fig(i) if k == "figure" else i) for k, i in dyn[2]]))

    eng = enginemod.section(results)  # the engines' findings (reports/engines.py)
    if eng is not None:
        sections.append(Section("engines", *eng))

    t = tables.runs_table(results, vtu_files)
    if t is not None:
        sections.append(Section("runs", "All runs and VTU files",
                                "Deformed states as VTU (open in ParaView, Warp By Vector on 'displacement'): "
                                "<code>vtu/&lt;key&gt;.vtu</code> next to this page. This list is not printed.",
                                [("table", t)], screen_only=True))

    _copy_tables(results, out)
    for sec in sections:  # a printed table never runs over a page: its excess rows stay in the HTML
        for kind, item in sec.items:
            if kind == "table" and not item.screen_only:
                tables.cap_printed_rows(item)
    k = 0
    for sec in sections:
        for kind, item in sec.items:
            if kind == "figure":
                k += 1
                item["label"] = f"Figure {k}"
    all_tables = {item.id: item for sec in sections for kind, item in sec.items if kind == "table"}
    generated = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    html = _render_html(results, ov, sections, len(vtu_files), warnings, generated)
    index = out / "index.html"
    index.write_text(html, encoding="utf-8")
    log("index.html")
    pdf_path, pages, texts, anchors = None, 0, [], []
    if pdf:
        pdf_path = out / "report.pdf"
        # the printed page: the HTML without what print hides (screen-only sections, tables and
        # rows), which weasyprint would otherwise parse and style (the full reproduction: ~5e5
        # elements, most of the PDF's time); the PDF depends on it only, so that, the build time
        # stamp aside, an unchanged page reuses it
        printed = _render_html(results, ov, sections, len(vtu_files), warnings, generated, printed=True)
        key = hashlib.sha256(printed.replace(generated, "").encode()).hexdigest()[:20]
        cached_pdf, cached_meta = cache / f"report-{key}.pdf", cache / f"report-{key}.json"
        if cached_pdf.exists() and cached_meta.exists():
            meta = json.loads(cached_meta.read_text())
            pages, texts, anchors = meta["pages"], meta["text"], meta["anchors"]
            shutil.copyfile(cached_pdf, pdf_path)
        else:
            from weasyprint import HTML

            doc = HTML(string=printed, base_url=str(out)).render()
            layout.check_fits(doc)  # a table or figure wider than the page fails the build
            pages = len(doc.pages)
            texts = [_page_text(p) for p in doc.pages]
            anchors = [sorted(p.anchors) for p in doc.pages]
            tmp = out / ".report.pdf.tmp"
            doc.write_pdf(tmp)
            tmp.replace(pdf_path)
            for old in cache.glob("report-*"):
                old.unlink()
            shutil.copyfile(pdf_path, cached_pdf)
            cached_meta.write_text(json.dumps({"pages": pages, "text": texts, "anchors": anchors}))
        log(f"report.pdf ({pages} pages)")
    n_figs = sum(1 for sec in sections for kind, _ in sec.items if kind == "figure")
    return BuildResult(index, pdf_path, pages, time.perf_counter() - t0, n_figs, all_tables, len(vtu_files),
                       warnings, texts, anchors)


def _copy_tables(results: Results, out: Path) -> None:
    """The stored tables next to the page (``tables/<name>.csv``), for the links of the HTML."""
    dst = out / "tables"
    dst.mkdir(parents=True, exist_ok=True)
    for name in results.table_names():
        shutil.copyfile(results.tables_dir / f"{name}.csv", dst / f"{name}.csv")


def _finding(sid: str, results: Results):
    """(answer in one or two sentences, short table or None) of a study section."""
    if sid == "pareto":
        return (findings.budget_sentence(findings.budget_answers(results.table("budget")))
                + figmod.no_result_note(figmod.no_result_count(results.table("pareto")))), None
    if sid == "performance":
        return (findings.performance_sentence(results.table("performance_summary")),
                tables.performance_short(results))
    if sid == "stability":
        return findings.stability_sentence(results.table("stability_extreme"), results.table("dt_stability"),
                                           results.published_model("proposed")), None
    if sid == "damping":
        return findings.damping_sentence(results.table("damping_steps")), tables.damping_short(results)
    if sid == "limit":
        return findings.limit_sentence(results.table("limit_stretch")), None
    if sid == "baudet":
        f = findings.b09_frame(results.table("baudet_cantilever"), results.table("baudet_lshape"),
                               tables.paper_table("b09_errors"))
        norm = tables.b09_normalisation(f) if not f.empty else f
        return findings.b09_sentence(f) + " " + tables.b09_sd_sentence(norm), tables.b09_table(results)
    return "", None


def _page_text(page) -> str:
    """Text of the boxes laid out on one weasyprint page (empty if the layout tree is unavailable)."""
    parts = []

    def walk(box):
        t = getattr(box, "text", None)
        if isinstance(t, str):
            parts.append(t)
        for c in getattr(box, "children", None) or ():
            walk(c)

    root = getattr(page, "_page_box", None)
    if root is not None:
        walk(root)
    return " ".join(parts)


def _render_html(results: Results, ov: dict, sections: list, n_vtu: int, warnings: list, generated: str,
                 printed: bool = False) -> str:
    """The page (``printed``: without the screen-only sections, tables and rows, for the PDF)."""
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)),
                             autoescape=jinja2.select_autoescape(["html", "j2"]), trim_blocks=True,
                             lstrip_blocks=True)
    env.filters["duration"] = _duration
    css = (TEMPLATES / "report.css").read_text()
    return env.get_template("report.html.j2").render(
        title="hybmss: reproduction of the hybrid 3D mass-spring system of Golec et al. [G20]",
        generated=generated,
        results_dir=str(results.root), ov=ov, sections=sections, css=css, n_vtu=n_vtu, warnings=warnings,
        thresholds=summary.thresholds(), printed=printed)


def _duration(s) -> str:
    s = float(s)
    if s < 60:
        return f"{s:.1f} s"
    if s < 3600:
        return f"{s / 60:.1f} min ({s:.0f} s)"
    return f"{s / 3600:.2f} h ({s:.0f} s)"
