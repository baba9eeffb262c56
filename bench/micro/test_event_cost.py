"""Benchmark (pytest-benchmark): the exact event integrator's cost per impact (issue 34 item 5).

Each case is one whole public call ``observer.simulate(scenario, integrator="event")`` (the
master alone, the scenario's own grid step h and t_end), timed over :data:`ROUNDS` rounds
of one call each after a first call that is excluded and reported apart
(``extra_info["first_call_s"]``: the compiled kernels of :mod:`observer.event.kernels`
compiled or loaded from numba's cache, plus one run). The report's number is the median
call divided by the call's impacts (``extra_info["impacts"]``, rows of kind ``impact`` in
``res.events``): ``extra_info["ms_per_impact"]``, and by all its event rows:
``extra_info["ms_per_event"]`` (``grazing`` has graze rows only). The load average of the machine before
and after the rounds is kept in ``extra_info["load_before"]`` / ``["load_after"]``, and the
median CPU time of a call (``time.process_time``) in ``extra_info["cpu_call_s"]`` and
``["cpu_ms_per_impact"]``, less sensitive to other processes than the wall time (on a
shared machine a time is only comparable with one taken under the same load; the
before/after comparison of two source trees in one run, alternating call by call, is
``python -m bench.revisions REVISION --problem event_oscillator`` and the other
``event_*`` problems of :data:`bench.revisions.PROBLEMS`).

Cases (:data:`CASES`): the built-in ``impact_oscillator`` (the 1-DOF forced oscillator, 20 s),
``bouncing_ball`` (Zeno accumulation, then rest, 6 s), ``grazing`` and ``double_mass`` (their
scenarios' t_end), and the **vibrating table**: no scenario of the project builds it, so it
is the ``bouncing_ball`` scenario with a moving ground, gap ``g = q − A sin(ωt)``
(``system.gap.amplitude = −A``), A = 1 mm, ω = 2π·20 rad/s (peak table acceleration
Aω² = 1.61 g0), Newton restitution e = 0.5, the ball released at rest on the table at
t = 0, run for 0.5 s: impacts, a Zeno accumulation, sticking to the table and a lift-off
(:data:`TABLE`). Targets of issue 34 (``extra_info["target"]``): ≤ 1 ms per impact for the
oscillator, under 1 s for the table's whole 0.5 s run.

:func:`test_event_kernels_compile` reports the kernels' compile time apart: a fresh process
with an empty numba cache folder compiles them (``extra_info["compile_s"]``), a second process
loads them from that cache (``extra_info["cache_load_s"]``).

Every benchmark checks its answer (a timing of a wrong answer is worthless): the run ends
``ok`` with impacts (``grazing``: graze rows and no impact); every impact row obeys Newton's
law ``γ⁺ = −e γ⁻`` to 1e-12 relative (4 eps of the largest |γ⁻| absolute), but one that
sticks at once (a ``stick`` row at its time), whose rebound ``−e γ⁻`` is then within
``ZENO_TIME_RTOL`` of the largest |γ⁻| and held at γ⁺ = 0; the ball's
impact times match the closed form :func:`observer.scenarios.exact.impact_times` to 1e-9 s and
the oscillator's positions its closed form (:func:`observer.scenarios.exact.oscillator_reference`)
to 1e-8. With ``--benchmark-disable`` each case is run once, checked, not timed::

    python -m pytest bench/micro/test_event_cost.py --benchmark-only --benchmark-json=event.json
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

import observer
from observer.event.master import ZENO_TIME_RTOL
from observer.scenarios.exact import impact_times, oscillator_reference

ROUNDS = 5
"""Timed rounds per case (one whole call each; the median is reported)."""

TABLE = {"param.h0": 0.0, "param.restitution": 0.5, "param.t_end": 0.5,
         "system.gap.amplitude": [-1e-3], "system.gap.omega": 2.0 * math.pi * 20.0}
"""The vibrating table: ``bouncing_ball`` (m = 1 kg, g0 = 9.81 m/s²) on a ground moving as
``ν(t) = A sin(ωt)``, A = 1 mm, ω = 2π·20 rad/s, e = 0.5, released at rest on the table, 0.5 s."""

CASES = {
    "impact_oscillator": ("impact_oscillator", {}, {"ms_per_impact": 1.0}),
    "vibrating_table": ("bouncing_ball", TABLE, {"call_s": 1.0}),
    "bouncing_ball": ("bouncing_ball", {}, {}),
    "grazing": ("grazing", {}, {}),
    "double_mass": ("double_mass", {}, {}),
}
"""name → (scenario, overrides, targets of issue 34)."""

ROOT = Path(__file__).resolve().parents[2]


def scenario(name: str):
    base, overrides, _ = CASES[name]
    return observer.load_scenario(base, overrides)


def run(sc):
    return observer.simulate(sc, integrator="event", observers=[])


def check(name: str, sc, res) -> int:
    """The answer's checks (module docstring); returns the number of impacts."""
    assert res.status.state.value == "ok", res.status
    ev = res.events
    imp = ev[ev.kind == "impact"]
    assert len(imp) > 0 if name != "grazing" else (len(imp) == 0 and (ev.kind == "graze").sum() > 0)
    e = np.asarray(sc.law.restitution, dtype=float)[imp.contact.to_numpy(int)]
    gm, gp = imp.gamma_minus.to_numpy(float), imp.gamma_plus.to_numpy(float)
    scale = float(np.max(np.abs(gm))) if gm.size else 0.0
    sticks = set(zip(ev[ev.kind == "stick"].time, ev[ev.kind == "stick"].contact))
    held = np.array([(t, c) in sticks for t, c in zip(imp.time, imp.contact)], dtype=bool)
    np.testing.assert_allclose(gp[~held], -e[~held] * gm[~held], rtol=1e-12,
                               atol=4.0 * np.finfo(float).eps * scale)
    # an impact that sticks at once: its rebound −eγ⁻ within the stated accuracy of the
    # run's velocities (zeno_time_rtol of the largest |γ⁻|), held at γ⁺ = 0
    assert np.all(gp[held] == 0.0) and np.all(-e[held] * gm[held] <= ZENO_TIME_RTOL * scale)
    assert np.isfinite(res.q).all() and np.isfinite(res.u).all()
    if name == "bouncing_ball":
        g0 = -float(sc.system.forcing.constant[0]) / float(sc.system.M[0, 0])
        ref = impact_times(float(sc.q0[0]), g0, float(e[0]), 10)
        np.testing.assert_allclose(imp.time.to_numpy(float)[:10], ref, rtol=0.0, atol=1e-9)
    if name == "impact_oscillator":
        ref = oscillator_reference(sc, res.t)
        assert ref is not None
        np.testing.assert_allclose(res.q[:, 0], np.asarray(ref)[:, 0], rtol=0.0, atol=1e-8)
    return len(imp)


