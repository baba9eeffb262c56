"""A stop loses nothing (issue 34, item 4): a stalled search, an event cap, a signal keep every
finished grid row and event before the stop, with the status; ``simulate(t0=…)`` shifts the
time origin. Expected values are closed forms written here (the harmonic oscillator, the
bouncing ball)."""

from __future__ import annotations

import numpy as np
import pytest

import observer
import observer.event.roots as roots
from observer.errors import InputError
from observer.event.master import run_master
from observer.result import RunState, RunStatus
from observer.scenario import Scenario

G0 = 9.81


def quiet_oscillator(t_end: float = 1e5, w: float = 1e3) -> Scenario:
    """x'' + ω²x = 0 from x = 1, a wall 9 below the orbit's lowest point (g = x + 10 > 0):
    a quiet phase of t_end seconds, every window of the search 0.5/ω long."""
    doc = {"scenario": {"name": "quiet"},
           "system": {"M": [[1.0]], "C": [[0.0]], "K": [[w * w]], "W": [[1.0]],
                      "gap": {"offset": [10.0]}},
           "impact": {"law": "newton", "restitution": 0.5},
           "initial": {"q": [1.0], "u": [0.0]},
           "simulation": {"t_end": t_end, "h": 1e-2}}
    return Scenario.from_dict(doc)


def test_a_stalled_quiet_phase_keeps_every_row_up_to_the_stall(monkeypatch):
    """The 1e5 s quiet phase stalls the search (MAX_STEPS safe steps; lowered here so that the
    stall comes after ~1 s instead of ~100 s): the rows up to the stall are the closed form
    cos(ωt), none is lost, none is NaN, and the status says it stalled."""
    monkeypatch.setattr(roots, "MAX_STEPS", 2000)
    w = 1e3
    res = run_master(quiet_oscillator(w=w))
    assert str(res.status).startswith("stopped: root isolation stalled")
    t_stall = float(str(res.status).split("near t = ")[1].split(" ")[0])
    assert t_stall > 0.5                              # 2000 windows of 0.5/ω at least
    t = res.t
    assert t.size >= int(t_stall / 1e-2)              # every grid row before the stall
    assert t[-1] <= t_stall < t[-1] + 1e-2 + 1e-12
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.u))
    assert np.max(np.abs(res.q[:, 0] - np.cos(w * t))) <= 1e-11
    assert np.max(np.abs(res.u[:, 0] + w * np.sin(w * t))) <= 1e-8


def test_a_stalled_run_through_simulate_keeps_its_rows(monkeypatch):
    monkeypatch.setattr(roots, "MAX_STEPS", 1000)
    res = observer.simulate(quiet_oscillator(), integrator="event")
    assert not res.status.ok and "stalled" in res.status.reason
    assert len(res.t) > 10 and np.isfinite(res.q).all()


def test_the_masters_stop_is_a_status_from_where_it_stopped(monkeypatch):
    """The exact master decides its :class:`RunStatus` where it stops (state, reason; no
    "stopped: …" string to parse): the run's status says it is the master's stop, the
    metadata keeps the master's own; a non-finite stop names the master's quantity itself."""
    monkeypatch.setattr(roots, "MAX_STEPS", 1000)
    master = run_master(quiet_oscillator())
    assert isinstance(master.status, RunStatus) and master.status.state is RunState.STOPPED
    assert master.status.reason.startswith("root isolation stalled") and not master.nonfinite
    res = observer.simulate(quiet_oscillator(), integrator="event")
    assert res.status == RunStatus(RunState.STOPPED, f"master: {master.status.reason}")
    assert res.metadata["master_status"] == f"stopped: {master.status.reason}"
    ok = run_master(ball(t_end=0.5))
    assert ok.status == RunStatus() and str(ok.status) == "ok"


def ball(height: float = 1.0, e: float = 0.5, t_end: float = 1.0) -> Scenario:
    doc = {"scenario": {"name": "ball"},
           "system": {"M": [[1.0]], "C": [[0.0]], "K": [[0.0]], "W": [[1.0]],
                      "forcing": {"constant": [-G0]}, "gap": {"offset": [0.0]}},
           "impact": {"law": "newton", "restitution": e},
           "initial": {"q": [height], "u": [0.0]},
           "simulation": {"t_end": t_end, "h": 1e-2}}
    return Scenario.from_dict(doc)


def ball_impacts(height: float, e: float, count: int) -> np.ndarray:
    t, v, out = np.sqrt(2 * height / G0), np.sqrt(2 * G0 * height), []
    for _ in range(count):
        out.append(t)
        v *= e
        t += 2 * v / G0
    return np.array(out)


def test_an_event_cap_keeps_the_events_before_it():
    res = run_master(ball(t_end=2.0), max_events=4)
    assert str(res.status).startswith("stopped: event cap 4")
    impacts = res.impact_times()
    assert impacts.size == 4
    assert np.max(np.abs(impacts - ball_impacts(1.0, 0.5, 4))) <= 1e-12
    assert res.t[-1] < impacts[-1] + 0.5 and np.isfinite(res.q).all()


def test_t0_shifts_the_time_origin_of_an_event_run():
    """The ball from t0 = 1000: the grid starts at t0, every impact is t0 + the closed form."""
    T = 1000.0
    sc = ball(t_end=T + 1.5)
    res = observer.simulate(sc, integrator="event", t0=T)
    assert res.status.ok
    assert res.t[0] == T and res.t[-1] == pytest.approx(T + 1.5)
    assert res.q[0, 0] == 1.0
    impacts = np.sort(res.events.query("kind == 'impact'").time.to_numpy())[:4]
    assert np.max(np.abs(impacts - (T + ball_impacts(1.0, 0.5, 4)))) <= 1e-12 * T
    assert res.metadata["t0"] == T


def test_t0_is_refused_by_time_stepping_and_after_t_end():
    with pytest.raises(InputError) as err:
        observer.simulate(ball(), t0=1.0)
    assert err.value.field == "t0"
    with pytest.raises(InputError) as err:
        observer.simulate(ball(t_end=1.0), integrator="event", t0=2.0)
    assert err.value.field == "t0"
