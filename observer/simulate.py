"""The façade: load a scenario, describe the run once, hand it to an engine, return a result.

The engines and what each accepts are :mod:`observer.engines`; every engine returns a
:class:`~observer.result.RunRecord`, which becomes the public
:class:`~observer.result.SimulationResult` in one place
(:meth:`~observer.result.SimulationResult.from_record`).
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Iterable

from observer.engines import ENGINES, INTEGRATORS, choose, describe
from observer.engines.base import scenario_observers  # noqa: F401  (re-exported)
from observer.engines.timestepping import result_events, stepping_events  # noqa: F401  (re-exported)
from observer.errors import InputError, is_numerical_failure, user_callback
from observer.engines.loop import check_record_every
from observer.plant_model import with_model
from observer.observers import Slave, check_coupling, make_slaves  # noqa: F401  (make_slaves re-exported)
from observer.result import SimulationResult
from observer.scenario import (Scenario, check_finite_energy,  # noqa: F401  (re-exported:
                               load_scenario)                  # observer.load_scenario)
from observer.sensor import Sensor
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
             solver: str | None = None, theta: float | None = None, master_projection: bool | None = None,
             observers: Iterable[str | Slave] | str = (), source: str | None = None,
             coupling: tuple[float, float] | None | str = "scenario", log: str | Path | None = None,
             residual_tol: float = 1e-9, engine: str | None = None, record_every: int | None = None,
             store: str = "full", integrator: str | None = None, on_chunk=None,
             t0: float = 0.0, sensor: dict | None = None, model: dict | None = None) -> SimulationResult:
    """Simulate the master and the observers of ``scenario`` on a registered engine.

    Parameters
    ----------
    scenario : str, Path or Scenario
        Built-in name, TOML path or a loaded :class:`Scenario`.
    h, t_end, solver, theta, master_projection : optional
        Override the scenario's settings.
    observers, source, coupling, log, residual_tol, record_every, store, on_chunk : optional
        The run's observers and their χ, its tolerance, the rows it keeps and who receives
        them: see :class:`observer.engines.base.RunDescription` (defaults from the scenario).
    engine, integrator : str, optional
        An engine of :data:`observer.engines.ENGINES` (compiled, python, event) and
        ``"time-stepping"`` or ``"event"``. Default: the first engine of the integrator that
        accepts the run (compiled; else python, and ``metadata["engine_note"]`` says why). An
        engine asked for that cannot take the run raises :class:`InputError` naming ``engine``.
    t0 : float, optional
        The time origin (default 0): the initial state is taken at t0, the grid is
        t_k = t0 + k·h up to t_end, forcing and gap offsets at the absolute time; a time shift
        is this keyword, not a launch delay. Only the event integrator takes t0 ≠ 0.
    sensor : dict, optional
        The observers' χ from a contact sensor (:mod:`observer.sensor`), the keys of the
        ``[observer.sensor]`` table; given, it replaces the scenario's table. A sensor that is
        not ideal drives the observers by the log it sees (:func:`sensed_scenario`) and
        ``metadata["sensor"]`` records its settings.
    model : dict, optional
        The observers' own model, the ``[observer.model]`` table (:mod:`observer.plant_model`:
        M, C, K, W in full or as ``{"scale": ...}``, ``{"factors": ...}``,
        ``{"relative_std": ..., "seed": ...}``; forcing, gap, impact, error_metric), replacing
        the scenario's. The master is the plant; V is measured against it. None: the
        scenario's table, if any.

    Returns
    -------
    SimulationResult
        Built from the engine's :class:`~observer.result.RunRecord`.
    """
    integrator, coupling, residual_tol, observers = check_arguments(
        engine, integrator, coupling, residual_tol, record_every, observers, on_chunk)
    sc = with_model(_scenario(scenario, h=h, t_end=t_end, solver=solver, theta=theta,
                              master_projection=master_projection), model)
    sensed = None
    if observers and (observers != "scenario" or sc.observer):
        sc, sensed = sensed_scenario(sc, sensor, integrator, source, log, engine)
        if sensed is not None:
            source, log = "log", sc.observer["log"]
    elif sensor is not None:
        Sensor.from_table(sensor)                   # checked, though no observer reads χ
    run = describe(sc, integrator, observers, source, coupling, log, residual_tol, record_every,
                   store, None if on_chunk is None else user_callback("on_chunk", on_chunk))
    t0 = as_scalar("t0", t0)
    if t0 != 0.0:
        if not t0 <= sc.t_end:
            raise InputError("t0", f"must be at most t_end = {sc.t_end!r}, got {t0!r}")
        run = dataclasses.replace(run, t0=t0)
    chosen, note = choose(run, engine)
    record = chosen.run(run)
    if note:
        record.metadata["engine_note"] = note
    if sensed is not None:
        record.metadata["sensor"] = sensed
        record.metadata["log"] = sensed["log"]
    return SimulationResult.from_record(record, sc.system)


def sensed_scenario(sc: Scenario, sensor: dict | None, integrator: str = "time-stepping",
                    source: str | None = None, log=None, engine: str | None = None) -> tuple[Scenario, dict | None]:
    """``sc`` with its observers driven by what a contact sensor sees (:mod:`observer.sensor`).

    The sensor is ``sensor`` (the ``[observer.sensor]`` keys; None: the scenario's table). An
    ideal one (or none) gives ``sc`` back without the table. Else, with χ from the master
    (``source``, default the scenario's: ``"master"``), the plant is run alone (time-stepping,
    every step kept), its gaps give the seen-closed steps and the sensor's other parts the
    log (:func:`observer.sensor.sensed_master_log`); with ``source = "log"`` the measured
    log passes through the sensor's timing, missed and false parts
    (:func:`observer.sensor.sense_log`). The scenario returned reads that log
    (``observer.source = "log"``, ``observer.log`` the DataFrame).

    Returns
    -------
    (Scenario, dict or None)
        The scenario, and the sensor's settings with ``applied_to`` (``"master"`` or
        ``"log"``), ``log`` (the measured log's path, or ``"sensor"``) and ``intervals`` (rows
        of the log seen); None for the ideal sensor.

    Raises
    ------
    InputError
        Naming ``observer.sensor.FIELD`` for a bad setting; ``observer.sensor`` for χ that no
        sensor can act on (self-driven observers) or a master run by the event integrator;
        ``observer.sensor.threshold`` for δ > 0 with a measured log (no gap is known).
    """
    from observer.observers import ObserverConfig
    from observer.sensor import FIELD, sense_log, sensed_master_log
    from observer.switching import read_log

    table = sc.observer.get("sensor") if sensor is None else sensor
    spec = Sensor.from_table(table)
    plain = dataclasses.replace(sc, observer={k: v for k, v in sc.observer.items() if k != "sensor"})
    if spec.ideal:
        return plain, None
    base_dir = str(Path(sc.source).parent) if sc.source.endswith(".toml") else None
    given = {"source": source} if source else {}
    if log is not None:
        given["log"] = log
    cfg = ObserverConfig.from_table({**plain.observer, **given}, sc.system.n, sc.q0, sc.u0, base_dir)
    if cfg.source == "self":
        raise InputError(FIELD, "the observers are self-driven (source = \"self\"): they read no χ, "
                         "so a sensor has nothing to act on")
    if cfg.source == "log":
        if spec.threshold > 0.0:
            raise InputError(f"{FIELD}.threshold", "a measured log (source = \"log\") has no gap to "
                             "compare with a threshold: only latency, sampling_period, jitter, missed "
                             "and false_rate apply to it")
        path = cfg.log
        seen = sense_log(read_log(path, sc.system.m), spec, m=sc.system.m, t_end=sc.t_end, h=sc.h)
        label = str(path) if isinstance(path, (str, Path)) else f"DataFrame ({len(path)} rows)"
    else:
        if integrator != "time-stepping":
            raise InputError(FIELD, "χ from a sensor on the master's gaps needs the time-stepping "
                             "integrator (the gaps are read on its grid); with integrator = \"event\" "
                             "a sensor applies to a measured log only (source = \"log\")")
        res = simulate(plain, observers=(), store="full", engine=engine)
        seen = sensed_master_log(res.t, res.q, res.u, res.active, sc.system, sc.h, spec)
        label = "sensor"
    meta = {**spec.to_dict(), "applied_to": cfg.source, "log": label, "intervals": int(len(seen))}
    return dataclasses.replace(plain, observer={**plain.observer, "source": "log", "log": seen}), meta


def _scenario(scenario: str | Path | Scenario, **settings) -> Scenario:
    """``scenario`` loaded with the :func:`simulate` keywords that override its ``[simulation]``
    settings (h, t_end and θ must be numbers, as in the TOML document: a string is refused)."""
    for name in ("h", "t_end", "theta"):
        if settings[name] is not None:
            as_scalar(f"simulation.{name}", settings[name])
    sc = load_scenario(scenario)
    overrides = {f"simulation.{k}": v for k, v in settings.items() if v is not None}
    return sc.with_overrides(overrides) if overrides else sc


def check_arguments(engine, integrator, coupling, residual_tol, record_every, observers,
                    on_chunk) -> tuple:
    """Validate the keywords of :func:`simulate` that do not come from the scenario document
    (the others are validated with the document, with the TOML path's messages); return
    ``(integrator, coupling, residual_tol, observers)`` normalized (the integrator defaulted
    to the requested engine's, else time-stepping; a window as a tuple of floats, an
    iterable of observers as a list).

    Raises
    ------
    InputError
        Naming the keyword (``observer.coupling`` for the window, as the TOML path does).
    """
    if integrator is None:
        requested = ENGINES.get(engine) if isinstance(engine, str) else None
        integrator = requested.integrator if requested is not None else "time-stepping"
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
    return integrator, coupling, residual_tol, observers
