"""The exact event-driven engine (:mod:`observer.event`): exact flow between events, impact
times to round-off, Zeno resolved into persistent contact; sampled on the grid t_k = k·h.

The master and the observers run in the gap frame (:class:`observer.event.frame.GapFrame`)
when it lowers the gaps' representation floor at the initial state:
coordinates x = q − q* with the origin q* on the contacts (``Wᵀq* + ν₀ ≈ 0``), the shifted
problem the same problem (its forcing and gap-offset constants exact, then rounded), so that
a translation of the coordinates by c costs only what float64 forces on the inputs (ulp(c)),
not ulp(c) in every gap evaluation, enclosure and touch band; the rows are moved back to q.
``metadata["gap_frame"]`` is the origin q* of a run so carried (absent: the run in its own
coordinates, :meth:`~observer.event.frame.GapFrame.for_scenario`).

The master's and the observers' arrays go into the :class:`~observer.result.RunRecord`
directly (no DataFrame is built unless a user reads one); the master's and the observers'
:class:`~observer.result.RunStatus` are decided where each stopped (:mod:`observer.event.master`,
:mod:`observer.event.observers`) and composed here into the run's.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from observer.engines.base import Engine, Refusal, RunDescription
from observer.sparse import DENSE_MAX_N
from observer.result import EventTable, RunRecord, RunState, RunStatus, SlaveTrajectory, StepStats, \
    package_versions


EVENT_MAX_N = DENSE_MAX_N
"""Largest system the event engine accepts (:data:`observer.sparse.DENSE_MAX_N`, 512 degrees of
freedom): its exact flow uses dense matrix exponentials of size 2n and dense M⁻¹, so a larger
(sparse) system is refused with the size instead of attempted."""


EVENT_MAX_PERIODS = 1e6
"""Most periods of a forcing or gap-offset term over the run the event engine accepts: it
locates every root of the gap functions, and a gap driven at ω has O(ω·t_end) of them."""


def _signal_periods(sc):
    """``(field, ω, periods)`` of the first harmonic term of f(t) or ν(t) with more than
    :data:`EVENT_MAX_PERIODS` periods over ``[0, t_end]``, else None."""
    for field, sig in (("system.forcing", sc.system.forcing), ("system.gap", sc.system.gap)):
        for j, w in enumerate(np.asarray(sig.omega, dtype=float)):
            count = w * sc.t_end / (2 * np.pi)
            if count > EVENT_MAX_PERIODS and np.any(np.asarray(sig.amplitude)[j] != 0):
                return field, float(w), float(count)
    return None


class EventEngine(Engine):
    """The exact event-driven integrator: impact problems by pivoting, the impact laws that
    declare :attr:`~observer.impact.ImpactLawDefinition.event_engine`, χ from the master's
    exact intervals or a closing log."""

    name = "event"
    integrator = "event"
    description = "exact event-driven integration, sampled on t_k = t0 + k·h"
    time_origin = True

    def refuses(self, run: RunDescription) -> Refusal | None:
        """Time-stepping options, another solver, a law it lacks, a self-driven χ, a system
        larger than :data:`EVENT_MAX_N` degrees of freedom."""
        n = run.scenario.system.n
        if n > EVENT_MAX_N:
            return Refusal(f"the event-driven integrator handles up to {EVENT_MAX_N} degrees of freedom "
                           f"(it forms dense 2n × 2n matrix exponentials, O(n³)); this system has "
                           f"n = {n}: use integrator=\"time-stepping\"", "integrator")
        periods = _signal_periods(run.scenario)
        if periods is not None:
            field, w, count = periods
            return Refusal(f"oscillates {count:.3g} times over the run (ω = {w:.4g} rad/s, "
                           f"t_end = {run.scenario.t_end:g}): the event-driven integrator follows every "
                           f"oscillation of the gaps (at most {EVENT_MAX_PERIODS:.0e}); use "
                           "integrator=\"time-stepping\" or a slower signal", field)
        for option, value, default in (("record_every", run.record_every, None),
                                       ("store", run.store, "full")):
            if value != default:
                return Refusal(f"{option} is a time-stepping option; integrator=\"event\" samples on "
                               f"the grid t_k = k·h (got {option} = {value!r})", option)
        sc = run.scenario
        if sc.solver != "pivoting":
            return Refusal("the event-driven integrator solves its impact problems by pivoting "
                           f"(got {sc.solver!r})", "simulation.solver")
        if not sc.law.definition.event_engine:
            return Refusal(f"impact law {sc.law.law!r} is not supported by the event-driven engine",
                           "impact.law")
        if run.slaves and run.source not in ("master", "log"):
            return Refusal(f"the event-driven integrator drives observers by the master or a log, "
                           f"not {run.source!r}", "observer.source")
        return None

    def run(self, run: RunDescription) -> RunRecord:
        """The master, then the observers, stoppable by a signal when ``run.on_chunk`` is set
        (the rows every system reached are kept, the status says where)."""
        from observer.engines.loop import Stopper

        with Stopper(run.on_chunk is not None) as stopper:
            return _event_run(run, lambda: stopper.signal)


def master_status(master) -> RunStatus:
    """The run's status from the master's (:attr:`observer.event.master.MasterEventResult.status`,
    decided where the master stopped): a non-finite stop names the master's quantity already,
    any other stop is said to be the master's."""
    status = master.status
    if status.ok or master.nonfinite:
        return status
    return RunStatus(RunState.STOPPED, f"master: {status.reason}")


