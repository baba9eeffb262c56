"""HTML report (reports/): sections, tables without NaN, self-contained figures, browser check.

The browser check opens the generated page in headless Chromium (Debian ``chromium``);
it is skipped only when no Chromium is installed (``.ci/run`` installs it).
"""

from __future__ import annotations

import base64
import os
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.run import micro_path, results_path, run_suite
from reports.browser import check_page, find_chromium
from reports.build import build_report, fit_power, ratio_rows
from reports.tables import fmt, fmt_rho, fmt_time

REPO = Path(__file__).resolve().parent.parent
SECTIONS = ["Key numbers", "Scenarios: trajectories", "Observer table", "Work-precision",
            "Robustness", "Scaling", "Micro-benchmarks", "Proof-step checks",
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


@pytest.fixture(scope="module")
def smoke_report(tmp_path_factory):
    """The smoke suite, a small real micro-benchmark run, and the report built from them."""
    out = tmp_path_factory.mktemp("results")
    summary = run_suite("smoke", out, progress=False)
    assert not summary.failed, summary.failed
    env = {**os.environ, "PYTHONPATH": str(REPO), "OPENBLAS_NUM_THREADS": "1"}
    res = subprocess.run([sys.executable, "-m", "pytest", "bench/micro", "-q", "-p", "no:cacheprovider",
                          "--benchmark-only", f"--benchmark-json={micro_path('smoke', out)}",
                          "--benchmark-min-rounds=2", "--benchmark-max-time=0.001",
                          "-k", "double_mass or solve and 1]"],
                         cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    index = build_report([results_path("smoke", out)], tmp_path_factory.mktemp("report"))
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
    index, _ = smoke_report
    html = index.read_text(encoding="utf-8")
    assert "n/a (K = 0" in html                          # jump observer on the bouncing ball
    assert "not reached" in html                         # 1 s runs do not reach 1e-9


def test_proof_check_section_is_defensive(smoke_report, tmp_path):
    """With check rows the table is shown; without, the section says why (no crash)."""
    index, out = smoke_report
    html = index.read_text(encoding="utf-8")
    try:
        import proofs_checks  # noqa: F401
        assert "Proof-check table" in html
        assert "PASS" in html
    except Exception:
        assert "No proof-check results" in html
    rows = [line for line in results_path("smoke", out).read_text().splitlines()
            if '"kind":"checks"' not in line]
    path = tmp_path / "nochecks.jsonl"
    path.write_text("\n".join(rows) + "\n")
    page = build_report([path], tmp_path / "r").read_text(encoding="utf-8")
    assert "No proof-check results" in page


def test_cli_builds_report_and_rejects_missing_results(smoke_report, tmp_path):
    _, out = smoke_report
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    res = subprocess.run([sys.executable, "-m", "reports", "smoke", "--results", str(out),
                          "--out", str(tmp_path / "cli")], cwd=REPO, env=env, capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "cli" / "index.html").exists()
    res = subprocess.run([sys.executable, "-m", "reports", "nosuchsuite", "--results", str(tmp_path)],
                         cwd=REPO, env=env, capture_output=True, text=True)
    assert res.returncode == 2 and "python -m bench run nosuchsuite" in res.stderr


# ----------------------------------------------------------------------------- pieces
def _obs_row(name, observer, t3, t6, floor_rel, closed, status="ok", note=""):
    inf = float("inf")
    return {"name": name, "observer": observer, "status": status, "note": note, "t_on": 0.0,
            "t_off": 10.0, "t_sync_0.001": t3, "t_sync_1e-05": t6, "t_sync_1e-06": t6,
            "t_sync_1e-09": inf, "floor_rel": floor_rel, "master_closed_fraction": closed}


def test_ratio_rows_and_verdicts():
    inf = float("inf")
    obs = pd.DataFrame([
        _obs_row("dm", "jump", 2.0, 4.0, 1e-10, 0.2), _obs_row("dm", "nojump", 3.0, 8.0, 1e-7, 0.2),
        _obs_row("rest", "jump", 3.0, 6.0, 1e-9, 1.0), _obs_row("rest", "nojump", inf, inf, 0.5, 1.0),
        _obs_row("ball", "jump", np.nan, np.nan, np.nan, 0.1, "n/a", "K is not positive definite"),
        _obs_row("ball", "nojump", 3.9, 4.0, 0.0, 0.1)])
    recs = {r["name"]: r for r in ratio_rows(obs)}
    assert "2.00 at ρ = 1e−6" in recs["dm"]["headline"]
    assert recs["dm"]["verdict"].startswith("converges")
    assert "does NOT converge at all: persistent contact" in recs["rest"]["verdict"]
    assert recs["rest"]["headline"].startswith("∞")
    assert recs["ball"]["headline"].startswith("n/a") and "K = 0" in recs["ball"]["headline"]


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


def test_broken_proofs_checks_is_reported_not_fatal(tmp_path, monkeypatch):
    """If proofs_checks raises, the suite skips the checks (retried next run, not written) and
    the report's proof-check section says why instead of crashing."""
    import types

    from bench.results import ResultsFile
    from bench.run import unavailable_path
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
    assert summary.ran == 1 and not summary.failed
    assert len(summary.unavailable) == 1 and "under construction" in summary.unavailable[0][1]
    assert ResultsFile(results_path("pc", tmp_path)).done_ids() == {suite.cases[0].case_id}
    assert unavailable_path("pc", tmp_path).exists()
    page = build_report([results_path("pc", tmp_path)], tmp_path / "r").read_text(encoding="utf-8")
    assert "No proof-check results" in page and "checks under construction" in page
