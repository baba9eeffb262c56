"""proofs_checks.result.CheckResult: its verdict rule and every text view, character by
character, on hand-built results (synthetic, well under a second). Written against the
mutation run of ``result.py`` (``tests/mutants/proofs_checks_small.md``).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from proofs_checks.result import EVIDENCE_LEVELS, STATUS_TEXT, CheckResult, _fmt, _jsonable


def test_from_margin_verdict_edge_and_negative_zero():
    r = CheckResult.from_margin("x", -0.1, 0.1, {}, "eq")
    assert r.passed is True and r.margin == -0.1 and r.tolerance == 0.1    # margin = −tolerance passes
    assert CheckResult.from_margin("x", -0.1000001, 0.1, {}, "eq").passed is False
    r = CheckResult.from_margin("x", -0.0, 0, {"a": 1}, "eq (1)", ("a",), "why")
    assert math.copysign(1.0, r.margin) == 1.0 and r.passed is True
    assert isinstance(r.tolerance, float) and r.witness == {"a": 1}
    assert (r.name, r.equation, r.summary_keys, r.reason) == ("x", "eq (1)", ("a",), "why")
    assert r.scenario == "" and r.elapsed == 0.0
    r = CheckResult.from_margin("x", np.float64(np.nan), 1.0, {}, "eq")
    assert r.passed is False and isinstance(r.passed, bool)
    assert CheckResult.from_margin("x", np.inf, 0.0, {}, "").passed is True
    assert CheckResult.from_margin("x", -np.inf, 1e300, {}, "").passed is False


def test_not_applicable_record():
    r = CheckResult.not_applicable("y", "because", "A1", k=3)
    assert r.passed is None and math.isnan(r.margin) and math.isnan(r.tolerance)
    assert r.witness == {"k": 3} and r.reason == "because" and r.equation == "A1" and r.name == "y"
    assert CheckResult.not_applicable("y", "r").equation == ""
    assert STATUS_TEXT == {True: "PASS", False: "FAIL", None: "n/a"}


def test_summary_texts():
    w = {"a": 1.23456, "b": "s", "c": np.arange(3.0), "d": 7}
    r = CheckResult.from_margin("x", 1.0, 0.0, w, "eq", ("c", "a", "missing"))
    assert r.summary() == "c=[0, 1, 2], a=1.235"
    r = CheckResult.from_margin("x", 1.0, 0.0, dict(w, e=5), "eq")          # no keys: the first four
    assert r.summary() == "a=1.235, b=s, c=[0, 1, 2], d=7"
    r = CheckResult.from_margin("x", -1.0, 0.0, {"a": 2.0}, "eq", ("a",), "bad thing")
    assert r.summary() == "bad thing | a=2"
    r = CheckResult.from_margin("x", -1.0, 0.0, {}, "eq", (), "bad thing")
    assert r.summary() == "bad thing"
    r = CheckResult.from_margin("x", 1.0, 0.0, {"a": 2.0}, "eq", ("a",), "a note")
    assert r.summary() == "a=2; a note"
    r = CheckResult.from_margin("x", 1.0, 0.0, {}, "eq", (), "a note")
    assert r.summary() == "a note"
    r = CheckResult.not_applicable("y", "because")
    assert r.summary() == "not applicable: because"
    long = CheckResult.not_applicable("y", "z" * 200)
    assert long.summary() == ("not applicable: " + "z" * 200)[:107] + "..."
    assert len(long.summary(20)) == 20 and long.summary(20).endswith("...")
    exact = CheckResult.not_applicable("y", "z" * 94)             # 16 + 94 = 110: not cut
    assert exact.summary() == "not applicable: " + "z" * 94


def test_message_lines():
    r = CheckResult.from_margin("chk", -0.5, 0.125, {"a": 1.5, "v": np.arange(3.0)}, "eq. (0)", ("v",),
                                "it broke")
    r.scenario = "sc"
    assert r.message().splitlines() == [
        "chk [eq. (0)] FAIL on sc",
        "  evidence  = violated",
        "  margin    = -0.5 (tolerance 0.125; satisfied when margin >= -tolerance)",
        "  reason    = it broke",
        "  witness:",
        "    a = 1.5",
        "    v = [0, 1, 2]",
    ]
    na = CheckResult.not_applicable("chk", "no K", "A1")
    assert na.message().splitlines() == ["chk [A1] NOT APPLICABLE", "  reason    = no K"]
    ok = CheckResult.from_margin("chk", 2.0, 0.0, {}, "E")
    assert ok.message() == ("chk [E] PASS\n  evidence  = sampled\n"
                            "  margin    = 2 (tolerance 0; satisfied when margin >= -tolerance)")
    proved = CheckResult.from_margin("chk", 2.0, 0.0, {}, "E", evidence="proved", verdict="exact LDLᵀ")
    assert proved.message().splitlines()[1] == "  evidence  = proved: exact LDLᵀ"


def test_rows_dicts_and_truth_value():
    r = CheckResult.from_margin("chk", -0.5, 0.1, {"v": np.arange(2), "x": np.float64(np.inf),
                                                   "s": {1}, "o": object}, "eq", ("v",), "why")
    r.scenario, r.elapsed = "sc", 1.5
    row = r.to_row()
    assert row == {"scenario": "sc", "check": "chk", "equation": "eq", "status": "FAIL", "evidence": "violated",
                   "passed": False, "margin": -0.5, "tolerance": 0.1, "verdict": None,
                   "witness": "why | v=[0, 1]", "reason": "why", "elapsed": 1.5}
    long = CheckResult.from_margin("c", 1.0, 0.0, {"a": "q" * 300}, "e", ("a",))
    assert long.to_row()["witness"] == "a=" + "q" * 300                   # the row is not cut
    d = r.to_dict()
    assert d["status"] == "FAIL" and "summary_keys" not in d
    assert d["witness"]["v"] == [0, 1] and d["witness"]["x"] == "Infinity"
    assert d["witness"]["s"] == [1] and d["witness"]["o"] == str(object)
    assert d["margin"] == -0.5 and d["name"] == "chk" and d["passed"] is False
    assert d["evidence"] == "violated" and d["verdict"] is None
    json.dumps(d)
    assert CheckResult.not_applicable("y", "r").to_dict()["margin"] == "NaN"
    with pytest.raises(TypeError, match="use CheckResult.passed"):
        bool(r)


def test_jsonable_and_fmt():
    assert _jsonable(np.array([[1, 2]])) == [[1, 2]]
    assert _jsonable(np.float32(0.5)) == 0.5 and type(_jsonable(np.int64(3))) is int
    assert _jsonable(np.bool_(True)) is True
    assert _jsonable((1, 2)) == [1, 2] and _jsonable(frozenset([4])) == [4]
    assert _jsonable(1 + 2j) == "(1+2j)"
    assert _fmt(1.23456789) == "1.235" and _fmt(np.float32(2.0)) == "2"
    assert _fmt(True) == "True" and _fmt(np.int64(4)) == "4" and _fmt("s") == "s" and _fmt(np.bool_(False)) == "False"
    assert _fmt([1.0, 2.5]) == "[1, 2.5]" and _fmt((1, 2)) == "[1, 2]"
    assert _fmt(np.arange(10)) == "[0, 1, 2, 3, 4, 5, 6, 7, ...]"
    assert _fmt(np.arange(8)) == "[0, 1, 2, 3, 4, 5, 6, 7]"
    assert _fmt(np.arange(10), long=True) == "[" + ", ".join(map(str, range(10))) + "]"
    assert _fmt(np.arange(70.0), long=True).endswith("63, ...]")
    assert _fmt(np.arange(64.0), long=True).endswith(", 63]")
    assert _fmt(np.eye(2)) == "(2x2)[1, 0, 0, 1]"
    assert _fmt(np.array([True, False])) == "[True, False]"
    assert _fmt(np.array([1 + 1j])) == "[1.+1.j]"
    assert _fmt(None) == "None" and _fmt(["a"]) == "['a']"
    assert _fmt(np.array(0.123456)) == "[0.1235]"


def test_texts_near_their_width_limits():
    """The message prints whole arrays up to 64 entries (the long form); a row keeps a summary
    of exactly 10 000 characters and cuts one of 10 001; the truth-value error says what to use."""
    r = CheckResult.from_margin("c", 1.0, 0.0, {"v": np.arange(20)}, "e")
    assert r.message().splitlines()[-1] == "    v = [" + ", ".join(map(str, range(20))) + "]"
    fits = CheckResult.from_margin("c", 1.0, 0.0, {}, "e", (), "r" * 10_000)
    assert fits.to_row()["witness"] == "r" * 10_000
    cut = CheckResult.from_margin("c", 1.0, 0.0, {}, "e", (), "r" * 10_001)
    assert cut.to_row()["witness"] == "r" * 9_997 + "..."
    with pytest.raises(TypeError, match=r"^use CheckResult\.passed \(True/False/None\), not the result's "
                                        r"truth value$"):
        bool(r)


def test_fmt_prints_other_iterables_with_str():
    """Only lists, tuples and arrays print as numbers; any other value with its str()."""
    assert _fmt(range(3)) == "range(0, 3)"
    assert _fmt({"a": 1}) == "{'a': 1}"


def test_evidence_levels_defaults_and_consistency():
    """Every result carries an evidence level; 'n/a' exactly when not applicable; a failure
    is never 'proved'; unknown levels and inconsistent pairs are refused."""
    assert EVIDENCE_LEVELS == ("proved", "bounded", "sampled", "violated")
    assert CheckResult("c", True, 1.0, 0.0).evidence == "sampled"             # the weakest claim
    assert CheckResult("c", False, -1.0, 0.0).evidence == "violated"
    assert CheckResult("c", None, math.nan, math.nan).evidence == "n/a"
    assert CheckResult.not_applicable("c", "r").evidence == "n/a"
    assert CheckResult.from_margin("c", 1.0, 0.0, {}, "e", evidence="proved").evidence == "proved"
    assert CheckResult.from_margin("c", -1.0, 0.0, {}, "e", evidence="proved").evidence == "violated"
    assert CheckResult.from_margin("c", -1.0, 0.0, {}, "e", evidence="sampled").evidence == "sampled"
    assert CheckResult.from_margin("c", 1.0, 0.0, {}, "e", verdict="ok").verdict == "ok"
    for bad in ({"passed": True, "evidence": "maybe"}, {"passed": True, "evidence": "n/a"},
                {"passed": None, "evidence": "proved"}, {"passed": True, "evidence": "violated"}):
        with pytest.raises(ValueError, match="evidence"):
            CheckResult("c", margin=0.0, tolerance=0.0, **bad)
