"""Results written as the run produces them: a long run interrupted loses no finished step.

:class:`ChunkWriter` is an ``on_chunk`` consumer of :func:`observer.loop.run` (through
``simulate(..., on_chunk=writer)``): each :class:`~observer.loop.Chunk` of finished rows
becomes rows of the result file at once, with the columns of
:meth:`observer.SimulationResult.to_frame`:

* ``.parquet``: one row group per chunk (``pyarrow.parquet.ParquetWriter``); the metadata
  (the run's metadata and its ``status``) goes into the file's key-value metadata under
  :data:`observer.io.PARQUET_KEY` when the writer is closed — :func:`observer.io.read_result`
  reads it as from a file written in one piece;
* ``.csv``: rows appended (17 significant digits, as :func:`observer.io.write_frame`), the
  ``NAME.json`` sidecar written at close.

A run stopped by SIGINT/SIGTERM (the loop stops after its current window, see
:mod:`observer.loop`) or by an exception still closes the file, with a status
``{"state": "stopped", "reason": ...}`` saying where it stopped: every finished step stays
readable. (A SIGKILL leaves a Parquet file without its footer: unreadable; the CSV keeps
every row written.)

Use::

    with ChunkWriter("run.parquet") as writer:
        res = simulate(sc, on_chunk=writer)
        writer.finish(res)
"""

from __future__ import annotations

import json
import signal
from pathlib import Path
from typing import TYPE_CHECKING

from observer.io import PARQUET_KEY, SUFFIXES, sidecar_path, to_json
from observer.errors import InputError

if TYPE_CHECKING:
    import pandas as pd

#: Exit status of ``observer run`` for a run stopped by each signal (128 + signal number).
SIGNAL_EXIT = {"SIGINT": 128 + int(signal.SIGINT), "SIGTERM": 128 + int(signal.SIGTERM)}
#: Exit status of a run stopped for another reason (its residual above tolerance).
STOPPED_EXIT = 1


def chunk_frame(chunk) -> pd.DataFrame:
    """The rows of ``chunk`` with the columns of :meth:`SimulationResult.to_frame` (no attrs).

    V of each observer is the kernel's (``store="summary"``) or
    :func:`observer.observers.lyapunov` of the chunk's rows, as :func:`observer.simulate`
    computes it.
    """
    from observer.observers import lyapunov
    from observer.result import SimulationResult, SlaveTrajectory

    slaves = {}
    for i, name in enumerate(chunk.names, start=1):
        V = (chunk.V[i] if chunk.V is not None
             else lyapunov(chunk.system, chunk.q[i], chunk.u[i], chunk.q[0], chunk.u[0]))
        slaves[name] = SlaveTrajectory(name, chunk.q[i], chunk.u[i], chunk.P[i], V, None, None, None,
                                       chunk.sigma[i])
    res = SimulationResult(chunk.t, chunk.q[0], chunk.u[0], chunk.P[0], chunk.active, chunk.system,
                           {}, chi=chunk.chi if slaves else None, slaves=slaves, sigma=chunk.sigma[0])
    df = res.to_frame()
    df.attrs = {}
    return df


class ChunkWriter:
    """Append the chunks of a run to ``path`` (.parquet or .csv); metadata and status at close.

    Parameters
    ----------
    path : str or Path
        The result file; written in place (a reader sees every finished chunk once the
        writer is closed; the CSV at any time).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.suffix = self.path.suffix.lower()
        if self.suffix not in SUFFIXES:
            raise InputError("--out", f"unsupported extension {self.path.suffix!r}; use .csv or .parquet")
        self.rows = 0
        self.chunks = 0
        self.t_last: float | None = None
        self.closed = False
        self._writer = None
        self._schema = None

    # -- the on_chunk callback ----------------------------------------------------------
    def __call__(self, chunk) -> None:
        self.write(chunk_frame(chunk))

    def write(self, df: pd.DataFrame) -> None:
        """Append the rows of ``df`` (one row group / one CSV append)."""
        if self.closed:
            raise InputError(str(self.path), "the writer is closed")
        if len(df) == 0:
            return
        if self.suffix == ".parquet":
            self._write_parquet(df)
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            df.to_csv(self.path, mode="w" if self.chunks == 0 else "a", header=self.chunks == 0,
                      index=False, float_format="%.17g")
        self.rows += len(df)
        self.chunks += 1
        self.t_last = float(df["t"].iloc[-1])

    def _write_parquet(self, df: pd.DataFrame) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pandas(df, schema=self._schema, preserve_index=False)
        if self._writer is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._schema = table.schema
            # store_schema=False: the file's key-value metadata (the observer key added at
            # close) is then what readers see as the schema metadata
            self._writer = pq.ParquetWriter(self.path, self._schema, store_schema=False)
        self._writer.write_table(table)

    # -- closing --------------------------------------------------------------------------
    def close(self, metadata: dict) -> Path:
        """Write ``metadata`` (with its ``status``) and close the file; idempotent."""
        if self.closed:
            return self.path
        meta = dict(metadata)
        meta["streamed"] = {"rows": self.rows, "chunks": self.chunks, "t_last": self.t_last}
        text = to_json(meta)
        if self.suffix == ".parquet":
            if self._writer is None:                     # no row at all: an empty file with the metadata
                import pyarrow as pa
                import pyarrow.parquet as pq

                self._writer = pq.ParquetWriter(self.path, pa.schema([("t", pa.float64())]),
                                                store_schema=False)
            self._writer.add_key_value_metadata({PARQUET_KEY: text.encode("utf-8")})
            self._writer.close()
        else:
            if self.chunks == 0:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self.path.write_text("t\n", encoding="utf-8")
            sidecar_path(self.path).write_text(text + "\n", encoding="utf-8")
        self.closed = True
        return self.path

    def finish(self, result) -> Path:
        """Close with the metadata and status of ``result`` (a :class:`SimulationResult`).

        A result whose rows never came as chunks (an integrator without ``on_chunk``) is
        written whole here; its :attr:`~SimulationResult.events`, if any, go to
        ``NAME.events.EXT`` beside the file, as :meth:`SimulationResult.write` does."""
        from observer.io import write_frame

        meta = json.loads(to_json(result.metadata))
        meta["status"] = result.status.to_dict()
        if self.rows == 0 and result.t.size:
            df = result.to_frame()
            df.attrs = {}
            self.write(df)
        if getattr(result, "events", None) is not None:
            events_path = self.path.with_name(f"{self.path.stem}.events{self.path.suffix}")
            write_frame(result.events, events_path)
            meta["events_file"] = events_path.name
        return self.close(meta)

    def __enter__(self) -> "ChunkWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is not None and self.chunks == 0:
            self.closed = True                           # failed before any row: no file at all
        elif exc_type is not None and not self.closed:
            where = f"after t = {self.t_last:.9g}" if self.t_last is not None else "before the first step"
            self.close({"status": {"state": "stopped",
                                   "reason": f"{exc_type.__name__} {where} ({self.rows} rows written)"}})
        elif not self.closed:
            self.close({"status": {"state": "stopped", "reason": "the writer was not finished"}})
        return False


def exit_status(result) -> int:
    """Exit status of ``observer run`` for ``result``: 0, or :data:`SIGNAL_EXIT` of the signal
    that stopped it, or :data:`STOPPED_EXIT` for a run stopped for another reason."""
    stopped = result.metadata.get("stopped")
    if not stopped:
        return 0
    return SIGNAL_EXIT.get(stopped.get("signal") or "", STOPPED_EXIT)
