"""Issue 34, item 1: whether a contact's relative velocity after an impact is zero (a
candidate to stay closed) is decided from its certified float64 error, not from 1000 motion
tolerances on the system's time scale τ.

A ball dropped from 5 cm (e = 0.5) on a very soft spring (ω = 1e-3 rad/s, connected to the
ball: its time scale τ = 1e3 s enters the motion tolerance ``64 eps·Σ_k |γ^(k)| τ^k/k!``, 1.4e-7
m/s after the factor 1000). Its impacts accumulate at t∞ (an independent 30-digit reference,
:mod:`mp_exact`). The rule before held the ball at the impact whose γ⁺ = 1.2e-7 m/s fell
inside that band, 4.8e-8 s before t∞ (the Zeno tail ``2γ⁺/(g(1 − e))`` lost); decided on the
certified error of γ⁺ (its evaluation, the state's representation and the velocity jump's
rounding), the impacts go on until the Zeno extrapolation, which rests at t∞ (measured 3e-17
s off). The band includes the accumulated state error (``_Run.err`` componentwise, or its
energy-norm bound, the smaller, :meth:`observer.event.master._Run.velocity_bands`): a band of
the current state's certified errors alone treated a held contact's velocity of -3.6e-29
m/s — the held flow's round-off — as a certain approach (in one of test_invariance's
two-contact tails under a change of units the held contact was re-launched six times and
rested 1.8e-4 s late). collide still takes the smaller of it and the τ-based band.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from observer.event.master import run_master
from observer.scenario import Scenario

_spec = importlib.util.spec_from_file_location("mp_exact", Path(__file__).with_name("mp_exact.py"))
mp_exact = importlib.util.module_from_spec(_spec)        # the reference beside this file
_spec.loader.exec_module(mp_exact)

G0, E, OMEGA = 9.81, 0.5, 1e-3


def soft_ball() -> Scenario:
    doc = {"scenario": {"name": "soft_ball"},
           "system": {"M": [[1.0]], "C": [[0.0]], "K": [[OMEGA * OMEGA]], "W": [[1.0]],
                      "forcing": {"constant": [-G0]}, "gap": {"offset": [0.0]}},
           "impact": {"law": "newton", "restitution": E},
           "initial": {"q": [0.05], "u": [0.0]},
           "simulation": {"t_end": 0.4, "h": 1e-2}}
    return Scenario.from_dict(doc)


def test_a_ball_on_a_soft_spring_rests_at_the_30_digit_t_inf():
    """The ball's rest time (its ``stick`` row) is the reference's to 1e-9 s, the stated
    resolution of a Zeno limit (measured: 3e-17 s; 4.8e-8 s early before)."""
    sc = soft_ball()
    ref = mp_exact.Reference(sc.system, E, sc.q0, sc.u0).run(0.4, max_events=200)
    t_rest = float(next(o[0] for o in ref if o[1] == "stick"))
    res = run_master(sc)
    assert res.status.ok
    ev = res.events
    stick = ev[ev["kind"] == "stick"]["time"].to_numpy(dtype=float)
    assert stick.size == 1
    assert abs(stick[0] - t_rest) <= 1e-9, stick[0] - t_rest
    # every resolved impact is at the reference's time (the same sequence, to 1e-12 s)
    t_ref = np.array([float(o[0]) for o in ref if o[1] == "impact"])
    t_imp = ev[ev["kind"] == "impact"]["time"].to_numpy(dtype=float)
    np.testing.assert_allclose(t_imp, t_ref[:t_imp.size], rtol=0, atol=1e-12)
