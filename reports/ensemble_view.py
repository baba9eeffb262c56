"""The ensemble results as the report shows them: the member rows, the paired statistics and
claims of :mod:`reports.analysis` (computed once per page), the settling matrix scenario ×
design, and the stored V(t) paths.

Member rows are the bench rows of kind ``"ensemble"`` (one per design × member, the columns of
:func:`observer.ensemble`). When the results hold none, or :mod:`reports.analysis` has no
ensemble statistics, :func:`ensemble_view` says why instead of failing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from reports import analysis, registry

KIND = "ensemble"
"""Row kind of the ensemble members."""
MATRIX_RHO = 1e-6
"""Threshold of the settling matrix (ρ of ``t_settle_1e-06``); falls back to the deepest ρ of
the rows when they lack it."""
BAND_Q = (0.1, 0.9)
"""Quantiles of the bands (10–90 %)."""
BOOTSTRAP_SEED = 0
"""Seed of the bootstrap resamples (the page is reproducible)."""
BOOTSTRAP_RESAMPLES = 1000
"""Bootstrap resamples per confidence interval (the page must build in seconds)."""
ANCHORS = {"speed": "settling-matrix", "failure": "settling-matrix", "k_metric": "k-metric",
           "artifact": "discrete-artifacts"}
"""HTML id of the evidence of each kind of claim (ids of :mod:`reports.sections.ensemble` and
:mod:`reports.sections.artifacts`)."""
GROUP = ["label", "integrator", "design"]
"""A cell of the settling matrix: scenario variant, integrator, design."""


@dataclass
class EnsembleView:
    """What the report shows of the ensembles.

    Attributes
    ----------
    members : DataFrame
        Member rows (empty when there are none).
    paired, rises, claims : DataFrame
        :func:`reports.analysis.paired_settling`, ``rise_distribution`` and ``ensemble_claims``
        (empty when unavailable).
    reason : str
        Why there are no claims ("" when there are).
    """

    members: pd.DataFrame
    paired: pd.DataFrame = field(default_factory=pd.DataFrame)
    rises: pd.DataFrame = field(default_factory=pd.DataFrame)
    claims: pd.DataFrame = field(default_factory=pd.DataFrame)
    reason: str = ""


def member_rows(df: pd.DataFrame) -> pd.DataFrame:
    """The ensemble member rows of the page's rows (a ``label`` column filled from the
    scenario where missing; ``integrator`` "time-stepping" where missing or spelled the old way,
    "timestepping")."""
    if df.empty or "kind" not in df:
        return pd.DataFrame()
    m = df[df["kind"] == KIND].copy()
    if m.empty:
        return m
    if "label" not in m:
        m["label"] = m["scenario"]
    m["label"] = m["label"].where(m["label"].astype(str).str.len() > 0, m["scenario"])
    m["label"] = m["label"].fillna(m["scenario"]).astype(str)
    if "integrator" not in m:
        m["integrator"] = "time-stepping"
    m["integrator"] = m["integrator"].fillna("time-stepping").astype(str).replace("timestepping", "time-stepping")
    return m.dropna(axis=1, how="all").reset_index(drop=True)


def _statistics():
    """The three ensemble functions of :mod:`reports.analysis`, or None if it lacks them."""
    names = ("paired_settling", "rise_distribution", "ensemble_claims")
    funcs = [getattr(analysis, n, None) for n in names]
    return None if any(f is None for f in funcs) else funcs


def ensemble_view(df: pd.DataFrame) -> EnsembleView:
    """Members, paired statistics and claims of the rows ``df`` (one bootstrap per page)."""
    members = member_rows(df)
    if members.empty:
        return EnsembleView(members, reason="no ensemble results in these results (the suite "
                                            "ran no case of kind \"ensemble\")")
    stats = _statistics()
    if stats is None:
        return EnsembleView(members, reason="no ensemble results: reports.analysis has no "
                                            "ensemble statistics in this version")
    paired_settling, rise_distribution, ensemble_claims = stats
    pairs = getattr(analysis, "DEFAULT_PAIRS", registry.ratio_pairs())
    present = set(members["design"].astype(str))
    pairs = tuple(p for p in pairs if set(p) <= present)
    paired = paired_settling(members, pairs, n_resamples=BOOTSTRAP_RESAMPLES,
                             rng=np.random.default_rng(BOOTSTRAP_SEED))
    rises = rise_distribution(members)
    claims = ensemble_claims(paired, rises, anchors=ANCHORS)
    reason = "" if len(claims) else "the ensemble statistics support no claim on these results"
    return EnsembleView(members, paired, rises, claims.reset_index(drop=True), reason)


def settle_column(members: pd.DataFrame, rho: float = MATRIX_RHO) -> tuple[str, float]:
    """The settling column at ``rho`` (or at the deepest ρ the rows have) and its ρ."""
    col = registry.settle_column(rho)
    if col in members:
        return col, rho
    have = [r for r in analysis.RHOS if registry.settle_column(r) in members]
    if not have:
        raise ValueError("members: no t_settle_<ρ> column")
    return registry.settle_column(min(have)), min(have)


def settling_matrix(members: pd.DataFrame, rho: float = MATRIX_RHO) -> pd.DataFrame:
    """Per (label, integrator, design): n members, median and 10–90 % of the settling time at ρ
    over all members (``inf`` = never settles, so a quantile may be ``inf``) and the fraction
    that never settles."""
    col, rho = settle_column(members, rho)
    rows = []
    for key, g in members.groupby(GROUP, sort=False):
        t = g[col].to_numpy(dtype=float)
        t = t[~np.isnan(t)]
        q = np.quantile(t, (0.5, *BAND_Q), method="inverted_cdf") if t.size else [math.nan] * 3
        rows.append({**dict(zip(GROUP, key)), "rho": rho, "n": int(t.size), "median": float(q[0]),
                     "q10": float(q[1]), "q90": float(q[2]),
                     "never": float(np.mean(np.isinf(t))) if t.size else math.nan})
    return pd.DataFrame(rows, columns=[*GROUP, "rho", "n", "median", "q10", "q90", "never"])


def load_paths(members: pd.DataFrame) -> pd.DataFrame:
    """The stored V(t) of the members (columns label, integrator, design, member, t, V): the
    Parquet files a ``paths`` column points to (relative to ``results_dir``), else nothing."""
    if "paths" not in members:
        return pd.DataFrame()
    frames = []
    keys = members.dropna(subset=["paths"]).drop_duplicates(["label", "integrator", "paths"])
    for _, r in keys.iterrows():
        rel = r["paths"]
        path = Path(r.get("results_dir", ".")) / str(rel)
        if isinstance(rel, str) and rel and path.exists():
            p = pd.read_parquet(path)
            frames.append(p.assign(label=r["label"], integrator=r["integrator"]))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def path_band(paths: pd.DataFrame) -> pd.DataFrame:
    """Per (design, t): median and 10–90 % of V/V(t_0) over the members (each member's V
    divided by its first sample, so members of different V(t_on) share one axis)."""
    p = paths.sort_values(["design", "member", "t"])
    v0 = p.groupby(["design", "member"])["V"].transform("first")
    p = p.assign(rel=p["V"] / v0.where(v0 > 0))
    q = p.groupby(["design", "t"])["rel"].quantile([0.5, *BAND_Q]).unstack()
    q.columns = ["median", "q10", "q90"]
    return q.reset_index()
