"""Long runs lose nothing (issue 12, item 3): rows are written as the loop finishes them, and a
run stopped by SIGINT/SIGTERM leaves a readable file holding every finished step, with a
status saying where it stopped.

The reference for every streamed row is an uninterrupted run of the same engine on the same
grid: equal bitwise (the same arithmetic, step by step).
"""

from __future__ import annotations

import inspect
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import observer.loop as loop
from observer.engines import python as python_engine
from observer.engines.compiled import driver
from observer.io import part_path, read_result
from observer.loop import LoopInput
from observer.simulate import simulate
from observer.scenario import load_scenario
from observer.stepping import MoreauJean
from observer.stream import SIGNAL_EXIT, ChunkWriter, chunk_frame

REPO = Path(__file__).resolve().parents[2]


def _loop_input(name: str, t_end: float, h: float | None = None, jumps=(), **kw) -> LoopInput:
    """The master of built-in ``name`` (and observers started from its [observer] state)."""
    sc = load_scenario(name, {"simulation.t_end": t_end, **({"simulation.h": h} if h else {})})
    st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta)
    q0 = [sc.q0] + [np.asarray(sc.observer["q"], float) for _ in jumps]
    u0 = [sc.u0] + [np.asarray(sc.observer["u"], float) for _ in jumps]
    return LoopInput(st, np.stack(q0), np.stack(u0), np.array([False, *jumps]), False,
                     names=tuple(f"o{i}" for i in range(len(jumps))), **kw)


def _frame_of(out, inp: LoopInput) -> pd.DataFrame:
    """The whole output of a loop run as one chunk's frame (the uninterrupted reference)."""
    chunk = loop.Chunk(out.rows, inp.stepper.time(out.rows), out.q, out.u, out.P, out.sigma,
                       out.active, out.chi, out.V, inp.stepper.system, inp.names)
    return chunk_frame(chunk)


def _assert_prefix(part: pd.DataFrame, full: pd.DataFrame) -> None:
    """``part`` is the first rows of ``full``, column by column, bitwise."""
    assert list(part.columns) == list(full.columns)
    assert 0 < len(part) <= len(full)
    for c in full.columns:
        a, b = part[c].to_numpy(), full[c].to_numpy()[:len(part)]
        assert np.array_equal(a.astype(float), b.astype(float)), c


