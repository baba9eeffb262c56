"""Linear complementarity problems with symmetric PSD matrices, and exact pivoting solvers.

Every contact problem of a Moreau–Jean step is an LCP

    0 ≤ w = G x + b  ⊥  x ≥ 0,

with G = W_Aᵀ Â⁻¹ W_A (the Delassus matrix of the active set A, SPD when the columns of
W are independent) or, for rank-deficient data such as FCLIB, only PSD. It is the KKT
system of the convex QP ``min ½xᵀGx + bᵀx, x ≥ 0``.

Solutions are judged by the natural residual ``‖min(x, w)‖_∞`` relative to the scale of
the problem (:func:`lcp_residual`), **recomputed from the returned x** by every solver
(never a status flag, never a hard-coded value).

Badly scaled contacts (diagonal entries of G spread over many decades, e.g.
diag(1e-10, 1, 1e10)) are handled by the symmetric diagonal (Jacobi) scaling of
:func:`jacobi_scaling`: with D = diag(G)^(-1/2), ``LCP(G, b)`` and ``LCP(DGD, Db)`` have
the solutions ``x = D y`` and the same complementarity pattern, and DGD has a unit
diagonal, so that relative pivot tolerances mean the same thing for every contact.

The functions here use plain float arrays and loops only, so that they can later be
compiled (numba) without a redesign.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

TINY = 1e-300
EPS = float(np.finfo(float).eps)
ROUNDOFF = 16.0
"""Round-off allowance of the pivoting tests, in units of ``m·eps`` of the row's magnitude."""


class LCPSolution(NamedTuple):
    """Result of one LCP solve.

    Attributes
    ----------
    x : ndarray, shape (m,)
        The complementary variable (impulse), ``x >= 0``.
    residual : float
        Relative natural residual of ``x``, recomputed by :func:`lcp_residual`.
    iterations : int
        Pivots (pivoting methods) or solver iterations (reference).
    method : str
        Which algorithm produced ``x`` (after any internal fallback).
    fallbacks : int
        Internal fallbacks tried while producing this answer (0: ``method`` was the first
        and only algorithm run).
    """

    x: np.ndarray
    residual: float
    iterations: int
    method: str
    fallbacks: int = 0


def lcp_residual(G: np.ndarray, b: np.ndarray, x: np.ndarray) -> float:
    """Relative complementarity residual ``‖min(x, Gx + b)‖_∞ / scale``.

    ``scale = max(‖b‖_∞, ‖G x‖_∞)`` makes the measure independent of the units of the
    impulse; it is 0 exactly at a solution and covers feasibility (x ≥ 0, w ≥ 0) and
    complementarity together.
    """
    Gx = G @ x
    w = Gx + b
    r = np.max(np.abs(np.minimum(x, w))) if x.size else 0.0
    scale = max(np.max(np.abs(b)) if b.size else 0.0, np.max(np.abs(Gx)) if x.size else 0.0, TINY)
    return float(r / scale)


def solution(G: np.ndarray, b: np.ndarray, x: np.ndarray, iterations: int, method: str) -> LCPSolution:
    """Package ``x`` with its residual recomputed from ``w = Gx + b`` (:func:`lcp_residual`)."""
    return LCPSolution(x, lcp_residual(G, b, x), iterations, method)


def jacobi_scaling(G: np.ndarray) -> np.ndarray:
    """Diagonal scaling ``d = diag(G)^(-1/2)`` (1 where ``G_ii <= 0``): ``d_i d_j G_ij`` has unit diagonal.

    For PSD G a zero diagonal entry means a zero row and column; that contact is left
    unscaled.
    """
    g = np.diag(G)
    d = np.ones(g.shape)
    pos = g > 0.0
    d[pos] = 1.0 / np.sqrt(g[pos])
    return d


def solve_single(G: np.ndarray, b: np.ndarray) -> LCPSolution:
    """Closed form for one contact with ``G > 0``: ``x = max(0, -b/G)``; residual recomputed."""
    g = G[0, 0]
    x = np.array([-b[0] / g]) if b[0] < 0.0 else np.zeros(1)
    return solution(G, b, x, 0, "closed-form")


