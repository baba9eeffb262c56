"""observer.members: an ensemble's members advanced alone after one master run.

The claim of :mod:`observer.members` is that member i's summary is bitwise that of a single
:func:`observer.simulate` of that member (the same floating-point operations per observer
step), so the checks below are exact equalities against independent single runs, on runs
chosen to reach each branch of the member loop: several contacts closed at once (the
general contact solver and projection), a moving ground (ν and ν̇ tables) with a coupling
window, a closing log instead of the master's χ, projection metrics other than K, and grids
longer than one kernel window (:data:`observer.loop.WINDOW` steps).
"""

from __future__ import annotations

import importlib

import numpy as np
import pandas as pd
import pytest

import observer.engines.compiled.members as members
from observer import load_scenario, simulate
from observer.ensemble import ensemble, member_slaves, sample_errors
from observer.loop import WINDOW
from observer.switching import log_from_active

ens = importlib.import_module("observer.ensemble")      # the module (observer.ensemble is also the function)
COLUMNS = ["V_on", "V_max", "V_end", "rises", "max_rise_rel", *ens.SUMMARY_COLUMNS[5:]]


@pytest.fixture
def no_kernel_chunks(monkeypatch):
    """Fail if the ensemble falls back to the kernel's chunks: the rows must come from
    :func:`observer.members.member_summaries`."""
    def refuse(*args, **kwargs):
        raise AssertionError("the ensemble ran the kernel's chunks instead of observer.members")

    monkeypatch.setattr(ens, "_run_chunk", refuse)


def _assert_members_equal_single_runs(sc, designs, n, seed, df):
    """Every member's summary columns equal those of a single run of that member, exactly."""
    X, _ = sample_errors(sc, n, "energy_sphere", np.random.default_rng(seed), None)
    for i in range(n):
        alone = simulate(sc, observers=member_slaves(sc, designs, X, [i]), store="summary").summary
        alone = alone.set_index("observer")
        for d in designs:
            row = df[(df.design == d) & (df.member == i)].iloc[0]
            ref = alone.loc[f"{d}#{i}"]
            got, want = row[COLUMNS].to_numpy(float), ref[COLUMNS].to_numpy(float)
            np.testing.assert_array_equal(got, want, err_msg=f"{d}#{i}")


def test_several_contacts_at_once_and_other_metrics(no_kernel_chunks):
    sc = load_scenario("random_system", {"param.dof": 5, "param.contacts": 4, "param.seed": 3,
                                         "simulation.t_end": 3.5})
    assert round(sc.t_end / sc.h) > WINDOW                  # the tables cross a kernel window
    master = simulate(sc)
    assert master.active.sum(axis=1).max() >= 2             # the general contact branch runs
    designs = ("jump", "nojump", "jump_identity")
    df = ensemble(sc, designs=designs, n=2, seed=4, workers=2)
    assert (df.rises[df.design == "jump_identity"] > 0).all()    # something to compare
    _assert_members_equal_single_runs(sc, designs, 2, 4, df)


def test_moving_ground_coupling_window_and_a_closing_log(no_kernel_chunks, tmp_path):
    sc = load_scenario("rocking_chain", {"param.N": 3, "param.t_on": 0.5, "param.t_off": 1.6,
                                         "simulation.t_end": 1.8})
    assert round(sc.t_end / sc.h) > WINDOW
    designs = ("jump", "nojump", "jump_mass")
    df = ensemble(sc, designs=designs, n=2, seed=1, workers=1)
    assert np.isfinite(df.V_on).all() and (df.V_end < df.V_on).any()
    _assert_members_equal_single_runs(sc, designs, 2, 1, df)
    master = simulate(sc)                                   # χ from a log, closings 3 steps late
    log = log_from_active(master.t, master.active)
    log[["t_close", "t_open"]] += 3 * sc.h
    path = tmp_path / "late.csv"
    log.to_csv(path, index=False, float_format="%.17g")
    late = sc.with_overrides({"observer.source": "log", "observer.log": str(path)})
    df_late = ensemble(late, designs=("jump",), n=2, seed=1, workers=2)
    assert not np.array_equal(df_late.V_end, df[df.design == "jump"].V_end)
    _assert_members_equal_single_runs(late, ("jump",), 2, 1, df_late)


def test_specialized_members_equal_the_kernel_chunks_and_keep_paths(monkeypatch):
    X = sample_errors(load_scenario("double_mass"), 3, "energy_sphere", np.random.default_rng(7), None)[0]
    kw = {"n": 3, "initial_errors": X, "h": 2e-4, "t_end": 1.0, "paths": 1, "workers": 2}
    monkeypatch.setattr(members, "SPECIALIZE_STEPS", 0)     # n, m compiled as constants (the bench's)
    assert members.sizes(2, 1, 4, 1) == ((0, 0), (0,), (0, 0, 0, 0))
    fast = ensemble("double_mass", **kw)
    monkeypatch.setattr(members, "applicable", lambda *args: False)
    chunks = ensemble("double_mass", **kw)
    pd.testing.assert_frame_equal(fast[COLUMNS + ["status"]], chunks[COLUMNS + ["status"]])
    sc = load_scenario("double_mass", {"simulation.h": 2e-4, "simulation.t_end": 1.0})
    for d in ("jump", "nojump"):              # V(t) of member 0 against a full single run's
        path = fast.attrs["paths"].query("design == @d and member == 0")
        full = simulate(sc, observers=member_slaves(sc, (d,), X, [0]))
        np.testing.assert_array_equal(path.t.to_numpy(), full.t)
        np.testing.assert_allclose(path.V.to_numpy(), full.slaves[f"{d}#0"].V, rtol=1e-12, atol=0)
