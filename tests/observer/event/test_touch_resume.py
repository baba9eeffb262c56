"""A touch at a minimum resumes the search after the minimum (issue 34: "no progress" stalls).

The system is the 3-DOF, 2-contact plastic (e = 0) case ``impacting-0`` that hypothesis
generated in tests/observer/test_properties.py (its numbers, dumped to 17 digits). After each
plastic impact the contact's gap has a minimum at the impact time itself (ψ ≈ 0, ψ' ≈ 0,
ψ'' > 0): a touch whose minimum lies closer than the time resolution. Its resume was capped at
``a + 2s_m`` (s_m = −ψ'/ψ'' in float64), which rounds to the touch's own time: the same touch
was taken again and again, and on an AVX-512 machine the run stopped with "master: no
progress, 50 events at t = 0.20937296154758017 (contact 0, a degenerate contact state)".

The checks are against an independent 30-digit reference of the exact flow (:mod:`mp_exact`).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import mpmath as mp
import numpy as np

import observer
import observer.event.master as master
from observer.event.frame import GapFrame
from observer.event.master import run_master
from observer.scenario import Scenario

_spec = importlib.util.spec_from_file_location("mp_exact", Path(__file__).with_name("mp_exact.py"))
mp_exact = importlib.util.module_from_spec(_spec)        # the reference beside this file (the
_spec.loader.exec_module(mp_exact)                       # tests run in importlib mode)
Reference = mp_exact.Reference

DOC = {
    "scenario": {"name": "impacting-0"},
    "system": {
        "M": [[0.6478003182007351, 0.10517576922849227, -0.1372832573686061],
              [0.10517576922849227, 0.6428988985521774, -0.20833322986130354],
              [-0.1372832573686061, -0.20833322986130354, 1.5308739168458454]],
        "C": [[0.08485299890136783, -0.011745165163644341, 0.03769802787959607],
              [-0.011745165163644341, 0.16221771329056364, 0.060711669799389974],
              [0.03769802787959607, 0.060711669799389974, 0.09185918767026052]],
        "K": [[43.191173193409824, 50.45037716235571, 20.87963574132862],
              [50.45037716235571, 126.76553306181766, 36.9284215142778],
              [20.87963574132862, 36.9284215142778, 25.541318468406928]],
        "W": [[-0.9217253762584194, -0.45772582566733916],
              [0.2201951234700494, -1.009618183538736],
              [-0.20917557487171307, -0.15922500991447772]],
        "forcing": {"constant": [2.4458558850721808, 0.9204599029488024, 0.6294927141303069]},
        "gap": {"offset": [0.23793606708029374, 0.07157081942581073]}},
    "impact": {"law": "newton", "restitution": 0.0},
    "initial": {"q": [0.05408455846858077, 0.02146591225063409, 0.03553727090399214],
                "u": [1.127801870756062, 0.1070800781707883, 1.0173651763338867]},
    "simulation": {"t_end": 0.32, "h": 0.02}}

TIME_TOL = 1e-12
"""Impact times against the reference: the engine isolates each root to its time resolution
(two ulp of t); the impact states carry the flow's rounding."""
STATE_TOL = 1e-12
"""The state at t_end against the reference."""


def _scenario() -> Scenario:
    return Scenario.from_dict(DOC)


def repeated_touches(events) -> list:
    """(time, contact) pairs with more than one graze row: the same functional taken again at
    the same time (the stall's signature)."""
    grazes = events[events["kind"] == "graze"]
    counts = grazes.groupby(["time", "contact"]).size()
    return [k for k, v in counts.items() if v > 1]


def test_the_plastic_impacts_run_to_t_end_as_the_reference_says():
    """The run ends ok at t_end (before the fix, on this machine: "no progress, 50 events" at
    the second impact); its impacts are the reference's two, at its times, with γ⁻ and the
    plastic law's γ⁺ = 0; no contact is touched twice at one time, and every graze row is a
    plastic impact's γ⁺ = 0 minimum (at an impact of its contact); the gaps recomputed from the
    returned q stay non-negative and the state at t_end is the reference's."""
    sc = _scenario()
    ref = Reference(sc.system, sc.law.restitution, sc.q0, sc.u0)
    ref_events = ref.run(sc.t_end)
    assert [(k, c) for _, k, c, *_ in ref_events] == [("impact", 1), ("impact", 0)]
    res = observer.simulate(sc, integrator="event")
    assert res.status.ok, res.status
    assert res.t[-1] == sc.t_end
    ev = res.events
    assert repeated_touches(ev) == []
    imp = ev[ev["kind"] == "impact"]
    assert imp["contact"].tolist() == [1, 0]
    t_ref = np.array([float(e[0]) for e in ref_events])
    np.testing.assert_allclose(imp["time"].to_numpy(dtype=float), t_ref, rtol=0, atol=TIME_TOL)
    gm_ref = np.array([float(e[3]) for e in ref_events])
    np.testing.assert_allclose(imp["gamma_minus"].to_numpy(dtype=float), gm_ref, rtol=1e-11)
    gp = imp["gamma_plus"].to_numpy(dtype=float)
    assert np.all(np.abs(gp) <= 1e-14 * np.abs(gm_ref))      # e = 0: γ⁺ = 0 to round-off
    assert np.all(imp["impulse"].to_numpy(dtype=float) > 0.0)
    for _, row in ev[ev["kind"] == "graze"].iterrows():
        assert abs(row.time - t_ref[[c for _, _, c, *_ in ref_events].index(row.contact)]) <= TIME_TOL
    W, nu = sc.system.W, sc.system.gap.constant
    gaps = res.q @ W + nu                                     # from the returned state alone
    assert gaps.min() >= -1e-12
    x_ref = np.array([float(v) for v in ref.z[:2 * sc.system.n]])
    np.testing.assert_allclose(np.concatenate([res.q[-1], res.u[-1]]), x_ref, rtol=0, atol=STATE_TOL)


