"""The sticking decision from enclosures (issue 34 item 1): which contacts of a candidate set
(g = γ = 0) keep a positive force or stay identically closed under the acceleration LCP
``0 ≤ λ ⊥ Gλ + b ≥ 0``, against an independent exact (Fraction) solution of the LCP; and its
float64 first try (``_stick_fast``), which either declines or returns what the ball-arithmetic
path (``_stick_arb``, called directly) returns."""

from fractions import Fraction
from itertools import combinations

import numpy as np
import pytest
from hypothesis import Phase, given, settings
from hypothesis import strategies as st

from observer.event.enclosures import _stick_arb, _stick_fast, stick_decisions


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


# -- the float64 first try against the arb path --------------------------------------------------

def _cancelling(c, eps):
    """b = c + eps − c (vrows = [I I I], A = I): float64 rounds c + eps, the exact b is eps
    (the sum of the float data)."""
    m = len(c)
    z = np.concatenate([c, eps, -c])
    return np.hstack([np.eye(m)] * 3), np.eye(3 * m), z


@st.composite
def lcp_case(draw):
    """A random SPD Delassus matrix of 1–4 contacts (W of full column rank, M SPD) and free
    accelerations with cancellations at a random scale, a radius 0 … 100, the float64 LCP's
    solution (or, sometimes, a random vector: another active set)."""
    m = draw(st.integers(1, 4))
    n = m + draw(st.integers(0, 2))
    fl = st.floats(-3.0, 3.0, allow_nan=False)
    L = np.array(draw(st.lists(fl, min_size=n * n, max_size=n * n))).reshape(n, n)
    M = L @ L.T + draw(st.floats(0.1, 5.0)) * np.eye(n)
    W = np.array(draw(st.lists(fl, min_size=n * m, max_size=n * m))).reshape(n, m)
    W[np.arange(m), np.arange(m)] += 4.0
    c = np.array(draw(st.lists(st.floats(0.1, 3.0), min_size=m, max_size=m)))
    c *= np.array(draw(st.lists(st.sampled_from([1.0, -1.0]), min_size=m, max_size=m)))
    scale = 10.0 ** draw(st.sampled_from([0, -8, 0, -15, 0, -16, -17]))
    eps = np.array(draw(st.lists(fl, min_size=m, max_size=m))) * scale
    vrows, A, z = _cancelling(c, eps)
    radius = np.full(m, 0.0) if draw(st.integers(0, 3)) == 3 else \
        10.0 ** (np.array(draw(st.lists(st.floats(0.0, 22.0), min_size=m, max_size=m))) - 20.0)
    b = vrows @ A @ z
    lam = _float_lcp(M, W, b) if draw(st.integers(0, 4)) else \
        np.array(draw(st.lists(st.sampled_from([0.0, 1.0]), min_size=m, max_size=m)))
    return M, W, vrows, A, z, radius, lam


@settings(max_examples=300, deadline=None, derandomize=True, database=None,
          phases=[Phase.explicit, Phase.generate])
@given(lcp_case())
def test_the_float64_try_declines_or_returns_the_arb_answer(case):
    """300 random systems: ``_stick_fast`` returns None or exactly ``_stick_arb``'s flags and
    notes, and ``stick_decisions`` returns ``_stick_arb``'s."""
    if np.linalg.matrix_rank(case[1]) < case[1].shape[1]:
        return
    arb = _stick_arb(*case)
    fast = _stick_fast(*case)
    assert fast is None or fast == arb, (fast, arb)
    assert stick_decisions(*case) == arb


