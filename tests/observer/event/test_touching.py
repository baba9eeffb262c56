"""Identically closed contacts are a state (issue 34, item 2): touching bodies and bodies that
move together after a plastic impact stay closed under the contact-force LCP and the run goes
on to t_end. Expected values are closed forms written here, independently of the engine."""

from __future__ import annotations

import numpy as np
import pytest

from observer.event.master import run_master
from observer.scenario import Scenario

G0 = 9.81


def row_of_balls(n: int, law: str, e: float, height: float, ground: bool, gravity: float,
                 t_end: float, u0=None) -> Scenario:
    """n unit balls on a line touching each other (gaps q_{i+1} − q_i = 0), the lowest at
    ``height`` above a ground (contact 0) when ``ground``; gravity along the line."""
    W = np.zeros((n, n - 1 + ground))
    if ground:
        W[0, 0] = 1.0
    for i in range(n - 1):
        W[i, i + ground], W[i + 1, i + ground] = -1.0, 1.0
    doc = {"scenario": {"name": "row"},
           "system": {"M": np.eye(n).tolist(), "C": np.zeros((n, n)).tolist(),
                      "K": np.zeros((n, n)).tolist(), "W": W.tolist(),
                      "forcing": {"constant": [-gravity] * n},
                      "gap": {"offset": [0.0] * W.shape[1]}},
           "impact": {"law": law, "restitution": e},
           "initial": {"q": [height] * n, "u": [0.0] * n if u0 is None else u0},
           "simulation": {"t_end": t_end, "h": 1e-2}}
    return Scenario.from_dict(doc)


@pytest.mark.parametrize("n", [3, 4])
@pytest.mark.parametrize("law", ["newton", "poisson"])
def test_a_stack_in_free_fall_stays_together_with_no_force(n, law):
    """Touching balls in free fall: every ball follows −g t²/2, no impulse, to t_end."""
    res = run_master(row_of_balls(n, law, 0.5, 0.0, False, G0, 0.5))
    assert res.status.ok and res.t[-1] == pytest.approx(0.5)
    assert np.allclose(res.q, (-G0 * res.t ** 2 / 2)[:, None], rtol=0, atol=1e-13)
    assert np.max(np.abs(res.g)) <= 1e-13 and np.max(np.abs(res.P)) <= 1e-13


@pytest.mark.parametrize("n", [3, 4])
@pytest.mark.parametrize("law", ["newton", "poisson"])
def test_a_touching_stack_lands_and_bounces_as_one_body(n, law):
    """The stack dropped from 1 m: the ground impact at √(2/g), every ball leaves with e·v
    (the LCP's closed form for both laws: the touching contacts have γ⁻ = 0, so Newton keeps
    γ⁺ = 0 on them; Poisson's restitution impulses are e times its compression impulses,
    which stop every ball), the next impact at √(2/g) + 2ev/g."""
    e, h = 0.5, 1.0
    res = run_master(row_of_balls(n, law, e, h, True, G0, 1.0))
    assert res.status.ok and res.t[-1] == pytest.approx(1.0)
    t1, v = np.sqrt(2 * h / G0), np.sqrt(2 * G0 * h)
    ground = res.impact_times(0)
    assert ground[:2] == pytest.approx([t1, t1 + 2 * e * v / G0], abs=1e-12)
    k = int(np.searchsorted(res.t, t1)) + 1         # the first row after the impact
    dt = res.t[k] - t1
    assert np.allclose(res.u[k], e * v - G0 * dt, atol=1e-10)
    assert np.max(np.abs(res.g[:, 1:])) <= 1e-12     # the balls stay touching


def test_a_cradle_row_of_five_touching_balls_at_rest_stays_at_rest():
    res = run_master(row_of_balls(5, "newton", 1.0, 0.0, False, 0.0, 1.0))
    assert res.status.ok and res.t.size == 101
    assert np.all(res.q == 0.0) and np.all(res.u == 0.0) and np.all(res.P == 0.0)


def test_a_plastic_collision_of_two_free_masses_moves_them_together_to_t_end():
    """m1 = 1 at 0 with u = 1 hits m2 = 2 at 1 at rest, e = 0: impact at t = 1, impulse
    m1 m2/(m1 + m2) = 2/3, both at 1/3 afterwards, touching to t_end = 2."""
    doc = {"scenario": {"name": "plastic"},
           "system": {"M": [[1.0, 0.0], [0.0, 2.0]], "C": np.zeros((2, 2)).tolist(),
                      "K": np.zeros((2, 2)).tolist(), "W": [[-1.0], [1.0]],
                      "gap": {"offset": [0.0]}},
           "impact": {"law": "newton", "restitution": 0.0},
           "initial": {"q": [0.0, 1.0], "u": [1.0, 0.0]},
           "simulation": {"t_end": 2.0, "h": 1e-2}}
    res = run_master(Scenario.from_dict(doc))
    assert res.status.ok and res.t[-1] == pytest.approx(2.0)
    imp = res.events.query("kind == 'impact'")
    assert len(imp) == 1 and imp.time.iloc[0] == pytest.approx(1.0, abs=1e-15)
    assert imp.impulse.iloc[0] == pytest.approx(2.0 / 3.0, rel=1e-14)
    after = res.t > 1.0
    assert np.allclose(res.u[after], 1.0 / 3.0, atol=1e-14)
    assert np.allclose(res.q[after, 0], 1.0 + (res.t[after] - 1.0) / 3.0, atol=1e-13)
    assert np.max(np.abs(res.g[after])) <= 1e-13


def test_a_force_certainly_nonzero_in_float64_is_not_identically_zero():
    """The identically-zero test of a held force (:func:`observer.event.master._identically_zero`)
    decides from the certified error of its float64 evaluation, not from 64 eps·Σ|r z| (a
    count of round-offs): ``z0 + z1 = 20 ulp(1e6) ≈ 2.3e-9`` is exact in float64 and above
    the certified bound ``(γ_4 + u)·Σ|r z| ≈ 1.1e-9``, so the force is not zero (the old rule,
    2.8e-8, called it zero and stopped watching it); an exact cancellation still is zero, and
    so is a derivative row that is zero up to its own certified error."""
    from types import SimpleNamespace

    from observer.event.master import _identically_zero

    big = 1e6
    row = np.array([1.0, 1.0, 0.0])
    z = np.array([big, -big + 20 * np.spacing(big), 1.0])
    assert z[0] + z[1] == 20 * np.spacing(big)                  # exact: a certain 2.3e-9
    still = SimpleNamespace(A=np.zeros((3, 3)))
    assert not _identically_zero(still, row, z)
    assert _identically_zero(still, row, np.array([big, -big, 1.0]))
    # the velocity of a uniform motion: ψ = q0 + q1 = 0 exactly, ψ' = u-rows·z = 0 exactly
    drift = SimpleNamespace(A=np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]]))
    assert _identically_zero(drift, row, np.array([big, -big, 1.0]))
    assert not _identically_zero(drift, np.array([1.0, 0.0, 0.0]), np.array([big, -big, 1.0]))
