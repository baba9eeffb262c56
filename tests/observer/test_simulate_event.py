"""observer.simulate(integrator="event"): the exact integrator behind the public API, and
the approximate event table of time-stepped runs."""

from __future__ import annotations

import numpy as np
import pytest

import observer
from observer.result import EVENT_COLUMNS
from observer.scenarios.bouncing_ball import accumulation_time, impact_times


def test_event_run_through_simulate_matches_the_closed_form_ball():
    sc = observer.load_scenario("bouncing_ball", {"simulation.t_end": 5.0})
    res = observer.simulate(sc, integrator="event")
    assert res.status.ok and res.metadata["integrator"] == "event"
    assert tuple(res.events.columns) == EVENT_COLUMNS
    imp = res.events[res.events.kind == "impact"].time.to_numpy()
    ref = impact_times(1.0, 9.81, 0.8, 30)          # docs/theory/oracles.md §1 closed form
    np.testing.assert_allclose(imp[:30], ref, rtol=0, atol=1e-12)
    acc = res.events[res.events.kind == "accumulation"].time.to_numpy()
    assert acc.size == 1 and abs(acc[0] - accumulation_time(1.0, 9.81, 0.8)) <= 1e-9
    # at rest after the accumulation: on the ground, not moving
    after = res.t > acc[0] + 1e-6
    assert np.max(np.abs(res.q[after])) <= 1e-12 and np.max(np.abs(res.u[after])) <= 1e-12


def _error(ev, ts):
    return float(np.mean(np.max(np.abs(ev.q - ts.q), axis=1)))


def test_time_stepping_converges_at_first_order_to_the_event_solution():
    """Fitted over five step sizes (halving): order ≈ 1 on the ball (measured 1.06)."""
    sc = observer.load_scenario("bouncing_ball", {"simulation.t_end": 3.0})
    hs = [2e-3 / 2 ** j for j in range(5)]
    err = [_error(observer.simulate(sc, h=h, integrator="event"), observer.simulate(sc, h=h))
           for h in hs]
    order = np.polyfit(np.log(hs), np.log(err), 1)[0]
    assert 0.9 <= order <= 1.2, (err, order)


def test_event_observers_agree_with_time_stepping_as_h_shrinks():
    """double_mass (Newton) with both observers: the same grid and V(t_on), and the master's
    error against the event solution shrinks with h (by ≥ 4× over a 16× smaller h; the fitted
    order there is 0.77, impact-time errors depend on where the grid falls)."""
    sc = observer.load_scenario("double_mass", {"simulation.t_end": 2.0, "impact.law": "newton"})
    err = []
    for h in (2e-3, 1.25e-4):
        ev = observer.simulate(sc, h=h, integrator="event", observers=("jump", "nojump"))
        ts = observer.simulate(sc, h=h, observers=("jump", "nojump"))
        assert np.array_equal(ev.t, ts.t)
        err.append(_error(ev, ts))
        for name in ("jump", "nojump"):
            assert ev.slaves[name].V[0] == pytest.approx(ts.slaves[name].V[0], rel=1e-12)
    assert err[1] < err[0] / 4, err


def test_time_stepping_fills_the_event_table_from_its_closing_steps():
    sc = observer.load_scenario("impact_oscillator", {"simulation.t_end": 10.0})
    res = observer.simulate(sc)
    ev = res.events
    assert tuple(ev.columns) == EVENT_COLUMNS and (ev.kind == "impact").sum() >= 3
    gamma = res.u @ sc.system.W + sc.system.nu_dot(res.t)
    for row in ev[ev.kind == "impact"].itertuples():
        k = int(np.flatnonzero(res.t == row.time)[0])
        assert row.impulse == res.P[k + 1, row.contact] > 0
        assert row.gamma_plus == gamma[k + 1, row.contact]
        # Newton's discrete law, recomputed: γ_{k+1} + e γ_k = 0 on an impact step
        e = sc.law.restitution[row.contact]
        assert abs(row.gamma_plus + e * row.gamma_minus) <= 1e-12 * max(1.0, abs(row.gamma_minus))


@pytest.mark.parametrize("option", [{"engine": "python"}, {"record_every": 2}, {"store": "summary"},
                                    {"solver": "lemke"}])
def test_event_integrator_refuses_time_stepping_options(option):
    with pytest.raises(observer.InputError) as info:
        observer.simulate("bouncing_ball", t_end=0.1, integrator="event", **option)
    assert info.value.field in ("engine", "record_every", "store", "simulation.solver")


def test_unknown_integrator_is_named():
    with pytest.raises(observer.InputError, match="integrator"):
        observer.simulate("bouncing_ball", t_end=0.1, integrator="rk4")


def test_event_observers_driven_by_a_log_of_the_masters_exact_intervals(tmp_path):
    """source="log" with the master's exact closed intervals written to a CSV gives the same
    observers as source="master" (to round-off: the times pass through a %.17g text file)."""
    import pandas as pd
    from observer.event.master import run_master

    sc = observer.load_scenario("double_mass", {"simulation.t_end": 3.0, "impact.law": "newton",
                                                "simulation.h": 1e-3})
    master = run_master(sc)
    rows = [(j, a, b) for j in range(sc.system.m) for a, b in master.intervals(j) if np.isfinite(b)]
    rows += [(j, a, sc.t_end) for j in range(sc.system.m) for a, b in master.intervals(j) if not np.isfinite(b)]
    log = tmp_path / "exact.csv"
    pd.DataFrame(rows, columns=["contact", "t_close", "t_open"]).sort_values(["contact", "t_close"]) \
        .to_csv(log, index=False, float_format="%.17g")
    by_master = observer.simulate(sc, integrator="event", observers=("jump", "nojump"))
    by_log = observer.simulate(sc, integrator="event", observers=("jump", "nojump"), source="log", log=log)
    assert by_log.metadata["source"] == "log"
    for name in ("jump", "nojump"):
        np.testing.assert_allclose(by_log.slaves[name].V, by_master.slaves[name].V, rtol=1e-9, atol=1e-15)
    with pytest.raises(observer.InputError) as info:
        observer.simulate(sc, integrator="event", observers=("jump",), source="self")
    assert info.value.field == "observer.source"
