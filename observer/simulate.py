"""The façade: load a scenario, describe the run once, hand it to an engine, return a result.

The engines and what each accepts are :mod:`observer.engines`; every engine returns a
:class:`~observer.result.RunRecord`, which becomes the public
:class:`~observer.result.SimulationResult` in one place
(:meth:`~observer.result.SimulationResult.from_record`).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Iterable

from observer.engines import ENGINES, INTEGRATORS, choose, describe
from observer.engines.base import scenario_observers  # noqa: F401  (re-exported)
from observer.engines.timestepping import result_events, stepping_events  # noqa: F401  (re-exported)
from observer.errors import InputError, is_numerical_failure
from observer.loop import check_record_every
from observer.observers import Slave, check_coupling, make_slaves  # noqa: F401  (make_slaves re-exported)
from observer.result import SimulationResult
from observer.scenario import (Scenario, check_finite_energy,  # noqa: F401  (re-exported:
                               load_scenario)                  # observer.load_scenario)
from observer.validation import MAX_STEPS, as_scalar


def _numerical_failures_refused(func):
    """``func`` (:func:`simulate`) with a numerical library's own exception
    (:func:`~observer.errors.is_numerical_failure`: a ``LinAlgError``, a numba error, an
    overflow) raised as an :class:`InputError` naming ``scenario`` (the library's exception
    chained as its cause), so that no NumPy, SciPy or numba exception reaches an API user."""
    @functools.wraps(func)
    def wrapper(scenario, *args, **kwargs):
        try:
            return func(scenario, *args, **kwargs)
        except InputError:
            raise
        except Exception as exc:        # noqa: BLE001  (re-raised unless a library's failure)
            if not is_numerical_failure(exc):
                raise
            name = scenario.name if isinstance(scenario, Scenario) else str(scenario)
            raise InputError("scenario", f"{name}: the computation failed ({type(exc).__name__}: "
                             f"{exc}); please report this input") from exc
    return wrapper


@_numerical_failures_refused
def simulate(scenario: str | Path | Scenario, h: float | None = None, t_end: float | None = None, *,
             solver: str | None = None, theta: float | None = None,
             master_projection: bool | None = None,
             observers: Iterable[str | Slave] | str = (), source: str | None = None,
             coupling: tuple[float, float] | None | str = "scenario",
             log: str | Path | None = None, residual_tol: float = 1e-9,
             engine: str | None = None, record_every: int | None = None,
             store: str = "full", integrator: str | None = None,
             on_chunk=None) -> SimulationResult:
    """Simulate the master (and the observers) of ``scenario`` on an engine of
    :data:`observer.engines.ENGINES` (default: Moreau–Jean on the compiled kernel).

    Parameters
    ----------
    scenario : str, Path or Scenario
        Built-in name, TOML path or a loaded :class:`Scenario`.
    h, t_end, solver, theta, master_projection
        Override the scenario's settings.
    observers : iterable of str or Slave, or "scenario"
        Registered design names (:data:`~observer.observers.OBSERVER_DESIGNS`) start from the
        scenario's ``[observer]`` state; a :class:`~observer.observers.Slave` gives its own
        name, design and state; ``"scenario"`` runs the designs the scenario's
        ``[observer] observers`` lists (none when it has no ``[observer]`` table). Default:
        none (the master alone).
    source : {"master", "log", "self"}, optional
        Switching signal (default: the scenario's ``observer.source``, else "master").
    coupling : (t_on, t_off) or None
        Coupling window (default: the scenario's; None couples over the whole run).
    log : path, optional
        Closing log for ``source="log"`` (default: the scenario's ``observer.log``).
    engine : str, optional
        A registered engine (:data:`observer.engines.ENGINES`): ``"compiled"`` (the numba
        kernel), ``"python"`` (the readable numpy reference; both give the same trajectories
        to round-off) or ``"event"``. Default: the first engine of ``integrator`` that accepts
        the run, so the compiled one unless it lacks the run's contact solver (it has block
        pivoting only) or impact law; then the python engine runs it and
        ``metadata["engine_note"]`` says why. An engine asked for by name that cannot take the
        run raises :class:`InputError` naming ``engine``, with its reason.
    record_every : int, optional
        Keep every k-th step (row r = step r·k); default 1, or about 10 000 rows with
        ``store="summary"``. The per-step decrements of V need every step and are left out
        (None) otherwise.
    store : {"full", "summary"}
        ``"summary"`` (compiled engine) computes in the kernel, streaming over every step,
        V of each observer, its damping/impulse/remaining parts, first-passage and settling
        times, the master's closings per contact and its deepest penetration, and keeps the
        trajectories only at the recorded rows: memory independent of the horizon beyond
        that (``result.summary``, a DataFrame built on first read: the run itself does not
        import pandas).

    on_chunk : callable, optional
        Time-stepping: called with each :class:`observer.loop.Chunk` of finished rows as the
        loop produces them (e.g. an :class:`observer.stream.ChunkWriter`); while it is set,
        SIGINT/SIGTERM stop the run after the current window and the result's status says
        where (``metadata["stopped"]``). ``integrator="event"`` passes no chunk (its rows are
        written whole at the end, :meth:`~observer.stream.ChunkWriter.finish`), but with
        ``on_chunk`` set a signal stops it likewise, with the rows finished up to there.
    integrator : {"time-stepping", "event"}, optional
        Default: the requested engine's, else ``"time-stepping"``. ``"event"``: the exact
        event-driven integrator (:mod:`observer.event`): exact flow between events, impact
        times to round-off, Zeno resolved into persistent contact; the observers switch at the
        master's exact closing and opening times. The result is sampled on the grid
        t_k = k·h; ``solver`` (other than pivoting), ``record_every`` and ``store`` are
        time-stepping options and are refused.

    Returns
    -------
    SimulationResult
        With one :class:`~observer.result.SlaveTrajectory` per observer (V relative to the
        master), the switching signal ``chi`` and ``events`` (time-stepping: the master's
        closing and opening steps, an approximation of the event table).
    """
    requested = ENGINES.get(engine) if isinstance(engine, str) else None
    if integrator is None:
        integrator = requested.integrator if requested is not None else "time-stepping"
    coupling, residual_tol, observers = check_arguments(integrator, coupling, residual_tol,
                                                        record_every, observers, on_chunk)
    for name, value in (("h", h), ("t_end", t_end), ("theta", theta)):
        if value is not None:       # a number, as in the TOML document (a string is refused)
            as_scalar(f"simulation.{name}", value)
    sc = load_scenario(scenario)
    overrides = {k: v for k, v in (("simulation.h", h), ("simulation.t_end", t_end),
                                   ("simulation.solver", solver), ("simulation.theta", theta),
                                   ("simulation.master_projection", master_projection))
                 if v is not None}
    if overrides:
        sc = sc.with_overrides(overrides)
    run = describe(sc, integrator, observers, source, coupling, log, residual_tol, record_every,
                   store, on_chunk)
    chosen, note = choose(run, engine)
    record = chosen.run(run)
    if note:
        record.metadata["engine_note"] = note
    return SimulationResult.from_record(record, sc.system)


def check_arguments(integrator, coupling, residual_tol, record_every, observers,
                    on_chunk) -> tuple:
    """Validate the keywords of :func:`simulate` that do not come from the scenario document
    (the others are validated with the document, with the TOML path's messages); return
    ``(coupling, residual_tol, observers)`` normalized (a window as a tuple of floats,
    an iterable of observers as a list).

    Raises
    ------
    InputError
        Naming the keyword (``observer.coupling`` for the window, as the TOML path does).
    """
    if not isinstance(integrator, str) or integrator not in INTEGRATORS:
        raise InputError("integrator", f"must be one of {list(INTEGRATORS)}, got {integrator!r}")
    if coupling not in ("scenario", None):
        coupling = check_coupling(coupling)
    residual_tol = as_scalar("residual_tol", residual_tol, positive=True)
    if record_every is not None:
        check_record_every(record_every)
        if record_every > MAX_STEPS:
            raise InputError("record_every", f"must be at most 2^53 (a grid counts no more steps), "
                             f"got {record_every!r}")
    if not isinstance(observers, str):
        try:
            observers = list(observers)
        except TypeError:
            raise InputError("observer.observers", f"must be design names or Slave objects, got "
                             f"{observers!r}") from None
        for ob in observers:
            if not isinstance(ob, (str, Slave)):
                raise InputError("observer.observers", f"must be design names or Slave objects, "
                                 f"got {ob!r}")
    if on_chunk is not None and not callable(on_chunk):
        raise InputError("on_chunk", f"must be callable (or None), got {on_chunk!r}")
    return coupling, residual_tol, observers
