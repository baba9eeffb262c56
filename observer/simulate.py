"""The façade: load a scenario, simulate the master and its observers, return a result."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import TYPE_CHECKING, Iterable

import numpy as np

from observer.errors import InputError, is_numerical_failure
from observer.loop import LoopInput, check_engine, check_record_every, summary_frame
from observer.loop import run as run_loop
from observer.observers import OBSERVER_DESIGNS, ObserverConfig, Slave, check_coupling, \
    check_observer_name, lyapunov, lyapunov_decrements
from observer.result import (EVENT_COLUMNS, LazyFrame, RunStatus, SimulationResult, SlaveTrajectory,
                             package_versions, records_frame, run_metadata)
from observer.scenario import (Scenario, check_finite_energy,  # noqa: F401  (re-exported:
                               load_scenario)                  # observer.load_scenario)
from observer.stepping import MoreauJean
from observer.switching import SOURCES, read_log
from observer.validation import MAX_STEPS, as_scalar

if TYPE_CHECKING:
    import pandas as pd


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
             engine: str = "compiled", record_every: int | None = None,
             store: str = "full", integrator: str = "time-stepping",
             on_chunk=None) -> SimulationResult:
    """Simulate the master (and the observers) of ``scenario`` with the Moreau–Jean scheme.

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
    engine : {"compiled", "python"}
        The time loop (:mod:`observer.loop`): the numba kernel (default) or the readable
        numpy reference; both give the same trajectories to round-off. The kernel solves its
        contact problems by block pivoting (the ``"pivoting"`` solver); with another
        ``solver`` the run uses the python engine and ``metadata["engine_note"]`` says so.
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
    integrator : {"time-stepping", "event"}
        ``"event"``: the exact event-driven integrator (:mod:`observer.event`): exact flow
        between events, impact times to round-off, Zeno resolved into persistent contact; the
        observers switch at the master's exact closing and opening times. The result is
        sampled on the grid t_k = k·h; ``engine``, ``solver`` (other than pivoting),
        ``record_every`` and ``store`` are time-stepping options and are refused.

    Returns
    -------
    SimulationResult
        With one :class:`~observer.result.SlaveTrajectory` per observer (V relative to the
        master), the switching signal ``chi`` and ``events`` (time-stepping: the master's
        closing and opening steps, an approximation of the event table).
    """
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
    if integrator == "event":
        return _simulate_event(sc, observers, source, coupling, log, engine, record_every, store,
                               on_chunk)
    check_engine(engine)
    engine_note = None
    if engine == "compiled" and sc.solver != "pivoting":
        # the kernel solves its LCPs by compiled block pivoting only; other solvers run on
        # the numpy engine, and the result says so
        engine, engine_note = "python", (f"solver {sc.solver!r} runs on the python engine "
                                         "(the compiled kernel has block pivoting only)")
    if engine == "compiled" and sc.law.code is None:
        engine, engine_note = "python", (f"impact law {sc.law.law!r} runs on the python engine "
                                         "(it has no code in the compiled kernel)")
    system = sc.system
    stepper = MoreauJean(system, sc.law, sc.h, sc.t_end, sc.theta, solver=sc.solver,
                         residual_tol=residual_tol,
                         structure="auto" if engine == "compiled" else "dense")
    if record_every is None:
        record_every = max(1, stepper.steps // 10_000) if store == "summary" else 1
    record_every = check_record_every(record_every)
    if isinstance(observers, str):
        observers = scenario_observers(sc) if observers == "scenario" else [observers]
    observers = list(observers)
    slaves: list[Slave] = []
    if observers:
        base_dir = str(Path(sc.source).parent) if sc.source.endswith(".toml") else None
        cfg = ObserverConfig.from_table(sc.observer, system.n, sc.q0, sc.u0, base_dir)
        slaves = make_slaves(cfg, observers)
        for s in slaves:
            check_finite_energy("observer", system, s.q0, s.u0)
        source = source or cfg.source
        if coupling == "scenario":
            coupling = cfg.coupling
        log = log or cfg.log
        for s in slaves:
            if s.position_jumps and s.metric == "K":
                system.require_definite_stiffness(f"the observer {s.name!r} (position jumps in the K metric)")
    if source is not None and source not in SOURCES:
        raise InputError("observer.source", f"must be one of {list(SOURCES)}, got {source!r}")
    log_frame = None
    if slaves and source == "log":
        if log is None:
            raise InputError("observer.log", "source = \"log\" needs a log file")
        log_frame = read_log(log, system.m)

    inp = LoopInput(stepper, np.stack([sc.q0] + [s.q0 for s in slaves]),
                    np.stack([sc.u0] + [s.u0 for s in slaves]),
                    np.array([False] + [s.position_jumps for s in slaves]),
                    bool(sc.master_projection), None if coupling == "scenario" else coupling,
                    source == "self", log_frame,
                    metrics=(None,) + tuple(_metric_matrix(s, system) for s in slaves),
                    names=tuple(s.name for s in slaves))
    other_metric = any(s.position_jumps and s.metric != "K" for s in slaves)
    out = run_loop(inp, engine=engine, record_every=record_every, store=store,
                   record_pre=other_metric and store == "full", on_chunk=on_chunk)

    meta = run_metadata(sc, stepper, out)
    if engine_note:
        meta["engine_note"] = engine_note
    names = [s.name for s in slaves]
    if slaves:
        meta.update(observers=names, source=source,
                    coupling=None if coupling in ("scenario", None) else list(coupling),
                    log=str(log) if log else None)
    master = {"q": out.q[0], "u": out.u[0], "P": out.P[0], "sigma": out.sigma[0]}
    if out.q_pre is not None:
        master["q_pre"] = out.q_pre[0]
    trajectories = {s.name: _trajectory(system, sc.h, out, i, s.name, master, record_every)
                    for i, s in enumerate(slaves, start=1)}
    summary = None
    if out.summary is not None:                     # the tables: DataFrames built on first read
        rows = summary_frame(out, names, stepper.t0, stepper.h, frame=False)
        summary = LazyFrame(records_frame, (rows,), {"master_closings": out.summary["closings"].tolist()})
    t = out.t if out.t is not None else stepper.time(out.rows)
    events = LazyFrame(result_events, of_result=True) if record_every == 1 else None
    return SimulationResult(t, out.q[0], out.u[0], out.P[0], out.active,
                            system, meta, chi=out.chi if slaves else None, slaves=trajectories,
                            sigma=out.sigma[0], summary=summary, events=events)


INTEGRATORS = ("time-stepping", "event")


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


def result_events(res: SimulationResult) -> pd.DataFrame:
    """:func:`stepping_events` of a time-stepped result keeping every step (its
    :attr:`~observer.result.SimulationResult.events`, built on first read)."""
    return stepping_events(res.t, res.q, res.u, res.P, res.active, res.system)


def stepping_events(t, q, u, P, active, system) -> pd.DataFrame:
    """The event table of a time-stepped master, approximately: a closing step with an
    impulse is an ``impact`` (γ⁻ = γ_k, γ⁺ = γ_{k+1}, the step's impulse; time t_k), a
    closing step without one a ``stick``, an opening step a ``liftoff``."""
    import pandas as pd

    rows = []
    closing = active[1:] & ~active[:-1]
    opening = ~active[1:] & active[:-1]
    ks, js = np.nonzero(closing | opening)
    if ks.size:                                     # γ = Wᵀu + ν̇ at the event rows only
        both = np.concatenate([ks, ks + 1])
        gamma = u[both] @ system.W + system.nu_dot(t[both])
        g_minus, g_plus = gamma[:ks.size], gamma[ks.size:]
    for i, (k, j) in enumerate(zip(ks, js)):
        kind = "liftoff" if opening[k, j] else ("impact" if P[k + 1, j] > 0 else "stick")
        rows.append((float(t[k]), int(j), kind, float(g_minus[i, j]), float(g_plus[i, j]),
                     float(P[k + 1, j])))
    return pd.DataFrame(rows, columns=list(EVENT_COLUMNS)).astype(
        {"time": float, "contact": int, "kind": str, "gamma_minus": float, "gamma_plus": float,
         "impulse": float})


def _simulate_event(sc: Scenario, observers, source, coupling, log, engine, record_every,
                    store, on_chunk=None) -> SimulationResult:
    """:func:`simulate` with ``integrator="event"`` (see there).

    With ``on_chunk`` (a streamed run: ``observer run --out``) SIGINT and SIGTERM stop the
    master between events or blocks of samples, and the observers between switchings; the
    result ends at the last row every system reached, with the status and ``metadata["stopped"]``
    naming the signal, and is written whole by the caller (:meth:`ChunkWriter.finish`)."""
    from observer.loop import _Stopper

    with _Stopper(on_chunk is not None) as stopper:
        return _event_run(sc, observers, source, coupling, log, engine, record_every, store,
                          lambda: stopper.signal)


def _event_run(sc: Scenario, observers, source, coupling, log, engine, record_every, store,
               signalled) -> SimulationResult:
    from observer.event.master import run_master
    from observer.event.observers import run_observers

    for name, value, default in (("engine", engine, "compiled"), ("record_every", record_every, None),
                                 ("store", store, "full")):
        if value != default:
            raise InputError(name, f"is a time-stepping option; integrator=\"event\" samples "
                             f"on the grid t_k = k·h (got {name} = {value!r})")
    if sc.solver != "pivoting":
        raise InputError("simulation.solver", "the event-driven integrator solves its impact "
                         f"problems by pivoting (got {sc.solver!r})")
    system = sc.system
    if isinstance(observers, str):
        observers = scenario_observers(sc) if observers == "scenario" else [observers]
    observers = list(observers)
    master = run_master(sc, should_stop=signalled)   # overflow is a stop (status), silenced inside
    master_signal = signalled()
    df = master.frame
    n, m = system.n, system.m
    t = df["t"].to_numpy(float)
    cols = lambda p, k: df[[f"{p}{j}" for j in range(k)]].to_numpy()  # noqa: E731
    q, u, P, active = cols("q", n), cols("u", n), cols("P", m), cols("active", m).astype(bool)
    meta = {"scenario": sc.name, "integrator": "event", "h": sc.h, "t_end": sc.t_end,
            "n": n, "m": m, "law": sc.law.law, "restitution": sc.law.restitution.tolist(),
            "steps": int(t.size - 1), "master_status": master.status,
            "events": int(len(master.events)), "zeno": master.zeno,
            "versions": package_versions()}
    slaves, chi = {}, None
    observers_whole = True                  # every observer reached the master's last row
    status = (RunStatus() if master.status == "ok"
              else RunStatus("stopped", master.status.removeprefix("stopped: "))
              if master.status.startswith("stopped: non-finite")      # names the master's quantity
              else RunStatus("stopped", f"master: {master.status}"))
    if observers:
        base_dir = str(Path(sc.source).parent) if sc.source.endswith(".toml") else None
        cfg = ObserverConfig.from_table(sc.observer, n, sc.q0, sc.u0, base_dir)
        specs = make_slaves(cfg, observers)
        for s in specs:
            check_finite_energy("observer", system, s.q0, s.u0)
        source = source or cfg.source
        intervals = _event_intervals(sc, master, source, log or cfg.log)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # overflow: stopped below
            obs = run_observers(master, sc, specs, intervals=intervals,
                                coupling=cfg.coupling if coupling == "scenario" else coupling,
                                should_stop=None if master_signal else signalled)
        chi = obs.chi
        for name, r in obs.runs.items():
            slaves[name] = SlaveTrajectory(name, r.q, r.u, r.P, r.V, None, None, None, r.sigma)
        meta.update(observers=list(obs.runs), source=source,
                    observer_events={name: int(len(r.events)) for name, r in obs.runs.items()})
        observers_whole = all(r.status == "ok" for r in obs.runs.values())
        if obs.status != "ok" and status.ok:
            status = RunStatus("stopped", f"observer {obs.status}")
    sig = signalled()
    keep, bad = _event_finite_rows(t, q, u, P, slaves)
    if bad is not None:                     # rows an observer did not reach or where it overflowed
        t, q, u, P, active = t[:keep], q[:keep], u[:keep], P[:keep], active[:keep]
        chi = chi[:keep] if chi is not None else None
        slaves = {name: SlaveTrajectory(name, r.q[:keep], r.u[:keep], r.P[:keep], r.V[:keep], None, None,
                                        None, r.sigma[:keep]) for name, r in slaves.items()}
        if not sig and observers_whole:     # an observer's state or V overflowed first: a stop, no row
            status = RunStatus("stopped", f"non-finite {bad}; the output ends at t = {t[-1]:.9g}, "
                                          "the last finite state")
        elif not sig:                       # an observer stopped (its rows not reached are NaN)
            status = RunStatus("stopped", f"{status.reason}; the output ends at t = {t[-1]:.9g}")
    if sig and (status.ok or sig in status.reason):
        status = RunStatus("stopped", f"{sig} at t = {t[-1]:.9g} (the event-driven run was "
                                      f"interrupted; every row up to there is whole)")
    if not status.ok:                       # where and why, as a stopped time-stepped run says it
        meta["steps"] = int(t.size - 1)
        meta["stopped"] = {"step": int(t.size - 1), "t": float(t[-1]) if t.size else None,
                           "reason": status.reason, "signal": sig if sig and sig in status.reason else None}
    events = master.events[list(EVENT_COLUMNS)]
    if not status.ok and t.size:            # the events of the rows kept
        events = events[events["time"] <= t[-1]].reset_index(drop=True)
        meta["events"] = int(len(events))
    return SimulationResult(t, q, u, P, active, system, meta, chi=chi, slaves=slaves,
                            sigma=np.zeros_like(P), events=events, status=status)


def _event_finite_rows(t, q, u, P, slaves: dict) -> tuple[int, str | None]:
    """Rows of an event-driven result before the first one holding a non-finite value (the
    master's rows are finite already, :func:`observer.event.master.run_master`; an
    observer's q, u, P or V may overflow later), and that quantity with its time (None:
    every row finite). One vectorised test in the usual case."""
    blocks = [(f"{p} of the master", a) for p, a in (("q", q), ("u", u), ("P", P))]
    for name, r in slaves.items():
        blocks += [(f"{p} of observer {name!r}", a) for p, a in (("q", r.q), ("u", r.u), ("P", r.P))]
        blocks.append((f"V of observer {name!r}", np.asarray(r.V)[:, None]))
    if all(np.isfinite(a).all() for _, a in blocks):
        return t.size, None
    first, what = t.size, None
    for name, a in blocks:
        rows = np.flatnonzero(~np.isfinite(a).all(axis=1))
        if rows.size and rows[0] < first:
            col = int(np.flatnonzero(~np.isfinite(a[rows[0]]))[0])
            label = name if name.startswith("V ") else f"{name[0]}{col}{name[1:]}"
            first, what = int(rows[0]), f"{label} ({a[rows[0], col]}) at t = {t[rows[0]]:.9g}"
    return first, what


def _event_intervals(sc: Scenario, master, source: str, log) -> list[np.ndarray] | None:
    """χ's closed intervals per contact: None for the master's exact ones (the observers
    take them from the master run), a closing log's for ``source="log"``."""
    if source == "master":
        return None
    if source != "log":
        raise InputError("observer.source", f"the event-driven integrator drives observers by "
                         f"the master or a log, not {source!r}")
    if log is None:
        raise InputError("observer.log", "source = \"log\" needs a log file")
    frame = read_log(log, sc.system.m)
    return [frame.loc[frame.contact == j, ["t_close", "t_open"]].to_numpy(float)
            for j in range(sc.system.m)]


def _trajectory(system, h: float, out, i: int, name: str, master: dict,
                record_every: int) -> SlaveTrajectory:
    """Observer ``i`` of the loop's output as a :class:`SlaveTrajectory` (V and, when every
    step is kept, its per-step damping/impulse/projection parts)."""
    traj = {"q": out.q[i], "u": out.u[i], "P": out.P[i], "sigma": out.sigma[i]}
    if out.q_pre is not None:
        traj["q_pre"] = out.q_pre[i]
    V = (out.V[i] if out.V is not None
         else lyapunov(system, traj["q"], traj["u"], master["q"], master["u"]))
    parts = (lyapunov_decrements(system, h, traj, master) if record_every == 1
             else {"damping": None, "impulse": None, "projection": None})
    return SlaveTrajectory(name, traj["q"], traj["u"], traj["P"], V, parts["damping"],
                           parts["impulse"], parts["projection"], traj["sigma"])


def make_slaves(cfg: ObserverConfig, observers: list[str | Slave]) -> list[Slave]:
    """Observer names become slaves started from the ``[observer]`` state; Slave objects pass."""
    out: list[Slave] = []
    for ob in observers:
        if isinstance(ob, Slave):
            out.append(ob)
            continue
        check_observer_name(ob)
        design = OBSERVER_DESIGNS[ob]
        out.append(Slave(ob, design.position_jumps, cfg.q0, cfg.u0, design))
    names = [s.name for s in out]
    if len(set(names)) != len(names):
        raise InputError("observer.observers", f"observer names must be unique, got {names}")
    return out


def _metric_matrix(slave: Slave, system) -> np.ndarray | None:
    """The slave's projection metric as a matrix (None: K)."""
    if slave.design is not None:
        return slave.design.metric_matrix(system)
    return None


def scenario_observers(sc: Scenario) -> list[str]:
    """The observer designs a scenario asks for: its ``[observer] observers`` (the paper's two
    designs when the table leaves the key out), none without an ``[observer]`` table."""
    if not sc.observer:
        return []
    return list(ObserverConfig.from_table(sc.observer, sc.system.n, sc.q0, sc.u0).observers)
