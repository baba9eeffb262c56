"""Execute one :class:`~bench.suites.Case` and return its tidy rows (one per run).

Every row holds the case's declared fields, the metrics of its kind, the timing
(``cpu_time_s`` from :func:`time.process_time` around the simulation only, ``wall_time_s``,
``steps_per_s`` = steps / CPU time; ``engine`` and ``loop_time_s``, the time loop's own wall
time from the result's metadata), ``status`` (``"ok"`` or ``"n/a"``), ``note`` and the
environment of :func:`bench.results.environment` (versions, CPU, commit, and
``compile_time_s``: the kernel's compile or cache-load time, measured once per suite run by
:func:`observer.engines.compiled.driver.compile_time` before any case is timed, so no row pays it) plus ``date``.

Engines: every simulation runs on the compiled engine (the default of
:func:`observer.simulate`), except cases whose contact solver the kernel does not have
(:func:`bench.suites.engine_for`: the numpy engine).

Error norms (work-precision): for a trajectory q_h on the grid t_k and a reference q_ref,
``e_k = max_i |q_h,i(t_k) − q_ref,i(t_k)|``; the reported error ``err_mean`` is the time
average ``(1/T) ∫ e dt`` (trapezoid on the grid of h), ``err_max = max_k e_k``. The time
average converges at the scheme's order even when impacts (or the observers' position
jumps) fall into different steps at different h, where the max norm only measures the
size of a mistimed jump.
"""

from __future__ import annotations

import gc
import re
import time
import tracemalloc
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import observer
from observer import Slave
from observer.observers import OBSERVER_DESIGNS
from observer.scenarios import SCENARIOS, info
from observer.contact import get_solver
from observer.errors import InputError
from observer.metrics import excursions_after_passage, settling_time, switchings
from observer.switching import log_from_active

from bench.norms import trajectory_error  # noqa: F401  (its home before bench.norms)
from bench.perturb import perturb_log
from observer.closed_form import closed_form_position
from bench.results import now_iso
from observer.metrics import RHOS, above_column, settle_column

from observer.row_schema import check_row
from bench.suites import Case, engine_for

ERROR_NORM = "mean over t of max_i |q_i − q_ref,i|"
MAX_PLOT_POINTS = 4000


def plot_choice(scenario: str) -> tuple[int, int]:
    """(coordinate, contact) the per-scenario figures draw (the scenario's ``PLOT``)."""
    if scenario not in SCENARIOS:
        return 0, 0
    meta = info(scenario)
    return meta.dof, meta.contact


class Unavailable(RuntimeError):
    """The case cannot run in this environment (e.g. proofs_checks not importable); its rows
    are not written, so a later run retries it."""


PROCESS_CACHE: dict = {}
"""What the cases run in one process share (the master's closing log of the robustness
cases, the event-driven references of the work-precision sweeps): a suite run, or a Dask
worker, computes each once, whatever the case it first serves."""


@dataclass
class Context:
    """What the cases of one suite run share: output folders, environment, caches.

    ``reference_grids`` maps a work-precision reference group (:func:`reference_group`) to
    the finest error grid of its cases in the run (:func:`reference_grids`): the group's
    event-driven reference is computed once on that grid and subsampled for the others.
    """

    suite: str
    out_dir: Path
    env: dict
    cache: dict = field(default_factory=lambda: PROCESS_CACHE)
    reference_grids: dict = field(default_factory=dict)

    @property
    def artefacts(self) -> Path:
        return self.out_dir / self.suite


def safe_name(case_id: str) -> str:
    """A file-name-safe version of a case id."""
    return re.sub(r"[^A-Za-z0-9_.=-]+", "_", case_id).strip("_")[:180]


def base_row(case: Case, sc) -> dict[str, Any]:
    """Declared fields of the case plus the effective scenario settings."""
    params = dict(case.params)
    return {
        "kind": case.kind, "scenario": case.scenario, "name": case.name,
        "params": ", ".join(f"{k}={v}" for k, v in case.params) or "",
        "solver": case.solver, "law": sc.law.law if sc is not None else (case.law or ""),
        "h": sc.h if sc is not None else case.h, "t_end": sc.t_end if sc is not None else case.t_end,
        "seed": case.seed, "N": params.get("param.N"),
        "n": sc.system.n if sc is not None else None, "m": sc.system.m if sc is not None else None,
    }


