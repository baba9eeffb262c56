"""Results written as the run produces them: a long run interrupted loses no finished step.

:class:`ChunkWriter` is an ``on_chunk`` consumer of :meth:`observer.engines.timestepping.TimeStepping.advance` (through
``simulate(..., on_chunk=writer)``): each :class:`~observer.engines.loop.Chunk` of finished rows
becomes rows of the result file at once, with the columns of
:meth:`observer.SimulationResult.to_frame`:

* ``.parquet``: one row group per chunk (``pyarrow.parquet.ParquetWriter``), written to
  :func:`observer.io.part_path` and renamed to ``path`` when the writer is closed; the
  metadata (the run's metadata, its ``status`` and the integrity record) goes into the
  file's key-value metadata under :data:`observer.io.PARQUET_KEY` at close —
  :func:`observer.io.read_result` reads and verifies it as a file written in one piece;
* ``.csv``: rows appended (17 significant digits, as :func:`observer.io.write_frame`), the
  ``NAME.json`` sidecar written at close.

Before the first row a sidecar saying ``"running"`` is written (:func:`observer.io.running_path`),
replaced (CSV) or removed (Parquet) once the file is whole: a killed run leaves it, and
:func:`observer.io.read_result` refuses the file (or, ``partial=True``, reads a CSV's whole rows).
Every file carries its row count and checksums (:func:`observer.io.integrity_record`), written last.

A run stopped by SIGINT/SIGTERM/SIGHUP (the loop stops after its current window, see
:mod:`observer.loop`) or by an exception still closes the file, with a status
``{"state": "stopped", "reason": ...}`` saying where it stopped: every finished step stays
readable. Once rows are on disk, the writer (used as a context manager in the main thread)
masks SIGINT, SIGTERM and SIGHUP outside the loop until the file is closed — a second signal during
the stop cannot cut the close short — and delivers the first one it masked after that. A
failed write (a full disk) raises an ``OSError`` naming the file.

Use::

    with ChunkWriter("run.parquet") as writer:
        res = simulate(sc, on_chunk=writer)
        writer.finish(res)
"""

from __future__ import annotations

import json
import os
import signal
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from observer.io import (INTEGRITY_KEY, PARQUET_KEY, SUFFIXES, ContentHash, integrity_record, new_run_id,
                         part_path, remove_events, running_path, running_record, sidecar_path, to_json)
from observer.errors import InputError

if TYPE_CHECKING:
    import pandas as pd

