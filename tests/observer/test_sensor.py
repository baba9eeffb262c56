"""χ from a contact sensor (observer/sensor.py, issue 33): each part against what it must do.

The references are independent of the code under test: the grid's own steps (a latency of d
moves χ by d/h steps, rounded), exact rational arithmetic for the sample instants, the
closed-form flight of the bouncing ball for the threshold's crossing time, the master's
closed set for δ = 0, and Poisson counting for the false detections.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pandas as pd
import pytest
from scipy import stats

import observer
from observer.errors import InputError
from observer.scenarios import SCENARIOS
from observer.sensor import Sensor, sense_log, sensed_master_log, seen_closed
from observer.simulate import sensed_scenario
from observer.switching import log_from_active, sample_log

H = 1e-3
T_END = 2.0


@pytest.fixture(scope="module")
def master():
    """double_mass on h = 1 ms for 2 s, both observers, χ from the master (today's run)."""
    return observer.simulate("double_mass", h=H, t_end=T_END, observers="scenario")


def _run(**sensor):
    return observer.simulate("double_mass", h=H, t_end=T_END, observers="scenario", sensor=sensor)


def _same(a, b) -> bool:
    """Every array of two results equal to the bit (master, χ, every observer)."""
    arrays = ["t", "q", "u", "P", "active", "chi"]
    if any(not np.array_equal(getattr(a, k), getattr(b, k)) for k in arrays if getattr(a, k) is not None):
        return False
    return set(a.slaves) == set(b.slaves) and all(
        np.array_equal(a.slaves[s].q, b.slaves[s].q) and np.array_equal(a.slaves[s].u, b.slaves[s].u)
        and np.array_equal(a.slaves[s].V, b.slaves[s].V) for s in a.slaves)


# ------------------------------------------------------------------------- the ideal sensor
@pytest.mark.parametrize("name", list(SCENARIOS))
def test_the_ideal_sensor_is_today_s_run_to_the_bit_on_every_builtin(name):
    sc = observer.load_scenario(name)
    kw = dict(h=sc.h, t_end=40 * sc.h, observers=["nojump"] if not sc.observer else "scenario")
    today = observer.simulate(sc, **kw)
    for sensor in ({}, {"threshold": 0.0, "latency": 0.0, "jitter": 0.0, "missed": 0.0,
                        "false_rate": 0.0, "seed": 7}):
        res = observer.simulate(sc, sensor=sensor, **kw)
        assert _same(today, res) and "sensor" not in res.metadata
    table = observer.simulate(sc.with_overrides({"observer.sensor": {"seed": 3}}), **kw)
    assert _same(today, table)


def test_the_ideal_sensor_leaves_an_ensemble_as_it_was():
    kw = dict(n=3, t_end=0.5, h=H, workers=1)
    today = observer.ensemble("double_mass", **kw)
    pd.testing.assert_frame_equal(today, observer.ensemble("double_mass", sensor={}, **kw))
    assert "sensor" not in observer.ensemble("double_mass", sensor={"seed": 1}, **kw).attrs["metadata"]
    late = observer.ensemble("double_mass", sensor={"latency": H}, **kw)          # the near miss
    assert not np.array_equal(today["V_end"], late["V_end"])
    assert late.attrs["metadata"]["sensor"]["latency"] == H


def test_threshold_zero_sees_exactly_the_master_s_closed_set(master):
    """δ = 0: the seen-closed steps are the master's closed set, and the log made of them
    samples back onto the grid to it; a run through that log (δ = 1e-300, not ideal, so the
    whole sensor pipeline runs) is today's run to the bit."""
    sc = observer.load_scenario("double_mass").with_overrides({"simulation.h": H, "simulation.t_end": T_END})
    plant = observer.simulate(sc)
    seen = seen_closed(plant.t, plant.q, plant.u, plant.active, sc.system, H, 0.0)
    assert np.array_equal(seen, plant.active) and plant.active.any()
    log = sensed_master_log(plant.t, plant.q, plant.u, plant.active, sc.system, H, Sensor())
    assert np.array_equal(sample_log(log, plant.t, 1), plant.active[1:])
    res = _run(threshold=1e-300)
    assert res.metadata["sensor"]["threshold"] == 1e-300
    assert _same(master, res)


# ------------------------------------------------------------------------------- latency
@pytest.mark.parametrize("steps, shift", [(2.3, 2), (2.7, 3), (10.0, 10)])
def test_latency_moves_chi_by_the_latency_rounded_to_whole_steps(master, steps, shift):
    res = _run(latency=steps * H)
    true, seen = master.active[1:], res.chi[1:]
    assert np.array_equal(seen[shift:], true[:-shift])
    assert not seen[:shift].any()
    assert not np.array_equal(seen[shift + 1:], true[:-shift - 1])          # one step off: not it
    assert res.metadata["sensor"]["latency"] == steps * H


def test_latency_shifts_every_interval_of_the_log_by_exactly_d():
    log = pd.DataFrame({"contact": [0, 0, 1], "t_close": [0.1, 0.5, 0.3], "t_open": [0.1, 0.8, 0.3]})
    out = sense_log(log, Sensor(latency=0.0375), m=2, t_end=2.0, h=H)
    ref = log.sort_values(["contact", "t_close"]).reset_index(drop=True)
    assert np.array_equal(out["t_close"], ref["t_close"] + 0.0375)
    assert np.array_equal(out["t_open"], ref["t_open"] + 0.0375)


# ------------------------------------------------------------------------------ sampling
def test_sampling_reports_each_endpoint_at_the_first_sample_at_or_after_it():
    """T = 0.25 s: an endpoint on a sample stays, one between samples moves to the next; an
    impact between two samples is latched (seen as an impact at the next sample); two closings
    within one period merge. Reference: exact rational arithmetic."""
    T = 0.25
    rows = [(0, 0.1, 0.1), (0, 0.75, 1.1), (0, 1.31, 1.32), (0, 1.7, 1.7), (0, 1.75, 1.8)]
    log = pd.DataFrame(rows, columns=["contact", "t_close", "t_open"])
    out = sense_log(log, Sensor(sampling_period=T), m=1, t_end=3.0, h=H)

    def first_sample(t):
        j = -(-Fraction(t) // Fraction(T))                # ceil in exact arithmetic
        j = j - 1 if (j - 1) * Fraction(T) >= Fraction(t) else j
        return float(j * Fraction(T))

    expected = [(first_sample(a), first_sample(b)) for _, a, b in rows]
    merged = []
    for a, b in expected:
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], b))
        else:
            merged.append((a, b))
    assert list(zip(out["t_close"], out["t_open"])) == merged
    assert merged == [(0.25, 0.25), (0.75, 1.25), (1.5, 1.5), (1.75, 2.0)]       # the rule, by hand
    samples = np.round(np.concatenate([out["t_close"], out["t_open"]]) / T, 9)
    assert np.all(samples == np.round(samples))                              # only sample instants


