"""Robustness: the observers with χ from an imperfect contact sensor (latency, jitter, missed and
false detections, threshold δ, sampling period), from paired ensembles over several masters.

Every robustness row is one (design, master, member) of a paired ensemble at one level of one
sensor perturbation (the suite's masters × initial errors, the same for both designs and at
every level); its ``floor`` is the median of V/V(t_on) over the window's last ``tail``. Here:

* :func:`level_floors` — per (perturbation, level, design) the median floor over every
  (master, member) with its cluster bootstrap interval over masters
  (:func:`observer.stats.cluster_ci`), and the verdict against :data:`BREAK_LEVEL`: ``holds``
  (the interval below it), ``breaks`` (above it), ``undecided`` (it straddles it), or
  ``one master`` (no interval over masters: not decided);
* :func:`paired_ratios` — per (perturbation, level) the median of the paired
  log₁₀(floor_a / floor_b) (the same master, member and sensor draws) with its interval over
  masters, and which design is lower where the interval excludes 0;
* :func:`brackets` — per (perturbation, design) where the observer breaks: an *interval*
  between the last level that holds and the first that breaks, or an interval open at one end
  ("holds at every level tried", "breaks at the smallest level tried"), never a point.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from reports import figures, registry
from reports.blocks import Block, Section
from reports.context import ReportContext
from reports.sections.settings import MISSING
from reports.tables import Table, fmt, fmt_rho

TITLE = "Robustness: observers under imperfect switching signals"

BREAK_LEVEL = 1e-3
"""An observer *breaks* at a level when its median floor of V/V(t_on) is above this (decided by
the interval over masters); it *holds* when below."""

SEED = 0
"""Seed of every bootstrap of this section."""

VERDICTS = ("holds", "breaks", "undecided", "one master")


def _perturbations(meta: dict) -> tuple[list[str], dict[str, str], dict[str, str]]:
    """``(kinds, labels, units)`` of the perturbations as the suite's metadata sidecar records
    them (``"perturbations"``, written by bench from ``bench.perturb``)."""
    return list(meta["kinds"]), dict(meta["labels"]), dict(meta["units"])


def _median_ci(x: np.ndarray, clusters: np.ndarray) -> tuple[float, float, float, str]:
    """The median of ``x`` and its cluster bootstrap interval (clusters = masters)."""
    from observer.stats import cluster_ci

    if x.size == 0:
        return math.nan, math.nan, math.nan, ""
    if x.size == 1:
        return float(x[0]), math.nan, math.nan, "members"
    lo, hi, unit = cluster_ci(lambda idx: _median(x[idx]), clusters, seed=SEED)
    return float(np.median(x)), lo, hi, unit


def _median(v: np.ndarray) -> float:
    """The median of a fresh 1-d array (sorted in place; numpy's median costs 30× more per call
    on the bootstrap's small samples)."""
    v.sort()
    n = v.size
    return 0.5 * float(v[(n - 1) // 2] + v[n // 2])


def verdict(low: float, high: float, unit: str, level: float = BREAK_LEVEL) -> str:
    """``holds`` / ``breaks`` / ``undecided`` from an interval over masters; ``one master``
    when the interval resampled members (one master: nothing is decided)."""
    if unit != "clusters" or not (np.isfinite(low) and np.isfinite(high)):
        return "one master"
    if high < level:
        return "holds"
    if low > level:
        return "breaks"
    return "undecided"


def level_floors(rob: pd.DataFrame, level: float = BREAK_LEVEL) -> pd.DataFrame:
    """Per (perturbation, size, design): ``masters``, ``members``, the median ``floor`` with
    ``low``/``high`` over masters, ``unit`` and the ``verdict`` (module docstring)."""
    ok = rob[(rob["status"] == "ok") & np.isfinite(rob["floor"].astype(float))]
    out = []
    for (kind, size, design), g in ok.groupby(["perturbation", "size", "design"], sort=False):
        x, cl = g["floor"].to_numpy(dtype=float), g["master"].to_numpy()
        med, lo, hi, unit = _median_ci(x, cl)
        out.append({"perturbation": kind, "size": float(size), "design": design,
                    "masters": int(np.unique(cl).size), "members": int(x.size), "floor": med,
                    "low": lo, "high": hi, "unit": unit, "verdict": verdict(lo, hi, unit, level)})
    return pd.DataFrame(out)


def paired_ratios(rob: pd.DataFrame, a: str, b: str) -> pd.DataFrame:
    """Per (perturbation, size): the median paired log₁₀(floor_a / floor_b) over the (master,
    member) pairs with its interval over masters, and ``lower``: the design with the lower
    floor where the interval excludes 0, else ``undecided`` (``one master`` with one)."""
    ok = rob[(rob["status"] == "ok") & np.isfinite(rob["floor"].astype(float))]
    key = ["perturbation", "size", "master", "member"]
    wide = ok.pivot_table(index=key, columns="design", values="floor", aggfunc="first")
    wide = wide.dropna(subset=[a, b]).reset_index()
    out = []
    for (kind, size), g in wide.groupby(["perturbation", "size"], sort=False):
        d = np.log10(g[a].to_numpy(dtype=float) / g[b].to_numpy(dtype=float))
        med, lo, hi, unit = _median_ci(d, g["master"].to_numpy())
        lower = ("one master" if unit != "clusters" else a if hi < 0 else b if lo > 0 else "undecided")
        out.append({"perturbation": kind, "size": float(size), "pairs": int(d.size), "log_ratio": med,
                    "low": lo, "high": hi, "lower": lower})
    return pd.DataFrame(out)


def bracket(sizes: list[float], verdicts: list[str]) -> dict:
    """Where an observer breaks, from its verdicts at ascending ``sizes``: ``low``, ``high`` of
    the interval (``low`` = 0: breaks at or below the smallest level tried; ``high`` = inf:
    holds at every level tried; both NaN: nothing decided) and ``text``."""
    brk = next((i for i, v in enumerate(verdicts) if v == "breaks"), None)
    stop = len(sizes) if brk is None else brk
    held = [i for i in range(stop) if verdicts[i] == "holds"]
    a = held[-1] if held else None
    if brk is None:
        if a is None:
            return {"low": math.nan, "high": math.nan, "text": "not decided at any level tried"}
        if len(held) == len(sizes):
            return {"low": sizes[-1], "high": math.inf,
                    "text": "holds at every level tried: the break, if any, lies above the largest"}
        return {"low": sizes[a], "high": math.inf,
                "text": "holds up to the low end, undecided above it; breaks at no level tried"}
    if a is None:
        text = ("breaks at the smallest level tried: the break lies at or below it" if brk == 0
                else "breaks at the high end; not decided at any smaller level")
        return {"low": 0.0, "high": sizes[brk], "text": text}
    gap = "" if a == brk - 1 else "; undecided between"
    again = [sizes[i] for i in range(brk + 1, len(sizes)) if verdicts[i] == "holds"]
    tail = f"; holds again at {', '.join(fmt(s) for s in again)}" if again else ""
    return {"low": sizes[a], "high": sizes[brk], "text": "holds at the low end, breaks at the high end" + gap + tail}


def brackets(levels: pd.DataFrame) -> pd.DataFrame:
    """Per (perturbation, design) of :func:`level_floors` (the ideal sensor left out) its
    :func:`bracket`."""
    out = []
    per = levels[levels["perturbation"] != "none"]
    for (kind, design), g in per.groupby(["perturbation", "design"], sort=False):
        g = g.sort_values("size")
        out.append({"perturbation": kind, "design": design, "levels": int(len(g)),
                    **bracket(g["size"].tolist(), g["verdict"].tolist())})
    return pd.DataFrame(out)


def interval_text(r, unit: str) -> str:
    """A bracket as an interval of levels: ``(a, b]``, ``(0, b]`` or ``[a, ∞)``."""
    lo, hi = float(r["low"]), float(r["high"])
    if math.isnan(lo):
        return "—"
    u = f" {unit}" if unit else ""
    if math.isinf(hi):
        return f"[{fmt(lo)}, ∞){u}"
    return f"({fmt(lo)}, {fmt(hi)}]{u}"


def _cell(med: float, lo: float, hi: float) -> str:
    return fmt(med) if math.isnan(lo) else f"{fmt(med)} [{fmt(lo)} – {fmt(hi)}]"


def levels_table(levels: pd.DataFrame, ratios: pd.DataFrame, designs: list[str], units: dict[str, str]) -> Table:
    """Per perturbation level: each design's median floor [interval over masters] and verdict,
    and the paired floor ratio of the first two designs with the lower one."""
    a, b = designs[:2]
    t = Table("Robustness: floor of V/V(t_on) per level (median over masters × errors [95 % interval "
              "over masters])", ["perturbation", "level", "masters × errors"]
              + [f"{registry.label(d)}: floor; verdict" for d in designs]
              + [f"{registry.label(a)} ÷ {registry.label(b)} floor (paired)", "lower floor"])
    rt = ratios.set_index(["perturbation", "size"])
    for (kind, size), g in levels.groupby(["perturbation", "size"], sort=False):
        g = g.set_index("design")
        cells = [f"{_cell(g.loc[d, 'floor'], g.loc[d, 'low'], g.loc[d, 'high'])}; {g.loc[d, 'verdict']}"
                 if d in g.index else "n/a" for d in designs]
        r0 = g.iloc[0]
        if (kind, size) in rt.index:
            p = rt.loc[(kind, size)]
            ratio = _cell(10 ** p["log_ratio"], 10 ** p["low"], 10 ** p["high"])
            lower = registry.label(p["lower"]) if p["lower"] in designs else p["lower"]
        else:
            ratio, lower = "n/a", "n/a"
        t.add(["none (ideal sensor)" if kind == "none" else kind,
               "0" if kind == "none" else fmt(size, unit=units.get(kind, "")),
               f"{int(r0['masters'])} × {int(r0['members']) // max(int(r0['masters']), 1)}",
               *cells, ratio, lower])
    return t


def brackets_table(br: pd.DataFrame, units: dict[str, str]) -> Table:
    """Per perturbation and design: the interval in which the observer breaks."""
    t = Table(f"Robustness: where each observer breaks (median floor above {fmt_rho(BREAK_LEVEL)}·V(t_on), "
              "decided over masters)", ["perturbation", "observer", "levels", "breaks within", "reading"])
    for _, r in br.iterrows():
        t.add([r["perturbation"], registry.label(r["design"]), str(int(r["levels"])),
               interval_text(r, units.get(r["perturbation"], "")), r["text"]])
    return t


def robustness_figure(levels: pd.DataFrame, kinds: list[str], labels: dict[str, str],
                      units: dict[str, str]) -> figures.Figure | None:
    """Per perturbation kind: each design's median floor against the level with its interval
    over masters, the ideal sensor's floor (dotted) and :data:`BREAK_LEVEL` (dashed)."""
    plt = figures.plt
    kinds = [k for k in kinds if k != "none" and (levels["perturbation"] == k).any()]
    if not kinds:
        return None
    cols = min(3, len(kinds))
    rows = -(-len(kinds) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.8 * cols, 3.0 * rows), squeeze=False)
    base = levels[levels["perturbation"] == "none"].set_index("design")
    for ax, kind in zip(axes.flat, kinds):
        for d, g in levels[levels["perturbation"] == kind].sort_values("size").groupby("design", sort=False):
            c = registry.look(d).color
            y, lo, hi = (g[k].to_numpy(dtype=float) for k in ("floor", "low", "high"))
            err = np.vstack([np.nan_to_num(y - lo), np.nan_to_num(hi - y)])
            ax.errorbar(g["size"].to_numpy(dtype=float), y, yerr=err, fmt="o-", ms=4, capsize=3, color=c,
                        label=registry.look(d).label)
            if d in base.index:
                ax.axhline(float(base.loc[d, "floor"]), color=c, lw=0.8, ls=":")
        ax.axhline(BREAK_LEVEL, color="grey", lw=0.8, ls="--")
        ax.set_xscale("log")
        ax.set_yscale("log")
        unit = units.get(kind, "")
        ax.set_xlabel(labels.get(kind, kind) + (f" ({unit})" if unit else ""), fontsize=8)
        ax.set_ylabel("floor / V(t_on)")
        ax.set_title(kind, fontsize=10)
        ax.grid(alpha=0.3, which="both")
    for ax in list(axes.flat)[len(kinds):]:
        ax.set_visible(False)
    axes[0, 0].legend(fontsize=7)
    figures.fixed_layout(fig, top=0.35, hspace=0.7)
    return figures.Figure(figures.to_data_uri(fig, fit=False), "robustness: floor against the sensor perturbation",
                          "Markers: median floor over every master and initial error; bars: its 95 % "
                          "cluster bootstrap interval over masters. Dotted: the ideal sensor's floor; "
                          f"dashed: the break level {fmt_rho(BREAK_LEVEL)}.")


def intro(rob: pd.DataFrame, kinds: list[str], labels: dict[str, str]) -> str:
    """Setting of the robustness runs, from the rows."""
    r0 = rob.iloc[0]
    masters, members = int(rob["master"].nunique()), int(rob.groupby("design")["member"].nunique().max())
    tail = fmt(r0["tail"]) if pd.notna(r0["tail"]) else MISSING
    return (f"Scenario {', '.join(dict.fromkeys(rob['name'].astype(str)))} (h = {fmt(r0['h'])} s, "
            f"T = {fmt(r0['t_end'])} s, coupled over the whole run). The observers read χ from a contact "
            f"sensor on each master ([observer.sensor], observer.sensor), one setting at a time: "
            + "; ".join(f"{k}: {labels[k]}" for k in kinds if k in labels) + ". Every level is a paired "
            f"ensemble of {masters} masters (the scenario's initial state and others sampled around it) × "
            f"{members // max(masters, 1)} initial errors per master, the same for both designs and at every "
            f"level. A member's floor is the median of V/V(t_on) over the last {tail} of the window (for a "
            f"design still decaying at the window's end, where its decay stands then rather than a floor; "
            f"compare the ideal sensor's row); a "
            f"cell gives the median over every (master, error) and its 95 % cluster bootstrap interval "
            f"over masters. An observer holds at a level when that interval lies below "
            f"{fmt_rho(BREAK_LEVEL)}, breaks when it lies above, and is undecided otherwise; where it "
            f"breaks is given as an interval of levels, never a point.")


def summary_items(br: pd.DataFrame, units: dict[str, str]) -> list[str]:
    """One line per observer: its break interval per perturbation."""
    items = []
    for d, g in br.groupby("design", sort=False):
        parts = [f"{r['perturbation']} {interval_text(r, units.get(r['perturbation'], ''))} ({r['text']})"
                 for _, r in g.iterrows()]
        items.append(f"Observer {registry.label(d)} breaks within: " + "; ".join(parts) + ".")
    return items


def build(ctx: ReportContext) -> Section:
    """The robustness section; adds one key-number line."""
    sec = Section("robustness", TITLE)
    rob = ctx.rows_or_say(sec, "robustness", "robustness runs")
    if rob is None:
        return sec
    perturbations = ctx.declared("perturbations")
    if perturbations is None:
        sec.p(f"The robustness results are not shown: {MISSING}.")
        return sec
    if rob["master"].isna().all():
        sec.p("These robustness rows come from the earlier suite (one initial error and a few seeds per "
              "level, no masters): no interval over masters can be given. Rerun the robustness suite.")
        return sec
    rob = rob[rob["master"].notna()]              # rows of the earlier suite beside new ones: left out
    kinds, labels, units = _perturbations(perturbations)
    designs = list(dict.fromkeys(rob["design"].astype(str)))
    levels = level_floors(rob)
    ratios = paired_ratios(rob, designs[0], designs[1]) if len(designs) > 1 else pd.DataFrame()
    br = brackets(levels)
    sec.p(intro(rob, kinds, labels))
    sec.figure(robustness_figure(levels, kinds, labels, units), "No robustness data.")
    sec.table(levels_table(levels, ratios, designs, units))
    sec.table(brackets_table(br, units))
    items = summary_items(br, units)
    sec.blocks.append(Block("list", items))
    if items:
        ctx.key_numbers.append(f"Robustness ({int(rob['master'].nunique())} masters per level; break = median "
                               f"floor above {fmt_rho(BREAK_LEVEL)}·V(t_on), intervals over masters): "
                               + " ".join(items))
    return sec
