"""The power-law fit and the crossover of observer/floor_curves.py on floors of known laws."""

from __future__ import annotations

import numpy as np

import pytest

from observer.floor_curves import (ABOVE_EXACT, BROKEN, crossover_intervals, crossovers, fit_curve, fit_range,
                                percentile_interval, tolerance)

SIZES = np.logspace(-4, -1, 10)


def _floors(exponent: float, scale: float, base: float, members: int = 6, spread: float = 0.03):
    """Member floors max(base, scale·size^exponent) times a member's own factor (±spread in log),
    saturating at 1.5 (a broken observer); and the floors at size 0 (base)."""
    f = 10 ** np.random.default_rng(2).uniform(-spread, spread, members)
    F = np.minimum(1.5, np.maximum(base, scale * SIZES[:, None] ** exponent) * f[None, :])
    return F, base * f


def test_the_fit_range_is_the_sizes_between_the_exact_floor_and_the_broken_observer():
    F, exact = _floors(2.0, 20.0, 5e-8)             # 20·ε²: 2e-7 at 1e-4 … 0.2 at 1e-1
    law = 20.0 * SIZES ** 2
    expected = (law >= ABOVE_EXACT * 5e-8 * 1.1) & (law < BROKEN * 0.9)
    assert fit_range(SIZES, F, exact).tolist() == expected.tolist()
    assert not expected[0] and not expected[-1] and expected[1:-1].all()


def test_the_slope_of_a_square_law_is_two_inside_both_intervals_and_a_near_miss_is_not():
    F, exact = _floors(2.0, 10.0, 1e-12)
    fit = fit_curve(SIZES, F, exact)
    assert fit["status"] == "ok" and abs(fit["slope"] - 2.0) < 0.02 and abs(fit["intercept"] - 1.0) < 0.05, fit
    for lo, hi in fit["interval"].values():
        assert lo <= 2.0 <= hi and hi - lo < 0.1, fit
    steeper = fit_curve(SIZES, *_floors(2.15, 10.0, 1e-12))
    for lo, hi in steeper["interval"].values():
        assert not lo <= 2.0 <= hi, steeper


def test_fewer_than_three_sizes_in_range_is_said_not_fitted():
    fit = fit_curve(SIZES, *_floors(2.0, 10.0, 5e-3))     # only 10·ε² ∈ [5e-2, 0.1): one size
    assert fit["status"].startswith("not fitted") and fit["slope"] is None


def test_a_crossover_is_bracketed_and_interpolated_where_the_floors_swap():
    a, b = 2e-2 * SIZES, 10.0 * SIZES ** 2          # equal at ε = 2e-3: a lower above it
    (c,) = crossovers(SIZES, a, b, "jump", "nojump")
    assert c["between"][0] < 2e-3 < c["between"][1] and abs(np.log10(c["at"] / 2e-3)) < 1e-9
    assert c["lower_above"] == "jump"
    assert crossovers(SIZES, 0.5 * b, b, "jump", "nojump") == []       # parallel: none
    (d,) = crossovers(SIZES, b, a, "jump", "nojump")
    assert d["lower_above"] == "nojump"


# --- crossovers with intervals (paired members) -----------------------------------------------
CROSS = 2e-3
"""Where the two laws below cross: 2e-2·ε = 10·ε² at ε = 2e-3."""
QUICK = {"resamples": 199}
"""Fewer resamples than the default: the tests' cases are decided well inside them."""
X = np.log10(SIZES)


def _paired(noise: float, members: int = 12, seed: int = 5, laws=(lambda e: 2e-2 * e, lambda e: 10.0 * e ** 2)):
    """Member floors of two designs following ``laws`` exactly, times a factor each member
    shares across designs and sizes (cancels in the paired ratio), times an independent
    lognormal noise of ``noise`` decades per (design, size, member)."""
    rng = np.random.default_rng(seed)
    shared = 10 ** rng.uniform(-0.5, 0.5, members)
    out = []
    for law in laws:
        out.append(law(SIZES)[:, None] * shared[None, :] * 10 ** (noise * rng.standard_normal((SIZES.size, members))))
    return out


def _ratio(log_ratio):
    """Laws whose log10 ratio a/b is ``log_ratio(log10 ε)`` (b = 10·ε²)."""
    return (lambda e: 10.0 * e ** 2 * 10 ** log_ratio(np.log10(e)), lambda e: 10.0 * e ** 2)


def _inside(value: float, interval) -> bool:
    lo, hi = interval
    return lo is not None and hi is not None and lo * (1 - 1e-12) <= value <= hi * (1 + 1e-12)


def test_two_exact_power_laws_cross_where_they_are_equal_and_the_interval_is_that_point():
    Fa, Fb = _paired(0.0)
    res = crossover_intervals(SIZES, Fa, Fb, "jump", "nojump", **QUICK)
    (c,) = res["crossovers"]
    assert res["status"] == "crossovers" and c["status"] == "placed" and c["lower_above"] == "jump"
    assert c["at"] == pytest.approx(CROSS, rel=1e-9) and c["between"][0] < CROSS < c["between"][1]
    assert c["interval"] == pytest.approx([CROSS, CROSS], rel=1e-9)
    assert res["range"] == pytest.approx([SIZES[0], SIZES[-1]])
    (d,) = crossover_intervals(SIZES, Fb, Fa, "jump", "nojump", **QUICK)["crossovers"]
    assert d["lower_above"] == "nojump" and d["at"] == pytest.approx(CROSS, rel=1e-9)


