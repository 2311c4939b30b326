"""The report: built from a small results set generated here (static MSS and linear FEM runs on
2×2×2 cubes and 2×2×6 beams), then checked as a reader would: the HTML parses, every image is
embedded and not flat, the PDF has the expected pages and text, every table has its rows."""

from __future__ import annotations

import base64
import functools
import io
import itertools
import re
import zlib
from html.parser import HTMLParser

import numpy as np
import pandas as pd
import pytest

from studies.paper import baudet

NUS = (0.0, 0.25, 0.499)


def _tasks():
    from studies.sweep.runner import SolverSpec, Task
    from studies.sweep.scenes import SceneSpec

    static = SolverSpec("static")
    hex1 = SolverSpec("fem", element="hex1", law="linear")
    tasks = []
    scenes = {"compression": dict(mesh=(2, 2, 2), deformation=0.05), "shear": dict(mesh=(2, 2, 2), deformation=0.05),
              "torsion": dict(mesh=(2, 2, 2), angle_deg=1.0), "tension": dict(mesh=(2, 2, 6), deformation=0.05)}
    for (exp, kw), nu in itertools.product(scenes.items(), NUS):
        spec = SceneSpec.default(exp, nu=nu, **kw)
        for model in ("hybmss", "hybmss-fd"):
            tasks.append(Task(spec.replace(model=model), static, exp))
        tasks.append(Task(spec, hex1, exp))
    # the publication's explicit protocol (NumPy kernel: nothing to compile); it ends at rest, so
    # its run counts among the differences against the FEM
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, deformation=0.05, damping=2.0)
    tasks.append(Task(spec, SolverSpec("explicit", dt=1e-3, steps=10_000, ramp_time=1.0, kernel="numpy"), "compression"))
    for E in (1e7, 2e6):
        spec = SceneSpec.default("bending", mesh=(2, 2, 6), E=E, nu=0.25, gravity=10.0)
        for model in ("hybmss", "hybmss-fd"):
            tasks.append(Task(spec.replace(model=model), static, "bending"))
        tasks.append(Task(spec, SolverSpec("fem", element="hex2", law="linear"), "bending"))
    return tasks


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A results folder with the real layout, one failed run and a performance table."""
    from studies.sweep.runner import run_tasks
    from studies.sweep.store import Store
    import studies.paper.tables as studies_tables

    root = tmp_path_factory.mktemp("results")
    store = Store(root)
    tasks = _tasks()
    run_tasks(tasks, store, jobs=1, progress=False)
    # a failed run, stored the way the runner stores one
    row = store.row(tasks[0].key())
    row.update(key="f" * 24, status="diverged", message="ExplicitDivergenceError: |v| > 1e6 m/s at step 812",
               solver="mss-explicit", label=row["label"] + " (explicit)")
    for k in ("force_x", "force_y", "force_z"):  # e and max|u| stay: a failed run's last state, never a result
        row.pop(k, None)
    store.save(row["key"], row)
    with pytest.MonkeyPatch.context() as mp:  # moduli at three ν keep the test short
        mp.setattr(studies_tables, "moduli_table", functools.partial(studies_tables.moduli_table, nus=NUS))
        studies_tables.write_tables(store)
    # [B09]'s two experiments on their coarsest mesh, every model, against a Hex2 solve twice as fine
    from studies.paper import baudet

    store.write_table("baudet_cantilever", baudet._experiment(baudet.cantilever_scene, (1,), 2, 1, False, "c"))
    store.write_table("baudet_lshape", baudet._experiment(baudet.lshape_scene, (2,), 4, 2, False, "l"))
    store.write_table("performance", pd.DataFrame({
        "variant": ["hybmss-fd", "hybmss", "hybmss-fd", "hybmss"], "volumes": [1000, 1000, 8000, 8000],
        "time_1000_steps_s": [0.1, 0.2, 0.8, 1.7]}))
    # the performance study's summary as it stores it (ratios to [G20]'s baseline, the publication's beside)
    store.write_table("performance_summary", pd.DataFrame({
        "scene": "compression", "mesh": ["10x10x10"] * 3 + ["20x20x20"] * 3, "threads": 1,
        "volumes": [1000] * 3 + [8000] * 3, "variant": ["hybmss-fd", "hybmss-cf", "hybmss"] * 2, "nu": 0.3,
        "label": ["hybmss-fd ν=0.3", "hybmss-cf ν=0.3", "hybmss ν=0.3"] * 2,
        "per_step_us": [100.0, 150.0, 200.0, 800.0, 1150.0, 1700.0], "baseline": "hybmss-fd",
        "ratio_to_baseline": [1.0, 1.5, 2.0, 1.0, 1.44, 2.12], "paper_ratio_to_baseline": [np.nan, 1.4, 2.1] * 2,
        "springs_only": "hybmss-cf", "ratio_to_springs_only": [0.67, 1.0, 1.33, 0.7, 1.0, 1.48], "noise": 0.01}))
    from studies.paper.claims import write_claims

    write_claims(store)  # as the reproduction does once every study wrote its tables
    return root


@pytest.fixture(scope="module")
def report(results, tmp_path_factory):
    from reports.build import build

    out = tmp_path_factory.mktemp("report")
    return build(results, out), out


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs, self.tables, self.links = [], {}, []
        self._table, self._in_tbody = None, False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a.get("src", ""))
        elif tag == "a":
            self.links.append(a.get("href", ""))
        elif tag == "table" and "id" in a:
            self._table = a["id"]
            self.tables[self._table] = {"declared": a.get("data-rows"), "rows": 0}
        elif tag == "tbody":
            self._in_tbody = True
        elif tag == "tr" and self._in_tbody and self._table:
            self.tables[self._table]["rows"] += 1

    def handle_endtag(self, tag):
        if tag == "tbody":
            self._in_tbody = False
        elif tag == "table":
            self._table = None


def _parse(path) -> _Page:
    p = _Page()
    p.feed(path.read_text(encoding="utf-8"))
    p.close()
    return p


def _pdf_pages(data: bytes) -> int:
    """Page objects of a PDF, looking into compressed object streams too."""
    n = len(re.findall(rb"/Type\s*/Page(?![a-zA-Z])", data))
    for m in re.finditer(rb"stream\r?\n(.*?)\r?\nendstream", data, re.S):
        try:
            n += len(re.findall(rb"/Type\s*/Page(?![a-zA-Z])", zlib.decompress(m.group(1))))
        except zlib.error:
            pass
    return n


@pytest.mark.slow
def test_html_parses_and_images_are_embedded_and_not_blank(report):
    from PIL import Image

    res, out = report
    assert res.warnings == []
    page = _parse(res.html)
    assert len(page.imgs) == res.figures >= 10  # 5 matplotlib figures, 4 render grids, performance
    for src in page.imgs:
        assert src.startswith("data:image/png;base64,"), src[:40]
        img = Image.open(io.BytesIO(base64.b64decode(src.split(",", 1)[1]))).convert("RGB")
        a = np.asarray(img)[::3, ::3].astype(np.int64)
        colours = np.unique(a[..., 0] * 65536 + a[..., 1] * 256 + a[..., 2])
        assert len(colours) > 8
        assert a.std() > 5.0
    assert not any(src.startswith(("http", "file:", "/")) for src in page.imgs)


@pytest.mark.slow
def test_every_table_has_its_rows(report, results):
    res, _ = report
    page = _parse(res.html)
    for tid, t in page.tables.items():
        if t["declared"] is not None:
            assert t["rows"] == int(t["declared"]), tid
    csv = {name: pd.read_csv(results / "tables" / f"{name}.csv") for name in
           ("table2_compression", "table3_tension", "table4_shear", "table5_torsion", "bending", "differences",
            "moduli", "eform_check")}
    expect = {"table2": len(csv["table2_compression"]), "table3": len(csv["table3_tension"]),
              "table4": len(csv["table4_shear"]), "table5": len(csv["table5_torsion"]),
              "table_bending": len(csv["bending"]), "table_diff": len(csv["differences"]),
              "table_moduli": len(csv["moduli"]), "table_eform": len(csv["eform_check"]),
              "table6": 8, "table_failures": 1, "table_performance": 4,
              "table_explicit": 2,  # the short run and the stored divergence
              "table_runs": len(list((results / "runs").glob("*.json"))),
              # compression, tension, shear, torsion at 3 ν and one load each, bending at 2 E
              "table_headline": 4 * 3 + 2}
    assert len(csv["table2_compression"]) == 3 and len(csv["differences"]) == 25
    for tid, n in expect.items():
        assert tid in page.tables, tid
        assert page.tables[tid]["rows"] == n, (tid, page.tables[tid]["rows"], n)
    assert page.tables["table_claims"]["rows"] >= 8
    assert "table_pareto" not in page.tables and "table_stability" not in page.tables


@pytest.mark.slow
def test_pdf_pages_and_text(report):
    res, out = report
    data = (out / "report.pdf").read_bytes()
    assert data.startswith(b"%PDF")
    assert _pdf_pages(data) == res.pages
    # cover + contents + one section a page at least; the list of runs is not printed
    assert res.pages >= 9
    text = " ".join(res.page_text)
    for needle in ("Summary", "Table 2 beside [G20]: compression", "Table 3 beside [G20]: tension", "Table 4: shear",
                   "Table 5: torsion", "Table 2, other models", "Where each method wins",
                   "Table 6: meshes", "Deformed shapes", "Euler", "Runs that did not reach a result", "diverged",
                   "Explicit protocol against the static equilibrium",
                   "ExplicitDivergenceError", "Effective moduli", "E-form check", "Performance", "reproduced"):
        assert needle in text, needle
    assert "All runs and VTU files" not in " ".join(res.page_text[2:])
    anchors = {a for page in res.page_anchors for a in page}
    assert {"summary", "table2", "table3", "table4", "table5", "table6", "failures", "moduli"} <= anchors
    assert "runs" not in anchors


@pytest.mark.slow
def test_vtu_files_open_with_fields(report, results):
    import meshio

    res, out = report
    page = _parse(res.html)
    vtus = [h for h in page.links if h.endswith(".vtu")]
    assert len(vtus) == res.vtu == len(list((results / "runs").glob("*.npz")))
    m = meshio.read(out / vtus[0])
    assert {"displacement", "displacement_magnitude"} <= set(m.point_data)
    dv = m.cell_data["relative_volume_change"][0]
    assert np.all(np.isfinite(dv)) and np.abs(dv).max() < 0.5


@pytest.mark.slow
def test_summary_derives_verdicts_from_the_data(results):
    from reports.data import Results
    from studies.paper.claims import REPRODUCED, claims, headline

    r = Results(results)
    h = headline(r)
    cl = {c.statement: c for c in claims(r, h)}
    moduli = next(c for s, c in cl.items() if s.startswith("hybmss and hybmss-fd have the input"))
    assert moduli.verdict == REPRODUCED
    runs_ok = next(c for s, c in cl.items() if s.startswith("The publication's scenes run"))
    assert runs_ok.verdict != REPRODUCED and "diverged" in runs_ok.evidence
    comp = h[(h["experiment"] == "compression") & np.isclose(h["nu"], 0.25)].iloc[0]
    assert comp["paper_mss"] == pytest.approx(3.17) and comp["fem"] > 0


@pytest.mark.slow
def test_rebuild_reuses_cached_figures(report, results, monkeypatch):
    """A rebuild from unchanged results and drawing code copies the cached figures: drawing them
    again would fail here."""
    from reports import build as buildmod

    res, out = report

    def redraw(*args, **kwargs):
        raise AssertionError("figures redrawn although the results and the drawing code did not change")

    monkeypatch.setattr(buildmod.figmod, "all_figures", redraw)
    again = buildmod.build(results, out, pdf=False)
    assert again.figures == res.figures


def test_cli_reports_missing_results(tmp_path, capsys):
    from reports.__main__ import main

    assert main(["build", "--results", str(tmp_path / "none"), "--out", str(tmp_path / "out")]) == 2
    assert "no results" in capsys.readouterr().err


def test_cell_volume_change_of_a_stretched_lattice():
    from reports.vtu import averaged_edge_volumes, relative_volume_change

    g = np.arange(3, dtype=float)
    X = np.array([[x, y, z] for z in g for y in g for x in g])  # particle i + 3j + 9k
    cells = np.array([[i + 3 * j + 9 * k + di + 3 * dj + 9 * dk for dk in (0, 1) for dj in (0, 1) for di in (0, 1)]
                      for k in range(2) for j in range(2) for i in range(2)])
    assert averaged_edge_volumes(X, cells) == pytest.approx(np.ones(8))
    u = X * np.array([0.1, 0.0, -0.2])
    assert relative_volume_change({"X": X, "u": u, "cells": cells}) == pytest.approx(np.full(8, 1.1 * 0.8 - 1))


@pytest.mark.parametrize("method, family", [
    ("hybmss static", "hybmss"), ("hybmss-fd explicit", "hybmss-fd"), ("hybmss (E-form) static", "hybmss (E-form)"),
    ("fem-auto-neo-hookean", "fem-neo-hookean"), ("fem-hex2-linear", "fem-linear"), ("paper hybmss", "paper"),
    ("Euler-Bernoulli", "Euler-Bernoulli")])
def test_one_colour_per_model(method, family):
    from reports import palette
    from studies.paper.tables import models_table

    with palette.models(models_table()) as styles:
        assert palette.family(method) == family
        assert palette.color(method) == (palette.COLORS[family] if family in palette.COLORS else styles[family][0])


def test_unknown_model_is_not_coloured_as_another():
    """A method of no stored model gets the neutral 'other' style, never a model's colour."""
    from reports import palette
    from studies.paper.tables import models_table

    with palette.models(models_table()) as styles:
        assert palette.family("hybmss-xyz static") == palette.OTHER
        assert palette.color("hybmss-xyz static") not in {c for c, _, _ in styles.values()}
        assert palette.family("hybmss static") == "hybmss"
    assert palette.family("hybmss static") == palette.OTHER  # outside the block: no stored styles


