"""HTML report (reports/): sections, tables without NaN, self-contained figures, browser check.

The browser check opens the generated page in headless Chromium (Debian ``chromium``);
it is skipped only when no Chromium is installed (``.ci/run`` installs it).
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass, field
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.results import ResultsFile
from bench.run import micro_path, results_path, run_suite
from observer.observers import OBSERVER_DESIGNS
from reports.analysis import fit_power
from reports.context import load_rows
from reports.browser import check_page, find_chromium
from reports.build import build_report
from reports.tables import fmt, fmt_ratio, fmt_rho, fmt_time

pytestmark = pytest.mark.xdist_group("report_build")
"""With ``--dist loadgroup`` the module runs on one worker: its module fixtures (the smoke page, the
synthetic sections) are built once, not once per worker. With pytest 9.2 and pytest-xdist 3.8 the
group is ignored (the worker renames the node id through a field pytest no longer reads:
pytest-xdist issue 1386); ``--dist loadscope`` keeps a module on one worker meanwhile."""

REPO = Path(__file__).resolve().parents[2]
SECTIONS = ["Key numbers", "Scenarios: trajectories", "Observer table", "Work-precision",
            "Robustness", "Model error and sensors", "Hard cases", "Scaling", "Peers: Siconos", "Micro-benchmarks", "Proof-step checks",
            "Settings and tolerances", "Limitations", "How to reproduce"]


class _Cells(HTMLParser):
    """Collects table cells, the text before each table, images and external references."""

    def __init__(self):
        super().__init__()
        self.cells, self.imgs, self.external = [], [], []
        self.tables_without_title = 0
        self._in_cell = False
        self._buf = ""
        self._last_p_class = None
        self._last_tag = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag in ("td", "th"):
            self._in_cell, self._buf = True, ""
        if tag == "table" and self._last_p_class != "table-title":
            self.tables_without_title += 1
        if tag == "p":
            self._last_p_class = a.get("class")
        elif tag not in ("td", "th", "tr", "thead", "tbody", "table", "br", "code", "a"):
            self._last_p_class = None if tag not in ("details", "summary") else self._last_p_class
        if tag == "img":
            self.imgs.append(a)
        for key in ("src", "href"):
            v = a.get(key, "") or ""
            if v.startswith(("http:", "https:", "//")):
                self.external.append(v)
        if tag in ("link", "iframe"):
            self.external.append(tag)
        if tag == "script" and a.get("src"):
            self.external.append(a["src"])

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._in_cell = False
            self.cells.append(self._buf.strip())

    def handle_data(self, data):
        if self._in_cell:
            self._buf += data


NUMBER = re.compile(r"[−-]?\d+(?:\.\d+)?(?:e[−-]?\d+)?")


def _num(text: str) -> float:
    """The first number in a cell ("1.23e−7 s" → 1.23e-7; the report writes − for minus)."""
    m = NUMBER.search(text)
    assert m is not None, f"no number in {text!r}"
    return float(m.group(0).replace("−", "-"))


def _nums(text: str) -> list[float]:
    return [float(x.replace("−", "-")) for x in NUMBER.findall(text)]


@dataclass
class _Table:
    title: str
    columns: list = field(default_factory=list)
    rows: list = field(default_factory=list)

    def dicts(self) -> list[dict]:
        return [dict(zip(self.columns, r)) for r in self.rows]

    def column(self, name: str) -> list[str]:
        i = self.columns.index(name)
        return [r[i] for r in self.rows]


@dataclass
class _Body:
    """What one ``<section id=...>`` shows directly: paragraphs, list items, tables."""

    paragraphs: list = field(default_factory=list)
    items: list = field(default_factory=list)
    tables: list = field(default_factory=list)

    def text(self) -> str:
        return "\n".join(self.paragraphs + self.items)


class _Page(HTMLParser):
    """Sections of the report by id, with their paragraphs, list items and titled tables."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.sections: dict[str, _Body] = {}
        self._stack: list[str] = []
        self._buf: str | None = None
        self._p_class = None
        self._title = None
        self._table: _Table | None = None
        self._row: list | None = None
        self._header = False

    def _body(self) -> _Body:
        return self.sections.setdefault(self._stack[-1] if self._stack else "", _Body())

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "section":
            self._stack.append(a.get("id", ""))
            self._body()
        elif tag in ("p", "li", "td", "th"):
            self._buf = ""
            if tag == "p":
                self._p_class = a.get("class")
            if tag == "th":
                self._header = True
        elif tag == "table":
            self._table = _Table(self._title or "")
            self._body().tables.append(self._table)
            self._title = None
        elif tag == "tr":
            self._row, self._header = [], False

    def handle_endtag(self, tag):
        if tag == "section":
            self._stack.pop()
        elif tag == "p" and self._buf is not None:
            text = " ".join(self._buf.split())
            if self._p_class == "table-title":
                self._title = text
            else:
                self._body().paragraphs.append(text)
            self._buf = None
        elif tag == "li" and self._buf is not None:
            self._body().items.append(" ".join(self._buf.split()))
            self._buf = None
        elif tag in ("td", "th") and self._row is not None:
            self._row.append(" ".join((self._buf or "").split()))
            self._buf = None
        elif tag == "tr" and self._table is not None and self._row is not None:
            if self._header:
                self._table.columns = self._row
            else:
                self._table.rows.append(self._row)
            self._row = None

    def handle_data(self, data):
        if self._buf is not None:
            self._buf += data

    def table(self, section: str, title_start: str) -> _Table:
        found = [t for t in self.sections[section].tables if t.title.startswith(title_start)]
        assert len(found) == 1, (title_start, [t.title for t in self.sections[section].tables])
        return found[0]


def _parse(index: Path) -> _Page:
    page = _Page()
    page.feed(index.read_text(encoding="utf-8"))
    return page


def _section_page(files: list[Path], out_dir: Path, *ids: str) -> Path:
    """``out_dir/index.html`` holding only the registry's sections ``ids`` (in page order), each
    built, its figures rendered and the page rendered as :func:`reports.build.build_report` does
    with the whole registry: for the tests that read those sections only (a whole page costs
    every section, the stored model-error figures alone ≈ 2 s CPU)."""
    from reports.build import render, resolve_figures
    from reports.context import load_context
    from reports.header import header_table
    from reports.sections import SECTIONS, build_sections

    specs = tuple(s for s in SECTIONS if s.id in ids)
    assert {s.id for s in specs} == set(ids), ids
    ctx = load_context(files, out_dir)
    ctx.out_dir.mkdir(parents=True, exist_ok=True)
    sections = build_sections(ctx, specs)
    resolve_figures(sections)
    page = render(title="sections " + ", ".join(ids), header=header_table(ctx), command=ctx.command,
                  sections=[s for s in sections if not s.lead], lead=[s for s in sections if s.lead])
    index = ctx.out_dir / "index.html"
    index.write_text(page, encoding="utf-8")
    return index


