"""The transparent reference contact solver: the LCP written as a convex QP in cvxpy, solved by OSQP.

The QP ``min ½‖R x‖² + bᵀx, x ≥ 0`` with ``RᵀR = G`` is built **once per problem size**
with cvxpy ``Parameter``s (R and b), which keeps it DPP: later solves only update the
parameter values and skip canonicalisation. (A ``quad_form`` with a parameter matrix
would not be DPP.) When the diagonal of G spans more than :data:`SCALE_SPREAD` (badly
scaled contacts, e.g. diag(1e-10, 1, 1e10)), the QP is posed on the Jacobi-scaled problem
``LCP(DGD, Db)`` (``D = diag(G)^(-1/2)``, x = D y), so that OSQP's absolute tolerances mean
the same thing for a soft and a stiff contact; otherwise on (G, b) as given (scaling
then buys nothing, and OSQP's iterates on rank-deficient FCLIB data are measurably
worse with it: PerioBox residual 7e-8 against 4e-10). OSQP runs with tight
tolerances and polishing; the result is polished on its support and judged by its
complementarity residual, recomputed from x, like every other solver's.
"""

from __future__ import annotations

import numpy as np

from observer.contact.lcp import LCPSolution, _polish, jacobi_scaling, solution


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


SCALE_SPREAD = 1e4
"""Largest ratio max/min of diag(G) solved without Jacobi scaling."""

METHOD = "cvxpy-osqp"
"""``method`` of the reference solver's answers (a failed solve has x = NaN, residual = inf)."""


def _failure(m: int) -> LCPSolution:
    return LCPSolution(np.full(m, np.nan), np.inf, 0, METHOD)


def reference_scaling(G: np.ndarray) -> np.ndarray:
    """The reference's diagonal scaling: :func:`jacobi_scaling` when diag(G) spans more than
    :data:`SCALE_SPREAD`, else ones."""
    g = np.abs(np.diag(G))
    if g.size and np.min(g) * SCALE_SPREAD < np.max(g):
        return jacobi_scaling(G)
    return np.ones(g.size)


def solve_reference(G: np.ndarray, b: np.ndarray) -> LCPSolution:
    """Solve LCP(G, b) as a QP with cvxpy + OSQP (Jacobi-scaled); polish on the support."""
    import cvxpy as cp

    m = b.shape[0]
    if np.all(b >= 0.0):
        return solution(G, b, np.zeros(m), 0, METHOD)
    d = reference_scaling(G)
    problem, x, R, bp = _CACHE.get(m)
    R.value = psd_factor(G * np.outer(d, d))
    bp.value = d * np.asarray(b, dtype=float)
    try:
        problem.solve(solver=cp.OSQP, warm_start=True, **OSQP_SETTINGS)
    except cp.error.SolverError:
        return _failure(m)
    if x.value is None:
        return _failure(m)
    y = np.clip(np.asarray(x.value, dtype=float), 0.0, None)
    sol = _polish(G, b, d * y)
    iters = int(problem.solver_stats.num_iters or 0) if problem.solver_stats else 0
    return solution(G, b, sol, iters, METHOD)
