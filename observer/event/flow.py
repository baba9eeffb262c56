"""Exact flow of the master between events: one autonomous linear system, one matrix exponential.

Between events the system (paper eqs. (1)-(3)) is linear with harmonic forcing f(t) and
harmonic gap offset ν(t) (:class:`observer.model.Harmonic`). Each distinct angular
frequency ω of f and ν contributes an oscillator state ``(cos ωt, sin ωt)`` with
``d/dt (c, s) = ω(−s, c)``, and a constant state 1 carries the constant parts, so that

    z = (q, u, c_1, s_1, …, c_F, s_F, 1),      ż = A z,      z(t0 + τ) = exp(Aτ) z(t0)

is exact (up to the round-off of ``scipy.linalg.expm``) for singular K too (the bouncing
ball: A is then nilpotent on (q, u, 1)). The oscillator components are always set from t
analytically (``z(t, x)``), so no phase error accumulates over long runs.

With a set I of contacts held closed (persistent contact, docs/theory/event.md §3), the contact force
λ_I keeps ``γ̇_I = 0``: ``γ̇_I = (γ̇_I)_free + G_I λ_I`` with the Delassus matrix
``G_I = W_Iᵀ M⁻¹ W_I``, so ``λ_I = −G_I⁻¹ (γ̇_I)_free`` is an exact linear function of z
(a row matrix ``Λ``), and the constrained flow has the generator
``A_I = A + E_u M⁻¹ W_I Λ``. Gaps, contact velocities, their derivatives and λ are all
linear functionals ``r·z``; :mod:`observer.event.roots` finds their zeros.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from functools import cached_property

import flint
import numpy as np
import scipy.linalg as sla

from observer.event import kernels
from observer.model import Harmonic, LinearSystem

FREQUENCY_MATCH = 1e-14
"""Relative difference below which two harmonic frequencies share one oscillator."""


_PADE13 = (64764752532480000., 32382376266240000., 7771770303897600., 1187353796428800.,
           129060195264000., 10559470521600., 670442572800., 33522128640., 1323241920.,
           40840800., 960960., 16380., 182., 1.)
_THETA13 = 5.371920351148152


def expm_pade13(A: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring with the [13/13] Padé approximant (Higham 2005).

    A small-matrix numpy version of ``scipy.linalg.expm`` (same algorithm, degree 13
    always): the reference of the compiled :func:`observer.event.kernels.expm_pade13`,
    which the flow uses (the same products and solve, without a Python call per product).
    """
    N = A.shape[0]
    nrm = float(np.abs(A).sum(axis=0).max())
    s = 0 if nrm <= _THETA13 else int(np.ceil(np.log2(nrm / _THETA13)))
    A = A / (2.0 ** s)
    b1I, b0I = _identity_terms(N)
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    b = _PADE13
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4 + b[3] * A2 + b1I)
    V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 + b0I
    E = np.linalg.solve(V - U, V + U)
    for _ in range(s):
        E = E @ E
    return E


_IDENTITY_TERMS: dict = {}


def _identity_terms(N: int) -> tuple[np.ndarray, np.ndarray]:
    """``(b_1 I, b_0 I)`` of :func:`expm_pade13` for size N, built once (read-only)."""
    hit = _IDENTITY_TERMS.get(N)
    if hit is None:
        I = np.eye(N)
        hit = (_PADE13[1] * I, _PADE13[0] * I)
        for arr in hit:
            arr.flags.writeable = False
        _IDENTITY_TERMS[N] = hit
    return hit


def _frequencies(*signals: Harmonic) -> list[float]:
    """Distinct positive frequencies of the harmonic terms of ``signals`` (sorted)."""
    out: list[float] = []
    for sig in signals:
        for w in sig.omega:
            w = float(w)
            if w > 0.0 and not any(abs(w - v) <= FREQUENCY_MATCH * max(w, v) for v in out):
                out.append(w)
    return sorted(out)


