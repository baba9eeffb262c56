"""The page's answer to the paper's question: the paired decay-rate ratio jump / nojump with
its interval per ensemble (the forest plot) and one claim per scenario the paper names.

Every number is an estimand of :mod:`observer.stats` (:func:`observer.stats.rate_ratio`:
the ratio of mean rates with its cluster bootstrap interval — masters resampled within an
ensemble on several (members within one), systems across the random family — and "faster in k of m" with its
Clopper–Pearson interval); nothing is re-derived here. The per-member rate is the ensemble
rows' ``rate`` (:func:`observer.compare.member_fits`: least squares of ln V from t_on until V
first reaches 10³× the largest floor met so far, :func:`observer.stats.floor_path`, the floor
being the V of a zero-error observer against the same master), so a rate is a property of the
decay, not of a settling threshold that a floor or the window's end could decide; each claim
says over how long a span the rates were fitted and in how many members a floor stopped the fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from observer import stats
from reports import registry

PAIR = tuple(reversed(registry.ratio_pairs()[0]))
"""(a, b) of the ratio, the first declared (baseline, candidate) pair reversed (jump / no jump):
> 1 means a's V decays faster."""
EXACT = "event"
"""The integrator of the exact event-driven master (the floor-free reference)."""
EXCLUDE = ("perturbed χ",)
"""Labels containing these are robustness ensembles, not a scenario's answer."""
RESAMPLES = 999
SEED = 0


@dataclass(frozen=True)
class ScenarioClaim:
    """A scenario the paper names: its name on the page and how its ensembles are found."""

    key: str
    title: str
    scenario: str
    label_prefix: str = ""
    note: str = ""


SCENARIOS: tuple[ScenarioClaim, ...] = (
    ScenarioClaim("double_mass", "Double mass", "double_mass", "double_mass"),
    ScenarioClaim("grazing", "Grazing", "grazing", "grazing"),
    ScenarioClaim("zeno", "Zeno (bouncing ball on a spring, K > 0)", "bouncing_ball",
                  "bouncing_ball (ball on a spring",
                  note="the K = 0 ball is outside the theorem (V does not see the position error)"),
    ScenarioClaim("chain", "Rocking chain", "rocking_chain", "rocking_chain"),
    ScenarioClaim("impact_oscillator", "Impact oscillator", "impact_oscillator", "impact_oscillator"),
    ScenarioClaim("random", "Random systems", "random_system", "random_system"),
)
"""One claim each, in page order (at most 8)."""


def _plain(label: str) -> bool:
    return "projected master" not in label and not any(x in label for x in EXCLUDE)


def _ratio(g: pd.DataFrame, cluster: str) -> dict | None:
    """:func:`observer.stats.rate_ratio` of jump / nojump over the rows ``g`` (clusters: the
    values of column ``cluster``); members whose rate is not finite in either design are
    left out and counted (``dropped``)."""
    g = g[g["design"].isin(PAIR)]
    if "rate" not in g or set(g["design"]) != set(PAIR):
        return None
    w = g.pivot_table(index=[cluster, "member"], columns="design", values="rate", aggfunc="first")
    keep = np.isfinite(w[list(PAIR)].to_numpy(dtype=float)).all(axis=1)
    if not keep.any():
        return None
    long = w[keep][list(PAIR)].stack().rename("rate").reset_index().rename(columns={cluster: "cluster"})
    rr = stats.rate_ratio(long, *PAIR, n_resamples=RESAMPLES, seed=SEED).iloc[0].to_dict()
    same = bool(np.all(w[keep][PAIR[0]].to_numpy() == w[keep][PAIR[1]].to_numpy()))
    grid = 0
    if "rate_points" in g:
        pts = g.pivot_table(index=[cluster, "member"], columns="design", values="rate_points", aggfunc="first")
        grid = int(np.sum((pts[list(PAIR)].to_numpy(dtype=float) < stats.MIN_POINTS).any(axis=1)[keep]))
    rr.update(dropped=int((~keep).sum()), identical=same, grid_decided=grid, t_fit=np.nan, floor_stops=0)
    if "rate_t_fit" in g and g["rate_t_fit"].notna().all():
        tf = g.pivot_table(index=[cluster, "member"], columns="design", values="rate_t_fit", aggfunc="first")
        rr["t_fit"] = float(np.median(tf[list(PAIR)].to_numpy(dtype=float)[keep]))
    if "rate_floor_stop" in g and g["rate_floor_stop"].notna().all():
        fs = g.assign(_s=g["rate_floor_stop"].astype(bool)).pivot_table(
            index=[cluster, "member"], columns="design", values="_s", aggfunc="first")
        rr["floor_stops"] = int(np.sum(fs[list(PAIR)].to_numpy(dtype=bool).any(axis=1)[keep]))
    return rr


