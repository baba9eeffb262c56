"""The numpy time-stepping engine: the readable reference loop.

Every step is :meth:`observer.stepping.MoreauJean.step` (numpy), system by system
(:func:`observer.engines.loop.python_step`), every step checked for a non-finite quantity
(:class:`~observer.engines.loop.FiniteGuard`) and its complementarity residual recomputed
from the velocity it applied (:func:`newton_residual`); the oracle of the compiled kernel.
"""

from __future__ import annotations

import time

import numpy as np

from observer.engines.base import Refusal, RunDescription
from observer.engines.loop import (FiniteGuard, LoopInput, LoopOutput, Stopper, allocate_records, emitter,
                                   finish, loop_records, python_step, stopped_text)
from observer.engines.timestepping import TimeStepping
from observer.errors import InputError
from observer.stepping import MoreauJean, NonFiniteState


class PythonEngine(TimeStepping):
    """Moreau–Jean in numpy, step by step: every registered contact solver and impact law
    (through its step map), dense matrices; the oracle of the compiled kernel."""

    name = "python"
    structure = "dense"
    description = "Moreau–Jean time-stepping in numpy (the reference)"

    def refuses(self, run: RunDescription) -> Refusal | None:
        """The streaming summary is computed by the kernel only."""
        if run.store == "summary":
            return Refusal('store="summary" needs the compiled engine', "store")
        return None

    def loop(self, inp: LoopInput, record_every: int, record_pre: bool, store: str, rhos: tuple | None,
             on_chunk, stopper: Stopper) -> LoopOutput:
        """:func:`run_python` (the streaming summary refused: it is the kernel's)."""
        if store == "summary":
            raise InputError("store", 'store="summary" needs engine="compiled"')
        return run_python(inp, record_every, record_pre, on_chunk, stopper)


PYTHON_CHUNK = 4096
"""Steps between two chunks of the python engine."""


def run_python(inp: LoopInput, record_every: int, record_pre: bool, on_chunk=None,
               stopper: Stopper | None = None) -> LoopOutput:
    """The master and the observers of ``inp``, step by step in numpy (a chunk every
    :data:`PYTHON_CHUNK` steps; the stop signal checked every step)."""
    stepper = inp.stepper
    rec, _ = allocate_records(inp, record_every, record_pre)
    S = inp.q0.shape[0]
    states = [(inp.q0[s].copy(), inp.u0[s].copy()) for s in range(S)]
    coupled = inp.coupled(stepper.grid.t)
    chi_log = inp.chi_window(stepper.grid.t, 0)
    emit = emitter(inp, rec, record_every, on_chunk)
    health = {"applied_residual": 0.0, "applied_residual_step": -1, "min_gap": np.inf,
              "min_gap_step": -1, "residual_source": "applied"}
    tol = float(stepper.residual_tol)
    stop, reason = None, ""
    t0 = time.perf_counter()
    guard = FiniteGuard(inp)
    with np.errstate(over="ignore", invalid="ignore"):     # overflow: the guard's to stop
        for k in range(stepper.grid.steps):
            if stopper is not None and stopper.signal:
                stop, reason = k, stopped_text(stepper, stopper.signal, k)
                break
            r = (k + 1) // record_every if (k + 1) % record_every == 0 else -1
            chi = None
            within = True
            for s in range(S):
                q, u = states[s]
                try:
                    q1, u1, P, sig, q_pre, act, chi = python_step(inp, stepper, k, s, q, u, chi, coupled[k],
                                                                   None if chi_log is None else chi_log[k])
                except NonFiniteState:                  # the step's free velocity is not finite
                    stop, reason = k, guard.stop_text(guard.free_velocity(k, s, q, u) or "free velocity", k)
                    break
                if not guard._within(q1, u1):
                    within = False
                    bad = guard.free_velocity(k + 1, s, q1, u1) if not (np.all(np.isfinite(q1))
                                                                         and np.all(np.isfinite(u1))) else None
                    if bad is not None:                 # (names the first non-finite entry of the state)
                        stop, reason = k, guard.stop_text(bad, k)
                        break
                res = _python_health(stepper, k, s, q, u, u1, P, act, q1, health)
                if not res <= tol:
                    stop, reason = k, stopped_text(stepper, f"complementarity residual {res:.3g} > "
                                                 f"tolerance {tol:.3g} in step {k} (system {s})", k)
                    break
                states[s] = (q1, u1)
                if r >= 0:
                    rec["q"][s, r], rec["u"][s, r] = q1, u1
                    rec["P"][s, r, act] = P
                    if sig is not None:
                        rec["sigma"][s, r, act] = sig
                    if record_pre:
                        rec["q_pre"][s, r] = q_pre
                    if s == 0:
                        rec["active"][r, act] = True
                        if S > 1:
                            rec["chi"][r, chi] = True
            if stop is None and not within:             # the new states, their gaps and V finite?
                bad = guard.first_problem(k + 1, np.stack([q for q, _ in states]), np.stack([u for _, u in states]))
                if bad is not None:
                    stop, reason = k, guard.stop_text(bad, k)
            if stop is not None:
                break
            if (k + 1) % PYTHON_CHUNK == 0:
                emit(k + 1)
    emit(stepper.grid.steps if stop is None else stop)
    run_time = time.perf_counter() - t0
    st = stepper.stats
    out = LoopOutput(record_every, **loop_records(rec, record_pre), engine="python",
                     stats={"contact_solves": st.contact_solves, "iterations": st.iterations,
                            "max_residual": st.max_residual, "fallbacks": st.fallbacks, **health},
                     run_time_s=run_time)
    return finish(inp, out, stop, reason, stopper.signal if stopper is not None else None)


