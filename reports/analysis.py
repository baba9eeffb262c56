"""The report's numbers as DataFrames, computed from the tidy result rows (no HTML).

The sections of :mod:`reports.sections` format these frames; tests recompute them from the
rows. Designs, ratio pairs, thresholds and solvers come from :mod:`reports.registry`.

* :func:`observer_runs` — the observer table: one row per observer run;
* :func:`observer_ratios` — per scenario, declared (baseline, candidate) pair and threshold ρ:
  the settling times (time after t_on from which V stays ≤ ρ·V(t_on) until the end of the
  coupling window, :func:`observer.metrics.settling_time`), their ratio baseline / candidate,
  and the first-passage times and ratio for comparison; :func:`headline` picks one per pair;
* :func:`settle_verdict` — what one observer run does (converges, persistent contact, …);
* :func:`design_summary` — per registered design: runs, applicable runs, median final V;
* :func:`wp_orders` — fitted orders of the work-precision sweeps; :func:`solver_comparison`
  — each fast contact solver against the reference on the same method;
* :func:`scaling_fits` — fitted exponents of the chain's cost against N (the acceptance
  exponent from the suite's ``scaling_fit_from`` N to the largest N);
* :func:`micro_speedups` — speed-ups of the fast contact solvers over the reference;
* :func:`micro_loops` — time per step of every loop benchmark, per engine, and the speed-up
  of the compiled engine;
* :func:`peer_summary` — Siconos against the toolkit: time ratios and trajectory differences;
* :func:`check_counts` — proof-check statuses per design and in total.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from observer.engines import ENGINES
from reports import registry
from reports.tables import text

RHOS = registry.rhos()
"""Synchronization thresholds of the rows (:func:`reports.registry.rhos`)."""

SETTLE = {rho: registry.settle_column(rho) for rho in RHOS}
"""Row column of the settling time at each ρ."""
FIRST = {rho: registry.sync_column(rho) for rho in RHOS}
"""Row column of the first-passage time at each ρ."""
ABOVE = {rho: registry.above_column(rho) for rho in RHOS}
"""Row column: fraction of window samples after the first passage with V back above ρ·V(t_on)."""


def rho_col(prefix: str, rho: float, suffix: str = "") -> str:
    """Column of a per-ρ quantity in the frames of this module (``settle_1e-06``,
    ``settle_1e-06_median``): the one place these names are built."""
    return f"{prefix}_{rho:g}{suffix}"


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


def time_ratio(t_cand: float, t_base: float) -> float:
    """t_base / t_cand: ``inf`` when only the candidate gets there (or t_cand = 0 < t_base),
    ``0`` when only the baseline does, NaN when neither or unknown."""
    if math.isnan(t_cand) or math.isnan(t_base):
        return float("nan")
    if math.isinf(t_cand):
        return float("nan") if math.isinf(t_base) else 0.0
    if math.isinf(t_base):
        return float("inf")
    if t_cand == 0:
        return 1.0 if t_base == 0 else float("inf")
    return t_base / t_cand


def _pick(g: pd.DataFrame, observer: str) -> pd.Series | None:
    sel = g[g["observer"] == observer]
    return sel.iloc[0] if len(sel) else None


RATIO_COLUMNS = ["name", "baseline", "candidate", "rho", "settle_base", "settle_cand", "ratio",
                 "first_base", "first_cand", "first_ratio", "base_ok", "cand_ok"]


def _pair_rows(name: str, b: pd.Series, c: pd.Series, pair: tuple[str, str]) -> list[dict]:
    rows = []
    for rho in RHOS:
        sb, sc = _get(b, SETTLE[rho]), _get(c, SETTLE[rho])
        fb, fc = _get(b, FIRST[rho]), _get(c, FIRST[rho])
        rows.append({"name": name, "baseline": pair[0], "candidate": pair[1], "rho": rho,
                     "settle_base": sb, "settle_cand": sc, "ratio": time_ratio(sc, sb),
                     "first_base": fb, "first_cand": fc, "first_ratio": time_ratio(fc, fb),
                     "base_ok": b.get("status") == "ok", "cand_ok": c.get("status") == "ok"})
    return rows


def observer_ratios(obs: pd.DataFrame, pairs=None) -> pd.DataFrame:
    """One row per (scenario name, declared pair, ρ): settling and first-passage times.

    Parameters
    ----------
    obs : DataFrame
        Observer rows (``kind == "observers"``).
    pairs : sequence of (baseline, candidate), optional
        Default: the declared :data:`observer.observers.RATIOS`. A pair appears for a scenario
        when both observers have a row there.

    Returns
    -------
    DataFrame
        Columns ``name, baseline, candidate, rho, settle_base, settle_cand, ratio`` (settling
        time ratio baseline / candidate, :func:`time_ratio`), ``first_base, first_cand,
        first_ratio`` (the same with first passage), ``base_ok, cand_ok`` (the observer
        applies and ran). Times are seconds from t_on; ``inf`` = not within the window, NaN =
        not applicable.
    """
    pairs = registry.ratio_pairs() if pairs is None else pairs
    rows = []
    for name, g in obs.groupby("name", sort=False):
        for pair in pairs:
            b, c = _pick(g, pair[0]), _pick(g, pair[1])
            if b is not None and c is not None:
                rows += _pair_rows(name, b, c, pair)
    return pd.DataFrame(rows, columns=RATIO_COLUMNS)


def headline(ratios: pd.DataFrame) -> dict:
    """The headline of one scenario's rows of :func:`observer_ratios` for one pair.

    ``kind`` is ``"ratio"`` (both observers settle below some ρ: the deepest such ρ, its
    ratio and times), ``"candidate only"`` / ``"baseline only"`` (only that observer settles;
    ``rho`` is the deepest ρ it settles below), ``"neither"``, ``"candidate n/a"`` (the
    candidate design does not apply) or ``"unknown"`` (rows without settling times).
    """
    if not ratios["cand_ok"].any():
        return {"kind": "candidate n/a"}
    if ratios["settle_cand"].isna().all():
        return {"kind": "unknown"}
    shallowest = float(ratios["rho"].max())
    both = ratios[np.isfinite(ratios["settle_cand"]) & np.isfinite(ratios["settle_base"])]
    if len(both):
        r = both.sort_values("rho").iloc[0]
        return {"kind": "ratio", "rho": r["rho"], "ratio": r["ratio"], "settle_cand": r["settle_cand"],
                "settle_base": r["settle_base"], "first_ratio": r["first_ratio"]}
    for kind, col in (("candidate only", "settle_cand"), ("baseline only", "settle_base")):
        one = ratios[np.isfinite(ratios[col])]
        if len(one):
            r = one.sort_values("rho").iloc[0]
            return {"kind": kind, "rho": r["rho"], "settle": r[col], "shallowest": shallowest}
    return {"kind": "neither", "shallowest": shallowest}


PERSISTENT_FRACTION = 0.99
"""An observer that does not settle is said to face persistent contact when the master is
closed in at least this fraction of the steps (χ ≡ 1 in practice)."""


def settle_verdict(row: pd.Series | None) -> dict:
    """What one observer run does, from its settling times: ``kind`` in {"no run", "n/a",
    "unknown", "persistent contact", "no settling", "converges"} with ``rho`` (the deepest ρ it
    settles below, or the shallowest it misses), ``floor_rel`` and ``closed_fraction``."""
    if row is None:
        return {"kind": "no run"}
    if row.get("status") != "ok":
        return {"kind": "n/a", "note": text(row.get("note"))}
    settle = {rho: _get(row, c) for rho, c in SETTLE.items()}
    if any(math.isnan(v) for v in settle.values()):
        return {"kind": "unknown"}
    shallow = max(RHOS)
    closed = float(row.get("master_closed_fraction", float("nan")) or float("nan"))
    if math.isinf(settle[shallow]):
        kind = "persistent contact" if closed >= PERSISTENT_FRACTION else "no settling"
        return {"kind": kind, "rho": shallow, "floor_rel": float(row["floor_rel"]),
                "closed_fraction": closed}
    deepest = min(rho for rho, v in settle.items() if not math.isinf(v))
    return {"kind": "converges", "rho": deepest}


def observer_runs(obs: pd.DataFrame) -> pd.DataFrame:
    """The observer table as numbers: one row per run, in registry order of the designs
    within each scenario. Columns ``name, observer, status, note, h, t_on, t_off, V_on``,
    the settling and first-passage time at each ρ (``settle_<ρ>``, ``first_<ρ>``), ``rate,
    floor_rel, V_end_rel, e_q_end, master_closings, cpu_time_s, steps_per_s``."""
    cols = ["name", "observer", "status", "note", "h", "t_on", "t_off", "V_on"]
    cols += [rho_col("settle", rho) for rho in RHOS] + [rho_col("first", rho) for rho in RHOS]
    cols += ["rate", "floor_rel", "V_end_rel", "e_q_end", "master_closings", "cpu_time_s",
             "steps_per_s"]
    rows = []
    for name, g in obs.groupby("name", sort=False):
        for observer in registry.in_registry_order(g["observer"]):
            r = _pick(g, observer)
            rec = {c: r.get(c) for c in cols}
            ok = r.get("status") == "ok"
            for rho in RHOS:
                rec[rho_col("settle", rho)] = _get(r, SETTLE[rho]) if ok else float("nan")
                rec[rho_col("first", rho)] = _get(r, FIRST[rho]) if ok else float("nan")
            rows.append(rec)
    return pd.DataFrame(rows, columns=cols)


def design_pivot(obs: pd.DataFrame, value: str = "V_end_rel") -> pd.DataFrame:
    """One row per scenario name, one column per observer design that ran (registry order):
    ``value`` of that run (NaN where the design does not apply or did not run)."""
    ok = obs[obs["status"] == "ok"] if len(obs) else obs
    designs = registry.in_registry_order(obs["observer"]) if len(obs) else []
    names = list(dict.fromkeys(obs["name"])) if len(obs) else []
    table = pd.DataFrame(float("nan"), index=pd.Index(names, name="name"), columns=designs)
    for _, r in ok.iterrows():
        table.loc[r["name"], r["observer"]] = float(r[value])
    return table


def design_summary(obs: pd.DataFrame) -> pd.DataFrame:
    """Per registered observer design (registry order): scenarios where it ran (``runs``),
    where it applies (``applicable``), and the median over those of the final V/V(t_on)
    (``median_V_end_rel``) and of the rate. A registered design without rows has 0 runs."""
    rows = []
    for name in registry.designs():
        g = obs[obs["observer"] == name] if len(obs) else obs
        ok = g[g["status"] == "ok"] if len(g) else g
        rows.append({"observer": name, "runs": int(len(g)), "applicable": int(len(ok)),
                     "median_V_end_rel": float(ok["V_end_rel"].median()) if len(ok) else float("nan"),
                     "median_rate": float(ok["rate"].median()) if len(ok) else float("nan")})
    return pd.DataFrame(rows, columns=["observer", "runs", "applicable", "median_V_end_rel",
                                       "median_rate"])


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
    smallest error and its CPU time, and the total CPU time of the sweep; ``integrator`` (the
    rows' integrator, "" when they do not say)."""
    rows = []
    for method, g in wp.groupby("method", sort=False):
        integrator = text(g["integrator"].iloc[0]) if "integrator" in g else ""
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
                     "cpu_total": g["cpu_time_s"].sum(), "integrator": integrator})
    return pd.DataFrame(rows)