def _timed(fn, *args, **kwargs):
    """``(fn(...), CPU seconds, wall seconds)``. (No ``gc.collect()`` before: with cvxpy and
    pandas loaded a full collection costs more than most runs.)"""
    c0, w0 = time.process_time(), time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.process_time() - c0, time.perf_counter() - w0


def simulate(sc, case: Case, **kwargs):
    """:func:`observer.simulate` with the case's integrator and engine (:func:`engine_kwargs`),
    timed: ``(result, cpu seconds, wall seconds)``."""
    if case.integrator == "event":
        kwargs = {k: v for k, v in kwargs.items() if k not in ("solver", "record_every")}
        return _timed(observer.simulate, sc, integrator="event", **{**engine_kwargs(case), **kwargs})
    kwargs = {**engine_kwargs(case, kwargs.get("solver")), **kwargs}
    return _timed(observer.simulate, sc, **kwargs)


def engine_kwargs(case: Case, solver: str | None = None) -> dict[str, str]:
    """The engine keyword of a case (run with contact solver ``solver``, default the case's):
    its declared :attr:`~bench.suites.Case.engine`; else none for the event integrator or
    when the engine registry's first engine has the solver (the registry's first that accepts
    the run), else the engine :func:`bench.suites.engine_for` names."""
    from observer.engines import ENGINES

    if case.engine is not None:
        return {"engine": case.engine}
    if case.integrator == "event":
        return {}
    chosen = engine_for(solver or case.solver)
    return {} if chosen == next(iter(ENGINES)) else {"engine": chosen}


def engine_columns(res) -> dict[str, Any]:
    """Engine, matrix structure and the loop's own wall time (from the result's metadata)."""
    md = res.metadata
    steps = md.get("steps") or 0
    loop = md.get("wall_time_s", float("nan"))
    engine = "event" if md.get("integrator") == "event" else md.get("engine", "python")
    return {"engine": engine, "structure": md.get("structure", ""),
            "loop_time_s": loop, "loop_per_step_s": loop / steps if steps else float("nan"),
            "run_compile_time_s": md.get("compile_time_s", 0.0),
            "solver_fallbacks": md.get("solver_fallbacks", 0)}


def _finish(rows: list[dict], ctx: Context) -> list[dict]:
    """The rows, each checked against its kind's schema (:mod:`observer.row_schema`), with the date
    and the environment."""
    date = now_iso()
    return [{**check_row(r), "date": date, **ctx.env} for r in rows]


def run_case(case: Case, ctx: Context) -> list[dict]:
    """Run one case; return its rows (environment and date included)."""
    runner = {"observers": run_observers, "work_precision": run_work_precision,
              "robustness": run_robustness, "scaling": run_scaling, "checks": run_checks,
              "peers": run_peers, "hard": run_hard, "ensemble": run_ensemble}[case.kind]
    return _finish(runner(case, ctx), ctx)


# --------------------------------------------------------------------------------- observers
def _slaves(case: Case, sc, names) -> list[Slave]:
    if case.slave_offset is None:
        return list(names)
    dq, du = (np.asarray(x, dtype=float) for x in case.slave_offset)
    return [Slave(name, OBSERVER_DESIGNS[name].position_jumps, sc.q0 + dq, sc.u0 + du,
                  OBSERVER_DESIGNS[name]) for name in names]


REQUIRED_COLUMNS = {kind: tuple(settle_column(r) for r in RHOS) for kind in ("observers", "robustness")}
"""Columns every row of a kind must have; rows written before a column existed are moved
to the stale file and their cases rerun (:func:`bench.run.run_suite`)."""


def sync_metrics(res, name: str) -> dict[str, Any]:
    """Synchronization metrics of observer ``name`` in a result (window = coupling window).

    Per threshold ρ in :data:`observer.metrics.RHOS`: ``t_sync_ρ`` the first passage of
    V ≤ ρ·V(t_on), ``t_settle_ρ`` the settling time (V stays below until t_off) and
    ``above_after_ρ`` the fraction of window samples after the first passage with V back
    above the threshold.
    """
    row = res.synchronization(RHOS).set_index("observer").loc[name].to_dict()
    s = res.slaves[name]
    t_on, t_off = float(row["t_on"]), float(row["t_off"])
    for rho in RHOS:
        row[settle_column(rho)] = settling_time(res.t, s.V, rho, t_on, t_off)
        row[above_column(rho)] = excursions_after_passage(res.t, s.V, rho, t_on, t_off)
    V_on = row["V_on"]
    row.update(
        floor_rel=row["floor"] / V_on if V_on > 0 else float("nan"),
        V_end_rel=row["V_end"] / V_on if V_on > 0 else float("nan"),
        e_q_end=float(np.max(np.abs(s.q[-1] - res.q[-1]))),
        e_u_end=float(np.max(np.abs(s.u[-1] - res.u[-1]))),
        chi_closings=switchings(res.chi) if res.chi is not None else 0,
        V_min=float(np.min(s.V)),
        master_closed_fraction=float(res.active[1:].any(axis=1).mean()),
    )
    return row


