"""Floor-versus-size curves: the power-law fit and the crossover of two designs (issue 33, item 3).

Shared by the benchmark scripts that store the curves (``bench.model_error_parameters``: one
parameter of the observers' model off by a relative ε; ``bench.sensor_floor``: the contact
sensor's jitter and threshold δ) and by the report that reads them. A
curve is, per design, the member floors ``F`` (shape: sizes × members, member i the same
initial error at every size) at ascending sizes > 0 and the member floors at size 0 (the exact
model or ideal sensor: the floor of the grid and the window).

The **fit range** is the sizes whose median floor is at least :data:`ABOVE_EXACT` times the
median at size 0 (the uncertainty's floor, not the grid's) and below :data:`BROKEN` (above it
the observer no longer synchronises); over it ``log10 floor = a + s·log10 size`` is fitted to the
median floor (log10 of the median over members) by least squares, with two 95 % intervals: the regression's (slope ± t·standard
error, k − 2 degrees of freedom) and the members' (percentiles of the slope refitted on
:data:`RESAMPLES` paired resamples of the members). Fewer than 3 sizes in range: no fit, and
the status says so.

The **crossover** of two designs is every pair of consecutive sizes between which the sign of
log10(median floor a / median floor b) changes, with the log-log interpolated size of the
change and the design that has the lower floor above it.

The **crossover with an interval** (:func:`crossover_intervals`) uses the pairing instead: per
size the paired statistic ``r = median over members of log10(F_a/F_b)`` (member i is the same
initial error, master and plant in both designs, so what they share cancels), its zero
interpolated linearly in log10 size between the bracketing sizes, and a percentile interval
from the cluster bootstrap (:func:`cluster_resamples`, the scheme of
:func:`observer.stats.cluster_ci`: whole clusters resampled, the same members at every size and
in both designs; by default each member its own cluster, the
stored curves having one master and one plant). In a resample the crossover is sought in the
point estimate's own window (between its neighbouring crossovers, or the swept range); a
resample in which the sign does not change there puts it beyond an end of the window (±∞). A
crossover whose interval reaches an end is **undecided**, not a number; with no sign change
in the point estimate the answer is **none** ("no crossover in [a, b]") when fewer than
(1 − confidence)/2 of the resamples change sign, else undecided.

**What the model must be known to** (:func:`tolerances`): for a target floor, the largest size
at which the fitted law ``floor = 10^a·size^s`` stays at or below it, ``10^((log10 target −
a)/s)``, with the percentile interval of the same inversion refitted on cluster resamples. A
target at or below the median floor at size 0 (the exact model's floor: the discretisation
and window floor at this h) is **not reachable** at any size; a size outside the fitted sizes
is flagged as extrapolated.
"""

from __future__ import annotations

import numpy as np

ABOVE_EXACT = 10.0
"""A size is in the fit range when its median floor is at least this many times the one at size 0 …"""
BROKEN = 0.1
"""… and below this V/V(t_on)."""
CONFIDENCE = 0.95
"""Confidence level of every interval here."""
RESAMPLES = 2000
"""Paired (cluster) resamples of the members behind each bootstrap interval."""
TARGETS = (1e-9, 1e-6, 1e-4, 1e-2)
"""Target floors of V/V(t_on) for :func:`tolerances`: the report's two thresholds (1e-9, 1e-6)
and two coarser accuracies."""


