"""Uncertainty ensembles: the observers' floors over plants drawn from a stated model uncertainty.

:func:`uncertainty_ensemble` draws ``plants`` seeded relative perturbations of the scenario's
matrices (``{"K": {"relative_std": 0.01}}``: ``Â = A ∘ (1 + σZ)``, Z standard normal and
symmetric for M, C and K, the draw law of :func:`observer.plant_model.perturbed`) and, per
drawn plant, runs the same n paired members of every design (the same initial errors for every
design and every plant). With ``sample="plant"`` (the default) the master is the drawn plant
and the observers carry the nominal model (the scenario's matrices, given in full as
``[observer.model]``); with ``sample="model"`` the master is the nominal plant and the
observers carry the drawn model. Either way the observers advance their model driven by χ of
the master (paper eqs. (7)-(11) with the model's data) and V (eq. (16)) and the position error
are measured against the master's state, in the master's M and K.

A member's **floor** is the largest V(t)/V(t_on) over the last ``tail`` of the coupling window,
and its **position floor** the largest Euclidean ‖q̂(t) − q(t)‖ there (sampled every
``record_every`` steps). Per design the result gives the median of each over every (plant,
member), with a cluster bootstrap interval over plants (:func:`observer.stats.cluster_ci`, the
plant the cluster: the spread a new plant from the same uncertainty would bring).

Seeds: ``numpy.random.SeedSequence(seed).spawn(2)`` gives the initial errors' generator (the
first child) and the plants' seeds (the second child's ``generate_state(plants·p)``, p the number
of perturbed matrices, plant-major in the order given); plant j's matrix ``name`` is
``perturbed(name, A, {"relative_std": σ, "seed": s})`` with the seed recorded in
``metadata["plants"]``, so one plant can be rerun alone with ``model=`` or ``[observer.model]``.
:func:`observer.compare` with ``plants=`` draws its plants with the same :func:`plant_seeds`
and :func:`drawn_scenario` (from its own child of the seed, :data:`PLANT_SPAWN_KEY`).

**Time to a level.** Per member, the first-passage time of V/V(t_on) below ``level`` (the first
recorded sample of the coupling window with V ≤ level·V(t_on), seconds from t_on: the
definition of :func:`observer.metrics.sync_time`); a member that does not reach it inside the
window is right-censored at the window's length. Per design the median is the Kaplan–Meier
median (:func:`observer.stats.kaplan_meier`) with its cluster bootstrap interval over plants (:func:`observer.stats.cluster_ci`),
"not reached" (NaN) where the curve stays above one half, never 0 or ∞. The default level is
:data:`LEVEL_FACTOR` times the largest member floor (over every design and plant), rounded up
to the grid :data:`LEVEL_GRID` (tenths of a decade): above every member's floor. A level at or
below the upper end of a design's floor interval (``floor_V_high``) measures the floor, not the
convergence: that design's time is reported as undecided (NaN, ``t_level_status``).
"""

from __future__ import annotations

import time
import warnings
from contextlib import contextmanager
from typing import Any

import numpy as np

from observer.errors import InputError

SAMPLES = ("plant", "model")
"""What is drawn: the master's plant (observers nominal) or the observers' model (plant nominal)."""
MAX_ROWS = 20000
"""Most recorded rows per run: ``record_every`` defaults to the steps divided by this."""
TAIL = 0.25
METRIC = "V and ‖q̂ − q‖ against the master's state, in the master's M and K"
LEVEL_FACTOR = 10.0
"""The default level is this times the largest member floor (rounded up to :data:`LEVEL_GRID`)."""
LEVEL_GRID = 10.0 ** (-np.arange(1, 201) / 10.0)
"""The levels a default level is chosen from: 10^(−k/10), k = 1 … 200 (first passages of every
member are kept at each, so the level can follow the floors measured)."""
PLANT_SPAWN_KEY = 2 ** 31
""":func:`observer.compare` draws its plants from ``SeedSequence(seed, spawn_key=(PLANT_SPAWN_KEY,))``
(a child of the seed that none of its masters' seeds, children 0 … masters, is)."""


