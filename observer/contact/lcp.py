"""Linear complementarity problems with symmetric PSD matrices, and exact pivoting solvers.

Every contact problem of a Moreau–Jean step is an LCP

    0 ≤ w = G x + b  ⊥  x ≥ 0,

with G = W_Aᵀ Â⁻¹ W_A (the Delassus matrix of the active set A, SPD when the columns of
W are independent) or, for rank-deficient data such as FCLIB, only PSD. It is the KKT
system of the convex QP ``min ½xᵀGx + bᵀx, x ≥ 0``.

Solutions are judged by the natural residual ``‖min(x, w)‖_∞`` relative to the scale of
the problem (:func:`lcp_residual`), never by a solver's status flag.

The functions here use plain float arrays and loops only, so that they can later be
compiled (numba) without a redesign.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

TINY = 1e-300


class LCPSolution(NamedTuple):
    """Result of one LCP solve.

    Attributes
    ----------
    x : ndarray, shape (m,)
        The complementary variable (impulse), ``x >= 0``.
    residual : float
        Relative natural residual, see :func:`lcp_residual`.
    iterations : int
        Pivots (pivoting methods) or solver iterations (reference).
    method : str
        Which algorithm produced ``x`` (after any internal fallback).
    """

    x: np.ndarray
    residual: float
    iterations: int
    method: str


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


def solve_single(G: np.ndarray, b: np.ndarray) -> LCPSolution:
    """Closed form for one contact: ``x = max(0, -b/G)`` (exact, residual 0 up to round-off)."""
    g = G[0, 0]
    x = np.array([-b[0] / g]) if b[0] < 0.0 else np.zeros(1)
    return LCPSolution(x, 0.0, 0, "closed-form")


def block_principal_pivoting(G: np.ndarray, b: np.ndarray, max_iter: int = 200) -> LCPSolution | None:
    """Exact block principal pivoting (Júdice & Pires; Kim & Park's backup rule) for SPD G.

    Starts from the basis ``{i : b_i < 0}``, flips all infeasible indices at once while
    their number decreases, and falls back to Murty's single least-index flip (finite for
    P-matrices) after three non-improving rounds. Returns ``None`` when a principal
    submatrix is singular (G only PSD) or the pivots do not terminate, so that the
    caller can fall back to Lemke.
    """
    m = b.shape[0]
    basic = b < 0.0
    best, backups = m + 1, 3
    x = np.zeros(m)
    for it in range(1, max_iter + 1):
        x[:] = 0.0
        idx = np.flatnonzero(basic)
        if idx.size:
            try:
                x[idx] = np.linalg.solve(G[np.ix_(idx, idx)], -b[idx])
            except np.linalg.LinAlgError:
                return None
        w = G @ x + b
        scale = max(np.max(np.abs(b)), TINY)
        tol = 1e-13 * scale
        infeasible = (basic & (x < 0.0)) | (~basic & (w < -tol))
        count = int(infeasible.sum())
        if count == 0:
            x[~basic] = 0.0
            np.maximum(x, 0.0, out=x)
            return LCPSolution(x, lcp_residual(G, b, x), it, "block-pivoting")
        if count < best:
            best, backups = count, 3
            basic ^= infeasible
        elif backups > 0:
            backups -= 1
            basic ^= infeasible
        else:
            j = int(np.flatnonzero(infeasible)[-1])
            basic[j] = not basic[j]
    return None


def lemke(G: np.ndarray, b: np.ndarray, max_iter: int | None = None) -> LCPSolution | None:
    """Lemke's complementary pivoting with covering vector 1 (dense tableau).

    Processes every LCP with a PSD (more generally copositive-plus) matrix: it ends
    with a solution, or on a secondary ray (returns ``None``) when the LCP is
    infeasible. The final support is polished by a least-squares solve.
    """
    m = b.shape[0]
    if np.all(b >= 0.0):
        return LCPSolution(np.zeros(m), 0.0, 0, "lemke")
    # LCP(G, b) is homogeneous in b: solve the problem scaled to max|b| = 1 so that the
    # pivoting tolerances are relative, then scale back.
    b_scale = float(np.max(np.abs(b)))
    G_scale = max(float(np.max(np.abs(G))), TINY)
    sol = _lemke_unit(G / G_scale, b / b_scale, max_iter or 50 * (m + 1))
    if sol is None:
        return None
    x = _polish(G, b, sol[0] * (b_scale / G_scale))
    return LCPSolution(x, lcp_residual(G, b, x), sol[1], "lemke")


def _lemke_unit(G: np.ndarray, b: np.ndarray, max_iter: int) -> tuple[np.ndarray, int] | None:
    """Lemke's pivots on a problem scaled to max|G| = max|b| = 1; returns (x, pivots) or None."""
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
    """Re-solve ``G_SS x_S = -b_S`` on the support S of ``x``; keep it only if it is better."""
    support = np.flatnonzero(x > 0.0)
    if support.size == 0:
        return x
    y = np.zeros_like(x)
    y[support] = np.linalg.lstsq(G[np.ix_(support, support)], -b[support], rcond=None)[0]
    if np.all(y >= 0.0) and lcp_residual(G, b, y) <= lcp_residual(G, b, x):
        return y
    return x


def nnls_cholesky(G: np.ndarray, b: np.ndarray) -> LCPSolution:
    """Exact solve for SPD G as non-negative least squares on the Cholesky factor.

    With G = LLᵀ, ``min ½xᵀGx + bᵀx`` over x ≥ 0 equals ``min ‖Lᵀx + L⁻¹b‖²`` over x ≥ 0
    (``scipy.optimize.nnls``, Lawson–Hanson active set).
    """
    from scipy.linalg import solve_triangular
    from scipy.optimize import nnls

    L = np.linalg.cholesky(G)
    c = solve_triangular(L, b, lower=True)
    x, _ = nnls(L.T, -c)
    return LCPSolution(x, lcp_residual(G, b, x), 0, "nnls")
