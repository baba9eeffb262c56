"""The robustness suite's paired ensembles (bench/perturb.py): a member's floor recomputed from its
own run (the master it belongs to, that master's sensed χ, its initial error), and the pairing
(every design and level on the same masters and initial errors)."""

from __future__ import annotations

import numpy as np
import pytest

import observer
from bench.perturb import TAIL, perturb_log, robustness_case_rows, sensor_of
from bench.runners import _ensemble_masters
from bench.suites import Case
from observer import Slave
from observer.observers import OBSERVER_DESIGNS
from observer.switching import log_from_active

H, T = 1e-3, 1.0


def case(kind="none", size=0.0) -> Case:
    return Case("robustness", "double_mass", h=H, t_end=T, perturbation=kind, size=size, masters=2, members=4)


def rows_and_masters(c: Case):
    sc = observer.load_scenario(c.scenario, c.overrides())
    masters = _ensemble_masters(c, sc)
    return robustness_case_rows(c, masters), masters


def own_floor(sc, design: str, x: np.ndarray, sensor: dict | None) -> float:
    """The member's floor from a run of its own: one observer from the master's state + x with χ
    from ``sensor`` on this master, the median of V/V(t_on) over the last TAIL of [0, T]."""
    n = sc.system.n
    d = OBSERVER_DESIGNS[design]
    res = observer.simulate(sc, observers=[Slave(design, d.position_jumps, sc.q0 + x[:n], sc.u0 + x[n:], d)],
                            sensor=sensor)
    t, V = np.asarray(res.t), np.asarray(res.slaves[design].V)
    tail = (t >= (1 - TAIL) * T - 1e-12)
    return float(np.median(V[tail]) / V[0])


def test_floor_of_a_member_of_the_second_master_is_that_of_its_own_run(tmp_path):
    """Latency 5 ms (deterministic): the row of a member of master 1 (not the scenario's own)
    has the floor of that member run alone against master 1 with master 1's own sensed χ (a
    latency applied to master 0's log instead changes it)."""
    c = case("delay", 5e-3)
    rows, masters = rows_and_masters(c)
    assert len(rows) == 2 * c.members and {r["master"] for r in rows} == {0, 1}
    sc1 = masters[1][0]
    nd = sc1.system.n
    checked = 0
    for r in rows:
        if r["master"] != 1 or r["member"] % 2:
            continue
        x = np.array([r[f"dq0_{j}"] for j in range(nd)] + [r[f"du0_{j}"] for j in range(nd)])
        sensor = sensor_of("delay", 5e-3, r["sensor_seed"])
        assert r["floor"] == pytest.approx(own_floor(sc1, r["design"], x, sensor), rel=1e-9)
        checked += 1
    assert checked == 2
    # the known-bad: master 0's sensed χ (the scenario's) driving master 1's observers
    res0 = observer.simulate(masters[0][0])
    log0 = perturb_log(log_from_active(res0.t, res0.active), "delay", 5e-3, seed=0, m=1, t_end=T, h=H)
    path = tmp_path / "log0.csv"
    log0.to_csv(path, index=False, float_format="%.17g")
    r = next(r for r in rows if r["master"] == 1 and r["design"] == "jump")
    x = np.array([r[f"dq0_{j}"] for j in range(nd)] + [r[f"du0_{j}"] for j in range(nd)])
    d = OBSERVER_DESIGNS["jump"]
    res = observer.simulate(sc1, observers=[Slave("jump", d.position_jumps, sc1.q0 + x[:nd], sc1.u0 + x[nd:], d)],
                            source="log", log=path)
    t, V = np.asarray(res.t), np.asarray(res.slaves["jump"].V)
    wrong = float(np.median(V[t >= (1 - TAIL) * T - 1e-12]) / V[0])
    assert wrong != pytest.approx(r["floor"], rel=1e-3)


def test_designs_and_levels_are_paired_on_the_same_masters_and_errors():
    """Both designs and both levels (ideal sensor, 5 ms latency) carry the same (master, member)
    initial errors; the masters differ from one another."""
    a, masters = rows_and_masters(case())
    b, _ = rows_and_masters(case("delay", 5e-3))
    key = lambda r: (r["master"], r["member"])            # noqa: E731
    err = lambda r: (r["dq0_0"], r["dq0_1"], r["du0_0"], r["du0_1"])   # noqa: E731
    by = {}
    for r in a + b:
        by.setdefault(key(r), set()).add(err(r))
    assert len(by) == 4 and all(len(v) == 1 for v in by.values())
    assert {r["design"] for r in a} == {"jump", "nojump"}
    assert not np.allclose(masters[0][0].q0, masters[1][0].q0)
    assert {r["sensor_seed"] for r in b} == {0, 1} and {r["sensor_seed"] for r in a} == {-1}


def test_each_master_s_sensor_draws_with_its_own_seed():
    """Jitter 2 ms (random): master 1's member has the floor of its own run with the sensor seeded
    1000·(case seed) + 1 (bench.perturb.sensor_seed), not with master 0's seed."""
    c = case("jitter", 2e-3)
    rows, masters = rows_and_masters(c)
    sc1 = masters[1][0]
    r = next(r for r in rows if r["master"] == 1 and r["design"] == "jump")
    assert r["sensor_seed"] == 1
    x = np.array([r["dq0_0"], r["dq0_1"], r["du0_0"], r["du0_1"]])
    assert r["floor"] == pytest.approx(own_floor(sc1, "jump", x, sensor_of("jitter", 2e-3, 1)), rel=1e-9)
    assert r["floor"] != pytest.approx(own_floor(sc1, "jump", x, sensor_of("jitter", 2e-3, 0)), rel=1e-6)
