"""Issue 34, item 1: which entries of a held flow's accelerations the balancing ignores
(:func:`observer.event.flow.held_zeros`): those whose exact value, from the same float64
data, is 0 -- no count of round-offs against the row's largest term (the rule it replaced,
``64 eps`` of the row maximum) and no a-priori float64 bound of the last product alone.

The reference here is written apart from the engine: the held accelerations
``H = M⁻¹L − M⁻¹W_I (W_IᵀM⁻¹W_I)⁻¹ (gap rows of I)·A·A`` (L = (−K, −C, forcing rows)) in
Python's ``fractions.Fraction`` (Gauss–Jordan), from the system's float data taken as exact
rationals.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from observer.event.enclosures import gamma
import observer.event.flow as flow_module
from observer.event.flow import Flow, _signal_rows, balance, held_zeros
from observer.scenario import Scenario


def _doc(M, K, C, W, q0, nu, f, a, w, phi, alpha=1.0, beta=1.0) -> dict:
    """A scenario document (lengths × α, times × β) of the given matrices."""
    M, K, C, W = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (M, K, C, W))
    return {"scenario": {"name": "held-zeros"},
            "system": {"M": M.tolist(), "C": (C / beta).tolist(), "K": (K / beta ** 2).tolist(),
                       "W": W.tolist(),
                       "forcing": {"constant": (np.asarray(f) * alpha / beta ** 2).tolist(),
                                   "amplitude": (np.asarray(a) * alpha / beta ** 2).tolist(),
                                   "omega": w / beta, "phase": phi},
                       "gap": {"offset": (np.asarray(nu) * alpha).tolist()}},
            "impact": {"law": "newton", "restitution": 0.5},
            "initial": {"q": (np.asarray(q0) * alpha).tolist(), "u": [0.0] * M.shape[0]},
            "simulation": {"t_end": 0.2 * beta, "h": 0.05 * beta}}


TINY_PHASE = _doc(M=np.diag([1.7061716986606097, 1.1]), K=np.diag([1.7098978604619472, 0.0]),
                  C=np.diag([0.001, 0.0]), W=[[1.0, 0.0002], [-0.1984156123669675, 1.0]],
                  q0=[0.0002, 0.0002], nu=[0.009556734041782087, 0.00990711841983954],
                  f=[-17.061375007034005, -11.0], a=[0.0, -0.019841561236696753],
                  w=2.273894586042595, phi=3.2541865008425024e-176, alpha=1e3, beta=0.1)
"""``test_invariance.TINY_PHASE`` in mm and 0.1 s: both DOFs held, so every exact held
acceleration is 0; the float64 ones keep nonzero residues (their size depends on the BLAS and
LAPACK build)."""

ONE_ULP = 2.0 ** -52
PROJECTION = _doc(M=np.eye(2), K=[[1.0, 1.0], [1.0, 1.0 + ONE_ULP]], C=np.zeros((2, 2)),
                  W=[[1.0], [1.0]], q0=[0.0, 0.0], nu=[0.1], f=[0.0, 0.0], a=[0.0, 0.0],
                  w=1.0, phi=0.0)
"""M = I and one contact on both DOFs (w = (1, 1)): the held accelerations are the free ones
projected off w, ``H = (I − wwᵀ/2)(−K)``. K's first column is parallel to w (H's column 0 is
exactly 0); its second is one ulp off it (H's column 1 is ±2^-53, exactly, against terms of
1: nonzero, though below both a count of round-offs and the float64 bound γ_4)."""


def _fractions(x) -> list[list[Fraction]]:
    return [[Fraction(float(v)) for v in row] for row in np.atleast_2d(np.asarray(x, float))]


def _mul(X, Y):
    return [[sum((X[i][k] * Y[k][j] for k in range(len(Y))), Fraction(0))
             for j in range(len(Y[0]))] for i in range(len(X))]


def _solve(G, X):
    """G⁻¹X by Gauss–Jordan in fractions (G nonsingular)."""
    p = len(G)
    aug = [list(G[i]) + list(X[i]) for i in range(p)]
    for c in range(p):
        r = next(i for i in range(c, p) if aug[i][c] != 0)
        aug[c], aug[r] = aug[r], aug[c]
        piv = aug[c][c]
        aug[c] = [v / piv for v in aug[c]]
        for i in range(p):
            if i != c and aug[i][c] != 0:
                fac = aug[i][c]
                aug[i] = [v - fac * u for v, u in zip(aug[i], aug[c])]
    return [row[p:] for row in aug]


def _loads(flow: Flow) -> np.ndarray:
    """``(−K, −C, harmonic forcing rows, constant force)``: M times the free accelerations."""
    s = flow.system
    f_osc, f_const = _signal_rows(s.forcing, flow.freqs)     # the forcing's coefficients
    return np.hstack([-s.K, -s.C, f_osc, f_const.reshape(-1, 1)])


def exact_held(flow: Flow) -> list[list[Fraction]]:
    """The exact held accelerations of ``flow``'s system (M, the loads, W_I, the gap rows;
    the free generator's rows but the accelerations: the identity and the rotations)."""
    n, I, s = flow.n, list(flow.active), flow.system
    M = _fractions(s.M)
    A_u = _solve(M, _fractions(_loads(flow)))
    A = _fractions(Flow(s, ()).A)
    A[n:2 * n] = A_u
    W = _fractions(s.W[:, I])
    P = _solve(M, W)
    G = _mul([list(col) for col in zip(*W)], P)
    X = _mul(_mul(_fractions(flow.gap_rows[I]), A), A)
    PF = _mul(P, _solve(G, X))
    return [[A_u[i][j] - PF[i][j] for j in range(flow.N)] for i in range(n)]