def integrator_comparison(wp: pd.DataFrame) -> pd.DataFrame:
    """Where each integrator wins, per scenario and law with an exact event-driven row: the
    event integrator's error and CPU time against the closed form, the time-stepping sweep's
    smallest error (fast contact solvers, its step and CPU time), and ``cpu_ratio`` = time-stepping
    CPU at its smallest error / event CPU (the event run is also the more accurate when
    ``event_err ≤ ts_err``); ``ts_cpu_at_event_err`` extrapolates the sweep's fitted work
    curve (CPU ∝ error^p, p < 0; NaN otherwise) to the event integrator's error and
    ``ratio_at_equal_error`` divides it by the event CPU."""
    if wp.empty or "integrator" not in wp:
        return pd.DataFrame()
    ok = wp[wp["status"] == "ok"]
    rows = []
    for (scen, law), g in ok.groupby(["scenario", "law"], sort=False):
        ev = g[g["integrator"] == "event"]
        ts = g[(g["integrator"] != "event") & (g["solver"] != registry.REFERENCE_SOLVER)
               & (g["target"] == registry.MASTER)]
        if ev.empty or len(ts) < 2:
            continue
        e = ev.iloc[0]
        best = ts.loc[ts["err_mean"].idxmin()]
        p_c, c_c = fit_power(ts["err_mean"], ts["cpu_time_s"])     # CPU ∝ error^p_c
        extrap = (float(np.exp(c_c) * max(e["err_mean"], 1e-300) ** p_c) if p_c < 0
                  else float("nan"))       # no extrapolation without a decreasing work curve
        rows.append({"scenario": scen, "law": law, "event_err": e["err_mean"],
                     "event_cpu": e["cpu_time_s"], "ts_h": best["h"], "ts_err": best["err_mean"],
                     "ts_cpu": best["cpu_time_s"], "cpu_ratio": best["cpu_time_s"] / e["cpu_time_s"],
                     "ts_cpu_at_event_err": extrap, "ratio_at_equal_error": extrap / e["cpu_time_s"]})
    return pd.DataFrame(rows)


