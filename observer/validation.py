"""Small validators that turn raw user data into float arrays or raise :class:`InputError`."""

from __future__ import annotations

from typing import Any

import numpy as np

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


def check_spd(field: str, A: np.ndarray) -> None:
    """Raise unless ``A`` is symmetric positive definite (Cholesky succeeds, cond < 1e14)."""
    check_symmetric(field, A)
    eig = np.linalg.eigvalsh(0.5 * (A + A.T))
    if eig[0] <= 0 or eig[0] <= 1e-14 * eig[-1]:
        raise InputError(field, f"matrix is not positive definite (smallest eigenvalue {eig[0]:.3g})")


def check_psd(field: str, A: np.ndarray) -> None:
    """Raise unless ``A`` is symmetric positive semi-definite (to :data:`PSD_RTOL`)."""
    check_symmetric(field, A)
    eig = np.linalg.eigvalsh(0.5 * (A + A.T))
    scale = max(float(np.max(np.abs(eig))), 1.0e-300)
    if eig[0] < -PSD_RTOL * scale:
        raise InputError(field, f"matrix is not positive semi-definite (smallest eigenvalue {eig[0]:.3g})")
