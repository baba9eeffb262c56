"""What every command line of the toolkit shares: one-line argparse errors, ``KEY=VALUE``
pairs, and :func:`guarded`, which turns an input, solver, file or numerical failure into one
``error:`` line and exit status 2.

A neutral module below the command lines: ``observer.cli``, ``proofs_checks.cli`` and
``python -m bench`` import it; no command line imports another's.
"""

from __future__ import annotations

import argparse
import sys

from observer.errors import ContactSolverError, InputError, is_numerical_failure, one_line


def parse_pairs(items: list[str] | None, flag: str = "--set") -> dict[str, str]:
    """``["a.b=1", "c=x"]`` → ``{"a.b": "1", "c": "x"}``; a malformed item is an error on ``flag``."""
    out = {}
    for item in items or []:
        if "=" not in item:
            raise InputError(flag, f"expected KEY=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        out[key.strip()] = value.strip()
    return out


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``error: ...``, exit status 2), like every other input error."""

    def error(self, message: str):
        self.exit(2, f"error: {message} (see --help)\n")


def _os_error_file(exc: OSError, args: tuple) -> str:
    """The file an :class:`OSError` is about: its own ``filename``, else the command's output
    file(s) (a failed ``write`` on an open file, "No space left on device", names none)."""
    if exc.filename is not None:
        return str(exc.filename)
    ns = args[0] if args else None
    outs = [str(v) for k in ("out", "events", "json") if (v := getattr(ns, k, None))]
    return " or ".join(outs) or "output file"


def _silence_stdout() -> None:
    """Point standard output at ``/dev/null`` (its reader closed it: ``... | head``), so that
    the interpreter's final flush stays silent."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


#: Exit status of a command whose standard output was closed by its reader (128 + SIGPIPE).
BROKEN_PIPE_EXIT = 141


def guarded(func, *args) -> int:
    """Call ``func(*args)``; turn input, solver, file and out-of-memory errors, and a numerical
    library's own exception (:func:`~observer.errors.is_numerical_failure`), into one
    ``error:`` line on stderr and exit status 2 (130 on Ctrl-C). Shared by every command line
    of the toolkit."""
    try:
        return func(*args)
    except (InputError, ContactSolverError) as exc:
        print(f"error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except BrokenPipeError as exc:
        if exc.filename is None:        # results go to regular files only: this is a pipe, stdout
            _silence_stdout()
            print("error: standard output was closed by its reader (broken pipe); the files "
                  "written are not affected", file=sys.stderr)
            return BROKEN_PIPE_EXIT
        print(f"error: {one_line(_os_error_file(exc, args))}: {one_line(exc.strerror or str(exc))}",
              file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: {one_line(_os_error_file(exc, args))}: {one_line(exc.strerror or str(exc))}",
              file=sys.stderr)
        return 2
    except MemoryError:
        print("error: --store: the run does not fit in memory; keep fewer rows (--record-every K, "
              "or --store summary), shorten the run (--t-end, --h) or use a smaller system", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:            # noqa: BLE001  (re-raised unless a library's failure)
        if not is_numerical_failure(exc):
            raise
        where = getattr(args[0], "scenario", None) if args else None
        print(f"error: {one_line(str(where or 'input'))}: the computation failed "
              f"({type(exc).__name__}: {one_line(str(exc))}); please report this input",
              file=sys.stderr)
        return 2