def test_sampling_holds_chi_between_samples_on_the_grid(master):
    """T = 10 h: the observers' χ changes value only at steps next to a sample instant."""
    res = _run(sampling_period=10 * H)
    chi = res.chi[1:, 0]
    change = np.flatnonzero(np.diff(chi.astype(int))) + 1      # first step of a new value
    assert change.size > 4
    assert np.all((change % 10 == 0) | (change % 10 == 1))
    assert not np.array_equal(chi, master.active[1:, 0])


# ----------------------------------------------------------------------------- threshold
def test_a_threshold_closes_the_falling_ball_where_its_closed_form_gap_reaches_delta():
    """Ball dropped from h0 = 1 m: g(t) = h0 − g0 t²/2, so the gap reaches δ at
    t_δ = sqrt(2(h0 − δ)/g0). The first seen closing starts at the first step midpoint past
    t_δ (within one step h), for δ = 0 (the master's impact) and δ = 0.1 m (23 ms earlier)."""
    sc = observer.load_scenario("bouncing_ball").with_overrides({"simulation.t_end": 0.6})
    h0, g0, h = 1.0, 9.81, sc.h
    first = {}
    for delta in (0.0, 0.1, 0.11):
        if delta == 0.0:
            res = observer.simulate(sc)
            log = log_from_active(res.t, res.active)
        else:
            log = sensed_scenario(sc, {"threshold": delta})[0].observer["log"]
        first[delta] = float(log["t_close"].iloc[0])
        t_delta = np.sqrt(2 * (h0 - delta) / g0)
        assert t_delta <= first[delta] < t_delta + h + 1e-6, (delta, first[delta], t_delta)
    assert first[0.1] < first[0.0] - 20 * h
    t_near = np.sqrt(2 * (h0 - 0.1) / g0)                         # 10 % more δ: off by > 2 steps
    assert not (t_near <= first[0.11] < t_near + h + 1e-6)


