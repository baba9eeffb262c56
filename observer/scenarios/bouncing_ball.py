"""Bouncing ball (Zeno): a point mass dropped from rest at height h0 onto the ground.

1 DOF, q = height, M = m, C = 0, K = k (default k = 0: a free rigid mode, outside the
theorem's K ≻ 0, so V = ½m v² does not see the position error; the observer with position
jumps needs K ≻ 0), f = −m g0, g = q ≥ 0, Newton restitution e. ``k > 0`` is the ball on a
spring (spring at rest at q = 0, pulling towards q = −m g0/k below the ground): K ≻ 0, the
paper's setting, so the Zeno ensemble has a K-positive twin (the closed form below is for
k = 0 only; :func:`reference` returns None otherwise).
Closed form (docs/theory/oracles.md §1): first impact t1 = sqrt(2h0/g0), impact times
t_k = t1 + (2v1/g0) e(1 − e^{k−1})/(1 − e), accumulation time
t_∞ = sqrt(2h0/g0)(1 + e)/(1 − e) = 4.0637 s for h0 = 1 m, e = 0.8; then persistent
contact with λ = m g0.
"""

from __future__ import annotations

from observer.scenarios.exact import accumulation_time, ball_reference, impact_times  # noqa: F401

DESCRIPTION = "ball dropped on the ground: Zeno accumulation at t_inf = 4.06 s, then rest"

PARAMETERS = dict(m=1.0, k=0.0, g0=9.81, h0=1.0, restitution=0.8, law="newton", h=1e-3, t_end=6.0)

PLOT = dict(dof=0, contact=0, labels=("height q (m)", "gap (m)"))
NOTES = ("K = 0 (default): only the no-jump observer applies and V does not see the position "
         "error; Zeno accumulation of impacts, then persistent contact. param.k > 0: the ball "
         "on a spring (K > 0).")
REFERENCE_TEXT = "closed form (docs/theory/oracles.md §1: impact times, parabolic flights)"
SPRING_K = 20.0
"""Stiffness (N/m) of the ball-on-a-spring variant of the suites: m g0/k = 0.49 m, so the spring
holds the ball on the ground after the impacts die out (K ≻ 0 beside the K = 0 ball)."""
SUITE = {
    "observers": [dict(label="bouncing_ball (Zeno)", h=(1e-3, 1e-4), t_end=(6.0, 6.0),
                       slave_offset=((0.2,), (-1.0,))),
                  dict(label="bouncing_ball (ball on a spring, K > 0)", params=(("param.k", SPRING_K),),
                       h=(1e-3, 1e-4), t_end=(6.0, 6.0), slave_offset=((0.2,), (-1.0,)))],
    "work_precision": dict(h0=2e-3, t_end=3.0, targets=("master",)),
    "checks": "quick",
}


def reference(scenario, t):
    """The closed form of the free ball (docs/theory/oracles.md §1,
    :func:`observer.scenarios.exact.ball_reference`);
    None for the ball on a spring (K ≠ 0: no closed form here)."""
    if scenario.system.K[0, 0] != 0.0:
        return None
    return ball_reference(scenario, t)


def document(**overrides) -> dict:
    p = {**PARAMETERS, **overrides}
    return {
        "scenario": {"name": "bouncing_ball", "description": DESCRIPTION},
        "system": {"M": [[p["m"]]], "C": [[0.0]], "K": [[float(p["k"])]], "W": [[1.0]],
                   "forcing": {"constant": [-p["m"] * p["g0"]]}, "gap": {"offset": [0.0]}},
        "impact": {"law": p["law"], "restitution": p["restitution"]},
        "initial": {"q": [p["h0"]], "u": [0.0]},
        "simulation": {"t_end": p["t_end"], "h": p["h"], "theta": 0.5},
    }
