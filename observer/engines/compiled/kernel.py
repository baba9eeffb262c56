"""The compiled time loop (``engine="compiled"``): master and observers in one numba call.

This is the same scheme as :class:`observer.stepping.MoreauJean` and the loop of
:mod:`observer.loop` (the readable reference, ``engine="python"``), written on plain arrays
for numba: no allocation and no Python-level dispatch per step, the impact law and the
matrix structure selected by integer codes, the small LCPs solved by compiled exact
solvers that return ``(iterations, status, residual)``.

* **Free velocity.** Dense systems use the precomputed ``u_free = Bu u + Bq q + Bf f̄``
  (:class:`~observer.stepping.SchemeMatrices`). Banded systems (``STRUCTURE_BANDED``) solve
  ``Â u_free = R_u u + R_q q + h f̄`` with the banded Cholesky factor of
  ``Â = M + hθC + h²θ²K`` computed once per h, ``R_u = M − h(1−θ)C − h²θ(1−θ)K`` and
  ``R_q = −hK`` (the same algebra as ``Bu = Â⁻¹R_u``, ``Bq = Â⁻¹R_q``, ``Bf = hÂ⁻¹``):
  O(n·bandwidth²) per step instead of O(n²).
* **Contacts.** W is stored by columns (CSC), so gaps and contact velocities cost
  O(nnz(W)); the closed set's Delassus matrices are gathered from the precomputed dense
  ``Ĝ = WᵀÂ⁻¹W`` and ``G₀ = WᵀM⁻¹W`` and the impulse is applied through the columns of
  ``Â⁻¹W``: O(n|A| + |A|³) per step with |A| closed contacts. Large banded systems
  (:data:`CONTACTS_FACTORED`, n ≥ :data:`observer.stepping.FACTORED_MIN_N`) hold no n×m or
  m×m matrix: ``Ĝ_AA`` and the projection's ``L_A = W_AᵀK⁻¹W_A`` are assembled per step from
  the banded Cholesky factors of Â and K and a bounded cache of solved columns
  (:func:`factored_gram`), and ``δu = Â⁻¹(W_A P)``, ``δq = K⁻¹(W_A Σ)`` are one banded solve
  each: O(n·bw) per contact step, plus O(n·bw) per closed contact not in the cache; memory
  O(n·(bw + cache)).
* **LCPs.** One contact: the closed form ``x = max(0, −b/G)``. Several: block principal
  pivoting (Júdice & Pires with Murty's single-flip backup, finite for P-matrices) on a
  Cholesky-solved basis, the round-off tests of :mod:`observer.contact.lcp`. A solve whose
  relative natural residual ``‖min(x, Gx + b)‖_∞ / max(‖b‖_∞, ‖Gx‖_∞)`` exceeds the
  tolerance, or whose basis is not positive definite, stops the kernel with a nonzero
  status at that step: the caller re-solves that step with the reference solver, records
  it, and resumes (:meth:`observer.engines.timestepping.TimeStepping.advance`).

* **Signals.** f(t), ν(t), ν̇(t) are evaluated in the loop from tables of their harmonic
  terms (:func:`observer.engines.compiled.bundles.signal_tables`), only in the columns that vary, the waves of
  each window computed beforehand (:func:`observer.engines.compiled.bundles.wave_table`, by anchored angle
  addition: the anchors by numpy, :func:`observer.model.grid_anchors`, combined by the
  compiled :func:`fill_waves`, the values of :func:`observer.model.grid_wave`): no n-wide
  signal arrays, the same values bit for bit as the python engine's grid.

* **Health.** After every contact step the complementarity residual is recomputed from the
  velocity actually applied (:func:`applied_residual`: ``Wᵀ(u_{k+1} − u_free)`` in place of
  the solver's ``ĜP``); its largest value and step go to ``stats[5:7]``. A step whose applied
  residual exceeds the tolerance stops the kernel with :data:`RESIDUAL_EXCEEDED` (the caller
  stops the run there, :mod:`observer.loop`).

* **Cost.** The step loop of :func:`advance` (:func:`_advance_loop`) creates no array value
  per step (no views, no tuples, no inlined calls with array arguments: each would be an
  atomic reference-count increment and decrement): systems are rows of the 2-D state arrays,
  indexed in place, the work buffers are allocated once per call, and the steps without
  contacts (the common case) run without a function call. The contact impulse, the banded
  solve and the projection are plain compiled calls; the observers' summary is written in
  the loop (as a call it cost ~36 reference counts per observer step). The common case (the
  master alone, dense, plain records) is a second compiled specialization of the same
  function (``general=None``), in which numba prunes the observers', summary's and
  projection's branches at compile time; with one degree of freedom and one contact,
  :func:`advance_scalar` runs that loop on scalars (numba reloads every array value after
  each store to a record: it cannot tell they do not alias), about twice as fast: the same
  template in its scalar form (:func:`observer.engines.compiled.step.scalar_source`). The entry
  points take their arguments in a few named bundles (:class:`SystemBundle`, …); the step
  loops are generated from one template (:mod:`observer.engines.compiled.step`) and bind each
  field to its name once per call. Every function uses numba's ``error_model="numpy"`` (IEEE
  division, no ``ZeroDivisionError`` branch: every denominator here is positive or guarded),
  whose raise branches would otherwise keep numba's reference-count pruning from removing
  the increments.

Statuses: :data:`OK`, :data:`LCP_FAILED` (the step's contact problem was not solved to
tolerance), :data:`PROJECTION_FAILED` (L_I not positive definite), :data:`RESIDUAL_EXCEEDED`
(the applied impulse violates the impact law beyond the tolerance).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from observer.engines.compiled.step import build, impulse_one  # noqa: F401 (impulse_one: the kernel's)
from observer.primitives import (CONTACTS_DENSE, CONTACTS_FACTORED, EPS, F_DAMP, F_IMP, F_KON,  # noqa: F401
                                 F_MAXIMP, F_MAXINC, F_NINC, F_PROJ, F_VEND, F_VMAX, F_VON, JIT,
                                 LCP_FAILED, OK, PROJECTION_FAILED, RESIDUAL_EXCEEDED, ROUNDOFF, STATS_SIZE,
                                 STRUCTURE_BANDED, STRUCTURE_DENSE, SUMMARY_FIELDS, TINY, _cho_solve,
                                 _cholesky, _wt, _wt_row, applied_residual, csc_arrays, lcp_residual,
                                 predicted_closed, predicted_term, project_closed, project_one,
                                 project_positions)
FACTORED_BLOCK = 64
"""Initial side of the closed-set work matrices with factored contacts (grown in the loop when
more contacts close at once)."""
WAVE_COS, WAVE_SIN, WAVE_MINUS_SIN = 0, 1, 2
WAVE_NAMES = ("cos", "sin", "-sin")
"""Functions of the signal waves, by code: code c is ``WAVE_NAMES[c]``
(:func:`observer.engines.compiled.bundles.signal_tables`, :func:`observer.engines.compiled.bundles.wave_table`)."""


@njit(**JIT)
def solve_lcp(G, b, a, x, basic, infeas, Gs, rhs, sol, Lf, max_iter):
    """Exact LCP solve; returns ``(iterations, status, residual)`` and x in ``x[:a]``.

    One contact: closed form. Several: block principal pivoting started from
    ``{i : b_i < 0}``; every infeasible index (basic with ``x_i < 0``, non-basic with
    ``w_i < −tol``, tol = 16·a·eps·(|b_i| + (|G||x|)_i)) is flipped while their number
    decreases, then three more full flips, then Murty's single flip of the largest index.
    """
    if a == 1:
        g = G[0, 0]
        x[0] = -b[0] / g if b[0] < 0.0 else 0.0
        return 0, OK, lcp_residual(G, b, x, 1)
    for i in range(a):
        basic[i] = b[i] < 0.0
    best = a + 1
    backups = 3
    for it in range(1, max_iter + 1):
        nb = 0
        for i in range(a):
            if basic[i]:
                rhs[nb] = -b[i]
                c = 0
                for j in range(a):
                    if basic[j]:
                        Gs[nb, c] = G[i, j]
                        c += 1
                nb += 1
        if nb > 0 and not _cholesky(Gs, nb, Lf):
            return it, LCP_FAILED, np.inf
        _cho_solve(Lf, nb, rhs, sol)
        c = 0
        for i in range(a):
            if basic[i]:
                x[i] = sol[c]
                c += 1
            else:
                x[i] = 0.0
        count = 0
        for i in range(a):
            gx = 0.0
            ag = 0.0
            for j in range(a):
                gx += G[i, j] * x[j]
                ag += abs(G[i, j]) * abs(x[j])
            tol = ROUNDOFF * a * EPS * (abs(b[i]) + ag)
            if basic[i]:
                bad = x[i] < 0.0                      # exact sign test (observer.contact.lcp)
            else:
                bad = gx + b[i] < -tol
            infeas[i] = bad
            if bad:
                count += 1
            if not np.isfinite(x[i]):
                return it, LCP_FAILED, np.inf
        if count == 0:
            for i in range(a):
                if x[i] < 0.0:
                    x[i] = 0.0
            return it, OK, lcp_residual(G, b, x, a)
        if count < best:
            best = count
            backups = 3
            for i in range(a):
                if infeas[i]:
                    basic[i] = not basic[i]
        elif backups > 0:
            backups -= 1
            for i in range(a):
                if infeas[i]:
                    basic[i] = not basic[i]
        else:
            for i in range(a - 1, -1, -1):
                if infeas[i]:
                    basic[i] = not basic[i]
                    break
    return max_iter, LCP_FAILED, np.inf


@njit(**JIT)
def _solve_counted(G, b, a, x, basic, infeas, Gs, rhs, sol, Lf, max_iter, tol, stats):
    """:func:`solve_lcp`, counted in ``stats`` ([solves, iterations, max residual]); False
    when the solve failed or its residual exceeds ``tol``."""
    it, st, res = solve_lcp(G, b, a, x, basic, infeas, Gs, rhs, sol, Lf, max_iter)
    stats[0] += 1
    stats[1] += it
    if st != OK or not res <= tol:
        return False
    if res > stats[2]:
        stats[2] = res
    return True


# ---------------------------------------------------------------------------------------
# banded symmetric matrices (lower band storage: ab[d, j] = A[j + d, j])
# ---------------------------------------------------------------------------------------
@njit(**JIT, inline="always")
def _band_matvec_add(ab, bw, X, s, out):
    """out += A X[s] for symmetric A in lower band storage."""
    n = X.shape[1]
    for j in range(n):
        out[j] += ab[0, j] * X[s, j]
        for d in range(1, bw + 1):
            i = j + d
            if i >= n:
                break
            a = ab[d, j]
            out[i] += a * X[s, j]
            out[j] += a * X[s, i]


@njit(**JIT, inline="always")
def _band_cho_solve(cb, bw, x):
    """Solve (L Lᵀ) y = x in place, L lower Cholesky factor in band storage."""
    n = x.shape[0]
    for j in range(n):
        x[j] /= cb[0, j]
        for d in range(1, bw + 1):
            i = j + d
            if i >= n:
                break
            x[i] -= cb[d, j] * x[j]
    for j in range(n - 1, -1, -1):
        s = x[j]
        for d in range(1, bw + 1):
            i = j + d
            if i >= n:
                break
            s -= cb[d, j] * x[i]
        x[j] = s / cb[0, j]


@njit(**JIT)
def banded_free_velocity(k, s, qs, us, h, Ru_b, Rq_b, Ach_b, bw, fbar, uf):
    """``u_free`` of system s on the banded path: ``Â u_free = R_u u + R_q q + h f̄_k``."""
    n = qs.shape[1]
    for i in range(n):
        uf[i] = h * fbar[k, i]
    _band_matvec_add(Ru_b, bw, us, s, uf)
    _band_matvec_add(Rq_b, bw, qs, s, uf)
    _band_cho_solve(Ach_b, bw, uf)


@njit(**JIT)
def _applied(Wp, Wi, Wv, act, a, law, uf, du, u1, bvec, x, le, tol, stats):
    """The velocity after an impulse, ``u1 = u_free + δu``, and its applied residual
    (:func:`applied_residual`, into ``stats[7]``): the status of the step
    (:data:`RESIDUAL_EXCEEDED` beyond ``tol``). The end of :func:`contact_impulse` and of
    :func:`factored_impulse`."""
    for i in range(uf.shape[0]):
        u1[i] = uf[i] + du[i]
    res = applied_residual(Wp, Wi, Wv, act, a, du, bvec, x if (law == 0 or a == 1) else le)
    stats[7] = res
    if not res <= tol:
        return RESIDUAL_EXCEEDED
    return OK


@njit(**JIT)
def contact_impulse(k, s, us, uf, act, a, law, W, nu_dot, AinvWT, Ghat, e, tol, stats, work, mats, u1, P):
    """The impulse of system s's step on the closed set ``act[:a]`` (a ≥ 1) and its velocity.

    The closed set's block of the precomputed Ĝ, the impact law's impulse on it
    (:func:`_law_impulse`); writes ``P[:a]``, ``u1 = u_free + δu`` with
    ``δu = Σ_j (Â⁻¹W)_j P_j`` summed once, and the applied residual
    (:func:`applied_residual`) in ``stats[7]``; returns the status. ``W`` is ``(Wp, Wi, Wv)``,
    ``work`` the buffers ``(gk, bvec, x, lc, le, gc, rhs, sol, basic, infeas, du)`` ((m,), du
    (n,)) and ``mats`` ``(G, Gs, Lf)`` ((m, m)): separate arrays, not views (a view costs a
    reference count).
    """
    Wp, Wi, Wv = W
    x, le, du = work[2], work[4], work[10]
    bvec, G = work[1], mats[0]
    n = uf.shape[0]
    for r in range(a):
        for c in range(a):
            G[r, c] = Ghat[act[r], act[c]]
    status = _law_impulse(k, s, us, uf, act, a, law, W, nu_dot, e, tol, stats, work, mats)
    if status != OK:
        return status
    for i in range(n):
        du[i] = 0.0
    for r in range(a):                                       # δu = Σ_j (Â⁻¹W)_j P_j, once
        P[r] = x[r]
        j = act[r]
        for i in range(n):
            du[i] += AinvWT[j, i] * x[r]
    return _applied(Wp, Wi, Wv, act, a, law, uf, du, u1, bvec, x, le, tol, stats)


@njit(**JIT)
def _law_impulse(k, s, us, uf, act, a, law, W, nu_dot, e, tol, stats, work, mats):
    """The impact law's impulse on the closed set ``act[:a]`` with its Delassus block
    ``G[:a, :a] = Ĝ_AA`` into ``x[:a]``; the LCP's right-hand side stays in ``bvec`` (and, for
    Poisson on several contacts, μ = Λ_E − ε∘Λ_C in ``le``) for the applied residual.

    Newton (``law == 0``), and Poisson on one contact (the same map): ``LCP(Ĝ, γ_free + e∘γ_k)``;
    Poisson on several: Glocker's compression and expansion phases. Returns the status
    (``W``, ``work``, ``mats``: :func:`contact_impulse`).
    """
    Wp, Wi, Wv = W
    gk, bvec, x, lc, le, gc, rhs, sol, basic, infeas, _ = work
    G, Gs, Lf = mats
    max_iter = max(200, 20 * a)
    for r in range(a):
        j = act[r]
        gk[r] = _wt_row(Wp, Wi, Wv, us, s, j) + nu_dot[k, j]
        gc[r] = _wt(Wp, Wi, Wv, uf, j) + nu_dot[k + 1, j]                   # γ_free
    newton = law == 0 or a == 1
    if newton:
        for r in range(a):
            bvec[r] = gc[r] + e[act[r]] * gk[r]
        if not _solve_counted(G, bvec, a, x, basic, infeas, Gs, rhs, sol, Lf, max_iter, tol, stats):
            return LCP_FAILED
        return OK
    # Poisson: Glocker's phases with Ĝ on γ̃ = (γ_free + ε∘γ_k)/(1+ε)
    for r in range(a):
        er = e[act[r]]
        bvec[r] = (gc[r] + er * gk[r]) / (1.0 + er)
    if not _solve_counted(G, bvec, a, lc, basic, infeas, Gs, rhs, sol, Lf, max_iter, tol, stats):
        return LCP_FAILED
    for r in range(a):                                   # γ_C = γ̃ + ĜΛ_C
        acc = 0.0
        for c in range(a):
            acc += G[r, c] * lc[c]
        gc[r] = bvec[r] + acc
    for r in range(a):                                   # γ_C + Ĝ(ε∘Λ_C)
        acc = 0.0
        for c in range(a):
            acc += G[r, c] * (e[act[c]] * lc[c])
        le[r] = gc[r] + acc
    if not _solve_counted(G, le, a, x, basic, infeas, Gs, rhs, sol, Lf, max_iter, tol, stats):
        return LCP_FAILED
    for r in range(a):                                   # P = Λ_C + (ε∘Λ_C + μ)
        le[r] = x[r]                                     # μ = Λ_E − ε∘Λ_C, kept
        x[r] = lc[r] + (e[act[r]] * lc[r] + x[r])
    return OK


# ---------------------------------------------------------------------------------------
# factored contact data (CONTACTS_FACTORED): large banded systems, no n×m or m×m matrix
# ---------------------------------------------------------------------------------------
@njit(**JIT)
def _factored_column(j, Wp, Wi, Wv, fac, bw, cache, slot_of, owner, stamp, col):
    """The row of ``cache`` that holds ``N⁻¹W_j`` (N = L Lᵀ, ``fac`` its lower banded Cholesky
    factor), solved into the least recently used row not used since the clock ``stamp[-1]``
    last ticked; −1 when every row is in use (the column is then solved into ``col``).

    ``slot_of`` (m,) maps a contact to its row (−1: none), ``owner`` (C,) a row to its contact
    (−1: none), ``stamp`` (C + 1,) each row's last use and, last, the clock. O(n·bw) on a miss,
    O(1) on a hit.
    """
    C = owner.shape[0]
    clock = stamp[C]
    c = slot_of[j]
    if c < 0:
        best = clock
        for r in range(C):
            if stamp[r] < best:
                best = stamp[r]
                c = r
        if c >= 0:
            if owner[c] >= 0:
                slot_of[owner[c]] = -1
            owner[c] = j
            slot_of[j] = c
        n = col.shape[0]
        for i in range(n):
            col[i] = 0.0
        for p in range(Wp[j], Wp[j + 1]):
            col[Wi[p]] = Wv[p]
        _band_cho_solve(fac, bw, col)
        if c >= 0:
            for i in range(n):
                cache[c, i] = col[i]
    if c >= 0:
        stamp[c] = clock
    return c


@njit(**JIT)
def factored_gram(act, a, Wp, Wi, Wv, fac, bw, cache, slot_of, owner, stamp, col, G):
    """``G[:a, :a] = sym(W_AᵀN⁻¹W_A)`` for the closed set ``act[:a]`` from the banded Cholesky
    factor of N (Ĝ with N = Â, L_A with N = K, paper eqs. (13)-(14)): one banded solve per
    column not in the cache (:func:`_factored_column`), then O(a·nnz(W_A)); symmetrized as
    the dense ``0.5(Ĝ + Ĝᵀ)`` is."""
    C = owner.shape[0]
    stamp[C] += 1                                        # a new use: this set's rows are kept
    for r in range(a):
        c = _factored_column(act[r], Wp, Wi, Wv, fac, bw, cache, slot_of, owner, stamp, col)
        for q in range(a):
            j = act[q]
            acc = 0.0
            if c >= 0:
                for p in range(Wp[j], Wp[j + 1]):
                    acc += Wv[p] * cache[c, Wi[p]]
            else:
                for p in range(Wp[j], Wp[j + 1]):
                    acc += Wv[p] * col[Wi[p]]
            G[q, r] = acc
    for r in range(a):
        for q in range(r + 1, a):
            v = 0.5 * (G[r, q] + G[q, r])
            G[r, q] = v
            G[q, r] = v


@njit(**JIT)
def _factored_apply(act, a, Wp, Wi, Wv, fac, bw, x, out):
    """``out = N⁻¹(W_A x)`` by one banded solve (O(n·bw))."""
    n = out.shape[0]
    for i in range(n):
        out[i] = 0.0
    for r in range(a):
        j = act[r]
        for p in range(Wp[j], Wp[j + 1]):
            out[Wi[p]] += Wv[p] * x[r]
    _band_cho_solve(fac, bw, out)


@njit(**JIT)
def factored_impulse(k, s, us, uf, act, a, law, W, nu_dot, Ach_b, bw, cache, e, tol, stats, work, mats, u1, P,
                     col):
    """:func:`contact_impulse` without the n×m ``Â⁻¹W`` and the m×m Ĝ: ``Ĝ_AA`` from the banded
    factor of Â (:func:`factored_gram`, cached columns ``Acache``) and ``δu = Â⁻¹(W_A P)``
    by one banded solve: O(n·bw) per contact step plus O(n·bw) per uncached closed contact.
    ``cache`` is ``(Acache, Aslot, Aowner, Astamp)``; ``W``, ``work``, ``mats`` as there."""
    Wp, Wi, Wv = W
    Acache, Aslot, Aowner, Astamp = cache
    x, le, du = work[2], work[4], work[10]
    bvec, G = work[1], mats[0]
    factored_gram(act, a, Wp, Wi, Wv, Ach_b, bw, Acache, Aslot, Aowner, Astamp, col, G)
    status = _law_impulse(k, s, us, uf, act, a, law, W, nu_dot, e, tol, stats, work, mats)
    if status != OK:
        return status
    for r in range(a):
        P[r] = x[r]
    _factored_apply(act, a, Wp, Wi, Wv, Ach_b, bw, x, du)
    return _applied(Wp, Wi, Wv, act, a, law, uf, du, u1, bvec, x, le, tol, stats)


@njit(**JIT)
def factored_project(k, act, a, slot, W, nu, Kch, bwk, cache, q1, sig, g, s_, Gp, Lf, col):
    """:func:`project_positions` from the banded factor of the metric (``Kch[slot]``, eqs.
    (13)-(14)): ``L_A`` by :func:`factored_gram` (cached columns ``Kcache[slot]``) and
    ``q1 += N⁻¹(W_A Σ)`` by one banded solve. Returns the status (:data:`PROJECTION_FAILED`
    when L_A is not positive definite, a singular factor included). ``W`` is ``(Wp, Wi, Wv)``,
    ``cache`` ``(Kcache, Kslot, Kowner, Kstamp)``."""
    Wp, Wi, Wv = W
    Kcache, Kslot, Kowner, Kstamp = cache
    for r in range(a):
        g[r] = _wt(Wp, Wi, Wv, q1, act[r]) + nu[k, act[r]]
    factored_gram(act, a, Wp, Wi, Wv, Kch[slot], bwk, Kcache[slot], Kslot[slot], Kowner[slot], Kstamp[slot],
                  col, Gp)
    if not _cholesky(Gp, a, Lf):
        return PROJECTION_FAILED
    _cho_solve(Lf, a, g, s_)
    for r in range(a):
        s_[r] = -s_[r]
        sig[r] = s_[r]
    _factored_apply(act, a, Wp, Wi, Wv, Kch[slot], bwk, s_, col)
    for i in range(q1.shape[0]):
        q1[i] += col[i]
    return OK


@njit(**JIT)
def fill_waves(ca, sa, cb, sb, function, k0, out):
    """The waves of a window by angle addition (:func:`observer.model.grid_wave`'s values, bit
    for bit): ``out[p, k − k0] = function_p(A_a + β_j)`` for the grid points k = aB + j of the
    window, k0 ≤ k < k0 + out.shape[1], B = ``cb.shape[1]``;
    ``cos(A_a + β_j) = cos A_a cos β_j − sin A_a sin β_j``,
    ``sin(A_a + β_j) = sin A_a cos β_j + cos A_a sin β_j`` (−sin: its negation), each product
    rounded and then added or subtracted, as numpy's outer products do. Row p of ``ca``, ``sa``
    holds wave p's anchors from block k0 // B on, of ``cb``, ``sb`` its β_j
    (:func:`observer.model.grid_anchors`, evaluated by numpy: numba's trigonometric functions
    may round differently). Compiled, the angle addition itself costs little next to the
    anchors' numpy calls, which remain; together they cost somewhat less than the table by
    numpy's outer products (issue 21)."""
    P, K = out.shape
    B = cb.shape[1]
    a0 = k0 // B
    k1 = k0 + K - 1
    for p in range(P):
        fn = function[p]
        for a in range(a0, k1 // B + 1):
            x = ca[p, a - a0]
            y = sa[p, a - a0]
            o = a * B - k0
            j0, j1 = max(k0 - a * B, 0), min(k1 - a * B, B - 1) + 1
            if fn == WAVE_COS:                      # the function chosen per block, not per point
                for j in range(j0, j1):
                    out[p, o + j] = x * cb[p, j] - y * sb[p, j]
            elif fn == WAVE_SIN:
                for j in range(j0, j1):
                    out[p, o + j] = y * cb[p, j] + x * sb[p, j]
            else:
                for j in range(j0, j1):
                    out[p, o + j] = -(y * cb[p, j] + x * sb[p, j])


@njit(**JIT, inline="always")
def _quad(structure, A, x, o, n, bw):
    """yᵀAy with ``y = x[o:o + n]``, for dense A or symmetric A in lower band storage."""
    acc = 0.0
    if structure == STRUCTURE_DENSE:
        for i in range(n):
            r = 0.0
            for j in range(n):
                r += A[i, j] * x[o + j]
            acc += x[o + i] * r
    else:
        for j in range(n):
            acc += A[0, j] * x[o + j] * x[o + j]
            for d in range(1, bw + 1):
                i = j + d
                if i >= n:
                    break
                acc += 2.0 * A[d, j] * x[o + i] * x[o + j]
    return acc


@njit(**JIT, inline="always")
def _summary_sample(kg, V, s, summ, k_on, k_off, rhos):
    """Fold the sample V(t_kg) of observer s into its summary row (the first sample,
    :func:`summary_start`; the step loop :func:`_advance_loop` does the same operations in
    place, since a call there costs reference counts per observer step)."""
    nr = rhos.shape[0]
    summ[s, F_VEND] = V
    if kg < k_on or kg > k_off:
        return
    if kg == k_on:
        summ[s, F_VON] = V
        summ[s, F_KON] = kg
        summ[s, F_VMAX] = V
    if V > summ[s, F_VMAX]:
        summ[s, F_VMAX] = V
    V0 = summ[s, F_VON]
    for i in range(nr):
        below = V <= rhos[i] * V0
        if below and summ[s, SUMMARY_FIELDS + i] < 0:
            summ[s, SUMMARY_FIELDS + i] = kg
        if not below:
            summ[s, SUMMARY_FIELDS + nr + i] = kg


@njit(**JIT)
def summary_start(state, system, tally):
    """The summary's first sample: V(t_0) of every observer, and v_0 for the damping part
    (:class:`StateBundle`, :class:`SystemBundle`, :class:`SummaryBundle`)."""
    qs, us = state.qs, state.us
    structure, bw = system.structure, system.bw
    Mq, Kq, vprev, Vprev, summ = tally.Mq, tally.Kq, tally.vprev, tally.Vprev, tally.summ
    k_on, k_off, rhos, rec_V = tally.k_on, tally.k_off, tally.rhos, tally.rec_V
    S, n = qs.shape
    wv = np.empty(n)
    for s in range(1, S):
        for i in range(n):
            wv[i] = us[s, i] - us[0, i]
            vprev[s, i] = wv[i]
        V = 0.5 * _quad(structure, Mq, wv, 0, n, bw)
        for i in range(n):
            wv[i] = qs[s, i] - qs[0, i]
        V += 0.5 * _quad(structure, Kq, wv, 0, n, bw)
        Vprev[s] = V
        rec_V[s, 0] = V
        _summary_sample(0, V, s, summ, k_on, k_off, rhos)


# ---------------------------------------------------------------------------------------
# the loop: master (system 0) and observers (1..S-1)
# ---------------------------------------------------------------------------------------
def advance(k0, k1, s0, system, impact, signals, window, observers, state, storage, tally, general):
    """Advance every system from step k0 (starting with system s0) up to step k1.

    One Moreau–Jean step of system s (row s of ``qs``, ``us``) on its closed set A: the
    master's from Siconos' predictor ``g_k + (h/2)γ_k ≤ 0`` (projected when
    ``master_projection``), an observer's χ_k while coupled (projected when ``jumps[s]``),
    else its own predicted set; ``u_free`` (dense ``Bu u + Bq q + Bf f̄``, or the banded
    solve), the impulse of the impact law on A (:func:`contact_impulse`),
    ``q_{k+1} = q_k + h((1−θ)u_k + θu_{k+1})`` and the position jump
    (:func:`project_positions`). The n×m matrices come transposed (a contact's column
    contiguous); ``KinvWT`` (N⁻¹W)ᵀ and ``L`` WᵀN⁻¹W are stacks over the projection
    metrics, ``slots[s]`` selects system s's.

    The signals f, ν and ν̇ are evaluated here at every grid point t_k = t0 + k·h from their
    tables (:func:`observer.engines.compiled.bundles.signal_tables`): ``waves`` holds the distinct waves
    ``function(ω t_k + phase)`` of the window (column k − kb, :func:`observer.engines.compiled.bundles.wave_table`:
    the trigonometric calls stay out of the step loop); per signal, its entries ``(column,
    coefficient, wave)`` in the summation order of :class:`observer.model.Harmonic` (so the
    values are those of :meth:`observer.stepping.Grid.window` bit for bit) and its varying
    columns; f̄_k = (1−θ)f(t_k) + θf(t_{k+1}). Only the varying columns are evaluated per step
    (the others keep their constant): O(columns with a harmonic term + entries) per step.
    ``coupled`` and ``chi_log`` are a window of the grid starting at step ``kb`` (row k − kb
    holds step k). ``qs``, ``us`` (S, n) hold the current states and are updated in place;
    ``chi_now`` (m,) the closed set fed to the observers at the current step (the master's, or
    the log's). Row r of the records holds
    step ``r·record_every`` (row 0: the initial state, written by the caller); impulses and
    multipliers are those of the step ending at the row. ``rec_P``, ``rec_sig`` and ``rec_act``
    come zero-filled (each row is written once: only the closed contacts' entries are set).

    With ``summary``, every step also updates the streaming summary of each observer
    (:data:`SUMMARY_FIELDS`, coupling window = grid samples k_on..k_off, thresholds ``rhos``),
    records V at the recorded rows (``rec_V``), and counts the master's closings per contact.
    ``stats`` (:data:`STATS_SIZE`) = [solves, iterations, max residual, min gap after a step,
    its step, max applied residual, its step, last applied residual].

    ``general`` selects the compiled specialization: ``True`` the loop as described; ``None``
    the lean loop of the common case — the master alone (S = 1), dense structure, no summary,
    no pre-projection records, no master projection — where numba prunes every other branch
    at compile time (the same operations on the same values: bitwise the same trajectory, a
    shorter step). The caller passes ``None`` only in that case
    (:func:`observer.engines.compiled.bundles.specialization`).

    Returns ``(k, s, status)``: ``status == OK`` and k = k1 when done; otherwise the step and
    system that failed (their state untouched).

    The loop is generated from the step's template (:mod:`observer.engines.compiled.step`:
    the same source as the members' loop) and takes the bundles: ``system``
    (:class:`SystemBundle`), ``impact`` (:class:`LawBundle`), ``signals``
    (:class:`SignalBundle`), ``window`` (:class:`WindowBundle`), ``observers``
    (:class:`ObserverBundle`), ``state`` (:class:`StateBundle`, advanced in place), ``storage``
    (:class:`StorageBundle`, the records written in place) and ``tally``
    (:class:`SummaryBundle`), each field bound to its name once per call
    (:data:`observer.engines.compiled.step.KERNEL_FIELDS`). This is a Python function on
    purpose: a compiled wrapper gets the loop inlined into it by LLVM, which compiles it again,
    differently.
    """
    return _advance_loop(k0, k1, s0, system, impact, signals, window, observers, state, storage, tally, general)


_advance_loop = build("_advance_loop", globals())
"""The step loop of :func:`advance`, generated from the step's template
(:func:`observer.engines.compiled.step.kernel_source`)."""


def advance_model(k0, k1, s0, system, impact, signals, window, observers, state, storage, tally, model):
    """:func:`advance` (general specialization) with the observers on a model of their own: the
    master (system 0) steps on ``system``, ``impact`` and ``signals`` (the plant), every
    observer on the arrays of ``model`` (:class:`observer.engines.compiled.bundles.ModelBundle`:
    its scheme's matrices, W, (Â⁻¹W)ᵀ, Ĝ, impact law, signal tables and the window's waves),
    fed χ_k from the plant; ``observers`` holds the projection metrics of each system's own
    model. The loop, :func:`_advance_model_loop`, is :func:`_advance_loop`'s template with the
    per-system binding (:func:`observer.engines.compiled.step.model_form`): the loops of a run
    without a model are not changed by it. Dense structure and contacts only. Returns
    ``(k, s, status)`` as :func:`advance`."""
    return _advance_model_loop(k0, k1, s0, system, impact, signals, window, observers, state, storage, tally,
                               True, model)


_advance_model_loop = build("_advance_model_loop", globals())
""":func:`advance_model`'s loop (:func:`observer.engines.compiled.step.model_source`)."""


# ---------------------------------------------------------------------------------------
# the scalar loop: one degree of freedom, one contact, the master alone
# ---------------------------------------------------------------------------------------
def advance_scalar(k0, k1, system, impact, signals, window, state, storage):
    """:func:`advance` for n = m = 1 (the master alone, dense): the scalar step loop
    :func:`_advance_scalar_loop` (the state in registers; bitwise the same trajectory) fed by
    the same bundles: the arrays it reads per step passed by name, the rest in three tuples
    (the grid's t0, h, θ; the signals' pointers; the scheme's and contact's arrays with the
    tolerance): passing the bundles themselves, unpacked in the loop, made its step measurably
    slower (``python -m bench.revisions --problem`` measures it). Writes
    the rows' times into ``storage.t`` when it has a row per record. Returns ``(k, 0, status)``.
    """
    return _advance_scalar_loop(
        k0, k1, window.kb, state.qs, state.us, storage.record_every, storage.q, storage.u, storage.P,
        storage.active, storage.t, (system.t0, system.h, system.theta), window.waves, (signals.e_ptr, signals.v_ptr),
        signals.e_coef, signals.e_wave, signals.f_c, signals.nu_c,
        (system.Bu, system.Bq, system.Bf, system.Wp, system.Wi, system.Wv, system.AinvWT, system.Ghat, impact.e,
         impact.tol), state.stats)


_advance_scalar_loop = build("_advance_scalar_loop", globals())
""":func:`advance`'s lean loop for n = m = 1 (the master alone, dense), generated from the same
template as :func:`_advance_loop` (:func:`observer.engines.compiled.step.scalar_source`): the same
operations on the same values, with the state, the signals and the scheme's 1×1 matrices held
in scalars instead of arrays (numba cannot tell that a store to a record does not change an
array it reads, and reloads every array value after each store; scalars stay in registers).
Bitwise the same trajectory as :func:`advance`; the same return value ``(k, 0, status)``, the
state written back to ``qs``, ``us`` at the end and on a failed step. When ``rec_t`` has a row
per record (else it is empty), each recorded row's time ``t0 + k·h`` is written there too,
computed as :meth:`observer.stepping.MoreauJean.time` computes it (bitwise its values).

``grid`` is ``(t0, h, θ)``, ``ptrs`` ``(e_ptr, v_ptr)`` and ``contact`` ``(Bu, Bq, Bf, Wp, Wi,
Wv, AinvWT, Ghat, e, tol)`` (:func:`advance_scalar`). A contact step calls :func:`impulse_one` on
one-element buffers. Called only by :func:`advance_scalar`."""