def _cluster(g: pd.DataFrame) -> pd.Series:
    """The master of each row (one master when the rows carry none)."""
    return g["master"].fillna(0).astype(int) if "master" in g else pd.Series(0, index=g.index)


def forest_rows(members: pd.DataFrame) -> pd.DataFrame:
    """One row per ensemble (label × integrator) with both designs of :data:`PAIR`: the rate
    ratio of :func:`observer.stats.rate_ratio` (one master: members resampled)."""
    rows = []
    if members.empty or "rate" not in members:
        return pd.DataFrame()
    for (label, integ), g in members.groupby(["label", "integrator"], sort=False):
        if any(x in str(label) for x in EXCLUDE):
            continue
        g = g.assign(_c=_cluster(g))
        rr = _ratio(g, "_c")
        if rr is not None:
            rows.append({"label": str(label), "integrator": str(integ), "scenario": str(g["scenario"].iloc[0]),
                         "masters": int(g["_c"].nunique()), "systems": 1, **rr})
    return pd.DataFrame(rows)


def family_row(members: pd.DataFrame, scenario: str, integrator: str) -> dict | None:
    """The pooled ratio over the plain-master ensembles of ``scenario`` (each label a system:
    the cluster bootstrap resamples systems)."""
    g = members[(members["scenario"] == scenario) & (members["integrator"] == integrator)
                & members["label"].map(_plain)]
    if g["label"].nunique() < 2:
        return None
    rr = _ratio(g, "label")
    if rr is None:
        return None
    masters = int(g.assign(_c=_cluster(g)).groupby("label")["_c"].nunique().min())
    return {"label": f"{scenario} (all {g['label'].nunique()} systems)", "integrator": integrator,
            "scenario": scenario, "masters": masters, "systems": int(g["label"].nunique()), **rr}


def _pick(forest: pd.DataFrame, spec: ScenarioClaim) -> pd.DataFrame:
    """The forest rows of one scenario, plain master, the exact master's first when present."""
    f = forest[(forest["scenario"] == spec.scenario) & forest["label"].str.startswith(spec.label_prefix)
               & forest["label"].map(_plain)]
    if f.empty:
        return f
    order = (f["integrator"] != EXACT).astype(int) * 1000 + f["label"].str.len()
    return f.assign(_o=order).sort_values("_o", kind="stable").drop(columns="_o")


def verdict(r) -> str:
    """"undecided" (a member's rate fitted on fewer than :data:`observer.stats.MIN_POINTS`
    samples above 10³× the floor: the floor, not the observers, decides), else "faster"
    (interval above 1), "slower" (below 1) or "not different" (contains 1)."""
    if r.get("grid_decided", 0):
        return "undecided"
    if r["low"] > 1.0:
        return "faster"
    if r["high"] < 1.0:
        return "slower"
    return "not different"


def evidence(r) -> str:
    """Members × masters (× systems) of a ratio, and what its interval resamples."""
    masters, systems = int(r["masters"]), int(r.get("systems", 1) or 1)
    per = int(r["members"]) // max(masters * systems, 1)
    text = f"{per} members × {masters} master{'s' if masters > 1 else ''}"
    if systems > 1:
        return text + f" × {systems} systems, systems resampled"
    return text + (", masters resampled" if masters > 1 else ", members resampled")


def _interval(r) -> str:
    from reports.tables import fmt

    digits = 3
    while digits < 6 and fmt(r["low"], digits) == fmt(r["high"], digits):    # a narrow interval, not 1–1
        digits += 1
    return f"{fmt(r['estimate'], digits)} (95 % CI {fmt(r['low'], digits)}–{fmt(r['high'], digits)})"


def scenario_claims(members: pd.DataFrame, forest: pd.DataFrame) -> list[dict]:
    """At most one claim per :data:`SCENARIOS` entry with ensembles: text (estimand, interval,
    evidence), ``key``, ``verdict``, ``estimate``, ``low``, ``high``."""
    out = []
    if forest.empty:
        return out
    for spec in SCENARIOS:
        f = _pick(forest, spec)
        if f.empty:
            continue
        if spec.key == "random":
            out.append(_random_claim(members, f, spec))
            continue
        if spec.key == "chain":                    # the largest N the results hold
            n_of = f["label"].str.extract(r"N = (\d+)")[0].astype(float).fillna(0.0)
            f = f[n_of == n_of.max()]
        r = f.iloc[0]
        v = verdict(r)
        master = "exact event-driven master" if r["integrator"] == EXACT else "time-stepped master"
        a, b = (registry.label(d) for d in PAIR)
        text = (f"{spec.title} — {r['label']}: {a}'s V decays {_interval(r)} × the rate of {b}'s "
                f"({v}; paired rate ratio, {evidence(r)}, {master})")
        if r["identical"]:
            text += "; the two designs' V are identical: the master closes no contact in the window"
        text += _fit_span(r)
        if r.get("grid_decided", 0):
            text += (f"; UNDECIDED: in {int(r['grid_decided'])} of {int(r['members'])} members a rate is "
                     f"fitted on fewer than {stats.MIN_POINTS} samples above {stats.SAFETY:g}× the design's "
                     "floor with this master (the floor decides, not the observers)")
        others = f[(f["label"] != r["label"]) & (f["integrator"] == r["integrator"])]
        if spec.key == "grazing" and not others.empty:
            text += "; grid sensitivity: " + ", ".join(f"{o['label'].split('(')[-1].rstrip(')')} → "
                                                     f"{_interval(o)}" for _, o in others.iterrows())
        if spec.note:
            text += f"; {spec.note}"
        out.append({"key": spec.key, "text": text + ".", "verdict": v, "label": r["label"],
                    "estimate": r["estimate"], "low": r["low"], "high": r["high"]})
    return out