def check_uncertainty(uncertainty: Any) -> dict[str, float]:
    """``{matrix: relative_std}`` from the ``model=`` table of :func:`uncertainty_ensemble`.

    Raises
    ------
    InputError
        Naming ``model`` or ``model.NAME``: not a table, an unknown matrix, a value that is not
        ``{"relative_std": σ}`` with σ ≥ 0 finite.
    """
    from observer.plant_model import MATRICES
    from observer.validation import as_scalar

    if not isinstance(uncertainty, dict) or not uncertainty:
        raise InputError("model", f"must be a non-empty table {{matrix: {{relative_std: σ}}}}, got {uncertainty!r}")
    out = {}
    for name, spec in uncertainty.items():
        if name not in MATRICES:
            raise InputError(f"model.{name}", f"unknown matrix (known: {', '.join(MATRICES)})")
        if not isinstance(spec, dict) or set(spec) != {"relative_std"}:
            raise InputError(f"model.{name}", f"must be {{relative_std = σ}} (the seeds are drawn), got {spec!r}")
        out[name] = as_scalar(f"model.{name}.relative_std", spec["relative_std"], low=0.0)
    return out


UNCERTAINTY_FLAG = "--uncertainty"
"""The command-line option of an uncertainty (``--uncertainty K=0.01``, repeatable)."""


def parse_uncertainty(items: list[str] | None) -> dict | None:
    """``["K=0.01", "M=1e-3"]`` (``--uncertainty``) → ``{"K": {"relative_std": 0.01}, ...}``
    (a value that is not a number is passed on as text, for :func:`check_uncertainty` to refuse);
    None without items.

    Raises
    ------
    InputError
        Naming ``--uncertainty`` (not ``NAME=σ``) or ``--uncertainty NAME`` (given twice).
    """
    from observer.cli_common import parse_pairs

    if not items:
        return None
    out: dict = {}
    for item in items:
        (name, value), = parse_pairs([item], UNCERTAINTY_FLAG).items()
        if name in out:
            raise InputError(f"{UNCERTAINTY_FLAG} {name}", "given twice")
        try:
            out[name] = {"relative_std": float(value)}
        except ValueError:
            out[name] = {"relative_std": value}
    return out


@contextmanager
def flag_names():
    """Re-raise an :class:`~observer.errors.InputError` on ``model.NAME`` (or ``model.NAME.relative_std``)
    as one on ``--uncertainty NAME``: the command line's spelling of the same field."""
    try:
        yield
    except InputError as exc:
        parts = exc.field.split(".")
        if parts[0] != "model" or len(parts) < 2:
            raise
        raise InputError(f"{UNCERTAINTY_FLAG} {parts[1]}", exc.problem) from None


def plant_seeds(seed, plants: int, names: tuple[str, ...]) -> tuple[np.random.Generator, list[dict]]:
    """The initial errors' generator and, per plant, ``{matrix: seed}`` (module docstring).

    Parameters
    ----------
    seed : int or numpy.random.SeedSequence
        The seed (``SeedSequence(seed)``) or the sequence itself, whose ``spawn(2)`` gives the
        errors' generator and the plants' seeds.
    plants : int
    names : tuple of str
        The perturbed matrices, in the order their seeds are drawn (plant-major).
    """
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    errors, draws = ss.spawn(2)
    state = draws.generate_state(plants * len(names), dtype=np.uint32).reshape(plants, len(names))
    return np.random.default_rng(errors), [{n: int(s) for n, s in zip(names, row)} for row in state]


