"""Issue 23's acceptance measurements of the rocking chain at scale (not part of any suite).

Two measurements, each printed as JSON lines:

* ``sweep`` — the user's whole call, ``load_scenario("rocking_chain", {"param.N": N})`` then
  ``simulate(sc, h=1e-3, t_end=1.0)`` (the master alone, 1000 steps), for N = 10 … 10⁴ in one
  process (the kernel compiled, or loaded from numba's cache, by a first small run); CPU
  (``time.process_time``) and wall time per N, and the exponent p of ``time ∝ N^p`` fitted by
  log-log least squares over the sizes. CPU time is the number to read on a shared machine:
  the wall time of a process that gets a fraction of a core scales with the load, not N.
* ``big`` — one run of N blocks (default 10⁵) with the master and the ``jump`` and ``nojump``
  observers, 1000 steps, ``store="summary"``, coupled over the whole run: wall and CPU time,
  the loop's own wall time, the peak resident memory (``VmHWM`` of ``/proc/self/status``: this
  process only), the load average, the health record's ω_max and how it and K ≻ 0 were
  established, and the observers' summary (V at the start and the end, the projection and
  impulse parts of ΔV).

No result is kept in this docstring: the numbers depend on the machine and its load (on a
shared machine read the CPU times; wall times scale with the load). The scaling suite
(``python -m bench run scaling``, N = 5 … 10⁵) stores its results, and the report's scaling
section (:mod:`reports.sections.scaling`) shows them.

Run from the repository root::

    python bench/micro/scale_chain.py sweep [N ...]
    python bench/micro/scale_chain.py big [N] [param=value ...]

``param=value`` overrides a chain parameter (e.g. ``b=0.5 a=0.45``).
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

SWEEP_N = (10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10_000)


def peak_rss_mb() -> float:
    """This process's peak resident set size (``VmHWM``), MB; ``ru_maxrss`` without /proc."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def exponent(N, t) -> float:
    """p of ``t ∝ N^p``, log-log least squares."""
    return float(np.polyfit(np.log(np.asarray(N, float)), np.log(np.asarray(t, float)), 1)[0])


def whole_call(N: int, **params) -> dict:
    """``load_scenario`` + ``simulate`` of the chain's master, 1000 steps, timed as one."""
    import observer
    c0, w0 = time.process_time(), time.perf_counter()
    sc = observer.load_scenario("rocking_chain", {"param.N": N, **{f"param.{k}": v for k, v in params.items()}})
    res = observer.simulate(sc, h=1e-3, t_end=1.0)
    return {"N": N, "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - w0,
            "loop_wall_s": res.stats.wall_time_s, "structure": res.metadata["structure"],
            "contact_solves": res.stats.contact_solves}


def sweep(sizes=SWEEP_N) -> dict:
    """:func:`whole_call` for every N, one process; the fitted exponents."""
    import observer
    observer.simulate("rocking_chain", h=1e-3, t_end=0.01)          # the kernel, compiled or loaded
    rows = []
    for N in sizes:
        rows.append(whole_call(int(N)))
        print(json.dumps(rows[-1]), flush=True)
    Ns = [r["N"] for r in rows]
    return {"sizes": Ns, "exponent_cpu": exponent(Ns, [r["cpu_s"] for r in rows]),
            "exponent_wall": exponent(Ns, [r["wall_s"] for r in rows]),
            "exponent_loop_wall": exponent(Ns, [r["loop_wall_s"] for r in rows])}


def big(N: int = 100_000, **params) -> dict:
    """Master + jump + nojump over 1000 steps, summary storage, coupled throughout."""
    import observer
    observer.simulate("rocking_chain", h=1e-3, t_end=0.01)
    c0, w0 = time.process_time(), time.perf_counter()
    sc = observer.load_scenario("rocking_chain", {"param.N": N, **{f"param.{k}": v for k, v in params.items()}})
    load = time.perf_counter() - w0
    res = observer.simulate(sc, h=1e-3, t_end=1.0, observers=["jump", "nojump"], store="summary",
                            coupling=(0.0, 1.0))
    health = res.metadata["health"]
    return {"N": N, "params": params, "load_average": os.getloadavg(),
            "wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0,
            "load_wall_s": load, "loop_wall_s": res.stats.wall_time_s, "peak_rss_mb": peak_rss_mb(),
            "status": str(res.status.state.value), "contact_solves": res.stats.contact_solves,
            "max_abs_sigma_jump": float(np.abs(res.slaves["jump"].sigma).max()),
            "h_omega_max": health["h_omega_max"], "omega_max": health["h_omega_max"] / 1e-3,
            "omega_max_by": health["computed_by"]["omega_max"],
            "K_definite_by": health["computed_by"].get("K_definite"), "min_eig_L": health["min_eig_L"],
            "warnings": list(health["warnings"]),
            "summary": {r["observer"]: {k: r[k] for k in ("V_on", "V_end", "sum_projection", "sum_impulse")}
                        for r in res.summary.to_dict("records")}}


if __name__ == "__main__":
    what, args = (sys.argv[1] if len(sys.argv) > 1 else "sweep"), sys.argv[2:]
    if what == "sweep":
        print(json.dumps(sweep([int(a) for a in args] or SWEEP_N)))
    else:
        sizes = [int(a) for a in args if "=" not in a]
        kv = dict(a.split("=", 1) for a in args if "=" in a)
        print(json.dumps(big(sizes[0] if sizes else 100_000, **{k: float(v) for k, v in kv.items()})))
