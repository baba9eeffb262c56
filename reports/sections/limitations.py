"""Limitations: what the numbers do and do not say; the items that depend on the results
(thresholds, references, horizons, scenarios) are worded from the rows."""

from __future__ import annotations

from reports import registry
from reports.analysis import RHOS
from reports.blocks import Section
from reports.context import ReportContext
from reports.tables import fmt, fmt_rho

TITLE = "Limitations"

DISCRETE_TIME = (
    "What holds in discrete time (θ = ½), for the error between two solutions driven by the same "
    "closed sets: the identity ΔV = damping + impulse (+ projection) holds exactly up to round-off; "
    "the damping term is ≤ 0 (C ⪰ 0) and the projection term ≤ 0 (a K-orthogonal projection) "
    "exactly; the impulse term has no sign in discrete time: besides the impact map's own term "
    "(≤ 0 when the map is monotone, A3) it carries a slack −(1−ε)/(2(1+ε))ΔPᵀΔδ with Δδ = O(h), "
    "which vanishes only as h → 0 (or for ε = 1). V may therefore rise on an impact step by an "
    "O(h) amount; the proof-check table reports where, and the fitted order of that slack.")


def metric_item() -> list[str]:
    """Designs whose position jump projects in another metric than K (registry)."""
    other = [f"{d.name} ({d.metric} metric)" for d in map(registry.design, registry.designs())
             if d.position_jumps and d.metric != "K"]
    if not other:
        return []
    return [f"The sign of the projection term holds for the K-metric projection only: {', '.join(other)} "
            "project in another metric, so their position jump can raise V = ½vᵀMv + ½eᵀKe; the "
            "observer table and the proof checks measure what it does."]
TIMINGS = (
    "Timings are CPU seconds of one process (time.process_time) on the machine in the header, "
    "with {blas} BLAS thread(s); the machine may have been shared with other jobs. Compare "
    "timings within one report, not across machines. Runs with the kernel's contact solver use "
    "the compiled engine; the kernel's compile (or cache-load) time is measured once before any "
    "case and is in no row's time. Runs with another contact solver (the cvxpy/OSQP reference) "
    "use the numpy engine, the only one that has it, so their CPU times also contain the "
    "slower loop.")
FIXED = (
    "The micro-benchmarks solve fixed, small LCPs; the speed-up of the fast solver over the "
    "cvxpy/OSQP reference includes cvxpy's per-call overhead, which is most of the reference's time.",
    "A settling time only covers the coupling window: V may leave the threshold after t_off "
    "(the window end is the last sample checked).",
    "The proof checks are numerical evidence on the built-in scenarios with their default "
    "settings, not proofs.")


def _uniq(rows, col: str) -> str:
    """The distinct values of a column, in order of appearance, as text ('' without any)."""
    if col not in rows:
        return ""
    return ", ".join(dict.fromkeys(fmt(v) for v in rows[col].dropna()))


def thresholds_item(ctx: ReportContext) -> str:
    return ("Suites with coarser steps and shorter horizons (quick) give numbers that differ from "
            f"the full suite's (see Settings); the deepest threshold ({fmt_rho(min(RHOS))}) can sit "
            "below the discretization floor of an observer with position jumps (the floor scales "
            "like h², docs/theory/scheme.md §6).")


def work_precision_items(ctx: ReportContext) -> list[str]:
    wp = ctx.rows("work_precision")
    if wp.empty:
        return []
    refs = [r for r in dict.fromkeys(wp["reference"].astype(str)) if not r.startswith("closed form")]
    out = []
    if refs:
        out.append("Without a closed form the reference is a finer run of the same scheme ("
                   + "; ".join(refs) + "): it measures convergence of the scheme, not modelling error.")
    out.append(f"The work-precision error norm is {_uniq(wp, 'norm') or 'n/a'}; the maximum norm is "
               "also stored (err_max) but does not converge where impacts or position jumps move by "
               "one step between step sizes.")
    return out


def not_applicable_items(ctx: ReportContext) -> list[str]:
    obs = ctx.rows("observers")
    if obs.empty or "status" not in obs:
        return []
    na = obs[obs["status"] != "ok"]
    return [f"{r['name']}: the design {r['observer']} does not apply ({r.get('note') or 'no reason given'}); "
            "where K = 0, V = ½vᵀMv does not see position errors either (see 'final max|q̂ − q|')."
            for _, r in na.drop_duplicates(["name", "observer"]).iterrows()]


def robustness_item(ctx: ReportContext) -> list[str]:
    rob = ctx.rows("robustness")
    if rob.empty:
        return []
    return [f"Robustness uses {_uniq(rob, 'name')} only, one sensor setting at a time (a real sensor "
            "combines them), on the master's own grid; where an observer breaks is known only to "
            "within the levels tried."]


def scaling_item(ctx: ReportContext) -> list[str]:
    scal = ctx.rows("scaling")
    if scal.empty:
        return []
    horizons = ", ".join(fmt(t) for t in dict.fromkeys(scal["t_end"].astype(float)))
    return [f"Scaling times the master only (no observers), from rest over T = {horizons} s; the "
            "per-step time mixes free-flight and contact steps (see 'mean closed contacts'). The "
            "per-step time subtracts a short run's CPU time (the setup); it is a difference of two "
            "measurements and noisier than either. The memory is the peak traced by tracemalloc "
            "(NumPy arrays included), not the resident set size."]


def peers_item(ctx: ReportContext) -> list[str]:
    return ["The peer comparison needs Debian's python3-siconos; Siconos' time includes its Python "
            "stepping loop (computeOneStep/nextStep from Python), the way its Python API is used; "
            "'run()' is its C++ loop on the unforced system, for timing only."]


def limitations(ctx: ReportContext) -> list[str]:
    """Every limitation line for these results."""
    timings = TIMINGS.format(blas=_uniq(ctx.df, "blas_threads") or "an unrecorded number of")
    return ([DISCRETE_TIME] + metric_item() + [timings, thresholds_item(ctx)] + work_precision_items(ctx)
            + not_applicable_items(ctx) + robustness_item(ctx) + scaling_item(ctx)
            + peers_item(ctx) + list(FIXED))


def build(ctx: ReportContext) -> Section:
    """The limitations section."""
    sec = Section("limitations", TITLE)
    sec.items(limitations(ctx))
    return sec
