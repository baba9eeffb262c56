"""Small validators that turn raw user data into float arrays or raise :class:`InputError`."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.linalg as sla

from observer.errors import InputError

SYMMETRY_RTOL = 1e-10
"""Relative tolerance on ``max|A - A^T|`` (scaled by ``max|A|``) for symmetric matrices."""

PSD_RTOL = 1e-10
"""Smallest eigenvalue allowed for a PSD matrix, relative to its largest absolute eigenvalue."""


def as_array(field: str, value: Any, shape: tuple[int | None, ...]) -> np.ndarray:
    """Convert ``value`` to a finite float64 array of the given shape (``None`` = any length)."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(field, f"not a numeric array ({exc})") from None
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "x".join("*" if s is None else str(s) for s in shape) or "scalar"
        got = "x".join(str(a) for a in arr.shape) or "scalar"
        raise InputError(field, f"wrong shape: expected {want}, got {got}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(field, f"contains NaN or infinity (first at index {tuple(int(i) for i in bad)})")
    return arr


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
    """Accept a scalar or a vector of ``length`` entries; return a vector."""
    if np.ndim(value) == 0:
        return np.full(length, as_scalar(field, value))
    return as_array(field, value, (length,))


def check_symmetric(field: str, A: np.ndarray) -> None:
    """Raise unless ``A`` is symmetric to :data:`SYMMETRY_RTOL`."""
    scale = max(float(np.max(np.abs(A))), np.finfo(float).tiny)
    asym = float(np.max(np.abs(A - A.T)))
    if asym > SYMMETRY_RTOL * scale:
        raise InputError(field, f"matrix is not symmetric (max |A - A^T| = {asym:.3g})")


BANDED_EIG_MIN_N = 64
"""From this size on, narrowly banded symmetric matrices get their extreme eigenvalues from
the banded eigensolver (O(n·bw²)) instead of a dense one (O(n³))."""


def extreme_eigenvalues(A: np.ndarray) -> tuple[float, float]:
    """Smallest and largest eigenvalue of the symmetric part of ``A``.

    Dense ``eigvalsh`` for small or wide-band matrices; for n ≥ :data:`BANDED_EIG_MIN_N` with
    bandwidth ≤ n/8 (the chain's M, C, K), ``scipy.linalg.eigvals_banded`` on the band only.
    """
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


def check_spd(field: str, A: np.ndarray) -> None:
    """Raise unless ``A`` is symmetric positive definite (smallest eigenvalue > 1e-14·largest)."""
    check_symmetric(field, A)
    lo, hi = extreme_eigenvalues(A)
    if lo <= 0 or lo <= 1e-14 * hi:
        raise InputError(field, f"matrix is not positive definite (smallest eigenvalue {lo:.3g})")


def check_psd(field: str, A: np.ndarray) -> None:
    """Raise unless ``A`` is symmetric positive semi-definite (to :data:`PSD_RTOL`)."""
    check_symmetric(field, A)
    lo, hi = extreme_eigenvalues(A)
    scale = max(abs(lo), abs(hi), 1.0e-300)
    if lo < -PSD_RTOL * scale:
        raise InputError(field, f"matrix is not positive semi-definite (smallest eigenvalue {lo:.3g})")
