"""Observer table: the declared (baseline, candidate) settling-time ratios per scenario, every
observer run of every registered design, and a per-design summary.

Settling time at ρ: the time after t_on from which V stays ≤ ρ·V(t_on) up to the end of the
coupling window (:func:`observer.metrics.settling_time`); first passage: the first sample
with V ≤ ρ·V(t_on).
"""

from __future__ import annotations

import math

import pandas as pd

from reports import analysis, registry
from reports.analysis import RHOS
from reports.blocks import Block, Section
from reports.context import ReportContext
from reports.tables import Table, fmt, fmt_int, fmt_pct, fmt_rho, fmt_time, fmt_window, ratio_text, text

TITLE = "Observer table: every design, declared ratios across scenarios"

SETTLE_NOTE = ("settles below ρ: time after the start of coupling t_on from which V stays "
               "≤ ρ·V(t_on) up to the end of the coupling window ('not reached' when V ends the "
               "window above it); first passage: time of the first sample with V ≤ ρ·V(t_on)")


def _rho_list() -> str:
    return " / ".join(fmt_rho(rho) for rho in RHOS)


def observer_table(obs: pd.DataFrame, title: str | None = None) -> Table:
    """Per observer run (:func:`reports.analysis.observer_runs`): settling times per ρ, first
    passages, rate, floor, final error, cost."""
    first_col = "first passage " + _rho_list()
    cols = (["scenario", "observer", "h (s)", "window (s)", "V(t_on)"]
            + [f"settles below {fmt_rho(rho)}" for rho in RHOS]
            + [first_col, "rate (1/s)", "floor / V(t_on)", "V_end / V(t_on)", "final max|q̂ − q|",
               "master closings", "CPU time (s)", "steps/s"])
    t = Table(title or "Observer table: settling time (from t_on) below ρ·V(t_on), first passage, "
                       "rate, floor, final error, cost",
              cols, note=SETTLE_NOTE + "; rate: least-squares exponential rate of V over the "
                         "window; floor: median of V over the last part of the window; CPU time: "
                         "master + this observer.")
    for _, r in analysis.observer_runs(obs).iterrows():
        head = [r["name"], registry.label(r["observer"]), fmt(r["h"])]
        if r["status"] != "ok":
            reason = text(r["note"]) or "not applicable"
            t.add(head + ["n/a", f"n/a ({reason})"] + ["n/a"] * (len(cols) - 5))
            continue
        t.add(head + [fmt_window(r["t_on"], r["t_off"]), fmt(r["V_on"])]
              + [fmt_time(r[analysis.rho_col("settle", rho)]) for rho in RHOS]
              + [" / ".join(fmt_time(r[analysis.rho_col("first", rho)]) for rho in RHOS)]
              + [fmt(r["rate"]), fmt(r["floor_rel"]), fmt(r["V_end_rel"]), fmt(r["e_q_end"]),
                 fmt_int(r["master_closings"]), fmt(r["cpu_time_s"]), fmt(r["steps_per_s"])])
    return t


def verdict_text(row: pd.Series | None, name: str) -> str:
    """What the baseline observer ``name`` does (:func:`reports.analysis.settle_verdict`)."""
    v = analysis.settle_verdict(row)
    kind = v["kind"]
    if kind == "no run":
        return f"no {name} run"
    if kind == "n/a":
        return f"n/a ({v['note']})"
    if kind == "unknown":
        return "unknown (these rows have no settling times; rerun the suite)"
    if kind == "converges":
        return f"converges (settles below {fmt_rho(v['rho'])}·V(t_on) within the window)"
    stall = f"V stalls at {fmt(v['floor_rel'])}·V(t_on)"
    if kind == "persistent contact":
        return (f"does NOT converge at all: persistent contact (master closed in "
                f"{fmt_pct(v['closed_fraction'])} of the steps, χ ≡ 1), it cannot move along W; {stall}")
    return f"does not settle below {fmt_rho(v['rho'])}·V(t_on) within the window; {stall}"


def headline_text(h: dict, pair: tuple[str, str]) -> str:
    """The headline sentence of :func:`reports.analysis.headline` for ``(baseline, candidate)``."""
    base, cand = pair
    kind = h["kind"]
    if kind == "ratio":
        return (f"settling-time ratio {base}/{cand} = {ratio_text(h['ratio'])} at ρ = "
                f"{fmt_rho(h['rho'])} ({fmt(h['settle_base'])} s vs {fmt(h['settle_cand'])} s; "
                f"first-passage ratio {ratio_text(h['first_ratio'])})")
    if kind in ("candidate only", "baseline only"):
        never, settles = (base, cand) if kind == "candidate only" else (cand, base)
        value = "∞" if kind == "candidate only" else "0"
        return (f"{value}: {never} never settles below ρ = {fmt_rho(h['shallowest'])}; {settles} "
                f"settles below ρ = {fmt_rho(h['rho'])} after {fmt(h['settle'])} s")
    if kind == "neither":
        return f"neither {base} nor {cand} settles below ρ = {fmt_rho(h['shallowest'])} in the window"
    if kind == "unknown":
        return "n/a: these rows have no settling times (rerun the suite)"
    return f"n/a: {cand} does not apply here"


