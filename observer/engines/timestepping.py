"""What the two Moreau–Jean engines share: the stepper, the loop's input, the record.

:class:`TimeStepping` runs a :class:`~observer.engines.base.RunDescription` through its
:meth:`~TimeStepping.advance`, which checks the loop's options and calls the engine's own
loop (:meth:`TimeStepping.loop`); the compiled and the numpy engine
(:mod:`observer.engines.compiled`, :mod:`observer.engines.python`) differ in their loop, in
what they accept and in the stepper's matrix structure.
"""

from __future__ import annotations

import numpy as np

from observer.engines.base import EXTRAS, Engine, RunDescription
from observer.engines.loop import STORES, LoopInput, LoopOutput, Stopper, check_record_every, summary_frame
from observer.observers import lyapunov, lyapunov_decrements
from observer.result import (LazyFrame, RunRecord, RunStatus, SimulationResult, SlaveTrajectory,
                             StepStats, records_frame, run_metadata)
from observer.errors import InputError
from observer.stepping import FACTORED_MIN_N, MoreauJean


SUMMARY_ROW_VALUES = 1 << 24
"""Most state values (q and u of every system, over the recorded rows) ``store="summary"``
keeps by default: 2²⁴ floats = 128 MiB, whatever the horizon and the system's size."""


