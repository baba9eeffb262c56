"""Simulated runs for the run-based checks, through the engine registry.

:func:`replay` describes the run once (:class:`observer.engines.RunDescription`: the master
and every observer coupled to χ over the whole run) and hands it to an engine of
:data:`observer.engines.ENGINES` — the one named, or the first that accepts it, as
:func:`observer.simulate` does — which returns a :class:`~observer.result.RunRecord`. The
description sets the extras the checks need (:data:`observer.engines.base.EXTRAS`):
``record_pre`` (the positions before the step's projection, ``RunRecord.q_pre``), and when
asked an explicit χ and a swappable projection ``metric``; an engine that cannot provide one
refuses the run by that field's name. With the same settings and engine a replay is
therefore bitwise identical to :func:`observer.simulate` (a test asserts it). With ``metric``
set, the position jumps use the given metric N instead of K::

    q⁺ = q⁻ − N⁻¹W_I (W_Iᵀ N⁻¹ W_I)⁻¹ g_I(q⁻, t_{k+1})

which is how the tests build the known-bad "wrong projection metric" integrator
(N = identity: the Euclidean projection, paper section 1: "non-energy consistent").

Arrays are time-major, row 0 the initial state and row k+1 the step t_k → t_{k+1}.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from observer.engines import RunDescription, choose
from observer.model import LinearSystem
from observer.observers import Slave, lyapunov
from observer.scenario import Scenario
from observer.stepping import MoreauJean

Projector = Callable[[int, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class SlaveSpec:
    """An observer of the replay: name, design (position jumps or not), initial state and its
    own projection metric N (None: the replay's ``metric``, by default K)."""

    name: str
    position_jumps: bool
    q0: np.ndarray
    u0: np.ndarray
    metric: np.ndarray | None = None


@dataclass
class Trajectory:
    """One system of a replay.

    Attributes
    ----------
    q : ndarray, shape (N+1, n)
        Positions after the step's projection (the state).
    q_pre : ndarray, shape (N+1, n)
        Positions before the projection (``q_pre[k+1] = q_k + h[(1−θ)u_k + θu_{k+1}]``);
        equal to ``q`` for steps without projection.
    u : ndarray, shape (N+1, n)
    P : ndarray, shape (N+1, m)
        Impulse of step k in row k+1 (zero on open contacts).
    sigma : ndarray, shape (N+1, m)
        Multiplier Σ returned by the projector (zero where nothing was projected).
    active : ndarray of bool, shape (N+1, m)
        Closed set used by the step (row k+1).
    projected : bool
        Whether position projections were applied.
    """

    name: str
    q: np.ndarray
    q_pre: np.ndarray
    u: np.ndarray
    P: np.ndarray
    sigma: np.ndarray
    active: np.ndarray
    projected: bool

    def as_dict(self) -> dict:
        """The dict expected by :func:`observer.observers.lyapunov_decrements`."""
        return {"q": self.q, "u": self.u, "P": self.P, "sigma": self.sigma}


@dataclass
class Run:
    """A replayed master run with observers driven by the master's closed set χ.

    ``g_pred[k+1]`` is the master's predicted gap ``g_k + (h/2)γ_k`` that decided its
    closed set of step k (Siconos rule, ``χ = g_pred ≤ 0``); ``chi[k+1]`` is the closed
    set fed to the observers in step k (the master's, unless overridden).
    """

    system: LinearSystem
    stepper: MoreauJean
    t: np.ndarray
    master: Trajectory
    slaves: dict[str, Trajectory]
    chi: np.ndarray
    g_pred: np.ndarray
    metric: str = "K (library projection)"
    settings: dict = field(default_factory=dict)
    scenario: Scenario | None = None
    """The scenario of the replay (with ``settings["metric"]`` and ``settings["system"]``
    it lets a check re-run the same case at other step sizes, :func:`rerun`)."""
    slave_metrics: dict = field(default_factory=dict)
    """Observer name → its own projection metric N (only observers that have one)."""

    @property
    def h(self) -> float:
        return self.stepper.h

    @property
    def theta(self) -> float:
        return self.stepper.theta


def make_projector(stepper: MoreauJean, metric: np.ndarray | Projector | None) -> tuple[Projector, str]:
    """Projector ``(k, q, active) -> (q⁺, Σ)`` onto ``{g_I(q, t_k) = 0}`` and its description.

    ``None`` is the library's K-metric projection (eqs. (13)-(14)); an (n, n) matrix N is
    the N-metric projection (``N = K`` reproduces the library up to round-off; ``N = I`` is
    the known-bad Euclidean projection); a callable is used as is.
    """
    if metric is None:
        return stepper.project, "K (library projection)"
    if callable(metric):
        return metric, getattr(metric, "__name__", "custom projector")
    N = np.asarray(metric, dtype=float)
    W, nu = stepper.system.W, stepper.grid.nu

    def project(k: int, q: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if active.size == 0:
            return q, np.zeros(0)
        W_I = W[:, active]
        NinvW = np.linalg.solve(N, W_I)
        L_N = W_I.T @ NinvW
        g = q @ W_I + nu[k, active]
        sigma = -np.linalg.solve(L_N, g)
        return q + NinvW @ sigma, sigma

    if np.array_equal(N, stepper.system.K):
        desc = "K (explicit matrix)"
    elif np.array_equal(N, np.eye(N.shape[0])):
        desc = "identity (Euclidean)"
    else:
        desc = "custom matrix"
    return project, desc


def replay(scenario: Scenario, *, h: float | None = None, t_end: float | None = None,
           slaves: tuple[SlaveSpec, ...] | list[SlaveSpec] = (), master_projection: bool = False,
           metric: np.ndarray | None = None, system: LinearSystem | None = None,
           chi: np.ndarray | None = None, engine: str | None = None) -> Run:
    """Simulate the master and observers coupled over the whole run, recording everything.

    Parameters
    ----------
    scenario : Scenario
        Supplies the system, impact law, master initial state, h, θ and solver.
    h, t_end : float, optional
        Override the scenario's step and horizon.
    slaves : sequence of SlaveSpec
        Observers; all are driven by the same χ (the master's closed set, or ``chi``).
    master_projection : bool
        Project the master on its own closed set (the "projected master").
    metric : ndarray or None
        Projection metric N of the position jumps (None: K, the library's projection).
    system : LinearSystem, optional
        Replace the scenario's system (e.g. a known-bad one built with ``check=False``).
    chi : ndarray of bool, shape (N+1, m), optional
        Switching signal for the observers (row k+1 = step k) instead of the master's.
    engine : str, optional
        An engine of :data:`observer.engines.ENGINES`; default: the first time-stepping engine
        that accepts the run (:func:`observer.engines.choose`, as :func:`observer.simulate`).

    Returns
    -------
    Run

    Raises
    ------
    InputError
        An engine (named, or every candidate) that cannot take the run, naming the field it
        lacks (e.g. ``record_pre``: the positions before projection every check reads).
    """
    system = system or scenario.system
    sc = dataclasses.replace(scenario, system=system, h=float(h or scenario.h),
                             t_end=float(t_end or scenario.t_end), master_projection=bool(master_projection))
    stepper = MoreauJean(system, sc.law, sc.h, sc.t_end, sc.theta, solver=sc.solver)
    steps, m = stepper.steps, system.m
    slaves = list(slaves)
    if callable(metric):
        raise ValueError("replay takes a metric matrix N (or None for K), not a callable")
    desc = _metric_description(stepper, metric)
    if chi is not None:
        chi = np.asarray(chi, dtype=bool)
        if chi.shape != (steps + 1, m):
            raise ValueError(f"chi has shape {chi.shape}, expected {(steps + 1, m)}")
    run = RunDescription(sc, "time-stepping", tuple(Slave(s.name, s.position_jumps, np.asarray(s.q0, float),
                                                          np.asarray(s.u0, float)) for s in slaves),
                         "master", None, chi=None if chi is None else chi[1:],
                         metric=None if metric is None else np.asarray(metric, dtype=float),
                         metrics=tuple(s.metric for s in slaves) if any(s.metric is not None for s in slaves)
                         else None, record_pre=True)
    chosen, _ = choose(run, engine)
    rec = chosen.run(run)
    t = rec.t

    def trajectory(i: int, name: str, projected: bool, active: np.ndarray) -> Trajectory:
        tr = rec.slaves[name] if i else rec
        return Trajectory(name, tr.q, rec.q_pre[i], tr.u, tr.P, tr.sigma, active, projected)

    master = trajectory(0, "master", master_projection, rec.active)
    chi_rec = rec.chi if slaves else (rec.active.copy() if chi is None else chi)
    subs = [trajectory(i, s.name, s.position_jumps, chi_rec) for i, s in enumerate(slaves, start=1)]
    g_pred = np.zeros((t.size, m))
    g_pred[1:] = ((rec.q[:-1] + 0.5 * stepper.h * rec.u[:-1]) @ system.W + system.nu(t[:-1])
                  + 0.5 * stepper.h * system.nu_dot(t[:-1]))
    return Run(system, stepper, t, master, {tr.name: tr for tr in subs}, chi_rec, g_pred, desc,
               {"h": stepper.h, "t_end": float(t[-1]), "theta": stepper.theta,
                "master_projection": master_projection, "metric": metric, "system": system,
                "chi_override": chi is not None, "engine": rec.engine}, scenario,
               {s.name: s.metric for s in slaves if s.metric is not None})


def _metric_description(stepper: MoreauJean, metric) -> str:
    if metric is None:
        return "K (library projection)"
    N = np.asarray(metric, dtype=float)
    if np.array_equal(N, stepper.system.K):
        return "K (explicit matrix)"
    if np.array_equal(N, np.eye(N.shape[0])):
        return "identity (Euclidean)"
    return "custom matrix"


def slave_specs_of(run: Run) -> list[SlaveSpec]:
    """The observers of a run as :class:`SlaveSpec` (initial states and designs)."""
    return [SlaveSpec(name, tr.projected, tr.q[0].copy(), tr.u[0].copy(), run.slave_metrics.get(name))
            for name, tr in run.slaves.items()]


def rerun(run: Run, h: float) -> Run:
    """The same case as ``run`` (scenario, system, metric, observers, horizon, engine) at step ``h``.

    Raises ValueError when the run used an explicit χ (it lives on the run's own grid).
    """
    st = run.settings
    if run.scenario is None or st.get("chi_override"):
        raise ValueError("the run cannot be repeated at another step (no scenario, or an explicit χ)")
    return replay(run.scenario, h=h, t_end=st["t_end"], slaves=slave_specs_of(run),
                  master_projection=st["master_projection"], metric=st["metric"], system=st["system"],
                  engine=st["engine"])


def lyapunov_pair(system: LinearSystem, a: Trajectory, b: Trajectory, pre: bool = False) -> np.ndarray:
    """V = ½vᵀMv + ½eᵀKe between two trajectories (paper (16) with the ½ on both terms;
    docs/theory/index.md §2 erratum 2); with ``pre`` the position error uses the pre-projection states."""
    qa, qb = (a.q_pre, b.q_pre) if pre else (a.q, b.q)
    return lyapunov(system, qa, a.u, qb, b.u)
