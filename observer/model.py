"""Linear time-invariant multibody model with unilateral constraints.

The model is the paper's system (1)-(3)::

    M du = (-C u - K q + f(t)) dt + W dΛ,      g = Wᵀ q + ν(t) ≥ 0,      γ = Wᵀ u + ν̇(t)

A :class:`LinearSystem` holds data only (no state); it validates everything on
construction and raises :class:`~observer.errors.InputError` naming the field.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from observer import sparse as sps
from observer.errors import InputError
from observer.validation import (PROJECTION_COND_MAX, as_array, as_matrix, as_scalar, broadcast_vector,
                                 check_independent_columns, check_psd, check_spd, check_symmetric,
                                 extreme_eigenvalues, projection_condition)


TRIG = {"cos": np.cos, "sin": np.sin, "-sin": lambda x: -np.sin(x)}
"""The functions of :class:`Harmonic`'s terms and their derivatives, by name."""

GRID_BLOCK = 128
"""Grid points per anchor of :func:`grid_wave` (a power of two, so that the compiled loop's
windows, :data:`observer.engines.compiled.driver.WINDOW`, hold whole blocks)."""


def grid_anchors(t0: float, h: float, k0: int, k1: int, omega: float,
                 phase: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The anchors of :func:`grid_wave` for the grid points k0..k1: ``cos A_a``, ``sin A_a`` of
    the blocks a = k0 // B .. k1 // B and ``cos β_j``, ``sin β_j``, j = 0..B − 1 (B =
    :data:`GRID_BLOCK`; also combined in compiled code, :func:`observer.engines.compiled.kernel.fill_waves`)."""
    B = GRID_BLOCK
    a0, a1 = k0 // B, k1 // B
    ta = np.multiply(np.arange(a0 * B, a1 * B + 1, B), h, dtype=float)    # the anchors' t_k
    ta += t0
    A = omega * ta + phase
    beta = omega * np.multiply(np.arange(B), h, dtype=float)
    return np.cos(A), np.sin(A), np.cos(beta), np.sin(beta)


def grid_wave(t0: float, h: float, k0: int, k1: int, omega: float, phase: float, function: str) -> np.ndarray:
    """``function(ω t_k + phase)`` at the grid points ``t_k = t0 + k·h``, k = k0..k1, by angle
    addition from anchors: two trigonometric calls per :data:`GRID_BLOCK` points instead of one
    per point.

    Point k = aB + j (B = GRID_BLOCK, 0 ≤ j < B) is its block's anchor advanced by β_j:
    ``cos(A_a + β_j) = cos A_a cos β_j − sin A_a sin β_j`` and
    ``sin(A_a + β_j) = sin A_a cos β_j + cos A_a sin β_j``, with ``A_a = ω t_{aB} + phase`` (the
    grid time t_{aB} = t0 + aB·h, then ω t + phase, rounded as the direct evaluation
    ``function(ω t_k + phase)`` rounds them) and ``β_j = ω·(j·h)``. The anchors sit at absolute
    grid indices, so any window of the grid has bitwise its part of the whole grid's values,
    and an anchor's value is the direct evaluation's bit for bit (cos 0 = 1, sin 0 = 0).

    Accuracy (as the direct evaluation): both round the angle, ≈ (|ω t_k| + |phase|)·ε, and the
    angle addition adds a few ε (``t_{aB} + j·h`` is t_k up to the rounding of the grid times):
    |value − function(ω t_k + phase)| ≤ 4(|ω|·max(|t_k|, |t_{aB}|) + |phase| + 1)·ε, where the
    exact value uses the float grid time t_k (tests/observer/test_model_signals.py checks this bound against
    extended precision, and that the two evaluations agree to it). ``function`` is ``"cos"``,
    ``"sin"`` or ``"-sin"``.
    """
    a0 = k0 // GRID_BLOCK
    ca, sa, cb, sb = grid_anchors(t0, h, k0, k1, omega, phase)
    if function == "cos":
        v = np.multiply.outer(ca, cb)
        v -= np.multiply.outer(sa, sb)
    else:
        v = np.multiply.outer(sa, cb)
        v += np.multiply.outer(ca, sb)
        if function == "-sin":
            np.negative(v, out=v)
    return v.ravel()[k0 - a0 * GRID_BLOCK:k1 - a0 * GRID_BLOCK + 1]


@dataclass(frozen=True)
class Harmonic:
    """A vector signal ``x(t) = constant + Σ_j amplitude_j ∘ trig(omega_j t + phase_j)``.

    ``trig`` is ``cos`` for forcing and ``sin`` for the gap offset ν(t) (the TOML
    convention of the scenario format). Arrays: ``constant`` shape (d,),
    ``amplitude`` and ``phase`` shape (T, d), ``omega`` shape (T,), for T terms.
    """

    constant: np.ndarray
    amplitude: np.ndarray
    omega: np.ndarray
    phase: np.ndarray
    kind: str = "cos"

    @staticmethod
    def build(field_name: str, dim: int, *, constant: Any = 0.0, terms: list[dict] | None = None,
              kind: str = "cos", constant_name: str = "constant",
              term_names: list[str] | None = None) -> "Harmonic":
        """Validate and build from a constant and a list of ``{amplitude, omega, phase}`` terms.

        ``amplitude`` and ``phase`` may be scalars (broadcast) or ``dim``-vectors. Error
        messages name ``field_name.constant_name`` and ``term_names[j]`` (default
        ``field_name.harmonics[j]``).
        """
        c = broadcast_vector(f"{field_name}.{constant_name}", constant, dim)
        amps, omegas, phases = [], [], []
        for j, term in enumerate(terms or []):
            where = term_names[j] if term_names else f"{field_name}.harmonics[{j}]"
            amps.append(broadcast_vector(f"{where}.amplitude", term.get("amplitude", 0.0), dim))
            omegas.append(as_scalar(f"{where}.omega", term.get("omega", 0.0), low=0.0))
            phases.append(broadcast_vector(f"{where}.phase", term.get("phase", 0.0), dim))
        return Harmonic(c, np.array(amps, dtype=float).reshape(-1, dim), np.array(omegas, dtype=float),
                        np.array(phases, dtype=float).reshape(-1, dim), kind)

    @property
    def dim(self) -> int:
        return self.constant.shape[0]

    def __call__(self, t: Any) -> np.ndarray:
        """Evaluate at scalar ``t`` (shape (d,)) or a time array (shape (len(t), d)).

        Each term evaluates its trigonometric function once per distinct phase among its
        nonzero columns (a zero column adds ±0 and is skipped) and adds ``a_j·trig(ω t + p_j)``
        to each such column: every entry is ``c_j + Σ_terms a_j·trig(ω t + p_j)``, summed in
        the order of the terms. (The rocking chain's ground motion has one phase and 2
        nonzero columns out of 2N.)
        """
        return self._evaluate(t, derivative=False)

    def derivative(self, t: Any) -> np.ndarray:
        """Exact time derivative ``Σ_terms a_j·ω·trig'(ω t + p_j)``, same shapes (and the same
        per-phase evaluation) as :meth:`__call__`."""
        return self._evaluate(t, derivative=True)

    def _groups(self, derivative: bool):
        """Per term, per distinct phase among its nonzero columns: ``(ω, phase, function,
        columns, coefficients of those columns)``, in summation order (a zero column adds ±0
        and is skipped). ``function`` is ``"cos"``, ``"sin"`` or ``"-sin"``."""
        if derivative:
            func = "-sin" if self.kind == "cos" else "cos"
        else:
            func = self.kind
        for a, w, p in zip(self.amplitude, self.omega, self.phase):
            cols = np.flatnonzero(a)
            coef = a * w if derivative else a
            for ph in np.unique(p[cols]):
                same = cols[p[cols] == ph]
                yield w, ph, func, same, coef[same]

    def entries(self, derivative: bool = False) -> list[tuple[int, float, float, float, str]]:
        """The evaluation of :meth:`__call__` (or :meth:`derivative`) as a list of
        ``(column, coefficient, ω, phase, function)`` in summation order, ``function`` one of
        ``"cos"``, ``"sin"``, ``"-sin"``: the value is the constant (zero for the derivative)
        plus, entry by entry, ``coefficient·function(ω t + phase)`` added to its column (the
        compiled kernel evaluates the signals from these, :func:`observer.engines.compiled.bundles.signal_tables`)."""
        return [(int(j), float(c), float(w), float(ph), func)
                for w, ph, func, cols, coefs in self._groups(derivative) for j, c in zip(cols, coefs)]

    def on_grid(self, t0: float, h: float, k0: int, k1: int, derivative: bool = False) -> np.ndarray:
        """:meth:`__call__` (or :meth:`derivative`) at the grid points ``t_k = t0 + k·h``,
        k = k0..k1 (shape (k1 − k0 + 1, d)): the same sum in the same order, each wave from
        :func:`grid_wave` (anchored angle addition) instead of one trigonometric call per point.
        The time-stepping engines evaluate the signals so (:class:`observer.stepping.Grid`,
        :func:`observer.engines.compiled.bundles.wave_table`)."""
        return self._evaluate(np.empty(k1 - k0 + 1), derivative, (t0, h, k0, k1))

    def _evaluate(self, t: Any, derivative: bool, grid: tuple | None = None) -> np.ndarray:
        t_arr = np.asarray(t, dtype=float)
        out = np.empty(t_arr.shape + (self.dim,))
        out[...] = 0.0 if derivative else self.constant
        for w, ph, func, cols, coefs in self._groups(derivative):
            v = TRIG[func](w * t_arr + ph) if grid is None else grid_wave(*grid, w, ph, func)
            if cols.size == self.dim:
                out += coefs * v[..., None]
            else:
                for j, c in zip(cols, coefs):
                    out[..., j] += c * v
        return out

    def bound(self) -> np.ndarray:
        """Componentwise sup ``|x(t)|`` over all t (exact upper bound: ``|c| + Σ|a|``)."""
        return np.abs(self.constant) + np.abs(self.amplitude).sum(axis=0)

    def terms(self) -> list[dict]:
        """The harmonic terms as plain dicts (for TOML output)."""
        return [{"amplitude": a.tolist(), "omega": float(w), "phase": p.tolist()}
                for a, w, p in zip(self.amplitude, self.omega, self.phase)]


def harmonic_table(field_name: str, d: dict, n: int, kind: str, const_key: str) -> Harmonic:
    """The :class:`Harmonic` of a document's signal table ``d`` (``[system.forcing]`` or
    ``[system.gap]``: the table's own term, then its ``harmonics``); errors name ``field_name.*``."""
    terms, names = [], []
    if any(k in d for k in ("amplitude", "omega", "phase")):
        terms.append({k: d[k] for k in ("amplitude", "omega", "phase") if k in d})
        names.append(field_name)
    for j, term in enumerate(d.get("harmonics", [])):
        terms.append(term)
        names.append(f"{field_name}.harmonics[{j}]")
    return Harmonic.build(field_name, n, constant=d.get(const_key, 0.0), terms=terms, kind=kind,
                          constant_name=const_key, term_names=names)


