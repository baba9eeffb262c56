"""Build the self-contained HTML report of one or more suite results.

``build_report(result_files, out_dir)`` reads the tidy rows written by :mod:`bench` (and the
pytest-benchmark JSON of the micro-benchmarks next to them), draws the figures inline
(PNG data URIs), formats every table for reading (no NaN cells) and writes
``out_dir/index.html``: header, contents, key numbers, one section per scenario (the paper's
figures), the observer table with the no-jump/jump ratios of settling times (the time after
which V stays below ρ·V(t_on); first passage as an extra column), work-precision diagrams with
fitted orders, robustness curves (median and 10–90 % band over seeds), the scaling fit, the
Siconos peers, the micro-benchmarks (time per step of both engines, contact solves), the
proof-check table, settings and tolerances, limitations and the exact command that
reproduces it.
"""

from __future__ import annotations

import json
import math
import platform
import re
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import pandas as pd

from bench.suites import RHOS
from reports import figures
from reports.analysis import (ACCEPTANCE_EXPONENT, FIRST, SETTLE, fit_power,  # noqa: F401
                              has_settling, headline, micro_loops, micro_speedups, observer_ratios,
                              peer_summary, robustness_bands, scaling_fits, settling_excursions,
                              wp_orders)
from reports.tables import Table, fmt, fmt_int, fmt_pct, fmt_ratio, fmt_rho, fmt_time

TEMPLATES = Path(__file__).resolve().parent / "templates"
OBS_NAMES = {"jump": "with jumps (new)", "nojump": "without jumps ([4])"}


# ------------------------------------------------------------------------------ structures
@dataclass
class Block:
    """One piece of a section: ``kind`` in {"p", "list", "table", "figure", "details", "pre"}."""

    kind: str
    content: Any
    summary: str = ""


@dataclass
class Section:
    id: str
    title: str
    blocks: list = field(default_factory=list)
    subsections: list = field(default_factory=list)

    def p(self, text: str) -> None:
        self.blocks.append(Block("p", text))

    def items(self, items: list[str]) -> None:
        self.blocks.append(Block("list", items))

    def table(self, t: Table) -> None:
        self.blocks.append(Block("table", t))

    def figure(self, f: figures.Figure | None, missing: str) -> None:
        if f is None:
            self.p(missing)
        else:
            self.blocks.append(Block("figure", f))

    def details(self, summary: str, t: Table) -> None:
        self.blocks.append(Block("details", t, summary))

    def pre(self, text: str) -> None:
        self.blocks.append(Block("pre", text))


def slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "x"


# ------------------------------------------------------------------------------ inputs
def _suite_of(path: Path) -> str:
    return path.stem[:-len("-micro")] if path.stem.endswith("-micro") else path.stem


def discover_micro(result_files: Iterable[Path]) -> list[Path]:
    """``<dir>/<suite>-micro.json`` next to each results file, where it exists."""
    out = []
    for p in result_files:
        cand = p.parent / f"{_suite_of(p)}-micro.json"
        if cand.exists() and cand not in out:
            out.append(cand)
    return out


def load_micro(paths: Iterable[Path]) -> tuple[pd.DataFrame, dict]:
    """pytest-benchmark JSON files → one row per benchmark (times in seconds), and metadata."""
    rows, meta = [], {}
    for p in paths:
        data = json.loads(Path(p).read_text())
        meta = {"datetime": data.get("datetime", ""), "version": data.get("version", ""),
                "cpu": (data.get("machine_info", {}).get("cpu", {}) or {}).get("brand_raw", ""),
                "file": str(p)}
        for b in data.get("benchmarks", []):
            st, ex = b.get("stats", {}), b.get("extra_info", {})
            rows.append({"file": str(p), "group": b.get("group") or "", "name": b.get("name", ""),
                         "kind": ex.get("kind", ""), "solver": ex.get("solver", ""),
                         "m": ex.get("m"), "scenario": ex.get("scenario", ""),
                         "case": ex.get("case", ""), "engine": ex.get("engine", ""),
                         "steps": ex.get("steps"), "n": ex.get("n"), "systems": ex.get("systems"),
                         "compile_time_s": ex.get("compile_time_s"),
                         "mean_s": st.get("mean"), "median_s": st.get("median"),
                         "stddev_s": st.get("stddev"), "min_s": st.get("min"),
                         "rounds": st.get("rounds"), "residual": ex.get("residual"),
                         "iterations": ex.get("iterations")})
    return pd.DataFrame(rows), meta


def load_trajectory(row: pd.Series) -> pd.DataFrame | None:
    rel = row.get("trajectory")
    if not isinstance(rel, str) or not rel:
        return None
    path = Path(row.get("results_dir", ".")) / rel
    return pd.read_parquet(path) if path.exists() else None


# ------------------------------------------------------------------------------ sections
def header_table(df: pd.DataFrame, files: list[Path], micro_meta: dict) -> Table:
    from bench.results import cpu_model, git_commit, package_versions

    def uniq(col: str, default: str = "n/a") -> str:
        if col not in df or df[col].dropna().empty:
            return default
        return ", ".join(str(v) for v in dict.fromkeys(df[col].dropna().astype(str)))

    now = package_versions()
    t = Table("Report header: versions, commit, date and machine", ["item", "value"])
    t.add(["toolkit version (observer)", uniq("v_observer", now.get("observer", "n/a"))])
    t.add(["git commit of the runs", uniq("git_commit", "unknown")])
    t.add(["git commit of this report", git_commit()])
    dates = df["date"].dropna().astype(str) if "date" in df else pd.Series(dtype=str)
    t.add(["runs finished (UTC)", f"{dates.min()} … {dates.max()}" if len(dates) else "n/a"])
    t.add(["report built (UTC)", datetime.now(timezone.utc).isoformat(timespec="seconds")])
    t.add(["CPU", uniq("cpu", cpu_model())])
    t.add(["cores / BLAS threads", f"{uniq('cores')} / {uniq('blas_threads')}"])
    t.add(["platform", uniq("platform", platform.platform())])
    t.add(["Python", uniq("v_python", now["python"])])
    for pkg in ("numpy", "scipy", "pandas", "cvxpy", "osqp", "matplotlib"):
        t.add([pkg, uniq(f"v_{pkg}", now.get(pkg, "n/a"))])
    t.add(["suites", uniq("suite")])
    t.add(["results files", ", ".join(str(p) for p in files)])
    t.add(["micro-benchmark file", micro_meta.get("file", "none")])
    t.add(["rows", str(len(df))])
    return t


def _median_time(g: pd.DataFrame, col: str) -> str:
    """Median over seeds of a time column ("n/a" when the rows do not have it)."""
    return fmt_time(g[col].median()) if col in g else "n/a"


