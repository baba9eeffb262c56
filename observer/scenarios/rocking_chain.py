"""Chain of N rocking blocks on a harmonically moving ground (paper, Example 2; docs/theory/models.md §2).

Block i = 1..N (1 = lowest) is a rectangle of width 2b, height H, mass m_i and centroidal
inertia J = m(4b² + H²)/12; it translates vertically (y_i) and rotates (φ_i):
q = (y1, φ1, …, yN, φN), n = 2N. Interface j joins block j−1 (the ground if j = 1) to
block j with two vertical spring–dampers (k, c) at x = ±a, so
``K_j = Σ_r k [1, x_r]ᵀ[1, x_r] = diag(2k, 2ka²)`` and the chain stiffness is
``K = Σ_j (E_j − E_{j−1})ᵀ K_j (E_j − E_{j−1})`` (E_0 := 0), C likewise.

Contacts are the corners x = −b (L) and x = +b (R) of every interface, m = 2N:
``g_{j,s} = g⁰_{j,s} + [1, x_s]·(p_j − p_{j−1})``, so W is square, block lower-bidiagonal
with det W = (2b)^N. The ground moves as y_g = Y sin Ωt (φ_g ≡ 0); it enters the force
through interface 1, ``f = f_grav + E_1ᵀ(K_1 p0 + C_1 ṗ0)``, and the gaps of interface 1,
``ν_{1,s} = g⁰_{1,s} − Y sin Ωt``. The unloaded clearances g⁰ = s − Wᵀq_s are set from the
desired static gaps s (s_L at left corners, s_R at right corners) at the static
configuration q_s = K⁻¹f_grav. Unequal s_L ≠ s_R break the left/right symmetry, which
would otherwise keep every rotation at zero.

Neglected (this is what keeps the model LTI): P-Δ terms, horizontal corner motion,
friction, finite rotation of the contact normals. Poisson law in Glocker's inequality
form (the Delassus matrix has negative off-diagonals for flat blocks, H < 2√2 b).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

DESCRIPTION = "N rocking blocks (y, phi), two corner contacts per interface, moving ground"

PARAMETERS = dict(N=10, m=1.0, b=0.1, H=0.1, a=0.08, k=1000.0, c=5.0, g0=9.81, s_L=0.002,
                  s_R=0.003, Y=0.02, Omega=6.0, restitution=0.9, law="poisson", h=1e-4,
                  t_end=8.0, t_on=4.0, t_off=8.0, slave_offset=1e-6)
"""Defaults (SI units). ``slave_offset`` perturbs φ1 and y_N of the observers' initial state."""

MEMORY_PER_UNIT = {"N": 5000}
"""Bytes per block that building the chain takes (its document, sparse matrices and their
checks): measured 2.4 kB per block (peak RSS of ``load_scenario`` at N = 2000 and 20 000),
doubled as a margin; ``param.N`` beyond the available memory is refused before building."""