def summary_record_every(steps: int, n: int, systems: int) -> int:
    """The default ``record_every`` of ``store="summary"``: about 10 000 rows, and fewer when
    the states of that many rows would exceed :data:`SUMMARY_ROW_VALUES` values (a chain of
    10⁵ blocks, 3 systems, 1000 steps: every 72nd step), so that the memory of a summary run
    is bounded for any n (the summary itself streams over every step)."""
    per_row = 2 * n * systems
    return max(1, steps // 10_000, -(-(steps + 1) * per_row // SUMMARY_ROW_VALUES))


class TimeStepping(Engine):
    """A Moreau–Jean engine: its loop (:meth:`loop`) on the stepper of the scenario (matrix
    structure :attr:`structure`)."""

    integrator = "time-stepping"
    structure = "dense"
    extras = frozenset(EXTRAS)

    def advance(self, inp: LoopInput, record_every: int = 1, record_pre: bool = False, store: str = "full",
                rhos: tuple | None = None, on_chunk=None) -> LoopOutput:
        """Advance the master and the observers of ``inp`` over the stepper's grid.

        ``store="summary"`` (compiled engine) also computes, streaming over every step, what
        the synchronization metrics need (:func:`~observer.engines.loop.summary_frame`; ``rhos``
        its thresholds); with it the trajectories are kept only every ``record_every`` steps.
        ``on_chunk(chunk)`` (optional) is called with each :class:`~observer.engines.loop.Chunk`
        of finished rows, in order, the last one before returning; while it is set, SIGINT and
        SIGTERM stop the run after the current window (``LoopOutput.stop_signal``) instead of
        raising.

        Raises
        ------
        InputError
            Naming ``record_every`` or ``store``.
        """
        record_every = check_record_every(record_every)
        if store not in STORES:
            raise InputError("store", f"must be one of {list(STORES)}, got {store!r}")
        with Stopper(on_chunk is not None) as stopper:
            return self.loop(inp, record_every, record_pre, store, rhos, on_chunk, stopper)

    def loop(self, inp: LoopInput, record_every: int, record_pre: bool, store: str, rhos: tuple | None,
             on_chunk, stopper: Stopper) -> LoopOutput:
        """The engine's loop over ``inp`` (options checked by :meth:`advance`)."""
        raise NotImplementedError(f"engine {self.name!r} has no time-stepping loop")

    def run(self, run: RunDescription) -> RunRecord:
        """The master and the observers over the grid t_k = t0 + k·h (with an observer model,
        :meth:`run_with_model`)."""
        if run.scenario.model is not None and run.slaves:
            return self.run_with_model(run)
        sc, slaves = run.scenario, run.slaves
        stepper = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, solver=sc.solver,
                             residual_tol=run.residual_tol, structure=self.structure)
        record_every = run.record_every
        if record_every is None:
            record_every = (summary_record_every(stepper.steps, sc.system.n, 1 + len(slaves))
                            if run.store == "summary" else 1)
        record_every = check_record_every(record_every)
        other_metric = any(s.position_jumps and s.metric != "K" for s in slaves)
        if other_metric and stepper.S.factored:         # its metric would be a dense n × n matrix
            raise InputError("observers", f"a projection metric other than K needs n < {FACTORED_MIN_N} "
                             f"degrees of freedom; this system has n = {sc.system.n} (use \"jump\", the K metric)")
        inp = loop_input(run, stepper)
        out = self.advance(inp, record_every=record_every, store=run.store,
                           record_pre=run.record_pre or (other_metric and (run.store == "full" or record_every == 1)),
                           on_chunk=run.on_chunk)
        return stepping_record(run, stepper, out, record_every)

    def run_with_model(self, run: RunDescription) -> RunRecord:
        """The true plant as the master, the observers on their own model
        (:mod:`observer.plant_model`): two loops of this engine, no new one.

        1. The plant alone, every step recorded: its trajectory and its closed sets χ_k.
        2. The nominal scenario (:func:`~observer.plant_model.model_scenario`) with the
           observers, χ_k given explicitly as the plant's (``source="master"``; a log or
           ``"self"`` as the run asks), so that every observer step is the one of a run of the
           nominal model fed the plant's closing log.

        The result's master is the plant (every ``record_every``-th row of loop 1), its health
        the plant's; V is measured against it in the model's ``error_metric``
        (:meth:`~observer.plant_model.ObserverModel.metric_system`), and
        ``metadata["observer_model"]`` records the model, the metric and the observers' own
        health record (loop 2's, recorded and not warned: its master is the nominal model,
        which the plant's χ does not follow, so its observer-gap bound, whose premise is that
        χ is that master's closed set, :func:`observer.health.observer_gaps`, says nothing
        about the observers; the plant's health is warned as in every run). ``on_chunk`` receives no chunk (loop 2's rows carry the nominal
        master): the result is written whole at the end, as the event engine's. The per-step
        parts of ΔV (eq. (17)) are not given (the decomposition holds for one model: a
        mismatch adds a term of its own).

        Raises
        ------
        InputError
            Naming ``store`` for ``store="summary"`` (the kernel's summary measures V against
            the loop's own master; :func:`observer.ensemble` has its own path).
        """
        import dataclasses
        import warnings

        from observer.health import RunHealthWarning
        from observer.plant_model import model_scenario

        if run.store == "summary":
            raise InputError("store", 'store="summary" measures V against the loop\'s own master; with '
                             'observer.model use store="full" (observer.ensemble has its own path)')
        sc = run.scenario
        model = sc.model
        plant_run = dataclasses.replace(run, slaves=(), on_chunk=None, chi=None, metrics=None, record_pre=False)
        plant_stepper = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, solver=sc.solver,
                                   residual_tol=run.residual_tol, structure=self.structure)
        plant = self.advance(loop_input(plant_run, plant_stepper))
        chi = run.chi
        if chi is None and run.log_frame is None and run.source != "self":
            chi = np.zeros((plant_stepper.steps, sc.system.m), dtype=bool)
            chi[:plant.active.shape[0] - 1] = plant.active[1:]
        nominal = dataclasses.replace(run, scenario=model_scenario(sc), chi=chi, on_chunk=None)
        with warnings.catch_warnings():     # its health is recorded below, not warned (docstring)
            warnings.simplefilter("ignore", RunHealthWarning)
            out = self._nominal_loop(nominal)
        every, R = out.record_every, out.q.shape[1]
        rows = plant.q.shape[1]
        R = min(R, (rows - 1) // every + 1)
        cut = {k: getattr(out, k)[:, :R].copy() for k in ("q", "u", "P", "sigma")}
        for k in ("q", "u", "P", "sigma"):
            cut[k][0] = getattr(plant, k)[0, ::every][:R]
        stop = plant if plant.stopped_at is not None else out
        merged = dataclasses.replace(out, **cut, active=plant.active[::every][:R], chi=out.chi[:R],
                                     q_pre=None if out.q_pre is None else out.q_pre[:, :R], t=None, V=None,
                                     stopped_at=stop.stopped_at, stop_reason=stop.stop_reason,
                                     stop_signal=stop.stop_signal, health=plant.health,
                                     stats={**out.stats, **{k: plant.stats[k] for k in ("min_gap", "min_gap_step")
                                                            if k in plant.stats}})
        record = stepping_record(run, plant_stepper, merged, every, metric=model.metric_system(sc.system))
        record.metadata["observer_model"] = {**model.metadata(sc.system),
                                             "observers_health": out.health.to_dict() if out.health else None}
        return record

    def _nominal_loop(self, nominal: RunDescription) -> LoopOutput:
        """Loop 2 of :meth:`run_with_model`: the nominal scenario's master and observers."""
        sc, slaves = nominal.scenario, nominal.slaves
        stepper = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, solver=sc.solver,
                             residual_tol=nominal.residual_tol, structure=self.structure)
        record_every = check_record_every(1 if nominal.record_every is None else nominal.record_every)
        other_metric = any(s.position_jumps and s.metric != "K" for s in slaves)
        return self.advance(loop_input(nominal, stepper), record_every=record_every, store="full",
                            record_pre=nominal.record_pre or other_metric)


