"""Discrete artifacts: where V of an observer with position jumps rises in discrete time, why
(the time-stepped master penetrates, so the slave's projection adds ½‖g_m⁻‖²_{L_I⁻¹} to V;
docs/theory/scheme.md §6, the ``projection_unprojected_gap`` part of the proof checks' decomposition of
ΔV, eq. (17)), how large the effect is, and the remedy side by side: the same run with a
projected master and event-driven.

Sources: the observer runs (kind "observers": one row per design and master variant, with
their downsampled trajectory) and the ensemble rise distribution per integrator
(:func:`reports.analysis.rise_distribution`). The claims of the first screen that touch a
rising design carry :func:`caveats`.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd

from reports import figures, registry
from reports.blocks import Section
from reports.context import ReportContext, load_trajectory
from reports.tables import Table, fmt, fmt_int, fmt_pct, fmt_rho, fmt_time, text

TITLE = "Discrete artifacts: where V rises in discrete time, why, and the remedy"
ID = "discrete-artifacts"
VARIANTS = ("time-stepping", "projected master", "event-driven")
"""Master variants, in the order shown."""
RISE_FACTOR = 2.0
"""A recorded sample with V more than this times the previous one counts as a jump up of V."""
K_METRIC = "K"
"""Metric of the paper's design (V non-increasing in continuous time)."""
GAP_KEY = "projection_unprojected_gap"
"""Name of the master-penetration term in the proof checks' witnesses."""
CAUSE = ("the time-stepped master penetrates its constraints (g_m < 0 by O(h|γ|) after a "
         "closing step), and the observer's projection onto the master's closed set then adds "
         "½‖g_m⁻‖²_{L_I⁻¹} to V (eq. (17): the jump part is ≤ 0 only when master and observer "
         "are both on the constraint)")


def variant(r: pd.Series) -> str:
    """The master variant of an observer row: event-driven, projected master or time-stepping."""
    if text(r.get("integrator")).startswith("event"):
        return "event-driven"
    params = text(r.get("params")) + " " + text(r.get("name"))
    if re.search(r"master_projection\W*(=|,|:)?\W*(true|1)\b|projected master", params, re.I):
        return "projected master"
    return "time-stepping"


PROJECTED_MARK = "projected master"
"""How a suite names a run or ensemble with the projected master (in its name or label)."""


def label_variant(label: str, integrator: str) -> tuple[str, str]:
    """(base label, master variant) of an ensemble: event-driven by its integrator, projected
    master by its label ("double_mass (projected master)")."""
    base = re.sub(r"\s*\(" + PROJECTED_MARK + r"\)\s*", "", str(label)).strip()
    if str(integrator).startswith("event"):
        return base, "event-driven"
    return base, PROJECTED_MARK if PROJECTED_MARK in str(label) else "time-stepping"


def base_name(name: str) -> str:
    """The run's name without its master variant suffix (" · event", " · projected master")."""
    return str(name).split(" · ")[0]


def jump_designs(names) -> list[str]:
    """The registered designs with position jumps among ``names`` (registry order)."""
    return [d for d in registry.in_registry_order(names)
            if d in registry.designs() and registry.design(d).position_jumps]


def rises(v: np.ndarray, factor: float = RISE_FACTOR) -> tuple[int, float]:
    """(number of recorded samples with V > factor·previous, largest ratio V_k+1 / V_k)."""
    v = np.asarray(v, dtype=float)
    prev, nxt = v[:-1], v[1:]
    ok = (prev > 0) & np.isfinite(prev) & np.isfinite(nxt)
    ratio = nxt[ok] / prev[ok]
    if ratio.size == 0:
        return 0, math.nan
    return int(np.sum(ratio > factor)), float(ratio.max())


def _traj_v(r: pd.Series, design: str):
    traj = load_trajectory(r)
    col = f"V_{design}"
    if traj is None or col not in traj:
        return None
    return traj["t"].to_numpy(dtype=float), traj[col].to_numpy(dtype=float)


def artifact_runs(obs: pd.DataFrame, deepest: float) -> pd.DataFrame:
    """Per (run, design, master variant) of the scenarios run under more than one variant: final
    and smallest V / V(t_on), recorded jumps up of V, settling time at ``deepest``."""
    obs = obs[obs["status"] == "ok"].assign(
        base=obs["name"].map(base_name), variant=obs.apply(variant, axis=1))
    settle = registry.settle_column(deepest)
    out = []
    for base, g in obs.groupby("base", sort=False):
        if g["variant"].nunique() < 2:
            continue
        for _, r in g.iterrows():
            tv = _traj_v(r, r["observer"])
            n_up, worst = rises(tv[1]) if tv is not None else (math.nan, math.nan)
            out.append({"base": base, "design": r["observer"], "variant": r["variant"],
                        "h": r["h"], "t_end": r["t_end"], "V_end_rel": r.get("V_end_rel"),
                        "V_min_rel": r.get("V_min") / r.get("V_on") if r.get("V_on") else math.nan,
                        "jumps_up": n_up, "largest_rise": worst, "settle": r.get(settle, math.nan)})
    return pd.DataFrame(out, columns=["base", "design", "variant", "h", "t_end", "V_end_rel",
                                      "V_min_rel", "jumps_up", "largest_rise", "settle"])


