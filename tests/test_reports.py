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

NUS = (0.0, 0.25, 0.499)


def _tasks():
    from studies.runner import SolverSpec, Task
    from studies.scenes import SceneSpec

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
    # the publication's explicit protocol, shortened (NumPy kernel: nothing to compile)
    spec = SceneSpec.default("compression", mesh=(2, 2, 2), nu=0.25, deformation=0.05, damping=2.0)
    tasks.append(Task(spec, SolverSpec("explicit", dt=1e-3, steps=300, ramp_time=0.1, kernel="numpy"), "compression"))
    for E in (1e7, 2e6):
        spec = SceneSpec.default("bending", mesh=(2, 2, 6), E=E, nu=0.25, gravity=10.0)
        for model in ("hybmss", "hybmss-fd"):
            tasks.append(Task(spec.replace(model=model), static, "bending"))
        tasks.append(Task(spec, SolverSpec("fem", element="hex2", law="linear"), "bending"))
    return tasks


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A results folder with the real layout, one failed run and a performance table."""
    from studies.runner import run_tasks
    from studies.store import Store
    import studies.tables as studies_tables

    root = tmp_path_factory.mktemp("results")
    store = Store(root)
    tasks = _tasks()
    run_tasks(tasks, store, jobs=1, progress=False)
    # a failed run, stored the way the runner stores one
    row = store.row(tasks[0].key())
    row.update(key="f" * 24, status="diverged", message="ExplicitDivergenceError: |v| > 1e6 m/s at step 812",
               solver="mss-explicit", label=row["label"] + " (explicit)")
    for k in ("volume_change", "max_displacement", "force_x", "force_y", "force_z"):
        row.pop(k, None)
    store.save(row["key"], row)
    with pytest.MonkeyPatch.context() as mp:  # moduli at three ν keep the test short
        mp.setattr(studies_tables, "moduli_table", functools.partial(studies_tables.moduli_table, nus=NUS))
        studies_tables.write_tables(store)
    store.write_table("performance", pd.DataFrame({
        "variant": ["hybmss-fd", "hybmss", "hybmss-fd", "hybmss"], "volumes": [1000, 1000, 8000, 8000],
        "time_1000_steps_s": [0.1, 0.2, 0.8, 1.7]}))
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


def test_pdf_pages_and_text(report):
    res, out = report
    data = (out / "report.pdf").read_bytes()
    assert data.startswith(b"%PDF")
    assert _pdf_pages(data) == res.pages
    # cover + contents + one section a page at least; the list of runs is not printed
    assert res.pages >= 9
    text = " ".join(res.page_text)
    for needle in ("Summary", "Table 2: compression", "Table 3: tension", "Table 4: shear", "Table 5: torsion",
                   "Table 6: meshes", "Deformed shapes", "Euler", "Runs that did not reach a result", "diverged",
                   "Explicit protocol against the static equilibrium",
                   "ExplicitDivergenceError", "Effective moduli", "E-form check", "Performance", "reproduced"):
        assert needle in text, needle
    assert "All runs and VTU files" not in " ".join(res.page_text[2:])
    anchors = {a for page in res.page_anchors for a in page}
    assert {"summary", "table2", "table3", "table4", "table5", "table6", "failures", "moduli"} <= anchors
    assert "runs" not in anchors


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


def test_summary_derives_verdicts_from_the_data(results):
    from reports.data import Results
    from reports.summary import REPRODUCED, claims, headline

    r = Results(results)
    h = headline(r)
    cl = {c.statement: c for c in claims(r, h)}
    moduli = next(c for s, c in cl.items() if s.startswith("hybmss and hybmss-fd have the input"))
    assert moduli.verdict == REPRODUCED
    runs_ok = next(c for s, c in cl.items() if s.startswith("The publication's scenes run"))
    assert runs_ok.verdict != REPRODUCED and "diverged" in runs_ok.evidence
    comp = h[(h["experiment"] == "compression") & np.isclose(h["nu"], 0.25)].iloc[0]
    assert comp["paper_mss"] == pytest.approx(3.17) and comp["fem"] > 0


def test_rebuild_is_cached_and_fast(report, results):
    import time

    from reports.build import build

    res, out = report
    t0 = time.perf_counter()
    again = build(results, out, pdf=False)
    assert time.perf_counter() - t0 < 10.0
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
    from studies.tables import models_table

    with palette.models(models_table()) as styles:
        assert palette.family(method) == family
        assert palette.color(method) == (palette.COLORS[family] if family in palette.COLORS else styles[family][0])


def test_unknown_model_is_not_coloured_as_another():
    """A method of no stored model gets the neutral 'other' style, never a model's colour."""
    from reports import palette
    from studies.tables import models_table

    with palette.models(models_table()) as styles:
        assert palette.family("hybmss-xyz static") == palette.OTHER
        assert palette.color("hybmss-xyz static") not in {c for c, _, _ in styles.values()}
        assert palette.family("hybmss static") == "hybmss"
    assert palette.family("hybmss static") == palette.OTHER  # outside the block: no stored styles


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
