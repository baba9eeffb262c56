"""Ensembles of initial errors: one master run drives n observers per design.

:func:`ensemble` samples n initial errors ``x = (e, v) = (q̂(0) − q(0), û(0) − u(0))`` (or takes
them as an array), builds one :class:`~observer.observers.Slave` per (design, member) started
from the master's initial state plus that member's error, and computes every member's
streaming summary (``store="summary"``) against one master run: the observers of one run are
independent given χ (paper eqs. (7)-(11)). The same n errors are used for every design
(paired), and member i of a design is, step for step, the observer of a single
:func:`~observer.simulate.simulate` started from that member's state.

The time-stepped summary runs the master once and then each member alone over the whole grid
(:mod:`observer.members`), the members in ``workers`` contiguous chunks, one thread each (the
compiled loop releases the GIL, ``nogil``). Runs that path does not cover (banded systems,
a failing step, V(t) paths with ``store="full"``, the event integrator) run the master with
a chunk of members in the kernel (:func:`observer.simulate`), one chunk per thread, each with
its own copy of the master, bitwise the same.
"""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from observer.errors import InputError
from observer.metrics import RHOS, settle_column, sync_column, settling_time, sync_time
from observer.observers import OBSERVER_DESIGNS, Slave
from observer.scenario import Scenario, load_scenario
from observer.validation import as_scalar, check_output_path

SAMPLERS = ("energy_sphere", "box")
"""Named samplers of the initial errors (else an array of shape (n, 2·dof))."""

INTEGRATOR_NAMES = {"time-stepping": "time-stepping", "event": "event"}
"""Accepted values of ``integrator`` (the :func:`observer.simulate` integrator each means)."""

DEPRECATED_INTEGRATOR_NAMES = {"timestepping": "time-stepping"}
"""Old spellings of ``integrator``: accepted with a :class:`DeprecationWarning`."""

PATH_VALUES = 1 << 24
"""Most recorded state values a chunk keeps when ``paths > 0`` (its rows of q, u, P and σ of
every system): the V(t) paths are sampled every ``record_every`` steps to stay below it."""


# ---------------------------------------------------------------------------------------
# the initial errors
# ---------------------------------------------------------------------------------------
def scenario_error(sc: Scenario) -> np.ndarray:
    """The scenario's own observer initial error ``(q̂(0) − q(0), û(0) − u(0))`` (2·dof,), zero
    without an ``[observer]`` state."""
    n = sc.system.n
    q = np.asarray(sc.observer.get("q", sc.q0), dtype=float).reshape(n)
    u = np.asarray(sc.observer.get("u", sc.u0), dtype=float).reshape(n)
    return np.concatenate([q - sc.q0, u - sc.u0])


def energy_metric(sc: Scenario) -> np.ndarray:
    """The block-diagonal metric ``A = diag(K_e, M)`` of the sphere ``½xᵀAx = V0`` (2·dof, 2·dof).

    ``K_e = K`` when K ≻ 0 (then ½xᵀAx is the error Lyapunov function V of paper (16)). When
    K is not positive definite (a free body, K = 0), the position part is measured in
    ``K_e = K + μM`` with ``μ = max(tr K / tr M, 1) s⁻²``, so that every direction of e has a
    positive size; V(0) then differs from V0 by the ½μeᵀMe part.
    """
    from observer.sparse import dense

    M, K = dense(sc.system.M), dense(sc.system.K)
    if not sc.system.is_stiffness_definite():
        K = K + max(float(np.trace(K) / np.trace(M)), 1.0) * M
    n = M.shape[0]
    A = np.zeros((2 * n, 2 * n))
    A[:n, :n], A[n:, n:] = K, M
    return A