def observer_rows(df: pd.DataFrame) -> pd.DataFrame:
    return df[df["kind"] == "observers"].copy() if "kind" in df else pd.DataFrame()


def _window(r: pd.Series) -> str:
    return f"[{fmt(r.get('t_on'))}, {fmt(r.get('t_off'))}]"


def _cell_time(r: pd.Series, col: str) -> str:
    return fmt_time(r[col]) if col in r else "n/a"


def ratio_text(x: float) -> str:
    """A ratio with 2 decimals, "∞", or "n/a"."""
    x = float(x)
    return "n/a" if math.isnan(x) else "∞" if math.isinf(x) else f"{x:.2f}"


SETTLE_NOTE = ("settles below ρ: time after the start of coupling t_on from which V stays "
               "≤ ρ·V(t_on) up to the end of the coupling window ('not reached' when V ends the "
               "window above it); first passage: time of the first sample with V ≤ ρ·V(t_on)")


def observer_table(obs: pd.DataFrame, title: str | None = None) -> Table:
    """Per observer run: settling times per ρ, first passages, rate, floor, final error, cost."""
    first_col = "first passage " + " / ".join(fmt_rho(rho) for rho in RHOS)
    cols = (["scenario", "observer", "h (s)", "window (s)", "V(t_on)"]
            + [f"settles below {fmt_rho(rho)}" for rho in RHOS]
            + [first_col, "rate (1/s)", "floor / V(t_on)", "V_end / V(t_on)", "final max|q̂ − q|",
               "master closings", "CPU time (s)", "steps/s"])
    t = Table(title or "Observer table: settling time (from t_on) below ρ·V(t_on), first passage, "
                       "rate, floor, final error, cost",
              cols, note=SETTLE_NOTE + "; rate: least-squares exponential rate of V over the "
                         "window; floor: median of V over the last 10 % of the window; CPU time: "
                         "master + this observer.")
    for _, r in obs.iterrows():
        name = OBS_NAMES.get(r["observer"], r["observer"])
        if r.get("status") != "ok":
            reason = str(r.get("note") or "not applicable")
            short = "n/a (K = 0: no position jumps)" if "K" in reason else f"n/a ({reason})"
            t.add([r["name"], name, fmt(r["h"]), "n/a"] + [short] + ["n/a"] * (len(cols) - 5))
            continue
        t.add([r["name"], name, fmt(r["h"]), _window(r), fmt(r["V_on"])]
              + [_cell_time(r, SETTLE[rho]) for rho in RHOS]
              + [" / ".join(_cell_time(r, FIRST[rho]) for rho in RHOS)]
              + [fmt(r["rate"]), fmt(r["floor_rel"]), fmt(r["V_end_rel"]), fmt(r["e_q_end"]),
                 fmt_int(r["master_closings"]), fmt(r["cpu_time_s"]), fmt(r["steps_per_s"])])
    return t


def _verdict(nj: pd.Series | None) -> str:
    """What the no-jump observer does, from its settling times."""
    if nj is None:
        return "no no-jump run"
    if nj.get("status") != "ok":
        return f"n/a ({nj.get('note')})"
    settle = {rho: (float(nj[c]) if c in nj and nj[c] is not None else float("nan"))
              for rho, c in SETTLE.items()}
    if any(math.isnan(v) for v in settle.values()):
        return "unknown (these rows have no settling times; rerun the suite)"
    shallow = max(RHOS)
    if math.isinf(settle[shallow]):
        closed = nj.get("master_closed_fraction", float("nan"))
        stall = f"V stalls at {fmt(nj['floor_rel'])}·V(t_on)"
        if isinstance(closed, float) and closed >= 0.99:
            return (f"does NOT converge at all: persistent contact (master closed in "
                    f"{fmt_pct(closed)} of the steps, χ ≡ 1), it cannot move along W; {stall}")
        return f"does not settle below {fmt_rho(shallow)}·V(t_on) within the window; {stall}"
    deepest = min(rho for rho, v in settle.items() if not math.isinf(v))
    return f"converges (settles below {fmt_rho(deepest)}·V(t_on) within the window)"


def headline_text(h: dict) -> str:
    """The headline sentence of :func:`reports.analysis.headline`."""
    kind = h["kind"]
    if kind == "ratio":
        return (f"settling-time ratio no-jump/jump = {ratio_text(h['ratio'])} at ρ = "
                f"{fmt_rho(h['rho'])} ({fmt(h['settle_nojump'])} s vs {fmt(h['settle_jump'])} s; "
                f"first-passage ratio {ratio_text(h['first_ratio'])})")
    if kind == "jump only":
        return (f"∞: the no-jump observer never settles below ρ = {fmt_rho(h['shallowest'])}; the "
                f"jump observer settles below ρ = {fmt_rho(h['rho'])} after {fmt(h['settle_jump'])} s")
    if kind == "neither":
        return f"neither observer settles below ρ = {fmt_rho(h['shallowest'])} in the window"
    if kind == "unknown":
        return "n/a: these rows have no settling times (rerun the suite)"
    return "n/a: the observer with jumps does not apply here"


def ratio_rows(obs: pd.DataFrame) -> list[dict]:
    """Per scenario: the rows of :func:`reports.analysis.observer_ratios`, the headline (settling
    times) and the no-jump verdict."""
    frame = observer_ratios(obs)
    out = []
    for name, g in obs.groupby("name", sort=False):
        j = g[g["observer"] == "jump"]
        n = g[g["observer"] == "nojump"]
        jr = j.iloc[0] if len(j) else None
        nr = n.iloc[0] if len(n) else None
        per = frame[frame["name"] == name]
        h = headline(per)
        rec = {"name": name, "verdict": _verdict(nr), "per_rho": per, "headline": headline_text(h),
               "headline_data": h,
               "window": float(jr["t_off"] - jr["t_on"]) if jr is not None and jr.get("status") == "ok"
               else float("nan")}
        if h["kind"] == "no jump observer" and jr is not None and "K" in str(jr.get("note", "")):
            rec["headline"] += " (K = 0)"
            if nr is not None and nr.get("status") == "ok" and nr.get("e_q_end", 0) > 1e-6:
                rec["verdict"] += (f"; but V = ½vᵀMv does not see positions here (K = 0): the final "
                                   f"position error is still {fmt(nr['e_q_end'])}")
        out.append(rec)
    return out