def _event_run(run: RunDescription, signalled) -> RunRecord:
    from observer.event.frame import GapFrame
    from observer.event.master import run_master

    sc = run.scenario
    frame = GapFrame.for_scenario(sc)       # the run in x = q − q*, origin on the contacts
    master = run_master(sc if frame is None else frame.scenario(sc), t0=run.t0,
                        should_stop=signalled,   # overflow is a stop (status), silenced inside
                        origin=None if frame is None else frame.origin)
    master_signal = signalled()
    t, q, u, P, active = master.t, master.q, master.u, master.P, master.active
    n, m = sc.system.n, sc.system.m
    meta = {"scenario": sc.name, "integrator": "event", "h": sc.h, "t_end": sc.t_end, "t0": run.t0,
            "n": n, "m": m, "law": sc.law.law, "restitution": sc.law.restitution.tolist(),
            "steps": int(t.size - 1), "master_status": str(master.status),
            "events": len(master.event_rows), "zeno": master.zeno,
            "versions": package_versions(), "engine": "event"}
    if frame is not None:
        meta["gap_frame"] = frame.origin.tolist()
    status = master_status(master)
    slaves, chi, observers_whole = {}, None, True
    if run.slaves:
        slaves, chi, obs = _observers(run, master, master_signal, signalled, frame)
        meta.update(observers=list(obs.runs), source=run.source,
                    observer_events={name: len(r.event_rows) for name, r in obs.runs.items()})
        observers_whole = all(r.status.ok for r in obs.runs.values())
        if sc.model is not None:
            meta["observer_model"] = sc.model.metadata(sc.system)
        if not obs.status.ok and status.ok:
            status = RunStatus(RunState.STOPPED, f"observer {obs.status.reason}")
    if frame is not None:                   # the rows back in the run's coordinates q = x + q*
        q = frame.output(q)
        slaves = {name: dataclasses.replace(r, q=frame.output(r.q)) for name, r in slaves.items()}
    sig = signalled()
    keep, bad = _event_finite_rows(t, q, u, P, slaves)
    if bad is not None:                     # rows an observer did not reach or where it overflowed
        t, q, u, P, active = t[:keep], q[:keep], u[:keep], P[:keep], active[:keep]
        chi = chi[:keep] if chi is not None else None
        slaves = {name: SlaveTrajectory(name, r.q[:keep], r.u[:keep], r.P[:keep], r.V[:keep], None, None,
                                        None, r.sigma[:keep]) for name, r in slaves.items()}
        if not sig and observers_whole:     # an observer's state or V overflowed first: a stop, no row
            status = RunStatus(RunState.STOPPED, f"non-finite {bad}; the output ends at t = {t[-1]:.9g}, "
                                                 "the last finite state")
        elif not sig:                       # an observer stopped (its rows not reached are NaN)
            status = RunStatus(RunState.STOPPED, f"{status.reason}; the output ends at t = {t[-1]:.9g}")
    if sig and (status.ok or sig in status.reason):
        status = RunStatus(RunState.STOPPED, f"{sig} at t = {t[-1]:.9g} (the event-driven run was "
                                             f"interrupted; every row up to there is whole)")
    events = EventTable.from_rows(master.event_rows)
    if not status.ok:                       # where and why, as a stopped time-stepped run says it
        meta["steps"] = int(t.size - 1)
        meta["stopped"] = {"step": int(t.size - 1), "t": float(t[-1]) if t.size else None,
                           "reason": status.reason, "signal": sig if sig and sig in status.reason else None}
        # the events before the stop: the master's stop time, or the last row kept when an
        # observer ended the output earlier
        cut = master.t_stop if bad is None and np.isfinite(master.t_stop) else \
            (t[-1] if t.size else None)
        if cut is not None:
            events = events.until(cut)
            meta["events"] = len(events)
    return RunRecord("event", t, q, u, P, np.zeros_like(P), active, chi, slaves, status,
                     StepStats.from_metadata(meta), meta, events)


def _observers(run: RunDescription, master, master_signal, signalled, frame=None):
    """The event-driven observers of ``run`` against ``master``: ``(slaves, χ, result)``. With an
    observer model (:mod:`observer.plant_model`) the master is the plant and the observers
    advance the nominal scenario (:func:`~observer.plant_model.model_scenario`) switched at the
    plant's exact closing and opening times (or the log's); V is measured against the plant.
    With a gap frame (:class:`observer.event.frame.GapFrame`) the master ran in it, and so do
    the observers (their own scenario shifted by the same origin, with its own K and W; their
    states shifted, the errors q̂ − q unchanged): the rows are in the frame."""
    from observer.event.observers import run_observers
    from observer.observers import lyapunov
    from observer.plant_model import model_scenario

    sc = run.scenario                       # with an observer model: the observers run on it
    own = sc if sc.model is None else model_scenario(sc)
    slaves = list(run.slaves)
    if frame is not None:
        own = frame.scenario(own)
        slaves = [dataclasses.replace(s, q0=frame.state(s.q0)) for s in slaves]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # overflow: stopped by the caller
        obs = run_observers(master, own, slaves, intervals=_intervals(run),
                            coupling=run.coupling, should_stop=None if master_signal else signalled)
        if sc.model is not None:            # V against the plant, in the model's error metric
            for r in obs.runs.values():
                r.V = lyapunov(sc.model.metric_system(sc.system), r.q, r.u, master.q, master.u)
    slaves = {name: r.as_slave() for name, r in obs.runs.items()}
    return slaves, obs.chi, obs


def _intervals(run: RunDescription) -> list[np.ndarray] | None:
    """χ's closed intervals per contact: None for the master's exact ones (the observers
    take them from the master run), the closing log's for ``source="log"``."""
    if run.source != "log":
        return None
    frame = run.log_frame
    return [frame.loc[frame.contact == j, ["t_close", "t_open"]].to_numpy(float)
            for j in range(run.scenario.system.m)]


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
