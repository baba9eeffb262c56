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

The projection metric of the position jumps is K (paper eqs. (13)-(14)); ``metrics`` gives
each system its own metric N (``q⁺ = q⁻ − N⁻¹W_I(W_IᵀN⁻¹W_I)⁻¹g_I``: the registered designs
projecting in the mass or identity metric), and ``metric=N`` replaces K for every system
(the proof checks use it to build known-bad integrators). ``record_pre=True`` also keeps the positions
before the projection (``q_pre``), which the position-jump part of eq. (17) needs.

Every run ends with a :class:`~observer.health.Health` record (:attr:`LoopOutput.health`;
its warnings also go to stderr). A step whose complementarity residual, recomputed from the
velocity it applied, exceeds the tolerance stops the run there: the records are truncated
to the last complete step (no unwritten rows) and :attr:`LoopOutput.stopped_at` /
``stop_reason`` say where and why. So does a non-finite quantity (:class:`FiniteGuard`: a
state entry, a gap of the master or an observer's V): the run stops at the last step whose
every quantity is finite — the compiled engine checks once per window and re-runs a window
that fails one step at a time (the kernel is untouched), the python engine checks every step. ``on_chunk`` receives the finished rows as they are
produced (:class:`Chunk`: every window of the compiled engine, every
:data:`PYTHON_CHUNK` steps of the python one); with it, SIGINT, SIGTERM and SIGHUP stop the run
after the current window instead of killing it (``stop_signal``), so a streamed file
(:mod:`observer.stream`) keeps every finished step.
"""

from __future__ import annotations

import signal
import threading
import time
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from observer.errors import InputError
from observer.sparse import abs_sum
from observer.stepping import FACTORED_MIN_N, MoreauJean, NonFiniteState

if TYPE_CHECKING:
    import pandas as pd

    from observer.kernel import (LawBundle, ObserverBundle, SignalBundle, StateBundle, StorageBundle,
                                 SummaryBundle, SystemBundle, WindowBundle)

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
    coupling : (t_on, t_off) or None
        Steps with t_on ≤ t_k ≤ t_off couple the observers to χ_k (None: every step).
    self_driven : bool
        No step is coupled (``source="self"``): each observer uses its own predicted set.
    log : DataFrame or None
        Closing log (contact, t_close, t_open): χ_k from it instead of the master's set.
    chi : ndarray of bool, shape (N, m), optional
        χ_k given explicitly (row k = step k), overriding the master's set and the log.
    metric : ndarray (n, n) or None
        Projection metric of every system without its own (None: K).
    metrics : tuple of (ndarray (n, n) or None), length S, optional
        Per system, its own projection metric (None: ``metric``).
    names : tuple of str, length S − 1, optional
        The observers' names (for :class:`Chunk` consumers; default ``obs1``, ``obs2``, ...).
    """

    stepper: MoreauJean
    q0: np.ndarray
    u0: np.ndarray
    jumps: np.ndarray
    master_projection: bool
    coupling: tuple[float, float] | None = None
    self_driven: bool = False
    log: object = None
    chi: np.ndarray | None = None
    metric: np.ndarray | None = None
    metrics: tuple | None = None
    names: tuple = ()

    def metric_of(self, s: int) -> np.ndarray | None:
        """The projection metric of system s (None: K)."""
        if self.metrics is not None and self.metrics[s] is not None:
            return np.asarray(self.metrics[s], dtype=float)
        return self.metric

    def coupled(self, t: np.ndarray) -> np.ndarray:
        """Coupling of the steps of the window with grid points ``t`` (bool, len(t) − 1)."""
        from observer.switching import coupling_mask
        mask = coupling_mask(t, self.coupling)
        if self.self_driven:
            mask[:] = False
        return mask

    def chi_window(self, t: np.ndarray, k0: int) -> np.ndarray | None:
        """χ of the steps of the window starting at step k0 (None: the master's closed set)."""
        if self.chi is not None:
            return np.asarray(self.chi[k0:k0 + t.size - 1], dtype=bool)
        if self.log is not None:
            from observer.switching import sample_log
            return sample_log(self.log, t, self.stepper.system.m)
        return None


@dataclass(frozen=True)
class LoopOutput:
    """Records of one loop run; system s (0 = master) in the first axis.

    Row r holds step r·``record_every`` (the state after step r·record_every − 1, row 0 the
    initial state; ``rows``, built on first read, lists these step indices); ``P`` and
    ``sigma`` the impulse and projection multiplier of the step ending at the row; ``active``
    the master's closed set and ``chi`` the observers' signal of that step; ``q_pre`` (or
    None) the positions before the step's projection; ``t`` (or None) the rows' times
    t0 + rows·h when the loop computed them anyway (compiled engine, every step recorded): the
    values of ``stepper.time(rows)``.
    """

    record_every: int
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
    V: np.ndarray | None = None
    summary: dict | None = None
    stopped_at: int | None = None
    stop_reason: str = ""
    stop_signal: str | None = None
    health: object = None
    t: np.ndarray | None = None

    @cached_property
    def rows(self) -> np.ndarray:
        """The recorded step indices ``0, k, 2k, …`` (k = ``record_every``), one per row."""
        return np.arange(0, self.q.shape[1] * self.record_every, self.record_every)

    def stop_info(self, stepper) -> dict | None:
        """``{"step", "t", "reason", "signal"}`` of a stopped run (None: it ran to the end)."""
        if self.stopped_at is None:
            return None
        return {"step": int(self.stopped_at), "t": float(stepper.time(self.stopped_at)),
                "reason": self.stop_reason, "signal": self.stop_signal}


@dataclass(frozen=True)
class Chunk:
    """Finished rows ``rows`` (grid indices) of a running loop, as views of its records.

    ``q``, ``u``, ``P``, ``sigma`` have system s (0 = master) in the first axis; ``V`` the
    kernel's V per observer (``store="summary"``; else None); ``system`` and ``names`` (the
    observers') let a consumer build the result's columns (:mod:`observer.stream`).
    """

    rows: np.ndarray
    t: np.ndarray
    q: np.ndarray
    u: np.ndarray
    P: np.ndarray
    sigma: np.ndarray
    active: np.ndarray
    chi: np.ndarray
    V: np.ndarray | None
    system: object
    names: tuple


PYTHON_CHUNK = 4096
"""Steps between two chunks of the python engine."""


class _Stopper:
    """SIGINT/SIGTERM/SIGHUP → a flag the loop checks between windows (installed only while a
    streamed run is in progress, and only in the main thread)."""

    SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")

    def __init__(self, active: bool):
        self.signal: str | None = None
        self._old: dict = {}
        self._active = active and threading.current_thread() is threading.main_thread()

    def __enter__(self):
        if self._active:
            for name in self.SIGNALS:
                signum = getattr(signal, name)
                self._old[signum] = signal.signal(signum, self._handle)
        return self

    def _handle(self, signum, frame):
        self.signal = signal.Signals(signum).name

    def __exit__(self, *exc):
        for signum, old in self._old.items():
            signal.signal(signum, old)
        return False


def _emitter(inp: LoopInput, rec: dict, record_every: int, on_chunk, rec_V=None):
    """``emit(k)``: pass the rows finished up to grid index k (not yet passed) to ``on_chunk``."""
    state = {"done": 0}
    names = tuple(inp.names) or tuple(f"obs{i}" for i in range(1, inp.q0.shape[0]))

    def emit(k: int) -> None:
        if on_chunk is None:
            return
        r1 = min(rec["q"].shape[1], k // record_every + 1)     # rows r with r·record_every ≤ k
        r0 = state["done"]
        if r1 <= r0:
            return
        sl = slice(r0, r1)
        rows = np.arange(r0, r1) * record_every
        on_chunk(Chunk(rows, inp.stepper.time(rows), rec["q"][:, sl], rec["u"][:, sl],
                       rec["P"][:, sl], rec["sigma"][:, sl], rec["active"][sl], rec["chi"][sl],
                       None if rec_V is None else rec_V[:, sl], inp.stepper.system, names))
        state["done"] = r1

    return emit


def _finish(inp: LoopInput, out: LoopOutput, stopped_at: int | None, reason: str = "",
            sig: str | None = None) -> LoopOutput:
    """Truncate the records of a stopped run to its last complete step, attach the health
    record and send its warnings to stderr."""
    from dataclasses import replace

    from observer.health import assess, emit

    if stopped_at is not None:
        R = min(out.q.shape[1], stopped_at // out.record_every + 1)   # the rows of steps ≤ stopped_at
        cut = {k: getattr(out, k)[:, :R] for k in ("q", "u", "P", "sigma")}
        cut.update(active=out.active[:R], chi=out.chi[:R])
        if out.t is not None:
            cut["t"] = out.t[:R]
        if out.q_pre is not None:
            cut["q_pre"] = out.q_pre[:, :R]
        if out.V is not None:
            cut["V"] = out.V[:, :R]
        out = replace(out, stopped_at=int(stopped_at), stop_reason=reason, stop_signal=sig, **cut)
    if inp.stepper.S.factored:
        L = FactoredL(inp.stepper)
        L_of = lambda s: L  # noqa: E731
    else:
        slots, _, Ls = projection_slots(inp)
        L_of = lambda s: Ls[slots[s]]  # noqa: E731
    health = assess(inp, out.record_every, out.q, out.u, out.active, out.chi, out.stats, L_of)
    emit(health)
    return replace(out, health=health)


def _snapshot(state: tuple, fallbacks: list, stepper) -> tuple:
    """Copies of the loop's mutable arrays (and the fallbacks' count and reference statistics)."""
    from dataclasses import replace

    ref = getattr(stepper, "_reference_twin", None)
    return [a.copy() for a in state], len(fallbacks), None if ref is None else replace(ref.stats)


def _restore(state: tuple, snap: tuple, fallbacks: list, stepper) -> None:
    """Put back what :func:`_snapshot` copied (the records are rewritten by the re-run)."""
    from observer.stepping import StepStats

    arrays, nfb, ref_stats = snap
    for a, b in zip(state, arrays):
        a[...] = b
    del fallbacks[nfb:]
    ref = getattr(stepper, "_reference_twin", None)
    if ref is not None:
        ref.stats = StepStats() if ref_stats is None else ref_stats


OVERFLOW = 1e300
"""Bound on the result's derived quantities below which they are certainly finite (the
largest double is 1.8·10³⁰⁸): :class:`FiniteGuard` checks states against the magnitude that
keeps V and the gaps under it."""


class FiniteGuard:
    """Non-finite quantities are a stop, never a row.

    The result's columns are the states q, u of every system, the master's gaps
    ``g = Wᵀq + ν(t)`` and, per observer, ``V = ½vᵀMv + ½eᵀKe`` (v, e its differences to the
    master). With ``A = max |q_i|, |u_i|`` over the systems, ``|g_j| ≤ Σ|W|·A + |ν_j|`` and
    ``V ≤ 2A²(Σ|M| + Σ|K|)`` (|v_i|, |e_i| ≤ 2A), so every one of them is finite while
    ``A ≤`` :attr:`limit` (the bounds kept under :data:`OVERFLOW`). The loop compares A with
    the limit once per window (compiled engine; a NaN fails the comparison) or per step
    (python engine); past it, :meth:`first_problem` evaluates the quantities themselves and
    names the first that is not finite.
    """

    def __init__(self, inp: LoopInput):
        sys_ = inp.stepper.system
        self.inp = inp
        self.stepper = inp.stepper
        self.system = sys_
        self.S = inp.q0.shape[0]
        self.names = ("the master",) + tuple(
            f"observer {n!r}" for n in (tuple(inp.names) or tuple(f"obs{i}" for i in range(1, self.S))))
        with np.errstate(over="ignore", invalid="ignore"):
            lim = OVERFLOW / (abs_sum(sys_.W) + 1.0)
            if self.S > 1:
                quad = 2.0 * (abs_sum(sys_.M) + abs_sum(sys_.K))
                lim = min(lim, float(np.sqrt(OVERFLOW / quad)) if quad > 0.0 else lim)
        self.limit = lim if np.isfinite(lim) else 0.0

    def _within(self, *arrays) -> bool:
        """Every entry of ``arrays`` within :attr:`limit` (False for a NaN)."""
        for x in arrays:
            if x.size and not abs(x).max() <= self.limit:
                return False
        return True

    def state_ok(self, qs: np.ndarray, us: np.ndarray, summ: np.ndarray | None = None) -> bool:
        """Every state within :attr:`limit` (and the kernel's summary finite)."""
        return self._within(qs, us) and (summ is None or bool(np.all(np.isfinite(summ))))

    def first_problem(self, k: int, qs: np.ndarray, us: np.ndarray) -> str | None:
        """The first non-finite quantity of the states ``qs``, ``us`` (S, n) at grid index k:
        a state entry, a gap of the master, an observer's V (None: every one finite)."""
        if self._within(qs, us):
            return None
        from observer.observers import lyapunov

        for s in range(self.S):
            for name, x in (("u", us[s]), ("q", qs[s])):    # in the step's order: u_{k+1}, then q_{k+1}
                bad = np.flatnonzero(~np.isfinite(x))
                if bad.size:
                    return f"{name}{bad[0]} of {self.names[s]} ({x[bad[0]]})"
        t = float(self.stepper.time(k))
        with np.errstate(all="ignore"):
            g = self.system.gaps(qs[0], t)
            bad = np.flatnonzero(~np.isfinite(g))
            if bad.size:
                return f"gap g{bad[0]} of the master ({g[bad[0]]})"
            for s in range(1, self.S):
                V = float(lyapunov(self.system, qs[s][None], us[s][None], qs[0][None], us[0][None])[0])
                if not np.isfinite(V):
                    return f"V of {self.names[s]} ({V})"
        return None

    def free_velocity(self, k: int, s: int, q: np.ndarray, u: np.ndarray) -> str | None:
        """Whether step k of system s (state q, u) has a non-finite state or free velocity
        (the name of the quantity; None: finite)."""
        from observer.stepping import Grid

        for name, x in (("u", u), ("q", q)):
            bad = np.flatnonzero(~np.isfinite(x))
            if bad.size:
                return f"{name}{bad[0]} of {self.names[s]} ({x[bad[0]]})"
        st = self.stepper
        with np.errstate(all="ignore"):
            fbar = Grid.window(self.system, st.h, st.theta, st.t0, k, k + 1).fbar[0]
            if st.S.band is None:
                uf = st.S.Bu @ u + st.S.Bq @ q + st.S.Bf @ fbar
            else:
                uf = st.S.band.free_velocity(st.h, q, u, fbar)
        bad = np.flatnonzero(~np.isfinite(uf))
        if bad.size:
            return f"free velocity u{bad[0]} of {self.names[s]} ({uf[bad[0]]})"
        return None

    def stop_text(self, what: str, k: int) -> str:
        """The stop reason: ``what`` became non-finite in step k; the output ends at t_k."""
        st = self.stepper
        return (f"non-finite {what} at t = {float(st.time(k + 1)):.9g} (step {k} of {st.steps}); "
                f"the output ends at t = {float(st.time(k)):.9g}, the last finite state")


def _stop_text(stepper, what: str, k: int) -> str:
    return f"{what} at t = {float(stepper.time(k)):.9g} (step {k} of {stepper.steps})"


class FactoredL:
    """``L = WᵀK⁻¹W`` of factored contact data (:attr:`observer.stepping.SchemeMatrices.factored`),
    indexed by a closed set only: ``L[np.ix_(I, I)]`` is L_I from the banded factor of K
    (:meth:`observer.stepping.MoreauJean._active_slices`, O(n·bw·|I|)); zeros when K is not
    positive definite, as the dense ``L`` of :func:`projection_matrices`."""

    def __init__(self, stepper: MoreauJean):
        self.stepper = stepper

    def __getitem__(self, ix) -> np.ndarray:
        idx = np.asarray(ix[1], dtype=np.int64).ravel()
        L = self.stepper._active_slices(idx)[5]
        return np.zeros((idx.size, idx.size)) if L is None else L


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


def projection_slots(inp: LoopInput) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per system its slot in the stacks of the distinct projection metrics, and the stacks
    ``(N⁻¹W)ᵀ`` (P, m, n) and ``WᵀN⁻¹W`` (P, m, m) (contiguous, in the kernel's layout);
    computed once per input (the kernel's data, the run and its health all ask for them)."""
    cached = inp.__dict__.get("_projection_slots")
    if cached is not None:
        return cached
    S = inp.q0.shape[0]
    slots, keys, NinvWT, L = np.zeros(S, np.int64), [], [], []
    for s in range(S):
        N = inp.metric_of(s)
        key = None if N is None else N.tobytes()
        if key not in keys:
            keys.append(key)
            a, b = projection_matrices(inp.stepper, N)
            NinvWT.append(a.T)
            L.append(b)
        slots[s] = keys.index(key)
    out = slots, np.ascontiguousarray(np.stack(NinvWT)), np.ascontiguousarray(np.stack(L))
    object.__setattr__(inp, "_projection_slots", out)      # LoopInput is frozen: a private memo
    return out


STORES = ("full", "summary")
WINDOW = 1 << 14
"""Steps per window of the compiled engine (the signals of one window are built at a time).
16 384 steps keep a window's signals in cache (measured, 10⁵ steps of the chain N = 10: 2.9 µs
per step in all with 65 536, 2.4 µs with 16 384; the 1-DOF oscillator: no difference), at the
cost of one kernel call and one grid evaluation per window."""


def run(inp: LoopInput, engine: str = "compiled", record_every: int = 1,
        record_pre: bool = False, store: str = "full", rhos: tuple | None = None,
        on_chunk=None) -> LoopOutput:
    """Advance the master and the observers of ``inp`` over the stepper's grid.

    ``store="summary"`` (compiled engine) also computes, streaming over every step, what the
    synchronization metrics need (:func:`summary_frame`); with it the trajectories are kept
    only every ``record_every`` steps, so memory does not grow with the horizon beyond that.

    ``on_chunk(chunk)`` (optional) is called with each :class:`Chunk` of finished rows, in
    order, the last one before returning; while it is set, SIGINT, SIGTERM and SIGHUP stop the run
    after the current window (``LoopOutput.stop_signal``) instead of raising.
    """
    check_engine(engine)
    record_every = check_record_every(record_every)
    if store not in STORES:
        raise InputError("store", f"must be one of {list(STORES)}, got {store!r}")
    if engine == "python":
        if store == "summary":
            raise InputError("store", 'store="summary" needs engine="compiled"')
        with _Stopper(on_chunk is not None) as stopper:
            return _run_python(inp, record_every, record_pre, on_chunk, stopper)
    from observer.metrics import RHOS
    with _Stopper(on_chunk is not None) as stopper:
        return _run_compiled(inp, record_every, record_pre, store == "summary",
                             tuple(RHOS if rhos is None else rhos), on_chunk=on_chunk, stopper=stopper)


def _allocate(inp: LoopInput, record_every: int, record_pre: bool):
    stepper = inp.stepper
    steps, n, m = stepper.steps, stepper.system.n, stepper.system.m
    S = inp.q0.shape[0]
    R = steps // record_every + 1
    rec = {"q": np.empty((S, R, n)), "u": np.empty((S, R, n)), "P": np.zeros((S, R, m)),
           "sigma": np.zeros((S, R, m)), "active": np.zeros((R, m), dtype=bool),
           "chi": np.zeros((R, m), dtype=bool),
           "q_pre": np.empty((S, R if record_pre else 0, n))}
    rec["q"][:, 0], rec["u"][:, 0] = inp.q0, inp.u0
    if record_pre:
        rec["q_pre"][:, 0] = inp.q0
    return rec, R


# ---------------------------------------------------------------------------------------
# engine="python": the reference
# ---------------------------------------------------------------------------------------
def _run_python(inp: LoopInput, record_every: int, record_pre: bool, on_chunk=None,
                stopper: _Stopper | None = None) -> LoopOutput:
    stepper = inp.stepper
    rec, _ = _allocate(inp, record_every, record_pre)
    S = inp.q0.shape[0]
    states = [(inp.q0[s].copy(), inp.u0[s].copy()) for s in range(S)]
    coupled = inp.coupled(stepper.grid.t)
    chi_log = inp.chi_window(stepper.grid.t, 0)
    emit = _emitter(inp, rec, record_every, on_chunk)
    health = {"applied_residual": 0.0, "applied_residual_step": -1, "min_gap": np.inf,
              "min_gap_step": -1, "residual_source": "applied"}
    tol = float(stepper.residual_tol)
    stop, reason = None, ""
    t0 = time.perf_counter()
    guard = FiniteGuard(inp)
    with np.errstate(over="ignore", invalid="ignore"):     # overflow: the guard's to stop
        for k in range(stepper.grid.steps):
            if stopper is not None and stopper.signal:
                stop, reason = k, _stop_text(stepper, stopper.signal, k)
                break
            r = (k + 1) // record_every if (k + 1) % record_every == 0 else -1
            chi = None
            within = True
            for s in range(S):
                q, u = states[s]
                try:
                    q1, u1, P, sig, q_pre, act, chi = _python_step(inp, stepper, k, s, q, u, chi, coupled[k],
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
                    stop, reason = k, _stop_text(stepper, f"complementarity residual {res:.3g} > "
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
    out = LoopOutput(record_every, rec["q"], rec["u"], rec["P"], rec["sigma"], rec["active"], rec["chi"],
                     rec["q_pre"] if record_pre else None, "python",
                     {"contact_solves": st.contact_solves, "iterations": st.iterations,
                      "max_residual": st.max_residual, "fallbacks": st.fallbacks, **health},
                     [], 0.0, run_time)
    return _finish(inp, out, stop, reason, stopper.signal if stopper is not None else None)


def _python_health(stepper: MoreauJean, k: int, s: int, q, u, u1, P, act, q1, health: dict) -> float:
    """Fold step k of system s into ``health``; return its recomputed residual (0 without
    contacts). The master's gaps after the step update the deepest penetration. The residual
    is that of Newton's discrete law ``0 ≤ γ_{k+1} + e∘γ_k ⊥ P ≥ 0`` with ``ĜP`` replaced by
    ``W_Aᵀ(u_{k+1} − u_free)`` (the kernel's :func:`observer.kernel.applied_residual`), valid
    where the law declares its step Newton's (:meth:`~observer.impact.ImpactLawDefinition.newton_on`:
    Newton's law, a one-contact Poisson step); other steps count the solver's own residual
    (``residual_source = "applied+solver"``)."""
    if s == 0:
        g = stepper.system.gaps(q1, stepper.time(k + 1))
        j = int(np.argmin(g)) if g.size else -1
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
    kernel's own :func:`observer.kernel.applied_residual` (one implementation for both engines)."""
    from observer.kernel import applied_residual

    W_A = stepper.S.W[:, act]
    u_free = stepper.free_velocity(k, q, u)
    nd = stepper.grid.nu_dot
    b = (u_free @ W_A + nd[k + 1, act]) + stepper.law.restitution[act] * (u @ W_A + nd[k, act])
    du = stepper._active_slices(act)[1] @ P if stepper.S.factored else stepper.S.AinvW[:, act] @ P
    Wp, Wi, Wv = stepper.csc
    c = lambda x, dtype=np.float64: np.ascontiguousarray(x, dtype=dtype)  # noqa: E731
    return float(applied_residual(Wp, Wi, Wv, c(act, np.int64), int(act.size), c(du), c(b), c(P)))


def _python_step(inp: LoopInput, stepper: MoreauJean, k: int, s: int, q, u, chi,
                 coupled_k: bool, chi_row):
    """Step k of system s with the numpy stepper: its closed set (the master's predictor, χ
    while coupled, else its own predictor), the step, the projection. Returns
    ``(q1, u1, P, Σ or None, q_pre, closed set, χ)``; χ is the master's set (or the log's
    row) after the master's step, and passed through otherwise."""
    if s == 0:
        act = np.flatnonzero(stepper.predicted_active(k, q, u))
        proj = inp.master_projection
        chi = act if chi_row is None else np.flatnonzero(chi_row)
    elif coupled_k:
        act, proj = chi, bool(inp.jumps[s])
    else:
        act, proj = np.flatnonzero(stepper.predicted_active(k, q, u)), inp.master_projection
    q1, u1, P, _ = stepper.step(k, q, u, act, False)
    q_pre = q1
    sig = None
    if proj and act.size and stepper.S.factored:     # the K metric from its factor
        q1, sig = stepper.project(k + 1, q1, act, None if inp.metric_of(s) is None else (None, None))
    elif proj and act.size:
        slots, NinvWT, L = projection_slots(inp)        # the kernel's projection, in system s's metric
        q1, sig = stepper.project(k + 1, q1, act, (NinvWT, L), slots[s])
    return q1, u1, P, sig, q_pre, act, chi




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
                        False)
        _run_compiled(inp, 1, True, True, (1e-3,), warm=True)             # the general loop
        _run_compiled(LoopInput(st, sc.q0[None], sc.u0[None], np.array([False]), False), 1, False,
                      warm=True)                                            # the lean one
        one = Scenario.from_dict({
            "system": {"M": [[1.0]], "C": [[0.1]], "K": [[1.0]], "W": [[1.0]], "gap": {"offset": [0.0]}},
            "impact": {"law": "newton", "restitution": 0.5}, "initial": {"q": [0.0], "u": [-1.0]},
            "simulation": {"t_end": 0.02, "h": 0.01}}, "warm-up")
        st = MoreauJean(one.system, one.law, one.h, one.t_end, one.theta)
        _run_compiled(LoopInput(st, one.q0[None], one.u0[None], np.array([False]), False), 1, False,
                      warm=True)                                            # and the scalar one
        _COMPILED = True
    return time.perf_counter() - t0


def system_bundle(inp: LoopInput) -> "SystemBundle":
    """The scheme's constant arrays in the kernel's layout (:class:`observer.kernel.SystemBundle`):
    dense ``Bu, Bq, Bf`` or the banded ``R_u, R_q`` and factor of Â, W in CSC, ``(Â⁻¹W)ᵀ``,
    Ĝ, G₀, and the grid's h, θ, t0. Every array a fresh C-contiguous float64 (or int64) one,
    so that every run types the kernel alike (:func:`quadratic_forms`)."""
    from observer.kernel import CONTACTS_DENSE, CONTACTS_FACTORED, STRUCTURE_BANDED, STRUCTURE_DENSE, SystemBundle

    stepper = inp.stepper
    S = stepper.S
    Wp, Wi, Wv = stepper.csc
    c = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    dummy = np.zeros((1, 1))
    if S.band is None:
        structure, dense, banded, bw = STRUCTURE_DENSE, (c(S.Bu), c(S.Bq), c(S.Bf)), (dummy,) * 3, 0
    else:
        b = S.band
        banded = (c(b.Ru), c(b.Rq), c(b.Achol))
        structure, dense, bw = STRUCTURE_BANDED, (dummy,) * 3, int(b.bw)
    if S.factored:
        contacts, cache = CONTACTS_FACTORED, column_cache(1, stepper.system.n, stepper.system.m)
        AinvWT, Ghat, G0 = dummy, dummy, dummy
    else:
        contacts, cache = CONTACTS_DENSE, column_cache(1, 1, 1, 1)
        AinvWT, Ghat, G0 = c(S.AinvW.T), c(S.Ghat), c(S.G0)
    return SystemBundle(structure=structure, Bu=dense[0], Bq=dense[1], Bf=dense[2], Ru_b=banded[0],
                        Rq_b=banded[1], Ach_b=banded[2], bw=bw, Wp=Wp, Wi=Wi, Wv=Wv, AinvWT=AinvWT,
                        Ghat=Ghat, G0=G0, contacts=contacts, Acache=cache[0][0], Aslot=cache[1][0],
                        Aowner=cache[2][0], Astamp=cache[3][0], h=float(stepper.h),
                        theta=float(stepper.theta), t0=float(stepper.t0))


FACTORED_CACHE_BYTES = 1 << 26
"""Memory of each cache of solved columns (``N⁻¹W_j``) of the factored contact data: 64 MiB,
at least 8 and at most 256 columns (:func:`column_cache`)."""


def column_cache(P: int, n: int, m: int, C: int | None = None) -> tuple[np.ndarray, ...]:
    """P empty caches of C solved columns of length n for m contacts, in the kernel's layout
    (:func:`observer.kernel._factored_column`): ``(cols (P, C, n), slot_of (P, m) = −1,
    owner (P, C) = −1, stamp (P, C + 1) = 0)``; C from :data:`FACTORED_CACHE_BYTES` unless given."""
    if C is None:
        C = int(min(m, max(8, min(256, FACTORED_CACHE_BYTES // (8 * n)))))
    return (np.zeros((P, C, n)), np.full((P, m), -1, np.int64), np.full((P, C), -1, np.int64),
            np.zeros((P, C + 1), np.int64))


def law_bundle(stepper: MoreauJean) -> "LawBundle":
    """The impact law's kernel code, its restitution and the residual tolerance."""
    from observer.kernel import LawBundle

    e = np.ascontiguousarray(stepper.law.restitution, dtype=np.float64)
    return LawBundle(code=int(stepper.law.code), e=e, tol=float(stepper.residual_tol))


def observer_bundle(inp: LoopInput) -> "ObserverBundle":
    """The designs' jumps, each system's projection slot and the stacked metrics
    (:func:`projection_slots`)."""
    from observer.kernel import ObserverBundle

    jumps, mp = np.asarray(inp.jumps, dtype=np.bool_), bool(inp.master_projection)
    st = inp.stepper
    if st.S.factored:
        slots, Kch = factored_metrics(inp)
        cache = column_cache(Kch.shape[0], st.system.n, st.system.m)
        dummy = np.zeros((1, 1, 1))
        return ObserverBundle(jumps=jumps, slots=slots, master_projection=mp, KinvWT=dummy, L=dummy, Kch=Kch,
                              bwk=int(Kch.shape[1] - 1), Kcache=cache[0], Kslot=cache[1], Kowner=cache[2],
                              Kstamp=cache[3])
    slots, NinvWT, L = projection_slots(inp)
    cache = column_cache(1, 1, 1, 1)
    return ObserverBundle(jumps=jumps, slots=slots, master_projection=mp, KinvWT=NinvWT, L=L,
                          Kch=np.zeros((1, 1, 1)), bwk=0, Kcache=cache[0], Kslot=cache[1], Kowner=cache[2],
                          Kstamp=cache[3])


def factored_metrics(inp: LoopInput) -> tuple[np.ndarray, np.ndarray]:
    """With factored contact data: every system's projection slot (0) and the one metric's
    banded factor stack (1, bw + 1, n), K's (zeros when K is not positive definite: the
    projection then fails, :data:`observer.kernel.PROJECTION_FAILED`). Another metric raises
    :class:`InputError` naming ``observers``."""
    st = inp.stepper
    if any(inp.metric_of(s) is not None for s in range(inp.q0.shape[0])):
        raise InputError("observers", "a projection metric other than K (jump_mass, jump_identity) needs "
                         f"n < {FACTORED_MIN_N} degrees of freedom; this system has "
                         f"n = {st.system.n} (use the K-metric design \"jump\")")
    b = st.S.band
    Kch = np.zeros((b.bw + 1, st.system.n)) if b.Kchol is None else np.array(b.Kchol, dtype=np.float64)
    return np.zeros(inp.q0.shape[0], np.int64), np.ascontiguousarray(Kch[None])


def state_bundle(inp: LoopInput) -> "StateBundle":
    """Fresh copies of the initial states, χ cleared, the counters at their start values."""
    from observer.kernel import STATS_SIZE, StateBundle

    stats = np.zeros(STATS_SIZE)
    stats[3:7] = (np.inf, -1.0, 0.0, -1.0)
    return StateBundle(qs=inp.q0.astype(float).copy(), us=inp.u0.astype(float).copy(),
                       chi_now=np.zeros(inp.stepper.system.m, dtype=np.bool_), stats=stats)


def storage_bundle(rec: dict, record_every: int, record_pre: bool, t_rec: np.ndarray | None) -> "StorageBundle":
    """The records of :func:`_allocate` (``t_rec``: the rows' times, or None)."""
    from observer.kernel import StorageBundle

    return StorageBundle(record_every=int(record_every), q=rec["q"], u=rec["u"], P=rec["P"], sigma=rec["sigma"],
                         active=rec["active"], chi=rec["chi"], q_pre=rec["q_pre"], record_pre=bool(record_pre),
                         t=np.empty(0) if t_rec is None else t_rec)


def summary_bundle(inp: LoopInput, on: bool, rhos: tuple, R: int) -> "SummaryBundle":
    """The streaming summary's arrays (placeholders of the same types when ``on`` is False)."""
    from observer.kernel import SUMMARY_FIELDS, SummaryBundle

    S, n, m = inp.q0.shape[0], inp.stepper.system.n, inp.stepper.system.m
    Mq, Kq, Cq = quadratic_forms(inp.stepper) if on else (np.zeros((1, 1)),) * 3
    rho_arr = np.asarray(rhos, dtype=np.float64)
    k_on, k_off = coupling_samples(inp)
    summ = np.zeros((S, SUMMARY_FIELDS + 2 * rho_arr.size))
    summ[:, SUMMARY_FIELDS:] = -1.0
    return SummaryBundle(on=bool(on), k_on=int(k_on), k_off=int(k_off), rhos=rho_arr, summ=summ,
                         vprev=np.zeros((S, n)), Vprev=np.zeros(S), rec_V=np.zeros((S, R if on else 0)),
                         closings=np.zeros(m, np.int64), prev_act=np.zeros(m, np.bool_), Mq=Mq, Kq=Kq, Cq=Cq)


_NO_COUPLING, _NO_LOG = np.zeros(1, np.bool_), np.zeros((1, 1), np.bool_)


def window_bundle(inp: LoopInput, signals: "SignalBundle", kb: int, k1: int,
                  tw: np.ndarray | None) -> "WindowBundle":
    """The window of steps kb..k1: its waves, and (with observers; ``tw`` its grid points)
    the coupling and χ from a log."""
    from observer.kernel import WindowBundle

    st = inp.stepper
    waves = wave_table(st.t0, st.h, kb, k1, signals.omega, signals.phase, signals.function)
    if inp.q0.shape[0] == 1:
        return WindowBundle(kb=int(kb), waves=waves, coupled=_NO_COUPLING, chi_log=_NO_LOG, use_log=False)
    chi_w = inp.chi_window(tw, kb)
    return WindowBundle(kb=int(kb), waves=waves, coupled=np.ascontiguousarray(inp.coupled(tw), dtype=np.bool_),
                        chi_log=_NO_LOG if chi_w is None else np.ascontiguousarray(chi_w, dtype=np.bool_),
                        use_log=chi_w is not None)


def signal_tables(system) -> "SignalBundle":
    """The kernel's tables of the signals f(t), ν(t), ν̇(t) (:func:`observer.kernel.advance`
    evaluates them at every grid point), as a :class:`observer.kernel.SignalBundle`.

    ``(ω, phase, function)`` of the distinct waves (function codes
    :data:`~observer.kernel.WAVE_COS`, ``WAVE_SIN``, ``WAVE_MINUS_SIN``); the entries
    ``(column, coefficient, wave)`` of f, then ν, then ν̇, each signal's in the summation
    order of :meth:`observer.model.Harmonic.entries` (``e_ptr`` (4,): signal i's entries are
    ``e_ptr[i]:e_ptr[i+1]``); the varying columns (those with an entry) of the three signals
    (``v_ptr``, ``v_col`` likewise); and the constants of f and ν. A wave shared by several
    entries (the same ω, phase and function) is evaluated once per grid point.
    """
    from observer.kernel import WAVE_NAMES, SignalBundle

    codes = {name: code for code, name in enumerate(WAVE_NAMES)}
    waves: dict[tuple, int] = {}
    cols, coefs, wave, e_ptr, v_col, v_ptr = [], [], [], [0], [], [0]
    for entries in (system.forcing.entries(), system.gap.entries(), system.gap.entries(derivative=True)):
        for col, coef, w, ph, fn in entries:
            cols.append(col)
            coefs.append(coef)
            wave.append(waves.setdefault((w, ph, codes[fn]), len(waves)))
        varying = sorted({col for col, *_ in entries})
        v_col += varying
        e_ptr.append(len(cols))
        v_ptr.append(len(v_col))
    wv = np.array(list(waves), dtype=float).reshape(-1, 3)
    i64 = lambda x: np.array(x, dtype=np.int64)  # noqa: E731
    return SignalBundle(omega=np.ascontiguousarray(wv[:, 0]), phase=np.ascontiguousarray(wv[:, 1]),
                        function=wv[:, 2].astype(np.int64), e_ptr=i64(e_ptr), e_col=i64(cols),
                        e_coef=np.array(coefs, dtype=float), e_wave=i64(wave), v_ptr=i64(v_ptr), v_col=i64(v_col),
                        f_c=np.ascontiguousarray(system.forcing.constant, dtype=float),
                        nu_c=np.ascontiguousarray(system.gap.constant, dtype=float))


SPECIALIZATIONS = ("general", "lean", "scalar")
"""The compiled loop's specializations, from the most general (:func:`specialization`)."""


def specialization(S: int, structure: int, summary: bool, record_pre: bool, master_projection: bool,
                   n: int, m: int) -> str:
    """Which compiled loop a run takes (each the same operations as the general one on what
    it runs: bitwise the same trajectory).

    ``"lean"``: the master alone, dense structure, no summary, no pre-projection records and
    no master projection (:func:`observer.kernel.advance` with ``general=None``); ``"scalar"``:
    that case with one degree of freedom and one contact (:func:`observer.kernel.advance_scalar`,
    the state in registers); ``"general"`` otherwise.
    """
    from observer.kernel import STRUCTURE_DENSE

    if not (S == 1 and structure == STRUCTURE_DENSE and not summary and not record_pre
            and not master_projection):
        return "general"
    return "scalar" if n == 1 and m == 1 else "lean"


def wave_table(t0: float, h: float, k0: int, k1: int, omega: np.ndarray, phase: np.ndarray,
               function: np.ndarray) -> np.ndarray:
    """The waves of :func:`signal_tables` at the grid points k0..k1: shape (waves, k1 − k0 + 1),
    entry ``[p, k − k0] = function_p(ω_p t_k + phase_p)``, the values of
    :func:`observer.model.grid_wave` (so of :meth:`observer.model.Harmonic.on_grid`) bit for
    bit: its anchors (:func:`observer.model.grid_anchors`, numpy) combined by the compiled
    :func:`observer.kernel.fill_waves`."""
    from observer.kernel import fill_waves
    from observer.model import grid_anchors

    P = omega.size
    out = np.empty((P, k1 - k0 + 1))
    if P == 0:
        return out
    anchors = [grid_anchors(t0, h, k0, k1, w, ph) for w, ph in zip(omega, phase)]
    ca, sa, cb, sb = (np.ascontiguousarray([a[i] for a in anchors], dtype=np.float64) for i in range(4))
    fill_waves(ca, sa, cb, sb, np.ascontiguousarray(function, dtype=np.int64), int(k0), out)
    return out


def quadratic_forms(stepper: MoreauJean) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, K and the symmetric part of C in the kernel's structure (dense or lower band).

    Always fresh writable C-contiguous copies: numba types a read-only array differently, so
    passing the scenario's (sometimes read-only) matrices as they are compiled a second
    specialization of the kernel in the middle of a timed run (12–17 s, seen in the bench's
    observer cases)."""
    from observer.stepping import dense, to_band

    sys_ = stepper.system
    C = 0.5 * (sys_.C + sys_.C.T)
    if stepper.S.band is None:
        return tuple(np.array(dense(A), dtype=np.float64, order="C", copy=True) for A in (sys_.M, sys_.K, C))
    bw = stepper.S.band.bw
    return tuple(np.array(to_band(A, bw), dtype=np.float64, order="C", copy=True) for A in (sys_.M, sys_.K, C))


def coupling_samples(inp: LoopInput) -> tuple[int, int]:
    """Grid samples k_on..k_off of the coupling window (t_on ≤ t_k ≤ t_off), as in
    :func:`observer.metrics.sync_time`; the whole run when not coupled to a window."""
    st = inp.stepper
    if inp.coupling is None or inp.self_driven:
        return 0, st.steps
    t_on, t_off = inp.coupling
    k_on = max(0, int(np.ceil((t_on - st.t0) / st.h - 1e-9)))
    while k_on > 0 and st.time(k_on - 1) >= t_on:
        k_on -= 1
    while k_on <= st.steps and st.time(k_on) < t_on:
        k_on += 1
    k_off = min(st.steps, int(np.floor((t_off - st.t0) / st.h + 1e-9)))
    while k_off < st.steps and st.time(k_off + 1) <= t_off:
        k_off += 1
    while k_off >= 0 and st.time(k_off) > t_off:
        k_off -= 1
    return k_on, k_off


class _CompiledRun:
    """One run of the compiled engine: the kernel's bundles, built once, and the windows.

    The run advances window by window (:data:`WINDOW` steps): :meth:`window` calls the kernel
    (:meth:`advance_to`, which handles its statuses: the reference solver for a failed
    contact step, a stop for an exceeded residual) and, when the window ends with a
    non-finite (or overflowing) state, runs it again one step at a time to stop before the
    step that made it (:class:`FiniteGuard`); :meth:`output` assembles the records.
    """

    def __init__(self, inp: LoopInput, record_every: int, record_pre: bool, summary: bool, rhos: tuple,
                 warm: bool, on_chunk, stopper: _Stopper | None):
        from observer.kernel import summary_start

        st = self.stepper = inp.stepper
        self.inp, self.warm, self.stopper, self.rhos = inp, warm, stopper, rhos
        self.S = inp.q0.shape[0]
        self.compile_time = 0.0 if (warm or _COMPILED) else compile_time()
        self.rec, R = _allocate(inp, record_every, record_pre)
        self.t_rec = np.empty(R) if record_every == 1 else None
        if self.t_rec is not None:
            self.t_rec[0] = st.time(np.zeros(1, np.int64))[0]   # row 0; rows 1.. by the loop (scalar) or tw
        self.system, self.law, self.signals = system_bundle(inp), law_bundle(st), signal_tables(st.system)
        self.observers, self.state = observer_bundle(inp), state_bundle(inp)
        self.storage = storage_bundle(self.rec, record_every, record_pre, self.t_rec)
        self.tally = summary_bundle(inp, summary, rhos, R)
        self.spec = specialization(self.S, self.system.structure, summary, record_pre, inp.master_projection,
                                   st.system.n, st.system.m)
        if summary:
            summary_start(self.state, self.system, self.tally)
        self.fallbacks: list[dict] = []
        self.emit = _emitter(inp, self.rec, record_every, on_chunk, self.tally.rec_V if summary else None)
        self.guard = FiniteGuard(inp)
        t = self.tally
        self.mutable = (*self.state, t.summ, t.vprev, t.Vprev, t.closings, t.prev_act)

    def kernel(self, window, k: int, k_end: int, s: int) -> tuple[int, int, int]:
        """One kernel call from (k, s) up to step k_end in the run's specialization."""
        from observer import kernel

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
        from observer.kernel import OK

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
        from observer.kernel import PROJECTION_FAILED, RESIDUAL_EXCEEDED

        st = self.stepper
        if status == RESIDUAL_EXCEEDED:
            return _stop_text(st, f"complementarity residual {self.state.stats[7]:.3g} > tolerance "
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
        _fallback_step(self.inp, st, k, s, self.state.qs, self.state.us, self.state.chi_now,
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
                stop, reason = k, _stop_text(self.stepper, self.stopper.signal, k)
                break
            k, s, stop, reason = self.window(k, s)
            self.emit(k if stop is None else stop)
        out = self.output(time.perf_counter() - t0)
        if self.warm:
            return out
        return _finish(self.inp, out, stop, reason, self.stopper.signal if self.stopper is not None else None)

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
        return LoopOutput(self.storage.record_every, rec["q"], rec["u"], rec["P"], rec["sigma"], rec["active"],
                          rec["chi"], rec["q_pre"] if self.storage.record_pre else None, "compiled", counts,
                          self.fallbacks, self.compile_time, run_time, t.rec_V if t.on else None, out_summary,
                          t=self.t_rec)


def _run_compiled(inp: LoopInput, record_every: int, record_pre: bool, summary: bool = False,
                  rhos: tuple = (1e-3,), warm: bool = False, on_chunk=None,
                  stopper: _Stopper | None = None) -> LoopOutput:
    """Run ``inp`` on the compiled engine (:class:`_CompiledRun`); ``warm``: a compile-only
    run (no guard re-runs, no health record)."""
    return _CompiledRun(inp, record_every, record_pre, summary, rhos, warm, on_chunk, stopper).run()


def summary_frame(out: LoopOutput, names: list[str], t0: float, h: float, *,
                  frame: bool = True) -> "pd.DataFrame | list[dict]":
    """One row per observer from the kernel's streaming summary: V(t_on), max V, V(end), the
    count and largest relative size of the rises of V, the sums of the damping, impulse and
    remaining parts of ΔV, the largest impulse part relative to V, and per threshold ρ the
    first-passage time ``t_sync_ρ`` and the settling time ``t_settle_ρ`` (definitions of
    :mod:`observer.metrics`, evaluated at every step, not only at the recorded rows).
    ``frame=False`` returns the rows as dicts (``pandas.DataFrame(rows)`` is the frame)
    without importing pandas."""
    from observer.kernel import (F_DAMP, F_IMP, F_MAXIMP, F_MAXINC, F_NINC, F_PROJ, F_VEND, F_VMAX,
                                 F_VON, SUMMARY_FIELDS)
    from observer.metrics import settle_column, sync_column

    sm = out.summary
    f, rhos, k_on, k_off = sm["fields"], sm["rhos"], sm["k_on"], sm["k_off"]
    rows = []
    for s, name in enumerate(names, start=1):
        row = {"observer": name, "t_on": t0 + k_on * h, "t_off": t0 + k_off * h, "V_on": f[s, F_VON],
               "V_max": f[s, F_VMAX], "V_end": f[s, F_VEND], "rises": int(f[s, F_NINC]),
               "max_rise_rel": f[s, F_MAXINC], "sum_damping": f[s, F_DAMP],
               "sum_impulse": f[s, F_IMP], "sum_projection": f[s, F_PROJ],
               "max_impulse_rel": f[s, F_MAXIMP]}
        for i, rho in enumerate(rhos):
            first, last = f[s, SUMMARY_FIELDS + i], f[s, SUMMARY_FIELDS + len(rhos) + i]
            row[sync_column(rho)] = (first - k_on) * h if first >= 0 else float("inf")
            row[settle_column(rho)] = (0.0 if last < 0 else float("inf") if last >= k_off
                                        else (last + 1 - k_on) * h)
        rows.append(row)
    if not frame:
        return rows
    import pandas as pd

    return pd.DataFrame(rows)


def _fallback_step(inp, stepper, k, s, qs, us, chi_now, record_every, record_pre, rec,
                   coupled_k, chi_row) -> None:
    """Step k of system s, which the kernel could not solve, with the reference solver."""
    ref = _reference_stepper(stepper)
    q1, u1, P, sig, q_pre, act, chi = _python_step(inp, ref, k, s, qs[s], us[s],
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


def _reference_stepper(stepper: MoreauJean) -> MoreauJean:
    """The stepper's twin with the reference solver (same grid), built once."""
    ref = getattr(stepper, "_reference_twin", None)
    if ref is None:
        ref = MoreauJean(stepper.system, stepper.law, stepper.h, float(stepper.time(stepper.steps)),
                         stepper.theta, t0=stepper.t0, solver="reference",
                         residual_tol=stepper.residual_tol,
                         structure="banded" if stepper.S.factored else "dense")
        stepper._reference_twin = ref
    return ref