def _ratio_cell(r: pd.Series, window: float) -> str:
    tj, tn, ratio = r["settle_jump"], r["settle_nojump"], r["ratio"]
    if not r["jump_ok"]:
        return "n/a (no jump observer)"
    if not r["nojump_ok"]:
        return "no no-jump run"
    if math.isinf(ratio):
        bound = f", ratio > {window / tj:.2f}" if tj > 0 and math.isfinite(window) else ""
        return f"∞ (jump settles at {fmt(tj)} s; no-jump does not{bound})"
    if ratio == 0:
        return "only the no-jump observer settles"
    if math.isnan(ratio):
        return "neither settles" if math.isinf(tj) else "n/a"
    return f"{ratio_text(ratio)} ({fmt(tn)} s / {fmt(tj)} s)"


def ratio_table(ratios: list[dict]) -> Table:
    cols = (["scenario"] + [f"ratio at ρ = {fmt_rho(rho)}" for rho in RHOS]
            + ["first-passage ratio " + " / ".join(fmt_rho(rho) for rho in RHOS),
               "headline", "no-jump verdict"])
    t = Table("Settling-time ratio no-jump / jump per scenario (t_no-jump / t_jump at each ρ)",
              cols, note="Each cell: ratio of the settling times (t no-jump / t jump), the times "
                         "after t_on from which V stays ≤ ρ·V(t_on) until the end of the window; "
                         "'∞' when only the jump observer settles within the coupling window (the "
                         "ratio is then larger than window / t jump, given in brackets). The "
                         "first-passage ratios (first sample with V ≤ ρ·V(t_on)) are given for "
                         "comparison.")
    for rec in ratios:
        per = rec["per_rho"]
        cells = [_ratio_cell(r, rec["window"]) for _, r in per.iterrows()]
        first = " / ".join(ratio_text(x) for x in per["first_ratio"]) if per["jump_ok"].any() else "n/a"
        t.add([rec["name"], *cells, first, rec["headline"], rec["verdict"]])
    return t


def observer_prose(obs: pd.DataFrame, ratios: list[dict]) -> list[Block]:
    """Paragraphs and lists of the observer section; every number comes from the rows."""
    blocks = [Block("p", "All times and ratios in this section are settling times: the time after "
                    "the start of coupling t_on from which V stays at or below ρ·V(t_on) up to "
                    "the end of the coupling window (the sample after V's last excursion above "
                    "the threshold; 'not reached' when V ends the window above it). The headline "
                    "ratio is t_no-jump / t_jump at the deepest ρ both observers settle below. "
                    "First-passage times (the first sample with V ≤ ρ·V(t_on)) are kept as an "
                    "extra column; they are shorter where V dips below a threshold and comes "
                    "back above it.")]
    if not has_settling(obs):
        blocks.append(Block("p", "Some of these rows were written before settling times were "
                                 "recorded: their settling columns read n/a. Running the suite "
                                 "again reruns those cases."))
    blocks.append(Block("list", [f"{rec['name']}: {rec['headline']}." for rec in ratios]))
    exc = settling_excursions(obs)
    if exc.empty:
        blocks.append(Block("p", "In these runs no V returns above a threshold it has reached: "
                                 "first-passage and settling times coincide."))
        return blocks
    blocks.append(Block("p", f"V returns above the threshold after its first passage in "
                             f"{len(exc)} case(s); there the first passage overstates the observer:"))
    items = []
    for _, e in exc.iterrows():
        settle = ("never settles (ends the window above it)" if math.isinf(e["settle"])
                  else f"settles at {fmt(e['settle'])} s")
        items.append(f"{e['name']}, observer {OBS_NAMES.get(e['observer'], e['observer'])}, "
                     f"ρ = {fmt_rho(e['rho'])}: first passage at {fmt(e['first'])} s, {settle}; "
                     f"above the threshold on {fmt_pct(e['above_after'])} of the later samples.")
    blocks.append(Block("list", items))
    return blocks


LIMITATIONS = [
    "What holds in discrete time (θ = ½), for the error between two solutions driven by the same "
    "closed sets: the identity ΔV = damping + impulse (+ projection) holds exactly up to round-off; "
    "the damping term is ≤ 0 (C ⪰ 0) and the projection term ≤ 0 (a K-orthogonal projection) "
    "exactly; the impulse term has no sign in discrete time: besides the impact map's own term "
    "(≤ 0 when the map is monotone, A3) it carries a slack −(1−ε)/(2(1+ε))ΔPᵀΔδ with Δδ = O(h), "
    "which vanishes only as h → 0 (or for ε = 1). V may therefore rise on an impact step by an "
    "O(h) amount; the proof-check table reports where, and the fitted order of that slack.",
    "Timings are CPU seconds of one process (time.process_time) on the machine in the header, "
    "with BLAS pinned to one thread; the machine may have been shared with other jobs. Compare "
    "timings within one report, not across machines. Runs with the pivoting solver use the "
    "compiled engine; the kernel's compile (or cache-load) time is measured once before any "
    "case and is in no row's time. Runs with another contact solver (the cvxpy/OSQP reference) "
    "use the numpy engine, the only one that has it, so their CPU times also contain the "
    "slower loop.",
    "The quick suite uses coarser steps and shorter horizons than the full suite (see Settings), "
    "so its numbers differ from the full suite's; deep thresholds (1e-9) can sit below the "
    "discretization floor of the observer with jumps (the floor scales like h², THEORY §6.6).",
    "Without a closed form the reference is a run at h_min/16 of the same scheme (pivoting "
    "solver, same impact law): it measures convergence of the scheme, not modelling error.",
    "The work-precision error norm is the time average of max_i |q_i − q_ref,i|; the maximum "
    "norm is also stored (err_max) but does not converge where impacts or position jumps move "
    "by one step between step sizes.",
    "bouncing_ball has K = 0: the observer with position jumps does not apply, and V = ½vᵀMv "
    "does not see position errors (the no-jump observer's V reaches 0 at the accumulation time "
    "while its position error stays; see 'final max|q̂ − q|').",
    "Robustness uses one scenario (double_mass) and perturbations of the master's own closing "
    "log on the same grid; a real sensor also has a detection threshold on the gap, which is "
    "not modelled.",
    "Scaling times the master only (no observers), from rest over the first 2 s (quick) or 4 s "
    "(full); contacts start to close after about 1 s, so the per-step time mixes free-flight "
    "and contact steps (see 'mean closed contacts'). The per-step time subtracts a 10-step run's "
    "CPU time (the setup); it is a difference of two measurements and noisier than either. The "
    "memory is the peak traced by tracemalloc (NumPy arrays included), not the resident set size.",
    "The peer comparison needs Debian's python3-siconos; Siconos' time includes its Python "
    "stepping loop (computeOneStep/nextStep from Python), the way its Python API is used; "
    "'run()' is its C++ loop on the unforced system, for timing only.",
    "The micro-benchmarks solve fixed, small LCPs; the speed-up of the fast solver over the "
    "cvxpy/OSQP reference includes cvxpy's per-call overhead, which is most of the reference's time.",
    "A settling time only covers the coupling window: V may leave the threshold after t_off "
    "(the window end is the last sample checked).",
    "The proof checks are numerical evidence on the built-in scenarios with their default "
    "settings, not proofs.",
]


