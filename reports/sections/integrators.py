"""Where each integrator wins: the exact event-driven integrator against time-stepping on the
scenarios with a closed form (isolated impacts), from the work-precision rows."""

from __future__ import annotations

from reports import analysis
from reports.blocks import Section
from reports.context import ReportContext
from reports.tables import Table, fmt, fmt_ratio

TITLE = "Integrators: exact event-driven against time-stepping"

INTRO = ("Between impacts every built-in system is linear with harmonic forcing, so the "
         "event-driven integrator (observer.event) follows the exact flow and locates impacts to "
         "round-off: its cost is set by the number of events, not by a step size. Both are measured "
         "against the same closed form. A scenario declares whether it gets exact observer rows "
         "(SUITE['exact']); dense clusters of simultaneous impacts, as in the rocking chain, are "
         "left to time-stepping, whose cost does not grow with the number of impacts.")


def comparison_table(cmp) -> Table:
    """One row per scenario and law (:func:`reports.analysis.integrator_comparison`)."""
    t = Table("Event-driven against time-stepping (fast contact solver, master, error vs the closed form)",
              ["scenario", "law", "event error", "event CPU (s)", "time-stepping smallest error",
               "at h (s)", "its CPU (s)", "CPU ratio (time-stepping / event)",
               "time-stepping CPU extrapolated to the event's error (s)", "ratio at equal error"])
    for _, r in cmp.iterrows():
        t.add([r["scenario"], r["law"], fmt(r["event_err"]), fmt(r["event_cpu"]), fmt(r["ts_err"]),
               fmt(r["ts_h"]), fmt(r["ts_cpu"]), fmt_ratio(r["cpu_ratio"]),
               fmt(r["ts_cpu_at_event_err"]), fmt_ratio(r["ratio_at_equal_error"])])
    return t


def key_sentence(cmp) -> str:
    """The smallest CPU ratio at which the event integrator is also the more accurate."""
    better = cmp[cmp["event_err"] <= cmp["ts_err"]]
    if better.empty:
        return "Event-driven integrator: no scenario where it is both more accurate and measured."
    worst = better.loc[better["cpu_ratio"].idxmin()]
    msg = (f"Event-driven integrator: more accurate than time-stepping's finest step and "
           f"{fmt_ratio(worst['cpu_ratio'])}× cheaper or better on every measured scenario and law "
           f"(least: {worst['scenario']}, {worst['law']}; event error {fmt(worst['event_err'])} vs "
           f"{fmt(worst['ts_err'])})")
    eq = better.dropna(subset=["ratio_at_equal_error"])
    if not eq.empty:
        lo = eq.loc[eq["ratio_at_equal_error"].idxmin()]
        msg += (f"; at equal error (time-stepping extrapolated along its fitted work curve) at "
                f"least {fmt_ratio(lo['ratio_at_equal_error'])}× cheaper ({lo['scenario']}, {lo['law']})")
    return msg


def build(ctx: ReportContext) -> Section:
    """The integrators section; adds its key number."""
    sec = Section("integrators", TITLE)
    wp = ctx.rows_or_say(sec, "work_precision", "work-precision runs")
    if wp is None:
        return sec
    cmp = analysis.integrator_comparison(wp)
    sec.p(INTRO)
    if cmp.empty:
        sec.p("No event-driven work-precision rows in these results.")
        return sec
    sec.table(comparison_table(cmp))
    msg = key_sentence(cmp)
    sec.p(msg + ".")
    ctx.key_numbers.append(msg + ".")
    return sec
