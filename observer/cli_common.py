"""What every command line of the toolkit shares: one-line argparse errors, ``KEY=VALUE``
pairs, and :func:`guarded`, which turns an input, solver, file or numerical failure into one
``error:`` line and exit status 2.

A neutral module below the command lines: ``observer.cli``, ``proofs_checks.cli`` and
``python -m bench`` import it; no command line imports another's.
"""

from __future__ import annotations

import argparse
import codecs
import re
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


NEGATIVE_NUMBER = re.compile(r"^-(\d[\d_]*\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$",
                             re.IGNORECASE)
"""What argparse takes for a negative number rather than an option: ``-3``, ``-1e-4``, ``-.5``,
``-2.5E+3``, ``-inf`` (its own pattern knows neither exponents nor infinity, so ``--h -1e-4``
was "expected one argument"); the value then reaches the field's own check (``simulation.h:
must be > 0``)."""


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``error: ...``, exit status 2), like every other input
    error, and negative numbers (:data:`NEGATIVE_NUMBER`) accepted as option values."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER

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


def _escape_unencodable(err: UnicodeEncodeError) -> tuple[str, int]:
    """A character the terminal's encoding lacks (``§``, ``≻`` under ``LANG=C``) as its
    ``\\uXXXX`` escape, which a TOML string reads back as the same character."""
    text = err.object[err.start:err.end]
    return "".join(f"\\u{ord(c):04x}" if ord(c) <= 0xFFFF else f"\\U{ord(c):08x}" for c in text), err.end


ESCAPE_ERRORS = "observer-escape"
codecs.register_error(ESCAPE_ERRORS, _escape_unencodable)


def escape_unencodable_output() -> None:
    """Let stdout and stderr write what their encoding cannot (an ASCII terminal under
    ``LANG=C``) as ``\\uXXXX`` escapes instead of dying with ``UnicodeEncodeError``."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        encoding = getattr(stream, "encoding", None) or "ascii"
        if reconfigure is not None and not codecs.lookup(encoding).name.startswith("utf"):
            try:
                reconfigure(errors=ESCAPE_ERRORS)
            except (ValueError, OSError):      # a stream that cannot change now: left as it is
                pass


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
    of the toolkit. Characters the output streams cannot encode are written as escapes
    (:func:`escape_unencodable_output`)."""
    escape_unencodable_output()
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
