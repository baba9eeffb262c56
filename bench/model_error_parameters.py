"""The floor of V against a relative error ε of each of M, C, K, W, per scenario (issue 33, item 3).

For each parameter P of :data:`PARAMETERS` and each ε of :data:`EPSILONS` (1e-4 … 1e-1, three
per decade) the observers carry ``P̂ = (1 + ε)P`` (``[observer.model] P = { scale = 1 + ε }``),
the others exact, while the master is the true plant; both designs run paired members (the same
initial errors on the energy sphere at every ε and in both designs, seed
:data:`bench.model_error.SEED`; the floor = max V/V(t_on) over the last quarter of the coupling
window). Per parameter and design: the median floor, the power-law fit over the sizes where the
floor is the parameter's (:func:`observer.floor_curves.fit_curve`) and the crossover of the two
designs (:func:`observer.floor_curves.crossovers`).

On ``double_mass`` (the default) the members are those of :func:`bench.model_error.member_floors`
(:data:`bench.model_error.MEMBERS`, the scenario's own step, horizon and initial error). Another
scenario of :data:`SCENARIOS` runs :func:`scenario_floors`, the same measurement with the
settings stated there (a horizon long enough for both designs to reach their floor, and the
sphere's level V0 where the scenario has no ``[observer]`` initial error); its result names
them.

``python -m bench.model_error_parameters [--scenario NAME] [--out FILE]`` writes the result
(default :func:`stored_path` of the scenario); ``--quick`` runs 4 members over 2 s (a check that
it runs, not the measurement).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from bench.floor_curves import curve_record, write_json
from bench.model_error import DESIGNS, MEMBERS, SEED, member_floors, path_floors

PARAMETERS = ("M", "C", "K", "W")
EPSILONS = tuple(float(x) for x in np.logspace(-4, -1, 10))
"""The relative errors: 1e-4 … 1e-1, three per decade, both ends included."""
DEFAULT = "double_mass"
SCENARIOS = {
    "double_mass": {},
    "impact_oscillator": {"t_end": 300.0, "h": 5e-4, "V0": 5e-3},
}
"""Per scenario the settings that differ from the scenario's own (``t_end`` and the step ``h``
in s, ``V0`` the energy sphere's level): on impact_oscillator (undamped, no ``[observer]``
table) the observers are coupled over the whole run, V0 = ½·0.1² (a position error of 0.1 in
the metric ½eᵀKe + ½vᵀMv), 300 s lets the design without jumps reach its floor, and half the
scenario's step lowers the floor of the exact model, which bounds the fitted range from below."""
STORED = Path(__file__).parent / "stored" / "model_error_parameters_double_mass.json"


def stored_path(scenario: str) -> Path:
    """The stored result of ``scenario``: ``bench/stored/model_error_parameters_<scenario>.json``."""
    return STORED.with_name(f"model_error_parameters_{scenario}.json")


def scenario_floors(scenario: str, eps: float, n: int, seed: int, t_end: float | None, workers: int | None,
                    parameter: str = "K", h: float | None = None, V0: float | None = None) -> dict:
    """Per design, the n members' floors on ``scenario`` with the observers' ``parameter`` (a
    matrix: M, C, K or W) times 1 + ε: :func:`bench.model_error.member_floors` for any scenario,
    with the step ``h`` and the sphere's level ``V0`` (None: the scenario's own)."""
    import observer

    model = None if eps == 0.0 else {parameter: {"scale": 1.0 + eps}}
    df = observer.ensemble(scenario, DESIGNS, n=n, seed=seed, t_end=t_end, h=h, V0=V0, paths=n,
                           workers=workers, model=model)
    paths = df.attrs["paths"]
    t_end_run = float(df["t_end"].iloc[0])
    t_on, t_off = observer.load_scenario(scenario).observer.get("coupling") or (0.0, t_end_run)
    t_off = min(float(t_off), t_end_run)
    return path_floors(paths, n, t_on, t_off)


def floors_of(scenario: str, settings: dict, n: int, seed: int, t_end: float | None, workers: int | None):
    """The member-floor function of ``scenario``: ``f(eps, parameter)``."""
    if scenario == DEFAULT:
        return lambda e, p="K": member_floors(e, n, seed, t_end, workers, p)
    t_end = settings.get("t_end") if t_end is None else t_end
    return lambda e, p="K": scenario_floors(scenario, e, n, seed, t_end, workers, p, settings.get("h"),
                                            settings.get("V0"))


def measure(n: int = MEMBERS, seed: int = SEED, t_end: float | None = None, workers: int | None = None,
            scenario: str = DEFAULT) -> dict:
    """The measurement of the module docstring, as a JSON-ready dict with its metadata."""
    from observer.result import package_versions

    t0 = time.perf_counter()
    settings = SCENARIOS[scenario]
    floors = floors_of(scenario, settings, n, seed, t_end, workers)
    exact = floors(0.0)
    curves = []
    for p in PARAMETERS:
        per = [floors(e, p) for e in EPSILONS]
        curves.append(curve_record(p, f"relative {p} error ε (observers' {p}̂ = (1 + ε){p})", "",
                                   EPSILONS, per, exact, DESIGNS, seed))
    command = "python -m bench.model_error_parameters" + ("" if scenario == DEFAULT else f" --scenario {scenario}")
    extra = {} if scenario == DEFAULT else {"settings": {"t_end": settings.get("t_end") if t_end is None else t_end,
                                                         "h": settings.get("h"), "V0": settings.get("V0")}}
    return {"what": "floor of V/V(t_on) against a relative error of one parameter of the observers' model",
            "scenario": scenario, "model": "P = { scale = 1 + eps }, the other parameters exact",
            "command": command, "members": n, "seed": seed, "t_end": t_end, **extra,
            "floor": "max V/V(t_on) over the last quarter of the coupling window; median over members",
            "designs": list(DESIGNS), "curves": curves,
            "status": "ok" if all(c["designs"][d]["fit"]["status"] == "ok" for c in curves for d in DESIGNS)
            else "partial: some curves not fitted (see each fit's status)",
            "versions": package_versions(), "wall_time_s": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.model_error_parameters",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=DEFAULT, help=f"one of {', '.join(SCENARIOS)} (default {DEFAULT})")
    parser.add_argument("--out", type=Path, default=None,
                        help="the JSON result (default: the scenario's stored one)")
    parser.add_argument("--quick", action="store_true", help="2 s, 4 members: a check that it runs")
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args(argv)
    if args.scenario not in SCENARIOS:
        print(f"error: --scenario: must be one of {', '.join(SCENARIOS)}, got {args.scenario!r}", file=sys.stderr)
        return 2
    out = stored_path(args.scenario) if args.out is None else args.out
    result = measure(workers=args.workers, scenario=args.scenario, **({"n": 4, "t_end": 2.0} if args.quick else {}))
    write_json(result, out)
    for c in result["curves"]:
        for d, r in c["designs"].items():
            f = r["fit"]
            print(f"{c['key']} {d}: {f['status']}, slope {f['slope']} {f['interval']} over {f['sizes']}")
        print(f"{c['key']} crossovers: {c['crossovers']}")
    print(f"wrote {out} ({result['wall_time_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