def sparse_matrices(N: int, m: float, b: float, H: float, a: float, k: float, c: float):
    """Return M, C, K, W of the chain (n = m = 2N) as CSR matrices, assembled from triplets in
    O(N) (never a dense n × n), and the interface matrices K_j, C_j (2 × 2, dense).

    Interface j+1 joins block j (the ground if j = 0) to block j+1: with D = E_{j+1} − E_j,
    ``DᵀXD`` adds X on the (j+1, j+1) block, −X on the off-diagonal blocks and X on the (j, j)
    block; repeated entries are summed (two equal terms: exactly the dense assembly's values).
    """
    n = 2 * N
    J = m * (4 * b * b + H * H) / 12.0
    offsets = (-a, a)
    K_int = sum(k * np.outer([1.0, x], [1.0, x]) for x in offsets)
    C_int = sum(c * np.outer([1.0, x], [1.0, x]) for x in offsets)
    r2, c2 = np.repeat([0, 1], 2), np.tile([0, 1], 2)              # a 2×2 block's entries
    j = np.arange(N)
    hi = (2 * j)[:, None]                                            # first row of block j+1
    lo = (2 * j - 2)[1:, None]                                       # first row of block j (j ≥ 1)

    def assemble(X):
        x = X.ravel()
        rows = [hi + r2, lo + r2, lo + r2, hi[1:] + r2]
        cols = [hi + c2, lo + c2, hi[1:] + c2, lo + c2]
        vals = [np.broadcast_to(x, (N, 4)), np.broadcast_to(x, (N - 1, 4)),
                np.broadcast_to(-x, (N - 1, 4)), np.broadcast_to(-x, (N - 1, 4))]
        return sp.csr_matrix((np.concatenate([v.ravel() for v in vals]),
                              (np.concatenate([r.ravel() for r in rows]),
                               np.concatenate([q.ravel() for q in cols]))), shape=(n, n))

    M = sp.diags(np.tile([m, J], N)).tocsr()
    w = np.array([[1.0, -b], [1.0, b]])                               # [1, x_s] for s = L, R
    col = (2 * j[:, None] + np.arange(2))                            # contact (j, s)
    rows = [hi[:, :, None] + np.arange(2)[None, None, :] + 0 * col[:, :, None],
            lo[:, :, None] + np.arange(2)[None, None, :] + 0 * col[1:, :, None]]
    cols = [np.broadcast_to(col[:, :, None], (N, 2, 2)), np.broadcast_to(col[1:, :, None], (N - 1, 2, 2))]
    vals = [np.broadcast_to(w, (N, 2, 2)), np.broadcast_to(-w, (N - 1, 2, 2))]
    W = sp.csr_matrix((np.concatenate([v.ravel() for v in vals]),
                       (np.concatenate([r.ravel() for r in rows]),
                        np.concatenate([q.ravel() for q in cols]))), shape=(n, n))
    for A in (M, W):
        A.sum_duplicates()
    return M, assemble(C_int), assemble(K_int), W, K_int, C_int


def matrices(N: int, m: float, b: float, H: float, a: float, k: float, c: float):
    """Return M, C, K, W of the chain (n = m = 2N) as dense arrays and the interface matrices
    K_j, C_j (:func:`sparse_matrices`, densified: for small N and the tests)."""
    M, C, K, W, K_int, C_int = sparse_matrices(N, m, b, H, a, k, c)
    return M.toarray(), C.toarray(), K.toarray(), W.toarray(), K_int, C_int


def document_matrix(A) -> list | dict:
    """A matrix as the document holds it: nested lists up to n = :data:`observer.sparse.DENSE_MAX_N`
    (as always), beyond a banded table of NumPy arrays (:func:`observer.sparse.banded_document`:
    O(n·bandwidth), never a dense n × n; ``Scenario.to_dict`` gives the TOML lists)."""
    from observer.sparse import DENSE_MAX_N, banded_document
    return A.toarray().tolist() if A.shape[0] <= DENSE_MAX_N else banded_document(A, plain=False)


def static_state(K, W, f_grav: np.ndarray, s: np.ndarray):
    """The static configuration ``q_s = K⁻¹f_grav`` and the unloaded clearances
    ``g⁰ = s − Wᵀq_s``: dense for n ≤ :data:`observer.sparse.DENSE_MAX_N` (the reference
    values, bit for bit), else a banded Cholesky solve and a sparse product (O(n))."""
    from observer.sparse import DENSE_MAX_N, to_band
    n = K.shape[0]
    if n <= DENSE_MAX_N:
        q_s = np.linalg.solve(K.toarray(), f_grav)
        return q_s, s - W.toarray().T @ q_s
    chol = sla.cholesky_banded(to_band(K, 3), lower=True)
    q_s = sla.cho_solve_banded((chol, True), f_grav)
    return q_s, s - W.T @ q_s


