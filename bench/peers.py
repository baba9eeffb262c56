"""Peer suite: the same problems in Siconos and in this toolkit, in one run.

Siconos (Debian package ``python3-siconos``) runs under Debian's system Python, not the
toolkit's interpreter, so it is driven in a subprocess: :mod:`bench.siconos_driver` reads a
problem as JSON on stdin and returns the trajectory and its timing. Both codes run the same
discrete scheme — Moreau–Jean θ-scheme, forcing ``h[(1−θ)f(t_k) + θf(t_{k+1})]``, closed
set from the predicted gap ``g_k + (h/2)γ_k ≤ 0``, Newton's law on each contact, one LCP per
step on the step's Delassus matrix (README, "The scheme in one paragraph") — so with the
Newton law their trajectories agree to round-off, and the per-step times compare the same
work.

Problems (:func:`peer_problems`), built from the built-in scenarios through the public API
(:func:`observer.load_scenario`):

``impact_oscillator``
    the forced 1-DOF impact oscillator as built in (Newton law, e = 0.8).
``double_mass``
    the paper's Example 1 master with the Newton law (its default is Poisson; for one
    contact the discrete steps are the same), mass 1 released 1 mm above its resting
    position (:func:`double_mass_drop_overrides` says why not from rest).
``rocking_chain``
    the chain of N rocking blocks **in the ground frame**. Siconos'
    ``LagrangianLinearTIR`` has a constant gap offset and no ν̇ in its velocity relation,
    so the moving ground ``ν₁(t) = g⁰ − Y sin Ωt`` cannot be given to it. Writing every
    block's height relative to the ground, ``q̃ = q − y_g(t)e`` (e = 1 on every y, 0 on
    every φ), removes ν(t) exactly: the gaps become ``Wᵀq̃ + g⁰`` and, because ``Ke`` and
    ``Ce`` only load interface 1 (rigid translation stretches nothing else), the spring and
    damper terms of the ground motion cancel and leave the inertial force
    ``−M e ÿ_g = m Y Ω² sin(Ωt) e`` — one harmonic, a constant offset. The initial velocity
    becomes ``u₀ − ẏ_g(0)e = −YΩe``. This is the same continuous system as the built-in
    (moving-ground) chain; its discrete trajectory differs from the built-in's by the
    discretisation error, which is why the toolkit side runs the ground-frame scenario too
    (built with overrides of the built-in, ``param.Y = 0`` plus the force above).

Timing. Siconos: the Python loop of ``computeOneStep``/``nextStep`` alone
(:func:`time.perf_counter` around it; model construction excluded); a forced problem makes
it write ``fExt`` from Python every step (``siconos_forcing`` says so). Toolkit: the whole
:func:`observer.simulate` call (:func:`time.perf_counter` around it, after one short warm-up
call that triggers any compilation); ``toolkit_loop_ns_per_step`` is its loop alone, from
the result's metadata. The driver also times Siconos' own C++ loop, ``TimeStepping.run()``,
on the same system with ``fExt`` held at its constant part (``siconos_run_ns_per_step``):
no Python per step at all, but for a forced problem a different trajectory (timing only;
it can cost more per step when the unforced system rests on a closed contact, as
double_mass does). ``ratio`` = Siconos ÷ toolkit time per step (> 1: the toolkit is
faster), ``ratio_run`` the same with the run() time.

>>> from bench.peers import peer_problems, run_peer, siconos_available
>>> siconos_available()                                            # doctest: +SKIP
(True, '4.5.0 (Debian python3-siconos 4.4.0+dfsg-2)')
>>> run_peer(peer_problems()["impact_oscillator"], steps=10_000)   # doctest: +SKIP
"""

from __future__ import annotations

import inspect
import json
import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

import observer
from observer.errors import InputError

DRIVER = Path(__file__).resolve().with_name("siconos_driver.py")
"""The standalone Siconos script (runs under :data:`SICONOS_PYTHON`)."""

SICONOS_PYTHON = os.environ.get("OBSERVER_SICONOS_PYTHON", "/usr/bin/python3")
"""Interpreter that can ``import siconos`` (Debian's system Python; the environment variable
``OBSERVER_SICONOS_PYTHON`` names another)."""

