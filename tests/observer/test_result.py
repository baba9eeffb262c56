"""SimulationResult: status, step statistics, the events table, and result files any tool reads
(CSV with a plain header and a JSON sidecar, Parquet with its metadata in the schema).

Runs are short (``bouncing_ball``/``double_mass`` over at most 0.05 s).
"""

from __future__ import annotations

import dataclasses
import json
import pickle

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

import observer
from observer import InputError, simulate
from observer.io import PARQUET_KEY, events_path, read_events, read_frame, read_result
from observer.metrics import RHOS
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
    assert _bare(observed_run).events is None
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


# ---------------------------------------------------------------------------------------
# files any tool reads
# ---------------------------------------------------------------------------------------
def documented_columns(n: int, m: int, observers: tuple[str, ...]) -> list[str]:
    """The columns README/`to_frame` document, spelled out independently of the code."""
    cols = ["t"] + [f"{p}{j}" for p, w in (("q", n), ("u", n), ("g", m), ("P", m), ("active", m))
                    for j in range(w)]
    if observers:
        cols += [f"chi{j}" for j in range(m)]
    for ob in observers:
        cols += [f"{ob}_q{j}" for j in range(n)] + [f"{ob}_u{j}" for j in range(n)] + [f"V_{ob}"]
    return cols


DM_COLUMNS = documented_columns(2, 1, ("jump", "nojump"))


def test_plain_read_csv_gives_the_documented_columns_and_exact_values(observed_run, tmp_path):
    path = observed_run.write(tmp_path / "run.csv")
    first = path.read_text(encoding="utf-8").splitlines()[0]
    assert first == ",".join(DM_COLUMNS)                      # a plain header row, nothing above
    df = pd.read_csv(path)
    assert list(df.columns) == DM_COLUMNS and len(df) == 51
    assert np.array_equal(df["t"].to_numpy(), observed_run.t)             # %.17g: exact
    assert np.array_equal(df["q1"].to_numpy(), observed_run.q[:, 1])
    assert np.array_equal(df["V_jump"].to_numpy(), observed_run.slaves["jump"].V)
    assert np.array_equal(df["active0"].to_numpy(), observed_run.active[:, 0].astype(int))
    side = json.loads((tmp_path / "run.json").read_text(encoding="utf-8"))
    assert side["scenario"] == "double_mass" and side["h"] == 1e-3 and side["steps"] == 50
    assert side["observers"] == ["jump", "nojump"]
    assert side["status"] == {"state": "ok", "reason": ""}


def test_plain_read_parquet_gives_the_documented_columns_and_schema_metadata(observed_run, tmp_path):
    path = observed_run.write(tmp_path / "run.parquet")
    df = pd.read_parquet(path)
    assert list(df.columns) == DM_COLUMNS
    assert np.array_equal(df["V_nojump"].to_numpy(), observed_run.slaves["nojump"].V)
    raw = pq.read_schema(path).metadata[PARQUET_KEY]
    meta = json.loads(raw)
    assert meta["scenario"] == "double_mass" and meta["status"]["state"] == "ok"
    assert not (tmp_path / "run.json").exists()                # Parquet needs no sidecar


@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_read_result_returns_frame_and_metadata(observed_run, tmp_path, ext):
    expected = observed_run.to_frame()
    path = observed_run.write(tmp_path / f"r.{ext}")
    df, meta = read_result(path)
    assert list(df.columns) == DM_COLUMNS
    for col in DM_COLUMNS:
        assert np.array_equal(df[col].to_numpy(), expected[col].to_numpy()), col
    # the run's metadata, plus the name of the events table written beside this file
    assert meta == {**expected.attrs, "events_file": events_path(path).name}
    assert df["P0"].dtype == np.float64 and df["active0"].dtype.kind == "i"
    assert read_frame(tmp_path / f"r.{ext}").attrs == meta          # the attrs view agrees


