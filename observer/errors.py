"""Error types raised by the toolkit.

Every error about user input names the offending field, so that a message reads
like ``system.M: matrix is not symmetric (max |M - M^T| = 0.5)``.
"""

from __future__ import annotations


class InputError(ValueError):
    """Invalid user input (a scenario field, a matrix, a step size...).

    Parameters
    ----------
    field : str
        Dotted name of the offending field, e.g. ``"system.M"``.
    problem : str
        What is wrong with it.
    """

    def __init__(self, field: str, problem: str):
        self.field = one_line(str(field))
        self.problem = one_line(str(problem))
        super().__init__(f"{self.field}: {self.problem}")


class InputWarning(UserWarning):
    """Input the toolkit accepts but whose default the user may not have meant (a missing
    ``[system.gap]`` offset: every contact closed at q = 0); the message names the field."""


LINE_BREAKS = {c: repr(chr(c))[1:-1] for c in (0x0A, 0x0B, 0x0C, 0x0D, 0x1C, 0x1D, 0x1E, 0x85,
                                                0x2028, 0x2029)}
"""The characters :meth:`str.splitlines` breaks at, mapped to their escapes (``\\n``, ...)."""

CONTROLS = {**{c: f"\\x{c:02x}" for c in (*range(0x00, 0x09), *range(0x0B, 0x20), *range(0x7F, 0xA0))},
            **LINE_BREAKS}
"""Every C0 and C1 control character but the tab (BEL, ESC, DEL, the line breaks...), mapped
to its escape: a terminal would act on it (ring, move the cursor, recolour) rather than show it."""


def one_line(text: str) -> str:
    """``text`` with every line break and control character escaped (``\\n``, ``\\r``,
    ``\\x07``, ``\\x1b``...), so that an error message stays on one line and shows what it
    quotes (a path, a value, a scenario name) rather than letting a terminal act on it."""
    return text.translate(CONTROLS)


printable = one_line
"""The same escaping for a name echoed on a normal output line (``observer run``'s summary)."""


class ContactSolverError(RuntimeError):
    """A contact problem could not be solved to the required complementarity residual."""


NUMERICAL_MODULES = ("numpy", "scipy", "numba", "llvmlite", "tomllib")
"""Libraries whose own exceptions (``numpy.linalg.LinAlgError``, a numba ``TypingError``...)
never reach a user: :func:`is_numerical_failure` picks them out."""


CALLBACK_NOTE = "raised by the {name} callback given to the toolkit (the user's code), not by the toolkit"
"""The note :func:`user_callback` adds to an exception of a user's callback."""


def user_callback(name: str, func):
    """``func`` wrapped so that an exception it raises leaves unchanged (the user's own type,
    to catch as such) but noted as the callback's (:data:`CALLBACK_NOTE`, shown under its
    traceback): :func:`is_numerical_failure` then never reports it as the toolkit's failure
    (a ``ZeroDivisionError`` in an ``on_chunk`` was "the computation failed ... please report
    this input")."""
    def call(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except Exception as exc:           # noqa: BLE001  (re-raised, only annotated)
            exc.add_note(CALLBACK_NOTE.format(name=name))
            raise
    return call


def is_callback_failure(exc: BaseException) -> bool:
    """Whether ``exc`` was raised by a user's callback (:func:`user_callback`)."""
    return any(n.startswith("raised by the ") and n.endswith(", not by the toolkit")
               for n in getattr(exc, "__notes__", ()))


def is_numerical_failure(exc: BaseException) -> bool:
    """Whether ``exc`` is an arithmetic failure (overflow, division by zero, recursion too
    deep) or an exception raised by one of :data:`NUMERICAL_MODULES` rather than by the
    toolkit: the command line and :func:`observer.simulate` turn it into one error naming
    the scenario."""
    if isinstance(exc, MemoryError) or is_callback_failure(exc):   # a run too large; the user's code
        return False
    if isinstance(exc, (ArithmeticError, RecursionError)):
        return True
    return any(type(exc).__module__.split(".")[0] == m for m in NUMERICAL_MODULES)
