"""Fault injection (issue 36, items 16-19, 23, 24): outputs that collide with inputs or each
other, results whose parts come from different writings, a damaged numba cache, FIFOs and
devices, signals, a closed stdout, an aliased forcing and failed writes.

Each test checks the exit status, one ``error:`` line naming the field or file, no
traceback, no partial or temporary file left, and that finished rows are kept. A full disk
is simulated by making the writer raise ``OSError(ENOSPC)`` (no root, no tmpfs).
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from bench.results import case_key
from observer.cli import main
from observer.errors import InputError
from observer.io import events_path, read_events, read_result, sidecar_path
from observer.scenario import load_scenario
from observer.simulate import simulate

ROOT = Path(__file__).resolve().parents[2]


def _one_error_line(err: str, *names: str) -> str:
    """The single ``error:`` line of ``err`` (no traceback), containing each of ``names``."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    errors = [ln for ln in lines if ln.startswith("error:")]
    assert len(errors) == 1, err
    for name in names:
        assert name in errors[0], errors[0]
    return errors[0]


def _leftovers(folder: Path, allowed: set[str]) -> set[str]:
    return {p.name for p in folder.iterdir()} - allowed


def _run(tmp_path, *args, t_end="0.005"):
    return main(["run", "double_mass", "--h", "1e-3", "--t-end", t_end, *args])


