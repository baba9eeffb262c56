"""The compiled primitives both time-stepping engines share: one definition each.

The bottom floor of the Moreau–Jean engines (:mod:`observer.engines.compiled` runs them in its
step loop, :mod:`observer.engines.python` and :class:`observer.stepping.MoreauJean` call them
from numpy), so that the two engines compute these quantities with the same code:

* **Siconos' predictor** of the closed set of step k → k+1, ``g_k + (h/2)γ_k ≤ 0`` with
  ``g_k = Wᵀq_k + ν(t_k)`` and ``γ_k = Wᵀu_k + ν̇(t_k)`` (paper, Section 2: the index set of
  the time-stepping scheme): :func:`predicted_term` (one term ``W_ij(q_i + (h/2)u_i)`` of the
  predicted gap, summed over W's column) and :func:`predicted_closed` (the decision).
* **The position projection** of eqs. (13)-(14), ``q⁺ = q⁻ + N⁻¹W_IΣ`` with
  ``(W_IᵀN⁻¹W_I)Σ = −g_I(q⁻)``: :func:`project_positions` (any closed set; one contact in
  closed form, :func:`project_one`) and :func:`project_closed` (the same for a caller outside
  the step loop).
* **Residuals**: :func:`lcp_residual` (the solver's natural residual) and
  :func:`applied_residual` (recomputed from the velocity change a step applied).
* **The summary layout** of ``store="summary"`` (:data:`SUMMARY_FIELDS`, ``F_*``) and the
  kernel's statuses, statistics layout (:data:`STATS_SIZE`) and structure codes.

Every function is compiled with :data:`JIT`; W is in CSC storage (:func:`csc_arrays`). These
are exact transcriptions of the formulas in floating point: what holds exactly is that both
engines evaluate the same operations in the same order (bitwise the same values), not that
the values equal the real-number quantities.
"""

from __future__ import annotations

import textwrap

import numpy as np
from numba import njit

from observer.codegen import compile_function, fill
from observer.numba_cache import install as _install_cache_guard

_install_cache_guard()        # a damaged or unwritable numba cache: a warning and a recompile

OK, LCP_FAILED, PROJECTION_FAILED, RESIDUAL_EXCEEDED = 0, 1, 2, 3
STATS_SIZE = 8
"""``stats`` of :func:`observer.engines.compiled.kernel.advance`: [contact solves, iterations, max LCP residual, min gap of the
master after a step, its step, max applied residual (:func:`applied_residual`), its step, the
applied residual of the last contact step]."""
STRUCTURE_DENSE, STRUCTURE_BANDED = 0, 1
CONTACTS_DENSE, CONTACTS_FACTORED = 0, 1
"""How the kernel holds the contacts' Delassus data (:attr:`observer.engines.compiled.bundles.SystemBundle.contacts`): the
precomputed dense ``Â⁻¹W``, Ĝ and per-metric ``N⁻¹W``, ``WᵀN⁻¹W``, or, for large banded
systems, the banded Cholesky factors of Â and of the projection metrics, from which each step
assembles its closed set's blocks (:func:`observer.engines.compiled.kernel.factored_impulse`, :func:`observer.engines.compiled.kernel.factored_project`)."""
EPS = float(np.finfo(np.float64).eps)
ROUNDOFF = 16.0
TINY = 1e-300
JIT = {"cache": True, "error_model": "numpy", "nogil": True}
"""Options of every kernel function (:func:`numba.njit`). The small helpers are also inlined
(``inline="always"``) into the functions that call them, never into the step loop of
:func:`observer.engines.compiled.kernel.advance`: there an inlined array argument is a reference count per step, while a
function that calls nothing (a leaf) has its reference counts pruned by numba."""