def _plot_frame(res, dof: int, contact: int) -> pd.DataFrame:
    stride = max(1, int(np.ceil(res.t.size / MAX_PLOT_POINTS)))
    sel = np.arange(0, res.t.size, stride)
    if sel[-1] != res.t.size - 1:
        sel = np.append(sel, res.t.size - 1)
    t = res.t[sel]
    sysm = res.system
    cols = {"t": t, "master_q": res.q[sel, dof], "master_u": res.u[sel, dof],
            "master_g": sysm.gaps(res.q[sel], t)[:, contact]}
    for name, s in res.slaves.items():
        cols[f"{name}_q"] = s.q[sel, dof]
        cols[f"{name}_u"] = s.u[sel, dof]
        cols[f"{name}_g"] = sysm.gaps(s.q[sel], t)[:, contact]
        cols[f"V_{name}"] = s.V[sel]
    return pd.DataFrame(cols)


def run_observers(case: Case, ctx: Context) -> list[dict]:
    """Each observer in its own run with the master (so ``cpu_time_s`` = master + that
    observer); rows carry the synchronization metrics; a downsampled trajectory of the
    master and all observers is saved for the report's figures."""
    sc = observer.load_scenario(case.scenario, case.overrides())
    dof, contact = plot_choice(case.scenario)
    rows, frames = [], []
    for name in case.observers:
        row = {**base_row(case, sc), "observer": name}
        if OBSERVER_DESIGNS[name].needs_spd_K and not sc.system.is_stiffness_definite():
            rows.append({**row, "status": "n/a",
                         "note": "K is not positive definite (K = 0 here): the K-metric "
                                 "projection q ← q − K⁻¹W L⁻¹g is undefined"})
            continue
        slaves = _slaves(case, sc, (name,))
        res, cpu, wall = simulate(sc, case, observers=slaves)
        steps = res.metadata["steps"]
        rows.append({**row, **sync_metrics(res, name), **engine_columns(res), "status": "ok", "note": "",
                     "cpu_time_s": cpu, "wall_time_s": wall, "steps": steps,
                     "steps_per_s": steps / cpu if cpu > 0 else float("nan"),
                     "cpu_scope": "master + this observer",
                     "contact_solves": res.metadata.get("contact_solves", 0),
                     "integrator": case.integrator, "plot_dof": dof, "plot_contact": contact})
        frames.append(_plot_frame(res, dof, contact))
    if frames:
        traj = frames[0]
        for f in frames[1:]:
            traj = traj.join(f[[c for c in f.columns if c not in traj.columns]])
        path = ctx.artefacts / "traj" / f"{safe_name(case.case_id)}.parquet"
        path.parent.mkdir(parents=True, exist_ok=True)
        traj.to_parquet(path, index=False)
        rel = str(path.relative_to(ctx.out_dir))
        for r in rows:
            r["trajectory"] = rel
    return rows


# ---------------------------------------------------------------------------- work-precision
def _warm_up_reference(m: int) -> None:
    """Compile the cvxpy problems of sizes 1..m once, so that no case pays the compile time."""
    solver = get_solver("reference")
    for k in range(1, min(m, 8) + 1):
        solver.solve(np.eye(k), -np.ones(k))


def record_every(h: float, h_record: float | None) -> int:
    """Steps between stored samples so that they are ``h_record`` apart (1 when h ≥ h_record).

    Raises
    ------
    InputError
        ``h_record`` is not an integer multiple of ``h``.
    """
    if h_record is None or h >= h_record * (1 - 1e-9):
        return 1
    k = int(round(h_record / h))
    if abs(h_record / h - k) > 1e-6 * k:
        raise InputError("h_record", f"h_record = {h_record} is not an integer multiple of h = {h}")
    return k


def error_grid(case: Case) -> float:
    """Spacing of the grid a work-precision case's error is measured on:
    h · :func:`record_every` (h, h_record)."""
    return case.h * record_every(case.h, case.h_record)


