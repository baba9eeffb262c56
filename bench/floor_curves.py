"""The stored floor-versus-size curves (issue 33, item 3): the record of one curve, its JSON
file and the scripts' command line. The statistics (the power-law fit, the crossovers with
their intervals, the size a model must be known to) are :mod:`observer.floor_curves`'s.
"""

from __future__ import annotations

import numpy as np

from observer.floor_curves import crossovers, fit_curve


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
