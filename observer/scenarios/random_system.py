"""Random systems: a seeded family of linear systems with unilateral contacts (issue 22).

For ``seed``, ``dof`` = n ∈ 2…8 and ``contacts`` = m ∈ 1…4 (m ≤ n), a generator
``numpy.random.default_rng(seed)`` draws, in this order:

* M = I + B_M B_Mᵀ / n, K = k (I + B_K B_Kᵀ / n), C = c (I + B_C B_Cᵀ / n) with ``B_·`` standard
  normal n × n: symmetric positive definite (eigenvalues ≥ 1, ≥ k, ≥ c), so every observer
  design applies (K ≻ 0, docs/theory/index.md §2 item 6);
* W (n × m): standard normal columns scaled to unit length, redrawn until rank m (independent
  columns: the Delassus matrix WᵀM⁻¹W is positive definite and every LCP of the step has one
  solution);
* the clearances s ∈ U(s_min, s_max)^m and the observers' initial error (q̂ − q, û − u) of
  standard-normal directions scaled by ``err_q`` and ``err_u``.

The master starts at rest at q = 0 with gap offsets ν = s, so g(0) = s > 0 (a feasible
state). No constant force; the harmonic force F cos Ωt has the amplitude
``a = −δ K W (WᵀW)⁻¹ 1`` with δ = ``push``·max s, whose static response K⁻¹a lowers every
gap by δ (Wᵀ K⁻¹ a = −δ 1), and Ω = ``omega_ratio``·ω₁ (ω₁ the lowest undamped natural
frequency of (M, K)): every contact is hit, impacts recur once per forcing period.
Newton's law with one restitution e (for one contact Poisson's law gives the same).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from observer.errors import InputError

DESCRIPTION = "random SPD M, K, C and random W (2-8 DOF, 1-4 contacts), seeded; forced onto its contacts"

PARAMETERS = dict(seed=0, dof=3, contacts=2, k=100.0, c=2.0, s_min=0.005, s_max=0.01, push=2.0,
                  omega_ratio=0.8, restitution=0.5, law="newton", h=2e-4, t_end=10.0,
                  err_q=0.01, err_u=0.05)
"""Defaults: ``k`` and ``c`` scale the stiffness and damping, clearances in [s_min, s_max] m,
``push``·s_max the static gap reduction of the forcing, Ω = ``omega_ratio``·ω₁."""

DOF_RANGE = (2, 8)
CONTACT_RANGE = (1, 4)

PLOT = dict(dof=0, contact=0, labels=("q₁", "gap₁"))
NOTES = ("a seeded random system (SPD M, K, C, random contact normals W): asks whether the "
         "built-ins' conclusions hold beyond them.")
SUITE = {
    "observers": [dict(h=(5e-4, 2e-4), t_end=(5.0, 10.0))],
    "work_precision": None,
    "checks": "full",
    "exact": False,          # several random contacts: time-stepping's ground (ensembles included)
}


def _integer(p: dict, key: str, lo: int, hi: int) -> int:
    v = p[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or v != int(v) or not lo <= v <= hi:
        raise InputError(f"param.{key}", f"must be an integer in {lo}…{hi}, got {v!r}")
    return int(v)


def _spd(rng: np.random.Generator, n: int, scale: float) -> np.ndarray:
    """scale·(I + B Bᵀ / n), B standard normal: symmetric, eigenvalues ≥ scale."""
    B = rng.standard_normal((n, n))
    A = scale * (np.eye(n) + B @ B.T / n)
    return (A + A.T) / 2


def _normals(rng: np.random.Generator, n: int, m: int) -> np.ndarray:
    """n × m unit columns of rank m (redrawn in the rare case of dependence)."""
    while True:
        W = rng.standard_normal((n, m))
        W /= np.linalg.norm(W, axis=0)
        if np.linalg.matrix_rank(W, tol=1e-3) == m:
            return W


def matrices(seed: int, n: int, m: int, k: float, c: float):
    """M, C, K, W of the random system (the draws of the module docstring, in its order) and
    the generator, positioned after them."""
    rng = np.random.default_rng(seed)
    M, K, C = _spd(rng, n, 1.0), _spd(rng, n, k), _spd(rng, n, c)
    return M, C, K, _normals(rng, n, m), rng


def document(**overrides) -> dict:
    """The scenario document for the given parameters (see :data:`PARAMETERS`)."""
    p = {**PARAMETERS, **overrides}
    n = _integer(p, "dof", *DOF_RANGE)
    m = _integer(p, "contacts", *CONTACT_RANGE)
    seed = _integer(p, "seed", 0, 2 ** 63 - 1)
    if m > n:
        raise InputError("param.contacts", f"must not exceed dof = {n} (independent contact normals), got {m}")
    M, C, K, W, rng = matrices(seed, n, m, p["k"], p["c"])
    s = rng.uniform(p["s_min"], p["s_max"], m)
    dq, du = rng.standard_normal(n), rng.standard_normal(n)
    dq *= p["err_q"] / np.linalg.norm(dq)
    du *= p["err_u"] / np.linalg.norm(du)
    delta = p["push"] * p["s_max"]
    amp = -delta * K @ W @ np.linalg.solve(W.T @ W, np.ones(m))
    omega1 = float(np.sqrt(sla.eigh(K, M, eigvals_only=True)[0]))
    return {
        "scenario": {"name": "random_system", "description": DESCRIPTION},
        "system": {"M": M.tolist(), "C": C.tolist(), "K": K.tolist(), "W": W.tolist(),
                   "forcing": {"constant": [0.0] * n, "amplitude": amp.tolist(),
                               "omega": p["omega_ratio"] * omega1, "phase": 0.0},
                   "gap": {"offset": s.tolist()}},
        "impact": {"law": p["law"], "restitution": p["restitution"]},
        "initial": {"q": [0.0] * n, "u": [0.0] * n},
        "simulation": {"t_end": p["t_end"], "h": p["h"], "theta": 0.5},
        "observer": {"q": dq.tolist(), "u": du.tolist(), "coupling": [0.0, p["t_end"]],
                     "source": "master", "observers": ["jump", "nojump"]},
    }
