"""The paper's question for any system: is one observer design faster than another?

:func:`compare` runs paired ensembles (:func:`observer.ensemble`: member i of every design
starts from the same initial error against the same master) against *several masters* — the
scenario's own initial state and ``masters − 1`` states sampled around it (optionally each
on a time grid h·(1 + δ), |δ| ≤ ``grid_jitter``) — with one extra, zero-error member per
master whose V is the design's floor with that master (the matched master). From the members
it computes the estimands of :mod:`observer.stats`: per pair of designs the decay-rate ratio
with its cluster bootstrap interval (clusters = masters) and "faster in k of m masters", the
censored settling summary per design at ρ·V(t_on), the sign test on which design settles
first, and the flags that say when a comparison is decided by a floor, a window or the grid.

With ``plants=`` (``--uncertainty NAME=σ --plants P``) every master and member runs against each
of P plants drawn from a stated relative uncertainty (:func:`plant_draw`, :func:`plant_runs`:
the draws of :mod:`observer.uncertainty`), the observers carrying the nominal model (or the
reverse, ``sample="model"``); the intervals then resample plants, the masters and members
nested in them (:func:`bootstrap_frame`).

``python -m observer compare SCENARIO|FILE.toml`` prints it (:func:`cmd_compare`), ``--json``
writes it for scripts, ``--report DIR`` writes a one-page HTML report (:func:`write_report`).
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:                  # pandas is imported where a table is built: `import observer` stays light
    import pandas as pd

from observer.errors import InputError
from observer.metrics import RHOS, settle_column, window_of

SPREAD = 0.05
"""Default size of the masters' initial-state perturbations: ½δxᵀAδx = SPREAD²·½x₀ᵀAx₀
(A = diag(K_e, M), :func:`observer.ensemble.energy_metric`)."""

POSITION_MEMBERS = 20
"""Members per design of the first master whose position error is measured when K is singular."""

MASTER_TRIES = 100
"""Samples tried for a master initial state that does not penetrate a contact."""


# ---------------------------------------------------------------------------------------
# the masters
# ---------------------------------------------------------------------------------------
def master_scenarios(sc, masters: int, spread: float, grid_jitter: float, rng: np.random.Generator) -> list:
    """The scenario itself and ``masters − 1`` scenarios whose master starts from
    ``x₀ + δx`` (δx uniform in direction on ½δxᵀAδx = spread²·E, E = ½x₀ᵀAx₀, or the
    scenario's observer-error level when x₀ = 0; a sample penetrating a contact is drawn
    again), on the step h·(1 + U(−grid_jitter, grid_jitter)). The observer's initial error
    is defined relative to the master's state, so every master gets errors from the same
    distribution (the scenario's ``[observer]`` initial state, where it has one, moves with
    the master's)."""
    from observer.ensemble import energy_metric, sample_errors, scenario_error

    out = [sc]
    A = energy_metric(sc)
    x0 = np.concatenate([sc.q0, sc.u0])
    E = 0.5 * float(x0 @ A @ x0)
    if not E > 0.0:
        xe = scenario_error(sc)
        E = 0.5 * float(xe @ A @ xe)
    nd = sc.system.n
    for j in range(1, masters):
        for _ in range(MASTER_TRIES):
            dx, _v = sample_errors(sc, 1, "energy_sphere", rng, max(spread ** 2 * E, 1e-300))
            over = {"initial.q": (sc.q0 + dx[0, :nd]).tolist(), "initial.u": (sc.u0 + dx[0, nd:]).tolist()}
            over.update({f"observer.{k}": (np.asarray(sc.observer[k]) + dx[0, j]).tolist()
                         for k, j in (("q", slice(0, nd)), ("u", slice(nd, None))) if k in sc.observer})
            if grid_jitter:
                over["simulation.h"] = float(sc.h * (1.0 + rng.uniform(-grid_jitter, grid_jitter)))
            try:
                out.append(sc.with_overrides(over))
                break
            except InputError:
                continue
        else:
            raise InputError("masters", f"no sampled initial state of master {j} avoids penetrating a "
                                        f"contact in {MASTER_TRIES} tries; use a smaller spread")
    return out


def member_fits(sc, df: pd.DataFrame, n: int, designs) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The decay rate of members 0…n−1 (:func:`observer.stats.decay_rates`, stopped at
    :func:`observer.stats.fit_levels` of the designs' floor met so far,
    :func:`observer.stats.floor_path`) from an :func:`observer.ensemble`
    frame ``df`` run with ``paths`` for every member, whose member n started without error
    (its largest V in the window is the design's floor with this master: the matched master).
    ``df.attrs["paths"]`` is taken out of the attrs (pandas deep-copies them on every operation).

    Returns
    -------
    (DataFrame, DataFrame)
        Per (design, member < n): ``rate, points, t_fit, reached_level, grid_decided`` and
        ``floor_stop`` (a floor, not the level 1e-12·V(t_on) or the window's end, stopped the
        fit: beyond t_fit the master cannot tell the member from its floor); per design: ``floor``.
    """
    import pandas as pd
    from observer import stats

    paths = df.attrs.pop("paths")
    pd_member = paths["member"].to_numpy()
    pd_t, pd_V = paths["t"].to_numpy(), paths["V"].to_numpy()
    t_on, t_off = window_of(sc)
    zero = df[df["member"] == n]
    floors = pd.DataFrame({"design": zero["design"].to_numpy(), "floor": zero["V_max"].to_numpy(dtype=float)})
    t, V = {}, {}
    for d in designs:
        sel = np.flatnonzero((paths["design"] == d).to_numpy(dtype=bool))
        sel = sel[np.lexsort((pd_t[sel], pd_member[sel]))]
        t[d] = pd_t[sel[pd_member[sel] == 0]]
        V[d] = pd_V[sel].reshape(n + 1, t[d].size)
    floor = stats.floor_path(t[designs[0]], np.vstack([V[d][n] for d in designs]), t_on, t_off)
    parts = []
    for d in designs:
        rows = df[(df["design"] == d) & (df["member"] < n)].sort_values("member")
        V_on = rows["V_on"].to_numpy()
        fit = stats.decay_rates(t[d], V[d][:n], t_on, t_off, stats.fit_levels(V_on, floor))
        k_stop = np.searchsorted(t[d], t_on) + fit["points"].to_numpy()
        at_stop = floor[np.minimum(k_stop, floor.size - 1)]
        fit["floor_stop"] = fit["reached_level"].to_numpy() & (stats.SAFETY * at_stop >= stats.LEVEL_MIN * V_on)
        parts.append(pd.concat([rows[["design", "member"]].reset_index(drop=True), fit], axis=1))
    return pd.concat(parts, ignore_index=True), floors


def run_master(sc, designs, n: int, seed: int, integrator: str, engine, workers, initial_errors, V0,
               cluster: int, positions: bool) -> dict:
    """One master's paired members plus its zero-error member: per member V_on, the settling
    times, the decay rate (:func:`observer.stats.decay_rates`); per design the floor. A plain
    function of picklable arguments (it runs on Dask workers)."""
    import pandas as pd
    from observer.ensemble import ensemble, sample_errors

    rng = np.random.default_rng(seed)
    X, _ = sample_errors(sc, n, initial_errors, rng, V0)
    X = np.vstack([X, np.zeros((1, X.shape[1]))])          # member n: no error (the floor)
    df = ensemble(sc, designs=designs, n=n + 1, initial_errors=X, integrator=integrator, engine=engine,
                  paths=n + 1, workers=workers)
    fits, floors = member_fits(sc, df, n, designs)
    cols = ["design", "member", "status", "V_on", "V_end", *[settle_column(r) for r in RHOS]]
    keep = df[df["member"] < n][cols].merge(fits, on=["design", "member"], validate="one_to_one")
    members = pd.concat([keep[keep["design"] == d].sort_values("member") for d in designs], ignore_index=True)
    floors.insert(0, "cluster", cluster)
    members.insert(0, "cluster", cluster)
    out = {"members": members, "floors": floors, "h": sc.h, "positions": None}
    if positions:
        out["positions"] = _positions(sc, designs, X[:min(n, POSITION_MEMBERS)], integrator, cluster)
    return out


def _positions(sc, designs, X, integrator, cluster) -> pd.DataFrame:
    """Position errors q̂ − q at the window's start and end of the first members (K singular)."""
    import pandas as pd
    from observer import stats
    from observer.ensemble import member_name, member_slaves
    from observer.simulate import simulate

    res = simulate(sc, observers=member_slaves(sc, designs, X, range(X.shape[0])),
                   integrator=integrator)
    t_on, t_off = window_of(sc)
    k_on = int(np.searchsorted(res.t, t_on - 1e-12))
    k_off = int(np.searchsorted(res.t, t_off + 1e-12)) - 1
    frames = []
    for d in designs:
        e_on = np.array([res.slaves[member_name(d, i)].q[k_on] - res.q[k_on] for i in range(X.shape[0])])
        e_off = np.array([res.slaves[member_name(d, i)].q[k_off] - res.q[k_off] for i in range(X.shape[0])])
        frames.append(stats.position_errors(e_off, e_on, d).assign(cluster=cluster))
    return pd.concat(frames, ignore_index=True)


# ---------------------------------------------------------------------------------------
# the result
# ---------------------------------------------------------------------------------------
@dataclass
class Comparison:
    """What :func:`compare` returns: the per-member frame, the floors, and the estimands
    (one DataFrame each), the warnings and the metadata. ``cluster_level`` names what the
    intervals resample: ``"masters"``, or ``"plants"`` for a comparison over two or more drawn
    plants (``members`` then has ``plant`` and ``master`` columns; its ``cluster`` is the run)."""

    scenario: str
    designs: tuple
    pairs: tuple
    rho: float
    window: tuple
    members: pd.DataFrame
    floors: pd.DataFrame
    rate_ratios: pd.DataFrame
    settling: pd.DataFrame
    order: pd.DataFrame
    floor_flags: pd.DataFrame
    band_flags: pd.DataFrame
    positions: pd.DataFrame | None
    warnings: list = field(default_factory=list)
    metadata: dict = field(default_factory=dict)
    cluster_level: str = "masters"

    @property
    def evidence(self) -> dict:
        """Members per master, masters, and pairs (members × masters) per design pair; over
        drawn plants also ``plants`` (pairs = members × masters × plants)."""
        per = int(self.members.groupby(["cluster", "design"]).size().iloc[0])
        if "plant" not in self.members:
            n_masters = int(self.members["cluster"].nunique())
            return {"members_per_master": per, "masters": n_masters, "pairs": per * n_masters}
        n_masters, n_plants = int(self.members["master"].nunique()), int(self.members["plant"].nunique())
        return {"members_per_master": per, "masters": n_masters, "plants": n_plants,
                "pairs": per * n_masters * n_plants}

    def _unit(self, unit: str) -> str:
        """What an interval resampled: the cluster level for "clusters", else ``unit``."""
        return self.cluster_level if unit == "clusters" else unit

    def to_dict(self) -> dict:
        """JSON-ready: per pair ``rate_ratio`` {estimate, low, high}, per design the censored
        settling summary, the evidence and the warnings (a value the data do not give: null)."""
        def num(x):
            return None if x is None or (isinstance(x, float) and not math.isfinite(x)) else x

        pairs = []
        for (a, b), rr, od in zip(self.pairs, self.rate_ratios.to_dict("records"), self.order.to_dict("records")):
            pairs.append({"a": a, "b": b,
                          "rate_ratio": {"estimate": num(rr["estimate"]), "low": num(rr["low"]),
                                         "high": num(rr["high"]), "resampled": self._unit(rr["unit"]),
                                         "status": rr["status"]},
                          f"faster_{self.cluster_level}": {"k": rr["k_clusters"], "m": rr["clusters"],
                                                           "low": rr["k_low"], "high": rr["k_high"]},
                          "settles_first": {k: num(v) for k, v in od.items() if k not in ("a", "b")}})
        settling = {r["design"]: {k: num(v) for k, v in r.items() if k != "design"}
                    for r in self.settling.to_dict("records")}
        floors = {r["design"]: {k: num(v) for k, v in r.items() if k != "design"}
                  for r in self.floor_flags.to_dict("records")}
        out = {"scenario": self.scenario, "designs": list(self.designs), "rho": self.rho,
               "window": list(self.window), "pairs": pairs, "settling": settling, "floors": floors,
               "evidence": self.evidence, "warnings": list(self.warnings), "metadata": self.metadata}
        if self.positions is not None:
            out["position_errors"] = [{k: num(v) for k, v in r.items()} for r in self.positions.to_dict("records")]
        return json.loads(json.dumps(out, default=_json_default))

    def lines(self) -> list[str]:
        """The few lines the command line prints."""
        ev, meta = self.evidence, self.metadata
        drawn = "" if "plants" not in ev else (
            f" x {ev['plants']} plants ({meta['sample']} drawn: "
            + ", ".join(f"{k} relative_std {v['relative_std']:g}" for k, v in meta["uncertainty"].items()) + ")")
        out = [f"{self.scenario}: {ev['members_per_master']} members x {ev['masters']} masters{drawn} per design "
               f"({meta['integrator']}, h = {meta['h']:g}, window [{self.window[0]:g}, {self.window[1]:g}] s); "
               f"intervals {int(100 * meta['confidence'])} %"]
        for (a, b), rr, od in zip(self.pairs, self.rate_ratios.to_dict("records"), self.order.to_dict("records")):
            if rr["status"] == "ok":
                out.append(f"decay-rate ratio {a}/{b}: {rr['estimate']:.3g} [{rr['low']:.3g}, {rr['high']:.3g}] "
                           f"(resampling {self._unit(rr['unit'])}); {a}'s rate larger in {rr['k_clusters']} of "
                           f"{rr['clusters']} {self.cluster_level} [{100 * rr['k_low']:.0f}-{100 * rr['k_high']:.0f} %]")
            else:
                out.append(f"decay-rate ratio {a}/{b}: {rr['status']}")
            untied = od["a_first"] + od["b_first"]
            share = (f"{100 * od['share']:.0f} % [{100 * od['low']:.0f}, {100 * od['high']:.0f}]" if untied
                     else "no untied pair")
            out.append(f"settles first below {self.rho:g}·V(t_on) (never = later): {a} in {od['a_first']} of "
                       f"{untied} untied pairs ({share}), {od['ties']} ties")
        W = self.window[1] - self.window[0]
        out.append(f"settling below {self.rho:g}·V(t_on), censored at the window's end ({W:g} s after t_on):")
        for r in self.settling.to_dict("records"):
            out.append(f"  {r['design']:<8} settled {100 * r['share_settled']:.1f} % [{100 * r['share_low']:.1f}, "
                       f"{100 * r['share_high']:.1f}]; median {_t(r['median'])} [{_t(r['median_low'])}, "
                       f"{_t(r['median_high'])}]; restricted mean {r['rmst']:.3g} s [{r['rmst_low']:.3g}, "
                       f"{r['rmst_high']:.3g}]")
        fl = ", ".join(f"{r['design']} {r['floor_max']:.2g}" for r in self.floor_flags.to_dict("records"))
        out.append(f"floors (largest V of a zero-error observer with this master): {fl}")
        if self.positions is not None:
            for r in self.positions.groupby("design", sort=False)["median_end"].median().items():
                out.append(f"  K singular: {r[0]} median position error at the window's end {r[1]:.3g}")
        out += [f"warning: {w}" for w in self.warnings]
        return out


def _t(x: float) -> str:
    from observer import stats
    return stats.NOT_REACHED if not math.isfinite(x) else f"{x:.3g} s"


def _json_default(x):
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, (np.bool_,)):
        return bool(x)
    return str(x)


# ---------------------------------------------------------------------------------------
# the entry point
# ---------------------------------------------------------------------------------------
def compare(scenario, designs=("jump", "nojump"), n: int = 200, masters: int = 5, *, rho: float = 1e-6,
            seed: int = 0, overrides: dict | None = None, h: float | None = None, t_end: float | None = None,
            integrator: str = "time-stepping", engine: str | None = None, spread: float = SPREAD,
            grid_jitter: float = 0.0, initial_errors: str = "energy_sphere", V0: float | None = None,
            workers: int | None = None, scheduler: str | None = None, confidence: float | None = None,
            n_resamples: int | None = None, sensor: dict | None = None,
            model: dict | None = None, plants: int | None = None, sample: str | None = None) -> Comparison:
    """Compare observer designs on ``scenario`` with paired members against several masters.

    Parameters
    ----------
    scenario : str, Path or Scenario
        Built-in name, TOML file or a loaded scenario.
    designs : sequence of str
        At least two designs; each of ``designs[:-1]`` is compared with the last (default
        jump against nojump).
    n : int
        Members per master (initial errors as :func:`observer.ensemble` samples them).
    masters : int
        Master trajectories (:func:`master_scenarios`); the intervals resample them.
    rho : float
        Settling threshold, one of :data:`observer.metrics.RHOS`.
    seed : int
        Seeds the masters and every master's errors.
    overrides, model : dict, optional
        Dotted-key overrides (``--set``); ``h``, ``t_end`` override the step and horizon;
        ``model``: the observers' own model (:mod:`observer.plant_model`), the masters the plant;
        with ``plants``, the uncertainty the plants are drawn from (``{"K": {"relative_std": 0.01}}``,
        :func:`observer.uncertainty.check_uncertainty`).
    plants : int, optional
        Draw this many plants from the uncertainty ``model`` (:func:`plant_runs`): every design
        runs the same masters and members against each; the plant becomes the cluster the
        intervals resample (with two or more plants), the masters and members nested in it.
    sample : {"plant", "model"}, optional
        With ``plants``: draw the masters' plant, the observers carrying the nominal model
        (default), or the observers' model, the plant nominal.
    integrator : {"time-stepping", "event"}
        The masters' and observers' integrator; ``"event"`` is the exact event-driven
        reference, free of discretization floors.
    spread, grid_jitter : float
        Size of the masters' initial-state perturbations; relative spread of their steps.
    workers : int, optional
        Threads per master run.
    scheduler : str, optional
        A Dask scheduler address: the masters run there, one task each.
    sensor : dict, optional
        ``[observer.sensor]`` keys: χ from a contact sensor on each master (:func:`compared_scenario`).

    Returns
    -------
    Comparison

    Raises
    ------
    InputError
        Naming the argument that is not valid.
    """
    from observer import stats

    confidence = stats.CONFIDENCE if confidence is None else confidence
    n_resamples = stats.N_RESAMPLES if n_resamples is None else n_resamples
    t0 = time.perf_counter()
    designs, integrator = _check_arguments(designs, integrator, n, masters, seed, rho, spread, grid_jitter)
    draw = plant_draw(model, plants, sample, seed)
    sc, sensed = compared_scenario(scenario, overrides, h, t_end, sensor, None if draw else model)
    master_seed, *member_seeds = np.random.SeedSequence(seed).spawn(masters + 1)
    scs = master_scenarios(sc, masters, spread, grid_jitter, np.random.default_rng(master_seed))
    runs = plant_runs(scs, draw)
    positions = not sc.system.is_stiffness_definite()
    jobs = [(s, designs, n, int(member_seeds[k].generate_state(1)[0]), integrator, engine, workers,
             initial_errors, V0, c, positions and c == 0) for c, (_j, k, s) in enumerate(runs)]
    done = _run_jobs(jobs, scheduler)
    level = _label_plants(done, runs, draw)
    result = _assemble(sc, designs, rho, done, confidence, n_resamples, seed, level)
    result.metadata = _metadata(sc, sensed, done, dict(designs=list(designs), n=n, masters=masters, seed=seed,
                                spread=spread, grid_jitter=grid_jitter, integrator=integrator, engine=engine,
                                confidence=confidence, n_resamples=n_resamples), time.perf_counter() - t0)
    if draw is not None:
        result.metadata.update(_plant_metadata(draw, runs, masters, level))
    return result


def _label_plants(done: list, runs: list, draw: dict | None) -> str:
    """Give each run's members their ``plant`` and ``master`` (over drawn plants); the level the
    intervals resample: ``"plants"`` with two or more drawn plants, else ``"masters"``."""
    if draw is None:
        return "masters"
    for d, (j, k, _s) in zip(done, runs):
        d["members"].insert(1, "plant", j)
        d["members"].insert(2, "master", k)
    return "plants" if len(draw["seeds"]) >= 2 else "masters"


def _check_arguments(designs, integrator, n, masters, seed, rho, spread, grid_jitter) -> tuple:
    """The designs and the integrator's name, once every argument of :func:`compare` is valid."""
    from observer.ensemble import _check_designs, integrator_name

    designs = _check_designs(designs)
    integrator = integrator_name(integrator)
    if len(designs) < 2:
        raise InputError("designs", "compare needs at least two designs")
    for name, value, low in (("n", n, 2), ("masters", masters, 1), ("seed", seed, 0)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise InputError(name, f"must be an integer ≥ {low}, got {value!r}")
    if rho not in RHOS:
        raise InputError("rho", f"must be one of {list(RHOS)} (the thresholds the runs record), got {rho!r}")
    for name, value in (("spread", spread), ("grid_jitter", grid_jitter)):
        if not (isinstance(value, (int, float)) and 0.0 <= value < 1.0):
            raise InputError(name, f"must be a number in [0, 1), got {value!r}")
    return designs, integrator


def plant_draw(model, plants, sample, seed) -> dict | None:
    """None without ``plants``; else the uncertainty ``{"sigmas", "seeds", "sample"}``: σ per
    matrix (:func:`observer.uncertainty.check_uncertainty`) and, per plant, ``{matrix: seed}``
    from :func:`observer.uncertainty.plant_seeds` of ``SeedSequence(seed, spawn_key=(2**31,))``
    (:data:`observer.uncertainty.PLANT_SPAWN_KEY`: a child of the seed no master's seed is).

    Raises
    ------
    InputError
        Naming ``plants`` (not an integer ≥ 1), ``model`` (missing, or not an uncertainty) or
        ``sample`` (given without ``plants``, or not one of "plant", "model").
    """
    from observer.uncertainty import PLANT_SPAWN_KEY, SAMPLES, check_uncertainty, plant_seeds

    if plants is None:
        if sample is not None:
            raise InputError("sample", "says what plants= draws: give plants= (and the uncertainty as model=)")
        return None
    if isinstance(plants, bool) or not isinstance(plants, (int, np.integer)) or plants < 1:
        raise InputError("plants", f"must be an integer ≥ 1, got {plants!r}")
    if model is None:
        raise InputError("model", "plants= draws the plants from the uncertainty model= "
                                  "{matrix: {relative_std: σ}}: give it")
    sigmas = check_uncertainty(model)
    sample = "plant" if sample is None else sample
    if sample not in SAMPLES:
        raise InputError("sample", f"must be one of {list(SAMPLES)}, got {sample!r}")
    ss = np.random.SeedSequence(int(seed), spawn_key=(PLANT_SPAWN_KEY,))
    return {"sigmas": sigmas, "seeds": plant_seeds(ss, int(plants), tuple(sigmas))[1], "sample": sample}


def plant_runs(scs: list, draw: dict | None) -> list[tuple]:
    """``(plant, master, scenario)`` per run: the masters ``scs`` as they are (plant None), or each
    master with each drawn plant's matrices (:func:`observer.uncertainty.drawn_scenario`),
    plant-major. Every plant is drawn, and checked, before any run."""
    if draw is None:
        return [(None, k, s) for k, s in enumerate(scs)]
    from observer.uncertainty import drawn_scenario

    if scs[0].model is not None:
        raise InputError("model", "plants= draws the plants from model=; the scenario has an [observer.model] "
                                  "table of its own: remove one of them")

    return [(j, k, drawn_scenario(s, draw["sigmas"], seeds, draw["sample"]))
            for j, seeds in enumerate(draw["seeds"]) for k, s in enumerate(scs)]


def _plant_metadata(draw: dict, runs: list, masters: int, level: str) -> dict:
    """What a comparison over drawn plants adds to the metadata: the uncertainty, what is drawn,
    per plant its seeds and the relative difference of the observers' matrices from the master's
    (master 0's run), the seed rule and the level the intervals resample."""
    plants = []
    for j, seeds in enumerate(draw["seeds"]):
        s = runs[j * masters][2]
        plants.append({"plant": j, "seeds": seeds, "relative_difference":
                       s.model.metadata(s.system)["relative_difference"]})
    return {"uncertainty": {k: {"relative_std": v} for k, v in draw["sigmas"].items()}, "sample": draw["sample"],
            "plants": plants, "cluster_level": level,
            "plant_seeds": "observer.uncertainty.plant_seeds(SeedSequence(seed, spawn_key=(2**31,)), plants, matrices)"}


def _metadata(sc, sensed, done, settings: dict, wall: float) -> dict:
    """The comparison's metadata: the scenario, the call's ``settings``, the masters' steps,
    the wall time, the sensor's settings (when not ideal) and the observers' model (if any)."""
    return {"scenario": sc.name, "params": sc.parameters(), **{k: settings[k] for k in
            ("designs", "n", "masters", "seed", "spread", "grid_jitter", "integrator", "engine")},
            "h": sc.h, "t_end": sc.t_end, "master_steps": [d["h"] for d in done],
            "confidence": settings["confidence"], "n_resamples": settings["n_resamples"], "wall_time_s": wall,
            **({} if sensed.ideal else {"sensor": sensed.to_dict()}),
            **({} if sc.model is None else {"observer_model": sc.model.metadata(sc.system)})}


def compared_scenario(scenario, overrides, h, t_end, sensor, model=None):
    """The scenario :func:`compare` runs (``overrides``, then ``h`` and ``t_end``), with
    ``sensor`` (a dict) as its ``[observer.sensor]`` table, and that table's
    :class:`~observer.sensor.Sensor`, and ``model`` (a dict) as its ``[observer.model]``
    table (:func:`observer.plant_model.with_model`). Each master's ensemble applies the sensor
    to that master (:func:`observer.ensemble`); a sensor that is not ideal is in
    ``metadata["sensor"]``."""
    from observer.ensemble import _load
    from observer.scenario import check_overrides, load_scenario
    from observer.sensor import Sensor

    if sensor is not None:
        overrides = {**check_overrides(overrides), "observer.sensor": sensor}
    sc = _load(load_scenario(scenario, overrides) if overrides else scenario, h, t_end, model)
    return sc, Sensor.from_table(sc.observer.get("sensor"))


def _run_jobs(jobs, scheduler):
    if scheduler is None:
        return [run_master(*job) for job in jobs]
    try:
        from distributed import Client
    except ImportError:
        raise InputError("--scheduler", "needs dask[distributed] (pip install 'dask[distributed]')") from None
    try:
        client = Client(scheduler)
    except (OSError, ValueError, TypeError) as exc:
        raise InputError("--scheduler", f"cannot reach {scheduler!r}: {exc}") from None
    with client:
        return client.gather([client.submit(run_master, *job, pure=False) for job in jobs])


def bootstrap_frame(members: pd.DataFrame, level: str) -> pd.DataFrame:
    """The members as the estimands of :mod:`observer.stats` read them: ``cluster`` the unit the
    intervals resample. ``level="masters"``: the frame itself (cluster = the run's master);
    ``"plants"``: cluster = the plant, and ``member`` = master·n + member (the pairs across designs
    are still one (plant, master, member) each)."""
    if level != "plants":
        return members
    per = int(members["member"].max()) + 1
    return members.assign(cluster=members["plant"], member=members["master"] * per + members["member"])


def _assemble(sc, designs, rho, done, confidence, n_resamples, seed, level: str = "masters") -> Comparison:
    import pandas as pd
    from observer import stats
    members = pd.concat([d["members"] for d in done], ignore_index=True)
    floors = pd.concat([d["floors"] for d in done], ignore_index=True)
    positions = next((d["positions"] for d in done if d["positions"] is not None), None)
    window = window_of(sc)
    W = window[1] - window[0]
    col = settle_column(rho)
    pairs = tuple((a, designs[-1]) for a in designs[:-1])
    kw = dict(confidence=confidence, n_resamples=n_resamples, seed=seed)
    boot = bootstrap_frame(members, level)
    rr = pd.concat([stats.rate_ratio(boot, a, b, **kw) for a, b in pairs], ignore_index=True)
    order = pd.concat([stats.settle_order(boot, col, a, b, **kw) for a, b in pairs], ignore_index=True)
    settling = stats.settling_summary(boot, col, W, **kw)
    ff = stats.floor_flags(members, floors, rho)
    bf = stats.band_flags(members, col, max(d["h"] for d in done))
    warnings = _warnings(members, rr, settling, ff, bf, positions, rho)
    return Comparison(sc.name, designs, pairs, rho, window, members, floors, rr, settling, order, ff, bf,
                      positions, warnings, cluster_level=level)


def _warnings(members, rr, settling, ff, bf, positions, rho) -> list[str]:
    """Why a reading of the estimands could be decided by a floor, a window or the grid."""
    from observer import stats
    out = []
    for r in ff.to_dict("records"):
        if r["below_floor"]:
            out.append(f"floor-decided: rho = {rho:g} is at or below {r['design']}'s floor with this master for "
                       f"{r['below_floor']} of {r['n']} members (settling there measures the master's "
                       f"discretization); use rho ≥ {r['rho_min']:.1g} or --integrator event")
        elif r["floor_decided"]:
            out.append(f"floor-near: rho = {rho:g} is within {stats.SAFETY:g}x of {r['design']}'s floor for some "
                       f"members; use rho ≥ {r['rho_min']:.1g} or --integrator event")
    for r in settling.to_dict("records"):
        if r["settled"] < r["n"]:
            out.append(f"window-censored: {r['n'] - r['settled']} of {r['n']} {r['design']} members do not settle "
                       "within the window; the restricted mean and the share depend on its length "
                       "(the rate ratio does not)")
    for r in bf.to_dict("records"):
        if r["zero_width"]:
            out.append(f"grid-decided: {r['design']}'s settling times have a zero-width 10-90 % band "
                       f"[{r['band_low']:.4g}, {r['band_high']:.4g}] s: a floor or grid crossing, not the observer")
    grid = members.groupby("design", sort=False)["grid_decided"].mean()
    for d, share in grid.items():
        if share > 0.05:
            out.append(f"grid-decided: {d}'s V reaches the fit level within {stats.MIN_POINTS} samples in "
                       f"{100 * share:.0f} % of members; refine h")
    if positions is not None:
        out.append("K is singular: V = ½eᵀKe + ½vᵀMv does not see position errors in ker K; a settled V is not "
                   "synchronization (see the position errors)")
    return out


# ---------------------------------------------------------------------------------------
# the command line and the report
# ---------------------------------------------------------------------------------------
def add_parser(sub) -> None:
    """The ``compare`` subcommand's arguments."""
    s = sub.add_parser("compare", help="is one observer design faster than another? paired members "
                                       "against several masters: rate ratio, censored settling, floors")
    s.add_argument("scenario", help="built-in name or .toml path")
    s.add_argument("--designs", default="jump,nojump", help="comma-separated designs; each is compared "
                                                            "with the last (default jump,nojump)")
    s.add_argument("--n", type=int, default=200, help="members per master (default 200)")
    s.add_argument("--masters", type=int, default=5, help="master trajectories (default 5)")
    s.add_argument("--rho", type=float, default=1e-6, help=f"settling threshold, one of {list(RHOS)}")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--V0", type=float, default=None, help="level of the members' energy sphere (default: "
                                                          "V of the scenario's observer error)")
    s.add_argument("--h", type=float, help="step size")
    s.add_argument("--t-end", type=float, help="final time")
    s.add_argument("--integrator", choices=["time-stepping", "event"], default="time-stepping")
    s.add_argument("--spread", type=float, default=SPREAD, help="size of the masters' initial-state "
                                                                "perturbations (default 0.05)")
    s.add_argument("--grid-jitter", type=float, default=0.0, help="masters' steps h·(1 ± this) (default 0)")
    s.add_argument("--workers", type=int, default=None, help="threads per master run")
    s.add_argument("--scheduler", default=None, help="Dask scheduler address to run the masters on")
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override (param.NAME for builder parameters, else dotted TOML key)")
    s.add_argument("--uncertainty", action="append", metavar="NAME=SIGMA",
                   help="draw the plants from this relative uncertainty of matrix NAME (M, C, K, W), "
                        "e.g. K=0.01; repeatable (with --plants)")
    s.add_argument("--plants", type=int, default=None, help="plants drawn from --uncertainty (default 20); "
                                                            "the intervals then resample plants")
    s.add_argument("--sample", choices=["plant", "model"], default=None,
                   help="with --uncertainty: draw the masters' plant (default; observers nominal) or the "
                        "observers' model (plant nominal)")
    s.add_argument("--json", default=None, metavar="FILE", help="write the estimands as JSON")
    s.add_argument("--report", default=None, metavar="DIR", help="write a one-page HTML report there")
    s.set_defaults(func=cmd_compare)


def plant_options(args) -> dict:
    """``model``, ``plants``, ``sample`` of :func:`compare` from ``--uncertainty``, ``--plants``,
    ``--sample`` (no keyword without ``--uncertainty``; ``--plants`` defaults to 20 with it).

    Raises
    ------
    InputError
        Naming ``--plants`` or ``--sample`` given without ``--uncertainty``, or ``--uncertainty``
        not ``NAME=σ`` (:func:`observer.uncertainty.parse_uncertainty`).
    """
    from observer.uncertainty import parse_uncertainty

    table = parse_uncertainty(args.uncertainty)
    if table is None:
        for flag, value in (("--plants", args.plants), ("--sample", args.sample)):
            if value is not None:
                raise InputError(flag, "draws plants from an uncertainty: give --uncertainty NAME=SIGMA too")
        return {}
    return {"model": table, "plants": 20 if args.plants is None else args.plants, "sample": args.sample}


def cmd_compare(args) -> int:
    """``compare``: print the estimands; ``--json`` and ``--report`` write them."""
    from observer.cli_common import parse_pairs
    from observer.uncertainty import flag_names
    from observer.validation import check_output_path

    if args.json is not None:
        check_output_path("--json", args.json, (".json",))
    if args.report is not None and Path(args.report).exists() and not Path(args.report).is_dir():
        raise InputError("--report", f"{args.report} exists and is not a directory")
    designs = [d.strip() for d in args.designs.split(",") if d.strip()]
    drawn = plant_options(args)
    with flag_names():
        res = compare(args.scenario, designs, n=args.n, masters=args.masters, rho=args.rho, seed=args.seed,
                      overrides=parse_pairs(args.set) or None, h=args.h, t_end=args.t_end,
                      integrator=args.integrator, spread=args.spread, grid_jitter=args.grid_jitter, V0=args.V0,
                      workers=args.workers, scheduler=args.scheduler, **drawn)
    for line in res.lines():
        print(line)
    if args.json is not None:
        p = Path(args.json)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(res.to_dict(), indent=1, allow_nan=False))
        print(f"wrote {p}")
    if args.report is not None:
        print(f"wrote {write_report(res, args.report)}")
    return 0