# -------------------------------------------------------------------- missed and false
def test_missed_one_sees_nothing_and_missed_zero_everything(master):
    none = _run(missed=1.0)
    assert not none.chi[1:].any() and none.metadata["sensor"]["intervals"] == 0
    assert _same(master, _run(missed=0.0))
    half = _run(missed=0.5, seed=4)
    assert 0 < half.metadata["sensor"]["intervals"] < log_from_active(master.t, master.active).shape[0]


def test_false_detections_count_as_a_poisson_process():
    """No true closing, λ = 100/s over 2 s on 3 contacts, 100 seeds: the counts are Poisson
    (λ t_end): their sum within 4σ of 100·λ·t_end (significance 6e-5) and their index of
    dispersion inside the χ²(99) 0.1–99.9 % range. 20 % more λ fails the first test."""
    empty = pd.DataFrame({"contact": pd.Series([], dtype=int), "t_close": [], "t_open": []})
    lam, t_end, seeds = 100.0, 2.0, 100

    def counts(rate):
        out = [sense_log(empty, Sensor(false_rate=rate, seed=s), m=3, t_end=t_end, h=H) for s in range(seeds)]
        for df in out:
            assert (df["t_close"] == df["t_open"]).all() and df["t_close"].between(0, t_end).all()
        return np.array([len(df) for df in out])

    x = counts(lam)
    mu = lam * t_end
    z = (x.sum() - seeds * mu) / np.sqrt(seeds * mu)
    assert abs(z) < 4.0, z
    D = ((x - x.mean()) ** 2).sum() / x.mean()
    assert stats.chi2.ppf(0.001, seeds - 1) < D < stats.chi2.ppf(0.999, seeds - 1), D
    z_more = (counts(1.2 * lam).sum() - seeds * mu) / np.sqrt(seeds * mu)
    assert z_more > 4.0


def test_false_detections_fall_only_where_the_contact_is_open():
    log = pd.DataFrame({"contact": [0], "t_close": [0.5], "t_open": [1.5]})
    out = sense_log(log, Sensor(false_rate=200.0, seed=2), m=1, t_end=2.0, h=H)
    extra = out[(out["t_close"] != 0.5)]
    assert len(extra) > 100
    assert not ((extra["t_close"] > 0.5) & (extra["t_close"] < 1.5)).any()
    assert ((out["t_close"] == 0.5) & (out["t_open"] == 1.5)).sum() == 1


# ----------------------------------------------------------------------- seeds, sources
def test_the_seed_makes_a_sensor_reproducible_and_another_seed_another_log(master):
    a, b, c = (_run(jitter=2e-3, missed=0.2, false_rate=2.0, seed=s) for s in (5, 5, 6))
    assert _same(a, b)
    assert not np.array_equal(a.chi, c.chi)


def test_a_measured_log_passes_through_the_timing_parts_only(tmp_path):
    path = tmp_path / "log.csv"
    pd.DataFrame({"contact": [0, 0], "t_close": [0.2, 0.6], "t_open": [0.2, 0.9]}).to_csv(path, index=False)
    kw = dict(h=H, t_end=1.0, observers=["jump"], source="log", log=str(path))
    res = observer.simulate("double_mass", sensor={"latency": 5e-3}, **kw)
    plain = observer.simulate("double_mass", **kw)
    assert np.array_equal(res.chi[1 + 5:], plain.chi[1:-5])
    assert res.metadata["sensor"]["applied_to"] == "log" and res.metadata["log"] == str(path)
    with pytest.raises(InputError, match="no gap") as info:
        observer.simulate("double_mass", sensor={"threshold": 1e-3}, **kw)
    assert info.value.field == "observer.sensor.threshold"


def test_self_driven_observers_and_an_event_master_refuse_a_sensor():
    with pytest.raises(InputError, match="self-driven") as info:
        observer.simulate("double_mass", t_end=0.01, observers=["jump"], source="self", sensor={"latency": 1e-3})
    assert info.value.field == "observer.sensor"
    with pytest.raises(InputError, match="time-stepping") as info:
        observer.simulate("double_mass", t_end=0.01, observers=["jump"], integrator="event",
                          sensor={"latency": 1e-3})
    assert info.value.field == "observer.sensor"