def reference_group(case: Case) -> tuple:
    """Work-precision cases sharing one event-driven reference: same scenario, parameters,
    law and horizon, and the same measured trajectory (the master alone, or the master and
    the target observer: the reference runs no observer that nobody measures)."""
    observers = () if case.target == "master" else (case.target,)
    return (case.scenario, case.params, case.law, case.t_end, observers)


def reference_grids(cases) -> dict[tuple, float]:
    """Per reference group (:func:`reference_group`) of the ``event solution`` cases among
    ``cases``: the finest error grid (:func:`error_grid`). The sweeps halve h, so every
    coarser grid of the group is a power-of-two multiple of it."""
    grids: dict[tuple, float] = {}
    for c in cases:
        if c.kind == "work_precision" and c.reference == "event solution" and c.h is not None:
            g = reference_group(c)
            grids[g] = min(grids.get(g, np.inf), error_grid(c))
    return grids


REFERENCE_CACHE_SIZE = 6
"""Event-driven references kept per process (the sweeps of one scenario and law visit at
most master + 2 observer targets, twice: fast and reference contact solver)."""


@dataclass(frozen=True)
class EventReference:
    """An event-driven reference run, reduced to what the errors need: the grid ``t``, the
    master's positions ``q``, the observers' positions ``slaves`` (name → q), its ``spacing``
    and the CPU time of the run."""

    t: np.ndarray
    q: np.ndarray
    slaves: dict
    spacing: float
    cpu: float

    def every(self, k: int) -> "EventReference":
        """Every ``k``-th sample (the grid of spacing k·spacing)."""
        if k == 1:
            return self
        return EventReference(self.t[::k], self.q[::k], {n: q[::k] for n, q in self.slaves.items()},
                              self.spacing * k, self.cpu)


def _stride(spacing: float, fine: float) -> int | None:
    """``spacing / fine`` when it is a whole number ≥ 1 (to 1e-9 relative), else None."""
    k = round(spacing / fine)
    return k if k >= 1 and abs(spacing / fine - k) <= 1e-9 * k else None


def _event_reference(case: Case, spacing: float, ctx: Context) -> EventReference:
    """The exact event-driven run of the case's scenario (the master, and the target
    observer if the case measures one) sampled every ``spacing`` seconds.

    Computed once per process on the finest grid of the case's reference group in this run
    (``ctx.reference_grids``, when ``spacing`` is a whole multiple of it) and subsampled: the
    event integrator's samples are the exact flow at t_k = k·h, so the subsampled reference
    equals a run on the coarser grid to round-off (``tests/bench/test_suites.py``).
    """
    group = reference_group(case)
    fine = ctx.reference_grids.get(group, spacing)
    k = _stride(spacing, fine)
    if k is None:
        fine, k = spacing, 1
    key = ("wp-event", group, round(fine, 15))
    cache = ctx.cache
    if key not in cache:
        cached = [x for x in cache if isinstance(x, tuple) and x[0] == "wp-event"]
        for old in cached[:max(0, len(cached) - REFERENCE_CACHE_SIZE + 1)]:
            del cache[old]
        sc = observer.load_scenario(case.scenario, {**case.overrides(), "simulation.h": fine})
        observers = group[-1]
        res, cpu, _ = _timed(observer.simulate, sc, observers=observers, integrator="event")
        cache[key] = EventReference(res.t, res.q, {n: res.slaves[n].q for n in observers},
                                    fine, cpu)
    return cache[key].every(k)


