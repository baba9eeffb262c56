"""The compiled engine's driver: the kernel's bundles built once, then the run window by window.

:func:`run_compiled` advances a :class:`~observer.engines.loop.LoopInput` by the numba kernel
(:mod:`observer.engines.compiled.kernel`) in windows of :data:`WINDOW` steps
(:class:`CompiledRun`): the kernel's statuses handled (a failed contact step re-solved with the
reference solver, :func:`fallback_step`; an exceeded residual a stop), a window that ends with
a non-finite quantity run again one step at a time to stop before the step that made it
(:class:`~observer.engines.loop.FiniteGuard`), the finished rows passed to ``on_chunk`` and
the stop signal checked between windows. :func:`compile_time` compiles (or loads) every loop
variant once.
"""

from __future__ import annotations

import time

import numpy as np

from observer.engines.compiled import kernel
from observer.engines.compiled.bundles import (law_bundle, model_bundle, model_observers, model_window,
                                               observer_bundle, signal_tables, specialization, state_bundle,
                                               storage_bundle, summary_bundle, system_bundle, window_bundle)
from observer.engines.compiled.kernel import summary_start
from observer.engines.loop import (FiniteGuard, LoopInput, LoopOutput, Stopper, allocate_records, emitter,
                                   finish, loop_records, python_step, stopped_text)
from observer.errors import InputError
from observer.primitives import OK, PROJECTION_FAILED, RESIDUAL_EXCEEDED
from observer.scenario import Scenario
from observer.stepping import MoreauJean, SolverCounts

WINDOW = 1 << 14
"""Steps per window of the compiled engine (the signals of one window are built at a time).
16 384 steps keep a window's signals in cache: on the chain N = 10 this was faster per step
than a window of 65 536 steps, on the 1-DOF oscillator no different (issue 21), at the cost of
one kernel call and one grid evaluation per window."""




# ---------------------------------------------------------------------------------------
# engine="compiled": the numba kernel, with the reference solver for failed steps
# ---------------------------------------------------------------------------------------
_COMPILED = False


def compile_time() -> float:
    """Compile (or load from numba's on-disk cache) the kernel; return the seconds it took."""
    global _COMPILED
    t0 = time.perf_counter()
    if not _COMPILED:
        sc = Scenario.from_dict({
            "system": {"M": [[1.0, 0.0], [0.0, 1.0]], "C": [[0.1, 0.0], [0.0, 0.1]],
                       "K": [[1.0, 0.0], [0.0, 1.0]], "W": [[1.0, 0.0], [0.0, 1.0]],
                       "gap": {"offset": [0.0, 0.0]}},
            "impact": {"law": "poisson", "restitution": 0.5},
            "initial": {"q": [0.0, 0.0], "u": [-1.0, -1.0]},
            "simulation": {"t_end": 0.02, "h": 0.01}}, "warm-up")
        st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta)
        inp = LoopInput(st, np.stack([sc.q0, sc.q0]), np.stack([sc.u0, sc.u0]), np.array([False, True]),
                        False)
        run_compiled(inp, 1, True, True, (1e-3,), warm=True)             # the general loop
        run_compiled(LoopInput(st, sc.q0[None], sc.u0[None], np.array([False]), False), 1, False,
                      warm=True)                                            # the lean one
        one = Scenario.from_dict({
            "system": {"M": [[1.0]], "C": [[0.1]], "K": [[1.0]], "W": [[1.0]], "gap": {"offset": [0.0]}},
            "impact": {"law": "newton", "restitution": 0.5}, "initial": {"q": [0.0], "u": [-1.0]},
            "simulation": {"t_end": 0.02, "h": 0.01}}, "warm-up")
        st = MoreauJean(one.system, one.law, one.h, one.t_end, one.theta)
        run_compiled(LoopInput(st, one.q0[None], one.u0[None], np.array([False]), False), 1, False,
                      warm=True)                                            # and the scalar one
        _COMPILED = True
    return time.perf_counter() - t0


def _snapshot(state: tuple, fallbacks: list, stepper) -> tuple:
    """Copies of the loop's mutable arrays (and the fallbacks' count and reference statistics)."""
    from dataclasses import replace

    ref = getattr(stepper, "_reference_twin", None)
    return [a.copy() for a in state], len(fallbacks), None if ref is None else replace(ref.stats)


