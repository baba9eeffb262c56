"""The floor of V against the contact sensor's jitter and threshold δ on double_mass (issue 33, item 3).

As :mod:`bench.latency_floor` (same step :data:`bench.latency_floor.H`, horizon, coupling
window, tail, paired members and seed; :func:`bench.latency_floor.measure_sensor`; a member's
floor is the median of V/V(t_on) over the last :data:`bench.latency_floor.TAIL` of the
window), with χ from the sensor ``{"jitter": σ}`` for σ of :data:`JITTERS` (every closing and
opening time moved by an independent N(0, σ²) error, sensor seed :data:`SENSOR_SEED`), and
from ``{"threshold": δ}`` for δ of :data:`THRESHOLDS` (a contact is seen closed as soon as the
plant's predicted gap falls below δ), :mod:`observer.sensor`. Per uncertainty and design: the
median floor, the power-law fit over the sizes where the floor is the sensor's
(:func:`observer.floor_curves.fit_curve`) and the crossover of the two designs
(:func:`observer.floor_curves.crossovers`).

``python -m bench.sensor_floor [--out FILE]`` writes the result (default :data:`STORED`, beside
the latency result).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from bench.floor_curves import curve_record, floor_arguments, write_json
from bench.latency_floor import DESIGNS, H, MEMBERS, SEED, T_END, TAIL, measure_sensor

JITTERS = (1e-5, 2e-5, 5e-5, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2)
"""The sensor's timing jitter σ (s): 1e-5 … 1e-2, three per decade."""
THRESHOLDS = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2)
"""The sensor's threshold δ (m): one per decade."""
SENSOR_SEED = 0
STORED = Path(__file__).resolve().parent / "stored" / "sensor_floor_double_mass.json"
UNCERTAINTIES = (("jitter", "sensor timing jitter σ", "s", JITTERS),
                 ("threshold", "sensor threshold δ", "m", THRESHOLDS))


def member_floors(sensor: dict | None, members: int, t_end: float) -> dict:
    """Per design, the members' floors (ordered by member) with χ from ``sensor``."""
    rows = measure_sensor(sensor, members, H, t_end)
    return {d: rows[rows["design"] == d].sort_values("member")["floor"].to_numpy(float).tolist() for d in DESIGNS}


def measure(members: int = MEMBERS, t_end: float = T_END) -> dict:
    """The measurement of the module docstring, as a JSON-ready dict with its metadata."""
    from observer.result import package_versions

    t0 = time.perf_counter()
    exact = member_floors(None, members, t_end)
    curves = []
    for key, label, unit, sizes in UNCERTAINTIES:
        per = [member_floors({key: s, "seed": SENSOR_SEED}, members, t_end) for s in sizes]
        curves.append(curve_record(key, label, unit, sizes, per, exact, DESIGNS, SEED))
    return {"what": "floor of V/V(t_on) against the contact sensor's jitter and threshold",
            "scenario": "double_mass", "command": "python -m bench.sensor_floor",
            "settings": {"h": H, "t_end": t_end, "coupling": [0.0, t_end], "tail": TAIL, "members": members,
                         "seed": SEED, "sensor_seed": SENSOR_SEED},
            "floor": f"median of V/V(t_on) over the last {TAIL:g} of the coupling window; median over members",
            "designs": list(DESIGNS), "curves": curves,
            "status": "ok" if all(c["designs"][d]["fit"]["status"] == "ok" for c in curves for d in DESIGNS)
            else "partial: some curves not fitted (see each fit's status)",
            "versions": package_versions(), "wall_time_s": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    args = floor_arguments(argv, "python -m bench.sensor_floor", __doc__.splitlines()[0], STORED,
                           "the JSON result (default: the stored one)", MEMBERS)
    if args is None:
        return 2
    result = measure(args.members)
    write_json(result, args.out)
    for c in result["curves"]:
        for d, r in c["designs"].items():
            f = r["fit"]
            print(f"{c['key']} {d}: medians {np.round(r['floor_median'], 12).tolist()}; {f['status']}, "
                  f"slope {f['slope']} {f['interval']}")
        print(f"{c['key']} crossovers: {c['crossovers']}")
    print(f"wrote {args.out} ({result['wall_time_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