def build_report(result_files: Iterable[str | Path], out_dir: str | Path, *,
                 micro_files: Iterable[str | Path] | None = None, command: str | None = None,
                 title: str | None = None) -> Path:
    """Build ``out_dir/index.html`` from results files and return its path.

    Parameters
    ----------
    result_files : iterable of path
        ``.jsonl`` (or exported ``.csv``) results written by :mod:`bench`.
    out_dir : path
        Output folder (created).
    micro_files : iterable of path, optional
        pytest-benchmark JSON files; default: ``<suite>-micro.json`` next to each results file.
    command : str, optional
        The "how to reproduce" command (default derived from the suite names).
    title : str, optional
    """
    from bench.results import load_results

    files = [Path(p) for p in result_files]
    missing = [str(p) for p in files if not p.exists()]
    if missing:
        raise FileNotFoundError(f"results file(s) not found: {', '.join(missing)}")
    df = load_results(files)
    if df.empty:
        raise ValueError("the results files contain no rows")
    micro_paths = [Path(p) for p in micro_files] if micro_files is not None else discover_micro(files)
    micro, micro_meta = load_micro(micro_paths)
    suites = list(dict.fromkeys(df["suite"].astype(str)))
    suite_label = ", ".join(suites)
    if command is None:
        s = suites[0] if len(suites) == 1 else "SUITE"
        command = f"nox -s report -- {s}"
    title = title or f"Observer toolkit benchmark report: {suite_label}"

    sections: list[Section] = []
    key_numbers: list[str] = []

    # -- scenarios + observers ------------------------------------------------------------
    obs = observer_rows(df)
    ratios = ratio_rows(obs) if not obs.empty else []
    sec_scn = Section("scenarios", "Scenarios: trajectories and Lyapunov function (the paper's figures)")
    sec_scn.p("Each run couples the observers to the master through the master's own closed set χ "
              "(same grid) inside the shaded window. Colours as in the paper: master black, observer "
              "with position jumps blue (dashed), observer without jumps red (dotted).")
    from bench.runners import PLOT_LABELS
    from observer import SCENARIOS
    for name, g in obs.groupby("name", sort=False):
        scen = g["scenario"].iloc[0]
        sub = Section(f"scn-{slug(name)}", str(name))
        desc = getattr(SCENARIOS.get(scen), "DESCRIPTION", "")
        ok = g[g["status"] == "ok"]
        r0 = ok.iloc[0] if len(ok) else g.iloc[0]
        what = {"rocking_chain": " Drawn: φ₁, the rotation of the lowest block, and the gap of "
                                 "its right ground corner (the paper's Fig. 5).",
                "double_mass": " Drawn: q₁ and the gap of the lower mass."}.get(scen, "")
        sub.p(f"{desc[:1].upper() + desc[1:]}.{what} Settings: h = {fmt(r0['h'])} s, T = {fmt(r0['t_end'])} s, coupling window "
              f"{_window(r0) if len(ok) else 'n/a'} s, law {r0['law']}, solver {r0['solver']}"
              + (f", {r0['params']}" if isinstance(r0.get("params"), str) and r0.get("params") else "")
              + ".")
        traj = load_trajectory(r0) if len(ok) else None
        names = [o for o in ok["observer"]]
        dof = int(r0.get("plot_dof", 0) or 0) if len(ok) else 0
        con = int(r0.get("plot_contact", 0) or 0) if len(ok) else 0
        coord, gap = PLOT_LABELS.get(scen, (f"q{dof} (m)", f"gap g{con} (m)"))
        fig = figures.scenario_figure(
            traj, str(name), names, (float(r0.get("t_on", 0.0)), float(r0.get("t_off", r0["t_end"]))),
            coord, gap) if traj is not None else None
        sub.figure(fig, "No trajectory file for this scenario (rerun the suite).")
        sub.table(observer_table(g, f"Synchronization of the observers on {name}"))
        rec = next((r for r in ratios if r["name"] == name), None)
        if rec is not None:
            sub.p(f"Headline (settling times): {rec['headline']}. No-jump observer: "
                  f"{rec['verdict']}.")
        sec_scn.subsections.append(sub)
    if obs.empty:
        sec_scn.p("No observer runs in these results.")
    sections.append(sec_scn)

    sec_obs = Section("observers", "Observer table: jump vs no-jump across scenarios")
    if obs.empty:
        sec_obs.p("No observer runs in these results.")
    else:
        sec_obs.blocks += observer_prose(obs, ratios)
        sec_obs.table(ratio_table(ratios))
        sec_obs.table(observer_table(obs))
        for rec in ratios:
            key_numbers.append(f"{rec['name']}: {rec['headline']}; no-jump {rec['verdict']}.")
    sections.append(sec_obs)

    # -- work-precision ----------------------------------------------------------------------
    wp = df[df["kind"] == "work_precision"].copy()
    sec_wp = Section("work-precision", "Work-precision: error against CPU time, fitted orders")
    if wp.empty:
        sec_wp.p("No work-precision runs in these results.")
    else:
        orders = wp_orders(wp)
        od = dict(zip(orders["method"], orders["order"]))
        sec_wp.p("Every point is one run at one step size h; its error is measured against the "
                 "reference stated in the table (closed form where one exists, otherwise a run at "
                 "h_ref = h_min/16). Error norm: the time average over the run of "
                 "max_i |q_i(t_k) − q_ref,i(t_k)| on the grid of h. Fitted order p: least-squares "
                 "slope of log error against log h; work slope s: error ∝ CPU^(−s).")
        sec_wp.figure(figures.work_precision_figure(wp, od), "No work-precision data.")
        t = Table("Fitted orders of convergence per method (scenario · quantity · law · solver)",
                  ["scenario", "quantity", "law", "solver", "reference", "points", "h range (s)",
                   "order p (mean norm)", "order (max norm)", "work slope s", "smallest error",
                   "CPU at smallest error (s)"])
        for _, r in orders.iterrows():
            t.add([r["scenario"], r["target"], r["law"], r["solver"], r["reference"], str(r["points"]),
                   f"{fmt(r['h_min'])} … {fmt(r['h_max'])}", f"{r['order']:.2f}",
                   f"{r['order_max']:.2f}", f"{r['work_slope']:.2f}", fmt(r["best_err"]),
                   fmt(r["best_cpu"])])
        sec_wp.table(t)
        master = orders[(orders["target"] == "master")]
        closed = master[master["reference"].str.startswith("closed form")]
        if len(master):
            parts = []
            if len(closed):
                parts.append(f"first order against closed forms, p = {closed['order'].min():.2f} … "
                              f"{closed['order'].max():.2f} ({', '.join(dict.fromkeys(closed['scenario']))})")
            other = master[~master.index.isin(closed.index)]
            for (scen, law), g in other.groupby(["scenario", "law"], sort=False):
                parts.append(f"{scen} {law} (h/16 reference) p = {g['order'].iloc[0]:.2f}")
            msg = "Master with impacts: " + "; ".join(parts)
            sec_wp.p(msg + ". Both contact solvers give the same errors (they solve the same "
                           "LCPs exactly); only the CPU time differs.")
            key_numbers.append(msg + ".")
        for target in ("jump", "nojump"):
            ot = orders[(orders["target"] == target) & (orders["solver"] == "pivoting")]
            if len(ot):
                key_numbers.append(f"Observer {OBS_NAMES[target]}: fitted order "
                                   + ", ".join(f"{r['law']} {r['order']:.2f}" for _, r in ot.iterrows())
                                   + f" (against {ot['reference'].iloc[0].split(' (')[0]}).")
        keys = ["scenario", "target", "law"]
        both = orders[orders["solver"] == "pivoting"].merge(
            orders[orders["solver"] == "reference"], on=keys, suffixes=("_piv", "_ref")).set_index(keys)
        if len(both):
            t2 = Table("Contact solvers on the same method: total CPU time over the sweep, smallest error",
                       ["scenario", "quantity", "law", "CPU pivoting (s)", "CPU reference (s)",
                        "ratio", "smallest error pivoting", "smallest error reference"])
            for (scen, target, law), r in both.iterrows():
                t2.add([scen, target, law, fmt(r["cpu_total_piv"]), fmt(r["cpu_total_ref"]),
                        fmt_ratio(r["cpu_total_ref"] / r["cpu_total_piv"]), fmt(r["best_err_piv"]),
                        fmt(r["best_err_ref"])])
            sec_wp.table(t2)
        pts = Table("Every work-precision point (error against the stated reference)",
                    ["method", "h (s)", "error (mean)", "error (max)", "CPU time (s)", "CPU scope",
                     "contact solves", "reference"])
        for _, r in wp.sort_values(["method", "h"]).iterrows():
            pts.add([r["method"], fmt(r["h"]), fmt(r["err_mean"]), fmt(r["err_max"]),
                     fmt(r["cpu_time_s"]), r["cpu_scope"], fmt_int(r["contact_solves"]), r["reference"]])
        sec_wp.details(f"All {len(wp)} points", pts)
    sections.append(sec_wp)

    # -- robustness ----------------------------------------------------------------------------
    from bench.perturb import KINDS as PKINDS, LABELS as PLABELS, UNITS as PUNITS
    rob = df[df["kind"] == "robustness"].copy()
    sec_rob = Section("robustness", "Robustness: observers under imperfect switching signals")
    if rob.empty:
        sec_rob.p("No robustness runs in these results.")
    else:
        sec_rob.blocks += robustness_blocks(rob, key_numbers, PKINDS, PLABELS, PUNITS)
    sections.append(sec_rob)

    # -- scaling -------------------------------------------------------------------------------
    scal = df[df["kind"] == "scaling"].copy()
    sec_sc = Section("scaling", "Scaling: rocking_chain against N")
    if scal.empty:
        sec_sc.p("No scaling runs in these results.")
    else:
        sec_sc.blocks += scaling_blocks(scal, key_numbers)
    sections.append(sec_sc)

    # -- peers ----------------------------------------------------------------------------------
    sections.append(peers_section(df, key_numbers))

    # -- micro ----------------------------------------------------------------------------------
    sec_mi = Section("micro", "Micro-benchmarks: one step, one contact solve")
    if micro.empty:
        sec_mi.p("No micro-benchmark results (pytest-benchmark JSON) next to these results files; "
                 "run `python -m bench run SUITE` (it runs `pytest bench/micro --benchmark-json=...`).")
    else:
        sec_mi.blocks += loop_blocks(micro, key_numbers)
        sp = micro_speedups(micro)
        if len(sp):
            t = Table("Speed-up of the fast contact solvers over the cvxpy/OSQP reference (mean time per solve)",
                      ["m", "reference (µs)", "pivoting (µs)", "speed-up pivoting", "lemke (µs)",
                       "speed-up lemke", "nnls (µs)", "speed-up nnls"])
            for _, r in sp.iterrows():
                t.add([fmt_int(r["m"]), fmt(r["reference"] * 1e6), fmt(r["pivoting"] * 1e6),
                       f"{fmt_ratio(r['speedup_pivoting'])}×", fmt(r["lemke"] * 1e6),
                       f"{fmt_ratio(r['speedup_lemke'])}×", fmt(r["nnls"] * 1e6), f"{fmt_ratio(r['speedup_nnls'])}×"])
            sec_mi.table(t)
            key_numbers.append("Fast contact solver (pivoting) vs cvxpy/OSQP reference: "
                               + ", ".join(f"{fmt_ratio(r['speedup_pivoting'])}× at m = {fmt_int(r['m'])}"
                                           for _, r in sp.iterrows()) + " (mean time per solve).")
        sec_mi.figure(figures.micro_figure(micro), "No contact-solve benchmarks.")
        t = Table("All micro-benchmarks (pytest-benchmark; times per call, a loop call is a whole window)",
                  ["group", "benchmark", "mean (µs)", "median (µs)", "std dev (µs)", "rounds",
                   "LCP residual"])
        micro = micro.assign(_m=micro["m"].fillna(-1).astype(float))
        for _, r in micro.sort_values(["kind", "_m", "mean_s"], ascending=[False, True, True]).iterrows():
            t.add([r["group"], r["name"].replace("test_", ""), fmt(r["mean_s"] * 1e6),
                   fmt(r["median_s"] * 1e6), fmt(r["stddev_s"] * 1e6), fmt_int(r["rounds"]),
                   fmt(r["residual"], na="n/a (time loop)")])
        sec_mi.table(t)
        sec_mi.p(f"Source: {micro_meta.get('file')} (pytest-benchmark {micro_meta.get('version')}, "
                 f"{micro_meta.get('datetime')}).")
    sections.append(sec_mi)

    # -- proof checks ---------------------------------------------------------------------------
    sections.append(checks_section(df, key_numbers))

    # -- settings ---------------------------------------------------------------------------------
    sections.append(settings_section(df, suites))

    sec_lim = Section("limitations", "Limitations")
    sec_lim.items(LIMITATIONS)
    sections.append(sec_lim)

    files_txt = " ".join(str(p) for p in files)
    sec_rep = Section("reproduce", "How to reproduce")
    sec_rep.p("One command (runs the suite if its results are missing or incomplete, then builds this page):")
    sec_rep.pre(command)
    first = suites[0]
    sec_rep.p("The same in two steps, without nox:")
    sec_rep.pre(f"python -m bench run {first}\npython -m reports {files_txt} --out {Path(out_dir)}")
    sec_rep.p("Commands that produced these results: "
              + ", ".join(dict.fromkeys(str(c) for c in df.get("command", pd.Series(dtype=str)).dropna()))
              + ".")
    sections.append(sec_rep)

    sec_sum = Section("key-numbers", "Key numbers")
    sec_sum.items(key_numbers or ["No results."])
    sections.insert(0, sec_sum)

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    page = render(title=title, header=header_table(df, files, micro_meta), sections=sections,
                  command=command)
    path = out_dir / "index.html"
    path.write_text(page, encoding="utf-8")
    return path


