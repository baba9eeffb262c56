"""An ensemble's members after one master run: each observer advanced alone over the whole grid.

The observers of a run are independent given the master (paper eqs. (7)-(11)): what an
observer's step reads from the rest of the run is χ_k (the master's closed set, or the log's),
the master's state and impulse after the step (for V and its impulse part) and the signals
f̄_k, ν, ν̇ at the grid points. :func:`member_summaries` runs the master once with the
compiled kernel (:meth:`observer.engines.timestepping.TimeStepping.advance`, every step recorded), tabulates those quantities
per step (:func:`master_tables`), and then advances every member over the whole grid in
:func:`advance_members`, a compiled loop with the member's state in cache and no other
system's work per step; chunks of members run in threads (``nogil``).

:func:`advance_members` is the kernel's step loop's observer step, not a copy of it: both
loops are generated from one template (:mod:`observer.engines.compiled.step`), the members'
with the master's tables as the data source of χ_k, the coupling, the signals and the
master's state and impulse after the step (:class:`MasterTables`), the summary row held in
registers and n, m as compile-time constants when given (:func:`sizes`). Member i's summary
is bitwise that of a single :func:`observer.simulate` of that member
(``tests/observer/test_ensemble_members.py`` checks every branch against single runs). The
master alone takes the kernel's lean specialization, whose trajectory is bitwise the general
loop's (:func:`observer.engines.compiled.bundles.specialization`).

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
from typing import NamedTuple

import numpy as np

from observer.engines.compiled.bundles import (law_bundle, observer_bundle, signal_tables, state_bundle,
                                               summary_bundle, system_bundle, wave_table)
from observer.engines.compiled import driver
from observer.engines.compiled.driver import run_compiled
from observer.engines.compiled import kernel
from observer.engines.compiled.kernel import summary_start
from observer.engines.compiled.step import build
from observer.engines.loop import FiniteGuard, LoopInput, summary_frame
from observer.metrics import RHOS
from observer.primitives import CONTACTS_DENSE, OK, STRUCTURE_DENSE

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


class MasterTables(NamedTuple):
    """What an observer's step reads from the rest of the run, per grid step
    (:func:`master_tables`, :func:`signal_tables_on_grid`).

    Attributes
    ----------
    q, u, P : ndarray (steps + 1, n), (steps + 1, n), (steps + 1, m)
        The master's state and impulse after each step (row k + 1: after step k).
    chi : ndarray of bool (steps, m)
        χ_k (the master's closed set or the log's).
    coupled : ndarray of bool (steps,)
        Whether step k follows χ_k.
    fbar : ndarray (steps, n)
        f̄_k.
    nu, nu_dot : ndarray (steps + 1, m)
        ν(t_k), ν̇(t_k).
    """

    q: np.ndarray
    u: np.ndarray
    P: np.ndarray
    chi: np.ndarray
    coupled: np.ndarray
    fbar: np.ndarray
    nu: np.ndarray
    nu_dot: np.ndarray


class PathBundle(NamedTuple):
    """The V paths kept: member s's V after every ``every``-th step in ``V[row[s]]`` when
    ``row[s] ≥ 0`` (row 0 of ``V``, V(t_0), written by the caller)."""

    row: np.ndarray
    every: int
    V: np.ndarray


advance_members = build("advance_members", {**vars(kernel), "__name__": __name__})
"""``advance_members(n_, m_, r_, j0, j1, master, system, impact, observers, state, tally, paths)``:
advance observers j0..j1−1 (rows of ``state.qs``, ``state.us``, ``tally.summ``; the master,
row 0, is not advanced) over the whole grid, each alone, with the step of the kernel's loop
(generated from the same template, :func:`observer.engines.compiled.step.members_source`): the
closed set (χ_k of ``master.chi`` while ``master.coupled[k]``, else the observer's own
prediction), u_free, the impulse, the positions and their jump, the summary against the
master's state and impulse after the step (:class:`MasterTables`), the signals read at the
global step. ``n_``, ``m_``, ``r_`` are tuples of n, m and ``len(rhos)`` zeros, so that these
sizes are compile-time constants of the specialization (its loops unrolled: faster per step
of double_mass than with n and m from the arrays), or empty for n and m taken from the arrays
(:func:`sizes`). ``system``, ``impact``, ``observers``, ``tally`` are the kernel's bundles
(:mod:`observer.engines.compiled.bundles`) of the observers' model; ``paths`` a
:class:`PathBundle`. Returns ``(k, s, status)``: the step and observer that failed, or
``status == OK`` when all are done."""


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
    master = MasterTables(*tables[:3], tables[3], tables[4], FB, NU, NUD)
    kept = PathBundle(row=path_row, every=every, V=rec_V)
    bounds = np.linspace(1, S, min(workers, S - 1) + 1).round().astype(int)
    chunk = lambda j: advance_members(n_, m_, r_, bounds[j], bounds[j + 1], master, system, law, obs,  # noqa: E731
                                      state, tally, kept)
    with ThreadPoolExecutor(max_workers=len(bounds) - 1) as pool:
        done = list(pool.map(chunk, range(len(bounds) - 1)))
    if any(status != OK for *_, status in done) or not FiniteGuard(inp).state_ok(state.qs, state.us, tally.summ):
        return None
    out = types.SimpleNamespace(summary={"fields": tally.summ, "k_on": tally.k_on, "k_off": tally.k_off,
                                         "rhos": tuple(RHOS)})
    rows = summary_frame(out, [s.name for s in slaves], st.t0, st.h, frame=False)
    t = st.time(np.arange(rec_V.shape[1]) * every)
    return rows, {i: (t, rec_V[r]) for r, i in enumerate(paths)}
