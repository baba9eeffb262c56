"""The joint tails' decisions from enclosures (issue 34, item 1): whether a contact's next hop
from its contact point, ``2γ⁺/α``, lasts no longer than the time coordinate's resolution is the
sign of ``w = −res·α' − 2γ⁺`` decided from a certified enclosure (float64, else ball arithmetic),
checked here against exact rational arithmetic on the same float64 data."""

from __future__ import annotations

import re
from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest

from observer.event.roots import time_resolution
from observer.event.tails import hop_within


def _flow() -> SimpleNamespace:
    """A stand-in flow: contact 0's velocity row sums z0 + z1 + z2, its acceleration row
    (velocity row · A) reads z3."""
    A = np.zeros((4, 4))
    A[0, 3] = 1.0
    return SimpleNamespace(velocity_rows=np.array([[1.0, 1.0, 1.0, 0.0]]), A=A)


def _exact_within(z: np.ndarray, res: float) -> bool:
    q = [Fraction(float(v)) for v in z]
    v, a = q[0] + q[1] + q[2], q[3]
    return -Fraction(res) * a - 2 * v >= 0


@pytest.mark.parametrize("scale", [0.0, 1e20])
@pytest.mark.parametrize("factor", [0.25, 0.5, 1.0, 2.0])
def test_the_hop_decision_is_the_exact_one_even_where_float64_cancels(scale, factor):
    """γ⁺ = δ carried under a cancelling ±scale (float64 loses δ entirely at 1e20: its w
    says "within" for every δ), α = 1: the hop 2δ lasts ≤ res exactly when δ ≤ res/2 —
    hop_within agrees with the exact rational sign on both sides of the boundary, and at it."""
    res = time_resolution(1.0)
    delta = factor * res
    z = np.array([scale, delta, -scale, -1.0])
    assert hop_within(_flow(), 0, z, res) == _exact_within(z, res) == (factor <= 0.5)


def test_the_hop_decision_uses_the_resolution_of_the_time_coordinate_only():
    """The same hop (1e-12 s) is within the resolution at t = 1e4 (3.6e-12 s) and not at
    t = 1 (4.4e-16 s): the decision reads t, nothing else (no time scale of the system)."""
    z = np.array([0.0, 5e-13, 0.0, -1.0])
    assert hop_within(_flow(), 0, z, time_resolution(1e4))
    assert not hop_within(_flow(), 0, z, time_resolution(1.0))


def _jump_run(minv: float, w: float) -> SimpleNamespace:
    """A stand-in run of one body on one contact: velocity row (0, w, 0) on z = (q, u, 1),
    M⁻¹ = minv, W = w."""
    flow = SimpleNamespace(velocity_rows=np.array([[0.0, w, 0.0]]),
                           z=lambda t, x: np.concatenate([x, [1.0]]))
    return SimpleNamespace(free_flow=flow, n=1, Minv=np.array([[minv]]),
                           system=SimpleNamespace(W=np.array([[w]])))


def _jump(run, u: float, lam: float) -> tuple[np.ndarray, np.ndarray]:
    before = np.array([0.0, u])
    after = before.copy()
    after[1:] += run.Minv @ run.system.W @ np.array([lam])
    return before, after


def _exact_velocity(run, u: float, lam: float) -> Fraction:
    w, m = Fraction(float(run.system.W[0, 0])), Fraction(float(run.Minv[0, 0]))
    return w * (Fraction(u) + m * w * Fraction(lam))


@pytest.mark.parametrize("minv, w, u, lam", [
    (1.0, 1.0, -1.0, 1.0 + 1e-14),            # leaves at 1e-14·|γ⁻|: the old cut said "held"
    (1.0, 1.0, -1.0, 1.0),                    # exactly zero
    (1.0 / 3.0, 3.0, -0.1, 0.1),              # float64 gives 0, exactly −0.1·2⁻⁵⁴·9
    (1.0 / 3.0, 3.0, -0.1, np.nextafter(0.1, 1.0)),
    (1.0 / 7.0, 7.0, -1e3, 1e3),
    (1.0 / 7.0, 7.0, -1e3, np.nextafter(1e3, 0.0)),
])
def test_whether_an_impact_lifts_a_contact_is_the_exact_sign_of_its_velocity(minv, w, u, lam):
    """The velocity after the jump u + M⁻¹Wλ, from the float64 data (u, M⁻¹, W, λ), has the
    exact rational sign: a contact left with 1e-14 of its impact speed certainly leaves (the
    old cut, 1e3·eps·|γ⁻| = 2.2e-13, held it); one left exactly at rest, or at a velocity that
    float64 rounds away, gets the exact sign (0, or the sign of what float64 lost)."""
    from observer.event.tails import leaves
    run = _jump_run(minv, w)
    before, after = _jump(run, u, lam)
    dec = leaves(run, 0.0, before, after, [0], np.array([lam]), 0)
    v = _exact_velocity(run, u, lam)
    assert dec.sign == (v > 0) - (v < 0)
    assert Fraction(dec.lower) <= v <= Fraction(dec.upper)


