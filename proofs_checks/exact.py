"""Exact and certified linear algebra behind the ``proved`` verdicts (python-flint).

Every float64 number is a dyadic rational, so a float matrix *is* a rational matrix: it is
converted without rounding to a ``flint.fmpq_mat`` (:func:`to_fmpq_mat`) and decided there.

* :func:`classify_symmetric` — the inertia class of a symmetric rational matrix
  (``"definite"``, ``"semidefinite"`` (singular, PSD) or ``"indefinite"``) by an exact LDLᵀ
  with diagonal pivoting (Schur complements). With a positive pivot available it is
  eliminated; when every remaining diagonal entry is ≤ 0 the matrix is decided: a negative
  diagonal entry, or a zero diagonal entry with a nonzero off-diagonal entry in its row,
  gives a vector x with xᵀAx < 0 (for ``e_i − sign(s_ij) e_j``: −2|s_ij|); an all-zero
  Schur complement means PSD and singular. The certificate (the pivots, and the vector x,
  lifted to the full space through the eliminated block and re-checked by computing
  ``xᵀAx`` exactly) is returned: pivots > 0 prove definiteness (Sylvester's law of
  inertia: A = LDLᵀ is congruent to D).
* :func:`certify_definite_ball` — for large n (more than :data:`EXACT_MAX_N` rows) a
  rigorous ball-arithmetic certificate: with a float Cholesky factor A ≈ RRᵀ and the float
  matrix X ≈ R⁻¹ (exactly triangular with nonzero diagonal, so nonsingular), the arb
  enclosure of ``B = X A Xᵀ`` is computed; if every Gershgorin disc of B stays right of 0
  (``max_i Σ_j |B − I|_ij < 1`` as a rigorous upper bound), B ≻ 0 and hence A ≻ 0 by
  Sylvester's law of inertia (B is congruent to A).
* :func:`rank` — rank over Q (``fmpq_mat.rref``); :func:`null_vector` an exact kernel vector.

References: Sylvester's law of inertia and the LDLᵀ/Schur-complement inertia formula
(Haynsworth 1968), e.g. Horn & Johnson, *Matrix Analysis*, 2nd ed., Thm. 4.5.8 and §0.8.5;
Gershgorin's theorem, ibid. Thm. 6.1.1; arb ball arithmetic: F. Johansson, "Arb: efficient
arbitrary-precision midpoint-radius interval arithmetic", IEEE Trans. Comput. 66 (2017).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import flint
import numpy as np

EXACT_MAX_N = 100
"""Largest dimension decided by exact rational LDLᵀ; larger matrices use ball arithmetic."""


# ----------------------------------------------------------------------------- conversions
def to_fmpq(x: float) -> flint.fmpq:
    """The float ``x`` as an exact rational (ValueError for NaN/inf)."""
    p, q = float(x).as_integer_ratio()
    return flint.fmpq(p, q)


def to_fmpq_mat(A) -> flint.fmpq_mat:
    """A float array (1-D as a column) as an exact ``fmpq_mat``, entry by entry without rounding."""
    A = np.asarray(A, dtype=float)
    if A.ndim == 1:
        A = A[:, None]
    if not np.all(np.isfinite(A)):
        raise ValueError("matrix has non-finite entries")
    r, c = A.shape
    return flint.fmpq_mat(r, c, [to_fmpq(v) for v in A.ravel()])


def to_float(x: flint.fmpq) -> float:
    """Nearest-ish float of an exact rational (for witnesses and margins; the sign is exact
    unless the value underflows)."""
    p, q = int(x.p), int(x.q)
    try:
        return p / q                                  # correctly rounded by Python
    except OverflowError:
        return float("inf") if p > 0 else float("-inf")


def to_array(A: flint.fmpq_mat) -> np.ndarray:
    """Float array of an ``fmpq_mat`` (rounded; for display)."""
    return np.array([[to_float(A[i, j]) for j in range(A.ncols())] for i in range(A.nrows())])


def sym_part(A: flint.fmpq_mat) -> flint.fmpq_mat:
    """½(A + Aᵀ), exactly."""
    return (A + A.transpose()) / 2


def quad(A: flint.fmpq_mat, x: list) -> flint.fmpq:
    """xᵀAx exactly (x a list of rationals)."""
    v = flint.fmpq_mat(len(x), 1, list(x))
    return (v.transpose() * A * v)[0, 0]


# ----------------------------------------------------------------------------- inertia class
@dataclass
class Definiteness:
    """Certificate of the inertia class of a symmetric matrix.

    Attributes
    ----------
    status : {"definite", "semidefinite", "indefinite"}
        Positive definite; positive semi-definite and singular; not PSD.
    method : str
        ``"exact LDLᵀ over Q"`` or ``"arb ball congruence (Gershgorin)"``.
    pivots : list of fmpq
        The positive LDLᵀ pivots eliminated (all n of them when definite).
    vector : list of fmpq or None
        x with xᵀAx = ``value`` ≤ 0 (< 0 indefinite, = 0 with Ax = 0 semidefinite).
    value : fmpq or None
        xᵀAx, recomputed exactly from A and x.
    """

    status: str
    method: str
    pivots: list = field(default_factory=list)
    vector: list | None = None
    value: flint.fmpq | None = None

    @property
    def min_pivot(self):
        return min(self.pivots) if self.pivots else None


def leading_minors_positive(A: flint.fmpq_mat) -> list | None:
    """The LDLᵀ pivots of ``A`` (ratios of consecutive leading principal minors) when every
    leading principal minor is positive — Sylvester's criterion: then A ≻ 0 — else None.

    Fast path in C: the integer matrix ``den·A`` is factored fraction-free (Bareiss,
    ``fmpz_mat.fflu``); without a row exchange the k-th diagonal entry of U is the k-th
    leading principal minor of ``den·A``."""
    n = A.nrows()
    if n == 0:
        return []
    Z, den = A.numer_denom()
    P, _, _, U = Z.fflu()
    if P != flint.fmpz_mat(n, n, [int(i == j) for i in range(n) for j in range(n)]):
        return None
    minors = [U[k, k] for k in range(n)]
    if any(not mk > 0 for mk in minors):
        return None
    out, prev = [], flint.fmpz(1)
    for mk in minors:
        out.append(flint.fmpq(mk, prev) / den)
        prev = mk
    return out


def classify_symmetric(A: flint.fmpq_mat) -> Definiteness:
    """Exact inertia class of the symmetric rational matrix ``A`` (see module docstring)."""
    n = A.nrows()
    if A.ncols() != n or A != A.transpose():
        raise ValueError("classify_symmetric needs a square symmetric matrix")
    fast = leading_minors_positive(A)
    if fast is not None:
        return Definiteness("definite", "exact LDLᵀ over Q (Sylvester: leading minors > 0, Bareiss)", fast)
    S = [[A[i, j] for j in range(n)] for i in range(n)]
    rest = list(range(n))          # indices of the current Schur complement
    done: list[int] = []           # eliminated indices, in order
    pivots = []
    zero = flint.fmpq(0)
    while rest:
        p = next((i for i in rest if S[i][i] > 0), None)
        if p is None:
            break
        d = S[p][p]
        pivots.append(d)
        rest.remove(p)
        done.append(p)
        row = {j: S[p][j] / d for j in rest if S[p][j] != 0}
        for i in rest:
            sip = S[i][p]
            if sip == 0:
                continue
            Si = S[i]
            for j, r in row.items():
                Si[j] = Si[j] - sip * r
    if not rest:
        return Definiteness("definite", "exact LDLᵀ over Q", pivots)
    # every remaining diagonal entry is ≤ 0: decide, with a vector y on `rest`
    y = None
    neg = next((i for i in rest if S[i][i] < 0), None)
    if neg is not None:
        y = {neg: flint.fmpq(1)}
    else:
        for i in rest:
            j = next((j for j in rest if j != i and S[i][j] != 0), None)
            if j is not None:
                y = {i: flint.fmpq(1), j: flint.fmpq(-1 if S[i][j] > 0 else 1)}
                break
    status = "indefinite" if y is not None else "semidefinite"
    if y is None:
        y = {rest[0]: flint.fmpq(1)}
    x = _lift(A, done, rest, y)
    value = quad(A, x)
    if (status == "indefinite" and not value < 0) or (status == "semidefinite" and value != zero):
        raise AssertionError("exact LDLᵀ certificate failed its re-check")       # pragma: no cover
    return Definiteness(status, "exact LDLᵀ over Q", pivots, x, value)


def _lift(A: flint.fmpq_mat, done: list[int], rest: list[int], y: dict) -> list:
    """x with x_rest = y and x_done = −A_dd⁻¹ A_dr y, so that xᵀAx = yᵀ S y (S the Schur
    complement of the eliminated block ``done``, which is positive definite)."""
    n = A.nrows()
    x = [flint.fmpq(0)] * n
    for i, v in y.items():
        x[i] = v
    if done:
        k = len(done)
        Add = flint.fmpq_mat(k, k, [A[i, j] for i in done for j in done])
        b = flint.fmpq_mat(k, 1, [-sum((A[i, j] * v for j, v in y.items()), flint.fmpq(0)) for i in done])
        z = Add.solve(b)
        for t, i in enumerate(done):
            x[i] = z[t, 0]
    return x


def certify_definite_ball(A: np.ndarray) -> Definiteness | None:
    """Rigorous proof of A ≻ 0 for a large symmetric float matrix by ball arithmetic, or
    None when the certificate cannot be completed (not a disproof)."""
    A = np.asarray(A, dtype=float)
    try:
        R = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        return None
    X = np.linalg.inv(R)
    X = np.tril(X)
    if np.any(np.diag(X) == 0) or not np.all(np.isfinite(X)):
        return None
    Xa = flint.arb_mat(X.tolist())
    B = Xa * flint.arb_mat(A.tolist()) * Xa.transpose()
    n = A.shape[0]
    worst = flint.arb(0)
    for i in range(n):
        s = flint.arb(0)
        for j in range(n):
            s += abs(B[i, j] - (1 if i == j else 0))
        worst = max(worst, s.upper())
    if worst < 1:
        return Definiteness("definite", f"arb ball congruence X A Xᵀ (Gershgorin radius ≤ "
                                        f"{float(worst.mid()):.3g} < 1)")
    return None


def classify_float(A: np.ndarray, *, exact_max_n: int = EXACT_MAX_N) -> Definiteness:
    """Inertia class of the *symmetric part* of a float matrix, decided rigorously.

    Exact LDLᵀ over Q for n ≤ ``exact_max_n``; beyond, :func:`certify_definite_ball`, and if
    that does not prove definiteness, an exact check of the float eigenvector of the
    smallest eigenvalue (xᵀAx < 0 exactly: indefinite); if neither decides, the exact LDLᵀ
    after all (slow but rigorous)."""
    A = np.asarray(A, dtype=float)
    Q = sym_part(to_fmpq_mat(A))
    n = A.shape[0]
    if n <= exact_max_n:
        return classify_symmetric(Q)
    S = 0.5 * (A + A.T)
    cert = certify_definite_ball(S)
    if cert is not None:
        return cert
    w, V = np.linalg.eigh(S)
    x = [to_fmpq(v) for v in V[:, 0]]
    value = quad(Q, x)
    if value < 0:
        return Definiteness("indefinite", "float eigenvector, xᵀAx < 0 re-checked exactly over Q", [], x, value)
    return classify_symmetric(Q)


# ----------------------------------------------------------------------------- rank
def rank(A) -> int:
    """Rank over Q of a float matrix (exact)."""
    Q = A if isinstance(A, flint.fmpq_mat) else to_fmpq_mat(A)
    return Q.rref()[1]


def null_vector(A) -> list | None:
    """An exact nonzero x with A x = 0 (list of fmpq), or None when the columns are independent."""
    Q = A if isinstance(A, flint.fmpq_mat) else to_fmpq_mat(A)
    R, r = Q.rref()
    m = Q.ncols()
    if r == m:
        return None
    pivots = []
    row = 0
    for j in range(m):
        if row < r and R[row, j] != 0:
            pivots.append(j)
            row += 1
    free = next(j for j in range(m) if j not in pivots)
    x = [flint.fmpq(0)] * m
    x[free] = flint.fmpq(1)
    for t, j in enumerate(pivots):
        x[j] = -R[t, free]
    return x
