"""The time loop: the master and any number of observers advanced together, on arrays only.

One loop, two engines that give one answer:

* ``engine="python"`` — the readable reference: every step is
  :meth:`observer.stepping.MoreauJean.step` (numpy), the implementation the docs explain;
* ``engine="compiled"`` (default) — :func:`observer.kernel.advance`, the same scheme in one
  numba call over the horizon, with no allocation or Python dispatch per step. When the
  kernel's contact solve fails at a step (status ≠ 0), that step is re-solved here by the
  python stepper with the reference solver (cvxpy + OSQP), recorded in
  :attr:`LoopOutput.fallbacks`, and the kernel resumes — never silently.

Per step k (row k+1 of every record): the master takes its closed set from Siconos'
predictor ``g_k + (h/2)γ_k ≤ 0`` (and is projected on it when ``master_projection``); χ_k
is that set, or row k of a closing log; each observer steps on χ_k (projected when it has
position jumps) while coupled, and otherwise on its own predicted set like the master.

The projection metric of the position jumps is K (paper eqs. (13)-(14)); ``metric=N``
projects in the N metric instead (``q⁺ = q⁻ − N⁻¹W_I(W_IᵀN⁻¹W_I)⁻¹g_I``), which the proof
checks use to build known-bad integrators. ``record_pre=True`` also keeps the positions
before the projection (``q_pre``), which the position-jump part of eq. (17) needs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from observer.errors import InputError
from observer.stepping import MoreauJean

ENGINES = ("compiled", "python")
"""Registered engines; the first is the default."""


@dataclass(frozen=True)
class LoopInput:
    """What the loop advances: the stepper and, per system (master first), its start and design.

    Attributes
    ----------
    stepper : MoreauJean
    q0, u0 : ndarray, shape (S, n)
        Initial states; row 0 is the master.
    jumps : ndarray of bool, shape (S,)
        Position jumps while coupled (row 0 ignored).
    master_projection : bool
    coupled : ndarray of bool, shape (N,)
        Step k couples the observers to χ_k.
    chi_log : ndarray of bool, shape (N, m) or None
        χ_k from a log instead of the master's closed set.
    metric : ndarray (n, n) or None
        Projection metric (None: K).
    """

    stepper: MoreauJean
    q0: np.ndarray
    u0: np.ndarray
    jumps: np.ndarray
    master_projection: bool
    coupled: np.ndarray
    chi_log: np.ndarray | None = None
    metric: np.ndarray | None = None


@dataclass(frozen=True)
class LoopOutput:
    """Records of one loop run; system s (0 = master) in the first axis.

    ``rows`` are the step indices recorded (row r holds the state after step rows[r]−1, row 0
    the initial state); ``P`` and ``sigma`` the impulse and projection multiplier of the step
    ending at the row; ``active`` the master's closed set and ``chi`` the observers' signal
    of that step; ``q_pre`` (or None) the positions before the step's projection.
    """

    rows: np.ndarray
    q: np.ndarray
    u: np.ndarray
    P: np.ndarray
    sigma: np.ndarray
    active: np.ndarray
    chi: np.ndarray
    q_pre: np.ndarray | None
    engine: str
    stats: dict
    fallbacks: list = field(default_factory=list)
    compile_time_s: float = 0.0
    run_time_s: float = 0.0


def check_engine(engine: str) -> str:
    if engine not in ENGINES:
        raise InputError("engine", f"must be one of {list(ENGINES)}, got {engine!r}")
    return engine


def check_record_every(record_every) -> int:
    if isinstance(record_every, bool) or not isinstance(record_every, (int, np.integer)) or record_every < 1:
        raise InputError("record_every", f"must be a positive integer, got {record_every!r}")
    return int(record_every)


def projection_matrices(stepper: MoreauJean, metric: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """``(N⁻¹W, WᵀN⁻¹W)`` of the projection metric N (K by default; None when K is singular)."""
    S = stepper.S
    if metric is None:
        if S.KinvW is None:
            n, m = S.W.shape
            return np.zeros((n, m)), np.zeros((m, m))
        return S.KinvW, S.L
    N = np.asarray(metric, dtype=float)
    NinvW = np.linalg.solve(N, S.W)
    L = S.W.T @ NinvW
    return NinvW, 0.5 * (L + L.T)


def run(inp: LoopInput, engine: str = "compiled", record_every: int = 1,
        record_pre: bool = False) -> LoopOutput:
    """Advance the master and the observers of ``inp`` over the stepper's grid."""
    check_engine(engine)
    record_every = check_record_every(record_every)
    if engine == "python":
        return _run_python(inp, record_every, record_pre)
    return _run_compiled(inp, record_every, record_pre)


