"""Result files that any tool reads: CSV with a plain header row plus a JSON sidecar, or Parquet
with the metadata in the file's schema metadata.

Layout
------
``run.csv``
    One header row (the column names of :meth:`observer.SimulationResult.to_frame`), then one
    row per recorded step, floats written with 17 significant digits (exact round trip).
    ``pandas.read_csv("run.csv")``, R's ``read.csv`` or a spreadsheet read it as is.
``run.json`` (beside ``run.csv``)
    The metadata (scenario parameters, h, θ, solver work, status, versions) as one JSON object.
``run.parquet``
    The same columns; the metadata is the JSON value of the schema metadata key
    :data:`PARQUET_KEY` (``pyarrow.parquet.read_schema(path).metadata[b"observer"]``).
``run.events.csv`` / ``run.events.parquet``
    Runs with an events table (:attr:`observer.SimulationResult.events`): one row per event,
    columns ``time, contact, kind, gamma_minus, gamma_plus, impulse`` (:func:`read_events`).

Integrity
---------
Every file carries its row count and checksums, written last (:data:`INTEGRITY_KEY` of the
metadata: ``{"state": "complete", "rows", "sha256", "metadata_sha256", "digest", "run"}``): for a CSV
the SHA-256 of its bytes, in the sidecar; for Parquet the SHA-256 of its columns' values
(:class:`ContentHash`), in the schema metadata. ``metadata_sha256`` covers the rest of the
metadata, and ``digest`` (:func:`bound_digest`) binds the two and the row count: a file whose
content and metadata each carry a valid checksum of their own but come from two different
writings (another run's metadata on rows of the same shape) is refused. Files of the previous
format (no ``digest``) are not trusted: refused, or read with ``partial=True`` as unverified.
A run that streams its file (:mod:`observer.stream`) first writes a sidecar whose
integrity says ``"running"`` (``NAME.json`` for a CSV, :func:`running_path` for Parquet, whose
rows go to :func:`part_path` and are renamed when the file is closed), replaced when it
finishes: a killed run leaves it saying ``"running"``.

:func:`read_result` reads either back as ``(DataFrame, metadata)`` after checking them: a
file cut short, altered, unfinished or without a row count and checksum is refused with one
line naming it, or, with ``partial=True``, read as its whole rows with the status
``{"state": "partial", "reason": ...}``. CSV files written before the sidecar existed
(metadata in a leading ``# metadata: {...}`` comment line) are read with ``partial=True``.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from observer.errors import InputError

if TYPE_CHECKING:
    import pandas as pd

#: Schema-metadata key of a Parquet result file holding the metadata (JSON).
PARQUET_KEY = b"observer"
#: Extensions :func:`write_frame` accepts.
SUFFIXES = (".csv", ".parquet")
_LEGACY_PREFIX = "# metadata:"
#: Metadata key of a result file's integrity record (row count, checksums, state).
INTEGRITY_KEY = "integrity"
COMPLETE, RUNNING, PARTIAL = "complete", "running", "partial"


def jsonable(x):
    """JSON fallback for NumPy arrays and scalars (anything else: its ``str``)."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    return str(x)


def to_json(metadata: dict) -> str:
    """``metadata`` as JSON text (NumPy values converted, ``inf``/``nan`` kept as Python's json does)."""
    return json.dumps(metadata, default=jsonable)


def sidecar_path(path: str | Path) -> Path:
    """The metadata sidecar of a CSV result: ``NAME.json`` beside ``NAME.csv``."""
    return Path(path).with_suffix(".json")


def events_path(path: str | Path) -> Path:
    """The events table of a result file: ``NAME.events.csv`` beside ``NAME.csv`` (or
    ``.parquet``), written when the result has events."""
    path = Path(path)
    return path.with_name(f"{path.stem}.events{path.suffix}")


def part_path(path: str | Path) -> Path:
    """Where a streamed Parquet file is written until it is closed: ``.NAME.parquet.part``."""
    path = Path(path)
    return path.with_name(f".{path.name}.part")


def running_path(path: str | Path) -> Path:
    """The sidecar that says a run is writing ``path``: ``NAME.json`` for a CSV (replaced by
    the metadata when the run finishes), ``NAME.parquet.running`` for Parquet (removed then)."""
    path = Path(path)
    if path.suffix.lower() == ".csv":
        return sidecar_path(path)
    return path.with_name(f"{path.name}.running")


