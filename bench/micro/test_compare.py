"""Benchmark (pytest-benchmark): ``observer.compare`` at the acceptance size of issue 31.

double_mass, 20 masters × 200 members × {jump, nojump}, 10 s at h = 2e-4 (50 000 steps per
master), the estimands of :mod:`observer.stats` included; the acceptance budget is
``BUDGET_S`` seconds of wall time on 2 idle cores (``extra_info["wall_s"]`` against
``extra_info["budget_s"]``). One round; the kernel is compiled (or loaded from
numba's cache) first. The answer is checked: the rate-ratio interval holds its estimate and
the evidence is 20 × 200.

With ``--benchmark-disable`` the case shrinks to :data:`SMOKE`::

    python -m pytest bench/micro/test_compare.py --benchmark-only --benchmark-json=compare.json
"""

from __future__ import annotations

import time

import observer

FULL = dict(n=200, masters=20, h=2e-4, t_end=10.0)
SMOKE = dict(n=4, masters=2, h=1e-3, t_end=1.0, n_resamples=49)
BUDGET_S = 60.0


def test_compare_acceptance(benchmark):
    case = SMOKE if benchmark.disabled else FULL
    if not benchmark.disabled:                         # compile before timing (the smoke run: no timing)
        observer.compare("double_mass", **SMOKE)
    t0 = time.perf_counter()
    res = benchmark.pedantic(lambda: observer.compare("double_mass", **case), rounds=1, iterations=1)
    benchmark.extra_info["wall_s"] = time.perf_counter() - t0
    benchmark.extra_info["budget_s"] = BUDGET_S
    rr = res.rate_ratios.iloc[0]
    assert rr["low"] <= rr["estimate"] <= rr["high"]
    assert res.evidence == {"members_per_master": case["n"], "masters": case["masters"],
                            "pairs": case["n"] * case["masters"]}