HOW_TO_GET = "apt-get install python3-siconos (Debian; runs under /usr/bin/python3)"
"""What to do when Siconos is absent."""

PROBLEMS = ("impact_oscillator", "double_mass", "rocking_chain")
"""The peer problems, in report order."""

COLUMNS = ("problem", "scenario", "n", "m", "h", "steps", "law", "siconos_ns_per_step",
           "siconos_forcing", "siconos_run_ns_per_step", "toolkit_ns_per_step",
           "toolkit_loop_ns_per_step", "toolkit_engine", "ratio", "ratio_run",
           "max_abs_diff_q", "max_abs_diff_u", "max_abs_diff_P", "max_abs_q", "impulse_steps",
           "repeats", "siconos_version", "status", "note")
"""Columns of :func:`run_peer`'s rows (a missing measurement is NaN). ``max_abs_q`` (the
largest |q| of Siconos' run) and ``impulse_steps`` (its steps with a nonzero impulse) say what
the differences are compared with: a run whose contacts never close would match trivially."""

NOTES = {"double_mass": "mass 1 released 1 mm above rest (not a round-off tie at g = 0)",
         "rocking_chain": "chain in the ground frame: moving ground as inertial force"}
"""What the report should say about each problem (module docstring for the reasons)."""


# ----------------------------------------------------------------------------- availability
def siconos_available(python: str | None = None, timeout: float = 120.0) -> tuple[bool, str]:
    """Whether Siconos can be driven, and its version or why not.

    Parameters
    ----------
    python : str, optional
        Interpreter to try (default :data:`SICONOS_PYTHON`).
    timeout : float
        Seconds allowed for ``python siconos_driver.py --version``.

    Returns
    -------
    (bool, str)
        ``(True, version)`` or ``(False, reason, then how to get it)``.
    """
    python = python or SICONOS_PYTHON
    if not Path(python).exists():
        return False, f"no interpreter at {python}; {HOW_TO_GET}"
    try:
        proc = subprocess.run([python, str(DRIVER), "--version"], capture_output=True, text=True,
                              timeout=timeout)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return False, f"{python} could not run the driver ({type(exc).__name__}: {exc}); {HOW_TO_GET}"
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
        return False, f"{python} cannot import siconos ({last}); {HOW_TO_GET}"
    return True, _last_json(proc.stdout)["siconos_version"]


_RECORDS: dict[str, dict[str, Any]] = {}
""":func:`siconos_record` per interpreter, probed once per process."""


def siconos_record(python: str | None = None) -> dict[str, Any]:
    """What a suite's metadata records about Siconos when the suite runs, for the report
    (which reads results, not :mod:`bench`).

    The probe (:func:`siconos_available`, one subprocess) runs once per interpreter and
    process; later calls return a copy of the first answer.

    Parameters
    ----------
    python : str, optional
        Interpreter to try (default :data:`SICONOS_PYTHON`).

    Returns
    -------
    dict
        ``"available"`` (bool), ``"version"`` (its version, None when absent), ``"reason"``
        (why it is absent, with how to get it; None when available), ``"python"`` (the
        interpreter tried) and ``"how_to_get"`` (:data:`HOW_TO_GET`).
    """
    python = python or SICONOS_PYTHON
    if python not in _RECORDS:
        ok, info = siconos_available(python)
        _RECORDS[python] = {"available": ok, "version": info if ok else None,
                            "reason": None if ok else info, "python": python, "how_to_get": HOW_TO_GET}
    return dict(_RECORDS[python])


def _last_json(stdout: str) -> dict:
    """The driver's output: the last non-empty line of its stdout, a JSON object."""
    lines = [line for line in stdout.splitlines() if line.strip()]
    if not lines:
        raise RuntimeError("Siconos driver printed nothing")
    return json.loads(lines[-1])


