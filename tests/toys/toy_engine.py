"""A toy engine (one module plus one registry entry, ``ENGINES["toy"] = TOY_ENGINE``): the
master alone, step by step with the numpy stepper, no projection, every step kept."""

import time

import numpy as np

from observer.engines.base import Engine, Refusal
from observer.result import RunRecord, RunStatus, StepStats
from observer.stepping import MoreauJean


class ToyEngine(Engine):
    name = "toy"
    integrator = "time-stepping"
    description = "toy: the master alone with the numpy stepper"

    def refuses(self, run):
        if run.slaves:
            return Refusal("the toy engine runs the master alone (no observers)")
        if run.scenario.master_projection:
            return Refusal("the toy engine does not project the master's positions",
                           "simulation.master_projection")
        if run.store != "full" or run.record_every not in (None, 1):
            return Refusal("the toy engine keeps every step", "record_every")
        return None

    def run(self, run):
        sc = run.scenario
        st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, solver=sc.solver,
                        residual_tol=run.residual_tol)
        N, n, m = st.steps, sc.system.n, sc.system.m
        q, u = np.empty((N + 1, n)), np.empty((N + 1, n))
        P, active = np.zeros((N + 1, m)), np.zeros((N + 1, m), dtype=bool)
        q[0], u[0] = sc.q0, sc.u0
        t0 = time.perf_counter()
        for k in range(N):
            act = np.flatnonzero(st.predicted_active(k, q[k], u[k]))
            q[k + 1], u[k + 1], P[k + 1, act], _ = st.step(k, q[k], u[k], act, False)
            active[k + 1, act] = True
        wall = time.perf_counter() - t0
        meta = dict(sc.parameters(), engine=self.name, h=sc.h, steps=N, record_every=1,
                    wall_time_s=wall, steps_per_second=N / wall if wall > 0 else float("nan"),
                    compile_time_s=0.0, max_contact_residual=st.stats.max_residual,
                    solver_fallbacks=st.stats.fallbacks, solver=st.solver.name)
        return RunRecord(self.name, st.time(np.arange(N + 1)), q, u, P, np.zeros_like(P), active,
                         None, {}, RunStatus(), StepStats(steps=N), meta)


TOY_ENGINE = ToyEngine()
