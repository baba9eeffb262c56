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

:func:`read_result` reads either back as ``(DataFrame, metadata)``; CSV files written before
the sidecar existed (metadata in a leading ``# metadata: {...}`` comment line) are still read.
"""

from __future__ import annotations

import json
import os
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


def read_events(path: str | Path) -> pd.DataFrame | None:
    """The events table written beside the result file ``path`` (None if there is none)."""
    import pandas as pd

    ev = events_path(path)
    if not ev.exists():
        return None
    return pd.read_parquet(ev) if ev.suffix.lower() == ".parquet" else pd.read_csv(ev)


def _check_suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError("--out", f"unsupported extension {path.suffix!r}; use .csv or .parquet")
    return suffix


def _write_sidecar(side: Path, meta_json: str | None) -> None:
    """Write the metadata sidecar atomically; no metadata: no sidecar (an old one is removed)."""
    if meta_json is None:
        side.unlink(missing_ok=True)
        return
    tmp = side.with_name(f".{side.name}.tmp")
    tmp.write_text(meta_json + "\n", encoding="utf-8")
    os.replace(tmp, side)


def write_frame(df: pd.DataFrame, path: str | Path) -> Path:
    """Write ``df`` by extension, with ``df.attrs`` as the metadata.

    ``.csv``: plain header row, metadata in the sidecar :func:`sidecar_path` (none when
    ``df.attrs`` is empty); ``.parquet``:
    metadata in the schema metadata under :data:`PARQUET_KEY`. Each file is written under a
    temporary name and renamed, so a reader never sees a half-written file.

    Returns
    -------
    Path
        ``path``.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    suffix = _check_suffix(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta_json = to_json(df.attrs)
    tmp = path.with_name(f".{path.name}.tmp")
    if suffix == ".csv":
        plain = df.copy()
        plain.attrs = {}
        plain.to_csv(tmp, index=False, float_format="%.17g")
        _write_sidecar(sidecar_path(path), meta_json if df.attrs else None)
    else:
        table = pa.Table.from_pandas(df, preserve_index=False)
        schema_meta = dict(table.schema.metadata or {})
        schema_meta[PARQUET_KEY] = meta_json.encode("utf-8")
        pq.write_table(table.replace_schema_metadata(schema_meta), tmp)
    os.replace(tmp, path)
    return path


def _read_csv(path: Path) -> tuple[pd.DataFrame, dict]:
    import pandas as pd

    with path.open(encoding="utf-8") as fh:
        first = fh.readline()
    if first.startswith(_LEGACY_PREFIX):                      # files of earlier versions
        return pd.read_csv(path, skiprows=1), json.loads(first[len(_LEGACY_PREFIX):])
    side = sidecar_path(path)
    meta = json.loads(side.read_text(encoding="utf-8")) if side.exists() else {}
    if not isinstance(meta, dict):
        raise InputError(str(side), "metadata sidecar is not a JSON object")
    return pd.read_csv(path), meta


def _read_parquet(path: Path) -> tuple[pd.DataFrame, dict]:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    raw = (table.schema.metadata or {}).get(PARQUET_KEY)
    df = table.to_pandas()
    df.attrs = {}
    return df, (json.loads(raw) if raw else {})


def read_result(path: str | Path) -> tuple[pd.DataFrame, dict]:
    """Read a result file written by :func:`write_frame` (or ``SimulationResult.write``).

    Parameters
    ----------
    path : str or Path
        ``.csv`` (metadata from the ``NAME.json`` sidecar, ``{}`` if there is none) or
        ``.parquet`` (metadata from the schema metadata).

    Returns
    -------
    frame : DataFrame
        The columns as written; flag columns (``active*``, ``chi*``) as integers, every other
        numeric column as float64.
    metadata : dict

    Raises
    ------
    InputError
        Missing file, unsupported extension, or not a result file (no column ``t``).
    """
    import pandas as pd

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(str(path), f"unsupported extension {path.suffix!r}; use .csv or .parquet")
    if not path.exists():
        raise InputError(str(path), "file not found")
    try:
        df, meta = _read_parquet(path) if suffix == ".parquet" else _read_csv(path)
    except (UnicodeDecodeError, ValueError, OSError) as exc:
        raise InputError(str(path), f"not a result file written by this toolkit ({exc})") from None
    if "t" not in df.columns:
        raise InputError(str(path), "not a result file (no column 't')")
    flags = [c for c in df.columns if c.startswith(("active", "chi"))]
    numeric = [c for c in df.columns if c not in flags and pd.api.types.is_numeric_dtype(df[c])]
    return df.astype({c: float for c in numeric}), meta


def read_frame(path: str | Path) -> pd.DataFrame:
    """:func:`read_result` as one DataFrame with the metadata in ``DataFrame.attrs``."""
    df, meta = read_result(path)
    df.attrs.update(meta)
    return df
