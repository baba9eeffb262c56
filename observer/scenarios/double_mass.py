"""Double-mass impact oscillator (paper, Example 1; parameters ours, docs/theory/models.md §1).

Mass 1 (lower) can hit the ground; mass 2 (upper) hangs from a fixed support by the
spring–damper (k2, c2) and carries the harmonic force F cos(Ωt); masses 1 and 2 are
coupled by (k1, c1). q = (q1, q2) are upward displacements from the unloaded
configuration, in which mass 1 is a height d0 above the ground::

    M = diag(m1, m2),  K = [[k1, -k1], [-k1, k1 + k2]],  C likewise with c1, c2
    f(t) = (-m1 g0, -m2 g0 + F cos Ωt),   g = q1 + d0 ≥ 0   (W = [1, 0]ᵀ, ν = d0)

Gravity alone would give g = d0 − 0.2943 m < 0, so at rest mass 1 sits on the ground
with the preload λ_s = −g_s / (wᵀK⁻¹w) = 2.215 N; the master starts in that static
contact equilibrium. With F = 5 N and Ω = 6 rad/s (just below the first resonance,
6.18 rad/s) mass 1 lifts off once per forcing period, lands through a Zeno sequence and
rests: accumulation points and persistent contact, as in the paper's Figs. 2–3.
Generalized Poisson law with global ε = 0.8 (the paper's choice).
"""

from __future__ import annotations

import numpy as np

DESCRIPTION = "two masses, lower one hits the ground; lifts off once per period, Zeno landing, rests"

PARAMETERS = dict(m1=1.0, m2=1.0, k1=100.0, k2=100.0, c1=1.0, c2=1.0, g0=9.81, d0=0.25, F=5.0,
                  Omega=6.0, restitution=0.8, law="poisson", h=1e-4, t_end=20.0,
                  slave_dq1=0.02, slave_dq2=-0.01, slave_u1=0.1, slave_u2=-0.1)
"""Defaults: SI units (kg, N/m, N s/m, m/s², m, N, rad/s, s)."""


def static_equilibrium(M, K, W, f_grav, nu0):
    """Static contact equilibrium under gravity for one contact (docs/theory/oracles.md §5).

    Returns (q*, λ_s): q_s = K⁻¹f_grav; if g(q_s) < 0, λ_s = −g_s/(wᵀK⁻¹w) and
    q* = q_s + K⁻¹wλ_s, else λ_s = 0 and q* = q_s.
    """
    q_s = np.linalg.solve(K, f_grav)
    w = W[:, 0]
    g_s = w @ q_s + nu0
    if g_s >= 0:
        return q_s, 0.0
    Kinv_w = np.linalg.solve(K, w)
    lam = -g_s / (w @ Kinv_w)
    return q_s + Kinv_w * lam, lam


PLOT = dict(dof=0, contact=0, labels=("q₁ (m)", "gap (m)"))
NOTES = ("the paper's Example 1: the lower mass lifts off once per forcing period; with F = 0 "
         "it comes to rest in persistent contact.")
SUITE = {
    "observers": [dict(h=(2e-4, 1e-4), t_end=(10.0, 20.0)),
                  dict(label="persistent contact (double_mass, F = 0)", params=(("param.F", 0.0),),
                       h=(5e-4, 1e-4), t_end=(10.0, 20.0), slave_offset=((0.01, 0.0), (0.0, 0.0)))],
    "work_precision": dict(h0=4e-3, t_end=1.0, targets=("master", "jump", "nojump")),
    "checks": "quick",
}


def document(**overrides) -> dict:
    """The scenario document for the given parameters (see :data:`PARAMETERS`)."""
    p = {**PARAMETERS, **overrides}
    M = np.diag([p["m1"], p["m2"]])
    K = np.array([[p["k1"], -p["k1"]], [-p["k1"], p["k1"] + p["k2"]]])
    C = np.array([[p["c1"], -p["c1"]], [-p["c1"], p["c1"] + p["c2"]]])
    W = np.array([[1.0], [0.0]])
    f_grav = np.array([-p["m1"] * p["g0"], -p["m2"] * p["g0"]])
    q0, _ = static_equilibrium(M, K, W, f_grav, p["d0"])
    dq = np.array([p["slave_dq1"], p["slave_dq2"]])
    return {
        "scenario": {"name": "double_mass", "description": DESCRIPTION},
        "system": {"M": M.tolist(), "C": C.tolist(), "K": K.tolist(), "W": W.tolist(),
                   "forcing": {"constant": f_grav.tolist(), "amplitude": [0.0, p["F"]],
                               "omega": p["Omega"], "phase": 0.0},
                   "gap": {"offset": [p["d0"]]}},
        "impact": {"law": p["law"], "restitution": p["restitution"]},
        "initial": {"q": q0.tolist(), "u": [0.0, 0.0]},
        "simulation": {"t_end": p["t_end"], "h": p["h"], "theta": 0.5},
        "observer": {"q": (q0 + dq).tolist(), "u": [p["slave_u1"], p["slave_u2"]],
                     "coupling": [0.0, p["t_end"]], "source": "master",
                     "observers": ["jump", "nojump"]},
    }