PLOT = dict(dof=1, contact=1, labels=("φ₁ (rad)", "corner gap (m)"))
"""φ₁ (rotation of the lowest block) and its right ground corner, as in the paper's Fig. 5."""
NOTES = "the paper's Example 2: dense clusters of simultaneous impacts on many contacts."
SUITE = {
    "observers": [dict(params=(("param.N", 10),), h=(2e-4, 1e-4), t_end=(8.0, 8.0))],
    # event reference: N = 4 blocks over 1.5 s, 37 impacts on 5 of its 8 contacts (a cluster
    # of 23 at t ≈ 0.82–0.91 s), no two impacts closer than 4.4e-4 s. Time-stepping treats
    # impacts less than a step or two apart as one multi-contact impact (or swaps them), an
    # O(1) change of the outcome, so it converges only once h is below about half the
    # smallest interval between impacts:
    # N = 5 over 2 s (intervals down to 2.6e-6 s) has error ≈ 1e-3 for every h from 1e-3 to
    # 2e-6, then 4.9e-7 at 1e-6 and 1.0e-7 at 2.5e-7; N = 10 over 2 s (down to 1.5e-8 s) is
    # out of reach (its event run takes longer than the suites allow). The error jumps with
    # where the impacts fall on the grid, so the order is fitted over 11 halvings
    # (4e-3 … 3.9e-6 s; full: 13, to 9.8e-7 s)
    "work_precision": dict(h0=4e-3, t_end=1.5, params=(("param.N", 4),), targets=("master",),
                           sizes=dict(quick=11, full=13)),
    "checks": "full",
    "exact": False,        # N = 10: dense clusters of impacts, time-stepping's ground, not event-driven's
}


def document(**overrides) -> dict:
    p = {**PARAMETERS, **overrides}
    N = int(p["N"])
    if N < 1 or N != p["N"]:
        from observer.errors import InputError
        raise InputError("param.N", f"must be a positive integer, got {p['N']!r}")
    M, C, K, W, K_int, C_int = sparse_matrices(N, p["m"], p["b"], p["H"], p["a"], p["k"], p["c"])
    n = 2 * N
    f_grav = np.zeros(n)
    f_grav[0::2] = -p["g0"] * p["m"]
    q_s, g0 = static_state(K, W, f_grav, np.tile([p["s_L"], p["s_R"]], N))
    entry = document_matrix
    Y, Om = p["Y"], p["Omega"]
    # f = f_grav + E_1ᵀ(K_1 [Y sin Ωt, 0] + C_1 [YΩ cos Ωt, 0]); sin Ωt = cos(Ωt − π/2)
    amp_k = np.zeros(n)
    amp_k[:2] = Y * K_int[:, 0]
    amp_c = np.zeros(n)
    amp_c[:2] = Y * Om * C_int[:, 0]
    gap_amp = np.zeros(n)
    gap_amp[:2] = -Y                          # ν_{1,s} = g⁰ − [1, x_s]·p0 = g⁰ − Y sin Ωt
    slave_q = q_s.copy()
    slave_q[1] += p["slave_offset"]
    slave_q[n - 2] += p["slave_offset"]
    return {
        "scenario": {"name": "rocking_chain", "description": DESCRIPTION},
        "system": {"M": entry(M), "C": entry(C), "K": entry(K), "W": entry(W),
                   "forcing": {"constant": f_grav.tolist(), "amplitude": amp_c.tolist(),
                               "omega": Om, "phase": 0.0,
                               "harmonics": [{"amplitude": amp_k.tolist(), "omega": Om,
                                              "phase": -np.pi / 2}]},
                   "gap": {"offset": g0.tolist(), "amplitude": gap_amp.tolist(), "omega": Om,
                           "phase": 0.0}},
        "impact": {"law": p["law"], "restitution": p["restitution"]},
        "initial": {"q": q_s.tolist(), "u": [0.0] * n},
        "simulation": {"t_end": p["t_end"], "h": p["h"], "theta": 0.5},
        "observer": {"q": slave_q.tolist(), "u": [0.0] * n, "coupling": [p["t_on"], p["t_off"]],
                     "source": "master", "observers": ["jump", "nojump"]},
    }