def test_the_interval_contains_the_crossing_and_widens_with_the_noise():
    widths = []
    for noise in (0.0, 0.02, 0.08):
        (c,) = crossover_intervals(SIZES, *_paired(noise), "jump", "nojump", **QUICK)["crossovers"]
        assert c["status"] == "placed" and _inside(CROSS, c["interval"]), (noise, c)
        widths.append(np.log10(c["interval"][1] / c["interval"][0]))
    assert widths[0] < 1e-9 < widths[1] < widths[2], widths


def test_parallel_laws_have_no_crossover_and_name_the_lower_design():
    Fa, Fb = _paired(0.02, laws=(lambda e: 10.0 * e ** 2, lambda e: 20.0 * e ** 2))
    res = crossover_intervals(SIZES, Fa, Fb, "jump", "nojump", **QUICK)
    assert res["status"] == "none" and res["crossovers"] == [] and res["lower_throughout"] == "jump"
    assert res["interval"] == [None, None]
    swapped = crossover_intervals(SIZES, Fb, Fa, "jump", "nojump", **QUICK)
    assert swapped["status"] == "none" and swapped["lower_throughout"] == "nojump"


def test_the_statistic_is_the_median_of_the_paired_ratios_not_the_ratio_of_the_medians():
    """Five members, a/b = 0.5 for three of them and 2 for two: a is lower for the majority
    (the paired statistic), although a's median floor is twice b's (b = 1, 2, 3, 4, 100 →
    a = 0.5, 1, 6, 8, 50)."""
    b = np.array([1.0, 2.0, 3.0, 4.0, 100.0])
    a = b * np.array([0.5, 0.5, 2.0, 2.0, 0.5])
    assert np.median(a) == 2 * np.median(b)
    law = 10.0 * SIZES[:, None] ** 2
    res = crossover_intervals(SIZES, law * a, law * b, "jump", "nojump", **QUICK)
    assert res["crossovers"] == [] and res["lower_throughout"] == "jump"


@pytest.mark.parametrize("offset, status", [(0.04, "undecided"), (0.3, "none")])
def test_a_sign_change_the_point_estimate_lacks_but_resamples_have_is_undecided(offset, status):
    """log10(a/b) = offset + 0.1·(decades above the first size), noise 0.03 decade: the
    point estimate is positive throughout; 0.04 at the first size is within the members'
    scatter (resamples change sign there: undecided, the first change inside the range at the
    interval's lower end), 0.3 is not (none)."""
    laws = _ratio(lambda x: offset + 0.1 * (x - X[0]))
    res = crossover_intervals(SIZES, *_paired(0.03, laws=laws), "jump", "nojump", **QUICK)
    assert res["crossovers"] == [] and res["lower_throughout"] == "nojump"
    assert res["status"] == status, res
    lo, hi = res["interval"]
    assert hi is None and (lo is None) == (status == "none"), res
    if lo is not None:
        assert SIZES[0] < lo < SIZES[1]


def test_a_crossing_near_the_end_of_the_range_with_noisy_members_is_undecided():
    """log10(a/b) = 0.05·log10(ε/top), top between the last two sizes: with noise some
    resamples keep the sign to the end, the interval's upper end is not reached."""
    top = SIZES[-2] * 1.5
    laws = _ratio(lambda x: 0.05 * (x - np.log10(top)))
    (c,) = crossover_intervals(SIZES, *_paired(0.1, laws=laws), "jump", "nojump", **QUICK)["crossovers"]
    assert c["status"] == "undecided" and c["interval"][1] is None and c["interval"][0] is not None, c
    (exact,) = crossover_intervals(SIZES, *_paired(0.0, laws=laws), "jump", "nojump", **QUICK)["crossovers"]
    assert exact["status"] == "placed" and exact["at"] == pytest.approx(top, rel=1e-9)


def test_two_crossings_are_each_placed_in_their_own_window():
    """log10(a/b) = |x − x5| − 0.5 (x = log10 ε, x5 the sixth size): zeros half a decade each
    side of x5, both strictly between sizes and the ratio straight in each bracket."""
    laws = _ratio(lambda x: np.abs(x - X[5]) - 0.5)
    zeros = 10 ** (X[5] - 0.5), 10 ** (X[5] + 0.5)
    for noise in (0.0, 0.02):
        first, second = crossover_intervals(SIZES, *_paired(noise, laws=laws), "jump", "nojump", **QUICK)["crossovers"]
        assert first["lower_above"] == "jump" and second["lower_above"] == "nojump"
        for c, at in zip((first, second), zeros):
            assert c["status"] == "placed" and abs(np.log10(c["at"] / at)) < (0.05 if noise else 1e-9), (noise, c)
            assert _inside(c["at"], c["interval"]) and (noise or _inside(at, c["interval"])), (noise, c)
        assert first["window"] == [SIZES[0], second["between"][0]]
        assert second["window"] == [first["between"][1], SIZES[-1]]


