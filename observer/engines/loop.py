"""What the two time-stepping engines' loops share: their input, output, records and guards.

The master and any number of observers advance together on arrays only, by one of two
engines that give one answer (the bitwise tests of ``tests/observer``):

* ``engine="python"`` (:mod:`observer.engines.python`) — the readable reference: every step
  is :meth:`observer.stepping.MoreauJean.step` (numpy), the implementation the docs explain;
* ``engine="compiled"`` (:mod:`observer.engines.compiled`) — the same scheme in one numba call
  per window of steps, with no allocation or Python dispatch per step. When the kernel's
  contact solve fails at a step (status ≠ 0), that step is re-solved by :func:`python_step`
  with the reference solver (cvxpy + OSQP), recorded in :attr:`LoopOutput.fallbacks`, and
  the kernel resumes — never silently.

Each engine's loop is its :meth:`~observer.engines.timestepping.TimeStepping.advance`; this
module holds what both read and write: :class:`LoopInput`, :class:`LoopOutput`,
:class:`Chunk`, the records (:func:`allocate_records`), the stop on a signal
(:class:`Stopper`) or a non-finite quantity (:class:`FiniteGuard`), the end of a run
(:func:`finish`), the projection metrics (:func:`projection_slots`) and one step of one
system by the numpy stepper (:func:`python_step`).

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
:data:`observer.engines.python.PYTHON_CHUNK` steps of the python one); with it, SIGINT, SIGTERM and SIGHUP stop the run
after the current window instead of killing it (``stop_signal``), so a streamed file
(:mod:`observer.stream`) keeps every finished step.
"""

from __future__ import annotations

import signal
import threading
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from observer.errors import InputError
from observer.result import RECORD_ARRAYS
from observer.sparse import abs_sum
from observer.stepping import MoreauJean

if TYPE_CHECKING:
    import pandas as pd



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


class Stopper:
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


STREAMED = tuple(a for a in RECORD_ARRAYS if not a.optional)
"""The record arrays a :class:`Chunk` carries (every one but the optional ``q_pre``)."""


def emitter(inp: LoopInput, rec: dict, record_every: int, on_chunk, rec_V=None):
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
        on_chunk(Chunk(rows, inp.stepper.time(rows), **{a.name: a.rows(rec[a.name], sl) for a in STREAMED},
                       V=None if rec_V is None else rec_V[:, sl], system=inp.stepper.system, names=names))
        state["done"] = r1

    return emit


def finish(inp: LoopInput, out: LoopOutput, stopped_at: int | None, reason: str = "",
            sig: str | None = None) -> LoopOutput:
    """Truncate the records of a stopped run to its last complete step, attach the health
    record and send its warnings to stderr."""
    from dataclasses import replace

    from observer.health import assess, emit

    if stopped_at is not None:
        R = min(out.q.shape[1], stopped_at // out.record_every + 1)   # the rows of steps ≤ stopped_at
        cut = {a.name: a.rows(getattr(out, a.name), slice(R)) for a in RECORD_ARRAYS
               if getattr(out, a.name) is not None}
        if out.t is not None:
            cut["t"] = out.t[:R]
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


def stopped_text(stepper, what: str, k: int) -> str:
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


def allocate_records(inp: LoopInput, record_every: int, record_pre: bool) -> tuple[dict, int]:
    """The loops' records (:data:`~observer.result.RECORD_ARRAYS`, name → array; ``q_pre`` with
    no rows unless ``record_pre``) with row 0 the initial states, and their row count R."""
    stepper = inp.stepper
    steps, n, m = stepper.steps, stepper.system.n, stepper.system.m
    S = inp.q0.shape[0]
    R = steps // record_every + 1
    rec = {a.name: a.allocate(S, R if record_pre or not a.optional else 0, n, m) for a in RECORD_ARRAYS}
    rec["q"][:, 0], rec["u"][:, 0] = inp.q0, inp.u0
    if record_pre:
        rec["q_pre"][:, 0] = inp.q0
    return rec, R


def loop_records(rec: dict, record_pre: bool) -> dict:
    """The record arrays of :func:`allocate_records` as :class:`LoopOutput`'s fields (``q_pre``
    None unless recorded)."""
    return {a.name: None if a.optional and not record_pre else rec[a.name] for a in RECORD_ARRAYS}


def python_step(inp: LoopInput, stepper: MoreauJean, k: int, s: int, q, u, chi,
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


def summary_frame(out: LoopOutput, names: list[str], t0: float, h: float, *,
                  frame: bool = True) -> "pd.DataFrame | list[dict]":
    """One row per observer from the kernel's streaming summary: V(t_on), max V, V(end), the
    count and largest relative size of the rises of V, the sums of the damping, impulse and
    remaining parts of ΔV, the largest impulse part relative to V, and per threshold ρ the
    first-passage time ``t_sync_ρ`` and the settling time ``t_settle_ρ`` (definitions of
    :mod:`observer.metrics`, evaluated at every step, not only at the recorded rows).
    ``frame=False`` returns the rows as dicts (``pandas.DataFrame(rows)`` is the frame)
    without importing pandas."""
    from observer.primitives import (F_DAMP, F_IMP, F_MAXIMP, F_MAXINC, F_NINC, F_PROJ, F_VEND, F_VMAX, F_VON,
                                     SUMMARY_FIELDS)
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