# ---------------------------------------------------------------------------------------
# small dense linear algebra on work buffers
# ---------------------------------------------------------------------------------------
@njit(**JIT)
def _cholesky(G, a, Lf):
    """Lower Cholesky factor of G[:a, :a] into Lf[:a, :a]; False if not positive definite."""
    for j in range(a):
        s = G[j, j]
        for p in range(j):
            s -= Lf[j, p] * Lf[j, p]
        if not s > 0.0:
            return False
        d = np.sqrt(s)
        Lf[j, j] = d
        for i in range(j + 1, a):
            s = G[i, j]
            for p in range(j):
                s -= Lf[i, p] * Lf[j, p]
            Lf[i, j] = s / d
    return True


@njit(**JIT)
def _cho_solve(Lf, a, rhs, out):
    """Solve (Lf Lfᵀ) out = rhs on the first a entries."""
    for i in range(a):
        s = rhs[i]
        for p in range(i):
            s -= Lf[i, p] * out[p]
        out[i] = s / Lf[i, i]
    for i in range(a - 1, -1, -1):
        s = out[i]
        for p in range(i + 1, a):
            s -= Lf[p, i] * out[p]
        out[i] = s / Lf[i, i]


# ---------------------------------------------------------------------------------------
# LCP 0 ≤ Gx + b ⊥ x ≥ 0 with SPD G (the first a rows/columns of the buffers)
# ---------------------------------------------------------------------------------------
@njit(**JIT, inline="always")
def lcp_residual(G, b, x, a):
    """Relative natural residual ‖min(x, Gx + b)‖_∞ / max(‖b‖_∞, ‖Gx‖_∞)."""
    r = 0.0
    sb = 0.0
    sg = 0.0
    for i in range(a):
        gx = 0.0
        for j in range(a):
            gx += G[i, j] * x[j]
        r, sb, sg = _residual_row(x[i], b[i], gx, r, sb, sg)
    return r / max(sb, sg, TINY)


@njit(**JIT, inline="always")
def _residual_row(z, b, d, r, sb, sd):
    """One row of a relative natural residual (:func:`lcp_residual`, :func:`applied_residual`):
    the running maxima ``r`` of ``|min(z, b + d)|``, ``sb`` of ``|b|`` and ``sd`` of ``|d|``
    updated (``b + d`` is ``d + b``: IEEE addition commutes)."""
    v = abs(min(z, b + d))
    if v > r:
        r = v
    if abs(b) > sb:
        sb = abs(b)
    if abs(d) > sd:
        sd = abs(d)
    return r, sb, sd


# ---------------------------------------------------------------------------------------
# one step of one system: the pieces (row s of the 2-D states qs, us is the system)
# ---------------------------------------------------------------------------------------
@njit(**JIT, inline="always")
def _wt(Wp, Wi, Wv, x, j):
    """(Wᵀx)_j from the CSC storage of W."""
    s = 0.0
    for p in range(Wp[j], Wp[j + 1]):
        s += Wv[p] * x[Wi[p]]
    return s


@njit(**JIT, inline="always")
def _wt_row(Wp, Wi, Wv, X, s, j):
    """(Wᵀ X[s])_j from the CSC storage of W."""
    acc = 0.0
    for p in range(Wp[j], Wp[j + 1]):
        acc += Wv[p] * X[s, Wi[p]]
    return acc


@njit(**JIT, inline="always")
def applied_residual(Wp, Wi, Wv, act, a, du, bvec, z):
    """Complementarity residual of the impulse as applied, relative like :func:`lcp_residual`.

    With ``d = W_Aᵀδu`` (``δu = Σ (Â⁻¹W)_j P_j = u_{k+1} − u_free``, the velocity change the
    step applied, summed apart from u_free so that the round-off of the velocity itself does
    not enter; ``d`` equals ``ĜP`` up to round-off) and ``bvec`` the LCP's right-hand side (Newton:
    ``γ_free + e∘γ_k``, so ``bvec + d = γ_{k+1} + e∘γ_k``, Siconos' law ``0 ≤ γ_{k+1} + eγ_k ⊥ P ≥ 0``;
    Poisson: γ̃, so ``bvec + d = γ̃ + ĜP``, Glocker's expansion condition
    ``0 ≤ γ̃ + ĜP ⊥ Λ_E − εΛ_C ≥ 0``), ``z`` the complementary unknown (P, or Λ_E − εΛ_C):
    ``max_r |min(z_r, bvec_r + d_r)| / max(‖bvec‖_∞, ‖d‖_∞)``.
    """
    r_ = 0.0
    sb = 0.0
    sd = 0.0
    for r in range(a):
        d = _wt(Wp, Wi, Wv, du, act[r])
        r_, sb, sd = _residual_row(z[r], bvec[r], d, r_, sb, sd)
    return r_ / max(sb, sd, TINY)