@pytest.fixture(scope="module")
def smoke_build(tmp_path_factory):
    """The smoke suite, a small real micro-benchmark run, and the report built from them by the
    command line in this process (``reports.__main__.main``): the page's index, the results
    folder, main's exit code and what it printed."""
    from reports.__main__ import main

    out = tmp_path_factory.mktemp("results")
    summary = run_suite("smoke", out, progress=False)
    assert not summary.failed, summary.failed
    # not an xdist worker's variables: pytest-benchmark would take the child for a worker
    # and disable timing (which --benchmark-only refuses)
    env = {**{k: v for k, v in os.environ.items() if not k.startswith("PYTEST_XDIST")},
           "PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "1"}
    res = subprocess.run([sys.executable, "-m", "pytest", "bench/micro", "-q", "-p", "no:cacheprovider",
                          "--benchmark-only", f"--benchmark-json={micro_path('smoke', out)}",
                          "--benchmark-min-rounds=2", "--benchmark-max-time=0.001",
                          "-k", "compiled-double_mass] or solve and 1]"],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    report = tmp_path_factory.mktemp("report")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["smoke", "--results", str(out), "--out", str(report)])
    return report / "index.html", out, code, printed.getvalue()


@pytest.fixture(scope="module")
def smoke_report(smoke_build):
    """The smoke page (:func:`smoke_build`) and its results folder."""
    index, out, code, printed = smoke_build
    assert code == 0, printed
    return index, out


def test_report_has_every_section_and_a_reproduce_command(smoke_report):
    index, _ = smoke_report
    html = index.read_text(encoding="utf-8")
    for title in SECTIONS:
        assert title in html, title
    for item in ("toolkit version", "git commit", "CPU", "Python", "numpy", "cvxpy", "osqp"):
        assert item in html, item
    assert "nox -s report -- smoke" in html
    assert 'href="#observers"' in html and 'id="observers"' in html          # contents list
    assert "Speed-up of the fast contact solvers" in html
    assert "Fitted orders of convergence" in html and "Fitted exponents" in html


def test_limitations_state_what_holds_in_discrete_time(smoke_report):
    """The report states the discrete facts as the README does: the identity exact, damping
    and projection ≤ 0 exactly, the impulse term without sign (an O(h) slack)."""
    index, out = smoke_report
    html = index.read_text(encoding="utf-8")
    lim = html[html.index('id="limitations"'):]
    lim = lim[:lim.index("</section>")] if "</section>" in lim else lim
    for phrase in ("holds exactly up to round-off", "no sign in discrete time",
                   "vanishes only as h → 0", "−(1−ε)/(2(1+ε))ΔPᵀΔδ"):
        assert phrase in lim, phrase
    threads = load_rows([results_path("smoke", out)])["blas_threads"].dropna().unique()
    assert len(threads) == 1 and f"with {fmt(threads[0])} BLAS thread(s)" in lim


def test_report_tables_are_titled_and_have_no_nan_cells(smoke_report):
    index, _ = smoke_report
    p = _Cells()
    p.feed(index.read_text(encoding="utf-8"))
    assert p.tables_without_title == 0
    assert p.cells
    bad = [c for c in p.cells if c == "" or re.fullmatch(r"(?i)nan|none|null|inf|-inf", c)]
    assert not bad, bad[:10]


def test_report_is_self_contained(smoke_report):
    index, _ = smoke_report
    p = _Cells()
    p.feed(index.read_text(encoding="utf-8"))
    assert p.external == []
    assert len(p.imgs) >= 5
    for img in p.imgs:
        src = img["src"]
        assert src.startswith("data:image/png;base64,")
        assert base64.b64decode(src.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
        assert img.get("alt")


def test_not_applicable_and_not_reached_are_spelled_out(smoke_report):
    index, out = smoke_report
    html = index.read_text(encoding="utf-8")
    rows = load_rows([results_path("smoke", out)])
    na = rows[(rows["kind"] == "observers") & (rows["status"] != "ok")]
    assert len(na) and all(f"n/a ({note}" in html for note in na["note"])  # the reason, spelled out
    assert "not reached" in html                         # 1 s runs do not reach 1e-9


def test_proof_check_section_shows_the_check_rows(smoke_report, tmp_path):
    """With check rows the proof-check table lists every one of them (scenario, check, status,
    margin); without, the section says why (no crash)."""
    index, out = smoke_report
    page = _parse(index)
    rows = load_rows([results_path("smoke", out)])
    checks = rows[rows["kind"] == "checks"]
    assert len(checks) > 0                      # proofs_checks is part of this repository
    table = page.table("proof-checks", "Proof-check table")
    assert len(table.rows) == len(checks)
    for cells, (_, r) in zip(table.dicts(), checks.iterrows()):
        assert (cells["scenario"], cells["check"], cells["status"]) == \
            (r["scenario"], r["check"], r["check_status"])
        if r["check_status"] != "n/a":
            assert _num(cells["margin"]) == pytest.approx(r["margin"], rel=5e-3, abs=1e-300)
    path = tmp_path / "nochecks.csv"
    rows[rows["kind"] != "checks"].drop(columns="results_dir").to_csv(path, index=False)
    page = _section_page([path], tmp_path / "r", "proof-checks").read_text(encoding="utf-8")
    assert "No proof-check results" in page and "Proof-check table" not in page


def test_cli_builds_report_and_rejects_missing_results(smoke_build, tmp_path):
    """The command line's build in this process (:func:`smoke_build`: the smoke page the other
    tests read is the one it built; a new interpreter would import and build the whole page
    again); its refusal through ``python -m reports``, the entry point itself."""
    index, out, code, printed = smoke_build
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    assert code == 0
    assert printed.startswith(f"report: {index} (")
    assert index.exists()
    res = subprocess.run([sys.executable, "-m", "reports", "nosuchsuite", "--results", str(tmp_path)],
                         cwd=REPO, env=env, capture_output=True, text=True)
    assert res.returncode == 2 and "python -m bench run nosuchsuite" in res.stderr


# ----------------------------------------------------------------------------- pieces
def test_formatting_never_prints_nan():
    assert fmt(float("nan")) == "n/a" and fmt(None) == "n/a"
    assert fmt(float("inf")) == "∞" and fmt_time(float("inf")) == "not reached"
    assert fmt(1.23456e-7) == "1.23e−7" and fmt(0.5) == "0.5" and fmt(12345.0) == "1.23e4"
    assert fmt_rho(1e-6) == "1e−6" and fmt_time(4.5) == "4.5 s"
    p, c = fit_power(np.array([1.0, 2.0, 4.0]), np.array([3.0, 12.0, 48.0]))
    assert p == pytest.approx(2.0) and np.exp(c) == pytest.approx(3.0)
    assert np.isnan(fit_power(np.array([1.0]), np.array([1.0]))[0])


# ----------------------------------------------------------------------------- browser
needs_chromium = pytest.mark.skipif(find_chromium() is None,
                                    reason="chromium is not installed (apt-get install chromium)")


@needs_chromium
def test_report_in_headless_chromium(smoke_report):
    """Every image decodes (complete, naturalWidth > 0), no script or console errors, and a
    screenshot is written."""
    index, _ = smoke_report
    res = check_page(index, index.parent / "screenshot.png")
    assert res.script_ran, res.text()
    assert res.images_total >= 5 and res.images_ok == res.images_total, res.text()
    assert res.page_errors == [] and res.console_errors == [], res.text()
    assert res.screenshot is not None and res.screenshot.stat().st_size > 10_000
    assert res.ok


@needs_chromium
def test_browser_check_detects_broken_images_and_errors(tmp_path, smoke_report):
    """The checker is not vacuous: a broken image and a thrown error are reported."""
    index, _ = smoke_report
    html = index.read_text(encoding="utf-8")
    broken = html.replace("<footer>", '<img src="data:image/png;base64,AAAA" alt="broken one">'
                          '<script>throw new Error("boom in report");</script><footer>', 1)
    page = tmp_path / "broken.html"
    page.write_text(broken, encoding="utf-8")
    res = check_page(page, tmp_path / "broken.png")
    assert not res.ok
    assert res.images_ok == res.images_total - 1 and "broken one" in res.images_bad
    assert any("boom in report" in e for e in res.page_errors + res.console_errors)


def test_broken_proofs_checks_fails_its_case_and_the_report_still_builds(tmp_path, monkeypatch):
    """If proofs_checks raises, the checks case fails with the message (no row written, so a
    later run retries it); the report of the other rows builds and its proof-check section says
    there are no check results instead of crashing."""
    import types

    from bench.suites import Case, Suite

    fake = types.ModuleType("proofs_checks")

    def run_checks(*args, **kwargs):
        raise RuntimeError("checks under construction")

    fake.run_checks, fake.results_frame = run_checks, lambda results: pd.DataFrame()
    monkeypatch.setitem(sys.modules, "proofs_checks", fake)
    suite = Suite("pc", "", (Case("work_precision", "bouncing_ball", law="newton", h=2e-3, t_end=0.5,
                                  observers=(), reference="closed form"),
                             Case("checks", "bouncing_ball", observers=())))
    summary = run_suite(suite, tmp_path, progress=False)
    assert summary.ran == 1
    assert [cid for cid, _ in summary.failed] == [suite.cases[1].case_id]
    assert "checks under construction" in summary.failed[0][1]
    rows = load_rows([results_path("pc", tmp_path)])
    assert set(rows["case_id"]) == {suite.cases[0].case_id}
    # figures rendered in place (as the ensemble page: tests/reports/test_report_ensemble.py says why)
    page = _parse(build_report([results_path("pc", tmp_path)], tmp_path / "r", workers=1))
    assert page.sections["proof-checks"].paragraphs[0].startswith("No proof-check results")
    assert page.sections["proof-checks"].tables == []


# ----------------------------------------------------------------------------- synthetic rows
# A report built from hand-made rows whose numbers are known: every test below recomputes the
# reported numbers from these rows (independently of reports.analysis) and compares them with
# the cells and sentences of the section that shows them.
INF = float("inf")
RHO_KEYS = {1e-3: "0.001", 1e-5: "1e-05", 1e-6: "1e-06", 1e-9: "1e-09"}
OBSERVERS = {
    # name: {observer: (first passage per ρ, settling per ρ, fraction above after first passage)}
    "dm": {"jump": ((0.5, 1.5, 2.0, 2.5), (0.5, 1.5, 3.0, 8.0), (0.0, 0.0, 0.1, 0.34)),
           "nojump": ((1.0, 3.6, 4.5, 12.0), (1.0, 3.6, 4.5, 12.0), (0.0,) * 4)},
    "stuck": {"jump": ((2.0, 4.0, 5.0, 9.0), (2.0, 4.0, 5.0, INF), (0.0, 0.0, 0.0, 0.5)),
              "nojump": ((INF,) * 4, (INF,) * 4, (float("nan"),) * 4)},
}
WP_METHODS = {
    # (scenario, target, law, solver, reference): (constant, order)
    ("impact_oscillator", "master", "newton", "pivoting", "closed form (event-driven)"): (2.0, 1.0),
    ("double_mass", "master", "poisson", "pivoting", "h/16 run"): (0.5, 0.8),
    ("double_mass", "master", "poisson", "reference", "h/16 run"): (0.5, 0.8),
    ("double_mass", "jump", "poisson", "pivoting", "h/16 run"): (3.0, 1.3),
}
WP_H = (4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4)
WP_NOISE = (1.0, 1.04, 0.97, 1.02, 0.99)
SCALING_N = (5, 10, 20, 50, 100, 200, 500, 1000)
SCALING_NOISE = (1.6, 0.95, 1.05, 1.0, 0.98, 1.03, 0.97, 1.02)
"""N = 5 is off the power law (fixed costs), so the fit from N = 10 differs from the fit over all N."""
ROB_MASTERS, ROB_ERRORS = 5, 4
ROB_POINTS = (("none", 0.0), ("delay", 1e-3), ("delay", 1e-2), ("jitter", 1e-3), ("jitter", 1e-2),
              ("missed", 0.3))
"""Robustness points, each a paired ensemble of ROB_MASTERS masters × ROB_ERRORS initial errors."""
PEERS = (("impact_oscillator", 1, 1, 2e5, 7700.0, 5600.0, 300.0, 60.0, 0.0, 0.0),
         ("double_mass", 2, 1, 1e5, 9200.0, 12100.0, 800.0, 150.0, 3e-15, 2e-13),
         ("rocking_chain", 20, 20, 2e4, 97000.0, 74000.0, 9000.0, 2500.0, 4e-12, 8e-10))
"""(problem, n, m, steps, Siconos ns/step, run() ns/step, toolkit ns/step, loop ns/step, Δq, Δu)."""
LOOPS = {("impact_oscillator", "compiled"): (20_000, 1, 1.0e-3), ("impact_oscillator", "python"): (20_000, 1, 0.5),
         ("rocking_chain_N10+jump+nojump", "compiled"): (20_000, 3, 0.1),
         ("rocking_chain_N10+jump+nojump", "python"): (20_000, 3, 2.6)}
"""(case, engine): (steps, systems, median seconds per call)."""
CHECKS = [("double_mass", "mass_spd", "section 2: M ≻ 0", "PASS", 0.999, 0.0, "lambda_min=1", ""),
          ("double_mass", "lyapunov_decrease", "(16)", "FAIL", -4.1e-4, 1e-9, "step 12: dV > 0", ""),
          ("ball", "projection_defined", "(10)", "n/a", float("nan"), float("nan"), "",
           "K = 0: the projection is undefined")]
CHECK_EVIDENCE = {"mass_spd": ("proved", "M ≻ 0 (exact)"),
                  "lyapunov_decrease": ("violated", "violated: V rises at step 12 <exactly>"),
                  "projection_defined": ("n/a", "")}
"""Evidence level and verdict of the synthetic check rows (by check)."""
MICRO_MEANS = {(1, "reference"): 2.0e-3, (1, "pivoting"): 4.0e-6, (1, "lemke"): 1.6e-5,
               (1, "nnls"): 5.0e-5, (8, "reference"): 3.0e-3, (8, "pivoting"): 6.0e-5,
               (8, "lemke"): 2.5e-4, (8, "nnls"): 3.0e-4}


def _observer_rows() -> list[tuple[str, list[dict]]]:
    cases = []
    for name, runs in OBSERVERS.items():
        rows = []
        for observer, (first, settle, above) in runs.items():
            row = {"kind": "observers", "scenario": "double_mass", "name": name, "observer": observer,
                   "status": "ok", "note": "", "h": 1e-3, "t_end": 21.0, "t_on": 1.0, "t_off": 21.0,
                   "law": "newton", "solver": "pivoting", "params": "", "V_on": 0.5, "rate": 1.2,
                   "floor_rel": 1e-11 if name == "dm" else 0.4, "V_end_rel": 1e-11, "e_q_end": 1e-6,
                   "master_closings": 40, "cpu_time_s": 0.5, "steps_per_s": 4e4,
                   "master_closed_fraction": 0.3 if name == "dm" else 1.0}
            for i, key in enumerate(RHO_KEYS.values()):
                row.update({f"t_sync_{key}": first[i], f"t_settle_{key}": settle[i],
                            f"above_after_{key}": above[i]})
            rows.append(row)
        cases.append((f"observers:{name}", rows))
    ball = [{"kind": "observers", "scenario": "bouncing_ball", "name": "ball", "observer": "jump",
             "status": "n/a", "note": "K is not positive definite (K = 0 here)", "h": 1e-3,
             "t_end": 2.0, "law": "newton", "solver": "pivoting", "params": ""},
            {**cases[0][1][1], "scenario": "bouncing_ball", "name": "ball", "e_q_end": 0.2}]
    cases.append(("observers:ball", ball))
    return cases


def _synthetic_rows() -> list[tuple[str, list[dict]]]:
    cases = _observer_rows()
    for (scen, target, law, solver, ref), (c, p) in WP_METHODS.items():
        for h, noise in zip(WP_H, WP_NOISE):
            cases.append((f"wp:{scen}:{target}:{law}:{solver}:{h}", [{
                "kind": "work_precision", "scenario": scen, "name": scen, "target": target,
                "law": law, "solver": solver, "reference": ref, "status": "ok", "h": h,
                "method": f"{scen} · {target} · {law} · {solver}", "err_mean": c * h ** p * noise,
                "err_max": 3 * c * h ** (p / 2) / noise, "cpu_time_s": 2e-4 / h * noise ** 2
                * (50 if solver == "reference" else 1), "cpu_scope": "master",
                "contact_solves": int(1 / h)}]))
    for N, noise in zip(SCALING_N, SCALING_NOISE):
        cases.append((f"scaling:{N}", [{
            "kind": "scaling", "scenario": "rocking_chain", "name": "rocking_chain", "status": "ok",
            "N": N, "n": 2 * N, "h": 1e-3, "t_end": 2.0, "steps": 2000, "structure": "banded",
            "cpu_per_step_s": 3e-6 * N ** 1.04 * noise, "steps_per_s": 1 / (3e-6 * N ** 1.04 * noise),
            "loop_per_step_s": 2e-6 * N ** 1.08 / noise, "setup_cpu_time_s": 1e-4 * N,
            "mean_active": 0.5, "max_active": 3, "peak_mem_mb": 0.2 * N ** 2 / noise,
            "trajectory_mb": 0.01 * N, "whole_call_cpu_s": 1e-3 * N ** 1.06 * noise ** 2,
            "whole_call_wall_s": 1.1e-3 * N ** 1.06, "load_cpu_s": 1e-5 * N}]))
    rng = np.random.default_rng(2024)
    for kind, size in ROB_POINTS:
        rows = []
        for name, scale in (("jump", 1e-8), ("nojump", 1e-4)):
            for j in range(ROB_MASTERS):
                for i in range(ROB_ERRORS):
                    rows.append({"kind": "robustness", "scenario": "double_mass", "name": "double_mass",
                                 "design": name, "perturbation": kind, "size": size, "seed": 0,
                                 "master": j, "member": j * ROB_ERRORS + i, "masters": ROB_MASTERS,
                                 "members": ROB_MASTERS * ROB_ERRORS, "status": "ok", "h": 1e-4,
                                 "t_end": 10.0, "law": "poisson", "solver": "pivoting", "tail": 0.25,
                                 "floor": scale * (1 + 1e3 * size) * rng.lognormal(0, 1),
                                 "t_settle_0.001": rng.uniform(0.5, 4.0), "t_settle_1e-06": INF})
        cases.append((f"robustness:{kind}:{size}", rows))
    for prob, n, m, steps, sic, run, tk, loop, dq, du in PEERS:
        cases.append((f"peers:{prob}", [{
            "kind": "peers", "scenario": prob, "name": prob, "problem": prob, "status": "ok",
            "n": n, "m": m, "h": 1e-4, "steps": int(steps), "law": "newton",
            "siconos_ns_per_step": sic, "siconos_run_ns_per_step": run, "toolkit_ns_per_step": tk,
            "toolkit_loop_ns_per_step": loop, "toolkit_engine": "compiled", "ratio": sic / tk,
            "ratio_run": run / tk, "max_abs_diff_q": dq, "max_abs_diff_u": du, "max_abs_diff_P": 0.0,
            "repeats": 5, "siconos_version": "4.5.0 (test)", "siconos_forcing": "fExt written every step",
            "note": "a note" if prob == "double_mass" else ""}]))
    cases.append(("checks", [{"kind": "checks", "scenario": s, "name": s, "check": c, "equation": e,
                              "check_status": st, "margin": mg, "tolerance": tol, "witness": w,
                              "reason": why, "status": "ok",
                              "evidence": CHECK_EVIDENCE[c][0], "verdict": CHECK_EVIDENCE[c][1]}
                             for s, c, e, st, mg, tol, w, why in CHECKS]))
    return cases


RESIDUAL_PER_SECOND = 1e-10
"""Synthetic LCP residual of a solve: proportional to its mean time (distinct per solve)."""


def _micro_json() -> dict:
    return {"datetime": "2024-01-01T00:00:00", "version": "4.0.0", "machine_info": {"cpu": {}},
            "benchmarks": [{"group": f"contact solve m={m}", "name": f"test_solve[{solver}-{m}]",
                            "stats": {"mean": mean, "median": mean, "stddev": mean / 10,
                                      "min": mean, "rounds": 5},
                            "extra_info": {"kind": "contact_solve", "solver": solver, "m": m,
                                           "residual": mean * RESIDUAL_PER_SECOND}}
                           for (m, solver), mean in MICRO_MEANS.items()]
            + [{"group": "time loop", "name": f"test_loop[{engine}-{case}]",
                "stats": {"mean": 1.1 * med, "median": med, "stddev": med / 10, "min": med,
                          "rounds": 10 if engine == "compiled" else 5},
                "extra_info": {"kind": "loop", "case": case, "engine": engine, "steps": steps,
                               "systems": systems, "scenario": case.split("_N")[0].split("+")[0],
                               "n": 1, "m": 1, "compile_time_s": 0.8}}
               for (case, engine), (steps, systems, med) in LOOPS.items()]}


@pytest.fixture(scope="module")
def synthetic_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("synthetic")
    path = _rows_file(out / "synthetic.cases", _synthetic_rows())
    (out / "synthetic-micro.json").write_text(json.dumps(_micro_json()))
    index = _section_page([path], out / "report", *SYNTHETIC_SECTIONS)
    return _parse(index), load_rows([path])


SYNTHETIC_SECTIONS = ("ensemble", "scenarios", "all-key-numbers", "observers", "work-precision", "robustness",
                      "scaling", "peers", "micro", "proof-checks", "settings", "limitations")
"""The sections the tests of the synthetic rows read (the whole page of these rows is built and
checked by tests/reports/test_report_ensemble.py)."""


def _settle(name: str, observer: str, rho: float) -> float:
    return OBSERVERS[name][observer][1][list(RHO_KEYS).index(rho)]


def _first(name: str, observer: str, rho: float) -> float:
    return OBSERVERS[name][observer][0][list(RHO_KEYS).index(rho)]


def test_observer_ratios_are_settling_time_ratios(synthetic_report):
    """Every finite cell of the ratio table is t_settle(no-jump) / t_settle(jump) recomputed
    from the rows; on 'dm' at ρ = 1e-6 and 1e-9 the first-passage ratio differs (2.25, 4.80)
    from the settling ratio (1.50, 1.50), so a ratio of first passages is caught."""
    page, _ = synthetic_report
    table = page.table("observers", "Settling-time ratio")
    cells = {r["scenario"]: r for r in table.dicts() if r["baseline / candidate"] == "nojump / jump"}
    assert set(cells) == set(OBSERVERS) | {"ball"}
    for rho in RHO_KEYS:
        col = f"ratio at ρ = {fmt_rho(rho)}"
        tj, tn = _settle("dm", "jump", rho), _settle("dm", "nojump", rho)
        assert _nums(cells["dm"][col])[:3] == pytest.approx([tn / tj, tn, tj], rel=5e-3)
    first = _nums(cells["dm"][next(c for c in table.columns if c.startswith("first-passage ratio"))])
    assert first == pytest.approx([_first("dm", "nojump", r) / _first("dm", "jump", r)
                                   for r in RHO_KEYS], rel=5e-3)
    # stuck: only the jump observer settles (ρ ≤ 1e-6); at 1e-9 it only passes, never settles
    stuck = cells["stuck"]
    for rho in (1e-3, 1e-5, 1e-6):
        cell = stuck[f"ratio at ρ = {fmt_rho(rho)}"]
        assert cell.startswith("∞") and _num(cell) == pytest.approx(_settle("stuck", "jump", rho))
        assert _nums(cell.split("ratio >")[1])[0] == pytest.approx(20.0 / _settle("stuck", "jump", rho),
                                                                   rel=5e-3)
    assert stuck["ratio at ρ = 1e−9"] == "neither settles"
    assert cells["ball"]["ratio at ρ = 1e−3"].startswith("n/a")


def test_observer_headline_uses_settling_times_at_the_deepest_common_rho(synthetic_report):
    """The headline (ratio table, observer-section list, the collapsed list of all key numbers)
    is the settling ratio at the deepest ρ both observers settle below: 'dm' 12.0/8.0 = 1.50 at
    1e−9, not the first-passage 4.80; no scenario repeats it in a paragraph of its own."""
    page, _ = synthetic_report
    tn, tj = _settle("dm", "nojump", 1e-9), _settle("dm", "jump", 1e-9)
    expected = f"settling-time ratio nojump/jump = {tn / tj:.2f} at ρ = 1e−9"
    first = _first("dm", "nojump", 1e-9) / _first("dm", "jump", 1e-9)
    head = next(r["headline"] for r in page.table("observers", "Settling-time ratio").dicts()
                if (r["scenario"], r["baseline / candidate"]) == ("dm", "nojump / jump"))
    assert head.startswith(expected) and f"first-passage ratio {first:.2f}" in head
    assert _nums(head.split("(")[1])[:2] == pytest.approx([tn, tj], rel=5e-3)
    obs_items = page.sections["observers"].items
    assert any(i.startswith(f"dm: {expected}") for i in obs_items), obs_items
    assert any(i.startswith(f"dm: {expected}") for i in page.sections["all-key-numbers"].items)
    assert not any(expected in p for p in page.sections["scn-dm"].paragraphs)
    stuck = next(i for i in obs_items if i.startswith("stuck:"))
    assert "never settles below ρ = 1e−3" in stuck
    assert f"settles below ρ = 1e−6 after {fmt(_settle('stuck', 'jump', 1e-6))} s" in stuck
    assert "settling times" in page.sections["observers"].paragraphs[0]


def test_observer_prose_lists_every_return_above_a_threshold(synthetic_report):
    """Exactly the (scenario, observer, ρ) with settle > first passage are listed, with both
    times and the fraction above, taken from the rows."""
    page, _ = synthetic_report
    expected = [(name, obs, rho) for name, runs in OBSERVERS.items() for obs in runs
                for rho in RHO_KEYS if np.isfinite(_first(name, obs, rho))
                and _settle(name, obs, rho) > _first(name, obs, rho)]
    assert len(expected) == 3
    items = [i for i in page.sections["observers"].items if "first passage at" in i]
    assert len(items) == len(expected)
    assert any(f"in {len(expected)} case(s)" in p for p in page.sections["observers"].paragraphs)
    for item, (name, obs, rho) in zip(items, expected):
        assert item.startswith(f"{name}, observer ") and f"ρ = {fmt_rho(rho)}:" in item
        numbers = _nums(item.split(":", 1)[1])
        assert numbers[0] == pytest.approx(_first(name, obs, rho))
        above = OBSERVERS[name][obs][2][list(RHO_KEYS).index(rho)]
        assert f"{100 * above:.0f} %" in item
        if np.isinf(_settle(name, obs, rho)):
            assert "never settles" in item
        else:
            assert numbers[1] == pytest.approx(_settle(name, obs, rho))


def test_observer_table_shows_settling_and_first_passage_columns(synthetic_report):
    page, _ = synthetic_report
    table = page.table("observers", "Observer table")
    first_col = next(c for c in table.columns if c.startswith("first passage"))
    rows = [r for r in table.dicts() if r["scenario"] == "dm"]
    assert [r["observer"] for r in rows] == [OBSERVER_DESIGNS[o].label for o in ("jump", "nojump")]
    for r, obs in zip(rows, ("jump", "nojump")):
        for rho in RHO_KEYS:
            assert _num(r[f"settles below {fmt_rho(rho)}"]) == pytest.approx(_settle("dm", obs, rho))
        assert _nums(r[first_col]) == pytest.approx([_first("dm", obs, rho) for rho in RHO_KEYS])
    stuck_jump = next(r for r in table.dicts() if r["scenario"] == "stuck")
    assert stuck_jump["settles below 1e−9"] == "not reached"
    assert _nums(stuck_jump[first_col])[-1] == pytest.approx(_first("stuck", "jump", 1e-9))


def _fitted(x, y) -> float:
    return float(np.polyfit(np.log(np.asarray(x, float)), np.log(np.asarray(y, float)), 1)[0])


def test_work_precision_orders_are_recomputed_from_the_points(synthetic_report):
    """Order p (mean and max norm) and work slope of every method, fitted here by least squares
    on the rows, match the table to its 2 decimals (a flipped sign or swapped axes fail)."""
    page, rows = synthetic_report
    table = page.table("work-precision", "Fitted orders of convergence")
    cells = {(r["scenario"], r["quantity"], r["law"], r["solver"]): r for r in table.dicts()}
    assert len(cells) == len(WP_METHODS)
    wp = rows[rows["kind"] == "work_precision"]
    for (scen, target, law, solver, _), (_, order) in WP_METHODS.items():
        g = wp[(wp["scenario"] == scen) & (wp["target"] == target) & (wp["law"] == law)
               & (wp["solver"] == solver)]
        p = _fitted(g["h"], g["err_mean"])
        assert p == pytest.approx(order, abs=0.05)             # the data are ∝ h^order
        r = cells[(scen, target, law, solver)]
        assert _num(r["order p (mean norm)"]) == pytest.approx(p, abs=0.006)
        assert _num(r["order (max norm)"]) == pytest.approx(_fitted(g["h"], g["err_max"]), abs=0.006)
        assert _num(r["work slope s"]) == pytest.approx(-_fitted(g["cpu_time_s"], g["err_mean"]),
                                                        abs=0.006)
        assert _num(r["smallest error"]) == pytest.approx(g["err_mean"].min(), rel=5e-3)
        assert r["points"] == str(len(WP_H))
    # the sentence under the table and the key numbers quote the same fitted orders
    osc = wp[wp["scenario"] == "impact_oscillator"]
    p_osc = _fitted(osc["h"], osc["err_mean"])
    dm = wp[(wp["scenario"] == "double_mass") & (wp["target"] == "master") & (wp["solver"] == "pivoting")]
    p_dm = _fitted(dm["h"], dm["err_mean"])
    text = page.sections["work-precision"].text()
    assert f"p = {p_osc:.2f} … {p_osc:.2f} (impact_oscillator)" in text
    assert f"double_mass poisson (h/16 run reference) p = {p_dm:.2f}" in text
    jump = wp[(wp["target"] == "jump")]
    assert any(f"poisson {_fitted(jump['h'], jump['err_mean']):.2f}" in i
               for i in page.sections["all-key-numbers"].items)


def test_solver_comparison_totals_are_recomputed(synthetic_report):
    page, rows = synthetic_report
    wp = rows[(rows["kind"] == "work_precision") & (rows["target"] == "master")
              & (rows["scenario"] == "double_mass")]
    piv = wp[wp["solver"] == "pivoting"]["cpu_time_s"].sum()
    ref = wp[wp["solver"] == "reference"]["cpu_time_s"].sum()
    r = page.table("work-precision", "Contact solvers on the same method").dicts()[0]
    assert (r["scenario"], r["solver"]) == ("double_mass", "pivoting")
    assert _num(r["CPU solver (s)"]) == pytest.approx(piv, rel=5e-3)
    assert _num(r["CPU reference (s)"]) == pytest.approx(ref, rel=5e-3)
    assert _num(r["ratio reference / solver"]) == pytest.approx(ref / piv, rel=5e-3)


def test_scaling_exponents_are_recomputed(synthetic_report):
    """Every exponent of the fit table, refitted here by least squares on the rows; the
    acceptance exponent (from N = 10 to 1000) in the key numbers with its verdict; N = 5 is off
    the power law, so taking the fit over all N instead would be caught."""
    page, rows = synthetic_report
    sc = rows[rows["kind"] == "scaling"].sort_values("N")
    from10, big = sc[sc["N"] >= 10], sc[sc["N"] >= 50]
    expected = {"CPU time per step": _fitted(sc["N"], sc["cpu_per_step_s"]),
                "CPU time per step (N ≥ 10)": _fitted(from10["N"], from10["cpu_per_step_s"]),
                "CPU time per step (N ≥ 50)": _fitted(big["N"], big["cpu_per_step_s"]),
                "loop wall time per step (N ≥ 10)": _fitted(from10["N"], from10["loop_per_step_s"]),
                "whole call CPU time (N ≥ 10)": _fitted(from10["N"], from10["whole_call_cpu_s"]),
                "peak memory": _fitted(sc["N"], sc["peak_mem_mb"])}
    p10 = expected["CPU time per step (N ≥ 10)"]
    assert p10 == pytest.approx(1.04, abs=0.03)
    assert abs(expected["CPU time per step"] - p10) > 0.03          # the N = 5 outlier matters
    table = {r["quantity"]: r for r in page.table("scaling", "Fitted exponents").dicts()}
    assert set(table) == set(expected)
    for q, p in expected.items():
        assert _num(table[q]["exponent p"]) == pytest.approx(p, abs=0.006)
    assert table["CPU time per step (N ≥ 10)"]["N range"] == "10 … 1000"
    assert table["CPU time per step (N ≥ 50)"]["N range"] == "50 … 1000"
    key = next(i for i in page.sections["all-key-numbers"].items if i.startswith("Chain scaling"))
    assert key.startswith(f"Chain scaling: CPU time per step ∝ N^{p10:.2f} from N = 10 to 1000")
    assert f"all N from 5: N^{expected['CPU time per step']:.2f}" in key
    assert f"; N ≥ 50: N^{expected['CPU time per step (N ≥ 50)']:.2f})" in key
    assert ("acceptance (≤ 1.1 from N = 10 to 1000): met" in key) == (round(p10, 2) <= 1.1)
    whole = expected["whole call CPU time (N ≥ 10)"]
    assert f"the whole call (load_scenario + simulate: builder, validation, setup, loop, health) ∝ N^{whole:.2f}" in key
    whole_col = page.table("scaling", "Scaling of the chain").column("whole call CPU (s)")
    assert [_num(c) for c in whole_col] == pytest.approx(list(sc["whole_call_cpu_s"]), rel=5e-3)
    per_step = page.table("scaling", "Scaling of the chain").column("CPU per step (µs)")
    assert [_num(c) for c in per_step] == pytest.approx(list(sc["cpu_per_step_s"] * 1e6), rel=5e-3)


def test_robustness_medians_are_recomputed(synthetic_report):
    """Each floor cell of the robustness table starts with numpy's median of its point's rows
    (every master and initial error of the design), the table has one row per point, and the
    key number names the masters per level (the intervals are those of
    tests/reports/test_robustness_section.py)."""
    page, rows = synthetic_report
    rob = rows[rows["kind"] == "robustness"]
    table = page.table("robustness", "Robustness: floor of V/V(t_on) per level").dicts()
    assert len(table) == len(ROB_POINTS)
    for cells in table:
        kind = "none" if cells["perturbation"].startswith("none") else cells["perturbation"]
        assert cells["masters × errors"] == f"{ROB_MASTERS} × {ROB_ERRORS}"
        for name, d in OBSERVER_DESIGNS.items():
            col = next((c for c in cells if c.startswith(f"{d.label}: floor")), None)
            if col is None:
                continue
            g = rob[(rob["perturbation"] == kind) & (rob["design"] == name)]
            if kind != "none":
                g = g[np.isclose(g["size"].astype(float), _num(cells["level"]), rtol=5e-3)]
            assert len(g) == ROB_MASTERS * ROB_ERRORS
            assert _nums(cells[col])[0] == pytest.approx(np.median(g["floor"].astype(float)), rel=5e-3)
    key = next(i for i in page.sections["all-key-numbers"].items if i.startswith("Robustness ("))
    assert key.startswith(f"Robustness ({ROB_MASTERS} masters per level")
    assert "cluster bootstrap interval over masters" in page.sections["robustness"].paragraphs[0]


def _peer_cells(page) -> dict:
    return {r["problem"]: r for r in page.table("peers", "Siconos vs toolkit").dicts()}


def test_peers_section_ratios_are_recomputed(synthetic_report):
    """Per problem: the per-step times, Siconos ÷ toolkit for the whole call and for the loop,
    and the largest trajectory difference, from the rows; the same in the key numbers."""
    page, rows = synthetic_report
    pe = rows[rows["kind"] == "peers"].set_index("problem")
    cells = _peer_cells(page)
    assert sorted(cells) == sorted(p[0] for p in PEERS)
    for prob, r in pe.iterrows():
        c = cells[prob]
        assert _num(c["Siconos (µs/step)"]) == pytest.approx(r["siconos_ns_per_step"] / 1e3, rel=5e-3)
        assert _num(c["toolkit loop (µs/step)"]) == pytest.approx(r["toolkit_loop_ns_per_step"] / 1e3,
                                                                  rel=5e-3)
        assert _num(c["ratio (simulate)"]) == pytest.approx(
            r["siconos_ns_per_step"] / r["toolkit_ns_per_step"], rel=5e-3)
        assert _num(c["ratio (loop)"]) == pytest.approx(
            r["siconos_ns_per_step"] / r["toolkit_loop_ns_per_step"], rel=5e-3)
        assert _num(c["ratio run() / simulate"]) == pytest.approx(
            r["siconos_run_ns_per_step"] / r["toolkit_ns_per_step"], rel=5e-3)
        assert _num(c["max |Δu|"]) == pytest.approx(r["max_abs_diff_u"], rel=5e-3, abs=1e-300)
    key = next(i for i in page.sections["all-key-numbers"].items if i.startswith("Peers ("))
    for prob, r in pe.iterrows():
        ratio = r["siconos_ns_per_step"] / r["toolkit_ns_per_step"]
        loop = r["siconos_ns_per_step"] / r["toolkit_loop_ns_per_step"]
        assert f"{prob} {fmt_ratio(ratio)}× / {fmt_ratio(loop)}×" in key
    worst = max(pe["max_abs_diff_q"].max(), pe["max_abs_diff_u"].max())
    assert f"differ by at most {fmt(worst)}" in key


def _rows_file(path: Path, cases: list[tuple[str, list[dict]]]) -> Path:
    """Hand-made rows stored as a suite named ``path.stem`` (bench.results' case store); the
    path build_report reads."""
    from bench.run import write_suite_meta
    from bench.suites import Suite

    store = ResultsFile(path)
    for case_id, rows in cases:
        store.append_case(path.stem, case_id, rows)
    write_suite_meta(Suite(path.stem, "hand-made rows", ()), path.parent)    # as a bench run does
    return store.path


def test_peers_section_without_siconos(tmp_path, monkeypatch):
    """No peer rows: with the suite's 'Siconos absent' notes the section says so and how to get
    it; without peer cases it says where the comparison runs and whether the suite found
    Siconos (not, when its interpreter was missing: the suite's metadata records it)."""
    from bench import peers
    from bench.run import unavailable_path

    monkeypatch.setattr(peers, "SICONOS_PYTHON", "/nonexistent/bin/python3")
    cases = [c for c in _synthetic_rows() if c[0].startswith("scaling:")]
    path = _rows_file(tmp_path / "absent.cases", cases)
    unavailable_path("absent", tmp_path).write_text(json.dumps(
        {"peers:impact_oscillator:h=0.0001": "Siconos absent: no interpreter at /nonexistent/bin/python3; "
                                              + peers.HOW_TO_GET}))
    page = _parse(_section_page([path], tmp_path / "r1", "peers", "all-key-numbers"))
    text = page.sections["peers"].text()
    assert "Siconos was not available when the suite ran" in text and peers.HOW_TO_GET in text
    assert "peers:impact_oscillator" in text and page.sections["peers"].tables == []
    assert any(i.startswith("Peers: no Siconos results") for i in page.sections["all-key-numbers"].items)
    unavailable_path("absent", tmp_path).unlink()
    # the page shows the section as built (above): the section alone is enough from here
    from reports.context import load_context
    from reports.sections import peers as section

    sec = section.build(load_context([path], tmp_path / "r2"))
    text = " ".join(b.content for b in sec.blocks if b.kind == "p")
    assert [b.kind for b in sec.blocks] == ["p"]
    assert "python -m bench run peers" in text
    assert "Siconos was not available when the suite ran" in text and peers.HOW_TO_GET in text


def test_loop_micro_benchmarks_per_step_are_recomputed(synthetic_report):
    """Time per step = median per call ÷ steps for each engine, and the speed-up python ÷
    compiled, from the benchmark JSON."""
    page, _ = synthetic_report
    table = {r["case"]: r for r in page.table("micro", "Time loop per step").dicts()}
    assert set(table) == {case for case, _ in LOOPS}
    for case in table:
        steps, _, comp = LOOPS[(case, "compiled")]
        py = LOOPS[(case, "python")][2]
        assert _num(table[case]["compiled (µs/step)"]) == pytest.approx(comp / steps * 1e6, rel=5e-3)
        assert _num(table[case]["python (µs/step)"]) == pytest.approx(py / steps * 1e6, rel=5e-3)
        assert _num(table[case]["speed-up"]) == pytest.approx(py / comp, rel=5e-3)
        assert table[case]["rounds (compiled / python)"] == "10 / 5"
    key = next(i for i in page.sections["all-key-numbers"].items if i.startswith("Time per step"))
    assert "compile/cache load 0.8 s, not included" in key


def test_micro_speedups_are_recomputed(synthetic_report):
    page, _ = synthetic_report
    table = page.table("micro", "Speed-up of the fast contact solvers").dicts()
    assert [r["m"] for r in table] == ["1", "8"]
    for r in table:
        m = int(r["m"])
        for solver in ("pivoting", "lemke", "nnls"):
            speedup = MICRO_MEANS[(m, "reference")] / MICRO_MEANS[(m, solver)]
            assert r[f"speed-up {solver}"].endswith("×")
            assert _num(r[f"speed-up {solver}"]) == pytest.approx(speedup, rel=5e-3)
            assert _num(r[f"{solver} (µs)"]) == pytest.approx(MICRO_MEANS[(m, solver)] * 1e6, rel=5e-3)
    key = next(i for i in page.sections["all-key-numbers"].items if i.startswith("Fast contact solver"))
    assert _nums(key)[:2] == pytest.approx([MICRO_MEANS[(1, "reference")] / MICRO_MEANS[(1, "pivoting")], 1])


def test_proof_check_matrix_is_coloured_by_evidence_with_the_witness_on_hover(synthetic_report, tmp_path):
    """Scenario × check: each cell is the row's evidence level with its class and a hover text
    naming check, scenario, status, verdict and witness (HTML-escaped); "—" where a scenario has
    no row for a check; it is shown with the evidence of the claims; the full table sits in a
    <details> block of the proof-check section."""
    page, _ = synthetic_report
    m = page.table("ensemble", "Proof-check matrix").dicts()
    checks = list(dict.fromkeys(c[1] for c in CHECKS))
    assert [r["scenario"] for r in m] == list(dict.fromkeys(c[0] for c in CHECKS))
    rows = {r["scenario"]: r for r in m}
    for scen, check, _, status, *_ in CHECKS:
        assert rows[scen][check] == CHECK_EVIDENCE[check][0]
    for scen in rows:
        assert sum(rows[scen][c] == "—" for c in checks) == len(checks) - sum(c[0] == scen for c in CHECKS)
    doc = next(tmp_path.parent.glob("synthetic*/report/index.html")).read_text(encoding="utf-8")
    for scen, check, _, status, _, _, witness, reason in CHECKS:
        level, verdict = CHECK_EVIDENCE[check]
        cls = "evidence-na" if level == "n/a" else f"evidence-{level}"
        hover = f"{check} on {scen}: {status} — " + (reason if status == "n/a" else f"{verdict} | {witness}")
        hover = hover.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
        assert f'<td class="{cls}" title="{hover}">{level}</td>' in doc, hover
    sec = doc[doc.index('<section id="proof-checks">'):]
    assert sec.index("<details><summary>Witnesses: all 3 check rows") < sec.index("Proof-check table")
    table = page.table("proof-checks", "Proof-check table").dicts()
    assert [(r["evidence"], r["verdict"]) for r in table] == [
        (CHECK_EVIDENCE[c][0], CHECK_EVIDENCE[c][1] or "—") for _, c, *_ in CHECKS]
    assert "Proof-step evidence: 1 proved, 0 bounded, 0 sampled, 1 violated, 1 n/a." in \
        "\n".join(page.sections["all-key-numbers"].items)


@pytest.mark.parametrize("status,evidence,cell,cls", [
    ("PASS", "bounded", "bounded", "evidence-bounded"), ("FAIL", "violated", "violated", "evidence-violated"),
    ("FAIL", "sampled", "FAIL (sampled)", "evidence-violated"), ("n/a", "n/a", "n/a", "evidence-na"),
    ("PASS", "", "PASS", "evidence-unknown"), ("n/a", None, "n/a", "evidence-na")])
def test_matrix_cell_of_a_row(status, evidence, cell, cls):
    import pandas as pd
    from reports.sections.proof_checks import matrix_cell
    r = pd.Series({"scenario": "s", "check": "c", "check_status": status, "evidence": evidence,
                   "verdict": "v" if evidence else None, "witness": "w", "reason": "why"})
    got = matrix_cell(r)
    assert got[:2] == (cell, cls)
    assert got[2] == ("c on s: n/a — why" if status == "n/a" else f"c on s: {status} — " +
                      ("v | w" if evidence else "w"))


def test_proof_check_table_lists_every_check_row(synthetic_report):
    """Status, margin, tolerance and witness (or reason for n/a) of each check row, and the
    counts in the sentence above the table and in the key numbers."""
    page, _ = synthetic_report
    table = page.table("proof-checks", "Proof-check table").dicts()
    assert len(table) == len(CHECKS)
    for r, (scen, check, eq, status, margin, tol, witness, reason) in zip(table, CHECKS):
        assert (r["scenario"], r["check"], r["equation"], r["status"]) == (scen, check, eq, status)
        if status == "n/a":
            assert r["margin"] == "n/a" and r["witness / reason"] == reason
        else:
            assert _num(r["margin"]) == pytest.approx(margin, rel=5e-3)
            assert _num(r["tolerance"]) == pytest.approx(tol, rel=5e-3)
            assert r["witness / reason"] == witness
    counts = {s: sum(c[3] == s for c in CHECKS) for s in ("PASS", "FAIL", "n/a")}
    text = page.sections["proof-checks"].paragraphs[0]
    assert text.startswith(f"{len(CHECKS)} checks on 2 scenarios: {counts['PASS']} PASS, "
                           f"{counts['FAIL']} FAIL, {counts['n/a']} n/a.")
    assert f"Proof-step checks: {counts['PASS']} PASS, {counts['FAIL']} FAIL" in \
        "\n".join(page.sections["all-key-numbers"].items)
    # these rows do not say which design a check concerns: every design listed, no counts claimed
    per_design = page.table("proof-checks", "Proof checks per observer design").dicts()
    assert [r["design"] for r in per_design] == list(OBSERVER_DESIGNS)
    assert all(r["PASS"].startswith("n/a") for r in per_design)


# ----------------------------------------------------------------------------- analysis frames
# reports.analysis returns every table as a DataFrame: these tests check the frames without HTML,
# against numbers recomputed from the hand-made rows.
def _obs_frame() -> pd.DataFrame:
    return pd.DataFrame([r for _, rows in _observer_rows() for r in rows])


def test_analysis_observer_ratios_frame():
    """observer_ratios for the declared pair (nojump, jump): t_nojump / t_jump per ρ from the
    rows; a pair whose observers did not both run is left out."""
    from reports.analysis import headline, observer_ratios

    frame = observer_ratios(_obs_frame(), pairs=(("nojump", "jump"), ("jump", "jump_mass")))
    assert set(zip(frame["baseline"], frame["candidate"])) == {("nojump", "jump")}
    assert len(frame) == 3 * len(RHO_KEYS)
    dm = frame[frame["name"] == "dm"].set_index("rho")
    for rho in RHO_KEYS:
        assert dm.loc[rho, "ratio"] == pytest.approx(_settle("dm", "nojump", rho) / _settle("dm", "jump", rho))
        assert dm.loc[rho, "first_ratio"] == pytest.approx(_first("dm", "nojump", rho) / _first("dm", "jump", rho))
    stuck = frame[frame["name"] == "stuck"].set_index("rho")
    assert list(stuck["ratio"].iloc[:3]) == [INF] * 3 and np.isnan(stuck.loc[1e-9, "ratio"])
    assert headline(frame[frame["name"] == "dm"])["rho"] == 1e-9
    h = headline(frame[frame["name"] == "stuck"])
    assert h["kind"] == "candidate only" and h["settle"] == _settle("stuck", "jump", 1e-6)
    assert headline(frame[frame["name"] == "ball"])["kind"] == "candidate n/a"


def test_analysis_ratio_of_a_reversed_pair_is_the_reciprocal():
    """Declaring (jump, nojump) instead gives t_jump / t_nojump: the reciprocal where finite."""
    from reports.analysis import observer_ratios

    fwd = observer_ratios(_obs_frame(), pairs=(("nojump", "jump"),)).set_index(["name", "rho"])
    rev = observer_ratios(_obs_frame(), pairs=(("jump", "nojump"),)).set_index(["name", "rho"])
    both = np.isfinite(fwd["ratio"]) & (fwd["ratio"] > 0)
    assert both.sum() == len(RHO_KEYS)                     # dm only
    assert (fwd["ratio"][both] * rev["ratio"][both]).to_numpy() == pytest.approx(1.0, rel=1e-12)


def test_analysis_observer_runs_and_design_summary():
    """observer_runs: one row per run, the settling times of the rows; design_summary: every
    registered design listed, runs and applicable runs counted from the rows."""
    from reports.analysis import design_summary, observer_runs

    obs = _obs_frame()
    runs = observer_runs(obs)
    assert len(runs) == len(obs)
    dm_jump = runs[(runs["name"] == "dm") & (runs["observer"] == "jump")].iloc[0]
    assert [dm_jump[f"settle_{rho:g}"] for rho in RHO_KEYS] == list(OBSERVERS["dm"]["jump"][1])
    assert np.isnan(runs[(runs["name"] == "ball") & (runs["observer"] == "jump")]["settle_0.001"].iloc[0])
    summ = design_summary(obs).set_index("observer")
    assert list(summ.index) == list(OBSERVER_DESIGNS)
    for name in OBSERVER_DESIGNS:
        mine = obs[obs["observer"] == name]
        assert summ.loc[name, "runs"] == len(mine)
        assert summ.loc[name, "applicable"] == int((mine["status"] == "ok").sum())


def test_analysis_solver_comparison_and_check_counts():
    """solver_comparison: sums of the CPU times of each solver's sweep; check_counts: statuses
    counted per design (every registered design present) and in total."""
    from reports.analysis import check_counts, solver_comparison, wp_orders

    rows = pd.DataFrame([r for _, rs in _synthetic_rows() for r in rs])
    wp = rows[rows["kind"] == "work_precision"]
    comp = solver_comparison(wp_orders(wp))
    assert len(comp) == 1
    sel = wp[(wp["scenario"] == "double_mass") & (wp["target"] == "master")]
    piv, ref = (sel[sel["solver"] == s]["cpu_time_s"].sum() for s in ("pivoting", "reference"))
    assert comp["cpu_solver"].iloc[0] == pytest.approx(piv) and comp["ratio"].iloc[0] == pytest.approx(ref / piv)
    ch = rows[rows["kind"] == "checks"].assign(design=["", "jump", ""])
    counts = check_counts(ch).set_index("design")
    assert list(counts.index) == ["all", *OBSERVER_DESIGNS]
    for status in ("PASS", "FAIL", "n/a"):
        assert counts.loc["all", status] == sum(c[3] == status for c in CHECKS)
    assert (counts.loc["jump", "FAIL"], counts.loc["jump", "PASS"]) == (1, 0)
    assert counts.loc["nojump", ["PASS", "FAIL", "n/a"]].sum() == 0


def test_solver_comparison_uses_only_the_step_sizes_both_sweeps_ran():
    """A fast solver's sweep that goes to smaller h than the reference's is compared with it
    on the shared step sizes only: CPU sums and smallest errors over those h (the whole-sweep
    comparison would credit the fast solver with its extra, smaller steps)."""
    from reports.analysis import solver_comparison, wp_orders

    rows = pd.DataFrame([r for _, rs in _synthetic_rows() for r in rs])
    wp = rows[(rows["kind"] == "work_precision") & (rows["scenario"] == "double_mass")
              & (rows["target"] == "master")]
    h_ref = sorted(set(wp["h"]))[-3:]                      # the reference ran the 3 largest h
    wp = wp[(wp["solver"] != "reference") | wp["h"].isin(h_ref)]
    comp = solver_comparison(wp_orders(wp), wp).iloc[0]
    piv = wp[(wp["solver"] == "pivoting") & wp["h"].isin(h_ref)]
    ref = wp[wp["solver"] == "reference"]
    assert comp["steps"] == 3
    assert comp["cpu_solver"] == pytest.approx(piv["cpu_time_s"].sum())
    assert comp["cpu_reference"] == pytest.approx(ref["cpu_time_s"].sum())
    assert comp["best_err_solver"] == pytest.approx(piv["err_mean"].min())
    whole = solver_comparison(wp_orders(wp)).iloc[0]
    assert whole["best_err_solver"] < comp["best_err_solver"]     # the extra small steps


# ----------------------------------------------------------------------------- registries
def test_a_registered_design_shows_in_every_observer_table(tmp_path, monkeypatch):
    """A toy design added to the registry (one entry) and to the declared ratios: its runs appear
    in the observer table under its label, its ratio against the baseline is recomputed from the
    rows, and the design and proof-check summaries list it with its counts."""
    from observer.observers import ObserverDesign
    from reports import registry

    toy = ObserverDesign("toy", True, "identity", "toy design (test)", "tab:olive", "-.")
    monkeypatch.setitem(OBSERVER_DESIGNS, "toy", toy)
    monkeypatch.setattr(registry, "RATIOS", (("nojump", "jump"), ("nojump", "toy")))
    cases = _observer_rows()
    dm_jump = next(r for r in cases[0][1] if r["observer"] == "jump")
    slow = 1.7                                              # the toy settles 1.7× later than jump
    toy_row = {**dm_jump, "observer": "toy",
               **{f"t_settle_{k}": slow * dm_jump[f"t_settle_{k}"] for k in RHO_KEYS.values()},
               **{f"t_sync_{k}": slow * dm_jump[f"t_sync_{k}"] for k in RHO_KEYS.values()}}
    cases.append(("observers:dm:toy", [toy_row]))
    cases.append(("checks", [{"kind": "checks", "scenario": "dm", "name": "dm", "check": c, "design": d,
                              "equation": "(16)", "check_status": st, "margin": mg, "tolerance": 0.0,
                              "witness": "w", "reason": "", "status": "ok"}
                             for c, d, st, mg in (("lyapunov_decrease", "toy", "FAIL", -1.0),
                                                  ("proposition1_exact", "toy", "PASS", 0.0),
                                                  ("mass_spd", "", "PASS", 1.0))]))
    page = _parse(_section_page([_rows_file(tmp_path / "toy.cases", cases)], tmp_path / "r", "observers",
                                "proof-checks"))
    observers = [r for r in page.table("observers", "Observer table").dicts() if r["scenario"] == "dm"]
    assert [r["observer"] for r in observers] == [OBSERVER_DESIGNS[o].label for o in ("jump", "nojump")] \
        + [toy.label]
    ratio = {(r["scenario"], r["baseline / candidate"]): r
             for r in page.table("observers", "Settling-time ratio").dicts()}
    for rho in RHO_KEYS:
        cell = ratio[("dm", "nojump / toy")][f"ratio at ρ = {fmt_rho(rho)}"]
        t_toy = slow * _settle("dm", "jump", rho)
        assert _nums(cell)[:3] == pytest.approx([_settle("dm", "nojump", rho) / t_toy,
                                                 _settle("dm", "nojump", rho), t_toy], rel=5e-3)
    assert ("stuck", "nojump / toy") not in ratio           # the toy did not run there
    designs = {r["design"]: r for r in page.table("observers", "Registered observer designs").dicts()}
    assert list(designs) == list(OBSERVER_DESIGNS)
    assert (designs["toy"]["label"], designs["toy"]["runs"]) == (toy.label, "1")
    per_design = {r["design"]: r for r in page.table("proof-checks", "Proof checks per observer design").dicts()}
    assert (per_design["toy"]["PASS"], per_design["toy"]["FAIL"]) == ("1", "1")
    assert per_design["nojump"]["PASS"] == "0"
    checks = page.table("proof-checks", "Proof-check table").dicts()
    assert [r["design"] for r in checks] == [toy.label, toy.label, "—"]


def test_rows_are_ordered_whatever_the_storage_order(tmp_path):
    """load order of case files carries no meaning: order_rows sorts by suite, the declared case
    order (from the suite's metadata sidecar; case id without one) and the row within the case."""
    from bench.run import write_suite_meta
    from reports.context import order_rows

    rows = pd.DataFrame([{"suite": "synthetic", "case_id": cid, "row": i, **r}
                         for cid, rs in _synthetic_rows() for i, r in enumerate(rs)])
    shuffled = rows.sample(frac=1.0, random_state=3).reset_index(drop=True)
    a, b = order_rows(rows), order_rows(shuffled)
    assert a[["case_id", "row"]].values.tolist() == b[["case_id", "row"]].values.tolist()
    assert list(a["case_id"]) == sorted(rows["case_id"])      # undeclared suite: by case id
    from bench.suites import SUITES, Suite
    cases = SUITES["quick"].cases[:5][::-1]                   # declared against case-id order
    quick = [c.case_id for c in cases]
    assert sorted(quick) != quick
    declared = pd.DataFrame({"suite": "q", "case_id": sorted(quick), "row": 0, "results_dir": str(tmp_path)})
    assert list(order_rows(declared)["case_id"]) == sorted(quick)   # no sidecar: by case id
    write_suite_meta(Suite("q", "", cases), tmp_path)
    assert list(order_rows(declared)["case_id"]) == quick     # declared suite: declared order


def test_suite_names_resolve_to_where_bench_stores_them(tmp_path):
    from reports.context import suite_results

    assert suite_results("quick", tmp_path) == results_path("quick", tmp_path)


def test_limitations_and_settings_quote_the_rows_and_the_registries(synthetic_report):
    """The numbers in the limitations and settings prose come from the rows, the suites'
    thresholds and the solvers' acceptance constant, not from fixed text."""
    from observer.contact import ACCEPT_RESIDUAL
    from observer.metrics import RHOS

    page, rows = synthetic_report
    lim = "\n".join(page.sections["limitations"].items)
    assert f"the deepest threshold ({fmt_rho(min(RHOS))})" in lim
    scal = rows[rows["kind"] == "scaling"]
    assert f"from rest over T = {fmt(float(scal['t_end'].iloc[0]))} s;" in lim
    assert "Robustness uses double_mass only" in lim
    assert "an unrecorded number of BLAS thread(s)" in lim        # the synthetic rows have none
    ball = rows[(rows["name"] == "ball") & (rows["status"] != "ok")].iloc[0]
    assert f"ball: the design {ball['observer']} does not apply ({ball['note']})" in lim
    for design in ("jump_mass", "jump_identity"):
        if design in OBSERVER_DESIGNS:
            assert f"{design} ({OBSERVER_DESIGNS[design].metric} metric)" in lim
    refs = set(rows.loc[rows["kind"] == "work_precision", "reference"]) - {"closed form (event-driven)"}
    assert all(r in lim for r in refs)
    settings = {r["quantity"]: r["definition / value"]
                for r in page.table("settings", "Tolerances and definitions").dicts()}
    assert settings["synchronization thresholds ρ"] == ", ".join(fmt(r) for r in RHOS)
    assert f"≤ {fmt(ACCEPT_RESIDUAL)} for block pivoting" in settings["contact-solve acceptance"]
    worst = max(MICRO_MEANS.values()) * RESIDUAL_PER_SECOND
    assert settings["largest residual of a timed contact solve"] == fmt(worst)
    assert settings["ratios (baseline / candidate)"].startswith("nojump/jump")


def test_context_rows_carry_every_schema_column_and_refuse_unknown_kinds(tmp_path):
    """ReportContext.rows(kind): the rows of that kind with every column observer.row_schema declares
    for it (NaN where missing); an unknown kind is an error naming it."""
    from observer.row_schema import ROWS
    from reports.context import ReportContext

    df = pd.DataFrame([{"kind": "scaling", "N": 5, "status": "ok"}, {"kind": "checks", "status": "n/a"}])
    ctx = ReportContext(df=df, files=[], micro=pd.DataFrame(), micro_meta={}, suites=["x"],
                        command="", out_dir=tmp_path)
    scal = ctx.rows("scaling")
    assert len(scal) == 1 and set(ROWS["scaling"]) <= set(scal.columns)
    assert np.isnan(scal["peak_mem_mb"].iloc[0]) and scal["N"].iloc[0] == 5
    assert ctx.rows("checks", ok_only=True).empty and ctx.rows("observers").empty
    with pytest.raises(ValueError, match="kind: unknown row kind 'scalling'"):
        ctx.rows("scalling")


def test_a_registered_contact_solver_shows_in_the_micro_benchmarks(tmp_path, monkeypatch):
    """A toy contact solver added to CONTACT_SOLVERS (one entry) gets its own columns in the
    speed-up table, its speed-up recomputed from the benchmark JSON."""
    from observer.contact import CONTACT_SOLVERS

    monkeypatch.setitem(CONTACT_SOLVERS, "toy", object)
    data = _micro_json()
    toy_means = {1: 8.0e-6, 8: 1.0e-4}
    data["benchmarks"] += [{"group": f"contact solve m={m}", "name": f"test_solve[toy-{m}]",
                            "stats": {"mean": t, "median": t, "stddev": t / 10, "min": t, "rounds": 5},
                            "extra_info": {"kind": "contact_solve", "solver": "toy", "m": m, "residual": 0.0}}
                           for m, t in toy_means.items()]
    path = _rows_file(tmp_path / "solvers.cases", [c for c in _synthetic_rows() if c[0].startswith("checks")])
    (tmp_path / "solvers-micro.json").write_text(json.dumps(data))
    page = _parse(_section_page([path], tmp_path / "r", "micro"))
    table = {r["m"]: r for r in page.table("micro", "Speed-up of the fast contact solvers").dicts()}
    for m, t in toy_means.items():
        assert _num(table[str(m)]["speed-up toy"]) == pytest.approx(MICRO_MEANS[(m, "reference")] / t, rel=5e-3)
        assert _num(table[str(m)]["toy (µs)"]) == pytest.approx(t * 1e6, rel=5e-3)


def test_a_registered_scenario_brings_its_description_and_notes(tmp_path, monkeypatch):
    """A toy scenario module in SCENARIOS (one entry): its subsection opens with the module's
    own description and notes, then the settings of its rows."""
    import types

    from observer.scenarios import SCENARIOS

    toy = types.ModuleType("toy_scenario")
    toy.DESCRIPTION, toy.PARAMETERS = "toy oscillator for the report test", {}
    toy.NOTES = "drawn: the toy coordinate."
    monkeypatch.setitem(SCENARIOS, "toy_scenario", toy)
    rows = [{**r, "scenario": "toy_scenario", "name": "toy run"} for r in _observer_rows()[0][1]]
    page = _parse(_section_page([_rows_file(tmp_path / "scn.cases", [("observers:toy", rows)])], tmp_path / "r",
                                "scenarios"))
    intro = page.sections["scn-toy-run"].paragraphs[0]
    assert intro.startswith("Toy oscillator for the report test. Drawn: the toy coordinate. Settings: "
                            f"h = {fmt(rows[0]['h'])} s, T = {fmt(rows[0]['t_end'])} s")


def test_design_pivot_puts_each_run_in_its_cell(synthetic_report):
    """The per-scenario × design table: V_end/V(t_on) and the rate of each run, from the rows;
    n/a where the design does not apply."""
    from reports.analysis import design_pivot

    page, rows = synthetic_report
    obs = rows[rows["kind"] == "observers"]
    piv = design_pivot(obs)
    ok = obs[obs["status"] == "ok"]
    assert piv.notna().sum().sum() == len(ok)
    for _, r in ok.iterrows():
        assert piv.loc[r["name"], r["observer"]] == r["V_end_rel"]
    table = {r["scenario"]: r for r in page.table("observers", "V at the end of the window").dicts()}
    label = OBSERVER_DESIGNS["jump"].label
    assert table["ball"][label] == "n/a"
    dm = ok[(ok["name"] == "dm") & (ok["observer"] == "jump")].iloc[0]
    assert _nums(table["dm"][label])[:2] == pytest.approx([dm["V_end_rel"], dm["rate"]], rel=5e-3)


def test_runs_of_another_integrator_are_named_apart(tmp_path):
    """A scenario run by the default integrator and by another one shows as two runs (the
    other's name carries its integrator), never merged into one row of the ratio table."""
    from reports.context import ReportContext
    from reports.registry import default_integrator

    rows = [r for r in _observer_rows()[0][1]]
    event = [{**r, "integrator": "event", "V_end_rel": 1e-20} for r in rows]
    df = pd.DataFrame([{**r, "integrator": default_integrator()} for r in rows] + event)
    ctx = ReportContext(df=df, files=[], micro=pd.DataFrame(), micro_meta={}, suites=["x"],
                        command="", out_dir=tmp_path)
    obs = ctx.rows("observers")
    assert sorted(set(obs["name"])) == ["dm", "dm · event"]
    assert (obs.loc[obs["name"] == "dm · event", "V_end_rel"] == 1e-20).all()


def test_event_driven_sweeps_are_not_compared_as_contact_solvers():
    """A work-precision sweep of another integrator keeps its own fitted order and stays out
    of the contact-solver comparison (which is about the time-stepping LCPs)."""
    from reports.analysis import solver_comparison, wp_orders

    rows = pd.DataFrame([r for _, rs in _synthetic_rows() for r in rs])
    wp = rows[rows["kind"] == "work_precision"].assign(integrator="time-stepping")
    master = wp[(wp["scenario"] == "double_mass") & (wp["target"] == "master") & (wp["solver"] == "pivoting")]
    event = master.assign(integrator="event", method=master["method"] + " · event-driven",
                          err_mean=master["err_mean"] * 1e-6)
    orders = wp_orders(pd.concat([wp, event]))
    ev = orders[orders["integrator"] == "event"]
    assert len(ev) == 1 and ev["order"].iloc[0] == pytest.approx(_fitted(event["h"], event["err_mean"]))
    assert len(solver_comparison(orders)) == len(solver_comparison(wp_orders(wp))) == 1


def test_design_key_number_is_the_median_final_v_of_each_design(synthetic_report):
    page, rows = synthetic_report
    obs = rows[(rows["kind"] == "observers") & (rows["status"] == "ok")]
    key = next(i for i in page.sections["all-key-numbers"].items if i.startswith("Observer designs, median"))
    for name, g in obs.groupby("observer"):
        label = OBSERVER_DESIGNS[name].label
        assert f"{label} {fmt(float(np.median(g['V_end_rel'])))} ({len(g)} runs)" in key


def test_peak_memory_is_fitted_within_one_storage_mode():
    """The full scaling suite stores every step up to N = 1000 and one row every 0.1 s beyond:
    a single fit across the switch measures the switch. Synthetic rows: memory ∝ N in each mode,
    with a 10× drop at the switch; each mode's fit gives 1, a fit across both would give ≈ 0.5."""
    from reports.analysis import scaling_fits

    N = np.array([10, 100, 1000, 2000, 20_000, 200_000], float)
    sparse = N > 1000
    mem = np.where(sparse, 0.01, 0.1) * N
    rows = pd.DataFrame({"N": N, "cpu_per_step_s": 1e-6 * N, "peak_mem_mb": mem,
                         "h_record": np.where(sparse, 0.1, np.nan)})
    fits = scaling_fits(rows, 10).set_index("quantity")["exponent"]
    assert fits["peak memory (every step stored)"] == pytest.approx(1.0, abs=1e-12)
    assert fits["peak memory (a row every 0.1 s)"] == pytest.approx(1.0, abs=1e-12)
    assert "peak memory" not in fits
    assert _fitted(N, mem) < 0.8                                  # what one fit across both says
    one_mode = scaling_fits(rows.assign(h_record=np.nan), 10).set_index("quantity")["exponent"]
    assert one_mode["peak memory"] == pytest.approx(_fitted(N, mem), abs=1e-12)
