"""pandas is imported only when a DataFrame is first needed (issue 9: a long
``store="summary"`` run must stay small; pandas and pyarrow are ~48 MB of resident memory).

``import observer`` and a ``simulate`` run load neither pandas nor pyarrow; the result's
tables (``summary``, ``events``) are :class:`observer.result.LazyFrame` values built on first
read, equal to what the run computed (checked against the ``store="full"`` run's metrics,
as ``tests/observer/test_loop.py`` does).
"""

from __future__ import annotations

import dataclasses
import json
import pickle
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import observer
from observer import InputError
from observer.metrics import RHOS, settle_column, sync_column
from observer.result import EVENT_COLUMNS, LazyFrame, SimulationResult

H, T_END = 5e-4, 6.0
"""double_mass with its scenario observers (jump, nojump; coupled over [0, 20]) for 12 000
steps: the summary run keeps every step (record_every 1), so its events table exists too."""

CHILD = r"""
import json, sys

def heavy():
    return sorted(m for m in ("pandas", "pyarrow") if m in sys.modules)

import observer
out = {"after_import": heavy()}
res = observer.simulate("double_mass", observers="scenario", h=%(h)r, t_end=%(t_end)r,
                        store="summary")
out["after_run"] = heavy()
out["record_every"] = res.metadata["record_every"]
summary = res.summary
out["after_summary"] = heavy()
import pandas
out["is_frame"] = isinstance(summary, pandas.DataFrame)
out["cached"] = res.summary is summary
out["summary"] = summary.to_dict("records")
out["attrs"] = summary.attrs
out["events"] = res.events.to_dict("records")
print(json.dumps(out, default=lambda x: x.item()))
""" % {"h": H, "t_end": T_END}


@pytest.fixture(scope="module")
def child() -> dict:
    """The summary run in a fresh process: which heavy modules were loaded when, and its tables."""
    proc = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True,
                          check=False, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def full() -> SimulationResult:
    return observer.simulate("double_mass", observers="scenario", h=H, t_end=T_END)


def test_import_and_summary_run_load_neither_pandas_nor_pyarrow(child):
    assert child["after_import"] == []
    assert child["after_run"] == []
    assert child["record_every"] == 1                       # the events table is pending too
    assert "pandas" in child["after_summary"]               # reading the summary builds it
    assert child["is_frame"] and child["cached"]


def test_lazily_built_summary_equals_the_full_runs_metrics(child, full):
    """Every column of the summary built on first read against the full run's trajectories."""
    rows = child["summary"]
    assert [r["observer"] for r in rows] == list(full.slaves) == ["jump", "nojump"]
    sync = full.synchronization()
    finite = 0
    for row in rows:
        ref = sync[sync.observer == row["observer"]].iloc[0]
        for rho in RHOS:
            for col in (sync_column(rho), settle_column(rho)):
                assert row[col] == pytest.approx(ref[col], abs=1e-12), (row["observer"], col)
                finite += bool(np.isfinite(row[col]))
        s = full.slaves[row["observer"]]
        V = s.V
        assert row["t_on"] == 0.0 and row["t_off"] == pytest.approx(T_END, rel=1e-15)
        assert row["V_on"] == pytest.approx(V[0], rel=1e-14)
        assert row["V_end"] == pytest.approx(V[-1], rel=1e-9, abs=1e-300)
        assert row["V_max"] == pytest.approx(V.max(), rel=1e-12)
        assert row["rises"] == int(np.sum(np.diff(V) > 0))
        for col, part in (("sum_damping", s.dV_damping), ("sum_impulse", s.dV_impulse),
                          ("sum_projection", s.dV_projection)):
            assert row[col] == pytest.approx(part.sum(), rel=1e-9, abs=1e-12 * V[0])
    assert finite > 0                                       # not only inf == inf
    closings = int(np.sum(full.active[1:, 0] & ~full.active[:-1, 0]))
    assert closings > 0 and child["attrs"] == {"master_closings": [closings]}


def test_lazily_built_events_are_the_masters_closing_and_opening_steps(child, full):
    """The summary run's events (built on first read): one row per closing and opening step
    of the master, recounted from the full run's closed sets, at the same times."""
    ev = pd.DataFrame(child["events"])
    assert list(ev.columns) == list(EVENT_COLUMNS)
    a = full.active
    closing, opening = a[1:] & ~a[:-1], ~a[1:] & a[:-1]
    assert int((ev.kind != "liftoff").sum()) == int(closing.sum()) > 0
    assert int((ev.kind == "liftoff").sum()) == int(opening.sum())
    k = np.flatnonzero((closing | opening).any(axis=1))
    np.testing.assert_array_equal(np.unique(ev.time.to_numpy()), np.unique(full.t[k]))
    pd.testing.assert_frame_equal(ev, full.events.reset_index(drop=True), check_dtype=False)


def test_pending_tables_survive_pickle_and_replace():
    res = observer.simulate("double_mass", observers="scenario", h=1e-3, t_end=0.5, store="summary")
    back = pickle.loads(pickle.dumps(res))              # pickled before any table was built
    copy = dataclasses.replace(res)
    for other in (back, copy):
        pd.testing.assert_frame_equal(other.summary, res.summary)
        assert other.summary.attrs == res.summary.attrs == {"master_closings": res.summary.attrs["master_closings"]}
        pd.testing.assert_frame_equal(other.events, res.events)
    assert res.summary is res.summary and res.events is res.events
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.summary = None


def test_lazy_events_are_checked_when_built(full):
    """An events table given lazily is checked (columns) on its first read, as a DataFrame
    given directly is at construction."""
    bad = LazyFrame(pd.DataFrame, ({"time": [0.0]},))
    res = SimulationResult(full.t, full.q, full.u, full.P, full.active, full.system, events=bad)
    with pytest.raises(InputError) as ei:
        res.events
    assert ei.value.field == "events"
    with pytest.raises(InputError) as ei:
        LazyFrame(pd.DataFrame, of_result=True).frame()
    assert ei.value.field == "result"