PROJECT_ONE = """
j1 = $J
g1 = 0.0
for p1 in range(Wp[j1], Wp[j1 + 1]):
    g1 += Wv[p1] * q1[Wi[p1]]
g1 = g1 + nu[$ROW, j1]
l00 = L[$SLOT, j1, j1]
ok1 = l00 > 0.0
s1 = -g1 / l00 if ok1 else 0.0
$SIGMA
for i1 in range(n):
    q1[i1] += KinvWT[$SLOT, j1, i1] * s1
status = OK if ok1 else PROJECTION_FAILED
"""
"""The position jump of eqs. (13)-(14) on one closed contact ``$J``, in closed form:
``Σ = −g_j(q1)/L_jj`` with the gap at row ``$ROW`` of ``nu``, ``q1 += (N⁻¹W)_j Σ`` in the metric
of slot ``$SLOT``; ``$SIGMA`` keeps Σ (``sig[0] = s1``, or nothing), the status into
``status`` (:data:`PROJECTION_FAILED`
when ``L_jj ≤ 0``). The one source of the one-contact projection: the body of
:func:`project_one` and, placed inline, of the compiled step loops'
(:mod:`observer.engines.compiled.step`; a call there costs every array's fields per step). No
branch around an array access, like :func:`observer.engines.compiled.kernel.impulse_one`."""

project_one = compile_function("project_one", f'''
def project_one(k, j, slot, Wp, Wi, Wv, nu, KinvWT, L, q1, sig):
    """:func:`project_positions` on the one closed contact j (:data:`PROJECT_ONE`)."""
    n = q1.shape[0]
{textwrap.indent(fill(PROJECT_ONE, {"J": "j", "ROW": "k", "SLOT": "slot", "SIGMA": "sig[0] = s1"}), "    ")}
    return status
''', globals(), __file__, JIT)


@njit(**JIT)
def project_positions(k, act, a, slot, Wp, Wi, Wv, nu, KinvWT, L, q1, sig, g, s_, Gp, Lf):
    """The position jump of eqs. (13)-(14) on the closed set ``act[:a]`` (a ≥ 1), in the
    metric of projection slot ``slot``: ``q1 ← q1 + (N⁻¹W_A)Σ`` with
    ``(W_AᵀN⁻¹W_A)Σ = −g_A(q1)``; Σ into ``sig[:a]`` (``g``, ``s_`` (m,), ``Gp``, ``Lf`` (m, m):
    work buffers). Returns the status
    (:data:`PROJECTION_FAILED` when ``W_AᵀN⁻¹W_A`` is not positive definite)."""
    if a == 1:
        return project_one(k, act[0], slot, Wp, Wi, Wv, nu, KinvWT, L, q1, sig)
    n = q1.shape[0]
    for r in range(a):
        j = act[r]
        g[r] = _wt(Wp, Wi, Wv, q1, j) + nu[k, j]
    for r in range(a):
        for c in range(a):
            Gp[r, c] = L[slot, act[r], act[c]]
    if not _cholesky(Gp, a, Lf):
        return PROJECTION_FAILED
    _cho_solve(Lf, a, g, s_)
    for r in range(a):
        s_[r] = -s_[r]
    for r in range(a):
        sig[r] = s_[r]
        j = act[r]
        for i in range(n):
            q1[i] += KinvWT[slot, j, i] * s_[r]
    return OK


