"""Every number the README's "What the measurements say" quotes is the stored result's.

The README quotes measurements only from ``bench/stored/`` (the guide's rule: a number in
prose only where a stored result keeps it true). These tests recompute each quoted string
from the stored JSON, formatted as the README writes it, and fail when the text and the result
disagree: a re-run of ``python -m bench.model_error`` or ``python -m bench.latency_floor`` that
moves a slope makes the README wrong, and this test says which number.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
STORED = REPO / "bench" / "stored"


def section() -> str:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    m = re.search(r"^## What the measurements say\n(.*?)^## ", text, re.S | re.M)
    assert m, "README has no 'What the measurements say' section"
    return " ".join(m.group(1).split())          # one line: the quotes may wrap


def interval(x: float, lo: float, hi: float, digits: int) -> str:
    return f"{x:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def sci(x: float) -> str:
    """``8.4e-3``: two significant digits, the exponent as the README writes it."""
    mantissa, exponent = f"{x:.1e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def model_quotes() -> list[str]:
    r = json.loads((STORED / "model_error_floor_double_mass.json").read_text())
    assert r["status"] == "ok"
    j, n = r["designs"]["jump"], r["designs"]["nojump"]
    eps = r["epsilons"]
    return [interval(j["slope"], *j["slope_interval_95"], 3) + " with jumps",
            interval(n["slope"], *n["slope_interval_95"], 2) + " without",
            f"over {r['members']} paired members",
            f"ε = {eps[0]:.0e} … {eps[-1]:.0e}".replace("e-0", "e-"),
            f"At ε = 1 % the floors are {sci(j['floor_median'][-1])} and {sci(n['floor_median'][-1])}"]


def latency_quotes() -> list[str]:
    r = json.loads((STORED / "latency_floor_double_mass.json").read_text())
    assert r["status"] == "ok"
    fits = {f["design"]: f for f in r["fits"]}
    assert all(f["status"] == "ok" for f in fits.values())
    j, n = fits["jump"], fits["nojump"]
    lat = r["settings"]["latencies"]
    return [interval(j["slope"], *j["interval"]["regression"], 3) + " with jumps",
            interval(n["slope"], *n["interval"]["regression"], 3) + " without",
            f"d = {lat[0]:.0e} … {lat[-1]:.0e} s".replace("e-0", "e-")]


@pytest.mark.parametrize("quotes", [model_quotes, latency_quotes], ids=["model-error", "latency"])
def test_the_readme_quotes_the_stored_result(quotes):
    text = section()
    missing = [q for q in quotes() if q not in text]
    assert not missing, f"README's 'What the measurements say' does not quote the stored result: {missing}"


def test_a_moved_slope_is_caught(tmp_path, monkeypatch):
    """The near miss: the stored slope moved in its third decimal is no longer what the README says."""
    r = json.loads((STORED / "model_error_floor_double_mass.json").read_text())
    r["designs"]["jump"]["slope"] += 0.002
    (tmp_path / "model_error_floor_double_mass.json").write_text(json.dumps(r))
    monkeypatch.setitem(globals(), "STORED", tmp_path)
    text = section()
    assert [q for q in model_quotes() if q not in text] == [model_quotes()[0]]