def _restore(state: tuple, snap: tuple, fallbacks: list, stepper) -> None:
    """Put back what :func:`_snapshot` copied (the records are rewritten by the re-run)."""
    arrays, nfb, ref_stats = snap
    for a, b in zip(state, arrays):
        a[...] = b
    del fallbacks[nfb:]
    ref = getattr(stepper, "_reference_twin", None)
    if ref is not None:
        ref.stats = SolverCounts() if ref_stats is None else ref_stats


class CompiledRun:
    """One run of the compiled engine: the kernel's bundles, built once, and the windows.

    The run advances window by window (:data:`WINDOW` steps): :meth:`window` calls the kernel
    (:meth:`advance_to`, which handles its statuses: the reference solver for a failed
    contact step, a stop for an exceeded residual) and, when the window ends with a
    non-finite (or overflowing) state, runs it again one step at a time to stop before the
    step that made it (:class:`FiniteGuard`); :meth:`output` assembles the records.
    """

    def __init__(self, inp: LoopInput, record_every: int, record_pre: bool, summary: bool, rhos: tuple,
                 warm: bool, on_chunk, stopper: Stopper | None, model_inp: LoopInput | None = None):

        st = self.stepper = inp.stepper
        self.inp, self.warm, self.stopper, self.rhos = inp, warm, stopper, rhos
        self.S = inp.q0.shape[0]
        self.compile_time = 0.0 if (warm or _COMPILED) else compile_time()
        self.rec, R = allocate_records(inp, record_every, record_pre)
        self.t_rec = np.empty(R) if record_every == 1 else None
        if self.t_rec is not None:
            self.t_rec[0] = st.time(np.zeros(1, np.int64))[0]   # row 0; rows 1.. by the loop (scalar) or tw
        self.system, self.law, self.signals = system_bundle(inp), law_bundle(st), signal_tables(st.system)
        self.model_inp = model_inp
        self.model = None if model_inp is None else model_bundle(model_inp)
        self.observers = observer_bundle(inp) if model_inp is None else model_observers(inp, model_inp)
        self.state = state_bundle(inp)
        self.storage = storage_bundle(self.rec, record_every, record_pre, self.t_rec)
        self.tally = summary_bundle(inp, summary, rhos, R)
        self.spec = specialization(self.S, self.system.structure, summary, record_pre, inp.master_projection,
                                   st.system.n, st.system.m) if model_inp is None else "model"
        if summary:
            summary_start(self.state, self.system, self.tally)
        self.fallbacks: list[dict] = []
        self.emit = emitter(inp, self.rec, record_every, on_chunk, self.tally.rec_V if summary else None)
        self.guard = FiniteGuard(inp)
        t = self.tally
        self.mutable = (*self.state, t.summ, t.vprev, t.Vprev, t.closings, t.prev_act)

    def kernel(self, window, k: int, k_end: int, s: int) -> tuple[int, int, int]:
        """One kernel call from (k, s) up to step k_end in the run's specialization."""
        if self.spec == "model":
            return kernel.advance_model(k, k_end, s, system=self.system, impact=self.law, signals=self.signals,
                                        window=window, observers=self.observers, state=self.state,
                                        storage=self.storage, tally=self.tally,
                                        model=self.model_w)
        if self.spec == "scalar":
            return kernel.advance_scalar(k, k_end, system=self.system, impact=self.law, signals=self.signals,
                                         window=window, state=self.state, storage=self.storage)
        return kernel.advance(k, k_end, s, system=self.system, impact=self.law, signals=self.signals,
                              window=window, observers=self.observers, state=self.state, storage=self.storage,
                              tally=self.tally, general=None if self.spec == "lean" else True)

    def advance_to(self, window, k: int, s: int, k_end: int):
        """Advance from (k, s) up to step k_end; the kernel's statuses handled (the reference
        solver for a failed contact step). Returns (k, s, stop, reason, finite): ``finite``
        False when the stop is a non-finite free velocity."""

        qs, us = self.state.qs, self.state.us
        while k < k_end:
            k, s, status = self.kernel(window, k, k_end, s)
            if status == OK:
                break
            bad = self.guard.free_velocity(k, s, qs[s], us[s])
            if bad is not None:                 # the failed step's input is not finite
                return k, s, k, self.guard.stop_text(bad, k), False
            stop = self._failed_step(window, k, s, status)
            if stop is not None:
                return k, s, k, stop, True
            s += 1
            if s == self.S:
                k, s = k + 1, 0
        return k, s, None, "", True

    def _failed_step(self, window, k: int, s: int, status: int) -> str | None:
        """Step k of system s, at which the kernel stopped with ``status``: the stop reason
        (residual exceeded), an error (projection failed; summary store), or the step re-solved
        with the reference solver and recorded (None)."""

        st = self.stepper
        if status == RESIDUAL_EXCEEDED:
            return stopped_text(st, f"complementarity residual {self.state.stats[7]:.3g} > tolerance "
                              f"{st.residual_tol:.3g} in step {k} (system {s})", k)
        if status == PROJECTION_FAILED:
            st.system.require_definite_stiffness("the position projection (position jumps)")
            raise InputError("system.W", f"W_IᵀK⁻¹W_I is not positive definite at step {k} "
                             f"(t = {float(st.time(k)):.6g}): the closed contacts' columns "
                             "of W are dependent in the K metric")
        if self.tally.on:
            raise InputError("store", f'store="summary": the kernel could not solve the contact '
                             f"problem of step {k} (t = {float(st.time(k)):.6g}); run with "
                             'store="full", which re-solves such steps with the reference solver')
        kw = k - window.kb
        inp = self.inp if self.model_inp is None or s == 0 else self.model_inp
        fallback_step(inp, inp.stepper, k, s, self.state.qs, self.state.us, self.state.chi_now,
                       self.storage.record_every, self.storage.record_pre, self.rec,
                       self.S > 1 and bool(window.coupled[kw]), window.chi_log[kw] if window.use_log else None)
        self.fallbacks.append({"step": int(k), "t": float(st.time(k)), "system": int(s)})
        return None

    def window(self, k: int, s: int):
        """The window from step k: its bundle, the kernel over it, and, when it ends with a
        quantity that is not finite, the same window again one step at a time to stop before
        the step that made it. Returns (k, s, stop, reason)."""
        st, kb = self.stepper, k
        k1 = min(st.steps, kb + WINDOW)
        tw = None
        # the window's grid points; every step recorded: written in place as the rows' times
        # (the scalar loop writes them itself)
        if (self.t_rec is not None and self.spec != "scalar") or self.S > 1:
            tw = st.time(np.arange(kb, k1 + 1), out=None if self.t_rec is None else self.t_rec[kb:k1 + 1])
        window = window_bundle(self.inp, self.signals, kb, k1, tw)
        self.model_w = None if self.model is None else model_window(self.model, st.t0, st.h, kb, k1)
        snap = _snapshot(self.mutable, self.fallbacks, st)
        k, s, stop, reason, finite = self.advance_to(window, k, s, k1)
        state = self.state
        if self.warm or (finite and self.guard.state_ok(state.qs, state.us,
                                                          self.tally.summ if self.tally.on else None)):
            return k, s, stop, reason
        _restore(self.mutable, snap, self.fallbacks, st)
        k, s, stop, reason = kb, 0, None, ""
        while k < k1 and stop is None:
            one = _snapshot(self.mutable, self.fallbacks, st)
            k_before = k
            k, s, stop, reason, _ = self.advance_to(window, k, s, k + 1)
            if stop is None:
                bad = self.guard.first_problem(k, state.qs, state.us)
                if bad is not None:
                    _restore(self.mutable, one, self.fallbacks, st)
                    stop, reason = k_before, self.guard.stop_text(bad, k_before)
        return k, s, stop, reason

    def run(self) -> LoopOutput:
        """Every window, the stop signal checked between them; the output."""
        stop, reason = None, ""
        t0 = time.perf_counter()
        k, s = 0, 0
        while k < self.stepper.steps and stop is None:
            if self.stopper is not None and self.stopper.signal and not self.warm:
                stop, reason = k, stopped_text(self.stepper, self.stopper.signal, k)
                break
            k, s, stop, reason = self.window(k, s)
            self.emit(k if stop is None else stop)
        out = self.output(time.perf_counter() - t0)
        if self.warm:
            return out
        return finish(self.inp, out, stop, reason, self.stopper.signal if self.stopper is not None else None)

    def output(self, run_time: float) -> LoopOutput:
        """The records, the counters (the reference solver's added) and the summary."""
        ref = getattr(self.stepper, "_reference_twin", None)
        ref_stats = ref.stats if (ref is not None and self.fallbacks) else None
        stats, t, rec = self.state.stats, self.tally, self.rec
        out_summary = None
        if t.on:
            out_summary = {"fields": t.summ, "closings": t.closings, "k_on": t.k_on, "k_off": t.k_off,
                           "rhos": tuple(self.rhos)}
        counts = {"contact_solves": int(stats[0]) + (ref_stats.contact_solves if ref_stats else 0),
                  "iterations": int(stats[1]) + (ref_stats.iterations if ref_stats else 0),
                  "max_residual": max(float(stats[2]), ref_stats.max_residual if ref_stats else 0.0),
                  "fallbacks": len(self.fallbacks), "min_gap": float(stats[3]),
                  "min_gap_step": int(stats[4]), "applied_residual": float(stats[5]),
                  "applied_residual_step": int(stats[6]), "residual_source": "applied"}
        return LoopOutput(self.storage.record_every, **loop_records(rec, self.storage.record_pre),
                          engine="compiled", stats=counts, fallbacks=self.fallbacks,
                          compile_time_s=self.compile_time, run_time_s=run_time, V=t.rec_V if t.on else None,
                          summary=out_summary, t=self.t_rec)