def _band_cell(median: float, lo: float, hi: float, seeds: int) -> str:
    """"median [lo – hi]" for several seeds, the value alone for one (deterministic) run."""
    if seeds <= 1 or math.isnan(lo):
        return fmt(median)
    return f"{fmt(median)} [{fmt(lo)} – {fmt(hi)}]"


def robustness_blocks(rob: pd.DataFrame, key_numbers: list[str], kinds, labels, units) -> list[Block]:
    """The robustness section: setting, figure (median and 10–90 % band over seeds), the table
    of :func:`reports.analysis.robustness_bands` and one line per observer."""
    from bench.suites import BAND

    lo_pct, hi_pct = (f"{100 * q:.0f}" for q in BAND)
    bands = robustness_bands(rob)
    r0 = rob.iloc[0]
    rnd = bands[bands["perturbation"].isin(["jitter", "missed", "false"])]
    seeds = int(rnd["seeds"].max()) if len(rnd) else 1
    blocks = [Block("p", f"Scenario {r0['name']} (h = {fmt(r0['h'])} s, T = {fmt(r0['t_end'])} s, "
                         f"coupled over the whole run). The observers read χ from the master's "
                         f"closing log (source = \"log\") after one perturbation: "
                         + "; ".join(f"{k}: {labels[k]}" for k in kinds) + ". "
                         f"Random perturbations (jitter, missed, false) are run with {seeds} seeds per "
                         f"point (numpy.random.default_rng(seed)); each cell gives the median over "
                         f"the seeds and, in brackets, the {lo_pct}–{hi_pct} % band (numpy's linear "
                         f"quantiles). A delay is deterministic: one run per size.")]
    fig = figures.robustness_figure(rob, list(kinds), labels, units, bands)
    blocks.append(Block("p", "No robustness data.") if fig is None else Block("figure", fig))
    t = Table(f"Robustness: floor and rate of V against the perturbation (median [{lo_pct}–{hi_pct} %] "
              f"over seeds)",
              ["perturbation", "size", "seeds", "observer", "floor / V(t_on)", "rate (1/s)",
               "settles below 1e−3 (median; seeds settled)", "settles below 1e−6 (median; seeds settled)",
               "log intervals (true)"])
    for _, b in bands.iterrows():
        kind, n = b["perturbation"], int(b["seeds"])
        settle = [f"{fmt_time(b[f'settle_{rho:g}_median'])}; {int(b[f'settled_{rho:g}'])}/{n}"
                  for rho in (1e-3, 1e-6)]
        t.add(["none (exact χ)" if kind == "none" else kind,
               "0" if kind == "none" else fmt(b["size"], unit=units.get(kind, "")), str(n),
               OBS_NAMES.get(b["observer"], b["observer"]),
               _band_cell(b["floor_median"], b["floor_lo"], b["floor_hi"], n),
               _band_cell(b["rate_median"], b["rate_lo"], b["rate_hi"], n), *settle,
               f"{fmt_int(b['log_intervals'])} ({fmt_int(b['true_intervals'])})"])
    blocks.append(Block("table", t))
    items = []
    for name in ("jump", "nojump"):
        base = bands[(bands["perturbation"] == "none") & (bands["observer"] == name)]
        if base.empty:
            continue
        parts = []
        for kind in kinds[1:]:
            g = bands[(bands["perturbation"] == kind) & (bands["observer"] == name)]
            if g.empty:
                continue
            over = g[g["floor_median"] > 1e-6]
            parts.append(f"{kind}: " + (f"median floor above 1e-6 from {fmt(over['size'].min(), unit=units[kind])}"
                                        if len(over) else "median floor below 1e-6 for every size"))
        b0 = base.iloc[0]
        items.append(f"Observer {OBS_NAMES[name]} (exact χ: floor {fmt(b0['floor_median'])}·V(t_on), "
                     f"rate {fmt(b0['rate_median'])}/s): " + "; ".join(parts) + ".")
    blocks.append(Block("list", items))
    if items:
        key_numbers.append(f"Robustness ({seeds} seeds per random perturbation, medians): "
                           + " ".join(items))
    return blocks


