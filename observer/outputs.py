"""What a command may write: never over one of its inputs, another of its outputs, a file
that is not a regular file, or a file another run is writing.

:func:`check_outputs` is called by each command line before any work is done; every writer
of :mod:`observer.io` and :mod:`observer.stream` refuses a non-regular target itself
(:func:`check_regular`) and holds :func:`output_lock` while it writes.
"""

from __future__ import annotations

import os
import stat
from contextlib import contextmanager
from pathlib import Path

from observer.errors import InputError

#: Seconds a writer waits for another run's lock on its output before refusing.
LOCK_TIMEOUT_S = 0.0


def family(path: str | Path) -> list[Path]:
    """``path`` and every file written beside it for it: the CSV sidecar, the events table and
    its sidecar, the Parquet ``running`` sidecar and the lock."""
    p = Path(path)
    ev = p.with_name(f"{p.stem}.events{p.suffix}")
    return [p, p.with_suffix(".json"), ev, ev.with_suffix(".json"),
            p.with_name(f"{p.name}.running"), lock_path(p)]


def _same(a: Path, b: Path) -> bool:
    """Whether two paths name one file: equal once resolved (symbolic links), or one inode
    (hard links)."""
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_regular(field: str, path: str | Path) -> None:
    """Refuse an existing ``path`` (followed through links) that is not a regular file: a
    FIFO would block the writer for ever, a device or socket is no result file."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return
    except NotADirectoryError:
        raise InputError(field, f"cannot use {str(path)!r}: a folder on its path is not a directory "
                                f"(it is a file)") from None
    except OSError as exc:
        raise InputError(field, f"cannot use {str(path)!r}: {exc.strerror or exc}") from None
    if stat.S_ISDIR(mode):
        raise InputError(field, f"{str(path)!r} is a directory")
    if not stat.S_ISREG(mode):
        kind = "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "not a regular file"
        raise InputError(field, f"{str(path)!r} is {kind}: results are written to regular files only")


def check_outputs(outputs: dict[str, str | Path | None], inputs: dict[str, str | Path | None]) -> None:
    """Refuse, before any work, an output that is one of the command's inputs, an output that
    is (or is written beside) another output, and an output or any file written beside it
    that exists and is not a regular file.

    Parameters
    ----------
    outputs, inputs : dict
        Flag (``--out``, ``--events``, ``result``, ...) → path; None entries are skipped.
    """
    outs = {k: Path(v) for k, v in outputs.items() if v is not None}
    ins = {k: Path(v) for k, v in inputs.items() if v is not None}
    for field, p in outs.items():
        for q in family(p):
            check_regular(field, q)
        for in_field, q in ins.items():
            if q.exists() and any(f.exists() and _same(f, q) for f in family(p)):
                raise InputError(field, f"{str(p)!r} would overwrite the input {in_field} "
                                        f"{str(q)!r}; choose another output file")
    names = list(outs)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            pa, pb = outs[a], outs[b]
            if any(_same(x, pb) for x in family(pa)) or any(_same(x, pa) for x in family(pb)):
                raise InputError(b, f"{str(pb)!r} is also written as {a} {str(pa)!r} (or beside it); "
                                    "give each output its own file")


def lock_path(path: str | Path) -> Path:
    """The lock of an output being written: ``.NAME.lock`` beside it."""
    p = Path(path)
    return p.with_name(f".{p.name}.lock")


@contextmanager
def output_lock(path: str | Path, timeout: float = LOCK_TIMEOUT_S):
    """Hold an inter-process lock on ``path`` while it is written (``filelock``): a second
    writer of the same file is refused with one line instead of interleaving its bytes. The
    lock file is removed when released."""
    from filelock import FileLock, Timeout

    lp = lock_path(path)
    lp.parent.mkdir(parents=True, exist_ok=True)
    lock = FileLock(lp, timeout=timeout)
    try:
        lock.acquire()
    except Timeout:
        raise InputError(str(path), f"another run is writing this file (its lock {lp.name} is "
                                    "held); wait for it or choose another output file") from None
    try:
        yield
    finally:
        try:
            lp.unlink(missing_ok=True)      # while still held: no other writer owns this name
        except OSError:
            pass
        lock.release()


def atomic_write(path: str | Path, write) -> Path:
    """Call ``write(tmp)`` on a temporary name beside ``path``, then rename it to ``path``
    (under :func:`output_lock`): a reader never sees a half-written file, and a failed write
    (a full disk, a read-only folder) leaves neither a partial ``path`` nor the temporary file.

    Returns
    -------
    Path
        ``path``.
    """
    p = Path(path)
    check_regular(str(p), p)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.stem}.tmp{p.suffix}")       # the suffix kept: writers choose the format by it
    with output_lock(p):
        try:
            write(tmp)
            os.replace(tmp, p)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
    return p