def new_run_id() -> str:
    """A fresh identifier of one writing of a file (its ``running`` sidecar and its integrity
    record name the same run)."""
    return uuid.uuid4().hex


def running_record(run: str) -> str:
    """The text of a ``running`` sidecar (JSON)."""
    return to_json({"status": {"state": RUNNING, "reason": "the run writing this file has not "
                                                           "finished (or was killed)"},
                    INTEGRITY_KEY: {"state": RUNNING, "run": run}}) + "\n"


def metadata_digest(meta: dict) -> str:
    """SHA-256 of the metadata without its integrity record, as JSON with sorted keys (the
    same text before writing and after reading: values go through JSON first)."""
    body = {k: v for k, v in json.loads(to_json(meta)).items() if k != INTEGRITY_KEY}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode("utf-8")).hexdigest()


class ContentHash:
    """The checksum of a result's content, fed as it is written.

    CSV: SHA-256 of the file's bytes (:meth:`add_bytes`). Parquet: per column, SHA-256 of its
    values in row order (numbers and flags as their little-endian bytes, text as UTF-8 with a
    NUL after each value), chunk after chunk (:meth:`add_table`); the checksum is the SHA-256
    of the columns' names, types and digests — the same however the rows are grouped.
    """

    def __init__(self):
        self.bytes = hashlib.sha256()
        self.columns: dict[str, tuple[str, object]] = {}
        self.rows = 0

    def add_bytes(self, data: bytes, rows: int) -> None:
        self.bytes.update(data)
        self.rows += rows

    def add_table(self, table) -> None:
        for name, col in zip(table.column_names, table.columns):
            a = col.to_numpy(zero_copy_only=False)
            kind = str(col.type)
            h = self.columns.setdefault(name, (kind, hashlib.sha256()))[1]
            if a.dtype.kind in "biuf":
                h.update(np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).tobytes())
            else:
                for v in a:
                    h.update(str(v).encode("utf-8") + b"\0")
        self.rows += table.num_rows

    def hexdigest(self) -> str:
        if not self.columns:
            return self.bytes.hexdigest()
        top = hashlib.sha256()
        for name, (kind, h) in self.columns.items():
            top.update(f"{name}\0{kind}\0{h.hexdigest()}\0".encode("utf-8"))
        return top.hexdigest()


def bound_digest(rows, content_sha: str, metadata_sha: str, run) -> str:
    """SHA-256 of one writing of a file: its row count, content checksum, metadata checksum
    and run id together (none of them can be taken from another writing)."""
    text = f"observer-integrity-2\0{rows}\0{content_sha}\0{metadata_sha}\0{run}"
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def integrity_record(content: ContentHash, meta: dict, run: str) -> dict:
    """The integrity record of a complete file: rows, content and metadata checksums and the
    digest binding them (:func:`bound_digest`)."""
    rec = {"state": COMPLETE, "rows": content.rows, "sha256": content.hexdigest(),
           "metadata_sha256": metadata_digest(meta), "run": run}
    rec["digest"] = bound_digest(rec["rows"], rec["sha256"], rec["metadata_sha256"], run)
    return rec


def _binding_problem(integ: dict, content_sha: str, meta: dict) -> str | None:
    """What keeps a file's parts from being one writing (None: bound)."""
    if "digest" not in integ:
        return ("was written by an earlier version of the toolkit (its content and metadata are "
                "not bound by one digest): it cannot be verified")
    if bound_digest(integ.get("rows"), content_sha, metadata_digest(meta), integ.get("run")) != integ["digest"]:
        return ("its content and its metadata come from different writings (the integrity "
                "digest does not bind them): the metadata belongs to another run")
    return None


#: Fraction of the memory available that a result file read whole may take.
MEMORY_FRACTION = 0.5


def check_input_file(path: Path, field: str | None = None) -> None:
    """Refuse a result file that is not a regular file (a FIFO, ``/dev/zero``, a link to one)
    or larger than :data:`MEMORY_FRACTION` of the memory available, naming it."""
    import stat

    name = field or str(path)
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise InputError(name, f"{str(path)!r} is not a regular file (a device, FIFO or link to one)")
    try:
        avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):     # no such counter on this system
        return
    if st.st_size > MEMORY_FRACTION * avail:
        raise InputError(name, f"{str(path)!r} is {st.st_size / 2**30:.1f} GiB, more than half the "
                               f"memory available ({avail / 2**30:.1f} GiB): too large to read whole")