def _pick(g: pd.DataFrame, observer: str) -> pd.Series | None:
    sel = g[g["observer"] == observer]
    return sel.iloc[0] if len(sel) else None


def _ratio_record(name: str, g: pd.DataFrame, per: pd.DataFrame, pair: tuple[str, str]) -> dict:
    base, cand = _pick(g, pair[0]), _pick(g, pair[1])
    h = analysis.headline(per)
    rec = {"name": name, "pair": pair, "per_rho": per, "headline": headline_text(h, pair),
           "headline_data": h, "verdict": verdict_text(base, pair[0]),
           "window": float(cand["t_off"] - cand["t_on"]) if cand.get("status") == "ok" else float("nan")}
    note = text(cand.get("note"))
    if h["kind"] == "candidate n/a" and note:
        rec["headline"] += f" ({note})"
        if "K = 0" in note and base.get("status") == "ok":
            rec["verdict"] += (f"; but V = ½vᵀMv does not see positions here (K = 0): the final "
                               f"position error is {fmt(base['e_q_end'])}")
    return rec


def ratio_rows(obs: pd.DataFrame) -> list[dict]:
    """Per scenario and declared pair with both observers run: the rows of
    :func:`reports.analysis.observer_ratios`, the headline and the baseline's verdict."""
    frame = analysis.observer_ratios(obs)
    out = []
    for (name, b, c), per in frame.groupby(["name", "baseline", "candidate"], sort=False):
        out.append(_ratio_record(name, obs[obs["name"] == name], per, (b, c)))
    return out


def _ratio_cell(r: pd.Series, window: float) -> str:
    tc, tb, ratio = r["settle_cand"], r["settle_base"], r["ratio"]
    if not r["cand_ok"]:
        return f"n/a ({r['candidate']} does not apply)"
    if not r["base_ok"]:
        return f"n/a ({r['baseline']} does not apply)"
    if math.isinf(ratio):
        bound = f", ratio > {window / tc:.2f}" if tc > 0 and math.isfinite(window) else ""
        return f"∞ ({r['candidate']} settles at {fmt(tc)} s; {r['baseline']} does not{bound})"
    if ratio == 0:
        return f"only {r['baseline']} settles"
    if math.isnan(ratio):
        return "neither settles" if math.isinf(tc) else "n/a"
    return f"{ratio_text(ratio)} ({fmt(tb)} s / {fmt(tc)} s)"


def ratio_table(ratios: list[dict]) -> Table:
    """One row per (scenario, declared pair): the settling-time ratio at each ρ."""
    cols = (["scenario", "baseline / candidate"] + [f"ratio at ρ = {fmt_rho(rho)}" for rho in RHOS]
            + ["first-passage ratio " + _rho_list(), "headline", "baseline verdict"])
    t = Table("Settling-time ratio baseline / candidate per scenario and declared pair "
              "(t_baseline / t_candidate at each ρ)",
              cols, note="Each cell: ratio of the settling times (t baseline / t candidate), the "
                         "times after t_on from which V stays ≤ ρ·V(t_on) until the end of the "
                         "window; '∞' when only the candidate settles within the coupling window "
                         "(the ratio is then larger than window / t candidate, given in brackets). "
                         "The first-passage ratios (first sample with V ≤ ρ·V(t_on)) are given "
                         "for comparison.")
    for rec in ratios:
        per = rec["per_rho"]
        cells = [_ratio_cell(r, rec["window"]) for _, r in per.iterrows()]
        first = " / ".join(ratio_text(x) for x in per["first_ratio"]) if per["cand_ok"].any() else "n/a"
        t.add([rec["name"], " / ".join(rec["pair"]), *cells, first, rec["headline"], rec["verdict"]])
    return t


