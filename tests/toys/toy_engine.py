"""A toy engine (one module plus one registry entry, ``ENGINES["toy"] = TOY_ENGINE``): the
master and its observers step by step with the numpy stepper, every step kept, every observer
coupled to χ (the master's closed set, or the run's explicit χ) over the whole run, position
jumps in the K metric only. It records the positions before the projection, so that the
proof checks' replays (:func:`proofs_checks.runs.replay`, which ask for ``record_pre``)
take it too; a metric other than K is refused by the base class (field ``metric``)."""

import time

import numpy as np

from observer.engines.base import Engine, Refusal
from observer.observers import lyapunov
from observer.result import RunRecord, RunStatus, SlaveTrajectory, StepStats
from observer.stepping import MoreauJean


class ToyEngine(Engine):
    name = "toy"
    integrator = "time-stepping"
    description = "toy: the master and its observers with the numpy stepper"
    extras = frozenset({"chi", "record_pre"})

    def refuses(self, run):
        if run.slaves and (run.source != "master" or run.coupling is not None):
            return Refusal("the toy engine couples the observers to the master over the whole run",
                           "observer.coupling")
        if any(s.metric not in ("K", None) for s in run.slaves):
            return Refusal("the toy engine projects in the K metric only", "observer.observers")
        if run.store != "full" or run.record_every not in (None, 1):
            return Refusal("the toy engine keeps every step", "record_every")
        return None

    def run(self, run):
        sc = run.scenario
        st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, solver=sc.solver,
                        residual_tol=run.residual_tol)
        N, n, m, S = st.steps, sc.system.n, sc.system.m, 1 + len(run.slaves)
        q, q_pre, u = np.empty((3, S, N + 1, n))
        P, sigma = np.zeros((2, S, N + 1, m))
        active, chi = np.zeros((2, N + 1, m), dtype=bool)
        q[:, 0] = q_pre[:, 0] = [sc.q0] + [s.q0 for s in run.slaves]
        u[:, 0] = [sc.u0] + [s.u0 for s in run.slaves]
        jumps = [bool(sc.master_projection)] + [s.position_jumps for s in run.slaves]
        t0 = time.perf_counter()
        for k in range(N):
            closed = np.flatnonzero(st.predicted_active(k, q[0, k], u[0, k]))
            active[k + 1, closed] = True
            chi[k + 1] = active[k + 1] if run.chi is None else run.chi[k]
            for s in range(S):
                act = closed if s == 0 else np.flatnonzero(chi[k + 1])
                q_pre[s, k + 1], u[s, k + 1], P[s, k + 1, act], _ = st.step(k, q[s, k], u[s, k], act)
                q[s, k + 1] = q_pre[s, k + 1]
                if jumps[s] and act.size:
                    q[s, k + 1], sigma[s, k + 1, act] = st.project(k + 1, q_pre[s, k + 1], act)
        wall = time.perf_counter() - t0
        meta = dict(sc.parameters(), engine=self.name, h=sc.h, steps=N, record_every=1,
                    wall_time_s=wall, steps_per_second=N / wall if wall > 0 else float("nan"),
                    compile_time_s=0.0, max_contact_residual=st.stats.max_residual,
                    solver_fallbacks=st.stats.fallbacks, solver=st.solver.name)
        slaves = {s.name: SlaveTrajectory(s.name, q[i], u[i], P[i], lyapunov(sc.system, q[i], u[i], q[0], u[0]),
                                          None, None, None, sigma[i])
                  for i, s in enumerate(run.slaves, start=1)}
        return RunRecord(self.name, st.time(np.arange(N + 1)), q[0], u[0], P[0], sigma[0], active,
                         chi if run.slaves else None, slaves, RunStatus(), StepStats(steps=N), meta,
                         q_pre=q_pre)


TOY_ENGINE = ToyEngine()