def fit_range(sizes: np.ndarray, F: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """Boolean mask of the sizes in the fit range (module docstring)."""
    med = np.median(F, axis=1)
    return (med >= ABOVE_EXACT * np.median(exact)) & (med < BROKEN)


def fit_curve(sizes, F, exact, seed: int = 0) -> dict:
    """The fit of the module docstring over the fit range, as a JSON-ready dict."""
    from scipy import stats

    sizes, F, exact = np.asarray(sizes, float), np.asarray(F, float), np.asarray(exact, float)
    keep = fit_range(sizes, F, exact)
    x, F = np.log10(sizes[keep]), F[keep]
    if x.size < 3:
        return {"status": f"not fitted: {x.size} size(s) in the power-law range (need 3)",
                "sizes": sizes[keep].tolist(), "slope": None, "intercept": None, "interval": None}
    reg = stats.linregress(x, np.log10(np.median(F, axis=1)))
    a = (1.0 - CONFIDENCE) / 2
    half = float(stats.t.ppf(1 - a, x.size - 2) * reg.stderr)
    rng = np.random.default_rng(seed)
    n = F.shape[1]
    boot = [np.polyfit(x, np.log10(np.median(F[:, rng.integers(0, n, n)], axis=1)), 1)[0] for _ in range(RESAMPLES)]
    return {"status": "ok", "sizes": sizes[keep].tolist(), "slope": float(reg.slope),
            "intercept": float(reg.intercept),
            "interval": {"regression": [float(reg.slope) - half, float(reg.slope) + half],
                         "members": [float(np.quantile(boot, a)), float(np.quantile(boot, 1 - a))]}}


def crossovers(sizes, median_a, median_b, a: str, b: str) -> list[dict]:
    """Every crossover of design ``a``'s median floor with ``b``'s (module docstring)."""
    sizes = np.asarray(sizes, float)
    d = np.log10(np.asarray(median_a, float)) - np.log10(np.asarray(median_b, float))
    out = []
    for i in range(len(d) - 1):
        if d[i] * d[i + 1] < 0:
            w = d[i] / (d[i] - d[i + 1])
            at = 10.0 ** (np.log10(sizes[i]) + w * np.log10(sizes[i + 1] / sizes[i]))
            out.append({"between": [float(sizes[i]), float(sizes[i + 1])], "at": float(at),
                        "lower_above": a if d[i + 1] < 0 else b})
    return out


def sign_changes(x: np.ndarray, r: np.ndarray) -> list[tuple[int, float, float]]:
    """Every i with ``r[i]·r[i+1] < 0``: ``(i, zero, sign of r above it)``, the zero of the
    straight line through (x[i], r[i]) and (x[i+1], r[i+1])."""
    out = []
    for i in np.flatnonzero(r[:-1] * r[1:] < 0):
        w = r[i] / (r[i] - r[i + 1])
        out.append((int(i), float(x[i] + w * (x[i + 1] - x[i])), float(np.sign(r[i + 1]))))
    return out


def _located(x: np.ndarray, r: np.ndarray, window: tuple[int, int], after: float, near: float) -> float:
    """One resample's crossover in ``window`` (indices, inclusive) towards the sign ``after``:
    the zero of that direction nearest ``near``; −∞ when r has the sign ``after`` throughout
    the window (it crossed below it), +∞ when it has the other sign throughout (above it), NaN
    otherwise (only changes the other way)."""
    lo, hi = window
    xs, rs = x[lo:hi + 1], r[lo:hi + 1]
    zeros = [z for _, z, s in sign_changes(xs, rs) if s == after]
    if zeros:
        return min(zeros, key=lambda z: abs(z - near))
    if np.all(rs * after > 0):
        return -np.inf
    if np.all(rs * after < 0):
        return np.inf
    return np.nan


def _first_change(x: np.ndarray, r: np.ndarray, sign: float) -> float:
    """One resample's first sign change (either way) when the point estimate has the sign
    ``sign`` throughout: its zero; +∞ when r keeps ``sign`` throughout, −∞ when it has the
    other sign throughout, NaN otherwise (a zero sample)."""
    found = sign_changes(x, r)
    if found:
        return found[0][1]
    return np.inf if np.all(r * sign > 0) else (-np.inf if np.all(r * sign < 0) else np.nan)


def cluster_resamples(clusters, resamples: int, seed: int):
    """The member indices of ``resamples`` cluster-bootstrap resamples, and the unit resampled.

    The scheme of :func:`observer.stats.cluster_ci`: with two or more distinct cluster labels
    whole clusters are drawn with replacement (all members of a drawn cluster enter, as often
    as it is drawn); with one, the members. Drawn here once so that every statistic of one
    curve (both ends of an interval, every target) is read off the same resamples."""
    clusters = np.asarray(clusters)
    labels, inverse = np.unique(clusters, return_inverse=True)
    rng = np.random.default_rng(seed)
    if labels.size < 2:
        return [rng.integers(0, clusters.size, clusters.size) for _ in range(resamples)], "members"
    members_of = [np.flatnonzero(inverse == c) for c in range(labels.size)]
    return [np.concatenate([members_of[c] for c in rng.integers(0, labels.size, labels.size)])
            for _ in range(resamples)], "clusters"


def resampled_medians(F: np.ndarray, picks: list) -> np.ndarray:
    """The median over the members of each resample of ``picks`` (:func:`cluster_resamples`),
    per row of ``F`` (rows × members): shape (rows, resamples); one array operation when the
    resamples have one length (members, or clusters of one size)."""
    if len({len(i) for i in picks}) == 1:
        return np.median(F[:, np.stack(picks)], axis=2)
    return np.stack([np.median(F[:, i], axis=1) for i in picks], axis=1)


def percentile_interval(values, confidence: float) -> tuple[float, float]:
    """The percentile interval of resampled ``values`` (±∞ allowed: an end not reached), the
    order statistics either side (no interpolation across an infinite value); a NaN resample
    (nothing placed) counts as −∞ for the lower end and +∞ for the upper."""
    v = np.asarray(values, float)
    a = (1.0 - confidence) / 2
    lo = np.quantile(np.where(np.isnan(v), -np.inf, v), a, method="lower")
    hi = np.quantile(np.where(np.isnan(v), np.inf, v), 1 - a, method="higher")
    return float(lo), float(hi)


def _interval(stat, L: np.ndarray, clusters, confidence, resamples, seed) -> tuple[float, float, str]:
    """:func:`percentile_interval` of ``stat`` (a function of the paired statistic r, one value
    per size) over the :func:`cluster_resamples` of the members of ``L`` (the log10 ratios)."""
    picks, unit = cluster_resamples(clusters, resamples, seed)
    R = resampled_medians(L, picks)
    return (*percentile_interval([stat(R[:, j]) for j in range(R.shape[1])], confidence), unit)


def _end(v: float, lo: float, hi: float) -> float | None:
    """A log10 interval end as a size, or None where it is not inside the window [lo, hi]
    (an end the data do not reach; NaN from a percentile between infinite resamples too)."""
    return float(10.0 ** v) if np.isfinite(v) and lo <= v <= hi else None


def crossover_intervals(sizes, Fa, Fb, a: str, b: str, clusters=None, confidence: float = CONFIDENCE,
                        resamples: int = 999, seed: int = 0) -> dict:
    """The crossovers of designs ``a`` and ``b`` with intervals (module docstring).

    Parameters
    ----------
    sizes : array_like
        Ascending sizes > 0 (k of them).
    Fa, Fb : array_like
        Member floors of the two designs, shape (k, members), paired by member.
    clusters : array_like, optional
        A cluster label per member (its master or plant); default each member its own.

    Returns
    -------
    dict
        ``status``: ``"crossovers"`` (each ``placed`` or ``undecided``), ``"none"`` or
        ``"undecided"``; ``range``, the swept sizes' ends; ``crossovers``: per point-estimate
        sign change ``at`` (the size), ``between`` (the bracketing sizes), ``interval``
        ([low, high], an end None where the data do not reach it), ``window``, ``status`` and
        ``lower_above`` (the design with the lower paired floor above it); without one,
        ``lower_throughout`` and the resamples' ``interval`` of the first sign change.
    """
    x = np.log10(np.asarray(sizes, float))
    Fa, Fb = np.asarray(Fa, float), np.asarray(Fb, float)
    clusters = np.arange(Fa.shape[1]) if clusters is None else np.asarray(clusters)
    L = np.log10(Fa) - np.log10(Fb)
    r = np.median(L, axis=1)
    found = sign_changes(x, r)
    out = {"designs": [a, b], "range": [float(10 ** x[0]), float(10 ** x[-1])], "confidence": confidence,
           "resamples": resamples, "seed": seed,
           "statistic": "median over members of log10(floor a / floor b), zero interpolated in log10 size",
           "crossovers": []}
    for k, (i, z, after) in enumerate(found):
        window = (found[k - 1][0] + 1 if k else 0, found[k + 1][0] if k + 1 < len(found) else x.size - 1)
        lo, hi, unit = _interval(lambda rs: _located(x, rs, window, after, z), L, clusters, confidence,
                                 resamples, seed)
        ends = [_end(lo, x[window[0]], x[window[1]]), _end(hi, x[window[0]], x[window[1]])]
        out["crossovers"].append({"at": float(10 ** z), "between": [float(10 ** x[i]), float(10 ** x[i + 1])],
                                  "interval": ends, "window": [float(10 ** x[window[0]]), float(10 ** x[window[1]])],
                                  "status": "placed" if None not in ends else "undecided",
                                  "lower_above": a if after < 0 else b})
        out["unit"] = unit
    if found:
        out["status"] = "crossovers"
        return out
    sign = float(np.sign(np.median(r)))
    lo, hi, out["unit"] = _interval(lambda rs: _first_change(x, rs, sign), L, clusters, confidence,
                                    resamples, seed)
    out["lower_throughout"] = a if sign < 0 else b
    out["interval"] = [_end(lo, x[0], x[-1]), _end(hi, x[0], x[-1])]
    out["status"] = "none" if lo == np.inf else "undecided"
    return out


def tolerances(sizes, F, exact, targets=TARGETS, fit_sizes=None, clusters=None,
               confidence: float = CONFIDENCE, resamples: int = 999, seed: int = 0) -> list[dict]:
    """Per target floor of ``targets``, the largest size at which one design's fitted floor law
    stays at or below it (module docstring), with its interval; every target read off the same
    resamples.

    Parameters
    ----------
    sizes, F, exact
        As :func:`fit_curve`: ascending sizes, member floors (sizes × members), floors at size 0.
    targets : sequence of float
        Floors of V/V(t_on) aimed at.
    fit_sizes : array_like, optional
        The sizes the law is fitted on (default :func:`fit_range`).
    clusters : array_like, optional
        A cluster label per member; default each member its own.

    Returns
    -------
    list of dict
        Per target: ``status`` ``"ok"`` (the size lies in the fitted sizes), ``"extrapolated"``,
        ``"not reachable"`` (target ≤ the median floor at size 0), ``"whole range"`` (no growing
        law, every median floor at or below the target: the size is at least the largest
        swept, ``at_least``) or ``"not fitted"``; ``size`` and ``interval`` ([low, high], an end
        None where the resamples do not reach it).
    """
    sizes, F, exact = np.asarray(sizes, float), np.asarray(F, float), np.asarray(exact, float)
    keep = fit_range(sizes, F, exact) if fit_sizes is None else np.isin(sizes, np.asarray(fit_sizes, float))
    x, Fk = np.log10(sizes[keep]), F[keep]
    base = float(np.median(exact))
    slope = np.polyfit(x, np.log10(np.median(Fk, axis=1)), 1)[0] if x.size >= 3 else 0.0
    lines = None
    if slope > 0:
        picks, unit = cluster_resamples(np.arange(F.shape[1]) if clusters is None else clusters, resamples, seed)
        Y = np.log10(np.column_stack([np.median(Fk, axis=1), resampled_medians(Fk, picks)]))
        lines = np.polyfit(x, Y, 1)                         # row 0 slopes, row 1 intercepts; column 0 the data
    out = []
    for target in map(float, targets):
        t = {"target": target, "exact_floor": base, "size": None, "interval": None}
        if target <= base:
            t["status"] = "not reachable"
        elif lines is None:
            whole = bool(np.all(np.median(F, axis=1) <= target))
            t.update(status="whole range" if whole else "not fitted", at_least=float(sizes[-1]) if whole else None)
        else:
            with np.errstate(divide="ignore", over="ignore"):
                v = np.where(lines[0] > 0, 10.0 ** ((np.log10(target) - lines[1]) / lines[0]), np.inf)
            lo, hi = percentile_interval(v[1:], confidence)
            inside = 10 ** x[0] * (1 - 1e-12) <= v[0] <= 10 ** x[-1] * (1 + 1e-12)
            t.update(status="ok" if inside else "extrapolated", size=float(v[0]), unit=unit,
                     interval=[lo if np.isfinite(lo) else None, hi if np.isfinite(hi) else None],
                     fit_sizes=[float(10 ** x[0]), float(10 ** x[-1])])
        out.append(t)
    return out


def tolerance(sizes, F, exact, target: float, **kw) -> dict:
    """:func:`tolerances` for one target."""
    return tolerances(sizes, F, exact, (target,), **kw)[0]
