"""The sticking decision from enclosures (issue 34 item 1): which contacts of a candidate set
(g = γ = 0) keep a positive force or stay identically closed under the acceleration LCP
``0 ≤ λ ⊥ Gλ + b ≥ 0``, against an independent exact (Fraction) solution of the LCP."""

from fractions import Fraction
from itertools import combinations

import numpy as np
import pytest

from observer.event.enclosures import stick_decisions


def _exact_lcp(M, W, b):
    """The LCP solution by enumeration of active sets, in Fractions (G a P-matrix: unique)."""
    n, m = len(M), len(b)
    Mi = [[Fraction(0)] * n for _ in range(n)]
    for i in range(n):                      # diagonal M only (the cases below)
        Mi[i][i] = 1 / Fraction(M[i][i])
    G = [[sum(Fraction(W[k][i]) * Mi[k][k] * Fraction(W[k][j]) for k in range(n))
          for j in range(m)] for i in range(m)]
    for size in range(m + 1):
        for S in combinations(range(m), size):
            lam = _solve([[G[i][j] for j in S] for i in S], [-b[i] for i in S])
            if lam is None or any(v <= 0 for v in lam):
                continue
            full = [Fraction(0)] * m
            for k, i in enumerate(S):
                full[i] = lam[k]
            w = [sum(G[i][j] * full[j] for j in range(m)) + b[i] for i in range(m)]
            if all(wi >= 0 for wi in w):
                return full, w
    raise AssertionError("no LCP solution")


def _solve(A, y):
    n = len(y)
    A = [row[:] + [y[i]] for i, row in enumerate(A)]
    for c in range(n):
        p = next((r for r in range(c, n) if A[r][c] != 0), None)
        if p is None:
            return None
        A[c], A[p] = A[p], A[c]
        for r in range(n):
            if r != c:
                f = A[r][c] / A[c][c]
                A[r] = [a - f * b for a, b in zip(A[r], A[c])]
    return [A[i][n] / A[i][i] for i in range(n)]


def _exact_b(vrows, A, z):
    Az = [sum(Fraction(a) * Fraction(v) for a, v in zip(row, z)) for row in A]
    return [sum(Fraction(r) * v for r, v in zip(row, Az)) for row in vrows]


def _float_lcp(M, W, b):
    """The float64 LCP by enumeration (the active set the engine's solver would return)."""
    G = W.T @ np.linalg.inv(M) @ W
    m = len(b)
    for size in range(m + 1):
        for S in combinations(range(m), size):
            lam = np.zeros(m)
            if S:
                lam[list(S)] = np.linalg.solve(G[np.ix_(S, S)], -b[list(S)])
            if np.all(lam[list(S)] > 0) and np.all(G @ lam + b >= 0):
                return lam
    return np.zeros(m)


def test_cancelling_free_acceleration_lifts_off_where_float64_sees_zero():
    """b = 1 + 1e-17 − 1: float64 evaluates 0 (a touching contact, kept by a round-off
    floor), the exact relative acceleration is 1e-17 > 0: the contact certainly lifts off."""
    M, W = np.eye(1), np.eye(1)
    vrows, A, z = np.ones((1, 3)), np.eye(3), np.array([1.0, 1e-17, -1.0])
    assert float((vrows @ A @ z)[0]) == 0.0
    keep, notes = stick_decisions(M, W, vrows, A, z, np.zeros(1), np.zeros(1))
    assert keep == [False] and notes == {}


def test_identically_closed_contact_is_kept_without_note():
    """Touching with no force: b exactly 0 on the float state, a carried state error
    around it: kept (no force, no relative acceleration), no undecided note."""
    M, W = np.eye(2), np.array([[1.0], [-1.0]])
    vrows, A, z = np.array([[1.0, -1.0]]), np.eye(2), np.array([0.5, 0.5])
    keep, notes = stick_decisions(M, W, vrows, A, z, np.array([1e-12]), np.zeros(1))
    assert keep == [True] and notes == {}


def test_undecided_within_the_carried_error_is_kept_and_noted():
    M, W = np.eye(1), np.eye(1)
    vrows, A, z = np.eye(1), np.eye(1), np.array([1e-14])
    keep, notes = stick_decisions(M, W, vrows, A, z, np.array([1e-12]), np.zeros(1))
    assert keep == [True] and "undecided stick" in notes[0]
    keep, notes = stick_decisions(M, W, vrows, A, z, np.array([1e-15]), np.zeros(1))
    assert keep == [False] and notes == {}


@pytest.mark.parametrize("seed", range(40))
def test_decisions_match_the_exact_lcp(seed):
    """Random 2–3-contact candidate sets on 3 masses, b of mixed signs with tiny margins:
    a decided contact is kept exactly when the exact LCP gives it λ > 0 or w = 0."""
    rng = np.random.default_rng(seed)
    n, m = 3, int(rng.integers(2, 4))
    M = np.diag(rng.integers(1, 5, n).astype(float))
    W = rng.integers(-2, 3, (n, m)).astype(float)
    W[np.arange(m) % n, np.arange(m)] = 3.0       # full column rank: G a P-matrix
    if np.linalg.matrix_rank(W) < m:
        pytest.skip("singular Delassus matrix")
    vrows, A = np.eye(m, 2 * m), np.eye(2 * m)
    z = np.concatenate([rng.normal(size=m), rng.normal(size=m) * 1e-16])
    b = vrows @ A @ z
    keep, notes = stick_decisions(M, W, vrows, A, z, np.zeros(m), _float_lcp(M, W, b))
    lam, w = _exact_lcp(M.tolist(), W.tolist(), _exact_b(vrows, A, z))
    for i in range(m):
        if i not in notes:
            assert keep[i] == (lam[i] > 0 or w[i] == 0), (i, lam, w)
