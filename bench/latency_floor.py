"""Floor of V against the contact sensor's latency on double_mass, and the fitted power law.

For each latency d of :data:`LATENCIES` (and d = 0, the floor of the grid itself) both designs
run :data:`MEMBERS` paired members (initial errors on the energy sphere of the scenario's own
error, :func:`observer.ensemble`) whose χ comes from the sensor ``{"latency": d}``
(:mod:`observer.sensor`) on the step :data:`H` (so every latency is a whole number of steps).
A member's *floor* is the median of V/V(t_on) over the last :data:`TAIL` of the coupling
window [0, :data:`T_END`] (the level V keeps between impacts: a latency d also makes V spike at
each impact, for d seconds, by about the kinetic energy of the velocity jump, whatever d is;
the largest V there is kept as ``peak``). Per design the slope of log₁₀(floor) against log₁₀(d) is fitted over the
latencies whose median floor lies in the power-law range (:func:`fit_range`), with two 95 %
intervals (:func:`fit_slope`): the regression's (Student t, from the points' scatter about the
line: how well one power law describes the curve) and the members' (resampling the initial
errors; narrow, since with one master the floor hardly depends on the initial error).

Run ``python -m bench.latency_floor [--out FILE.json]``: it writes the member rows
(``FILE.csv``) and the fits with the settings and metadata (``FILE.json``), by default the
stored result ``bench/stored/latency_floor_double_mass.{json,csv}`` that the README quotes.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

import observer

LATENCIES = (1e-5, 2e-5, 5e-5, 1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2)
"""The sensor latencies (s): 1e-5 … 1e-2, three per decade."""
H = 1e-5
"""The step (s): the smallest latency is one step, every one a whole number of steps."""
T_END = 20.0
"""Horizon (s); the observers are coupled over [0, T_END]."""
TAIL = 0.2
"""The floor is the median of V/V(t_on) over the last TAIL of the window."""
MEMBERS = 5
"""Paired members (initial errors) per design and latency."""
SEED = 0
DESIGNS = ("jump", "nojump")
ABOVE_GRID = 100.0
"""A latency's floor counts (is the latency's, not the grid's or the window's) when its median
is at least this many times the median floor at d = 0."""
BROKEN = 0.1
"""… and below this V/V(t_on): above it the observer no longer synchronises (no power law)."""
CONFIDENCE = 0.95
RESAMPLES = 2000
OUT = Path(__file__).resolve().parent / "stored" / "latency_floor_double_mass.json"


def measure(latency: float, members: int = MEMBERS, h: float = H, t_end: float = T_END) -> pd.DataFrame:
    """One latency: per (design, member) ``V_on``, the floor and the peak of V over the tail
    (each absolute, ``*_V``, and relative to V_on)."""
    out = measure_sensor({"latency": latency} if latency > 0 else None, members, h, t_end)
    out.insert(0, "latency", latency)
    return out


def measure_sensor(sensor: dict | None, members: int = MEMBERS, h: float = H, t_end: float = T_END) -> pd.DataFrame:
    """As :func:`measure` for any ``[observer.sensor]`` table (None: the ideal sensor)."""
    sc = observer.load_scenario("double_mass", {"observer.coupling": [0.0, t_end]})
    df = observer.ensemble(sc, designs=DESIGNS, n=members, seed=SEED, h=h, t_end=t_end, workers=1,
                           paths=members, sensor=sensor)
    paths = df.attrs["paths"]
    tail = paths[paths["t"] >= (1.0 - TAIL) * t_end]
    by = tail.groupby(["design", "member"])["V"]
    levels = pd.concat([by.median().rename("floor_V"), by.max().rename("peak_V")], axis=1).reset_index()
    out = df[["design", "member", "V_on", "status"]].merge(levels, on=["design", "member"], validate="one_to_one")
    out["floor"] = out["floor_V"] / out["V_on"]
    out["peak"] = out["peak_V"] / out["V_on"]
    out["intervals_seen"] = df.attrs["metadata"].get("sensor", {}).get("intervals")
    return out


def fit_range(rows: pd.DataFrame, design: str) -> list[float]:
    """The latencies > 0 of ``design`` whose median floor is at least :data:`ABOVE_GRID` times
    the median at d = 0 and below :data:`BROKEN`."""
    med = rows[rows["design"] == design].groupby("latency")["floor"].median()
    base = float(med.get(0.0, 0.0))
    return [float(d) for d, f in med.items() if d > 0 and f >= ABOVE_GRID * base and f < BROKEN]


def fit_slope(rows: pd.DataFrame, design: str, latencies: list[float], seed: int = 0) -> dict:
    """Least-squares slope of log₁₀(median floor over members) on log₁₀(latency) over
    ``latencies``, with two :data:`CONFIDENCE` intervals: ``interval["regression"]`` (slope ±
    t·standard error, k − 2 degrees of freedom for k latencies) and ``interval["members"]``
    (percentiles of the slope over :data:`RESAMPLES` resamplings of the members, paired: a
    resampled member keeps its floors at every latency)."""
    from scipy import stats

    sub = rows[(rows["design"] == design) & rows["latency"].isin(latencies)]
    table = sub.pivot(index="member", columns="latency", values="floor")[sorted(latencies)]
    x = np.log10(np.asarray(table.columns, dtype=float))
    if x.size < 3:
        return {"design": design, "status": "too few latencies in the power-law range",
                "latencies": list(map(float, table.columns)), "slope": None, "interval": None}
    F = np.log10(table.to_numpy(dtype=float))

    def slope(logs):
        return float(np.polyfit(x, np.median(logs, axis=0), 1)[0])

    rng = np.random.default_rng(seed)
    boot = [slope(F[rng.integers(0, F.shape[0], F.shape[0])]) for _ in range(RESAMPLES)]
    a = (1.0 - CONFIDENCE) / 2
    reg = stats.linregress(x, np.median(F, axis=0))
    half = float(stats.t.ppf(1 - a, x.size - 2) * reg.stderr)
    return {"design": design, "status": "ok", "latencies": list(map(float, table.columns)),
            "slope": float(reg.slope), "intercept": float(reg.intercept),
            "interval": {"regression": [float(reg.slope) - half, float(reg.slope) + half],
                         "members": [float(np.quantile(boot, a)), float(np.quantile(boot, 1 - a))]},
            "members": int(F.shape[0])}


def run(out: Path, members: int = MEMBERS, h: float = H, t_end: float = T_END,
        latencies=LATENCIES) -> dict:
    """Measure every latency (and d = 0), fit both designs, write ``out`` (JSON) and its CSV."""
    from observer.result import package_versions

    t0 = time.perf_counter()
    rows = pd.concat([measure(d, members, h, t_end) for d in (0.0, *latencies)], ignore_index=True)
    fits = [fit_slope(rows, d, fit_range(rows, d)) for d in DESIGNS]
    result = {"what": "floor of V/V(t_on) against the contact sensor's latency, double_mass",
              "status": "ok" if all(f["status"] == "ok" for f in fits) else "incomplete",
              "settings": {"scenario": "double_mass", "h": h, "t_end": t_end, "coupling": [0.0, t_end],
                           "tail": TAIL, "members": members, "seed": SEED, "designs": list(DESIGNS),
                           "latencies": list(latencies), "above_grid": ABOVE_GRID, "broken": BROKEN,
                           "confidence": CONFIDENCE, "resamples": RESAMPLES},
              "fits": fits,
              "median_floor": {d: {str(k): float(v) for k, v in
                                   rows[rows["design"] == d].groupby("latency")["floor"].median().items()}
                               for d in DESIGNS},
              "versions": package_versions(), "wall_time_s": time.perf_counter() - t0}
    out.parent.mkdir(parents=True, exist_ok=True)
    rows.to_csv(out.with_suffix(".csv"), index=False, float_format="%.17g")
    out.write_text(json.dumps(result, indent=1, default=float) + "\n", encoding="utf-8")
    return result


def main(argv=None) -> int:
    from bench.floor_curves import floor_arguments

    args = floor_arguments(argv, "python -m bench.latency_floor", __doc__.splitlines()[0], OUT,
                           "the JSON result (the rows go to the .csv beside it)", MEMBERS)
    if args is None:
        return 2
    if args.out.suffix != ".json":
        print("error: --out: must end in .json (the rows go to the .csv beside it)", file=sys.stderr)
        return 2
    try:
        result = run(args.out, args.members)
    except observer.InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for f in result["fits"]:
        print(f"{f['design']}: slope {f['slope']} (95 % intervals {f['interval']}) over {f['latencies']} "
              f"({f['status']})")
    print(f"wrote {args.out} and {args.out.with_suffix('.csv')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