def _allocate(inp: LoopInput, record_every: int, record_pre: bool):
    stepper = inp.stepper
    steps, n, m = stepper.grid.steps, stepper.system.n, stepper.system.m
    S = inp.q0.shape[0]
    R = steps // record_every + 1
    rec = {"q": np.empty((S, R, n)), "u": np.empty((S, R, n)), "P": np.zeros((S, R, m)),
           "sigma": np.zeros((S, R, m)), "active": np.zeros((R, m), dtype=bool),
           "chi": np.zeros((R, m), dtype=bool),
           "q_pre": np.empty((S, R if record_pre else 0, n))}
    rec["q"][:, 0], rec["u"][:, 0] = inp.q0, inp.u0
    if record_pre:
        rec["q_pre"][:, 0] = inp.q0
    return rec, np.arange(R) * record_every


# ---------------------------------------------------------------------------------------
# engine="python": the reference
# ---------------------------------------------------------------------------------------
def _run_python(inp: LoopInput, record_every: int, record_pre: bool) -> LoopOutput:
    stepper = inp.stepper
    rec, rows = _allocate(inp, record_every, record_pre)
    NinvW, L = projection_matrices(stepper, inp.metric)
    S = inp.q0.shape[0]
    states = [(inp.q0[s].copy(), inp.u0[s].copy()) for s in range(S)]
    t0 = time.perf_counter()
    for k in range(stepper.grid.steps):
        r = (k + 1) // record_every if (k + 1) % record_every == 0 else -1
        chi = None
        for s in range(S):
            q, u = states[s]
            if s == 0:
                act = np.flatnonzero(stepper.predicted_active(k, q, u))
                proj = inp.master_projection
                chi = act if inp.chi_log is None else np.flatnonzero(inp.chi_log[k])
            elif inp.coupled[k]:
                act, proj = chi, bool(inp.jumps[s])
            else:
                act, proj = np.flatnonzero(stepper.predicted_active(k, q, u)), inp.master_projection
            q1, u1, P, _ = stepper.step(k, q, u, act, False)
            q_pre = q1
            sig = None
            if proj and act.size:
                q1, sig = _project(stepper, inp.metric, NinvW, L, k + 1, q1, act)
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
    run_time = time.perf_counter() - t0
    st = stepper.stats
    return LoopOutput(rows, rec["q"], rec["u"], rec["P"], rec["sigma"], rec["active"], rec["chi"],
                      rec["q_pre"] if record_pre else None, "python",
                      {"contact_solves": st.contact_solves, "iterations": st.iterations,
                       "max_residual": st.max_residual, "fallbacks": st.fallbacks},
                      [], 0.0, run_time)


def _project(stepper, metric, NinvW, L, k, q, act):
    """The step's position projection: the library's K projection, or the N-metric one."""
    if metric is None:
        return stepper.project(k, q, act)
    g = q @ stepper.S.W[:, act] + stepper.grid.nu[k, act]
    sigma = -np.linalg.solve(L[np.ix_(act, act)], g)
    return q + NinvW[:, act] @ sigma, sigma


# ---------------------------------------------------------------------------------------
# engine="compiled": the numba kernel, with the reference solver for failed steps
# ---------------------------------------------------------------------------------------
_COMPILED = False


def compile_time() -> float:
    """Compile (or load from numba's on-disk cache) the kernel; return the seconds it took."""
    global _COMPILED
    t0 = time.perf_counter()
    if not _COMPILED:
        from observer.scenario import Scenario

        sc = Scenario.from_dict({
            "system": {"M": [[1.0, 0.0], [0.0, 1.0]], "C": [[0.1, 0.0], [0.0, 0.1]],
                       "K": [[1.0, 0.0], [0.0, 1.0]], "W": [[1.0, 0.0], [0.0, 1.0]],
                       "gap": {"offset": [0.0, 0.0]}},
            "impact": {"law": "poisson", "restitution": 0.5},
            "initial": {"q": [0.0, 0.0], "u": [-1.0, -1.0]},
            "simulation": {"t_end": 0.02, "h": 0.01}}, "warm-up")
        st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta)
        inp = LoopInput(st, np.stack([sc.q0, sc.q0]), np.stack([sc.u0, sc.u0]), np.array([False, True]),
                        False, np.ones(st.grid.steps, bool))
        _run_compiled(inp, 1, True, warm=True)
        _COMPILED = True
    return time.perf_counter() - t0


def kernel_data(stepper: MoreauJean, metric: np.ndarray | None) -> tuple:
    """The scheme's arrays in the kernel's argument order (after ``h, theta``)."""
    from observer.kernel import STRUCTURE_BANDED, STRUCTURE_DENSE

    S, grid = stepper.S, stepper.grid
    Wc = sp.csc_matrix(S.W)
    Wc.sort_indices()
    NinvW, L = projection_matrices(stepper, metric)
    band = S.band
    if band is None:
        structure, bw = STRUCTURE_DENSE, 0
        dummy = np.zeros((1, 1))
        Bu, Bq, Bf, Ru_b, Rq_b, Ach_b = S.Bu, S.Bq, S.Bf, dummy, dummy, dummy
    else:
        structure, bw = STRUCTURE_BANDED, band.bw
        dummy = np.zeros((1, 1))
        Bu = Bq = Bf = dummy
        Ru_b, Rq_b, Ach_b = band.Ru, band.Rq, band.Achol
    c = lambda a, dtype=np.float64: np.ascontiguousarray(a, dtype=dtype)  # noqa: E731
    return (structure, c(Bu), c(Bq), c(Bf), c(Ru_b), c(Rq_b), c(Ach_b), int(bw), c(grid.fbar),
            c(grid.nu), c(grid.nu_dot), c(Wc.indptr, np.int64), c(Wc.indices, np.int64), c(Wc.data),
            c(S.AinvW), c(S.Ghat), c(S.G0), c(NinvW), c(L), c(stepper.law.restitution),
            float(stepper.residual_tol))


