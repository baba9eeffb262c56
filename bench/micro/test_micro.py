"""Micro-benchmarks (pytest-benchmark): one Moreau–Jean step and one contact (LCP) solve.

Run with the suite (``python -m bench run quick`` writes ``bench/results/quick-micro.json``)
or directly::

    python -m pytest bench/micro --benchmark-only --benchmark-json=micro.json

Contact problems are real Delassus matrices ``G = W_AᵀÂ⁻¹W_A`` of the built-in scenarios
(m = 1: double_mass; m = 4 and 20: rocking_chain N = 10 with its first 4 / all 20 contacts
closed), with seeded random right-hand sides that have negative entries (so that no solver
can return the trivial solution). Every benchmark also asserts the solution, recomputed
here from the returned x (never the solver's self-reported ``residual``): x ≥ 0 and the
relative complementarity residual ``‖min(x, Gx + b)‖∞ / max(‖b‖∞, ‖Gx‖∞)`` ≤ 1e-9
(timings of wrong answers are worthless); the pivoting solver must answer by its fast
path (no Lemke fallback). Groups
put the solvers of one size side by side; the report divides the reference (cvxpy + OSQP)
time by the fast solvers' times.
"""

from __future__ import annotations

import numpy as np
import pytest

import observer
from observer.contact import get_solver

SIZES = (1, 4, 20)
SOLVERS = ("reference", "pivoting", "lemke", "nnls")


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


STEP_CASES = {
    "double_mass, free flight (n=2)": ("double_mass", {}, 0, False),
    "double_mass, 1 closed contact (n=2)": ("double_mass", {}, 1, False),
    "rocking_chain N=10, free flight (n=20)": ("rocking_chain", {"param.N": 10}, 0, False),
    "rocking_chain N=10, 4 closed contacts (n=20)": ("rocking_chain", {"param.N": 10}, 4, False),
    "rocking_chain N=10, 4 closed + projection (jump observer)": ("rocking_chain", {"param.N": 10}, 4, True),
}


@pytest.mark.parametrize("case", list(STEP_CASES))
def test_step(benchmark, case):
    """One Moreau–Jean step (scenario's law and solver) on a given closed set."""
    name, params, closed, project = STEP_CASES[case]
    sc = observer.load_scenario(name, params)
    stepper = observer.MoreauJean(sc.system, sc.law, sc.h, 100 * sc.h, solver="pivoting")
    rng = np.random.default_rng(7)
    q = sc.q0.copy()
    u = sc.u0 - 0.05 * np.abs(rng.standard_normal(sc.system.n))   # moving down onto the contacts
    active = np.arange(closed)
    stepper.step(0, q, u, active, project)
    benchmark.group = "Moreau–Jean step"
    benchmark.extra_info.update(kind="step", scenario=name, n=sc.system.n, closed=closed,
                                projection=project, law=sc.law.law)
    q1, u1, P, _ = benchmark(stepper.step, 0, q, u, active, project)
    assert np.all(np.isfinite(q1)) and np.all(np.isfinite(u1))
    assert P.shape == (closed,) and np.all(P >= 0.0)
