"""Micro-benchmarks (pytest-benchmark): the time loop on both engines, one contact (LCP) solve.

Run with the suite (``python -m bench run quick`` writes ``bench/results/quick-micro.json``)
or directly::

    python -m pytest bench/micro --benchmark-only --benchmark-json=micro.json

**Time loops** (``test_loop``): :func:`observer.loop.run` — the one loop that
:func:`observer.simulate` calls — over a fixed window of every built-in scenario's master,
and of double_mass and rocking_chain (N = 10) with both observers, on the compiled engine
(numba kernel) and the numpy engine, the same steps for both. Setup is not timed (the
stepper's matrices and grid are built once, as :func:`observer.simulate` does before its
loop); the kernel is compiled (or loaded from numba's cache) and every case run once before
timing, so compile time is excluded; :data:`LOOP_ROUNDS` rounds of one call each, the report
divides the median by ``extra_info["steps"]``: the time per step. Each call's trajectory
is stored in full (``record_every = 1``). Each benchmark checks its answer: a finite
trajectory of the right length, and, in the test suite's run, the other engine on the same
window agrees to 1e-9 relative (the engines' equality to 1e-13 is tested in
``tests/observer/test_loop.py``).

**Contact solves** (``test_contact_solve``): real Delassus matrices ``G = W_AᵀÂ⁻¹W_A`` of
the built-in scenarios (m = 1: double_mass; m = 4 and 20: rocking_chain N = 10 with its first
4 / all 20 contacts closed), with seeded random right-hand sides that have negative entries
(so that no solver can return the trivial solution). Every benchmark also asserts the
solution, recomputed here from the returned x (never the solver's self-reported
``residual``): x ≥ 0 and the relative complementarity residual
``‖min(x, Gx + b)‖∞ / max(‖b‖∞, ‖Gx‖∞)`` ≤ 1e-9 (timings of wrong answers are worthless);
the pivoting solver must answer by its fast path (no Lemke fallback). Groups put the
solvers of one size side by side; the report divides the reference (cvxpy + OSQP) time by
the fast solvers' times.

With ``--benchmark-disable`` (the test suite's run) every loop covers only
:data:`SMOKE_STEPS` steps: a correctness run, not a timing.
"""

from __future__ import annotations


import numpy as np
import pytest

import observer
from observer.contact import CONTACT_SOLVERS, get_solver
from observer.loop import ENGINES  # the registry's time-stepping engines, in its order

SIZES = (1, 4, 20)
SOLVERS = tuple(CONTACT_SOLVERS)


def delassus(m: int) -> np.ndarray:
    """A real m×m Delassus matrix Ĝ of a built-in scenario at its default h."""
    if m == 1:
        sc = observer.load_scenario("double_mass")
    else:
        sc = observer.load_scenario("rocking_chain", {"param.N": 10})
    stepper = observer.MoreauJean(sc.system, sc.law, sc.h, 10 * sc.h)
    G = stepper.S.Ghat[:m, :m]
    return 0.5 * (G + G.T)


def complementarity_residual(G: np.ndarray, b: np.ndarray, x: np.ndarray) -> float:
    """``‖min(x, w)‖∞ / max(‖b‖∞, ‖Gx‖∞)`` with ``w = Gx + b`` recomputed here from x."""
    Gx = G @ x
    scale = max(float(np.max(np.abs(b))), float(np.max(np.abs(Gx))), 1e-300)
    return float(np.max(np.abs(np.minimum(x, Gx + b)))) / scale


