"""The per-parameter and sensor curves of the "Model error and sensors" section against values
recomputed here from the stored JSON (numpy's own medians, fit range, fits and sign changes, not
the section's or bench's code); doctored copies (a slope off by 0.01, floors just across or just
short of a crossing) are caught."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from reports import registry
from reports.sections import model_error

pytestmark = pytest.mark.xdist_group("model_error_section")
"""With ``--dist loadgroup``, this module and the other reading the stored section share a worker
(so the session fixture is built once). With pytest 9.2 and pytest-xdist 3.8 the group is ignored
(the worker renames the node id through a field pytest no longer reads: pytest-xdist issue 1386);
``--dist loadscope`` keeps a module on one worker meanwhile."""

STORED = Path(__file__).resolve().parents[2] / "bench" / "stored"
PARAMETER_FILES = tuple(sorted(STORED.glob("model_error_parameters_*.json")))
"""Every stored per-parameter result (one per scenario), globbed here, not by the section."""
DOUBLE = STORED / "model_error_parameters_double_mass.json"
FILES = (*PARAMETER_FILES, STORED / model_error.SENSOR)


def numbers(text: str) -> list[float]:
    return [float(x.replace("−", "-")) for x in re.findall(r"[−-]?\d+(?:\.\d+)?(?:e[−-]?\d+)?", text)]


def expected(data: dict) -> dict:
    """(uncertainty label, design) → (fitted sizes, slope, intercept, crossings), recomputed:
    fit range = median floor ≥ 10 × the median at size 0 and < 0.1; crossings = sign changes
    of log10(median a / median b) between consecutive sizes, as (lower, upper, design lower above)."""
    out = {}
    for rec in data["curves"]:
        sizes = np.array(rec["sizes"])
        meds = {d: np.median(np.array(r["member_floors"]), axis=1) for d, r in rec["designs"].items()}
        (a, ma), (b, mb) = meds.items()
        r = np.log10(ma / mb)
        cross = [(sizes[i], sizes[i + 1], a if r[i + 1] < 0 else b) for i in range(len(r) - 1) if r[i] * r[i + 1] < 0]
        for d, r_ in rec["designs"].items():
            keep = (meds[d] >= 10 * np.median(r_["exact_member_floors"])) & (meds[d] < 0.1)
            fit = np.polyfit(np.log10(sizes[keep]), np.log10(meds[d][keep]), 1) if keep.sum() >= 3 else (None, None)
            out[rec["label"], d] = (sizes[keep], fit[0], fit[1], cross)
    return out


def table_of(sec, data: dict):
    head = f"{data['what']} ({data['scenario']}; {data['command']})"
    (table,) = [b.content for b in sec.blocks if b.kind == "table" and b.content.title.startswith(head)]
    return table


def mismatches(sec, data: dict) -> list[str]:
    """Rows of the section's table for ``data`` that differ from :func:`expected` beyond display rounding."""
    exp, bad = expected(data), []
    labels = {registry.label(d): d for d in registry.designs()}
    rows = table_of(sec, data).rows
    if len(rows) != len(exp):
        bad.append(f"{len(rows)} rows for {len(exp)} curves")
    for row in rows:
        sizes, s, a, cross = exp[row[0], labels[row[1]]]
        if s is None:
            if not row[2].startswith("not fitted"):
                bad.append(f"{row[:2]}: fitted, expected not")
        elif (abs(numbers(row[2])[0] - s) > 6e-4 or abs(numbers(row[4])[0] - a) > 6e-3 * max(1.0, abs(a))
              or numbers(row[5])[-1] != sizes.size):
            bad.append(f"{row[:2]}: {row[2]} / {row[4]} / {row[5]} vs {s:.4f} / {a:.3f} / {sizes.size}")
        if cross:
            parts = row[7].split("; between")
            got = [numbers(p)[:2] for p in parts]
            if len(parts) != len(cross) or any(
                    g != pytest.approx([lo, hi], rel=6e-3) or registry.label(low) + " lower above" not in p
                    for g, p, (lo, hi, low) in zip(got, parts, cross)):
                bad.append(f"{row[:2]} crossover {row[7]!r} vs {cross}")
        elif not row[7].startswith("no crossing on the stored sizes"):
            bad.append(f"{row[:2]} crossover {row[7]!r}, expected none")
    return bad


