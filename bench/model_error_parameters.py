"""The floor of V against a relative error ε of each of M, C, K, W on double_mass (issue 33, item 3).

For each parameter P of :data:`PARAMETERS` and each ε of :data:`EPSILONS` (1e-4 … 1e-1, three
per decade) the observers carry ``P̂ = (1 + ε)P`` (``[observer.model] P = { scale = 1 + ε }``),
the others exact, while the master is the true plant; both designs run the paired members of
:func:`bench.model_error.member_floors` (the same members as :mod:`bench.model_error`:
:data:`bench.model_error.MEMBERS` initial errors on the energy sphere, seed
:data:`bench.model_error.SEED`, the floor = max V/V(t_on) over the last quarter of the coupling
window). Per parameter and design: the median floor, the power-law fit over the sizes where the
floor is the parameter's (:func:`observer.floor_curves.fit_curve`) and the crossover of the two
designs (:func:`observer.floor_curves.crossovers`).

``python -m bench.model_error_parameters [--out FILE]`` writes the result (default
:data:`STORED`); ``--quick`` runs 4 members over 2 s (a check that it runs, not the measurement).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bench.floor_curves import curve_record, write_json
from bench.model_error import DESIGNS, MEMBERS, SEED, member_floors

PARAMETERS = ("M", "C", "K", "W")
EPSILONS = tuple(float(x) for x in np.logspace(-4, -1, 10))
"""The relative errors: 1e-4 … 1e-1, three per decade, both ends included."""
STORED = Path(__file__).parent / "stored" / "model_error_parameters_double_mass.json"


def measure(n: int = MEMBERS, seed: int = SEED, t_end: float | None = None, workers: int | None = None) -> dict:
    """The measurement of the module docstring, as a JSON-ready dict with its metadata."""
    from observer.result import package_versions

    t0 = time.perf_counter()
    exact = member_floors(0.0, n, seed, t_end, workers)
    curves = []
    for p in PARAMETERS:
        per = [member_floors(e, n, seed, t_end, workers, p) for e in EPSILONS]
        curves.append(curve_record(p, f"relative {p} error ε (observers' {p}̂ = (1 + ε){p})", "",
                                   EPSILONS, per, exact, DESIGNS, seed))
    return {"what": "floor of V/V(t_on) against a relative error of one parameter of the observers' model",
            "scenario": "double_mass", "model": "P = { scale = 1 + eps }, the other parameters exact",
            "command": "python -m bench.model_error_parameters", "members": n, "seed": seed, "t_end": t_end,
            "floor": "max V/V(t_on) over the last quarter of the coupling window; median over members",
            "designs": list(DESIGNS), "curves": curves,
            "status": "ok" if all(c["designs"][d]["fit"]["status"] == "ok" for c in curves for d in DESIGNS)
            else "partial: some curves not fitted (see each fit's status)",
            "versions": package_versions(), "wall_time_s": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.model_error_parameters",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=STORED, help="the JSON result (default: the stored one)")
    parser.add_argument("--quick", action="store_true", help="2 s, 4 members: a check that it runs")
    parser.add_argument("--workers", type=int, default=None)
    args = parser.parse_args(argv)
    result = measure(workers=args.workers, **({"n": 4, "t_end": 2.0} if args.quick else {}))
    write_json(result, args.out)
    for c in result["curves"]:
        for d, r in c["designs"].items():
            f = r["fit"]
            print(f"{c['key']} {d}: {f['status']}, slope {f['slope']} {f['interval']} over {f['sizes']}")
        print(f"{c['key']} crossovers: {c['crossovers']}")
    print(f"wrote {args.out} ({result['wall_time_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
