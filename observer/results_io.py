"""Reading the benchmark suites' stored results, and the machine a run describes.

What both the writer of the results (``bench.results``) and their reader (``reports``)
need, so that the report reads result rows without importing ``bench``: the layout names
of a suite's case folder (``OUT/<suite>.cases/<key>.parquet``), the check that a case file is
whole (:func:`read_case`: it opens, its SHA-256 checksum matches its rows, it holds
``case_rows`` rows of the one case its name stands for), :func:`load_results` (a concat of
the whole case files) and the machine description stamped on every row
(:func:`cpu_model`, :func:`git_commit`; the package versions are
:func:`observer.result.package_versions`).
"""

from __future__ import annotations

import hashlib
import platform
import subprocess
from pathlib import Path
from typing import Callable, Iterable

from observer.result import package_versions

__all__ = ["CASES_SUFFIX", "CHECKSUM_KEY", "META_SUFFIX", "DamagedCase", "case_key", "case_files", "content_digest",
           "cpu_model", "frame_of", "git_commit", "load_results", "meta_path", "package_versions", "read_case",
           "read_suite_meta"]

#: Key of the rows' checksum in a case file's Parquet schema metadata.
CHECKSUM_KEY = b"bench.rows_sha256"
#: Suffix of a suite's folder of case files (``OUT/<suite>.cases``).
CASES_SUFFIX = ".cases"
#: Suffix of a suite's metadata sidecar (``OUT/<suite>.meta.json``, :func:`read_suite_meta`).
META_SUFFIX = ".meta.json"


class DamagedCase(Exception):
    """A case file that cannot count as done (see :func:`read_case`)."""

    def __init__(self, path: Path, reason: str):
        self.path, self.reason = Path(path), reason
        super().__init__(f"{path}: {reason}")


def case_key(case_id: str) -> str:
    """File name stem of a case: the first 20 hex digits of SHA-256 of its ``case_id``."""
    return hashlib.sha256(case_id.encode("utf-8")).hexdigest()[:20]


def content_digest(table) -> str:
    """SHA-256 of a table's column names, types and values (:class:`observer.io.ContentHash`,
    the checksum of the toolkit's own Parquet results): the same for the table written and the
    table read back from Parquet, different as soon as one value, row or column differs."""
    from observer.io import ContentHash

    content = ContentHash()
    content.add_table(table)
    return content.hexdigest()


def read_case(path: Path):
    """Read one case file; raise :class:`DamagedCase` if it does not open, has no checksum,
    a checksum that does not match its rows, fewer/more rows than ``case_rows`` says, or rows
    of a case other than the one its name stands for (the file name is :func:`case_key` of the
    ``case_id`` its checksummed rows carry: a file copied under another case's name would
    count as that case, leaving one missing and one twice)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise DamagedCase(path, f"does not open ({type(exc).__name__}: {exc})") from None
    stored = (table.schema.metadata or {}).get(CHECKSUM_KEY)
    if stored is None:
        raise DamagedCase(path, "has no checksum (written before checksums, or not by bench)")
    if content_digest(table.replace_schema_metadata(None)) != stored.decode("ascii", "replace"):
        raise DamagedCase(path, "checksum does not match its rows (altered)")
    if "case_rows" not in table.column_names or table.num_rows == 0 \
            or table.column("case_rows")[0].as_py() != table.num_rows:
        raise DamagedCase(path, f"holds {table.num_rows} rows, not the case_rows it was written with")
    ids = set(table.column("case_id").to_pylist()) if "case_id" in table.column_names else set()
    if len(ids) != 1:
        raise DamagedCase(path, f"holds the rows of {len(ids)} cases, not of one")
    (case_id,) = ids
    if case_key(str(case_id)) != path.stem:
        raise DamagedCase(path, f"holds case {case_id!r}, whose file is {case_key(str(case_id))}.parquet: "
                          "a case file copied or renamed under another case's name")
    return table


def case_files(folder: Path) -> list[Path]:
    """The case files of a case folder, sorted by name (stale and damaged ones excluded: they
    are in a subfolder or have another suffix), unverified."""
    folder = Path(folder)
    return sorted(folder.glob("*.parquet")) if folder.is_dir() else []


def _whole(path: Path):
    """The table of the case file ``path``, or None when it is damaged or gone."""
    try:
        return read_case(path)
    except DamagedCase:
        return None


def frame_of(files: Iterable[Path], read: Callable[[Path], object] = _whole):
    """All rows of the whole case files among ``files``, one DataFrame (in the order given);
    ``read(path)`` gives a file's table, or None for a file that does not count."""
    import pandas as pd

    frames = [t.to_pandas() for f in files if (t := read(f)) is not None and t.num_rows]
    if not frames:
        return pd.DataFrame()
    return pd.concat(frames, ignore_index=True, sort=False)


def load_results(paths: Iterable[str | Path]):
    """Read suite results into one DataFrame (a concat).

    Parameters
    ----------
    paths : iterable of path
        Case folders ``OUT/<suite>.cases`` (``bench.run.results_path``), or exported
        ``.csv``/``.parquet`` files.

    Returns
    -------
    DataFrame
        The rows of the whole case files, with a column ``results_dir``: the folder each row's
        artefact paths are relative to (``OUT``). Empty when there is nothing.

    Raises
    ------
    FileNotFoundError
        A path does not exist.
    observer.errors.InputError
        A path is neither a case folder nor a ``.csv``/``.parquet`` file.
    """
    import pandas as pd

    frames = []
    for p in map(Path, paths):
        if p.is_dir():
            df = frame_of(case_files(p))
        elif p.suffix == ".csv":
            df = pd.read_csv(p)
        elif p.suffix == ".parquet":
            df = pd.read_parquet(p)
        elif not p.exists():
            raise FileNotFoundError(f"{p}: no such results folder or file")
        else:
            from observer.errors import InputError      # (a ValueError: one line at a CLI)
            raise InputError(str(p), f"not a results folder or file (expected OUT/<suite>{CASES_SUFFIX}, "
                             ".csv or .parquet)")
        if len(df):
            df["results_dir"] = str(p.parent)
            frames.append(df)
    if not frames:
        return pd.DataFrame()
    return pd.concat(frames, ignore_index=True, sort=False)


def meta_path(suite: str, folder: str | Path) -> Path:
    """``OUT/<suite>.meta.json``: what the suite declares that its rows do not carry, written
    by ``bench`` when it runs the suite."""
    return Path(folder) / f"{suite}{META_SUFFIX}"


def read_suite_meta(suite: str, folder: str | Path) -> dict | None:
    """The metadata sidecar of ``suite`` under ``folder`` (:func:`meta_path`): a dict with at
    least ``"cases"``, the suite's case ids in declared order; None where there is none, or
    it does not read as such (results written before the sidecar, or damaged): the reader
    then says the metadata is missing rather than failing."""
    import json

    try:
        meta = json.loads(meta_path(suite, folder).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(meta, dict) or not isinstance(meta.get("cases"), list):
        return None
    return meta


# -- the machine -------------------------------------------------------------------------------
def cpu_model() -> str:
    """CPU model name (``/proc/cpuinfo`` on Linux, else ``platform.processor()``)."""
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