@pytest.mark.slow
def test_the_command_reads_results_only(report, results):
    """``python -m reports build`` in a fresh interpreter: no solver module is imported."""
    import subprocess
    import sys

    res, out = report
    code = ("import sys; from reports.__main__ import main; rc = main(['build', '--results', sys.argv[1], '--out', "
            "sys.argv[2], '--no-pdf', '--quiet']); "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('hybmss', 'fem_reference', 'skfem', 'numba')]; "
            "print('SOLVERS', bad); sys.exit(rc)")
    p = subprocess.run([sys.executable, "-c", code, str(results), str(out)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    assert "SOLVERS []" in p.stdout


# ------------------------------------------------------------------ the publication's numbers beside ours
def _visible_text(html: str) -> str:
    """The text a reader sees in the HTML page (no attributes, no embedded images, no style)."""
    class P(HTMLParser):
        def __init__(self):
            super().__init__()
            self.parts, self._skip = [], 0

        def handle_starttag(self, tag, attrs):
            self._skip += tag in ("style", "script")

        def handle_endtag(self, tag):
            self._skip -= tag in ("style", "script")

        def handle_data(self, data):
            if not self._skip:
                self.parts.append(data)

    p = P()
    p.feed(html)
    return " ".join(p.parts)


@pytest.mark.slow
def test_new_tables_have_their_rows_and_published_columns(report):
    from studies.paper.values import load

    res, _ = report
    page = _parse(res.html)
    expect = {"table4_g20": len(load("g20_table4_shear")), "table5_g20": len(load("g20_table5_torsion")),
              "table_middle_layer": len(load("g20_middle_layer")),
              # [B09]: every model of the studies on the cantilever 4x1x1 and the L-shape 2x2x2
              "table_b09": 2 * len(baudet.error_models())}
    assert expect == {"table4_g20": 2, "table5_g20": 2, "table_middle_layer": 6,
                      "table_b09": 2 * len(baudet.error_models())}
    for tid, n in expect.items():
        assert page.tables[tid]["rows"] == n, tid
    t4 = res.tables["table4_g20"]
    assert "hybmss [G20] (N)" in t4.columns and "FEM [G20] (N)" in t4.columns
    assert [r[t4.columns.index("hybmss [G20] (N)")][0] for r in t4.rows] == ["3396", "1.460e+04"] or \
        [r[t4.columns.index("hybmss [G20] (N)")][0] for r in t4.rows] == ["3396", "14600"]
    head = res.tables["table_headline"]
    g = head.columns.index("[G20] hybmss")
    shear = [r for r in head.rows if r[0][0] == "shear" and r[2][0] == "0.25"]
    assert [r[g][0] for r in shear] == ["3396"]  # [G20] Table 4 in the headline, where it publishes a value
    assert all(r[g][0] == "–" for r in head.rows if r[0][0] == "shear" and r[2][0] != "0.25")
    t5 = res.tables["table5_g20"]
    assert [r[t5.columns.index("load here")][0] for r in t5.rows] == ["θ = 1°", "θ = 45°"]
    ml = res.tables["table_middle_layer"]
    col = ml.columns.index("[G20] (m)")
    assert [r[col][0] for r in ml.rows] == ["0.042", "0.013", "0.019", "0.064", "0.03", "0.008"]
    # the fixture has no 20 % shear run and no 45° torsion: every row says so instead of a number
    assert all(r[col + 1][0] == "missing" for r in ml.rows)
    b = res.tables["table_b09"]
    m = b.columns.index("[B09] M")
    rows = {(r[0][0], r[1][0], r[2][0]): r for r in b.rows}
    assert rows[("cantilever", "4x1x1", "baudet2009")][m][0] == "16.3"
    assert rows[("L-shape", "2x2x2", "baudet2009")][m][0] == "6.99"
    ours = b.columns.index("ours M")
    assert all(float(r[ours][0]) > 0 for r in b.rows if r[ours][0] not in ("–",) and not r[ours][0].startswith("failed"))


@pytest.mark.slow
def test_no_nan_reaches_a_reader(report):
    res, _ = report
    text = _visible_text(res.html.read_text(encoding="utf-8"))
    assert not re.search(r"\bnan\b", text, re.I)
    assert not re.search(r"\bnan\b", " ".join(res.page_text), re.I)


@pytest.mark.slow
def test_no_study_section_prints_a_stored_table(report):
    from reports.build import STUDY_SECTIONS

    res, _ = report
    printed = {a for page in res.page_anchors for a in page}
    stored = {f"table_{name}" for *_, names in STUDY_SECTIONS for name in names}
    assert "table_performance" in res.tables  # the fixture's performance table is in the HTML ...
    assert res.tables["table_performance"].csv == "tables/performance.csv"
    assert not printed & stored  # ... and no stored study table is in the PDF
    assert "as stored by the study" not in " ".join(res.page_text)
    assert "study_performance" in printed and "table_b09" in printed  # the sections and their short tables are


@pytest.mark.slow
def test_every_printed_table_fits_one_page(report):
    res, _ = report
    norm = [" ".join(t.split()) for t in res.page_text]
    checked = 0
    for tid, t in res.tables.items():
        pages = [i for i, a in enumerate(res.page_anchors) if tid in a]
        if t.screen_only or not pages:
            continue
        start = " ".join(t.caption.split())[:40]
        assert start in norm[pages[0]], (tid, pages[0])  # the caption, below the table, on the table's page
        checked += 1
    assert checked >= 10


def test_a_table_longer_than_a_page_is_not_printed_in_part():
    """No dump of the first rows: a long table stays whole in the HTML page, the PDF says where."""
    from reports.tables import PRINT_ROWS, Table, cap_printed_rows

    t = Table("t", "t", "caption.", ["a"], [[(str(i), "")] for i in range(PRINT_ROWS + 7)])
    cap_printed_rows(t)
    assert t.screen_only and not t.row_classes
    assert f"{PRINT_ROWS + 7} rows" in t.print_note and "HTML" in t.print_note
    short = Table("s", "s", "caption.", ["a"], [[(str(i), "")] for i in range(PRINT_ROWS)])
    assert not cap_printed_rows(short).screen_only and not short.print_note


@pytest.mark.slow
def test_a_failed_run_shows_no_value(report):
    """The list of runs (HTML) shows '–' for the volume change and displacement of every run that
    did not reach a result; the fixture's diverged run is one."""
    res, _ = report
    t = res.tables["table_runs"]
    status, e, u = (t.columns.index(c) for c in ("status", "signed e (%)", "max |u| (m)"))
    failed = [r for r in t.rows if r[status][0] != "ok"]
    assert failed, "the fixture stores a diverged run"
    assert all(r[e][0] == "–" and r[u][0] == "–" for r in failed)
    assert all(r[e][0] != "–" for r in t.rows if r[status][0] == "ok")
    ex = res.tables["table_explicit"]
    shown = [r[i] for r in ex.rows if r[5][0] == "diverged" for i in (6, 8, 9, 10)]  # not 7: the static twin's e
    assert shown and all(c[0] == "–" for c in shown)


STATUS_HEADERS = ("status", "state", "at_rest", "answer")
"""Columns that say whether a row's run reached a result."""
RESULT_TEXT = ("ok", "converged", "inverted", "yes", "fastest", "meets no budget", "", "–")
"""Their texts for a result ('inverted': an equilibrium with inverted cells is one); a material
whose measured moduli are outside the stable range ('unstable material ...') is a result too."""
VALUE_HEADER = re.compile(r"error|err_|rel|signed e|e explicit|Δ|‖|\|u\||speed|time(?!_repeats)|_s$|disp|force|volume|_eff"
                          r"|value|cost|deflection|_pct|per_step|spread|^de_", re.I)
"""Columns that hold a measure of the row's own run (not the count of its timed repeats)."""
OTHER_RUN = re.compile(r"fem|static|ref|paper|g20|b09|quantity", re.I)
"""Columns of another run beside it (the reference, the static twin, the publication) or names."""


def _no_result(text: str) -> bool:
    t = text.strip()
    return t not in RESULT_TEXT and not t.startswith("unstable material")


def _number(text: str) -> bool:
    try:
        float(text.replace("−", "-").replace("×", "").replace("%", "").strip())
    except ValueError:
        return False
    return True


def values_of_no_result(tables) -> list:
    """(table, header, text) of every number shown in a measure column of a row whose run reached
    no result (status, state, at_rest or answer says so)."""
    shown = []
    for tid, t in tables.items():
        status = [i for i, c in enumerate(t.columns) if c.strip().lower() in STATUS_HEADERS]
        values = [i for i, c in enumerate(t.columns) if VALUE_HEADER.search(c) and not OTHER_RUN.search(c)]
        for r in t.rows:
            if any(_no_result(r[i][0]) for i in status):
                shown += [(tid, t.columns[i], r[i][0]) for i in values if _number(r[i][0])]
    return shown


@pytest.mark.slow
def test_no_table_shows_a_value_of_a_run_without_result(report):
    """Every table of the page (HTML, the PDF's included) with a status column: a row whose run
    reached no result (not at rest, diverged, unstable, no result) shows '–' in every column that
    measures its own run; the fixture's diverged run and the engines' unstable moduli are such rows."""
    res, _ = report
    checked = [tid for tid, t in res.tables.items() if any(c.strip().lower() in STATUS_HEADERS for c in t.columns)
               and any(_no_result(r[i][0]) for r in t.rows for i, c in enumerate(t.columns)
                       if c.strip().lower() in STATUS_HEADERS)]
    assert {"table_runs", "table_explicit", "table_moduli"} <= set(checked), checked
    assert values_of_no_result(res.tables) == []


def test_the_check_of_values_without_result_sees_one():
    """The check above on a table made here: a diverged run's time and a pareto row not at rest
    with an error are found; the reference's value beside them and an ok row are not."""
    from reports.tables import Table

    t = Table("t", "t", "c.", ["scene", "status", "time (s)", "e static (%)", "error_field", "at_rest"],
              [[("a", ""), ("diverged", ""), ("0.025", ""), ("4.9", ""), ("–", ""), ("", "")],
               [("b", ""), ("ok", ""), ("0.5", ""), ("4.9", ""), ("0.01", ""), ("yes", "")],
               [("c", ""), ("not-converged", ""), ("–", ""), ("4.9", ""), ("0.02", ""), ("no", "")]])
    assert values_of_no_result({"t": t}) == [("t", "time (s)", "0.025"), ("t", "error_field", "0.02")]


@pytest.mark.slow
def test_a_failed_run_reads_failed_with_its_reason(report):
    res, _ = report
    t = res.tables["table_explicit"]
    assert any(r[5][0] == "diverged" for r in t.rows)
    fail = res.tables["table_failures"]
    assert any("ExplicitDivergenceError" in c[0] for r in fail.rows for c in r)


def _runs(rows):
    base = {"experiment": "compression", "solver": "mss-static", "study": "compression", "mesh": "4x4x4",
            "message": ""}
    return pd.DataFrame([{**base, **r} for r in rows])


def test_eform_check_never_borrows_the_g_form_value():
    from studies.paper.tables import eform_check

    rows = []
    for model in ("hybmss", "hybmss-fd"):
        for nu, d in ((0.0, 0.20), (0.0, 0.05), (0.25, 0.05)):
            rows.append(dict(model=model, nu=nu, deformation=d, e_form=False, status="ok",
                             volume_change=-0.1843))
        rows.append(dict(model=model, nu=0.0, deformation=0.20, e_form=True,
                         status="unstable", volume_change=np.nan, message="StaticSolveError: limit point"))
    out = eform_check(_runs(rows))
    comp = out[out["experiment"] == "compression"]
    bad = comp[np.isclose(comp["nu"], 0.0) & np.isclose(comp["deformation"], 0.20)]
    assert len(bad) == 2
    assert bad["E_form_pct"].isna().all() and bad["G_form_pct"].eq(18.43).all()
    assert bad["E_form_state"].str.startswith("failed (unstable").all()
    assert bad["closer"].str.startswith("undecided").all() and not bad["decisive"].any()
    miss = comp[np.isclose(comp["nu"], 0.0) & np.isclose(comp["deformation"], 0.05)]
    assert (miss["E_form_state"] == "missing").all() and miss["E_form_pct"].isna().all()
    quarter = comp[np.isclose(comp["nu"], 0.25)]
    assert quarter["E_form_state"].str.startswith("identical").all() and not quarter["decisive"].any()


def _eform(closers):
    return pd.DataFrame({"closer": closers, "decisive": [c in ("E-form", "G-form") for c in closers]})


def test_eform_verdict_supported_counts_only_decisive_rows():
    from studies.paper.claims import SUPPORTED, eform_claim

    c = eform_claim(_eform(["E-form", "E-form", "G-form", "undecided (E-form failed (unstable))",
                            "same (differ by ≤ 0.01 pp)"]), "Table 2", "compression")
    assert c.verdict == SUPPORTED
    assert "2 of 3 decisive rows" in c.evidence and "2 of 5 rows not counted" in c.evidence


def test_eform_verdict_not_supported():
    from studies.paper.claims import NOT_SUPPORTED, eform_claim

    c = eform_claim(_eform(["G-form", "G-form", "E-form", "undecided (G-form missing)", "undecided (G-form missing)",
                            "undecided (G-form missing)"]), "Table 3", "tension")
    assert c.verdict == NOT_SUPPORTED and "1 of 3 decisive rows" in c.evidence


def test_eform_verdict_not_tested_without_decisive_rows():
    from studies.paper.claims import UNTESTED, eform_claim

    c = eform_claim(_eform(["same (differ by ≤ 0.01 pp)", "undecided (E-form missing)"]), "Table 2", "compression")
    assert c.verdict == UNTESTED and "0 of 2 rows" in c.evidence


@pytest.mark.parametrize("n_ok, n, kind", [(4, 4, "reproduced"), (2, 4, "partly reproduced"),
                                           (1, 4, "not reproduced"), (0, 0, "not tested")])
def test_count_verdicts(n_ok, n, kind):
    from studies.paper.claims import count_verdict

    assert count_verdict(n_ok, n) == kind


@pytest.mark.slow
def test_published_claims_follow_their_criteria(results):
    """The Table 4 claim, recomputed here from the stored runs and the published CSV."""
    from reports.data import Results
    from studies.paper.claims import REL_PCT, count_verdict, published_claims
    from studies.paper.values import load

    r = Results(results)
    cl = {c.statement: c for c in published_claims(r)}
    t4 = next(c for s, c in cl.items() if "Table 4" in s)
    paper = load("g20_table4_shear")
    rows = r.rows
    n_ok = 0
    for _, p in paper.iterrows():
        for model in ("hybmss", "hybmss-fd"):
            m = rows[(rows["experiment"] == "shear") & (rows["method"] == f"{model} static")
                     & np.isclose(rows["nu"], p["nu"]) & np.isclose(rows["deformation"], p["deformation"])
                     & (rows["status"] == "ok")]
            n_ok += len(m) > 0 and abs(float(m["force_x"].iloc[0]) / p[model] - 1) <= REL_PCT / 100
    assert t4.verdict == count_verdict(n_ok, 4)
    assert "missing" in t4.evidence  # no 20 % shear run in the fixture
    b09 = next(c for s, c in cl.items() if "[B09]'s (mean error" in s)
    assert b09.evidence.startswith(("0 of 2", "1 of 2", "2 of 2"))


@pytest.mark.slow
def test_performance_claim_and_short_table_come_from_the_stored_summary(results):
    """The [G20] time-ratio claim reads the ratios the performance study joined with the
    publication's (cf / fd 1.4 and hybmss / fd 2.1), names the baseline as stored, and judges
    each ratio within ±50 %."""
    from reports.data import Results
    from reports.findings import performance_sentence
    from reports.sections.studies import performance_short
    from studies.paper.claims import REPRODUCED, claims, headline

    r = Results(results)
    perf = [c for c in claims(r, headline(r)) if c.statement.startswith("Per step")]
    assert len(perf) == 1
    c = perf[0]
    assert c.statement == "Per step, hybmss-cf about 1.4× and hybmss about 2.1× the time of hybmss-fd"
    assert c.verdict == REPRODUCED and "hybmss-cf / hybmss-fd per step: 1.44–1.5 (publication 1.4)" in c.evidence
    assert "relative to hybmss-fd" in performance_sentence(r.table("performance_summary"))
    t = performance_short(r)
    assert t.title == "Time per step relative to hybmss-fd" and t.n_rows == 6


def test_budget_answers_pick_the_fastest_method_that_meets_the_budget():
    from reports.findings import budget_answers, budget_sentence
    from studies.paper.pareto import budget_table

    n = 5
    pareto = pd.DataFrame({"config": ["c"] * n, "experiment": ["shear"] * n, "nu": [0.25] * n,
                           "kind": ["static"] * n, "status": ["ok"] * 4 + ["diverged"],
                           "method": ["corot-hex8 static", "corot-hex8 static", "xpbd-nh static", "hybmss static",
                                      "fem-hex1-linear"],
                           "mesh": ["2", "4", "2", "2", "2"], "factor": [1, 2, 1, 1, 1],
                           "time_s": [1.0, 3.0, 2.0, 0.5, 0.1], "time_spread": [0.01, 0.01, 0.6, 0.01, np.nan],
                           "error_field": [0.008, 0.002, 0.004, 0.2, np.nan],
                           "error_force": [np.nan] * n, "error_volume": [np.nan] * n})
    ans = budget_answers(budget_table(pareto, budgets=(0.001, 0.005, 0.01, 0.5)))
    assert set(ans["measure"]) == {"force", "volume", "field"}
    assert (ans.loc[ans["measure"] != "field", "method"] == "none").all()  # no run has these errors
    ans = ans[ans["measure"] == "field"].set_index("budget")
    assert ans.loc[0.001, "method"] == "none" and np.isnan(ans.loc[0.001, "lead"])
    # at 0.5 %, corot-hex8 only meets it on its finer mesh (3 s): xpbd-nh (2 s) wins, a tie
    # since its spread (0.6) is larger than its lead (1.5 - 1)
    assert (ans.loc[0.005, "method"], ans.loc[0.005, "runner_up"]) == ("xpbd-nh static", "corot-hex8 static")
    assert ans.loc[0.005, "lead"] == pytest.approx(1.5) and bool(ans.loc[0.005, "tie"])
    assert (ans.loc[0.01, "method"], ans.loc[0.01, "mesh"], ans.loc[0.01, "lead"]) == (
        "corot-hex8 static", "2", pytest.approx(2.0))
    assert not bool(ans.loc[0.01, "tie"])
    assert (ans.loc[0.5, "method"], ans.loc[0.5, "lead"]) == ("hybmss static", pytest.approx(2.0))
    text = budget_sentence(ans.reset_index(), budget=0.01)
    assert "displacement field error: corot-hex8 1 (of 1)" in text and "mass-spring" not in text
    assert "Of the 3 answers with a runner-up (all budgets), 1 is a tie" in text


@pytest.mark.parametrize("status, inverted, state", [("converged", 0, "converged"), ("ok", 0, "converged"),
                                                     ("converged", 3, "inverted"), ("diverged", 0, "diverged"),
                                                     ("unstable", 0, "unstable"), ("nan", 0, "missing")])
def test_stability_outcomes(status, inverted, state):
    from reports.findings import outcome

    assert outcome(status, inverted) == state


def test_beam_figure_skips_beams_without_stored_centre_lines(tmp_path):
    """Beams under gravity of another study (no centre line stored) get no panel, and the
    figure is drawn with the curves that are stored (Fig. 5)."""
    from reports import figures

    z = np.linspace(0.0, 2.4, 5)
    curves = pd.DataFrame({"key": "a" * 24, "method": "hybmss static", "mesh": "4x4x24", "E": 1e7, "z": z,
                           "u_y": -0.01 * z ** 2})
    theory = pd.DataFrame({"mesh": "4x4x24", "E": 1e7, "z": z, "u_y": -0.011 * z ** 2})
    rows = pd.DataFrame({"key": ["a" * 24, "b" * 24], "method": ["hybmss static", "hybmss static"],
                         "mesh": ["4x4x24", "1x1x6"], "E": [1e7, 1e7], "nu": 0.25,
                         "rho": 1000.0, "gravity": 10.0, "study": ["bending", "pareto"]})

    class _Results:
        def find(self, experiment):
            return rows

        def table(self, name):
            return {"bending_curves": curves, "euler_bernoulli": theory}[name]

        def method_order(self, methods):
            return list(methods)

    fig = figures.beam_deflection(_Results(), tmp_path / "fig5.png")
    assert fig is not None and fig.path.stat().st_size > 0
    from PIL import Image

    w, h = Image.open(fig.path).size
    assert h < w  # one row of panels (4x4x24), not a second for the 1x1x6 beam without curves


@pytest.mark.slow
def test_exports_are_made_here_when_the_forked_process_fails(results, tmp_path, monkeypatch):
    """The VTU files and renders come from a forked process; one that dies without a result
    leaves them to the building process: the same files, no warning."""
    from reports import build as build_mod

    monkeypatch.setattr(build_mod._Exports, "_child", lambda self, conn: conn.close())
    res = build_mod.build(results, tmp_path, pdf=False)
    assert res.warnings == []
    assert res.vtu == len(list((tmp_path / "vtu").glob("*.vtu"))) > 0
    assert any(p.name.startswith("render_") for p in (tmp_path / "figures").glob("*.png"))


@pytest.mark.slow
def test_the_report_prints_the_claims_the_studies_judged(report, results):
    """``tables/claims.csv`` is what the studies judge from the stored results (recomputed here
    from the same folder) and the summary page prints its rows, verdicts included, as stored:
    the report formats, it does not decide."""
    from studies.paper.claims import CLAIMS_COLUMNS, claims, headline
    from studies.sweep.results import Results

    res, _ = report
    r = Results(results)
    stored = r.table("claims")
    assert list(stored.columns) == CLAIMS_COLUMNS
    again = [c.row() for c in claims(r, headline(r))]
    assert [(c["claim"], c["verdict"], c["evidence"]) for c in again] == \
        list(zip(stored["claim"], stored["verdict"], stored["evidence"].fillna("")))
    counted = stored.dropna(subset=["rows_counted"])
    assert (counted["rows_within"] <= counted["rows_counted"]).all() and len(counted) >= len(stored) - 3
    printed = [row for tid, t in sorted(res.tables.items()) if tid.startswith("table_claims") for row in t.rows]
    assert sorted((row[0][0], row[2][0]) for row in printed) == sorted(zip(stored["claim"], stored["verdict"]))


# ------------------------------------------------------------------ the printed page
EDGE_MM = 3.0
"""Width of the band along each paper edge that must stay blank (the page margins are 11–13 mm)."""


def edge_ink(pdf_path, dpi: int = 50, edge_mm: float = EDGE_MM) -> list[tuple[int, str]]:
    """(page, edge) of every PDF page whose rendered image has ink within ``edge_mm`` of an edge."""
    import pypdfium2 as pdfium

    found = []
    pdf = pdfium.PdfDocument(str(pdf_path))
    try:
        for i in range(len(pdf)):
            img = np.asarray(pdf[i].render(scale=dpi / 72).to_pil().convert("L"))
            k = max(1, int(round(edge_mm / 25.4 * dpi)))
            bands = {"left": img[:, :k], "right": img[:, -k:], "top": img[:k, :], "bottom": img[-k:, :]}
            found += [(i + 1, name) for name, band in bands.items() if (band < 200).any()]
    finally:
        pdf.close()
    return found


@pytest.mark.slow
def test_no_ink_at_the_page_edges(report):
    """Every page of the PDF, rendered: nothing runs to the paper's edge (a table wider than the
    page would, and the build's own check would have refused it before)."""
    res, out = report
    assert edge_ink(out / "report.pdf") == []


def test_edge_ink_sees_a_table_off_the_page(tmp_path):
    """The image check itself: a 27-column table printed without the build's check runs to the edge."""
    from weasyprint import HTML

    head = "".join(f"<th>column {i}</th>" for i in range(27))
    HTML(string=f"<style>@page {{ size: A4 landscape; margin: 11mm }} th {{ white-space: nowrap }}</style>"
              f"<table><tr>{head}</tr></table>").write_pdf(tmp_path / "wide.pdf")
    assert (1, "right") in edge_ink(tmp_path / "wide.pdf")
    HTML(string="<style>@page { size: A4 landscape; margin: 11mm }</style><p>narrow</p>").write_pdf(tmp_path / "n.pdf")
    assert edge_ink(tmp_path / "n.pdf") == []


@pytest.mark.slow
def test_build_refuses_a_table_wider_than_the_page(results, tmp_path, monkeypatch):
    """A 27-column table in the printed report: the build fails naming it, and no PDF is written."""
    from reports import build as buildmod
    from reports.sections import publication as tabmod
    from reports.layout import PageOverflowError

    wide = tabmod.Table("table_wide", "A table of 27 columns", "", [f"column {i}" for i in range(27)],
                        [[(f"{1000 * i + j:.4g}", "") for j in range(27)] for i in range(3)])
    monkeypatch.setattr(tabmod, "meshes_table", lambda results: wide)
    with pytest.raises(PageOverflowError, match="table_wide"):
        buildmod.build(results, tmp_path / "out")
    assert not (tmp_path / "out" / "report.pdf").exists()


def test_no_two_series_share_a_colour_or_marker():
    """Every registered variant, and the references, have a colour of their own, and no two variants
    share a marker while spare markers remain; explicit and static runs of one model differ in line."""
    from reports import palette
    from studies.paper.tables import models_table

    table = models_table()
    with palette.models(table) as styles:
        colours = [c.lower() for c, _, _ in styles.values()]
        assert len(set(colours)) == len(colours) == len(table)
        assert not set(colours) & {c.lower() for c in palette.COLORS.values()}
        markers = [m for _, m, _ in styles.values()]
        assert len(set(markers)) == min(len(markers), len(palette.SPARE_MARKERS))
        for v in styles:
            assert palette.linestyle(f"{v} static") != palette.linestyle(f"{v} explicit"), v
    # declared duplicates are what the check is for: two models declaring one colour
    dup = pd.DataFrame({"variant": ["a", "b"], "color": ["#123456", "#123456"], "marker": ["o", "o"],
                        "linestyle": ["-", "-"]})
    assert len({c for c, _, _ in palette.unique_styles(dup.to_dict("records")).values()}) == 2


@pytest.mark.slow
def test_summary_opens_with_the_verdict(report, results):
    """§1 opens with sentences on where each method wins, then the verdict table; the long headline
    comparison comes last. The verdict's errors are the tables' own numbers: (model − FEM)/|FEM|
    recomputed here from tables/table4_shear.csv."""
    res, _ = report
    html = res.html.read_text(encoding="utf-8")
    start = html.index('<section id="summary"')
    summary = html[start:html.index("</section>", start)]
    assert summary.index('class="intro"') < summary.index("<table") < summary.index('id="table_headline"')
    assert summary.index('id="table_verdict"') < summary.index('id="table_claims"')
    assert "best" in _visible_text(summary[:summary.index("<table")]) and "Caveats" in summary
    v = pd.read_csv(results / "tables" / "verdict.csv")
    t = pd.read_csv(results / "tables" / "table4_shear.csv")
    row = t[(t["nu"] == t["nu"].max()) & (t["deformation"] == t["deformation"].max())].iloc[0]
    shear = v[(v["regime"] == "near incompressibility") & v["quantity"].str.startswith("shear")]
    assert len(shear) >= 2
    ref = row[next(c for c in t.columns if c.startswith("fem") and c.endswith("linear"))]  # 5 %: linear FEM
    for _, r in shear.iterrows():
        expect = 100 * (row[f"{r['method']} static"] - ref) / abs(ref)
        assert r["value"] == pytest.approx(expect, rel=1e-9)
    best = shear.loc[shear["value"].abs().idxmin(), "method"]
    assert shear.set_index("method").loc[best, "rank"] == "best"
    # the explicit cost: the run's stepping time per step (not its set-up or compilation) over half
    # its dt_crit, per simulated second
    import json

    c = v[(v["regime"] == "cost") & v["quantity"].str.contains("ν = 0.25")].iloc[:1]
    mesh = c["scene"].iloc[0].split("mesh ")[1]
    runs = [r for r in (json.loads(p.read_text()) for p in (results / "runs").glob("*.json"))
            if r["solver"] == "mss-explicit" and r["status"] == "ok" and r["variant"] == c["method"].iloc[0]
            and r["experiment"] == "compression" and r["nu"] == 0.25 and r["mesh"] == mesh]
    assert runs and all(r["wall_time_s"] < r["elapsed_s"] for r in runs)
    best = min(runs, key=lambda r: r["wall_time_s"] / r["steps"])
    expect_ms = 1e3 * (best["wall_time_s"] / best["steps"]) / (0.5 * best["info"]["dt_crit"])
    assert c["value"].iloc[0] == pytest.approx(expect_ms, rel=1e-9)


@pytest.mark.slow
def test_tables_beside_the_publication_fit_and_name_their_sign(report):
    """Tables 2–5 as [G20] beside ours in at most 14 columns, the other models in tables of their
    own, every difference signed and its convention stated."""
    from reports.tables import MAX_COLUMNS

    res, _ = report
    for tid, t in res.tables.items():
        if not t.screen_only and not t.csv:
            assert len(t.columns) <= MAX_COLUMNS, (tid, len(t.columns))
    t2 = res.tables["table2"]
    assert "hybmss ours" in t2.columns and "hybmss [G20]" in t2.columns and "verdict" in t2.columns
    assert "model − reference" in t2.caption
    assert any(tid.startswith("table2_others") for tid in res.tables)
    others = res.tables["table2_others"]
    assert "hybmss (pp)" not in others.columns and "hybmss-fd (pp)" not in others.columns
    d = t2.columns.index("Δ hybmss − FEM, ours (pp)")
    assert all(c[0] == "–" or c[0] == "0" or c[0][0] in "+-" for c in (r[d] for r in t2.rows))


@pytest.mark.slow
def test_the_report_reads_the_derived_tables_as_the_studies_store_them(results, tmp_path):
    """The tables the studies derive for the report (middle layer, [B09] comparison, ...) read the
    same from a folder stored without them (derived on read) as written by the studies; the
    [B09] comparison carries our error of every model run and [B09]'s published means beside them."""
    import shutil

    from reports.data import DERIVED_TABLES, Results
    from studies.paper.stored import write_derived
    from studies.sweep.store import Store

    copy = tmp_path / "stored"
    shutil.copytree(results, copy)
    written = write_derived(Store(copy))
    assert {"b09_comparison", "b09_published"} <= set(written)
    on_read, stored = Results(results), Results(copy)
    assert not (results / "tables" / "b09_comparison.csv").exists()
    for name in DERIVED_TABLES:
        a, b = on_read.table(name), stored.table(name)
        assert (a is None) == (b is None), name
        if a is not None:
            pd.testing.assert_frame_equal(a.reset_index(drop=True), b, check_dtype=False)
    cmp = stored.table("b09_comparison")
    cant = stored.table("baudet_cantilever")
    assert set(cmp.loc[cmp["experiment"] == "cantilever", "model"]) == set(cant["model"])
    assert cmp["b09_mean_pct"].notna().any()


@pytest.mark.parametrize("threads", [(1,), (1, 2)])
def test_performance_caption_names_the_thread_counts_timed(threads, tmp_path):
    """The quick study times one thread: its figure's caption must not describe a dashed line it lacks."""
    from reports.study_figures import performance

    rows = [{"scene": "compression", "variant": v, "nu": 0.3, "threads": th, "volumes": n, "steps": 100,
             "best_s": 1e-4 * n / th} for v in ("hybmss", "hybmss-fd") for th in threads for n in (64, 512)]
    caption = performance(pd.DataFrame(rows), tmp_path / "perf.png").caption
    assert ("dashed 2 threads" in caption) == (2 in threads)
    assert ("1 thread" in caption) and ("solid" in caption) == (len(threads) > 1)
