"""Issue 34, items 1 and 3: which contacts are impacted together is not decided on the
system's time scale τ = 1/ω_max.

Two free balls under gravity (unconnected, contacts 0 and 1 with the ground) released at
rest from heights d and d + δ land at ``√(2d/g)`` and ``√(2(d + δ)/g)``, 5e-15 s apart
(about 360 ulp of t): two impacts, in order, each at its own time (to 1e-15 s, 70 ulp), with
a spring of 1e-6 rad/s connected to nothing (a third coordinate) beside them. The band of
simultaneity built on a time scale (1000 time resolutions of max(|t|, τ) at the approach
speed: 2.8e-14 m at τ = 0.1 s, the motion's own scale) merged them into one impact at the
first landing, 5e-15 s early; the landings cannot be ordered only within the time
coordinate's resolution (two ulp of t) or the state's accumulated error.
"""

from __future__ import annotations

import numpy as np

from observer.event.master import run_master
from observer.scenario import Scenario

G0, D, E = 9.81, 0.05, 0.5
DT = 5e-15                                  # the landings' separation


def two_balls_and_a_slow_spring(omega: float) -> tuple[Scenario, float, float]:
    """The two balls (q0, q1) and an unconnected oscillator q2 of ω = omega; the closed-form
    landing times of the two balls."""
    t_a = np.sqrt(2 * D / G0)
    t_b = t_a + DT
    d_b = 0.5 * G0 * t_b * t_b
    doc = {"scenario": {"name": "two_balls"},
           "system": {"M": np.eye(3).tolist(), "C": np.zeros((3, 3)).tolist(),
                      "K": np.diag([0.0, 0.0, omega * omega]).tolist(),
                      "W": [[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]],
                      "forcing": {"constant": [-G0, -G0, 0.0]}, "gap": {"offset": [0.0, 0.0]}},
           "impact": {"law": "newton", "restitution": E},
           "initial": {"q": [D, d_b, 1.0], "u": [0.0, 0.0, 0.0]},
           "simulation": {"t_end": 0.15, "h": 1e-2}}
    return Scenario.from_dict(doc), t_a, np.sqrt(2 * d_b / G0)


def test_two_landings_5e_15_s_apart_stay_two_impacts_in_order():
    sc, t_a, t_b = two_balls_and_a_slow_spring(1e-6)
    res = run_master(sc)
    assert res.status.ok
    ev = res.events[res.events["kind"] == "impact"]
    first = {int(c): float(ev[ev["contact"] == c]["time"].iloc[0]) for c in (0, 1)}
    assert abs(first[0] - t_a) <= 1e-15
    assert abs(first[1] - t_b) <= 1e-15