#: Exit status of ``observer run`` for a run stopped by each signal (128 + signal number).
SIGNAL_EXIT = {"SIGINT": 128 + int(signal.SIGINT), "SIGTERM": 128 + int(signal.SIGTERM),
               "SIGHUP": 128 + int(signal.SIGHUP)}
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
    """Append the chunks of a run to ``path`` (.parquet or .csv); metadata, status and
    integrity record at close.

    Parameters
    ----------
    path : str or Path
        The result file (a Parquet file appears under this name once closed; a CSV is
        written in place, its sidecar saying ``"running"`` until it is closed).
    """

    SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")

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
        self._run = new_run_id()
        self._content = ContentHash()
        self._target = part_path(self.path) if self.suffix == ".parquet" else self.path
        self._old_handlers: dict = {}
        self._masked: list[int] = []
        self._closing = False
        self._opened = False
        self._lock = None
        from observer.outputs import check_regular, family

        for f in family(self.path)[:2]:
            check_regular(str(self.path), f)

    # -- the on_chunk callback ----------------------------------------------------------
    def __call__(self, chunk) -> None:
        self.write(chunk_frame(chunk))

    def _oserror(self, exc: OSError, path: Path | None = None) -> OSError:
        """``exc`` as an OSError naming the file (one line: ``PATH: PROBLEM``)."""
        return OSError(exc.errno, exc.strerror or str(exc), str(path or self.path))

    def _start(self) -> None:
        """Before the first row: the directory and the ``running`` sidecar."""
        from observer.outputs import output_lock

        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self._lock is None:
            self._lock = output_lock(self.path)
            self._lock.__enter__()                   # refused if another run writes this file
        if self.suffix == ".csv":
            remove_events(self.path)                 # the earlier result is being overwritten
        side = running_path(self.path)
        tmp = side.with_name(f".{side.name}.tmp")
        tmp.write_text(running_record(self._run), encoding="utf-8")
        os.replace(tmp, side)

    def write(self, df: pd.DataFrame) -> None:
        """Append the rows of ``df`` (one row group / one CSV append)."""
        if self.closed:
            raise InputError(str(self.path), "the writer is closed")
        if len(df) == 0:
            return
        try:
            if self.chunks == 0:
                self._start()
            if self.suffix == ".parquet":
                self._write_parquet(df)
            else:
                data = df.to_csv(None, header=self.chunks == 0, index=False, float_format="%.17g",
                                 lineterminator="\n").encode("utf-8")
                self._opened = True
                with open(self.path, "wb" if self.chunks == 0 else "ab") as fh:
                    fh.write(data)
                self._content.add_bytes(data, len(df))
        except OSError as exc:
            raise self._oserror(exc) from None
        self.rows += len(df)
        self.chunks += 1
        self.t_last = float(df["t"].iloc[-1])

    def _write_parquet(self, df: pd.DataFrame) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pandas(df, schema=self._schema, preserve_index=False)
        if self._writer is None:
            self._schema = table.schema
            # store_schema=False: the file's key-value metadata (the observer key added at
            # close) is then what readers see as the schema metadata
            self._writer = pq.ParquetWriter(self._target, self._schema, store_schema=False)
        self._writer.write_table(table)
        self._content.add_table(table)

    # -- closing --------------------------------------------------------------------------
    def close(self, metadata: dict) -> Path:
        """Write ``metadata`` (with its ``status``) and the integrity record, and close the
        file (Parquet: renamed to ``path``); idempotent."""
        if self.closed:
            return self.path
        self._closing = True
        meta = json.loads(to_json(dict(metadata)))
        meta.pop(INTEGRITY_KEY, None)
        meta["streamed"] = {"rows": self.rows, "chunks": self.chunks, "t_last": self.t_last}
        try:
            if self.chunks == 0:
                self._start()
            if self.suffix == ".parquet":
                import pyarrow as pa
                import pyarrow.parquet as pq

                if self._writer is None:                 # no row at all: an empty file with the metadata
                    self._writer = pq.ParquetWriter(self._target, pa.schema([("t", pa.float64())]),
                                                    store_schema=False)
                meta[INTEGRITY_KEY] = integrity_record(self._content, meta, self._run)
                self._writer.add_key_value_metadata({PARQUET_KEY: to_json(meta).encode("utf-8")})
                self._writer.close()
                os.replace(self._target, self.path)
                running_path(self.path).unlink(missing_ok=True)
                if "events_file" not in meta:
                    remove_events(self.path)
            else:
                if self.chunks == 0:
                    data = b"t\n"
                    self.path.write_bytes(data)
                    self._content.add_bytes(data, 0)
                meta[INTEGRITY_KEY] = integrity_record(self._content, meta, self._run)
                side = sidecar_path(self.path)
                tmp = side.with_name(f".{side.name}.tmp")
                tmp.write_text(to_json(meta) + "\n", encoding="utf-8")
                os.replace(tmp, side)                   # written last: the file is whole
        except OSError as exc:
            self.closed = True
            self._discard()
            self._release()
            raise self._oserror(exc) from None
        self.closed = True
        self._release()
        return self.path

    def _release(self) -> None:
        """Release the lock on the output (:func:`observer.outputs.output_lock`)."""
        if self._lock is not None:
            lock, self._lock = self._lock, None
            lock.__exit__(None, None, None)

    def _discard(self) -> None:
        """A Parquet file that cannot be closed is unreadable: its partial file is removed, and
        so is the ``running`` sidecar unless an earlier file of that name is there (then it
        stays, saying that file is not this run's); nothing else is left."""
        if self.suffix == ".parquet":
            from pyarrow import ArrowException

            try:
                if self._writer is not None:
                    self._writer.close()
            except (OSError, ValueError, ArrowException):
                pass
            self._writer = None
            part_path(self.path).unlink(missing_ok=True)
            if not self.path.exists():
                running_path(self.path).unlink(missing_ok=True)
        else:
            tmp = sidecar_path(self.path)
            tmp.with_name(f".{tmp.name}.tmp").unlink(missing_ok=True)

    def finish(self, result) -> Path:
        """Close with the metadata and status of ``result`` (a :class:`SimulationResult`).

        A result whose rows never came as chunks (an integrator without ``on_chunk``) is
        written whole here; its :attr:`~SimulationResult.events`, if any, go to
        ``NAME.events.EXT`` beside the file, as :meth:`SimulationResult.write` does."""
        from observer.io import write_frame

        self._closing = True
        meta = json.loads(to_json(result.metadata))
        meta["status"] = result.status.to_dict()
        if self.rows == 0 and result.t.size:
            df = result.to_frame()
            df.attrs = {}
            self.write(df)
        if getattr(result, "events", None) is not None:
            events_path = self.path.with_name(f"{self.path.stem}.events{self.path.suffix}")
            try:
                write_frame(result.events, events_path)
            except OSError as exc:
                raise self._oserror(exc, events_path) from None
            meta["events_file"] = events_path.name
        return self.close(meta)

    # -- signals ----------------------------------------------------------------------------
    def _mask(self, signum, frame) -> None:
        """SIGINT/SIGTERM outside the loop: before any row, what they did before; after,
        kept until the file is closed."""
        if self.chunks or self._closing:
            self._masked.append(signum)
            return
        old = self._old_handlers.get(signum)
        if callable(old):
            old(signum, frame)                           # e.g. KeyboardInterrupt
        elif old != signal.SIG_IGN:
            self._unmask()
            signal.raise_signal(signum)                  # the default action

    def _unmask(self) -> None:
        for signum, old in self._old_handlers.items():
            signal.signal(signum, old)
        self._old_handlers = {}

    def __enter__(self) -> "ChunkWriter":
        if threading.current_thread() is threading.main_thread():
            for name in self.SIGNALS:
                signum = getattr(signal, name)
                self._old_handlers[signum] = signal.signal(signum, self._mask)
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        try:
            if exc_type is not None and self.chunks == 0 and not self.closed:
                self.closed = True                       # failed before any row: no file at all
                self._discard()
                if self._opened and self.suffix == ".csv":
                    self.path.unlink(missing_ok=True)    # a first chunk cut short
                running_path(self.path).unlink(missing_ok=True)
                self._release()
            elif exc_type is not None and not self.closed and not issubclass(exc_type, OSError):
                where = f"after t = {self.t_last:.9g}" if self.t_last is not None else "before the first step"
                self.close({"status": {"state": "stopped",
                                       "reason": f"{exc_type.__name__} {where} ({self.rows} rows written)"}})
            elif exc_type is not None and not self.closed:
                self.closed = True                       # a failed write (a full disk): nothing more to write
                self._discard()
                self._release()
            elif not self.closed:
                self.close({"status": {"state": "stopped", "reason": "the writer was not finished"}})
        finally:
            masked = self._masked[:1]
            self._unmask()
            if masked and exc_type is None:
                signal.raise_signal(masked[0])           # the masked signal, now that the file is closed
        return False


def exit_status(result) -> int:
    """Exit status of ``observer run`` for ``result``: 0, or :data:`SIGNAL_EXIT` of the signal
    that stopped it, or :data:`STOPPED_EXIT` for a run stopped for another reason."""
    stopped = result.metadata.get("stopped")
    if not stopped:
        return 0
    return SIGNAL_EXIT.get(stopped.get("signal") or "", STOPPED_EXIT)
