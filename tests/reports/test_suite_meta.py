"""The report reads what a suite declares from the metadata sidecar bench writes beside its
results (``OUT/<suite>.meta.json``); a results folder written before the sidecar still builds,
and the page says the metadata is missing."""

import json

import pandas as pd

from bench.results import CaseStore
from bench.perturb import KINDS, LABELS, UNITS
from bench.run import results_path, run_suite
from bench.suites import BAND, SCALING_FIT_FROM, Case, Suite
from observer.results_io import meta_path, read_suite_meta
from reports.build import build_report
from reports.context import load_context
from reports.header import header_table

MINI = Suite("mini", "two tiny cases, declared against case-id order", (
    Case("work_precision", "bouncing_ball", law="newton", h=2e-3, t_end=0.5, observers=(),
         reference="closed form"),
    Case("work_precision", "bouncing_ball", law="newton", h=1e-3, t_end=0.5, observers=(),
         reference="closed form")))

ROW = {"kind": "observers", "scenario": "oscillator", "name": "osc", "status": "ok"}


def _old_folder(tmp_path):
    """A results folder as bench wrote it before the sidecar: case files, no meta.json."""
    store = CaseStore(results_path("old", tmp_path))
    store.write_case("old", "observers:b", [ROW])
    store.write_case("old", "observers:a", [ROW])
    return store.path


def _header(ctx) -> dict:
    return {r[0]: r[1] for r in header_table(ctx).rows}


def test_run_suite_writes_the_declared_case_order(tmp_path, monkeypatch):
    from bench import peers

    monkeypatch.setattr(peers, "SICONOS_PYTHON", "/nonexistent/bin/python3")
    ids = [c.case_id for c in MINI.cases]
    assert sorted(ids) != ids                            # so a sorted listing would fail below
    run_suite(MINI, tmp_path, progress=False, limit=0, micro=False)
    meta = json.loads(meta_path("mini", tmp_path).read_text())
    siconos = {"available": False, "version": None, "python": "/nonexistent/bin/python3",
               "reason": f"no interpreter at /nonexistent/bin/python3; {peers.HOW_TO_GET}",
               "how_to_get": peers.HOW_TO_GET}
    assert meta == {"suite": "mini", "cases": ids, "description": MINI.description, "settings": {},
                    "band": list(BAND), "scaling_fit_from": SCALING_FIT_FROM,
                    "perturbations": {"kinds": list(KINDS), "labels": LABELS, "units": UNITS},
                    "siconos": siconos}


def test_settings_section_reads_the_sidecar_and_says_when_it_is_missing(tmp_path):
    from reports.sections.settings import MISSING, definitions_table, suite_tables

    folder = _old_folder(tmp_path)
    ctx = load_context([folder], tmp_path / "r")
    (t,) = suite_tables(ctx)
    assert [r[1] for r in t.rows] == [MISSING]
    defs = {r[0]: r[1] for r in definitions_table(ctx).rows}
    assert defs["robustness band"] == MISSING and MISSING in defs["scaling exponent"]
    meta_path("old", tmp_path).write_text(json.dumps(
        {"suite": "old", "cases": ["observers:b", "observers:a"], "description": "two old cases",
         "settings": {"h": "0.001"}, "band": [0.25, 0.75], "scaling_fit_from": 7}))
    ctx = load_context([folder], tmp_path / "r")
    (t,) = suite_tables(ctx)
    assert t.title.endswith("two old cases") and [r[:2] for r in t.rows] == [["cases", "2"], ["h", "0.001"]]
    defs = {r[0]: r[1] for r in definitions_table(ctx).rows}
    assert defs["robustness band"].startswith("median and 25–75 % quantiles")
    assert "from N = 7 (" in defs["scaling exponent"]


def test_missing_or_damaged_sidecar_reads_as_none(tmp_path):
    assert read_suite_meta("x", tmp_path) is None
    meta_path("x", tmp_path).write_text("{not json")
    assert read_suite_meta("x", tmp_path) is None
    meta_path("x", tmp_path).write_text('{"suite": "x"}')              # no case list
    assert read_suite_meta("x", tmp_path) is None
    meta_path("x", tmp_path).write_text('{"suite": "x", "cases": ["b", "a"]}')
    assert read_suite_meta("x", tmp_path) == {"suite": "x", "cases": ["b", "a"]}


def test_old_results_without_sidecar_build_and_the_page_says_so(tmp_path):
    folder = _old_folder(tmp_path)
    ctx = load_context([folder], tmp_path / "r")
    assert ctx.suites_without_meta() == ["old"]
    said = _header(ctx)["suite metadata (<suite>.meta.json)"]
    assert said.startswith("missing for old:")
    assert list(ctx.df["case_id"]) == ["observers:a", "observers:b"]     # case-id order


def test_a_real_folder_without_its_sidecar_builds_and_the_page_says_so(tmp_path):
    run_suite(MINI, tmp_path, progress=False, limit=1, micro=False)
    meta_path("mini", tmp_path).unlink()                  # as written before the sidecar
    page = build_report([results_path("mini", tmp_path)], tmp_path / "page").read_text(encoding="utf-8")
    assert "missing for mini" in page and "Traceback" not in page
    run_suite(MINI, tmp_path, progress=False, limit=0, micro=False)      # records it again
    # the page shows the header table (above), the one place that says "missing for"
    ctx = load_context([results_path("mini", tmp_path)], tmp_path / "page2")
    assert _header(ctx)["suite metadata (<suite>.meta.json)"] == "present"


def test_with_the_sidecar_the_declared_order_and_no_missing_note(tmp_path):
    folder = _old_folder(tmp_path)
    meta_path("old", tmp_path).write_text(json.dumps({"suite": "old", "cases": ["observers:b", "observers:a"]}))
    ctx = load_context([folder], tmp_path / "r")
    assert ctx.suites_without_meta() == []
    assert _header(ctx)["suite metadata (<suite>.meta.json)"] == "present"
    assert list(ctx.df["case_id"]) == ["observers:b", "observers:a"]


def test_scaling_and_robustness_say_the_metadata_is_missing_rather_than_guess(tmp_path):
    """Without the sidecar the fit start and the band are unknown: the sections say so (no
    table, no key number); with it they are built with the recorded values."""
    from reports.context import ReportContext
    from reports.sections import robustness, scaling
    from reports.sections.settings import MISSING

    rows = pd.DataFrame([{"suite": "old", "case_id": f"scaling:{n}", "kind": "scaling", "status": "ok",
                          "N": n, "h": 1e-3, "t_end": 0.1, "cpu_per_step_s": 1e-6 * n, "peak_mem_mb": 0.1 * n, "structure": "banded",
                          "results_dir": str(tmp_path)}
                         for n in (5, 10, 20, 40)]
                        + [{"suite": "old", "case_id": "robustness:none", "kind": "robustness", "status": "ok",
                            "results_dir": str(tmp_path)}])
    ctx = ReportContext(df=rows, files=[], micro=pd.DataFrame(), micro_meta={}, suites=["old"],
                        command="", out_dir=tmp_path)
    for module in (scaling, robustness):
        sec = module.build(ctx)
        assert [b.kind for b in sec.blocks] == ["p"] and MISSING in sec.blocks[0].content
    assert ctx.key_numbers == []
    meta_path("old", tmp_path).write_text(json.dumps({"suite": "old", "cases": [], "scaling_fit_from": 20}))
    sec = scaling.build(ctx)
    assert MISSING not in " ".join(str(b.content) for b in sec.blocks if b.kind == "p")
    assert ctx.key_numbers and "from N = 20 to 40" in ctx.key_numbers[0]