# -- item 16: data destroyed with exit 0 --------------------------------------------------
def test_events_equal_to_out_is_refused_before_any_work(tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert _run(tmp_path, "--out", str(out), "--events", str(out)) == 2
    _one_error_line(capsys.readouterr().err, "--events", "r.csv")
    assert list(tmp_path.iterdir()) == []


def test_events_on_a_symlink_or_hard_link_to_out_is_refused(tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert _run(tmp_path, "--out", str(out)) == 0
    before = out.read_bytes()
    os.link(out, tmp_path / "hard.csv")
    (tmp_path / "soft.csv").symlink_to(out)
    for other in ("hard.csv", "soft.csv"):
        assert _run(tmp_path, "--out", str(out), "--events", str(tmp_path / other)) == 2
        _one_error_line(capsys.readouterr().err, "--events")
    assert out.read_bytes() == before
    read_result(out)                                  # still whole


def test_log_out_equal_to_its_result_is_refused(tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert _run(tmp_path, "--out", str(out)) == 0
    capsys.readouterr()
    before = out.read_bytes()
    assert main(["log", str(out), "--out", str(out)]) == 2
    _one_error_line(capsys.readouterr().err, "--out", "r.csv", "input")
    assert out.read_bytes() == before


def test_closing_log_given_as_input_and_out_is_refused(tmp_path, capsys):
    log = tmp_path / "log.csv"
    log.write_text("contact,t_close,t_open\n0,0.001,0.002\n")
    assert _run(tmp_path, "--source", "log", "--log", str(log), "--out", str(log)) == 2
    _one_error_line(capsys.readouterr().err, "--out", "--log")
    assert log.read_text() == "contact,t_close,t_open\n0,0.001,0.002\n"


def test_an_output_being_written_by_another_process_is_refused(tmp_path):
    """A second writer of one file is refused while the first holds its lock (filelock),
    and the first one's file is whole."""
    from observer.outputs import output_lock

    out = tmp_path / "same.parquet"
    with output_lock(out):                            # another run writing the file
        proc = subprocess.run([sys.executable, "-m", "observer", "run", "double_mass", "--h", "1e-3",
                               "--t-end", "0.005", "--out", str(out)], capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert proc.returncode == 2, proc.stderr
    _one_error_line(proc.stderr, "same.parquet", "another run")
    assert not out.exists() and _leftovers(tmp_path, set()) == set()


def test_a_rerun_without_events_removes_the_earlier_events(tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert _run(tmp_path, "--out", str(out)) == 0
    assert events_path(out).exists()                  # the first run kept its events
    assert _run(tmp_path, "--out", str(out), "--record-every", "2") == 0
    assert not events_path(out).exists() and not sidecar_path(events_path(out)).exists()
    assert read_events(out) is None


def test_read_events_refuses_events_that_are_not_the_results(tmp_path):
    res = simulate("double_mass", h=1e-3, t_end=0.005)
    first, second = tmp_path / "a.csv", tmp_path / "b.csv"
    res.write(first)
    res.write(second)
    os.unlink(events_path(second))                    # b has events of its own: now a's
    os.unlink(sidecar_path(events_path(second)))
    meta = json.loads(sidecar_path(second).read_text())
    assert meta["events_file"] == "b.events.csv"
    res_no = simulate("double_mass", h=1e-3, t_end=0.005, record_every=2)
    res_no.write(second)
    for f in (events_path(first), sidecar_path(events_path(first))):
        (tmp_path / f.name.replace("a.", "b.")).write_bytes(f.read_bytes())
    with pytest.raises(InputError, match="not the events table of b.csv"):
        read_events(second)


# -- item 17: content and metadata bound by one digest ------------------------------------
def _two_runs(tmp_path, suffix):
    a = simulate("double_mass", h=1e-3, t_end=0.005)
    b = simulate("double_mass", h=2e-3, t_end=0.01)           # another run, same columns
    pa, pb = tmp_path / f"a{suffix}", tmp_path / f"b{suffix}"
    a.write(pa)
    b.write(pb)
    return pa, pb


def test_a_csv_with_another_runs_metadata_is_refused(tmp_path):
    pa, pb = _two_runs(tmp_path, ".csv")
    ma, mb = json.loads(sidecar_path(pa).read_text()), json.loads(sidecar_path(pb).read_text())
    spliced = {k: v for k, v in mb.items() if k != "integrity"}
    spliced["integrity"] = {**ma["integrity"], "metadata_sha256": mb["integrity"]["metadata_sha256"]}
    sidecar_path(pa).write_text(json.dumps(spliced))   # each part's own checksum valid
    with pytest.raises(InputError, match="different writings"):
        read_result(pa)


def test_a_parquet_file_with_another_runs_metadata_is_refused(tmp_path):
    import pyarrow.parquet as pq

    pa_, pb = _two_runs(tmp_path, ".parquet")
    ta, tb = pq.read_table(pa_), pq.read_table(pb)
    ma = json.loads(ta.schema.metadata[b"observer"])
    mb = json.loads(tb.schema.metadata[b"observer"])
    spliced = {k: v for k, v in mb.items() if k != "integrity"}
    spliced["integrity"] = {**ma["integrity"], "metadata_sha256": mb["integrity"]["metadata_sha256"]}
    pq.write_table(ta.replace_schema_metadata({b"observer": json.dumps(spliced).encode()}), pa_)
    with pytest.raises(InputError, match="different writings"):
        read_result(pa_)


def test_a_file_of_the_previous_format_is_refused_and_read_partially(tmp_path):
    res = simulate("double_mass", h=1e-3, t_end=0.005)
    p = tmp_path / "old.csv"
    res.write(p)
    meta = json.loads(sidecar_path(p).read_text())
    del meta["integrity"]["digest"]                  # what the previous version wrote
    sidecar_path(p).write_text(json.dumps(meta))
    with pytest.raises(InputError, match="earlier version"):
        read_result(p)
    df, meta = read_result(p, partial=True)
    assert len(df) == res.t.size and meta["status"]["state"] == "partial"


# -- item 18: numba's cache ----------------------------------------------------------------
_CACHED = textwrap.dedent('''
    import warnings, sys
    sys.path.insert(0, sys.argv[1])
    from observer.numba_cache import install
    install()
    from numba import njit
    @njit(cache=True)
    def f(x):
        return 2.0 * x + 1.0
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        print(f(3.0))
    print("WARN", [str(x.message) for x in w])
''')


def _cached_call(tmp_path, cache_dir, env_extra=None):
    mod = tmp_path / "m.py"
    if not mod.exists():
        mod.write_text(_CACHED)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache_dir), **(env_extra or {})}
    return subprocess.run([sys.executable, str(mod), str(ROOT)], capture_output=True, text=True,
                          env=env, timeout=120)


@pytest.fixture(scope="module")
def numba_cache_written(tmp_path_factory):
    """A folder with ``m.py`` (:data:`_CACHED`) and the numba cache its first call wrote in
    ``cache/`` (the same first call for every damage: made once): (folder, that call)."""
    d = tmp_path_factory.mktemp("numba-cached")
    return d, _cached_call(d, d / "cache")


@pytest.mark.parametrize("damage", ["index", "data"])
def test_a_damaged_numba_cache_is_a_warning_and_a_recompile(tmp_path, damage, numba_cache_written):
    import shutil

    folder, first = numba_cache_written
    assert first.returncode == 0 and "7.0" in first.stdout, first.stderr
    cache = tmp_path / "cache"                        # this test's copy (the cache follows m.py's folder)
    shutil.copytree(folder / "cache", cache)
    files = sorted(cache.rglob("*.nbi" if damage == "index" else "*.nbc"))
    assert files
    for f in files:
        with open(f, "r+b") as fh:
            fh.truncate(0 if damage == "index" else min(1000, f.stat().st_size // 2))
    second = _cached_call(folder, cache)
    assert second.returncode == 0, second.stderr
    assert "Traceback" not in second.stderr and "7.0" in second.stdout
    if damage == "data":
        assert "is damaged (" in second.stdout       # the warning (the folder names "damaged" too)
    third = _cached_call(folder, cache)               # the cache was rewritten whole
    assert third.returncode == 0 and "WARN []" in third.stdout, third.stdout + third.stderr


def test_an_unwritable_numba_cache_is_a_warning(tmp_path, monkeypatch):
    """A cache folder numba cannot write (a read-only installation): simulated by making
    numba's save raise PermissionError, as it does there (root ignores permission bits)."""
    from numba.core import caching

    from observer.numba_cache import CacheWarning, install

    install()
    wrapped = caching.Cache.save_overload
    inner = wrapped.__closure__
    assert inner is not None                          # our wrapper around numba's
    monkeypatch.setattr(caching.IndexDataCacheFile, "save",
                        lambda self, key, data: (_ for _ in ()).throw(PermissionError(13, "Permission denied")))
    from numba import njit
    from numba.core import config

    def g(x):
        return x * 3.0 + 0.5
    before = config.CACHE_DIR
    try:
        with monkeypatch.context() as env:
            env.setenv("NUMBA_CACHE_DIR", str(tmp_path))
            with pytest.warns(CacheWarning, match="cannot be written"):
                assert njit(cache=True)(g)(2.0) == 6.5
    finally:
        # numba's compiler re-read NUMBA_CACHE_DIR into its config: read it again now that the
        # variable is back, or every function this process decorates later is looked up (and
        # compiled, for tens of seconds) in tmp_path's empty cache
        config.reload_config()
    assert config.CACHE_DIR == before


# -- item 19: hangs and silent waits --------------------------------------------------------
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_fifo_output_is_refused_at_once(tmp_path, capsys, suffix):
    fifo = tmp_path / f"f{suffix}"
    os.mkfifo(fifo)
    t0 = time.monotonic()
    assert _run(tmp_path, "--out", str(fifo)) == 2
    assert time.monotonic() - t0 < 5
    _one_error_line(capsys.readouterr().err, "--out", "FIFO")


def test_the_event_integrator_refuses_a_forcing_it_cannot_follow(tmp_path, capsys):
    t0 = time.monotonic()
    code = main(["run", "impact_oscillator", "--integrator", "event", "--t-end", "0.1",
                 "--set", "system.forcing.amplitude=[500.0]", "--set", "system.forcing.omega=1e15",
                 "--out", str(tmp_path / "r.csv")])
    assert code == 2 and time.monotonic() - t0 < 10
    _one_error_line(capsys.readouterr().err, "system.forcing", "oscillates")
    assert _leftovers(tmp_path, set()) == set()


def test_sighup_during_a_parquet_run_keeps_the_rows(tmp_path):
    out = tmp_path / "r.parquet"
    proc = subprocess.Popen([sys.executable, "-m", "observer", "run", "double_mass", "--engine", "python",
                             "--h", "1e-4", "--t-end", "1000", "--observers", "none", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    deadline = time.monotonic() + 60
    part = out.with_name(f".{out.name}.part")
    while not part.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    time.sleep(0.3)
    proc.send_signal(signal.SIGHUP)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGHUP, err
    df, meta = read_result(out)
    assert len(df) > 1 and meta["status"]["state"] == "stopped" and "SIGHUP" in meta["status"]["reason"]


# -- item 23: a closed stdout ------------------------------------------------------------
def test_a_closed_stdout_does_not_blame_the_result_file(tmp_path):
    out = tmp_path / "r.csv"
    proc = subprocess.Popen([sys.executable, "-m", "observer", "run", "double_mass", "--h", "1e-3",
                             "--t-end", "0.005", "--observers", "jump,nojump", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    proc.stdout.close()                              # the reader of `| head` is gone
    err = proc.stderr.read().decode()
    proc.wait(timeout=120)
    assert proc.returncode == 141, err
    line = _one_error_line(err, "standard output")
    assert "r.csv" not in line
    read_result(out)                                 # whole


# -- item 24: silent wrong answers and leftovers -----------------------------------------------
def test_an_aliased_forcing_is_a_health_warning():
    """500 N at 1e15 rad/s on the 1-DOF oscillator: the exact velocity response is
    ≤ 2F/(mω) ≈ 1e-12 m/s, the stepped one is O(F h/m); the run must say the forcing is
    aliased (h·ω ≫ π)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                       # the warning is read from the status
        sc = load_scenario("impact_oscillator", {"system.forcing.amplitude": "[500.0]",
                                                 "system.forcing.omega": "1e15"})
        res = simulate(sc, h=1e-3, t_end=0.01)
    assert any("aliased" in w and "system.forcing" in w for w in res.status.warnings), res.status


def test_a_resolved_forcing_gets_no_alias_warning():
    res = simulate("impact_oscillator", h=1e-3, t_end=0.01)
    assert not any("aliased" in w for w in res.status.warnings)


def _enospc(*a, **k):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_during_the_closing_log_leaves_nothing(tmp_path, capsys, monkeypatch):
    out = tmp_path / "r.csv"
    assert _run(tmp_path, "--out", str(out)) == 0
    capsys.readouterr()
    import pandas as pd

    real = pd.DataFrame.to_csv

    def half(self, path=None, *a, **k):
        if path is not None and str(path).endswith(".csv"):
            Path(path).write_text("contact,t_cl")
            _enospc()
        return real(self, path, *a, **k)
    monkeypatch.setattr(pd.DataFrame, "to_csv", half)
    before = {p.name for p in tmp_path.iterdir()}
    assert main(["log", str(out), "--out", str(tmp_path / "log.csv")]) == 2
    _one_error_line(capsys.readouterr().err, "No space left")
    assert {p.name for p in tmp_path.iterdir()} == before


def test_a_full_disk_during_a_plot_leaves_nothing(tmp_path, capsys, monkeypatch):
    out = tmp_path / "r.csv"
    assert _run(tmp_path, "--out", str(out)) == 0
    capsys.readouterr()
    import matplotlib.figure

    def half(self, fname, *a, **k):
        Path(fname).write_bytes(b"\x89PNG")
        _enospc()
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", half)
    before = {p.name for p in tmp_path.iterdir()}
    assert main(["plot", str(out), "--out", str(tmp_path / "p.png")]) == 2
    _one_error_line(capsys.readouterr().err, "No space left")
    assert {p.name for p in tmp_path.iterdir()} == before


def test_a_full_disk_during_an_ensemble_leaves_nothing(tmp_path, monkeypatch):
    import pandas as pd

    from observer.ensemble import write_ensemble

    df = pd.DataFrame({"design": ["jump"], "t_settle": [1.0]})
    df.attrs = {"metadata": {"n": 1}}

    def half(self, path, *a, **k):
        Path(path).write_bytes(b"PAR1")
        _enospc()
    monkeypatch.setattr(pd.DataFrame, "to_parquet", half)
    with pytest.raises(OSError):
        write_ensemble(df, tmp_path / "e.parquet")
    assert list(tmp_path.iterdir()) == []


def test_a_sidecar_name_taken_by_a_folder_is_refused_before_any_work(tmp_path, capsys):
    (tmp_path / "r.json").mkdir()
    assert _run(tmp_path, "--out", str(tmp_path / "r.csv")) == 2
    _one_error_line(capsys.readouterr().err, "r.json", "directory")
    assert _leftovers(tmp_path, {"r.json"}) == set()


def test_a_full_disk_writing_a_csv_result_leaves_nothing(tmp_path, monkeypatch):
    res = simulate("double_mass", h=1e-3, t_end=0.005, record_every=2)
    real = Path.write_text

    def full(self, *a, **k):
        if self.name.endswith(".json.tmp"):
            _enospc()
        return real(self, *a, **k)
    monkeypatch.setattr(Path, "write_text", full)
    with pytest.raises(OSError):
        res.write(tmp_path / "r.csv")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("target", ["/dev/zero", "fifo"])
def test_a_result_that_is_a_device_or_fifo_is_refused(tmp_path, target):
    link = tmp_path / "r.csv"
    if target == "fifo":
        os.mkfifo(link)
    else:
        link.symlink_to(target)
    with pytest.raises(InputError, match="not a regular file"):
        read_result(link)


def test_a_sparse_result_larger_than_memory_is_refused_by_size(tmp_path, monkeypatch):
    import observer.io as io

    p = tmp_path / "big.csv"
    with open(p, "wb") as fh:
        fh.truncate(6 * 2**30)                      # 6 GiB, no block written
    monkeypatch.setattr(io, "MEMORY_FRACTION", 1e-9)  # whatever the machine: the bound applies
    with pytest.raises(InputError, match="big.csv.*GiB"):
        read_result(p)


# -- item 20 (part): reports into a read-only folder or a full disk ---------------------------
def test_a_report_that_cannot_be_written_leaves_no_truncated_index(tmp_path, monkeypatch, capsys):
    """The page is rendered, then its write fails half-way (a full disk): ``python -m
    reports`` exits 2 with one line, and no index.html (nor a temporary file) is left."""
    import reports.__main__ as cli
    from reports import build

    monkeypatch.setattr(build, "load_context", lambda files, out, **k: _Ctx(Path(out)))
    monkeypatch.setattr(build, "build_sections", lambda ctx: [])
    monkeypatch.setattr(build, "header_table", lambda ctx: None)
    monkeypatch.setattr(build, "render", lambda **k: "<html>" + "x" * 10_000 + "</html>")
    real = Path.write_text

    def half(self, text, *a, **k):
        if self.suffix == ".html":
            real(self, text[:100], *a, **k)
            _enospc()
        return real(self, text, *a, **k)
    monkeypatch.setattr(Path, "write_text", half)
    results = tmp_path / "quick.cases"
    results.mkdir()
    out = tmp_path / "out"
    assert cli.main([str(results), "--out", str(out)]) == 2
    _one_error_line(capsys.readouterr().err, "index.html", "No space left")
    assert list(out.iterdir()) == []


class _Ctx:
    def __init__(self, out):
        self.out_dir, self.suites, self.command = out, ["quick"], "x"


# -- item 10: an observer through the wall while the log says the contact is open ----------------
# double_mass: M = I, K = [[100, -100], [-100, 200]], W = e_0, ν = 0.25 → ‖W_0‖²_{K⁻¹} = (K⁻¹)_00
# = 200/10000 = 0.02; the length scale ℓ = 0.25 (the clearance), so the master's bound is 1 % of it.
DM_M = np.eye(2)
DM_K = np.array([[100.0, -100.0], [-100.0, 200.0]])
DM_WK = np.sqrt(0.02)
DM_MARGIN = 0.01 * 0.25


def _exact_log(frame, h):
    """The master's closed intervals as a log (runs of closed steps; step k decided at t_{k+1} − h/2)."""
    import pandas as pd
    t, act = frame["t"].to_numpy(), frame["active0"].to_numpy(int)
    edges = np.diff(np.concatenate([[0], act, [0]]))
    a, b = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    return pd.DataFrame({"contact": 0, "t_close": t[a] - h / 2, "t_open": t[b] - h / 2})


def _observer_depth_and_bound(frame, name):
    """Per row: the observer's depth −g below the wall and the bound b = 1 % ℓ + ‖W‖_{K⁻¹}·sqrt(2 min V),
    recomputed here from the states with the matrices above (V of paper eq. (16))."""
    q = frame[[f"{name}_q0", f"{name}_q1"]].to_numpy()
    e = q - frame[["q0", "q1"]].to_numpy()
    v = frame[[f"{name}_u0", f"{name}_u1"]].to_numpy() - frame[["u0", "u1"]].to_numpy()
    V = 0.5 * np.einsum("ki,ij,kj->k", v, DM_M, v) + 0.5 * np.einsum("ki,ij,kj->k", e, DM_K, e)
    depth = -(q[:, 0] + 0.25)
    bound = DM_MARGIN + DM_WK * np.sqrt(2.0 * np.minimum.accumulate(V))
    open_ = frame["chi0"].to_numpy() == 0
    return np.where(open_, depth, -np.inf), bound


def _log_run(log):
    from observer.health import RunHealthWarning
    sc = load_scenario("double_mass", {"simulation.h": 1e-3, "simulation.t_end": 4.5})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = simulate(sc, observers=("jump", "nojump"), source="log", log=log)
    return res, [str(w.message) for w in caught if issubclass(w.category, RunHealthWarning)]


@pytest.fixture(scope="module")
def dm_log():
    frame = simulate(load_scenario("double_mass", {"simulation.h": 1e-3, "simulation.t_end": 4.5})).to_frame()
    return _exact_log(frame, 1e-3)


def test_an_observer_through_the_wall_of_a_dropped_resting_interval_is_a_health_warning(dm_log):
    """The log misses the longest resting interval (mass 1 on the ground for 0.18 s): both
    observers fall through the wall the master rests on, deeper than their error explains."""
    longest = (dm_log["t_open"] - dm_log["t_close"]).idxmax()
    res, msgs = _log_run(dm_log.drop(index=longest))
    frame = res.to_frame()
    for name in ("jump", "nojump"):
        line = [m for m in msgs if f"observer {name!r}" in m]
        assert len(line) == 1 and "gap 0" in line[0] and "χ = 0" in line[0], msgs
        depth, bound = _observer_depth_and_bound(frame, name)
        assert np.max(depth - bound) > 0.005                 # 2 mm beyond the bound, recomputed here
        rec = res.metadata["health"]["observer_gap"][name]
        k = int(np.argmin(np.abs(frame["t"].to_numpy() - rec["t"])))
        assert rec["depth"] == pytest.approx(depth[k], rel=1e-12)
        assert rec["bound"] == pytest.approx(bound[k], rel=1e-9)


def test_an_exact_log_keeps_every_observer_above_its_bound(dm_log):
    """Near miss: with the exact log the jump observer does go below −1 % ℓ while χ = 0 (its
    initial error: a bound of the master's kind alone would fire), yet stays above the bound
    that adds what its error at V's smallest explains — no warning."""
    res, msgs = _log_run(dm_log)
    assert not any("observer " in m for m in msgs), msgs
    assert res.metadata["health"]["observer_gap"] == {}
    depth, bound = _observer_depth_and_bound(res.to_frame(), "jump")
    assert depth.max() > 2 * DM_MARGIN
    assert np.max(depth - bound) < 0


def _gap_rows(d_rows, V1_offset=0.0):
    """Three recorded rows of double_mass (master at rest on the ground) and one observer:
    rows 0 and 1 have the error (a, 0) (V = ½·100·a²), row 2 the error (−d, 0) (its gap −d); χ = 0."""
    from observer.loop import LoopInput
    from observer.stepping import MoreauJean
    sc = load_scenario("double_mass", {"simulation.h": 1e-3, "simulation.t_end": 0.01})
    st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta)
    qm = np.tile(sc.q0, (3, 1))
    qs = qm.copy()
    qs[:2, 0] += V1_offset
    qs[2, 0] -= d_rows
    q = np.stack([qm, qs])
    u = np.zeros_like(q)
    inp = LoopInput(st, q[:, 0], u[:, 0], np.array([False, True]), False, names=("jump",))
    return inp, q, u, np.zeros((3, 1), bool)


@pytest.mark.parametrize("a", [0.0, 1e-3])
def test_the_observer_gap_bound_is_sharp(a):
    """The bound b = 1 % ℓ + ‖W‖_{K⁻¹}·sqrt(2 min V) = 0.0025 + sqrt(0.02)·sqrt(100 a²) by hand
    (min V = V of rows 0-1 = 50 a², since the observer's gap at row 2 is what is tested): one part
    in 10⁶ inside is quiet, one part in 10⁶ outside is flagged."""
    from observer.health import observer_gaps
    b = DM_MARGIN + DM_WK * np.sqrt(100.0) * a
    assert sc_q0_gap_is_zero()
    for d, flagged in ((b * (1 - 1e-6), False), (b * (1 + 1e-6), True)):
        inp, q, u, chi = _gap_rows(d, a)
        out = observer_gaps(inp, 1, q, u, chi, 0.25)
        assert bool(out) == flagged, (d, b, out)
        if flagged:
            assert out["jump"]["bound"] == pytest.approx(b, rel=1e-9)
            assert out["jump"]["depth"] == pytest.approx(d, rel=1e-9)


def sc_q0_gap_is_zero() -> bool:
    """The built-in's master starts resting on the ground: its gap is 0 (to round-off)."""
    sc = load_scenario("double_mass")
    return abs(float(sc.q0[0]) + 0.25) < 1e-12


# -- item 19: a bench client behind a case lock held by a stopped client -------------------------
_HOLDER = """
import sys, time
from bench.results import CaseStore
held = CaseStore(sys.argv[1]).holding(sys.argv[2])
held.__enter__()
print("held", flush=True)
time.sleep(300)
"""


def _behind_a_stopped_holder(folder, case_id: str, monkeypatch, action):
    """Run ``action()`` in a thread while a SIGSTOPped client holds the case's lock, with
    $BENCH_LOCK_TIMEOUT = 0.5 s; it must return within 15 s. Returns (its result, holder pid)."""
    import threading

    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(folder), case_id],
                              stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert holder.stdout.readline().strip() == "held"
        os.kill(holder.pid, signal.SIGSTOP)
        monkeypatch.setenv("BENCH_LOCK_TIMEOUT", "0.5")
        outcome = []
        waiter = threading.Thread(target=lambda: outcome.append(action()), daemon=True)
        t0 = time.monotonic()
        waiter.start()
        waiter.join(timeout=30)
        assert not waiter.is_alive(), "still waiting behind the lock"
        assert time.monotonic() - t0 < 15
    finally:
        os.kill(holder.pid, signal.SIGCONT)
        holder.kill()
        holder.wait(timeout=30)
    (out,) = outcome
    return out, holder.pid


def test_a_bench_client_behind_a_stopped_clients_lock_says_so_and_gives_up(tmp_path, monkeypatch, capsys):
    """A client holds a case's lock and is stopped (SIGSTOP): another client says in one line
    which case and lock it waits for and who holds it, waits at most $BENCH_LOCK_TIMEOUT s and
    reports the case failed naming the lock — instead of waiting without a word."""
    from bench.run import execute_case, results_path
    from bench.suites import Case

    case = Case("work_precision", "bouncing_ball", law="newton", h=4e-3, t_end=0.3, observers=(),
                reference="closed form")
    folder = results_path("locked", tmp_path)
    out, pid = _behind_a_stopped_holder(folder, case.case_id, monkeypatch,
                                        lambda: execute_case(case, "locked", tmp_path, {}))
    lock = folder / ".locks" / f"{case_key(case.case_id)}.lock"
    assert out.state == "failed" and str(lock) in out.message and "0.5 s" in out.message, out
    assert f"pid {pid} (stopped)" in out.message
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and case.case_id in err[0] and str(lock) in err[0] and "at most 0.5 s" in err[0], err
    assert not (folder.exists() and list(folder.glob("*.parquet")))


def test_quarantine_behind_a_stopped_clients_lock_says_so_and_leaves_the_file(tmp_path, monkeypatch, capsys):
    """A damaged case file whose lock a stopped client holds: the quarantine says which file,
    lock and holder it waits for, gives up after $BENCH_LOCK_TIMEOUT s and leaves the file as
    it is (the next run moves it) — instead of waiting without a bound."""
    from bench.results import CaseStore
    from bench.run import execute_case, results_path
    from bench.suites import Case

    case = Case("work_precision", "bouncing_ball", law="newton", h=4e-3, t_end=0.3, observers=(),
                reference="closed form")
    folder = results_path("quarantined", tmp_path)
    assert execute_case(case, "quarantined", tmp_path, {}).state == "ran"
    (path,) = CaseStore(folder).files()
    path.write_bytes(path.read_bytes()[:-7])                 # damaged: its checksum no longer holds
    assert CaseStore(folder).damaged()
    out, pid = _behind_a_stopped_holder(folder, case.case_id, monkeypatch, CaseStore(folder).quarantine)
    assert out == [] and path.exists()
    lock = folder / ".locks" / f"{case_key(case.case_id)}.lock"
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 2 and all(path.name in ln and str(lock) in ln for ln in err), err
    assert "at most 0.5 s" in err[0] and f"pid {pid} (stopped)" in err[1] and "left as it is" in err[1]
    assert CaseStore(folder).quarantine() and not path.exists()   # the holder gone: moved


def test_a_bench_lock_timeout_that_is_not_a_number_is_refused(monkeypatch):
    from bench.results import lock_timeout
    for bad in ("soon", "-1", "inf", "nan"):
        monkeypatch.setenv("BENCH_LOCK_TIMEOUT", bad)
        with pytest.raises(InputError, match="BENCH_LOCK_TIMEOUT"):
            lock_timeout()
    monkeypatch.setenv("BENCH_LOCK_TIMEOUT", "0")
    assert lock_timeout() == 0.0


# -- item 24: a bench case file copied under another case's name ---------------------------------
def test_a_bench_case_file_copied_under_another_cases_name_is_damaged(tmp_path):
    """Case B's file replaced by a byte copy of case A's (each a valid checksum of its rows): B
    is not done (A's rows name A), the store serves each case once."""
    import shutil

    from bench.results import CaseStore
    store = CaseStore(tmp_path / "s.cases")
    a = store.write_case("s", "case A", [{"x": 1.0}])
    b = store.write_case("s", "case B", [{"x": 2.0}])
    shutil.copyfile(a, b)
    assert store.has("case A") and not store.has("case B")
    reason = store.problem(b)
    assert "'case A'" in reason and "another case's name" in reason, reason
    assert [r["case_id"] for r in store.rows()] == ["case A"]
    assert store.done_ids() == {"case A"}


# -- item 19: SIGINT during a stuck event search -------------------------------------------------
QUIET_TOML = """
[scenario]
name = "quiet"
[system]
M = [[1.0]]
C = [[0.0]]
K = [[1000000.0]]
W = [[1.0]]
[system.gap]
offset = [10.0]
[impact]
law = "newton"
restitution = 0.5
[initial]
q = [1.0]
u = [0.0]
[simulation]
t_end = 100000.0
h = 0.01
"""
"""x'' + ω²x = 0 (ω = 1000 rad/s) from x = 1, a wall 9 below the orbit: one quiet phase of 10⁵ s,
searched in windows of 0.5/ω — one event search that runs for minutes (or stalls)."""


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (``/proc/PID/stat`` fields 14-15)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return float("inf")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _closed_form_rows(t, q, u):
    """Every kept row is the exact orbit x = cos ωt, on the grid k·h without a gap."""
    w = 1000.0
    assert np.allclose(np.diff(t), 0.01, rtol=0, atol=1e-9)
    assert np.max(np.abs(q - np.cos(w * t))) <= 1e-10
    assert np.max(np.abs(u + w * np.sin(w * t))) <= 1e-7


def test_a_signal_during_a_stuck_event_search_stops_it_and_keeps_the_rows(tmp_path, monkeypatch):
    """A stop asked during the one long search: the search ends there (not at its stall
    after MAX_STEPS safe steps, lowered here so that the old behaviour fails fast), the status
    names the signal, and every grid row up to the certified point is kept, exact."""
    import observer.event.roots as roots
    from observer.event.master import run_master
    from observer.scenario import Scenario

    monkeypatch.setattr(roots, "MAX_STEPS", 20000)
    (tmp_path / "quiet.toml").write_text(QUIET_TOML)
    sc = load_scenario(str(tmp_path / "quiet.toml"))
    assert isinstance(sc, Scenario)
    asked = []

    def should_stop():                     # the signal from the 20th look on (the search looks every 64 steps)
        asked.append(time.monotonic())
        return "SIGINT" if len(asked) >= 20 else None
    res = run_master(sc, should_stop=should_stop)
    assert str(res.status).startswith("stopped: SIGINT"), res.status
    assert time.monotonic() - asked[19] < 5
    assert res.t.size > 10
    _closed_form_rows(res.t, res.q[:, 0], res.u[:, 0])


def _cpu_to_exit(command: list[str]) -> tuple[int, float]:
    """Exit status and CPU seconds (user + system) of ``command`` run to its exit."""
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, usage.ru_utime + usage.ru_stime


def test_sigint_during_a_stuck_event_search_exits_promptly_with_the_rows(tmp_path):
    """``observer run`` on the same quiet phase, SIGINT during its search: exit 130
    within seconds (was: at the stall, 0 rows), one line naming the signal, and the result
    holds the exact rows up to where it stopped. The middle is measured on this machine, not
    guessed: the CPU seconds of the same command to t_end = 2h (imports and set-up) and to its
    stall (exit 1, :data:`observer.event.roots.MAX_STEPS` safe steps, then its file); the
    signal is sent a quarter of the way from the one to the other (the search is what lies
    between; the stall's end, its file and exit, is the last part)."""
    (tmp_path / "quiet.toml").write_text(QUIET_TOML)
    (tmp_path / "start.toml").write_text(QUIET_TOML.replace("t_end = 100000.0", "t_end = 0.02"))
    out = tmp_path / "r.csv"
    run = [sys.executable, "-m", "observer", "run", "--integrator", "event"]
    status, setup = _cpu_to_exit([*run[:4], str(tmp_path / "start.toml"), *run[4:], "--out", str(tmp_path / "s.csv")])
    assert status == 0
    status, stall = _cpu_to_exit([*run[:4], str(tmp_path / "quiet.toml"), *run[4:], "--out", str(tmp_path / "t.csv")])
    assert status == 1 and stall - setup > 0.5, (status, setup, stall)   # a search long enough to land in
    proc = subprocess.Popen([*run[:4], str(tmp_path / "quiet.toml"), *run[4:], "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    deadline = time.monotonic() + 120
    while _cpu_seconds(proc.pid) < setup + 0.25 * (stall - setup) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    _, err = proc.communicate(timeout=60)
    assert time.monotonic() - t0 < 10 and proc.returncode == 130, err
    _one_error_line(err, "SIGINT")
    df, meta = read_result(out)
    assert meta["status"]["state"] == "stopped" and len(df) > 10
    _closed_form_rows(df["t"].to_numpy(), df["q0"].to_numpy(), df["u0"].to_numpy())


_TWO_CACHED = _CACHED.replace("    print(f(3.0))", "    print(f(3.0))\n    @njit(cache=True)\n    def g(x):\n        return x - 1.0\n    print(g(3.0))")


@pytest.mark.parametrize("where", ["no-folder-at-all", "pycache-only"])
def test_an_unwritable_cache_folder_is_a_warning_not_a_failure(tmp_path, where):
    """A read-only installation, made real without permissions (root ignores them): the
    module's ``__pycache__`` is a regular file, so numba cannot create its cache beside it.
    With NUMBA_CACHE_DIR and the user's cache folder also below a regular file, numba has no
    folder at all (its ``RuntimeError: no locator available`` at decoration, a traceback
    before): one CacheWarning line, the functions compiled, the right values. With the user's
    cache folder writable, numba caches there and nothing is said."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    (tmp_path / "__pycache__").write_text("")       # the module's cache folder cannot exist
    mod = tmp_path / "m.py"
    mod.write_text(_TWO_CACHED)
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    if where == "no-folder-at-all":
        env.update(NUMBA_CACHE_DIR=str(blocker / "cache"), XDG_CACHE_HOME=str(blocker / "xdg"),
                   HOME=str(blocker))
    else:
        env.update(XDG_CACHE_HOME=str(tmp_path / "xdg"))
    proc = subprocess.run([sys.executable, str(mod), str(ROOT)], capture_output=True, text=True,
                          env=env, timeout=120)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stdout.splitlines()[:2] == ["7.0", "2.0"], proc.stdout
    said = [ln for ln in proc.stderr.splitlines() if "CacheWarning" in ln]
    if where == "no-folder-at-all":
        assert len(said) == 1 and "no writable cache folder" in said[0] and str(mod) in said[0], proc.stderr
    else:
        assert said == [] and list((tmp_path / "xdg").rglob("*.nbi")), proc.stderr


# -- item 24: a failed streamed Parquet write leaves nothing -----------------------------------
@pytest.mark.parametrize("earlier", [False, True])
def test_a_full_disk_during_a_streamed_parquet_run_leaves_nothing(tmp_path, capsys, monkeypatch, earlier):
    """The second row group of a streamed Parquet run fails (ENOSPC): exit 2, one line naming
    the file; the unreadable partial file is gone and so is its ``running`` sidecar (it
    described nothing); an earlier whole file of that name is left as it was, with the
    sidecar saying it is not this run's."""
    import pyarrow.parquet as pq

    from observer.io import running_path
    out = tmp_path / "r.parquet"
    if earlier:
        assert main(["run", "double_mass", "--h", "1e-3", "--t-end", "0.005", "--observers", "none",
                     "--out", str(out)]) == 0
        before = out.read_bytes()
    capsys.readouterr()
    real, calls = pq.ParquetWriter.write_table, []

    def full(self, table, *a, **k):
        calls.append(1)
        if len(calls) == 2:
            _enospc()
        return real(self, table, *a, **k)
    monkeypatch.setattr(pq.ParquetWriter, "write_table", full)
    code = main(["run", "double_mass", "--h", "1e-4", "--t-end", "2", "--observers", "none", "--out", str(out)])
    assert code == 2 and len(calls) == 2
    _one_error_line(capsys.readouterr().err, "r.parquet", "No space left")
    if earlier:
        assert out.read_bytes() == before and _leftovers(tmp_path, {"r.parquet", "r.events.parquet"}) == \
            {running_path(out).name}
        with pytest.raises(InputError, match="earlier one"):
            read_result(out)
    else:
        assert _leftovers(tmp_path, set()) == set()