@pytest.mark.parametrize("name", list(CASES))
def test_event_cost(benchmark, name):
    """One whole ``simulate(..., integrator="event")`` call of case ``name``, per impact."""
    sc = scenario(name)
    t0 = time.perf_counter()
    res = run(sc)                                   # compile or cache load, excluded
    first = time.perf_counter() - t0
    impacts = check(name, sc, res)
    if benchmark.disabled:
        return
    cpu: list[float] = []

    def timed(sc):
        c0 = time.process_time()
        out = run(sc)
        cpu.append(time.process_time() - c0)
        return out

    load_before = os.getloadavg()
    res = benchmark.pedantic(timed, args=(sc,), rounds=ROUNDS, iterations=1, warmup_rounds=0)
    load_after = os.getloadavg()
    assert check(name, sc, res) == impacts
    median, cpu_median = float(benchmark.stats.stats.median), float(np.median(cpu))
    targets = CASES[name][2]
    benchmark.extra_info.update(
        kind="event_cost", case=name, scenario=CASES[name][0], overrides=CASES[name][1],
        t_end=float(sc.t_end), impacts=impacts, events=int(len(res.events)),
        ms_per_impact=1e3 * median / impacts if impacts else None,
        ms_per_event=1e3 * median / len(res.events), call_s=median, first_call_s=first,
        cpu_call_s=cpu_median, cpu_ms_per_impact=1e3 * cpu_median / impacts if impacts else None,
        load_before=list(load_before), load_after=list(load_after), target=targets,
        meets_target=all((1e3 * median / impacts if k == "ms_per_impact" else median) <= v
                         for k, v in targets.items()) if targets else None)


COMPILE = r"""
import time
t0 = time.perf_counter()
import numpy as np
from observer.event import kernels as K
t1 = time.perf_counter()
K.expm_pade13(np.eye(3))
K.blocked_expm(np.eye(2), np.ones(2), np.arange(2), np.array([0, 1, 2]), 0.5)
K.norm_upper(np.ones(3))
K.screen_step(np.ones((4, 1)), np.ones((6, 1)), np.ones(3), np.ones(3), np.arange(3), 1.0, np.ones(1),
              1.0, 0.5, 0.125)
print(time.perf_counter() - t1)
"""
"""A fresh process: import the kernels, call each once; prints the seconds of the calls."""


def _kernel_seconds(cache: str) -> float:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", COMPILE], env=env, cwd=ROOT, capture_output=True,
                         text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def test_event_kernels_compile(benchmark):
    """The compile time of :mod:`observer.event.kernels` (empty cache), and its cache load."""
    if benchmark.disabled:
        pytest.skip("compiles in a fresh process: a benchmark run only")
    with tempfile.TemporaryDirectory(prefix="event-kernels-") as cache:
        load_before = os.getloadavg()
        compile_s = benchmark.pedantic(_kernel_seconds, args=(cache,), rounds=1, iterations=1)
        load_s = _kernel_seconds(cache)
    benchmark.extra_info.update(kind="event_compile", compile_s=compile_s, cache_load_s=load_s,
                                load_before=list(load_before), load_after=list(os.getloadavg()))
    assert load_s < compile_s