def measured_gap(ch: pd.DataFrame, scenario: str) -> float:
    """The largest master-penetration term / V the proof checks measured on ``scenario``
    (``max_projection_unprojected_gap/V`` in a witness), NaN when no check reports it."""
    if ch.empty or "witness" not in ch:
        return math.nan
    vals = []
    for w in ch.loc[ch["scenario"].astype(str) == scenario, "witness"].map(text):
        for m in re.finditer(re.escape(GAP_KEY) + r"/V\W{0,4}([-+]?[0-9.]+(?:e[-+]?\d+)?)", w):
            vals.append(float(m.group(1)))
    return max(vals) if vals else math.nan


def side_by_side_table(runs: pd.DataFrame, deepest: float) -> Table:
    """One row per (run, design): each variant's final V / V(t_on), recorded jumps up and
    settling time side by side."""
    present = [v for v in VARIANTS if (runs["variant"] == v).any()]
    t = Table("V of each design under the time-stepped master, the projected master and "
              "event-driven (same system, same initial error)",
              ["run", "design"] + [f"{v}: V_end / V(t_on) · jumps up · settles below {fmt_rho(deepest)}"
                                   for v in present],
              note=f"jumps up: recorded samples where V exceeds {fmt(RISE_FACTOR)}× the previous "
                   "one (largest factor in brackets); the trajectories are downsampled, so this is "
                   "a lower bound of the steps where V rises.")
    for (base, design), g in runs.groupby(["base", "design"], sort=False):
        cells = []
        for v in present:
            r = g[g["variant"] == v]
            if r.empty:
                cells.append("n/a (not run)")
                continue
            r = r.iloc[0]
            up = "n/a (no trajectory)" if pd.isna(r["jumps_up"]) else (
                f"{fmt_int(r['jumps_up'])} (×{fmt(r['largest_rise'])})")
            cells.append(f"{fmt(r['V_end_rel'])} · {up} · {fmt_time(r['settle'])}")
        t.add([base, registry.label(design), *cells])
    return t


def _variant_rises(r: pd.DataFrame) -> pd.DataFrame:
    """The rise distribution with each row's master variant (:func:`label_variant`)."""
    v = [label_variant(lab, integ) for lab, integ in zip(r["label"], r["integrator"])]
    return r.assign(base=[b for b, _ in v], variant=[x for _, x in v])


def _share_text(g: pd.DataFrame) -> str:
    return f"{fmt_pct(g['frac_rising'].max())}, largest {fmt(g['rise_max'].max())}·V"


def caveats(view) -> dict[str, str]:
    """Per design with position jumps whose V rises in the time-stepped ensembles: one sentence
    with the share of members, the largest rise and the same with the remedies (projected
    master, event-driven) where the suite ran them. For the K metric (V non-increasing in
    continuous time, Theorem 1) the rise is a discretisation artifact and the sentence names its
    cause; for another metric the remedies' share is the metric's own effect."""
    r = view.rises
    if r is None or r.empty or "frac_rising" not in r:
        return {}
    r = _variant_rises(r)
    out = {}
    for design in dict.fromkeys(r["design"].astype(str)):
        d = registry.design(design) if design in registry.designs() else None
        ts = r[(r["design"] == design) & (r["variant"] == "time-stepping")]
        if d is None or not d.position_jumps or ts.empty or not ts["frac_rising"].max() > 0:
            continue
        head = (f"V of {registry.label(design)} rises in up to {fmt_pct(ts['frac_rising'].max())} of "
                f"the time-stepped members (largest one-step rise {fmt(ts['rise_max'].max())}·V")
        for v in VARIANTS[1:]:
            g = r[(r["design"] == design) & (r["variant"] == v)]
            head += f"; {v}: {_share_text(g)}" if len(g) else ""
        if d.metric == K_METRIC:
            out[design] = (head + "): an artifact, the time-stepped master penetrates and the "
                           "projection adds ½‖g_m⁻‖²_{L_I⁻¹}.")
        else:
            out[design] = head + ")."
    return out


