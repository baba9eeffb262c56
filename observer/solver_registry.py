"""The contact-solver registry :data:`CONTACT_SOLVERS`, below both the model and the solvers.

A scenario names its contact solver (``simulation.solver``); validating that name needs the
registry, not the solvers. So the registry lives here: :mod:`observer.contact` fills it with
its factories when it is imported (``import observer`` does that first) and re-exports it,
and :mod:`observer.scenario` checks a name with :func:`solver_factory` without importing
any solver.
"""

from __future__ import annotations

from typing import Any, Callable

from observer.errors import InputError

CONTACT_SOLVERS: dict[str, Callable[..., Any]] = {}
"""Registry: stable name → solver factory (``pivoting``: block pivoting with Lemke as
fallback; ``lemke``: Lemke's algorithm, any PSD G; ``nnls``: NNLS on the Cholesky factor, SPD G;
``reference``: cvxpy + OSQP on the equivalent convex QP, compiled once per size). The
micro-benchmarks and the report iterate over it."""


def solver_factory(name: str, field: str = "solver") -> Callable[..., Any]:
    """The factory registered as contact solver ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`CONTACT_SOLVERS`.
    field : str
        The input named in the error.

    Returns
    -------
    callable
        The factory (called with the solver's options, it returns the solver).

    Raises
    ------
    InputError
        ``name`` is not registered (the message lists the registered names).
    """
    try:
        return CONTACT_SOLVERS[name]
    except (KeyError, TypeError):
        raise InputError(field, f"unknown contact solver {name!r}; "
                         f"choose from {sorted(CONTACT_SOLVERS)}") from None
