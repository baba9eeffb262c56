"""Test helper: the exit code of a CLI ``main`` that may leave through argparse's ``SystemExit``."""

from __future__ import annotations


class ExitCode:
    """Context manager catching ``SystemExit`` as :attr:`value` (other exceptions propagate)."""

    value: int | None = None

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is SystemExit:
            self.value = exc.code
            return True
        return False