# -------------------------------------------------------------------------------- scaling
ACCEPTANCE_EXPONENT = 1.1
"""Issue 9: the chain's time per step grows at most like N^1.1 from N = 10 to 1000."""
ACCEPTANCE_N_MAX = 1000
"""The largest N the acceptance exponent must hold up to (from the suite's ``scaling_fit_from``)."""


def scaling_fits(scal: pd.DataFrame, fit_from: int, big_from: int = 50) -> pd.DataFrame:
    """Fitted exponents p of quantity ∝ N^p: CPU time per step over all N, from N =
    ``fit_from`` (the acceptance fit: ``"CPU time per step (N ≥ 10)"``), over N ≥ ``big_from``
    (each with ≥ 2 points and only when it differs from the full range), the loop's wall time
    per step and the whole call's CPU time (load + setup + loop + health, issue 23) from N =
    ``fit_from`` (when the rows have them) and the peak memory. Columns
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
    if len(sub) >= 2 and "whole_call_cpu_s" in sub and sub["whole_call_cpu_s"].notna().all():
        add(f"whole call CPU time (N ≥ {fit_from})", sub, "whole_call_cpu_s")
    if "peak_mem_mb" in scal:
        _memory_fits(scal, add)
    return pd.DataFrame(rows, columns=["quantity", "N_min", "N_max", "exponent", "coefficient"])


def _memory_fits(scal: pd.DataFrame, add) -> None:
    """Peak memory's exponent within one storage mode: rows keeping every step and rows keeping
    one row every ``h_record`` seconds (the full suite's N ≥ 2000) store different amounts per
    step, so one fit across both would measure the switch, not the scaling (e.g. 282 MB at
    N = 1000 then 25 MB at N = 2000). One mode only: ``"peak memory"``."""
    sparse_rows = scal["h_record"].notna() if "h_record" in scal else pd.Series(False, index=scal.index)
    if not sparse_rows.any() or sparse_rows.all():
        add("peak memory", scal, "peak_mem_mb")
        return
    every = scal[~sparse_rows]
    if len(every) >= 2:
        add("peak memory (every step stored)", every, "peak_mem_mb")
    for h_rec, sub in scal[sparse_rows].groupby("h_record"):
        if len(sub) >= 2:
            add(f"peak memory (a row every {h_rec:g} s)", sub, "peak_mem_mb")


# ---------------------------------------------------------------------------------- micro
def micro_speedups(micro: pd.DataFrame) -> pd.DataFrame:
    """Per contact count m: mean time per solve of the reference and of each registered fast
    solver (:func:`reports.registry.fast_solvers`), and the speed-ups reference / solver.
    Columns ``m, reference, <solver>, speedup_<solver>`` (seconds; NaN: not benchmarked)."""
    solvers = registry.fast_solvers()
    cols = ["m", "reference"] + [c for s in solvers for c in (s, f"speedup_{s}")]
    if micro.empty or "kind" not in micro:
        return pd.DataFrame(columns=cols)
    cs = micro[micro["kind"] == "contact_solve"]
    rows = []
    for m, g in cs.groupby("m"):
        ref = g[g["solver"] == registry.REFERENCE_SOLVER]["mean_s"]
        if ref.empty:
            continue
        rec = {"m": int(m), "reference": float(ref.iloc[0])}
        for s in solvers:
            v = g[g["solver"] == s]["mean_s"]
            rec[s] = float(v.iloc[0]) if len(v) else float("nan")
            rec[f"speedup_{s}"] = rec["reference"] / rec[s] if len(v) and rec[s] > 0 else float("nan")
        rows.append(rec)
    return pd.DataFrame(rows, columns=cols)


def micro_loops(micro: pd.DataFrame) -> pd.DataFrame:
    """Loop benchmarks (``kind == "loop"``): one row per case with the median time per step
    of each engine of :data:`observer.ENGINES` (median of the rounds ÷ steps; NaN for an
    engine the case has no benchmark of), the speed-up compiled over python, the steps,
    systems and compile time. Columns ``case, scenario, systems, steps, n, m``, then
    ``<engine>_s`` per engine, ``speedup``, ``rounds_<engine>`` per engine and
    ``compile_time_s``."""
    engines = list(ENGINES)
    cols = ["case", "scenario", "systems", "steps", "n", "m", *(f"{e}_s" for e in engines), "speedup",
            *(f"rounds_{e}" for e in engines), "compile_time_s"]
    if micro.empty or "kind" not in micro:
        return pd.DataFrame(columns=cols)
    lp = micro[micro["kind"] == "loop"]
    rows = []
    for case, g in lp.groupby("case", sort=False):
        rec = {"case": case, "scenario": g["scenario"].iloc[0], "systems": g["systems"].iloc[0],
               "steps": g["steps"].iloc[0], "n": g["n"].iloc[0], "m": g["m"].iloc[0],
               "compile_time_s": g["compile_time_s"].max()}
        for engine in engines:
            e = g[g["engine"] == engine]
            rec[f"{engine}_s"] = float(e["median_s"].iloc[0] / e["steps"].iloc[0]) if len(e) else float("nan")
            rec[f"rounds_{engine}"] = e["rounds"].iloc[0] if len(e) else float("nan")
        compiled, python = rec.get("compiled_s", float("nan")), rec.get("python_s", float("nan"))
        rec["speedup"] = python / compiled if compiled > 0 else float("nan")
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


# ------------------------------------------------------------------- work-precision solvers
def solver_comparison(orders: pd.DataFrame, wp: pd.DataFrame | None = None) -> pd.DataFrame:
    """The same method (scenario · target · law) with each fast contact solver and with the
    reference solver: total CPU time of the sweep, its ratio reference / solver and the
    smallest errors. Columns ``scenario, target, law, solver, cpu_solver, cpu_reference,
    ratio, best_err_solver, best_err_reference, steps``.

    With the points ``wp`` (the rows :func:`wp_orders` fitted), the CPU times and smallest
    errors are taken over the step sizes both sweeps ran (``steps``: how many), so that a
    fast solver's longer sweep is not compared with the reference's shorter one; without
    them, over each whole sweep (``steps`` NaN)."""
    cols = ["scenario", "target", "law", "solver", "cpu_solver", "cpu_reference", "ratio",
            "best_err_solver", "best_err_reference", "steps"]
    if orders.empty:
        return pd.DataFrame(columns=cols)
    keys = ["scenario", "target", "law"]
    if "integrator" in orders:                       # contact solvers only matter to time-stepping
        orders = orders[orders["integrator"].map(registry.is_default_integrator).astype(bool)]
    ref = orders[orders["solver"] == registry.REFERENCE_SOLVER]
    fast = orders[orders["solver"] != registry.REFERENCE_SOLVER]
    both = fast.merge(ref, on=keys, suffixes=("_s", "_r"))
    rows = []
    for _, r in both.iterrows():
        cpu_s, cpu_r, err_s, err_r, steps = (r["cpu_total_s"], r["cpu_total_r"], r["best_err_s"],
                                             r["best_err_r"], float("nan"))
        if wp is not None:
            ok = wp[wp["status"] == "ok"]
            a, b = ok[ok["method"] == r["method_s"]], ok[ok["method"] == r["method_r"]]
            common = np.intersect1d(a["h"].to_numpy(float), b["h"].to_numpy(float))
            if common.size == 0:
                continue
            a, b = a[a["h"].isin(common)], b[b["h"].isin(common)]
            cpu_s, cpu_r = a["cpu_time_s"].sum(), b["cpu_time_s"].sum()
            err_s, err_r, steps = a["err_mean"].min(), b["err_mean"].min(), int(common.size)
        rows.append({"scenario": r["scenario"], "target": r["target"], "law": r["law"],
                     "solver": r["solver_s"], "cpu_solver": cpu_s, "cpu_reference": cpu_r,
                     "ratio": cpu_r / cpu_s, "best_err_solver": err_s, "best_err_reference": err_r,
                     "steps": steps})
    return pd.DataFrame(rows, columns=cols)


# --------------------------------------------------------------------------- proof checks
CHECK_STATUSES = ("PASS", "FAIL", "n/a")
"""Status values of a proof-check row."""


def check_counts(ch: pd.DataFrame) -> pd.DataFrame:
    """Per design the check rows concern (column ``design`` of the rows, "" for checks of the
    model; every registered design listed, with zeros when it has no rows) and in total
    (``design == "all"``): how many rows have each status, and on how many scenarios.
    Columns ``design, scenarios, PASS, FAIL, n/a``."""
    design = ch["design"].fillna("").astype(str) if "design" in ch else pd.Series("", index=ch.index)
    groups = [("all", ch)] + [(d, ch[design == d]) for d in registry.designs()]
    extra = [d for d in dict.fromkeys(design) if d and d not in registry.designs()]
    groups += [(d, ch[design == d]) for d in extra]
    rows = []
    for name, g in groups:
        status = g["check_status"].astype(str) if len(g) else pd.Series(dtype=str)
        rec = {"design": name, "scenarios": int(g["scenario"].nunique()) if len(g) else 0}
        rec.update({s: int((status == s).sum()) for s in CHECK_STATUSES})
        rows.append(rec)
    return pd.DataFrame(rows, columns=["design", "scenarios", *CHECK_STATUSES])


EVIDENCE_ORDER = ("proved", "bounded", "sampled", "violated", "n/a")
"""Evidence levels of a check row (:data:`proofs_checks.result.EVIDENCE_LEVELS` and "n/a"), strongest first."""


def check_evidence(r: pd.Series) -> str:
    """The evidence level of a check row: its ``evidence`` column, or, for rows written before
    the levels existed, "n/a" when not applicable and "" (unknown) otherwise."""
    ev = r.get("evidence")
    if isinstance(ev, str) and ev:
        return ev
    return "n/a" if str(r.get("check_status")) == "n/a" else ""


def check_matrix(ch: pd.DataFrame) -> tuple[list[str], list[str], dict]:
    """Scenarios (rows, in first-seen order), checks (columns, in first-seen order) and, per
    (scenario, check), the last row of that pair (a later run replaces an earlier one)."""
    scenarios = list(dict.fromkeys(ch["scenario"].astype(str)))
    checks = list(dict.fromkeys(ch["check"].astype(str)))
    cells = {(str(r["scenario"]), str(r["check"])): r for _, r in ch.iterrows()}
    return scenarios, checks, cells


# ------------------------------------------------------------------------------ ensembles
# Statistics over ensembles of initial errors (issue 22): the members' rows of
# :func:`observer.ensemble` (one row per design and member, the same member ids paired across
# designs). Settling times are seconds from t_on, ``inf`` = V never stays below ρ·V(t_on)
# within the window.
DEFAULT_PAIRS: tuple[tuple[str, str], ...] = registry.ratio_pairs()
"""Declared (baseline, candidate) pairs of the ensemble statistics."""

CI_METHOD = ("percentile bootstrap (scipy.stats.bootstrap) of the median of the per-member "
             "ratio t_candidate / t_baseline, members resampled (the pairing kept)")
"""How :func:`paired_settling` computes its confidence interval (stated in its rows)."""

MIN_WILCOXON = 5
"""Fewest members settling under both designs for which :func:`paired_settling` reports a
Wilcoxon p-value."""

RISE_ROUNDOFF = 1e-10
"""A member's V "rises" when its largest one-step relative increase ``max_rise_rel`` exceeds
this: round-off of V = ½eᵀKe + ½vᵀMv is ≈ 1e-16 relative per step, and the O(h) slack of the
discrete impulse term (docs/theory/index.md §1: ≲ 1e-6 relative per step) is counted as a rise."""

GROUP_KEYS = ("label", "integrator")
"""Columns an ensemble's statistics are grouped by (those present; ``label`` falls back to
``scenario``)."""


def _groups(members: pd.DataFrame):
    """``((label, integrator), frame)`` per ensemble in first-seen order."""
    df = members
    if "label" not in df:
        df = df.assign(label=df["scenario"] if "scenario" in df else "")
    if "integrator" not in df:
        df = df.assign(integrator="")
    return df.groupby(list(GROUP_KEYS), sort=False)


def paired_ratio(t_base: np.ndarray, t_cand: np.ndarray) -> np.ndarray:
    """Per member the settling-time ratio t_cand / t_base with "never" (inf) made explicit:
    finite / finite (0/0 = 1), ``inf`` when only the baseline settles, ``0`` when only the
    candidate does, NaN when neither (undefined; such members are counted in
    ``never_baseline`` and ``never_candidate`` instead)."""
    tb, tc = np.asarray(t_base, float), np.asarray(t_cand, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = tc / tb
    r = np.where((tb == 0) & (tc == 0), 1.0, r)
    r = np.where(np.isinf(tc) & np.isfinite(tb), np.inf, r)
    r = np.where(np.isinf(tb) & np.isfinite(tc), 0.0, r)
    return np.where(np.isinf(tb) & np.isinf(tc), np.nan, r)


def _quantile(x: np.ndarray, q: float) -> float:
    """Quantile by the inverted empirical CDF (no interpolation, so ``inf`` members stay
    ``inf`` instead of making NaN)."""
    return float(np.quantile(x, q, method="inverted_cdf")) if x.size else float("nan")


def _median_ci(ratios: np.ndarray, confidence: float, n_resamples: int, rng) -> tuple[float, float]:
    """Percentile-bootstrap CI of the median of ``ratios`` (may hold ``inf``)."""
    from scipy import stats

    with np.errstate(invalid="ignore"):              # inf members: scipy's standard error is NaN
        res = stats.bootstrap((ratios,), np.median, n_resamples=n_resamples, method="percentile",
                              confidence_level=confidence, rng=rng)
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def _wilcoxon(tb: np.ndarray, tc: np.ndarray) -> tuple[float, str]:
    """Two-sided Wilcoxon signed-rank p-value of log t_cand − log t_base over the members that
    settle (t > 0) under both designs, and why it is NaN when undefined."""
    from scipy import stats

    both = np.isfinite(tb) & np.isfinite(tc) & (tb > 0) & (tc > 0)
    d = np.log(tc[both]) - np.log(tb[both])
    if both.sum() < MIN_WILCOXON:
        return float("nan"), f"Wilcoxon: fewer than {MIN_WILCOXON} members settle under both designs"
    if not np.any(d != 0):
        return float("nan"), "Wilcoxon: every paired difference is zero"
    return float(stats.wilcoxon(d).pvalue), ""


def _pair_stats(tb: np.ndarray, tc: np.ndarray, confidence: float, n_resamples: int, rng) -> dict:
    """The statistics of one (pair, ρ) of one ensemble (:func:`paired_settling`)."""
    r = paired_ratio(tb, tc)
    defined = r[~np.isnan(r)]
    rec = {"n": int(tb.size), "n_ratio": int(defined.size),
           "ratio_median": float(np.median(defined)) if defined.size else float("nan"),
           "ratio_q10": _quantile(defined, 0.1), "ratio_q90": _quantile(defined, 0.9),
           "ci_low": float("nan"), "ci_high": float("nan"),
           "frac_candidate_first": float(np.mean(tc < tb)) if tb.size else float("nan"),
           "never_baseline": float(np.mean(np.isinf(tb))) if tb.size else float("nan"),
           "never_candidate": float(np.mean(np.isinf(tc))) if tb.size else float("nan"),
           "ci_method": CI_METHOD}
    reasons = []
    if defined.size >= 2:
        rec["ci_low"], rec["ci_high"] = _median_ci(defined, confidence, n_resamples, rng)
    else:
        reasons.append("no CI: fewer than 2 members settle under either design")
    rec["wilcoxon_p"], why = _wilcoxon(tb, tc)
    rec["reason"] = "; ".join(reasons + ([why] if why else []))
    return rec


PAIRED_COLUMNS = ["label", "integrator", "baseline", "candidate", "rho", "n", "n_ratio",
                  "ratio_median", "ratio_q10", "ratio_q90", "ci_low", "ci_high",
                  "frac_candidate_first", "never_baseline", "never_candidate", "wilcoxon_p",
                  "reason", "ci_method"]


def paired_settling(members: pd.DataFrame, pairs=DEFAULT_PAIRS, rhos=RHOS, *,
                    confidence: float = 0.95, n_resamples: int = 2000, rng=None) -> pd.DataFrame:
    """Paired settling-time statistics of ensembles (issue 22 item 2).

    Parameters
    ----------
    members : DataFrame
        One row per (design, member) (:func:`observer.ensemble`): columns ``design``,
        ``member``, ``t_settle_ρ`` for each ρ, and ``label`` (else ``scenario``) and
        ``integrator`` when several ensembles are stacked.
    pairs : sequence of (baseline, candidate)
        Design pairs; a pair is reported where both designs have rows. Members are matched by
        their ``member`` id (never by row order).
    rhos : sequence of float
        Thresholds ρ (settling below ρ·V(t_on), :func:`observer.metrics.settling_time`).
    confidence, n_resamples : float, int
        Of the bootstrap confidence interval (:data:`CI_METHOD`).
    rng : numpy.random.Generator or int, optional
        Seed of the bootstrap resampling (explicit for reproducible intervals).

    Returns
    -------
    DataFrame
        :data:`PAIRED_COLUMNS`, one row per (label, integrator, baseline, candidate, ρ):
        ``n`` paired members, ``n_ratio`` of them with a defined ratio (:func:`paired_ratio`:
        at least one design settles), the median and 10/90 % quantiles of t_cand / t_base
        (``inf`` where only the baseline settles), its bootstrap CI (NaN, with ``reason``,
        when fewer than 2 ratios), the fraction of members where the candidate settles
        strictly first, the fractions that never settle per design, and the Wilcoxon
        signed-rank p-value on the log-times of the members settling under both.
    """
    rng = np.random.default_rng(rng)
    rows = []
    for (label, integ), g in _groups(members):
        for base, cand in pairs:
            b, c = g[g["design"] == base], g[g["design"] == cand]
            if b.empty or c.empty:
                continue
            both = b.merge(c, on="member", how="inner", suffixes=("_b", "_c"), sort=True)
            for rho in rhos:
                col = SETTLE[rho]
                tb, tc = (both[f"{col}_{s}"].to_numpy(float) for s in "bc")
                rows.append({"label": label, "integrator": integ, "baseline": base,
                             "candidate": cand, "rho": rho,
                             **_pair_stats(tb, tc, confidence, n_resamples, rng)})
    return pd.DataFrame(rows, columns=PAIRED_COLUMNS)


def proportion_ci(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Clopper–Pearson (exact binomial) interval of a fraction k / n (NaNs when n = 0)."""
    from scipy import stats

    if n == 0:
        return float("nan"), float("nan")
    ci = stats.binomtest(int(k), int(n)).proportion_ci(confidence, method="exact")
    return float(ci.low), float(ci.high)