SELF_CHECK = """<script>
(function () {
  var errors = [];
  function note() { if (document.body) { document.body.setAttribute("data-errors", errors.join(" | ")); } }
  window.addEventListener("error", function (e) { errors.push(String(e.message || e)); note(); }, true);
  window.addEventListener("load", function () {
    var imgs = Array.prototype.slice.call(document.images);
    var bad = imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0); });
    var b = document.body;
    b.setAttribute("data-images-total", String(imgs.length));
    b.setAttribute("data-images-ok", String(imgs.length - bad.length));
    b.setAttribute("data-images-bad", bad.map(function (i) { return i.alt; }).join(" | "));
    note(); b.setAttribute("data-check", "done");
  });
})();
</script>"""
"""Records script errors and whether every image decoded on ``<body>`` (read by a headless browser)."""


def _figure(res: Comparison) -> str:
    """A PNG (base64): the rate ratios with their intervals, and the Kaplan–Meier curves."""
    from observer import stats
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.4))
    rr = res.rate_ratios
    y = np.arange(len(rr))
    ok = rr["status"] == "ok"
    ax1.errorbar(rr["estimate"][ok], y[ok], xerr=[(rr["estimate"] - rr["low"])[ok], (rr["high"] - rr["estimate"])[ok]],
                 fmt="o", capsize=4)
    ax1.axvline(1.0, color="grey", lw=0.8, ls="--")
    ax1.set_yticks(y, [f"{a}/{b}" for a, b in res.pairs])
    ax1.set_xlabel("decay-rate ratio (95 % interval)")
    W = res.window[1] - res.window[0]
    col = settle_column(res.rho)
    for d in res.designs:
        sf = stats.kaplan_meier(res.members.loc[res.members["design"] == d, col].to_numpy(), W)
        if sf is None:
            ax2.plot([0, W], [1, 1], label=f"{d} (none settled)")
        else:
            ax2.step(np.concatenate([[0], sf.quantiles, [W]]), np.concatenate([[1], sf.probabilities,
                                                                                [sf.probabilities[-1]]]),
                     where="post", label=d)
    ax2.set_xlabel(f"seconds after t_on until V stays ≤ {res.rho:g}·V(t_on)")
    ax2.set_ylabel("share not settled (Kaplan–Meier)")
    ax2.set_xlim(0, W)
    ax2.legend()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def _table(frame: pd.DataFrame) -> str:
    from observer import stats

    def cell(v):
        if isinstance(v, float):
            return stats.NOT_REACHED if not math.isfinite(v) else f"{v:.4g}"
        return html.escape(str(v))
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in r) + "</tr>" for r in frame.itertuples(index=False))
    return f"<table><tr>{head}</tr>{body}</table>"


