"""Benchmark results: one Parquet file per finished case; loading a suite is a concat.

Layout of a suite's output folder ``OUT`` (default ``bench/results``)::

    OUT/<suite>.cases/<key>.parquet   the rows of one finished case (key: hash of its case_id,
                                      i.e. of its declared parameters)
    OUT/<suite>.cases/stale/          case files no longer in the suite, or written without a
                                      column the report now needs (kept, not loaded)
    OUT/<suite>.csv                   all rows as CSV, exported when a run of the suite ends
    OUT/<suite>.meta.json             what the suite declares that its rows do not carry (its
                                      case order, Siconos), for the report (:func:`bench.run.write_suite_meta`)
    OUT/<suite>-micro.json            pytest-benchmark JSON of the micro-benchmarks
    OUT/<suite>/traj/<case>.parquet   downsampled trajectories for the report's figures
    OUT/<suite>/logs/<case>.csv       perturbed closing logs of the perturbed-χ ensembles

A case file is written under a temporary name in the same folder and renamed: it appears
complete or not at all, whatever kills the writer. Its Parquet schema metadata carries a
SHA-256 checksum of its rows (:func:`content_digest`). A case is *done* when its file opens,
holds ``case_rows`` rows and its checksum matches (:meth:`CaseStore.has`); a damaged file
(cut short, altered, written without a checksum) is reported, moved aside to
``<key>.parquet.damaged`` by the next ``bench run`` (:meth:`CaseStore.quarantine`) and its
case computed again. A killed process (client or worker) loses at most the cases it was
running, and a rerun computes none twice; concurrent clients on one folder take a lock per
case (:meth:`CaseStore.lock`, ``filelock``), so each case is computed once. Every row
carries ``suite``, ``case_id``, ``case_rows`` (rows of the case) and ``row`` (0-based index
within the case); the kinds of runs have different metric columns, so :func:`load_results`
concatenates with NaN for a kind's missing columns.
"""

from __future__ import annotations

import os
import platform
import sys
import time
import uuid
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable

from observer.result import package_versions
from observer.results_io import (  # the reading side, shared with the report
    CASES_SUFFIX, CHECKSUM_KEY, DamagedCase, case_files, case_key, content_digest, cpu_model, frame_of,
    git_commit, load_results, read_case)

RESERVED = ("suite", "case_id", "case_rows", "row")
#: Suffix appended to a damaged case file when it is moved aside.
DAMAGED_SUFFIX = ".damaged"
#: Subfolder of the per-case lock files.
LOCKS = ".locks"
STALE = "stale"


def _table(rows: list[dict]):
    """A pyarrow table of ``rows`` with the union of their keys as columns (null where a row
    lacks one); a column mixing kinds of values (a number in one row, text in another) is
    stored as text rather than refused."""
    import pyarrow as pa

    names = list(dict.fromkeys(k for r in rows for k in r))
    columns = {}
    for k in names:
        values = [r.get(k) for r in rows]
        try:
            columns[k] = pa.array(values)
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            columns[k] = pa.array([None if v is None else str(v) for v in values])
    return pa.table(columns)


LOCK_TIMEOUT_S = 3600.0
"""Default of the longest wait for a case's lock held by another client (:meth:`CaseStore.holding`)."""
LOCK_TIMEOUT_ENV = "BENCH_LOCK_TIMEOUT"
"""Environment variable that sets that wait in seconds."""


class LockTimeout(Exception):
    """A case's lock stayed held by another client beyond the wait (:meth:`CaseStore.holding`)."""


def lock_timeout() -> float:
    """The longest wait for a case's lock: ``$BENCH_LOCK_TIMEOUT`` seconds (a finite number
    ≥ 0), else :data:`LOCK_TIMEOUT_S`."""
    raw = os.environ.get(LOCK_TIMEOUT_ENV)
    if raw is None:
        return LOCK_TIMEOUT_S
    try:
        value = float(raw)
    except ValueError:
        value = float("nan")
    if not (0.0 <= value < float("inf")):
        from observer.errors import InputError
        raise InputError(LOCK_TIMEOUT_ENV, f"must be a number of seconds ≥ 0, got {raw!r}")
    return value


