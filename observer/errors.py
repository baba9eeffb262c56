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
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


class ContactSolverError(RuntimeError):
    """A contact problem could not be solved to the required complementarity residual."""
