"""observer.impact.newton_step: the documented return (P, Λ_C, Λ_E) with empty phases, P
the LCP solution for G and γ_free + e∘γ_k checked by complementarity recomputed here.
Written against the mutation run of ``observer/impact.py`` (``tests/mutants/impact.md``).
"""

from __future__ import annotations

import numpy as np

from lcp_enum import lcp_enum
from observer.contact.lcp import LCPSolution
from observer.impact import newton_step


def test_newton_step_returns_the_lcp_impulse_and_no_phases():
    G = np.array([[2.0, 0.5], [0.5, 1.0]])
    gamma_free, gamma_k, e = np.array([-1.0, 0.4]), np.array([-2.0, 0.1]), np.array([0.5, 0.25])
    seen = []

    def solve(A, b):
        seen.append(b.copy())
        return LCPSolution(lcp_enum(A, b), 0.0, 1, "enum")
    P, lam_c, lam_e = newton_step(G, gamma_free, gamma_k, e, solve)
    assert np.array_equal(seen[0], gamma_free + e * gamma_k)
    w = G @ P + gamma_free + e * gamma_k                   # γ_{k+1} + e∘γ_k
    assert np.all(P >= 0) and np.all(w >= -1e-12) and abs(P @ w) <= 1e-12
    assert P[0] > 0
    assert lam_c.shape == (0,) and lam_e.shape == (0,)
