"""The report's numbers as DataFrames, computed from the tidy result rows (no HTML).

:mod:`reports.build` formats these frames; tests recompute them from the rows.

* :func:`observer_ratios` — per scenario and threshold ρ: the settling times of the two
  observers (time after t_on from which V stays ≤ ρ·V(t_on) until the end of the coupling
  window, :func:`observer.metrics.settling_time`), their ratio no-jump / jump, and the
  first-passage times and ratio for comparison;
* :func:`observer_headlines` — per scenario the headline ratio (deepest ρ at which both
  observers settle) and the no-jump verdict;
* :func:`wp_orders` — fitted orders of the work-precision sweeps;
* :func:`robustness_bands` — per perturbation point and observer: the median and the
  10–90 % band over seeds of the floor and the rate, the median settling times and how many
  seeds settle;
* :func:`scaling_fits` — fitted exponents of the chain's cost against N (the acceptance
  exponent from N = 10 to the largest N);
* :func:`micro_speedups` — speed-ups of the fast contact solvers over the reference;
* :func:`micro_loops` — time per step of every loop benchmark, per engine, and the speed-up
  of the compiled engine;
* :func:`peer_summary` — Siconos against the toolkit: time ratios and trajectory differences.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from bench.suites import BAND, RHOS, SCALING_FIT_FROM

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


# ----------------------------------------------------------------------------- robustness
def band(values, quantiles: tuple[float, float] = BAND) -> tuple[float, float, float]:
    """``(median, q_lo, q_hi)`` of the finite values (numpy's linear quantiles); NaNs when none."""
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan"), float("nan"), float("nan")
    lo, hi = np.quantile(x, quantiles)
    return float(np.median(x)), float(lo), float(hi)


def robustness_bands(rob: pd.DataFrame, quantiles: tuple[float, float] = BAND) -> pd.DataFrame:
    """One row per (perturbation, size, observer) over its seeds (``ok`` rows).

    Columns: ``perturbation, size, observer, seeds``; for the floor (``floor_rel``) and the
    rate: ``floor_median, floor_lo, floor_hi, rate_median, rate_lo, rate_hi`` (median and the
    ``quantiles`` band, :func:`band`); per ρ in (1e-3, 1e-6): ``settle_<ρ>_median`` (median
    settling time over the seeds, ``inf`` when at least half do not settle) and
    ``settled_<ρ>`` (how many seeds settle within the window); ``log_intervals`` (median) and
    ``true_intervals``.
    """
    cols = ["perturbation", "size", "observer", "seeds", "floor_median", "floor_lo", "floor_hi",
            "rate_median", "rate_lo", "rate_hi"]
    for rho in (1e-3, 1e-6):
        cols += [f"settle_{rho:g}_median", f"settled_{rho:g}"]
    cols += ["log_intervals", "true_intervals"]
    rows = []
    ok = rob[rob["status"] == "ok"] if "status" in rob else rob
    for (kind, size, name), g in ok.groupby(["perturbation", "size", "observer"], sort=False):
        rec = {"perturbation": kind, "size": float(size), "observer": name, "seeds": int(g["seed"].nunique())}
        rec["floor_median"], rec["floor_lo"], rec["floor_hi"] = band(g["floor_rel"], quantiles)
        rec["rate_median"], rec["rate_lo"], rec["rate_hi"] = band(g["rate"], quantiles)
        for rho in (1e-3, 1e-6):
            col = SETTLE[rho]
            t = g[col].astype(float).to_numpy() if col in g else np.full(len(g), np.nan)
            rec[f"settle_{rho:g}_median"] = float(np.median(t)) if len(t) else float("nan")
            rec[f"settled_{rho:g}"] = int(np.isfinite(t).sum())
        rec["log_intervals"] = float(g["log_intervals"].median()) if "log_intervals" in g else float("nan")
        rec["true_intervals"] = float(g["true_intervals"].iloc[0]) if "true_intervals" in g else float("nan")
        rows.append(rec)
    return pd.DataFrame(rows, columns=cols)


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
ACCEPTANCE_EXPONENT = 1.1
"""Issue 9: the chain's time per step grows at most like N^1.1 from N = 10 to 1000."""


def scaling_fits(scal: pd.DataFrame, big_from: int = 50,
                 fit_from: int = SCALING_FIT_FROM) -> pd.DataFrame:
    """Fitted exponents p of quantity ∝ N^p: CPU time per step over all N, from N =
    ``fit_from`` (the acceptance fit: ``"CPU time per step (N ≥ 10)"``), over N ≥ ``big_from``
    (each with ≥ 2 points and only when it differs from the full range), the loop's wall time
    per step from N = ``fit_from`` (when the rows have it) and the peak memory. Columns
    ``quantity, N_min, N_max, exponent, coefficient`` (the fit's log-intercept)."""
    scal = scal.sort_values("N")
    rows = []

    def add(quantity, sub, col):
        if col not in sub:
            return
        p, c = fit_power(sub["N"], sub[col])
        if not math.isnan(p):
            rows.append({"quantity": quantity, "N_min": sub["N"].min(), "N_max": sub["N"].max(),
                         "exponent": p, "coefficient": c})

    add("CPU time per step", scal, "cpu_per_step_s")
    for lo in (fit_from, big_from):
        sub = scal[scal["N"] >= lo]
        if len(sub) >= 2 and len(sub) < len(scal):
            add(f"CPU time per step (N ≥ {lo})", sub, "cpu_per_step_s")
    sub = scal[scal["N"] >= fit_from]
    if len(sub) >= 2:
        add(f"loop wall time per step (N ≥ {fit_from})", sub, "loop_per_step_s")
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


def micro_loops(micro: pd.DataFrame) -> pd.DataFrame:
    """Loop benchmarks (``kind == "loop"``): one row per case with the median time per step
    of each engine (median of the rounds ÷ steps), the speed-up compiled over python, the
    steps, systems and compile time. Columns ``case, scenario, systems, steps, n, m,
    compiled_s, python_s, speedup, rounds_compiled, rounds_python, compile_time_s``."""
    cols = ["case", "scenario", "systems", "steps", "n", "m", "compiled_s", "python_s", "speedup",
            "rounds_compiled", "rounds_python", "compile_time_s"]
    if micro.empty or "kind" not in micro:
        return pd.DataFrame(columns=cols)
    lp = micro[micro["kind"] == "loop"]
    rows = []
    for case, g in lp.groupby("case", sort=False):
        rec = {"case": case, "scenario": g["scenario"].iloc[0], "systems": g["systems"].iloc[0],
               "steps": g["steps"].iloc[0], "n": g["n"].iloc[0], "m": g["m"].iloc[0],
               "compile_time_s": g["compile_time_s"].max()}
        for engine in ("compiled", "python"):
            e = g[g["engine"] == engine]
            rec[f"{engine}_s"] = float(e["median_s"].iloc[0] / e["steps"].iloc[0]) if len(e) else float("nan")
            rec[f"rounds_{engine}"] = e["rounds"].iloc[0] if len(e) else float("nan")
        rec["speedup"] = rec["python_s"] / rec["compiled_s"] if rec["compiled_s"] > 0 else float("nan")
        rows.append(rec)
    return pd.DataFrame(rows, columns=cols)


def peer_summary(pe: pd.DataFrame) -> pd.DataFrame:
    """Peer rows (``kind == "peers"``, status ok) → per problem: per-step times in µs (Siconos'
    Python loop, Siconos' C++ ``run()``, the toolkit's whole :func:`observer.simulate` call and
    its loop alone), the ratios Siconos ÷ toolkit (whole call and loop: > 1 means the toolkit
    is faster) and the largest trajectory difference (max over q and u)."""
    cols = ["problem", "n", "m", "h", "steps", "siconos_us", "siconos_run_us", "toolkit_us",
            "toolkit_loop_us", "ratio", "ratio_loop", "ratio_run", "max_diff"]
    rows = []
    ok = pe[pe["status"] == "ok"] if "status" in pe else pe
    for _, r in ok.iterrows():
        sic, tk = float(r["siconos_ns_per_step"]), float(r["toolkit_ns_per_step"])
        loop = float(r.get("toolkit_loop_ns_per_step", float("nan")))
        run = float(r.get("siconos_run_ns_per_step", float("nan")))
        rows.append({"problem": r["problem"], "n": r["n"], "m": r["m"], "h": r["h"], "steps": r["steps"],
                     "siconos_us": sic / 1e3, "siconos_run_us": run / 1e3, "toolkit_us": tk / 1e3,
                     "toolkit_loop_us": loop / 1e3, "ratio": sic / tk,
                     "ratio_loop": sic / loop if loop > 0 else float("nan"),
                     "ratio_run": run / tk,
                     "max_diff": max(float(r["max_abs_diff_q"]), float(r["max_abs_diff_u"]))})
    return pd.DataFrame(rows, columns=cols)
