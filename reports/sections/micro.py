"""Micro-benchmarks: the time loop per step on every engine, and one contact solve with every
registered contact solver against the cvxpy/OSQP reference."""

from __future__ import annotations

import math

import pandas as pd

from reports import analysis, figures, registry
from reports.blocks import Block, Section
from reports.context import ReportContext
from reports.tables import Table, fmt, fmt_int, fmt_ratio

TITLE = "Micro-benchmarks: one step, one contact solve"


def loop_blocks(micro: pd.DataFrame, key_numbers: list[str]) -> list[Block]:
    """Time per step of the loop benchmarks (:func:`reports.analysis.micro_loops`)."""
    ml = analysis.micro_loops(micro)
    if ml.empty:
        return []
    ct = float(ml["compile_time_s"].max())
    t = Table("Time loop per step on both engines (median of the rounds ÷ steps; compile time excluded)",
              ["case", "systems", "n", "m", "steps", "compiled (µs/step)", "python (µs/step)",
               "speed-up", "rounds (compiled / python)"])
    for _, r in ml.iterrows():
        t.add([r["case"], fmt_int(r["systems"]), fmt_int(r["n"]), fmt_int(r["m"]), fmt_int(r["steps"]),
               fmt(r["compiled_s"] * 1e6), fmt(r["python_s"] * 1e6),
               f"{fmt_ratio(r['speedup'])}×" if not math.isnan(r["speedup"]) else "n/a",
               f"{fmt_int(r['rounds_compiled'])} / {fmt_int(r['rounds_python'])}"])
    key_numbers.append("Time per step, compiled engine (python engine): "
                       + ", ".join(f"{r['case']} {fmt(r['compiled_s'] * 1e6)} µs"
                                   + (f" ({fmt(r['python_s'] * 1e6)} µs)" if not math.isnan(r["python_s"]) else "")
                                   for _, r in ml.iterrows())
                       + f"; kernel compile/cache load {fmt(ct)} s, not included.")
    return [Block("p", "Every loop benchmark times observer.loop.run — the loop observer.simulate "
                       "calls — on a fixed window of a built-in scenario (same steps on both engines), "
                       "full trajectory stored; the stepper is built before timing and the kernel "
                       f"compiled (or loaded from numba's cache) first, in {fmt(ct)} s. Per step = "
                       "median over the rounds of one call ÷ steps."),
            Block("table", t)]


def speedup_table(sp: pd.DataFrame) -> Table:
    """:func:`reports.analysis.micro_speedups`: one column pair per registered fast solver."""
    solvers = registry.fast_solvers()
    t = Table("Speed-up of the fast contact solvers over the cvxpy/OSQP reference (mean time per solve)",
              ["m", "reference (µs)"] + [c for s in solvers for c in (f"{s} (µs)", f"speed-up {s}")])
    for _, r in sp.iterrows():
        t.add([fmt_int(r["m"]), fmt(r["reference"] * 1e6)]
              + [c for s in solvers for c in (fmt(r[s] * 1e6, na="n/a (not benchmarked)"),
                                              f"{fmt_ratio(r[f'speedup_{s}'])}×")])
    return t


def all_table(micro: pd.DataFrame) -> Table:
    """Every benchmark record."""
    t = Table("All micro-benchmarks (pytest-benchmark; times per call, a loop call is a whole window)",
              ["group", "benchmark", "mean (µs)", "median (µs)", "std dev (µs)", "rounds", "LCP residual"])
    micro = micro.assign(_m=micro["m"].fillna(-1).astype(float))
    for _, r in micro.sort_values(["kind", "_m", "mean_s"], ascending=[False, True, True]).iterrows():
        t.add([r["group"], r["name"].replace("test_", ""), fmt(r["mean_s"] * 1e6),
               fmt(r["median_s"] * 1e6), fmt(r["stddev_s"] * 1e6), fmt_int(r["rounds"]),
               fmt(r["residual"], na="n/a (time loop)")])
    return t


def speedup_key(sp: pd.DataFrame) -> str:
    """Key-number line: the first fast solver's speed-up per m."""
    s = registry.fast_solvers()[0]
    return (f"Fast contact solver ({s}) vs cvxpy/OSQP reference: "
            + ", ".join(f"{fmt_ratio(r[f'speedup_{s}'])}× at m = {fmt_int(r['m'])}" for _, r in sp.iterrows())
            + " (mean time per solve).")


def build(ctx: ReportContext) -> Section:
    """The micro-benchmark section; adds loop times and solver speed-ups to the key numbers."""
    sec = Section("micro", TITLE)
    micro = ctx.micro
    if micro.empty:
        sec.p("No micro-benchmark results (pytest-benchmark JSON) next to these results files; "
              "run `python -m bench run SUITE` (it runs `pytest bench/micro --benchmark-json=...`).")
        return sec
    sec.blocks += loop_blocks(micro, ctx.key_numbers)
    sp = analysis.micro_speedups(micro)
    if len(sp):
        sec.table(speedup_table(sp))
        ctx.key_numbers.append(speedup_key(sp))
    sec.figure(figures.micro_figure(micro), "No contact-solve benchmarks.")
    sec.table(all_table(micro))
    meta = ctx.micro_meta
    sec.p(f"Source: {meta.get('file')} (pytest-benchmark {meta.get('version')}, {meta.get('datetime')}).")
    return sec