def _holder(owner: Path) -> str:
    """Who holds a lock: the pid in its ``.owner`` file and whether that process is stopped."""
    try:
        pid = int(owner.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return "another client"
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        state = ""
    return f"pid {pid}" + (" (stopped)" if state in ("T", "t") else "")


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


class CaseStore:
    """The folder of one suite's case files.

    Parameters
    ----------
    folder : str or Path
        ``OUT/<suite>.cases`` (:func:`bench.run.results_path`); created on the first write.
        Its parent is the results folder the rows' artefact paths are relative to.
    """

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self._verified: dict[Path, tuple] = {}     # path -> (mtime_ns, size, reason or None)

    @property
    def path(self) -> Path:
        """The folder (what :func:`load_results` takes)."""
        return self.folder

    def case_path(self, case_id: str) -> Path:
        """``FOLDER/<case_key>.parquet``."""
        return self.folder / f"{case_key(case_id)}.parquet"

    def files(self) -> list[Path]:
        """The case files, sorted by name (stale and damaged ones excluded), unverified."""
        return case_files(self.folder)

    def problem(self, path: Path) -> str | None:
        """Why the case file ``path`` is damaged (:func:`observer.results_io.read_case`), or
        None when it is whole; remembered until the file changes (its mtime or size)."""
        try:
            st = path.stat()
        except FileNotFoundError:
            return "is missing"
        stamp = (st.st_mtime_ns, st.st_size)
        cached = self._verified.get(path)
        if cached is not None and cached[:2] == stamp:
            return cached[2]
        return self._read(path, stamp)[1]

    def _read(self, path: Path, stamp: tuple) -> tuple:
        """``(table or None, reason or None)`` of the case file ``path``
        (:func:`observer.results_io.read_case`), its verdict remembered under ``stamp``."""
        try:
            table, reason = read_case(path), None
        except DamagedCase as exc:
            table, reason = None, exc.reason
        self._verified[path] = (*stamp, reason)
        return table, reason

    def good_files(self) -> list[Path]:
        """The case files that are whole (they open, their checksum matches)."""
        return [f for f in self.files() if self.problem(f) is None]

    def damaged(self) -> list[tuple[Path, str]]:
        """``(path, reason)`` of every damaged case file."""
        return [(f, r) for f in self.files() if (r := self.problem(f)) is not None]

    def quarantine(self) -> list[tuple[Path, str]]:
        """Move every damaged case file to ``<name>.damaged`` (its case is then computed
        again); return ``(moved-to path, reason)`` of each. A case whose lock a client holds
        is waited for as :meth:`holding` waits (said, and at most :func:`lock_timeout`
        seconds); past that the file is left as it is, in one line."""
        moved = []
        for f, _ in self.damaged():
            try:
                with self._held(f.stem, f"case file {f.name!r}"):   # a client may be rewriting it
                    reason = self.problem(f)
                    if reason is None or reason == "is missing":
                        continue              # rewritten whole, or moved by another client
                    dest = f.with_name(f.name + DAMAGED_SUFFIX)
                    os.replace(f, dest)
            except LockTimeout as exc:        # its holder is stuck: the file stays, said once
                _say(f"bench: case file {f.name!r} left as it is: {exc}")
                continue
            moved.append((dest, reason))
        return moved

    def has(self, case_id: str) -> bool:
        """Whether the case is done: its file exists, opens and its checksum matches."""
        path = self.case_path(case_id)
        return path.exists() and self.problem(path) is None

    def lock(self, case_id: str):
        """An inter-process lock of one case (``filelock.FileLock`` on
        ``FOLDER/.locks/<key>.lock``): hold it to check, compute and write the case, so that
        concurrent clients on one folder compute it once."""
        return self._lock(case_key(case_id))

    @contextmanager
    def holding(self, case_id: str, timeout: float | None = None, say=None):
        """Hold the case's lock (:meth:`lock`), waiting at most ``timeout`` seconds
        (:func:`lock_timeout` by default) for a client that holds it.

        A wait is said first, in one line to ``say`` (stderr by default) naming the case,
        the lock file and the holder (its pid, and "stopped" when it is: a suspended client
        keeps its lock); past the timeout :class:`LockTimeout` is raised, naming the same.
        The holder's pid is kept beside the lock (``<key>.owner``) while it is held.
        """
        with self._held(case_key(case_id), f"case {case_id!r}", timeout, say):
            yield

    @contextmanager
    def _held(self, key: str, what: str, timeout: float | None = None, say=None):
        """:meth:`holding` on the lock of ``key`` (``what`` names it in the lines)."""
        from filelock import Timeout

        timeout = lock_timeout() if timeout is None else float(timeout)
        lock = self._lock(key)
        owner = Path(lock.lock_file).with_suffix(".owner")
        try:
            lock.acquire(timeout=0)
        except Timeout:
            (say or _say)(f"bench: {what} waits for its lock {lock.lock_file}, held by "
                          f"{_holder(owner)}; at most {timeout:g} s ({LOCK_TIMEOUT_ENV})")
            try:
                lock.acquire(timeout=timeout)
            except Timeout:
                raise LockTimeout(f"its lock {lock.lock_file} was held by {_holder(owner)} for more "
                                  f"than {timeout:g} s ({LOCK_TIMEOUT_ENV}): not computed; it is "
                                  "computed by the next run once that client ends") from None
        try:
            owner.write_text(f"{os.getpid()}\n")
            yield
        finally:
            owner.unlink(missing_ok=True)
            lock.release()

    def _lock(self, key: str):
        from filelock import FileLock

        locks = self.folder / LOCKS
        locks.mkdir(parents=True, exist_ok=True)
        return FileLock(locks / f"{key}.lock")

    def write_case(self, suite: str, case_id: str, rows: list[dict]) -> Path:
        """Write the rows of one finished case with their checksum: a temporary file, then an
        atomic rename. A failed write (disk full) leaves no temporary file and raises the
        :class:`OSError` naming the case file."""
        if not rows:
            raise ValueError(f"case {case_id!r} produced no rows")
        clash = sorted({k for r in rows for k in RESERVED if k in r})
        if clash:
            raise ValueError(f"row of case {case_id!r} uses reserved column(s) {clash}")
        import pyarrow.parquet as pq

        table = _table([{"suite": suite, "case_id": case_id, "case_rows": len(rows), "row": i, **r}
                        for i, r in enumerate(rows)])
        table = table.replace_schema_metadata({CHECKSUM_KEY: content_digest(table).encode("ascii")})
        final = self.case_path(case_id)
        tmp = self.folder / f".{final.stem}.{uuid.uuid4().hex}.tmp"
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            pq.write_table(table, tmp)
            os.replace(tmp, final)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            if exc.filename is None or Path(exc.filename) == tmp:
                exc.filename = str(final)
            raise
        return final

    append_case = write_case

    def frame(self):
        """All rows of the done cases, one DataFrame (cases in file-name order)."""
        return frame_of(self.files(), self._table)

    def _table(self, path: Path):
        """The table of the case file ``path`` (each file read once: verified, then converted),
        or None when it is damaged or gone."""
        try:
            st = path.stat()
        except FileNotFoundError:
            return None
        return self._read(path, (st.st_mtime_ns, st.st_size))[0]

    def rows(self) -> list[dict]:
        """The rows as written (Python values, NaN kept; a key absent from a row and null in
        its file is left out), cases in file-name order."""
        import pyarrow.parquet as pq

        return [{k: v for k, v in r.items() if v is not None}
                for f in self.good_files() for r in pq.read_table(f).to_pylist()]

    def done_ids(self) -> set[str]:
        """``case_id`` of every done case."""
        import pyarrow.parquet as pq

        return {pq.read_table(f, columns=["case_id"]).column(0)[0].as_py() for f in self.good_files()}

    def remove_orphans(self, max_age_s: float = 3600.0) -> int:
        """Delete temporary files of writers killed mid-write (older than ``max_age_s``: a case
        file takes milliseconds to write, so a younger one may belong to a live writer);
        return how many were deleted."""
        if not self.folder.is_dir():
            return 0
        cutoff = time.time() - max_age_s
        orphans = [p for p in self.folder.glob(".*.tmp") if p.stat().st_mtime < cutoff]
        for p in orphans:
            p.unlink(missing_ok=True)
        return len(orphans)

    def retire(self, case_ids: Iterable[str]) -> int:
        """Move the files of ``case_ids`` to ``FOLDER/stale/`` (they are then rerun); return
        how many rows they held."""
        import pyarrow.parquet as pq

        moved = 0
        for cid in case_ids:
            src = self.case_path(cid)
            if src.exists():
                moved += pq.read_metadata(src).num_rows
                (self.folder / STALE).mkdir(exist_ok=True)
                os.replace(src, self.folder / STALE / src.name)
        return moved

    def retire_undeclared(self, keep_ids: Iterable[str]) -> int:
        """Retire the files whose case is not in ``keep_ids`` (the grid changed)."""
        keys = {case_key(c) for c in keep_ids}
        stray = [f for f in self.good_files() if f.stem not in keys]
        import pyarrow.parquet as pq

        ids = [pq.read_table(f, columns=["case_id"]).column(0)[0].as_py() for f in stray]
        return self.retire(ids)


#: The former name of :class:`CaseStore` (its ``rows``/``done_ids``/``append_case`` API).
ResultsFile = CaseStore


def export_csv(folder: str | Path, csv: str | Path | None = None) -> Path:
    """Write the rows of a case folder as one CSV (default ``OUT/<suite>.csv``)."""
    folder = Path(folder)
    csv = Path(csv) if csv is not None else folder.with_suffix(".csv")
    CaseStore(folder).frame().to_csv(csv, index=False, float_format="%.10g")
    return csv


# -- environment -----------------------------------------------------------------------------
def _command() -> str:
    """The command line of this process, with ``python -m PKG`` restored for module runs."""
    argv = list(sys.argv)
    if not argv:
        return ""
    head = Path(argv[0])
    if head.name == "__main__.py":
        argv[0] = f"-m {head.parent.name}"
    return " ".join(["python", *argv])


def environment() -> dict[str, Any]:
    """Metadata stamped on every row: versions, CPU, cores, BLAS threads, platform, commit."""
    env: dict[str, Any] = {f"v_{k}": v for k, v in package_versions().items()}
    env.update(cpu=cpu_model(), cores=os.cpu_count() or 0,
               blas_threads=os.environ.get("OPENBLAS_NUM_THREADS", "default"),
               platform=platform.platform(), git_commit=git_commit(),
               command=_command())
    return env


def now_iso() -> str:
    """Current UTC time, ISO 8601 with seconds."""
    return datetime.now(timezone.utc).isoformat(timespec="seconds")
