"""Compiled kernels of the exact event integrator's hot path (numba).

The event loop (:mod:`observer.event.master`, :mod:`observer.event.roots`) advances the exact
flow ``z(a + s) = exp(As) z(a)`` (:class:`observer.event.flow.Flow`) by a new step length s at
almost every safe step of the root isolation, so the matrix exponential of a small matrix
(the toolkit's N ≤ 2n + 2F + 1) is computed afresh each time: in numpy each of its fifteen
small products and its solve pays a Python call. The functions here are the same
arithmetic compiled, operation for operation:

* :func:`expm_pade13` — scaling and squaring with the [13/13] Padé approximant (Higham 2005),
  the same expression tree, products and solve as the numpy version it replaces (numba's
  ``@`` and ``np.linalg.solve`` call the same BLAS/LAPACK routines, ``dgemm`` and ``dgesv``);
* :func:`blocked_expm` — ``exp(A dt) = T exp(B dt) T⁻¹`` exponentiated per block of the
  sparsity of A (:attr:`observer.event.flow.Flow.blocks`), B = T⁻¹AT balanced;
* :func:`norm_upper` — the proved upper bound of ``‖v‖₂`` of
  :func:`observer.event.flow.norm_upper`, with CPython's correctly rounded ``math.fsum``
  (Shewchuk's exact partial sums, the same final rounding): a correctly rounded sum has one
  value, so the bound is the same float;
* :func:`screen_step` — the elementwise work of one safe step of the root isolation
  (:func:`observer.event.roots.first_zero`): finiteness, certified errors, the
  third-derivative bounds and the quick test of ``_safe_step``, the numpy expressions'
  operations in their order (no contraction into fused multiply-adds), so the same floats
  and the same decisions;
* :func:`carry_step` — one window step of the search's carried rounding
  (:class:`observer.event.roots.SearchCarry`): the a-priori bounds of the step's
  matrix-vector product, componentwise and in the energy norm, in one call (bounds whose
  factors dominate their own rounding in any summation order, so its loops need not be
  BLAS's; checked against an exact rational chain in
  ``tests/observer/event/test_search_carry.py``).

The results are the numpy versions' to the bit where the BLAS/LAPACK kernels agree (checked
in ``tests/observer/event/test_kernels.py``; :func:`carry_step`'s bounds are proved, not
bitwise); no decision of the event engine is made here
(:func:`screen_step` computes the quick test's outcome, ``_safe_step`` acts on it). The
matrix-vector products of the search stay in numpy (BLAS): a compiled loop sums them in
another order.
Compiled with ``cache=True`` (numba's on-disk cache, :mod:`observer.numba_cache`): the first
call of a process compiles or loads them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from observer.numba_cache import install as _install_cache_guard

_install_cache_guard()

JIT = {"cache": True, "error_model": "numpy", "nogil": True}
"""numba options of every kernel (as :data:`observer.primitives.JIT`)."""

PADE13 = np.array([64764752532480000., 32382376266240000., 7771770303897600., 1187353796428800.,
                   129060195264000., 10559470521600., 670442572800., 33522128640., 1323241920.,
                   40840800., 960960., 16380., 182., 1.])
"""Coefficients b_0 … b_13 of the [13/13] Padé approximant of exp (Higham 2005, Table 10.4)."""

THETA13 = 5.371920351148152
"""θ_13: the 1-norm up to which the [13/13] approximant is used unscaled (Higham 2005)."""


@njit(**JIT)
def expm_pade13(A: np.ndarray) -> np.ndarray:
    """Matrix exponential of the square matrix A by scaling and squaring with the [13/13]
    Padé approximant (Higham 2005): ``2^-s A`` with ``‖2^-s A‖₁ ≤ θ_13``,
    ``r_13 = (V − U)⁻¹(V + U)`` and s squarings; the evaluation of
    :func:`observer.event.flow.expm_pade13`, term by term."""
    N = A.shape[0]
    nrm = 0.0
    for j in range(N):
        col = 0.0
        for i in range(N):
            col += abs(A[i, j])
        nrm = max(nrm, col)
    s = 0 if nrm <= THETA13 else int(np.ceil(np.log2(nrm / THETA13)))
    A = np.ascontiguousarray(A) / (2.0 ** s)
    b = PADE13
    ident = np.eye(N)
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4 + b[3] * A2
             + b[1] * ident)
    V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * ident
    E = np.ascontiguousarray(np.linalg.solve(V - U, V + U))    # numba's solve: Fortran order
    for _ in range(s):
        E = E @ E
    return E


@njit(**JIT)
def blocked_expm(balanced: np.ndarray, scale: np.ndarray, order: np.ndarray, starts: np.ndarray,
                 dt: float) -> np.ndarray:
    """``exp(A dt) = T exp(B dt) T⁻¹`` (B = ``balanced`` = T⁻¹AT, T = diag(``scale``)), with
    ``exp(B dt)`` block diagonal over the index sets ``order[starts[k]:starts[k + 1]]`` (the
    connected components of the sparsity of A): each block exponentiated alone
    (:func:`expm_pade13`), the entries outside the blocks exactly zero."""
    N = balanced.shape[0]
    out = np.zeros((N, N))
    for k in range(starts.size - 1):
        idx = order[starts[k]:starts[k + 1]]
        nb = idx.size
        sub = np.empty((nb, nb))
        for p in range(nb):
            for q in range(nb):
                sub[p, q] = balanced[idx[p], idx[q]] * dt
        E = expm_pade13(sub)
        for p in range(nb):
            for q in range(nb):
                out[idx[p], idx[q]] = E[p, q]
    for i in range(N):
        for j in range(N):
            out[i, j] *= scale[i] / scale[j]
    return out


@njit(**JIT)
def exact_sum(x: np.ndarray) -> float:
    """The correctly rounded sum of the finite floats x: CPython's ``math.fsum`` (Shewchuk's
    non-overlapping partial sums, then the round-half-even correction of its final step)."""
    partials = np.empty(x.size + 1)
    n = 0
    for k in range(x.size):
        v = x[k]
        i = 0
        for j in range(n):
            y = partials[j]
            if abs(v) < abs(y):
                v, y = y, v
            hi = v + y
            lo = y - (hi - v)
            if lo != 0.0:
                partials[i] = lo
                i += 1
            v = hi
        partials[i] = v
        n = i + 1
    if n == 0:
        return 0.0
    n -= 1
    hi = partials[n]
    lo = 0.0
    while n > 0:
        v = hi
        n -= 1
        y = partials[n]
        hi = v + y
        yr = hi - v
        lo = y - yr
        if lo != 0.0:
            break
    if n > 0 and ((lo < 0.0 and partials[n - 1] < 0.0) or (lo > 0.0 and partials[n - 1] > 0.0)):
        y = lo * 2.0
        v = hi + y
        yr = v - hi
        if y == yr:
            hi = v
    return hi


_U = np.finfo(np.float64).eps / 2.0


@njit(**JIT)
def norm_upper(v: np.ndarray) -> float:
    """A proved upper bound of ‖v‖₂ (v a 1-D float array): the bound, and the float, of
    :func:`observer.event.flow.norm_upper` (scaling by 2^-e, squares, correctly rounded sum
    :func:`exact_sum` plus ``size·2^-1074``, two ulps up; sqrt raised by 4u, two ulps up)."""
    big = 0.0
    for k in range(v.size):
        a = v[k]
        if not math.isfinite(a):
            return np.inf
        big = max(big, abs(a))
    if big == 0.0:
        return 0.0
    e = math.frexp(big)[1]
    w = np.empty(v.size)
    for k in range(v.size):
        c = math.ldexp(v[k], -e)
        w[k] = c * c
    s = exact_sum(w) + v.size * 5e-324
    s = np.nextafter(np.nextafter(s, np.inf), np.inf)
    r = math.sqrt(s) * (1.0 + 4.0 * _U)
    r = np.nextafter(np.nextafter(r, np.inf), np.inf)
    return math.ldexp(r, e)


@njit(**JIT)
def screen_step(d: np.ndarray, both: np.ndarray, za: np.ndarray, scale: np.ndarray,
                support: np.ndarray, inflate: float, third_norm: np.ndarray, growth: float,
                w: float, w3: float):
    """The elementwise work of one safe step of :func:`observer.event.roots.first_zero` on
    the functionals' derivatives ``d`` (shape (4, p), ``ψ^{(k)}(a)``) and stacked sums
    ``both`` (shape (6, p), :meth:`observer.event.roots.FunctionalSet.sums` before its
    inflation) at the state ``za``, in one call: the same IEEE operations in the same order
    as the numpy expressions they replace (``w3 = w ** 3``, Python's pow), so the same floats.

    Returns ``(finite, errs, bound, bound_finite, quick)``: whether ``za`` and ``d`` are
    finite; the certified errors ``inflate · both[3:]``; the third-derivative bounds
    ``B_i = up(‖r_3 T‖_i · (growth · ‖(T⁻¹z)_S‖) · (1 + 4u))`` (the state norm
    :func:`norm_upper` of ``za[S]/scale[S]``, S = ``support``); whether they are all finite;
    and the quick test of :func:`observer.event.roots._safe_step` (the cubic lower bound
    positive over the whole window ``w``)."""
    finite = True
    for j in range(za.size):
        if not math.isfinite(za[j]):
            finite = False
    p = d.shape[1]
    for k in range(d.shape[0]):
        for i in range(p):
            if not math.isfinite(d[k, i]):
                finite = False
    errs = np.empty((3, p))
    for k in range(3):
        for i in range(p):
            errs[k, i] = inflate * both[3 + k, i]
    zs = np.empty(support.size)
    for j in range(support.size):
        zs[j] = za[support[j]] / scale[support[j]]
    grown = growth * norm_upper(zs)
    bound = np.empty(p)
    quick = np.empty(p, dtype=np.bool_)
    bound_finite = True
    for i in range(p):
        b = np.nextafter(third_norm[i] * grown * (1.0 + 4.0 * _U), np.inf)
        bound[i] = b
        if not math.isfinite(b):
            bound_finite = False
        l0, l1, l2 = d[0, i] - errs[0, i], d[1, i] - errs[1, i], d[2, i] - errs[2, i]
        m1 = l1 if l1 < 0.0 or math.isnan(l1) else 0.0    # np.minimum(l1, 0.0): its 0.0 on ties
        m2 = l2 if l2 < 0.0 or math.isnan(l2) else 0.0
        quick[i] = l0 > 0.0 and l0 + m1 * w + m2 * w * w / 2 - b * w3 / 6 > 0.0
    return finite, errs, bound, bound_finite, quick


@njit(**JIT)
def carry_step(E: np.ndarray, za: np.ndarray, z: np.ndarray, err: np.ndarray, eps: float,
               g: float, k: int, lo: int, hi: int, wfreq: np.ndarray, a: float,
               absP: np.ndarray, gp: float, rate: float, step: float, energy: bool,
               reset: bool):
    """One step of the search's carried rounding (:class:`observer.event.roots.SearchCarry`)
    in one call: the flight ``z = fl(E za)`` of a step, E = ``exp(A step)`` as computed.

    Componentwise (Higham §3.5, a matrix-vector product of N terms): ``new = γ·|E|·|za|``
    and ``err ← |E|·err·(1 + 2γ) + new``, new raised by ``1 + 2γ`` (γ = γ_{N+1}: the
    factor dominates the rounding of the bound's own sums, whatever their order). With
    ``energy`` (the run's :class:`~observer.event.energy.EnergyCarry`), the same error of
    the k mechanical components in its norm: ``w = new[:k] + |E[:k, lo:hi]|·err[lo:hi]·(1 + 2γ)``
    (what the oscillators' reset error feeds in), ``ε ← (ε·e^{rate·step}(1 + 4u) + ‖w‖_P)(1 + 4u)``,
    ``‖w‖_P ≤ sqrt(wᵀ|P|w·(1 + gp))`` raised twice (:func:`observer.event.energy.p_norm_bound`,
    gp = γ_{2k+1}, :func:`observer.event.energy.p_norm_gamma`); ε = inf where the rate or ε
    is not finite. With ``reset``: the oscillator
    states ``z[lo:hi]``, reset from ``fl(ω a)``, known to ``(ω·|a| + 2|z|)·u·(1 + 2γ)``
    (``wfreq``: the ω per oscillator state), and the time component exact.

    Returns ``(err, eps)``, new arrays."""
    N = za.size
    out = np.empty(N)
    new = np.empty(N)
    for i in range(N):
        s1 = 0.0
        s2 = 0.0
        for j in range(N):
            e = abs(E[i, j])
            s1 += e * abs(za[j])
            s2 += e * err[j]
        new[i] = g * s1 * (1.0 + 2.0 * g)
        out[i] = s2 * (1.0 + 2.0 * g) + new[i]
    if energy:
        if math.isfinite(rate) and math.isfinite(eps):
            w = np.empty(k)
            for i in range(k):
                s = 0.0
                for j in range(lo, hi):
                    s += abs(E[i, j]) * err[j]
                w[i] = new[i] + s * (1.0 + 2.0 * g)
            x = rate * step
            growth = math.exp(x) * (1.0 + 4.0 * _U) if x < 700.0 else math.inf
            q = 0.0
            for i in range(k):
                r = 0.0
                for j in range(k):
                    r += absP[i, j] * w[j]
                q += w[i] * r
            pn = np.nextafter(np.nextafter(math.sqrt(q * (1.0 + gp)), np.inf), np.inf)
            eps = (eps * growth + pn) * (1.0 + 4.0 * _U)
        else:
            eps = math.inf
    if reset:
        for m in range(lo, hi):
            out[m] = (wfreq[m - lo] * abs(a) + 2.0 * abs(z[m])) * _U * (1.0 + 2.0 * g)
        out[N - 1] = 0.0
    return out, eps
