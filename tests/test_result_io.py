"""SimulationResult: status, step statistics, the events table, and result files any tool reads
(CSV with a plain header and a JSON sidecar, Parquet with its metadata in the schema).

Runs are short (``bouncing_ball``/``double_mass`` over at most 0.05 s).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from observer import InputError, simulate
from observer.result import EVENT_COLUMNS, RunState, RunStatus, SimulationResult, StepStats


@pytest.fixture(scope="module")
def observed_run():
    return simulate("double_mass", observers=("jump", "nojump"), h=1e-3, t_end=0.05)


def _bare(res: SimulationResult, **kw) -> SimulationResult:
    return SimulationResult(res.t, res.q, res.u, res.P, res.active, res.system, **kw)


def _events(n: int = 2) -> pd.DataFrame:
    return pd.DataFrame({"time": np.linspace(0.1, 0.2, n), "contact": np.arange(n),
                         "kind": ["impact"] * n, "gamma_minus": -np.ones(n),
                         "gamma_plus": 0.5 * np.ones(n), "impulse": 1.5 * np.ones(n)})


# ---------------------------------------------------------------------------------------
# status and step statistics
# ---------------------------------------------------------------------------------------
def test_status_of_a_clean_run_is_ok_and_stats_match_the_metadata(observed_run):
    res = observed_run
    assert res.status == RunStatus(RunState.OK, "") and res.status.ok
    assert res.stats.steps == res.metadata["steps"] == 50
    assert res.stats.contact_solves == res.metadata["contact_solves"]
    assert res.stats.solver_fallbacks == 0 and res.stats.fallback_steps == ()
    # min_gap is the deepest master gap over every step: recomputed from the returned state
    assert res.stats.min_gap == pytest.approx(res.g[1:].min(), rel=1e-12, abs=1e-15)


def test_status_from_metadata_with_fallbacks_names_the_count():
    meta = {"solver_fallbacks": 3, "fallback_steps": [{"step": 4, "t": 0.4, "system": 0}, 7, 9]}
    st = RunStatus.from_metadata(meta)
    assert st.state is RunState.FALLBACK and not st.ok and "3 step" in st.reason
    assert StepStats.from_metadata(meta).fallback_steps == (4, 7, 9)


@pytest.mark.parametrize("state, reason, field", [("done", "x", "status.state"),
                                                  ("stopped", "", "status.reason")])
def test_bad_status_names_the_field(state, reason, field):
    with pytest.raises(InputError) as ei:
        RunStatus(state, reason)
    assert ei.value.field == field


def test_status_is_frozen():
    st = RunStatus("stopped", "SIGINT at step 10")
    assert st.state is RunState.STOPPED
    with pytest.raises(AttributeError):
        st.reason = "other"


# ---------------------------------------------------------------------------------------
# events
# ---------------------------------------------------------------------------------------
def test_events_default_to_none_and_accept_the_documented_columns(observed_run):
    assert observed_run.events is None
    ev = _events()
    res = _bare(observed_run, events=ev)
    assert list(res.events.columns) == list(EVENT_COLUMNS)
    assert res.events is ev


@pytest.mark.parametrize("bad", [pd.DataFrame({"time": [0.1]}), {"time": [0.1]},
                                 _events().iloc[:, ::-1]])
def test_events_with_wrong_type_or_columns_are_refused(observed_run, bad):
    with pytest.raises(InputError) as ei:
        _bare(observed_run, events=bad)
    assert ei.value.field == "events"
