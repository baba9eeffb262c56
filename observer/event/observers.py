"""Exact event-driven observers (issue 11, item 3): ``jump`` and ``nojump`` driven by the exact χ.

The observers' constraints are *time-triggered*: χ_i(t) = 1 exactly on the closed intervals of
contact i of the event-driven master (:func:`observer.event.master.run_master`; an impact is a
closed interval of zero length). Between switching times every observer is a linear system
with harmonic inputs, so its flow is the exponential of one augmented generator (state
``z = (q, u, x)`` with the exogenous state ``x = (1, cos ω_j t, sin ω_j t, …)`` re-set from t
analytically at the start of every flow segment). With ``I = {i : χ_i = 1}`` and ``A ⊆ I`` the
contacts whose velocity constraint is active (γ_A = 0 held by a force λ_A ≥ 0):

* ``nojump`` (switched kinematic constraints, paper eqs. (7)-(9) with σ = Σ = 0)::

      q̇ = u,    M u̇ = −Cu − Kq + f(t) + W_A λ_A

* ``jump`` (switched geometric constraints, eqs. (7)-(14)): additionally the kinematic
  equation carries σ = −P_I L_I⁻¹ P_Iᵀ γ (eq. (13)) so that ġ_I = 0 is held exactly::

      q̇ = u + K⁻¹W_I σ_I = (1 − K⁻¹W_I L_I⁻¹W_Iᵀ) u − K⁻¹W_I L_I⁻¹ ν̇_I(t),   L_I = W_IᵀK⁻¹W_I

  and at every switching-on the position jump of eq. (14), the K-metric projection
  ``q⁺ = q⁻ − K⁻¹W_I L_I⁻¹ g_I⁻`` onto g_I = 0 over the whole closed set I.

The other registered designs with position jumps (``jump_mass``, ``jump_identity``) use the
metric N = M or 1 in place of K (L_I = W_IᵀN⁻¹W_I); only N = K is covered by Theorem 1.

Both: when χ_i switches on with γ_i⁻ < 0 the observer impacts through the *same* impact-law
code as the master and the time-stepper (:mod:`observer.impact`, eq. (9), Delassus matrix
W_IᵀM⁻¹W_I; Poisson on all of I, Newton on the approaching contacts of I, see
:meth:`_ObserverIntegrator.collide`); while χ_i = 1 the velocity-level unilateral
constraint γ_i ≥ 0 holds (eq. (8)): a contact whose γ_i reaches 0 from above becomes active
("stick": λ from the acceleration-level LCP ``0 ≤ γ̇_B ⊥ λ_B ≥ 0``), an active contact
releases when its force λ_i — an exact linear function of the state — crosses zero
("liftoff"). These own events are found by a certified search (a Taylor bound with a
remainder from ‖A‖ on every interval, so no sign change is missed) and refined to machine
precision by safeguarded Newton steps on the exact flow.

The error Lyapunov function against the master is ``V = ½vᵀMv + ½eᵀKe`` (paper (16) with the
½ on both terms), sampled on the master's output grid.

Sampling convention: row 0 is the observer's initial state (before any event at t_0, as in
time-stepping); row k ≥ 1 is the state at t_k *after* the events at t_k (right limit).

Coupling window: before t_on each observer runs uncoupled (the event master of the same model
from its own state, as ``source = "self"`` in time-stepping); t_off must reach t_end.

API::

    from observer.event.master import run_master
    from observer.event.observers import run_observers, run_schedule
    master = run_master(scenario)
    obs = run_observers(master, scenario, observers=("jump", "nojump"))   # names or Slave objects
    obs.frame                 # t, chi0.., jump_q0.., jump_u0.., V_jump, nojump_q0.., ..., V_nojump
    obs.runs["jump"]          # EventObserverRun: q, u, V, P (impacts), sigma (position jumps), events, status
    obs.runs["jump"].events   # time, contact, kind (projection/impact/stick/liftoff), gamma_minus, gamma_plus, impulse
    obs.runs["jump"].as_slave()   # -> observer.result.SlaveTrajectory for SimulationResult.slaves
    run_schedule(system, law, t, q0, u0, intervals, metric="K")   # one observer for any χ (no master)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterable

import numpy as np

from observer.contact import get_solver
from observer.event.enclosures import dot_error
from observer.event.flow import expm_pade13
from observer.errors import InputError
from observer.impact import ImpactLaw
from observer.model import LinearSystem
from observer.observers import ObserverConfig, Slave, lyapunov, make_slaves
from observer.result import EVENT_COLUMNS, RunState, RunStatus

if TYPE_CHECKING:
    import pandas as pd

EVENT_KINDS = ("projection", "impact", "stick", "liftoff")
"""Kinds of an observer's own events: ``projection`` (position jump Σ_i of eq. (14), in the
``impulse`` column), ``impact`` (impulse Λ_i of eq. (9)), ``stick`` (γ_i reached 0 while
χ_i = 1: the velocity constraint becomes active), ``liftoff`` (its force λ_i crossed 0)."""

MAX_SUBDIVISIONS = 20_000
"""Largest number of intervals the certified search examines in one step before it gives up
(the run stops with a status saying so)."""

MAX_EVENTS_PER_INSTANT = 20
"""More own events than this at one instant stop the run (status says so): a mode cycle."""


expm = expm_pade13
"""Matrix exponential (:func:`observer.event.flow.expm_pade13`: numpy scaling and squaring with
the [13/13] Padé approximant; scipy's threaded BLAS made one small call cost milliseconds)."""


# ------------------------------------------------------------------------------------------
# exogenous signals: f(t), ν(t), ν̇(t), ν̈(t) as linear maps of x(t) = (1, cos ω_j t, sin ω_j t)
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Exosystem:
    """Harmonic inputs as linear functions of the exogenous state ``x(t)``.

    ``x(t) = (1, cos ω_1 t, sin ω_1 t, …)`` over the distinct frequencies of the forcing and
    of the gap offset; ``ẋ = S x`` exactly. ``f(t) = F x``, ``ν(t) = N0 x``, ``ν̇ = N1 x``,
    ``ν̈ = N2 x`` (paper eqs. (1)-(3)).
    """

    omegas: np.ndarray
    S: np.ndarray
    F: np.ndarray
    N0: np.ndarray
    N1: np.ndarray
    N2: np.ndarray

    @staticmethod
    def build(system: LinearSystem) -> "Exosystem":
        omegas = np.unique(np.concatenate([system.forcing.omega, system.gap.omega]))
        nx = 1 + 2 * omegas.size
        S = np.zeros((nx, nx))
        for j, w in enumerate(omegas):
            c, s = 1 + 2 * j, 2 + 2 * j
            S[c, s], S[s, c] = -w, w            # d/dt cos = −ω sin, d/dt sin = ω cos
        F = np.zeros((system.n, nx))
        F[:, 0] = system.forcing.constant
        for a, w, p in zip(system.forcing.amplitude, system.forcing.omega, system.forcing.phase):
            c = 1 + 2 * int(np.searchsorted(omegas, w))
            F[:, c] += a * np.cos(p)                    # a cos(ωt+φ) = a cosφ cos ωt − a sinφ sin ωt
            F[:, c + 1] -= a * np.sin(p)
        m = system.m
        N0, N1, N2 = np.zeros((m, nx)), np.zeros((m, nx)), np.zeros((m, nx))
        N0[:, 0] = system.gap.constant
        for b, w, p in zip(system.gap.amplitude, system.gap.omega, system.gap.phase):
            c = 1 + 2 * int(np.searchsorted(omegas, w))
            N0[:, c] += b * np.sin(p)                   # b sin(ωt+φ) = b sinφ cos ωt + b cosφ sin ωt
            N0[:, c + 1] += b * np.cos(p)
            N1[:, c] += b * w * np.cos(p)               # ν̇ = bω cos(ωt+φ)
            N1[:, c + 1] -= b * w * np.sin(p)
            N2[:, c] -= b * w * w * np.sin(p)           # ν̈ = −bω² sin(ωt+φ)
            N2[:, c + 1] -= b * w * w * np.cos(p)
        return Exosystem(omegas, S, F, N0, N1, N2)

    @property
    def size(self) -> int:
        return self.S.shape[0]

    def x(self, t: float) -> np.ndarray:
        """The exogenous state at time t, computed from t (no propagated phase)."""
        out = np.empty(self.size)
        out[0] = 1.0
        out[1::2] = np.cos(self.omegas * t)
        out[2::2] = np.sin(self.omegas * t)
        return out


# ------------------------------------------------------------------------------------------
# one mode (I, A) of one observer design: its generator and the linear outputs γ, g, λ
# ------------------------------------------------------------------------------------------
class Mode:
    """The exact flow of an observer in mode (I, A): generator, outputs, cached exponentials.

    Parameters
    ----------
    system : LinearSystem
    exo : Exosystem
    closed : tuple of int
        I, the contacts with χ_i = 1 (used by the ``jump`` design's σ, eq. (13)).
    active : tuple of int
        A ⊆ I, contacts whose velocity constraint γ_i = 0 is held by λ_i (eq. (8)).
    metric : ndarray (n, n) or None
        The projection metric N of a design with position jumps (N = K: the paper's
        ``jump``, σ = −L_I⁻¹γ_I of eq. (13) enters as N⁻¹W_Iσ); None: ``nojump``.
    """

    def __init__(self, system: LinearSystem, exo: Exosystem, closed: tuple, active: tuple,
                 metric: np.ndarray | None):
        n, nx = system.n, exo.size
        self.n, self.nz = n, 2 * n + nx
        M, C, K, W = system.M, system.C, system.K, system.W
        Minv = np.linalg.inv(M)
        gen = np.zeros((self.nz, self.nz))
        q, u, x = slice(0, n), slice(n, 2 * n), slice(2 * n, self.nz)
        gen[q, u] = np.eye(n)
        if metric is not None and closed:
            WI = W[:, list(closed)]
            NinvWI = np.linalg.solve(metric, WI)
            Q = NinvWI @ np.linalg.inv(WI.T @ NinvWI)              # N⁻¹W_I L_I⁻¹, L_I = W_IᵀN⁻¹W_I
            gen[q, u] -= Q @ WI.T
            gen[q, x] = -Q @ exo.N1[list(closed)]
        acc = np.hstack([-Minv @ K, -Minv @ C, Minv @ exo.F])      # M⁻¹(−Kq − Cu + f) on (q, u, x)
        self.force_rows = np.zeros((0, self.nz))
        if active:
            WA = W[:, list(active)]
            GA = WA.T @ Minv @ WA
            rhs = WA.T @ acc
            rhs[:, x] += exo.N2[list(active)]
            self.force_rows = -np.linalg.solve(GA, rhs)            # λ_A = −G_A⁻¹(W_AᵀM⁻¹(…) + ν̈_A)
            acc = acc + Minv @ WA @ self.force_rows
        gen[u, :] = acc
        gen[x, x] = exo.S
        self.A = gen
        self.gamma_rows = np.hstack([np.zeros((system.m, n)), W.T, exo.N1])
        self.gap_rows = np.hstack([W.T, np.zeros((system.m, n)), exo.N0])
        self.closed, self.active = closed, active
        self.norm = float(np.linalg.norm(gen, 2))
        self._expm: dict[float, np.ndarray] = {}

    def propagator(self, tau: float) -> np.ndarray:
        """exp(A τ), kept in a small LRU cache (the grid steps and their halvings repeat; the
        partial steps after events do not)."""
        P = self._expm.pop(tau, None)
        if P is None:
            P = expm(self.A * tau)
            if len(self._expm) >= 128:
                del self._expm[next(iter(self._expm))]
        self._expm[tau] = P
        return P


@dataclass
class _Monitor:
    """A linear functional φ(z) = c·z whose crossing of 0 from above is an event."""

    contact: int
    kind: str            # "stick" (φ = γ_i, i ∈ I∖A) or "liftoff" (φ = λ_i, i ∈ A)
    row: np.ndarray


def _monitors(mode: Mode, closed: frozenset) -> list[_Monitor]:
    """γ_i for the free contacts of I (``nojump`` modes do not carry I), λ_i for those of A."""
    out = [_Monitor(i, "stick", mode.gamma_rows[i]) for i in sorted(closed) if i not in mode.active]
    out += [_Monitor(i, "liftoff", mode.force_rows[k]) for k, i in enumerate(mode.active)]
    return out


# ------------------------------------------------------------------------------------------
# certified search for the first crossing of 0 from above of φ(τ) = c·exp(Aτ)z_a, τ ∈ (0, δ]
# ------------------------------------------------------------------------------------------
def _derivs(mode: Mode, row: np.ndarray, order: int) -> list[np.ndarray]:
    rows = [row]
    for _ in range(order):
        rows.append(rows[-1] @ mode.A)
    return rows


def _safe_start(mode: Mode, mon: _Monitor, z: np.ndarray, delta: float, zeros: int = 0) -> float:
    """Length of an initial interval on which φ certainly does not cross 0 from above.

    For φ(0) > 0 this is 0 (the search starts at once). For φ(0) ≈ 0 (the functional was just
    reset by an event: a contact freed with γ̇ > 0, or released with γ = γ̇ = 0 and γ̈ > 0)
    the first non-negligible derivative d_k must be positive, and the Taylor bound
    ``φ(s) ≥ Σ_{j≤k} d_j s^j/j! − B s^{k+1}/(k+1)!`` with ``B = ‖c A^{k+1}‖ e^{‖A‖δ}‖z‖`` gives
    s₁ with φ increasing from round-off level to φ(s₁) > 0 on (0, s₁]. Returns −1 when no
    derivative up to the second is certifiably positive (degenerate: the caller stops).

    ``zeros``: the derivatives d_0, …, d_{zeros−1} that the event which reset φ made exactly
    zero (a lift-off: γ = γ̇ = 0, the contact was held and its force is zero at the root; a
    plastic impulse, e = 0 and Λ > 0: γ⁺ = 0 by the law); the float state's values of them
    are the round-off of the held flow, of the root's location and of the jump, not of the
    motion, and are set to 0. (Not a stick: its state may lie past the root, where the float
    γ is certainly negative — a free contact of the chain at e = 0 then chattered between
    stick events instead of stopping.) The others are zero only within the certified float64
    error of their evaluation,
    γ_{N+1}·Σ|c_k z| (no count of round-offs: it was 1e3·eps·‖c_k‖‖z‖, which hid a
    lift-off's γ = −3e-21, certainly negative in the float state, as zero).
    """
    rows = _derivs(mode, mon.row, 3)
    d = [0.0 if k < zeros else float(r @ z) for k, r in enumerate(rows)]
    if d[0] > 0.0:
        return 0.0
    nz = float(np.linalg.norm(z))
    tiny = [dot_error(r, z) for r in rows]
    if d[0] < -tiny[0]:
        return -1.0
    cap = min(delta, 1.0 / mode.norm) if mode.norm > 0.0 else delta   # e^{‖A‖s} ≤ e on (0, cap]
    growth = np.exp(mode.norm * cap)
    for k in (1, 2):
        if d[k] < -tiny[k]:
            return -1.0
        if d[k] <= tiny[k]:
            continue
        B = float(np.linalg.norm(rows[k + 1])) * growth * nz
        if k == 1:      # φ ≥ d0 + d1 s − B s²/2 ≥ d0 + d1 s/2 for s ≤ d1/B
            s1 = min(cap, d[1] / B) if B > 0.0 else cap
            val = d[0] + 0.5 * d[1] * s1
        else:           # φ ≥ d0 + d1 s + d2 s²/2 − B s³/6 ≥ d0 + d1 s + d2 s²/4 for s ≤ 1.5 d2/B
            s1 = min(cap, 1.5 * d[2] / B) if B > 0.0 else cap
            val = d[0] + d[1] * s1 + 0.25 * d[2] * s1 * s1
        if val > 0.0 or s1 >= delta:    # φ' > 0 on [O(round-off), s₁]: no crossing from above
            return s1
        return -1.0
    return -1.0


def _lower_bound(phi_a: float, dphi_a: float, B: float, delta: float) -> float:
    """min over s ∈ [0, δ] of the concave bound φ(a) + φ'(a)s − Bs²/2 (attained at an end)."""
    return min(phi_a, phi_a + dphi_a * delta - 0.5 * B * delta * delta)


def _first_crossing(mode: Mode, row: np.ndarray, za: np.ndarray, delta: float,
                    start: float = 0.0) -> float | None:
    """First τ ∈ (start, δ] with φ(τ) ≤ 0 after φ > 0, φ(τ) = row·exp(Aτ)z_a; None if there is none.

    Certified: an interval [a, a+w] is discarded only when the Taylor bound
    ``φ(a) + φ'(a)s − ‖row A²‖ e^{‖A‖w}‖z(a)‖ s²/2`` (a bound on φ'' along the exact flow)
    stays positive on it; otherwise it is halved (the states at the midpoints are propagated
    with cached exponentials). A touch of 0 without a sign change narrower than ~1e-15 of the
    interval is not an event (it changes nothing).
    """
    row2 = row @ mode.A @ mode.A
    n_row2 = float(np.linalg.norm(row2)) * (1.0 + 1e-12)
    drow = row @ mode.A
    z0 = za if start == 0.0 else mode.propagator(start) @ za
    stack = [(start, delta - start, z0, 0)]
    for _ in range(MAX_SUBDIVISIONS):
        if not stack:
            return None
        a, w, z, depth = stack.pop()
        phi_a = float(row @ z)
        if phi_a <= 0.0 and a > start:
            return a
        B = n_row2 * np.exp(mode.norm * w) * float(np.linalg.norm(z))
        if _lower_bound(phi_a, float(drow @ z), B, w) > 0.0:
            continue
        if depth >= 52:
            zb = mode.propagator(w) @ z
            if float(row @ zb) <= 0.0:
                return a + w
            continue
        zm = mode.propagator(0.5 * w) @ z
        stack.append((a + 0.5 * w, 0.5 * w, zm, depth + 1))
        stack.append((a, 0.5 * w, z, depth + 1))
    if not stack:
        return None
    raise _Stalled(f"root isolation stalled ({MAX_SUBDIVISIONS} subdivisions of one step)")


class _Stalled(RuntimeError):
    """The certified search could not decide (a functional hugging 0 over a whole interval)."""


def _refine(mode: Mode, row: np.ndarray, za: np.ndarray, lo: float, hi: float) -> float:
    """The crossing of φ in [lo, hi] (φ(lo) > 0 ≥ φ(hi)) to machine precision: Newton with bisection."""
    drow = row @ mode.A
    t = hi
    for _ in range(200):
        z = mode.propagator(t) @ za
        phi = float(row @ z)
        if phi > 0.0:
            lo = t
        else:
            hi = t
        if hi - lo <= 2.0 * np.finfo(float).eps * max(1.0, abs(hi)):
            break
        dphi = float(drow @ z)
        step = t - phi / dphi if dphi != 0.0 else 0.5 * (lo + hi)
        t = step if lo < step < hi else 0.5 * (lo + hi)
    return hi


# ------------------------------------------------------------------------------------------
# one observer over the whole run
# ------------------------------------------------------------------------------------------
@dataclass
class EventObserverRun:
    """One exact observer: trajectory on the grid, error Lyapunov function, own events.

    Attributes
    ----------
    name : str
    position_jumps : bool
    q, u : ndarray, shape (N+1, n)
    V : ndarray, shape (N+1,)
        ``½vᵀMv + ½eᵀKe`` against the master on the same grid (paper (16)).
    P : ndarray, shape (N+1, m)
        Impact impulses Λ of the observer in (t_{k−1}, t_k] (row 0: at t_0).
    sigma : ndarray, shape (N+1, m)
        Position-jump multipliers Σ of eq. (14) in (t_{k−1}, t_k].
    event_rows : list of tuple
        The observer's own events, rows of :data:`observer.result.EVENT_COLUMNS` (kinds
        :data:`EVENT_KINDS`); :attr:`events` is their DataFrame.
    status : RunStatus
        ``ok``, or ``stopped`` with the reason (decided where the run stopped).
    """

    name: str
    position_jumps: bool
    q: np.ndarray
    u: np.ndarray
    V: np.ndarray
    P: np.ndarray
    sigma: np.ndarray
    event_rows: list = field(default_factory=list)
    status: RunStatus = field(default_factory=RunStatus)

    @property
    def events(self) -> pd.DataFrame:
        """The observer's own events as a DataFrame (:data:`observer.result.EVENT_COLUMNS`)."""
        return _event_frame(self.event_rows)

    def as_slave(self):
        """This run as a :class:`observer.result.SlaveTrajectory` (for ``SimulationResult.slaves``;
        the per-step decrements of V are time-stepping quantities: None)."""
        from observer.result import SlaveTrajectory
        return SlaveTrajectory(self.name, self.q, self.u, self.P, self.V, None, None, None, self.sigma)


@dataclass
class EventObserversResult:
    """All exact observers of one master run.

    Attributes
    ----------
    t : ndarray, shape (N+1,)
        The master's output grid.
    chi : ndarray of bool, shape (N+1, m)
        χ_j = 1 if contact j of the master is closed at some instant of (t_{k−1}, t_k] (row 0: at t_0).
    runs : dict[str, EventObserverRun]
    """

    t: np.ndarray
    chi: np.ndarray
    runs: dict = field(default_factory=dict)
    master_status: RunStatus = field(default_factory=RunStatus)

    @property
    def frame(self) -> pd.DataFrame:
        """``t, chi0.., NAME_q0.., NAME_u0.., V_NAME`` per observer (the naming of
        :meth:`observer.result.SimulationResult.to_frame`)."""
        import pandas as pd

        cols: dict[str, np.ndarray] = {"t": self.t}
        for j in range(self.chi.shape[1]):
            cols[f"chi{j}"] = self.chi[:, j].astype(np.int8)
        for name, r in self.runs.items():
            for j in range(r.q.shape[1]):
                cols[f"{name}_q{j}"] = r.q[:, j]
            for j in range(r.u.shape[1]):
                cols[f"{name}_u{j}"] = r.u[:, j]
            cols[f"V_{name}"] = r.V
        return pd.DataFrame(cols)

    @property
    def status(self) -> RunStatus:
        """``ok`` if the master and every observer ran to the end, else the first stop (its
        reason prefixed ``master:`` or the observer's name)."""
        if not self.master_status.ok:
            return _stopped(f"master: {self.master_status.reason}")
        return next((_stopped(f"{n}: {r.status.reason}") for n, r in self.runs.items() if not r.status.ok),
                    RunStatus())


def _stopped(reason: str) -> RunStatus:
    return RunStatus(RunState.STOPPED, reason)


def switching_schedule(intervals: list[np.ndarray], t0: float, t_end: float) -> list[tuple[float, list, list]]:
    """χ's switching instants from the closed intervals of every contact.

    Parameters
    ----------
    intervals : list of ndarray (k_j, 2)
        ``[closing, opening]`` of contact j (an impact: opening == closing; open at the end: inf).

    Returns
    -------
    list of (time, on, off)
        Sorted instants in [t0, t_end] with the contacts switching on and off there; a
        zero-length interval appears in both lists of its instant (on first, then off).
    """
    at: dict[float, tuple[list, list]] = {}
    for j, iv in enumerate(intervals):
        for tc, to in np.asarray(iv, dtype=float).reshape(-1, 2):
            if tc > t_end or to < t0:
                continue
            at.setdefault(max(float(tc), t0), ([], []))[0].append(j)
            if to <= t_end:
                at.setdefault(float(to), ([], []))[1].append(j)
    return [(t, sorted(on), sorted(off)) for t, (on, off) in sorted(at.items())]


class _ObserverIntegrator:
    """Runs one observer design through a χ schedule on an output grid (exact flow + events)."""

    def __init__(self, system: LinearSystem, law: ImpactLaw, metric: np.ndarray | None, solver):
        self.system, self.law, self.metric, self.solver = system, law, metric, solver
        self.jumps = metric is not None
        self.exo = Exosystem.build(system)
        self.Minv = np.linalg.inv(system.M)
        self._modes: dict[tuple, Mode] = {}
        self._hold_maps: dict[tuple, tuple] = {}
        self.events: list[tuple] = []
        self.should_stop = None        # callable → a signal name (stop between switchings) or None
        self.zeros: dict = {}          # monitor → derivatives the last switching made zero

    def mode(self, closed: frozenset, active: frozenset) -> Mode:
        key = (tuple(sorted(closed)) if self.jumps else (), tuple(sorted(active)))
        md = self._modes.get(key)
        if md is None:
            md = self._modes[key] = Mode(self.system, self.exo, key[0], key[1], self.metric)
        return md

    # -- instantaneous events --------------------------------------------------------------
    def project(self, t: float, q: np.ndarray, closed: frozenset, k_row: int) -> np.ndarray:
        """Position jump of eq. (14): q⁺ = q⁻ − N⁻¹W_I L_I⁻¹ g_I⁻ (argmin ‖q − q⁻‖_N s.t. g_I = 0; N = K)."""
        idx = sorted(closed)
        W = self.system.W[:, idx]
        g = W.T @ q + self.system.nu(t)[idx]
        NinvW = np.linalg.solve(self.metric, W)
        Sigma = -np.linalg.solve(W.T @ NinvW, g)
        for j, s in zip(idx, Sigma):
            self.events.append((t, j, "projection", np.nan, np.nan, float(s)))
            self.sigma[k_row, j] += s
        return q + NinvW @ Sigma

    def hold(self, t: float, q: np.ndarray, closed: frozenset) -> np.ndarray:
        """Remove the round-off drift of g_I (exactly 0 along the constrained flow) by the same
        projection, without recording it: a correction of a few ulps per segment."""
        if not (self.jumps and closed):
            return q
        idx = tuple(sorted(closed))
        corr = self._hold_maps.get(idx)
        if corr is None:
            W = self.system.W[:, list(idx)]
            NinvW = np.linalg.solve(self.metric, W)
            corr = self._hold_maps[idx] = (W, NinvW @ np.linalg.inv(W.T @ NinvW))
        W, R = corr
        return q - R @ (W.T @ q + self.system.nu(t)[list(idx)])

    def collide(self, t: float, u: np.ndarray, closed: frozenset, k_row: int) -> np.ndarray:
        """Impact of eq. (9) on the closed set I when some γ_i⁻ < 0 (the master's impact law).

        Where the law acts is its declared fact
        (:attr:`~observer.impact.ImpactLawDefinition.event_closed_set`): ``"all"`` of I (Poisson,
        Glocker's inequality form, keeps γ⁺ ≥ 0 by construction); ``"approaching"``: Newton's
        ``0 ≤ γ⁺ + eγ⁻ ⊥ Λ ≥ 0`` would let a separating contact of I (γ_i⁻ > 0) leave with
        γ_i⁺ = −eγ_i⁻ < 0, violating its velocity constraint; so it acts on the approaching and
        resting contacts J = {i ∈ I : γ_i⁻ ≤ 0}, and a separating contact the impulse drives to
        γ⁺ < 0 joins J with e = 0 (until none does; for one contact: the law itself).
        """
        idx = np.array(sorted(closed))
        gam = self.system.contact_velocities(u, t)[idx]
        if not np.any(gam < 0.0):
            return u
        law = self.law.definition
        if law.event_closed_set == "all":
            J, e = idx, self.law.restitution[idx]
            Lam = law.impact_map(self._delassus(idx), gam, e, self.solver.solve)
        else:
            J, Lam, e = self._on_approaching(t, u, idx, gam)
        # a plastic impulse (e = 0, Λ > 0) leaves γ⁺ = 0 by the law: the stick monitor of a
        # contact it leaves free starts from that zero, not from the jump's round-off
        self.zeros = {("stick", int(j)): 1 for j, lam, ej in zip(J, Lam, e)
                      if lam > 0.0 and ej == 0.0}
        u = u + self.Minv @ self.system.W[:, J] @ Lam
        gp = self.system.contact_velocities(u, t)
        gm = dict(zip(idx.tolist(), gam))
        for j, lam in zip(J, Lam):
            if lam > 0.0:
                self.events.append((t, int(j), "impact", float(gm[int(j)]), float(gp[j]), float(lam)))
            self.P[k_row, j] += lam
        return u

    def _delassus(self, idx) -> np.ndarray:
        """G = W_JᵀM⁻¹W_J, the Delassus matrix of the impact laws."""
        W = self.system.W[:, idx]
        return W.T @ self.Minv @ W

    def _on_approaching(self, t, u, idx, gam):
        """The law's impulse on J = {γ⁻ ≤ 0}, growing J (e = 0) by the separating contacts it
        pushes below 0: ``(J, Λ, e)``, e the restitution each contact of J got."""
        e_all = dict(zip(idx.tolist(), self.law.restitution[idx]))
        J = [int(i) for i, g in zip(idx, gam) if g <= 0.0]
        gm = dict(zip(idx.tolist(), gam))
        for _ in range(idx.size):
            e = np.array([e_all[j] for j in J])
            Lam = self.law.definition.impact_map(self._delassus(J), np.array([gm[j] for j in J]), e,
                                                 self.solver.solve)
            gp = self.system.contact_velocities(u + self.Minv @ self.system.W[:, J] @ Lam, t)
            tol = 1e-13 * max(1.0, float(np.max(np.abs(gam))))
            pushed = [int(i) for i in idx if int(i) not in J and gp[i] < -tol]
            if not pushed:
                break
            for j in pushed:
                e_all[j] = 0.0
            J = sorted(J + pushed)
        return np.array(J), Lam, np.array([e_all[j] for j in J])

    def select_active(self, t: float, q: np.ndarray, u: np.ndarray, closed: frozenset) -> frozenset:
        """A = {i ∈ I : γ_i = 0 and λ_i > 0} from ``0 ≤ γ̇_B ⊥ λ_B ≥ 0`` over B = {i ∈ I : γ_i ≤ tol}."""
        if not closed:
            return frozenset()
        idx = np.array(sorted(closed))
        gam = self.system.contact_velocities(u, t)[idx]
        scale = max(1.0, float(np.max(np.abs(u))) * float(np.max(np.abs(self.system.W))))
        B = idx[gam <= 1e-13 * scale]
        if B.size == 0:
            return frozenset()
        md = self.mode(closed, frozenset())
        z = np.concatenate([q, u, self.exo.x(t)])
        acc_free = (md.A @ z)[self.system.n:2 * self.system.n]
        WB = self.system.W[:, B]
        b = WB.T @ acc_free + (self.exo.N2 @ self.exo.x(t))[B]
        lam = self.solver.solve(WB.T @ self.Minv @ WB, b).x
        return frozenset(int(i) for i, l in zip(B, lam) if l > 0.0)

    # -- the run ---------------------------------------------------------------------------
    def run(self, t: np.ndarray, q0: np.ndarray, u0: np.ndarray,
            schedule: list[tuple[float, list, list]]) -> tuple[np.ndarray, np.ndarray, str]:
        n, N1 = self.system.n, t.shape[0]
        Q, U = np.empty((N1, n)), np.empty((N1, n))
        self.P = np.zeros((N1, self.system.m))
        self.sigma = np.zeros((N1, self.system.m))
        Q[0], U[0] = q0, u0
        q, u, now = q0.astype(float).copy(), u0.astype(float).copy(), float(t[0])
        closed, active = frozenset(), frozenset()
        k_next = 1                                   # next grid row to fill
        status = RunStatus()
        for t_sw, on, off in schedule + [(float(t[-1]), [], [])]:
            sig = self.should_stop() if self.should_stop is not None else None
            if sig:                                  # SIGINT/SIGTERM of a streamed run
                status = _stopped(f"{sig} at t = {now:.9g}")
                break
            q, u, now, closed, active, k_next, status = self._flow_until(
                t, Q, U, q, u, now, t_sw, closed, active, k_next)
            if not status.ok:
                break
            row = min(k_next, N1 - 1) if now > t[0] else 0
            if on:
                closed = closed | frozenset(on)
                if self.jumps:
                    q = self.project(now, q, closed, row)
                u = self.collide(now, u, closed, row)
            closed = closed - frozenset(off)
            active = self.select_active(now, q, u, closed)
            if k_next < N1 and t[k_next] == now:     # a grid sample at the event instant: right limit
                Q[k_next], U[k_next] = q, u
                k_next += 1
        if status.ok and k_next < N1:
            status = _stopped(f"output rows from t = {t[k_next]} not reached")
        Q[k_next:], U[k_next:] = np.nan, np.nan      # rows a stopped run did not reach
        return Q, U, status

    def _flow_until(self, t, Q, U, q, u, now, t_stop, closed, active, k_next):
        """Exact flow from ``now`` to ``t_stop`` in the current mode, handling own events;
        fills the grid rows with t_k < t_stop (and t_k == t_stop when it is the last sample)."""
        n, N1 = self.system.n, t.shape[0]
        count_here, last_event_t = 0, None
        z = None                                     # carried between samples (exogenous part exact)
        zeros, self.zeros = self.zeros, {}          # monitor → derivatives its reset made zero
        while now < t_stop:
            md = self.mode(closed, active)
            if z is None:
                z = np.concatenate([q, u, self.exo.x(now)])
            mons = _monitors(md, closed)
            if not mons:                             # free of own events: sample to sample
                while k_next < N1 and t[k_next] < t_stop:
                    z = md.propagator(float(t[k_next]) - now) @ z
                    now = float(t[k_next])
                    z[:n] = self.hold(now, z[:n], closed)
                    Q[k_next], U[k_next] = z[:n], z[n:2 * n]
                    k_next += 1
                z = md.propagator(t_stop - now) @ z
                now = t_stop
                q, u = self.hold(now, z[:n], closed), z[n:2 * n].copy()
                break
            # next stop: next grid sample or t_stop
            nxt = min(t_stop, float(t[k_next])) if k_next < N1 else t_stop
            delta = nxt - now
            hit = None
            for mon in mons:
                s0 = _safe_start(md, mon, z, delta, zeros.get((mon.kind, mon.contact), 0))
                if s0 < 0.0:
                    return q, u, now, closed, active, k_next, _stopped(
                        f"degenerate {mon.kind} monitor of contact {mon.contact} at t = {float(now)!r}")
                if s0 >= delta:
                    continue
                try:
                    tau = _first_crossing(md, mon.row, z, delta, s0)
                except _Stalled as exc:
                    return q, u, now, closed, active, k_next, _stopped(
                        f"{exc} for the {mon.kind} monitor of contact {mon.contact} at t = {float(now)!r}")
                if tau is not None:
                    lo = self._bracket_left(md, mon.row, z, s0, tau)
                    tau = _refine(md, mon.row, z, lo, tau)
                    if hit is None or tau < hit[0]:
                        hit = (tau, mon)
            zeros = {}
            if hit is None:
                z = md.propagator(delta) @ z
                now = nxt
                z[:n] = self.hold(now, z[:n], closed)
                q, u = z[:n].copy(), z[n:2 * n].copy()
                if k_next < N1 and t[k_next] == now and now < t_stop:
                    Q[k_next], U[k_next] = q, u
                    k_next += 1
                continue
            z_event, z = z, None
            tau, mon = hit
            zb = md.propagator(tau) @ z_event
            now = now + tau
            q, u = self.hold(now, zb[:n], closed), zb[n:2 * n]
            count_here = count_here + 1 if now == last_event_t else 1
            last_event_t = now
            if count_here > MAX_EVENTS_PER_INSTANT:
                return q, u, now, closed, active, k_next, _stopped(f"mode cycle at t = {float(now)!r}")
            gam = float(self.system.contact_velocities(u, now)[mon.contact])
            if mon.kind == "stick":                 # LCP decides: held (λ > 0) or touched and free
                active = self.select_active(now, q, u, closed)
            else:
                active = active - {mon.contact}
                zeros = {("stick", mon.contact): 2}  # released: γ = 0 held, γ̇ = −Gλ = 0
            self.events.append((now, mon.contact, mon.kind, gam, gam, 0.0))
        return q, u, now, closed, active, k_next, RunStatus()

    @staticmethod
    def _bracket_left(md: Mode, row: np.ndarray, z: np.ndarray, s0: float, tau: float) -> float:
        """A point left of ``tau`` (≥ s0) where φ > 0, found by backing off geometrically."""
        step = max(tau - s0, 0.0) * 0.5
        lo = s0
        while step > 0.0:
            cand = tau - step
            if cand <= s0:
                break
            if float(row @ (md.propagator(cand) @ z)) > 0.0:
                lo = cand
                break
            step *= 0.5
        return lo


def _event_frame(rows: list[tuple]) -> pd.DataFrame:
    import pandas as pd

    df = pd.DataFrame(rows, columns=list(EVENT_COLUMNS))
    return df.astype({"time": float, "contact": int, "kind": str, "gamma_minus": float,
                      "gamma_plus": float, "impulse": float})


def _grid_chi(t: np.ndarray, intervals: list[np.ndarray]) -> np.ndarray:
    """χ on the grid: contact j closed at some instant of (t_{k−1}, t_k] (row 0: at t_0)."""
    chi = np.zeros((t.shape[0], len(intervals)), dtype=bool)
    for j, iv in enumerate(intervals):
        for tc, to in np.asarray(iv, dtype=float).reshape(-1, 2):
            k0 = int(np.searchsorted(t, tc, side="left"))        # first t_k ≥ t_close
            k1 = int(np.searchsorted(t, to, side="left"))        # first t_k ≥ t_open
            chi[k0:min(k1, t.shape[0] - 1) + 1, j] = True
            if tc == t[0]:
                chi[0, j] = True
    return chi


def _slaves(scenario, observers: Iterable) -> list[Slave]:
    """Observer names (from the scenario's ``[observer]`` state) or Slave objects, as
    :func:`observer.simulate` builds them."""
    cfg = ObserverConfig.from_table(scenario.observer, scenario.system.n, scenario.q0, scenario.u0)
    return make_slaves(cfg, list(observers))


def run_observers(master, scenario, observers: Iterable = ("jump", "nojump"), *,
                  intervals: list[np.ndarray] | None = None, coupling="scenario",
                  solver: str = "pivoting", should_stop=None) -> EventObserversResult:
    """Exact event-driven observers driven by the exact χ of an event-driven master run.

    Parameters
    ----------
    master : MasterEventResult
        From :func:`observer.event.master.run_master`: its grid ``t`` and the master's ``q``,
        ``u`` (for V) and its closed intervals ``intervals(j)`` (χ_j = 1 on them).
    scenario : Scenario
        The scenario the master ran (system, impact law, ``[observer]`` initial state).
    observers : iterable of str or Slave
        ``"jump"``/``"nojump"`` start from the scenario's ``[observer]`` state; a
        :class:`~observer.observers.Slave` brings its own name, design and initial state.
    intervals : list of ndarray (k_j, 2), optional
        χ's closed intervals per contact instead of the master's (e.g. a perturbed log).
    coupling : "scenario", None or (t_on, t_off)
        Coupling window (as :func:`observer.simulate`): the scenario's ``observer.coupling``
        (default), None (coupled over the whole run) or an explicit window.
    solver : str
        Contact solver for the impact and force LCPs (default ``"pivoting"``).
    should_stop : callable, optional
        Called between two switchings; a signal name (``"SIGINT"``) stops the coupled run
        there (status ``"stopped: SIGINT at t = …"``, the rows not reached NaN).

    Returns
    -------
    EventObserversResult
        ``frame`` (t, chi0.., NAME_q0.., NAME_u0.., V_NAME) and per observer its
        :class:`EventObserverRun` (trajectory, V, own events, status).

    Notes
    -----
    With a coupling window [t_on, t_off] (the scenario's ``observer.coupling``) each observer
    runs uncoupled before t_on, as in time-stepping: it is then a master of the same model
    (:func:`~observer.event.master.run_master` from its own state; its state must not penetrate
    at t_0). t_on must be a grid sample; t_off must reach the end of the run (else
    ``InputError("observer.coupling")``).
    """
    system = scenario.system
    slaves = _slaves(scenario, observers)
    if any(s.metric == "K" for s in slaves):
        system.require_definite_stiffness("the observer with position jumps")
    t, qm, um = master.t, master.q, master.u
    if coupling == "scenario":
        coupling = scenario.observer.get("coupling")
    k_on = _coupling_start(coupling, t)
    if intervals is None:
        intervals = [np.asarray(master.intervals(j), dtype=float).reshape(-1, 2) for j in range(system.m)]
    intervals = _check_intervals(intervals, system.m)
    schedule = switching_schedule(intervals, float(t[k_on]), float(t[-1]))
    chi = _grid_chi(t, intervals)
    chi[:k_on] = False
    out = EventObserversResult(t, chi, master_status=getattr(master, "status", None) or RunStatus())
    limit = t.size               # rows to compute: fewer once a signal stopped an observer
    for s in slaves:
        if limit == t.size:
            run = _run_one(scenario, s, t, k_on, schedule, solver, should_stop)
            if should_stop is not None and should_stop() and not run.status.ok:
                reached = np.isfinite(run.q).all(axis=1)
                if not reached.all():
                    limit = max(int(np.argmin(reached)), k_on + 1)
        else:                    # the others up to the stopped one's last row, whole
            sched = switching_schedule(intervals, float(t[k_on]), float(t[limit - 1]))
            run = _pad(_run_one(scenario, s, t[:limit], k_on, sched, solver), t.size)
        run.V = lyapunov(system, run.q, run.u, qm, um)
        out.runs[s.name] = run
    return out


def _pad(run: EventObserverRun, size: int) -> EventObserverRun:
    """``run`` on the first rows of a grid of ``size`` rows: the rows not computed NaN (q, u)
    or 0 (P, σ), as a stopped run leaves them."""
    k = run.q.shape[0]
    grow = lambda a, fill: np.vstack([a, np.full((size - k,) + a.shape[1:], fill)])  # noqa: E731
    run.q, run.u = grow(run.q, np.nan), grow(run.u, np.nan)
    run.P, run.sigma = grow(run.P, 0.0), grow(run.sigma, 0.0)
    run.V = np.full(size, np.nan)
    return run


def _coupling_start(coupling, t: np.ndarray) -> int:
    """Grid row of t_on: the observers are coupled on [t_on, t_end]; before t_on each runs
    uncoupled (its own geometric constraints: the event master from its own state)."""
    if coupling is not None:
        c = np.asarray(coupling, dtype=float)
        if c.shape != (2,) or np.any(np.isnan(c)) or c[1] < c[0]:
            raise InputError("observer.coupling", f"must be [t_on, t_off] with t_on ≤ t_off, got {coupling!r}")
    if coupling is None or coupling[0] <= t[0]:
        k_on = 0
    else:
        k_on = int(np.searchsorted(t, coupling[0]))
        if k_on >= t.size or t[k_on] != coupling[0]:
            raise InputError("observer.coupling", f"t_on = {coupling[0]} must be a sample of the output "
                             f"grid t_k = k·h (h = {t[1] - t[0]:g}) within [{t[0]}, {t[-1]}]")
    if coupling is not None and coupling[1] < t[-1]:
        raise InputError("observer.coupling", f"the event-driven observers stay coupled to the end of "
                         f"the run (t_off ≥ {t[-1]}); got t_off = {coupling[1]}")
    return k_on


def _run_one(scenario, s: Slave, t: np.ndarray, k_on: int, schedule, solver: str,
             should_stop=None) -> EventObserverRun:
    """One observer: uncoupled on [t_0, t_on] (the event master from its state), coupled after."""
    system = scenario.system
    q0, u0 = np.asarray(s.q0, float), np.asarray(s.u0, float)
    pre = None
    if k_on > 0:
        pre = _uncoupled(scenario, q0, u0, t[:k_on + 1])
        q0, u0 = pre["q"][-1], pre["u"][-1]
    integ = _ObserverIntegrator(system, scenario.law, metric_matrix(system, s.metric), get_solver(solver))
    integ.should_stop = should_stop
    Q, U, status = integ.run(t[k_on:], q0, u0, schedule)
    P, sigma, events = integ.P, integ.sigma, list(integ.events)
    if pre is not None:
        Q, U = np.vstack([pre["q"][:-1], Q]), np.vstack([pre["u"][:-1], U])
        P = np.vstack([pre["P"][:-1], P])
        P[k_on] += pre["P"][-1]
        sigma = np.vstack([np.zeros((k_on, system.m)), sigma])
        events = pre["events"] + events
        if not pre["status"].ok:
            status = _stopped(f"uncoupled phase stopped: {pre['status'].reason}")
    return EventObserverRun(s.name, s.position_jumps, Q, U, np.full(t.size, np.nan), P, sigma, events, status)


def _uncoupled(scenario, q0: np.ndarray, u0: np.ndarray, t: np.ndarray) -> dict:
    """The observer before t_on: the exact master of the same model started from its state."""
    from observer.event.master import run_master
    sc = scenario.with_overrides({"initial.q": q0.tolist(), "initial.u": u0.tolist(),
                                  "simulation.t_end": float(t[-1])})
    res = run_master(sc, t0=float(t[0]))
    k = t.size
    if res.t.size < k or not np.array_equal(res.t[:k], t):
        raise InputError("observer.coupling", "the uncoupled phase's grid does not match the master's")
    return {"q": res.q[:k], "u": res.u[:k], "P": res.P[:k],
            "events": [r[:len(EVENT_COLUMNS)] for r in res.event_rows], "status": res.status}


def metric_matrix(system: LinearSystem, metric: str | None) -> np.ndarray | None:
    """The projection metric N of a design: K (the paper's), M, the identity; None: no jumps."""
    if metric is None:
        return None
    mats = {"K": system.K, "mass": system.M, "identity": np.eye(system.n)}
    if metric not in mats:
        raise InputError("observer.metric", f"unknown projection metric {metric!r}; choose from {sorted(mats)}")
    return mats[metric]


def _check_intervals(intervals, m: int) -> list[np.ndarray]:
    if len(intervals) != m:
        raise InputError("intervals", f"needs one array of [closing, opening] rows per contact "
                         f"(m = {m}), got {len(intervals)}")
    out = []
    for j, iv in enumerate(intervals):
        a = np.asarray(iv, dtype=float)
        if a.size and (a.ndim != 2 or a.shape[1] != 2):
            raise InputError(f"intervals[{j}]", f"must have shape (k, 2), got {a.shape}")
        a = a.reshape(-1, 2)
        if np.any(np.isnan(a)) or np.any(a[:, 1] < a[:, 0]):
            raise InputError(f"intervals[{j}]", "needs closing ≤ opening (no NaN) on every row")
        if np.any(a[1:, 0] < a[:-1, 1]):
            raise InputError(f"intervals[{j}]", "intervals must be sorted and must not overlap")
        out.append(a)
    return out


def run_schedule(system: LinearSystem, law: ImpactLaw, t: np.ndarray, q0: np.ndarray, u0: np.ndarray,
                 intervals: list[np.ndarray], metric: str | None = "K",
                 solver: str = "pivoting") -> EventObserverRun:
    """One exact observer on the grid ``t`` for a given χ (closed intervals per contact).

    The building block of :func:`run_observers`, usable without a master run (e.g. χ ≡ 1).
    ``metric``: the position-jump metric ("K": the ``jump`` observer; None: ``nojump``).
    ``V`` of the returned run is NaN (there is no master to compare with).
    """
    t = np.asarray(t, dtype=float)
    integ = _ObserverIntegrator(system, law, metric_matrix(system, metric), get_solver(solver))
    schedule = switching_schedule(_check_intervals(intervals, system.m), float(t[0]), float(t[-1]))
    Q, U, status = integ.run(t, np.asarray(q0, float), np.asarray(u0, float), schedule)
    name = "nojump" if metric is None else ("jump" if metric == "K" else f"jump_{metric}")
    return EventObserverRun(name, metric is not None, Q, U, np.full(t.shape[0], np.nan),
                            integ.P, integ.sigma, list(integ.events), status)