def loop_input(run: RunDescription, stepper: MoreauJean) -> LoopInput:
    """The loop's input: master first, then the observers (state, jumps, metric, name), with
    the description's extras (an explicit χ, the projection metrics)."""
    sc, slaves, system = run.scenario, run.slaves, run.scenario.system
    own = run.metrics or (None,) * len(slaves)
    return LoopInput(stepper, np.stack([sc.q0] + [s.q0 for s in slaves]),
                     np.stack([sc.u0] + [s.u0 for s in slaves]),
                     np.array([False] + [s.position_jumps for s in slaves]),
                     bool(sc.master_projection), run.coupling, run.source == "self", run.log_frame,
                     chi=run.chi, metric=run.metric,
                     metrics=(None,) + tuple(N if N is not None else None if s.design is None
                                             else s.design.metric_matrix(system)
                                             for s, N in zip(slaves, own)),
                     names=tuple(s.name for s in slaves))


def stepping_record(run: RunDescription, stepper: MoreauJean, out, record_every: int,
                    metric=None) -> RunRecord:
    """The :class:`RunRecord` of a loop's output (metadata, trajectories, V, tables); ``metric``
    (a system, with an observer model): V in its M and K, without the per-step parts of ΔV."""
    sc, slaves, system = run.scenario, run.slaves, run.scenario.system
    meta = run_metadata(sc, stepper, out)
    names = [s.name for s in slaves]
    if slaves:
        meta.update(observers=names, source=run.source,
                    coupling=None if run.coupling is None else list(run.coupling),
                    log=str(run.log) if run.log else None)
    master = {"q": out.q[0], "u": out.u[0], "P": out.P[0], "sigma": out.sigma[0]}
    if out.q_pre is not None:
        master["q_pre"] = out.q_pre[0]
    trajectories = {s.name: _trajectory(system if metric is None else metric, sc.h, out, i, s.name, master,
                                        record_every == 1 and metric is None)
                    for i, s in enumerate(slaves, start=1)}
    summary = None
    if out.summary is not None:                     # the tables: DataFrames built on first read
        rows = summary_frame(out, names, stepper.t0, stepper.h, frame=False)
        summary = LazyFrame(records_frame, (rows,), {"master_closings": out.summary["closings"].tolist()})
    t = out.t if out.t is not None else stepper.time(out.rows)
    events = LazyFrame(result_events, of_result=True) if record_every == 1 else None
    return RunRecord(out.engine, t, out.q[0], out.u[0], out.P[0], out.sigma[0], out.active,
                     out.chi if slaves else None, trajectories, RunStatus.from_metadata(meta),
                     StepStats.from_metadata(meta), meta, events, summary, out.q_pre)


def _trajectory(system, h: float, out, i: int, name: str, master: dict,
                with_parts: bool) -> SlaveTrajectory:
    """Observer ``i`` of the loop's output as a :class:`SlaveTrajectory` (V in ``system``'s M and
    K and, ``with_parts`` (every step kept, one model), its per-step damping/impulse/projection
    parts)."""
    traj = {"q": out.q[i], "u": out.u[i], "P": out.P[i], "sigma": out.sigma[i]}
    if out.q_pre is not None:
        traj["q_pre"] = out.q_pre[i]
    V = (out.V[i] if out.V is not None
         else lyapunov(system, traj["q"], traj["u"], master["q"], master["u"]))
    parts = (lyapunov_decrements(system, h, traj, master) if with_parts
             else {"damping": None, "impulse": None, "projection": None})
    return SlaveTrajectory(name, traj["q"], traj["u"], traj["P"], V, parts["damping"],
                           parts["impulse"], parts["projection"], traj["sigma"])


def result_events(res: SimulationResult):
    """:func:`stepping_events` of a time-stepped result keeping every step (its
    :attr:`~observer.result.SimulationResult.events`, built on first read)."""
    return stepping_events(res.t, res.q, res.u, res.P, res.active, res.system)


def stepping_events(t, q, u, P, active, system):
    """The event table of a time-stepped master, approximately: a closing step with an
    impulse is an ``impact`` (γ⁻ = γ_k, γ⁺ = γ_{k+1}, the step's impulse; time t_k), a
    closing step without one a ``stick``, an opening step a ``liftoff``."""
    from observer.result import EVENT_COLUMNS, EventTable

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
    df = EventTable.from_rows(rows).frame()
    return df.astype({"time": float, "contact": int, "kind": str, "gamma_minus": float,
                      "gamma_plus": float, "impulse": float})[list(EVENT_COLUMNS)]