def rhs(m: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    b = rng.standard_normal(m)
    b[rng.integers(0, m)] = -abs(b[0]) - 0.5          # at least one approaching contact
    return b


@pytest.mark.parametrize("m", SIZES)
@pytest.mark.parametrize("solver", SOLVERS)
def test_contact_solve(benchmark, solver, m):
    """One LCP solve ``0 ≤ Gx + b ⊥ x ≥ 0`` of size m by ``solver``."""
    G, b = delassus(m), rhs(m, 1000 + m)
    s = get_solver(solver)
    s.solve(G, b)                                     # warm-up (cvxpy compiles once per size)
    benchmark.group = f"contact solve m={m}"
    benchmark.extra_info.update(kind="contact_solve", solver=solver, m=m)
    sol = benchmark(s.solve, G, b)
    residual = complementarity_residual(G, b, sol.x)
    benchmark.extra_info.update(residual=residual, iterations=int(sol.iterations), method=sol.method)
    assert np.all(sol.x >= 0.0)
    assert residual <= 1e-9
    if solver == "pivoting":
        assert sol.method in ("closed-form", "block-pivoting") and sol.fallbacks == 0


# ------------------------------------------------------------------------------ time loops
LOOP_CASES = {
    # id: (scenario, overrides, observers, steps)
    "impact_oscillator": ("impact_oscillator", {}, (), 20_000),
    "bouncing_ball": ("bouncing_ball", {}, (), 6_000),
    "grazing": ("grazing", {}, (), 40_000),
    "double_mass": ("double_mass", {}, (), 20_000),
    "rocking_chain_N10": ("rocking_chain", {"param.N": 10}, (), 20_000),
    "double_mass+jump+nojump": ("double_mass", {}, ("jump", "nojump"), 20_000),
    "rocking_chain_N10+jump+nojump": ("rocking_chain", {"param.N": 10}, ("jump", "nojump"), 20_000),
}
"""Windows from t = 0 at the scenario's own h: the whole run of the 1-DOF scenarios
(bouncing_ball 6 s, impact_oscillator 20 s, grazing 40 s at h = 1e-3), 2 s of double_mass
(h = 1e-4) and of the chain (h = 1e-4; its contacts close after ≈ 1 s)."""

LOOP_ROUNDS = (10, 5)
"""Timed rounds per loop benchmark (one call each; the median is reported): the registry's
first time-stepping engine (its default), then every other (the slower references)."""


def loop_rounds(engine: str) -> int:
    return LOOP_ROUNDS[0] if engine == ENGINES[0] else LOOP_ROUNDS[1]


def other_engine(engine: str) -> str:
    """The time-stepping engine the smoke run compares ``engine`` with."""
    return next(e for e in ENGINES if e != engine)
SMOKE_STEPS = 200


def loop_input(scenario: str, overrides: dict, observers: tuple, steps: int, engine: str):
    """The :class:`observer.engines.loop.LoopInput` of ``steps`` steps of a built-in scenario, built as
    :func:`observer.simulate` builds it (observers from the ``[observer]`` table, coupled over
    the whole window)."""
    from observer.loop import LoopInput
    from observer.observers import OBSERVER_DESIGNS, ObserverConfig

    sc = observer.load_scenario(scenario, overrides)
    sc = sc.with_overrides({"simulation.t_end": steps * sc.h})
    stepper = observer.MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, solver=sc.solver,
                                  structure=observer.ENGINES[engine].structure)
    cfg = ObserverConfig.from_table(sc.observer, sc.system.n, sc.q0, sc.u0) if observers else None
    q0 = np.stack([sc.q0] + [cfg.q0 for _ in observers])
    u0 = np.stack([sc.u0] + [cfg.u0 for _ in observers])
    jumps = np.array([False] + [OBSERVER_DESIGNS[o].position_jumps for o in observers])
    return LoopInput(stepper=stepper, q0=q0, u0=u0, jumps=jumps,
                     master_projection=bool(sc.master_projection))


@pytest.fixture(scope="module")
def kernel_compiled():
    """Compile the kernel (or load it from numba's cache) before any loop is timed."""
    from observer.engines.compiled.driver import compile_time
    return compile_time()


@pytest.mark.parametrize("case", list(LOOP_CASES))
@pytest.mark.parametrize("engine", ENGINES)
def test_loop(benchmark, kernel_compiled, engine, case):
    """The time loop of one scenario window on one engine; per step = median / steps."""
    from observer.loop import run

    scenario, overrides, observers, steps = LOOP_CASES[case]
    if benchmark.disabled:
        steps = SMOKE_STEPS
    inp = loop_input(scenario, overrides, observers, steps, engine)
    out = run(inp, engine=engine)                                   # warm-up: caches, compile
    benchmark.group = "time loop (per call; per step = median / steps)"
    benchmark.extra_info.update(kind="loop", scenario=scenario, case=case, engine=engine,
                                steps=int(inp.stepper.grid.steps), n=int(inp.stepper.system.n),
                                m=int(inp.stepper.system.m), systems=1 + len(observers),
                                observers=",".join(observers), h=float(inp.stepper.h),
                                structure="dense" if inp.stepper.S.band is None else "banded",
                                compile_time_s=float(kernel_compiled))
    out = benchmark.pedantic(run, args=(inp,), kwargs={"engine": engine},
                             rounds=loop_rounds(engine), iterations=1, warmup_rounds=0)
    assert np.all(np.isfinite(out.q)) and np.all(np.isfinite(out.u))
    assert out.q.shape[1] == inp.stepper.grid.steps + 1
    other = run(loop_input(scenario, overrides, observers, steps, other_engine(engine)),
                engine=other_engine(engine)) if benchmark.disabled else None
    if other is not None:
        scale = max(1.0, float(np.max(np.abs(other.q))))
        assert np.max(np.abs(out.q - other.q)) <= 1e-9 * scale
