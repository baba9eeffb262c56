"""Run a suite: every case not yet on disk, in this process or on a Dask cluster, each finished
case written at once (its own Parquet file, :class:`bench.results.CaseStore`); then the
micro-benchmarks.

>>> from bench.run import run_suite
>>> summary = run_suite("smoke", out_dir="bench/results")               # doctest: +SKIP
>>> summary = run_suite("full", workers=2)                                # local Dask cluster
>>> summary = run_suite("full", scheduler="tcp://host:8786")             # an existing scheduler

A case's file is written by whoever ran it (this process or a Dask worker) before it reports
back, so a killed worker, a killed client (Ctrl-C, SIGKILL, a crash) or a restarted sweep loses
no finished case, and the next run computes none of them again. On a remote scheduler the
workers need this checkout importable (same environment, ``PYTHONPATH``) and ``OUT`` on a
shared file system.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import time
import traceback
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from observer.errors import InputError
from observer.results_io import meta_path

from bench import RESULTS_DIR
from bench.results import (CASES_SUFFIX, DAMAGED_SUFFIX, STALE, CaseStore, LockTimeout, environment,
                           export_csv)
from bench.suites import Case, Suite, get_suite

REPO = Path(__file__).resolve().parent.parent


@dataclass
class RunSummary:
    """What :func:`run_suite` did."""

    suite: str
    results: Path
    total: int
    skipped: int = 0
    ran: int = 0
    failed: list = field(default_factory=list)
    unavailable: list = field(default_factory=list)
    stale_rows: int = 0
    damaged: list = field(default_factory=list)
    micro: Path | None = None
    micro_status: str = "not requested"
    seconds: float = 0.0
    compile_time_s: float | None = None
    where: str = "this process"

    def text(self) -> str:
        lines = [f"suite {self.suite}: {self.total} cases, {self.skipped} already done, "
                 f"{self.ran} run, {len(self.failed)} failed, {len(self.unavailable)} unavailable "
                 f"({self.seconds:.1f} s, {self.where})", f"results: {self.results}"]
        if self.compile_time_s is not None:
            lines.append(f"compiled kernel ready in {self.compile_time_s:.2f} s (compile or load "
                         f"from numba's cache; before any case was timed, included in the total)")
        if self.stale_rows:
            lines.append(f"moved {self.stale_rows} row(s) of cases no longer in the suite (or "
                         f"written without a column the report now needs) to "
                         f"{self.results / STALE}")
        for path, reason in self.damaged:
            lines.append(f"damaged case file {path.name[:-len(DAMAGED_SUFFIX)]} {reason}: moved "
                         f"aside to {path.name}, its case computed again")
        for cid, msg in self.failed:
            lines.append(f"FAILED {cid}: {msg}")
        for cid, msg in self.unavailable:
            lines.append(f"skipped {cid}: {msg}")
        if self.micro is not None:
            lines.append(f"micro-benchmarks ({self.micro_status}): {self.micro}")
        return "\n".join(lines)


@dataclass(frozen=True)
class Outcome:
    """What became of one case: ``ran`` (its file written), ``done`` (its file was already
    there: nothing computed), ``unavailable`` or ``failed`` (with the message)."""

    case_id: str
    state: str
    message: str = ""


def results_path(suite: str, out_dir: str | Path = RESULTS_DIR) -> Path:
    """``OUT/<suite>.cases``: the folder of the suite's case files (what
    :func:`bench.results.load_results` takes)."""
    return Path(out_dir) / f"{suite}{CASES_SUFFIX}"


def unavailable_path(suite: str, out_dir: str | Path = RESULTS_DIR) -> Path:
    """``OUT/<suite>.unavailable.json``: cases skipped in the last run, with the reason."""
    return Path(out_dir) / f"{suite}.unavailable.json"


def micro_path(suite: str, out_dir: str | Path = RESULTS_DIR) -> Path:
    """``OUT/<suite>-micro.json``."""
    return Path(out_dir) / f"{suite}-micro.json"


def outdated_ids(rows: list[dict]) -> set[str]:
    """Cases with a row that lacks a column its kind requires now
    (:data:`bench.runners.REQUIRED_COLUMNS`, e.g. settling times added after the row was
    written): their files are moved to the stale folder and the cases run again."""
    from bench.runners import REQUIRED_COLUMNS

    return {r.get("case_id", "") for r in rows
            if r.get("status", "ok") == "ok"
            and any(c not in r for c in REQUIRED_COLUMNS.get(r.get("kind", ""), ()))}


_KERNEL_TIME: list[float] = []


def kernel_ready() -> float:
    """Compile the time-loop kernel, or load it from numba's on-disk cache, once per process,
    before any case is timed (:func:`observer.engines.compiled.driver.compile_time`), then run every built-in
    scenario for a few steps on the compiled engine, master alone and with its observers
    (:func:`warm_up_scenarios`): the kernel's warm-up system does not reach every
    specialization (measured in a fresh clone: the first master-only double_mass run after
    it still spent seconds compiling). Return the seconds it all took the first time (NaN
    when the toolkit has no compiled engine)."""
    if not _KERNEL_TIME:
        try:
            from observer.engines.compiled.driver import compile_time
        except ImportError:
            _KERNEL_TIME.append(float("nan"))
        else:
            t0 = time.perf_counter()
            compile_time()
            warm_up_scenarios()
            _KERNEL_TIME.append(time.perf_counter() - t0)
    return _KERNEL_TIME[0]


WARM_UP_STEPS = 20
"""Steps of each warm-up run (:func:`warm_up_scenarios`)."""


def warm_up_scenarios() -> None:
    """Run each built-in scenario for :data:`WARM_UP_STEPS` steps on the compiled engine, the
    master alone and with the observers its suite cases use, and the ball briefly on the event
    engine, so that numba compiles (or loads) every specialization before a case is timed."""
    import observer
    from observer.scenarios import SCENARIOS

    for name in SCENARIOS:
        sc = observer.load_scenario(name)
        sc = sc.with_overrides({"simulation.t_end": WARM_UP_STEPS * sc.h})
        observer.simulate(sc, observers=(), engine="compiled")
        if sc.observer:
            observer.simulate(sc, engine="compiled")
    # the event engine's compiled root finders (numba: importing and loading them is timed apart)
    observer.simulate("bouncing_ball", t_end=WARM_UP_STEPS * 1e-3, integrator="event")


def execute_case(case: Case, suite: str, out_dir: str | Path, env: dict,
                 reference_grids: dict | None = None) -> Outcome:
    """Run one case in this process (the client or a Dask worker) and write its file.

    Nothing is computed when the case is done (a worker that died after writing it, a case
    finished by an earlier sweep or by a concurrent client): the case's lock
    (:meth:`~bench.results.CaseStore.lock`) is held while it is checked, computed and written.
    A lock another client holds is waited for with one line saying so, at most
    :func:`bench.results.lock_timeout` seconds; past that the case is ``failed`` with the
    lock and its holder named (:meth:`~bench.results.CaseStore.holding`).
    The kernel is made ready in this process first, so no case pays its compile time;
    ``compile_time_s`` and ``pid`` in the rows are this process's. ``reference_grids``
    (:func:`bench.runners.reference_grids` of the run's cases) lets the work-precision cases of
    one sweep share one event-driven reference per process.
    """
    store = CaseStore(results_path(suite, out_dir))
    if store.has(case.case_id):
        return Outcome(case.case_id, "done")
    try:
        with store.holding(case.case_id):    # another client may be computing it: wait, then look again
            return _compute_held(case, suite, out_dir, env, reference_grids, store)
    except LockTimeout as exc:
        return Outcome(case.case_id, "failed", str(exc))


def _compute_held(case: Case, suite: str, out_dir, env: dict, reference_grids, store: CaseStore) -> Outcome:
    """:func:`execute_case` once the case's lock is held: look again, run, write."""
    from bench.runners import Context, Unavailable, run_case

    if store.has(case.case_id):
        return Outcome(case.case_id, "done")
    env = {**env, "compile_time_s": kernel_ready(), "pid": os.getpid()}
    try:
        rows = run_case(case, Context(suite, Path(out_dir), env,
                                      reference_grids=dict(reference_grids or {})))
    except Unavailable as exc:
        return Outcome(case.case_id, "unavailable", str(exc))
    except KeyboardInterrupt:
        raise
    except Exception as exc:  # record and go on; the case is retried next time
        if os.environ.get("BENCH_TRACEBACK"):
            traceback.print_exc()
        return Outcome(case.case_id, "failed", f"{type(exc).__name__}: {exc}")
    store.write_case(suite, case.case_id, rows)
    return Outcome(case.case_id, "ran")


def run_suite(suite: str | Suite, out_dir: str | Path = RESULTS_DIR, *, progress: bool = True,
              limit: int | None = None, micro: bool = True, workers: int | None = None,
              scheduler: str | None = None, client=None) -> RunSummary:
    """Run the cases of ``suite`` that are not yet on disk.

    Parameters
    ----------
    suite : str or Suite
        A name in :data:`bench.suites.SUITES` or a Suite.
    out_dir : path
        Results folder (``OUT/<suite>.cases/`` plus artefacts).
    progress : bool
        Show a tqdm progress bar (on stderr).
    limit : int, optional
        Run at most this many of the remaining cases (to test interruption/resume).
    micro : bool
        Also run the suite's pytest-benchmark micro-benchmarks if their JSON is missing.
    workers : int, optional
        Run the cases on a local Dask cluster of this many single-threaded worker processes.
    scheduler : str, optional
        Address of an existing Dask scheduler to run the cases on (``tcp://host:8786``).
    client : distributed.Client, optional
        A client to run the cases on (the caller keeps and closes it).
        With none of ``workers``, ``scheduler``, ``client``: in this process, one by one.

    Returns
    -------
    RunSummary
    """
    suite = get_suite(suite) if isinstance(suite, str) else suite
    out_dir = Path(out_dir)
    t0 = time.perf_counter()
    store = CaseStore(results_path(suite.name, out_dir))
    summary = RunSummary(suite.name, store.path, len(suite.cases))
    store.remove_orphans()
    summary.damaged = store.quarantine()
    summary.stale_rows = (store.retire_undeclared(c.case_id for c in suite.cases)
                          + store.retire(outdated_ids(store.rows())))
    write_suite_meta(suite, out_dir)
    todo = [c for c in suite.cases if not store.has(c.case_id)]
    summary.skipped = len(suite.cases) - len(todo)
    if limit is not None:
        todo = todo[:max(0, limit)]
    todo = run_order(todo)
    from bench.runners import reference_grids

    env = environment()
    grids = reference_grids(todo)
    alone = [c for c in todo if c.kind in RUN_ALONE]
    shared = [c for c in todo if c.kind not in RUN_ALONE]
    if alone or (shared and client is None and scheduler is None):
        # compiled here first (local workers then load it from numba's disk cache); on a
        # remote cluster each worker makes it ready before its first case
        summary.compile_time_s = kernel_ready()
    bar = _progress(len(todo), suite.name, enabled=progress) if todo else _NoBar()

    def record(outs) -> None:
        for out in outs:
            bar.set_postfix_str(out.case_id[:60])
            bar.update(1)
            _record(summary, out)

    if shared:        # a finished suite starts no cluster
        with _executor(workers, scheduler, client) as (where, outcomes):
            summary.where = where
            record(outcomes(shared, suite.name, out_dir, env, grids))
    if alone:         # after the cluster is gone: nothing else runs beside them
        record(_in_process(alone, suite.name, out_dir, env, grids))
        summary.where = (f"{summary.where if shared else ''}"
                         f"{'; ' if shared else ''}{', '.join(sorted({c.kind for c in alone}))} "
                         f"cases alone in this process")
    bar.close()
    if store.files():
        export_csv(store.path, out_dir / f"{suite.name}.csv")
    _write_unavailable(summary, unavailable_path(suite.name, out_dir))
    if micro and suite.micro is not None:
        summary.micro = micro_path(suite.name, out_dir)
        summary.micro_status = run_micro(suite, summary.micro)
    summary.seconds = time.perf_counter() - t0
    return summary


RUN_ALONE = ("peers",)
"""Kinds run last, in the client process, with no other case running: their rows compare
wall times per step (Siconos and the toolkit), which a neighbouring case on a shared core
would inflate."""

RUN_ORDER = ("observers", "checks", "peers", "scaling", "work_precision", "robustness")
"""Kinds in the order their cases are handed out, the longest first, so that no worker of a
cluster is left alone with a long case at the end (the order measured on ``quick``: the exact
observers cases, then the checks of double_mass, then the rest). Kinds
not listed (registered later, cost unknown) go first."""


def run_order(cases: list[Case]) -> list[Case]:
    """``cases`` in :data:`RUN_ORDER` (stable within a kind; exact, event-driven observer
    cases before time-stepped ones)."""
    def rank(c: Case) -> tuple[int, bool]:
        kind = RUN_ORDER.index(c.kind) if c.kind in RUN_ORDER else -1
        return kind, c.integrator != "event"
    return sorted(cases, key=rank)


MAX_DEFAULT_WORKERS = 4


def default_workers() -> int:
    """Worker processes of the local cluster ``python -m bench run`` starts by default: one
    per core this process may use, at most :data:`MAX_DEFAULT_WORKERS` (each case is
    single-threaded and CPU times are per process, so a case's timing does not include its
    neighbours'; memory grows by ≈ 0.5 GB per worker)."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:                      # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, MAX_DEFAULT_WORKERS))


def _record(summary: RunSummary, out: Outcome) -> None:
    if out.state == "ran":
        summary.ran += 1
    elif out.state == "done":
        summary.skipped += 1
    elif out.state == "unavailable":
        summary.unavailable.append((out.case_id, out.message))
    else:
        summary.failed.append((out.case_id, out.message))


def write_suite_meta(suite: Suite, out_dir: str | Path = RESULTS_DIR) -> Path:
    """Write ``OUT/<suite>.meta.json`` (:func:`observer.results_io.meta_path`): what the suite
    declares that its rows do not carry, for the report (which reads results, not
    :mod:`bench`): ``"suite"``; ``"cases"``, its case ids in declared order; its
    ``"description"`` and ``"settings"`` (as text); the robustness ``"band"``
    (:data:`bench.suites.BAND`), ``"scaling_fit_from"`` (:data:`bench.suites.SCALING_FIT_FROM`)
    and the robustness ``"perturbations"`` (``kinds``, ``labels``, ``units`` of :mod:`bench.perturb`);
    ``"siconos"``, whether the peer suite's Siconos could be driven when the suite ran
    (:func:`bench.peers.siconos_record`). Written whole (a temporary file, then a rename)."""
    from bench.peers import siconos_record
    from bench.perturb import KINDS, LABELS, UNITS
    from bench.suites import BAND, SCALING_FIT_FROM

    path = meta_path(suite.name, out_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    meta = {"suite": suite.name, "cases": [c.case_id for c in suite.cases], "description": suite.description,
            "settings": {str(k): str(v) for k, v in suite.settings.items()}, "band": list(BAND),
            "scaling_fit_from": SCALING_FIT_FROM,
            "perturbations": {"kinds": list(KINDS), "labels": dict(LABELS), "units": dict(UNITS)},
            "siconos": siconos_record()}
    tmp.write_text(json.dumps(meta, indent=1))
    os.replace(tmp, path)
    return path


def _write_unavailable(summary: RunSummary, note: Path) -> None:
    if summary.unavailable:
        note.parent.mkdir(parents=True, exist_ok=True)
        note.write_text(json.dumps(dict(summary.unavailable), indent=1))
    elif note.exists():
        note.unlink()


def _in_process(cases, suite, out_dir, env, grids):
    for case in cases:
        yield execute_case(case, suite, out_dir, env, grids)


def _on_dask(client):
    """An outcome generator submitting every case to ``client``, yielding as they finish."""
    from bench.results import case_key

    def outcomes(cases, suite, out_dir, env, grids):
        from distributed import as_completed

        # one key per (results folder, case): a resubmitted case still running for a killed
        # client is joined, not computed a second time
        folder = str(Path(out_dir).resolve())
        futures = {client.submit(execute_case, c, suite, str(out_dir), env, grids, pure=False,
                                 key=f"bench-{suite}-{case_key(folder + '|' + c.case_id)}"): c
                   for c in cases}
        for fut in as_completed(futures):
            try:
                yield fut.result()
            except Exception as exc:  # e.g. KilledWorker: the case is retried next time
                yield Outcome(futures[fut].case_id, "failed", f"{type(exc).__name__}: {exc}")
    return outcomes


@contextmanager
def _executor(workers: int | None, scheduler: str | None, client):
    """``(where, outcomes)``: a description and the function that runs cases and yields
    their :class:`Outcome` (in this process, or on a Dask client it opens and closes)."""
    if client is not None:
        yield f"Dask client {client.scheduler.address}", _on_dask(client)
        return
    if not workers and not scheduler:
        yield "this process", _in_process
        return
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        with _connect(scheduler) as c:
            yield f"Dask scheduler {scheduler}", _on_dask(c)
        return
    with dask.config.set(QUIET_WORKERS), \
            LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                         dashboard_address=None, silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as c:
        yield f"local Dask cluster of {int(workers)} worker(s)", _on_dask(c)


QUIET_WORKERS = {"distributed.worker.profile.enabled": False,
                 "distributed.admin.system-monitor.gil.enabled": False}
"""Dask settings of the local cluster's workers: no statistical profiler (a thread sampling
the running case's stack every 10 ms) and no GIL monitor (polling every 1 ms) — both run
beside the timed cases and cost CPU (a few per cent of quick's work-precision
cases)."""


def _connect(address: str):
    """A client of the scheduler at ``address``; an unreachable one is an input error naming
    ``--scheduler`` (the wait is Dask's ``distributed.comm.timeouts.connect``)."""
    from distributed import Client

    try:
        return Client(address)
    except (OSError, ValueError, TypeError) as exc:
        raise InputError("--scheduler", f"cannot connect to a Dask scheduler at {address!r} "
                                        f"({type(exc).__name__}: {exc})") from None


class _NoBar:
    """Stand-in for a tqdm bar when tqdm is missing or progress is off."""

    def update(self, n: int) -> None:
        pass

    def set_postfix_str(self, text: str) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, name: str, enabled: bool):
    """A tqdm progress bar on stderr (cases done / total, elapsed, ETA) if available."""
    if enabled:
        try:
            from tqdm import tqdm
        except ImportError:
            print(f"{name}: {total} cases to run (install tqdm for a progress bar)",
                  file=sys.stderr)
        else:
            return tqdm(total=total, desc=name, unit="case", file=sys.stderr, dynamic_ncols=True)
    return _NoBar()


def run_micro(suite: Suite, json_path: Path, force: bool = False) -> str:
    """Run ``pytest bench/micro`` with pytest-benchmark, writing ``json_path`` atomically.

    Skipped when the JSON exists (resume) unless ``force``. Returns a status word.
    """
    json_path = Path(json_path)
    if json_path.exists() and not force:
        return "already done"
    json_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = json_path.with_suffix(".json.tmp")
    env = dict(os.environ)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH", "")]))
    cmd = [sys.executable, "-m", "pytest", str(REPO / "bench" / "micro"), "-q", "-p", "no:cacheprovider",
           "--benchmark-only", f"--benchmark-json={tmp}", "--benchmark-disable-gc",
           "--benchmark-columns=mean,median,stddev,rounds", *suite.micro]
    proc = subprocess.run(cmd, cwd=REPO, env=env)
    if proc.returncode != 0 or not tmp.exists():
        return f"failed (pytest exit code {proc.returncode})"
    os.replace(tmp, json_path)
    return "ran"
