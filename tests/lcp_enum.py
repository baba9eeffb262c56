"""A brute-force LCP oracle for the tests: enumerate every active set (small SPD problems only)."""

from __future__ import annotations

import itertools

import numpy as np


def lcp_enum(G: np.ndarray, b: np.ndarray, rtol: float = 1e-13) -> np.ndarray:
    """The solution of ``0 ≤ Gx + b ⊥ x ≥ 0`` (G ≻ 0) by trying every active set; the sign
    tests allow ``rtol·(1 + ‖b‖_∞)`` of round-off."""
    m = b.size
    tol = rtol * (1.0 + np.abs(b).max())
    for r in range(m + 1):
        for J in itertools.combinations(range(m), r):
            J = list(J)
            x = np.zeros(m)
            if J:
                x[J] = np.linalg.solve(G[np.ix_(J, J)], -b[J])
            if np.all(x >= -tol) and np.all(G @ x + b >= -tol):
                return np.maximum(x, 0.0)
    raise AssertionError("no active set solves the LCP")