def held_flow(doc: dict, active: tuple[int, ...]) -> tuple[Flow, np.ndarray]:
    """The flow of ``doc`` holding ``active``, and the held accelerations' entries its
    balancing ignored (the mask :class:`Flow` handed to :func:`observer.event.flow.balance`;
    subnormal entries, ignored as well, are 0 in the reference)."""
    seen = []

    def spy(A, cancelled):
        seen.append(cancelled.copy())
        return balance(A, cancelled)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(flow_module, "balance", spy)
        flow = Flow(Scenario.from_dict(doc).system, active)
    n = flow.n
    mask = seen[0][n:2 * n]
    direct = held_zeros(Flow(flow.system, ()).A, flow.system.M, _loads(flow),
                        flow.system.W[:, list(flow.active)], flow.gap_rows[list(flow.active)])
    np.testing.assert_array_equal(mask, direct | (np.abs(flow.A[n:2 * n]) < np.finfo(float).tiny))
    return flow, mask


def _own_terms(flow: Flow) -> np.ndarray:
    """``|A_u| + |M⁻¹||W_I||F̂|`` (float64): the terms of each computed held acceleration."""
    n, I = flow.n, list(flow.active)
    free = Flow(flow.system, ())
    return (np.abs(free.A[n:2 * n]) + np.abs(flow.Minv) @ np.abs(flow.system.W[:, I])
            @ np.abs(flow.force_rows))


def test_every_exact_zero_is_cancelled_though_its_residue_exceeds_the_float64_bound():
    """:data:`TINY_PHASE` held on both contacts: the reference finds every held acceleration
    exactly 0, and all are cancelled, though float64 leaves nonzero residues (how large
    depends on the BLAS and LAPACK build: on some up to 150 γ_{n+p+1} of their own terms, which
    a float64 bound of the last product would keep); the balancing leaves every scale at 1
    (it was 2^-24 with that bound)."""
    flow, mask = held_flow(TINY_PHASE, (0, 1))
    n = flow.n
    H = exact_held(flow)
    assert all(h == 0 for row in H for h in row)
    assert mask.all()
    residue = np.abs(flow.A[n:2 * n])
    assert np.any(residue > 0.0)              # float64 leaves residues where H is exactly 0
    np.testing.assert_array_equal(flow.scale, np.ones(flow.N))


def test_an_entry_one_ulp_off_an_exact_zero_is_kept_and_the_exact_zero_is_cancelled():
    """:data:`PROJECTION`: the near miss. H[:, 0] is exactly 0 and cancelled; H[:, 1] is
    ±2^-53 exactly (the reference) and kept, though it is below 64 eps of its row's largest
    term (the old rule cancelled it) and below γ_4 of its own terms (a count too small for
    the solve, as a float64 bound of the last product, would cancel it)."""
    flow, mask = held_flow(PROJECTION, (0,))
    n = flow.n
    H = exact_held(flow)
    assert [H[0][0], H[1][0]] == [0, 0]
    assert [H[0][1], H[1][1]] == [Fraction(1, 2 ** 53), Fraction(-1, 2 ** 53)]
    zero = np.array([[h == 0 for h in row] for row in H])
    np.testing.assert_array_equal(mask, zero | (flow.A[n:2 * n] == 0.0))
    assert not mask[1, 1] and mask[0, 0] and mask[1, 0]   # (its float [0, 1] is 0.0)
    computed = abs(flow.A[n + 1, 1])                 # float64: 2^-52 (the other entry: 0)
    assert computed > 0.0
    assert computed <= 64.0 * np.finfo(float).eps * np.max(_own_terms(flow)[1])
    assert computed <= gamma(n + 1 + 1) * _own_terms(flow)[1, 1]


@pytest.mark.parametrize("held", [(0,), (1,), (0, 1)])
def test_the_cancelled_entries_are_the_exact_zeros_of_the_reference(held):
    """On a coupled, damped, harmonically forced 2-DOF system, holding each contact set:
    the cancelled entries are exactly the reference's zeros (all, when both DOFs are held)."""
    doc = _doc(M=[[2.0, 0.3], [0.3, 1.1]], K=[[3.0, -1.0], [-1.0, 2.0]],
               C=[[0.1, 0.0], [0.0, 0.05]], W=[[1.0, 0.2], [-0.3, 1.0]], q0=[0.1, 0.2],
               nu=[0.05, 0.07], f=[-9.81, -9.81], a=[0.4, 0.1], w=3.0, phi=0.3)
    flow, mask = held_flow(doc, held)
    zero = np.array([[h == 0 for h in row] for row in exact_held(flow)])
    np.testing.assert_array_equal(mask, zero | (flow.A[flow.n:2 * flow.n] == 0.0))
    assert zero.all() == (len(held) == 2)