# --------------------------------------------------------------------------------- problems
def chain_ground_frame_overrides(N: int = 10) -> dict[str, Any]:
    """Overrides of ``rocking_chain`` that give the chain in the ground frame (module docstring).

    ``param.Y = 0`` removes the moving ground; the force ``m Y Ω² sin(Ωt)`` on every block's
    height (``cos(Ωt − π/2)``, the only harmonic) and the initial velocity ``−YΩ`` on every
    height put the ground's motion back, with the built-in's Y, Ω and m.
    """
    from observer.scenarios import rocking_chain as rc

    p = rc.PARAMETERS
    n = 2 * N
    e = np.zeros(n)
    e[0::2] = 1.0
    Y, Om, m = p["Y"], p["Omega"], p["m"]
    return {"param.N": N, "param.Y": 0.0, "impact.law": "newton",
            "system.forcing.amplitude": (m * Y * Om ** 2 * e).tolist(),
            "system.forcing.omega": Om, "system.forcing.phase": -np.pi / 2,
            "system.forcing.harmonics": [],
            "initial.u": (-Y * Om * e).tolist()}


DROP = 1e-3
"""Height (m) above its resting position from which ``double_mass``'s mass 1 is released."""


def double_mass_drop_overrides(drop: float = DROP) -> dict[str, Any]:
    """Overrides of ``double_mass``: Newton law, mass 1 released ``drop`` above its rest.

    The built-in starts in the static contact equilibrium, g = 0 and γ = 0 exactly, where
    the closed set of the next step is decided by the sign of round-off: Siconos' contact
    velocity after the first step is +2.7e-20 (its predicted gap is positive, the contact
    opens for one step and mass 1 sinks by 2.2e-8 m), the toolkit's is exactly 0 (the
    contact stays closed). The two codes then differ by 1.3e-8 in q and 2.2e-4 in u over
    the run — a round-off tie, not a difference of schemes. Released from 1 mm, mass 1
    lands in a Zeno sequence and rests at a gap that is not a round-off tie, and the
    lift-off/landing cycles are the built-in's.
    """
    q0 = observer.load_scenario("double_mass").q0.copy()
    q0[0] += drop
    return {"impact.law": "newton", "initial.q": q0.tolist()}


def peer_overrides(N: int = 10) -> dict[str, dict[str, Any]]:
    """Scenario overrides of each peer problem (keys of :data:`PROBLEMS`)."""
    return {"impact_oscillator": {"impact.law": "newton"},
            "double_mass": double_mass_drop_overrides(),
            "rocking_chain": chain_ground_frame_overrides(N)}


def problem_from_scenario(sc: observer.Scenario) -> dict[str, Any]:
    """The driver's JSON problem of a scenario's master run.

    Raises
    ------
    InputError
        Naming the field Siconos' linear model cannot take: a Poisson law
        (``impact.law``), a time-varying gap offset (``system.gap``), more than one forcing
        harmonic (``system.forcing``) or a projected master
        (``simulation.master_projection``).
    """
    s = sc.system
    if sc.law.law != "newton":
        raise InputError("impact.law", f"the peer suite compares Newton's law (Siconos "
                         f"NewtonImpactNSL), got {sc.law.law!r}")
    if np.any(s.gap.amplitude != 0.0):
        raise InputError("system.gap", "Siconos' LagrangianLinearTIR takes a constant gap offset; "
                         "this scenario has a harmonic ν(t)")
    if sc.master_projection:
        raise InputError("simulation.master_projection", "Siconos has no K-metric projection")
    live = [j for j in range(s.forcing.omega.size) if np.any(s.forcing.amplitude[j] != 0.0)]
    if len(live) > 1:
        raise InputError("system.forcing", f"the driver takes one harmonic, this scenario has {len(live)}")
    j = live[0] if live else None
    return {
        "M": s.M.tolist(), "C": s.C.tolist(), "K": s.K.tolist(), "W": s.W.tolist(),
        "forcing": {"constant": s.forcing.constant.tolist(),
                    "amplitude": (s.forcing.amplitude[j] if live else np.zeros(s.n)).tolist(),
                    "omega": float(s.forcing.omega[j]) if live else 0.0,
                    "phase": (s.forcing.phase[j] if live else np.zeros(s.n)).tolist()},
        "gap_offset": s.gap.constant.tolist(),
        "restitution": sc.law.restitution.tolist(),
        "q0": sc.q0.tolist(), "u0": sc.u0.tolist(),
        "h": sc.h, "T": sc.t_end, "theta": sc.theta,
    }


