"""Verified positive definiteness of a large banded K, and the position jump at cond(K) ≈ 2.5e12
(issue 23: the default rocking chain of 10⁵ blocks).

Oracles: the closed-form spectrum of the chain's stiffness (a fixed-free chain of springs:
``λ = 4κ sin²((2k − 1)π / (2(2N + 1)))``, κ = 2k and 2ka² for the vertical and the rocking
subchains, which K decouples), matrices built from it with a chosen smallest eigenvalue
relative to the verification shift c, and the gaps recomputed from the jumped positions.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

from observer import sparse as sps
from observer.errors import InputError
from observer.model import Harmonic, LinearSystem
from observer.scenarios import rocking_chain as rc


def chain(N: int, **over):
    p = {**rc.PARAMETERS, **over}
    return rc.sparse_matrices(N, p["m"], p["b"], p["H"], p["a"], p["k"], p["c"])


def chain_lambda_min(N: int) -> float:
    """Smallest eigenvalue of the default chain's K: the rocking subchain's lowest mode."""
    p = rc.PARAMETERS
    kappa = 2.0 * p["k"] * p["a"] ** 2
    return 4.0 * kappa * np.sin(np.pi / (2.0 * (2 * N + 1))) ** 2


def test_closed_form_spectrum_is_the_chains():
    """The oracle itself, against dense eigenvalues at N = 200."""
    N = 200
    eig = np.linalg.eigvalsh(chain(N)[2].toarray())
    assert chain_lambda_min(N) == pytest.approx(eig[0], rel=1e-9)


def test_default_chain_of_1e5_blocks_is_verified_definite_where_the_old_threshold_refused():
    """cond(K) ≈ 2.5e12 > 1e12: the former test (λ_min > 1e-12·λ_max) refused it; the verified
    Cholesky of K − cI proves it, λ_min being ≈ 335·c."""
    N = 100_000
    K = chain(N)[2]
    lam_min, lam_max = chain_lambda_min(N), 4.0 * 2.0 * rc.PARAMETERS["k"]
    assert lam_min < 1e-12 * lam_max                      # the old criterion's refusal
    ok, how = sps.verified_definite(K)
    assert ok and how.startswith("verified")
    c = sps.verification_shift(2, float(K.diagonal().max()))
    u = 2.0 ** -53                                   # γ_4/(1 − γ_4) = 4u/(1 − 8u); 2w + 1 = 5; max K_ii = 4000
    assert c == pytest.approx(1.01 * (4 * u / (1 - 8 * u) * 5 * 4000.0 * (1 + u) + u * 4000.0), rel=1e-12)
    assert 100 * c < lam_min < 1000 * c


def shifted_chain(N: int, lam: float) -> sp.csr_matrix:
    """The chain's K shifted so that its smallest eigenvalue is ``lam`` (to the rounding of the
    shifted diagonal, ≤ u·max K_ii = 0.05·c here)."""
    K = chain(N)[2]
    return sp.csr_matrix(K + (lam - chain_lambda_min(N)) * sp.eye(K.shape[0]))


@pytest.mark.parametrize("ratio, definite", [(3.0, True), (0.99, False), (-0.01, False)])
def test_verified_test_accepts_a_margin_above_c_and_refuses_a_near_miss_and_a_negative_eigenvalue(ratio, definite):
    """λ_min = 3c: proved; λ_min = 0.99c (positive definite, but not provably so in floating
    point at this shift: the near miss): refused; λ_min = −c/100 (a tiny negative
    eigenvalue, 1e-17 of λ_max): refused. The smallest eigenvector lives in the rocking
    subchain (diagonal 25.6): its entries round to ≤ 2e-15, far below the 1 % of c = 9.4e-14
    that separates the near miss from c. Through the model: the system's K-metric projection
    is refused by name, with how."""
    N = 300
    K0 = chain(N)[2]
    c = sps.verification_shift(2, float(K0.diagonal().max()))
    K = shifted_chain(N, ratio * c)
    assert sps.verified_definite(K)[0] is definite
    M, C, _, W, _, _ = chain(N)
    n = K.shape[0]
    system = LinearSystem(M, C, K, W, Harmonic.build("f", n), Harmonic.build("g", n, constant=1.0, kind="sin"))
    assert system.is_stiffness_definite() is definite
    assert system.stiffness_definiteness()[1].startswith("verified")
    if not definite:
        with pytest.raises(InputError) as err:
            system.require_definite_stiffness("the test")
        assert err.value.field == "system.K"


def test_dense_stiffness_keeps_the_eigenvalue_threshold():
    """n ≤ 512 (dense): K with λ_min = 1e-13·λ_max is refused as before, how says eigenvalues."""
    N = 10
    K0 = chain(N)[2].toarray()
    lo, hi = np.linalg.eigvalsh(K0)[[0, -1]]
    K = K0 + (1e-13 * hi - lo) * np.eye(2 * N)
    M, C, _, W, _, _ = chain(N)
    system = LinearSystem(M, C, K, W, Harmonic.build("f", 2 * N),
                          Harmonic.build("g", 2 * N, constant=1.0, kind="sin"))
    assert not system.is_stiffness_definite()
    assert system.stiffness_definiteness()[1].startswith("eigenvalues")


def test_jump_at_1e5_blocks_closes_the_gaps_to_round_off():
    """The kernel's factored projection (eqs. (13)-(14), L_A from cached banded solves, the
    jump by one more) on the default chain of 10⁵ blocks, cond(K) ≈ 2.5e12: the closed gaps
    after the jump are zero to 1e-14 of the pre-jump gaps (measured ≤ 4e-16).

    Not cond(K)·u ≈ 3e-4: the solve's error lies in K's soft modes (the chain bending as a
    whole), which the gaps (relative motions at one interface) hardly see; what they feel is
    cond(L_A) ≤ cond(L) = 1.56 (L = WᵀK⁻¹W is block diagonal for the chain), so the bound is
    64·u·cond(L) ≈ 1.1e-14."""
    from observer.kernel import factored_project
    from observer.loop import column_cache
    N = 100_000
    _, _, K, W, _, _ = chain(N)
    n = 2 * N
    bw = sps.bandwidth(K)
    fac = sla.cholesky_banded(sps.to_band(K, bw), lower=True)[None]
    Wc = sp.csc_matrix(W)
    Wc.sort_indices()
    Wp, Wi, Wv = Wc.indptr.astype(np.int64), Wc.indices.astype(np.int64), Wc.data.copy()
    cache = column_cache(1, n, n, C=8)
    rng = np.random.default_rng(5)
    nu = np.full((1, n), -1e-4)
    for _ in range(3):
        act = np.unique(np.concatenate([[0, n - 1], rng.choice(n, 4, replace=False)])).astype(np.int64)
        a = act.size
        q = rng.normal(size=n) * 1e-3
        g0 = (W.T @ q + nu[0])[act]
        q1 = q.copy()
        status = factored_project(0, act, a, 0, (Wp, Wi, Wv), nu, fac, bw, cache, q1, np.empty(a), np.empty(a),
                                  np.empty(a), np.empty((a, a)), np.empty((a, a)), np.empty(n))
        assert status == 0
        g1 = (W.T @ q1 + nu[0])[act]
        assert np.max(np.abs(g1)) <= 1e-14 * np.max(np.abs(g0))