RISE_COLUMNS = ["label", "integrator", "design", "n", "rising", "frac_rising", "frac_ci_low",
                "frac_ci_high", "rise_median", "rise_q90", "rise_max", "threshold"]


def rise_distribution(members: pd.DataFrame, threshold: float = RISE_ROUNDOFF) -> pd.DataFrame:
    """How often, and by how much, V rises during the coupling window, per ensemble and design.

    Theorem 1 of the paper (V non-increasing) is proved for the K-metric jump; this measures
    it per member from ``max_rise_rel`` (largest one-step increase of V relative to the V
    before it, over the window, as the kernel's summary records it).

    Returns
    -------
    DataFrame
        :data:`RISE_COLUMNS`, one row per (label, integrator, design): ``n`` members,
        ``rising`` = how many have ``max_rise_rel > threshold`` (:data:`RISE_ROUNDOFF`), their
        fraction with its Clopper–Pearson 95 % interval, and the median, 90 % quantile and
        maximum of ``max_rise_rel`` over all members.
    """
    rows = []
    for (label, integ), g in _groups(members):
        for design, d in g.groupby("design", sort=False):
            x = d["max_rise_rel"].to_numpy(float)
            k = int(np.sum(x > threshold))
            lo, hi = proportion_ci(k, x.size)
            rows.append({"label": label, "integrator": integ, "design": design, "n": int(x.size),
                         "rising": k, "frac_rising": k / x.size if x.size else float("nan"),
                         "frac_ci_low": lo, "frac_ci_high": hi,
                         "rise_median": float(np.median(x)) if x.size else float("nan"),
                         "rise_q90": _quantile(x, 0.9),
                         "rise_max": float(x.max()) if x.size else float("nan"),
                         "threshold": threshold})
    return pd.DataFrame(rows, columns=RISE_COLUMNS)