def run_work_precision(case: Case, ctx: Context) -> list[dict]:
    """One step size of one method: error of the master (or of one observer) against the
    stated reference, and the CPU time of the run (master, plus the observer if measured)."""
    sc = observer.load_scenario(case.scenario, case.overrides())
    if case.solver == "reference":
        _warm_up_reference(sc.system.m)
    res, cpu, wall = simulate(sc, case, solver=case.solver, observers=case.observers,
                              record_every=record_every(case.h, case.h_record))
    q = res.q if case.target == "master" else res.slaves[case.target].q
    method = "event-driven" if case.integrator == "event" else case.solver
    row = {**base_row(case, sc), "target": case.target, "integrator": case.integrator,
           "method": f"{case.scenario} · {case.target} · {sc.law.law} · {method}",
           "norm": ERROR_NORM}
    if case.reference == "closed form":
        if case.target != "master":
            raise InputError("target", "a closed form exists only for the master")
        q_ref = closed_form_position(sc, res.t)
        if q_ref is None:
            raise InputError("reference", f"no closed form implemented for {case.scenario}")
        ref_text = info(case.scenario).reference_text or "closed form"
        ref_cpu, h_ref = float("nan"), None
    else:
        spacing = float(res.t[1] - res.t[0]) if res.t.size > 1 else case.h
        ref = _event_reference(case, spacing, ctx)
        if ref.t.shape != res.t.shape or np.max(np.abs(ref.t - res.t)) > 1e-9:
            raise InputError("reference", "the event solution's grid differs from the run's")
        q_ref = ref.q if case.target == "master" else ref.slaves[case.target]
        ref_cpu, h_ref = ref.cpu, ref.spacing
        ref_text = ("event solution (exact event-driven integrator, the master and the "
                    "measured observer, sampled on the run's grid)")
    steps = res.metadata["steps"]
    row.update(trajectory_error(res.t, q, q_ref))
    row.update(reference=ref_text, h_ref=h_ref, ref_cpu_time_s=ref_cpu, status="ok", note="",
               cpu_time_s=cpu, wall_time_s=wall, steps=steps,
               steps_per_s=steps / cpu if cpu > 0 else float("nan"),
               cpu_scope="master" if case.target == "master" else "master + this observer",
               contact_solves=res.metadata.get("contact_solves", 0), samples=int(res.t.size),
               error_grid_s=float(res.t[1] - res.t[0]) if res.t.size > 1 else case.h,
               **engine_columns(res))
    return [row]


# ------------------------------------------------------------------------------- robustness
def _base_log(sc, ctx: Context, key) -> pd.DataFrame:
    if key not in ctx.cache:
        res = observer.simulate(sc)
        ctx.cache[key] = log_from_active(res.t, res.active)
    return ctx.cache[key]


def run_robustness(case: Case, ctx: Context) -> list[dict]:
    """One level of one sensor perturbation as a paired ensemble over ``case.masters`` masters
    (:func:`_ensemble_masters`) × ``case.members`` initial errors, both designs
    (:func:`bench.perturb.robustness_case_rows`): one row per (design, master, member);
    ``cpu_time_s`` covers every master's sensed run and its members."""
    from bench.perturb import robustness_case_rows

    sc = observer.load_scenario(case.scenario, case.overrides())
    return [{**base_row(case, sc), **r} for r in robustness_case_rows(case, _ensemble_masters(case, sc))]


# ------------------------------------------------------------------------------- ensembles
ENSEMBLE_WORKERS = 1
"""Threads of one ensemble case (:func:`observer.ensemble`'s ``workers``): one, since a suite
already runs one case per core (Dask workers) and every extra thread re-runs the master."""


def _ensemble_scenario(case: Case, ctx: Context):
    """The case's scenario, and for a perturbed χ (``case.perturbation``) the same scenario with
    its observers driven by the master's closing log perturbed with the case's seed
    (:func:`bench.perturb.perturb_log`, written beside the results)."""
    sc = observer.load_scenario(case.scenario, case.overrides())
    if case.perturbation == "none":
        return sc
    base = _base_log(sc, ctx, ("log", case.scenario, case.params, case.law, case.h, case.t_end))
    log = perturb_log(base, case.perturbation, case.size, seed=case.seed, m=sc.system.m,
                      t_end=float(sc.t_end), h=sc.h)
    path = ctx.artefacts / "logs" / f"{safe_name(case.case_id)}.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    log.to_csv(path, index=False, float_format="%.17g")
    return sc.with_overrides({"observer.source": "log", "observer.log": str(path)})


