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
"""

from __future__ import annotations

import time
import warnings
from typing import Any

import numpy as np

from observer.errors import InputError

SAMPLES = ("plant", "model")
"""What is drawn: the master's plant (observers nominal) or the observers' model (plant nominal)."""
MAX_ROWS = 20000
"""Most recorded rows per run: ``record_every`` defaults to the steps divided by this."""
TAIL = 0.25
METRIC = "V and ‖q̂ − q‖ against the master's state, in the master's M and K"


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


def plant_seeds(seed: int, plants: int, names: tuple[str, ...]) -> tuple[np.random.Generator, list[dict]]:
    """The initial errors' generator and, per plant, ``{matrix: seed}`` (module docstring)."""
    errors, draws = np.random.SeedSequence(seed).spawn(2)
    state = draws.generate_state(plants * len(names), dtype=np.uint32).reshape(plants, len(names))
    return np.random.default_rng(errors), [{n: int(s) for n, s in zip(names, row)} for row in state]


def drawn_scenario(sc, sigmas: dict[str, float], seeds: dict[str, int], sample: str):
    """``sc`` for one plant: the drawn matrices in the master (``sample="plant"``, the nominal
    ones as the observers' model) or in the observers' model (``sample="model"``)."""
    from observer.plant_model import build_model, with_model
    from observer.sparse import dense

    table = {n: {"relative_std": s, "seed": seeds[n]} for n, s in sigmas.items()}
    if sample == "model":
        return with_model(sc, table)
    try:
        drawn = build_model(table, sc._document(plain=True), sc.system, sc.law).system
    except InputError as exc:                       # observer.model.K → model.K (the keyword)
        raise InputError("model" + exc.field[len("observer.model"):], exc.problem) from None
    plant = sc.with_overrides({f"system.{n}": dense(getattr(drawn, n)).tolist() for n in sigmas})
    return with_model(plant, {n: dense(getattr(sc.system, n)).tolist() for n in sigmas})


def member_floors(sc, designs: tuple[str, ...], X: np.ndarray, tail: float, record_every: int) -> list[dict]:
    """One run of ``sc`` with the paired members ``X`` of every design: per (design, member)
    V(t_on), the floor of V/V(t_on) and the position floor over the window's last ``tail``, and
    the number of the run's :class:`~observer.health.RunHealthWarning` (recorded, not shown: the
    health checks read a V that rises as a χ that is not the master's, which a model error
    also makes)."""
    from observer.compare import window_of
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
    return rows


def _summary(members, designs, confidence: float, n_resamples: int, seed: int):
    """Per design the median floors over (plant, member) and their cluster intervals over plants."""
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
    return pd.DataFrame(out)


def uncertainty_ensemble(scenario, designs=("jump", "nojump"), *, model: dict, plants: int = 20, n: int = 20,
                         seed: int = 0, sample: str = "plant", h: float | None = None, t_end: float | None = None,
                         tail: float = TAIL, record_every: int | None = None, confidence: float = 0.95,
                         n_resamples: int = 999):
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
    confidence, n_resamples : optional
        Of the cluster bootstrap over plants.

    Returns
    -------
    pandas.DataFrame
        One row per design: ``plants``, ``members``, the median ``floor_V`` (of V/V(t_on)) and
        ``floor_q`` (of ‖q̂ − q‖, the scenario's length unit) with ``*_low``/``*_high``
        intervals, ``interval_unit`` ("clusters" = plants; "members" with one plant).
        ``attrs["members"]``: one row per (plant, design, member); ``attrs["metadata"]``: the
        settings, the initial errors, per plant its seeds and the relative difference
        ‖Â − A‖_F / ‖A‖_F of the observers' matrices from the master's
        (:meth:`observer.plant_model.ObserverModel.metadata`), the metric, the versions.

    Raises
    ------
    InputError
        Naming the keyword that is not valid (or ``model.K`` for a draw that leaves K not
        positive definite: choose another seed or a smaller σ).
    """
    import pandas as pd

    from observer.ensemble import _check_designs, _count, _load, sample_errors

    t0 = time.perf_counter()
    designs, sigmas = _check_designs(designs), check_uncertainty(model)
    plants, n = _count("plants", plants, 1), _count("n", n, 1)
    tail = _check_options(sample, tail, seed)
    sc = _load(scenario, h, t_end)
    every = _count("record_every", record_every, 1) if record_every is not None else \
        max(1, int(round(sc.t_end / sc.h)) // MAX_ROWS)
    rng, seeds = plant_seeds(int(seed), plants, tuple(sigmas))
    X, V0 = sample_errors(sc, n, "energy_sphere", rng, None)
    rows, plant_meta = [], []
    for j, s in enumerate(seeds):
        drawn = drawn_scenario(sc, sigmas, s, sample)
        rows += [{"plant": j, **r} for r in member_floors(drawn, designs, X, tail, every)]
        plant_meta.append({"plant": j, "seeds": s, "relative_difference":
                           drawn.model.metadata(drawn.system)["relative_difference"]})
    members = pd.DataFrame(rows)
    out = _summary(members, designs, confidence, n_resamples, int(seed))
    out.attrs["members"] = members
    out.attrs["metadata"] = {"scenario": sc.name, "designs": list(designs), "uncertainty": {k: {"relative_std": v}
                             for k, v in sigmas.items()}, "sample": sample, "plants": plant_meta, "n": n,
                             "seed": int(seed), "initial_errors": X.tolist(), "V0": V0, "h": sc.h,
                             "t_end": sc.t_end, "tail": tail, "record_every": every, "confidence": confidence,
                             "n_resamples": n_resamples, "metric": METRIC, **_status(members, t0)}
    return out


def _check_options(sample: Any, tail: Any, seed: Any) -> float:
    """Raise unless ``sample``, ``tail`` and ``seed`` are valid; the tail as a float."""
    from observer.validation import as_scalar

    if sample not in SAMPLES:
        raise InputError("sample", f"must be one of {list(SAMPLES)}, got {sample!r}")
    tail = as_scalar("tail", tail, positive=True)
    if tail > 1.0:
        raise InputError("tail", f"must be at most 1 (a fraction of the window), got {tail!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError("seed", f"must be a non-negative integer, got {seed!r}")
    return tail


def _status(members, t0: float) -> dict:
    """The result's status (ok when every run is), the health warnings recorded, the versions."""
    from observer.result import package_versions

    return {"status": "ok" if (members["status"] == "ok").all() else "failed",
            "health_warnings": int(members.groupby("plant")["health_warnings"].first().sum()),
            "versions": package_versions(), "wall_time_s": time.perf_counter() - t0}