@pytest.fixture(scope="module")
def section(stored_model_error_section):
    """The section of the stored results (tests/reports/conftest.py: one build for this module and
    the other that reads it)."""
    return stored_model_error_section


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_each_stored_curve_file_has_its_figure_and_its_table_equal_to_the_recomputed_fits(section, path):
    data = json.loads(path.read_text())
    assert mismatches(section, data) == []
    figures = [b for b in section.blocks if b.kind == "figure"]
    assert len(figures) == 1 + len(FILES)   # the K-error/latency panels, then one figure per curve file
    exp = expected(data)
    assert any(v[1] is not None for v in exp.values())


def test_the_stored_fits_are_the_recomputed_ones():
    for path in FILES:
        data = json.loads(path.read_text())
        exp = expected(data)
        for rec in data["curves"]:
            for d, r in rec["designs"].items():
                sizes, s, a, _ = exp[rec["label"], d]
                assert r["fit"]["sizes"] == pytest.approx(sizes.tolist())
                if s is None:
                    assert r["fit"]["status"].startswith("not fitted")
                else:
                    assert r["fit"]["slope"] == pytest.approx(s, abs=1e-9)
                    lo, hi = r["fit"]["interval"]["regression"]
                    assert lo < s < hi


def _doctored(tmp_path: Path, path: Path, change) -> tuple[dict, object]:
    """``change`` applied to a copy of the stored file ``path``, and the section of a folder
    holding it beside the stored K-error and latency results (the results the section opens
    with; the other curve files, each a figure of its own, are left out: the tests read the
    doctored file's tables)."""
    latency = STORED / model_error.LATENCY
    for f in (STORED / model_error.MODEL_ERROR, latency, latency.with_suffix(".csv")):
        shutil.copy(f, tmp_path / f.name)
    data = json.loads(path.read_text())
    change(data)
    (tmp_path / path.name).write_text(json.dumps(data))
    return data, model_error.build_from(tmp_path, [])


def test_a_slope_off_by_a_hundredth_is_caught(tmp_path):
    """Near miss: one stored slope + 0.01, the floors untouched: the section shows it, the check sees it."""
    def change(data):
        fit = data["curves"][0]["designs"]["jump"]["fit"]
        fit["slope"] += 0.01
    data, sec = _doctored(tmp_path, DOUBLE, change)
    assert len(mismatches(sec, data)) == 1
    row = table_of(sec, data).rows[0]
    assert numbers(row[2])[0] == pytest.approx(data["curves"][0]["designs"]["jump"]["fit"]["slope"], abs=6e-4)


@pytest.mark.parametrize("factor, crosses", [(1.02, True), (0.98, False)])
def test_floors_just_across_or_just_short_of_a_crossing(tmp_path, factor, crosses):
    """The K curve (no crossing stored): the lower design's member floors at the last size raised
    to 1.02 (crossing) or 0.98 (none) times the other's median there."""
    def change(data):
        rec = next(r for r in data["curves"] if r["key"] == "K")
        meds = {d: np.median(np.array(r["member_floors"])[-1]) for d, r in rec["designs"].items()}
        low, high = sorted(meds, key=meds.get)
        F = np.array(rec["designs"][low]["member_floors"])
        F[-1] *= factor * meds[high] / meds[low]
        rec["designs"][low]["member_floors"] = F.tolist()
    data, sec = _doctored(tmp_path, DOUBLE, change)
    assert mismatches(sec, data) == []
    rec = next(r for r in data["curves"] if r["key"] == "K")
    cell = next(row for row in table_of(sec, data).rows if row[0] == rec["label"])[7]
    assert cell.startswith("between") == crosses, cell
    if crosses:
        assert numbers(cell)[:2] == pytest.approx(rec["sizes"][-2:], rel=6e-3)
    stale = json.loads(DOUBLE.read_text())
    assert (mismatches(sec, stale) != []) == crosses


