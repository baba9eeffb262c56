"""Run one linear impact problem in Siconos and print its trajectory and timing as JSON.

A standalone script for the Python that has Siconos (Debian: ``apt-get install
python3-siconos``, which runs under ``/usr/bin/python3``). It imports nothing from the
toolkit, only ``siconos``, ``numpy`` and the standard library; :mod:`bench.peers` drives it
in a subprocess::

    /usr/bin/python3 bench/siconos_driver.py < problem.json > result.json
    /usr/bin/python3 bench/siconos_driver.py --version          # {"siconos_version": ...}

Input (JSON on stdin; the format of ``../shared/oracles/siconos/generated/*.json``)
-------------------------------------------------------------------------------
``M``, ``C``, ``K`` (n×n), ``W`` (n×m, column j is w_j), ``forcing`` = {``constant`` (n),
``amplitude`` (n), ``omega``, ``phase`` (scalar or n)} with
``f(t) = constant + amplitude·cos(omega t + phase)``, ``gap_offset`` (m) with
``g = Wᵀq + gap_offset``, ``restitution`` (Newton's e; scalar or m), ``q0``, ``u0``, ``h``,
``T``, ``theta``. Optional: ``steps`` (default ``ceil(T/h − 1e-9)``, the toolkit's grid),
``repeats`` (timing runs, default 0), ``record`` (default true: run once and return the
trajectory).

The model (the one of the generated oracles): ``LagrangianLinearTIDS(q0, u0, M, K, C)``,
one ``LagrangianLinearTIR`` (row w_jᵀ, offset ν_j) with ``NewtonImpactNSL(e_j)`` per contact
— one Interaction *per contact*, because Siconos decides whether a multi-row Interaction
is active from its first row only — ``MoreauJeanOSI(theta)``, ``LCP(SICONOS_LCP_LEMKE)``,
``TimeStepping``. The force enters as the θ-average ``f̄_k = (1−θ)f(t_k) + θf(t_{k+1})``
on the grid ``t_k = k h``, written into ``fExt`` before step k (what a force plugin gives
for a linear system). With zero forcing amplitude ``fExt`` is set once, before the loop.

Output (JSON on stdout)
-----------------------
``siconos_version``, ``steps``, ``forcing_updates`` (true when fExt is rewritten every
step); with ``record``: ``t`` (steps+1), ``q``, ``u`` ((steps+1)×n), ``P`` ((steps+1)×m,
row k+1 = the impulse of step k, the Interaction's ``lambda(1)``) and
``record_loop_s`` (the recording loop's wall time); with ``repeats`` > 0: ``loop_s`` (one
wall time per timing run: :func:`time.perf_counter` around the stepping loop only —
model construction and initialisation excluded, nothing recorded) and
``loop_ns_per_step`` (their median / steps · 1e9). With ``repeats`` > 0 also
``run_s``/``run_ns_per_step``/``run_steps``: the same problem with ``fExt`` held at
``constant``, stepped by ``TimeStepping.run()`` — Siconos' own C++ loop, no Python per step
— the cost of the Siconos step itself (for a forced problem a different trajectory:
timing only; ``run_steps`` is the number of steps run() made, from its final time).

The JSON is printed as the last line of stdout (Siconos' C++ messages are sent to stderr).
"""

import json
import math
import os
import sys
import time

import numpy as np


def debian_package_version(package="python3-siconos", status="/var/lib/dpkg/status"):
    """Version of a Debian package from dpkg's status file, or None."""
    try:
        with open(status, encoding="utf-8", errors="replace") as fh:
            blocks = fh.read().split("\n\n")
    except OSError:
        return None
    for block in blocks:
        lines = block.splitlines()
        if f"Package: {package}" in lines:
            for line in lines:
                if line.startswith("Version: "):
                    return line[len("Version: "):].strip()
    return None


def siconos_version():
    """The Siconos module's version, plus the Debian package's when there is one.

    Debian's ``python3-siconos 4.4.0+dfsg-2`` reports ``siconos.version = "4.5.0"``, so both
    are given: ``"4.5.0 (Debian python3-siconos 4.4.0+dfsg-2)"``.
    """
    import siconos
    version = str(getattr(siconos, "version", getattr(siconos, "__version__", "unknown")))
    deb = debian_package_version()
    return f"{version} (Debian python3-siconos {deb})" if deb else version


def _matrix(problem, key, shape):
    a = np.array(problem[key], dtype=float)
    if a.shape != shape:
        raise ValueError(f"{key}: expected shape {shape}, got {a.shape}")
    return a


def parse(problem):
    """Validate the JSON problem and return its arrays (n, m inferred from M and W)."""
    M = np.array(problem["M"], dtype=float)
    n = M.shape[0]
    W = np.array(problem["W"], dtype=float).reshape(n, -1)
    m = W.shape[1]
    forcing = problem["forcing"]
    h, T, theta = float(problem["h"]), float(problem["T"]), float(problem["theta"])
    steps = int(problem.get("steps") or math.ceil(T / h - 1e-9))
    if steps < 1:
        raise ValueError(f"steps: must be at least 1, got {steps}")
    e = np.broadcast_to(np.array(problem["restitution"], dtype=float), (m,)).copy()
    return {
        "M": _matrix(problem, "M", (n, n)), "C": _matrix(problem, "C", (n, n)),
        "K": _matrix(problem, "K", (n, n)), "W": W,
        "f_const": np.broadcast_to(np.array(forcing.get("constant", 0.0), dtype=float), (n,)).copy(),
        "f_amp": np.broadcast_to(np.array(forcing.get("amplitude", 0.0), dtype=float), (n,)).copy(),
        "omega": float(forcing.get("omega", 0.0)),
        "phase": np.broadcast_to(np.array(forcing.get("phase", 0.0), dtype=float), (n,)).copy(),
        "nu": np.broadcast_to(np.array(problem["gap_offset"], dtype=float), (m,)).copy(),
        "e": e, "q0": _matrix(problem, "q0", (n,)), "u0": _matrix(problem, "u0", (n,)),
        "h": h, "theta": theta, "steps": steps, "n": n, "m": m,
    }