def design_table(obs: pd.DataFrame) -> Table:
    """Every registered design (:func:`reports.analysis.design_summary`), run or not."""
    t = Table("Registered observer designs: runs in these results, median final V / V(t_on)",
              ["design", "label", "position jumps (metric)", "runs", "applicable",
               "median V_end / V(t_on)", "median rate (1/s)"])
    for _, r in analysis.design_summary(obs).iterrows():
        d = registry.design(r["observer"])
        t.add([d.name, d.label, f"yes ({d.metric})" if d.position_jumps else "no", fmt_int(r["runs"]),
               fmt_int(r["applicable"]), fmt(r["median_V_end_rel"], na="n/a (no applicable run)"),
               fmt(r["median_rate"], na="n/a (no applicable run)")])
    return t


def pivot_table(obs: pd.DataFrame) -> Table:
    """Final V / V(t_on) and rate per scenario and design side by side
    (:func:`reports.analysis.design_pivot`): how V behaves under each projection metric."""
    end, rate = analysis.design_pivot(obs, "V_end_rel"), analysis.design_pivot(obs, "rate")
    t = Table("V at the end of the window / V(t_on) and decay rate (1/s), per scenario and design",
              ["scenario"] + [registry.label(d) for d in end.columns],
              note="Each cell: V_end / V(t_on); rate in brackets. n/a: the design does not apply.")
    for name in end.index:
        t.add([name] + [f"{fmt(end.loc[name, d])} ({fmt(rate.loc[name, d])}/s)"
                        if pd.notna(end.loc[name, d]) else "n/a" for d in end.columns])
    return t


def excursion_blocks(obs: pd.DataFrame) -> list[Block]:
    """Runs whose V comes back above a threshold after its first passage."""
    exc = analysis.settling_excursions(obs)
    if exc.empty:
        return [Block("p", "In these runs no V returns above a threshold it has reached: "
                           "first-passage and settling times coincide.")]
    items = []
    for _, e in exc.iterrows():
        settle = ("never settles (ends the window above it)" if math.isinf(e["settle"])
                  else f"settles at {fmt(e['settle'])} s")
        items.append(f"{e['name']}, observer {registry.label(e['observer'])}, "
                     f"ρ = {fmt_rho(e['rho'])}: first passage at {fmt(e['first'])} s, {settle}; "
                     f"above the threshold on {fmt_pct(e['above_after'])} of the later samples.")
    return [Block("p", f"V returns above the threshold after its first passage in "
                       f"{len(exc)} case(s); there the first passage overstates the observer:"),
            Block("list", items)]


INTRO = ("All times and ratios in this section are settling times: the time after the start of "
         "coupling t_on from which V stays at or below ρ·V(t_on) up to the end of the coupling "
         "window (the sample after V's last excursion above the threshold; 'not reached' when V "
         "ends the window above it). Ratios are declared as (baseline, candidate) pairs of "
         "observer designs; the headline ratio is t_baseline / t_candidate at the deepest ρ both "
         "settle below. First-passage times (the first sample with V ≤ ρ·V(t_on)) are kept as an "
         "extra column; they are shorter where V dips below a threshold and comes back above it.")


def observer_prose(obs: pd.DataFrame, ratios: list[dict]) -> list[Block]:
    """Paragraphs and lists of the observer section; every number comes from the rows."""
    blocks = [Block("p", INTRO)]
    if not analysis.has_settling(obs):
        blocks.append(Block("p", "Some of these rows were written before settling times were "
                                 "recorded: their settling columns read n/a. Running the suite "
                                 "again reruns those cases."))
    blocks.append(Block("list", [f"{rec['name']}: {rec['headline']}." for rec in ratios]))
    return blocks + excursion_blocks(obs)


def build(ctx: ReportContext) -> Section:
    """The observer section; adds one key-number line per (scenario, pair)."""
    sec = Section("observers", TITLE)
    obs = ctx.rows_or_say(sec, "observers", "observer runs")
    if obs is None:
        return sec
    ratios = ratio_rows(obs)
    sec.blocks += observer_prose(obs, ratios)
    sec.table(ratio_table(ratios))
    sec.table(pivot_table(obs))
    sec.table(observer_table(obs))
    sec.table(design_table(obs))
    ctx.key_numbers.append(designs_key(obs))
    for rec in ratios:
        ctx.key_numbers.append(f"{rec['name']}: {rec['headline']}; {rec['pair'][0]} {rec['verdict']}.")
    return sec


def designs_key(obs: pd.DataFrame) -> str:
    """Key-number line: per design that ran, the median over its applicable runs of V_end/V(t_on)."""
    summ = analysis.design_summary(obs)
    ran = summ[summ["applicable"] > 0]
    return ("Observer designs, median V_end / V(t_on) over their applicable runs: "
            + "; ".join(f"{registry.label(r['observer'])} {fmt(r['median_V_end_rel'])} "
                        f"({fmt_int(r['applicable'])} runs)" for _, r in ran.iterrows()) + ".")
