"""Root isolation (observer/event/roots.py): named regressions."""

from __future__ import annotations

import numpy as np
import pytest

from observer.event.flow import flow_for
from observer.event.roots import first_zero, time_resolution
from observer.scenario import Scenario

OMEGA, AMP, V1, GAP1 = 2.0, 0.05, 0.7, 0.14


def graze_and_approach() -> Scenario:
    """Two decoupled contacts: an oscillator x₀ = −A cos ωt whose gap g₀ = x₀ + A touches
    zero exactly at t = 0 (a graze: g₀ = A(1 − cos ωt) ≥ 0), and a free mass approaching its
    wall at V1 from GAP1 away (g₁ = GAP1 − V1 t)."""
    doc = {"scenario": {"name": "graze-and-approach"},
           "system": {"M": [[1.0, 0.0], [0.0, 1.0]], "C": [[0.0, 0.0], [0.0, 0.0]],
                      "K": [[OMEGA ** 2, 0.0], [0.0, 0.0]], "W": [[1.0, 0.0], [0.0, 1.0]],
                      "forcing": {"constant": [0.0, 0.0]}, "gap": {"offset": [AMP, 0.0]}},
           "impact": {"law": "newton", "restitution": 0.5},
           "initial": {"q": [-AMP, GAP1], "u": [0.0, -V1]},
           "simulation": {"t_end": 1.0, "h": 0.01}}
    return Scenario.from_dict(doc)


@pytest.mark.parametrize("t0", [0.0, 1e3])
@pytest.mark.parametrize("reach", [0.5, 2.0])
def test_right_after_a_graze_an_open_contact_far_away_is_not_taken_as_the_zero(reach, t0):
    """Regression of b3b82ce (``_unresolved``). Right after contact 0's graze, certified
    positive for less than the time resolution, the safe step falls below the resolution and
    the zero is "unresolved": the old rule took the approaching functional with the smallest
    first-order time to zero, here contact 1, GAP1 = 0.14 away, as a crossing at the graze
    instant (an impact of an open contact). Now only functionals vanishing near t qualify:
    up to ``reach`` × GAP1/V1 there is no zero before it, and the first zero is contact 1's,
    at GAP1/V1 (closed form). The system is time-invariant, so the graze is put at t0: at
    t0 = 1e3 the time resolution (two ulp of t, 4.4e-13 s) is wide enough for the step to
    fall below it, and the old rule fails there (without the reach filter of ``_unresolved``
    contact 1 is taken at t0; the certificate filter alone does not stop it here); at t0 = 0
    that path is not reached (the case only checks the answer)."""
    sc = graze_and_approach()
    fl = flow_for(sc.system, ())
    x0 = np.concatenate([sc.q0, sc.u0])
    z0 = fl.z(t0, x0)
    certified = {0: t0 + 0.25 * time_resolution(t0)}   # the graze's certificate ends within res
    t_hit = GAP1 / V1
    zero, t, _ = first_zero(fl, fl.gap_rows, t0, z0, t0 + reach * t_hit, certified)
    if reach < 1.0:
        assert zero is None and t == t0 + reach * t_hit
    else:
        assert zero is not None and zero.index == 1 and zero.kind == "cross"
        assert abs(zero.t - (t0 + t_hit)) <= 1e-14 + time_resolution(t0)


@pytest.mark.parametrize("offset", [0.0, 100.0])
def test_a_shallow_crossing_far_from_the_origin_is_a_crossing_as_at_the_origin(offset):
    """Issue 34: the graze band's floor is the certified error of the float64 evaluation of
    ψ at the minimum (:meth:`~observer.event.roots.FunctionalSet.errors`), not a count of
    round-offs of ``Σ|r z|``. An oscillator ``q = X + cos t`` (ω = 1, equilibrium X by a
    constant force) with the gap ``g = q − X + 1 − D`` crosses zero by D = 1e-11 near t = π,
    first at ``t* = arccos(D − 1)`` (closed form). Shifting the coordinates by X = 100 m
    raised the old floor ``16·64·eps·Σ|r z|`` to 5.2e-11 > D: the same crossing was taken as
    a touch at the minimum (t = π, 4.5e-6 s late)."""
    depth = 1e-11
    doc = {"scenario": {"name": "far-shallow-crossing"},
           "system": {"M": [[1.0]], "C": [[0.0]], "K": [[1.0]], "W": [[1.0]],
                      "forcing": {"constant": [offset]}, "gap": {"offset": [-offset + 1.0 - depth]}},
           "impact": {"law": "newton", "restitution": 0.5},
           "initial": {"q": [offset + 1.0], "u": [0.0]}, "simulation": {"t_end": 4.0, "h": 0.01}}
    sc = Scenario.from_dict(doc)
    fl = flow_for(sc.system, ())
    z0 = fl.z(0.0, np.concatenate([sc.q0, sc.u0]))
    zero, _, _ = first_zero(fl, fl.gap_rows, 0.0, z0, 4.0, {})
    t_star = np.pi - np.sqrt(2.0 * depth) * (1.0 + depth / 12.0)     # arccos(D − 1), series
    assert zero is not None and zero.kind == "cross"
    assert abs(zero.t - t_star) <= 1e-7
