"""Floor-versus-size curves: the power-law fit and the crossover of two designs (issue 33, item 3).

Shared by :mod:`bench.model_error_parameters` (one parameter of the observers' model off by a
relative ε) and :mod:`bench.sensor_floor` (the contact sensor's jitter and threshold δ). A
curve is, per design, the member floors ``F`` (shape: sizes × members, member i the same
initial error at every size) at ascending sizes > 0 and the member floors at size 0 (the exact
model or ideal sensor: the floor of the grid and the window).

The **fit range** is the sizes whose median floor is at least :data:`ABOVE_EXACT` times the
median at size 0 (the uncertainty's floor, not the grid's) and below :data:`BROKEN` (above it
the observer no longer synchronises); over it ``log10 floor = a + s·log10 size`` is fitted to the
median floor (log10 of the median over members) by least squares, with two 95 % intervals: the regression's (slope ± t·standard
error, k − 2 degrees of freedom) and the members' (percentiles of the slope refitted on
:data:`RESAMPLES` paired resamples of the members). Fewer than 3 sizes in range: no fit, and
the status says so.

The **crossover** of two designs is every pair of consecutive sizes between which the sign of
log10(median floor a / median floor b) changes, with the log-log interpolated size of the
change and the design that has the lower floor above it.
"""

from __future__ import annotations

import numpy as np

ABOVE_EXACT = 10.0
"""A size is in the fit range when its median floor is at least this many times the one at size 0 …"""
BROKEN = 0.1
"""… and below this V/V(t_on)."""
CONFIDENCE = 0.95
RESAMPLES = 2000


def fit_range(sizes: np.ndarray, F: np.ndarray, exact: np.ndarray) -> np.ndarray:
    """Boolean mask of the sizes in the fit range (module docstring)."""
    med = np.median(F, axis=1)
    return (med >= ABOVE_EXACT * np.median(exact)) & (med < BROKEN)


def fit_curve(sizes, F, exact, seed: int = 0) -> dict:
    """The fit of the module docstring over the fit range, as a JSON-ready dict."""
    from scipy import stats

    sizes, F, exact = np.asarray(sizes, float), np.asarray(F, float), np.asarray(exact, float)
    keep = fit_range(sizes, F, exact)
    x, F = np.log10(sizes[keep]), F[keep]
    if x.size < 3:
        return {"status": f"not fitted: {x.size} size(s) in the power-law range (need 3)",
                "sizes": sizes[keep].tolist(), "slope": None, "intercept": None, "interval": None}
    reg = stats.linregress(x, np.log10(np.median(F, axis=1)))
    a = (1.0 - CONFIDENCE) / 2
    half = float(stats.t.ppf(1 - a, x.size - 2) * reg.stderr)
    rng = np.random.default_rng(seed)
    n = F.shape[1]
    boot = [np.polyfit(x, np.log10(np.median(F[:, rng.integers(0, n, n)], axis=1)), 1)[0] for _ in range(RESAMPLES)]
    return {"status": "ok", "sizes": sizes[keep].tolist(), "slope": float(reg.slope),
            "intercept": float(reg.intercept),
            "interval": {"regression": [float(reg.slope) - half, float(reg.slope) + half],
                         "members": [float(np.quantile(boot, a)), float(np.quantile(boot, 1 - a))]}}


def crossovers(sizes, median_a, median_b, a: str, b: str) -> list[dict]:
    """Every crossover of design ``a``'s median floor with ``b``'s (module docstring)."""
    sizes = np.asarray(sizes, float)
    d = np.log10(np.asarray(median_a, float)) - np.log10(np.asarray(median_b, float))
    out = []
    for i in range(len(d) - 1):
        if d[i] * d[i + 1] < 0:
            w = d[i] / (d[i] - d[i + 1])
            at = 10.0 ** (np.log10(sizes[i]) + w * np.log10(sizes[i + 1] / sizes[i]))
            out.append({"between": [float(sizes[i]), float(sizes[i + 1])], "at": float(at),
                        "lower_above": a if d[i + 1] < 0 else b})
    return out


def curve_record(key: str, label: str, unit: str, sizes, per_size: list[dict], exact: dict,
                 designs: tuple, seed: int = 0) -> dict:
    """One uncertainty's stored curve: per design the member floors, the median and the fit,
    and the crossovers of the first two designs. ``per_size[j][design]`` is the member floors at
    ``sizes[j]``; ``exact[design]`` the member floors at size 0."""
    out = {"key": key, "label": label, "unit": unit, "sizes": [float(s) for s in sizes], "designs": {}}
    for d in designs:
        F = np.array([p[d] for p in per_size], dtype=float)
        out["designs"][d] = {"member_floors": F.tolist(), "exact_member_floors": [float(x) for x in exact[d]],
                             "floor_median": np.median(F, axis=1).tolist(),
                             "exact_floor_median": float(np.median(exact[d])),
                             "fit": fit_curve(sizes, F, exact[d], seed)}
    a, b = designs[:2]
    out["crossovers"] = crossovers(sizes, out["designs"][a]["floor_median"], out["designs"][b]["floor_median"], a, b)
    return out


def write_json(result: dict, out) -> None:
    """Write ``result`` to ``out`` through a temporary file beside it."""
    import json
    from pathlib import Path

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    tmp.replace(out)


def floor_arguments(argv, prog: str, description: str, out, out_help: str, members: int):
    """The ``--out FILE --members N`` command line of the floor scripts
    (:mod:`bench.latency_floor`, :mod:`bench.sensor_floor`): the parsed arguments, or None
    after one ``error: --members: ...`` line on stderr for fewer than one member."""
    import argparse
    import sys
    from pathlib import Path

    p = argparse.ArgumentParser(prog=prog, description=description)
    p.add_argument("--out", type=Path, default=out, help=out_help)
    p.add_argument("--members", type=int, default=members)
    args = p.parse_args(argv)
    if args.members < 1:
        print(f"error: --members: must be an integer ≥ 1, got {args.members}", file=sys.stderr)
        return None
    return args
