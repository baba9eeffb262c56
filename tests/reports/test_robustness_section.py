"""The robustness section (reports/sections/robustness.py) on synthetic paired-ensemble rows whose
answer is known by construction: where an observer breaks is an interval of levels decided over
masters (never a point, never one master's), the per-level cells are the median and the cluster
bootstrap interval over masters, and the paired ratio names the design with the lower floor."""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from observer.results_io import meta_path
from observer.stats import cluster_ci
from reports.context import ReportContext
from reports.sections import robustness
from reports.sections.robustness import BREAK_LEVEL

LEVELS = (1e-4, 1e-3, 1e-2, 1e-1)
UNITS = {"none": "", "delay": "s", "missed": "probability"}


def rows_of(floor_of, kinds=("delay",), levels=LEVELS, masters=5, per_master=4) -> pd.DataFrame:
    """One row per (kind, level, design, master, member); ``floor_of(kind, level, design,
    master, member)`` gives its floor; the ideal sensor (level 0) included."""
    out = []
    points = [("none", 0.0)] + [(k, s) for k in kinds for s in levels]
    for kind, size in points:
        for d in ("jump", "nojump"):
            for j in range(masters):
                for i in range(per_master):
                    out.append({"suite": "syn", "case_id": f"robustness:{kind}:{size}", "kind": "robustness",
                                "scenario": "double_mass", "name": "double_mass", "status": "ok", "h": 2e-4,
                                "t_end": 8.0, "design": d, "master": j, "member": j * per_master + i,
                                "perturbation": kind, "size": size, "tail": 0.25,
                                "floor": floor_of(kind, size, d, j, i)})
    return pd.DataFrame(out)


def context(rows: pd.DataFrame, tmp_path) -> ReportContext:
    rows = rows.assign(results_dir=str(tmp_path))
    meta_path("syn", tmp_path).write_text(json.dumps({
        "suite": "syn", "cases": list(dict.fromkeys(rows["case_id"])),
        "perturbations": {"kinds": ["none", "delay", "missed"],
                          "labels": {"none": "ideal", "delay": "latency d", "missed": "missed p"},
                          "units": UNITS}}))
    return ReportContext(df=rows, files=[], micro=pd.DataFrame(), micro_meta={}, suites=["syn"], command="",
                         out_dir=tmp_path)


def power_law(kind, size, d, j, i):
    """floor = 1e-6·(size/1e-4)² with a ±10 % spread over masters and members (nojump 3× higher):
    below BREAK_LEVEL at 1e-4 and 1e-3 (1e-6, 1e-4), far above it at 1e-2 and 1e-1."""
    base = 1e-9 if kind == "none" else 1e-6 * (size / 1e-4) ** 2
    return base * (3.0 if d == "nojump" else 1.0) * (1.0 + 0.05 * (j - 2) + 0.01 * i)


def table(sec, start: str):
    return next(b.content for b in sec.blocks if b.kind == "table" and b.content.title.startswith(start))


def texts(sec) -> str:
    out = []
    for b in sec.blocks:
        if b.kind == "table":
            out += [c for row in b.content.rows for c in row]
        elif b.kind in ("p", "list"):
            out += b.content if isinstance(b.content, list) else [b.content]
    return " ".join(out)


def test_breaking_level_is_the_interval_between_the_last_hold_and_the_first_break(tmp_path):
    """By construction jump and nojump hold at 1e-4 and 1e-3 and break at 1e-2: the section
    says "(0.001, 0.01] s" for both (the bracket, not "from 0.01"), in its table, its list and
    its key number."""
    ctx = context(rows_of(power_law), tmp_path)
    sec = robustness.build(ctx)
    br = table(sec, "Robustness: where each observer breaks")
    assert [r[0] for r in br.rows] == ["delay", "delay"]
    for r in br.rows:
        assert r[3] == "(0.001, 0.01] s"
        assert r[4] == "holds at the low end, breaks at the high end"
    assert "(0.001, 0.01] s" in ctx.key_numbers[0] and " from " not in ctx.key_numbers[0]
    lv = robustness.level_floors(ctx.rows("robustness"))
    d = lv[lv["perturbation"] == "delay"].set_index(["design", "size"])["verdict"]
    assert [d["jump", s] for s in LEVELS] == ["holds", "holds", "breaks", "breaks"]


