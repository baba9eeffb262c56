"""Work-precision: error against CPU time per method, fitted orders, each fast contact solver
against the reference on the same method, and every point."""

from __future__ import annotations

import numpy as np
import pandas as pd

from reports import analysis, figures, registry
from reports.context import ReportContext
from reports.blocks import Section
from reports.tables import Table, fmt, fmt_int, fmt_ratio

TITLE = "Work-precision: error against CPU time, fitted orders"

INTRO = ("Every point is one run at one step size h; its error is measured against the reference "
         "stated in the table: the closed form where one exists, otherwise the exact event-driven "
         "solution of the same scenario (the master and the measured observer, computed once "
         "per sweep on its finest grid and sampled on each run's grid). Error norm: {norm}. "
         "Fitted order p: least-squares slope of log error against log h; work slope s: "
         "error ∝ CPU^(−s).")


NO_FIT = "—"
"""Shown in place of a fitted order or slope that has fewer than two points (the fit's NaN)."""
NO_FIT_LEGEND = (f"{NO_FIT}: no fitted order or slope: fewer than two usable points (one step size, "
                 "or errors at zero), so there is no line to fit.")


def fitted(x: float) -> str:
    """A fitted order or slope to two decimals, or :data:`NO_FIT` where nothing was fitted."""
    return f"{x:.2f}" if np.isfinite(x) else NO_FIT


def _solver_cell(r: pd.Series) -> str:
    """The contact solver, or the integrator when it is not the suite's default one."""
    integ = r.get("integrator")
    return r["solver"] if registry.is_default_integrator(integ) else f"{integ} integrator"


def orders_table(orders: pd.DataFrame) -> Table:
    """The fitted orders of :func:`reports.analysis.wp_orders`."""
    t = Table("Fitted orders of convergence per method (scenario · quantity · law · solver)",
              ["scenario", "quantity", "law", "solver", "reference", "points", "h range (s)",
               "order p (mean norm)", "order (max norm)", "work slope s", "smallest error",
               "CPU at smallest error (s)"])
    for _, r in orders.iterrows():
        t.add([r["scenario"], r["target"], r["law"], _solver_cell(r), r["reference"], str(r["points"]),
               f"{fmt(r['h_min'])} … {fmt(r['h_max'])}", fitted(r['order']),
               fitted(r['order_max']), fitted(r['work_slope']), fmt(r["best_err"]),
               fmt(r["best_cpu"])])
    if any(NO_FIT in row for row in t.rows):
        t.note = NO_FIT_LEGEND
    return t


def master_sentence(orders: pd.DataFrame) -> str | None:
    """Fitted orders of the master: the range against closed forms, one per other method."""
    master = orders[orders["target"] == registry.MASTER]
    if master.empty:
        return None
    closed = master[master["reference"].str.startswith("closed form")]
    parts = []
    if len(closed):
        parts.append(f"against closed forms p = {fitted(closed['order'].min())} … "
                     f"{fitted(closed['order'].max())} ({', '.join(dict.fromkeys(closed['scenario']))})")
    other = master[~master.index.isin(closed.index)]
    for (scen, law), g in other.groupby(["scenario", "law"], sort=False):
        ref = g["reference"].iloc[0].split(" (")[0]
        parts.append(f"{scen} {law} ({ref} reference) p = {fitted(g['order'].iloc[0])}")
    return "Master with impacts: " + "; ".join(parts)


def solver_table(comp: pd.DataFrame) -> Table:
    """:func:`reports.analysis.solver_comparison` as a table."""
    t = Table("Contact solvers on the same method and the same step sizes: total CPU time, "
              "smallest error",
              ["scenario", "quantity", "law", "solver", "step sizes", "CPU solver (s)",
               "CPU reference (s)", "ratio reference / solver", "smallest error solver",
               "smallest error reference"])
    for _, r in comp.iterrows():
        t.add([r["scenario"], r["target"], r["law"], r["solver"], fmt_int(r["steps"]),
               fmt(r["cpu_solver"]), fmt(r["cpu_reference"]), fmt_ratio(r["ratio"]),
               fmt(r["best_err_solver"]), fmt(r["best_err_reference"])])
    return t


def solver_sentence(comp: pd.DataFrame) -> str:
    """How far the solvers' smallest errors are apart (they solve the same LCPs exactly)."""
    rel = (comp["best_err_solver"] - comp["best_err_reference"]).abs() / comp["best_err_reference"]
    return (f"The contact solvers' smallest errors differ by at most {fmt(float(rel.max()))} "
            f"(relative) on the same method and step sizes; the CPU time differs by a factor "
            f"{fmt_ratio(comp['ratio'].min())} … {fmt_ratio(comp['ratio'].max())}. The reference "
            f"solver's sweeps cover only the largest step sizes (at most "
            f"{fmt_int(comp['steps'].max())}), so its fitted orders in the table above can be "
            f"pre-asymptotic: the fast solver's longer sweep of the same method gives the order.")


def points_table(wp: pd.DataFrame) -> Table:
    """Every work-precision point."""
    t = Table("Every work-precision point (error against the stated reference)",
              ["method", "h (s)", "error (mean)", "error (max)", "CPU time (s)", "CPU scope",
               "contact solves", "reference"])
    for _, r in wp.sort_values(["method", "h"]).iterrows():
        t.add([r["method"], fmt(r["h"]), fmt(r["err_mean"]), fmt(r["err_max"]),
               fmt(r["cpu_time_s"]), r["cpu_scope"], fmt_int(r["contact_solves"]), r["reference"]])
    return t


def observer_key_numbers(orders: pd.DataFrame) -> list[str]:
    """One key-number line per observer design with a work-precision sweep (fast solvers)."""
    lines = []
    fast = orders[orders["solver"] != registry.REFERENCE_SOLVER]
    for target in registry.in_registry_order(t for t in fast["target"] if t != registry.MASTER):
        ot = fast[fast["target"] == target]
        lines.append(f"Observer {registry.label(target)}: fitted order "
                     + ", ".join(f"{r['law']} {fitted(r['order'])}" for _, r in ot.iterrows())
                     + f" (against {ot['reference'].iloc[0].split(' (')[0]}).")
    return lines


def build(ctx: ReportContext) -> Section:
    """The work-precision section; adds the master's and each observer's orders to the key numbers."""
    sec = Section("work-precision", TITLE)
    wp = ctx.rows_or_say(sec, "work_precision", "work-precision runs")
    if wp is None:
        return sec
    orders = analysis.wp_orders(wp)
    norm = str(wp["norm"].dropna().iloc[0]) if "norm" in wp and wp["norm"].notna().any() else "n/a"
    sec.p(INTRO.format(norm=norm))
    sec.figure(figures.work_precision_figure(wp, dict(zip(orders["method"], orders["order"]))),
               "No work-precision data.")
    sec.table(orders_table(orders))
    msg = master_sentence(orders)
    if msg:
        sec.p(msg + ".")
        ctx.key_numbers.append(msg + ".")
    ctx.key_numbers += observer_key_numbers(orders)
    comp = analysis.solver_comparison(orders, wp)
    if len(comp) and np.isfinite(comp["best_err_reference"]).all():
        sec.table(solver_table(comp))
        sec.p(solver_sentence(comp))
    sec.details(f"All {len(wp)} points", points_table(wp))
    return sec
