"""Estimands of "is one observer design faster than another?" that a floor, a window or
censoring cannot decide; each a :class:`pandas.DataFrame`.

The inputs are per-member quantities of paired ensembles (:func:`observer.ensemble`): member
i of every design starts from the same initial error against the same master, and members
come in *clusters* (one cluster per master trajectory, or per system). Members of one cluster
share the master's switching signal χ and are not independent; every interval here resamples
clusters (the cluster bootstrap, :func:`cluster_ci`), and member-level resampling is used only
when there is a single cluster (the interval is then conditional on that master).

* :func:`decay_rates` — the exponential rate r of V(t) ≈ V(t_on)·e^{−r(t−t_on)} per member:
  least squares of ln V on the samples from t_on until V first reaches a level above both
  designs' floors met so far (:func:`floor_path`, :func:`fit_levels`), or the window's end. A rate is a property of the
  decay, not of where the window ends (estimand (a) of the acceptance).
* :func:`rate_ratio` — the paired ratio of mean rates ``mean r_a / mean r_b`` with its cluster
  bootstrap interval, and "the rate of a is larger in k of m clusters" with its
  Clopper–Pearson interval.
* :func:`settling_summary` — settling times as right-censored data (censored at the window's
  length when V never settles): the Kaplan–Meier curve (:func:`scipy.stats.ecdf` on
  :class:`scipy.stats.CensoredData`), the median settling time where it exists (else "not
  reached", never 0 or ∞), the restricted mean over the window, the share settled by the
  window's end.
* :func:`settle_order` — the paired sign test on "which design settles first", never counting
  as later (both never: a tie, dropped), so that no member is lost to censoring.
* :func:`floor_flags` — the designs' floors with the chosen master (the largest V in the
  window of a zero-error observer: the matched master), and thresholds at or below a floor
  flagged; :func:`band_flags` flags zero-width settling bands (floor or grid crossings).
* :func:`position_errors` — for K singular (K = 0: V ignores positions in ker K) the position
  error beside V.

All intervals are 95 % by default; the bootstrap is :func:`scipy.stats.bootstrap` (percentile
method) with an explicit seed.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

SAFETY = 1e3
"""The rate fit stops when V first reaches SAFETY × the larger of the two designs' floors
(met so far: :func:`floor_path`)."""

LEVEL_MIN = 1e-12
"""…and at the latest when V first reaches LEVEL_MIN·V(t_on) (the fit needs no more decades)."""

MIN_POINTS = 8
"""Fewer fitted samples than this marks a rate as grid-decided (``grid_decided``)."""

CONFIDENCE = 0.95
N_RESAMPLES = 999

NOT_REACHED = "not reached"
"""What the text output prints for a median (or an interval end) that the data do not reach."""


# ---------------------------------------------------------------------------------------
# intervals
# ---------------------------------------------------------------------------------------
def clopper_pearson(k: int, m: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """The exact (Clopper–Pearson) interval of a binomial proportion k/m
    (:func:`scipy.stats.binomtest`); (0, 1) when m = 0."""
    from scipy.stats import binomtest

    if m == 0:
        return 0.0, 1.0
    ci = binomtest(int(k), int(m)).proportion_ci(confidence_level=confidence, method="exact")
    return float(ci.low), float(ci.high)


def cluster_ci(statistic, clusters: np.ndarray, *, confidence: float = CONFIDENCE,
               n_resamples: int = N_RESAMPLES, seed: int = 0) -> tuple[float, float, str]:
    """Percentile interval of ``statistic(mask_or_index)`` resampling whole clusters.

    ``statistic`` takes an integer array of member indices (with repetitions) and returns a
    float (``inf`` allowed: an end the data do not reach). With two or more distinct
    clusters the resampled units are the clusters (all members of a drawn cluster enter,
    as often as it is drawn); with one, the members (conditional on that cluster).
    Returns ``(low, high, unit)`` with unit ``"clusters"`` or ``"members"``.
    """
    from scipy.stats import bootstrap

    clusters = np.asarray(clusters)
    labels, inverse = np.unique(clusters, return_inverse=True)
    if labels.size >= 2:
        members_of = [np.flatnonzero(inverse == c) for c in range(labels.size)]
        stat = lambda pick: statistic(np.concatenate([members_of[int(c)] for c in pick]))  # noqa: E731
        units, unit = np.arange(labels.size), "clusters"
    else:
        stat, units, unit = (lambda pick: statistic(pick.astype(int))), np.arange(clusters.size), "members"
    with np.errstate(invalid="ignore"):         # an end not reached: inf − inf in the percentile's
        res = bootstrap((units,), stat, vectorized=False, n_resamples=n_resamples, confidence_level=confidence,
                        method="percentile", rng=np.random.default_rng(seed))
    return float(res.confidence_interval.low), float(res.confidence_interval.high), unit


def share_interval(share: float, low: float, high: float, clusters: np.ndarray,
                   confidence: float = CONFIDENCE) -> tuple[float, float]:
    """A cluster bootstrap interval ``(low, high)`` of a proportion ``share``, widened where it
    has no width: when every resampled value is the same (all clusters all-success, or
    all-failure), the percentile interval [1, 1] (or [0, 0]) says nothing of the sampling
    error. It is then the Clopper–Pearson interval of ``share`` with as many trials as there
    are clusters (members of one cluster counted as one observation: the design effect at its
    largest), the "k of m masters" bound."""
    if not (np.isfinite(low) and np.isfinite(high)) or high > low:
        return low, high
    m = int(np.unique(np.asarray(clusters)).size)
    return clopper_pearson(int(round(share * m)), m, confidence)


# ---------------------------------------------------------------------------------------
# floors and levels
# ---------------------------------------------------------------------------------------
def fit_levels(V_on: np.ndarray, floor) -> np.ndarray:
    """The level at which each member's rate fit stops: ``max(SAFETY·floor, LEVEL_MIN·V_on)``.

    ``floor`` is the larger of the paired designs' floors with this master: a number (one
    level per member), or a floor per sample (:func:`floor_path`: one level per member and
    sample, shape ``(members, samples)``)."""
    V_on = np.asarray(V_on, dtype=float)
    floor = np.asarray(floor, dtype=float)
    if floor.ndim == 0:
        return np.maximum(SAFETY * float(floor), LEVEL_MIN * V_on)
    return np.maximum(SAFETY * floor[None, :], LEVEL_MIN * V_on[:, None])


def floor_path(t: np.ndarray, V_zero: np.ndarray, t_on: float, t_off: float) -> np.ndarray:
    """The floor up to each sample: the largest V of the zero-error observers (one row of
    ``V_zero`` per design, the matched master) over the samples from t_on up to that sample,
    and over the designs (0 before t_on).

    A discretization floor is the zero-error observer's V, which starts at 0 and appears where
    the master's discrete contacts first differ from the observer's (at a closing); a member's
    V at time t cannot be told from the floors reached *up to t*, and a floor that appears
    later does not touch the samples before it. This running maximum is at every sample at
    least the floor there, and at most the window's largest floor (:func:`floor_flags`), so
    a fit stopped at :data:`SAFETY` times it (:func:`fit_levels`) uses only samples safely
    above every floor met so far."""
    t = np.asarray(t, dtype=float)
    V = np.atleast_2d(np.asarray(V_zero, dtype=float)).max(axis=0)
    inside = (t >= t_on) & (t <= t_off)
    return np.maximum.accumulate(np.where(inside, V, 0.0))


def floor_flags(members: pd.DataFrame, floors: pd.DataFrame, rho: float) -> pd.DataFrame:
    """Whether the threshold ρ·V(t_on) lies at or below a design's floor, per design.

    Parameters
    ----------
    members : DataFrame
        Columns ``cluster``, ``design``, ``V_on``.
    floors : DataFrame
        Columns ``cluster``, ``design``, ``floor``: the largest V in the coupling window of
        an observer started without error against the same master (the matched master).
        V of a member cannot be told from that floor below it: a settling time at such a
        threshold measures the master's discretization, not the observer.
    rho : float

    Returns
    -------
    DataFrame
        One row per design: ``floor_max`` (over clusters), ``below_floor`` (members with
        ρ·V_on ≤ floor), ``n``, ``floor_decided`` (any member with ρ·V_on ≤ SAFETY·floor),
        ``rho_min`` (the smallest ρ above SAFETY·floor/V_on for every member).
    """
    m = members.merge(floors, on=["cluster", "design"], how="left", validate="many_to_one")
    rows = []
    for d, g in m.groupby("design", sort=False):
        thr = rho * g["V_on"].to_numpy()
        fl = g["floor"].to_numpy()
        rows.append({"design": d, "rho": rho, "floor_max": float(fl.max()), "n": len(g),
                     "below_floor": int(np.sum(thr <= fl)),
                     "floor_decided": bool(np.any(thr <= SAFETY * fl)),
                     "rho_min": float(np.max(SAFETY * fl / g["V_on"].to_numpy()))})
    return pd.DataFrame(rows)


def band_flags(members: pd.DataFrame, column: str, resolution: float,
               quantiles: tuple[float, float] = (0.1, 0.9)) -> pd.DataFrame:
    """Per design: the 10–90 % band of the settled members' ``column`` and whether its width
    is at most ``resolution`` (the sampling step): every member then crosses the threshold
    on the same few samples — a floor or grid crossing, not the observers' behaviour."""
    rows = []
    for d, g in members.groupby("design", sort=False):
        t = g[column].to_numpy(dtype=float)
        t = t[np.isfinite(t)]
        lo, hi = (np.quantile(t, quantiles) if t.size else (np.nan, np.nan))
        rows.append({"design": d, "settled": int(t.size), "band_low": float(lo), "band_high": float(hi),
                     "zero_width": bool(t.size >= 5 and hi - lo <= resolution)})
    return pd.DataFrame(rows)