def csv_rows(data: bytes) -> int:
    """Data rows of CSV text with a header row (its newlines, less the header's)."""
    return max(data.count(b"\n") - 1, 0)


def read_events(path: str | Path) -> pd.DataFrame | None:
    """The events table written beside the result file ``path`` (None if there is none),
    checked like :func:`read_result`."""
    ev = events_path(path)
    if not ev.exists():
        return None
    df, meta = _read_checked(ev, False)
    res = Path(path)
    if res.exists():
        try:
            owner = _read_checked(res, False)[1]
        except InputError:
            owner = None
        if owner is not None and owner.get("events_file") != ev.name:
            raise InputError(str(ev), f"is not the events table of {res.name} (that run kept no "
                                      "event table): a leftover of an earlier run")
    return df


def _check_suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError("--out", f"unsupported extension {path.suffix!r}; use .csv or .parquet")
    return suffix


def _write_sidecar(side: Path, text: str) -> None:
    """Write a sidecar atomically (a temporary name, then renamed; removed if that fails)."""
    tmp = side.with_name(f".{side.name}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, side)
    except OSError:
        tmp.unlink(missing_ok=True)
        raise


def remove_events(path: str | Path) -> None:
    """Remove the events table (and its sidecar) beside the result ``path``: a rewritten
    result without events must not keep an earlier run's."""
    ev = events_path(path)
    for f in (ev, sidecar_path(ev)):
        if f.is_file() or f.is_symlink():
            f.unlink()


def write_frame(df: pd.DataFrame, path: str | Path) -> Path:
    """Write ``df`` by extension, with ``df.attrs`` as the metadata and its integrity record.

    ``.csv``: plain header row, metadata and integrity in the sidecar :func:`sidecar_path`,
    written after the file; ``.parquet``: both in the schema metadata under
    :data:`PARQUET_KEY`. Each file is written under a temporary name and renamed, so a reader
    never sees a half-written file.

    Returns
    -------
    Path
        ``path``.
    """
    from observer.outputs import check_regular, family, output_lock

    path = Path(path)
    suffix = _check_suffix(path)
    for f in family(path)[:2]:
        check_regular(str(path), f)
    path.parent.mkdir(parents=True, exist_ok=True)
    with output_lock(path):
        _write_frame_locked(df, path, suffix)
    return path


def _write_frame_locked(df: pd.DataFrame, path: Path, suffix: str) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    meta = json.loads(to_json(df.attrs))
    meta.pop(INTEGRITY_KEY, None)
    content = ContentHash()
    tmp = path.with_name(f".{path.name}.tmp")
    if suffix == ".csv":
        plain = df.copy()
        plain.attrs = {}
        data = plain.to_csv(None, index=False, float_format="%.17g", lineterminator="\n").encode("utf-8")
        content.add_bytes(data, csv_rows(data))
        meta[INTEGRITY_KEY] = integrity_record(content, meta, new_run_id())
        side_tmp = sidecar_path(path).with_name(f".{sidecar_path(path).name}.tmp")
        try:
            tmp.write_bytes(data)
            side_tmp.write_text(to_json(meta) + "\n", encoding="utf-8")
            os.replace(tmp, path)
            os.replace(side_tmp, sidecar_path(path))    # last: the file and its sidecar agree
        except OSError:
            tmp.unlink(missing_ok=True)
            side_tmp.unlink(missing_ok=True)
            raise
    else:
        table = pa.Table.from_pandas(df, preserve_index=False)
        content.add_table(table)
        meta[INTEGRITY_KEY] = integrity_record(content, meta, new_run_id())
        schema_meta = dict(table.schema.metadata or {})
        schema_meta[PARQUET_KEY] = to_json(meta).encode("utf-8")
        try:
            pq.write_table(table.replace_schema_metadata(schema_meta), tmp)
            os.replace(tmp, path)
        except OSError:
            tmp.unlink(missing_ok=True)
            raise


SIDECAR_MAX_BYTES = 16 * 1024 * 1024
"""Largest sidecar read (16 MiB, as a scenario file: a run's metadata is a few kB); a larger
or endless one (a link to ``/dev/zero``) is refused after reading at most this much."""


def _load_json(path: Path, what: str) -> dict:
    if not path.is_file():                       # a device (a link to /dev/zero), a FIFO
        raise InputError(str(path), f"{what} is not a regular file")
    with path.open("rb") as fh:
        data = fh.read(SIDECAR_MAX_BYTES + 1)
    if len(data) > SIDECAR_MAX_BYTES:
        raise InputError(str(path), f"{what} is larger than {SIDECAR_MAX_BYTES // 2 ** 20} MiB: "
                         "not a sidecar written by the toolkit")
    try:
        meta = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise InputError(str(path), f"{what} is damaged: not JSON ({exc})") from None
    except RecursionError:
        raise InputError(str(path), f"{what} is damaged: nested too deep to be a sidecar") from None
    if not isinstance(meta, dict):
        raise InputError(str(path), f"{what} is not a JSON object")
    return meta


def _csv_problem(data: bytes, meta: dict, integ) -> str | None:
    """What keeps a CSV's bytes from being the whole file its sidecar describes (None: whole)."""
    if not isinstance(integ, dict):
        return ("has no row count or checksum (no sidecar NAME.json, or written by another tool "
                "or an earlier version): it cannot be verified")
    if integ.get("state") != COMPLETE:
        return "the run writing it did not finish (its sidecar says 'running': killed, or still running)"
    rows = csv_rows(data)
    if rows != integ.get("rows") or not data.endswith(b"\n"):
        return f"holds {rows} rows where its sidecar says {integ.get('rows')}: cut short or extended"
    if hashlib.sha256(data).hexdigest() != integ.get("sha256"):
        return "its checksum does not match its sidecar's: the file was altered"
    if metadata_digest(meta) != integ.get("metadata_sha256"):
        return "the metadata checksum does not match: its sidecar was altered"
    return _binding_problem(integ, integ["sha256"], meta)


def _whole_csv_rows(data: bytes) -> pd.DataFrame:
    """The rows of CSV bytes that are whole: the header, then every complete line with the
    header's number of fields whose numbers parse, up to the first that is not."""
    import pandas as pd

    end = data.rfind(b"\n")
    if end < 0:
        raise InputError("partial", "not even a whole header row")
    lines = data[:end].split(b"\n")
    commas = lines[0].count(b",")
    good = 1
    while good < len(lines) and lines[good].count(b",") == commas:
        good += 1
    df = pd.read_csv(io.BytesIO(b"\n".join(lines[:good]) + b"\n"))
    bad = np.zeros(len(df), dtype=bool)
    for c in df.columns:
        if df[c].dtype.kind not in "biuf":
            num = pd.to_numeric(df[c], errors="coerce")
            if c == "kind" and num.isna().all():          # the events table's one text column
                continue
            bad |= num.isna().to_numpy()
        else:
            bad |= ~np.isfinite(df[c].to_numpy(dtype=float))
    first = int(np.argmax(bad)) if bad.any() else len(df)
    return df.iloc[:first].reset_index(drop=True)


def _read_csv(path: Path, partial: bool) -> tuple[pd.DataFrame, dict, str | None]:
    import pandas as pd

    data = path.read_bytes()
    if data.startswith(_LEGACY_PREFIX.encode()):                # files of earlier versions
        first, _, rest = data.partition(b"\n")
        meta = json.loads(first[len(_LEGACY_PREFIX):].decode("utf-8"))
        integ, data = None, rest
    else:
        side = sidecar_path(path)
        meta = _load_json(side, f"the sidecar of {path.name}") if side.exists() else {}
        integ = meta.pop(INTEGRITY_KEY, None)
    problem = _csv_problem(data, meta, integ)
    if problem is not None and partial:
        return _whole_csv_rows(data), meta, problem
    if problem is not None:
        return None, meta, problem
    return pd.read_csv(io.BytesIO(data)), meta, None


def _read_parquet(path: Path, partial: bool) -> tuple[pd.DataFrame, dict, str | None]:
    import pyarrow.parquet as pq

    running = running_path(path)
    run = None
    if running.exists():
        run = (_load_json(running, f"the sidecar {running.name}").get(INTEGRITY_KEY) or {}).get("run")
        if not path.exists():
            raise InputError(str(path), f"the run writing it did not finish ({running.name} says "
                                        "'running': killed, or still running); a Parquet file is "
                                        "readable only once closed")
    table = pq.read_table(path)
    raw = (table.schema.metadata or {}).get(PARQUET_KEY)
    meta = json.loads(raw) if raw else {}
    if not isinstance(meta, dict):
        raise InputError(str(path), "its metadata is not a JSON object")
    integ = meta.pop(INTEGRITY_KEY, None)
    if run is not None and (not isinstance(integ, dict) or integ.get("run") != run):
        raise InputError(str(path), f"a run writing it did not finish ({running.name} says "
                                    "'running'): this file is an earlier one")
    content = ContentHash()
    content.add_table(table)
    problem = None
    if not isinstance(integ, dict) or integ.get("state") != COMPLETE:
        problem = "has no row count or checksum (written by another tool or an earlier version): it cannot be verified"
    elif integ.get("rows") != table.num_rows:
        problem = f"holds {table.num_rows} rows where its metadata says {integ.get('rows')}"
    elif content.hexdigest() != integ.get("sha256"):
        problem = "its checksum does not match its metadata's: the file was altered"
    elif metadata_digest(meta) != integ.get("metadata_sha256"):
        problem = "the metadata checksum does not match: the metadata was altered"
    else:
        problem = _binding_problem(integ, integ["sha256"], meta)
    unbound = isinstance(integ, dict) and "digest" not in integ
    if problem is not None and not (partial and (integ is None or unbound)):
        return None, meta, problem                  # a damaged Parquet file: no row is known whole
    df = table.to_pandas(ignore_metadata=True)     # the columns as checked (no index was written)
    df.attrs = {}
    return df, meta, problem


def _read_checked(path: Path, partial: bool) -> tuple[pd.DataFrame, dict]:
    """Read and verify ``path`` (see :func:`read_result`), any table."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(str(path), f"unsupported extension {path.suffix!r}; use .csv or .parquet")
    if not path.exists() and not (suffix == ".parquet" and running_path(path).exists()):
        raise InputError(str(path), "file not found")
    from pyarrow import ArrowException

    try:
        if path.exists():
            check_input_file(path)
        df, meta, problem = (_read_parquet if suffix == ".parquet" else _read_csv)(path, partial)
    except (UnicodeDecodeError, ValueError, OSError, ArrowException) as exc:
        if isinstance(exc, InputError):
            raise
        text = " ".join(str(exc).split())
        raise InputError(str(path), f"not a whole result file written by this toolkit ({text})") from None
    if problem is not None and df is None:
        hint = "; read_result(path, partial=True) returns its whole rows" if suffix == ".csv" else ""
        raise InputError(str(path), problem + hint)
    if problem is not None:
        meta["status"] = {"state": PARTIAL, "reason": f"{problem}; {len(df)} whole rows read",
                          "written": meta.get("status")}
    return df, meta


def read_result(path: str | Path, partial: bool = False) -> tuple[pd.DataFrame, dict]:
    """Read a result file written by :func:`write_frame`, ``SimulationResult.write`` or a
    streamed run (:mod:`observer.stream`), after checking that it is whole.

    Parameters
    ----------
    path : str or Path
        ``.csv`` (metadata from the ``NAME.json`` sidecar) or ``.parquet`` (metadata from the
        schema metadata).
    partial : bool
        False (default): a file that is not provably whole is refused. True: a CSV cut short,
        altered or unfinished, and a file without an integrity record, are read as their
        whole rows (complete lines whose fields parse, up to the first that is not), with
        ``metadata["status"] = {"state": "partial", "reason": ..., "written": ...}`` (the
        status the file was written with, if any). A Parquet file whose checksum fails has
        no row known to be whole and is refused either way.

    Returns
    -------
    frame : DataFrame
        The columns as written; flag columns (``active*``, ``chi*``) as integers, every other
        numeric column as float64.
    metadata : dict
        Without the integrity record (:data:`INTEGRITY_KEY`), which was checked.

    Raises
    ------
    InputError
        One line naming the file: missing, unsupported extension, not a result file (no
        column ``t``), cut short (row count), altered (checksum), unfinished (a ``running``
        sidecar) or unverifiable (no integrity record), unless ``partial``.
    """
    import pandas as pd

    path = Path(path)
    if path.exists() and not path.is_file():     # a device (a link to /dev/zero), a FIFO: endless
        raise InputError(str(path), "not a regular file: a result is a file written by run")
    df, meta = _read_checked(path, partial)
    if "t" not in df.columns:
        raise InputError(str(path), "not a result file (no column 't')")
    flags = [c for c in df.columns if c.startswith(("active", "chi"))]
    numeric = [c for c in df.columns if c not in flags and pd.api.types.is_numeric_dtype(df[c])]
    return df.astype({c: float for c in numeric}), meta


def read_frame(path: str | Path, partial: bool = False) -> pd.DataFrame:
    """:func:`read_result` as one DataFrame with the metadata in ``DataFrame.attrs``."""
    df, meta = read_result(path, partial)
    df.attrs.update(meta)
    return df