CLAIM_COLUMNS = ["claim_id", "text", "value", "ci_low", "ci_high", "n", "anchor", "kind"]
MAX_CLAIMS = 8
CLAIM_ANCHORS = {"speed": "ensemble-matrix", "failure": "ensemble-matrix", "k_metric": "k-metric",
                 "artifact": "artifacts"}
"""Default HTML ids of the evidence of each kind of claim (the report's sections)."""


def _design_label(design: str) -> str:
    from observer.observers import OBSERVER_DESIGNS

    d = OBSERVER_DESIGNS.get(design)
    return d.label if d is not None else design


def _speed_claims(paired: pd.DataFrame, pair, rho: float, limit: int) -> list[dict]:
    """"The candidate settles k× sooner" per ensemble (value = t_base / t_cand, the inverse of
    the median ratio, its CI inverted likewise: ``inf`` when the median member settles only
    with the candidate, and then the text gives both designs' settled fractions)."""
    sel = paired[(paired["baseline"] == pair[0]) & (paired["candidate"] == pair[1])
                 & np.isclose(paired["rho"], rho) & np.isfinite(paired["ci_low"])]
    out = []
    for _, r in sel.head(limit).iterrows():
        with np.errstate(divide="ignore"):
            v, lo, hi = (float(np.float64(1.0) / r[c]) for c in ("ratio_median", "ci_high", "ci_low"))
        where = f"{r['label']}" + (f", {r['integrator']}" if r["integrator"] else "")
        n = int(r["n"])
        base, cand = _design_label(pair[0]), _design_label(pair[1])
        if np.isfinite(v) and v > 0:
            how = (f"{v:.3g}× sooner than {base} (median over {n} initial errors, 95 % CI "
                   f"{lo:.3g}–{hi:.3g}" if v >= 1 else
                   f"{1 / v:.3g}× later than {base} (median over {n} initial errors, 95 % CI "
                   f"{1 / hi:.3g}–{1 / lo:.3g}")
            text = (f"{cand} brings V to {rho:g}·V(t_on) {how}; sooner in "
                    f"{100 * r['frac_candidate_first']:.0f} % of them) on {where}.")
        else:                       # no finite ratio: the settled fractions, with their own CIs
            k_c = int(round(n * (1 - r["never_candidate"])))
            k_b = int(round(n * (1 - r["never_baseline"])))
            (lo, hi), (lo_b, hi_b) = proportion_ci(k_c, n), proportion_ci(k_b, n)
            v = k_c / n
            text = (f"{cand} settles below {rho:g}·V(t_on) in {100 * v:.0f} % of {n} initial errors "
                    f"(95 % CI {100 * lo:.0f}–{100 * hi:.0f} %), {base} in {100 * k_b / n:.0f} % "
                    f"(95 % CI {100 * lo_b:.0f}–{100 * hi_b:.0f} %; the candidate sooner in "
                    f"{100 * r['frac_candidate_first']:.0f} %) on {where}.")
            lo, hi = 100 * lo, 100 * hi
            v = 100 * v
        out.append({"claim_id": f"speed:{pair[1]}/{pair[0]}:{where}", "kind": "speed",
                    "value": v, "ci_low": lo, "ci_high": hi, "n": n, "text": text})
    return out