def run_ensemble(case: Case, ctx: Context) -> list[dict]:
    """One ensemble (:func:`observer.ensemble`): ``case.members`` initial errors per design on
    the energy sphere of the scenario's own initial error (or of ``case.slave_offset`` where
    the scenario has no ``[observer]`` table), seeded by ``case.seed``; one row per (design,
    member). Designs that do not apply (the K-metric jump where K is singular) are left out
    and the note says so; ``cpu_time_s`` covers the whole ensemble (every design and member,
    and one more member per design started without error: its largest V in the window is the
    design's ``floor`` with this master, and the members' decay ``rate`` is fitted above it,
    :func:`observer.compare.member_fits`)."""
    from observer.ensemble import energy_metric

    sc = _ensemble_scenario(case, ctx)
    definite = sc.system.is_stiffness_definite()
    designs = tuple(d for d in case.observers if definite or not OBSERVER_DESIGNS[d].needs_spd_K)
    skipped = sorted(set(case.observers) - set(designs))
    V0 = None
    if case.slave_offset is not None:
        x = np.concatenate([np.asarray(a, dtype=float) for a in case.slave_offset])
        V0 = 0.5 * float(x @ energy_metric(sc) @ x)
    frames, cpu, wall = [], 0.0, 0.0
    for j, (sc_j, n_j, rng) in enumerate(_ensemble_masters(case, sc)):
        df_j, c, w = _ensemble_members(case, sc_j, designs, n_j, rng, V0)
        df_j["member"] += sum(len(f) for f in frames) // len(designs)
        frames.append(df_j.assign(master=j))
        cpu, wall = cpu + c, wall + w
    df = pd.concat(frames, ignore_index=True)
    base = {**base_row(case, sc), "members": case.members, "perturbation": case.perturbation,
            "size": case.size, "cpu_time_s": cpu, "wall_time_s": wall,
            "cpu_scope": f"whole ensemble: {len(designs)} designs × {case.members} members"
                         + (f" over {case.masters} masters" if case.masters > 1 else ""),
            "note": f"not applicable (K singular): {', '.join(skipped)}" if skipped else ""}
    if case.paths:
        base["paths"] = ensemble_paths(case, ctx, sc, designs, df)
    return [{**rec, **base, "status": str(rec["status"])}     # base: the case's seed, n, name
            for rec in df.to_dict("records")]


MASTER_SPREAD = 0.05
"""Size of the extra masters' initial-state perturbations (:func:`observer.compare.master_scenarios`)."""