def forcing_average(p, t):
    """``f̄_k = (1−θ)f(t_k) + θf(t_{k+1})`` for every step, shape (steps, n)."""
    f = p["f_const"] + p["f_amp"] * np.cos(p["omega"] * t[:, None] + p["phase"])
    return (1.0 - p["theta"]) * f[:-1] + p["theta"] * f[1:]


def build(p):
    """The Siconos model: (simulation, dynamical system, interactions)."""
    import siconos.kernel as sk
    import siconos.numerics as sn

    ds = sk.LagrangianLinearTIDS(p["q0"].copy(), p["u0"].copy(), p["M"], p["K"], p["C"])
    ds.setFExtPtr(p["f_const"].copy())
    T = p["steps"] * p["h"]
    nsds = sk.NonSmoothDynamicalSystem(0.0, T)
    nsds.insertDynamicalSystem(ds)
    inters = []
    for j in range(p["m"]):
        rel = sk.LagrangianLinearTIR(p["W"][:, j].reshape(1, -1).copy(), np.array([p["nu"][j]]))
        inter = sk.Interaction(sk.NewtonImpactNSL(float(p["e"][j])), rel)
        nsds.link(inter, ds)
        inters.append(inter)
    osi = sk.MoreauJeanOSI(p["theta"])
    lcp = sk.LCP(sn.SICONOS_LCP_LEMKE)
    sim = sk.TimeStepping(nsds, sk.TimeDiscretisation(0.0, p["h"]), osi, lcp)
    sim.initialize()
    return sim, ds, inters


def record_run(p, fbar):
    """One run storing t, q, u, P every step; returns (arrays, loop wall time)."""
    sim, ds, inters = build(p)
    steps, n, m = p["steps"], p["n"], p["m"]
    q = np.empty((steps + 1, n))
    u = np.empty((steps + 1, n))
    P = np.zeros((steps + 1, m))
    q[0], u[0] = p["q0"], p["u0"]
    fext = ds.fExt()
    t0 = time.perf_counter()
    for k in range(steps):
        if fbar is not None:
            fext[:] = fbar[k]
        sim.computeOneStep()
        q[k + 1] = ds.q()
        u[k + 1] = ds.velocity()
        for j, inter in enumerate(inters):
            P[k + 1, j] = inter.lambda_(1)[0]
        sim.nextStep()
    return {"q": q, "u": u, "P": P}, time.perf_counter() - t0


def timed_run(p, fbar):
    """Wall time of the bare stepping loop (nothing recorded)."""
    sim, ds, _ = build(p)
    fext = ds.fExt()
    steps = p["steps"]
    one, nxt = sim.computeOneStep, sim.nextStep
    if fbar is None:
        t0 = time.perf_counter()
        for _ in range(steps):
            one()
            nxt()
        return time.perf_counter() - t0
    t0 = time.perf_counter()
    for k in range(steps):
        fext[:] = fbar[k]
        one()
        nxt()
    return time.perf_counter() - t0


def cpp_run(p):
    """Wall time of ``TimeStepping.run()`` with fExt = ``constant``, and its step count.

    run() prints progress lines on the C++ stdout; file descriptor 1 is pointed at stderr
    meanwhile, so that stdout carries only the JSON.
    """
    sim, _, _ = build(p)
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        t0 = time.perf_counter()
        sim.run()
        wall = time.perf_counter() - t0
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    return wall, int(round(sim.startingTime() / p["h"]))


def run(problem):
    """Run a problem (see the module docstring) and return the output dict."""
    p = parse(problem)
    steps = p["steps"]
    t = np.arange(steps + 1) * p["h"]
    forced = bool(np.any(p["f_amp"] != 0.0))
    fbar = forcing_average(p, t) if forced else None
    out = {"siconos_version": siconos_version(), "steps": steps, "n": p["n"], "m": p["m"],
           "forcing_updates": forced}
    if problem.get("record", True):
        traj, wall = record_run(p, fbar)
        out.update(t=t.tolist(), q=traj["q"].tolist(), u=traj["u"].tolist(),
                   P=traj["P"].tolist(), record_loop_s=wall)
    repeats = int(problem.get("repeats", 0))
    if repeats > 0:
        loops = [timed_run(p, fbar) for _ in range(repeats)]
        out.update(loop_s=loops, loop_ns_per_step=float(np.median(loops)) / steps * 1e9)
        runs = [cpp_run(p) for _ in range(repeats)]
        walls = [w for w, _ in runs]
        out.update(run_s=walls, run_steps=runs[0][1],
                   run_ns_per_step=float(np.median(walls)) / runs[0][1] * 1e9)
    return out


def main(argv):
    """``--version``: print the version; else read the problem from stdin, print the result.

    An argument ending in ``.npz`` receives the arrays t, q, u, P (``numpy.savez``) instead
    of the JSON output, which then holds ``npz`` = that path.
    """
    if "--version" in argv:
        sys.stdout.write("\n" + json.dumps({"siconos_version": siconos_version()}) + "\n")
        return 0
    npz = next((a for a in argv if a.endswith(".npz")), None)
    out = run(json.load(sys.stdin))
    if npz is not None and "q" in out:
        np.savez(npz, **{k: np.asarray(out.pop(k)) for k in ("t", "q", "u", "P")})
        out["npz"] = npz
    sys.stdout.write("\n" + json.dumps(out) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