def _pair(rec: dict) -> tuple[str, str]:
    (pair,) = [p for p in registry.ratio_pairs() if p[0] in rec["designs"] and p[1] in rec["designs"]]
    return pair


def _rows(sec, title: str) -> dict:
    return {r[0]: r for b in sec.blocks if b.kind == "table" and b.content.title.startswith(title)
            for r in b.content.rows}


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_the_paired_crossovers_of_each_file_are_the_recomputed_sign_changes(section, path):
    """Per curve: the zeros of the median over members of log10(floor a / floor b) (recomputed
    here, log-log interpolated), each either placed (the zero, inside its interval) or
    undecided between its bracketing sizes; without a zero, no crossover or undecided, naming
    the design the paired medians put lower."""
    data = json.loads(path.read_text())
    rows = _rows(section, f"Crossovers with intervals, {data['scenario']}, {data['command']}:")
    assert len(rows) == len(data["curves"])
    for rec in data["curves"]:
        a, b = _pair(rec)
        sizes, x = np.array(rec["sizes"]), np.log10(rec["sizes"])
        r = np.median(np.log10(np.array(rec["designs"][a]["member_floors"]) / np.array(rec["designs"][b]["member_floors"])), axis=1)
        brackets = [i for i in range(len(r) - 1) if r[i] * r[i + 1] < 0]
        cell = rows[rec["label"]][2]
        if not brackets:
            lower = registry.label(a if r[0] < 0 else b)
            assert (cell.startswith("no crossover in") and f"({lower} lower throughout)" in cell) or \
                cell.startswith(f"undecided: {lower} lower at every size"), cell
            continue
        parts = cell.split("; ")
        assert len(parts) == len(brackets), cell
        for i, part in zip(brackets, parts):
            zero = 10 ** (x[i] + r[i] / (r[i] - r[i + 1]) * (x[i + 1] - x[i]))
            if part.startswith("at "):
                at, lo, hi = numbers(part)[:3]
                assert at == pytest.approx(zero, rel=6e-3) and lo <= at * 1.006 and hi >= at / 1.006, part
            else:
                assert part.startswith("undecided between") and numbers(part)[:2] == pytest.approx(sizes[i:i + 2], rel=6e-3)
            above = registry.label(a if r[i + 1] < 0 else b)
            assert f"{above} lower above" in part, part


def test_the_threshold_crossovers_are_placed_and_the_model_parameters_know_to_table_holds(section):
    """The stored sensor-threshold curve crosses twice, both placed; in the per-parameter file,
    every target at or below a design's exact floor is not reachable, and a design whose floor
    never leaves the exact one (W for the observer without jumps) allows any size in the range
    for a target above it."""
    sensor = json.loads(FILES[-1].read_text())
    thr = next(r for r in sensor["curves"] if r["key"] == "threshold")
    cell = _rows(section, f"Crossovers with intervals, {sensor['scenario']}, {sensor['command']}:")[thr["label"]][2]
    assert [p.startswith("at ") for p in cell.split("; ")] == [True, True], cell
    params = json.loads(DOUBLE.read_text())
    known = [b.content for b in section.blocks if b.kind == "table" and b.content.title.startswith(
        f"Known to for a target floor, {params['scenario']}, {params['command']}:")]
    (table,) = known
    targets = [float(c.split("≤")[1].replace("−", "-")) for c in table.columns[4:]]
    labels = {registry.label(d): d for d in registry.designs()}
    by_label = {rec["label"]: rec for rec in params["curves"]}
    flat = 0
    for row in table.rows:
        rec = by_label[row[0]]
        r = rec["designs"][labels[row[1]]]
        exact = float(np.median(r["exact_member_floors"]))
        meds = np.median(np.array(r["member_floors"]), axis=1)
        for target, c in zip(targets, row[4:]):
            assert c.startswith("not reachable at this h") == (target <= exact), (row[:2], target, c)
            if target > exact and np.all(meds <= target) and r["fit"]["status"] != "ok":
                assert c.startswith(f"any size up to {rec['sizes'][-1]:g}"), c
                flat += 1
    assert flat >= 1