def _run_compiled(inp: LoopInput, record_every: int, record_pre: bool, warm: bool = False) -> LoopOutput:
    from observer.kernel import OK, PROJECTION_FAILED, advance

    stepper = inp.stepper
    steps, m = stepper.grid.steps, stepper.system.m
    S = inp.q0.shape[0]
    ct = 0.0 if (warm or _COMPILED) else compile_time()
    rec, rows = _allocate(inp, record_every, record_pre)
    data = kernel_data(stepper, inp.metric)
    qs, us = inp.q0.astype(float).copy(), inp.u0.astype(float).copy()
    jumps = np.asarray(inp.jumps, dtype=np.bool_)
    coupled = np.asarray(inp.coupled, dtype=np.bool_)
    use_log = inp.chi_log is not None
    chi_log = np.asarray(inp.chi_log, dtype=np.bool_) if use_log else np.zeros((1, 1), np.bool_)
    chi_now = np.zeros(m, dtype=np.bool_)
    stats = np.zeros(3)
    law = int(stepper.law.code)
    fallbacks: list[dict] = []
    k, s = 0, 0
    t0 = time.perf_counter()
    while k < steps:
        k, s, status = advance(k, steps, s, qs, us, jumps, bool(inp.master_projection), coupled,
                               chi_log, use_log, chi_now, record_every, rec["q"], rec["u"], rec["P"],
                               rec["sigma"], rec["active"], rec["chi"], rec["q_pre"], record_pre,
                               law, stepper.h, stepper.theta, *data, stats)
        if status == OK:
            break
        if status == PROJECTION_FAILED:
            stepper.system.require_definite_stiffness("the position projection (position jumps)")
            raise InputError("system.W", f"W_IᵀK⁻¹W_I is not positive definite at step {k} "
                             f"(t = {stepper.grid.t[k]:.6g}): the closed contacts' columns of W "
                             "are dependent in the K metric")
        _fallback_step(inp, stepper, k, s, qs, us, chi_now, record_every, record_pre, rec)
        fallbacks.append({"step": int(k), "t": float(stepper.grid.t[k]), "system": int(s)})
        s += 1
        if s == S:
            k, s = k + 1, 0
    run_time = time.perf_counter() - t0
    ref = getattr(stepper, "_reference_twin", None)
    ref_stats = ref.stats if (ref is not None and fallbacks) else None
    return LoopOutput(rows, rec["q"], rec["u"], rec["P"], rec["sigma"], rec["active"], rec["chi"],
                      rec["q_pre"] if record_pre else None, "compiled",
                      {"contact_solves": int(stats[0]) + (ref_stats.contact_solves if ref_stats else 0),
                       "iterations": int(stats[1]) + (ref_stats.iterations if ref_stats else 0),
                       "max_residual": max(float(stats[2]), ref_stats.max_residual if ref_stats else 0.0),
                       "fallbacks": len(fallbacks)},
                      fallbacks, ct, run_time)


def _fallback_step(inp, stepper, k, s, qs, us, chi_now, record_every, record_pre, rec) -> None:
    """Step k of system s, which the kernel could not solve, with the reference solver."""
    ref = _reference_stepper(stepper)
    q, u = qs[s], us[s]
    if s == 0:
        act = np.flatnonzero(stepper.predicted_active(k, q, u))
        proj = inp.master_projection
        chi_now[:] = False
        chi_now[act if inp.chi_log is None else np.flatnonzero(inp.chi_log[k])] = True
    elif inp.coupled[k]:
        act, proj = np.flatnonzero(chi_now), bool(inp.jumps[s])
    else:
        act, proj = np.flatnonzero(stepper.predicted_active(k, q, u)), inp.master_projection
    q1, u1, P, _ = ref.step(k, q, u, act, False)
    q_pre = q1
    sig = None
    if proj and act.size:
        NinvW, L = projection_matrices(stepper, inp.metric)
        q1, sig = _project(stepper, inp.metric, NinvW, L, k + 1, q1, act)
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


def _reference_stepper(stepper: MoreauJean) -> MoreauJean:
    ref = getattr(stepper, "_reference_twin", None)
    if ref is None:
        ref = MoreauJean(stepper.system, stepper.law, stepper.h, float(stepper.grid.t[-1]),
                         stepper.theta, t0=float(stepper.grid.t[0]), solver="reference",
                         residual_tol=stepper.residual_tol)
        stepper._reference_twin = ref
    return ref