def _signal_rows(sig: Harmonic, freqs: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of a harmonic signal on the oscillator states.

    Returns ``(osc, const)``: ``osc`` shape (d, 2F) on ``(c_1, s_1, …)`` and ``const`` shape
    (d,) so that ``x(t) = osc @ (cos ω_k t, sin ω_k t)_k + const``. Uses
    ``a cos(ωt + φ) = a cos φ · cos ωt − a sin φ · sin ωt`` and
    ``a sin(ωt + φ) = a sin φ · cos ωt + a cos φ · sin ωt``.
    """
    d = sig.dim
    osc = np.zeros((d, 2 * len(freqs)))
    const = np.array(sig.constant, dtype=float).copy()
    cos_kind = sig.kind == "cos"
    for a, w, p in zip(sig.amplitude, sig.omega, sig.phase):
        cc = a * (np.cos(p) if cos_kind else np.sin(p))      # coefficient of cos ωt
        cs = a * (-np.sin(p) if cos_kind else np.cos(p))     # coefficient of sin ωt
        if w == 0.0:
            const += cc                                        # cos 0 = 1, sin 0 = 0
            continue
        k = next(i for i, v in enumerate(freqs) if abs(w - v) <= FREQUENCY_MATCH * max(w, v))
        osc[:, 2 * k] += cc
        osc[:, 2 * k + 1] += cs
    return osc, const


class Flow:
    """Exact flow of ``system`` with the contacts ``active`` held closed.

    Parameters
    ----------
    system : LinearSystem
    active : tuple of int
        Contacts in persistent contact (g_i = γ_i = 0 kept by the force λ_i); ``()`` for
        the free flow.

    Attributes
    ----------
    A : ndarray, shape (N, N)
        Generator of the augmented state z (N = 2n + 2F + 1).
    gap_rows, velocity_rows : ndarray, shape (m, N)
        ``g = gap_rows @ z`` (paper eq. (2)), ``γ = velocity_rows @ z`` (eq. (3)).
    force_rows : ndarray, shape (len(active), N)
        ``λ_I = force_rows @ z`` (zero rows for the free flow).
    norm_bound : float
        ``‖T⁻¹AT‖₂`` for the balancing similarity T (``scale``): ``‖T⁻¹z(t+τ)‖ ≤
        exp(norm_bound·τ)‖T⁻¹z(t)‖`` (float64 SVD): it sets the root isolation's window.
    certified_norm : float
        A proved upper bound of ``‖T⁻¹AT‖₂`` (:func:`spectral_norm_upper`, computed on first
        use): the growth factor of the certified bounds of :mod:`observer.event.roots`.
    scale : ndarray, shape (N,)
        Diagonal of T.
    """

    def __init__(self, system: LinearSystem, active: tuple[int, ...] = ()) -> None:
        self.system = system
        self.active = tuple(int(i) for i in active)
        n, m = system.n, system.m
        self.n, self.m = n, m
        self.freqs = _frequencies(system.forcing, system.gap)
        self._freq_array = np.asarray(self.freqs, dtype=float)
        F = len(self.freqs)
        N = 2 * n + 2 * F + 1
        self.N = N
        Minv = np.linalg.inv(system.M)
        self.Minv = Minv
        f_osc, f_const = _signal_rows(system.forcing, self.freqs)
        nu_osc, nu_const = _signal_rows(system.gap, self.freqs)
        osc = slice(2 * n, 2 * n + 2 * F)
        A = np.zeros((N, N))
        A[:n, n:2 * n] = np.eye(n)
        A[n:2 * n, :n] = -Minv @ system.K
        A[n:2 * n, n:2 * n] = -Minv @ system.C
        A[n:2 * n, osc] = Minv @ f_osc
        A[n:2 * n, N - 1] = Minv @ f_const
        for k, w in enumerate(self.freqs):
            c, s = 2 * n + 2 * k, 2 * n + 2 * k + 1
            A[c, s] = -w
            A[s, c] = w
        gap_rows = np.zeros((m, N))
        gap_rows[:, :n] = system.W.T
        gap_rows[:, osc] = nu_osc
        gap_rows[:, N - 1] = nu_const
        W_I = system.W[:, list(self.active)]
        cancelled = np.zeros(A.shape, dtype=bool)
        if self.active:
            G_I = W_I.T @ Minv @ W_I
            free_accel = (gap_rows @ A @ A)[list(self.active)]          # (γ̇_I) of the free flow
            force_rows = -np.linalg.solve(G_I, free_accel)
            free_A, A = A, A.copy()
            A[n:2 * n, :] += Minv @ W_I @ force_rows
            # zero but for round-off: the exact held accelerations of the system's data are 0
            loads = np.hstack([-system.K, -system.C, f_osc, f_const.reshape(n, 1)])
            cancelled[n:2 * n, :] = held_zeros(free_A, system.M, loads, W_I,
                                               gap_rows[list(self.active)])
        else:
            force_rows = np.zeros((0, N))
        cancelled |= np.abs(A) < np.finfo(float).tiny        # subnormal: no scale information
        self.A = A
        self.gap_rows = gap_rows
        self.velocity_rows = gap_rows @ A
        self.force_rows = force_rows
        self.scale, self._balanced = balance(A, cancelled)
        self.norm_bound = float(np.linalg.norm(self._balanced, 2))
        self._expm_cache: OrderedDict = OrderedDict()
        self._phi_cache: OrderedDict = OrderedDict()
        self._certified_norm: float | None = None

    @cached_property
    def blocks(self) -> list[np.ndarray]:
        """Index sets of the connected components of the sparsity graph of A (A_ij ≠ 0 joins
        i and j): A is block diagonal over them, and so is exp(A dt). One block (all
        indices) for a system whose parts are all coupled."""
        nz = (self.A != 0.0) | (self.A != 0.0).T
        left = set(range(self.N))
        out = []
        while left:
            todo, comp = [min(left)], set()
            while todo:
                i = todo.pop()
                if i in comp:
                    continue
                comp.add(i)
                todo.extend(int(j) for j in np.flatnonzero(nz[i]) if j not in comp)
            left -= comp
            out.append(np.array(sorted(comp)))
        return out if len(out) > 1 else [np.arange(self.N)]

    @cached_property
    def _block_layout(self) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`blocks` as ``(order, starts)`` for :func:`observer.event.kernels.blocked_expm`:
        block k is ``order[starts[k]:starts[k + 1]]``."""
        order = np.concatenate(self.blocks).astype(np.int64)
        starts = np.cumsum([0] + [b.size for b in self.blocks]).astype(np.int64)
        return order, starts

    @property
    def certified_norm(self) -> float:
        """A proved upper bound of ``‖T⁻¹AT‖₂`` (:func:`spectral_norm_upper`), cached."""
        if self._certified_norm is None:
            self._certified_norm = spectral_norm_upper(self.A, self.scale)
        return self._certified_norm

    # -- augmented state -------------------------------------------------------------------
    def oscillators(self, t: float) -> np.ndarray:
        """Oscillator block ``(cos ω_k t, sin ω_k t)_k`` at time t (empty without harmonics)."""
        w = self._freq_array
        if not w.size:
            return np.empty(0)
        out = np.empty(2 * w.size)
        wt = w * t
        out[0::2] = np.cos(wt)
        out[1::2] = np.sin(wt)
        return out

    def z(self, t: float, x: np.ndarray) -> np.ndarray:
        """Augmented state at time t of the mechanical state ``x = (q, u)``."""
        out = np.empty(self.N)
        k = 2 * self.n
        out[:k] = x
        w = self._freq_array
        if w.size:
            wt = w * t
            out[k:-1:2] = np.cos(wt)
            out[k + 1:-1:2] = np.sin(wt)
        out[-1] = 1.0
        return out

    def x_of(self, z: np.ndarray) -> np.ndarray:
        """Mechanical state ``(q, u)`` of an augmented state."""
        return z[..., :2 * self.n].copy()

    # -- exponentials ----------------------------------------------------------------------
    def expm(self, dt: float) -> np.ndarray:
        """``exp(A dt)`` (a few recent values cached: the output step and the search window)."""
        dt = float(dt)
        hit = self._expm_cache.get(dt)
        if hit is None and dt == 0.0:
            return np.eye(self.N)                 # exactly (the Padé quotient is 1 − eps/2)
        if hit is None:
            # balanced: exp(A dt) = T exp(B dt) T⁻¹, B = T⁻¹AT of smaller norm; per block of
            # the sparsity of A (:attr:`blocks`: a mode coupled to nothing is exponentiated
            # alone, so its frequency sets no scaling of the others); compiled
            hit = kernels.blocked_expm(self._balanced, self.scale, *self._block_layout, dt)
            self._expm_cache[dt] = hit
            if len(self._expm_cache) > 8:
                self._expm_cache.popitem(last=False)
        return hit

    def phi(self, dt: float) -> np.ndarray:
        """``∫₀^dt exp(As) ds`` from the exponential of the block matrix ``[[A, I], [0, 0]]``."""
        dt = float(dt)
        hit = self._phi_cache.get(dt)
        if hit is None:
            N = self.N
            big = np.zeros((2 * N, 2 * N))
            big[:N, :N] = self.A
            big[:N, N:] = np.eye(N)
            hit = kernels.expm_pade13(big * dt)[:N, N:]
            self._phi_cache[dt] = hit
            if len(self._phi_cache) > 8:
                self._phi_cache.popitem(last=False)
        return hit

    def integral(self, dt: float, z: np.ndarray) -> np.ndarray:
        """``∫₀^dt exp(As) z ds`` for one vector z, from the exponential of the bordered
        matrix ``[[B dt, c], [0, 0]]`` (size N + 1; B = T⁻¹AT balanced, as in :meth:`expm`;
        c = T⁻¹z / ‖T⁻¹z‖_∞): the last column of its exponential is
        ``∫₀^1 exp(B dt r) c dr``, times ``dt ‖T⁻¹z‖_∞`` and T the integral sought.
        Cheaper than :meth:`phi` (size 2N) when the integral of one state is wanted."""
        dt = float(dt)
        N = self.N
        b = np.asarray(z, dtype=float) / self.scale
        size = float(np.max(np.abs(b)))
        if size == 0.0 or dt == 0.0:
            return np.zeros(N)
        big = np.zeros((N + 1, N + 1))
        big[:N, :N] = self._balanced * dt
        big[:N, N] = b / size                  # a unit border: it does not set the scaling
        return kernels.expm_pade13(big)[:N, N] * (dt * size) * self.scale

    def power_stack(self, dt: float, count: int) -> np.ndarray:
        """``exp(A j dt)`` for j = 1..count, shape (count, N, N): a whole block of equally
        spaced samples in one product. Cached for one dt and extended on demand (a short run
        does not pay for a long block)."""
        dt, count = float(dt), int(count)
        if getattr(self, "_stack_dt", None) != dt:
            self._stack, self._stack_dt = self.expm(dt)[None].copy(), dt
        have = self._stack.shape[0]
        if have < count:
            E = self.expm(dt)
            stack = np.empty((count, self.N, self.N))
            stack[:have] = self._stack
            for j in range(have, count):
                stack[j] = E @ stack[j - 1]
            self._stack = stack
        return self._stack[:count]

    # -- the flow --------------------------------------------------------------------------
    def propagate(self, t0: float, z0: np.ndarray, dt: float) -> np.ndarray:
        """Augmented state at ``t0 + dt`` from z0 at t0; the oscillators reset analytically."""
        z1 = self.expm(dt) @ z0
        z1[2 * self.n:-1] = self.oscillators(t0 + dt)
        z1[-1] = 1.0
        return z1

    def state(self, t0: float, x0: np.ndarray, dt: float) -> np.ndarray:
        """Exact mechanical state ``x(t0 + dt)`` from ``x(t0) = x0`` (dt ≥ 0)."""
        return self.x_of(self.expm(dt) @ self.z(t0, x0))

    def states(self, t0: float, x0: np.ndarray, dts) -> np.ndarray:
        """States at ``t0 + dts`` (array), shape (len(dts), 2n)."""
        z0 = self.z(t0, x0)
        return np.array([self.x_of(self.expm(float(d)) @ z0) for d in np.atleast_1d(dts)])

    # -- functionals -----------------------------------------------------------------------
    def gaps(self, t: float, x: np.ndarray) -> np.ndarray:
        """Gaps ``g = Wᵀq + ν(t)`` of all contacts (paper eq. (2))."""
        return self.gap_rows @ self.z(t, x)

    def velocities(self, t: float, x: np.ndarray) -> np.ndarray:
        """Contact velocities ``γ = Wᵀu + ν̇(t)`` of all contacts (paper eq. (3))."""
        return self.velocity_rows @ self.z(t, x)

    def forces(self, t: float, x: np.ndarray) -> np.ndarray:
        """Contact forces λ_I of the persistent set (empty for the free flow)."""
        return self.force_rows @ self.z(t, x)

    def gap_derivatives(self, t: float, x: np.ndarray, k: int) -> np.ndarray:
        """k-th time derivative of all gaps along this flow: ``gap_rows A^k z``."""
        return self.gap_rows @ np.linalg.matrix_power(self.A, k) @ self.z(t, x)

    def accelerations(self, t: float, x: np.ndarray) -> np.ndarray:
        """Contact accelerations ``γ̇`` of all contacts along this flow (0 on the active set)."""
        return self.velocity_rows @ self.A @ self.z(t, x)

    def force_impulse(self, t0: float, x0: np.ndarray, dt: float) -> np.ndarray:
        """``∫ λ_I dt`` over ``[t0, t0 + dt]`` (exact: ``Λ ∫exp(As)ds z0``)."""
        if not self.active:
            return np.zeros(0)
        return self.force_rows @ self.integral(dt, self.z(t0, x0))


# -- certified bounds (issue 19: δ* proved, not estimated) ----------------------------------

_U = np.finfo(float).eps / 2.0


def up(x: float, ulps: int = 1) -> float:
    """``x`` moved ``ulps`` floats towards +∞ (an outward rounding)."""
    x = float(x)
    for _ in range(ulps):
        x = math.nextafter(x, math.inf)
    return x


def norm_upper(v: np.ndarray) -> float:
    """A proved upper bound of the Euclidean norm ‖v‖₂ of the float vector v.

    v is scaled by a power of two 2^-e (exact) to ``max|v_i| ∈ [1/2, 1)``; each square is
    rounded (relative error ≤ u), ``math.fsum`` rounds the sum once (≤ u) and ``sqrt``
    once (≤ u), so ``‖v/2^e‖₂ ≤ r/(1 − u)² ≤ r(1 + 3u)``, rounded up by ulps; squares that
    underflow add at most ``N·2^-1074`` to the sum. Overflow cannot occur. Compiled
    (:func:`observer.event.kernels.norm_upper`, the same float as
    :func:`norm_upper_reference`).
    """
    return kernels.norm_upper(np.ascontiguousarray(v, dtype=float).ravel())


def norm_upper_reference(v: np.ndarray) -> float:
    """:func:`norm_upper` in Python (``math.fsum``): the reference of the compiled kernel."""
    v = np.asarray(v, dtype=float).ravel()
    if not np.isfinite(v).all():
        return np.inf
    big = float(np.max(np.abs(v))) if v.size else 0.0
    if big == 0.0:
        return 0.0
    e = math.frexp(big)[1]
    w = np.ldexp(v, -e)
    s = up(math.fsum((w * w).tolist()) + v.size * 5e-324, 2)
    r = up(math.sqrt(s) * (1.0 + 4.0 * _U), 2)
    return math.ldexp(r, e)


def exp_upper(x: float) -> float:
    """A proved upper bound of ``e^x`` (ball arithmetic, python-flint ``arb``); the last
    :data:`EXP_UPPER_CACHE` arguments' bounds are kept, per working precision of flint (a
    run asks for the same window's growth at every search)."""
    x = float(x)
    key = (x, flint.ctx.prec)                           # the bound arb gives at this precision
    hit = _EXP_UPPER.get(key)
    if hit is not None:
        return hit
    if np.isnan(x) or x == np.inf:
        return np.inf                                   # no bound: the search cannot proceed
    if x == -np.inf:
        return 0.0
    hit = up(float(flint.arb(x).exp().upper()), 1)
    if len(_EXP_UPPER) >= EXP_UPPER_CACHE:
        _EXP_UPPER.clear()
    _EXP_UPPER[key] = hit
    return hit


EXP_UPPER_CACHE = 256
"""Arguments of :func:`exp_upper` whose bounds are kept (all dropped when full)."""

_EXP_UPPER: dict = {}


def _exact(x: np.ndarray) -> flint.fmpq_mat:
    """The float64 matrix ``x`` as an exact rational matrix (every float is a rational)."""
    x = np.atleast_2d(np.asarray(x, dtype=float))
    return flint.fmpq_mat(x.shape[0], x.shape[1],
                          [flint.fmpq(*v.as_integer_ratio()) for v in x.ravel().tolist()])


def held_zeros(A: np.ndarray, M: np.ndarray, loads: np.ndarray, W_I: np.ndarray,
               gap_rows_I: np.ndarray) -> np.ndarray:
    """The entries of a held flow's accelerations ``A[n:2n] + M⁻¹W_I F_I`` that are zero but
    for round-off: those whose exact value, from the system's own data, is 0.

    The exact held accelerations are ``H = A_u − P G⁻¹X`` with ``A_u = M⁻¹L`` (L = ``loads``
    = ``(−K, −C, the harmonic forcing's rows, the constant force)``), ``P = M⁻¹W_I``,
    ``G = W_Iᵀ P`` and ``X = (gap rows of I)·A·A`` (the free gap accelerations' rows, A with
    its rows n:2n replaced by A_u). They are computed here exactly, in rational arithmetic
    (``flint.fmpq_mat``; every float is a rational: M, L, W_I, the gap rows and A's other
    rows, the identity and the harmonic rotations, are taken as exact), and an entry is
    cancelled iff its exact value is 0. The certified rounding bound of the computed entry
    ``ĥ`` against its exact value ``h`` is ``|ĥ − h|`` itself, so ``ĥ`` cannot be told from
    zero iff h = 0. No count of round-offs and no scale: an exact zero is cancelled whatever
    its float residue (a held DOF's rows, ~1e-17 of their terms), a nonzero entry is kept
    however small. The float M⁻¹ (``np.linalg.inv``) and ``A_u = fl(M⁻¹L)`` carry round-off
    of their own, so the exact value is taken from M and L, not from them.

    Why not a float64 a-priori bound. The last step alone, ``fl(A_u + fl(fl(M⁻¹ @ W_I) @ F̂))``
    (n products and n − 1 additions per entry of ``fl(M⁻¹W_I)``, then p = |I| products and
    p − 1 additions, then one addition; Higham §3.1, lemma 3.3), errs by at most
    ``γ_{n+p+1}(|A_u| + |M⁻¹||W_I||F̂|)`` entrywise, with ``|M⁻¹||W_I|``, not
    ``|fl(M⁻¹W_I)|``, which cancels. But F̂ is a float solve whose error is amplified by G's
    conditioning, and A_u and M⁻¹ are rounded: in the held pair of
    ``test_invariance.TINY_PHASE`` (both DOFs held, every exact entry 0) two entries are
    6.4e-15 and 8.4e-14 of their own terms, 12 and 150 times γ_5: that bound keeps them, and
    the balancing scaled a velocity by 2^-24. A bound of the solve would need a certified
    ``|G⁻¹|``; the exact value needs no more (a few exact products of matrices of the flow's
    size, once per flow: :func:`flow_for` caches flows).

    Parameters
    ----------
    A : ndarray, shape (N, N)
        The free flow's generator (its rows n:2n are replaced by the exact ``M⁻¹L``).
    M : ndarray, shape (n, n)
        Mass matrix.
    loads : ndarray, shape (n, N)
        L: ``M`` times the free accelerations' rows, ``(−K, −C, forcing rows, constant)``.
    W_I : ndarray, shape (n, p)
        The held contacts' columns of W.
    gap_rows_I : ndarray, shape (p, N)
        Their gap rows.

    Returns
    -------
    ndarray of bool, shape (n, N)
        True where the exact held acceleration is 0; all False if the data are not finite
        or the exact M or G is singular (nothing is known to cancel)."""
    n, N = loads.shape
    none = np.zeros((n, N), dtype=bool)
    if not all(np.all(np.isfinite(x)) for x in (A, M, loads, W_I, gap_rows_I)):
        return none
    try:
        Mq = _exact(M)
        A_u = Mq.solve(_exact(loads))
        P = Mq.solve(_exact(W_I))
        Aq = _exact(A)
        for i in range(n):
            for j in range(N):
                Aq[n + i, j] = A_u[i, j]
        F = (_exact(W_I).transpose() * P).solve(_exact(gap_rows_I) * Aq * Aq)
    except ZeroDivisionError:
        return none
    H = A_u - P * F
    return np.array([[H[i, j] == 0 for j in range(N)] for i in range(n)], dtype=bool)


def balance(A: np.ndarray, cancelled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Diagonal similarity ``B = T⁻¹AT`` (T = diag(scale), powers of two) that balances A
    (``scipy.linalg.matrix_balance``), computed with the entries ``cancelled`` (zero but for
    round-off) set to zero; B is A's own (exact: scaling by powers of two).

    With them, the velocities of the DOFs a held contact set fixes (their rows and columns
    of A are ~1e-17 where the constraint force cancels the free acceleration) drove their
    scales to 1e-77 and 1e-164; a state's round-off in those components, divided by them,
    made the certified third-derivative bound 1e116, and the root search after both contacts
    of a 2-DOF system were held took steps of 1e-54 s and stalled (issue 19). A row whose
    only nonzero entry was subnormal (4.9e-324, a forcing phase of 2.2e-309) was scaled by
    2.2e-162 likewise. Returns (scale, B)."""
    _, T = sla.matrix_balance(np.where(cancelled, 0.0, A), permute=False)
    scale = np.diag(T).copy()
    return scale, A * scale[None, :] / scale[:, None]


def spectral_norm_upper(A: np.ndarray, scale: np.ndarray) -> float:
    """A proved upper bound of ``‖T⁻¹AT‖₂`` (T = diag(scale)), by Gershgorin in ball arithmetic.

    With ``M = BᵀB`` (B = T⁻¹AT, formed exactly in 128-bit balls) and V the float
    eigenvectors of the float M, ``C ∋ V⁻¹MV`` is computed in ball arithmetic (``arb_mat``,
    V⁻¹ enclosed by a certified inverse). C is similar to M, whose eigenvalues are real, so
    ``‖B‖₂² = λ_max(M) ≤ max_i (C_ii + Σ_{j≠i} |C_ij|)`` (Gershgorin), with the balls'
    upper ends. V is nearly orthogonal, so the bound exceeds the SVD's value by O(N·eps).
    """
    A = np.asarray(A, dtype=float)
    N = A.shape[0]
    s = np.asarray(scale, dtype=float)
    B = A * s[None, :] / s[:, None]
    with np.errstate(over="ignore", invalid="ignore"):
        M = B.T @ B
    if not np.isfinite(M).all():
        return np.inf                                   # ‖B‖² beyond float64: no finite bound
    _, V = np.linalg.eigh(M)
    with flint.ctx.workprec(128):
        Ba = flint.arb_mat([[flint.arb(A[i, j]) * flint.arb(s[j]) / flint.arb(s[i])
                             for j in range(N)] for i in range(N)])
        Va = flint.arb_mat(V.tolist())
        C = Va.inv() * (Ba.transpose() * Ba) * Va
        rows = [C[i, i] + sum((abs(C[i, j]) for j in range(N) if j != i), flint.arb(0))
                for i in range(N)]
        top = max(up(float(r.upper()), 1) for r in rows)      # arf → float: at most 1 ulp low
    return up(math.sqrt(max(top, 0.0)), 1)


_FLOWS: dict = {}


def flow_for(system: LinearSystem, active=()) -> Flow:
    """The :class:`Flow` of ``system`` with ``active`` held closed, built once and cached."""
    key = (id(system), tuple(sorted(int(i) for i in active)))
    hit = _FLOWS.get(key)
    if hit is None or hit.system is not system:
        hit = Flow(system, key[1])
        if len(_FLOWS) > 512:
            _FLOWS.clear()
        _FLOWS[key] = hit
    return hit