def _failure_claim(paired: pd.DataFrame, rho: float) -> list[dict]:
    """The (ensemble, design) that most often never settles below ρ·V(t_on), if any does."""
    sel = paired[np.isclose(paired["rho"], rho)]
    best = None
    for _, r in sel.iterrows():
        for design, col in ((r["baseline"], "never_baseline"), (r["candidate"], "never_candidate")):
            if r[col] > 0 and (best is None or r[col] > best[0]):
                best = (r[col], design, r)
    if best is None:
        return []
    frac, design, r = best
    n = int(r["n"])
    lo, hi = proportion_ci(round(frac * n), n)
    where = f"{r['label']}" + (f", {r['integrator']}" if r["integrator"] else "")
    return [{"claim_id": f"failure:{design}:{where}", "kind": "failure", "value": frac,
             "ci_low": lo, "ci_high": hi, "n": n,
             "text": (f"{_design_label(design)} never settles below {rho:g}·V(t_on) in "
                      f"{100 * frac:.0f} % of {n} initial errors on {where} "
                      f"(95 % CI {100 * lo:.0f}–{100 * hi:.0f} %).")}]


def _pooled_rises(rises: pd.DataFrame, design: str) -> tuple[int, int, float]:
    d = rises[rises["design"] == design]
    return int(d["rising"].sum()), int(d["n"].sum()), float(d["rise_max"].max()) if len(d) else float("nan")


