"""Hard cases (issue 12 item 5): each runs to the end or stops with a clear status, never
returns NaN, holds its complementarity tolerance (recomputed from the returned states), and
its error against the exact event-driven solution is finite and reported where that
solution is available. cond(W) = 1e10 is refused with an input error naming system.W; the
long horizon runs in summary mode. The same cases as a benchmark kind with a report section:
:mod:`bench.hard` (its systems are built here with the same builders)."""

from __future__ import annotations

import numpy as np
import pytest

import observer
from bench import hard
from observer.errors import InputError
from observer.scenario import Scenario
from observer.validation import W_SV_RTOL


def _two_mass(m2: float, k2: float, h: float, t_end: float) -> Scenario:
    """Two masses in series (:func:`bench.hard.two_mass`): stiffness ratio k2/k1 and mass
    ratio m2/m1 set the difficulty."""
    doc = hard.two_mass(m2=m2, k2=k2)
    doc["simulation"].update(h=h, t_end=t_end)
    return Scenario.from_dict(doc, f"two_mass m2={m2:g} k2={k2:g}")


def _bed(n: int, h: float, t_end: float) -> Scenario:
    """n masses dropped together onto n stops (:func:`bench.hard.bed`)."""
    doc = hard.bed(n)
    doc["simulation"].update(h=h, t_end=t_end)
    return Scenario.from_dict(doc, f"bed of {n}")


def _sane(res) -> None:
    """No NaN anywhere, a status, and Newton's discrete law recomputed on every impulse step."""
    for arr in (res.q, res.u, res.P):
        assert np.all(np.isfinite(arr))
    assert res.status.state.value in ("ok", "fallback", "stopped")
    if res.status.state.value == "stopped":
        assert res.status.reason
    sysm = res.system
    gamma = res.u @ sysm.W + sysm.nu_dot(res.t)
    e = np.broadcast_to(np.asarray(res.metadata["restitution"], float), (sysm.m,))
    k = np.flatnonzero(res.P[1:].any(axis=1))
    for kk in k:
        act = res.P[kk + 1] > 0
        lhs = gamma[kk + 1, act] + e[act] * gamma[kk, act]
        scale = max(1.0, float(np.max(np.abs(gamma[kk, act]))))
        assert np.max(np.abs(lhs)) <= 1e-8 * scale, (kk, lhs)


def _event_error(sc: Scenario, res) -> float:
    ev = observer.simulate(sc, integrator="event")
    assert np.array_equal(ev.t.shape, res.t.shape) and ev.status.ok
    return float(np.max(np.abs(ev.q - res.q)))


def test_stiffness_ratio_1e8():
    """k2/k1 = 1e8 at h = 1e-3 (h·ω_max ≈ 100): time-stepping runs to the end, sane, and warns
    that its numbers mean little. (The exact reference is out of reach here: the certified
    root search steps ~1/ω_max, and stopped with "root isolation stalled near t = 0.179 (200000
    safe steps)" after 135 s in a measured run; a clear stop, too slow for the suite.)"""
    sc = _two_mass(1.0, 1e10, 1e-3, 0.5)
    res = observer.simulate(sc)
    _sane(res)
    assert any("ω" in w for w in res.status.warnings), res.status


def test_mass_ratio_1e6():
    sc = _two_mass(1e6, 100.0, 1e-3, 0.5)
    res = observer.simulate(sc)
    _sane(res)
    assert np.isfinite(_event_error(sc, res))


@pytest.mark.parametrize("h", [1e-2, 1e-3, 1e-5, 1e-7])
def test_step_sizes_from_1e_2_to_1e_7_on_the_ball(h):
    t_end = 0.5 if h >= 1e-5 else 0.46          # the first impact (t = 0.4515 s) included
    sc = observer.load_scenario("bouncing_ball", {"simulation.h": h, "simulation.t_end": t_end})
    res = observer.simulate(sc, record_every=1 if h >= 1e-5 else 100)
    _sane(res)
    err = _event_error(sc.with_overrides({"simulation.h": float(res.t[1] - res.t[0])}), res) \
        if h >= 1e-5 else None
    if err is not None:
        assert err <= 20 * h                   # first order, constant ≈ |u| at impact
    assert res.u[-1, 0] > 0                    # the impact happened: moving up at the end


