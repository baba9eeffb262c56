"""The record arrays are declared once (:data:`observer.result.RECORD_ARRAYS`): the loops
allocate, truncate and stream them from that declaration, and every class that carries them
lists them under the same names in the same order."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import observer
import observer.loop
from observer.engines.compiled.bundles import StorageBundle
from observer.engines.loop import STREAMED, Chunk, LoopInput, LoopOutput, allocate_records
from observer.result import RECORD_ARRAYS, RunRecord, SimulationResult
from observer.scenario import load_scenario
from observer.stepping import MoreauJean

NAMES = tuple(a.name for a in RECORD_ARRAYS)


def field_names(cls) -> tuple[str, ...]:
    return tuple(cls._fields) if hasattr(cls, "_fields") else tuple(f.name for f in dataclasses.fields(cls))


def in_order(names: tuple[str, ...], fields: tuple[str, ...]) -> bool:
    """``names`` all among ``fields``, in the same order."""
    return all(n in fields for n in names) and [f for f in fields if f in names] == list(names)


def test_the_declaration_names_the_seven_record_arrays():
    assert NAMES == ("q", "u", "P", "sigma", "active", "chi", "q_pre")
    assert len(set(NAMES)) == len(NAMES)
    assert [a.name for a in RECORD_ARRAYS if a.optional] == ["q_pre"]
    assert tuple(a.name for a in STREAMED) == NAMES[:-1]


@pytest.mark.parametrize("cls", [LoopOutput, StorageBundle, RunRecord], ids=lambda c: c.__name__)
def test_every_record_carrier_lists_the_declared_arrays_in_order(cls):
    assert in_order(NAMES, field_names(cls)), field_names(cls)


def test_chunks_carry_the_streamed_arrays_and_the_result_every_mandatory_one():
    assert in_order(tuple(a.name for a in STREAMED), field_names(Chunk))
    assert "q_pre" not in field_names(Chunk)
    assert set(NAMES[:-1]) <= set(field_names(SimulationResult))


def test_the_order_check_has_teeth():
    """The near miss: two arrays swapped, or one missing, is caught."""
    swapped = ("q", "u", "sigma", "P", "active", "chi", "q_pre")
    assert not in_order(NAMES, swapped)
    assert not in_order(NAMES, NAMES[:-1])


def _input(observers: int = 2) -> LoopInput:
    sc = load_scenario("double_mass", {"simulation.t_end": 0.01})
    st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta)
    S = 1 + observers
    q0 = np.stack([sc.q0 + 0.01 * s for s in range(S)])
    return LoopInput(st, q0, np.stack([sc.u0] * S), np.zeros(S, bool), False)


@pytest.mark.parametrize("record_pre", [False, True])
def test_the_loops_allocate_from_the_declaration(record_pre):
    """Shapes (S, R, n|m) or (R, m), dtypes, zero fill and row 0 the initial states."""
    inp = _input()
    S, (n, m) = inp.q0.shape[0], (inp.stepper.system.n, inp.stepper.system.m)
    rec, R = allocate_records(inp, 3, record_pre)
    assert R == inp.stepper.steps // 3 + 1 and list(rec) == list(NAMES)
    width = {"n": n, "m": m}
    for a in RECORD_ARRAYS:
        rows = R if (record_pre or not a.optional) else 0
        shape = ((S,) if a.per_system else ()) + (rows, width[a.width])
        assert rec[a.name].shape == shape and rec[a.name].dtype == a.dtype, a.name
        if a.zero_filled:
            assert not rec[a.name].any(), a.name
    assert np.array_equal(rec["q"][:, 0], inp.q0) and np.array_equal(rec["u"][:, 0], inp.u0)
    if record_pre:
        assert np.array_equal(rec["q_pre"][:, 0], inp.q0)


@pytest.mark.parametrize("engine", observer.loop.ENGINES)
def test_a_stopped_run_cuts_every_record_at_the_same_row(engine):
    """A run stopped by a residual above tolerance (the applied impulse made 1.5× too large, as
    in tests/observer/test_health.py) truncates q, u, P, sigma, active, chi and q_pre alike."""
    from observer.loop import run

    sc = load_scenario("bouncing_ball", {"simulation.t_end": 2.0})
    st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta)
    inp = LoopInput(st, sc.q0[None], sc.u0[None], np.zeros(1, bool), False)
    st.S = dataclasses.replace(st.S, AinvW=1.5 * st.S.AinvW)
    st._slices.clear()
    out = run(inp, engine=engine, record_pre=True)
    assert out.stopped_at is not None and out.stopped_at < st.steps
    R = out.stopped_at // out.record_every + 1
    for a in RECORD_ARRAYS:
        x = getattr(out, a.name)
        assert (x.shape[1] if a.per_system else x.shape[0]) == R, a.name


@pytest.mark.parametrize("record_pre", [False, True])
def test_q_pre_is_kept_only_when_asked_for(record_pre):
    inp = _input()
    out = observer.loop.run(inp, engine="python", record_pre=record_pre)
    assert (out.q_pre is not None) == record_pre
    if record_pre:
        assert out.q_pre.shape == out.q.shape