def peer_problem(name: str, h: float | None = None, t_end: float | None = None,
                 N: int = 10) -> dict[str, Any]:
    """One peer problem in the driver's format, plus ``problem``, ``scenario`` and ``overrides``
    (what :func:`run_peer` needs to run the toolkit on the same scenario; the driver ignores them).
    """
    if name not in PROBLEMS:
        raise InputError("problem", f"must be one of {list(PROBLEMS)}, got {name!r}")
    overrides = dict(peer_overrides(N)[name])
    if h is not None:
        overrides["simulation.h"] = h
    if t_end is not None:
        overrides["simulation.t_end"] = t_end
    sc = observer.load_scenario(name, overrides)
    return {**problem_from_scenario(sc), "problem": name, "scenario": name, "overrides": overrides}


def peer_problems(h: float | None = None, N: int = 10) -> dict[str, dict[str, Any]]:
    """The three peer problems (:data:`PROBLEMS`) at their built-in step (or ``h``)."""
    return {name: peer_problem(name, h=h, N=N) for name in PROBLEMS}


# -------------------------------------------------------------------------------- running
def run_siconos(problem: dict[str, Any], repeats: int = 0, record: bool = True,
                python: str | None = None, timeout: float = 3600.0) -> dict[str, Any]:
    """Run ``problem`` in the Siconos driver; return its output (arrays as ndarrays).

    Raises
    ------
    RuntimeError
        The driver exited with an error (its last stderr line is in the message).
    """
    python = python or SICONOS_PYTHON
    payload = {k: v for k, v in problem.items() if k != "overrides"}
    payload.update(repeats=int(repeats), record=bool(record))
    with tempfile.TemporaryDirectory(prefix="peers-") as tmp:
        npz = Path(tmp) / "trajectory.npz"
        proc = subprocess.run([python, str(DRIVER), str(npz)], input=json.dumps(payload),
                              capture_output=True, text=True, timeout=timeout)
        if proc.returncode != 0:
            last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
            raise RuntimeError(f"Siconos driver failed (exit {proc.returncode}): {last}")
        out = _last_json(proc.stdout)
        if record:
            with np.load(npz) as arrays:
                out.update({k: arrays[k] for k in ("t", "q", "u", "P")})
    return out


def simulate_kwargs(engine: str | None = "compiled") -> tuple[dict[str, Any], str]:
    """Keyword arguments selecting the toolkit engine, and its name for the row.

    ``engine`` is passed only if :func:`observer.simulate` has that option; otherwise the
    row says ``"python (no engine option)"``.
    """
    if engine is not None and "engine" in inspect.signature(observer.simulate).parameters:
        return {"engine": engine}, engine
    return {}, "python (no engine option)"


def run_toolkit(sc: observer.Scenario, repeats: int, engine: str | None = "compiled"):
    """Time :func:`observer.simulate` on ``sc`` (master only) ``repeats`` times.

    One warm-up call on a 10-step horizon first (compilation, caches); each timed call starts
    with the previous call's result freed (not two 10⁶-step results in memory at once). Returns
    ``(result of the last call, wall times of the calls, engine name)``.
    """
    kwargs, name = simulate_kwargs(engine)
    observer.simulate(sc, t_end=10 * sc.h, **kwargs)
    times, res = [], None
    for _ in range(max(1, repeats)):
        res = None                 # the previous result freed first: each call starts alike
        t0 = time.perf_counter()
        res = observer.simulate(sc, **kwargs)
        times.append(time.perf_counter() - t0)
    return res, times, res.metadata.get("engine", name)


def _absent_row(problem: dict[str, Any], reason: str) -> dict[str, Any]:
    row = dict.fromkeys(COLUMNS, float("nan"))
    row.update(problem=problem.get("problem", "custom"), scenario=problem.get("scenario", ""),
               n=len(problem["M"]), m=len(problem["W"][0]), h=problem["h"],
               steps=int(np.ceil(problem["T"] / problem["h"] - 1e-9)), law="newton",
               siconos_forcing="", toolkit_engine="", siconos_version="",
               status=f"siconos absent: {reason}", note="")
    return row