MATCHED = "projected master"
"""Label mark of the ensembles run with the projected master (docs/theory/scheme.md §6: the jump observers'
matched master, without the discrete floor); the K-metric claims use them when present."""


def _matched(frame: pd.DataFrame) -> tuple[pd.DataFrame, str]:
    """The rows of the matched-master ensembles if there are any (and the words saying so)."""
    sel = frame["label"].astype(str).str.contains(MATCHED, regex=False)
    return (frame[sel], f" with the {MATCHED}") if sel.any() else (frame, "")


def _k_metric_claims(paired: pd.DataFrame, rises: pd.DataFrame, rho: float, k_pairs) -> list[dict]:
    """Per non-K metric: how often V rises (pooled over the matched-master ensembles, against
    the K metric), and its settling time relative to the K metric's (the range of the
    ensembles' medians)."""
    out = []
    rises, how = _matched(rises)
    paired, _ = _matched(paired)
    thr = float(rises["threshold"].iloc[0]) if len(rises) else RISE_ROUNDOFF
    k_rising, k_n, _ = _pooled_rises(rises, registry.k_metric_design())
    for base, cand in k_pairs:
        k, n, biggest = _pooled_rises(rises, cand)
        if n:
            lo, hi = proportion_ci(k, n)
            kf = f"{100 * k_rising / k_n:.0f} % of {k_n}" if k_n else "n/a"
            out.append({"claim_id": f"k_metric:rises:{cand}", "kind": "k_metric", "value": k / n,
                        "ci_low": lo, "ci_high": hi, "n": n,
                        "text": (f"{_design_label(cand)} raises V by more than {thr:g}·V in one step in "
                                 f"{100 * k / n:.0f} % of {n} members (95 % CI {100 * lo:.0f}–{100 * hi:.0f} %; "
                                 f"largest {biggest:.3g}·V) against {kf} for the K metric, over "
                                 f"{rises['label'].nunique()} ensembles{how}.")})
        rows = paired[(paired["baseline"] == base) & (paired["candidate"] == cand)
                      & np.isclose(paired["rho"], rho)]
        sel = rows[np.isfinite(rows["ci_low"]) & np.isfinite(rows["ci_high"])]
        if len(sel):
            med = float(np.median(sel["ratio_median"]))
            w = rows["n"].to_numpy(float)
            nb, nc = (float(np.sum(rows[c] * w) / np.sum(w)) for c in ("never_baseline", "never_candidate"))
            out.append({"claim_id": f"k_metric:speed:{cand}", "kind": "k_metric", "value": med,
                        "ci_low": float(sel["ci_low"].min()), "ci_high": float(sel["ci_high"].max()),
                        "n": int(rows["n"].sum()),
                        "text": (f"{_design_label(cand)} takes {med:.3g}× the K metric's time to settle "
                                 f"below {rho:g}·V(t_on){how} (median of the medians of the {len(sel)} "
                                 f"ensembles where both settle, from {sel['ratio_median'].min():.3g} to "
                                 f"{sel['ratio_median'].max():.3g}; 95 % CIs within "
                                 f"{sel['ci_low'].min():.3g}–{sel['ci_high'].max():.3g}) and never settles "
                                 f"in {100 * nc:.0f} % of {int(rows['n'].sum())} members over "
                                 f"{len(rows)} ensembles (K metric: {100 * nb:.0f} %).")})
    return out


