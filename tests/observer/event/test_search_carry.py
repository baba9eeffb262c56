"""Issue 34: the search's own accumulated rounding (:class:`observer.event.roots.SearchCarry`,
one compiled :func:`observer.event.kernels.carry_step` per window step) bounds the true drift
of the search's float state, componentwise and in the energy norm.

The reference is the same chain of propagators E_k = ``flow.expm(s_k)`` (as computed: the
bound's scope) applied in exact rational arithmetic (:class:`fractions.Fraction`) to the same
start state: what the float chain ``z ← fl(E_k z)`` would give without rounding.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from observer.event.master import ZENO_VELOCITY_RATIO, _Run
from observer.event.roots import SearchCarry
from observer.scenario import Scenario


def chain(c: float) -> Scenario:
    """Two masses on springs (damping c), contacts far away (gaps never close)."""
    doc = {"scenario": {"name": "chain"},
           "system": {"M": [[1.0, 0.0], [0.0, 2.0]], "C": [[c, 0.0], [0.0, c]],
                      "K": [[3.0, -1.0], [-1.0, 1.0]], "W": [[1.0, 0.0], [0.0, 1.0]],
                      "forcing": {"constant": [0.3, -0.7]}, "gap": {"offset": [50.0, 50.0]}},
           "impact": {"law": "newton", "restitution": 0.5},
           "initial": {"q": [0.9, -1.3], "u": [0.2, 1.1]},
           "simulation": {"t_end": 40.0, "h": 10.0}}
    return Scenario.from_dict(doc)


def exact_product(E: np.ndarray, z: list) -> list:
    return [sum((Fraction(float(E[i, j])) * z[j] for j in range(len(z))), Fraction(0))
            for i in range(E.shape[0])]


@pytest.mark.parametrize("c", [0.0, 0.05])
def test_the_search_carry_bounds_the_float_chain_drift(c):
    """300 window steps of pseudo-random lengths 0.01 … 0.2 s: the float state's distance to
    the exact chain is within :attr:`SearchCarry.err` in every mechanical component and within
    ε in ‖·‖_P (the run's energy matrix, δᵀPδ in rationals), at every step and at the end
    carried a further 0.37 s by :meth:`SearchCarry.at`; and the drift is real (nonzero)."""
    sc = chain(c)
    run = _Run(sc, 10.0, 40.0, 10, ZENO_VELOCITY_RATIO)
    flow = run.free_flow
    k = 2 * flow.n
    z = flow.z(0.0, np.concatenate([sc.q0, sc.u0]))
    carry = SearchCarry(flow, flow.gap_rows, 0.0, z, None, run.energy)
    exact = [Fraction(float(v)) for v in z]
    P = [[Fraction(float(v)) for v in row] for row in run.energy.P]
    rng = np.random.default_rng(7)
    drift = 0.0

    def check(zf, ex, err, eps):
        d = [Fraction(float(zf[i])) - ex[i] for i in range(k)]
        assert all(abs(d[i]) <= Fraction(float(err[i])) for i in range(k))
        q = sum((d[i] * P[i][j] * d[j] for i in range(k) for j in range(k)), Fraction(0))
        assert q <= Fraction(eps) ** 2
        return max(abs(float(v)) for v in d)

    for _ in range(300):
        s = float(rng.uniform(0.01, 0.2))
        exact = exact_product(flow.expm(s), exact)
        z = carry.advance(s, z)
        drift = max(drift, check(z, exact, carry.err, carry.eps))
    s = 0.37
    err, eps = carry.at(carry.a + s)
    E = flow.expm(s)
    check(E @ z, exact_product(E, exact), err, eps)
    assert drift > 0.0 and math.isfinite(carry.eps)
