"""Harmonically forced 1-DOF impact oscillator (Shaw–Holmes; non-dimensional form).

``ẍ + 2ζẋ + x = A cos(ωt)`` for ``x ≤ σ`` with restitution r at the wall x = σ
(docs/theory/oracles.md §2). In the toolkit's convention q = x, M = 1, K = 1, C = 2ζ, f = A cos ωt,
g = σ − q ≥ 0 (W = [−1], ν = σ). Defaults ω = 2.8, r = 0.8, σ = 0: the (1,1) periodic
orbit has impact velocity V = 0.336177 (docs/theory/oracles.md §2).
"""

from __future__ import annotations

DESCRIPTION = "1-DOF harmonically forced oscillator hitting a wall (Shaw-Holmes form)"

PARAMETERS = dict(zeta=0.0, A=1.0, omega=2.8, sigma=0.0, restitution=0.8, law="newton",
                  q0=-0.5, u0=0.0, h=1e-3, t_end=20.0)


NOTES = "isolated impacts on a periodic orbit: the (1,1) orbit of docs/theory/oracles.md §2."
REFERENCE_TEXT = "closed form (event-driven: exact free flight, impacts by brentq)"
SUITE = {
    "observers": [dict(h=(1e-3, 1e-4), t_end=(20.0, 20.0), slave_offset=((0.1,), (0.0,)))],
    "work_precision": dict(h0=2e-3, t_end=10.0, targets=("master",)),
    "checks": "quick",
}


def reference(scenario, t):
    """The exact solution (:func:`observer.scenarios.exact.oscillator_reference`): undamped,
    one harmonic forcing term, fixed wall; None otherwise."""
    from observer.scenarios.exact import oscillator_reference
    return oscillator_reference(scenario, t)


def document(**overrides) -> dict:
    p = {**PARAMETERS, **overrides}
    return {
        "scenario": {"name": "impact_oscillator", "description": DESCRIPTION},
        "system": {"M": [[1.0]], "C": [[2.0 * p["zeta"]]], "K": [[1.0]], "W": [[-1.0]],
                   "forcing": {"constant": [0.0], "amplitude": [p["A"]], "omega": p["omega"],
                               "phase": 0.0},
                   "gap": {"offset": [p["sigma"]]}},
        "impact": {"law": p["law"], "restitution": p["restitution"]},
        "initial": {"q": [p["q0"]], "u": [p["u0"]]},
        "simulation": {"t_end": p["t_end"], "h": p["h"], "theta": 0.5},
    }