@njit(**JIT)
def project_closed(q, k, act, Wp, Wi, Wv, nu, NinvWT, L, slot):
    """:func:`project_positions` for a caller outside the step loop: the numpy reference
    (:meth:`observer.stepping.MoreauJean.project`) projects with this very code.

    ``q`` (n,) positions, ``act`` (int64) the closed contacts, ``nu[k]`` the gap offsets at the
    step's time, W in CSC (:func:`csc_arrays`), the stacks ``NinvWT`` (P, m, n) and ``L``
    (P, m, m) of the projection metrics and the metric's ``slot``. Returns
    ``(status, q⁺, Σ)`` (q is not modified).
    """
    m = Wp.shape[0] - 1
    a = act.shape[0]
    q1 = q.copy()
    sig = np.zeros(a)
    if a == 0:
        return OK, q1, sig
    g, s_, Gp, Lf = np.empty(m), np.empty(m), np.empty((m, m)), np.empty((m, m))
    status = project_positions(k, act, a, slot, Wp, Wi, Wv, nu, NinvWT, L, q1, sig, g, s_, Gp, Lf)
    return status, q1, sig


def csc_arrays(W: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """W (n, m) in the kernel's CSC storage ``(Wp, Wi, Wv)``: column j's nonzero entries are
    ``Wv[Wp[j]:Wp[j+1]]`` in rows ``Wi[Wp[j]:Wp[j+1]]`` (ascending; int64, int64, float64), what
    ``scipy.sparse.csc_matrix(W)`` stores with sorted indices."""
    WT = np.asarray(W, dtype=np.float64).T
    nz = WT != 0.0
    Wp = np.zeros(WT.shape[0] + 1, dtype=np.int64)
    np.cumsum(nz.sum(axis=1), out=Wp[1:])
    return Wp, np.ascontiguousarray(np.nonzero(nz)[1], dtype=np.int64), np.ascontiguousarray(WT[nz])


# ---------------------------------------------------------------------------------------
# Siconos' predictor g_k + (h/2)γ_k ≤ 0
# ---------------------------------------------------------------------------------------
@njit(**JIT, inline="always")
def predicted_term(w, q, u, h):
    """One term ``w(q + (h/2)u)`` of a predicted gap ``W_jᵀ(q_k + (h/2)u_k)``: W's entry w in
    the row of the coordinate with position q and velocity u (summed over column j in the
    order of its CSC storage). Scalars only, so that inlining it into a step loop adds no
    reference count."""
    return w * (q + 0.5 * h * u)


@njit(**JIT, inline="always")
def predicted_closed(g, nu, nu_dot, h):
    """Siconos' predictor: contact j closes for the step k → k+1 when
    ``W_jᵀ(q_k + (h/2)u_k) + ν_j(t_k) + (h/2)ν̇_j(t_k) ≤ 0``, i.e. ``g_k + (h/2)γ_k ≤ 0``
    (``g`` the sum of :func:`predicted_term` over W's column j, ``nu``, ``nu_dot`` ν_j(t_k),
    ν̇_j(t_k)). The one compiled definition of the predictor: both loops of
    :mod:`observer.engines.compiled.kernel` and the members' loop call it."""
    return g + nu + 0.5 * h * nu_dot <= 0.0


# ---------------------------------------------------------------------------------------
# streaming summary (store="summary"): V of every observer and its parts, without trajectories
# ---------------------------------------------------------------------------------------
F_VON, F_VMAX, F_VEND, F_NINC, F_MAXINC, F_DAMP, F_IMP, F_PROJ, F_MAXIMP, F_KON = range(10)
SUMMARY_FIELDS = 10
"""Per observer: V(t_on), max V in the window, V at the end, steps with V_{k+1} > V_k, the
largest relative rise, the sums of the damping, impulse and remaining (projection and, for
θ ≠ ½, numerical) parts of ΔV, the largest impulse part relative to V_k, the first window
sample; then, per threshold ρ, the first window sample with V ≤ ρV(t_on) and the last one
with V > ρV(t_on) (−1: none)."""