def test_the_float64_try_decides_a_clear_case_as_the_arb_path():
    """Two sticking contacts and one lifting off, margins far above the rounding and the
    radius: decided in float64, the arb path's answer ([True, True, False], no notes)."""
    M, W = np.diag([1.0, 2.0, 3.0]), np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.2], [0.0, 0.0, 1.0]])
    G = W.T @ np.linalg.solve(M, W)
    lam = np.array([1.0, 2.0, 0.0])
    b = -G @ lam + np.array([0.0, 0.0, 1.5])
    vrows, A, z = np.eye(3), np.eye(3), b
    case = (M, W, vrows, A, z, np.full(3, 1e-9), lam)
    assert _stick_fast(*case) == _stick_arb(*case) == ([True, True, False], {})


def test_a_sign_float64_gets_right_without_a_certain_bound_is_declined():
    """b = 1 + 3e-16 − 1: float64 gives 2.2e-16 > 0 (the exact 3e-16 is positive too), but
    its error bound covers 0: the float64 try declines, the arb path lifts the contact off.
    A force of 1e-14 with a radius of 4e-15 (certainly positive, but not by 3 radii): declined,
    the arb path keeps it."""
    M, W = np.eye(1), np.eye(1)
    vrows, A, z = np.ones((1, 3)), np.eye(3), np.array([1.0, 3e-16, -1.0])
    assert float((vrows @ A @ z)[0]) > 0.0
    case = (M, W, vrows, A, z, np.zeros(1), np.zeros(1))
    assert _stick_fast(*case) is None
    assert stick_decisions(*case) == _stick_arb(*case) == ([False], {})
    case = (M, W, np.eye(1), np.eye(1), np.array([-1e-14]), np.array([4e-15]), np.array([1e-14]))
    assert _stick_fast(*case) is None
    assert stick_decisions(*case) == _stick_arb(*case) == ([True], {})


def test_a_sign_float64_gets_wrong_is_declined():
    """b = 1 + 1.5e-16 − 1 − 2e-16: float64 gives +2.2e-17 (a lift-off for the empty active
    set), the exact value is −5e-17 (the contact sticks): the float64 try declines and the arb
    path keeps the contact."""
    M, W = np.eye(1), np.eye(1)
    vrows, A, z = np.ones((1, 4)), np.eye(4), np.array([1.0, 1.5e-16, -1.0, -2e-16])
    assert float((vrows @ A @ z)[0]) > 0.0
    case = (M, W, vrows, A, z, np.zeros(1), np.zeros(1))
    assert _stick_fast(*case) is None
    assert stick_decisions(*case) == _stick_arb(*case) == ([True], {})


def test_an_identically_closed_contact_is_declined():
    """b exactly 0 on the float state (touching, no force): the float64 try declines; the arb
    path keeps it, no note."""
    M, W = np.eye(2), np.array([[1.0], [-1.0]])
    case = (M, W, np.array([[1.0, -1.0]]), np.eye(2), np.array([0.5, 0.5]), np.array([1e-12]),
            np.zeros(1))
    assert _stick_fast(*case) is None
    assert stick_decisions(*case) == _stick_arb(*case) == ([True], {})


def test_an_exact_tie_of_pivots_is_followed_both_ways_and_decided_as_the_arb_path():
    """A Delassus matrix with G_20 = −G_00 (as a rocking chain's): arb's partial pivoting
    may take either row, both pivot sequences are followed, and the float64 try decides,
    with the arb path's answer (four contacts kept, no notes)."""
    M = 3.0 * np.eye(4)
    W = np.array([[1.0, 0.0, -1.0, 0.0], [1.0, 1.0, -1.0, 0.0],
                  [0.0, 0.0, 1.0, 1.0], [0.0, 1.0, 0.0, 1.0]])
    G = W.T @ np.linalg.solve(M, W)
    assert G[2, 0] == -G[0, 0] and np.linalg.matrix_rank(W) == 4
    lam = np.array([1.0, 2.0, 1.5, 0.5])
    b = -G @ lam
    case = (M, W, np.eye(4), np.eye(4), b, np.full(4, 1e-12), lam)
    assert _stick_fast(*case) == _stick_arb(*case) == ([True] * 4, {})