def _shown(sec, data: dict) -> list[str]:
    """What the section lacks of one stored per-parameter file: its figure (title naming the
    scenario), curves table, crossover, sensitivity and known-to tables, and its ranking items."""
    titles = [b.content.title if b.kind == "table" else b.content.alt for b in sec.blocks
              if b.kind in ("table", "figure")]
    scen, cmd = data["scenario"], data["command"]
    wanted = [f"floor of V/V(t_on) against M, C, K, W ({scen})", f"{data['what']} ({scen}; {cmd})",
              f"Crossovers with intervals, {scen}, {cmd}:", f"Sensitivity per parameter, {scen}, {cmd}:",
              f"Known to for a target floor, {scen}, {cmd}:"]
    missing = [w for w in wanted if sum(t.startswith(w) for t in titles) != 1]
    items = [t for b in sec.blocks if b.kind == "list" for t in b.content if t.startswith(f"{scen}, ")]
    if len(items) != len(data["designs"]):
        missing.append(f"{len(items)} ranking items for {scen}")
    return missing


def test_every_stored_parameter_file_is_shown_with_its_scenario(section):
    """Each stored model_error_parameters_*.json (globbed here) has its figure and tables, the
    scenario in each caption; at least two scenarios are stored."""
    assert len(PARAMETER_FILES) >= 2 and DOUBLE in PARAMETER_FILES
    scenarios = [json.loads(p.read_text())["scenario"] for p in PARAMETER_FILES]
    assert len(set(scenarios)) == len(scenarios)
    for path in PARAMETER_FILES:
        assert _shown(section, json.loads(path.read_text())) == [], path.name


def test_a_new_stored_parameter_file_is_shown_and_an_absent_one_is_not(tmp_path, section):
    """Near miss: a copy of the double_mass file under another scenario's name appears in the
    section built from a folder holding it (beside the K-error result), and not in the stored one."""
    data = json.loads(DOUBLE.read_text())
    data["scenario"] = "copy_for_test"
    shutil.copy(STORED / model_error.MODEL_ERROR, tmp_path / model_error.MODEL_ERROR)
    (tmp_path / "model_error_parameters_copy_for_test.json").write_text(json.dumps(data))
    assert _shown(model_error.build_from(tmp_path, []), data) == []
    assert _shown(section, data) != []


@pytest.mark.parametrize("path", PARAMETER_FILES, ids=lambda p: p.stem)
def test_the_sensitivity_ranking_of_each_scenario_is_recomputed(section, path):
    """Per design, the parameters ranked by their median floor (numpy's median of the stored
    member floors) at the stored size nearest to 1e-2, those within 1e-6 relative of the exact
    model's median floor named apart as without effect; the table's floors to 3 digits."""
    data = json.loads(path.read_text())
    rows = _rows(section, f"Sensitivity per parameter, {data['scenario']}, {data['command']}:")
    assert list(rows) == [rec["key"] for rec in data["curves"]]
    i = int(np.argmin(np.abs(np.log10(data["curves"][0]["sizes"]) + 2.0)))
    items = [t for b in section.blocks if b.kind == "list" for t in b.content
             if t.startswith(f"{data['scenario']}, ")]
    for j, d in enumerate(data["designs"]):
        floor = {rec["key"]: float(np.median(rec["designs"][d]["member_floors"][i])) for rec in data["curves"]}
        exact = float(np.median(data["curves"][0]["designs"][d]["exact_member_floors"]))
        none = [k for k, v in floor.items() if abs(v / exact - 1) <= 1e-6]
        ranked = sorted((k for k in floor if k not in none), key=floor.get, reverse=True)
        line_ = next(t for t in items if t.startswith(f"{data['scenario']}, {registry.label(d)}:"))
        assert f"order: {', '.join(ranked)}" + ("; no effect" if none else ".") in line_, line_
        assert line_.endswith(f": {', '.join(none)}." if none else "."), line_
        for k, v in floor.items():
            assert numbers(rows[k][1 + j])[0] == pytest.approx(v, rel=6e-3), (k, d, rows[k])