def drawn_scenario(sc, sigmas: dict[str, float], seeds: dict[str, int], sample: str):
    """``sc`` for one plant: the drawn matrices in the master (``sample="plant"``, the nominal
    ones as the observers' model) or in the observers' model (``sample="model"``)."""
    from observer.plant_model import build_model, with_model
    from observer.sparse import dense

    table = {n: {"relative_std": s, "seed": seeds[n]} for n, s in sigmas.items()}
    try:
        if sample == "model":
            return with_model(sc, table)
        drawn = build_model(table, sc._document(plain=True), sc.system, sc.law).system
    except InputError as exc:                       # observer.model.K → model.K (the keyword)
        if not exc.field.startswith("observer.model"):
            raise
        raise InputError("model" + exc.field[len("observer.model"):], exc.problem) from None
    plant = sc.with_overrides({f"system.{n}": dense(getattr(drawn, n)).tolist() for n in sigmas})
    return with_model(plant, {n: dense(getattr(sc.system, n)).tolist() for n in sigmas})


def member_floors(sc, designs: tuple[str, ...], X: np.ndarray, tail: float, record_every: int,
                  levels: np.ndarray | None = None) -> list[dict]:
    """One run of ``sc`` with the paired members ``X`` of every design: per (design, member)
    V(t_on), the floor of V/V(t_on) and the position floor over the window's last ``tail``, and
    the number of the run's :class:`~observer.health.RunHealthWarning` (recorded, not shown: the
    health checks read a V that rises as a χ that is not the master's, which a model error
    also makes). With ``levels``, each row's ``passage`` holds the first-passage times below
    each level (:func:`passage_times`)."""
    from observer.metrics import window_of
    from observer.ensemble import member_name, member_slaves
    from observer.health import RunHealthWarning
    from observer.simulate import simulate

    with warnings.catch_warnings(record=True) as seen:   # the health checks assume the exact model
        warnings.simplefilter("always", RunHealthWarning)
        res = simulate(sc, observers=member_slaves(sc, designs, X, range(X.shape[0])), record_every=record_every)
    health = sum(issubclass(w.category, RunHealthWarning) for w in seen)
    for w in seen:
        if not issubclass(w.category, RunHealthWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    t = np.asarray(res.t, dtype=float)
    t_on, t_off = window_of(sc)
    k_on = int(np.searchsorted(t, t_on - 1e-12))
    sel = (t >= t_off - tail * (t_off - t_on) - 1e-12) & (t <= t_off + 1e-12)
    q = np.asarray(res.q)[sel]
    rows = []
    for d in designs:
        for i in range(X.shape[0]):
            s = res.slaves[member_name(d, i)]
            V = np.asarray(s.V, dtype=float)
            rows.append({"design": d, "member": i, "status": res.status.state.value, "V_on": float(V[k_on]),
                         "floor_V": float(np.max(V[sel]) / V[k_on]),
                         "floor_q": float(np.max(np.linalg.norm(np.asarray(s.q)[sel] - q, axis=1))),
                         "health_warnings": health})
            if levels is not None:
                rows[-1]["passage"] = passage_times(t, V, levels, t_on, t_off)
    return rows


def passage_times(t: np.ndarray, V: np.ndarray, levels: np.ndarray, t_on: float, t_off: float) -> np.ndarray:
    """First-passage times of V below ``levels``·V(t_on), one per level: seconds from t_on to
    the first sample of the window ``t_on ≤ t ≤ t_off`` with V ≤ level·V(t_on), ``inf`` when
    no sample is (the definition of :func:`observer.metrics.sync_time`, for many levels at
    once: the first sample at which the running minimum of V is at or below the level)."""
    idx = np.flatnonzero((t >= t_on) & (t <= t_off))
    levels = np.asarray(levels, dtype=float)
    if idx.size == 0:
        return np.full(levels.shape, np.inf)
    Vw = np.asarray(V, dtype=float)[idx]
    low = -np.minimum.accumulate(Vw)               # non-decreasing
    k = np.searchsorted(low, -levels * Vw[0], side="left")
    tw = np.append(t[idx] - t[idx[0]], np.inf)
    return tw[k]


def _summary(members, designs, confidence: float, n_resamples: int, seed: int, level: float | None, window: float):
    """Per design the median floors over (plant, member) and their cluster intervals over plants,
    and the time to ``level`` (:func:`level_times`)."""
    import pandas as pd

    from observer.stats import cluster_ci

    out = []
    for d in designs:
        g = members[members["design"] == d]
        row = {"design": d, "plants": int(g["plant"].nunique()), "members": int(g["member"].nunique())}
        for col in ("floor_V", "floor_q"):
            x = g[col].to_numpy()
            lo, hi, unit = cluster_ci(lambda idx, x=x: float(np.median(x[idx])), g["plant"].to_numpy(),
                                      confidence=confidence, n_resamples=n_resamples, seed=seed)
            row.update({col: float(np.median(x)), f"{col}_low": lo, f"{col}_high": hi})
        row["interval_unit"] = unit
        out.append(row)
    out = pd.DataFrame(out)
    return out.merge(level_times(members, out, level, window, confidence=confidence, n_resamples=n_resamples,
                                 seed=seed), on="design", validate="one_to_one")


def default_level(floors: np.ndarray) -> float | None:
    """:data:`LEVEL_FACTOR` times the largest of ``floors`` (of V/V(t_on)), rounded up to the
    grid :data:`LEVEL_GRID`; None when that is not below the grid's largest level (the floors
    are within a decade of V(t_on): no level above them is worth a time)."""
    above = LEVEL_GRID[LEVEL_GRID >= LEVEL_FACTOR * float(np.max(floors))]
    return float(above.min()) if above.size else None


def level_times(members, floors, level: float | None, window: float, *, confidence: float = 0.95,
                n_resamples: int = 999, seed: int = 0):
    """Per design the censored time for V/V(t_on) to first fall to ``level``.

    Parameters
    ----------
    members : DataFrame
        Per (plant, design, member): ``t_level`` (seconds from t_on; inf = not reached inside
        the window, right-censored at ``window``).
    floors : DataFrame
        Per design: ``floor_V_high``, the upper end of the interval of its median floor.
    level : float or None
        The level (None: no level is above the floors).
    window : float
        The coupling window's length, where the members that never reach the level are censored.

    Returns
    -------
    DataFrame
        One row per design: ``level``, ``t_level`` (the Kaplan–Meier median, seconds from t_on)
        with ``t_level_low``, ``t_level_high`` (cluster bootstrap over plants, :func:`observer.stats.cluster_ci`,
        of the median of :func:`observer.stats.kaplan_meier`; NaN = an end not reached), ``t_level_reached``
        (members that reach it) and ``t_level_status``: "ok"; "not reached" (the Kaplan–Meier
        curve stays above ½: NaN, never 0 or ∞); "undecided" when the level is at or below the
        design's ``floor_V_high`` (the time would measure the floor) or there is no level (NaN).
    """
    import pandas as pd

    from observer.stats import _km_stats, cluster_ci

    rows = []
    for r in floors.to_dict("records"):
        g = members[members["design"] == r["design"]]
        row = {"design": r["design"], "level": np.nan if level is None else level, "t_level": np.nan,
               "t_level_low": np.nan, "t_level_high": np.nan,
               "t_level_reached": int(np.isfinite(g["t_level"]).sum()) if level is not None else 0}
        if level is None:
            row["t_level_status"] = "undecided: the floors are within a decade of V(t_on)"
        elif not level > r["floor_V_high"]:
            row["t_level_status"] = (f"undecided: level {level:.3g} is at or below the floor's upper end "
                                     f"{r['floor_V_high']:.3g} (the time would measure the floor)")
        else:
            times = g["t_level"].to_numpy(dtype=float)
            median = lambda i, times=times: _km_stats(times[i], window)[0]  # noqa: E731
            lo, hi, _unit = cluster_ci(median, g["plant"].to_numpy(), confidence=confidence,
                                       n_resamples=n_resamples, seed=seed)
            fin = lambda x: float(x) if np.isfinite(x) else np.nan  # noqa: E731
            row.update(t_level=fin(median(np.arange(times.size))), t_level_low=fin(lo), t_level_high=fin(hi))
            row["t_level_status"] = "ok" if np.isfinite(row["t_level"]) else "not reached"
        rows.append(row)
    return pd.DataFrame(rows)


def uncertainty_ensemble(scenario, designs=("jump", "nojump"), *, model: dict, plants: int = 20, n: int = 20,
                         seed: int = 0, sample: str = "plant", h: float | None = None, t_end: float | None = None,
                         tail: float = TAIL, record_every: int | None = None, level: float | None = None,
                         confidence: float = 0.95, n_resamples: int = 999):
    """The floors of the designs over ``plants`` plants drawn from the uncertainty ``model``.

    Parameters
    ----------
    scenario : str, Path or Scenario
        The nominal plant (built-in name, TOML path or a loaded scenario; dense matrices).
    designs : sequence of str
        Observer designs; every design and every plant gets the same n initial errors.
    model : dict
        The uncertainty, ``{matrix: {"relative_std": σ}}`` for matrices among M, C, K, W.
    plants, n : int
        Plants drawn, paired members per design (initial errors on the energy sphere of the
        nominal scenario, :func:`observer.ensemble.sample_errors`).
    seed : int
        The one seed of the initial errors and of the plants (module docstring).
    sample : {"plant", "model"}
        Draw the master's plant (observers nominal) or the observers' model (plant nominal).
    h, t_end : float, optional
        Override the scenario's step and horizon.
    tail : float
        The floors are taken over this last fraction of the coupling window (0 < tail ≤ 1).
    record_every : int, optional
        Record every k-th step (default: at most :data:`MAX_ROWS` rows per run).
    level : float, optional
        The level of V/V(t_on) whose first-passage time is summarized, 0 < level < 1 (default:
        :func:`default_level`, above every member's floor; module docstring).
    confidence, n_resamples : optional
        Of the cluster bootstrap over plants.

    Returns
    -------
    pandas.DataFrame
        One row per design: ``plants``, ``members``, the median ``floor_V`` (of V/V(t_on)) and
        ``floor_q`` (of ‖q̂ − q‖, the scenario's length unit) with ``*_low``/``*_high``
        intervals, ``interval_unit`` ("clusters" = plants; "members" with one plant), and the
        time to the level (:func:`level_times`: ``level``, ``t_level`` with ``t_level_low``,
        ``t_level_high``, ``t_level_reached``, ``t_level_status``).
        ``attrs["members"]``: one row per (plant, design, member), with ``t_level``;
        ``attrs["metadata"]``: the settings, the level and its rule, the initial errors, per
        plant its seeds and the relative difference ‖Â − A‖_F / ‖A‖_F of the observers'
        matrices from the master's (:meth:`observer.plant_model.ObserverModel.metadata`), the
        metric, the versions.

    Raises
    ------
    InputError
        Naming the keyword that is not valid (or ``model.K`` for a draw that leaves K not
        positive definite: choose another seed or a smaller σ); every plant is drawn, and
        checked, before any run.
    """
    from observer.metrics import window_of
    from observer.ensemble import _check_designs, _count, _load, sample_errors

    t0 = time.perf_counter()
    designs, sigmas = _check_designs(designs), check_uncertainty(model)
    plants, n, n_resamples = _count("plants", plants, 1), _count("n", n, 1), _count("n_resamples", n_resamples, 1)
    tail, level = _check_options(sample, tail, seed, level)
    sc = _load(scenario, h, t_end)
    every = _count("record_every", record_every, 1) if record_every is not None else \
        max(1, int(round(sc.t_end / sc.h)) // MAX_ROWS)
    rng, seeds = plant_seeds(int(seed), plants, tuple(sigmas))
    X, V0 = sample_errors(sc, n, "energy_sphere", rng, None)
    members, plant_meta = _run_plants(sc, sigmas, seeds, sample, designs, X, tail, every,
                                      LEVEL_GRID if level is None else np.array([level]))
    level, rule = _level_column(members, level)
    t_on, t_off = window_of(sc)
    out = _summary(members, designs, confidence, n_resamples, int(seed), level, t_off - t_on)
    out.attrs["members"] = members
    out.attrs["metadata"] = {"scenario": sc.name, "designs": list(designs), "uncertainty": {k: {"relative_std": v}
                             for k, v in sigmas.items()}, "sample": sample, "plants": plant_meta, "n": n,
                             "seed": int(seed), "initial_errors": X.tolist(), "V0": V0, "h": sc.h,
                             "t_end": sc.t_end, "tail": tail, "record_every": every, "level": level,
                             "level_rule": rule, "confidence": confidence, "n_resamples": n_resamples,
                             "metric": METRIC, **_status(members, t0)}
    return out


def _level_column(members, level: float | None) -> tuple[float | None, str]:
    """Replace the members' ``passage`` by ``t_level``, the first passage below the given level
    or the default one (:func:`default_level`); the level and its rule."""
    passage = np.vstack(members.pop("passage").to_numpy())
    if level is not None:
        members["t_level"] = passage[:, 0]
        return level, "given"
    level = default_level(members["floor_V"].to_numpy())
    members["t_level"] = np.nan if level is None else passage[:, int(np.flatnonzero(LEVEL_GRID == level)[0])]
    return level, f"{LEVEL_FACTOR:g} x the largest member floor, rounded up to 10^(-k/10)"


def _run_plants(sc, sigmas, seeds, sample, designs, X, tail, every, levels):
    """Every plant drawn first (a refused draw stops before any run), then run: the members'
    frame (with ``passage``, per row the first passages below ``levels``) and the plants' records."""
    import pandas as pd

    drawn = [drawn_scenario(sc, sigmas, s, sample) for s in seeds]
    rows, plant_meta = [], []
    for j, (s, dsc) in enumerate(zip(seeds, drawn)):
        rows += [{"plant": j, **r} for r in member_floors(dsc, designs, X, tail, every, levels)]
        plant_meta.append({"plant": j, "seeds": s, "relative_difference":
                           dsc.model.metadata(dsc.system)["relative_difference"]})
    return pd.DataFrame(rows), plant_meta


def _check_options(sample: Any, tail: Any, seed: Any, level: Any = None) -> tuple[float, float | None]:
    """Raise unless ``sample``, ``tail``, ``seed`` and ``level`` are valid; the tail and the
    level as floats."""
    from observer.validation import as_scalar

    if level is not None:
        level = as_scalar("level", level, positive=True)
        if not level < 1.0:
            raise InputError("level", f"must be below 1 (a fraction of V(t_on)), got {level!r}")

    if sample not in SAMPLES:
        raise InputError("sample", f"must be one of {list(SAMPLES)}, got {sample!r}")
    tail = as_scalar("tail", tail, positive=True)
    if tail > 1.0:
        raise InputError("tail", f"must be at most 1 (a fraction of the window), got {tail!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError("seed", f"must be a non-negative integer, got {seed!r}")
    return tail, level


def _status(members, t0: float) -> dict:
    """The result's status (ok when every run is), the health warnings recorded, the versions."""
    from observer.result import package_versions

    return {"status": "ok" if (members["status"] == "ok").all() else "failed",
            "health_warnings": int(members.groupby("plant")["health_warnings"].first().sum()),
            "versions": package_versions(), "wall_time_s": time.perf_counter() - t0}
