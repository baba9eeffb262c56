"""Issue 34 item 1: a decision that the float state makes but the data do not is reported in
its event row, with the enclosure. Two uncoupled unit masses fall onto their own stops
(gaps ``g_i = q_i``, gravity 10, Newton e = 0.5): mass 0 lands at t = 0.5 (the trigger)
while mass 1 is still ``d`` above its stop, approaching at 1 m/s. The run's enclosure of the
float state's distance to the exact trajectory (its carried error, ``_Run.err``) is set to
E in mass 1's position: for d ≤ E the data do not tell whether mass 1 lands before or after
mass 0. The carried error decides up to the run's stated accuracy, ``zeno_time_rtol`` times
each contact's reach (the largest |g_j|, |γ_j| of the run so far, ``_Run.reach``:
``_Run.accuracy_caps``). Within both, mass 1 lands together with mass 0, moved onto its stop
(no impulse at an open gap) and the move added to the carried error; beyond the cap (the
reach is 0 unless set) it lands later, in order, and the trigger's row names it as not
ordered by the data; for d > E, or with no carried error, the row says nothing. Likewise a
rebound γ⁺ within the carried error of the relative velocity is a candidate to stick within
the cap, and kept and noted beyond it.
"""

from __future__ import annotations

import numpy as np
import pytest

from observer.event.master import ZENO_VELOCITY_RATIO, _Run
from observer.scenario import Scenario


def two_masses(unit: float = 1.0) -> Scenario:
    """The two masses, lengths in a unit 1/``unit`` of the metre (gravity 10·unit)."""
    doc = {"scenario": {"name": "two masses"},
           "system": {"M": [[1.0, 0.0], [0.0, 1.0]], "C": [[0.0, 0.0], [0.0, 0.0]],
                      "K": [[0.0, 0.0], [0.0, 0.0]], "W": [[1.0, 0.0], [0.0, 1.0]],
                      "forcing": {"constant": [-10.0 * unit, -10.0 * unit]}},
           "impact": {"law": "newton", "restitution": 0.5},
           "initial": {"q": [1.0, 1.0], "u": [0.0, 0.0]},
           "simulation": {"t_end": 1.0, "h": 0.25}}
    return Scenario.from_dict(doc)


def collide_with(x: np.ndarray, carried: dict[int, float], reach=(0.0, 0.0),
                 rtol: float = 1e-9, out: list | None = None, unit: float = 1.0):
    """The impact of mass 0 at t = 0.5 from the state x after the run carried the error
    ``carried`` (component → bound; the componentwise enclosure only, no energy-norm one),
    the run's reach so far ``reach`` (max |g_j|, max |γ_j|, the same for both contacts) and
    ``zeno_time_rtol = rtol``; returns (impacted set, event rows); ``out`` gets
    (x⁺, the carried error after, in metres); ``unit``: the same in lengths of 1/unit m
    (x, the carried error and the reach scaled by it)."""
    run = _Run(two_masses(unit), 0.25, 1.0, 10, ZENO_VELOCITY_RATIO, zeno_time_rtol=rtol)
    run.reach[0], run.reach[1] = np.multiply(reach, unit)
    x = x * unit
    for k, e in carried.items():
        run.err[k] = e * unit
    run.energy.eps = np.inf if carried else 0.0
    x_after, _, A, _, _ = run.collide(0.5, x, (), {0})
    if out is not None:
        out.extend([x_after / unit, run.err / unit])
    return A, run.events


@pytest.mark.parametrize("d", [1e-10, 1e-8, 9.9e-7])
def test_a_later_landing_within_the_carried_error_is_named_in_the_triggers_row(d):
    A, rows = collide_with(np.array([0.0, d, -1.0, -1.0]), {1: 1e-6})
    assert A == [0] and [r[1] for r in rows] == [0]
    note = rows[0][7]
    assert "contact 1 not ordered by the data" in note
    gap, band = note.split("(gap ")[1].split(" within the carried error ±")
    assert float(gap) == pytest.approx(d, rel=1e-2)
    assert float(band.rstrip(")")) >= 1e-6


