"""Small validators that turn raw user data into float arrays or raise :class:`InputError`.

This is the model layer's validation: the scenario, the model and the stepper all import
from here (never the other way round).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from observer import sparse as sps
from observer.arrays import MAX_DEPTH, as_array, check_declared_size, non_numeric_entry  # noqa: F401  (re-exported)
from observer.memory import available_memory  # noqa: F401  (re-exported)
from observer.errors import InputError

SYMMETRY_RTOL = 0.0
"""Accepted ``max|A - A^T|`` (relative to ``max|A|``) of M, C and K: none. They are the
Hessians of the kinetic energy, the Rayleigh dissipation and the potential energy (paper
eq. (1)), symmetric by definition; the equations use A itself (``Mu̇``, ``Kq``), not its
symmetric part, so an asymmetric A defines another system, and the exact checks of
:mod:`proofs_checks` would have to prove a statement about a matrix the run does not use.
Round-off from assembling A is the user's to remove, with ``(A + Aᵀ)/2`` (exactly symmetric
in floating point)."""

PSD_RTOL = 1e-10
"""Smallest eigenvalue allowed for a PSD matrix, relative to its largest absolute eigenvalue."""


SQRT_MAX = float(np.sqrt(np.finfo(float).max))
"""Largest accepted magnitude of a system matrix entry (≈ 1.34e154): beyond, its square overflows."""

INV_MIN = float(1.0 / np.finfo(float).max)
"""Smallest accepted nonzero magnitude of a system matrix entry (≈ 5.56e-309): below, its
inverse overflows."""

def as_matrix(field: str, value: Any, shape: tuple[int | None, int | None]) -> Any:
    """A system matrix: :func:`as_array`, or a CSR matrix for a ``scipy.sparse`` value or a
    document's sparse triplet table (:data:`observer.sparse.TRIPLET_KEYS`) or banded table (a
    table with ``offsets``, :data:`observer.sparse.BANDED_KEYS`); the shape and the
    finiteness of the entries are checked either way (errors name ``field``)."""
    if isinstance(value, dict):
        value = sps.banded_matrix(field, value) if "offsets" in value else triplet_matrix(field, value)
    if not sps.is_sparse(value):
        return as_array(field, value, shape)
    A = sp.csr_matrix(value, dtype=float)
    if any(s is not None and s != a for s, a in zip(shape, A.shape)):
        want = "x".join("*" if s is None else str(s) for s in shape)
        raise InputError(field, f"wrong shape: expected {want}, got {A.shape[0]}x{A.shape[1]}")
    if not np.all(np.isfinite(A.data)):
        raise InputError(field, "contains NaN or infinity")
    return A


def triplet_matrix(field: str, value: dict) -> sp.csr_matrix:
    """A CSR matrix from a document's triplet table (:data:`observer.sparse.TRIPLET_KEYS`); errors name
    ``field.KEY``."""
    unknown = sorted(set(value) - set(sps.TRIPLET_KEYS))
    if unknown:
        raise InputError(f"{field}.{unknown[0]}", f"unknown key of a sparse matrix (known: "
                         f"{', '.join(sps.TRIPLET_KEYS)})")
    for key in sps.TRIPLET_KEYS:
        if key not in value:
            raise InputError(f"{field}.{key}", "required key of a sparse matrix is missing")
    shape = as_array(f"{field}.shape", value["shape"], (2,))
    if not (np.all(shape == np.round(shape)) and np.all(shape >= 1)):
        raise InputError(f"{field}.shape", f"must be two positive integers, got {value['shape']!r}")
    n, m = int(shape[0]), int(shape[1])
    vals = as_array(f"{field}.values", value["values"], (None,))
    check_declared_size(field, f"a {n} × {m} sparse matrix", 16.0 * (n + 1) + 40.0 * vals.size)  # row pointers
    idx = []
    for key, size in (("rows", n), ("cols", m)):
        ix = as_array(f"{field}.{key}", value[key], (vals.size,))
        if not (np.all(ix == np.round(ix)) and np.all(ix >= 0) and np.all(ix < size)):
            raise InputError(f"{field}.{key}", f"must be integers in 0..{size - 1}, one per value")
        idx.append(ix.astype(np.int64))
    A = sp.coo_matrix((vals, (idx[0], idx[1])), shape=(n, m)).tocsr()
    A.sum_duplicates()
    return A


def check_entry_range(field: str, A: np.ndarray) -> None:
    """Raise unless every entry's square and every nonzero entry's inverse are finite:
    :data:`INV_MIN` ≤ |a| ≤ :data:`SQRT_MAX` or a = 0 (the system matrices enter quadratic
    forms, products and inverses; a 1e308 stiffness or a 1e-310 mass would overflow them)."""
    if sps.is_sparse(A):
        A = sp.csr_matrix(A).data          # the stored entries (an index into them is reported)
    mag = np.abs(A)
    big = np.argwhere(mag > SQRT_MAX)
    if big.size:
        i = tuple(int(k) for k in big[0])
        raise InputError(field, f"entry {float(A[i])!r} at index {i} is too large: its square overflows "
                         f"(|entry| must be <= {SQRT_MAX:.3g})")
    tiny = np.argwhere((mag > 0.0) & (mag < INV_MIN))
    if tiny.size:
        i = tuple(int(k) for k in tiny[0])
        raise InputError(field, f"entry {float(A[i])!r} at index {i} is too small: its inverse overflows "
                         f"(a nonzero |entry| must be >= {INV_MIN:.3g})")


def as_scalar(field: str, value: Any, *, positive: bool = False, low: float | None = None,
              high: float | None = None) -> float:
    """Convert ``value`` to a finite float, optionally checking ``> 0`` or ``low <= x <= high``."""
    if isinstance(value, bool):
        raise InputError(field, "expected a number, got a boolean")
    x = float(as_array(field, value, ()))
    if positive and not x > 0:
        raise InputError(field, f"must be > 0, got {x!r}")
    if low is not None and x < low:
        raise InputError(field, f"must be >= {low}, got {x!r}")
    if high is not None and x > high:
        raise InputError(field, f"must be <= {high}, got {x!r}")
    return x


def broadcast_vector(field: str, value: Any, length: int) -> np.ndarray:
    """Accept a scalar or a vector of ``length`` entries (a list, or a compact periodic table:
    :data:`observer.arrays.VECTOR_KEYS`); return a vector."""
    if np.ndim(value) == 0 and not isinstance(value, dict):
        return np.full(length, as_scalar(field, value))
    return as_array(field, value, (length,))


def check_symmetric(field: str, A: np.ndarray) -> None:
    """Raise unless ``A``'s entries are in range (:func:`check_entry_range`) and ``A`` is
    exactly symmetric (:data:`SYMMETRY_RTOL`); the error names the first entry (row-major)
    that differs from its transpose, both values printed exactly (``repr``)."""
    check_entry_range(field, A)
    D = (A - A.T).tocoo() if sps.is_sparse(A) else None
    if D is not None:
        D.eliminate_zeros()
        bad = sorted(zip(D.row.tolist(), D.col.tolist()))
    else:
        bad = np.argwhere(A != A.T).tolist()
    if bad:
        i, j = bad[0]
        a, b = float(A[i, j]), float(A[j, i])
        raise InputError(field, f"matrix is not symmetric: entry [{i}, {j}] = {a!r} but [{j}, {i}] = {b!r} "
                         "(exact symmetry required; (A + Aᵀ)/2 removes assembly round-off)")


BANDED_EIG_MIN_N = 64
"""From this size on, narrowly banded symmetric matrices get their extreme eigenvalues from
the banded eigensolver (O(n·bw²)) instead of a dense one (O(n³))."""


def extreme_eigenvalues(A: np.ndarray) -> tuple[float, float]:
    """Smallest and largest eigenvalue of the symmetric part of ``A``.

    Dense ``eigvalsh`` for small or wide-band matrices; for n ≥ :data:`BANDED_EIG_MIN_N` with
    bandwidth ≤ n/8 (the chain's M, C, K), ``scipy.linalg.eigvals_banded`` on the band only; a
    sparse A (a large system, :data:`observer.sparse.DENSE_MAX_N`) by Lanczos
    (:func:`observer.sparse.extreme_eigenvalues`, O(n) for a banded A).
    """
    if sps.is_sparse(A):
        return sps.extreme_eigenvalues(A)
    S = 0.5 * (A + A.T)
    n = S.shape[0]
    if n >= BANDED_EIG_MIN_N:
        i, j = np.nonzero(S)
        bw = int(np.max(np.abs(i - j))) if i.size else 0
        if bw <= n // 8:
            band = np.zeros((bw + 1, n))
            for d in range(bw + 1):
                band[d, :n - d] = np.diagonal(S, -d)
            lo = sla.eigvals_banded(band, lower=True, select="i", select_range=(0, 0))
            hi = sla.eigvals_banded(band, lower=True, select="i", select_range=(n - 1, n - 1))
            return float(lo[0]), float(hi[0])
    eig = np.linalg.eigvalsh(S)
    return float(eig[0]), float(eig[-1])


def check_spd(field: str, A: np.ndarray) -> str:
    """Raise unless ``A`` is symmetric positive definite (smallest eigenvalue > 1e-14·largest).

    A sparse narrowly banded A passes when ``A − 1e-14·γ·I`` has a banded Cholesky factor (γ its
    Gershgorin bound ≥ λ_max: then λ_min > 1e-14·λ_max), in O(n·bw²); its eigenvalues are
    computed only to word a failure."""
    check_symmetric(field, A)
    if sps.is_sparse(A) and sps.definite_by_cholesky(A, -1e-14 * sps.gershgorin_max(A)):
        return "banded Cholesky of A − 1e-14·γ·I (γ: Gershgorin bound)"
    lo, hi = extreme_eigenvalues(A)
    if lo <= 0 or lo <= 1e-14 * hi:
        raise InputError(field, f"matrix is not positive definite (smallest eigenvalue {lo:.3g})")
    return "Lanczos extreme eigenvalues" if sps.is_sparse(A) else "dense or banded eigenvalues"


def check_psd(field: str, A: np.ndarray) -> str:
    """Raise unless ``A`` is symmetric positive semi-definite (to :data:`PSD_RTOL`).

    A sparse narrowly banded A passes when ``A + PSD_RTOL·γ·I`` has a banded Cholesky factor (γ
    its Gershgorin bound, ≥ its largest eigenvalue), in O(n·bw²)."""
    check_symmetric(field, A)
    if sps.is_sparse(A) and sps.definite_by_cholesky(A, PSD_RTOL * max(sps.gershgorin_max(A), 1e-300)):
        return "banded Cholesky of A + 1e-10·γ·I (γ: Gershgorin bound)"
    lo, hi = extreme_eigenvalues(A)
    scale = max(abs(lo), abs(hi), 1.0e-300)
    if lo < -PSD_RTOL * scale:
        raise InputError(field, f"matrix is not positive semi-definite (smallest eigenvalue {lo:.3g})")
    return "Lanczos extreme eigenvalues" if sps.is_sparse(A) else "dense or banded eigenvalues"


def _bandwidth(A: np.ndarray) -> int:
    i, j = np.nonzero(A)
    return int(np.max(np.abs(i - j))) if i.size else 0


def _to_band(S: np.ndarray, bw: int) -> np.ndarray:
    band = np.zeros((bw + 1, S.shape[0]))
    for d in range(bw + 1):
        band[d, :S.shape[0] - d] = np.diagonal(S, -d)
    return band


EPS = float(np.finfo(float).eps)
W_SV_RTOL = float(np.sqrt(EPS))
"""Smallest accepted σ_min(W)/σ_max(W) (√ε ≈ 1.5e-8). The contact problems work with Delassus
matrices ``W_AᵀÂ⁻¹W_A``, which square W's conditioning: below √ε they are numerically singular
(cond ≥ 1/ε) and the complementarity residual cannot be held (measured: σ_min/σ_max = 1e-9 on
``double_mass`` with a second contact fails the reference solver's residual at step 0)."""

PROJECTION_COND_MAX = 1e-6 / float(np.finfo(float).eps)
"""Largest accepted cond(L) of the projection metric ``L = WᵀK⁻¹W`` (≈ 4.5e9): the multiplier
``Σ_I = −L_I⁻¹g_I`` of eqs. (13)-(14) is then computed with a relative error of at most
cond(L_I)·ε ≤ 1e-6 on every active set I (cond(L_I) ≤ cond(L), Cauchy interlacing)."""


def singular_value_range(W: np.ndarray) -> tuple[float, float]:
    """Smallest and largest singular value of W (n×m, m ≤ n); (0, 1) when m > n.

    Dense SVD up to m = 512; beyond, from the extreme eigenvalues of WᵀW (banded, O(m·bw²);
    sparse W: the sparse WᵀW by Lanczos, shift-invert on its banded Cholesky factor for σ_min;
    σ_min = 0 when that factorization fails, i.e. σ_min/σ_max ≲ √ε: numerically dependent).
    """
    n, m = W.shape
    if m > n:
        return 0.0, 1.0
    if sps.is_sparse(W):
        G = sp.csr_matrix(W.T @ W)
        if sps.is_narrowly_banded(G) and sps.banded_cholesky(G) is None:
            # WᵀW not positive definite to round-off: σ_min/σ_max ≲ √ε, numerically rank deficient
            return 0.0, float(np.sqrt(max(sps.largest_eigenvalue(G)[0], 0.0)))
        lo, hi = sps.extreme_eigenvalues(G)
        return float(np.sqrt(max(lo, 0.0))), float(np.sqrt(max(hi, 0.0)))
    if m <= 512:
        sv = np.linalg.svd(W, compute_uv=False)
        return float(sv[-1]), float(sv[0])
    lo, hi = extreme_eigenvalues(W.T @ W)
    return float(np.sqrt(max(lo, 0.0))), float(np.sqrt(max(hi, 0.0)))


def check_independent_columns(field: str, W: np.ndarray) -> tuple[float, float]:
    """Raise unless the columns of W are independent with σ_min/σ_max > :data:`W_SV_RTOL`.

    "Not linearly independent" when W has more columns than rows or its numerical rank is
    below m (σ_min ≤ max(n, m)·ε·σ_max, the tolerance of ``numpy.linalg.matrix_rank``: an
    exactly dependent W computes σ_min at round-off level, not 0); "nearly dependent" when
    σ_min/σ_max ≤ √ε; first, entries out of range (:func:`check_entry_range`). Returns
    (σ_min, σ_max). A sparse W: σ² from the sparse WᵀW by Lanczos (shift-invert on its banded
    Cholesky factor for σ_min; a failed factorization is a dependent W).
    """
    check_entry_range(field, W)
    sv_min, sv_max = singular_value_range(W)
    if W.shape[1] > W.shape[0] or sv_min <= max(W.shape) * EPS * sv_max:   # numerical rank < m
        raise InputError(field, f"columns are not linearly independent (smallest singular value "
                         f"{sv_min:.3g}, {W.shape[1]} columns in dimension {W.shape[0]})")
    if sv_min <= W_SV_RTOL * sv_max:
        raise InputError(field, f"columns are nearly dependent: σ_min/σ_max = {sv_min / sv_max:.3g} "
                         f"<= {W_SV_RTOL:.3g} = √ε, so the Delassus matrices WᵀÂ⁻¹W (cond "
                         f"≈ {(sv_max / sv_min) ** 2:.3g}) are numerically singular")
    return sv_min, sv_max


def projection_condition(K: np.ndarray, W: np.ndarray,
                         k_range: tuple[float, float] | None = None) -> float:
    """Condition number of ``L = WᵀK⁻¹W`` (K ≻ 0), or an upper bound of it below the threshold.

    First the bound ``cond(L) ≤ cond(K)·cond(W)²``; if it is at most
    :data:`PROJECTION_COND_MAX` it is returned, otherwise L is formed (banded Cholesky of K
    for large narrowly banded K) and its exact condition number returned.
    """
    lo_k, hi_k = k_range if k_range is not None else extreme_eigenvalues(K)
    if not lo_k > 0.0:
        return float("inf")
    sv_min, sv_max = singular_value_range(W)
    if sv_min <= 0.0:
        return float("inf")
    bound = (hi_k / lo_k) * (sv_max / sv_min) ** 2
    if bound <= PROJECTION_COND_MAX:
        return float(bound)
    n, m = W.shape
    if sps.is_sparse(K) or sps.is_sparse(W):
        return sparse_projection_condition(K, W, bound)
    try:
        bw = _bandwidth(K)
        if n >= BANDED_EIG_MIN_N and bw <= n // 8:
            KinvW = sla.cho_solve_banded((sla.cholesky_banded(_to_band(0.5 * (K + K.T), bw), lower=True),
                                          True), W)
        else:
            KinvW = sla.cho_solve(sla.cho_factor(0.5 * (K + K.T)), W)
    except np.linalg.LinAlgError:
        return float("inf")
    sparse_W = np.count_nonzero(W) <= 0.1 * W.size
    L = np.asarray(sp.csc_matrix(W).T @ KinvW) if sparse_W else W.T @ KinvW
    L = 0.5 * (L + L.T)
    if m <= EXACT_COND_MAX_M:
        lo, hi = extreme_eigenvalues(L)
        return float(hi / lo) if lo > 0.0 else float("inf")
    return cholesky_condition_estimate(L)


def sparse_projection_condition(K: Any, W: Any, bound: float) -> float:
    """cond(WᵀK⁻¹W) of a large sparse system without forming it: λ_max by Lanczos on
    ``x ↦ Wᵀ K⁻¹ (W x)`` (banded Cholesky of K), λ_min as 1/λ_max of ``L⁻¹ = W⁻¹ K W⁻ᵀ`` when W is
    square (sparse LU of W); otherwise the bound cond(K)·cond(W)² is returned (an upper bound)."""
    n, m = W.shape
    chol = sps.banded_cholesky(K) if sps.is_narrowly_banded(K) else None
    if chol is None or n != m:
        return float(bound)
    import scipy.sparse.linalg as spla
    Ws = sp.csc_matrix(W)
    lu = spla.splu(Ws)
    L_op = spla.LinearOperator((m, m), dtype=float,
                               matvec=lambda x: Ws.T @ sla.cho_solve_banded((chol, True), Ws @ x))
    Linv_op = spla.LinearOperator((m, m), dtype=float,
                                  matvec=lambda x: lu.solve(K @ lu.solve(x, trans="T")))
    hi = sps.largest_eigenvalue(L_op)[0]
    inv_hi = sps.largest_eigenvalue(Linv_op)[0]
    return float(hi * inv_hi) if inv_hi > 0.0 else float("inf")


EXACT_COND_MAX_M = 512
"""Up to this many contacts cond(L) comes from L's eigenvalues; beyond, from LAPACK's
Cholesky-based 1-norm estimate (:func:`cholesky_condition_estimate`, O(m³/3))."""


def cholesky_condition_estimate(A: np.ndarray) -> float:
    """1-norm condition number estimate of an SPD matrix (LAPACK ``potrf`` + ``pocon``);
    inf when the Cholesky factorization fails. Within a factor of the dimension of the
    2-norm condition number, which is all a threshold of :data:`PROJECTION_COND_MAX` needs."""
    c, info = sla.lapack.dpotrf(A, lower=False)
    if info != 0:
        return float("inf")
    rcond, info = sla.lapack.dpocon(c, float(np.linalg.norm(A, 1)))
    return float(1.0 / rcond) if info == 0 and rcond > 0.0 else float("inf")


H_MIN = float(np.sqrt(np.finfo(float).tiny))
"""Smallest accepted step size (≈ 1.49e-154): below, h² is subnormal or 0, so the iteration
matrix ``M + hθC + h²θ²K`` drops K and a least-squares fit over t (the decay rate) divides by
an underflowed ‖t‖ (h = 1e-200 failed inside NumPy's SVD, 1e-310 at an integer conversion)."""


def check_step_parameters(h: Any, theta: Any) -> tuple[float, float]:
    """Validate the step size h ≥ :data:`H_MIN` and the Moreau–Jean θ ∈ [½, 1]; return them as floats.

    Raises
    ------
    InputError
        Naming ``simulation.h`` or ``simulation.theta``.
    """
    h = as_scalar("simulation.h", h, positive=True)
    if h < H_MIN:
        raise InputError("simulation.h", f"h = {h!r} is below {H_MIN:.3g} = √(smallest normal float): "
                         "h² underflows (the step matrix M + hθC + h²θ²K loses K, and the run's "
                         "time fits square t)")
    theta = as_scalar("simulation.theta", theta, low=0.5, high=1.0)
    return h, theta


MAX_STEPS = 2 ** 53
"""Largest number of steps of a run: the grid t_k = t0 + k·h evaluates k as a float, and
beyond 2^53 consecutive k are no longer distinct (nor could any array hold the run)."""


def check_step_count(h: float, t_end: float, t0: float = 0.0) -> float:
    """Raise unless ``(t_end − t0)/h`` steps fit in :data:`MAX_STEPS`; return that count.

    Raises
    ------
    InputError
        Naming ``simulation.h`` (the message gives h, t_end and the step count).
    """
    steps = (t_end - t0) / h
    if not steps <= MAX_STEPS:
        raise InputError("simulation.h", f"h = {h!r} up to t_end = {t_end!r} gives {steps:.3g} steps, "
                         f"more than the 2^53 ≈ {float(MAX_STEPS):.3g} a grid can count")
    return steps




def check_output_path(field: str, path: Any, suffixes: tuple[str, ...]) -> Path:
    """Validate an output file path before any work is done; return it as a :class:`Path`.

    The suffix must be one of ``suffixes`` (case-insensitive), the path must not be an
    existing directory, and its nearest existing ancestor must be a writable directory
    (missing parent directories are created by the writers).
    """
    if not isinstance(path, (str, Path)) or not str(path).strip():
        raise InputError(field, f"expected a file path, got {path!r}")
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise InputError(field, f"unsupported file type {p.suffix or '(none)'!r} of {str(p)!r}; "
                         f"use one of {', '.join(suffixes)}")
    if p.is_dir():
        raise InputError(field, f"{str(p)!r} is a directory")
    parent = p.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise InputError(field, f"cannot create {str(p)!r}: {str(parent)!r} is not a directory")
    if parent == p.parent:
        _probe_writable(field, p)
    elif not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(field, f"cannot write {str(p)!r}: directory {str(parent)!r} is not writable")
    return p


def _probe_writable(field: str, p: Path) -> None:
    """Open ``p`` for appending (removing it again if it did not exist): the one test of
    writability that also holds for root and for read-only or virtual file systems."""
    existed = p.exists()
    try:
        with p.open("ab"):
            pass
    except OSError as exc:
        raise InputError(field, f"cannot write {str(p)!r}: {exc.strerror or exc}") from None
    if not existed:
        p.unlink()