def test_a_hop_undecided_at_the_precision_cap_is_not_within_and_states_its_enclosure(monkeypatch):
    """γ⁺ = res/2 under a cancelling ±1e30 (the data span 153 binary orders), α = 1: the hop
    lasts exactly res, within (the real cap decides the exact zero); with the cap lowered to
    the first ball precision (128 bits) the sign is undecided: the hop is then not within,
    and the note gives an enclosure of w (containing the exact 0) and the precision reached."""
    import observer.event.enclosures as enclosures
    res = time_resolution(1.0)
    z = np.array([1e30, res / 2.0, -1e30, -1.0])
    assert hop_within(_flow(), 0, z, res)
    monkeypatch.setattr(enclosures, "PRECISION_CAP", 128)
    notes: dict = {}
    assert not hop_within(_flow(), 0, z, res, notes)
    assert set(notes) == {0}
    lo, hi = (float(v) for v in re.search(r"\[(\S+), (\S+)\] at 128 bits", notes[0]).groups())
    assert lo < 0.0 < hi


def test_an_undecided_decision_in_a_joint_tail_is_stated_in_its_event_rows(monkeypatch):
    """Two balls whose tails overlap, translated by 100 (a joint tail): with every lift-off decision of its
    impacts made undecided (the float64 enclosure kept, no sign), the tail's rows of those
    impacts carry the enclosure in their note, after the joint tail's own."""
    import observer.event.tails as tails
    from observer.event.enclosures import Decision
    from observer.event.master import run_master
    from tests.observer.event.test_joint_tails import two_contacts
    real = tails.leaves

    def undecided(*args):
        dec = real(*args)
        return Decision(None, dec.lower, dec.upper, 4096)
    monkeypatch.setattr(tails, "leaves", undecided)
    res = run_master(two_contacts(np.eye(2), (0.005, 0.005001), 0.4, 100.0, 0.1))
    ev = res.events
    tail = ev[ev["note"].str.startswith("joint tail of contacts (0, 1): exact hop")]
    assert len(tail) > 0
    assert tail["note"].str.contains(r"leaving its contact point undecided: sign of a value in \[",
                                     regex=True).all()


def test_a_hop_polynomial_is_taken_only_where_its_remainder_is_below_its_rounding():
    """A contact on a spring of 10 rad/s (g = q): wherever :func:`taylor_holds` accepts a hop
    of Δ, the degree-8 polynomial of the relative gap is within its own float64 evaluation
    bound of the exact flow (mpmath, 40 digits, from the same float64 data); it accepts the
    short hops (Δ ≤ 1e-3 s) and refuses Δ = 0.1 s, where the truncation is ~(ωΔ)⁹/9! ≈ 3e-6
    of the motion."""
    import mpmath as mp
    from observer.event.flow import flow_for
    from observer.event.tails import HOP_ORDER, _FACT, _rows, advance, taylor_holds
    from observer.scenario import Scenario
    from observer.event.enclosures import gamma
    sc = Scenario.from_dict({
        "scenario": {"name": "spring"},
        "system": {"M": [[1.0]], "C": [[0.0]], "K": [[100.0]], "W": [[1.0]],
                   "forcing": {"constant": [0.0]}, "gap": {"offset": [0.0]}},
        "impact": {"law": "newton", "restitution": 0.5},
        "initial": {"q": [0.3], "u": [1.7]}, "simulation": {"t_end": 1.0, "h": 0.1}})
    fl = flow_for(sc.system, ())
    z = fl.z(0.0, np.array([0.3, 1.7]))
    D = _rows(fl, 0) @ z
    accepted = []
    for dt in [1e-6, 1e-4, 1e-3, 1e-2, 3e-2, 0.1, 0.5]:
        with mp.workdps(40):
            w = mp.mpf(10)
            q, u = mp.mpf(float(z[0])), mp.mpf(float(z[1]))
            exact = q * mp.cos(w * dt) + u / w * mp.sin(w * dt) - q
        poly = advance(0.0, D, dt)
        terms = float(np.abs(D) @ (dt ** np.arange(1, HOP_ORDER + 1) / _FACT))
        if taylor_holds(fl, 0, z, 0.0, D, dt):
            accepted.append(dt)
            assert abs(mp.mpf(poly) - exact) <= 2 * gamma(2 * HOP_ORDER + 2) * terms, dt
    assert {1e-6, 1e-4, 1e-3} <= set(accepted) and 0.1 not in accepted and 0.5 not in accepted


def test_an_impact_of_a_decoupled_contact_lifts_no_held_contact():
    """Two free masses (W = I), contact 0 held with the held flow's round-off γ₀ = 1e-17 in its
    float state, contact 1 impacted (λ = (0, 0.3)): the velocity of contact 0 after the impact
    is exactly 0 (held before, the impulse on the other mass does not reach it), so it is not
    lifted. Evaluated on the float state, as if not held, the round-off would lift it: the
    translated pair of masses of the invariance test then rested 1.9e-4 s late."""
    from observer.event.tails import leaves
    flow = SimpleNamespace(velocity_rows=np.array([[0.0, 0.0, 1.0, 0.0, 0.0],
                                                   [0.0, 0.0, 0.0, 1.0, 0.0]]),
                           z=lambda t, x: np.concatenate([x, [1.0]]))
    run = SimpleNamespace(free_flow=flow, n=2, Minv=np.diag([1.0 / 3.0, 2.0]),
                          system=SimpleNamespace(W=np.eye(2)))
    before = np.array([0.0, 0.0, 1e-17, -0.4])
    lam = np.array([0.0, 0.3])
    after = before.copy()
    after[2:] += run.Minv @ lam
    held = leaves(run, 0.0, before, after, [0, 1], lam, 0, held=True)
    assert held.sign == 0
    assert leaves(run, 0.0, before, after, [0, 1], lam, 0).sign == 1     # the float state's
