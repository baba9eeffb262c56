"""Sparse and banded system matrices: storage, structure and O(n) spectral checks.

A system's M, C, K, W are NumPy arrays for small systems and ``scipy.sparse`` CSR matrices
for large sparse ones (:data:`DENSE_MAX_N`): a sparse input of at most that many degrees of
freedom is densified on construction, so every small system runs the dense code paths it
always ran (bitwise the same trajectories); beyond, nothing of size n × n is formed for a
banded system.

The spectral quantities of a large sparse matrix come from

* a banded Cholesky factorization (``scipy.linalg.cholesky_banded``, O(n·bw²)) — positive
  definiteness, and the shift-invert operator for the smallest eigenvalue;
* Lanczos (``scipy.sparse.linalg.eigsh``, ARPACK) for the extreme eigenvalues, with the
  residual tolerance :data:`LANCZOS_TOL` (for a symmetric matrix the Ritz value is within
  ``‖r‖ ≤ tol·|λ|`` of an eigenvalue, and the largest Ritz value never exceeds λ_max);
* the Gershgorin bound when Lanczos does not converge (a rigorous upper bound of λ_max).

Every function that computes one says how (the ``how`` strings end up in the health record).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from observer.arrays import PATTERN_KEYS, as_array, check_declared_size, periodic_vector  # noqa: F401  (PATTERN_KEYS re-exported)
from observer.errors import InputError

DENSE_MAX_N = 512
"""Largest n held as dense arrays: a sparse M, C, K, W (a TOML triplet table, a generator's
``scipy.sparse`` matrix) of a system with at most this many degrees of freedom is converted
with ``.toarray()`` on construction (dense n × n costs at most 2 MiB there, and the dense
code paths are the reference ones); a larger sparse system stays sparse (CSR)."""

LANCZOS_TOL = 1e-8
"""Relative residual tolerance of the shift-invert Lanczos for a smallest eigenvalue
(``eigsh(tol=...)``): the Ritz value θ has ``‖Ax − θx‖ ≤ tol·|θ|`` and so lies within that of
an eigenvalue (the inverse's top is well separated: a few dozen iterations)."""

LANCZOS_TOL_MAX = 1e-3
"""Relative residual tolerance of Lanczos for a largest eigenvalue. The top of a long chain's
spectrum is a dense cluster: a tight tolerance costs thousands of restarts (N = 10⁴ blocks:
50 s at 1e-6, 0.18 s at 1e-3), a loose one is met by a Ritz value θ ≤ λ_max within ``tol·θ``
of an eigenvalue of the cluster. Measured on the chain N = 500 against dense ``eigh``: λ_max
low by 2.0e-4 (ω_max by 1.0e-4); the health record's ω_max needs 1 %."""

LANCZOS_NCV = 32
"""Lanczos basis size (ARPACK ``ncv``): the chain's top eigenvalues cluster, a larger basis
converges in fewer restarts."""

TRIPLET_KEYS = ("shape", "rows", "cols", "values")
"""The keys of a sparse matrix in a scenario document: ``{shape = [n, m], rows = [...],
cols = [...], values = [...]}`` (0-based indices; repeated (row, col) pairs are summed)."""


def is_sparse(A: Any) -> bool:
    """True for a ``scipy.sparse`` matrix or array."""
    return sp.issparse(A)


def dense(A: Any) -> np.ndarray:
    """A as a dense array (a sparse system's matrix on a dense code path: the python engine's
    dense structure, a non-K projection metric); O(n²) memory, so only for what needs it."""
    return A.toarray() if is_sparse(A) else A


def _start_vector(n: int) -> np.ndarray:
    """A fixed Lanczos start vector (ARPACK's default is random: results would vary by run)."""
    return 1.0 + 0.5 * np.sin(np.arange(n, dtype=float))


def triplet_document(A: sp.spmatrix, plain: bool = True) -> dict:
    """The triplet table of sparse ``A`` (row-major order, the inverse of
    :func:`observer.validation.triplet_matrix`): TOML-ready lists, or with ``plain=False``
    NumPy arrays (a generator's document: read back without a pass over Python lists)."""
    C = sp.csr_matrix(A)
    C.sum_duplicates()
    coo = C.tocoo()
    cast = (lambda x: x.tolist()) if plain else np.asarray
    return {"shape": [int(C.shape[0]), int(C.shape[1])], "rows": cast(coo.row.astype(np.int64)),
            "cols": cast(coo.col.astype(np.int64)), "values": cast(coo.data)}


BANDED_KEYS = ("shape", "offsets", "diagonals", "symmetric")
"""The keys of a banded matrix in a scenario document: ``{shape = [n, m], offsets = [...],
diagonals = [[...], ...]}`` — diagonal k holds the entries ``A[i, i + k]`` in order of i (its
length ``min(n, m − k)`` for k ≥ 0, ``min(n + k, m)`` for k < 0, scipy's ``A.diagonal(k)``),
or one number when it is constant, or a periodic table ``{pattern = [...], head = [...],
tail = [...]}`` (:data:`PATTERN_KEYS`); with ``symmetric = true`` (optional) only offsets k ≤ 0
are given and mirrored. At most one value per stored entry and no indices
(:func:`banded_document`)."""

PATTERN_MAX_PERIOD = 8
"""Longest period :func:`periodic_form` looks for."""


def periodic_form(d: np.ndarray, plain: bool = True) -> dict | None:
    """``d`` as a periodic table (:data:`PATTERN_KEYS`) when that stores at most a quarter of
    its values: the shortest period p ≤ :data:`PATTERN_MAX_PERIOD` and the longest p-periodic
    stretch (``d[i] == d[i + p]`` throughout), what precedes it the head, what follows the tail;
    None otherwise."""
    n = d.size
    best = None
    for p in range(1, min(PATTERN_MAX_PERIOD, n // 2) + 1):
        bad = np.flatnonzero(d[p:] != d[:-p])
        edges = np.concatenate([[-1], bad, [n - p]])
        k = int(np.argmax(np.diff(edges)))
        start, end = int(edges[k]) + 1, int(edges[k + 1]) + p      # d[start:end] is p-periodic
        stored = start + p + (n - end)
        if best is None or stored < best[0]:
            best = (stored, p, start, end)
    if best is None or best[0] > n // 4:
        return None
    _, p, start, end = best
    cast = (lambda x: x.tolist()) if plain else np.asarray
    out = {"pattern": cast(d[start:start + p])}
    if start:
        out["head"] = cast(d[:start])
    if end < n:
        out["tail"] = cast(d[end:])
    return out


def _diagonal(field: str, d: Any, size: int) -> np.ndarray:
    """One diagonal of a banded table (a number, a list of ``size`` values, a periodic table)."""
    if isinstance(d, dict):
        return periodic_vector(field, d, size, PATTERN_KEYS)
    d = as_array(field, d, () if np.ndim(d) == 0 else (size,))
    return np.full(size, float(d)) if d.ndim == 0 else d


def vector_document(x: Any) -> Any:
    """Vector ``x`` as a scenario document writes it: a compact periodic table
    (:data:`observer.arrays.VECTOR_KEYS`, ``{n, pattern, head, tail}``) when it is longer than
    :data:`DENSE_MAX_N` and :func:`periodic_form` finds one (at most a quarter of its values
    stored), else a list — as before for every system of at most 512 entries. Read back bit
    for bit by :func:`observer.arrays.as_array`."""
    x = np.asarray(x, dtype=float)
    form = periodic_form(x) if x.ndim == 1 and x.size > DENSE_MAX_N else None
    return {"n": int(x.size), **form} if form is not None else x.tolist()


def banded_document(A: Any, plain: bool = True) -> dict:
    """The banded table of sparse ``A`` (:data:`BANDED_KEYS`, the inverse of
    :func:`banded_matrix`): its nonzero diagonals, each one number when constant, only the
    lower ones of an exactly symmetric A; TOML-ready lists, or with ``plain=False`` NumPy arrays."""
    C = sp.csr_matrix(A)
    C.sum_duplicates()
    coo = C.tocoo()
    nz = coo.data != 0.0
    offsets = np.unique(coo.col[nz].astype(np.int64) - coo.row[nz])
    symmetric = C.shape[0] == C.shape[1] and exactly_symmetric(C)
    if symmetric:
        offsets = offsets[offsets <= 0]
    diagonals = []
    for k in offsets:
        d = C.diagonal(int(k))
        if d.size and np.all(d == d[0]):
            diagonals.append(float(d[0]))
        else:
            diagonals.append(periodic_form(d, plain) or (d.tolist() if plain else d))
    if any(isinstance(d, dict) for d in diagonals):   # TOML: an array of tables holds tables only
        diagonals = [d if isinstance(d, dict) else {"pattern": [d] if np.ndim(d) == 0 else d} for d in diagonals]
    doc = {"shape": [int(C.shape[0]), int(C.shape[1])], "offsets": [int(k) for k in offsets],
           "diagonals": diagonals}
    if symmetric:
        doc["symmetric"] = True
    return doc


BANDED_BYTES_PER_ENTRY = 48
"""Bytes per entry of a banded table while it is built: its diagonals, the DIA, COO and CSR
forms scipy passes through (8-byte values and indices), with a margin."""


def banded_matrix(field: str, value: dict) -> sp.csr_matrix:
    """A CSR matrix from a document's banded table (:data:`BANDED_KEYS`), in O(entries); errors
    name ``field.KEY``."""
    unknown = sorted(set(value) - set(BANDED_KEYS))
    if unknown:
        raise InputError(f"{field}.{unknown[0]}", f"unknown key of a banded matrix (known: {', '.join(BANDED_KEYS)})")
    for key in BANDED_KEYS[:3]:
        if key not in value:
            raise InputError(f"{field}.{key}", "required key of a banded matrix is missing")
    shape = as_array(f"{field}.shape", value["shape"], (2,))
    if not (np.all(shape == np.round(shape)) and np.all(shape >= 1)):
        raise InputError(f"{field}.shape", f"must be two positive integers, got {value['shape']!r}")
    n, m = int(shape[0]), int(shape[1])
    symmetric = value.get("symmetric", False)
    if not isinstance(symmetric, bool) or (symmetric and n != m):
        raise InputError(f"{field}.symmetric", "must be true or false (true only for a square matrix)")
    offsets = as_array(f"{field}.offsets", value["offsets"], (None,))
    lo, hi = (-(n - 1), 0) if symmetric else (-(n - 1), m - 1)
    if not (np.all(offsets == np.round(offsets)) and np.all((offsets >= lo) & (offsets <= hi))
            and np.unique(offsets).size == offsets.size):
        raise InputError(f"{field}.offsets", f"must be distinct integers in {lo}..{hi}")
    diags = value["diagonals"]
    if not isinstance(diags, (list, tuple)) or len(diags) != offsets.size:
        raise InputError(f"{field}.diagonals", f"must be a list of {offsets.size} diagonals, one per offset")
    ks = [int(k) for k in offsets]
    entries = sum((min(n, m - k) if k >= 0 else min(n + k, m)) * (2 if symmetric and k < 0 else 1) for k in ks)
    check_declared_size(field, f"a {n} × {m} banded matrix of {entries} entries",
                        BANDED_BYTES_PER_ENTRY * entries + 8.0 * (n + 1))
    data = [_diagonal(f"{field}.diagonals[{i}]", d, min(n, m - k) if k >= 0 else min(n + k, m))
            for i, (k, d) in enumerate(zip(ks, diags))]
    A = sp.diags(data, ks, shape=(n, m), format="csr") if data else sp.csr_matrix((n, m))
    if symmetric:
        strict = sp.diags([d for d, k in zip(data, ks) if k < 0], [k for k in ks if k < 0], shape=(n, m),
                          format="csr") if any(k < 0 for k in ks) else sp.csr_matrix((n, m))
        A = sp.csr_matrix(A + strict.T)
    A.sum_duplicates()
    return A


def sparse_document(A: Any, plain: bool = True) -> dict:
    """Sparse ``A`` as the shorter of its document tables: banded (:func:`banded_document`) when
    its diagonals hold at most as many values as the triplet table's three per entry (counted
    in full: a periodic diagonal only makes it shorter), else the triplet table
    (:func:`triplet_document`)."""
    C = sp.csr_matrix(A)
    coo = C.tocoo()
    nz = coo.data != 0.0
    offsets = np.unique(coo.col[nz].astype(np.int64) - coo.row[nz])
    n, m = C.shape
    stored = sum(min(n, m - k) if k >= 0 else min(n + k, m) for k in offsets.tolist())
    if stored <= 3 * int(np.count_nonzero(nz)):
        return banded_document(A, plain)
    return triplet_document(A, plain)


def bandwidth(*mats: Any) -> int:
    """Largest |i − j| over the nonzero entries of the given n×n matrices (dense or sparse)."""
    bw = 0
    for A in mats:
        if is_sparse(A):
            coo = sp.coo_matrix(A)
            nz = coo.data != 0.0
            d = np.abs(coo.row[nz].astype(np.int64) - coo.col[nz])
        else:
            i, j = np.nonzero(np.asarray(A))
            d = np.abs(i - j)
        bw = max(bw, int(d.max()) if d.size else 0)
    return bw


def to_band(A: Any, bw: int) -> np.ndarray:
    """Lower band storage of symmetric A: ``ab[d, j] = A[j + d, j]`` (LAPACK/scipy layout);
    A dense or sparse (a sparse A is read diagonal by diagonal, O(n·bw))."""
    n = A.shape[0]
    ab = np.zeros((bw + 1, n))
    for d in range(bw + 1):
        ab[d, :n - d] = A.diagonal(-d) if is_sparse(A) else np.diagonal(A, -d)
    return ab


def exactly_symmetric(A: Any) -> bool:
    """``A == Aᵀ`` entry for entry (dense or sparse)."""
    if is_sparse(A):
        return (sp.csr_matrix(A) != sp.csr_matrix(A).T).nnz == 0
    return bool(np.array_equal(A, A.T))


def quadratic_rows(X: np.ndarray, A: Any) -> np.ndarray:
    """``x_kᵀ A x_k`` for every row x_k of X (shape (N, n)): the dense einsum for a dense A
    (the reference summation order), ``Σ_i x_ki (A x_k)_i`` for a sparse one (O(N·nnz))."""
    if is_sparse(A):
        return np.einsum("ki,ki->k", X, np.asarray(A @ X.T).T)
    return np.einsum("ki,ij,kj->k", X, A, X)


def abs_sum(A: Any) -> float:
    """``Σ|a_ij|`` (dense or sparse)."""
    return float(abs(A).sum()) if is_sparse(A) else float(np.sum(np.abs(A)))


def gershgorin_max(A: Any) -> float:
    """Gershgorin upper bound of the largest eigenvalue of symmetric A: ``max_i a_ii + Σ_{j≠i}|a_ij|``."""
    A = sp.csr_matrix(A)
    d = A.diagonal()
    return float(np.max(d + np.asarray(abs(A).sum(axis=1)).ravel() - np.abs(d)))


def banded_cholesky(A: Any, shift: float = 0.0) -> np.ndarray | None:
    """The lower banded Cholesky factor of ``A + shift·I`` (symmetric, narrowly banded), or None
    when the factorization fails (the shifted matrix is not positive definite to round-off)."""
    ab = to_band(A, max(bandwidth(A), 1))
    ab[0] += shift
    try:
        return sla.cholesky_banded(ab, lower=True)
    except np.linalg.LinAlgError:
        return None


def is_narrowly_banded(A: Any) -> bool:
    """Bandwidth at most n/8 (the banded factorizations pay off)."""
    return bandwidth(A) <= A.shape[0] // 8


def largest_eigenvalue(A: Any, M: Any = None) -> tuple[float, str]:
    """Largest eigenvalue of symmetric sparse A (of ``A v = λ M v`` with M SPD when given), and
    how it was computed: Lanczos to :data:`LANCZOS_TOL_MAX` or, if that does not converge, the
    Gershgorin upper bound (of ``D^{-1/2} A D^{-1/2}`` for a diagonal M). A may also be a
    ``LinearOperator`` (no Gershgorin fallback then)."""
    operator = isinstance(A, spla.LinearOperator)
    if not operator:
        A = sp.csr_matrix(A)
    n = A.shape[0]
    if M is not None and bandwidth(M) == 0:          # diagonal M: a standard problem, scaled
        s = sp.diags(1.0 / np.sqrt(sp.csr_matrix(M).diagonal()))
        A, M = sp.csr_matrix(s @ A @ s), None
    if n < 3 and not operator:
        lam = float(np.linalg.eigvalsh(A.toarray())[-1]) if M is None else float(
            sla.eigh(A.toarray(), sp.csr_matrix(M).toarray(), eigvals_only=True)[-1])
        return lam, "dense (n < 3)"
    try:
        lam = spla.eigsh(A, k=1, M=None if M is None else sp.csc_matrix(M), which="LA",
                         tol=LANCZOS_TOL_MAX, ncv=min(n - 1, LANCZOS_NCV), v0=_start_vector(n),
                         return_eigenvectors=False)[0]
        return float(lam), f"Lanczos (eigsh, relative residual {LANCZOS_TOL_MAX:g})"
    except spla.ArpackNoConvergence:
        if M is not None or operator:
            raise
        return gershgorin_max(A), "Gershgorin upper bound (Lanczos did not converge)"


def gershgorin_min(A: Any) -> float:
    """Gershgorin lower bound of the smallest eigenvalue of symmetric A."""
    A = sp.csr_matrix(A)
    d = A.diagonal()
    return float(np.min(d - (np.asarray(abs(A).sum(axis=1)).ravel() - np.abs(d))))


def smallest_eigenvalue(A: Any) -> tuple[float, str]:
    """Smallest eigenvalue of symmetric sparse A and how it was computed.

    Narrowly banded A: shift-invert Lanczos about a shift σ ≤ λ_min with a banded Cholesky
    factor of ``A − σI`` — σ = 0 when A is positive definite, else below the Gershgorin lower
    bound (then ``A − σI`` is positive definite and the eigenvalue nearest σ is λ_min): O(n) per
    iteration, to :data:`LANCZOS_TOL`. Otherwise Lanczos for the smallest algebraic eigenvalue."""
    A = sp.csr_matrix(A)
    n = A.shape[0]
    if n < 3:
        return float(np.linalg.eigvalsh(A.toarray())[0]), "dense (n < 3)"
    v0, ncv = _start_vector(n), min(n - 1, LANCZOS_NCV)
    if is_narrowly_banded(A):
        sigma, chol = 0.0, banded_cholesky(A)
        spread = max(abs(gershgorin_min(A)), abs(gershgorin_max(A)), np.finfo(float).tiny)
        while chol is None:
            sigma = min(sigma, gershgorin_min(A)) - 1e-6 * spread
            spread *= 2.0
            chol = banded_cholesky(A, -sigma)
        op = spla.LinearOperator((n, n), matvec=lambda x: sla.cho_solve_banded((chol, True), x),
                                 dtype=float)
        lam = spla.eigsh(A, k=1, sigma=sigma, which="LM", OPinv=op, tol=LANCZOS_TOL, ncv=ncv, v0=v0,
                         return_eigenvectors=False)[0]
        return float(lam), f"shift-invert Lanczos on a banded Cholesky factor ({LANCZOS_TOL:g})"
    lam = spla.eigsh(A, k=1, which="SA", tol=LANCZOS_TOL_MAX, ncv=ncv, v0=v0, maxiter=100 * n,
                     return_eigenvectors=False)[0]
    return float(lam), f"Lanczos (eigsh SA, relative residual {LANCZOS_TOL_MAX:g})"


def extreme_eigenvalues(A: Any) -> tuple[float, float]:
    """Smallest and largest eigenvalue of the symmetric part of sparse A (O(n) for a banded A:
    :func:`smallest_eigenvalue`, :func:`largest_eigenvalue`)."""
    S = sp.csr_matrix(0.5 * (A + A.T))
    return smallest_eigenvalue(S)[0], largest_eigenvalue(S)[0]


def definite_by_cholesky(A: Any, shift: float) -> bool | None:
    """Whether ``A + shift·I`` has a banded Cholesky factorization (None: A is not narrowly
    banded, the test does not apply)."""
    if not is_narrowly_banded(A):
        return None
    return banded_cholesky(A, shift) is not None


UNIT_ROUNDOFF = 2.0 ** -53
"""u, the unit round-off of float64 (round to nearest)."""

ETA = 2.0 ** -1074
"""η, the smallest positive (subnormal) float64: the absolute error of a product or quotient
that underflows."""

VERIFY_MARGIN = 1.01
"""Factor of the shift over the backward-error bound in :func:`verified_definite` (1 % over
the bound: the conclusion λ_min > 0 is strict, and the few roundings of computing c itself,
a few u, are covered)."""


def gamma(k: int) -> float:
    """``γ_k = k·u / (1 − k·u)`` (Higham, *Accuracy and Stability*, §3.1)."""
    return k * UNIT_ROUNDOFF / (1.0 - k * UNIT_ROUNDOFF)


def verification_shift(w: int, a_max: float) -> float:
    """The shift c of :func:`verified_definite` for bandwidth ``w`` and largest diagonal entry
    ``a_max``::

        c = 1.01·[ γ/(1−γ)·(2w+1)·a_max·(1+u)  +  u·a_max  +  4(2w+1)(2(w+2) + a_max)·η ],
        γ = γ_{w+2}

    The first term bounds ‖ΔA‖₂ of the Cholesky backward error (:func:`verified_definite`),
    the second the rounding of the shifted diagonal fl(a_ii − c), the third underflow."""
    g = gamma(w + 2)
    band = 2 * w + 1
    bound = (g / (1.0 - g)) * band * a_max * (1.0 + UNIT_ROUNDOFF) + UNIT_ROUNDOFF * a_max \
        + 4.0 * band * (2.0 * (w + 2) + a_max) * ETA
    return VERIFY_MARGIN * bound


def verified_definite(A: Any) -> tuple[bool, str] | None:
    """Whether the symmetric banded matrix A is positive definite, *proved* in floating point
    (Rump, "Verification of positive definiteness", BIT 46 (2006); Higham, *Accuracy and
    Stability of Numerical Algorithms*, 2nd ed., Thms 10.3-10.7), and how; None when the test
    does not apply (A not exactly symmetric or not narrowly banded: the caller falls back to
    eigenvalues). O(n·w²) for bandwidth w.

    A is positive definite when the floating-point banded Cholesky factorization of
    ``fl(A − c·I)`` runs to completion with c = :func:`verification_shift` (w, max_i a_ii).
    Why: the computed factor R satisfies ``RᵀR = Ã + Δ`` with
    ``|Δ| ≤ γ_{w+2}|Rᵀ||R|`` (Higham Thm 10.3, the inner products of a band of width w having
    at most w + 1 terms instead of n) plus an underflow term (Rump Thm 2.3, n → w + 2);
    column i of R has ``‖r_i‖² = ã_ii + Δ_ii ≤ ã_ii/(1 − γ)``, so by Cauchy-Schwarz
    ``(|Rᵀ||R|)_ij ≤ ‖r_i‖‖r_j‖ ≤ max_i ã_ii/(1 − γ)``, nonzero only for |i − j| ≤ w: each row
    of the nonnegative symmetric ``|Rᵀ||R|`` sums to at most (2w+1)·max ã_ii/(1 − γ), a bound
    of its 2-norm; ``ã_ii = fl(a_ii − c) ≤ a_ii(1 + u)``, and the rounding of the shifted
    diagonal is a diagonal error of at most u·max a_ii. RᵀR ⪰ 0 then gives
    ``λ_min(A) ≥ c − (those bounds) = c·(1 − 1/1.01) > 0``. Every diagonal entry must be
    positive (else A is not positive definite).

    The test cannot prove a positive definite A whose λ_min is below c (a near miss:
    ``A − cI`` is indefinite and its factorization breaks down, up to round-off), so
    c/max a_ii ≈ (2w+1)(w+2)·u is the smallest λ_min/max a_ii it can accept: 2.35e-15 for
    w = 2 (a chain of blocks). The default rocking chain of 10⁵ blocks (cond(K) = 2.5e12, λ_min = 3.16e-9, max K_ii = 4000) passes
    with λ_min = 335·c; its λ_min falls like 1/N², so it passes up to N ≈ 1.8·10⁶ blocks.
    """
    if not (A.shape[0] == A.shape[1] and is_narrowly_banded(A) and exactly_symmetric(A)):
        return None
    d = A.diagonal()
    if not np.all(d > 0.0):
        return False, "a diagonal entry ≤ 0 (a positive definite matrix has a positive diagonal)"
    w = max(bandwidth(A), 1)
    c = verification_shift(w, float(np.max(d)))
    ok = banded_cholesky(A, -c) is not None
    how = (f"verified (Rump 2006): banded Cholesky of fl(K − c·I) {'succeeded' if ok else 'failed'}, "
           f"c = {c:.3g} = 1.01·[γ_(w+2)/(1−γ_(w+2))·(2w+1)·max K_ii·(1+u) + u·max K_ii + underflow], "
           f"w = {w}" + (": λ_min(K) > 0" if ok else ": λ_min(K) may be below c, not proved positive"))
    return ok, how