def _ensemble_masters(case: Case, sc):
    """``(scenario, members, rng)`` per master of the case: the scenario's own and
    ``case.masters − 1`` sampled around it (seeded by the case's seed), ``case.members`` split
    evenly (the first masters take the remainder); one master: the scenario, every member,
    the case's seed (as before masters existed)."""
    if case.masters <= 1:
        return [(sc, case.members, np.random.default_rng(case.seed))]
    from observer.compare import master_scenarios

    master_ss, *member_ss = np.random.SeedSequence(case.seed).spawn(case.masters + 1)
    scs = master_scenarios(sc, case.masters, MASTER_SPREAD, 0.0, np.random.default_rng(master_ss))
    sizes = [case.members // case.masters + (j < case.members % case.masters) for j in range(case.masters)]
    return [(s, k, np.random.default_rng(ss)) for s, k, ss in zip(scs, sizes, member_ss)]


def _ensemble_members(case: Case, sc, designs, n: int, rng, V0):
    """One master's n members (and the zero-error member whose V is each design's floor):
    the rows with their decay ``rate`` (:func:`observer.compare.member_fits`), CPU and wall time."""
    from observer.compare import member_fits
    from observer.ensemble import sample_errors

    X, _ = sample_errors(sc, n, "energy_sphere", rng, V0)
    X = np.vstack([X, np.zeros((1, X.shape[1]))])          # member n: no error (the design's floor)
    df, cpu, wall = _timed(observer.ensemble, sc, designs, n=n + 1, initial_errors=X, paths=n + 1,
                           integrator=case.integrator, label=case.name, workers=ENSEMBLE_WORKERS,
                           engine=case.engine)
    fits, floors = member_fits(sc, df, n, designs)
    fits = fits[["design", "member", "rate", "points", "t_fit", "floor_stop"]].rename(
        columns={"points": "rate_points", "t_fit": "rate_t_fit", "floor_stop": "rate_floor_stop"})
    df = df[df["member"] < n].merge(fits, on=["design", "member"], validate="one_to_one").merge(floors, on="design")
    return df, cpu, wall


SUMMARY_EVERY_STEP = 40_000
"""Below this many steps an ensemble's summary run with paths records every step
(:func:`observer.ensemble`'s sampling keeps at most 20 000 rows)."""
PATH_POINTS = 250
"""Samples of V(t) kept per stored member (evenly spaced in steps, the first and last
included): enough for a band on a log axis, ≈ 40 kB of Parquet per design."""


def thin_paths(paths: pd.DataFrame, points: int = PATH_POINTS) -> pd.DataFrame:
    """The rows of ``paths`` (long format: design, member, t, V, every member on the same grid)
    at ``points`` evenly spaced samples of the grid, the first and the last included."""
    t = np.unique(paths["t"].to_numpy(dtype=float))
    keep = t[np.unique(np.linspace(0, t.size - 1, min(points, t.size)).round().astype(int))]
    return paths[paths["t"].isin(keep)].reset_index(drop=True)


def ensemble_paths(case: Case, ctx: Context, sc, designs: tuple[str, ...], df: pd.DataFrame) -> str:
    """V(t) of the first ``case.paths`` members of every design, for the report's bands: one more
    :func:`observer.ensemble` run of the same master with those members' initial errors (read
    from the rows ``df``; the members are independent given χ, so each path is the member's
    own run), thinned by :func:`thin_paths` and written to ``<suite>/paths/<case>.parquet``.
    Run after the timed ensemble (its ``cpu_time_s`` is not charged). Returns the file's path
    relative to the results folder (the rows' ``paths`` column)."""
    nd = sc.system.n
    own = df["master"] == 0 if "master" in df else True                # the paths rerun the scenario's master
    first = df[(df["design"] == designs[0]) & own].sort_values("member").head(case.paths)
    X = first[[f"dq0_{j}" for j in range(nd)] + [f"du0_{j}" for j in range(nd)]].to_numpy(dtype=float)
    # a summary run of fewer than 40 000 steps keeps every step anyway: "full" stores the same
    # rows (and the paths' ΔV parts); from 40 000 steps the summary's sampled V(t) suffices
    store = "full" if sc.t_end / sc.h < SUMMARY_EVERY_STEP else "summary"
    run = observer.ensemble(sc, designs, n=len(X), initial_errors=X, paths=len(X), store=store,
                            integrator=case.integrator, label=case.name, workers=ENSEMBLE_WORKERS,
                            engine=case.engine)
    paths = thin_paths(run.attrs["paths"])
    paths["member"] = first["member"].to_numpy()[paths["member"].to_numpy()]
    path = ctx.artefacts / "paths" / f"{safe_name(case.case_id)}.parquet"
    path.parent.mkdir(parents=True, exist_ok=True)
    paths.to_parquet(path, index=False)
    return str(path.relative_to(ctx.out_dir))


# ---------------------------------------------------------------------------------- scaling
SETUP_STEPS = 10
"""Steps of the short run whose CPU time is subtracted in :func:`run_scaling` (the per-call
setup: scenario matrices, banded factorization, Ĝ = WᵀÂ⁻¹W, the grid)."""


def whole_call(case: Case) -> dict[str, float]:
    """The user's whole call timed as one (issue 23): ``load_scenario`` (builder, document,
    validation) then ``simulate`` (setup, loop, health) of the master, as in the README;
    run after the case's first run, so that no compilation falls on it. Columns
    ``whole_call_cpu_s``, ``whole_call_wall_s`` and its part ``load_cpu_s``."""
    c0, w0 = time.process_time(), time.perf_counter()
    sc = observer.load_scenario(case.scenario, case.overrides())
    c1 = time.process_time()
    observer.simulate(sc, **engine_kwargs(case), record_every=record_every(case.h, case.h_record))
    return {"whole_call_cpu_s": time.process_time() - c0, "whole_call_wall_s": time.perf_counter() - w0,
            "load_cpu_s": c1 - c0}


def run_scaling(case: Case, ctx: Context) -> list[dict]:
    """The chain master alone: CPU time per step, with the per-call setup subtracted; the whole
    call (:func:`whole_call`); then the same run under tracemalloc for the peak traced memory (NumPy allocations included:
    matrices, grid, trajectories).

    ``cpu_per_step_s = (CPU(T) − CPU(10 h)) / (steps − 10)``: the CPU time of a 10-step run of
    the same scenario (same setup, its grid is shorter; run second, so that first-call costs
    fall on the long run) is taken off, so the fitted exponent is the step's, not the setup's
    (at N = 1000 the setup is ≈ 1 s, the order of 4000 steps). A run too short for the
    difference to be positive keeps CPU / steps (``cpu_scope`` says so).
    ``cpu_per_step_total_s`` keeps the plain CPU / steps, ``loop_per_step_s`` the loop's own
    wall time per step (metadata).
    """
    sc = observer.load_scenario(case.scenario, case.overrides())
    every = record_every(case.h, case.h_record)      # large N: rows every h_record (bounded memory)
    res, cpu, wall = simulate(sc, case, record_every=every)
    short = sc.with_overrides({"simulation.t_end": SETUP_STEPS * sc.h})
    _, cpu_setup, _ = simulate(short, case)          # after the main run: no first-call costs
    steps = res.metadata["steps"]
    closed = res.active[1:]
    per_step = (cpu - cpu_setup) / (steps - SETUP_STEPS) if steps > SETUP_STEPS else float("nan")
    scope = "master only, setup subtracted"
    if not per_step > 0:                              # a run too short to resolve the setup
        per_step, scope = cpu / steps, "master only, setup included (not resolved)"
    row = {**base_row(case, sc), "status": "ok", "note": "", "steps": steps,
           "cpu_time_s": cpu, "wall_time_s": wall, "setup_cpu_time_s": cpu_setup, "setup_steps": SETUP_STEPS,
           "cpu_per_step_s": per_step, "cpu_per_step_total_s": cpu / steps,
           "wall_per_step_s": wall / steps, "steps_per_s": 1.0 / per_step,
           "cpu_scope": scope, "contact_solves": res.metadata["contact_solves"],
           "closed_step_fraction": float(closed.any(axis=1).mean()),
           "mean_active": float(closed.sum(axis=1).mean()),
           "max_active": int(closed.sum(axis=1).max()), **engine_columns(res)}
    del res
    row.update(whole_call(case))
    if case.memory:
        gc.collect()
        tracemalloc.start()
        try:
            observer.simulate(sc, **engine_kwargs(case), record_every=every)
            _, peak = tracemalloc.get_traced_memory()
        finally:
            tracemalloc.stop()
        row["peak_mem_mb"] = peak / 1e6
        row["trajectory_mb"] = (steps // every + 1) * (3 * sc.system.n + 3 * sc.system.m) * 8 / 1e6
    return [row]


# ------------------------------------------------------------------------------------ peers
PEER_REPEATS = 5
"""Timing runs on each side of a peer case; the rows hold their medians."""


def run_peers(case: Case, ctx: Context) -> list[dict]:
    """Siconos and the toolkit on one peer problem (:func:`bench.peers.run_peer`); one row.

    Without Siconos the case is :class:`Unavailable` (no row is written, a later run retries
    it) and the message says how to get Siconos. The toolkit side runs on the compiled engine.
    """
    from bench import peers

    key = ("siconos", peers.SICONOS_PYTHON)          # per interpreter: the cache outlives a run
    ok, info = ctx.cache.get(key) or ctx.cache.setdefault(key, peers.siconos_available())
    if not ok:
        raise Unavailable(f"Siconos absent: {info}")
    N = int(dict(case.params).get("param.N", 10))
    problem = peers.peer_problem(case.scenario, h=case.h, t_end=case.t_end, N=N)
    row = peers.run_peer(problem, repeats=PEER_REPEATS, engine=None).iloc[0].to_dict()
    if row.get("status") != "ok":
        raise Unavailable(f"Siconos absent: {row.get('status')}")
    out = {**base_row(case, None), **row, "kind": "peers", "name": case.name,
           "N": N if case.scenario == "rocking_chain" else None,
           "cpu_scope": "median wall time per step of the repeats (both sides)"}
    return [out]


# ------------------------------------------------------------------------------------- hard
def run_hard(case, ctx: Context) -> list[dict]:
    """One hard case (:func:`bench.hard.run_hard`): one row."""
    from bench import hard

    return hard.run_hard(case, ctx)


# ----------------------------------------------------------------------------------- checks
def run_checks(case: Case, ctx: Context) -> list[dict]:
    """All registered proof checks of :mod:`proofs_checks` on the scenario (one row each)."""
    import proofs_checks

    c0, w0 = time.process_time(), time.perf_counter()
    df = proofs_checks.results_frame(proofs_checks.run_checks(case.scenario, seed=case.seed))
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    base = base_row(case, observer.load_scenario(case.scenario, case.overrides()))
    rows = []
    for rec in df.to_dict("records"):
        passed = rec.get("passed")
        rows.append({**base, "check": str(rec.get("check", "")),
                     "equation": str(rec.get("equation", "") or ""),
                     "check_status": str(rec.get("status", "")),
                     "passed": None if passed is None or (isinstance(passed, float) and np.isnan(passed))
                     else bool(passed),
                     "margin": _float(rec.get("margin")), "tolerance": _float(rec.get("tolerance")),
                     "witness": str(rec.get("witness", "") or ""),
                     "reason": str(rec.get("reason", "") or ""),
                     "check_elapsed_s": _float(rec.get("elapsed")),
                     "evidence": _text(rec.get("evidence")),
                     "verdict": _text(rec.get("verdict")),
                     "status": "ok", "note": "", "cpu_time_s": cpu, "wall_time_s": wall,
                     "cpu_scope": "all checks of the scenario"})
    return rows


def _text(x) -> str:
    """A text column of a results-frame row: "" for None or NaN (a frame's missing value)."""
    return "" if x is None or (isinstance(x, float) and np.isnan(x)) else str(x)


def _float(x) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")