# ---------------------------------------------------------------------------------------
# decay rates
# ---------------------------------------------------------------------------------------
def decay_rates(t: np.ndarray, V: np.ndarray, t_on: float, t_off: float, levels: np.ndarray) -> pd.DataFrame:
    """Least-squares rate of ln V per row of ``V`` (members on one time grid).

    The fit uses the samples ``t_on ≤ t_k ≤ t_off`` up to (excluding) the first at which
    ``V ≤ levels[i]`` (or V = 0), at least 3; ``levels`` is one level per member, or one per
    member and sample of ``t`` (a floor that grows with time, :func:`floor_path`). Exactly: ``rate = −slope`` of the ordinary
    least-squares line through (t_k, ln V_k), in closed form from the samples' sums.

    Returns
    -------
    DataFrame
        ``rate`` (1/s; positive = decaying), ``points`` (samples fitted), ``t_fit`` (seconds
        from t_on to the last fitted sample), ``reached_level`` (the level stopped the fit;
        False: the window's end did) and ``grid_decided`` (fewer than :data:`MIN_POINTS`).
    """
    t = np.asarray(t, dtype=float)
    V = np.atleast_2d(np.asarray(V, dtype=float))
    idx = np.flatnonzero((t >= t_on) & (t <= t_off))
    tw, Vw = t[idx] - t[idx[0]], V[:, idx]
    levels = np.asarray(levels, dtype=float)
    lw = levels[:, None] if levels.ndim == 1 else levels[:, idx]
    low = (Vw <= lw) | ~(Vw > 0.0)
    reached = low.any(axis=1)
    stop = np.where(reached, np.argmax(low, axis=1), tw.size)
    k = np.maximum(stop, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        L = np.log(np.where(Vw > 0.0, Vw, np.nan))
    take = np.arange(tw.size)[None, :] < k[:, None]
    L = np.where(take, L, 0.0)
    ok = np.all(np.isfinite(L), axis=1)
    L = np.where(np.isfinite(L), L, 0.0)
    T = np.where(take, tw[None, :], 0.0)
    St, Stt, Sl, Stl = T.sum(1), (T * T).sum(1), L.sum(1), (T * L).sum(1)
    slope = (k * Stl - St * Sl) / (k * Stt - St * St)
    rate = np.where(ok, -slope, np.nan)
    return pd.DataFrame({"rate": rate, "points": k, "t_fit": tw[np.minimum(k, tw.size) - 1],
                         "reached_level": reached, "grid_decided": k < MIN_POINTS})


def rate_ratio(rates: pd.DataFrame, a: str, b: str, *, confidence: float = CONFIDENCE,
               n_resamples: int = N_RESAMPLES, seed: int = 0) -> pd.DataFrame:
    """The paired rate ratio ``mean r_a / mean r_b`` with its cluster bootstrap interval.

    Parameters
    ----------
    rates : DataFrame
        Columns ``cluster``, ``member``, ``design``, ``rate`` (pairs: the same (cluster,
        member) in both designs).
    a, b : str
        The designs (ratio > 1: a's V decays faster).

    Returns
    -------
    DataFrame
        One row: ``estimate``, ``low``, ``high`` (NaN with ``status`` "undefined" when b's mean
        rate is not positive, or a rate is not finite), ``unit`` (what was resampled),
        ``members``, ``clusters``, ``k_clusters`` (clusters whose mean rate of a exceeds b's),
        ``k_low``, ``k_high`` (its Clopper–Pearson interval of the share), ``status``.
    """
    w = rates.pivot_table(index=["cluster", "member"], columns="design", values="rate", aggfunc="first")
    ra, rb = w[a].to_numpy(dtype=float), w[b].to_numpy(dtype=float)
    cl = w.index.get_level_values("cluster").to_numpy()
    means = pd.DataFrame({"a": ra, "b": rb, "c": cl}).groupby("c")[["a", "b"]].mean()
    k = int(np.sum(means["a"] > means["b"]))
    k_low, k_high = clopper_pearson(k, len(means), confidence)
    row = {"a": a, "b": b, "members": int(ra.size), "clusters": int(len(means)), "k_clusters": k,
           "k_low": k_low, "k_high": k_high, "estimate": np.nan, "low": np.nan, "high": np.nan, "unit": "",
           "status": "ok"}
    if not (np.all(np.isfinite(ra)) and np.all(np.isfinite(rb))) or not rb.mean() > 0.0:
        row["status"] = "undefined: a rate is not finite or the mean rate of " + b + " is not positive"
        return pd.DataFrame([row])
    stat = lambda i: float(ra[i].sum() / rb[i].sum()) if rb[i].sum() > 0 else np.inf  # noqa: E731
    low, high, unit = cluster_ci(stat, cl, confidence=confidence, n_resamples=n_resamples, seed=seed)
    row.update(estimate=float(ra.sum() / rb.sum()), low=low, high=high, unit=unit)
    return pd.DataFrame([row])


# ---------------------------------------------------------------------------------------
# settling times as censored data
# ---------------------------------------------------------------------------------------
def kaplan_meier(times: np.ndarray, window: float):
    """The Kaplan–Meier estimate (:func:`scipy.stats.ecdf`) of settling times, the members
    that never settle (``times`` = inf) right-censored at ``window``; returns its ``sf``
    (``quantiles``, ``probabilities``: S(t) after each distinct time)."""
    from scipy.stats import CensoredData, ecdf

    times = np.asarray(times, dtype=float)
    settled = times[np.isfinite(times)]
    never = np.full(int(np.sum(~np.isfinite(times))), float(window))
    if settled.size == 0:
        return None
    return ecdf(CensoredData(uncensored=settled, right=never)).sf


def _km_stats(times: np.ndarray, window: float) -> tuple[float, float, float]:
    """(median or inf when S stays above ½, restricted mean over [0, window], share settled
    by the window's end) of the Kaplan–Meier curve of ``times``."""
    sf = kaplan_meier(times, window)
    if sf is None:
        return np.inf, float(window), 0.0
    q, p = sf.quantiles, sf.probabilities
    half = np.flatnonzero(p <= 0.5)
    median = float(q[half[0]]) if half.size else np.inf
    edges = np.concatenate([[0.0], np.minimum(q, window), [window]])
    S = np.concatenate([[1.0], p])
    rmst = float(np.sum(S * np.diff(edges)))
    return median, rmst, float(1.0 - p[-1])


def settling_summary(members: pd.DataFrame, column: str, window: float, *, confidence: float = CONFIDENCE,
                     n_resamples: int = N_RESAMPLES, seed: int = 0) -> pd.DataFrame:
    """Per design: the censored settling summary of ``column`` (seconds from t_on, inf =
    never within the window of length ``window``).

    Returns
    -------
    DataFrame
        One row per design: ``n``, ``settled``, ``share_settled`` with ``share_low``,
        ``share_high`` (cluster bootstrap, :func:`share_interval` where it has no width;
        Clopper–Pearson with one cluster), ``median`` with
        ``median_low``, ``median_high`` (NaN = not reached: the Kaplan–Meier curve, or the
        interval's end, stays above ½ inside the window), ``rmst`` (restricted mean
        ∫₀^window S(t) dt, s) with ``rmst_low``, ``rmst_high``, ``window``, ``unit``.
    """
    rows = []
    for d, g in members.groupby("design", sort=False):
        times = g[column].to_numpy(dtype=float)
        cl = g["cluster"].to_numpy()
        med, rmst, share = _km_stats(times, window)
        ci = {}
        for j, name in enumerate(("median", "rmst", "share")):
            stat = lambda i, j=j: _km_stats(times[i], window)[j]  # noqa: E731
            ci[name] = cluster_ci(stat, cl, confidence=confidence, n_resamples=n_resamples, seed=seed)
        settled = int(np.sum(np.isfinite(times)))
        if ci["share"][2] == "members":
            ci["share"] = (*clopper_pearson(settled, times.size, confidence), "members")
        else:
            ci["share"] = (*share_interval(share, ci["share"][0], ci["share"][1], cl, confidence), "clusters")
        fin = lambda x: float(x) if np.isfinite(x) else np.nan  # noqa: E731
        rows.append({"design": d, "n": int(times.size), "settled": settled, "share_settled": share,
                     "share_low": ci["share"][0], "share_high": ci["share"][1],
                     "median": fin(med), "median_low": fin(ci["median"][0]), "median_high": fin(ci["median"][1]),
                     "rmst": rmst, "rmst_low": ci["rmst"][0], "rmst_high": ci["rmst"][1],
                     "window": float(window), "unit": ci["rmst"][2]})
    return pd.DataFrame(rows)


def settle_order(members: pd.DataFrame, column: str, a: str, b: str, *, confidence: float = CONFIDENCE,
                 n_resamples: int = N_RESAMPLES, seed: int = 0) -> pd.DataFrame:
    """The paired sign test of "a settles first": per pair, a first (t_a < t_b, a never
    settling counts as later), b first, or a tie (equal, or both never), ties dropped.

    Returns
    -------
    DataFrame
        One row: ``pairs``, ``a_first``, ``b_first``, ``ties``, ``share`` (a_first /
        (a_first + b_first)) with ``low``, ``high`` (cluster bootstrap, :func:`share_interval`
        where it has no width; Clopper–Pearson with one cluster), ``p_value`` (two-sided exact binomial test on the members, independent given
        the master: with one cluster only), ``unit``.
    """
    w = members.pivot_table(index=["cluster", "member"], columns="design", values=column, aggfunc="first")
    ta, tb = w[a].to_numpy(dtype=float), w[b].to_numpy(dtype=float)
    cl = w.index.get_level_values("cluster").to_numpy()
    # the order of the times only: never (inf) is later than every settling time
    first_a, first_b = ta < tb, tb < ta
    k, m = int(first_a.sum()), int(first_a.sum() + first_b.sum())
    row = {"a": a, "b": b, "pairs": int(ta.size), "a_first": k, "b_first": m - k, "ties": int(ta.size - m),
           "share": k / m if m else np.nan, "low": np.nan, "high": np.nan, "p_value": np.nan, "unit": ""}
    if m == 0:
        return pd.DataFrame([row])
    if np.unique(cl).size >= 2:
        def stat(i):
            mm = first_a[i].sum() + first_b[i].sum()
            return float(first_a[i].sum() / mm) if mm else 0.5
        low, high, row["unit"] = cluster_ci(stat, cl, confidence=confidence, n_resamples=n_resamples, seed=seed)
        row["low"], row["high"] = share_interval(row["share"], low, high, cl, confidence)
    else:
        from scipy.stats import binomtest

        row["low"], row["high"] = clopper_pearson(k, m, confidence)
        row["p_value"], row["unit"] = float(binomtest(k, m).pvalue), "members"
    return pd.DataFrame([row])


# ---------------------------------------------------------------------------------------
# K singular
# ---------------------------------------------------------------------------------------
def position_errors(e_end: np.ndarray, e_start: np.ndarray, design: str) -> pd.DataFrame:
    """For K singular: the Euclidean position error ‖q̂ − q‖ of each member at the window's
    start and end (V = ½eᵀKe + ½vᵀMv does not see e in ker K, so a V that settles is not
    synchronization); one row per design with ``median_end``, ``max_end``, ``median_start``."""
    ne = np.linalg.norm(np.atleast_2d(e_end), axis=1)
    ns = np.linalg.norm(np.atleast_2d(e_start), axis=1)
    return pd.DataFrame([{"design": design, "members": int(ne.size), "median_start": float(np.median(ns)),
                          "median_end": float(np.median(ne)), "max_end": float(np.max(ne))}])