def _python_health(stepper: MoreauJean, k: int, s: int, q, u, u1, P, act, q1, health: dict) -> float:
    """Fold step k of system s into ``health``; return its recomputed residual (0 without
    contacts). The master's gaps after the step update the deepest penetration. The residual
    is that of Newton's discrete law ``0 ≤ γ_{k+1} + e∘γ_k ⊥ P ≥ 0`` with ``ĜP`` replaced by
    ``W_Aᵀ(u_{k+1} − u_free)`` (the kernel's :func:`observer.primitives.applied_residual`), valid
    where the law declares its step Newton's (:meth:`~observer.impact.ImpactLawDefinition.newton_on`:
    Newton's law, a one-contact Poisson step); other steps count the solver's own residual
    (``residual_source = "applied+solver"``)."""
    if s == 0:
        g = stepper.system.gaps(q1, stepper.time(k + 1))
        j = int(g.argmin()) if g.size else -1
        if g.size and g[j] < health["min_gap"]:
            health["min_gap"], health["min_gap_step"] = float(g[j]), k + 1
    if act.size == 0:
        return 0.0
    if stepper.law.definition.newton_on(act.size):       # the law's declared fact
        res = newton_residual(stepper, k, q, u, u1, P, act)
    else:
        res = float(stepper.stats.max_residual)
        health["residual_source"] = "applied+solver"
    if res > health["applied_residual"]:
        health["applied_residual"], health["applied_residual_step"] = res, k + 1
    return res


def newton_residual(stepper: MoreauJean, k: int, q, u, u1, P, act) -> float:
    """``max|min(P, b + d)| / max(‖b‖_∞, ‖d‖_∞)`` with ``b = γ_free + e∘γ_k`` and
    ``d = W_Aᵀδu``, ``δu = Â⁻¹W_A P`` the velocity change the step applied: computed by the
    kernel's own :func:`observer.primitives.applied_residual` (one implementation for both engines)."""
    from observer.primitives import applied_residual

    slices = stepper._active_slices(act)
    W_A, e_A = stepper.S.W[:, act], slices[6]          # (W_A in this layout: the products' own rounding)
    u_free = stepper.last_free_velocity(k, q, u)        # the step's own (the same arrays, unchanged)
    nd = stepper.grid.nu_dot
    b = (u_free @ W_A + nd[k + 1, act]) + e_A * (u @ W_A + nd[k, act])
    du = slices[1] @ P if stepper.S.factored else stepper.S.AinvW[:, act] @ P
    Wp, Wi, Wv = stepper.csc
    c = np.ascontiguousarray
    return float(applied_residual(Wp, Wi, Wv, c(act, dtype=np.int64), int(act.size), c(du, dtype=np.float64),
                                  c(b, dtype=np.float64), c(P, dtype=np.float64)))
