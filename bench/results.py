"""Append-only, resumable results files: one tidy JSON object per line, one line per run.

Layout of a suite's output folder ``OUT`` (default ``bench/results``)::

    OUT/<suite>.jsonl              the tidy rows (appended as runs finish; never rewritten
                                   except to drop the torn tail of an interrupted write)
    OUT/<suite>.csv                the same rows as CSV, exported when the suite completes
    OUT/<suite>-micro.json         pytest-benchmark JSON of the micro-benchmarks
    OUT/<suite>/traj/<case>.parquet  downsampled trajectories for the report's figures
    OUT/<suite>/logs/<case>.csv      perturbed closing logs of the robustness suite

Every row carries ``case_id`` (stable across runs: derived from the case's declared fields),
``case_rows`` (how many rows the case writes) and ``row`` (0-based index within the case).
A case is *done* when all its rows are in the file; its rows are written with a single
``write`` followed by ``flush`` and ``fsync``. A case whose rows are incomplete (the process
was killed in the middle of a write) is dropped when the file is opened again and is rerun.

JSON-lines rather than CSV because the kinds of runs (observers, work-precision, robustness,
scaling) have different metric columns; :func:`load_results` turns any set of files into one
DataFrame (missing columns are NaN there, and the report only reads the columns of a kind).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable

from observer.result import package_versions

RESERVED = ("suite", "case_id", "case_rows", "row")


def _jsonable(x: Any) -> Any:
    """JSON fallback for NumPy scalars/arrays and paths."""
    try:
        import numpy as np
    except ImportError:  # pragma: no cover - numpy is a hard dependency
        np = None
    if np is not None:
        if isinstance(x, np.ndarray):
            return x.tolist()
        if isinstance(x, (np.floating, np.integer, np.bool_)):
            return x.item()
    if isinstance(x, Path):
        return str(x)
    return str(x)


def dumps_row(row: dict) -> str:
    """One row as a single JSON line (``Infinity``/``NaN`` kept, as Python's json does)."""
    return json.dumps(row, default=_jsonable, allow_nan=True, separators=(",", ":"))


class ResultsFile:
    """An append-only JSON-lines results file with case-level resume.

    Parameters
    ----------
    path : str or Path
        The ``.jsonl`` file (created with its folder on the first append).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)

    # -- reading ---------------------------------------------------------------------------
    def _scan(self) -> tuple[list[dict], bool]:
        """All complete cases' rows in file order, and whether anything had to be dropped."""
        if not self.path.exists():
            return [], False
        rows: list[dict] = []
        dropped = False
        with self.path.open("r", encoding="utf-8") as fh:
            for line in fh:
                if not line.endswith("\n"):          # torn last line of a killed write
                    dropped = True
                    break
                line = line.strip()
                if not line:
                    continue
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError:
                    dropped = True
        groups: dict[str, list[dict]] = {}
        for r in rows:
            groups.setdefault(r.get("case_id", ""), []).append(r)
        keep: list[dict] = []
        complete: set[str] = set()
        for cid, grp in groups.items():
            need = int(grp[0].get("case_rows", len(grp)))
            idx = {int(r.get("row", i)) for i, r in enumerate(grp)}
            if len(grp) == need and idx == set(range(need)):
                complete.add(cid)
            else:
                dropped = True
        keep = [r for r in rows if r.get("case_id", "") in complete]
        return keep, dropped

    def rows(self) -> list[dict]:
        """Rows of the complete cases, in the order they were written."""
        return self._scan()[0]

    def done_ids(self) -> set[str]:
        """``case_id`` of every complete case."""
        return {r["case_id"] for r in self.rows()}

    def repair(self) -> int:
        """Drop the rows of incomplete cases and torn lines (atomic rewrite); return how many
        lines were removed (0 when the file was clean and is left untouched)."""
        if not self.path.exists():
            return 0
        keep, dropped = self._scan()
        if not dropped:
            return 0
        with self.path.open("r", encoding="utf-8") as fh:
            before = sum(1 for _ in fh)
        self._rewrite(keep)
        return before - len(keep)

    def prune(self, keep_ids: set[str]) -> int:
        """Move the rows of cases not in ``keep_ids`` (the grid declaration changed) to
        ``<stem>.stale.jsonl`` next to the file; return how many rows were moved."""
        rows = self.rows()
        stale = [r for r in rows if r.get("case_id") not in keep_ids]
        if not stale:
            return 0
        archive = self.path.with_name(self.path.stem + ".stale.jsonl")
        with archive.open("a", encoding="utf-8") as fh:
            for r in stale:
                fh.write(dumps_row(r) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        self._rewrite([r for r in rows if r.get("case_id") in keep_ids])
        return len(stale)

    def _rewrite(self, rows: list[dict]) -> None:
        """Replace the file by ``rows`` atomically (write a temporary file, fsync, rename)."""
        tmp = self.path.with_suffix(self.path.suffix + ".tmp")
        with tmp.open("w", encoding="utf-8") as fh:
            for r in rows:
                fh.write(dumps_row(r) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)

    # -- writing ---------------------------------------------------------------------------
    def append_case(self, suite: str, case_id: str, rows: list[dict]) -> None:
        """Append all rows of one case with one write, then flush and fsync."""
        if not rows:
            raise ValueError(f"case {case_id!r} produced no rows")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        lines = []
        for i, r in enumerate(rows):
            clash = [k for k in RESERVED if k in r]
            if clash:
                raise ValueError(f"row of case {case_id!r} uses reserved column(s) {clash}")
            lines.append(dumps_row({"suite": suite, "case_id": case_id, "case_rows": len(rows),
                                    "row": i, **r}))
        with self.path.open("a", encoding="utf-8") as fh:
            fh.write("\n".join(lines) + "\n")
            fh.flush()
            os.fsync(fh.fileno())


def load_results(paths: Iterable[str | Path]):
    """Read results files (``.jsonl`` written by :class:`ResultsFile`, or an exported ``.csv``)
    into one DataFrame. A column ``results_dir`` records each row's folder (artefact paths in
    the rows are relative to it)."""
    import pandas as pd

    frames = []
    for p in paths:
        p = Path(p)
        if p.suffix == ".jsonl":
            df = pd.DataFrame(ResultsFile(p).rows())
        elif p.suffix == ".csv":
            df = pd.read_csv(p)
        else:
            raise ValueError(f"{p}: not a results file (expected .jsonl or .csv)")
        df["results_dir"] = str(p.parent)
        frames.append(df)
    if not frames:
        return pd.DataFrame()
    return pd.concat(frames, ignore_index=True, sort=False)


def export_csv(jsonl: str | Path, csv: str | Path | None = None) -> Path:
    """Write the complete rows of ``jsonl`` as CSV next to it (same stem) and return the path."""
    import pandas as pd

    jsonl = Path(jsonl)
    csv = Path(csv) if csv is not None else jsonl.with_suffix(".csv")
    pd.DataFrame(ResultsFile(jsonl).rows()).to_csv(csv, index=False, float_format="%.10g")
    return csv


# -- environment -----------------------------------------------------------------------------
def cpu_model() -> str:
    """CPU model name (``/proc/cpuinfo`` on Linux, else :func:`platform.processor`)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def git_commit(root: str | Path | None = None) -> str:
    """``git rev-parse --short=12 HEAD`` of the repository (``+dirty`` if the tracked tree
    has changes), or ``"unknown"`` outside a git checkout."""
    root = Path(root) if root is not None else Path(__file__).resolve().parent.parent
    try:
        sha = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=root, check=True,
                             capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=root, capture_output=True, text=True, timeout=10).stdout.strip()
        return sha + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


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