def test_read_result_is_public_api():
    assert observer.read_result is read_result and "read_result" in observer.__all__


def test_a_result_without_events_has_no_events_file(observed_run, tmp_path):
    path = _bare(observed_run).write(tmp_path / "plain.csv")
    assert read_events(path) is None and not events_path(path).exists()


def test_csv_without_sidecar_is_refused_unless_partial(observed_run, tmp_path):
    """A CSV with no row count or checksum (e.g. saved by a spreadsheet) cannot prove it is
    whole: refused by default, read as its whole rows with status "partial" on request."""
    observed_run.to_frame().to_csv(tmp_path / "edited.csv", index=False)
    with pytest.raises(InputError, match="no row count or checksum") as ei:
        read_result(tmp_path / "edited.csv")
    assert ei.value.field == str(tmp_path / "edited.csv")
    df, meta = read_result(tmp_path / "edited.csv", partial=True)
    assert list(df.columns) == DM_COLUMNS and len(df) == observed_run.t.size
    assert meta["status"]["state"] == "partial" and "no row count" in meta["status"]["reason"]


def test_legacy_csv_with_a_metadata_comment_line_is_read_as_partial(tmp_path):
    path = tmp_path / "old.csv"
    path.write_text('# metadata: {"h": 0.1}\nt,q0\n0,1.5\n0.1,2.5\n', encoding="utf-8")
    with pytest.raises(InputError, match="no row count or checksum"):
        read_result(path)
    df, meta = read_result(path, partial=True)
    assert meta["h"] == 0.1 and meta["status"]["state"] == "partial" and df["q0"].tolist() == [1.5, 2.5]


@pytest.mark.parametrize("name, field_part", [("x.xlsx", "unsupported extension"),
                                              ("missing.csv", "file not found")])
def test_bad_result_paths_name_the_file(tmp_path, name, field_part):
    with pytest.raises(InputError) as ei:
        read_result(tmp_path / name)
    assert field_part in str(ei.value) and ei.value.field == str(tmp_path / name)


def test_a_csv_that_is_not_a_result_is_refused(tmp_path):
    (tmp_path / "other.csv").write_text("a,b\n1,2\n", encoding="utf-8")
    with pytest.raises(InputError, match="no row count or checksum"):
        read_result(tmp_path / "other.csv")
    with pytest.raises(InputError, match="no column 't'"):
        read_result(tmp_path / "other.csv", partial=True)


def test_write_refuses_unknown_extension_and_leaves_no_file(observed_run, tmp_path):
    with pytest.raises(InputError) as ei:
        observed_run.write(tmp_path / "x.txt")
    assert ei.value.field == "--out"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_events_are_written_beside_the_result(observed_run, tmp_path, ext):
    ev = _events(3)
    res = _bare(observed_run, metadata=dict(observed_run.metadata), events=ev)
    path = res.write(tmp_path / f"ev.{ext}")
    assert events_path(path) == tmp_path / f"ev.events.{ext}"
    back = (pd.read_csv if ext == "csv" else pd.read_parquet)(tmp_path / f"ev.events.{ext}")
    assert list(back.columns) == list(EVENT_COLUMNS)
    assert read_events(path).equals(back)
    assert np.array_equal(back["time"].to_numpy(), ev["time"].to_numpy())
    assert back["kind"].tolist() == ["impact"] * 3
    if ext == "csv":                                 # the events file proves it is whole too
        side = json.loads((tmp_path / "ev.events.json").read_text(encoding="utf-8"))
        assert side["integrity"]["rows"] == 3 and side["integrity"]["state"] == "complete"