def scaling_blocks(scal: pd.DataFrame, key_numbers: list[str]) -> list[Block]:
    """The scaling section: figure, the per-N table and the fitted exponents of
    :func:`reports.analysis.scaling_fits`; the acceptance exponent (from N = 10) in the text."""
    from bench.suites import SCALING_FIT_FROM

    scal = scal.sort_values("N")
    fits = scaling_fits(scal).set_index("quantity")
    acc = f"CPU time per step (N ≥ {SCALING_FIT_FROM})"
    key = acc if acc in fits.index else "CPU time per step"
    p_acc, c_acc = ((float(fits.loc[key, "exponent"]), float(fits.loc[key, "coefficient"]))
                    if key in fits.index else (float("nan"), float("nan")))
    fit_mem = ((float(fits.loc["peak memory", "exponent"]), float(fits.loc["peak memory", "coefficient"]))
               if "peak memory" in fits.index else None)
    blocks = [Block("p", f"Master only (no observers), h = {fmt(scal['h'].iloc[0])} s, T = "
                         f"{fmt(scal['t_end'].iloc[0])} s from rest, compiled engine "
                         f"({', '.join(dict.fromkeys(scal.get('structure', pd.Series(['n/a'])).fillna('n/a').astype(str)))} "
                         "matrices). CPU time per step = (CPU time of the run − CPU time of a 10-step "
                         "run of the same scenario) / (steps − 10): the per-call setup (matrices, "
                         "factorization, grid) is subtracted, so the fit measures the step. Memory = "
                         "peak traced by tracemalloc during a third, identical run.")]
    fig = figures.scaling_figure(scal, (p_acc, c_acc), fit_mem,
                                 SCALING_FIT_FROM if key == acc else None)
    blocks.append(Block("p", "No scaling data.") if fig is None else Block("figure", fig))
    t = Table("Scaling of the chain: CPU time per step and memory against N",
              ["N", "n = m", "steps", "CPU per step (µs)", "loop wall per step (µs)", "setup CPU (s)",
               "steps/s", "mean closed contacts", "max closed contacts", "peak memory (MB)",
               "trajectory storage (MB)"])
    for _, r in scal.iterrows():
        t.add([fmt_int(r["N"]), fmt_int(r["n"]), fmt_int(r["steps"]), fmt(r["cpu_per_step_s"] * 1e6),
               fmt(r.get("loop_per_step_s", float("nan")) * 1e6), fmt(r.get("setup_cpu_time_s")),
               fmt(r["steps_per_s"]), fmt(r["mean_active"]), fmt_int(r["max_active"]),
               fmt(r.get("peak_mem_mb")), fmt(r.get("trajectory_mb"))])
    blocks.append(Block("table", t))
    t2 = Table("Fitted exponents (log-log least squares): quantity ∝ N^p",
               ["quantity", "N range", "exponent p"])
    for quantity, r in fits.iterrows():
        t2.add([quantity, f"{fmt_int(r['N_min'])} … {fmt_int(r['N_max'])}", f"{r['exponent']:.2f}"])
    blocks.append(Block("table", t2))
    n_lo, n_hi = int(scal["N"].min()), int(scal["N"].max())
    msg = f"Chain scaling: CPU time per step ∝ N^{p_acc:.2f}"
    if key == acc:
        msg += f" from N = {SCALING_FIT_FROM} to {n_hi}"
        others = [f"{q.replace('CPU time per step', '').strip().strip('()') or f'all N from {n_lo}'}: "
                  f"N^{fits.loc[q, 'exponent']:.2f}" for q in fits.index
                  if q.startswith("CPU time per step") and q != acc]
        if others:
            msg += " (" + "; ".join(others) + ")"
    else:
        msg += f" over N = {n_lo} … {n_hi}"
    if n_lo <= SCALING_FIT_FROM and n_hi >= 1000:
        verdict = "met" if p_acc <= ACCEPTANCE_EXPONENT else "NOT met"
        msg += f"; acceptance (≤ {ACCEPTANCE_EXPONENT} from N = 10 to 1000): {verdict}"
    else:
        msg += f"; the acceptance fit (≤ {ACCEPTANCE_EXPONENT} from N = 10 to 1000) needs the full suite"
    key_numbers.append(msg + ".")
    blocks.append(Block("p", msg + ". The step costs O(n) for the banded free velocity and "
                             "O(n|A| + |A|³) for |A| closed contacts; 'mean closed contacts' says how "
                             "many there are."))
    return blocks


