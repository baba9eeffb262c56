"""An ensemble's members after one master run: each observer advanced alone over the whole grid.

The observers of a run are independent given the master (paper eqs. (7)-(11)): what an
observer's step reads from the rest of the run is χ_k (the master's closed set, or the log's),
the master's state and impulse after the step (for V and its impulse part) and the signals
f̄_k, ν, ν̇ at the grid points. :func:`member_summaries` runs the master once with the
compiled kernel (:meth:`observer.engines.timestepping.TimeStepping.advance`, every step recorded), tabulates those quantities
per step (:func:`master_tables`), and then advances every member over the whole grid in
:func:`advance_members`, a compiled loop with the member's state in cache and no other
system's work per step; chunks of members run in threads (``nogil``).

:func:`advance_members` performs, per observer step, the operations of the observer branch
of :func:`observer.engines.compiled.kernel._advance_loop` in the same order on the same values (dense
structure and contact data, the streaming summary): the kernel's own functions for several
closed contacts (:func:`~observer.engines.compiled.kernel.contact_impulse`,
:func:`~observer.primitives.project_positions`) and, for one, the operations of
:func:`~observer.engines.compiled.kernel.impulse_one` and :func:`~observer.primitives.project_one` written inline
(a call with their array arguments cost reference counts on every contact step, a large
part of the loop's time on double_mass). Member i's summary is bitwise that of a single :func:`observer.simulate` of
that member (``tests/observer/test_ensemble_members.py`` checks every branch against single
runs: a change to the kernel's observer step must be made here too). The master alone takes
the kernel's lean specialization, whose trajectory is bitwise the general loop's
(:func:`observer.engines.compiled.bundles.specialization`).

With an observer model distinct from the plant (:mod:`observer.plant_model`) the master run is
the plant's and the members advance on the nominal model: :func:`observers_input` hands
:func:`advance_members` the model's matrices, signal tables, law and projection metrics (the
same loop, other data), and V is measured against the plant's recorded state.

A run this path does not cover returns None, and :mod:`observer.ensemble` takes the kernel's
run of the chunk instead (:func:`applicable` says which): banded or factored structure, a
master that stops or needs the reference solver, a member whose contact step fails or whose
state or summary is not finite (:class:`observer.engines.loop.FiniteGuard`; the kernel's run then
reports it the way a single run does).
"""

from __future__ import annotations

import types
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from observer.engines.compiled.bundles import (law_bundle, observer_bundle, signal_tables, state_bundle,
                                               summary_bundle, system_bundle, wave_table)
from observer.engines.compiled import driver
from observer.engines.compiled.driver import run_compiled
from observer.engines.compiled.kernel import contact_impulse, summary_start
from observer.engines.loop import FiniteGuard, LoopInput, summary_frame
from observer.metrics import RHOS
from observer.primitives import (CONTACTS_DENSE, F_DAMP, F_IMP, F_KON, F_MAXIMP, F_MAXINC, F_NINC, F_PROJ, F_VEND,
                                 F_VMAX, F_VON, JIT, LCP_FAILED, OK, PROJECTION_FAILED, RESIDUAL_EXCEEDED,
                                 STATS_SIZE, STRUCTURE_DENSE, SUMMARY_FIELDS, TINY, predicted_closed,
                                 predicted_term, project_positions)

SPECIALIZE_STEPS = 50_000_000
"""Observer steps (members × designs × steps) from which :func:`advance_members` is compiled
for the run's n and m (:func:`sizes`): the specialization costs a compilation once per
machine (numba's disk cache) and saves time on every observer step (double_mass); from this
many observer steps on, the saving outweighs the compilation."""
SPECIALIZE_MAX_N = 8
"""Largest n (and m) compiled as constants (the loops over them unrolled)."""

MASTER_VALUES = 1 << 25
"""Most values the per-step tables of the master may hold (q, u, P, χ, f̄, ν, ν̇ per step:
256 MiB); a longer or larger run takes the kernel's chunks instead."""


def applicable(stepper, system_bundle_, steps: int) -> bool:
    """Whether :func:`advance_members` covers the run: dense structure and contact data, and
    per-step tables of at most :data:`MASTER_VALUES` values."""
    n, m = stepper.system.n, stepper.system.m
    return (system_bundle_.structure == STRUCTURE_DENSE and system_bundle_.contacts == CONTACTS_DENSE
            and (steps + 1) * (3 * n + 4 * m) <= MASTER_VALUES)