# --- what the model must be known to ----------------------------------------------------------
def _law(noise: float, members: int = 10, seed: int = 3, scale: float = 20.0, exponent: float = 2.0, base=5e-8):
    rng = np.random.default_rng(seed)
    F = scale * SIZES[:, None] ** exponent * 10 ** (noise * rng.standard_normal((SIZES.size, members)))
    return F, np.full(members, base)


def test_the_tolerance_inverts_an_exact_law_and_says_when_it_extrapolates():
    F, exact = _law(0.0)
    fit = np.isin(SIZES, SIZES[2:8])
    for target in (1e-5, 1e-4):                     # 20·ε² = target inside the fitted sizes
        t = tolerance(SIZES, F, exact, target, fit_sizes=SIZES[fit], **QUICK)
        want = np.sqrt(target / 20.0)
        assert t["status"] == "ok" and t["size"] == pytest.approx(want, rel=1e-9)
        assert t["interval"] == pytest.approx([want, want], rel=1e-9)
    far = tolerance(SIZES, F, exact, 1e-7, fit_sizes=SIZES[fit], **QUICK)
    assert far["status"] == "extrapolated" and far["size"] == pytest.approx(np.sqrt(1e-7 / 20.0), rel=1e-9)
    assert far["size"] < SIZES[fit][0]


def test_a_target_at_or_below_the_exact_floor_is_not_reachable():
    F, exact = _law(0.0, base=5e-8)
    for target in (5e-8, 1e-9):
        t = tolerance(SIZES, F, exact, target, **QUICK)
        assert t["status"] == "not reachable" and t["size"] is None and t["exact_floor"] == 5e-8
    assert tolerance(SIZES, F, exact, 5.1e-8, **QUICK)["status"] != "not reachable"


def test_the_tolerance_interval_covers_the_true_size_under_noise():
    F, exact = _law(0.05)
    t = tolerance(SIZES, F, exact, 1e-4, **QUICK)
    want = np.sqrt(1e-4 / 20.0)
    lo, hi = t["interval"]
    assert lo < want < hi and hi / lo < 1.5, t


def test_without_a_law_the_floor_below_the_target_everywhere_is_the_whole_range():
    flat = np.full((SIZES.size, 4), 3e-8)
    t = tolerance(SIZES, flat, flat[0], 1e-6, **QUICK)
    assert t["status"] == "whole range" and t["at_least"] == SIZES[-1] and t["size"] is None
    step = np.where(SIZES[:, None] < 1e-2, 3e-8, 0.5) * np.ones((1, 4))     # exact, then broken
    assert tolerance(SIZES, step, flat[0], 1e-6, **QUICK)["status"] == "not fitted"


def test_a_resample_that_places_nothing_counts_against_both_ends_of_the_interval():
    """Percentile interval of resampled crossings: NaN (no same-direction change) is −∞ for the
    lower end and +∞ for the upper; the ends are order statistics, never interpolated."""
    values = np.arange(1.0, 201.0)
    assert percentile_interval(values, 0.95) == (5.0, 196.0)        # the 2.5 % and 97.5 % order statistics
    few = np.concatenate([values, [np.nan] * 3])                    # 1.5 % NaN: both ends placed
    lo, hi = percentile_interval(few, 0.95)
    assert np.isfinite(lo) and np.isfinite(hi)
    many = np.concatenate([values, [np.nan] * 20])                  # 9 % NaN: neither end placed
    assert percentile_interval(many, 0.95) == (-np.inf, np.inf)
    low = np.concatenate([values, [-np.inf] * 20])                  # −∞: only the lower end is lost
    assert percentile_interval(low, 0.95)[0] == -np.inf and np.isfinite(percentile_interval(low, 0.95)[1])


def test_resamples_draw_whole_clusters_and_members_only_within_one():
    """Clusters of 2, 3 and 1 members: every resample holds each drawn cluster whole (all its
    members, equally often) and as many clusters as there are; one cluster: the members."""
    from observer.floor_curves import cluster_resamples

    clusters = np.repeat(["a", "b", "c"], [2, 3, 1])
    picks, unit = cluster_resamples(clusters, 200, seed=1)
    assert unit == "clusters" and len(picks) == 200
    sizes = {"a": 2, "b": 3, "c": 1}
    for p in picks:
        counts = {c: np.bincount(p, minlength=6)[clusters == c] for c in sizes}
        assert all(len(set(v)) == 1 for v in counts.values()), p          # a drawn cluster enters whole
        assert sum(v[0] for v in counts.values()) == 3                      # three clusters drawn
    assert len({tuple(np.sort(p)) for p in picks}) > 3
    single, unit = cluster_resamples(np.zeros(5), 50, seed=1)
    assert unit == "members" and all(len(p) == 5 for p in single)
    assert any(len(set(p)) < 5 for p in single)
