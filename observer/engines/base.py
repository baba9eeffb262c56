"""The run description every engine takes, the engine interface and the refusal it gives.

:func:`describe` builds a :class:`RunDescription` once (the scenario with its overrides, the
observers as :class:`~observer.observers.Slave` objects, the switching signal's source, the
coupling window, the closing log, the storage options); an :class:`Engine` says whether it
takes it (:meth:`Engine.accepts`: None, or a :class:`Refusal`, one line) and runs it into a
:class:`~observer.result.RunRecord` (:meth:`Engine.run`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from observer.errors import InputError
from observer.observers import ObserverConfig, Slave, make_slaves
from observer.result import RunRecord
from observer.scenario import Scenario, check_finite_energy
from observer.switching import SOURCES, read_log

INTEGRATORS = ("time-stepping", "event")
"""The integrators an engine may implement (:attr:`Engine.integrator`)."""

EXTRAS = {"chi": "an explicit switching signal χ",
          "metric": "a projection metric other than K",
          "metrics": "the observers' own projection metric matrices",
          "record_pre": "the positions before the projection (q_pre)"}
"""The optional parts of a :class:`RunDescription` (field → what it asks for), set by the
proof checks' replays (:func:`proofs_checks.runs.replay`), never by :func:`observer.simulate`;
an engine takes a run that sets one only if it lists the field in :attr:`Engine.extras`."""


class Refusal(str):
    """Why an engine does not take a run: one line (a ``str``) and the input field it is
    about (``field``: ``"engine"`` unless a single option is the cause)."""

    field: str

    def __new__(cls, reason: str, field: str = "engine") -> "Refusal":
        self = super().__new__(cls, reason)
        self.field = field
        return self


@dataclass(frozen=True)
class RunDescription:
    """One run, described once for every engine (:func:`describe` builds it from the
    keywords of :func:`observer.simulate`).

    Attributes
    ----------
    scenario : Scenario
        With the call's overrides (h, t_end, solver, θ, master projection) applied.
    integrator : {"time-stepping", "event"}
        ``"event"``: the exact event-driven integrator (:mod:`observer.event`): exact flow
        between events, impact times to round-off, Zeno resolved into persistent contact,
        the observers switched at the master's exact closing and opening times; sampled on
        t_k = k·h (``record_every`` and ``store`` are time-stepping options).
    slaves : tuple of Slave
        The observers: registered design names (:data:`~observer.observers.OBSERVER_DESIGNS`)
        start from the scenario's ``[observer]`` state, a :class:`~observer.observers.Slave`
        brings its own; ``"scenario"`` gives the designs of ``[observer] observers``.
        Each has V relative to the master in the result.
    source : {"master", "log", "self"} or None
        Source of χ (default: the scenario's ``observer.source``, else "master").
    coupling : (t_on, t_off) or None
        The coupling window (default: the scenario's; None: the whole run).
    log : str or Path or None
        The closing log for ``source="log"`` (default: the scenario's ``observer.log``), read
        into ``log_frame``.
    log_frame : DataFrame or None
    residual_tol : float
        Largest complementarity residual a step may leave (above it the run stops).
    record_every : int or None
        Keep every k-th step (row r = step r·k); None: 1, or about 10 000 rows with
        ``store="summary"`` (fewer for a large system: at most 2²⁴ state values,
        :func:`observer.engines.timestepping.summary_record_every`). The per-step decrements of V need every step (else None).
    store : {"full", "summary"}
        ``"summary"`` (compiled engine): V of each observer, its damping/impulse/remaining
        parts, first-passage and settling times, the master's closings and deepest
        penetration computed in the kernel over every step, the trajectories kept only at
        the recorded rows (``result.summary``, a DataFrame built on first read).
    on_chunk : callable or None
        Time-stepping: called with each :class:`observer.engines.loop.Chunk` of finished rows (e.g.
        an :class:`observer.stream.ChunkWriter`). While it is set SIGINT/SIGTERM stop the run
        (time-stepping: after the current window; event: between events or switchings) and
        the result's status says where (``metadata["stopped"]``); the event engine passes no
        chunk (its rows are written whole at the end).
    chi : ndarray of bool, shape (N, m), or None
        χ_k given explicitly (row k = step k), instead of the master's closed set or a log
        (an extra, :data:`EXTRAS`).
    metric : ndarray (n, n) or None
        Projection metric N of the position jumps of every system without its own (None: K;
        an extra).
    metrics : tuple of (ndarray (n, n) or None) or None
        Per observer (in the order of ``slaves``), its own projection metric N, overriding
        its design's (an extra).
    record_pre : bool
        Keep the positions before each step's projection, :attr:`RunRecord.q_pre
        <observer.result.RunRecord.q_pre>` (an extra).
    t0 : float
        The time origin: the scenario's initial state is taken at t0 and the grid is
        t_k = t0 + k·h up to t_end (forcing and gap offsets are evaluated at the absolute time).
        Only an engine with :attr:`Engine.time_origin` takes t0 ≠ 0.
    """

    scenario: Scenario
    integrator: str
    slaves: tuple = ()
    source: str | None = None
    coupling: tuple | None = None
    log: Any = None
    log_frame: Any = None
    residual_tol: float = 1e-9
    record_every: int | None = None
    store: str = "full"
    on_chunk: Callable | None = None
    chi: Any = None
    metric: Any = None
    metrics: tuple | None = None
    record_pre: bool = False
    t0: float = 0.0


class Engine:
    """An engine: a name, the integrator it implements, what it accepts, how it runs.

    Subclasses set :attr:`name`, :attr:`integrator`, :attr:`description` and :attr:`extras`
    and implement :meth:`refuses` (only what is particular to them) and :meth:`run`. Adding an
    engine is one module with such a class plus one entry of :data:`observer.engines.ENGINES`.
    """

    name: str = ""
    integrator: str = "time-stepping"
    description: str = ""
    extras: frozenset = frozenset()
    """The fields of :data:`EXTRAS` this engine honours (a run setting another is refused,
    naming the field)."""
    time_origin: bool = False
    """True if the engine starts a run at :attr:`RunDescription.t0` (else it refuses t0 ≠ 0)."""

    def accepts(self, run: RunDescription) -> Refusal | None:
        """None when this engine takes ``run``, else why not (one line)."""
        if run.integrator != self.integrator:
            return Refusal(f"the {self.name} engine integrates by {self.integrator}, not "
                           f"integrator={run.integrator!r}")
        for extra, what in EXTRAS.items():
            value = getattr(run, extra)
            if value is not None and value is not False and extra not in self.extras:
                return Refusal(f"the {self.name} engine does not provide {what}", extra)
        if run.t0 != 0.0 and not self.time_origin:
            return Refusal(f"the {self.name} engine starts at t = 0 (got t0 = {run.t0!r}): "
                           "use integrator=\"event\"", "t0")
        return self.refuses(run)

    def refuses(self, run: RunDescription) -> Refusal | None:
        """The engine's own conditions (after the integrator matched): None or a refusal."""
        return None

    def run(self, run: RunDescription) -> RunRecord:
        """Run ``run`` (which :meth:`accepts` took) into a :class:`RunRecord`."""
        raise NotImplementedError(f"engine {self.name!r} does not implement run()")


def describe(sc: Scenario, integrator: str, observers, source, coupling, log, residual_tol: float,
             record_every: int | None, store: str, on_chunk) -> RunDescription:
    """The :class:`RunDescription` of a :func:`observer.simulate` call (arguments checked
    already by :func:`observer.simulate.check_arguments`): the observers resolved into
    slaves from the scenario's ``[observer]`` table, source, coupling and log defaulted from
    it, the closing log read.

    Raises
    ------
    InputError
        An unknown design or source, a missing log, an observer's non-finite energy.
    """
    check_initial_state(sc)
    if isinstance(observers, str):
        observers = scenario_observers(sc) if observers == "scenario" else [observers]
    slaves: list[Slave] = []
    if observers:
        system = sc.system
        base_dir = str(Path(sc.source).parent) if sc.source.endswith(".toml") else None
        cfg = ObserverConfig.from_table(sc.observer, system.n, sc.q0, sc.u0, base_dir)
        slaves = make_slaves(cfg, list(observers))
        for s in slaves:
            check_finite_energy("observer", system, s.q0, s.u0)
        source = source or cfg.source
        coupling = cfg.coupling if coupling == "scenario" else coupling
        log = cfg.log if log is None else log      # (a DataFrame has no truth value)
        for s in slaves:
            if s.position_jumps and s.metric == "K":
                system.require_definite_stiffness(f"the observer {s.name!r} (position jumps in the K metric)")
        if sc.model is not None:
            sc.model.require_projection(slaves)
    if source is not None and source not in SOURCES:
        raise InputError("observer.source", f"must be one of {list(SOURCES)}, got {source!r}")
    log_frame = None
    if slaves and source == "log":
        if log is None:
            raise InputError("observer.log", "source = \"log\" needs a log file")
        log_frame = read_log(log, sc.system.m)
        if not isinstance(log, (str, Path)):          # a DataFrame: the metadata says so
            log = f"DataFrame ({len(log_frame)} intervals)"
    return RunDescription(sc, integrator, tuple(slaves), source,
                          None if coupling == "scenario" else coupling, log, log_frame,
                          residual_tol, record_every, store, on_chunk)


def check_initial_state(sc: Scenario) -> None:
    """The master's initial state as the run finds it: a loaded scenario's ``q0``/``u0`` are
    plain arrays a user can edit after loading (``sc.q0[0] = nan``), so they are checked again
    when the run starts — n finite entries each and a finite energy — with an
    :class:`InputError` naming ``initial.q`` or ``initial.u``, never a NaN first row."""
    from observer.validation import as_array

    for name, value in (("initial.q", sc.q0), ("initial.u", sc.u0)):
        as_array(name, value, (sc.system.n,))
    check_finite_energy("initial", sc.system, np.asarray(sc.q0, float), np.asarray(sc.u0, float))


def scenario_observers(sc: Scenario) -> list[str]:
    """The observer designs a scenario asks for: its ``[observer] observers`` (the paper's two
    designs when the table leaves the key out), none without an ``[observer]`` table."""
    if not sc.observer:
        return []
    return list(ObserverConfig.from_table(sc.observer, sc.system.n, sc.q0, sc.u0).observers)
