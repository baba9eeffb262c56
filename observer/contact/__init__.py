"""Contact solvers behind one interface, and their registry :data:`CONTACT_SOLVERS`.

A contact solver is any object with a ``name`` and a method
``solve(G, b) -> LCPSolution`` for the LCP ``0 ≤ Gx + b ⊥ x ≥ 0`` with symmetric PSD G.

- ``"pivoting"`` (default, fast and exact): closed form for one contact, block principal
  pivoting for SPD G, Lemke for PSD G.
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


class PivotingSolver:
    """Fast exact solver: closed form (m = 1), block principal pivoting, Lemke as fallback."""

    name = "pivoting"

    def solve(self, G: np.ndarray, b: np.ndarray) -> LCPSolution:
        if b.shape[0] == 1 and G[0, 0] > 0.0:
            return solve_single(G, b)
        sol = block_principal_pivoting(G, b)
        if sol is None or sol.residual > 1e-10:
            alt = lemke(G, b)
            if alt is not None and (sol is None or alt.residual < sol.residual):
                sol = alt
        if sol is None:
            raise ContactSolverError("pivoting: no solution found (infeasible LCP or G not PSD)")
        return sol


class LemkeSolver:
    """Lemke's algorithm for every size (exact pivoting; handles PSD G)."""

    name = "lemke"

    def solve(self, G: np.ndarray, b: np.ndarray) -> LCPSolution:
        sol = lemke(G, b)
        if sol is None:
            raise ContactSolverError("lemke: ended on a secondary ray (infeasible LCP)")
        return sol


class NNLSSolver:
    """Cholesky factor + ``scipy.optimize.nnls`` (exact for SPD G)."""

    name = "nnls"

    def solve(self, G: np.ndarray, b: np.ndarray) -> LCPSolution:
        try:
            return nnls_cholesky(G, b)
        except np.linalg.LinAlgError:
            raise ContactSolverError("nnls: Delassus matrix is not positive definite") from None


class ReferenceSolver:
    """cvxpy + OSQP on the equivalent convex QP, compiled once per problem size."""

    name = "reference"

    def solve(self, G: np.ndarray, b: np.ndarray) -> LCPSolution:
        return solve_reference(G, b)


CONTACT_SOLVERS = {cls.name: cls for cls in (PivotingSolver, LemkeSolver, NNLSSolver, ReferenceSolver)}
"""Registry: stable name -> solver class."""


def get_solver(name: str, field: str = "solver"):
    """Instantiate a registered contact solver by name (``field`` names the input in errors)."""
    try:
        return CONTACT_SOLVERS[name]()
    except (KeyError, TypeError):
        raise InputError(field, f"unknown contact solver {name!r}; "
                         f"choose from {sorted(CONTACT_SOLVERS)}") from None


__all__ = ["CONTACT_SOLVERS", "LCPSolution", "get_solver", "lcp_residual", "PivotingSolver",
           "LemkeSolver", "NNLSSolver", "ReferenceSolver"]
