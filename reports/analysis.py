"""The report's numbers as DataFrames, computed from the tidy result rows (no HTML).

:mod:`reports.build` formats these frames; tests recompute them from the rows.

* :func:`observer_ratios` — per scenario and threshold ρ: the settling times of the two
  observers (time after t_on from which V stays ≤ ρ·V(t_on) until the end of the coupling
  window, :func:`observer.metrics.settling_time`), their ratio no-jump / jump, and the
  first-passage times and ratio for comparison;
* :func:`observer_headlines` — per scenario the headline ratio (deepest ρ at which both
  observers settle) and the no-jump verdict;
* :func:`wp_orders` — fitted orders of the work-precision sweeps;
* :func:`scaling_fits` — fitted exponents of the chain's cost against N;
* :func:`micro_speedups` — speed-ups of the fast contact solvers over the reference.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from bench.suites import RHOS

SETTLE = {rho: f"t_settle_{rho:g}" for rho in RHOS}
"""Row column of the settling time at each ρ."""
FIRST = {rho: f"t_sync_{rho:g}" for rho in RHOS}
"""Row column of the first-passage time at each ρ."""
ABOVE = {rho: f"above_after_{rho:g}" for rho in RHOS}
"""Row column: fraction of window samples after the first passage with V back above ρ·V(t_on)."""


def fit_power(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares fit log y = p log x + c; returns (p, c). NaN when < 2 usable points."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    ok = (x > 0) & (y > 0) & np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 2:
        return float("nan"), float("nan")
    p, c = np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)
    return float(p), float(c)


# ------------------------------------------------------------------------------ observers
def has_settling(obs: pd.DataFrame) -> bool:
    """Whether every applicable observer row carries settling times (rows written before
    they existed do not)."""
    ok = obs[obs["status"] == "ok"] if "status" in obs else obs
    if ok.empty:
        return True
    cols = list(SETTLE.values())
    return all(c in ok for c in cols) and not ok[cols].isna().any().any()


def _get(row: pd.Series | None, col: str) -> float:
    if row is None or row.get("status") != "ok" or col not in row:
        return float("nan")
    v = row[col]
    return float(v) if v is not None else float("nan")


def time_ratio(t_jump: float, t_nojump: float) -> float:
    """t_no-jump / t_jump: ``inf`` when only the jump observer gets there (or t_jump = 0 <
    t_no-jump), ``0`` when only the no-jump observer does, NaN when neither or unknown."""
    if math.isnan(t_jump) or math.isnan(t_nojump):
        return float("nan")
    if math.isinf(t_jump):
        return float("nan") if math.isinf(t_nojump) else 0.0
    if math.isinf(t_nojump):
        return float("inf")
    if t_jump == 0:
        return 1.0 if t_nojump == 0 else float("inf")
    return t_nojump / t_jump


def _pick(g: pd.DataFrame, observer: str) -> pd.Series | None:
    sel = g[g["observer"] == observer]
    return sel.iloc[0] if len(sel) else None


def observer_ratios(obs: pd.DataFrame) -> pd.DataFrame:
    """One row per (scenario name, ρ): settling and first-passage times of both observers.

    Columns: ``name, rho, settle_jump, settle_nojump, ratio`` (settling-time ratio no-jump /
    jump, :func:`time_ratio`), ``first_jump, first_nojump, first_ratio`` (the same with first
    passage), ``jump_ok, nojump_ok`` (the observer applies and ran). Times are seconds from
    t_on; ``inf`` = not within the window, NaN = no run / not applicable.
    """
    rows = []
    for name, g in obs.groupby("name", sort=False):
        j, n = _pick(g, "jump"), _pick(g, "nojump")
        for rho in RHOS:
            sj, sn = _get(j, SETTLE[rho]), _get(n, SETTLE[rho])
            fj, fn = _get(j, FIRST[rho]), _get(n, FIRST[rho])
            rows.append({"name": name, "rho": rho, "settle_jump": sj, "settle_nojump": sn,
                         "ratio": time_ratio(sj, sn), "first_jump": fj, "first_nojump": fn,
                         "first_ratio": time_ratio(fj, fn),
                         "jump_ok": j is not None and j.get("status") == "ok",
                         "nojump_ok": n is not None and n.get("status") == "ok"})
    return pd.DataFrame(rows, columns=["name", "rho", "settle_jump", "settle_nojump", "ratio",
                                       "first_jump", "first_nojump", "first_ratio", "jump_ok",
                                       "nojump_ok"])


def headline(ratios: pd.DataFrame) -> dict:
    """The headline of one scenario's rows of :func:`observer_ratios`.

    ``kind`` is ``"ratio"`` (both observers settle below some ρ: the deepest such ρ, its
    ratio and times), ``"jump only"`` (only the observer with jumps settles; ``rho`` is the
    deepest ρ it settles below), ``"neither"``, ``"no jump observer"`` or ``"unknown"``
    (rows without settling times).
    """
    if not ratios["jump_ok"].any():
        return {"kind": "no jump observer"}
    if ratios["settle_jump"].isna().all():
        return {"kind": "unknown"}
    both = ratios[np.isfinite(ratios["settle_jump"]) & np.isfinite(ratios["settle_nojump"])]
    if len(both):
        r = both.sort_values("rho").iloc[0]
        return {"kind": "ratio", "rho": r["rho"], "ratio": r["ratio"], "settle_jump": r["settle_jump"],
                "settle_nojump": r["settle_nojump"], "first_ratio": r["first_ratio"]}
    jump = ratios[np.isfinite(ratios["settle_jump"])]
    if len(jump):
        r = jump.sort_values("rho").iloc[0]
        return {"kind": "jump only", "rho": r["rho"], "settle_jump": r["settle_jump"],
                "shallowest": float(ratios["rho"].max())}
    return {"kind": "neither", "shallowest": float(ratios["rho"].max())}


def settling_excursions(obs: pd.DataFrame) -> pd.DataFrame:
    """Rows where V first passes below ρ·V(t_on) and comes back above it later: ``name,
    observer, rho, first, settle`` (``inf``: never settles), ``above_after`` (fraction of the
    later window samples above the threshold)."""
    rows = []
    for _, r in obs[obs["status"] == "ok"].iterrows():
        for rho in RHOS:
            first, settle = _get(r, FIRST[rho]), _get(r, SETTLE[rho])
            if math.isfinite(first) and not math.isnan(settle) and settle > first:
                rows.append({"name": r["name"], "observer": r["observer"], "rho": rho,
                             "first": first, "settle": settle,
                             "above_after": _get(r, ABOVE[rho])})
    return pd.DataFrame(rows, columns=["name", "observer", "rho", "first", "settle", "above_after"])


# ------------------------------------------------------------------------- work-precision
def wp_orders(wp: pd.DataFrame) -> pd.DataFrame:
    """Per method (scenario · target · law · solver): fitted order p of the mean-norm error
    against h (error ∝ h^p), of the max-norm error, the work slope s (error ∝ CPU^(−s)), the
    smallest error and its CPU time, and the total CPU time of the sweep."""
    rows = []
    for method, g in wp.groupby("method", sort=False):
        g = g[g["status"] == "ok"].sort_values("h")
        if g.empty:
            continue
        p_h, _ = fit_power(g["h"], g["err_mean"])
        p_c, _ = fit_power(g["cpu_time_s"], g["err_mean"])
        p_max, _ = fit_power(g["h"], g["err_max"])
        best = g.loc[g["err_mean"].idxmin()]
        rows.append({"method": method, "scenario": g["scenario"].iloc[0], "target": g["target"].iloc[0],
                     "law": g["law"].iloc[0], "solver": g["solver"].iloc[0],
                     "reference": g["reference"].iloc[0], "points": len(g),
                     "h_min": g["h"].min(), "h_max": g["h"].max(), "order": p_h, "order_max": p_max,
                     "work_slope": -p_c, "best_err": best["err_mean"], "best_cpu": best["cpu_time_s"],
                     "cpu_total": g["cpu_time_s"].sum()})
    return pd.DataFrame(rows)


# -------------------------------------------------------------------------------- scaling
def scaling_fits(scal: pd.DataFrame, big_from: int = 50) -> pd.DataFrame:
    """Fitted exponents p of quantity ∝ N^p: CPU time per step over all N, over N ≥
    ``big_from`` (with ≥ 2 points) and the peak memory. Columns ``quantity, N_min, N_max,
    exponent, coefficient`` (the fit's log-intercept)."""
    scal = scal.sort_values("N")
    rows = []

    def add(quantity, sub, col):
        p, c = fit_power(sub["N"], sub[col])
        if not math.isnan(p):
            rows.append({"quantity": quantity, "N_min": sub["N"].min(), "N_max": sub["N"].max(),
                         "exponent": p, "coefficient": c})

    add("CPU time per step", scal, "cpu_per_step_s")
    big = scal[scal["N"] >= big_from]
    if len(big) >= 2:
        add(f"CPU time per step (N ≥ {big_from})", big, "cpu_per_step_s")
    if "peak_mem_mb" in scal:
        add("peak memory", scal, "peak_mem_mb")
    return pd.DataFrame(rows, columns=["quantity", "N_min", "N_max", "exponent", "coefficient"])


# ---------------------------------------------------------------------------------- micro
def micro_speedups(micro: pd.DataFrame) -> pd.DataFrame:
    """Per contact count m: mean time per solve of the reference and of each fast solver,
    and the speed-ups reference / solver."""
    if micro.empty:
        return pd.DataFrame()
    cs = micro[micro["kind"] == "contact_solve"]
    rows = []
    for m, g in cs.groupby("m"):
        ref = g[g["solver"] == "reference"]["mean_s"]
        if ref.empty:
            continue
        ref = float(ref.iloc[0])
        rec = {"m": int(m), "reference": ref}
        for s in ("pivoting", "lemke", "nnls"):
            v = g[g["solver"] == s]["mean_s"]
            rec[s] = float(v.iloc[0]) if len(v) else float("nan")
            rec[f"speedup_{s}"] = ref / rec[s] if len(v) and rec[s] > 0 else float("nan")
        rows.append(rec)
    return pd.DataFrame(rows)