def sample_errors(sc: Scenario, n: int, sampler: Any, rng: np.random.Generator,
                  V0: float | None) -> tuple[np.ndarray, float | None]:
    """The (n, 2·dof) initial errors ``[e, v]`` and the V0 used (None for "box" and arrays).

    * ``"energy_sphere"``: ``x = √(2V0) L⁻ᵀ z/‖z‖`` with z standard normal and ``A = LLᵀ``
      (:func:`energy_metric`): a uniform direction in the whitened coordinates, on the
      ellipsoid ``½xᵀAx = V0`` exactly (to round-off). V0 defaults to ½x₀ᵀAx₀ of the
      scenario's own error x₀ (:func:`scenario_error`).
    * ``"box"``: uniform in the box ``|x_j| ≤ |x₀_j|``.
    * an array (n, 2·dof): taken as it is (finite numbers).

    Raises
    ------
    InputError
        Naming ``initial_errors`` (unknown sampler, wrong shape, non-finite, empty box) or
        ``V0`` (not positive, or no default: the scenario has no initial error).
    """
    dim = 2 * sc.system.n
    if isinstance(sampler, str):
        if sampler not in SAMPLERS:
            raise InputError("initial_errors", f"must be one of {list(SAMPLERS)} or an array "
                                               f"(n, {dim}), got {sampler!r}")
        x0 = scenario_error(sc)
        if sampler == "box":
            if not np.any(x0):
                raise InputError("initial_errors", f'"box" takes its half-widths from the scenario\'s '
                                                   f"[observer] initial error, which is zero in {sc.name!r}")
            return rng.uniform(-1.0, 1.0, size=(n, dim)) * np.abs(x0), None
        A = energy_metric(sc)
        if V0 is None:
            V0 = 0.5 * float(x0 @ A @ x0)
            if not V0 > 0.0:
                raise InputError("V0", f"scenario {sc.name!r} has no [observer] initial error to take "
                                       "V0 from: give V0 > 0")
        z = rng.standard_normal((n, dim))
        z /= np.linalg.norm(z, axis=1)[:, None]
        Lc = np.linalg.cholesky(A)
        X = np.sqrt(2.0 * V0) * np.linalg.solve(Lc.T, z.T).T
        return X, float(V0)
    try:
        X = np.array(sampler, dtype=float)
    except (TypeError, ValueError):
        raise InputError("initial_errors", f"must be one of {list(SAMPLERS)} or an array of numbers "
                                           f"(n, {dim})") from None
    if X.shape != (n, dim):
        raise InputError("initial_errors", f"must have shape (n, 2·dof) = ({n}, {dim}), got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise InputError("initial_errors", "must be finite numbers")
    return X, None


# ---------------------------------------------------------------------------------------
# the arguments
# ---------------------------------------------------------------------------------------
def _check_designs(designs: Any) -> tuple[str, ...]:
    if isinstance(designs, str):
        designs = (designs,)
    try:
        designs = tuple(designs)
    except TypeError:
        raise InputError("designs", f"must be observer design names, got {designs!r}") from None
    if not designs:
        raise InputError("designs", "needs at least one observer design")
    for d in designs:
        if not isinstance(d, str) or d not in OBSERVER_DESIGNS:
            raise InputError("designs", f"unknown observer design {d!r}; choose from {sorted(OBSERVER_DESIGNS)}")
    if len(set(designs)) != len(designs):
        raise InputError("designs", f"must be unique, got {list(designs)}")
    return designs


def _count(field: str, value: Any, low: int) -> int:
    """``value`` as an int ≥ low, or InputError naming ``field``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < low:
        raise InputError(field, f"must be an integer ≥ {low}, got {value!r}")
    return int(value)


MEMBER_BYTES = 4096
"""Bytes one (design, member) takes besides its states, with a margin: its observer, its
summary row and its share of the frame (an estimate, about twice the peak-memory growth per
member of a double_mass ensemble)."""


def check_member_memory(n: int, designs: int, dof: int) -> None:
    """Raise before sampling when n members of ``designs`` designs would not fit in the
    memory available (:func:`observer.memory.available_memory`): each takes
    :data:`MEMBER_BYTES` plus its error and two initial states, 8 bytes per entry. The error
    names ``n`` (``ensemble --n``); without it ``--n 10000000`` ran out of memory after
    minutes."""
    from observer import memory

    need = n * designs * (MEMBER_BYTES + 8 * 4 * dof)
    avail = memory.available_memory()
    if avail is not None and need > avail:
        raise InputError("n", f"{n} members × {designs} design(s) need about {need / 2 ** 30:.3g} GiB "
                         f"({MEMBER_BYTES + 32 * dof} bytes each, estimated) but {avail / 2 ** 30:.3g} GiB "
                         "are available: fewer members, or several runs with different seeds")


SEED_MAX = 2 ** 63 - 1
"""Largest seed: the rows' ``seed`` column is a 64-bit integer (pandas ``Int64``)."""


def _generator(seed: Any, rng: Any) -> tuple[np.random.Generator, int | None]:
    """The generator and the seed recorded in the rows (None when a Generator was given)."""
    if rng is not None:
        if not isinstance(rng, np.random.Generator):
            raise InputError("rng", f"must be a numpy.random.Generator, got {rng!r}")
        return rng, None
    if isinstance(seed, np.random.Generator):
        return seed, None
    seed = _count("seed", seed, 0)
    if seed > SEED_MAX:
        raise InputError("seed", f"must be at most 2^63 - 1 = {SEED_MAX} (the rows record it as a "
                                 f"64-bit integer), got {seed}")
    return np.random.default_rng(seed), seed


def integrator_name(integrator, stacklevel: int = 3) -> str:
    """``integrator`` as :func:`observer.simulate` names it: an old spelling
    (:data:`DEPRECATED_INTEGRATOR_NAMES`) with a :class:`DeprecationWarning`, anything else
    not in :data:`INTEGRATOR_NAMES` an :class:`InputError` naming ``integrator``."""
    if isinstance(integrator, str) and integrator in DEPRECATED_INTEGRATOR_NAMES:
        import warnings
        new = DEPRECATED_INTEGRATOR_NAMES[integrator]
        warnings.warn(f"integrator {integrator!r} is spelled {new!r}; the old spelling will be removed",
                      DeprecationWarning, stacklevel=stacklevel + 1)
        integrator = new
    if not isinstance(integrator, str) or integrator not in INTEGRATOR_NAMES:
        raise InputError("integrator", f"must be one of {sorted(INTEGRATOR_NAMES)}, got {integrator!r}")
    return INTEGRATOR_NAMES[integrator]


def _check_options(integrator, store, paths, n, workers, out):
    """Normalize integrator, store, paths, workers, out; InputError naming the keyword."""
    integrator = integrator_name(integrator, stacklevel=4)
    if store not in ("summary", "full"):
        raise InputError("store", f'must be "summary" or "full", got {store!r}')
    if integrator == "event":
        store = "full"                  # the event engine samples every grid point
    paths = _count("paths", paths, 0)
    if paths > n:
        raise InputError("paths", f"must be at most n = {n}, got {paths}")
    workers = (os.cpu_count() or 1) if workers is None else _count("workers", workers, 1)
    if out is not None:
        out = check_output_path("out", out, (".parquet",))
    return integrator, store, paths, workers, out


def _load(scenario, h, t_end, model=None) -> Scenario:
    """The scenario with the step, horizon and observer model (:func:`observer.plant_model.with_model`)
    of the call."""
    from observer.plant_model import with_model

    for name, value in (("h", h), ("t_end", t_end)):
        if value is not None:
            as_scalar(name, value, positive=True)
    sc = load_scenario(scenario)
    over = {f"simulation.{k}": v for k, v in (("h", h), ("t_end", t_end)) if v is not None}
    return with_model(sc.with_overrides(over) if over else sc, model)


def _load_sensed(scenario, h, t_end, sensor, integrator: str, engine,
                 model=None) -> tuple[Scenario, dict | None]:
    """:func:`_load`, then every member's χ from the contact sensor ``sensor`` (the
    ``[observer.sensor]`` keys, replacing the scenario's table) on the one master
    (:func:`observer.simulate.sensed_scenario`); ``model`` the observers' own model
    (:func:`observer.plant_model.with_model`). Returns the scenario and the sensor's
    settings (None: ideal; else ``attrs["metadata"]["sensor"]``)."""
    from observer.simulate import sensed_scenario
    return sensed_scenario(_load(scenario, h, t_end, model), sensor, integrator, engine=engine)


# ---------------------------------------------------------------------------------------
# the runs
# ---------------------------------------------------------------------------------------
def member_name(design: str, i: int) -> str:
    """The observer name of member i of ``design`` in the ensemble's runs: ``jump#17``."""
    return f"{design}#{i}"


def member_slaves(sc: Scenario, designs: tuple[str, ...], X: np.ndarray, members) -> list[Slave]:
    """One :class:`Slave` per (design, member), design-major, started from the master's
    initial state plus the member's error ``X[i] = [e, v]``."""
    nd = sc.system.n
    return [Slave(member_name(d, i), OBSERVER_DESIGNS[d].position_jumps, sc.q0 + X[i, :nd],
                  sc.u0 + X[i, nd:], OBSERVER_DESIGNS[d]) for d in designs for i in members]


def _record_every(sc: Scenario, systems: int, paths: int) -> int:
    """Rows the summary run keeps: the first and last only without paths; else as many as
    :data:`PATH_VALUES` allows (q, u, P, σ of every system), at most one per step."""
    steps = int(round(sc.t_end / sc.h))
    if paths == 0:
        return max(1, steps)
    per_row = 2 * (sc.system.n + sc.system.m) * systems
    return max(1, steps // 20_000, -(-(steps + 1) * per_row // PATH_VALUES))


def _run_chunk(sc: Scenario, designs, X, members, integrator, store, engine, paths):
    """One :func:`observer.simulate` of the master with the chunk's members of every design."""
    from observer.simulate import simulate

    slaves = member_slaves(sc, designs, X, members)
    kw: dict[str, Any] = {"observers": slaves, "integrator": integrator, "engine": engine}
    if integrator == "time-stepping":
        kw.update(store=store, record_every=_record_every(sc, 1 + len(slaves), paths) if store == "summary"
                  else None)
    return simulate(sc, **kw)


def window_summary(t: np.ndarray, V: np.ndarray, t_on: float, t_off: float) -> dict:
    """The summary columns of one observer from V on the grid (the event integrator and
    ``store="full"``), with the definitions of :func:`observer.engines.loop.summary_frame`: V(t_on),
    max V over the window, V at the end, the window steps with V_{k+1} > V_k and the largest
    relative rise (V_{k+1} − V_k)/V_k (0 without a rise), first-passage and settling times per ρ
    of :data:`observer.metrics.RHOS` (:mod:`observer.metrics`)."""
    idx = np.flatnonzero((t >= t_on) & (t <= t_off))
    row = {"V_on": float("nan"), "V_max": float("nan"), "V_end": float(V[-1]), "rises": 0, "max_rise_rel": 0.0}
    if idx.size:
        Vw = V[idx]
        dV = np.diff(Vw)
        pos = (dV > 0.0) & (Vw[:-1] > 0.0)
        row.update(V_on=float(Vw[0]), V_max=float(np.max(Vw)), rises=int(np.sum(dV > 0.0)),
                   max_rise_rel=float(np.max(dV[pos] / Vw[:-1][pos])) if pos.any() else 0.0)
    for rho in RHOS:
        row[sync_column(rho)] = sync_time(t, V, rho, t_on, t_off)
        row[settle_column(rho)] = settling_time(t, V, rho, t_on, t_off)
    return row


SUMMARY_COLUMNS = ("V_on", "V_max", "V_end", "rises", "max_rise_rel",
                   *(c(rho) for rho in RHOS for c in (settle_column, sync_column)))
"""The per-member columns taken from the run (the kernel's summary or :func:`window_summary`)."""


def _chunk_rows(sc: Scenario, res, designs, members, store: str) -> dict[tuple[str, int], dict]:
    """(design, member) → its summary columns and status, from one chunk's result."""
    status = res.status.state.value
    out = {}
    if store == "summary":
        table = res.summary.set_index("observer")
        for d in designs:
            for i in members:
                r = table.loc[member_name(d, i)]
                out[d, i] = {"status": status, **{c: r[c] for c in SUMMARY_COLUMNS}, "rises": int(r["rises"])}
        return out
    t_on, t_off = sc.observer.get("coupling", (float(res.t[0]), float(res.t[-1])))
    for d in designs:
        for i in members:
            out[d, i] = {"status": status, **window_summary(res.t, res.slaves[member_name(d, i)].V,
                                                             float(t_on), min(float(t_off), float(res.t[-1])))}
    return out


def _chunks(n: int, workers: int) -> list[range]:
    """Contiguous member ranges, one per worker (at most n)."""
    k = min(workers, n)
    bounds = np.linspace(0, n, k + 1).round().astype(int)
    return [range(bounds[j], bounds[j + 1]) for j in range(k)]


def run_members(sc: Scenario, designs, X, integrator, store, engine, paths, workers):
    """Every (design, member): the time-stepped summary after one master run
    (:func:`_members_after_one_master`) when :mod:`observer.members` covers the run, else in
    ``workers`` chunks of members, each chunk one run (in a thread when more than one).
    Returns (rows by (design, member), paths frame or None)."""
    if integrator == "time-stepping" and store == "summary":
        fast = _members_after_one_master(sc, designs, X, engine, paths, workers)
        if fast is not None:
            return fast
        if sc.model is not None:            # the kernel's summary would measure V against its own master
            store = "full"
    chunks = _chunks(X.shape[0], workers)
    if integrator == "time-stepping" and len(chunks) > 1:
        from observer.engines.compiled.driver import compile_time
        compile_time()                      # once, before the threads
    run = lambda members: _run_chunk(sc, designs, X, members, integrator, store, engine, paths)  # noqa: E731
    if len(chunks) == 1:
        results = [run(chunks[0])]
    else:
        with ThreadPoolExecutor(max_workers=len(chunks)) as pool:
            results = list(pool.map(run, chunks))
    rows: dict[tuple[str, int], dict] = {}
    frames = []
    for members, res in zip(chunks, results):
        rows.update(_chunk_rows(sc, res, designs, members, store))
        for d in designs:
            for i in members:
                if i < paths:
                    frames.append(_path_frame(res, d, i))
    if not frames:
        return rows, None
    import pandas as pd

    return rows, pd.concat(frames, ignore_index=True)


def _members_after_one_master(sc: Scenario, designs, X, engine, paths: int, workers: int):
    """:func:`run_members` by :func:`observer.engines.compiled.members.member_summaries` (one master run, then
    every member alone over the grid); None when that path does not cover the run."""
    from observer.engines.compiled.members import member_summaries
    from observer.result import RunState

    n = X.shape[0]
    keys = [(d, i) for d in designs for i in range(n)]
    wanted = tuple(j for j, (d, i) in enumerate(keys) if i < paths)
    done = member_summaries(sc, member_slaves(sc, designs, X, range(n)), engine, workers, wanted)
    if done is None:
        return None
    table, traces = done
    rows = {key: {"status": RunState.OK.value, **{c: r[c] for c in SUMMARY_COLUMNS}, "rises": int(r["rises"])}
            for key, r in zip(keys, table)}
    if not traces:
        return rows, None
    import pandas as pd

    frames = [pd.DataFrame({"design": keys[j][0], "member": keys[j][1], "t": t, "V": V})
              for j, (t, V) in traces.items()]
    return rows, pd.concat(frames, ignore_index=True)


def _path_frame(res, design: str, i: int):
    import pandas as pd

    V = res.slaves[member_name(design, i)].V
    return pd.DataFrame({"design": design, "member": i, "t": np.asarray(res.t, dtype=float), "V": V})


# ---------------------------------------------------------------------------------------
# the entry point
# ---------------------------------------------------------------------------------------
def ensemble(scenario: str | Path | Scenario, designs=("jump", "nojump"), n: int = 1000, *, seed=0,
             rng: np.random.Generator | None = None, initial_errors: Any = "energy_sphere",
             V0: float | None = None, h: float | None = None, t_end: float | None = None,
             integrator: str = "time-stepping", engine: str | None = None, store: str = "summary",
             paths: int = 0, workers: int | None = None, out: str | Path | None = None,
             label: str | None = None, sensor: dict | None = None, model: dict | None = None):
    """Run n observers per design from n initial errors against one master; one row per
    (design, member).

    Parameters
    ----------
    scenario : str, Path or Scenario
        Built-in name, TOML path or a loaded scenario.
    designs : sequence of str
        Observer designs of :data:`observer.OBSERVER_DESIGNS`; every design gets the same n
        initial errors (paired: member i of each design starts from the same error).
    n : int
        Members per design.
    seed : int or numpy.random.Generator
        Seed of the sampler (``rng``, a Generator, takes precedence).
    initial_errors : {"energy_sphere", "box"} or ndarray (n, 2·dof)
        The errors ``x = [e, v] = [q̂(0) − q(0), û(0) − u(0)]`` added to the master's initial
        state at t = 0 (:func:`sample_errors`): uniform directions on ``½eᵀKe + ½vᵀMv = V0``
        (paper (16); K not positive definite: :func:`energy_metric`), uniform in the box of the
        scenario's own error's half-widths, or given.
    V0 : float, optional
        The sphere's level (default: V of the scenario's own ``[observer]`` initial error).
    h, t_end, model : optional
        Override the scenario's step, horizon and observer model (:mod:`observer.plant_model`).
    integrator : {"time-stepping", "event"}
        Moreau–Jean time-stepping (the compiled kernel's streaming summary) or the exact
        event-driven engine (every member's V on the grid t_k = k·h, summarized here).
    engine : str, optional
        An engine of :data:`observer.ENGINES` (default: the first that accepts the run).
    store : {"summary", "full"}
        Time-stepping storage: ``"summary"`` (every step folded into the kernel's summary) or
        ``"full"`` (every step kept, summarized here by :func:`window_summary`).
    paths : int
        Keep V(t) of members 0..paths−1 of every design (``df.attrs["paths"]``, long format).
    workers : int, optional
        Threads, each advancing a contiguous chunk of the members (default: the machine's cores).
    out : str or Path, optional
        A ``.parquet`` file for the rows (and ``<stem>.paths.parquet`` with ``paths``).
    label : str, optional
        The scenario's variant label in the rows (default: its name).
    sensor : dict, optional
        ``[observer.sensor]`` keys: χ from a contact sensor on the master (:func:`_load_sensed`).

    Returns
    -------
    pandas.DataFrame
        One row per (design, member): scenario, label, design, member, integrator, h, t_end, seed,
        status, V_on, V_max, V_end, rises, max_rise_rel, ``t_settle_ρ`` and ``t_sync_ρ`` for ρ in
        :data:`observer.metrics.RHOS` (seconds from t_on; inf = never), and the member's error
        ``dq0_j``, ``du0_j``. ``attrs["metadata"]`` (JSON-serializable) and, with ``paths``,
        ``attrs["paths"]``.

    Raises
    ------
    InputError
        Naming the keyword (or the scenario's field) that is not valid.
    """
    t0 = time.perf_counter()
    designs = _check_designs(designs)
    n = _count("n", n, 1)
    gen, seed_value = _generator(seed, rng)
    integrator, store, paths, workers, out = _check_options(integrator, store, paths, n, workers, out)
    V0 = None if V0 is None else as_scalar("V0", V0, positive=True)
    sc, sensed = _load_sensed(scenario, h, t_end, sensor, integrator, engine, model)
    check_member_memory(n, len(designs), sc.system.n)
    X, V0_used = sample_errors(sc, n, initial_errors, gen, V0)
    rows, path_frame = run_members(sc, designs, X, integrator, store, engine, paths, workers)
    df = _frame(sc, sc.name if label is None else str(label), designs, X, rows, integrator, seed_value)
    df.attrs["metadata"] = _metadata(sc, designs, n, seed_value, initial_errors, V0_used, integrator, engine,
                                     store, workers, time.perf_counter() - t0, sensed)
    if path_frame is not None:
        df.attrs["paths"] = path_frame
    if out is not None:
        write_ensemble(df, out)
    return df


def _frame(sc, label, designs, X, rows, integrator, seed):
    """The tidy rows, design-major: identification, the run's summary, the member's error."""
    import pandas as pd

    nd, n = sc.system.n, X.shape[0]
    keys = [(d, i) for d in designs for i in range(n)]
    df = pd.DataFrame({"scenario": sc.name, "label": label, "design": [d for d, _ in keys],
                       "member": [i for _, i in keys], "integrator": integrator, "h": sc.h,
                       "t_end": sc.t_end, "seed": pd.array([seed] * len(keys), dtype="Int64")})
    first = rows[keys[0]]
    summary = pd.DataFrame({c: [rows[k][c] for k in keys] for c in first})
    errors = pd.DataFrame(np.tile(X, (len(designs), 1)),
                          columns=[f"dq0_{j}" for j in range(nd)] + [f"du0_{j}" for j in range(nd)])
    return pd.concat([df, summary, errors], axis=1)


def _metadata(sc, designs, n, seed, initial_errors, V0, integrator, engine, store, workers, wall,
              sensed=None) -> dict:
    from observer.result import package_versions

    meta = {"scenario": sc.name, "params": sc.parameters(), "designs": list(designs), "n": n, "seed": seed,
            "initial_errors": initial_errors if isinstance(initial_errors, str) else "array",
            "V0": V0, "h": sc.h, "t_end": sc.t_end, "integrator": integrator, "engine": engine,
            "store": store, "workers": workers, "versions": package_versions(), "wall_time_s": wall}
    if sensed is not None:                      # a sensor that is not ideal (observer.sensor)
        meta["sensor"] = sensed
    if sc.model is not None:
        meta["observer_model"] = sc.model.metadata(sc.system)
    return json.loads(json.dumps(meta, default=float))


def write_ensemble(df, out: str | Path) -> Path:
    """The rows to ``out`` (Parquet, the metadata in its attrs) and, when the frame carries
    paths, those to ``<stem>.paths.parquet`` beside it. Returns the rows' path."""
    from observer.outputs import atomic_write

    out = Path(out)
    rows = df.copy()
    rows.attrs = {"metadata": df.attrs.get("metadata", {})}
    if "paths" in df.attrs:             # written first: a failed write leaves no rows without their paths
        paths = df.attrs["paths"].copy()
        paths.attrs = {}
        atomic_write(out.with_name(out.stem + ".paths.parquet"), lambda tmp: paths.to_parquet(tmp, index=False))
    atomic_write(out, lambda tmp: rows.to_parquet(tmp, index=False))
    return out