def test_breaks_at_the_smallest_level_and_holds_everywhere_are_open_brackets(tmp_path):
    """jump's floor is 1e-8 at every level (holds everywhere: "[0.1, ∞)"), nojump's 0.5 at every
    level (breaks at the smallest tried: "(0, 1.00e−4]"): an open end, said as such."""
    def floor(kind, size, d, j, i):
        return (1e-8 if d == "jump" else 0.5) * (1.0 + 0.01 * j + 0.001 * i)
    tab = robustness.brackets_table(robustness.brackets(robustness.level_floors(rows_of(floor))), UNITS)
    br = {r[1]: r for r in tab.rows}
    jump, nojump = (br[robustness.registry.label(d)] for d in ("jump", "nojump"))
    assert jump[3] == "[0.1, ∞) s" and jump[4].startswith("holds at every level tried")
    assert nojump[3] == "(0, 1.00e−4] s" and nojump[4].startswith("breaks at the smallest level tried")


def test_one_master_decides_nothing(tmp_path):
    """With every member on one master the interval resamples members (no interval over
    masters): no level holds or breaks, and no bracket is given, however far the floors are from
    the break level."""
    rows = rows_of(power_law, masters=1, per_master=20)
    lv = robustness.level_floors(rows)
    assert set(lv["verdict"]) == {"one master"}
    for r in robustness.brackets_table(robustness.brackets(lv), UNITS).rows:
        assert r[3] == "—" and r[4] == "not decided at any level tried"


def test_the_scenario_s_own_master_alone_does_not_decide_the_bracket(tmp_path):
    """Master 0 (the scenario's own) breaks at 1e-3 while the nine others hold there: over the
    masters jump holds at 1e-3 (its bracket is (0.001, 0.01]); from master 0 alone it would be
    (0.0001, 0.001]."""
    def floor(kind, size, d, j, i):
        if kind == "delay" and size == 1e-3 and j == 0:
            return 1e-1 * (1 + 0.01 * i)
        return power_law(kind, size, d, min(j, 4), i)
    rows = rows_of(floor, masters=10, per_master=2)
    br = robustness.brackets(robustness.level_floors(rows)).set_index("design")
    assert (br.loc["jump", "low"], br.loc["jump", "high"]) == (1e-3, 1e-2)
    alone = robustness.brackets(robustness.level_floors(rows[rows["master"] == 0].assign(
        master=rows.loc[rows["master"] == 0, "member"] % 2)))   # master 0 split in two: a decision
    assert (alone.set_index("design").loc["jump", "low"], alone.set_index("design").loc["jump", "high"]) == (1e-4, 1e-3)


def test_cells_are_the_median_and_the_interval_over_masters(tmp_path):
    """The floor cell of one level is the median over every (master, member) and, in brackets,
    the 95 % percentile bootstrap interval resampling masters (cluster_ci with the masters as
    clusters: resampling members gives a narrower one)."""
    def floor(kind, size, d, j, i):
        return power_law(kind, size, d, j, i) * 10.0 ** (0.5 * (j - 2))   # masters differ by decades
    rows = rows_of(floor, levels=LEVELS[:2])
    tab = robustness.levels_table(robustness.level_floors(rows), pd.DataFrame(columns=["perturbation", "size"]),
                                  ["jump", "nojump"], UNITS)
    col = tab.columns.index(next(c for c in tab.columns if c.startswith(robustness.registry.label("jump"))))
    cell = next(r for r in tab.rows if r[0] == "delay" and r[1] == "0.001 s")[col]
    g = rows[(rows["perturbation"] == "delay") & (rows["size"] == 1e-3) & (rows["design"] == "jump")]
    x = g["floor"].to_numpy()
    lo, hi, unit = cluster_ci(lambda idx: float(np.median(x[idx])), g["master"].to_numpy(), seed=0)
    assert unit == "clusters" and hi / lo > 10                       # masters a decade apart
    nums = [float(v.replace("−", "-")) for v in re.findall(r"[−-]?\d+(?:\.\d+)?(?:e[−-]?\d+)?", cell)]
    assert nums[:3] == pytest.approx([np.median(x), lo, hi], rel=5e-3)
    wrong = cluster_ci(lambda idx: float(np.median(x[idx])), g["member"].to_numpy(), seed=0)
    assert not nums[1:3] == pytest.approx(list(wrong[:2]), rel=5e-3)


