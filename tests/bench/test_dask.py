"""Benchmark sweeps on Dask (issue 12 item 6): a killed worker of a 2-worker local cluster and
a killed client lose no finished case, and rerunning completes the sweep with every case
exactly once, none computed twice.

The suite is tiny: eight closed-form work-precision points of the bouncing ball on the numpy
engine (≈ 0.1–0.4 s each). One local cluster serves both tests.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import distributed
import pytest

from bench.results import CaseStore
from bench.run import kernel_ready, results_path, run_suite
from bench.suites import Case, Suite

REPO = Path(__file__).resolve().parents[2]
STEPS = (4e-4, 3.5e-4, 3e-4, 2.5e-4, 2e-4, 4.5e-4, 5e-4, 5.5e-4)


def tiny_suite() -> Suite:
    """Eight cheap, independent cases (the lemke solver runs on the numpy engine)."""
    return Suite("tiny", "Dask kill tests", tuple(
        Case("work_precision", "bouncing_ball", law="newton", solver="lemke", h=h, t_end=0.6,
             observers=(), reference="closed form") for h in STEPS))


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.ERROR) as cluster, \
            distributed.Client(cluster) as c:
        c.run(kernel_ready)            # both workers import the toolkit and load the kernel
        yield c


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.glob("*.parquet"))}


def _wait_for_first_case(store: CaseStore, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not store.files():
        time.sleep(0.005)


def assert_every_case_exactly_once(store: CaseStore, suite: Suite) -> None:
    """One file per declared case (named by its hash), each holding its case's rows once."""
    assert sorted(p.stem for p in store.files()) == sorted(store.case_path(c.case_id).stem
                                                          for c in suite.cases)
    rows = store.rows()
    keys = [(r["case_id"], r["row"]) for r in rows]
    assert len(keys) == len(set(keys)) == len(suite.cases)       # one row per case here
    assert {r["case_id"] for r in rows} == {c.case_id for c in suite.cases}


def test_killed_worker_loses_no_finished_case(client, tmp_path):
    suite = tiny_suite()
    store = CaseStore(results_path(suite.name, tmp_path))
    seen: dict = {}

    def kill_a_busy_worker():
        _wait_for_first_case(store)
        seen["files"] = _snapshot(store.folder)
        busy = [addr for addr, keys in client.processing().items() if keys]
        pids = client.run(os.getpid, workers=busy[:1] or None)
        seen["pid"] = next(iter(pids.values()))
        os.kill(seen["pid"], signal.SIGKILL)

    killer = threading.Thread(target=kill_a_busy_worker)
    killer.start()
    first = run_suite(suite, tmp_path, client=client, progress=False, micro=False)
    killer.join()
    assert 1 <= len(seen["files"]) < len(suite.cases)          # killed mid-sweep
    assert seen["pid"] not in client.run(os.getpid).values()    # that worker is gone
    lost = len(first.failed)                                    # KilledWorker, if any
    # a case the killed worker wrote but could not report is rerun by the scheduler and found
    # on disk ("already done", counted as skipped), not computed again
    assert first.ran + first.skipped + lost == len(suite.cases) and first.unavailable == []
    rerun = run_suite(suite, tmp_path, client=client, progress=False, micro=False)
    assert rerun.failed == [] and rerun.ran == lost             # only what was not finished
    assert rerun.skipped == len(suite.cases) - lost
    assert_every_case_exactly_once(store, suite)
    after = _snapshot(store.folder)
    assert {k: after[k] for k in seen["files"]} == seen["files"]   # none recomputed


def test_killed_client_loses_no_finished_case(client, tmp_path):
    suite = tiny_suite()
    store = CaseStore(results_path(suite.name, tmp_path))
    script = ("import sys; sys.path[:0] = [{repo!r}, {tests!r}]\n"
              "from test_dask import tiny_suite\n"
              "from bench.run import run_suite\n"
              "run_suite(tiny_suite(), {out!r}, scheduler={addr!r}, progress=False, micro=False)\n"
              ).format(repo=str(REPO), tests=str(REPO / "tests" / "bench"), out=str(tmp_path),
                       addr=client.scheduler.address)
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=REPO, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        _wait_for_first_case(store)
        at_kill = _snapshot(store.folder)
        os.killpg(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()
    assert 1 <= len(at_kill) < len(suite.cases)                 # killed mid-sweep
    rerun = run_suite(suite, tmp_path, client=client, progress=False, micro=False)
    assert rerun.failed == [] and rerun.unavailable == []
    assert rerun.ran + rerun.skipped == len(suite.cases)
    assert rerun.ran <= len(suite.cases) - len(at_kill)         # none of the finished ones
    assert_every_case_exactly_once(store, suite)
    after = _snapshot(store.folder)
    assert {k: after[k] for k in at_kill} == at_kill            # byte for byte


def test_unreachable_scheduler_is_an_input_error_naming_the_option(tmp_path, capsys):
    import dask

    from bench.__main__ import main

    with dask.config.set({"distributed.comm.timeouts.connect": "1s"}):
        code = main(["run", "smoke", "--out", str(tmp_path), "--no-progress", "--no-micro",
                     "--scheduler", "tcp://127.0.0.1:9"])
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --scheduler: cannot connect") and "Traceback" not in err
    assert not list(tmp_path.glob("smoke.cases/*.parquet"))


def test_timing_sensitive_cases_run_alone_in_the_client_after_the_cluster(client, tmp_path,
                                                                         monkeypatch):
    """Cases of the kinds in RUN_ALONE (the peers' wall-time comparisons) run in this process
    once the cluster's cases are all done, so nothing runs beside them; the others on the
    cluster. (A tiny work-precision kind stands in for peers, which needs Siconos.)"""
    import bench.run

    closed = Case("work_precision", "bouncing_ball", law="newton", solver="lemke", h=5e-4,
                  t_end=0.6, observers=(), reference="closed form")
    alone = Case("scaling", "rocking_chain", params=(("param.N", 2),), observers=(), h=1e-3,
                 t_end=0.05, memory=False)
    monkeypatch.setattr(bench.run, "RUN_ALONE", ("scaling",))
    summary = run_suite(Suite("alone", "", (alone, closed)), tmp_path, client=client,
                        progress=False, micro=False)
    assert summary.failed == [] and summary.ran == 2 and "scaling cases alone" in summary.where
    rows = {r["kind"]: r for r in CaseStore(results_path("alone", tmp_path)).rows()}
    assert rows["scaling"]["pid"] == os.getpid()
    assert rows["work_precision"]["pid"] in client.run(os.getpid).values()
    assert rows["scaling"]["date"] >= rows["work_precision"]["date"]