@pytest.mark.parametrize("d, carried", [(1.01e-6, {1: 1e-6}), (1e-12, {}), (1e-3, {1: 1e-6})])
def test_a_later_landing_the_data_order_leaves_no_note(d, carried):
    A, rows = collide_with(np.array([0.0, d, -1.0, -1.0]), carried)
    assert A == [0] and rows[0][7] == ""


def test_a_receding_contact_within_the_carried_error_is_not_named():
    """Mass 1 moving away from its stop (γ = +1 m/s) does not land: nothing to order."""
    A, rows = collide_with(np.array([0.0, 1e-9, -1.0, 1.0]), {1: 1e-6})
    assert A == [0] and rows[0][7] == ""


@pytest.mark.parametrize("carried, noted", [({2: 1e-8}, True), ({2: 1e-10}, False), ({}, False)])
def test_a_rebound_within_the_carried_velocity_error_is_kept_and_noted(carried, noted):
    """Mass 0 lands at γ⁻ = −1e-9 m/s: γ⁺ = 5e-10 m/s (Newton), kept (a rebound, not a
    stick); with a carried velocity error of 1e-8 m/s the data do not decide it, and its row
    says so with the enclosure; with 1e-10 m/s, or none, they do."""
    A, rows = collide_with(np.array([0.0, 1.0, -1e-9, 0.0]), carried)
    assert A == [0] and [(r[1], r[2]) for r in rows] == [(0, "impact")]
    assert rows[0][4] == pytest.approx(5e-10, rel=1e-6)
    note = rows[0][7]
    assert ("rebound γ⁺ = 5e-10 within the data's carried error ±" in note) == noted
    if noted:
        assert float(note.split("±")[1].split(" ")[0]) >= 1e-8


@pytest.mark.parametrize("unit", [1.0, 1e3, 2.0 ** -20])
@pytest.mark.parametrize("d, rtol", [(5e-10, 1e-9), (9.9e-10, 1e-9), (9e-7, 1e-6)])
def test_a_landing_within_the_carried_error_and_the_stated_accuracy_lands_together(d, rtol, unit):
    """Reach 1 m (both masses fell from 1 m), carried error 1e-6 m: within rtol·1 m mass 1 is
    impacted with mass 0, at its stop: its position after the impact is exactly 0 (M = W = I:
    the move is −d), its velocity Newton's 0.5 m/s (impulse 1.5), and the carried error of its
    position grew by the move. The same in millimetres and in units of 2^20 m."""
    out = []
    A, rows = collide_with(np.array([0.0, d, -1.0, -1.0]), {1: 1e-6}, (1.0, 1.0), rtol, out,
                           unit)
    x_after, err = out
    assert A == [0, 1] and [(r[1], r[2]) for r in rows] == [(0, "impact"), (1, "impact")]
    assert x_after[1] == 0.0 and x_after[0] == 0.0
    assert x_after[3] == pytest.approx(0.5, rel=1e-15)
    assert rows[1][5] == pytest.approx(1.5 * unit)
    assert err[1] >= (1e-6 + d) * (1.0 - 1e-15)
    assert f"landed with the impact: gap {d * unit:.3g} within the carried error ±" in rows[1][7]


@pytest.mark.parametrize("unit", [1.0, 1e3])
@pytest.mark.parametrize("d, rtol, reach", [(1.01e-9, 1e-9, 1.0), (5e-10, 1e-9, 0.49),
                                            (5e-10, 4.9e-10, 1.0)])
def test_a_landing_beyond_the_stated_accuracy_is_ordered_and_noted(d, rtol, reach, unit):
    """Near misses of the cap rtol·reach (by 1 %, 2 %): mass 1 lands later, in order, not
    moved, and the trigger's row says the data do not order it; the same in millimetres."""
    out = []
    A, rows = collide_with(np.array([0.0, d, -1.0, -1.0]), {1: 1e-6}, (reach, 1.0), rtol, out,
                           unit)
    assert A == [0] and [r[1] for r in rows] == [0]
    assert out[0][1] == pytest.approx(d, rel=1e-15)
    assert "contact 1 not ordered by the data" in rows[0][7]


