"""Settings and tolerances: each suite's settings and the definitions the numbers use."""

from __future__ import annotations

import inspect

from reports import registry
from reports.analysis import ACCEPTANCE_EXPONENT, ACCEPTANCE_N_MAX, RHOS
from reports.blocks import Section
from reports.context import ReportContext
from reports.tables import Table, fmt

TITLE = "Settings and tolerances"


MISSING = "n/a (suite metadata missing: results written before bench recorded <suite>.meta.json)"
"""What the settings say of a value the suites' metadata sidecar would carry, without it."""


def suite_tables(ctx: ReportContext) -> list[Table]:
    """One table per suite of the rows: its case count and settings, as bench recorded them in
    the suite's metadata sidecar (:meth:`reports.context.ReportContext.suite_meta`)."""
    out = []
    for s in ctx.suites:
        meta = ctx.suite_meta(s)
        if meta is None:
            t = Table(f"Settings of suite {s}", ["setting", "value"])
            t.add(["settings", MISSING])
        else:
            t = Table(f"Settings of suite {s}: {meta.get('description', '')}", ["setting", "value"])
            t.add(["cases", str(len(meta["cases"]))])
            for k, v in (meta.get("settings") or {}).items():
                t.add([k, str(v)])
        out.append(t)
    return out


def _rate_floor_fraction() -> float:
    from observer.metrics import decay_rate
    return inspect.signature(decay_rate).parameters["floor_fraction"].default


def _value(ctx: ReportContext, kind: str, col: str, default: str = "n/a") -> str:
    rows = ctx.rows(kind)
    if col not in rows or rows[col].dropna().empty:
        return default
    return ", ".join(dict.fromkeys(rows[col].dropna().astype(str)))


def definitions_table(ctx: ReportContext) -> Table:
    """Definitions of V, the thresholds, times, norms and bands."""
    from observer import stats

    band, fit_from = ctx.declared("band"), ctx.declared("scaling_fit_from")

    t = Table("Tolerances and definitions used by the suites", ["quantity", "definition / value"])
    t.add(["V", "½(û−u)ᵀM(û−u) + ½(q̂−q)ᵀK(q̂−q), observer minus master (paper (16), ½ on both terms)"])
    t.add(["observer designs", "; ".join(f"{d}: {registry.label(d)}" for d in registry.designs())])
    t.add(["ratios (baseline / candidate)", ", ".join(f"{b}/{c}" for b, c in registry.ratio_pairs())])
    t.add(["synchronization thresholds ρ", ", ".join(fmt(r) for r in RHOS)])
    t.add(["settling time at ρ", "time after t_on from which V ≤ ρ·V(t_on) holds at every sample up "
           "to the end of the coupling window: t_{k*+1} − t_on with k* the last sample above the "
           "threshold; 'not reached' when the last sample is above (observer.metrics.settling_time)"])
    t.add(["first passage at ρ", "time after t_on of the first sample with V ≤ ρ·V(t_on) "
           "(observer.metrics.sync_time)"])
    t.add(["floor", "median of V over the last part of the coupling window (observer.metrics.floor)"])
    t.add(["rate", "−slope of the least-squares line through log V over the window, up to "
           f"V ≤ {fmt(_rate_floor_fraction())}·V(t_on) (observer.metrics.decay_rate)"])
    t.add(["ensemble member's rate (the claims' rate ratio)", "−slope of the least-squares line through "
           "log V from t_on up to the first sample where V ≤ max("
           f"{fmt(stats.SAFETY)} × the largest V of the zero-error observers of every design against the "
           f"same master so far, {fmt(stats.LEVEL_MIN)}·V(t_on)), or the window's end "
           "(observer.compare.member_fits, observer.stats.floor_path); the claims' intervals resample "
           "masters (members split over the masters of an ensemble) or systems"])
    t.add(["work-precision error", _value(ctx, "work_precision", "norm") + " (time average, "
           "trapezoid on the stored grid: every step, or every k-th step at spacing h_record)"])
    t.add(["references of the work-precision points", _value(ctx, "work_precision", "reference")])
    t.add(["robustness band", MISSING if band is None else f"median and {100 * band[0]:.0f}–"
           f"{100 * band[1]:.0f} % quantiles, the band the suite declares (the robustness section "
           "gives instead the median over masters × initial errors with its 95 % cluster bootstrap "
           "interval over masters, observer.stats.cluster_ci)"])
    t.add(["scaling exponent", "least-squares slope of log(CPU time per step) against log N from "
           f"N = {MISSING if fit_from is None else fit_from} (acceptance ≤ {ACCEPTANCE_EXPONENT} up to "
           f"N = {ACCEPTANCE_N_MAX})"])
    t.add(["contact solvers", ", ".join(registry.contact_solvers())
           + f" (compared against {registry.REFERENCE_SOLVER})"])
    t.add(["contact-solve acceptance", "relative LCP residual ‖min(x, Gx+b)‖∞ / max(‖b‖∞, ‖Gx‖∞) "
           f"≤ {fmt(_accept_residual())} for block pivoting, else Lemke (observer.contact.ACCEPT_RESIDUAL)"])
    t.add(["largest residual of a timed contact solve", _largest_residual(ctx)])
    t.add(["scheme", "Moreau–Jean θ-scheme, closed set from the predicted gap g_k + (h/2)γ_k ≤ 0 "
           "(plain master, no projection)"])
    return t


def _accept_residual() -> float:
    from observer.contact import ACCEPT_RESIDUAL
    return ACCEPT_RESIDUAL


def _largest_residual(ctx: ReportContext) -> str:
    m = ctx.micro
    if m.empty or "residual" not in m or m["residual"].dropna().empty:
        return "n/a (no contact-solve benchmarks)"
    return fmt(float(m["residual"].dropna().astype(float).max()))


def build(ctx: ReportContext) -> Section:
    """The settings section."""
    sec = Section("settings", TITLE)
    for t in suite_tables(ctx):
        sec.table(t)
    sec.table(definitions_table(ctx))
    return sec
