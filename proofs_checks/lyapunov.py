"""Eq. (17), dV ≤ 0 along the error of two slaves driven by the same χ, and Theorem 1 (V → 0).

Lyapunov function (16) with the ½ on both terms (THEORY §2 erratum 2)::

    V(e, v) = ½ vᵀMv + ½ eᵀKe,    e = q₁ − q₂,  v = u₁ − u₂.

Continuous claim (17)::

    dV = −‖v‖²_C̄ dt − ½‖g₁⁻ − g₂⁻‖²_{P_I L_I⁻¹ P_Iᵀ} dη + (γ̄₁ − γ̄₂)ᵀ(Λ₁ − Λ₂) dη ≤ 0.

Discrete form (exact for the Moreau–Jean θ-scheme; THEORY §6.3, :mod:`observer.stepping`):
with v_θ = (1−θ)v_k + θv_{k+1}, v̄ = ½(v_k + v_{k+1}), ΔP the difference of the step
impulses, Δv = v_{k+1} − v_k, Δe = e⁻_{k+1} − e_k with e⁻_{k+1} the error before the step's
position projections, and Δg⁻ = W_Iᵀe⁻_{k+1},

    V_{k+1} − V_k = −h v_θᵀC̄v_θ                       (damping part, ≤ 0 iff C̄ ⪰ 0)
                    + (Wᵀv̄)ᵀΔP                         (impulse part: γ̄ of (17), twin of A3)
                    − ½ Δg⁻ᵀ P_I L_I⁻¹ P_Iᵀ Δg⁻         (position-jump part, ≤ 0)
                    − (θ − ½)(‖Δv‖²_M + ‖Δe‖²_K − (WᵀΔv)ᵀΔP)   (numerical; 0 for θ = ½)

(from M Δv = −hCv_θ − hKe_θ + WΔP and Δe = h v_θ; for θ = ½ this is the identity of
:func:`observer.observers.lyapunov_decrements`).

:func:`check_lyapunov_decrease` evaluates every part in closed form and compares them with
the realized per-step changes of V; :func:`check_convergence` checks the conclusions of
Theorem 1 (V → 0, v → 0, e → c = 0 via eqs. (19)-(21)) on the same run.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from observer.metrics import decay_rate
from proofs_checks.result import CheckResult
from proofs_checks.runs import Run

EPS = float(np.finfo(float).eps)


def decrement_parts(run: Run, a: str, b: str) -> dict[str, np.ndarray]:
    """Per-step parts of V_{k+1} − V_k between observers ``a`` and ``b`` of ``run``.

    Returns arrays of shape (N,) (entry k = step k): ``V`` (N+1,), ``total``, ``damping``,
    ``impulse``, ``numerical``, ``projection`` (realized ½‖e⁺‖²_K − ½‖e⁻‖²_K),
    ``projection_cf`` (closed form −½Δg⁻ᵀP_I L_I⁻¹P_IᵀΔg⁻, K metric, 0 unless both
    observers project), ``residual`` (total minus damping, impulse, numerical and realized
    projection: round-off), and ``roundoff`` (the per-step round-off allowance of V).
    """
    sys_ = run.system
    M, K, W = sys_.M, sys_.K, sys_.W
    Cbar = 0.5 * (sys_.C + sys_.C.T)
    A, B = run.slaves[a], run.slaves[b]
    h, th = run.h, run.theta
    v = A.u - B.u
    e = A.q - B.q
    e_pre = A.q_pre - B.q_pre
    quad = lambda X, Q: np.einsum("ki,ij,kj->k", X, Q, X)  # noqa: E731
    V = 0.5 * quad(v, M) + 0.5 * quad(e, K)
    v_th = (1 - th) * v[:-1] + th * v[1:]
    v_bar = 0.5 * (v[:-1] + v[1:])
    dv, de = v[1:] - v[:-1], e_pre[1:] - e[:-1]
    dP = A.P[1:] - B.P[1:]
    out = {"V": V, "total": np.diff(V), "damping": -h * quad(v_th, Cbar),
           "impulse": np.einsum("ki,ki->k", v_bar @ W, dP),
           "numerical": -(th - 0.5) * (quad(dv, M) + quad(de, K) - np.einsum("ki,ki->k", dv @ W, dP)),
           "projection": 0.5 * (quad(e[1:], K) - quad(e_pre[1:], K)),
           "projection_cf": np.zeros(V.size - 1)}
    if A.projected and B.projected and np.any(A.active[1:]):
        Kc = sla.cho_factor(K)
        L = W.T @ sla.cho_solve(Kc, W)
        L = 0.5 * (L + L.T)
        for k in np.flatnonzero(A.active[1:].any(axis=1)):
            I = np.flatnonzero(A.active[k + 1] & B.active[k + 1])
            if I.size:
                dg = e_pre[k + 1] @ W[:, I]
                out["projection_cf"][k] = -0.5 * dg @ sla.cho_solve(sla.cho_factor(L[np.ix_(I, I)]), dg)
    out["residual"] = out["total"] - out["damping"] - out["impulse"] - out["numerical"] - out["projection"]
    Q = max(float(np.max(np.sqrt(np.abs(quad(A.q, K))))), float(np.max(np.sqrt(np.abs(quad(B.q, K))))), 1e-300)
    U = max(float(np.max(np.sqrt(quad(A.u, M)))), float(np.max(np.sqrt(quad(B.u, M)))), 1e-300)
    size = np.sqrt(np.abs(quad(e, K))) * Q + np.sqrt(quad(v, M)) * U
    out["roundoff"] = 64 * EPS * (size[:-1] + size[1:])
    return out


def _worst(values: np.ndarray, V: np.ndarray, allowance: np.ndarray) -> tuple[float, int]:
    """max_k (values_k − allowance_k)/V_k (0/0 → 0, x/0 → inf for x > 0) and its argmax."""
    x = values - allowance
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(V > 0, x / np.where(V > 0, V, 1.0), np.where(x > 0, np.inf, 0.0))
    k = int(np.argmax(rel))
    return float(rel[k]), k


def check_lyapunov_decrease(run: Run, a: str | None = None, b: str | None = None, *,
                            tolerance: float = 1e-9, identity_tolerance: float = 1e-9,
                            impulse_tolerance: float = 1e-3) -> CheckResult:
    """dV ≤ 0, eq. (17): V between two slaves driven by the same χ never increases, part by part.

    Criteria (all per step, relative to V_k, after a round-off allowance
    64·eps·(‖e‖_K‖q‖_K + ‖v‖_M‖u‖_M)):

    * ``dV``: V_{k+1} − V_k ≤ tolerance·V_k (the claim; its margin is the check's margin
      unless another criterion is worse);
    * ``identity``: the realized change equals damping + impulse + numerical + realized
      projection part (scheme identity; fails for a scheme that is not the θ-method);
    * ``projection``: the realized projection part equals its closed form
      −½‖Δg⁻‖²_{P_I L_I⁻¹ P_Iᵀ} in the K metric (fails for a wrong projection metric);
    * ``damping_sign``, ``projection_sign``: the closed-form damping and position-jump parts
      are ≤ 0 (C̄ ⪰ 0, P_I L_I⁻¹ P_Iᵀ ⪰ 0);
    * ``impulse``: the impulse part ≤ impulse_tolerance·V_k. The discrete impulse term
      equals the monotone term of (17) only up to O(h) (the step impulse also carries the
      smooth contact force), hence the looser tolerance.

    Parameters
    ----------
    run : Run
        A replay with at least two observers of the same design.
    a, b : str, optional
        The two observers (default: the first two).

    Returns
    -------
    CheckResult
        ``margin = −max_k (V_{k+1} − V_k − allowance_k)/V_k`` (or, when another criterion fails, the worst
        failing one, with its tolerance); the witness has the largest per-step increase of V
        beyond round-off (``max_dV_beyond_roundoff``) and raw (``max_relative_increase``,
        with V and the allowance there), the worst step, every part there, and the worst
        value of every criterion (``max_identity``, ``max_projection``, ...).
    """
    name, eq = "lyapunov_decrease", "eq. (17), proof of Theorem 1"
    names = list(run.slaves)
    if a is None or b is None:
        if len(names) < 2:
            return CheckResult.not_applicable(name, "the run needs two observers", eq)
        a, b = names[0], names[1]
    p = decrement_parts(run, a, b)
    V, Vk, r = p["V"], p["V"][:-1], p["roundoff"]
    crit = {
        "dV": (_worst(p["total"], Vk, r), tolerance),
        "identity": (_worst(np.abs(p["residual"]), Vk, r), identity_tolerance),
        "projection": (_worst(np.abs(p["projection"] - p["projection_cf"]), Vk, r)
                       if run.slaves[a].projected and run.slaves[b].projected else (0.0, 0), identity_tolerance),
        "damping_sign": (_worst(p["damping"], Vk, r), identity_tolerance),
        "projection_sign": (_worst(p["projection_cf"], Vk, r), identity_tolerance),
        "impulse": (_worst(p["impulse"], Vk, r), impulse_tolerance),
    }
    # the claim dV ≤ 0 gives the margin, unless another criterion fails (then the worst one)
    failing = [c for c in crit if crit[c][0][0] > crit[c][1]]
    label = min(failing, key=lambda c: crit[c][1] - crit[c][0][0]) if failing else "dV"
    (value, k), tol = crit[label]
    inc, kinc = _worst(p["total"], Vk, np.zeros_like(Vk))
    witness = {"max_dV_beyond_roundoff": crit["dV"][0][0], "max_relative_increase": inc,
               "V_at_max_increase": float(Vk[kinc]), "roundoff_at_max_increase": float(r[kinc]),
               "max_increase_step": kinc, "max_increase_time": float(run.t[kinc]),
               "worst_criterion": label, "worst_step": k, "worst_time": float(run.t[k]), "V_at_worst": float(Vk[k]),
               "dV_at_worst": float(p["total"][k]), "damping_at_worst": float(p["damping"][k]),
               "impulse_at_worst": float(p["impulse"][k]), "projection_at_worst": float(p["projection"][k]),
               "projection_cf_at_worst": float(p["projection_cf"][k]),
               "numerical_at_worst": float(p["numerical"][k]),
               "e_at_worst": run.slaves[a].q_pre[k + 1] - run.slaves[b].q_pre[k + 1],
               "v_bar_at_worst": 0.5 * (run.slaves[a].u[k] - run.slaves[b].u[k] + run.slaves[a].u[k + 1]
                                        - run.slaves[b].u[k + 1])}
    witness.update({f"max_{c}": crit[c][0][0] for c in crit if c != "dV"})
    witness.update(V0=float(V[0]), V_end=float(V[-1]), steps=int(Vk.size), observers=[a, b],
                   position_jumps=bool(run.slaves[a].projected), metric=run.metric)
    keys = ("max_dV_beyond_roundoff", "max_relative_increase", "max_increase_time", "worst_criterion",
            "max_identity", "max_projection", "max_damping_sign", "max_impulse", "metric")
    reasons = {"dV": "V increases: dV ≤ 0 (eq. (17)) is violated",
               "identity": "the step does not satisfy the θ-scheme energy identity",
               "projection": "the position jumps are not the K-metric projection: the realized "
                             "jump part differs from −½‖Δg⁻‖²_{P L⁻¹ Pᵀ}",
               "damping_sign": "the damping part −h v̄ᵀC̄v̄ is positive: C̄ is not positive semi-definite",
               "projection_sign": "the jump part is positive: P_I L_I⁻¹ P_Iᵀ is not PSD",
               "impulse": "the impulse part is positive beyond the O(h) slack: impact map not monotone (A3)"}
    reason = "; ".join(reasons[c] for c in failing)
    if not run.slaves[a].projected:
        reason = (reason + "; " if reason else "") + "observers without position jumps (K not ≻ 0): " \
                 "no jump part"
    return CheckResult.from_margin(name, -value, tol, witness, eq, keys, reason)


def check_convergence(run: Run, a: str | None = None, b: str | None = None, *, rho: float = 1e-3,
                      window: float = 0.1) -> CheckResult:
    """Theorem 1: V → 0 between two slaves driven by the same χ; v → 0 and e → c = 0.

    Evidence on a finite run (the proof's steps after eq. (17)):

    * V decays: ``decades = log10(V_0/V_end)`` must reach ``log10(1/rho)``; the fitted
      exponential decay rate of V (:func:`observer.metrics.decay_rate`) must be positive;
    * eq. (20): the dissipated ``Σ h v_θᵀC̄v_θ`` is finite and at most V_0 − V_end plus the
      positive impulse parts (reported);
    * v → 0 and e → c: the kinetic and potential parts of V at the end, and the drift of e
      over the last ``window`` fraction of the run;
    * eq. (21), c = 0: with c the mean error over the final window and Λ̃ the averaged
      impulse difference there, the residual of ``Kc = WΛ̃`` and ``W_Iᵀc`` for the contacts
      closed in the window (the geometric constraints force W_Iᵀc = 0, then L_I Λ̃_I = 0
      gives c = 0).

    Not applicable when K is not positive definite or C̄ is only semi-definite (Theorem 1's
    hypotheses); an indefinite C̄ violates them and is checked (V typically grows).

    Returns
    -------
    CheckResult
        ``margin = decades − log10(1/rho)`` (tolerance 0); a non-positive rate fails.
    """
    name, eq = "convergence", "Theorem 1; eqs. (18)-(21)"
    sys_ = run.system
    Cbar = 0.5 * (sys_.C + sys_.C.T)
    wK = np.linalg.eigvalsh(0.5 * (sys_.K + sys_.K.T))
    if wK[-1] <= 0 or wK[0] <= 1e-12 * wK[-1]:
        return CheckResult.not_applicable(name, f"K is not positive definite (λ_min = {wK[0]:.3g}): V is not "
                                          "a norm of the error; Theorem 1 needs K ≻ 0", eq)
    wC = np.linalg.eigvalsh(Cbar)
    if wC[-1] <= 0 or abs(wC[0]) <= 1e-12 * wC[-1]:
        return CheckResult.not_applicable(name, f"C̄ is only positive semi-definite (λ_min = {wC[0]:.3g}): "
                                          "Theorem 1 needs C̄ ≻ 0 (an indefinite C̄ is checked and fails)", eq)
    names = list(run.slaves)
    if a is None or b is None:
        if len(names) < 2:
            return CheckResult.not_applicable(name, "the run needs two observers", eq)
        a, b = names[0], names[1]
    A, B = run.slaves[a], run.slaves[b]
    M, K, W = sys_.M, sys_.K, sys_.W
    t, h, th = run.t, run.h, run.theta
    quad = lambda X, Q: np.einsum("ki,ij,kj->k", X, Q, X)  # noqa: E731
    v, e = A.u - B.u, A.q - B.q
    T, U = 0.5 * quad(v, M), 0.5 * quad(e, K)
    V = T + U
    V0, Vend = float(V[0]), float(V[-1])
    if V0 <= 0:
        return CheckResult.not_applicable(name, "the two observers start in the same state (V0 = 0)", eq)
    decades = np.log10(V0 / Vend) if Vend > 0 else np.inf
    rate = decay_rate(t, V)
    v_th = (1 - th) * v[:-1] + th * v[1:]
    dissipated = float(np.sum(h * quad(v_th, Cbar)))
    impulse = np.einsum("ki,ki->k", (0.5 * (v[:-1] + v[1:])) @ W, A.P[1:] - B.P[1:])
    k0 = int((1 - window) * (t.size - 1))
    c = e[k0:].mean(axis=0)
    drift = float(np.max(np.sqrt(quad(e[k0:] - e[-1], K))) / np.sqrt(2 * V0))
    dt = t[-1] - t[k0]
    Lam = (A.P[k0 + 1:] - B.P[k0 + 1:]).sum(axis=0) / dt
    closed = np.flatnonzero(A.active[k0 + 1:].any(axis=0))
    Kc = K @ c
    balance = float(np.linalg.norm(Kc - W @ Lam) / max(np.linalg.norm(Kc) + np.linalg.norm(W @ Lam), 1e-300))
    below = np.flatnonzero(V > rho * V0)
    witness = {"decades": float(decades), "required_decades": float(np.log10(1 / rho)), "decay_rate": rate,
               "V0": V0, "V_end": Vend, "kinetic_end_rel": float(T[-1] / V0), "potential_end_rel": float(U[-1] / V0),
               "dissipated_eq20": dissipated, "V0_minus_Vend": V0 - Vend,
               "positive_impulse_sum": float(np.sum(np.maximum(impulse, 0.0))),
               "e_drift_last_window": drift, "c": c, "c_K_norm_rel": float(np.sqrt(c @ K @ c) / np.sqrt(2 * V0)),
               "Lambda_tilde": Lam, "eq21_balance_residual": balance, "closed_in_window": closed.tolist(),
               "WIt_c": c @ W[:, closed] if closed.size else np.zeros(0),
               "time_to_rho": float(t[below[-1] + 1] if below.size and below[-1] + 1 < t.size else
                                    (np.inf if below.size else 0.0)),
               "horizon": float(t[-1]), "observers": [a, b]}
    keys = ("decades", "decay_rate", "V_end", "kinetic_end_rel", "potential_end_rel", "c_K_norm_rel",
            "eq21_balance_residual", "horizon")
    reason = ""
    margin = float(decades - np.log10(1 / rho))
    if not (rate > 0):
        reason = f"V does not decay (fitted rate {rate:.3g} 1/s)"
        margin = min(margin, -1.0)
    elif margin < 0:
        reason = (f"V fell only {decades:.2f} decades in {t[-1]:.3g} s; " +
                  ("v → 0 but e → c ≠ 0 (c balanced by the averaged constraint force, eq. (21))"
                   if T[-1] < 1e-3 * U[-1] else "v has not decayed (a longer horizon may be needed)"))
    return CheckResult.from_margin(name, margin, 0.0, witness, eq, keys, reason)
