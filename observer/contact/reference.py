"""The transparent reference contact solver: the LCP written as a convex QP in cvxpy, solved by OSQP.

The QP ``min ½‖R x‖² + bᵀx, x ≥ 0`` with ``RᵀR = G`` is built **once per problem size**
with cvxpy ``Parameter``s (R and b), which keeps it DPP: later solves only update the
parameter values and skip canonicalisation. (A ``quad_form`` with a parameter matrix
would not be DPP.) OSQP runs with tight tolerances and polishing; the result is then
checked by its complementarity residual like every other solver's.
"""

from __future__ import annotations

import numpy as np

from observer.contact.lcp import LCPSolution, _polish, lcp_residual


def psd_factor(G: np.ndarray) -> np.ndarray:
    """A square matrix R with RᵀR = G for symmetric PSD G (Cholesky, else eigen-decomposition)."""
    try:
        return np.linalg.cholesky(G).T
    except np.linalg.LinAlgError:
        lam, V = np.linalg.eigh(0.5 * (G + G.T))
        return np.sqrt(np.clip(lam, 0.0, None))[:, None] * V.T


class ReferenceProblemCache:
    """cvxpy problems keyed by size m, each compiled once and re-used with new parameter values."""

    def __init__(self) -> None:
        self._problems: dict[int, tuple] = {}

    def get(self, m: int):
        import cvxpy as cp

        if m not in self._problems:
            x = cp.Variable(m, nonneg=True)
            R = cp.Parameter((m, m))
            b = cp.Parameter(m)
            problem = cp.Problem(cp.Minimize(0.5 * cp.sum_squares(R @ x) + b @ x))
            self._problems[m] = (problem, x, R, b)
        return self._problems[m]


_CACHE = ReferenceProblemCache()

OSQP_SETTINGS = dict(eps_abs=1e-12, eps_rel=1e-12, max_iter=200_000, polishing=True,
                     polish_refine_iter=10, verbose=False)
"""OSQP settings of the reference solver (tight tolerances, solution polishing on)."""


def solve_reference(G: np.ndarray, b: np.ndarray) -> LCPSolution:
    """Solve LCP(G, b) as a QP with cvxpy + OSQP; polish on the support if needed."""
    import cvxpy as cp

    m = b.shape[0]
    if np.all(b >= 0.0):
        return LCPSolution(np.zeros(m), 0.0, 0, "cvxpy-osqp")
    problem, x, R, bp = _CACHE.get(m)
    R.value = psd_factor(G)
    bp.value = np.asarray(b, dtype=float)
    try:
        problem.solve(solver=cp.OSQP, warm_start=True, **OSQP_SETTINGS)
    except cp.error.SolverError:
        return LCPSolution(np.full(m, np.nan), np.inf, 0, "cvxpy-osqp")
    if x.value is None:
        return LCPSolution(np.full(m, np.nan), np.inf, 0, "cvxpy-osqp")
    sol = np.clip(np.asarray(x.value, dtype=float), 0.0, None)
    sol = _polish(G, b, sol)
    iters = int(problem.solver_stats.num_iters or 0) if problem.solver_stats else 0
    return LCPSolution(sol, lcp_residual(G, b, sol), iters, "cvxpy-osqp")
