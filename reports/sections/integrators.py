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


def _span(values, f) -> str:
    lo, hi = min(values), max(values)
    return f(lo) if lo == hi else f"{f(lo)} … {f(hi)}"


def key_sentence(cmp) -> str:
    """Errors and costs of both integrators at time-stepping's finest step, and the ratio at
    equal error where the work curve allows the extrapolation."""
    msg = (f"Event-driven integrator ({', '.join(dict.fromkeys(cmp['scenario']))}): error "
           f"{_span(cmp['event_err'], fmt)} against time-stepping's {_span(cmp['ts_err'], fmt)} at "
           f"its finest step, for {_span(cmp['cpu_ratio'].rdiv(1.0), fmt_ratio)}× its CPU time")
    eq = cmp["ratio_at_equal_error"].dropna()
    if not eq.empty:
        msg += (f"; at equal error (time-stepping extrapolated along its fitted work curve) "
                f"{_span(eq, fmt_ratio)}× cheaper")
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