def test_paired_ratio_names_the_lower_design_only_when_the_interval_excludes_one(tmp_path):
    """At 1e-4 jump is 10× below nojump on every pair: ratio 0.1 [0.1 – 0.1], jump lower; at 1e-3
    it is 10× below on masters 0–2 and 10× above on masters 3–4: undecided."""
    def floor(kind, size, d, j, i):
        r = 1.0 if d == "nojump" else (0.1 if size != 1e-3 or j < 3 else 10.0)
        return 1e-6 * r * (1.0 + 0.01 * i)
    pr = robustness.paired_ratios(rows_of(floor), "jump", "nojump").set_index(["perturbation", "size"])
    assert 10 ** pr.loc[("delay", 1e-4), "log_ratio"] == pytest.approx(0.1)
    assert pr.loc[("delay", 1e-4), "lower"] == "jump"
    assert pr.loc[("delay", 1e-3), "lower"] == "undecided"
    assert pr.loc[("delay", 1e-4), "pairs"] == 20


def test_rows_of_the_earlier_suite_are_not_read_as_ensembles(tmp_path):
    """Rows without masters (the one-error suite) give no cells and no key number."""
    rows = rows_of(power_law).drop(columns=["master"])
    ctx = context(rows, tmp_path)
    sec = robustness.build(ctx)
    assert [b.kind for b in sec.blocks] == ["p"] and "earlier suite" in sec.blocks[0].content
    assert ctx.key_numbers == []


def test_bracket_of_verdicts():
    """The bracket's rules on verdict lists (levels 1, 2, 3, 4)."""
    s = [1.0, 2.0, 3.0, 4.0]
    b = robustness.bracket
    assert (b(s, ["holds", "holds", "breaks", "breaks"])["low"], b(s, ["holds", "holds", "breaks", "breaks"])["high"]) == (2.0, 3.0)
    r = b(s, ["holds", "undecided", "breaks", "holds"])
    assert (r["low"], r["high"]) == (1.0, 3.0) and "undecided between" in r["text"] and "holds again at 4" in r["text"]
    r = b(s, ["undecided", "breaks", "breaks", "breaks"])
    assert (r["low"], r["high"]) == (0.0, 2.0) and "not decided at any smaller level" in r["text"]
    r = b(s, ["holds", "undecided", "undecided", "undecided"])
    assert (r["low"], r["high"]) == (1.0, np.inf)
    assert np.isnan(b(s, ["one master"] * 4)["low"])


def test_rows_of_the_earlier_suite_beside_new_ones_are_left_out(tmp_path):
    """An old row (no master, no design, its floor an absolute V) in the same results changes no
    cell: the designs and the floors are the new rows'."""
    rows = rows_of(power_law, levels=LEVELS[:2])
    old = {"suite": "syn", "case_id": "robustness:double_mass:perturbation=delay", "kind": "robustness",
           "name": "double_mass", "status": "ok", "perturbation": "delay", "size": 1e-3, "observer": "jump",
           "floor": 50.0, "h": 2e-4, "t_end": 8.0}
    sec = robustness.build(context(pd.concat([rows, pd.DataFrame([old])], ignore_index=True), tmp_path))
    tab = table(sec, "Robustness: floor of V/V(t_on) per level")
    assert not any("nan" in c for c in tab.columns)
    cell = next(r for r in tab.rows if r[0] == "delay" and r[1] == "0.001 s")[3]
    g = rows[(rows["perturbation"] == "delay") & (rows["size"] == 1e-3) & (rows["design"] == "jump")]
    assert float(cell.split(" ")[0].replace("−", "-")) == pytest.approx(np.median(g["floor"]), rel=5e-3)