def _roundoff_scale(G: np.ndarray, b: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per-row magnitude ``|b_i| + (|G||x|)_i`` that bounds the round-off of ``w_i = (Gx + b)_i``."""
    return np.abs(b) + np.abs(G) @ np.abs(x)


def _infeasible(G: np.ndarray, b: np.ndarray, x: np.ndarray, basic: np.ndarray) -> np.ndarray:
    """Indices violating the LCP: ``x_i < 0`` (basic) or ``w_i < 0`` beyond round-off (non-basic).

    The sign test on x is exact (and scale invariant); ``w_i`` of a non-basic index is
    compared with its own round-off bound ``ROUNDOFF·m·eps·(|b_i| + (|G||x|)_i)``, which
    is invariant under a diagonal scaling of the contacts and lets a degenerate index
    (``x_i = w_i = 0`` at the solution, computed as ``x_i = -1e-17``) leave the basis
    without coming back.
    """
    w = G @ x + b
    tol = ROUNDOFF * b.shape[0] * EPS * _roundoff_scale(G, b, x)
    return (basic & (x < 0.0)) | (~basic & (w < -tol))


def block_principal_pivoting(G: np.ndarray, b: np.ndarray, max_iter: int | None = None) -> LCPSolution | None:
    """Exact block principal pivoting (Júdice & Pires; Kim & Park's backup rule) for SPD G.

    Starts from the basis ``{i : b_i < 0}``, solves ``G_BB x_B = -b_B``, and flips every
    infeasible index at once (basic with ``x_i < 0``, non-basic with ``w_i < 0``, see
    :func:`_infeasible`) while their number decreases; after three non-improving rounds
    it flips only the largest infeasible index (Murty's single flip, finite for
    P-matrices: it never meets a basis twice). Returns ``None`` when a principal submatrix
    is singular, a single-flip round meets a basis again (both happen for G only PSD) or
    the pivots do not terminate within ``max_iter`` (default ``max(200, 20 m)``), so that
    a caller can fall back to Lemke; otherwise the residual is recomputed from x.
    """
    m = b.shape[0]
    basic = b < 0.0
    best, backups = m + 1, 3
    single_flip_bases: set[bytes] = set()
    x = np.zeros(m)
    for it in range(1, (max_iter or max(200, 20 * m)) + 1):
        x[:] = 0.0
        idx = np.flatnonzero(basic)
        if idx.size:
            try:
                x[idx] = np.linalg.solve(G[np.ix_(idx, idx)], -b[idx])
            except np.linalg.LinAlgError:
                return None
        if not np.all(np.isfinite(x)):
            return None
        infeasible = _infeasible(G, b, x, basic)
        count = int(infeasible.sum())
        if count == 0:
            return solution(G, b, x, it, "block-pivoting")
        if count < best:
            best, backups = count, 3
            basic ^= infeasible
        elif backups > 0:
            backups -= 1
            basic ^= infeasible
        else:
            key = basic.tobytes()
            if key in single_flip_bases:
                return None      # a basis came back: not a P-matrix (G singular) or round-off
            single_flip_bases.add(key)
            j = int(np.flatnonzero(infeasible)[-1])
            basic[j] = not basic[j]
    return None


def lemke(G: np.ndarray, b: np.ndarray, max_iter: int | None = None) -> LCPSolution | None:
    """Lemke's complementary pivoting with covering vector 1 (dense tableau).

    Processes every LCP with a PSD (more generally copositive-plus) matrix: it ends
    with a solution, or on a secondary ray (returns ``None``) when the LCP is
    infeasible. The pivots run on the Jacobi-scaled problem ``LCP(DGD, Db/‖Db‖_∞)``
    (:func:`jacobi_scaling`; for PSD G, ``|(DGD)_ij| <= 1``), so that the relative pivot tolerances do not mistake a
    stiff or a soft contact for a zero column; the final support is polished by a
    least-squares solve on the original data and the residual recomputed from x.
    """
    m = b.shape[0]
    if np.all(b >= 0.0):
        return solution(G, b, np.zeros(m), 0, "lemke")
    d = jacobi_scaling(G)
    bs = d * b
    b_scale = float(np.max(np.abs(bs)))
    sol = _lemke_unit(G * np.outer(d, d), bs / b_scale, max_iter or 50 * (m + 1))
    if sol is None:
        return None
    x = _polish(G, b, d * sol[0] * b_scale)
    return solution(G, b, x, sol[1], "lemke")


def _lemke_unit(G: np.ndarray, b: np.ndarray, max_iter: int) -> tuple[np.ndarray, int] | None:
    """Lemke's pivots on a problem scaled to unit diagonal and max|b| = 1; returns (x, pivots) or None."""
    m = b.shape[0]
    # Tableau columns: w (0..m-1), z (m..2m-1), z0 (2m), rhs (2m+1).
    T = np.zeros((m, 2 * m + 2))
    T[:, :m] = np.eye(m)
    T[:, m:2 * m] = -G
    T[:, 2 * m] = -1.0
    T[:, -1] = b
    basis = np.arange(m)
    z0 = 2 * m

    def pivot(r: int, c: int) -> None:
        T[r] /= T[r, c]
        col = T[:, c].copy()
        col[r] = 0.0
        T[:] -= np.outer(col, T[r])

    r = int(np.argmin(b))
    pivot(r, z0)
    leaving = int(basis[r])
    basis[r] = z0
    it = 1
    while it < max_iter:
        entering = leaving + m if leaving < m else leaving - m
        col = T[:, entering]
        tol = 1e-12 * max(1.0, np.max(np.abs(col)))
        pos = col > tol
        if not np.any(pos):
            return None  # secondary ray
        ratios = np.full(m, np.inf)
        ratios[pos] = T[pos, -1] / col[pos]
        rmin = np.min(ratios)
        ties = np.flatnonzero(ratios <= rmin + 1e-12 * abs(rmin))
        z0_rows = ties[basis[ties] == z0]
        r = int(z0_rows[0]) if z0_rows.size else int(ties[np.argmax(col[ties])])
        pivot(r, entering)
        leaving = int(basis[r])
        basis[r] = entering
        it += 1
        if leaving == z0:
            break
    else:
        return None
    x = np.zeros(m)
    for i in range(m):
        if m <= basis[i] < 2 * m:
            x[basis[i] - m] = max(T[i, -1], 0.0)
    return x, it


def _polish(G: np.ndarray, b: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Re-solve the equations of a guessed support; return the best of ``x`` and the re-solves.

    Two supports are tried: ``{x_i > 0}`` and ``{x_i/d_i > d_i w_i}`` (whichever of x_i and
    w_i is the larger in Jacobi-scaled units, the guess that discards an iterative solver's
    tiny positive leftovers). On a support S, ``G_SS x_S = -b_S`` is solved in scaled form
    ``(DGD)_SS y_S = -(Db)_S``, ``x = D y`` (least squares, so that a singular PSD block
    gives its minimum-norm solution), which keeps every contact's relative accuracy
    when the diagonal of G spans many decades. A re-solve is kept only if it is
    non-negative and its residual (:func:`lcp_residual`) is not worse. D is
    :func:`jacobi_scaling`.
    """
    d = jacobi_scaling(G)
    w = G @ x + b
    best, best_res = x, lcp_residual(G, b, x)
    for support in (x > 0.0, x / d > d * w):
        S = np.flatnonzero(support)
        if S.size == 0:
            continue
        ds = d[S]
        y = np.zeros_like(x)
        y[S] = ds * np.linalg.lstsq(G[np.ix_(S, S)] * np.outer(ds, ds), -ds * b[S], rcond=None)[0]
        if np.all(y >= 0.0):
            res = lcp_residual(G, b, y)
            if res <= best_res:
                best, best_res = y, res
    return best


def nnls_cholesky(G: np.ndarray, b: np.ndarray) -> LCPSolution:
    """Exact solve for SPD G as non-negative least squares on the Cholesky factor.

    With ``DGD = LLᵀ`` (Jacobi scaling D, :func:`jacobi_scaling`), ``min ½yᵀDGDy + (Db)ᵀy``
    over y ≥ 0 equals ``min ‖Lᵀy + L⁻¹Db‖²`` over y ≥ 0 (``scipy.optimize.nnls``,
    Lawson–Hanson active set), and ``x = D y``, polished on its support (:func:`_polish`:
    ``nnls``'s own tolerance is relative to ‖Db‖, which would cost a soft contact its
    relative accuracy). Raises ``numpy.linalg.LinAlgError`` when
    G is not numerically positive definite.
    """
    from scipy.linalg import solve_triangular
    from scipy.optimize import nnls

    d = jacobi_scaling(G)
    L = np.linalg.cholesky(G * np.outer(d, d))
    if np.all(b >= 0.0):        # x = 0 is the solution (unique for SPD G): no approaching contact
        return solution(G, b, np.zeros_like(b, dtype=float), 0, "nnls")
    c = solve_triangular(L, d * b, lower=True)
    y, _ = nnls(L.T, -c)
    return solution(G, b, _polish(G, b, d * y), 0, "nnls")
