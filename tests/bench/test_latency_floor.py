"""The floor-versus-latency fit of bench/latency_floor.py on floors of a known power law."""

from __future__ import annotations

import numpy as np
import pandas as pd

from bench.latency_floor import ABOVE_GRID, BROKEN, fit_range, fit_slope

LAT = (1e-5, 2e-5, 5e-5, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2)


def _rows(exponent: float, base: float, scale: float, members: int = 5, spread: float = 0.05):
    """Floors scale·d^exponent (times a member's own factor, up to ±spread in log), d = 0: base;
    the power law saturates at 1.7 (a broken observer)."""
    rng = np.random.default_rng(1)
    out = []
    for i in range(members):
        f = 10 ** rng.uniform(-spread, spread)
        out.append({"design": "jump", "member": i, "latency": 0.0, "floor": base * f})
        for d in LAT:
            out.append({"design": "jump", "member": i, "latency": d,
                        "floor": min(1.7, max(base, scale * d ** exponent) * f)})
    return pd.DataFrame(out)


def test_the_fit_range_keeps_the_latencies_between_the_grid_floor_and_the_broken_observer():
    rows = _rows(2.0, base=1e-11, scale=1e3)         # floor 1e3·d²: 1e-7 at 1e-5, 0.1 at 1e-2
    kept = fit_range(rows, "jump")
    med = {d: 1e3 * d ** 2 for d in LAT}
    assert kept == [d for d in LAT if med[d] >= ABOVE_GRID * 1e-11 * 1.2 and med[d] < BROKEN * 0.8]
    assert 1e-2 not in kept and 1e-5 in kept
    assert fit_range(_rows(2.0, base=5e-9, scale=1e3), "jump")[0] == 5e-5     # 1e3·d² ≥ 100 × 5e-9


def test_the_slope_of_a_square_law_is_two_inside_its_interval_and_a_near_miss_is_not():
    rows = _rows(2.0, base=1e-12, scale=1e2)
    fit = fit_slope(rows, "jump", fit_range(rows, "jump"))
    assert fit["status"] == "ok" and abs(fit["slope"] - 2.0) < 0.02, fit
    for lo, hi in fit["interval"].values():
        assert lo <= 2.0 <= hi and hi - lo < 0.1, fit
    steeper = fit_slope(_rows(2.2, base=1e-12, scale=1e2), "jump", fit_range(rows, "jump"))
    for lo, hi in steeper["interval"].values():
        assert not lo <= 2.0 <= hi, steeper


def test_too_few_latencies_in_the_range_is_said_not_fitted():
    rows = _rows(2.0, base=1e-4, scale=1e3)          # only 1e3·d² = 0.025 at d = 5e-3 in the range
    fit = fit_slope(rows, "jump", fit_range(rows, "jump"))
    assert fit["status"].startswith("too few") and fit["slope"] is None
