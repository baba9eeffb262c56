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
            f"d = {lat[0]:.0e} … {lat[-1]:.0e} s".replace("e-0", "e-"),
            f"regression intervals over {r['settings']['members']} paired members"]


FOREST_NAMES = {"double_mass": "double mass", "grazing": "grazing",
                "bouncing_ball (ball on a spring, K > 0)": "ball on a spring",
                "impact_oscillator": "impact oscillator", "rocking_chain (N = 10)": "(N = 10)",
                "random_system (seed 0, 2 DOF, 1 contact)": "seed 0", "random_system (seed 1, 3 DOF, 2 contacts)": "seed 1",
                "random_system (seed 2, 4 DOF, 3 contacts)": "seed 2", "random_system (seed 3, 5 DOF, 4 contacts)": "seed 3",
                "random_system (all 4 systems)": "pooled"}
"""The forest rows the README quotes (label in ``quick_forest.csv`` → the README's name)."""


def forest_quotes() -> list[str]:
    import pandas as pd

    meta = json.loads((STORED / "quick_forest.json").read_text())
    assert meta["status"] == "ok"
    f = pd.read_csv(STORED / "quick_forest.csv").set_index("label")
    assert (f.loc[list(FOREST_NAMES), "status"] == "ok").all()
    g = lambda x: f"{x:.3g}"                                     # noqa: E731
    quotes = [f"{name} {g(f.at[label, 'estimate'])} [{g(f.at[label, 'low'])}, {g(f.at[label, 'high'])}]"
              for label, name in FOREST_NAMES.items()]
    slower = [label for label in FOREST_NAMES if f.at[label, "high"] < 1.0]
    faster = [label for label in FOREST_NAMES if f.at[label, "low"] > 1.0 and label.startswith("random_system (seed")]
    quoted = f.loc[[label for label in FOREST_NAMES if label != "random_system (all 4 systems)"]]
    (members,) = set(quoted["members"])
    masters = set(quoted["masters"])
    assert masters == {1, 5} and set(quoted.index[quoted["masters"] == 1]) == {"grazing"}
    quotes.append(f"{members} paired initial errors per scenario over 5 masters, grazing's over 1")
    words = {2: "two"}
    quotes += [f"slower on {words[len(slower)]} of four", f"faster on {words[len(faster)]} ("]
    return quotes


@pytest.mark.parametrize("quotes", [model_quotes, latency_quotes, forest_quotes],
                         ids=["model-error", "latency", "jump-vs-nojump"])
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