@pytest.mark.parametrize("reach_v, stuck", [(1.0, True), (0.49, False)])
def test_a_rebound_within_the_stated_accuracy_may_stick(reach_v, stuck):
    """γ⁻ = −1e-9 m/s, γ⁺ = 5e-10 m/s, carried velocity error 1e-8 m/s: with a velocity reach
    of 1 m/s (cap 1e-9 m/s) the rebound is a candidate to stick, and gravity holds it
    (a stick row, γ⁺ = 0 after; the approach itself, |γ⁻| within the cap, is a graze with
    its impulse applied); with 0.49 m/s (cap 4.9e-10 m/s, 2 % below γ⁺) it is an impact
    whose rebound is kept and noted."""
    out = []
    A, rows = collide_with(np.array([0.0, 1.0, -1e-9, 0.0]), {2: 1e-8}, (1.0, reach_v), 1e-9, out)
    kinds = [(r[1], r[2]) for r in rows]
    if stuck:
        assert kinds == [(0, "graze"), (0, "stick")] and out[0][2] == 0.0
        assert rows[0][5] == pytest.approx(1.5e-9, rel=1e-6)      # Newton: (1 + e)·|γ⁻|
        assert "rebound" not in rows[0][7]
    else:
        assert kinds == [(0, "impact")] and rows[0][4] == pytest.approx(5e-10, rel=1e-6)
        assert "rebound γ⁺ = 5e-10 within the data's carried error ±" in rows[0][7]


@pytest.mark.parametrize("height, due", [(0.99e-12, True), (1.01e-12, False)])
def test_a_joint_tail_of_a_simultaneous_pair_is_due_at_the_band_an_impact_would_merge(height, due):
    """Both masses just rebounded together from their stops (g = 0, γ⁺ = v, γ̇ = −10): their
    next hop ``v²/20`` against the simultaneity band an impact would merge (the carried
    position error 1e-12 m, within the stated accuracy 1e-3 of a 1 m reach,
    ``_Run.merge_band``). A hop 1 % lower is merged event by event: the joint tail is due (the
    cluster both contacts); 1 % higher, it is not (the location-noise criterion is far off:
    the budget share is 1e-3·0.5/4 s)."""
    from observer.event.tails import joint_due
    run = _Run(two_masses(), 0.25, 1.0, 10, ZENO_VELOCITY_RATIO, zeno_time_rtol=1e-3)
    run.reach[0], run.reach[1] = 1.0, 1.0
    run.err[:2] = 1e-12
    run.energy.eps = np.inf
    v = np.sqrt(20.0 * height)
    cluster = joint_due(run, (0, 1), 0.5, np.array([0.0, 0.0, v, v]), (), [])
    assert cluster == ([0, 1] if due else None)


def test_the_caps_are_the_stated_accuracy_of_the_largest_gap_and_speed_seen():
    """``_Run.accuracy_caps``: rtol times the largest |g_j| and |γ_j| passed so far (the
    reach only grows), 0 for a contact never seen off its stop (and with rtol = inf, not
    nan)."""
    run = _Run(two_masses(), 0.25, 1.0, 10, ZENO_VELOCITY_RATIO, zeno_time_rtol=1e-9)
    run.accuracy_caps(np.array([1.0, 0.0]), np.array([-2.0, 0.0]))
    cap_g, cap_v = run.accuracy_caps(np.array([0.5, 0.0]), np.array([3.0, 0.0]))
    assert cap_g.tolist() == [1e-9 * 1.0, 0.0] and cap_v.tolist() == [1e-9 * 3.0, 0.0]
    run.zeno_time_rtol = np.inf
    cap_g, cap_v = run.accuracy_caps(np.zeros(2), np.zeros(2))
    assert cap_g.tolist() == [np.inf, 0.0] and cap_v.tolist() == [np.inf, 0.0]
