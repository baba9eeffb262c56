"""Benchmark (pytest-benchmark): an ensemble in one pass against separate runs.

The acceptance case of issue 22: double_mass, :data:`MEMBERS` initial errors (energy sphere,
seed 0) × {jump, nojump}, 10 s at h = 2e-4 (50 000 steps):

* ``test_ensemble_one_pass`` — :func:`observer.ensemble` (``store="summary"``): the master
  run once, then every member alone over the grid (:mod:`observer.members`), the members in
  one chunk per core (threads);
* ``test_separate_calls[summary]`` / ``[full]`` — one :func:`observer.simulate` per member with
  its two observers (the same initial states), in the same process, ``store="summary"`` (the
  same summary per call) or the default ``store="full"``;
* ``test_mismatch_ensemble`` — the same ensemble with the observers on a model whose K is
  1 % off the plant's (issue 33: its median against ``test_ensemble_one_pass``'s is the
  cost of a mismatch ensemble).

The kernel and the members' loop (its specialization for double_mass's sizes, which the
full case takes: :data:`observer.engines.compiled.members.SPECIALIZE_STEPS`) are compiled (or loaded from
numba's cache) before timing; :data:`ROUNDS` rounds, the median is the figure
(``extra_info["observer_steps"]``: observers × steps per round; ``extra_info["cpu_s"]``: the
process's CPU time per round, every thread's). The speed-up is the ratio of the medians.
Each benchmark checks its answer: the ensemble's V(end), V_max and settling times of 5
sampled members equal those of a single run of that member (≤ 1e-12 relative in V, the
acceptance's equality); the separate runs' V(end) are finite.

With ``--benchmark-disable`` the case shrinks to :data:`SMOKE` (a correctness run)::

    python -m pytest bench/micro/test_ensemble.py --benchmark-only --benchmark-json=ensemble.json
"""

from __future__ import annotations

import time

import numpy as np
import pytest

import observer
from observer.ensemble import member_slaves, sample_errors
from observer.engines.compiled.driver import compile_time
from observer.metrics import RHOS, settle_column

MEMBERS, H, T_END = 1000, 2e-4, 10.0
SMOKE = {"n": 6, "t_end": 0.2}
ROUNDS = 3
DESIGNS = ("jump", "nojump")
SAMPLED = (0, 1, 2, 3, 4)


def _case(benchmark) -> tuple[int, float]:
    return (SMOKE["n"], SMOKE["t_end"]) if benchmark.disabled else (MEMBERS, T_END)


def _warm() -> None:
    """Compile (or load) the kernel and both loops of :mod:`observer.members`."""
    import observer.engines.compiled.members as members

    compile_time()
    saved = members.SPECIALIZE_STEPS
    try:
        for steps in (saved, 0):
            members.SPECIALIZE_STEPS = steps
            observer.ensemble("double_mass", DESIGNS, n=2, seed=0, h=H, t_end=0.01)
    finally:
        members.SPECIALIZE_STEPS = saved


def _cpu_timed(benchmark, fn, *args, **kwargs):
    """``benchmark.pedantic`` of fn, with the median CPU time per round in ``extra_info``."""
    cpu = []

    def run():
        c0 = time.process_time()
        out = fn(*args, **kwargs)
        cpu.append(time.process_time() - c0)
        return out

    out = benchmark.pedantic(run, rounds=1 if benchmark.disabled else ROUNDS, iterations=1)
    benchmark.extra_info["cpu_s"] = float(np.median(cpu))
    return out


def _single(sc, X, i: int, t_end: float, store: str):
    return observer.simulate(sc, h=H, t_end=t_end, observers=member_slaves(sc, DESIGNS, X, [i]), store=store)


def test_ensemble_one_pass(benchmark):
    n, t_end = _case(benchmark)
    _warm()
    sc = observer.load_scenario("double_mass")
    df = _cpu_timed(benchmark, observer.ensemble, "double_mass", designs=DESIGNS, n=n, seed=0, h=H, t_end=t_end)
    benchmark.extra_info.update(observer_steps=2 * n * round(t_end / H), members=n,
                                workers=df.attrs["metadata"]["workers"])
    X, _ = sample_errors(sc, n, "energy_sphere", np.random.default_rng(0), None)
    for i in SAMPLED[:n]:
        alone = _single(sc, X, i, t_end, "summary").summary.set_index("observer")
        for d in DESIGNS:
            row = df[(df.design == d) & (df.member == i)].iloc[0]
            ref = alone.loc[f"{d}#{i}"]
            for c in ("V_end", "V_max", "V_on"):
                assert abs(row[c] - ref[c]) <= 1e-12 * abs(ref[c]), (d, i, c)
            for rho in RHOS:
                assert row[settle_column(rho)] == ref[settle_column(rho)]


@pytest.mark.parametrize("store", ["summary", "full"])
def test_separate_calls(benchmark, store):
    n, t_end = _case(benchmark)
    _warm()
    sc = observer.load_scenario("double_mass")
    X, _ = sample_errors(sc, n, "energy_sphere", np.random.default_rng(0), None)

    def separate():
        return [_single(sc, X, i, t_end, store).slaves[f"jump#{i}"].V[-1] for i in range(n)]

    ends = _cpu_timed(benchmark, separate)
    benchmark.extra_info.update(observer_steps=2 * n * round(t_end / H), members=n, store=store)
    assert np.all(np.isfinite(ends)) and len(ends) == n


MISMATCH = {"K": {"scale": 1.01}}
"""The observer model of the mismatch ensemble (issue 33): the plant's K known to 1 %."""


def test_mismatch_ensemble(benchmark):
    """The acceptance case of issue 33: the same ensemble with the observers on a model whose K
    is 1 % off the plant's (:mod:`observer.plant_model`; the members loop on the model's
    matrices against one plant run); its cost against :func:`test_ensemble_one_pass`'s is the
    ratio of the medians. Checked: 5 sampled members' V(end) and V_max equal those of a single
    mismatch run (``store="full"``, the plant as master) to 1e-12 relative."""
    n, t_end = _case(benchmark)
    _warm()
    sc = observer.load_scenario("double_mass")
    df = _cpu_timed(benchmark, observer.ensemble, "double_mass", designs=DESIGNS, n=n, seed=0, h=H, t_end=t_end,
                    model=MISMATCH)
    benchmark.extra_info.update(observer_steps=2 * n * round(t_end / H), members=n,
                                workers=df.attrs["metadata"]["workers"])
    X, _ = sample_errors(sc, n, "energy_sphere", np.random.default_rng(0), None)
    for i in SAMPLED[:n]:
        alone = observer.simulate(sc, h=H, t_end=t_end, observers=member_slaves(sc, DESIGNS, X, [i]), model=MISMATCH)
        for d in DESIGNS:
            row = df[(df.design == d) & (df.member == i)].iloc[0]
            V = alone.slaves[f"{d}#{i}"].V
            assert abs(row["V_end"] - V[-1]) <= 1e-12 * V[-1] and abs(row["V_max"] - V.max()) <= 1e-12 * V.max()