def loop_blocks(micro: pd.DataFrame, key_numbers: list[str]) -> list[Block]:
    """Time per step of the loop benchmarks (:func:`reports.analysis.micro_loops`)."""
    ml = micro_loops(micro)
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


def peers_section(df: pd.DataFrame, key_numbers: list[str]) -> Section:
    """Siconos against the toolkit on the same problems (:mod:`bench.peers`): per-step times,
    their ratios and the largest trajectory difference; without Siconos, how to get it."""
    from bench import peers

    sec = Section("peers", "Peers: Siconos on the same problems")
    pe = df[(df["kind"] == "peers") & (df["status"] == "ok")] if "kind" in df else pd.DataFrame()
    notes = [n for n in _unavailable_notes(df) if n.startswith("peers:")]
    if pe.empty:
        if notes:
            sec.p(f"No peer results: Siconos was not available when the suite ran. To get it: "
                  f"{peers.HOW_TO_GET}; then run the suite again (finished cases are skipped).")
            sec.items(notes)
            key_numbers.append("Peers: no Siconos results — Siconos was absent (the Peers section "
                               "says how to get it).")
            return sec
        ok, info = peers.siconos_available()
        where = (f"Siconos is available here ({info})" if ok
                 else f"Siconos is not available here: {info}")
        sec.p("No peer results: these suites have no peer cases. The comparison with Siconos is "
              "the suite `python -m bench run peers` (also part of `nox -s report -- full`). "
              f"{where}.")
        return sec
    summ = peer_summary(pe)
    sec.p(f"Siconos {pe['siconos_version'].iloc[0]} and the toolkit run the same discrete scheme "
          "(Moreau–Jean θ = ½, Newton's law, one Siconos Interaction per contact, LCP by Lemke), so "
          "their trajectories agree to round-off. Siconos runs under Debian's system Python in a "
          "subprocess; its time is the stepping loop alone (a Python loop of computeOneStep/"
          "nextStep that writes fExt every step when the problem is forced). 'Siconos run()' is "
          "Siconos' own C++ loop with the force held at its constant part — no Python per step, "
          "a different trajectory when the problem is forced, timing only. The toolkit runs on "
          "its compiled engine: 'simulate' is the whole observer.simulate() call (setup and "
          "result included), 'loop' its time loop alone. Medians of "
          f"{fmt_int(pe['repeats'].max())} repeats on each side; ratio = Siconos ÷ toolkit "
          "(> 1: the toolkit is faster).")
    t = Table("Siconos vs toolkit: time per step and largest trajectory difference",
              ["problem", "n", "m", "h (s)", "steps", "Siconos (µs/step)", "Siconos run() (µs/step)",
               "toolkit simulate (µs/step)", "toolkit loop (µs/step)", "ratio (simulate)",
               "ratio (loop)", "ratio run() / simulate", "max |Δq|", "max |Δu|", "note"])
    for (_, r), (_, sm) in zip(pe.iterrows(), summ.iterrows()):
        t.add([str(r["problem"]), fmt_int(r["n"]), fmt_int(r["m"]), fmt(r["h"]), fmt_int(r["steps"]),
               fmt(sm["siconos_us"]), fmt(sm["siconos_run_us"]), fmt(sm["toolkit_us"]),
               fmt(sm["toolkit_loop_us"]), f"{fmt_ratio(sm['ratio'])}×", f"{fmt_ratio(sm['ratio_loop'])}×",
               f"{fmt_ratio(sm['ratio_run'])}×", fmt(r["max_abs_diff_q"]), fmt(r["max_abs_diff_u"]),
               str(r.get("note") or "—")])
    sec.table(t)
    if notes:
        sec.p("Some peer cases were skipped in the last run:")
        sec.items(notes)
    worst = float(summ["max_diff"].max())
    key_numbers.append("Peers (Siconos ÷ toolkit time per step, whole simulate call / loop alone): "
                       + ", ".join(f"{r['problem']} {fmt_ratio(r['ratio'])}× / {fmt_ratio(r['ratio_loop'])}×"
                                   for _, r in summ.iterrows())
                       + f"; trajectories differ by at most {fmt(worst)}.")
    return sec


