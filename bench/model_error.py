"""The floor of V under a stiffness error of relative size ε (issue 33, acceptance item 3).

On ``double_mass`` the observers carry ``K̂ = (1 + ε)K`` (``[observer.model] K = { scale = 1 + ε }``,
:mod:`observer.plant_model`) while the master is the true plant. Per ε of :data:`EPSILONS` (and
ε = 0, the discretisation floor), :data:`MEMBERS` paired members per design (the energy sphere
of :func:`observer.ensemble`, seed :data:`SEED`) run over the scenario's whole coupling window;
a member's **floor** is ``max V(t)/V(t_on)`` over the last quarter of the window (V sampled on
the members loop's path grid). Per design the floor is the median over the members, and

    log10 floor = a + s·log10 ε

is fitted by least squares over ε = 1e-4 … 1e-2; the slope s is stated with a 95 % interval
from :data:`RESAMPLES` bootstrap resamples of the members (paired across ε and designs: member
i is the same initial error everywhere), the percentile interval of the refitted slope.

A **sensitivity table** goes with it: the median floor per design when one parameter of the
plant is off by :data:`SENSITIVITY_EPS` relative (M, C, K or W times 1 + ε, or the gap offset
ν times 1 + ε), the others exact — which parameter's error costs most on this scenario.

An **uncertainty ensemble** completes it: :data:`DRAWS` observer models drawn around the plant,
``K = { relative_std = σ, seed = s }`` with σ = :data:`DRAW_STD` and s = 0 … DRAWS − 1 (the
plant fixed, the model sampled), the same members for every draw and design (paired); per
design the median floor of each draw, their median and 2.5–97.5 % range over the draws, and
the fraction of draws in which the observer without jumps has the lower floor.

``python -m bench.model_error [--out FILE]`` writes the result (default
:data:`STORED`, the stored result the guide's numbers come from); ``--quick`` runs a
short horizon and few members (a check that the script runs, not the measurement).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

EPSILONS = tuple(float(x) for x in np.logspace(-4, -2, 7))
"""The relative K errors of the fit (half-decade steps from 1e-4 to 1e-2, both ends included)."""
MEMBERS = 20
SEED = 0
RESAMPLES = 2000
TAIL = 0.25
"""The floor is the largest V/V(t_on) over this last fraction of the coupling window."""
DESIGNS = ("jump", "nojump")
DRAWS = 20
DRAW_STD = 1e-2
SENSITIVITY_EPS = 1e-2
SENSITIVITY = ("M", "C", "K", "W", "gap.offset")
"""The parameters of the sensitivity table, each off by :data:`SENSITIVITY_EPS` alone."""
STORED = Path(__file__).parent / "stored" / "model_error_floor_double_mass.json"


def one_parameter_model(name: str, eps: float) -> dict | None:
    """The ``[observer.model]`` table with parameter ``name`` (a matrix or ``gap.offset``) off by
    the relative ε (None for ε = 0)."""
    import observer

    if eps == 0.0:
        return None
    if name == "gap.offset":
        offset = observer.load_scenario("double_mass").system.gap.constant
        return {"gap": {"offset": ((1.0 + eps) * offset).tolist()}}
    return {name: {"scale": 1.0 + eps}}


def member_floors(eps: float, n: int, seed: int, t_end: float | None, workers: int | None,
                  parameter: str = "K", model: dict | None = None) -> dict:
    """Per design, the n members' floors (module docstring) with the observers' ``parameter``
    off by the relative ε (default K = (1 + ε)K), or with the observer model ``model``."""
    import observer

    model = one_parameter_model(parameter, eps) if model is None else model
    df = observer.ensemble("double_mass", DESIGNS, n=n, seed=seed, t_end=t_end, paths=n, workers=workers,
                           model=model)
    paths = df.attrs["paths"]
    sc = observer.load_scenario("double_mass")
    t_on, t_off = sc.observer["coupling"]
    t_off = min(float(t_off), float(df["t_end"].iloc[0]))
    return path_floors(paths, n, t_on, t_off)


def path_floors(paths, n: int, t_on: float, t_off: float) -> dict[str, list[float]]:
    """Per design of :data:`DESIGNS`, the floors of members 0 … n−1 read from their recorded
    paths (``t``, ``V`` per design and member): the largest V/V(t_on) over the window's last
    :data:`TAIL` fraction, ``[t_off − TAIL·(t_off − t_on), t_off]``."""
    start = t_off - TAIL * (t_off - t_on)
    out = {}
    for d in DESIGNS:
        floors = []
        for i in range(n):
            p = paths[(paths.design == d) & (paths.member == i)]
            t, V = p["t"].to_numpy(), p["V"].to_numpy()
            V_on = V[np.searchsorted(t, t_on)]
            floors.append(float(np.max(V[(t >= start) & (t <= t_off)]) / V_on))
        out[d] = floors
    return out


def fit_slope(eps: np.ndarray, floors: np.ndarray) -> tuple[float, float]:
    """Least-squares ``(slope, intercept)`` of log10(median floor) against log10 ε; ``floors``
    has shape (len(eps), members)."""
    s, a = np.polyfit(np.log10(eps), np.log10(np.median(floors, axis=1)), 1)
    return float(s), float(a)


def bootstrap_slopes(eps: np.ndarray, floors: np.ndarray, resamples: int, rng: np.random.Generator) -> np.ndarray:
    """The slope refitted on ``resamples`` resamples of the members (the same members at every ε)."""
    n = floors.shape[1]
    return np.array([fit_slope(eps, floors[:, rng.integers(0, n, n)])[0] for _ in range(resamples)])


def measure(n: int = MEMBERS, seed: int = SEED, t_end: float | None = None, workers: int | None = None,
            resamples: int = RESAMPLES) -> dict:
    """The measurement of the module docstring, as a JSON-ready dict with its metadata."""
    from observer.result import package_versions

    t0 = time.perf_counter()
    exact = member_floors(0.0, n, seed, t_end, workers)
    per_eps = [member_floors(e, n, seed, t_end, workers) for e in EPSILONS]
    eps = np.array(EPSILONS)
    result = {"scenario": "double_mass", "model": "K = { scale = 1 + eps }", "epsilons": list(EPSILONS),
              "members": n, "seed": seed, "t_end": t_end, "tail": TAIL, "resamples": resamples,
              "floor": "max V/V(t_on) over the last quarter of the coupling window; median over members",
              "designs": {}}
    rng = np.random.default_rng(seed)
    for d in DESIGNS:
        F = np.array([f[d] for f in per_eps])
        slope, intercept = fit_slope(eps, F)
        boot = bootstrap_slopes(eps, F, resamples, rng)
        lo, hi = np.percentile(boot, [2.5, 97.5])
        result["designs"][d] = {"exact_floor_median": float(np.median(exact[d])),
                                "floor_median": [float(x) for x in np.median(F, axis=1)],
                                "member_floors": F.tolist(), "exact_member_floors": exact[d],
                                "slope": slope, "slope_interval_95": [float(lo), float(hi)],
                                "intercept": intercept}
    result["sensitivity"] = {"eps": SENSITIVITY_EPS, "floor_median": {}}
    for name in SENSITIVITY:
        f = member_floors(SENSITIVITY_EPS, n, seed, t_end, workers, name)
        result["sensitivity"]["floor_median"][name] = {d: float(np.median(f[d])) for d in DESIGNS}
    result["uncertainty"] = sampled_models(n, seed, t_end, workers)
    result["status"] = "ok"
    result["versions"] = package_versions()
    result["wall_time_s"] = time.perf_counter() - t0
    return result


def sampled_models(n: int, seed: int, t_end: float | None, workers: int | None, draws: int = DRAWS) -> dict:
    """The uncertainty ensemble of the module docstring."""
    per = [member_floors(0.0, n, seed, t_end, workers, model={"K": {"relative_std": DRAW_STD, "seed": s}})
           for s in range(draws)]
    med = {d: np.array([np.median(f[d]) for f in per]) for d in DESIGNS}
    out = {"model": f"K = {{ relative_std = {DRAW_STD}, seed = s }}, s = 0..{draws - 1}", "draws": draws,
           "draw_floor_median": {d: med[d].tolist() for d in DESIGNS},
           "floor_median_over_draws": {d: float(np.median(med[d])) for d in DESIGNS},
           "floor_range_95": {d: [float(x) for x in np.percentile(med[d], [2.5, 97.5])] for d in DESIGNS}}
    out["nojump_lower_fraction"] = float(np.mean(med["nojump"] < med["jump"]))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.model_error", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=STORED, help="the JSON result (default: the stored one)")
    parser.add_argument("--quick", action="store_true", help="2 s, 4 members: a check that it runs")
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args(argv)
    kw = {"n": 4, "t_end": 2.0, "resamples": 200} if args.quick else {}
    result = measure(workers=args.workers, **kw)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1) + "\n")
    tmp.replace(args.out)
    for d, r in result["designs"].items():
        print(f"{d}: slope {r['slope']:.3f} [{r['slope_interval_95'][0]:.3f}, {r['slope_interval_95'][1]:.3f}]; "
              f"exact floor {r['exact_floor_median']:.3g}; floors {', '.join(f'{x:.3g}' for x in r['floor_median'])}")
    u = result["uncertainty"]
    print(f"{u['model']}: " + ", ".join(f"{d} {u['floor_median_over_draws'][d]:.3g} "
                                        f"[{u['floor_range_95'][d][0]:.3g}, {u['floor_range_95'][d][1]:.3g}]"
                                        for d in DESIGNS) + f"; nojump lower in {u['nojump_lower_fraction']:.0%}")
    for name, floors in result["sensitivity"]["floor_median"].items():
        print(f"{name} off by {result['sensitivity']['eps']:g}: " + ", ".join(f"{d} {v:.3g}" for d, v in floors.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