def _artifact_claim(rises: pd.DataFrame) -> list[dict]:
    """With the plain (time-stepped, penetrating) master the K-metric jump's V rises too: the
    discretisation floor of docs/theory/scheme.md §6, stated beside the K-metric claims."""
    sel = ~rises["label"].astype(str).str.contains(MATCHED, regex=False)
    k, n, biggest = _pooled_rises(rises[sel], registry.k_metric_design())
    if not n or not k:
        return []
    lo, hi = proportion_ci(k, n)
    thr = float(rises["threshold"].iloc[0])
    return [{"claim_id": "artifact:plain_master:jump", "kind": "artifact", "value": k / n, "ci_low": lo,
             "ci_high": hi, "n": n,
             "text": (f"With the plain time-stepped master the K-metric jump's V also rises by more than "
                      f"{thr:g}·V in one step in {100 * k / n:.0f} % of {n} members (95 % CI "
                      f"{100 * lo:.0f}–{100 * hi:.0f} %; largest {biggest:.3g}·V): the master penetrates by "
                      f"O(h·|γ|) and the projection to g = 0 re-injects it (docs/theory/scheme.md §6), a discretisation "
                      f"artifact that the projected master removes.")}]


def ensemble_claims(paired: pd.DataFrame, rises: pd.DataFrame, *, rho: float = 1e-6,
                    speed_pair: tuple[str, str] = DEFAULT_PAIRS[0], k_pairs=DEFAULT_PAIRS[1:],
                    max_speed: int = 2, anchors: dict | None = None) -> pd.DataFrame:
    """At most :data:`MAX_CLAIMS` one-sentence claims, each with its number, CI and n.

    Parameters
    ----------
    paired, rises : DataFrame
        :func:`paired_settling` and :func:`rise_distribution` of the same members.
    rho : float
        The threshold the claims speak of (must be one of the rows' ρ).
    speed_pair, k_pairs : (baseline, candidate)
        The pair of the speed claims (one per ensemble, at most ``max_speed``) and the pairs of
        the K-metric question (K metric first: jump vs jump_mass, jump vs jump_identity).
    anchors : dict, optional
        Kind → HTML id of the evidence (default :data:`CLAIM_ANCHORS`).

    Returns
    -------
    DataFrame
        :data:`CLAIM_COLUMNS`, kinds in the order speed, failure, k_metric, artifact. ``value``
        is a speed-up (t_base / t_cand) for "speed", a fraction for "failure", the K-metric
        rises and "artifact", a time ratio t_cand / t_base for the K-metric speed (its CI: the
        span of the ensembles' CIs). The K-metric claims pool the ensembles whose label marks
        the projected master (:data:`MATCHED`) when there are any: the jump observers' matched
        master, so that a rise is the metric's and not the discretisation floor's, which the
        "artifact" claim measures on the plain-master ensembles.
    """
    anchors = {**CLAIM_ANCHORS, **(anchors or {})}
    rows = (_speed_claims(paired, speed_pair, rho, max_speed) + _failure_claim(paired, rho)
            + _k_metric_claims(paired, rises, rho, k_pairs) + _artifact_claim(rises))
    for r in rows:
        r["anchor"] = anchors[r["kind"]]
    return pd.DataFrame(rows[:MAX_CLAIMS], columns=CLAIM_COLUMNS)


MATERIAL_RISE = 1e-3
"""A one-step rise of V above 0.1 % of V: far above round-off and the O(h) slack of the discrete
impulse term (≲ 1e-6·V per step, docs/theory/index.md §1), the threshold of the K-metric finding."""


def k_metric_summary(members: pd.DataFrame, rho: float = 1e-6, threshold: float = MATERIAL_RISE, *,
                     n_resamples: int = 2000, rng=None) -> pd.DataFrame:
    """The K-metric question (issue 22 item 6), pooled per family (built-in / random), master
    (plain / projected: :data:`MATCHED` in the label) and jump design.

    Returns
    -------
    DataFrame
        One row per (family, master, design): ``ensembles``, ``n`` members, ``rising`` and
        ``frac_rising`` (members whose V rises by more than ``threshold``·V in one step) with
        its Clopper–Pearson 95 % interval, ``rise_median`` of ``max_rise_rel``, ``never``
        (fraction not settling below ρ·V(t_on)), and ``ratio_median`` of the paired settling
        time t_design / t_jump over the members where one of the two settles, with its
        percentile-bootstrap 95 % CI (members resampled across the pooled ensembles).
    """
    rng = np.random.default_rng(rng)
    df = members.assign(family=np.where(members["scenario"] == "random_system", "random", "built-in"),
                        master=np.where(members["label"].astype(str).str.contains(MATCHED, regex=False),
                                        "projected", "plain"))
    col, rows = SETTLE[rho], []
    for (family, master), g in df.groupby(["family", "master"], sort=True):
        k_rows = g[g["design"] == registry.k_metric_design()][["label", "member", col]]
        for design, d in g[g["design"].isin(registry.jump_designs())].groupby("design"):
            x = d["max_rise_rel"].to_numpy(float)
            k = int(np.sum(x > threshold))
            lo, hi = proportion_ci(k, x.size)
            both = d[["label", "member", col]].merge(k_rows, on=["label", "member"], suffixes=("", "_k"))
            r = paired_ratio(both[f"{col}_k"].to_numpy(float), both[col].to_numpy(float))
            r = r[~np.isnan(r)]
            ci = _median_ci(r, 0.95, n_resamples, rng) if r.size >= 2 else (np.nan, np.nan)
            rows.append({"family": family, "master": master, "design": design,
                         "ensembles": int(d["label"].nunique()), "n": int(x.size), "rising": k,
                         "frac_rising": k / x.size, "frac_ci_low": lo, "frac_ci_high": hi,
                         "rise_median": float(np.median(x)),
                         "never": float(np.mean(np.isinf(d[col].to_numpy(float)))),
                         "ratio_median": float(np.median(r)) if r.size else np.nan,
                         "ratio_ci_low": ci[0], "ratio_ci_high": ci[1]})
    return pd.DataFrame(rows)