def run_peer(problem: dict[str, Any], steps: int | None = None, repeats: int = 5,
             engine: str | None = "compiled", python: str | None = None) -> pd.DataFrame:
    """Run one peer problem in Siconos and in the toolkit; one tidy row.

    Parameters
    ----------
    problem : dict
        From :func:`peer_problem` (needs ``scenario`` and ``overrides``).
    steps : int, optional
        Number of steps (default: the problem's ``T/h``); the horizon becomes ``steps·h``.
    repeats : int
        Timing runs on each side; the reported times are their medians.
    engine : str or None
        Toolkit engine (passed when :func:`observer.simulate` has the option).
    python : str, optional
        Siconos interpreter (default :data:`SICONOS_PYTHON`).

    Returns
    -------
    pandas.DataFrame
        One row with :data:`COLUMNS`. ``ratio`` = Siconos ns/step ÷ toolkit ns/step (> 1:
        the toolkit is faster); ``max_abs_diff_*`` = max over the common grid and all
        components of |toolkit − Siconos|. Without Siconos, ``status`` is
        ``"siconos absent: …"`` with how to get it, the numbers are NaN and nothing runs.
    """
    ok, info = siconos_available(python)
    if not ok:
        return pd.DataFrame([_absent_row(problem, info)], columns=list(COLUMNS))
    overrides = dict(problem["overrides"])
    if steps is not None:
        overrides["simulation.t_end"] = steps * problem["h"]
    sc = observer.load_scenario(problem["scenario"], overrides)
    prob = {**problem_from_scenario(sc), "problem": problem.get("problem", problem["scenario"])}
    sic = run_siconos(prob, repeats=repeats, python=python)
    res, times, engine_name = run_toolkit(sc, repeats, engine)
    n_steps = int(sic["steps"])
    if res.t.shape[0] != n_steps + 1 or not np.array_equal(res.t, sic["t"]):
        raise RuntimeError(f"grids differ: toolkit {res.t.shape[0] - 1} steps, Siconos {n_steps}")
    tk_ns = statistics.median(times) / n_steps * 1e9
    sic_ns = sic.get("loop_ns_per_step", float("nan"))
    run_ns = sic.get("run_ns_per_step", float("nan"))
    loop_s = res.metadata.get("wall_time_s")
    row = {
        "problem": prob["problem"], "scenario": sc.name, "n": sc.system.n, "m": sc.system.m,
        "h": sc.h, "steps": n_steps, "law": sc.law.law,
        "siconos_ns_per_step": sic_ns,
        "siconos_forcing": "fExt written every step" if sic["forcing_updates"] else "fExt set once",
        "siconos_run_ns_per_step": run_ns,
        "toolkit_ns_per_step": tk_ns,
        "toolkit_loop_ns_per_step": loop_s / n_steps * 1e9 if loop_s else float("nan"),
        "toolkit_engine": engine_name,
        "ratio": sic_ns / tk_ns, "ratio_run": run_ns / tk_ns,
        "max_abs_diff_q": float(np.max(np.abs(res.q - sic["q"]))),
        "max_abs_diff_u": float(np.max(np.abs(res.u - sic["u"]))),
        "max_abs_diff_P": float(np.max(np.abs(res.P - sic["P"]))),
        "max_abs_q": float(np.max(np.abs(sic["q"]))),
        "impulse_steps": int(np.count_nonzero(np.any(np.asarray(sic["P"]) != 0.0, axis=1))),
        "repeats": repeats, "siconos_version": sic["siconos_version"], "status": "ok",
        "note": NOTES.get(prob["problem"], ""),
    }
    return pd.DataFrame([row], columns=list(COLUMNS))


def run_peers(steps: dict[str, int] | None = None, repeats: int = 5, h: float | None = None,
              N: int = 10, engine: str | None = "compiled") -> pd.DataFrame:
    """Every peer problem (:data:`PROBLEMS`), one row each (see :func:`run_peer`)."""
    steps = steps or {}
    frames = [run_peer(p, steps=steps.get(name), repeats=repeats, engine=engine)
              for name, p in peer_problems(h=h, N=N).items()]
    return pd.concat(frames, ignore_index=True)
