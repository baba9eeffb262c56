"""What the registered checks share for one scenario: settings, seeded generators, cached runs.

The run-based checks (A1, eqs. (13)-(14), eq. (17), Theorem 1) use one replayed run
(:func:`proofs_checks.runs.replay`): the scenario's master (plain unless
``simulation.master_projection``) and the observers the toolkit runs, coupled to the
master's χ over the whole run: two with position jumps (``jump_a``, ``jump_b``; only when
K ≻ 0) and two without (``nojump_a``, ``nojump_b``), ``*_a`` started from the scenario's
``[observer]`` state (the report's observers), ``*_b`` from another state. The run is
computed once, on first use.

Horizons: the run uses the scenario's h and ``t_end = min(scenario t_end, max_steps·h)``;
Theorem 1's check (:attr:`CheckContext.convergence_run`) runs to the scenario's t_end unless
that exceeds :data:`CONVERGENCE_BUDGET` (then it says the horizon it used); the Proposition 1
runs use ``min(scenario t_end, short_steps·h)`` (the h-scaling with the steps h·(16, 4, 1)).
``--t-end`` (:attr:`CheckSettings.t_end`) sets every horizon.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from observer.scenario import Scenario
from proofs_checks.assumptions import jumps_runnable
from proofs_checks.runs import Run, SlaveSpec, replay


CONVERGENCE_BUDGET = 2_000_000
"""Largest steps·(n + m) of the convergence check's own run (its memory: about 50 bytes per
value for the master and four observers); beyond, the horizon is capped and the verdict says so."""


@dataclass(frozen=True)
class CheckSettings:
    """Settings of a :func:`proofs_checks.run_checks` call.

    Attributes
    ----------
    seed : int
        Seed of every random generator (each check gets its own stream, so results do
        not depend on which other checks run).
    h, t_end : float, optional
        Step and horizon of the run-based checks (defaults: see module docstring).
    max_steps, short_steps : int
        Step budgets of the shared run and of the runs of Proposition 1 (the exact pairs,
        and the finest step of the h-scaling).
    options : dict
        Per-check keyword arguments, ``{check_name: {keyword: value}}``, passed to the
        check functions (tolerances, sample counts, ...).
    engine : str or None
        The engine of every run of the checks (:data:`observer.engines.ENGINES`, as
        :func:`observer.simulate`'s ``engine``); None: the first time-stepping engine that
        accepts the run.
    """

    seed: int = 0
    h: float | None = None
    t_end: float | None = None
    max_steps: int = 40_000
    short_steps: int = 20_000
    options: dict = field(default_factory=dict)
    engine: str | None = None


class CheckContext:
    """A scenario with its check settings, seeded generators and lazily computed runs."""

    def __init__(self, scenario: Scenario, settings: CheckSettings | None = None):
        self.scenario = scenario
        self.settings = settings or CheckSettings()
        s = self.settings
        self.h = float(s.h or scenario.h)
        self.t_end = float(s.t_end or min(scenario.t_end, s.max_steps * self.h))
        self._run: Run | None = None
        self._conv_run: Run | None = None

    @property
    def system(self):
        return self.scenario.system

    @property
    def engine(self) -> str | None:
        """The engine of the checks' runs (:attr:`CheckSettings.engine`)."""
        return self.settings.engine

    @property
    def law(self):
        return self.scenario.law

    def rng(self, name: str) -> np.random.Generator:
        """An independent generator for ``name``, seeded by (seed, crc32(name))."""
        return np.random.default_rng([self.settings.seed, zlib.crc32(name.encode())])

    def options(self, name: str) -> dict:
        return dict(self.settings.options.get(name, {}))

    # -- the shared run --------------------------------------------------------------------
    def slave_specs(self) -> list[SlaveSpec]:
        """The observers of the shared run: state a is the scenario's ``[observer]`` state (if
        it differs from the master's) or a random one, state b a second random state
        (perturbations of 2 % of the position scale, velocities scaled by the slowest natural
        frequency); each state for the design with position jumps (when K ≻ 0: ``jump_a``,
        ``jump_b``, listed first) and without (``nojump_a``, ``nojump_b``)."""
        sc, sys_ = self.scenario, self.system
        rng = self.rng("slaves")
        n = sys_.n
        jumps = jumps_runnable(sys_.K)
        q_scale = max(float(np.max(np.abs(sc.q0))), float(np.max(np.abs(sys_.nu(0.0)))), 1e-3)
        dq = 0.02 * q_scale
        omega = 1.0
        if jumps:
            omega = float(np.sqrt(max(sla.eigh(sys_.K, sys_.M, eigvals_only=True)[0], 0.0)))
        du = dq * max(omega, 1.0)
        obs = sc.observer or {}
        qa = np.asarray(obs.get("q", sc.q0), dtype=float)
        ua = np.asarray(obs.get("u", sc.u0), dtype=float)
        za, zb = rng.standard_normal((2, 2 * n))
        if np.array_equal(qa, sc.q0) and np.array_equal(ua, sc.u0):
            qa, ua = sc.q0 + dq * za[:n], sc.u0 + du * za[n:]
        qb, ub = sc.q0 + dq * zb[:n], sc.u0 + du * zb[n:]
        designs = (("jump", True), ("nojump", False)) if jumps else (("nojump", False),)
        return [SlaveSpec(f"{d}_{x}", pj, q, u) for d, pj in designs for x, q, u in (("a", qa, ua), ("b", qb, ub))]

    @property
    def run(self) -> Run:
        """The shared run (computed on first use)."""
        if self._run is None:
            self._run = replay(self.scenario, h=self.h, t_end=self.t_end, slaves=self.slave_specs(),
                               master_projection=self.scenario.master_projection, engine=self.engine)
        return self._run

    def horizon_text(self, t_end: float) -> str:
        """Where a run's horizon ``t_end`` comes from, and the option that changes it."""
        if self.settings.t_end:
            return f"--t-end {self.settings.t_end:g} (CheckSettings.t_end); the scenario's t_end = {self.scenario.t_end:g} s"
        if t_end >= self.scenario.t_end:
            return "the scenario's t_end; --t-end (CheckSettings.t_end) changes it"
        return (f"capped at {round(t_end / self.h)} steps of h = {self.h:g} by the cost budget; the scenario's "
                f"t_end = {self.scenario.t_end:g} s; --t-end (CheckSettings.t_end) sets the horizon")

    @property
    def convergence_run(self) -> Run:
        """The run of Theorem 1's check: the scenario's whole horizon unless the user set
        ``t_end`` or the run would exceed :data:`CONVERGENCE_BUDGET` values per trajectory
        (steps·(n + m)); then the longer of the budget and the shared run (said in the
        verdict, :meth:`horizon_text`)."""
        if self._conv_run is None:
            sc, s = self.scenario, self.settings
            t_end = self.t_end
            if not s.t_end:
                steps = max(s.max_steps, CONVERGENCE_BUDGET // (self.system.n + self.system.m))
                t_end = max(self.t_end, min(sc.t_end, steps * self.h))
            run = self.run if t_end == self.t_end else replay(
                sc, h=self.h, t_end=t_end, slaves=self.slave_specs(), master_projection=sc.master_projection,
                engine=self.engine)
            run.settings["horizon_source"] = self.horizon_text(float(run.t[-1]) + 0.5 * self.h)
            self._conv_run = run
        return self._conv_run

    def visited_sets(self) -> list[np.ndarray]:
        """Distinct nonempty closed sets of the master in the shared run."""
        act = self.run.master.active[1:]
        rows = np.unique(act[act.any(axis=1)], axis=0)
        return [np.flatnonzero(r) for r in rows]

    @property
    def short_t_end(self) -> float:
        """Horizon of the Proposition 1 runs: ``min(t_end, short_steps·h)``."""
        return float(self.settings.t_end or min(self.scenario.t_end, self.settings.short_steps * self.h))