def test_a_touch_resumes_after_its_minimum_with_the_gap_above_its_band(monkeypatch):
    """Every touch the search returns in this run resumes strictly after its time, and the
    gap of the exact flow from the touch's state (the 30-digit reference, in the run's frame)
    is above twice the touch band at the resume and not below −band in between: the resume
    is certified. Before the fix the resume was the touch's own time (ψ ≈ −2.8e-16 there)."""
    touches = []
    search = master.first_zero

    def recording(flow, rows, *args, **kwargs):
        out = search(flow, rows, *args, **kwargs)
        if out[0] is not None and out[0].kind == "touch":
            touches.append((flow, rows, out[0]))
        return out

    monkeypatch.setattr(master, "first_zero", recording)
    run_sc = _run_scenario()
    res = run_master(run_sc)
    assert res.status.ok, res.status
    assert touches, "no touch: the case no longer exercises the resume"
    free = master.flow_for(run_sc.system, ())
    for flow, rows, zero in touches:
        j = next(c for c in range(run_sc.system.m) if np.array_equal(rows[zero.index], flow.gap_rows[c]))
        assert np.array_equal(flow.A, free.A)           # no contact held: the free flow
        _assert_certified_resume(run_sc, flow.x_of(zero.z), zero, j)


POST_IMPACT = (0.20937296154758017,
               [-0.05680061389303372, -0.13856703149932875, 0.10442319862531237,
                -0.2381515950832827, -0.6476467517086224, 0.3676419303467368])
"""The state (in the run's frame) right after contact 0's plastic impact, as the engine
before the fix computed it on an AVX-512 machine: gap 0 = −1.8e-18, its float64 slope
exactly 0.0, ψ'' ≈ 4 — a minimum at t that the slope cannot place."""


def test_a_zero_float64_slope_at_a_minimum_is_a_touch_that_resumes_after_it():
    """From POST_IMPACT the search's first zero is contact 0's touch at t, resuming strictly
    after t with the gap of the reference flow above twice its band there. Before the fix
    (convex minima only for a float64 slope ψ' < 0) it was a crossing at t itself, an impact
    whose γ⁻ = 0 collide labels a graze and leaves the state as it was: 50 times."""
    from observer.event.roots import first_zero, functional_set

    run_sc = _run_scenario()
    t, x = POST_IMPACT[0], np.array(POST_IMPACT[1])
    flow = master.flow_for(run_sc.system, ())
    z = flow.z(t, x)
    d = functional_set(flow, flow.gap_rows).derivatives(z)   # what the search sees
    assert d[0, 0] < 0.0 and d[1, 0] == 0.0 and d[2, 0] > 0.0                 # the degenerate state
    zero, _, _ = first_zero(flow, flow.gap_rows, t, z, run_sc.t_end)
    assert zero is not None and zero.kind == "touch" and zero.index == 0 and zero.t == t
    _assert_certified_resume(run_sc, flow.x_of(zero.z), zero, 0)


def _run_scenario() -> Scenario:
    """The scenario in the frame the event engine runs it in (:class:`GapFrame`)."""
    sc = _scenario()
    frame = GapFrame.for_scenario(sc)
    return sc if frame is None else frame.scenario(sc)


def _assert_certified_resume(run_sc: Scenario, x: np.ndarray, zero, j: int) -> None:
    """The touch ``zero`` of contact j's gap from state x: resume strictly after it, the
    reference gap above 2·band at the resume and not below −band in between."""
    assert zero.resume > zero.t
    n = run_sc.system.n
    ref = Reference(run_sc.system, run_sc.law.restitution, x[:n], x[n:], t0=zero.t)
    with mp.workdps(ref.dps):
        A = ref.A([])
        row = ref.gap_rows()[j]
        span = mp.mpf(zero.resume) - mp.mpf(zero.t)
        at_resume = row @ ref._at(A, ref.z, span)
        assert at_resume > 2 * zero.band, (zero.t, zero.resume, at_resume, zero.band)
        for k in range(1, 16):
            assert row @ ref._at(A, ref.z, span * k / 16) >= -zero.band