def test_cli_run_files_read_by_plain_pandas(tmp_path):
    """`observer run double_mass --observers jump,nojump --out …` (in process): both formats
    give the documented columns, V_jump and V_nojump included."""
    from observer.cli import main

    for ext in ("csv", "parquet"):
        out = tmp_path / f"dm.{ext}"
        assert main(["run", "double_mass", "--observers", "jump,nojump", "--h", "1e-3",
                     "--t-end", "0.02", "--out", str(out)]) == 0
        df = (pd.read_csv if ext == "csv" else pd.read_parquet)(out)
        assert list(df.columns) == DM_COLUMNS and len(df) == 21
        assert np.isfinite(df[["V_jump", "V_nojump"]].to_numpy()).all()


# ---------------------------------------------------------------------------------------
# frozen
# ---------------------------------------------------------------------------------------
def test_result_is_frozen_after_construction(observed_run):
    res = observed_run
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.chi = None
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.status = RunStatus("stopped", "x")
    with pytest.raises(TypeError, match="frozen"):
        res.metadata["h"] = 1.0
    with pytest.raises(TypeError, match="frozen"):
        res.slaves["other"] = res.slaves["jump"]
    with pytest.raises(TypeError, match="frozen"):
        res.metadata.update(h=1.0)
    assert res.metadata["h"] == 1e-3 and set(res.slaves) == {"jump", "nojump"}
    for arr in (res.t, res.q, res.u, res.P, res.active, res.chi, res.sigma):
        with pytest.raises(ValueError, match="read-only"):
            arr[0] = arr[0]


def test_replace_and_pickle_give_equal_frozen_copies(observed_run):
    stopped = dataclasses.replace(observed_run, status=RunStatus("stopped", "SIGINT at step 30"))
    assert stopped.status.state is RunState.STOPPED and observed_run.status.ok
    assert stopped.metadata == observed_run.metadata
    back = pickle.loads(pickle.dumps(observed_run))
    assert back.metadata == observed_run.metadata and back.status == observed_run.status
    assert np.array_equal(back.slaves["jump"].V, observed_run.slaves["jump"].V)
    with pytest.raises(TypeError, match="frozen"):
        back.metadata["h"] = 2.0


def test_the_caller_cannot_change_a_result_through_its_own_dicts(observed_run):
    meta, slaves = dict(observed_run.metadata), dict(observed_run.slaves)
    res = _bare(observed_run, metadata=meta, slaves=slaves)
    meta["h"], slaves["extra"] = 5.0, None
    assert res.metadata["h"] == 1e-3 and "extra" not in res.slaves
    q = observed_run.q.copy()
    own = _bare(dataclasses.replace(observed_run, q=q))
    q[0, 0] = 7.0                                   # the caller's array stays writable ...
    assert own.q[0, 0] == 7.0                       # ... and the result is a view of it, no copy


# ---------------------------------------------------------------------------------------
# synchronization metrics
# ---------------------------------------------------------------------------------------
def test_synchronization_of_a_window_after_the_run_is_nan_not_an_error():
    """rocking_chain couples from t = 4 s: a 0.05 s run has no window to measure."""
    res = simulate("double_mass", observers=("jump",), h=1e-3, t_end=0.05, coupling=(1.0, 2.0))
    row = res.synchronization().iloc[0]
    assert row["observer"] == "jump" and row["t_on"] == 1.0
    assert np.isnan(row["V_on"]) and np.isnan(row["rate"]) and np.isnan(row["floor"])
    times = row.filter(regex="^t_(sync|settle)_").astype(float)
    assert len(times) == 2 * len(RHOS) and np.isnan(times).all()
    assert row["V_end"] == res.slaves["jump"].V[-1]


def test_synchronization_column_order_and_v_on_from_the_returned_state(observed_run):
    sync = observed_run.synchronization(rhos=(1e-3,))
    assert list(sync.columns) == ["observer", "t_on", "t_off", "V_on", "t_sync_0.001",
                                  "t_settle_0.001", "rate", "floor", "V_end", "master_closings"]
    k_on = int(np.searchsorted(observed_run.t, sync["t_on"].iloc[0]))
    for _, row in sync.iterrows():
        assert row["V_on"] == observed_run.slaves[row["observer"]].V[k_on]