def ensemble_variant_table(view, deepest: float) -> Table | None:
    """Per ensemble run under several master variants and design with position jumps: the share
    of members whose V rises, the largest rise and the median settling time, side by side."""
    from reports.ensemble_view import settling_matrix

    if view.rises is None or view.rises.empty:
        return None
    r = _variant_rises(view.rises)
    mat = settling_matrix(view.members, deepest)
    med = {(lab, integ, des): (m, rho) for lab, integ, des, m, rho in
           zip(mat["label"], mat["integrator"], mat["design"], mat["median"], mat["rho"])}
    bases = [b for b, g in r.groupby("base", sort=False) if g["variant"].nunique() > 1]
    if not bases:
        return None
    t = Table("Ensembles: rises of V and median settling time under each master variant",
              ["scenario", "design"] + [f"{v}: members rising · largest rise · median settling"
                                        for v in VARIANTS],
              note="members rising: share of members whose V rises above round-off in one step; "
                   f"median settling below {fmt_rho(mat['rho'].iloc[0]) if len(mat) else '?'}·V(t_on).")
    for base in bases:
        for design in jump_designs(r.loc[r["base"] == base, "design"]):
            cells = []
            for v in VARIANTS:
                g = r[(r["base"] == base) & (r["design"] == design) & (r["variant"] == v)]
                if g.empty:
                    cells.append("n/a (not run)")
                    continue
                x = g.iloc[0]
                m = med.get((x["label"], x["integrator"], design), (math.nan, 0))[0]
                cells.append(f"{fmt_pct(x['frac_rising'])} · {fmt(x['rise_max'])}·V · {fmt_time(m)}")
            t.add([base, registry.label(design), *cells])
    return t


def rise_table(rises_df: pd.DataFrame) -> Table:
    """The ensemble rise distribution per scenario, integrator and design."""
    t = Table("Rises of V in the ensembles per scenario, integrator and design",
              ["scenario", "integrator", "design", "n", "members where V rises [95 % CI]",
               "median rise", "90 % quantile", "largest rise"],
              note="rise: the largest relative increase of V over one step of a member "
                   "(max_rise_rel); a member 'rises' above the round-off threshold of "
                   "reports.analysis.rise_distribution.")
    for _, r in rises_df.iterrows():
        t.add([text(r.get("label")), text(r.get("integrator")), registry.label(r["design"]),
               fmt_int(r["n"]), f"{fmt_pct(r['frac_rising'])} [{fmt_pct(r['frac_ci_low'])}–"
               f"{fmt_pct(r['frac_ci_high'])}]", fmt(r["rise_median"]),
               fmt(r["rise_q90"]), fmt(r["rise_max"])])
    return t


def _figure_of(obs: pd.DataFrame, runs: pd.DataFrame):
    """V of the first design with position jumps of the first run shown, under each variant."""
    base, design = runs["base"].iloc[0], jump_designs(runs["design"])[0]
    ok = obs[(obs["status"] == "ok") & (obs["observer"] == design)
             & (obs["name"].map(base_name) == base)]
    curves = {variant(r): _traj_v(r, design) for _, r in ok.iterrows()}
    return figures.artifact_figure(curves, f"{base}: V of {registry.label(design)}")


def _prose(runs: pd.DataFrame, ch: pd.DataFrame, obs: pd.DataFrame) -> str:
    parts = []
    for base, g in runs.groupby("base", sort=False):
        scen = str(obs.loc[obs["name"].map(base_name) == base, "scenario"].iloc[0])
        gap = measured_gap(ch, scen)
        ts = g[(g["variant"] == "time-stepping") & g["design"].isin(jump_designs(g["design"]))]
        worst = ts["largest_rise"].max() if len(ts) else math.nan
        if not (worst > RISE_FACTOR or gap > 0):
            continue
        parts.append(f"{base}: under plain time-stepping V jumps up by up to ×{fmt(worst)} in one "
                     "recorded sample" + (f"; the proof checks measure the master-penetration term "
                                          f"at up to {fmt(gap)}·V" if gap == gap else ""))
    return "; ".join(parts)


def _single_runs(sec: Section, ctx: ReportContext, deepest: float) -> bool:
    """The single runs' side-by-side figure and table (False when no system ran under two
    master variants)."""
    obs = ctx.rows("observers") if "kind" in ctx.df else pd.DataFrame()
    runs = artifact_runs(obs, deepest) if len(obs) else pd.DataFrame()
    if runs.empty or not jump_designs(runs["design"]):
        return False
    measured = _prose(runs, ctx.rows("checks"), obs)
    if measured:
        sec.p("Measured: " + measured + ".")
    sec.figure(_figure_of(obs, runs), "No trajectory stored for these runs.")
    sec.table(side_by_side_table(runs, deepest))
    return True


def build(ctx: ReportContext) -> Section:
    """The discrete-artifact section (its id is the target of the claims' caveats)."""
    sec = Section(ID, TITLE)
    sec.p(f"Where a design with position jumps sees V rise in discrete time, the cause is {CAUSE}. "
          "It vanishes as h → 0; a projected master or the event-driven integrator removes it.")
    deepest = min(registry.rhos())
    shown = _single_runs(sec, ctx, deepest)
    view = ctx.ensemble()
    ens = ensemble_variant_table(view, deepest) if len(view.members) else None
    if ens is not None:
        sec.table(ens)
    if not shown and ens is None:
        sec.p("These results hold no run of one system under two master variants "
              "(time-stepping, projected master, event-driven): no side-by-side comparison.")
    notes = caveats(view)
    if notes:
        sec.p("In the ensembles (rises of V per member, the K-metric evidence): "
              + " ".join(notes.values()))
    return sec
