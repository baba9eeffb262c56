"""Run a suite: resume from its results file, append each finished case, then the micro-benchmarks.

>>> from bench.run import run_suite
>>> summary = run_suite("smoke", out_dir="bench/results")     # doctest: +SKIP

An interrupted run (Ctrl-C, a killed process, a crash) loses at most the case that was
running: every finished case is already on disk, and the next run skips it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

from bench import RESULTS_DIR
from bench.results import ResultsFile, environment, export_csv
from bench.suites import Suite, get_suite

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
    repaired_lines: int = 0
    stale_rows: int = 0
    micro: Path | None = None
    micro_status: str = "not requested"
    seconds: float = 0.0
    compile_time_s: float | None = None

    def text(self) -> str:
        lines = [f"suite {self.suite}: {self.total} cases, {self.skipped} already done, "
                 f"{self.ran} run, {len(self.failed)} failed, {len(self.unavailable)} unavailable "
                 f"({self.seconds:.1f} s)", f"results: {self.results}"]
        if self.compile_time_s is not None:
            lines.append(f"compiled kernel ready in {self.compile_time_s:.2f} s (compile or load "
                         f"from numba's cache; before any case was timed, included in the total)")
        if self.repaired_lines:
            lines.append(f"dropped {self.repaired_lines} line(s) of an interrupted case")
        if self.stale_rows:
            lines.append(f"moved {self.stale_rows} row(s) of cases no longer in the suite (or "
                         f"written without a column the report now needs) to "
                         f"{self.results.stem}.stale.jsonl")
        for cid, msg in self.failed:
            lines.append(f"FAILED {cid}: {msg}")
        for cid, msg in self.unavailable:
            lines.append(f"skipped {cid}: {msg}")
        if self.micro is not None:
            lines.append(f"micro-benchmarks ({self.micro_status}): {self.micro}")
        return "\n".join(lines)


def results_path(suite: str, out_dir: str | Path = RESULTS_DIR) -> Path:
    """``OUT/<suite>.jsonl``."""
    return Path(out_dir) / f"{suite}.jsonl"


def unavailable_path(suite: str, out_dir: str | Path = RESULTS_DIR) -> Path:
    """``OUT/<suite>.unavailable.json``: cases skipped in the last run, with the reason."""
    return Path(out_dir) / f"{suite}.unavailable.json"


def micro_path(suite: str, out_dir: str | Path = RESULTS_DIR) -> Path:
    """``OUT/<suite>-micro.json``."""
    return Path(out_dir) / f"{suite}-micro.json"


def outdated_ids(rows: list[dict]) -> set[str]:
    """Cases with a row that lacks a column its kind requires now
    (:data:`bench.runners.REQUIRED_COLUMNS`, e.g. settling times added after the row was
    written): they are moved to the stale file and run again."""
    from bench.runners import REQUIRED_COLUMNS

    return {r.get("case_id", "") for r in rows
            if r.get("status", "ok") == "ok"
            and any(c not in r for c in REQUIRED_COLUMNS.get(r.get("kind", ""), ()))}


def run_suite(suite: str | Suite, out_dir: str | Path = RESULTS_DIR, *, progress: bool = True,
              limit: int | None = None, micro: bool = True) -> RunSummary:
    """Run the cases of ``suite`` that are not yet in its results file.

    Parameters
    ----------
    suite : str or Suite
        A name in :data:`bench.suites.SUITES` or a Suite.
    out_dir : path
        Results folder (``OUT/<suite>.jsonl`` plus artefacts).
    progress : bool
        Show a tqdm progress bar (on stderr).
    limit : int, optional
        Run at most this many of the remaining cases (to test interruption/resume).
    micro : bool
        Also run the suite's pytest-benchmark micro-benchmarks if their JSON is missing.

    Returns
    -------
    RunSummary
    """
    from bench.runners import Context, Unavailable, run_case

    suite = get_suite(suite) if isinstance(suite, str) else suite
    out_dir = Path(out_dir)
    t0 = time.perf_counter()
    rf = ResultsFile(results_path(suite.name, out_dir))
    summary = RunSummary(suite.name, rf.path, len(suite.cases))
    summary.repaired_lines = rf.repair()
    summary.stale_rows = rf.prune({c.case_id for c in suite.cases} - outdated_ids(rf.rows()))
    done = rf.done_ids()
    todo = [c for c in suite.cases if c.case_id not in done]
    summary.skipped = len(suite.cases) - len(todo)
    if limit is not None:
        todo = todo[:max(0, limit)]
    ctx = Context(suite.name, out_dir, environment())
    if todo:
        summary.compile_time_s = ctx.env["compile_time_s"] = kernel_ready()
    bar = _progress(todo, suite.name, enabled=progress and bool(todo))
    for case in bar:
        bar.set_postfix_str(f"{case.kind}: {case.name}"[:60])
        try:
            rows = run_case(case, ctx)
        except Unavailable as exc:
            summary.unavailable.append((case.case_id, str(exc)))
            continue
        except KeyboardInterrupt:
            raise
        except Exception as exc:  # record and go on; the case is retried next time
            summary.failed.append((case.case_id, f"{type(exc).__name__}: {exc}"))
            if os.environ.get("BENCH_TRACEBACK"):
                traceback.print_exc()
            continue
        rf.append_case(suite.name, case.case_id, rows)
        summary.ran += 1
    bar.close()
    if rf.path.exists():
        export_csv(rf.path)
    note = unavailable_path(suite.name, out_dir)
    if summary.unavailable:
        note.parent.mkdir(parents=True, exist_ok=True)
        note.write_text(json.dumps(dict(summary.unavailable), indent=1))
    elif note.exists():
        note.unlink()
    if micro and suite.micro is not None:
        summary.micro = micro_path(suite.name, out_dir)
        summary.micro_status = run_micro(suite, summary.micro)
    summary.seconds = time.perf_counter() - t0
    return summary


def kernel_ready() -> float:
    """Compile the time-loop kernel, or load it from numba's on-disk cache, once, before any
    case is timed (:func:`observer.loop.compile_time`); return the seconds it took (NaN when
    the toolkit has no compiled engine)."""
    try:
        from observer.loop import compile_time
    except ImportError:
        return float("nan")
    return float(compile_time())


class _NoBar(list):
    """Stand-in for a tqdm bar when tqdm is missing or progress is off."""

    def set_postfix_str(self, text: str) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(items: list, name: str, enabled: bool):
    """A tqdm progress bar on stderr (cases done / total, elapsed, ETA) if available."""
    if enabled:
        try:
            from tqdm import tqdm
        except ImportError:
            print(f"{name}: {len(items)} cases to run (install tqdm for a progress bar)",
                  file=sys.stderr)
        else:
            return tqdm(items, desc=name, unit="case", file=sys.stderr, dynamic_ncols=True)
    return _NoBar(items)


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
