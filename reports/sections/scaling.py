"""Scaling: the rocking chain's CPU time per step and memory against N, fitted exponents and
the acceptance exponent (issue 9) from the N the suite's metadata names (``scaling_fit_from``)."""

from __future__ import annotations

import pandas as pd

from reports import analysis, figures
from reports.analysis import ACCEPTANCE_EXPONENT, ACCEPTANCE_N_MAX
from reports.blocks import Section
from reports.context import ReportContext
from reports.sections.settings import MISSING
from reports.tables import Table, fmt, fmt_int

TITLE = "Scaling: rocking_chain against N"


def intro(scal: pd.DataFrame) -> str:
    """Setting of the scaling runs, from the rows."""
    structure = ", ".join(dict.fromkeys(scal.get("structure", pd.Series(["n/a"])).fillna("n/a").astype(str)))
    setup = (f"a {fmt_int(scal['setup_steps'].iloc[0])}-step run"
             if "setup_steps" in scal and scal["setup_steps"].notna().any() else "a short run")
    return (f"Master only (no observers), h = {fmt(scal['h'].iloc[0])} s, T = "
            f"{fmt(scal['t_end'].iloc[0])} s from rest, compiled engine ({structure} matrices). CPU "
            f"time per step = (CPU time of the run − CPU time of {setup} of the same scenario) / "
            "(difference of their steps): the per-call setup (matrices, factorization, grid) is "
            "subtracted, so the fit measures the step. The whole call is timed as a user makes it: "
            "load_scenario then simulate (builder, document, validation, setup, loop, health), "
            "after a first run (no compilation in it). Memory = peak traced by tracemalloc during "
            "a further, identical run.")


def per_n_table(scal: pd.DataFrame) -> Table:
    """One row per N."""
    t = Table("Scaling of the chain: CPU time per step and memory against N",
              ["N", "n = m", "steps", "CPU per step (µs)", "loop wall per step (µs)", "setup CPU (s)",
               "steps/s", "mean closed contacts", "max closed contacts", "peak memory (MB)",
               "trajectory storage (MB)", "whole call CPU (s)", "of it load (s)"])
    for _, r in scal.iterrows():
        t.add([fmt_int(r["N"]), fmt_int(r["n"]), fmt_int(r["steps"]), fmt(r["cpu_per_step_s"] * 1e6),
               fmt(r.get("loop_per_step_s", float("nan")) * 1e6), fmt(r.get("setup_cpu_time_s")),
               fmt(r["steps_per_s"]), fmt(r["mean_active"]), fmt_int(r["max_active"]),
               fmt(r.get("peak_mem_mb")), fmt(r.get("trajectory_mb")),
               fmt(r.get("whole_call_cpu_s", float("nan"))), fmt(r.get("load_cpu_s", float("nan")))])
    return t


def fits_table(fits: pd.DataFrame) -> Table:
    """:func:`reports.analysis.scaling_fits` as a table (indexed by quantity)."""
    t = Table("Fitted exponents (log-log least squares): quantity ∝ N^p", ["quantity", "N range", "exponent p"])
    for quantity, r in fits.iterrows():
        t.add([quantity, f"{fmt_int(r['N_min'])} … {fmt_int(r['N_max'])}", f"{r['exponent']:.2f}"])
    return t


def key_sentence(scal: pd.DataFrame, fits: pd.DataFrame, key: str, p_acc: float, fit_from: int) -> str:
    """The scaling key number: the acceptance exponent (fitted from N = ``fit_from``), the other
    time fits and the verdict."""
    acc = f"CPU time per step (N ≥ {fit_from})"
    n_lo, n_hi = int(scal["N"].min()), int(scal["N"].max())
    msg = f"Chain scaling: CPU time per step ∝ N^{p_acc:.2f}"
    if key == acc:
        msg += f" from N = {fit_from} to {n_hi}"
        others = [f"{q.replace('CPU time per step', '').strip().strip('()') or f'all N from {n_lo}'}: "
                  f"N^{fits.loc[q, 'exponent']:.2f}" for q in fits.index
                  if q.startswith("CPU time per step") and q != acc]
        if others:
            msg += " (" + "; ".join(others) + ")"
    else:
        msg += f" over N = {n_lo} … {n_hi}"
    target = f"≤ {ACCEPTANCE_EXPONENT} from N = {fit_from} to {ACCEPTANCE_N_MAX}"
    if n_lo <= fit_from and n_hi >= ACCEPTANCE_N_MAX:
        return msg + f"; acceptance ({target}): {'met' if p_acc <= ACCEPTANCE_EXPONENT else 'NOT met'}"
    return msg + f"; the acceptance fit ({target}) needs the full suite"


def _fit(fits: pd.DataFrame, key: str) -> tuple[float, float] | None:
    if key not in fits.index:
        return None
    return float(fits.loc[key, "exponent"]), float(fits.loc[key, "coefficient"])


def build(ctx: ReportContext) -> Section:
    """The scaling section; adds the acceptance exponent to the key numbers."""
    sec = Section("scaling", TITLE)
    scal = ctx.rows_or_say(sec, "scaling", "scaling runs")
    if scal is None:
        return sec
    fit_from = ctx.declared("scaling_fit_from")
    if fit_from is None:
        sec.p(f"The scaling fits are not shown: {MISSING}.")
        return sec
    fit_from = int(fit_from)
    scal = scal.sort_values("N")
    fits = analysis.scaling_fits(scal, fit_from).set_index("quantity")
    acc = f"CPU time per step (N ≥ {fit_from})"
    key = acc if acc in fits.index else "CPU time per step"
    p_acc, c_acc = _fit(fits, key) or (float("nan"), float("nan"))
    sec.p(intro(scal))
    whole_key = f"whole call CPU time (N ≥ {fit_from})"
    whole = _fit(fits, whole_key)
    sec.figure(figures.scaling_figure(scal, (p_acc, c_acc), _fit(fits, "peak memory"),
                                      fit_from if key == acc else None,
                                      (*whole, fit_from) if whole else None), "No scaling data.")
    sec.table(per_n_table(scal))
    sec.table(fits_table(fits))
    msg = key_sentence(scal, fits, key, p_acc, fit_from)
    if whole:
        msg += (f"; the whole call (load_scenario + simulate: builder, validation, setup, loop, "
                f"health) ∝ N^{whole[0]:.2f} from N = {fit_from} to {int(scal['N'].max())}")
    ctx.key_numbers.append(msg + ".")
    sec.p(msg + ". The step costs O(n) for the banded free velocity and O(n|A| + |A|³) for |A| "
                "closed contacts; 'mean closed contacts' says how many there are.")
    return sec
