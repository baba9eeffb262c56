"""Contact solvers behind one interface, and their registry :data:`CONTACT_SOLVERS`.

A contact solver is any object with a ``name`` and a method
``solve(G, b) -> LCPSolution`` for the LCP ``0 ≤ Gx + b ⊥ x ≥ 0`` with symmetric PSD G.
Every answer carries its residual recomputed from the returned x (``w = Gx + b``,
:func:`lcp_residual`) and, in ``method``, the algorithm that actually produced x.

- ``"pivoting"`` (default, fast and exact): closed form for one contact, block principal
  pivoting for SPD G, Lemke as fallback for PSD G. ``PivotingSolver(fallback=False)``
  (or ``get_solver("pivoting", fallback=False)``) runs the fast path alone; the
  instance counts the fallbacks it took in ``fallbacks``.
- ``"lemke"``: Lemke's algorithm only (exact, any PSD G).
- ``"nnls"``: NNLS on the Cholesky factor (exact, SPD G only).
- ``"reference"``: the QP written in cvxpy and solved by OSQP (transparent, slow).
"""

from __future__ import annotations

import numpy as np

from observer.contact.lcp import (LCPSolution, block_principal_pivoting, lcp_residual, lemke,
                                  nnls_cholesky, solve_single)
from observer.contact.reference import solve_reference
from observer.errors import ContactSolverError, InputError
from observer.solver_registry import CONTACT_SOLVERS, solver_factory

ACCEPT_RESIDUAL = 1e-10
"""Largest residual of block pivoting that the pivoting solver accepts without trying Lemke."""


class PivotingSolver:
    """Fast exact solver: closed form (m = 1, G > 0), block principal pivoting, Lemke as fallback.

    Parameters
    ----------
    fallback : bool
        Try Lemke when block pivoting fails (singular principal block: G only PSD) or
        leaves a residual above :data:`ACCEPT_RESIDUAL`; the better answer is returned
        with ``fallbacks = 1``. With ``fallback=False`` block pivoting's own answer is
        returned whatever its residual (the caller judges it), and a failure raises
        ``ContactSolverError``.

    Attributes
    ----------
    fallbacks : int
        Number of solves of this instance that fell back to Lemke.
    """

    name = "pivoting"

    def __init__(self, fallback: bool = True) -> None:
        self.fallback = bool(fallback)
        self.fallbacks = 0

    def solve(self, G: np.ndarray, b: np.ndarray) -> LCPSolution:
        if b.shape[0] == 1 and G[0, 0] > 0.0:
            return solve_single(G, b)
        sol = block_principal_pivoting(G, b)
        if self.fallback and (sol is None or sol.residual > ACCEPT_RESIDUAL):
            self.fallbacks += 1
            alt = lemke(G, b)
            if alt is not None and (sol is None or alt.residual < sol.residual):
                sol = alt
            if sol is not None:
                sol = sol._replace(fallbacks=1)
        if sol is None:
            tried = "block pivoting and lemke" if self.fallback else "block pivoting (fallback disabled)"
            raise ContactSolverError(f"pivoting: no solution found by {tried} "
                                     "(infeasible LCP or G not PSD)")
        return sol


class ExactSolver:
    """A solver made of one exact LCP function ``fn(G, b) -> LCPSolution | None`` (None, or
    ``numpy.linalg.LinAlgError``, means no solution: raised as ``ContactSolverError`` with
    ``failure`` as the message)."""

    def __init__(self, name: str, fn, failure: str) -> None:
        self.name, self._fn, self._failure = name, fn, failure

    def solve(self, G: np.ndarray, b: np.ndarray) -> LCPSolution:
        try:
            sol = self._fn(G, b)
        except np.linalg.LinAlgError:
            sol = None
        if sol is None:
            raise ContactSolverError(f"{self.name}: {self._failure}")
        return sol


CONTACT_SOLVERS.update({
    "pivoting": PivotingSolver,
    "lemke": lambda: ExactSolver("lemke", lemke, "ended on a secondary ray (infeasible LCP)"),
    "nnls": lambda: ExactSolver("nnls", nnls_cholesky, "Delassus matrix is not positive definite"),
    "reference": lambda: ExactSolver("reference", solve_reference, "no solution"),
})
# the registry itself (and its documentation) is in observer.solver_registry, below the model


def get_solver(name: str, field: str = "solver", **options):
    """Instantiate a registered contact solver by name (``field`` names the input in errors).

    ``options`` go to the solver's constructor (e.g. ``fallback=False`` for ``"pivoting"``);
    an option the solver does not have raises ``InputError`` naming ``field``.
    """
    factory = solver_factory(name, field)
    try:
        return factory(**options)
    except TypeError:
        raise InputError(field, f"contact solver {name!r} takes no options "
                         f"{sorted(options)}") from None


__all__ = ["ACCEPT_RESIDUAL", "CONTACT_SOLVERS", "ExactSolver", "LCPSolution", "PivotingSolver",
           "get_solver", "lcp_residual"]
