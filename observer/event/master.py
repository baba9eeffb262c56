"""The master's exact event-driven integration (issue 11): impacts, grazing, persistent contact, Zeno.

Between events the master follows the exact flow of :mod:`observer.event.flow` for its
current persistent-contact set I; the next event is the first zero, isolated by
:func:`observer.event.roots.first_zero` (it cannot be missed), of

* a gap g_j of an open contact (paper eq. (2)): a **cross** is an impact, a **touch**
  (double root within round-off) a graze;
* a force λ_i of a closed contact: a cross is a **lift-off**.

Impacts go through the impact laws of time-stepping (:func:`observer.impact.impact`:
generalized Newton, eq. (5), or Poisson, eq. (6)) with the Delassus matrix
``G = W_Aᵀ M⁻¹ W_A`` of the closed set A, which holds every contact that is closed at
the impact instant (simultaneous impacts: the multi-contact law). After an impact the
contacts with ``γ⁺ = 0`` (within round-off) enter persistent contact if the
acceleration LCP ``0 ≤ λ ⊥ γ̇ = G λ + γ̇_free ≥ 0`` gives them a positive force.

Grazing (certified bands, no scale of the motion): a **touch**, a local minimum m* of
g_j whose certified enclosure meets the touch band ±δ (:func:`observer.event.roots.graze_band`:
the evaluation error at the minimum, the run's accumulated state error carried there,
:meth:`_Run.search_band`, and the data's representation in the user's coordinates)
is a graze with zero impulse (the run continues past it); its row carries ``depth = m*`` and
a note stating the enclosure, δ and the guaranteed crossing depth δ* = δ + its width.
A crossing with ``|γ⁻|`` within γ's certified error (:meth:`_Run.velocity_bands`, its
carried part up to :meth:`_Run.accuracy_caps`) is labelled a graze too, and its (tiny)
impulse is applied. A minimum above the touch band is a miss: no event. An open contact is
impacted together with the one that triggers an impact (simultaneous impact) when its gap is
not certainly positive (its float64 value within its certified evaluation error,
γ_{N+1}·Σ|r z|, or within the run's carried state error up to ``zeno_time_rtol`` of the
contact's reach, :meth:`_Run.accuracy_caps`; it is then moved onto its contact point,
:meth:`_Run.onto_contacts`) or closes within what the time coordinate's resolution (two ulp
of t) hides at its speed: :meth:`_Run.simultaneous_band`. No time scale of the system, no
guessed length and no count of round-offs enters a decision.

Zeno: a run of impacts of one contact set whose intervals shrink geometrically (consecutive
ratios equal within :data:`ZENO_RATIO_SPREAD`) is stopped once the impact velocity has
fallen by :data:`ZENO_VELOCITY_RATIO`, or the last interval is within the time coordinate's
resolution (two ulp of t: the impact times no longer tell it from zero), or every next hop is
within the certified error of its gap (not resolvable, :meth:`_Run.hop_error`), or resolving
more impacts would put more of the gaps' representation error than ``zeno_time_rtol`` of the
elapsed time into t_∞ (:meth:`_Run.noisy_tail`, :func:`zeno_time_budget`; one contact: the
velocity tail's error, several: the geometric tail's); the accumulation time
t_∞ is extrapolated from the velocity γ⁺ after the last resolved impact and the exact
contact acceleration and its rate (:meth:`_Run.velocity_tail`: ``2γ⁺/(α(1 − e))`` for a
constant acceleration α, exact for the ball, docs/theory/oracles.md §1; several contacts: geometric,
:meth:`_Run.tail_time`), the state is carried to t_∞ by the constrained flow, and the
contacts switch to persistent contact there if the acceleration LCP gives them a positive
force.

Overlapping tails: when, after an impact of a set ``key``, other open contacts land within
a few tail lengths of it (two bodies landing together, a contact re-launched by the other's
impacts and accumulating again between them), or key's impact re-launches a held contact, or
key bounces on a held set (the chain's
blocks settling on each other), and one contact of key is resolved as far as
its gap's representation allows (next hop within the gap's certified error, or
:func:`zeno_time_budget` reached; several contacts: a hop no higher than the band an impact
would merge, :meth:`_Run.merge_band`), the cluster's **joint tail** (:mod:`observer.event.tails`)
resolves it by exact hops of every contact relative to its contact point until all of them
are held; each contact's ``accumulation`` row is at the time it was last held (its own t_∞)
and its note says ``joint tail of contacts …``. A joint tail that does not converge or would
skip another contact's event is not taken; the impacts are then resolved by their hops: an
impact after which a contact's next hop ``γ⁺²/(2|γ̇|)`` is within the certified error of its
gap (:meth:`_Run.hop_error`: its evaluation and the state's representation) lands that contact there (:meth:`_Run.land`: kind ``accumulation``, tail time 0),
and the acceleration LCP decides whether it stays closed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from observer.contact import get_solver
from observer.event.enclosures import (dot_sign, gamma, polish_lcp, represented_error,
                                       stick_decisions)
from observer.event.energy import EnergyCarry
from observer.event.flow import Flow, flow_for
from observer.event.roots import (WINDOW, FunctionalSet, NonFiniteFlow,
                                  RootIsolationError, SearchStopped, first_zero, time_resolution)
from observer.event.tails import JointTail, horner, joint_due, joint_tail, representation
from observer.impact import ImpactLaw, impact
from observer.result import RunState, RunStatus
from observer.scenario import Scenario

_U = np.finfo(float).eps / 2.0
"""Unit round-off u (the data's representation, :meth:`_Run.search_band`)."""

if TYPE_CHECKING:
    import pandas as pd

ZENO_MIN_IMPACTS = 6
"""Impacts of one run needed before a geometric accumulation is recognised."""

ZENO_RATIO_SPREAD = 0.02
"""Largest difference of the last two interval ratios Δ_k/Δ_{k−1} of a geometric run."""

ZENO_VELOCITY_RATIO = 1e-9
"""A geometric run is extrapolated once |γ⁻| has fallen below this fraction of its first value."""

ZENO_TIME_RTOL = 1e-9
"""Default of ``run_master(zeno_time_rtol=…)``: the stated accuracy of an extrapolated t_∞
relative to the run's elapsed time t − t0 (:func:`zeno_time_budget`); near the rule it
replaces, 2^22 ulp(t − t0), which lay between 2^-31 and 2^-30 of t − t0 by where t − t0
fell in its binade."""


def zeno_time_budget(t: float, t0: float, rtol: float) -> float:
    """rtol·|t − t0|: the most of the gaps' representation error that a Zeno tail cut at t may
    carry into t_∞ (``zeno_time_rtol`` of :func:`run_master`), from the run's elapsed time
    alone: the same under any shift of the time origin (up to the rounding of t − t0), no time
    scale of the system (a slow mode anywhere does not loosen it). A geometric run of one
    contact is extrapolated once its estimated carried error reaches it
    (:meth:`_Run.noisy_tail`); a cluster's joint tail starts there too
    (:func:`observer.event.tails.joint_due`). The elapsed time, not t: with |t|, a time
    origin at 1e3 let ~2^13 times more of the gap's round-off into t_∞, and composed with a
    translation by 100 moved t_∞ by more than 1e-9 (tests/observer/event/test_invariance.py
    fails that rule). Where the run is cut depends on the
    coordinates, t_∞ does not (:meth:`_Run.hop_tail`)."""
    return rtol * abs(float(t) - float(t0))


HOP_ORDER = 8
"""Degree of the Taylor polynomial of a hop in :meth:`_Run.hop_tail` (hops last ≲ the Zeno
tail ≪ τ, so the truncation is (Δ/τ)^9 of the hop, below round-off)."""

SAMPLE_BLOCK = 256
"""Output samples computed per block product (``exp(A j h)``, j = 1..SAMPLE_BLOCK)."""

STALL_EVENTS = 50
"""Events at one and the same instant after which the run stops (no progress)."""

EVENT_KINDS = ("impact", "graze", "stick", "liftoff", "accumulation")
EVENT_COLUMNS = ["time", "contact", "kind", "gamma_minus", "gamma_plus", "impulse"]
MASTER_EVENT_COLUMNS = EVENT_COLUMNS + ["depth", "note"]
"""The master's event table: :data:`EVENT_COLUMNS` plus ``depth`` (for a ``graze``, the gap's
local minimum m*: > 0 a clearance, < 0 a penetration shallower than the guaranteed crossing
depth; 0 otherwise) and ``note`` (empty, or how a decision float64 cannot take was taken)."""


@dataclass
class MasterEventResult:
    """Result of :func:`run_master`.

    Attributes
    ----------
    t : ndarray, shape (N+1,)
        The output grid ``t_k = t0 + k·h`` (up to the stop of a stopped run).
    q, u : ndarray, shape (N+1, n)
        The exact solution on the grid.
    g, P : ndarray, shape (N+1, m)
        Gaps; ``P_j``: impulse of contact j in ``(t_{k−1}, t_k]``, impacts plus ∫λ dt.
    active : ndarray of bool, shape (N+1, m)
        Contact j closed at some instant of ``(t_{k−1}, t_k]`` (row 0 at t0).
    event_rows : list of tuple
        The events as rows of :data:`MASTER_EVENT_COLUMNS`.
    segments : list of tuple
        The exact solution: ``(t_start, t_stop, held contacts, x(t_start))`` per flow piece
        (see :meth:`state`).
    status : RunStatus
        ``ok``, or ``stopped`` with the reason (``str(status)``: ``"stopped: <reason>"``); a
        stopped run's rows end at the last grid time before the stop (:attr:`t_stop`), never
        with NaN rows.
    nonfinite : bool
        The stop is a state that left the floating-point range (the reason names the master's
        quantity).
    closings, openings : list of ndarray
        Per contact, the times it closes and opens again (χ_j = 1 on each
        ``[closing, opening]``; an impact or graze is a zero-length interval; ``inf``:
        still closed at t_end). A Zeno tail (between the last resolved impact and t_∞, with
        infinitely many impacts) counts as closed: its interval starts at the last resolved
        impact; the extrapolation is in :attr:`zeno`.
    zeno : list of dict
        Per accumulation: ``contact, t_inf, impacts_resolved, tail_time, tail_impulse, ratio``.
    """

    scenario: Scenario
    h: float
    t_end: float
    t: np.ndarray
    q: np.ndarray
    u: np.ndarray
    g: np.ndarray
    P: np.ndarray
    active: np.ndarray
    event_rows: list
    status: RunStatus
    closings: list
    openings: list
    zeno: list = field(default_factory=list)
    segments: list = field(default_factory=list)
    t_stop: float = float("nan")
    nonfinite: bool = False

    @cached_property
    def frame(self) -> pd.DataFrame:
        """The solution as a DataFrame ``t, q0.., u0.., g0.., P0.., active0..`` (built on first
        read; ``attrs``: scenario, integrator, h, t_end, status, t_stop)."""
        import pandas as pd

        cols: dict[str, np.ndarray] = {"t": self.t}
        for name, arr in (("q", self.q), ("u", self.u), ("g", self.g), ("P", self.P)):
            for j in range(arr.shape[1]):
                cols[f"{name}{j}"] = arr[:, j]
        for j in range(self.active.shape[1]):
            cols[f"active{j}"] = self.active[:, j].astype(np.int8)
        frame = pd.DataFrame(cols)
        frame.attrs.update({"scenario": self.scenario.name, "integrator": "event", "h": self.h,
                            "t_end": self.t_end, "status": str(self.status), "t_stop": self.t_stop})
        return frame

    @cached_property
    def events(self) -> pd.DataFrame:
        """One row per event and contact: ``time, contact, kind, gamma_minus, gamma_plus,
        impulse, depth, note`` (:data:`MASTER_EVENT_COLUMNS`; built on first read)."""
        import pandas as pd

        return pd.DataFrame(self.event_rows, columns=MASTER_EVENT_COLUMNS)

    def state(self, t: float) -> np.ndarray:
        """Exact state ``(q, u)`` at any time t of the run (right-continuous at impacts), from
        :attr:`segments`: ``(t_start, t_stop, held contacts, x(t_start))`` of each flow piece."""
        for t_a, t_b, active, x_a in reversed(self.segments):
            if t_a <= t <= t_b:
                return flow_for(self.scenario.system, active).state(t_a, x_a, t - t_a)
        raise ValueError(f"t = {t!r} is outside the run [{self.segments[0][0] if self.segments else 0.0!r}, "
                         f"{self.t_end!r}]")

    def intervals(self, j: int) -> np.ndarray:
        """Closed intervals ``[closing, opening]`` of contact j, shape (k, 2)."""
        return np.column_stack([self.closings[j], self.openings[j]]) if len(self.closings[j]) \
            else np.zeros((0, 2))

    def impact_times(self, j: int | None = None) -> np.ndarray:
        """Times of the impacts (of contact j, or of any contact), in order."""
        return np.unique(np.array([r[0] for r in self.event_rows
                                   if r[2] == "impact" and (j is None or r[1] == j)], dtype=float))


class _Run:
    """Mutable state of one master run (the event loop's bookkeeping)."""

    def __init__(self, scenario: Scenario, h: float, t_end: float, max_events: int,
                 zeno_velocity_ratio: float, t0: float = 0.0,
                 zeno_time_rtol: float = ZENO_TIME_RTOL) -> None:
        self.sc = scenario
        self.system = scenario.system
        self.law: ImpactLaw = scenario.law
        self.solve = get_solver(scenario.solver, field="simulation.solver").solve
        self.n, self.m = self.system.n, self.system.m
        self.h, self.t_end, self.t0 = h, t_end, t0
        self.max_events = max_events
        self.zeno_velocity_ratio = zeno_velocity_ratio
        self.zeno_time_rtol = zeno_time_rtol
        count = int(np.floor((t_end - t0) / h + 1e-9)) + 1
        self.t_grid = np.minimum(t0 + h * np.arange(count), t_end)   # may exceed t_end by an ulp
        self.X = np.full((count, 2 * self.n), np.nan)
        self.P = np.zeros((count, self.m))
        self.k_next = 0
        self.events: list[tuple] = []
        self.closed_since: dict[int, float] = {}
        self.intervals: list[list[tuple[float, float]]] = [[] for _ in range(self.m)]
        self.zeno: list[dict] = []
        self.history: dict[tuple, list[tuple[float, float]]] = {}
        self.last_key: tuple | None = None
        self.segments: list[tuple[float, float, tuple, np.ndarray]] = []
        self.free_flow = flow_for(self.system, ())
        self.Minv = self.free_flow.Minv
        self.note, self.note_time = "", np.nan
        self.should_stop = None        # callable → a signal name (SIGINT/SIGTERM) or None
        self.hop_end = None            # (contact, t_k, t_last, x_last) of the last hop_tail
        self.halted: str | None = None # the signal that stopped the sampling (no row after)
        self.exact_delassus: dict[tuple, dict] = {}   # contact set → {bits: exact G} (exact_solve)
        self.stick_notes: dict[int, str] = {}   # contact → undecided stick enclosure (sticking)
        self.err = np.zeros(2 * self.n)   # bound on |x − x_exact| (carry_error, jump_error)
        self.energy = EnergyCarry(self.system, t_end - t0)   # the same error in ‖·‖_P
        self.origin: np.ndarray | None = None   # the gap frame's q* (run_master), for graze bands
        self.search_err, self.search_eps = np.zeros(2 * self.n), 0.0   # the searches' rounding
        self.reach = np.zeros((2, self.m))   # max |g_j|, |γ_j| of the run so far (accuracy_caps)

    # -- sampling --------------------------------------------------------------------------
    def fill(self, flow: Flow, t_a: float, x_a: np.ndarray, t_b: float, include_end: bool) -> None:
        """Samples of the grid in ``[t_a, t_b)`` (``]`` with include_end) from the flow out of
        (t_a, x_a), and the force impulses ∫λ dt of the persistent set per sample interval."""
        if t_b > t_a or include_end:
            self.segments.append((float(t_a), float(t_b), flow.active, np.array(x_a, dtype=float)))
        if self.halted:
            return
        tg, k = self.t_grid, self.k_next
        forced = list(flow.active)
        end = int(np.searchsorted(tg, t_b, side="right" if include_end else "left"))
        t_cur, z_cur = t_a, flow.z(t_a, x_a)
        if k < end:                                   # first sample: from the segment start
            z_cur = self._sample(flow, k, tg[k] - t_a, z_cur, forced)
            t_cur, k = tg[k], k + 1
        # the oscillator states of the samples, once: of all of them when the held forces'
        # impulses need every row's, else of each block's last row (the next block's start)
        k_osc, osc = k, None
        if k < end and flow.freqs:
            last = np.minimum(np.arange(k + SAMPLE_BLOCK - 1, end + SAMPLE_BLOCK - 1, SAMPLE_BLOCK),
                              end - 1)
            osc = _oscillator_block(flow, tg[k:end] if forced else tg[last])
        while k < end:                                # the rest: blocks of equal steps h
            if self.should_stop is not None and (sig := self.should_stop()):
                self.halted, self.k_next = sig, k     # a signal: the rows so far are whole
                return
            count = min(end - k, SAMPLE_BLOCK)
            stack = flow.power_stack(self.h, count)
            # (count, N): one matrix-vector product of the stacked rows (a stacked matmul pays a
            # BLAS call per sample; the samples' sums may differ in their last bit for N ≥ 9)
            Z = (stack.reshape(-1, stack.shape[-1]) @ z_cur).reshape(count, -1)
            if osc is not None and forced:
                Z[:, 2 * self.n:-1] = osc[k - k_osc:k - k_osc + count]
            elif osc is not None:                     # the other rows' are not read
                Z[-1, 2 * self.n:-1] = osc[(k - k_osc) // SAMPLE_BLOCK]
            Z[:, -1] = 1.0
            self.X[k:k + count] = Z[:, :2 * self.n]
            if forced:
                prev = np.vstack([z_cur[None, :], Z[:-1]])
                self.P[k:k + count, forced] += prev @ (flow.force_rows @ flow.phi(self.h)).T
            z_cur, t_cur, k = Z[-1], tg[k + count - 1], k + count
        if forced and k < tg.size and t_b > t_cur:
            self.P[k, forced] += flow.force_rows @ flow.integral(t_b - t_cur, z_cur)
        self.k_next = k

    def fill_certified(self, flow: Flow, t_a: float, x_a: np.ndarray, t_b: float) -> None:
        """The samples of ``[t_a, t_b)`` after a signal stopped a search at ``t_b``: no
        functional vanishes there, so they are whole and kept although a stop is pending."""
        stop, self.should_stop = self.should_stop, None
        try:
            if t_b > t_a:
                self.fill(flow, t_a, x_a, t_b, include_end=False)
        finally:
            self.should_stop = stop

    def _sample(self, flow: Flow, k: int, dt: float, z: np.ndarray, forced: list) -> np.ndarray:
        z_new = flow.expm(dt) @ z
        z_new[2 * self.n:-1] = flow.oscillators(self.t_grid[k])
        z_new[-1] = 1.0
        self.X[k] = z_new[:2 * self.n]
        if forced:
            self.P[k, forced] += flow.force_rows @ flow.integral(dt, z)
        return z_new

    def add_impulse(self, t: float, contacts, impulse) -> None:
        """Add an impulse at time t to the sample interval ``(t_{k−1}, t_k]`` holding t."""
        k = int(np.searchsorted(self.t_grid, t, side="left"))
        if k < self.t_grid.size:
            self.P[k, list(contacts)] += impulse

    # -- bookkeeping -----------------------------------------------------------------------
    def event(self, t, j, kind, gm, gp, imp, depth=0.0, note=None) -> None:
        if note is None:                       # the note of the zero that triggered the event
            note = self.note if t == self.note_time else ""
        self.events.append((float(t), int(j), kind, float(gm), float(gp), float(imp),
                            float(depth), str(note)))

    def close(self, j: int, t: float) -> None:
        self.closed_since.setdefault(j, t)

    def open(self, j: int, t: float) -> None:
        self.intervals[j].append((self.closed_since.pop(j, t), t))

    def touch(self, j: int, t: float) -> None:
        if j not in self.closed_since:
            self.intervals[j].append((t, t))

    # -- the accumulated state error --------------------------------------------------------
    def carry_error(self, flow: Flow, dt: float, z: np.ndarray, search: tuple = ()) -> None:
        """Carry :attr:`err`, the componentwise bound on the float state's distance to the
        exact trajectory of the scenario's data, over a flight of dt from the augmented state
        z: the error e of z moves to ``exp(A dt) e`` (bounded by ``|exp(A dt)|·|e|``; the
        forcing's components of z are exact), and the flight's own evaluation adds
        ``γ_{N+1}·|exp(A dt)|·|z|`` (a matrix-vector product, Higham §3.5). The same error
        in the energy norm (:attr:`energy`, :class:`EnergyCarry`): ``ε ← exp(μ dt)·ε + ‖that
        rounding‖_P``, which does not grow with ``‖|A|‖`` (:meth:`gap_error` takes the
        smaller enclosure).

        ``search``: the search's own accumulated rounding to the zero
        (:attr:`observer.event.roots.Zero.carried`, ``(err, eps)``): the float state at the
        zero came from the search's many window steps, each rounding, not from one product
        (without it a graze of the grazing scenario's steady orbit drifts out of its band:
        tests/observer/event/test_master.py, every graze of the steady orbit found). It is
        carried apart, in :attr:`search_err` and
        :attr:`search_eps` (propagated by the same flights, lost by a jump the energy bound
        does not hold), and enters the touch bands only (:meth:`search_band`): the
        simultaneity and velocity bands keep the one-product model (:meth:`carried`)."""
        if dt > 0.0:
            E = np.abs(flow.expm(dt))
            k = 2 * self.n
            g = gamma(E.shape[0] + 1)
            new = g * (E[:k] @ np.abs(z))
            self.err = (E[:k, :k] @ self.err) * (1.0 + 2.0 * g) + new
            self.energy.flight(flow, dt, new * (1.0 + 2.0 * g))
            self.search_err = (E[:k, :k] @ self.search_err) * (1.0 + 2.0 * g)
            self.search_eps = self.energy.after(flow, dt, np.zeros(k), self.search_eps)
        if search:                    # the search's own steps, at the zero (roots.SearchCarry.at)
            self.search_err = self.search_err + search[0][:2 * self.n]
            self.search_eps = self.search_eps + search[1]

    def jump_error(self, A: list[int], lam: np.ndarray, u: np.ndarray) -> None:
        """Add the rounding of a velocity jump ``u ← u + M⁻¹W_A λ`` to :attr:`err`:
        ``γ_{n+|A|+1}·|M⁻¹|·|W_A|·|λ|`` for the products, ``u·|u|`` for the sum; the energy
        bound carries the error through the law's map (:meth:`EnergyCarry.jump`)."""
        n = self.n
        W = np.abs(self.system.W[:, list(A)])
        g = gamma(n + len(A) + 1)
        new = g * (np.abs(self.Minv) @ (W @ np.abs(lam))) + g * np.abs(u)
        self.err[n:] += new
        e = self.law.restitution[list(A)]
        law = self.law.definition
        averaged = (len(A) == 1 and law.single_contact_is_newton) or \
            (law.name in ("newton", "poisson") and bool(np.all(e == e[0])))
        self.energy.jump(averaged, np.concatenate([np.zeros(n), new]))
        if not np.isfinite(self.energy.eps):
            self.search_eps = np.inf

    def gap_error(self, z: np.ndarray) -> np.ndarray:
        """Bound on every gap's distance to its exact value: the accumulated state error
        seen through the gap rows (their own evaluation rounding aside), the smaller of the
        componentwise ``|r|·err`` and the energy norm's ``‖r‖_{P⁻¹}·ε`` (both proved)."""
        return self.carried(self.free_flow.gap_rows)

    def carried(self, rows: np.ndarray, err: np.ndarray | None = None,
                eps: float | None = None) -> np.ndarray:
        """The accumulated state error seen through ``rows`` (of the augmented state: their
        mechanical columns act on it): the smaller of ``|r|·err`` and ``‖r‖_{P⁻¹}·ε``, a
        componentwise carry that overflowed (inf·0 = nan) counting as no bound. ``err``,
        ``eps``: another carried error than the run's (:meth:`search_band`)."""
        k = 2 * self.n
        with np.errstate(over="ignore", invalid="ignore"):
            comp = np.abs(rows[:, :k]) @ (self.err if err is None else err)
        comp = np.where(np.isnan(comp), np.inf, comp)
        return np.minimum(comp, self.energy.through(rows[:, :k], eps))

    def search_band(self, flow: Flow, rows: np.ndarray, t0: float, z0: np.ndarray):
        """The data's part of the touch bands of a search from ``(t0, z0)`` along ``flow``
        (:func:`observer.event.roots.graze_band` (b) and (c)): ``data(t, z)`` → per row of
        ``rows``, (b) the accumulated state error (the run's and its searches',
        :attr:`search_err`) carried from t0 to t as :meth:`carry_error` would carry it (componentwise ``|r|·err``, or the energy norm's ``‖r‖_{P⁻¹}·ε``, the
        smaller; :attr:`err` and ε are not changed), plus (c) the data's representation in
        the user's coordinates, ``(1 + 2γ)·u·Σ_j|r_ij z_j|`` with z taken back out of the
        gap frame (q = x + q*, :attr:`origin`) and the row's constant re-expressed there
        (``c − r_q·q*``, raised by its own rounding): at a translation by c a gap is known
        to ~u·|c| (issue 34: a graze at translation 100 inside that band is a graze).

        The state error's scope is :meth:`carry_error`'s (the propagator as computed)."""
        k, n = 2 * self.n, self.n
        err0, eps0 = self.err + self.search_err, self.energy.eps + self.search_eps
        g = gamma(z0.size + 1)

        def data(t: float, z: np.ndarray) -> np.ndarray:   # a touch decision: rare, so built here
            az0, ab = np.abs(z0), np.abs(rows)
            if self.origin is not None:
                q = self.origin
                const = np.abs(rows[:, -1] - rows[:, :n] @ q) + g * (ab[:, -1] + ab[:, :n] @ np.abs(q))
                ab[:, -1] = const * (1.0 + 2.0 * g)
            E = np.abs(flow.expm(float(t) - t0)) if t > t0 else np.eye(z0.size)
            new = g * (E[:k] @ az0)
            err = (E[:k, :k] @ err0) * (1.0 + 2.0 * g) + new
            eps = self.energy.after(flow, max(float(t) - t0, 0.0), new * (1.0 + 2.0 * g), eps0)
            carried = self.carried(rows, err, eps)
            zu = np.abs(z)
            if self.origin is not None:
                zu = zu.copy()
                zu[:n] = np.abs(z[:n] + self.origin) * (1.0 + _U)
            return (carried + (1.0 + 2.0 * g) * _U * (ab @ zu)) * (1.0 + 2.0 * g)
        return data

    # -- contact mechanics -----------------------------------------------------------------
    def delassus(self, idx) -> np.ndarray:
        W = self.system.W[:, list(idx)]
        return W.T @ self.Minv @ W

    def velocity_jump(self, A: list[int], lam: np.ndarray) -> np.ndarray:
        """``M⁻¹ W_A λ``, the velocity jump of the impulses λ on the contacts A. For several
        contacts ``W_A λ`` is summed from its exact products ``W_ij λ_j`` without fused
        multiply-adds (a BLAS product may contract ``a λ − a λ`` to the rounding error of
        ``a λ``): equal impulses on exactly opposite lever arms give exactly no rotation."""
        if len(A) < 2:
            return self.Minv @ self.system.W[:, A] @ lam
        return self.Minv @ (self.system.W[:, A] * np.asarray(lam, dtype=float)).sum(axis=1)

    def exact_solve(self, A: list[int]):
        """The contact solver for an impact on the contacts A: for several contacts, its
        float64 answer re-solved on its active set from the exact Delassus matrix
        (:func:`observer.event.enclosures.polish_lcp`), so that impulses of exactly symmetric
        data are equal (a symmetric landing stays symmetric, issue 34 item 3); the float64
        answer where that does not certify, and for one contact."""
        if len(A) < 2:
            return self.solve
        W, M = self.system.W[:, list(A)], self.system.M
        cache = self.exact_delassus.setdefault(tuple(A), {})

        def solve(G, b):
            sol = self.solve(G, b)
            x = polish_lcp(M, W, b, sol.x, cache=cache)
            return sol if x is None else sol._replace(x=x)
        return solve

    def sticking(self, t: float, x: np.ndarray, cand: list[int]) -> list[int]:
        """Contacts of ``cand`` (g = γ = 0) that stay closed under the acceleration LCP
        ``0 ≤ λ ⊥ w = Gλ + b ≥ 0`` on cand (``b = r_v A z``, the free relative
        accelerations), decided from enclosures (issue 34 item 1), no tolerance.

        The float64 LCP gives a first active set S = {λ > 0}. On S the exact solution is
        ``λ_S = −G_SS⁻¹ b_S``, ``w_R = G_RS λ_S + b_R`` (R = cand ∖ S); it is enclosed in ball
        arithmetic (:func:`~observer.event.enclosures.stick_decisions`) from the exact
        Delassus matrix of M, W and the ball ``b`` around the exact ``r_v·A·z`` of the float
        state z, of radius the accumulated state error through the rows (:meth:`carried`);
        float64 balls first, which decide only where the arb balls would decide the same.
        If every λ_S is certainly positive and every w_R certainly nonnegative, S solves the
        LCP of every b in the ball (G a P-matrix: unique); a set refuted (a λ or w certainly
        negative: the float64 solver's rounding chose it) gives way to the others. A contact
        of S keeps a positive force (stays closed); one of R with w certainly positive lifts
        off; one of R whose w is exactly 0 on the float state (identically closed, issue 34
        item 2: touching bodies, bodies moving together) has no force and no relative
        acceleration and stays closed. Undecided at
        :data:`~observer.event.enclosures.PRECISION_CAP` (a ball holding 0): the contact is
        kept closed (its held force is then watched for a lift-off) and the enclosure is
        stated in its event row (:attr:`stick_notes`)."""
        self.stick_notes = {}
        if not cand:
            return []
        fl = self.free_flow
        z = fl.z(t, x)
        rows = fl.velocity_rows @ fl.A
        b = rows[cand] @ z
        lam = self.solve(self.delassus(cand), b).x
        g = gamma(z.size + 1)
        radius = self.carried(rows[cand]) * (1.0 + 2.0 * g) ** 2
        cache = self.exact_delassus.setdefault(tuple(cand), {})
        keep, notes = stick_decisions(self.system.M, self.system.W[:, list(cand)],
                                      fl.velocity_rows[cand], fl.A, z, radius, lam, cache)
        self.stick_notes = {cand[k]: v for k, v in notes.items()}
        return [c for c, k in zip(cand, keep) if k]

    def project(self, t: float, x: np.ndarray, idx: list[int]) -> np.ndarray:
        """M-metric projection of (q, u) onto g_idx = 0, γ_idx = 0 (a round-off correction)."""
        if not idx:
            return x
        n = self.n
        W = self.system.W[:, idx]
        G = self.delassus(idx)
        g = self.free_flow.gaps(t, x)[idx]
        gam = self.free_flow.velocities(t, x)[idx]
        x = x.copy()
        x[:n] -= self.Minv @ W @ np.linalg.solve(G, g)
        x[n:] -= self.Minv @ W @ np.linalg.solve(G, gam)
        return x

    def collide(self, t: float, x: np.ndarray, persistent: tuple, trigger: set[int]):
        """Impact at t on every closed contact; returns (x⁺, new persistent set, impact set)."""
        fl = self.free_flow
        z = fl.z(t, x)
        g, gam = fl.gap_rows @ z, fl.velocity_rows @ z
        cap_g, cap_v = self.accuracy_caps(g, gam)
        vown, vband = self.velocity_bands(z)
        tol_v = np.maximum(vown, np.minimum(cap_v, vband))
        own, near, certified = self.simultaneous_band(t, z, gam, cap_g)
        closing = {j for j in range(self.m) if abs(g[j]) <= near[j] and gam[j] < tol_v[j]}
        A = sorted(set(persistent) | set(trigger) | closing)
        moved = [j for j in sorted(closing - set(trigger) - set(persistent)) if abs(g[j]) > own[j]]
        x, notes = self.onto_contacts(t, x, A, moved, g, near)
        for j, text in self.unordered_notes(trigger, A, g, gam, certified, vband).items():
            notes.setdefault(j, []).extend(text)
        idx = np.array(A, dtype=int)
        G = self.delassus(A)
        gm = gam[idx]
        lam = impact(self.law, G, gm, idx, self.exact_solve(A)) if np.any(gm < 0.0) \
            else np.zeros(len(A))
        lam = np.maximum(lam, 0.0)
        x[self.n:] += self.velocity_jump(A, lam)
        self.jump_error(A, lam, x[self.n:])
        gp = fl.velocities(t, x)[idx]
        zp = fl.z(t, x)
        vown_p, vband_p = self.velocity_bands(zp)
        vband_p = np.maximum(vband, vband_p)                                # + the jump
        band_p = np.maximum(np.maximum(tol_v, vown_p), np.minimum(cap_v, vband_p))
        cand = [c for c, v in zip(A, gp) if v <= band_p[c]]
        for c, v in zip(A, gp):
            if band_p[c] < v <= vband_p[c]:
                notes.setdefault(c, []).append(
                    f"rebound γ⁺ = {v:.3g} within the data's carried error ±{vband_p[c]:.3g} "
                    "(the data do not decide it)")
        stick = self.sticking(t, x, cand)
        x = self.project(t, x, stick)
        gp = fl.velocities(t, x)[idx]
        for c, a, b, l in zip(A, gm, gp, lam):
            if c in persistent:
                if c not in stick:
                    self.event(t, c, "liftoff", a, b, l, note=self.stick_notes.get(c))
                    self.open(c, t)
                elif l > 0.0:
                    self.event(t, c, "impact", a, b, l)
                continue
            if a < -tol_v[c] or l > 0.0 or c not in stick:
                self.event(t, c, "impact" if a < -tol_v[c] else "graze", a, b, l,
                           note=self.joined_note(t, notes.get(c)))
            if c in stick:
                self.event(t, c, "stick", b, b, 0.0, note=self.stick_notes.get(c))
                self.close(c, t)
            else:
                self.touch(c, t)
        self.add_impulse(t, A, lam)
        return x, tuple(stick), A, gm, lam

    def unordered_notes(self, trigger, A: list, g: np.ndarray, gam: np.ndarray,
                        certified: np.ndarray, vband: np.ndarray) -> dict[int, list[str]]:
        """Notes for the trigger's rows of an impact at t (:meth:`collide`) naming each open
        contact that lands later, in order, although its gap is within the run's carried
        state error (``certified``, the uncapped band of :meth:`simultaneous_band`) while it
        approaches: the data do not order the two landings (issue 34 item 1: an undecided
        case is reported with its enclosure); the float state's own band and the cap
        decided it."""
        later = [j for j in range(self.m) if j not in A and abs(g[j]) <= certified[j]
                 and gam[j] < vband[j]]
        if not later:
            return {}
        text = "; ".join(f"contact {j} not ordered by the data (gap {g[j]:.3g} within the "
                         f"carried error ±{certified[j]:.3g})" for j in later)
        return {c: [text] for c in trigger}

    def onto_contacts(self, t: float, x: np.ndarray, A: list, moved: list, g: np.ndarray,
                      band: np.ndarray) -> tuple[np.ndarray, dict[int, list[str]]]:
        """A copy of x, its positions moved onto ``g_A = 0`` when some contacts of the impact
        set A (``moved``) joined it although their float gaps are certainly not zero on the
        float state itself: the data do not order their landings with the trigger's (their
        gaps are within the carried state error ``band``, :meth:`simultaneous_band`; issue 34
        item 3), so they are impacted together, at their contact points and not at an open
        gap. The move is the M-metric projection ``Δq = −M⁻¹W_A G_AA⁻¹ g_A`` (velocities
        unchanged), within the carried error that allowed it; the carried error grows by it
        (:meth:`shifted`), so the enclosure of the exact trajectory stays proved. Returns
        ``(x, notes)``: each moved contact's note names its gap and the carried error."""
        x = x.copy()
        if not moved:
            return x, {}
        n = self.n
        W = self.system.W[:, A]
        dq = -(self.Minv @ (W @ np.linalg.solve(self.delassus(A), g[A])))
        x[:n] += dq
        self.shifted(np.abs(dq), np.abs(x[:n]))
        return x, {j: [f"landed with the impact: gap {g[j]:.3g} within the carried error "
                       f"±{band[j]:.3g} (the data do not order it), moved onto its contact "
                       "point"] for j in moved}

    def shifted(self, dq: np.ndarray, q: np.ndarray) -> None:
        """Add a move of the positions by ``dq`` (componentwise bound, ``q`` the moved
        positions' magnitudes for the sum's rounding ``u·|q|``) to :attr:`err` and to the
        energy norm's ε (:meth:`EnergyCarry.shift`)."""
        n = self.n
        new = (dq + _U * q) * (1.0 + 4.0 * _U)
        self.err[:n] += new
        self.energy.shift(np.concatenate([new, np.zeros(n)]))

    def joined_note(self, t: float, extra: list[str] | None) -> str | None:
        """The note of the zero that triggered the event at t (:meth:`event`'s default)
        followed by ``extra``; None (the default) when there is no extra."""
        if not extra:
            return None
        own = self.note if t == self.note_time else ""
        return "; ".join([own] + extra if own else extra)

    def accuracy_caps(self, g: np.ndarray, gam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How far the carried state error decides simultaneity and rebounds (:meth:`collide`):
        the run's stated relative accuracy ``zeno_time_rtol`` times each contact's own reach,
        the largest |g_j| and |γ_j| of the run so far (:attr:`reach`, raised by ``g`` and
        ``gam`` at this impact). Within ``rtol·max|g_j|`` a landing the data do not order with
        the trigger's is impacted together with it, moved onto its contact point
        (:meth:`onto_contacts`); within ``rtol·max|γ_j|`` a rebound the data do not decide is
        a candidate to stick. Beyond, the carried error has grown past the stated accuracy
        (late in a long chaotic run it outgrows the gaps): the float state orders the
        landings and resolves the rebound, and the event row says that the data do not
        decide it (:meth:`unordered_notes`). Relative to the run's own motion: no time scale
        of the system, no guessed length, no count of round-offs (issue 34 item 1); the same
        under a translation, a shift of the time origin and a change of units.

        Returns
        -------
        cap_g, cap_v : ndarray
            Per contact, in the gaps' and the relative velocities' units."""
        self.reach[0] = np.maximum(self.reach[0], np.abs(g))
        self.reach[1] = np.maximum(self.reach[1], np.abs(gam))
        cap = self._caps()
        return cap[0], cap[1]

    def _caps(self) -> np.ndarray:
        """``zeno_time_rtol·reach`` (0 where the reach is 0, also for rtol = inf)."""
        with np.errstate(invalid="ignore"):
            return np.where(self.reach > 0.0, self.zeno_time_rtol * self.reach, 0.0)

    def merge_band(self, t: float, x: np.ndarray) -> np.ndarray:
        """The gaps that an impact at t would land together with its trigger's
        (:meth:`simultaneous_band` with the caps of :meth:`accuracy_caps` at the run's reach
        so far, not raised): a joint tail (:func:`observer.event.tails.joint_due`) is due once
        a hop of a simultaneous key is no higher, where event-by-event impacts would merge
        its landings with the others'."""
        fl = self.free_flow
        z = fl.z(t, x)
        return self.simultaneous_band(t, z, fl.velocity_rows @ z, self._caps()[0])[1]

    def velocity_bands(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The certified distance of every contact's float64 relative velocity ``r_v·z`` to
        its exact value on the exact trajectory: its evaluation and the state's
        representation, ``(1 + 2γ)(γ + u)·Σ|r_v z|`` with γ = γ_{N+1}
        (:func:`~observer.event.enclosures.represented_error`), the rounding of the
        row ``r_v = r A`` itself, ``γ_{N+1}·(|r||A|)|z|``, and the accumulated state error
        through the row (:attr:`err` componentwise, or the energy norm's
        ``‖r_v‖_{P⁻¹}·ε``, the smaller). No time scale, no count of round-offs: a
        contact's γ⁺ outside it is certainly nonzero (issue 34 item 1).

        Returns
        -------
        own, band : ndarray
            The float state's own part alone (its evaluation and representation: the band of
            the exact flow from the float state itself), and the band with the carried error."""
        fl = self.free_flow
        rows = fl.velocity_rows
        g = gamma(z.size + 1)
        row_rounding = (1.0 + 2.0 * g) * g * (np.abs(fl.gap_rows) @ (np.abs(fl.A) @ np.abs(z)))
        own = represented_error(rows, z) + row_rounding
        tiny = np.finfo(float).tiny
        return (own * (1.0 + 2.0 * g) + tiny,
                (own + self.carried(rows)) * (1.0 + 2.0 * g) + tiny)

    def simultaneous_band(self, t: float, z: np.ndarray, gam: np.ndarray, cap: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The gaps within which an open contact is impacted together with the one that
        triggered an impact at t (:meth:`collide`): a gap not certainly positive, or one that
        closes within the time coordinate's resolution. From what is certified: the gap's
        float64 value is known to its evaluation error and the state's own representation,
        ``(γ_{N+1} + u)·Σ|r z|`` raised by ``1 + 2γ_{N+1}`` (Higham §3.1: within it no precision
        tells the gap from zero, z being known to no better), to the enclosure of the
        accumulated state error (:meth:`gap_error`), and the time coordinate's resolution
        hides ``|γ|·δt`` at its approach speed (δt two ulp of t,
        :func:`observer.event.roots.time_resolution`: no time scale of the system). No count
        of round-offs of the representation (it was 16·64 eps·Σ|r z|, which merged landings
        1e-11 s apart at a translation by 100): a contact in flight that close to its contact
        point but certainly above it lands later, in order (issue 19: one 9e-11 m above its
        contact point landing 4e-6 s later; two landings 5.5e-8 s apart, 3e-12 m).

        The accumulated state error is the smaller of its componentwise and energy-norm
        enclosures (:meth:`gap_error`); the energy norm's does not grow with ``‖|A|‖``
        (:class:`observer.event.energy.EnergyCarry`; tests/observer/event/test_energy_carry.py
        holds it to a small multiple of the steps' rounding over 10⁴ periods of an oscillator,
        where the componentwise one overflows). The carried part counts up to ``cap`` (the
        run's stated accuracy of each contact's gap, :meth:`accuracy_caps`): late in a long
        chaotic run the carried error outgrows the gaps, and uncapped it would land every
        contact together; beyond the cap the float state orders the landings and the row
        says the data do not (:meth:`unordered_notes`). A contact landing together beyond its
        own band is moved onto its contact point (:meth:`onto_contacts`): an impulse is
        never applied at an open gap (issue 34 items 1 and 3).

        Returns
        -------
        own, band, certified : ndarray
            The float state's own band (its representation and the time resolution), the
            band with the carried error up to ``cap``, and with all of it."""
        fl = self.free_flow
        floor = represented_error(fl.gap_rows, z)
        hidden = time_resolution(t) * np.abs(gam)
        own = np.maximum(floor, hidden)
        carried = self.gap_error(z)
        return own, np.maximum(own, np.minimum(cap, carried)), np.maximum(own, carried)

    # -- Zeno ------------------------------------------------------------------------------
    def zeno_check(self, key: tuple, t: float, x: np.ndarray, gm: np.ndarray,
                   persistent: tuple = ()) -> float | None:
        """Accumulation time t_∞ if the run of impacts of the contact set ``key`` is geometric
        and resolved enough: its impact speed max|γ⁻| fell by ``zeno_velocity_ratio``, or its
        last interval is within the time coordinate's resolution (two ulp of t,
        :func:`observer.event.roots.time_resolution`: the impact times no longer tell it from
        zero), or every next hop ``γ⁺²/(2|γ̇|)`` is within the certified error of its gap
        (:meth:`hop_error`: not resolvable), or resolving more impacts would put more of the
        gaps' representation into t_∞ than the extrapolation from here (:meth:`noisy_tail`)."""
        fl = self.free_flow
        z = fl.z(t, x)
        idx = list(key)
        v_plus = fl.velocity_rows[idx] @ z
        accel = fl.velocity_rows[idx] @ fl.A @ z
        hop = np.where(accel < 0.0, v_plus * v_plus / (2.0 * np.abs(accel) + 1e-300), np.inf)
        hop_small = bool(np.all(hop <= self.hop_error(fl, idx, z)))
        speed = float(np.max(np.abs(gm)))
        if self.last_key != key:
            self.history.clear()
            self.last_key = key
        hist = self.history.setdefault(key, [])
        hist.append((t, speed))
        if len(hist) < ZENO_MIN_IMPACTS:
            return None
        d = np.diff([p[0] for p in hist[-4:]])
        if np.any(d <= 0.0):
            return None
        r1, r2 = d[1] / d[0], d[2] / d[1]
        if not (0.0 < r2 < 1.0 and 0.0 < r1 < 1.0 and abs(r2 - r1) <= ZENO_RATIO_SPREAD):
            del hist[:-3]                      # not geometric: a new run starts
            return None
        v0 = hist[0][1]
        if (speed > self.zeno_velocity_ratio * v0 and d[2] > time_resolution(t)
                and not hop_small and not self.noisy_tail(key, fl, idx, z, v_plus, t, d)):
            return None
        tail = self.tail_after(key, t, x, persistent)
        t_inf = t + (tail if tail is not None else self.tail_time(key, d[1], d[2]))
        return t_inf if self.tail_is_clear(key, t, x, persistent, t_inf) else None

    def tail_is_clear(self, key: tuple, t: float, x: np.ndarray, persistent: tuple,
                      t_inf: float) -> bool:
        """True if no other event (a gap of another open contact closing, a held contact's
        force vanishing) falls in the tail ``[t, t_∞]``, searched on the flow that holds
        ``key`` and ``persistent`` (the tail's limit): the extrapolation skips the tail, so it
        must not skip another contact's impact (which, coming first, ends the run of ``key``;
        the accumulation is then resolved further)."""
        setp = tuple(sorted(set(persistent) | set(key)))
        flow = flow_for(self.system, setp)
        others = [j for j in range(self.m) if j not in setp]
        held = [setp.index(c) for c in persistent]
        rows = np.vstack([flow.gap_rows[others], flow.force_rows[held]])
        if rows.shape[0] == 0 or t_inf <= t:
            return True
        xp = self.project(t, x, list(setp))
        try:
            zero, _, _ = first_zero(flow, rows, t, flow.z(t, xp), min(t_inf, self.t_end))
        except RootIsolationError:
            return False
        return zero is None

    def tail_after(self, key: tuple, t: float, x: np.ndarray, persistent: tuple) -> float | None:
        """Tail duration after an impact of ``key`` at t (state x after it), on the flow that
        holds ``persistent``: :meth:`hop_tail` (exact hops), with :meth:`velocity_tail` (from γ⁺
        and the contact acceleration and its rate) as its fallback; None if neither applies."""
        held = flow_for(self.system, persistent)
        zh = held.z(t, x)
        idx = list(key)
        jerk_rows = held.velocity_rows[idx] @ held.A
        tail = self.velocity_tail(key, held.velocity_rows[idx] @ zh, jerk_rows @ zh,
                                  jerk_rows @ held.A @ zh)
        return None if tail is None else self.hop_tail(key[0], t, zh, held, tail)

    def hop_tail(self, c: int, t: float, z: np.ndarray, held: Flow, guess: float) -> float:
        """The tail after an impact of contact c alone at t (augmented state z after it) by
        exact hops relative to the contact point: each hop leaves g = 0 exactly, lasts the
        first zero Δ > 0 of ``g(t_k + Δ) − g(t_k) = Σ_{j≥1} g^{(j)}(t_k) Δ^j/j!`` (degree
        :data:`HOP_ORDER`, Newton from 2γ⁺/|γ̇|), and lands with the flow's exact velocity,
        which Newton's law returns times e. The gap's own value, which carries the
        coordinates' round-off (|q| + |ν|), is never used: the tail, and t_∞, are the same
        in any coordinates. Falls back to ``guess`` (:meth:`velocity_tail`) if a hop is not
        a falling-back parabola."""
        e = float(self.law.restitution[c])
        n = self.n
        R = [held.velocity_rows[c]]
        for _ in range(HOP_ORDER - 1):
            R.append(R[-1] @ held.A)
        R = np.array(R)                                     # rows of g', g'', …
        fact = np.cumprod(np.arange(1, HOP_ORDER + 1, dtype=float))   # 1!, 2!, …
        push = self.Minv @ self.system.W[:, c] / float(self.delassus([c])[0, 0])
        tail, v0 = 0.0, float(R[0] @ z)
        self.hop_end = None
        for _ in range(100_000):
            d = R @ z
            if d[0] <= 1e-12 * v0 or d[1] >= 0.0:          # landed, or no longer falling back
                self.hop_end = (c, t, t + tail, held.x_of(z))  # the state after the last hop
                return tail + (2.0 * max(d[0], 0.0) / -d[1] / (1.0 - e) if d[1] < 0.0 else 0.0)
            co = d / fact                                   # (g(t_k + Δ) − 0)/Δ = Σ co_j Δ^j
            dt = -2.0 * d[0] / d[1]
            high = co[::-1].tolist()                        # np.polyval's Horner, on floats
            dhigh = (co[1:] * np.arange(1, HOP_ORDER))[::-1].tolist()
            for _ in range(30):
                P = horner(high, dt)
                dP = horner(dhigh, dt)
                step = P / dP if dP != 0.0 else 0.0
                dt -= step
                if abs(step) <= 4e-16 * dt:
                    break
            if not 0.0 < dt <= 4.0 * d[0] / -d[1]:
                return guess
            z = held.propagate(t + tail, z, dt)
            tail += dt
            z[n:2 * n] -= push * (1.0 + e) * float(R[0] @ z)   # γ⁺ = −e γ⁻
        return guess

    def hop_error(self, fl: Flow, idx: list, z: np.ndarray) -> np.ndarray:
        """Certified error of the gaps ``idx`` of the float state z on ``fl``: their evaluation
        and the state's representation (:func:`observer.event.enclosures.represented_error`).
        A hop ``γ⁺²/(2|γ̇|)`` not certainly above it is not resolvable: its apex is not
        certainly off the contact point, no precision of the same state tells it from zero.
        It grows with |q| and |ν|; the extrapolated t_∞ does not (:meth:`hop_tail` from an
        accurate impact).

        Not the carried state error (:meth:`gap_error`): that bounds the float trajectory's
        distance to the exact one of the scenario's data, a displacement of the whole
        trajectory that the hop's take-off and apex share, not an error of the hop; and its
        enclosure grows far faster than the error (on double_mass it grows exponentially over
        the run), which would cut the late runs at large hops and leave long tails that the
        observers treat as closed (a floor in V: tests/observer/event/test_observers.py fails
        with the carried error added)."""
        return represented_error(fl.gap_rows[idx], z)

    def time_budget(self, t: float) -> float:
        """:func:`zeno_time_budget` at t for this run (its t0 and ``zeno_time_rtol``): what the
        joint tails of :mod:`observer.event.tails` compare with, without importing this module."""
        return zeno_time_budget(t, self.t0, self.zeno_time_rtol)

    def noisy_tail(self, key: tuple, fl: Flow, idx: list, z: np.ndarray, v_plus: np.ndarray,
                   t: float, d: np.ndarray) -> bool:
        """True once resolving more impacts would make the extrapolated t_∞ less accurate.

        The gap is evaluated with an absolute error δg ≈ eps·Σ|r z| (its representation: it
        grows with |q| and |ν|), and the time coordinate resolves t to two ulp
        (:func:`observer.event.roots.time_resolution`), so an impact at speed v is located to
        δt = δg/v + that resolution. One contact (Newton's law): γ⁺ then errs by |γ̇|δt and
        the velocity tail (:meth:`velocity_tail`) by about ``(1 + 2/(1 − e))·δt``. Several
        contacts: the geometric tail ``d₂ρ/(1 − ρ)`` from the last three impact times, each
        located to δt (its largest over the contacts, v = γ⁺), errs by at most
        ``((1 + ρ)/(1 − ρ))²·δt`` (its derivatives in the three times). Once that reaches
        :func:`zeno_time_budget` (``zeno_time_rtol`` of the elapsed time t − t0; a cut
        there, not earlier, keeps the tail, which the observers treat as closed, short), the run
        is extrapolated from the current (still accurate) impact. A shift of the time origin
        does not change the decision."""
        dg = representation(fl.gap_rows[idx], z)
        v = np.maximum(np.asarray(v_plus, dtype=float), np.finfo(float).tiny)
        if len(key) == 1:
            if not self.law.definition.single_contact_is_newton:
                return False
            e = float(self.law.restitution[key[0]])
            if not 0.0 <= e < 1.0:
                return False
            noise = (1.0 + 2.0 / (1.0 - e)) * (float(dg[0] / v[0]) + time_resolution(t))
        else:
            rho = d[2] / d[1]
            noise = ((1.0 + rho) / (1.0 - rho)) ** 2 * (float(np.max(dg / v)) + time_resolution(t))
        return noise >= zeno_time_budget(t, self.t0, self.zeno_time_rtol)

    def velocity_tail(self, key: tuple, v_plus: np.ndarray, accel: np.ndarray,
                      jerk: np.ndarray) -> float | None:
        """Tail duration from the accurate quantities after the last resolved impact: γ⁺ and
        the contact acceleration γ̇ = −α(t) of the flow (α > 0), with α(t) = α₀ + α₁(t − t_k)
        (α₁ = −γ̈, exact derivatives of the flow).

        A hop leaving with speed v at t flies ``Δ = 2v/α − 4α₁v²/(3α³)`` and lands with
        speed ``v + 2α₁v²/(3α²)`` (Taylor to second order in v), which Newton's law (eq. (5))
        returns multiplied by e; the hops are summed until they vanish. For α₁ = 0 the sum is
        ``2γ⁺/(α₀(1 − e))``, exact for a constant acceleration (docs/theory/oracles.md §1); the error is
        O(tail³·α₁²/α₀², …). None for several contacts or another law (for one contact
        Poisson’s law, eq. (6), is Newton’s).
        """
        if len(key) != 1 or not self.law.definition.single_contact_is_newton:
            return None
        e = float(self.law.restitution[key[0]])
        v, a0, a1 = float(v_plus[0]), -float(accel[0]), -float(jerk[0])
        if not (a0 > 0.0 and v >= 0.0 and 0.0 <= e < 1.0):
            return None
        tail = 0.0
        for _ in range(100_000):
            alpha = a0 + a1 * tail
            if alpha <= 0.0:
                return None
            step = 2.0 * v / alpha - 4.0 * a1 * v * v / (3.0 * alpha ** 3)
            tail += step
            v = e * (v + 2.0 * a1 * v * v / (3.0 * alpha * alpha))
            if step <= 1e-17 * tail or v <= 0.0:
                break
        return tail

    def tail_time(self, key: tuple, d_prev: float, d_last: float) -> float:
        """Duration of the unresolved tail after an interval d_last (preceded by d_prev).

        Several contacts: geometric with the last ratio ρ, ``d_last ρ/(1 − ρ)``. One contact:
        as the hops vanish the contact acceleration is frozen and the ratio tends to the
        restitution e (docs/theory/oracles.md §1); the deviation ρ − e is proportional to the interval, so
        the tail is summed with ``ρ_i = e + c Δ_i``, c fitted to the last ratio (error
        O(Δ²) instead of O(Δ)).
        """
        ratio = d_last / d_prev
        if len(key) != 1:
            return d_last * ratio / (1.0 - ratio)
        e = float(self.law.restitution[key[0]])
        c = (ratio - e) / d_prev
        tail, step = 0.0, d_last
        for _ in range(100_000):
            step *= e + c * step
            tail += step
            if not 0.0 < e + c * step < 1.0:
                return d_last * ratio / (1.0 - ratio)
            if step <= 1e-17 * max(tail, 1e-300):
                break
        return tail

    def accumulate(self, key: tuple, t: float, x: np.ndarray, persistent: tuple, t_inf: float,
                   speed: float, impacts: int | None = None):
        """Carry the state to the accumulation time t_∞ and switch ``key`` to persistent contact.

        The tail in the limit is persistent contact from the last resolved impact t_k on:
        the projection γ⁺ → 0 at t_k is the impulse −G⁻¹γ⁺, the rest of the tail's impulse
        is ∫λ dt over [t_k, t_∞] (so the frame's momentum balance holds exactly).
        ``impacts``: the impacts resolved, when the run's history is not the count (a landing
        of sub-round-off hops, :func:`_impact`); its ratio is then the restitution.
        """
        hist = self.history.pop(key, [])
        self.last_key = None
        d = np.diff([p[0] for p in hist[-3:]])
        ratio = d[1] / d[0] if d.size == 2 else float(self.law.restitution[key[0]])
        setp = tuple(sorted(set(persistent) | set(key)))
        for c in key:          # the tail is densely closed: χ_c = 1 from the last resolved impact
            if self.intervals[c] and self.intervals[c][-1] == (t, t):
                self.intervals[c].pop()
            self.closed_since[c] = t
        gam = self.free_flow.velocities(t, x)[list(setp)]
        proj_impulse = -np.linalg.solve(self.delassus(setp), gam)
        xp = self.project(t, x, list(setp))
        self.add_impulse(t, setp, proj_impulse)
        flow = flow_for(self.system, setp)
        self.fill(flow, t, xp, min(t_inf, self.t_end), include_end=t_inf >= self.t_end)
        if t_inf >= self.t_end:
            return None
        hop = self.hop_end
        if hop is not None and hop[0] == key[0] and hop[1] == t and t <= hop[2] <= t_inf:
            # the state after the exact hops (:meth:`hop_tail`), not the held flow's over the
            # whole tail: the same wherever the resolved impacts were cut
            x_last = self.project(hop[2], hop[3], list(setp))
            x_inf = self.project(t_inf, flow.state(hop[2], x_last, t_inf - hop[2]), list(setp))
        else:
            x_inf = self.project(t_inf, flow.state(t, xp, t_inf - t), list(setp))
        self.hop_end = None
        tail = proj_impulse + flow.force_impulse(t, xp, t_inf - t)
        for c in key:
            self.event(t_inf, c, "accumulation", -speed * ratio, 0.0, tail[setp.index(c)])
        self.zeno.append({"contact": key[0] if len(key) == 1 else key, "t_inf": t_inf,
                          "impacts_resolved": len(hist) if impacts is None else impacts,
                          "tail_time": t_inf - t,
                          "tail_impulse": float(np.sum([tail[setp.index(c)] for c in key])),
                          "ratio": ratio})
        stick = self.sticking(t_inf, x_inf, list(setp))
        for c in setp:
            if c in stick:
                if c not in persistent:
                    self.event(t_inf, c, "stick", 0.0, 0.0, 0.0)
                self.close(c, t_inf)
            else:
                if c in persistent:
                    self.event(t_inf, c, "liftoff", 0.0, 0.0, 0.0)
                self.open(c, t_inf)
        return self.project(t_inf, x_inf, stick), tuple(stick)

    def rests_at_end(self, jt: JointTail, rows: list, cluster: list) -> tuple[list, list]:
        """The contacts of a joint tail past t_end (:meth:`joint_accumulate`) that rest at
        t_end, as ``(t_c, c)``: each its settling time of the tail (``jt.settled``) or, if that
        comes at or after t_end (an impact of the tail lifted it and held it again, after
        t_end or by a hop below the time resolution), its last hold before t_end that no
        lift-off follows before t_end; such a hold's own ``stick`` row leaves ``rows`` (the
        accumulation row and its stick state it, as for a settling time). Returns (rows, rest)."""
        rest = []
        for c in cluster:
            t_c = jt.settled.get(c)
            if t_c is None:
                continue
            if t_c >= self.t_end:
                mine = [r for r in rows if r[1] == c and r[0] < self.t_end
                        and r[2] in ("stick", "liftoff")]
                if not mine or mine[-1][2] != "stick":
                    continue
                t_c = mine[-1][0]
                rows = [r for r in rows if r is not mine[-1]]
            rest.append((t_c, c))
        return rows, rest

    def joint_accumulate(self, jt: JointTail, t: float, x: np.ndarray, held: tuple,
                         cluster: list, key: tuple, gm: np.ndarray, impacts: int):
        """Carry the state to the common accumulation time of a joint tail
        (:func:`observer.event.tails.joint_tail`) resolved from the impact of ``key`` at t:
        the cluster is densely closed from t (as in :meth:`accumulate`): the sample intervals
        get the frame's own impulse, the projection onto the held set at t and the held
        forces' ∫λ dt to t_∞ (or t_end), not the tail's hops. The tail's events
        (:attr:`~observer.event.tails.JointTail.rows`: its impacts, lift-offs and holds, note
        "exact hop") are listed, ``accumulation`` rows at each contact's last hold say how
        the tail was resolved (its impulse), and the acceleration LCP decides which contacts
        stay closed. Returns (x, held set), or None if t_∞ ≥ t_end (the run ends; the tail's
        events before t_end are listed, an accumulation row's impulse is its contact's up to
        t_end, :attr:`~observer.event.tails.JointTail.until_end`)."""
        for c in cluster:
            if self.intervals[c] and self.intervals[c][-1] == (t, t):
                self.intervals[c].pop()
            self.closed_since.setdefault(c, t)
        setp = tuple(sorted(set(jt.held) | set(held)))
        idx = list(jt.held)      # the frame's tail (as in accumulate): the projection at t,
        gam = self.free_flow.velocities(t, x)[idx]           # then the held forces' ∫λ dt (fill)
        self.add_impulse(t, idx, -np.linalg.solve(self.delassus(idx), gam))
        self.fill(flow_for(self.system, jt.held), t, self.project(t, x, list(jt.held)),
                  min(jt.t_inf, self.t_end), include_end=jt.t_inf >= self.t_end)
        hop_note = f"joint tail of contacts {tuple(cluster)}: exact hop"
        rows = [(*row[:6], "; ".join(filter(None, [hop_note, row[6]])))   # the tail's own
                for row in jt.rows]                                          # events
        note = (f"joint tail of contacts {tuple(cluster)}: {jt.hops} impacts resolved by exact "
                f"hops from the contact points")
        e = np.asarray(self.law.restitution, dtype=float)
        if jt.t_inf >= self.t_end:        # the contacts settled before t_end rest there, held
            rows, rest = self.rests_at_end(jt, rows, cluster)
            for t_c, c in sorted(rest):
                if t_c < self.t_end:      # by the tail (the stick its accumulation row states)
                    speed = float(gm[key.index(c)]) * e[c] if c in key else 0.0
                    rows.append((t_c, c, "accumulation", speed, 0.0, jt.until_end[c], note))
                    if c not in held:
                        rows.append((t_c, c, "stick", 0.0, 0.0, 0.0, ""))
            for row in sorted(rows, key=lambda r: r[0]):
                if row[0] < self.t_end:
                    self.event(*row[:6], note=row[6])
            return None
        stick = self.sticking(jt.t_inf, jt.x, list(setp))
        for t_c, c in sorted((jt.settled.get(c, jt.t_inf), c) for c in cluster):
            speed = float(gm[key.index(c)]) * e[c] if c in key else 0.0
            rows.append((t_c, c, "accumulation", speed, 0.0, jt.impulse[c], note))
            self.zeno.append({"contact": c, "t_inf": t_c, "impacts_resolved": impacts + jt.hops,
                              "tail_time": t_c - t, "tail_impulse": float(jt.impulse[c]),
                              "ratio": None, "joint": tuple(cluster)})
            if c in stick and c not in held:
                rows.append((t_c, c, "stick", 0.0, 0.0, 0.0, ""))
        for row in sorted(rows, key=lambda r: r[0]):    # in time order (stable: a contact's
            self.event(*row[:6], note=row[6])            # last hop before its accumulation)
        for c in setp:
            if c in stick:
                self.close(c, jt.t_inf)
            else:
                if c in held:
                    self.event(jt.t_inf, c, "liftoff", 0.0, 0.0, 0.0)
                self.open(c, jt.t_inf)
        return self.project(jt.t_inf, jt.x, stick), tuple(stick)

    def tiny_hops(self, t: float, x: np.ndarray, contacts, persistent: tuple) -> list[int]:
        """Contacts of ``contacts`` falling back (γ̇ < 0 on the flow that holds ``persistent``)
        whose next hop ``γ⁺²/(2|γ̇|)`` is within the certified error of the gap
        (:meth:`hop_error`): such a hop is not resolvable, the impact sequence below it is
        driven by round-off, no longer by the dynamics."""
        fl = flow_for(self.system, persistent)
        z = fl.z(t, x)
        idx = list(contacts)
        v = fl.velocity_rows[idx] @ z
        a = (fl.velocity_rows[idx] @ fl.A) @ z
        tol = self.hop_error(fl, idx, z)
        return [c for c, vc, ac, tc in zip(idx, v, a, tol) if ac < 0.0 and vc * vc <= 2.0 * -ac * tc]

    def land(self, contacts: list[int], t: float, x: np.ndarray, persistent: tuple,
             impacts: int):
        """Land ``contacts`` at t (their hops are below round-off, :meth:`tiny_hops`): the
        tail of infinitely many sub-round-off impacts is the projection γ → 0 on them and the
        persistent set (impulse −G⁻¹γ), an accumulation with tail time 0; then the
        acceleration LCP decides which contacts stay closed. Returns (x, persistent set).

        The projection removes the last hop's upward velocity, so its impulse can be
        negative, of the hop's size (|P| ≤ 1.5e-7 N·s on the 10-block chain, where the
        impacts are ~0.1 N·s); ``impacts`` (impacts since the previous landing) goes to
        :attr:`MasterEventResult.zeno` as ``impacts_resolved``."""
        setp = tuple(sorted(set(persistent) | set(contacts)))
        gam = self.free_flow.velocities(t, x)[list(setp)]
        impulse = -np.linalg.solve(self.delassus(setp), gam)
        x = self.project(t, x, list(setp))
        self.add_impulse(t, setp, impulse)
        for c in contacts:
            if self.intervals[c] and self.intervals[c][-1] == (t, t):
                self.intervals[c].pop()
            i = setp.index(c)
            self.event(t, c, "accumulation", gam[i], 0.0, impulse[i])
        self.zeno.append({"contact": contacts[0] if len(contacts) == 1 else tuple(contacts),
                          "t_inf": float(t), "impacts_resolved": impacts, "tail_time": 0.0,
                          "tail_impulse": float(sum(impulse[setp.index(c)] for c in contacts)),
                          "ratio": None})
        stick = self.sticking(t, x, list(setp))
        for c in setp:
            if c in stick:
                if c not in persistent:
                    self.event(t, c, "stick", 0.0, 0.0, 0.0)
                self.close(c, t)
            elif c in persistent:
                self.event(t, c, "liftoff", 0.0, 0.0, 0.0)
                self.open(c, t)
            else:
                self.touch(c, t)
        return self.project(t, x, stick), tuple(stick)


def _oscillator_block(flow: Flow, t: np.ndarray) -> np.ndarray:
    """Oscillator states ``(cos ω_k t, sin ω_k t)_k`` at the times t, shape (len(t), 2F)."""
    w = flow._freq_array
    out = np.empty((t.size, 2 * w.size))
    wt = np.outer(t, w)
    out[:, 0::2] = np.cos(wt)
    out[:, 1::2] = np.sin(wt)
    return out


def run_master(scenario: Scenario, h: float | None = None, t_end: float | None = None,
               max_events: int = 100_000,
               zeno_velocity_ratio: float = ZENO_VELOCITY_RATIO, t0: float = 0.0,
               should_stop=None, origin: np.ndarray | None = None,
               zeno_time_rtol: float = ZENO_TIME_RTOL) -> MasterEventResult:
    """Exact event-driven run of the master of ``scenario`` (see module docstring).

    Parameters
    ----------
    scenario : Scenario
    h : float, optional
        Output step of the sampled frame (default: the scenario's h).
    t_end : float, optional
        End time (default: the scenario's).
    max_events : int
        Hard cap on the number of events; reaching it stops the run with status
        ``"stopped: event cap …"``.
    zeno_velocity_ratio : float
        See :data:`ZENO_VELOCITY_RATIO`.
    t0 : float
        Initial time (the scenario's initial state is taken at t0; the grid is t0 + k·h):
        a shift of the time origin.
    should_stop : callable, optional
        Called between events and between blocks of samples; a signal name (``"SIGINT"``)
        stops the run there (status ``"stopped: SIGINT at t = …"``, the frame up to the last
        sample computed): a streamed run interrupted keeps its finished rows.
    origin : ndarray, optional
        The gap frame's origin q* when ``scenario`` is the frame's
        (:meth:`observer.event.frame.GapFrame.scenario`): the touch bands take the data's
        resolution in the given coordinates q = x + q* (:meth:`_Run.search_band`).
    zeno_time_rtol : float
        Stated accuracy of an extrapolated accumulation time t_∞, relative to the run's
        elapsed time t − t0 (default :data:`ZENO_TIME_RTOL`; positive,
        ``inf`` turns this cut-off off): the largest part of the gaps' representation error
        that the extrapolation may carry into t_∞. Each resolved impact of a geometric run is
        located to δt = δg/γ⁺ + two ulp of t (δg = eps·Σ|r z|, the gap's representation);
        the run is extrapolated from the first impact at which the first-order propagation
        of δt into t_∞ (:meth:`_Run.noisy_tail`) reaches ``zeno_time_rtol·(t − t0)``, and a
        joint tail (:func:`observer.event.tails.joint_due`) starts there, a cluster of k
        contacts at 1/k² of it. Exact: the decision is this comparison, so from the same
        state a smaller value resolves no more impacts of a run (a cut never comes later),
        and a time shift changes it only through the rounding of t − t0 and the time
        resolution. Approximate:
        the propagation is first order and does not bound the error of the impacts resolved
        before the cut, nor the extrapolation's own error (exact for a constant contact
        acceleration); the other cut-offs (``zeno_velocity_ratio``, the hop within its gap's
        certified error, an interval within the time resolution) may cut first.
        The same value, relative to each contact's reach (its largest |g| and |γ| of the run),
        is how far the carried state error merges a landing with an impact and makes a
        rebound a candidate to stick (:meth:`_Run.accuracy_caps`); beyond it the event row
        says the data do not decide it (with ``inf``, the carried error decides without a
        cap).

    A run that stops (event cap, stalled isolation, no progress) returns the frame up to its
    stop time, never NaN rows, with the reason in ``status``. So does a state that leaves the
    floating-point range (issue 20): the root isolation checks the state and the derivatives
    it uses at every safe step (:class:`~observer.event.roots.NonFiniteFlow`), the frame's rows
    are checked once more when it is built, and the run stops with ``"stopped: non-finite
    QUANTITY of the master (VALUE) at t = …; the output ends at t = …, the last finite
    state"``; overflow inside the engine is silenced (``np.errstate``), the stop says it.
    """
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        return _run_master(scenario, h, t_end, max_events, zeno_velocity_ratio, t0, should_stop,
                           origin, zeno_time_rtol)


def _start(scenario: Scenario, h, t_end, max_events: int, zeno_velocity_ratio: float,
           t0: float, should_stop, zeno_time_rtol: float = ZENO_TIME_RTOL) -> tuple:
    """The run's state at t0: ``(run, t_end, x, persistent)`` (the initial closed set decided)."""
    h = float(scenario.h if h is None else h)
    t_end = float(scenario.t_end if t_end is None else t_end)
    t0 = float(t0)
    if not (np.isfinite(t0) and np.isfinite(t_end) and t_end >= t0):
        raise ValueError(f"t_end = {t_end!r} must be finite and ≥ t0 = {t0!r}")
    try:
        rtol = float(zeno_time_rtol)
    except (TypeError, ValueError):
        rtol = np.nan
    if not rtol > 0.0:
        raise ValueError(f"zeno_time_rtol = {zeno_time_rtol!r} must be a positive relative "
                         "accuracy of t_∞ (or inf to turn the cut-off off)")
    run = _Run(scenario, h, t_end, max_events, zeno_velocity_ratio, t0, rtol)
    run.should_stop = should_stop
    x = np.concatenate([scenario.q0, scenario.u0]).astype(float)
    run.accuracy_caps(run.free_flow.gaps(t0, x), run.free_flow.velocities(t0, x))   # the reach
    x, persistent = _initial_contacts(run, x)
    return run, t_end, x, persistent


def _run_master(scenario: Scenario, h, t_end, max_events: int, zeno_velocity_ratio: float,
                t0: float, should_stop, origin=None, zeno_time_rtol=ZENO_TIME_RTOL):
    run, t_end, x, persistent = _start(scenario, h, t_end, max_events, zeno_velocity_ratio, t0, should_stop, zeno_time_rtol)
    run.origin = None if origin is None else np.asarray(origin, dtype=float)
    t0 = run.t0
    status, nonfinite = RunStatus(), False
    t = t0
    certified: dict[tuple[str, int], float] = {}
    n_events, same_time, t_last_event = 0, 0, -np.inf
    n_impacts = 0                                      # impacts since the last landing
    while True:
        flow = flow_for(run.system, persistent)
        sig = run.halted or (should_stop() if should_stop is not None else None)
        if sig:                                        # SIGINT/SIGTERM of a streamed run
            if run.k_next == 0:                        # before any row: the initial state is one
                run.fill_certified(flow, t, x, float(np.nextafter(t, np.inf)))
            status = _stopped(f"{sig} at t = {t:.9g}")
            break
        rows, keys, cert = _functionals(run, flow, t, x, persistent, certified)
        try:
            zero, t_stop, _ = first_zero(flow, rows, t, flow.z(t, x), t_end, cert, should_stop,
                                         run.search_band(flow, rows, t, flow.z(t, x)), run.energy)
        except SearchStopped as exc:                  # a signal mid-search: the certified rows are kept
            run.fill_certified(flow, t, x, exc.t_ok)
            run.halted = exc.signal
            break
        except NonFiniteFlow as exc:                  # overflow: a stop at the last finite state
            if np.all(np.isfinite(exc.z_ok)):
                run.fill(flow, t, x, exc.t_ok, include_end=True)
            status = _stopped(f"non-finite {_flow_quantity(run, keys, exc)} at t = {exc.t:.9g}")
            nonfinite = True
            t = exc.t
            break
        except RootIsolationError as exc:             # a stall: the certified part is kept
            if exc.t_ok is not None and exc.t_ok > t:
                run.fill(flow, t, x, exc.t_ok, include_end=True)
                t = exc.t_ok
            status = _stopped(str(exc))
            break
        if zero is None:
            run.fill(flow, t, x, t_end, include_end=True)
            break
        run.fill(flow, t, x, zero.t, include_end=False)
        run.carry_error(flow, zero.t - t, flow.z(t, x), zero.carried)
        t, x = zero.t, flow.x_of(zero.z)
        kind, j = keys[zero.index]
        n_events += 1
        if n_events > max_events:
            status = _stopped(f"event cap {max_events} reached at t = {t:.17g}")
            break
        same_time = same_time + 1 if t == t_last_event else 0
        t_last_event = t
        if same_time >= STALL_EVENTS:
            status = _stopped(f"no progress, {STALL_EVENTS} events at t = {t:.17g} "
                              f"(contact {j}, a degenerate contact state)")
            break
        if zero.kind == "touch":                      # graze of a gap, or a force touching 0
            certified[(kind, j)] = zero.resume
            if kind == "g":
                gam = flow.velocities(t, x)[j]
                note = zero.note or _graze_note(zero)
                run.event(t, j, "graze", gam, gam, 0.0, depth=zero.value, note=note)
                run.touch(j, t)
            continue
        certified = {}
        run.note, run.note_time = zero.note, t
        if kind == "f":                                # lift-off: the force of j crosses zero
            x, persistent, cert_new = _liftoff(run, t, x, persistent, j)
            run.history.clear()
            certified.update(cert_new)
            continue
        t, x, persistent, n_impacts, done = _impact(run, t, x, persistent, j, n_impacts)
        if done:                                       # the accumulation lies beyond t_end
            break
    if run.halted and not nonfinite:
        t = float(run.t_grid[run.k_next - 1]) if run.k_next else t0
        status = _stopped(f"{run.halted} at t = {t:.9g}")
    if status.ok and run.k_next < run.t_grid.size:
        status = _stopped("sampling incomplete")
    return _result(run, scenario, status, t, nonfinite)


def _functionals(run: "_Run", flow, t: float, x: np.ndarray, persistent: tuple, certified: dict):
    """The functionals the search watches from (t, x): the free contacts' gaps and the
    persistent contacts' forces that are not identically zero; their keys (``("g", j)``,
    ``("f", j)``) and the certified ones (``{row: t}``, :func:`observer.event.roots.first_zero`)."""
    free = [j for j in range(run.m) if j not in persistent]
    z_now = flow.z(t, x)
    forced = [i for i in range(len(persistent)) if not _identically_zero(flow, flow.force_rows[i], z_now)]
    rows = np.vstack([flow.gap_rows[free], flow.force_rows[forced]])
    keys = [("g", j) for j in free] + [("f", persistent[i]) for i in forced]
    return rows, keys, {i: certified[k] for i, k in enumerate(keys) if k in certified}


def _stopped(reason: str) -> RunStatus:
    return RunStatus(RunState.STOPPED, reason)


def _impact(run: _Run, t: float, x: np.ndarray, persistent: tuple, j: int, n_impacts: int):
    """An impact triggered by contact j at t, then the Zeno check of the run of impacts and
    the landing of sub-round-off hops. Returns ``(t, x, persistent, n_impacts, done)``;
    done: an accumulation at or beyond t_end ended the run (t = t_end)."""
    x, new_persistent, A, gm, lam = run.collide(t, x, persistent, {j})
    n_impacts += 1
    key = tuple(c for c in A if c not in new_persistent)
    if key and set(new_persistent) == set(persistent):
        bouncing = [A.index(c) for c in key]
        t_inf = run.zeno_check(key, t, x, gm[bouncing], persistent)
        if t_inf is not None:
            out = run.accumulate(key, t, x, persistent, t_inf, float(np.max(np.abs(gm[bouncing]))))
            if out is None:
                return run.t_end, x, persistent, n_impacts, True
            return t_inf, out[0], out[1], n_impacts, False
    else:
        run.history.clear()
    landing = run.tiny_hops(t, x, key, new_persistent) if key else []
    cluster = joint_due(run, key, t, x, new_persistent, landing) if key else None
    relaunched = set(key) & set(persistent)         # held contacts this impact lifted
    if cluster is not None and (len(cluster) > len(key) or new_persistent or relaunched):
        jt = joint_tail(run, t, x, new_persistent, cluster, key)
        if jt is not None:             # others land within key's tail, key bounces on a held
            # set, or key re-launched a held contact (a Zeno sequence of Zeno sequences)
            out = run.joint_accumulate(jt, t, x, new_persistent, cluster, key, gm[
                [A.index(c) for c in key]], n_impacts)
            run.history.clear()
            if out is None:
                return run.t_end, x, new_persistent, 0, True
            return jt.t_inf, out[0], out[1], 0, False
    if not landing:
        return t, x, new_persistent, n_impacts, False
    # one contact bouncing alone, nothing held: its tail is extrapolated from γ⁺ (where the
    # hops fall below round-off depends on the coordinates, t∞ must not); a cluster, or a
    # contact bouncing on a held set (the chain's blocks), lands at t
    tail = (run.tail_after(key, t, x, new_persistent)
            if len(key) == 1 and landing == list(key) and not persistent and not new_persistent
            else None)
    if tail is not None and not run.tail_is_clear(key, t, x, persistent, t + tail):
        tail = None
    if tail is None:
        x, new_persistent = run.land(landing, t, x, new_persistent, n_impacts)
        run.history.clear()
        return t, x, new_persistent, 0, False
    out = run.accumulate(key, t, x, persistent, t + tail, float(abs(gm[A.index(key[0])])),
                         impacts=n_impacts)
    run.history.clear()
    if out is None:
        return run.t_end, x, persistent, 0, True
    return t + tail, out[0], out[1], 0, False


def _identically_zero(flow: Flow, row: np.ndarray, z: np.ndarray) -> bool:
    """True if the functional ``row·z(t)`` vanishes along ``flow`` from z, as far as float64
    can certify: no derivative ``row A^k z``, k < N (N the augmented dimension; Cayley–Hamilton:
    then every derivative vanishes), is certainly nonzero (a held contact whose force is zero
    along the flow: touching bodies, never a lift-off).

    ``ψ_k = r̂_k·z`` is certainly nonzero when ``|fl(r̂_k·z)|`` exceeds its certified error
    ``(e_k + (γ_{N+1} + u)|r̂_k|)·|z|``, raised by ``1 + 2γ_{N+1}``: the float64 evaluation of
    the product (γ_{N+1}, Higham §3.1), the float state's own representation of the exact one
    (u per component) and the error ``e_k ≥ |r̂_k − r A^k|`` of the computed derivative row
    (``e_{k+1} = (e_k + γ_{N+1}|r̂_k|)|A|``, raised alike, Higham §3.5). No count of round-offs:
    inside that enclosure no precision decides, since z itself is known to no better."""
    r = np.asarray(row, dtype=float)
    az, absA = np.abs(z), np.abs(flow.A)
    g = gamma(z.size + 1)
    raise_ = 1.0 + 2.0 * g
    e = np.zeros_like(r)
    for _ in range(z.size):
        if abs(float(r @ z)) > raise_ * float((e + (g + 0.5 * np.finfo(float).eps) * np.abs(r)) @ az):
            return False
        e = raise_ * ((e + g * np.abs(r)) @ absA)
        r = r @ flow.A
        if not (np.any(r) or np.any(e)):
            return True
    return True


def _initial_contacts(run: _Run, x: np.ndarray):
    """Closed contacts at t0: an impact if approaching, persistent contact if the force is positive.

    Three-valued decisions on the exact gap and velocity of the initial state
    (:func:`observer.event.enclosures.dot_sign`: float64 with its certified error, ball
    arithmetic where it cannot decide): a contact is closed at t0 when its gap is not
    certainly positive (zero, or a penetration accepted by the scenario,
    :data:`observer.scenario.INITIAL_GAP_TOL`) and its velocity is not certainly leaving. No
    scale of the motion enters: a ball 1 m above the ground is open whatever else the system
    holds (issue 34)."""
    fl = run.free_flow
    t0 = run.t0
    z = fl.z(t0, x)
    g = fl.gap_rows @ z
    closed = {j for j in range(run.m) if dot_sign(fl.gap_rows[j], z).sign != 1
              and dot_sign(fl.velocity_rows[j], z).sign != 1}
    if not closed:
        return x, ()
    qfix = x.copy()
    idx = sorted(closed)
    W = run.system.W[:, idx]
    qfix[:run.n] -= run.Minv @ W @ np.linalg.solve(run.delassus(idx), g[idx])
    x_new, stick, *_ = run.collide(t0, qfix, (), set(idx))
    return x_new, stick


def _graze_note(zero) -> str:
    """The note of a graze row: the minimum m*, its certified enclosure, the touch band (and,
    where the data's part of it dominates the evaluation's, that part: a minimum the data do
    not decide, :func:`observer.event.roots.graze_band_parts`) and the guaranteed crossing
    depth δ* = band + enclosure width there (:func:`observer.event.roots.minimum_enclosure`)."""
    lo, hi = zero.enclosure or (zero.value, zero.value)
    by_data = zero.band_data > zero.band - zero.band_data
    why = (f"; of the band {zero.band_data:.3g} the data's (the state's distance to the exact "
           "trajectory of the data, and their resolution): the data do not decide this minimum"
           ) if by_data else ""
    return (f"minimum {zero.value:.3g} in [{lo:.3g}, {hi:.3g}] (certified) within the touch band "
            f"±{zero.band:.3g}; guaranteed crossing depth {zero.band + (hi - lo):.3g}{why}")


def _liftoff(run: _Run, t: float, x: np.ndarray, persistent: tuple, j: int):
    """Contact j's force crossed zero: re-solve the acceleration LCP without j; j opens."""
    rest = [c for c in persistent if c != j]
    stick = run.sticking(t, x, rest)
    leaving = [c for c in persistent if c not in stick]
    for c in leaving:
        run.event(t, c, "liftoff", 0.0, 0.0, 0.0)
        run.open(c, t)
    new = tuple(stick)
    x = run.project(t, x, list(new))
    flow = flow_for(run.system, new)
    z = flow.z(t, x)
    cert = {}
    for c in leaving:
        until = _rise_band(flow, flow.gap_rows[c], z)
        if until is not None:
            cert[("g", c)] = t + until
    return x, new, cert


RISE_DOUBLINGS = 64
"""Doublings of the trial time in :func:`_rise_band` (from the first-order estimate)."""


def _rise_band(flow: Flow, row: np.ndarray, z: np.ndarray) -> float | None:
    """The undecidable start of a lifting contact's gap, from its certified enclosures: the
    gap of a lift-off starts as ``g ≈ γ ≈ γ̇ ≈ 0 < γ̈`` (``g ≈ γ̈ s³/6``), each of the first three
    within its certified float64 error (:meth:`observer.event.roots.FunctionalSet.errors`),
    where no sign is decidable. With ``γ̈`` certainly positive, returns the first trial time s
    (where ``γ̈ s³/6`` exceeds each ``(|ψ^(k)| + e_k) s^k/k!``, k < 3, then doubled) at which
    the gap of the exact flow from z is certainly positive (:meth:`~observer.event.roots.FunctionalSet.enclose`,
    a Taylor model with Lagrange remainder), the search resuming from there; None when γ̈ is
    not certainly positive or no trial within the Taylor model's window certifies.

    No motion tolerance: the band is what the gap's own certified errors leave undecided (it
    was 1000 motion tolerances on τ and 64 eps·Σ|r z|, which at a translation skipped a whole
    hop and took its landing late: tests/observer/event/test_liftoff_band.py)."""
    fs = FunctionalSet(flow, row[None, :])
    err = fs.errors(z, 3)[:, 0]
    d = [fs.value(0, k, z) for k in range(4)]
    rate = d[3] - err[3]
    if not rate > 0.0:
        return None
    # where the rise γ̈ s³/6 first exceeds each undecided term (|ψ^(k)| + e_k) s^k/k!: a
    # guess in the unit of time whatever the units of g (dimensionally consistent)
    s = max((6.0 * (abs(d[k]) + err[k]) / (rate * (1.0, 1.0, 2.0)[k])) ** (1.0 / (3 - k))
            for k in range(3))
    s = max(s, np.finfo(float).tiny)
    reach = WINDOW / fs.norm_bound if fs.norm_bound > 0.0 else np.inf
    for _ in range(RISE_DOUBLINGS):
        if s > reach:
            return None
        if fs.enclose(0, 0, z, s)[0] > 0.0:
            return s
        s *= 2.0
    return None


def _flow_quantity(run: _Run, keys: list, exc: NonFiniteFlow) -> str:
    """The non-finite quantity of a :class:`NonFiniteFlow`, named: ``u1 of the master (inf)``,
    ``derivative 2 of the master's gap g0 (inf)``, ``bound on derivative 3 of the master's
    gap g0 over the search window (inf)``."""
    n = run.n
    if exc.what[0] == "state":
        i = exc.what[1]
        name = f"q{i}" if i < n else (f"u{i - n}" if i < 2 * n else f"exogenous state z{i}")
        return f"{name} of the master ({exc.value})"
    k, i = exc.what[1], exc.what[2]
    kind, j = keys[i]
    base = f"gap g{j}" if kind == "g" else f"contact force λ{j}"
    if exc.what[0] == "bound":
        return f"bound on derivative 3 of the master's {base} over the search window ({exc.value})"
    if k == 0:
        return f"{base} of the master ({exc.value})"
    return f"derivative {k} of the master's {base} ({exc.value})"


def _finite_rows(run: _Run, G: np.ndarray) -> tuple[int, str | None]:
    """Rows of the frame before the first one with a non-finite q, u, g or P, and that
    quantity named (None: every row finite). Cheap: one vectorised test in the usual case."""
    n = run.n
    blocks = (("q", run.X[:, :n]), ("u", run.X[:, n:]), ("g", G), ("P", run.P))
    if all(np.isfinite(b).all() for _, b in blocks):
        return run.t_grid.size, None
    first, what = run.t_grid.size, None
    for name, b in blocks:
        bad = np.flatnonzero(~np.isfinite(b).all(axis=1))
        if bad.size and bad[0] < first:
            j = int(np.flatnonzero(~np.isfinite(b[bad[0]]))[0])
            first, what = int(bad[0]), f"{name}{j} of the master ({b[bad[0], j]})"
    return first, what


def _result(run: _Run, scenario: Scenario, status: RunStatus, t_stop: float,
            nonfinite: bool) -> MasterEventResult:
    n, m = run.n, run.m
    if not status.ok:                  # a stopped run ends at its stop time: no NaN rows
        keep = run.k_next
        run.t_grid, run.X, run.P = run.t_grid[:keep], run.X[:keep], run.P[:keep]
    G = run.X[:, :n] @ run.system.W + run.system.nu(run.t_grid)
    keep, bad = _finite_rows(run, G)   # non-finite rows (overflow): the output ends before them
    if bad is not None:
        if not nonfinite:
            status, nonfinite = _stopped(f"non-finite {bad} at t = {run.t_grid[keep]:.9g}"), True
        t_stop = float(run.t_grid[keep])
        run.t_grid, run.X, run.P, G = run.t_grid[:keep], run.X[:keep], run.P[:keep], G[:keep]
    if nonfinite:
        status = _stopped(status.reason + (f"; the output ends at t = {run.t_grid[-1]:.9g}, the last "
                                           "finite state" if run.t_grid.size else "; no finite output row"))
    t_grid = run.t_grid
    for j, since in list(run.closed_since.items()):
        run.intervals[j].append((since, np.inf))
    active = np.zeros((t_grid.size, m), dtype=np.int8)
    for j in range(m):
        for c, o in run.intervals[j]:
            k0 = int(np.searchsorted(t_grid, c, side="left"))
            k1 = int(np.searchsorted(t_grid, o, side="left")) if np.isfinite(o) else t_grid.size - 1
            active[k0:min(k1, t_grid.size - 1) + 1, j] = 1
    closings = [np.array([c for c, _ in iv]) for iv in run.intervals]
    openings = [np.array([o for _, o in iv]) for iv in run.intervals]
    return MasterEventResult(scenario, run.h, run.t_end, t_grid, run.X[:, :n], run.X[:, n:], G,
                             run.P, active.astype(bool), list(run.events), status, closings,
                             openings, run.zeno, run.segments,
                             float(run.t_end if status.ok else t_stop), nonfinite)