@pytest.mark.parametrize("engine", loop.ENGINES)
@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
def test_streamed_file_equals_the_run(tmp_path, monkeypatch, engine, suffix):
    """Several chunks (small windows), two observers: the file read back is the run."""
    monkeypatch.setattr(driver, "WINDOW", 700)
    monkeypatch.setattr(python_engine, "PYTHON_CHUNK", 700)
    inp = _loop_input("double_mass", 0.25, jumps=(True, False))
    path = tmp_path / f"run{suffix}"
    seen = []
    with ChunkWriter(path) as w:
        out = loop.run(inp, engine=engine, on_chunk=lambda c: (seen.append(c.rows.copy()), w(c)))
        w.close({"status": {"state": "ok", "reason": ""}})
    rows = np.concatenate(seen)
    assert len(seen) == -(-inp.stepper.steps // 700)          # one chunk per window, in order
    assert np.array_equal(rows, np.arange(inp.stepper.steps + 1))
    df, meta = read_result(path)
    assert meta["status"]["state"] == "ok" and meta["streamed"]["rows"] == len(df)
    _assert_prefix(df, _frame_of(out, inp))
    assert len(df) == inp.stepper.steps + 1


@pytest.mark.parametrize("engine", loop.ENGINES)
@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM"])
def test_signal_stops_the_run_after_the_window(tmp_path, monkeypatch, engine, signame):
    """A signal during a streamed run: the loop stops after the current window, the records are
    the uninterrupted run's first rows (no unwritten row, no NaN), the stop is reported."""
    monkeypatch.setattr(driver, "WINDOW", 500)
    monkeypatch.setattr(python_engine, "PYTHON_CHUNK", 500)
    inp = _loop_input("impact_oscillator", 3.0)                 # 3000 steps
    full = loop.run(inp, engine=engine)
    sent = []

    def on_chunk(c):
        if not sent:
            sent.append(c.rows[-1])
            os.kill(os.getpid(), getattr(signal, signame))

    before = signal.getsignal(signal.SIGINT)
    out = loop.run(inp, engine=engine, on_chunk=on_chunk)
    assert signal.getsignal(signal.SIGINT) is before            # handlers restored
    assert out.stop_signal == signame
    assert out.stopped_at == 500 == sent[0]                     # after the first window
    assert out.stop_reason.startswith(f"{signame} at t = 0.5 ")
    assert out.rows.size == 501 and np.all(np.isfinite(out.q)) and np.all(np.isfinite(out.u))
    for name in ("q", "u", "P"):
        assert np.array_equal(getattr(out, name), getattr(full, name)[:, :501]), name
    info = out.stop_info(inp.stepper)
    assert info == {"step": 500, "t": 0.5, "reason": out.stop_reason, "signal": signame}


def test_without_on_chunk_a_signal_is_not_caught(monkeypatch):
    """The Python API keeps Ctrl-C: without a streamed output the loop installs no handler."""
    monkeypatch.setattr(driver, "WINDOW", 200)
    inp = _loop_input("impact_oscillator", 1.0)
    calls = []

    def spy(signum, handler):
        calls.append(signum)
        return signal.SIG_DFL

    monkeypatch.setattr(signal, "signal", spy)
    loop.run(inp)
    assert calls == []


def test_writer_closes_with_a_stopped_status_on_an_exception(tmp_path):
    """An exception inside the ``with`` (e.g. a second Ctrl-C while the result is built) still
    leaves a readable file: every row written, status stopped, where."""
    inp = _loop_input("bouncing_ball", 0.5)
    out = loop.run(inp)
    df_full = _frame_of(out, inp)
    path = tmp_path / "x.parquet"
    with pytest.raises(KeyboardInterrupt):
        with ChunkWriter(path) as w:
            w.write(df_full.iloc[:100])
            w.write(df_full.iloc[100:250])
            raise KeyboardInterrupt
    df, meta = read_result(path)
    _assert_prefix(df, df_full)
    assert len(df) == 250
    assert meta["status"]["state"] == "stopped"
    assert f"after t = {df['t'].iloc[-1]:.9g}" in meta["status"]["reason"]


def test_writer_refuses_an_unsupported_extension(tmp_path):
    with pytest.raises(Exception, match="--out"):
        ChunkWriter(tmp_path / "x.xlsx")


# ---------------------------------------------------------------------------------------
# the acceptance test: `python -m observer run ... --out x.parquet`, SIGINT mid-run
# ---------------------------------------------------------------------------------------
def _cli_streams() -> bool:
    """True once ``observer run`` writes through a ChunkWriter (the CLI diff of issue 12)."""
    import observer.cli
    import observer.simulate

    sim = sys.modules["observer.simulate"].simulate
    return ("on_chunk" in inspect.signature(sim).parameters
            and "ChunkWriter" in inspect.getsource(observer.cli.cmd_run))


@pytest.mark.xfail(not _cli_streams(), strict=True,
                   reason="needs the CLI diff (/work/notes/H8_for_lead.md): run() streams into a ChunkWriter")
def test_sigint_mid_run_leaves_every_finished_step(tmp_path):
    """1e7 steps; SIGINT once the first windows are on disk: exit 130, and the partial file
    holds every finished step, bitwise the first rows of an uninterrupted run, with a status
    saying where it stopped."""
    assert _cli_streams(), "observer run writes its file only at the end"   # fail fast until then
    path = tmp_path / "long.parquet"
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    proc = subprocess.Popen([sys.executable, "-m", "observer", "run", "impact_oscillator",
                             "--t-end", "1e3", "--h", "1e-4", "--out", str(path)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            part = part_path(path)                                    # renamed when closed
            if part.exists() and part.stat().st_size > 1_000_000:     # a few windows written
                break
            time.sleep(0.05)
        assert proc.poll() is None, f"the run ended before it was interrupted: {proc.stderr.read()}"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=240)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == SIGNAL_EXIT["SIGINT"] == 130, err
    df, meta = read_result(path)
    k = len(df) - 1
    assert 0 < k < 10_000_000
    assert meta["status"]["state"] == "stopped"
    assert f"SIGINT at t = {df['t'].iloc[-1]:.9g}" in meta["status"]["reason"]
    assert meta["stopped"]["step"] == k and meta["stopped"]["signal"] == "SIGINT"
    assert np.array_equal(df["t"].to_numpy(), np.arange(k + 1) * 1e-4)
    # the uninterrupted run of the same steps, through the API, with the run's observers
    ref = simulate("impact_oscillator", t_end=(k + 1) * 1e-4, h=1e-4,
                   observers=list(meta.get("observers") or ())).to_frame()
    assert len(ref) > k
    _assert_prefix(df, ref)


def test_writer_leaves_no_file_when_the_run_fails_before_any_row(tmp_path):
    """Bad input found after the writer was opened: no file (as before streaming)."""
    path = tmp_path / "x.csv"
    with pytest.raises(ValueError):
        with ChunkWriter(path):
            raise ValueError("bad input")
    assert not path.exists() and not path.with_suffix(".json").exists()