def run_compiled(inp: LoopInput, record_every: int, record_pre: bool, summary: bool = False,
                  rhos: tuple = (1e-3,), warm: bool = False, on_chunk=None,
                  stopper: Stopper | None = None, model: LoopInput | None = None) -> LoopOutput:
    """Run ``inp`` on the compiled engine (:class:`CompiledRun`); ``warm``: a compile-only
    run (no guard re-runs, no health record). ``model``: the observers on a model of their
    own, one loop (:func:`observer.engines.compiled.kernel.advance_model`): the same
    systems on the model's stepper (same grid; the observers' designs and metrics), the
    master of ``inp`` the plant."""
    return CompiledRun(inp, record_every, record_pre, summary, rhos, warm, on_chunk, stopper, model).run()


def fallback_step(inp, stepper, k, s, qs, us, chi_now, record_every, record_pre, rec,
                   coupled_k, chi_row) -> None:
    """Step k of system s, which the kernel could not solve, with the reference solver."""
    ref = reference_stepper(stepper)
    q1, u1, P, sig, q_pre, act, chi = python_step(inp, ref, k, s, qs[s], us[s],
                                                   np.flatnonzero(chi_now), coupled_k, chi_row)
    if s == 0:
        chi_now[:] = False
        chi_now[chi] = True
    qs[s], us[s] = q1, u1
    if (k + 1) % record_every == 0:
        r = (k + 1) // record_every
        rec["q"][s, r], rec["u"][s, r] = q1, u1
        rec["P"][s, r] = 0.0
        rec["P"][s, r, act] = P
        rec["sigma"][s, r] = 0.0
        if sig is not None:
            rec["sigma"][s, r, act] = sig
        if record_pre:
            rec["q_pre"][s, r] = q_pre
        if s == 0:
            rec["active"][r] = False
            rec["active"][r, act] = True
            if inp.q0.shape[0] > 1:
                rec["chi"][r] = chi_now


def reference_stepper(stepper: MoreauJean) -> MoreauJean:
    """The stepper's twin with the reference solver (same grid), built once."""
    ref = getattr(stepper, "_reference_twin", None)
    if ref is None:
        ref = MoreauJean(stepper.system, stepper.law, stepper.h, float(stepper.time(stepper.steps)),
                         stepper.theta, t0=stepper.t0, solver="reference",
                         residual_tol=stepper.residual_tol,
                         structure="banded" if stepper.S.factored else "dense")
        stepper._reference_twin = ref
    return ref
