"""The power-law fit and the crossover of bench/floor_curves.py on floors of known laws."""

from __future__ import annotations

import numpy as np

from bench.floor_curves import ABOVE_EXACT, BROKEN, crossovers, fit_curve, fit_range

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
