"""Micro-benchmark (pytest-benchmark): the cost of a translation for the event engine (issue 34,
"translation by 1e6 not more than 2× the untranslated cost").

A ball dropped 0.3 m onto the ground (e = 0.5: its Zeno limit at 0.74 s, then at rest to 2 s), run by
``observer.simulate(..., integrator="event")`` in coordinates translated by c ∈ {0, 1e6,
1e8} (q₀ = 0.3 + c, ν = −c): the engine carries the translated runs in its gap frame
(``observer.event.frame``). Each round builds a new scenario outside the timing (so every
timed call builds its flows and, translated, its frame: the cost of a first run of a
scenario); one call per round, :data:`ROUNDS` rounds, the median reported. The compile
time is apart: the first run of the process (imports, compiled kernels) is timed once before
the rounds and stored in ``extra_info["compile_time_s"]``; ``extra_info["impacts"]`` gives
the cost per impact (median / impacts). Run::

    python -m pytest bench/micro/test_event_translation.py --benchmark-only

Each benchmark checks its answer: the accumulation time t∞ within 4·ulp(c)/v of the closed
form t∞ = t₁ + 2ve/(g(1 − e)) (from the float inputs, in 50-digit mpmath).
With ``--benchmark-disable`` (the test suite's run) each case runs once: that check only.
"""

from __future__ import annotations

import time

import mpmath as mp
import numpy as np
import pytest

import observer
from observer.scenario import Scenario

G0 = 9.81
E = 0.5
ROUNDS = 15
"""Timed rounds (one call each) per translation."""

_FIRST: dict = {}


def ball(c: float) -> Scenario:
    doc = {"scenario": {"name": "translated_ball"},
           "system": {"M": [[1.0]], "C": [[0.0]], "K": [[0.0]], "W": [[1.0]],
                      "forcing": {"constant": [-G0]}, "gap": {"offset": [-c]}},
           "impact": {"law": "newton", "restitution": E},
           "initial": {"q": [0.3 + c], "u": [0.0]},
           "simulation": {"t_end": 2.0, "h": 0.01}}
    return Scenario.from_dict(doc)


def closed_form(sc: Scenario) -> tuple[float, float]:
    """(t∞, v) of the ball from the float inputs, 50 digits."""
    with mp.workdps(50):
        g0 = mp.mpf(float(sc.q0[0])) + mp.mpf(float(sc.system.gap.constant[0]))
        g = mp.mpf(G0)
        v = mp.sqrt(2 * g * g0)
        return float(mp.sqrt(2 * g0 / g) + 2 * v * E / (g * (1 - E))), float(v)


def run(sc: Scenario):
    return observer.simulate(sc, integrator="event")


@pytest.mark.parametrize("c", [0.0, 1e6, 1e8], ids=["untranslated", "1e6", "1e8"])
def test_event_translation(benchmark, c):
    if "first" not in _FIRST:                   # compile and imports, timed apart
        start = time.perf_counter()
        run(ball(0.0))
        _FIRST["first"] = time.perf_counter() - start
    benchmark.group = "event engine: ball translated by c (per call)"
    res = benchmark.pedantic(run, setup=lambda: ((ball(c),), {}), rounds=ROUNDS, iterations=1)
    ev = res.events
    impacts = int((ev["kind"] == "impact").sum())
    benchmark.extra_info.update(kind="event_translation", translation=c, impacts=impacts,
                                compile_time_s=_FIRST["first"])
    assert res.status.ok, res.status
    t_inf = ev[ev["kind"] == "accumulation"]["time"].to_numpy()
    ref, v = closed_form(ball(c))
    assert t_inf.size == 1 and abs(t_inf[0] - ref) <= max(4 * np.spacing(c) / v, 1e-14)
