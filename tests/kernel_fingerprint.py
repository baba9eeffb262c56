"""Fingerprints of the compiled engine's trajectories on every built-in scenario.

``python tests/kernel_fingerprint.py`` (from the repository root) adds to
``tests/data/kernel_fingerprints.json`` this machine's digests: per built-in scenario and run
variant, the sha256 of the recorded arrays of a 4000-step run (at most the scenario's
horizon), kept as a list of one digest per floating-point build (BLAS and LAPACK kernels round
differently: an AVX-512 build's LAPACK solve gives other bits than another's). The stored
table was written by main at d26e40e, before the kernel took its arguments in bundles
(issue 21; ``random_system`` by 19073f2, which added it), on two builds: the machine of
61480db and an AVX-512 Xeon (the same commits run there, the script copied into their trees).
tests/observer/test_kernel.py recomputes it and requires every digest to be one of them, bit
for bit.

Variants (each takes a different compiled loop, :func:`observer.loop.specialization`):
``alone`` (the master alone: the lean or the scalar loop), ``observers`` (the scenario's
observers, or ``nojump``: the general loop), ``projected`` (the master projected, with a
jump observer: the general loop's projections; only where K is positive definite) and
``summary`` (``store="summary"``, every 10th row kept, the summary table hashed too).
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

PATH = Path(__file__).parent / "data" / "kernel_fingerprints.json"
STEPS = 4000


def digest(*arrays) -> str:
    """sha256 of the arrays' dtypes, shapes and bytes, in order (None hashed as a marker)."""
    h = hashlib.sha256()
    for a in arrays:
        if a is None:
            h.update(b"none")
            continue
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def result_digest(res) -> str:
    """The digest of a result's master and observers' recorded arrays."""
    arrays = [res.t, res.q, res.u, res.P, res.active]
    for name in sorted(res.slaves):
        s = res.slaves[name]
        arrays += [s.q, s.u, s.P, s.V]
    summary = getattr(res, "summary", None)
    if summary is not None:
        arrays.append(summary.select_dtypes("number").to_numpy(dtype=float))
    return digest(*arrays)


def variants(name: str) -> dict:
    """The runs of scenario ``name``: variant → simulate's keyword arguments."""
    import observer

    sc = observer.load_scenario(name)
    obs = tuple((sc.observer or {}).get("observers", ())) or ("nojump",)
    T = min(sc.t_end, STEPS * sc.h)
    out = {"alone": dict(observers=[]), "observers": dict(observers=obs),
           "summary": dict(observers=obs, store="summary", record_every=10)}
    if np.all(np.linalg.eigvalsh(sc.system.K) > 0):
        out["projected"] = dict(observers=("jump",), master_projection=True)
    return {k: dict(v, t_end=T) for k, v in out.items()}


def fingerprints() -> dict:
    """Scenario → variant → digest, on the compiled engine."""
    import observer
    from observer.scenarios import SCENARIOS

    table = {}
    for name in SCENARIOS:
        sc = observer.load_scenario(name)
        table[name] = {v: result_digest(observer.simulate(sc, engine="compiled", **kw))
                       for v, kw in variants(name).items()}
    return table


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    table = json.loads(PATH.read_text()) if PATH.exists() else {}
    for name, row in fingerprints().items():
        for variant, d in row.items():
            seen = table.setdefault(name, {}).setdefault(variant, [])
            if d not in seen:
                seen.append(d)
    PATH.write_text(json.dumps(table, indent=1, sort_keys=True) + "\n")
    print(PATH.read_text())
