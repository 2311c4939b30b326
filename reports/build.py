"""Assemble the report: figures, renders, tables and VTU files into ``index.html`` (self-contained,
images embedded as base64) and ``report.pdf`` (weasyprint), from a stored results folder.

Figures and renders are cached under ``<out>/.cache`` by a fingerprint of the stored files they
read and of the code that draws them, so restyling the report does not redraw what did not change
and a rebuild from unchanged results takes a few seconds.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from . import engines as enginemod
from . import figures as figmod
from . import layout, palette, plots, study_figures, tables, vtu
from . import dynamics as dynmod
from . import modes as modesmod
from . import render as rendermod
from .data import DERIVED_TABLES, Results, thresholds
from .sections import curves, failures, moduli, publication, runs, shapes, summary
from .sections import studies as study_sections
from .sections.base import Context, Section, from_parts
from .sections.studies import STUDY_SECTIONS

TEMPLATES = Path(__file__).parent / "templates"
OPTIONAL_TABLES = tuple(t for *_, names in STUDY_SECTIONS for t in names)
#: the stored tables the sections show (any other is listed as stored, in "Other study tables");
#: the tables derived for the report are shown by the sections that read them
KNOWN_TABLES = {"runs", "table2_compression", "table3_tension", "table4_shear", "table5_torsion", "bending",
                "differences", "eform_check", "moduli", "headline", "claims", *OPTIONAL_TABLES, *enginemod.TABLES,
                *modesmod.TABLES, *dynmod.TABLES, *(set(DERIVED_TABLES) - {"equilibria"})}


def _modes(ctx: Context) -> Section | None:
    """Natural frequencies (:mod:`reports.modes`)."""
    return from_parts("modes", modesmod.section(ctx.results, ctx.fig_dir))


def _dynamics(ctx: Context) -> Section | None:
    """Released transients (:mod:`reports.dynamics`)."""
    return from_parts("dynamics", dynmod.section(ctx.results, ctx.fig_dir))


def _engines(ctx: Context) -> Section | None:
    """The engines' findings (:mod:`reports.engines`)."""
    return from_parts("engines", enginemod.section(ctx.results))


def _others(ctx: Context) -> Section | None:
    return study_sections.others(ctx, KNOWN_TABLES)


#: the report's sections, in order: each a function of the build's :class:`Context` that returns a
#: :class:`Section`, a list of them, or None (a section the results do not give)
SECTIONS = (summary.section, publication.section, shapes.section, curves.section, study_sections.sections, _others,
            failures.section, moduli.section, _modes, _dynamics, _engines, runs.section)


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
    key = _fingerprint(results, figmod, study_figures, plots, palette)
    manifest = cache / f"figures-{key}.json"
    if manifest.exists():
        data = json.loads(manifest.read_text())
        if all((cache / "figures" / Path(f["path"]).name).exists() for f in data.values()):
            out = {}
            for fid, f in data.items():
                dst = fig_dir / Path(f["path"]).name
                shutil.copyfile(cache / "figures" / dst.name, dst)
                out[fid] = plots.Figure(fid, f["title"], dst, f["caption"])
            return out
    n_warn = len(warnings)
    figs = figmod.all_figures(results, fig_dir, warnings)
    for name, plot in study_figures.STUDY_PLOTS.items():
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

    ctx = Context(results, figs, renders, vtu_files, summary.headline(results), summary.claims(results), fig_dir)
    sections = sections_of(ctx)
    _copy_tables(results, out)
    all_tables = _finish(sections)
    generated = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    page = partial(_render_html, results, summary.overview(results), sections, len(vtu_files), warnings, generated)
    index = out / "index.html"
    index.write_text(page(), encoding="utf-8")
    log("index.html")
    pdf_path, pages, texts, anchors = None, 0, [], []
    if pdf:
        pdf_path = out / "report.pdf"
        pages, texts, anchors = _write_pdf(page(printed=True), generated, out, cache, pdf_path)
        log(f"report.pdf ({pages} pages)")
    n_figs = sum(1 for sec in sections for kind, _ in sec.items if kind == "figure")
    return BuildResult(index, pdf_path, pages, time.perf_counter() - t0, n_figs, all_tables, len(vtu_files),
                       warnings, texts, anchors)


def sections_of(ctx: Context) -> list[Section]:
    """The sections of :data:`SECTIONS`, in order, that the results give."""
    out: list[Section] = []
    for make in SECTIONS:
        made = make(ctx)
        out += made if isinstance(made, list) else [made] if made is not None else []
    return out


def _finish(sections: list[Section]) -> dict:
    """Cap the printed tables and number the figures of ``sections``; their tables by id."""
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
    return {item.id: item for sec in sections for kind, item in sec.items if kind == "table"}


def _write_pdf(printed: str, generated: str, out: Path, cache: Path, pdf_path: Path) -> tuple[int, list, list]:
    """Write ``pdf_path`` from the printed page (the HTML without what print hides: screen-only
    sections, tables and rows, which weasyprint would otherwise parse and style: the full
    reproduction's ~5e5 elements, most of the PDF's time); the PDF depends on it only, so that,
    the build time stamp aside, an unchanged page reuses the cached one.  (pages, text laid out on
    each page, element ids on each page)."""
    key = hashlib.sha256(printed.replace(generated, "").encode()).hexdigest()[:20]
    cached_pdf, cached_meta = cache / f"report-{key}.pdf", cache / f"report-{key}.json"
    if cached_pdf.exists() and cached_meta.exists():
        meta = json.loads(cached_meta.read_text())
        shutil.copyfile(cached_pdf, pdf_path)
        return meta["pages"], meta["text"], meta["anchors"]
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
    return pages, texts, anchors


def _copy_tables(results: Results, out: Path) -> None:
    """The stored tables next to the page (``tables/<name>.csv``), for the links of the HTML."""
    dst = out / "tables"
    dst.mkdir(parents=True, exist_ok=True)
    for name in results.table_names():
        shutil.copyfile(results.tables_dir / f"{name}.csv", dst / f"{name}.csv")


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
        thresholds=thresholds(), printed=printed)


def _duration(s) -> str:
    s = float(s)
    if s < 60:
        return f"{s:.1f} s"
    if s < 3600:
        return f"{s / 60:.1f} min ({s:.0f} s)"
    return f"{s / 3600:.2f} h ({s:.0f} s)"