@dataclass(frozen=True)
class LinearSystem:
    """An n-DOF LTI mechanical system with m unilateral contacts (paper eqs. (1)-(3)).

    Parameters
    ----------
    M, C, K : ndarray or scipy.sparse matrix, shape (n, n)
        Mass (SPD), damping and stiffness (symmetric PSD) matrices.
    W : ndarray or scipy.sparse matrix, shape (n, m)
        Generalized force directions w_j as columns, linearly independent.
        Sparse matrices stay sparse (CSR) when n > :data:`observer.sparse.DENSE_MAX_N` and
        are densified otherwise; dense ones stay dense. :attr:`sparse` says which.
    forcing : Harmonic
        f(t) = constant + Σ amplitude·cos(omega t + phase), dimension n.
    gap : Harmonic
        ν(t) = offset + Σ amplitude·sin(omega t + phase), dimension m.
    check : bool
        Validate the matrices (default). ``False`` is meant only for deliberately
        invalid systems built by the proof checks' known-bad cases.
    """

    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    W: np.ndarray
    forcing: Harmonic
    gap: Harmonic
    check: bool = field(default=True, repr=False, compare=False)

    def __post_init__(self) -> None:
        M = as_matrix("system.M", self.M, (None, None))
        n = M.shape[0]
        if M.shape != (n, n):
            raise InputError("system.M", f"must be square, got shape {M.shape[0]}x{M.shape[1]}")
        if n == 0:
            raise InputError("system.M", "must have at least one degree of freedom")
        C = as_matrix("system.C", self.C, (n, n))
        K = as_matrix("system.K", self.K, (n, n))
        W = as_matrix("system.W", self.W, (n, None))
        if n <= sps.DENSE_MAX_N:          # small: the dense code paths (sparse input densified)
            M, C, K, W = (A.toarray() if sps.is_sparse(A) else A for A in (M, C, K, W))
        m = W.shape[1]
        if m == 0:
            raise InputError("system.W", "needs at least one contact column")
        if self.forcing.dim != n:
            raise InputError("system.forcing", f"has dimension {self.forcing.dim}, expected n = {n}")
        if self.gap.dim != m:
            raise InputError("system.gap", f"has dimension {self.gap.dim}, expected m = {m}")
        if self.check:
            how = {"check_M": check_spd("system.M", M)}
            check_symmetric("system.C", C)
            how["check_C"] = check_psd("system.C", C)
            how["check_K"] = check_psd("system.K", K)
            check_independent_columns("system.W", W)
            how["check_W"] = ("σ of W from Lanczos on the sparse WᵀW" if sps.is_sparse(W)
                              else "dense SVD or banded eigenvalues of WᵀW")
            object.__setattr__(self, "check_methods", how)
        for name, arr in (("M", M), ("C", C), ("K", K), ("W", W)):
            if not sps.is_sparse(arr):
                arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def sparse(self) -> bool:
        """True when the matrices are held sparse (a large sparse system)."""
        return any(sps.is_sparse(A) for A in (self.M, self.C, self.K, self.W))

    # -- sizes -----------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of degrees of freedom."""
        return self.M.shape[0]

    @property
    def m(self) -> int:
        """Number of unilateral contacts."""
        return self.W.shape[1]

    # -- signals ---------------------------------------------------------------------------
    def f(self, t: Any) -> np.ndarray:
        """External force f(t), shape (n,) or (len(t), n)."""
        return self.forcing(t)

    def nu(self, t: Any) -> np.ndarray:
        """Gap offset ν(t), shape (m,) or (len(t), m)."""
        return self.gap(t)

    def nu_dot(self, t: Any) -> np.ndarray:
        """Exact derivative ν̇(t)."""
        return self.gap.derivative(t)

    def gaps(self, q: np.ndarray, t: Any) -> np.ndarray:
        """Gaps g = Wᵀq + ν(t) (paper eq. (2)); ``q`` shape (n,) or time-major (N, n)."""
        return q @ self.W + self.nu(t)

    def contact_velocities(self, u: np.ndarray, t: Any) -> np.ndarray:
        """Contact velocities γ = Wᵀu + ν̇(t) (paper eq. (3))."""
        return u @ self.W + self.nu_dot(t)

    # -- derived matrices ------------------------------------------------------------------
    def stiffness_eigenvalue_range(self) -> tuple[float, float]:
        """Smallest and largest eigenvalue of K (computed once)."""
        cached = self.__dict__.get("_K_eig")
        if cached is None:
            cached = extreme_eigenvalues(self.K)
            object.__setattr__(self, "_K_eig", cached)
        return cached

    def is_stiffness_definite(self) -> bool:
        """True if K is positive definite (needed for K-metric projections; computed once).

        A sparse, exactly symmetric, narrowly banded K (n > :data:`observer.sparse.DENSE_MAX_N`):
        *proved* positive definite in floating point by a banded Cholesky factorization of
        ``K − c·I`` (:func:`observer.sparse.verified_definite`, Rump 2006: c ≈ (2w+1)(w+2)·u·max
        K_ii for bandwidth w), in O(n·w²); no threshold on the condition number, so the default
        rocking chain of 10⁵ blocks (cond(K) ≈ 2.5e12) passes. Otherwise (dense K, as always):
        its smallest eigenvalue exceeds 1e-12 of its largest. :meth:`stiffness_definiteness`
        says which.
        """
        return self.stiffness_definiteness()[0]

    def stiffness_definiteness(self) -> tuple[bool, str]:
        """``(definite, how)`` of :meth:`is_stiffness_definite` (``how`` goes to the health
        record, ``computed_by["K_definite"]``)."""
        cached = self.__dict__.get("_K_definite")
        if cached is None:
            cached = sps.verified_definite(self.K) if sps.is_sparse(self.K) else None
            if cached is None:
                lo, hi = self.stiffness_eigenvalue_range()
                cached = (bool(lo > 0.0 and lo > 1e-12 * hi),
                          f"eigenvalues: λ_min = {lo:.3g} > 1e-12·λ_max = {1e-12 * hi:.3g} required")
            object.__setattr__(self, "_K_definite", cached)
        return cached

    def require_definite_stiffness(self, why: str) -> None:
        """Raise :class:`InputError` unless the K-metric projection is computable.

        Needs K ≻ 0 (else the error names ``system.K``) and a projection metric
        ``L = WᵀK⁻¹W`` whose condition number is at most :data:`PROJECTION_COND_MAX` (else
        it names ``system.W``): every active set's ``L_I`` is a principal submatrix of L,
        so ``cond(L_I) ≤ cond(L)`` (Cauchy interlacing) and the check covers every closed
        set χ can present to the projection of eqs. (13)-(14).
        """
        definite, how = self.stiffness_definiteness()
        if not definite:
            raise InputError("system.K", f"must be positive definite for {why} "
                             f"(smallest eigenvalue {self.stiffness_eigenvalue_range()[0]:.3g}; {how})")
        cond = self.projection_condition()
        if not cond <= PROJECTION_COND_MAX:
            raise InputError("system.W", f"columns are nearly dependent in the K metric, as {why} "
                             f"needs them independent: cond(WᵀK⁻¹W) = {cond:.3g} > "
                             f"{PROJECTION_COND_MAX:.3g} (the projection multiplier "
                             "Σ_I = −L_I⁻¹g_I of eqs. (13)-(14) would keep fewer than 6 digits)")

    def projection_condition(self) -> float:
        """Condition number of the projection metric ``L = WᵀK⁻¹W``, or an upper bound of it
        that is already within :data:`PROJECTION_COND_MAX` (needs K ≻ 0; cached).

        Cheap first: ``cond(L) ≤ cond(K)·cond(W)²``; only when that bound exceeds the
        threshold is L formed and its exact condition number computed
        (:func:`observer.validation.projection_condition`).
        """
        cached = self.__dict__.get("_L_cond")
        if cached is None:
            cached = projection_condition(self.K, self.W, self.stiffness_eigenvalue_range())
            object.__setattr__(self, "_L_cond", cached)
        return cached

    def energy(self, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Mechanical energy ½uᵀMu + ½qᵀKq (kinetic plus elastic), time-major input allowed."""
        if self.sparse:
            U, Q = np.atleast_2d(u), np.atleast_2d(q)
            E = 0.5 * sps.quadratic_rows(U, self.M) + 0.5 * sps.quadratic_rows(Q, self.K)
            return E if np.ndim(u) > 1 else E[0]
        return 0.5 * np.einsum("...i,ij,...j->...", u, self.M, u) + 0.5 * np.einsum(
            "...i,ij,...j->...", q, self.K, q)