def _fit_span(r) -> str:
    """Where the rates were fitted, and how many members' fit a floor stopped (beyond it the
    master cannot tell a member from its floor: that part of the decay is not decided)."""
    from reports.tables import fmt

    if not np.isfinite(r.get("t_fit", np.nan)):
        return ""
    text = f"; rates fitted over a median {fmt(r['t_fit'])} s after t_on"
    stops = int(r.get("floor_stops", 0))
    if stops:
        text += (f", stopped by a discretisation floor in {stops} of {int(r['members'])} members (V within "
                 f"{stats.SAFETY:g}× the largest V of a zero-error observer so far: beyond, not decided)")
    return text


def where_faster(forest: pd.DataFrame) -> str:
    """One sentence: over the ensembles of the forest plot with the plain master (one per
    system, no pooled row, no robustness ensemble; the exact master's where present), where
    the first design of :data:`PAIR` is faster (interval above 1) and by how much (the range of
    the estimates), where the intervals contain 1, and where it is slower, by name."""
    from reports.tables import fmt

    f = forest[forest["label"].map(_plain) & ~forest["label"].str.contains("all ", regex=False)]
    if f.empty:
        return ""
    f = f.assign(_o=(f["integrator"] != EXACT).astype(int)).sort_values("_o", kind="stable")
    f = f.drop_duplicates("label")
    faster, slower = f[f["low"] > 1.0], f[f["high"] < 1.0]
    same = f[(f["low"] <= 1.0) & (f["high"] >= 1.0)]
    a, b = (registry.label(d) for d in PAIR)
    text = f"Where {a} is faster than {b}, over these {len(f)} ensembles: faster (95 % CI above 1) in {len(faster)}"
    if len(faster):
        text += (f", its V decaying {fmt(faster['estimate'].min())}–{fmt(faster['estimate'].max())}× as fast "
                 f"(lowest CI end {fmt(faster['low'].min())})")
    text += f"; not different (CI contains 1) in {len(same)}"
    if len(same):
        text += " (" + ", ".join(same["label"]) + ")"
    text += f"; slower (CI below 1) in {len(slower)}"
    if len(slower):
        text += (" (" + ", ".join(f"{o['label']}: {fmt(o['estimate'])}" for _, o in slower.iterrows()) + ")")
    return text + "."


def _pair_text() -> str:
    return " / ".join(registry.label(d) for d in PAIR)


def _random_claim(members: pd.DataFrame, f: pd.DataFrame, spec: ScenarioClaim) -> dict:
    from reports.tables import fmt

    integ = f["integrator"].iloc[0]
    fam = family_row(members, spec.scenario, integ)
    each = f[(f["integrator"] == integ) & ~f["label"].str.contains("all ", regex=False)]
    slower = each[each["high"] < 1.0]
    faster = each[each["low"] > 1.0]
    if fam is not None:
        text = (f"{spec.title}: pooled rate ratio {_pair_text()} {_interval(fam)} (cluster bootstrap, "
                f"{evidence(fam)}); {registry.label(PAIR[0])}'s rate larger in {fam['k_clusters']} of {fam['clusters']} "
                f"systems ({fmt(100 * fam['k_low'])}–{fmt(100 * fam['k_high'])} %)")
        r = fam
    else:
        r = each.iloc[0].to_dict()
        text = f"{spec.title} — {r['label']}: rate ratio {_pair_text()} {_interval(r)} ({evidence(r)})"
    text += (f"; faster (CI above 1) in {len(faster)}, slower (CI below 1) in {len(slower)} of "
             f"{len(each)} systems")
    not_faster = each[each["low"] <= 1.0]
    if len(not_faster):
        text += (f"; {registry.label(PAIR[0])} is NOT faster on "
                 + ", ".join(f"{o['label'].replace('random_system ', '')} ({_interval(o)}, "
                             f"{'slower' if o['high'] < 1.0 else 'not different'})" for _, o in not_faster.iterrows()))
    return {"key": spec.key, "text": text + ".", "verdict": verdict(r), "label": r["label"],
            "estimate": r["estimate"], "low": r["low"], "high": r["high"]}