def write_report(res: Comparison, directory: str | Path) -> Path:
    """``DIR/index.html``: the lines, one figure (rate ratios, Kaplan–Meier curves), the tables;
    self-contained (the figure inline). A cell the data do not give reads "not reached"."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    lines = "".join(f"<li>{html.escape(s.strip())}</li>" for s in res.lines())
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>compare: {html.escape(res.scenario)}</title>
{SELF_CHECK}
<style>body {{ font-family: "DejaVu Sans", Arial, sans-serif; max-width: 1100px; margin: 1em auto; }}
table {{ border-collapse: collapse; font-size: 0.85em; margin-bottom: 1em; }}
td, th {{ border: 1px solid #ccc; padding: 2px 6px; }} li {{ margin: 0.15em 0; }}</style></head>
<body><h1>{html.escape(" vs ".join(res.designs))} on {html.escape(res.scenario)}</h1>
<ul>{lines}</ul>
<img alt="rate ratios and Kaplan-Meier curves" src="data:image/png;base64,{_figure(res)}" width="900">
<h2>Decay-rate ratios</h2>{_table(res.rate_ratios)}
<h2>Settling below {res.rho:g}·V(t_on), censored at the window's end</h2>{_table(res.settling)}
<p>"not reached": the Kaplan–Meier curve (or the interval's end) stays above one half inside the window.</p>
<h2>Which design settles first</h2>{_table(res.order)}
<h2>Floors (zero-error observer, matched master)</h2>{_table(res.floor_flags)}
</body></html>
"""
    out = d / "index.html"
    out.write_text(page, encoding="utf-8")
    return out