def _unavailable_notes(df: pd.DataFrame) -> list[str]:
    notes = []
    for (suite, folder), _ in df.groupby(["suite", "results_dir"]):
        path = Path(folder) / f"{suite}.unavailable.json"
        if path.exists():
            try:
                notes += [f"{cid}: {msg}" for cid, msg in json.loads(path.read_text()).items()]
            except (OSError, ValueError):
                pass
    return notes


def checks_section(df: pd.DataFrame, key_numbers: list[str]) -> Section:
    sec = Section("proof-checks", "Proof-step checks (proofs_checks)")
    ch = df[df["kind"] == "checks"] if "kind" in df else pd.DataFrame()
    notes = [n for n in _unavailable_notes(df) if n.startswith("checks:")]
    if ch.empty:
        try:
            import proofs_checks  # noqa: F401
            why = ("proofs_checks is importable, but these results have no check rows; run the "
                   "suite again (finished cases are skipped, the checks are added).")
        except Exception as exc:  # pragma: no cover - depends on the environment
            why = f"proofs_checks is not importable here ({type(exc).__name__}: {exc})."
        sec.p("No proof-check results. " + why)
        if notes:
            sec.p("The last suite run skipped the checks:")
            sec.items(notes)
        key_numbers.append("Proof-step checks: no results (see the proof-check section).")
        return sec
    if notes:
        sec.p("Some check cases were skipped in the last run (shown rows are from earlier runs):")
        sec.items(notes)
    status = ch["check_status"].astype(str)
    counts = status.value_counts()
    sec.p(f"{len(ch)} checks on {ch['scenario'].nunique()} scenarios: "
          + ", ".join(f"{counts.get(s, 0)} {s}" for s in ("PASS", "FAIL", "n/a")) + ". "
          "margin ≥ −tolerance means satisfied; the witness is where the margin is worst. "
          "n/a: the check's hypotheses do not hold for that system (reason given).")
    key_numbers.append(f"Proof-step checks: {counts.get('PASS', 0)} PASS, {counts.get('FAIL', 0)} FAIL, "
                       f"{counts.get('n/a', 0)} not applicable, over {ch['scenario'].nunique()} scenarios.")
    t = Table("Proof-check table: status, margin, tolerance and witness per scenario and check",
              ["scenario", "check", "equation", "status", "margin", "tolerance", "witness / reason"])
    for _, r in ch.iterrows():
        st = str(r["check_status"])
        na = st == "n/a"
        reason = str(r.get("reason") or "")
        wit = str(r.get("witness") or "")
        detail = (reason if na else wit or reason) or "—"
        if len(detail) > 220:
            detail = detail[:217] + "…"
        t.add([r["scenario"], r["check"], str(r.get("equation") or "—"), st,
               "n/a" if na else fmt(r["margin"]), "n/a" if na else fmt(r["tolerance"]), detail])
    sec.table(t)
    return sec


def settings_section(df: pd.DataFrame, suites: list[str]) -> Section:
    from bench.runners import ERROR_NORM
    from bench.suites import SUITES
    sec = Section("settings", "Settings and tolerances")
    for s in suites:
        suite = SUITES.get(s)
        if suite is None:
            continue
        t = Table(f"Settings of suite {s}: {suite.description}", ["setting", "value"])
        t.add(["cases", str(len(suite.cases))])
        for k, v in suite.settings.items():
            t.add([k, str(v)])
        sec.table(t)
    t = Table("Tolerances and definitions used by the suites", ["quantity", "definition / value"])
    t.add(["V", "½(û−u)ᵀM(û−u) + ½(q̂−q)ᵀK(q̂−q), observer minus master (paper (16), ½ on both terms)"])
    t.add(["synchronization thresholds ρ", ", ".join(fmt(r) for r in RHOS)])
    t.add(["settling time at ρ", "time after t_on from which V ≤ ρ·V(t_on) holds at every sample up "
           "to the end of the coupling window: t_{k*+1} − t_on with k* the last sample above the "
           "threshold; 'not reached' when the last sample is above (observer.metrics.settling_time)"])
    t.add(["first passage at ρ", "time after t_on of the first sample with V ≤ ρ·V(t_on) "
           "(observer.metrics.sync_time)"])
    t.add(["floor", "median of V over the last 10 % of the coupling window"])
    t.add(["rate", "−slope of the least-squares line through log V over the window, up to V ≤ 1e-9·V(t_on)"])
    t.add(["work-precision error", ERROR_NORM + " (time average, trapezoid on the stored grid: every "
           "step, or every k-th step at spacing h_record for the smallest h of the full sweeps)"])
    t.add(["reference without closed form", "run at h_ref = h_min/16 (pivoting solver, same law, compiled engine), "
           "compared on the common grid"])
    t.add(["robustness band", "median and 10–90 % quantiles (numpy, linear) over the seeds of a point"])
    t.add(["scaling exponent", "least-squares slope of log(CPU time per step) against log N from N = 10 "
           f"(acceptance ≤ {ACCEPTANCE_EXPONENT} up to N = 1000)"])
    t.add(["contact-solve acceptance", "relative LCP residual ‖min(x, Gx+b)‖∞ / max(‖b‖∞, ‖Gx‖∞) ≤ 1e-9, "
           "else the step falls back to the reference solver (counted)"])
    t.add(["micro-benchmark acceptance", "every timed solve must have residual ≤ 1e-9"])
    t.add(["scheme", "Moreau–Jean θ = ½, closed set from g_k + (h/2)γ_k ≤ 0 (plain master, no projection)"])
    sec.table(t)
    return sec


# ------------------------------------------------------------------------------ rendering
def render(*, title: str, header: Table, sections: list[Section], command: str) -> str:
    """Render the jinja2 template ``templates/report.html``."""
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)),
                             autoescape=jinja2.select_autoescape(["html"]), trim_blocks=True,
                             lstrip_blocks=True, undefined=jinja2.StrictUndefined)
    return env.get_template("report.html").render(title=title, header=header, sections=sections,
                                                  command=command)