def sizes(n: int, m: int, nr: int, observer_steps: int) -> tuple[tuple, tuple, tuple]:
    """The size arguments of :func:`advance_members`: n and m as compile-time constants when
    the run has at least :data:`SPECIALIZE_STEPS` observer steps and n, m ≤
    :data:`SPECIALIZE_MAX_N`, else empty (one compiled loop for every other size); the number
    of thresholds always (it is the same for every run)."""
    special = observer_steps >= SPECIALIZE_STEPS and max(n, m) <= SPECIALIZE_MAX_N
    return ((0,) * n if special else (), (0,) * m if special else (), (0,) * nr)


def signal_tables_on_grid(inp, signals, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """f̄_k (steps, n), ν(t_k) and ν̇(t_k) (steps + 1, m) on the whole grid, with the operations
    of the kernel's signal evaluation (:func:`observer.engines.compiled.kernel._advance_loop`): a constant plus
    each entry ``coefficient · wave`` in summation order, ``f̄_k = (1−θ)f(t_k) + θf(t_{k+1})``;
    the waves from :func:`observer.engines.compiled.bundles.wave_table` per kernel window
    (:data:`observer.engines.compiled.driver.WINDOW`), as the kernel reads them."""
    st = inp.stepper
    n, m, theta = st.system.n, st.system.m, float(st.theta)
    FB = np.empty((steps, n))
    NU = np.empty((steps + 1, m))
    NUD = np.empty((steps + 1, m))
    e_ptr, cols, coef, wave = signals.e_ptr, signals.e_col, signals.e_coef, signals.e_wave
    window = driver.WINDOW                  # read per call: a test may shorten it
    for kb in range(0, max(steps, 1), window):
        k1 = min(steps, kb + window)
        waves = wave_table(st.t0, st.h, kb, k1, signals.omega, signals.phase, signals.function)
        F = np.empty((k1 - kb + 1, n))
        F[:] = signals.f_c
        NU[kb:k1 + 1] = signals.nu_c
        NUD[kb:k1 + 1] = 0.0
        for out, lo, hi in ((F, e_ptr[0], e_ptr[1]), (NU[kb:k1 + 1], e_ptr[1], e_ptr[2]),
                            (NUD[kb:k1 + 1], e_ptr[2], e_ptr[3])):
            for i in range(lo, hi):
                out[:, cols[i]] += coef[i] * waves[wave[i]]
        FB[kb:k1] = (1.0 - theta) * F[:-1] + theta * F[1:]
    return FB, NU, NUD


def master_tables(inp, steps: int):
    """The master's run (kernel, every step) and what its observers read per step: χ_k (steps, m)
    and the coupling of step k (steps,), both as the kernel's windows give them
    (:func:`observer.engines.compiled.bundles.window_bundle`), and the master's q, u, P after each step
    (rows 1..steps). Returns None when the master stops or a step needed the reference solver."""
    st = inp.stepper
    alone = LoopInput(st, inp.q0[:1], inp.u0[:1], np.zeros(1, np.bool_), inp.master_projection)
    out = run_compiled(alone, 1, False, rhos=tuple(RHOS))
    if out.stopped_at is not None or out.fallbacks:
        return None
    chi = np.empty((steps, st.system.m), np.bool_)
    coupled = np.empty(steps, np.bool_)
    window = driver.WINDOW
    for kb in range(0, steps, window):
        k1 = min(steps, kb + window)
        t = st.time(np.arange(kb, k1 + 1))
        coupled[kb:k1] = inp.coupled(t)
        log = inp.chi_window(t, kb)
        chi[kb:k1] = out.active[kb + 1:k1 + 1] if log is None else log
    c = np.ascontiguousarray
    return c(out.q[0]), c(out.u[0]), c(out.P[0]), chi, coupled


@njit(**JIT)
def advance_members(n_, m_, r_, j0, j1, steps, QM, UM, PM, CHI, COUP, FB, NU, NUD, qs, us, jumps, slots,
                    master_projection, k_on, k_off, rhos, summ, vprev, Vprev, Mq, Kq, Cq, law, h, theta,
                    Bu, Bq, Bf, Wp, Wi, Wv, AinvWT, Ghat, KinvWT, L, e, tol, path_row, every, rec_V):
    """Advance observers j0..j1−1 (rows of ``qs``, ``us``, ``summ``; the master is row 0 and
    not advanced) over steps 0..steps−1; ``n_``, ``m_``, ``r_`` are tuples of n, m and
    ``len(rhos)`` zeros, so that these sizes are compile-time constants of the specialization
    (its loops unrolled: faster per step of double_mass than with n and m from the
    arrays), or empty for n and m taken from the arrays (:func:`sizes`). Returns the first
    observer whose step failed and the step, as ``(s, k, status)`` (``status == OK``: all
    done).

    Per observer step, the operations of the observer branch of
    :func:`observer.engines.compiled.kernel._advance_loop` on a dense system in the same order: the closed set
    (χ_k of ``CHI`` while ``COUP[k]``, projected when ``jumps[s]``; else the observer's own
    predicted set with ν(t_k), ν̇(t_k), projected when ``master_projection``), u_free, the
    impulse (one contact: :func:`~observer.engines.compiled.kernel.impulse_one`'s operations inline; several:
    :func:`~observer.engines.compiled.kernel.contact_impulse`), the positions and their jump (one contact:
    :func:`~observer.primitives.project_one`'s operations inline; several:
    :func:`~observer.primitives.project_positions`; metric slot ``slots[s]``), then the streaming
    summary (:data:`observer.primitives.SUMMARY_FIELDS`) against the master's state and impulse
    after the step (``QM``, ``UM``, ``PM`` rows k + 1, :func:`master_tables`); the signals
    are the tables of :func:`signal_tables_on_grid` read at the global step (the kernel's
    functions index them by the same k). With ``path_row[s] ≥ 0`` V is recorded after every
    ``every``-th step in ``rec_V[path_row[s]]`` (row 0, V(t_0), by the caller).

    One function because it is the hot loop (one observer step, ~30 flops for two degrees of
    freedom): every piece as a call would cost reference counts per step, as in the kernel.
    """
    n = len(n_) if len(n_) > 0 else qs.shape[1]     # compile-time constants when given
    m = len(m_) if len(m_) > 0 else Wp.shape[0] - 1
    nr = len(r_)
    act = np.empty(m, np.int64)
    uf, q1, u1 = np.empty(n), np.empty(n), np.empty(n)
    P, sig = np.zeros(m), np.zeros(m)
    wv = np.empty(2 * n + m)
    gk, bvec, x, lc, le = np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    gc, rhs, sol, gp, sp_ = np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m)
    G, Gs, Lf, Gp = np.empty((m, m)), np.empty((m, m)), np.empty((m, m)), np.empty((m, m))
    du = np.empty(n)
    basic, infeas = np.zeros(m, np.bool_), np.zeros(m, np.bool_)
    stats = np.zeros(STATS_SIZE)
    marks = np.empty(2 * nr)
    for s in range(j0, j1):
        prow = path_row[s]
        Vlast = Vprev[s]                        # the summary row in registers, written back below
        von, vmax, vend, kon = summ[s, F_VON], summ[s, F_VMAX], summ[s, F_VEND], summ[s, F_KON]
        ninc, maxinc, maximp = summ[s, F_NINC], summ[s, F_MAXINC], summ[s, F_MAXIMP]
        damp, imp, proj = summ[s, F_DAMP], summ[s, F_IMP], summ[s, F_PROJ]
        for i in range(2 * nr):
            marks[i] = summ[s, SUMMARY_FIELDS + i]
        for k in range(steps):
            if COUP[k]:                                     # the closed set A = act[:a]
                a = 0
                for j in range(m):
                    if CHI[k, j]:
                        act[a] = j
                        a += 1
                project = jumps[s]
            else:
                a = 0                                       # Siconos' predictor
                for j in range(m):
                    g = 0.0
                    for p in range(Wp[j], Wp[j + 1]):
                        g += predicted_term(Wv[p], qs[s, Wi[p]], us[s, Wi[p]], h)
                    if predicted_closed(g, NU[k, j], NUD[k, j], h):
                        act[a] = j
                        a += 1
                project = master_projection
            for i in range(n):                              # u_free, and the free step
                s1 = 0.0
                s2 = 0.0
                s3 = 0.0
                for j in range(n):
                    s1 += Bu[i, j] * us[s, j]
                for j in range(n):
                    s2 += Bq[i, j] * qs[s, j]
                for j in range(n):
                    s3 += Bf[i, j] * FB[k, j]
                ufi = s1 + s2 + s3
                uf[i] = ufi
                if a == 0:
                    u1[i] = ufi
                    q1[i] = qs[s, i] + h * ((1.0 - theta) * us[s, i] + theta * ufi)
            if a > 0:                                       # the impulse, the positions
                if a == 1:                                  # impulse_one's operations, inline
                    j = act[0]
                    gk1 = 0.0
                    for p in range(Wp[j], Wp[j + 1]):
                        gk1 += Wv[p] * us[s, Wi[p]]
                    gk1 = gk1 + NUD[k, j]
                    gc1 = 0.0
                    for p in range(Wp[j], Wp[j + 1]):
                        gc1 += Wv[p] * uf[Wi[p]]
                    gc1 = gc1 + NUD[k + 1, j]
                    gjj = Ghat[j, j]
                    b1 = gc1 + e[j] * gk1
                    x1 = -b1 / gjj if b1 < 0.0 else 0.0
                    gx = 0.0 + gjj * x1
                    v1 = abs(min(x1, gx + b1))
                    res = (v1 if v1 > 0.0 else 0.0) / max(abs(b1) if abs(b1) > 0.0 else 0.0,
                                                          abs(gx) if abs(gx) > 0.0 else 0.0, TINY)
                    for i in range(n):
                        u1[i] = uf[i] + (0.0 + AinvWT[j, i] * x1)
                    P[0] = x1
                    d1 = 0.0
                    for p in range(Wp[j], Wp[j + 1]):
                        d1 += Wv[p] * (0.0 + AinvWT[j, Wi[p]] * x1)
                    v1 = abs(min(x1, b1 + d1))
                    applied = (v1 if v1 > 0.0 else 0.0) / max(abs(b1) if abs(b1) > 0.0 else 0.0,
                                                          abs(d1) if abs(d1) > 0.0 else 0.0, TINY)
                    status = OK if res <= tol and applied <= tol else (
                        LCP_FAILED if not res <= tol else RESIDUAL_EXCEEDED)
                else:
                    status = contact_impulse(k, s, us, uf, act, a, law, Wp, Wi, Wv, NUD, AinvWT, Ghat, e, tol,
                                             stats, gk, bvec, x, lc, le, gc, rhs, sol, G, Gs, Lf, basic, infeas,
                                             du, u1, P)
                if status != OK:
                    return s, k, status
                for i in range(n):
                    q1[i] = qs[s, i] + h * ((1.0 - theta) * us[s, i] + theta * u1[i])
                if project:
                    if a == 1:                              # project_one's operations, inline
                        j = act[0]
                        g = 0.0
                        for p in range(Wp[j], Wp[j + 1]):
                            g += Wv[p] * q1[Wi[p]]
                        g = g + NU[k + 1, j]
                        l00 = L[slots[s], j, j]
                        s1 = -g / l00 if l00 > 0.0 else 0.0
                        for i in range(n):
                            q1[i] += KinvWT[slots[s], j, i] * s1
                        status = OK if l00 > 0.0 else PROJECTION_FAILED
                    else:
                        status = project_positions(k + 1, act, a, slots[s], Wp, Wi, Wv, NU, KinvWT, L, q1, sig,
                                                   gp, sp_, Gp, Lf)
                    if status != OK:
                        return s, k, status
            for i in range(n):
                qs[s, i] = q1[i]
                us[s, i] = u1[i]
            # --- the summary: the kernel's operations (observer.engines.compiled.kernel._advance_loop)
            kg = k + 1
            for i in range(n):                              # v, v̄ (wv[:n], wv[n:2n])
                vi = us[s, i] - UM[kg, i]
                wv[i] = vi
                wv[n + i] = 0.5 * (vi + vprev[s, i])
                vprev[s, i] = vi
            qM = 0.0
            qC = 0.0
            qK = 0.0
            for i in range(n):
                rM = 0.0
                rC = 0.0
                for j in range(n):
                    rM += Mq[i, j] * wv[j]
                    rC += Cq[i, j] * wv[n + j]
                qM += wv[i] * rM
                qC += wv[n + i] * rC
            for i in range(n):
                wv[i] = qs[s, i] - QM[kg, i]                # e
            for i in range(n):
                rK = 0.0
                for j in range(n):
                    rK += Kq[i, j] * wv[j]
                qK += wv[i] * rK
            V = 0.5 * qM
            damping = -h * qC
            V += 0.5 * qK
            impulse = 0.0                                   # (Wᵀv̄)ᵀ(P_s − P_m)
            for j in range(m):
                wv[2 * n + j] = -PM[kg, j]
            for i in range(a):
                wv[2 * n + act[i]] += P[i]
            for j in range(m):
                dP = wv[2 * n + j]
                if dP != 0.0:
                    g = 0.0
                    for p in range(Wp[j], Wp[j + 1]):
                        g += Wv[p] * wv[n + Wi[p]]
                    impulse += g * dP
            Vp = Vlast
            dV = V - Vp
            if kg - 1 >= k_on and kg <= k_off:
                if dV > 0.0:
                    ninc += 1
                    if Vp > 0.0 and dV / Vp > maxinc:
                        maxinc = dV / Vp
                damp += damping
                imp += impulse
                proj += dV - damping - impulse
                if impulse > 0.0 and Vp > 0.0 and impulse / Vp > maximp:   # maximp ≥ 0
                    maximp = impulse / Vp
            Vlast = V
            vend = V
            if kg >= k_on and kg <= k_off:
                if kg == k_on:
                    von = V
                    kon = kg
                    vmax = V
                if V > vmax:
                    vmax = V
                V0 = von
                for i in range(nr):
                    below = V <= rhos[i] * V0
                    if below and marks[i] < 0:
                        marks[i] = kg
                    if not below:
                        marks[nr + i] = kg
            if prow >= 0 and kg % every == 0:
                rec_V[prow, kg // every] = V
        Vprev[s] = Vlast
        summ[s, F_VON], summ[s, F_VMAX], summ[s, F_VEND], summ[s, F_KON] = von, vmax, vend, kon
        summ[s, F_NINC], summ[s, F_MAXINC], summ[s, F_MAXIMP] = ninc, maxinc, maximp
        summ[s, F_DAMP], summ[s, F_IMP], summ[s, F_PROJ] = damp, imp, proj
        for i in range(2 * nr):
            summ[s, SUMMARY_FIELDS + i] = marks[i]
    return j1, steps, OK


def _member_input(sc, slaves, engine):
    """The run's loop input (master first, then ``slaves``) as :func:`observer.simulate` builds
    it, or None when the compiled engine would not take the run."""
    import dataclasses

    from observer.engines import choose, describe
    from observer.engines.timestepping import loop_input
    from observer.stepping import MoreauJean

    first = {}
    for s in slaves:                        # describe() checks each slave: one per design here
        first.setdefault(id(s.design), s)
    run = describe(sc, "time-stepping", list(first.values()), None, "scenario", None, 1e-9, None, "summary", None)
    if not _finite_energies(sc.system, slaves):
        return None                         # the kernel's chunks raise describe()'s error
    run = dataclasses.replace(run, slaves=tuple(slaves))
    chosen, _ = choose(run, engine)
    if chosen.name != "compiled":
        return None
    stepper = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, solver=sc.solver,
                         residual_tol=run.residual_tol, structure=chosen.structure)
    return loop_input(run, stepper)