def test_two_hundred_contacts_closing_at_once():
    sc = _bed(200, 1e-3, 0.2)
    res = observer.simulate(sc)
    _sane(res)
    first = np.flatnonzero(res.active[1:].any(axis=1))[0] + 1
    assert res.active[first].sum() == 200      # all 200 close in the same step
    assert res.metadata["solver_fallbacks"] == 0


@pytest.mark.parametrize("e", [0.99, 0.01])
def test_zeno_with_extreme_restitution(e):
    sc = observer.load_scenario("bouncing_ball", {"impact.restitution": e, "simulation.t_end": 3.0,
                                                  "simulation.h": 1e-3})
    res = observer.simulate(sc)
    _sane(res)
    ev = observer.simulate(sc, integrator="event")
    assert ev.status.ok and ev.metadata["events"] > 0
    err = float(np.max(np.abs(ev.q - res.q)))
    assert np.isfinite(err) and err < 0.1


def test_grazing_every_period():
    sc = observer.load_scenario("grazing", {"simulation.t_end": 60.0})
    res = observer.simulate(sc)
    _sane(res)
    ev = observer.simulate(sc, integrator="event")
    grazes = ev.events[ev.events.kind == "graze"]
    assert len(grazes) >= 8                    # one per forcing period (H1: 8 in 60 s)
    assert np.isfinite(float(np.max(np.abs(ev.q - res.q))))


def test_cond_W_1e10_is_refused_naming_system_W():
    """cond(W) = 1e10 (σ_min/σ_max = 1e-10 < √ε): the Delassus matrices WᵀÂ⁻¹W would have
    cond ≈ 1e20, numerically singular, so no step could hold the residual. The right answer is
    a clear input error naming system.W, before any step; just above the threshold the same
    system runs, sane."""
    with pytest.raises(InputError) as info:
        Scenario.from_dict(hard.dependent_w(1e-10), "cond(W) 1e10")
    assert info.value.field == "system.W" and "nearly dependent" in str(info.value)
    sc = Scenario.from_dict(hard.dependent_w(100 * W_SV_RTOL), "cond(W) near the threshold")
    s = np.linalg.svd(sc.system.W, compute_uv=False)
    assert np.isclose(s[-1] / s[0], 100 * W_SV_RTOL, rtol=1e-6)
    _sane(observer.simulate(sc))


def test_long_horizon_in_summary_mode():
    """10⁶ steps of the forced impact oscillator in summary mode (the bench's hard case runs
    10⁸, ≈ 30 s): to the end, no NaN, the rows every 0.1 s, the deepest penetration the kernel
    saw over every step not below the one seen on the recorded rows, and the recorded rows
    within 1e-3 of the exact event solution over the first 20 s (measured 3.8e-4; later the
    two trajectories separate, 1e-2 at 40 s and O(1) after 60 s: the impact sequence of the
    forced oscillator is sensitive to its impact phases)."""
    h, T, every = 1e-4, 100.0, 1000
    sc = observer.load_scenario("impact_oscillator", {"simulation.h": h, "simulation.t_end": T})
    res = observer.simulate(sc, store="summary", record_every=every)
    assert res.status.ok and res.metadata["steps"] == 1_000_000
    for arr in (res.q, res.u, res.P):
        assert np.all(np.isfinite(arr))
    assert np.allclose(np.diff(res.t), every * h, rtol=0, atol=1e-9)
    pen_rows = max(0.0, -float(np.min(sc.system.gaps(res.q, res.t))))
    assert res.metadata["health"]["penetration"] >= pen_rows
    first = res.t <= 20.0
    ev = observer.simulate(sc.with_overrides({"simulation.h": every * h, "simulation.t_end": 20.0}),
                           integrator="event")
    assert ev.status.ok
    assert np.max(np.abs(ev.q - res.q[first])) <= 1e-3