def _finite_energies(system, slaves) -> bool:
    """Every slave's ½uᵀMu, ½qᵀKq and gaps finite (:func:`observer.scenario.check_finite_energy`,
    all at once)."""
    from observer.sparse import dense

    Q = np.array([s.q0 for s in slaves], dtype=float)
    U = np.array([s.u0 for s in slaves], dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        kinetic = np.einsum("si,si->s", U, U @ dense(system.M))
        elastic = np.einsum("si,si->s", Q, Q @ dense(system.K))
        gaps = Q @ dense(system.W)
    return bool(np.all(np.isfinite(kinetic)) and np.all(np.isfinite(elastic)) and np.all(np.isfinite(gaps)))


def observers_input(sc, slaves, engine, inp):
    """The loop input whose system the members advance and the one whose M, K, C measure
    their V: ``(inp, inp)`` without an observer model; with one (:mod:`observer.plant_model`),
    the nominal scenario's input (its matrices, signals, law and projection metrics go to
    :func:`advance_members` in place of the plant's: the same loop, other data) and, for V,
    the plant's ``inp`` or the nominal one by the model's ``error_metric``. ``(None, None)``
    when the compiled engine would not take the nominal run."""
    if sc.model is None:
        return inp, inp
    from observer.plant_model import model_scenario

    own = _member_input(model_scenario(sc), slaves, engine)
    return own, (inp if sc.model.error_metric == "plant" else own)


def member_summaries(sc, slaves, engine, workers: int, paths: tuple = ()):
    """The streaming summary of every observer in ``slaves`` against one master run of ``sc``,
    each equal to that of a single ``simulate(sc, observers=[slave], store="summary")``.

    Returns ``(rows, paths)``: one row per slave (the columns of
    :func:`observer.engines.loop.summary_frame`) and, for the slaves at indices ``paths``,
    ``{index: (t, V)}`` sampled every ``max(1, steps // 20 000)`` steps (with an observer model,
    :func:`observers_input`: the master the plant, the members on the model, V against the
    plant); or None when the run is
    not one this path covers (module docstring), the master or a member failed, or a result is
    not finite. ``workers`` threads advance contiguous chunks of the members.
    """
    inp = _member_input(sc, slaves, engine)
    if inp is None:
        return None
    st = inp.stepper
    steps, system = st.steps, system_bundle(inp)
    if not applicable(st, system, steps):
        return None
    tables = master_tables(inp, steps)
    if tables is None:
        return None
    own, metric = observers_input(sc, slaves, engine, inp)       # the observers' model, V's metric
    if own is None:
        return None
    if own is not inp:
        st, system = own.stepper, system_bundle(own)
        if not applicable(st, system, steps):
            return None
    FB, NU, NUD = signal_tables_on_grid(own, signal_tables(st.system), steps)
    law, obs, state = law_bundle(st), observer_bundle(own), state_bundle(own)
    tally = summary_bundle(metric, True, tuple(RHOS), 1)
    summary_start(state, system, tally)
    S = inp.q0.shape[0]
    every = max(1, steps // 20_000)
    path_row = np.full(S, -1, np.int64)
    path_row[[1 + i for i in paths]] = np.arange(len(paths))
    rec_V = np.zeros((len(paths), steps // every + 1))
    rec_V[:, 0] = tally.rec_V[[1 + i for i in paths], 0]
    n_, m_, r_ = sizes(st.system.n, st.system.m, len(RHOS), (S - 1) * steps)
    args = (steps, *tables, FB, NU, NUD, state.qs, state.us, obs.jumps, obs.slots, bool(inp.master_projection),
            tally.k_on, tally.k_off, tally.rhos, tally.summ, tally.vprev, tally.Vprev, tally.Mq, tally.Kq,
            tally.Cq, law.code, system.h, system.theta, system.Bu, system.Bq, system.Bf, system.Wp, system.Wi,
            system.Wv, system.AinvWT, system.Ghat, obs.KinvWT, obs.L, law.e, law.tol, path_row, every, rec_V)
    bounds = np.linspace(1, S, min(workers, S - 1) + 1).round().astype(int)
    chunk = lambda j: advance_members(n_, m_, r_, bounds[j], bounds[j + 1], *args)  # noqa: E731
    with ThreadPoolExecutor(max_workers=len(bounds) - 1) as pool:
        done = list(pool.map(chunk, range(len(bounds) - 1)))
    if any(status != OK for *_, status in done) or not FiniteGuard(inp).state_ok(state.qs, state.us, tally.summ):
        return None
    out = types.SimpleNamespace(summary={"fields": tally.summ, "k_on": tally.k_on, "k_off": tally.k_off,
                                         "rhos": tuple(RHOS)})
    rows = summary_frame(out, [s.name for s in slaves], st.t0, st.h, frame=False)
    t = st.time(np.arange(rec_V.shape[1]) * every)
    return rows, {i: (t, rec_V[r]) for r, i in enumerate(paths)}
