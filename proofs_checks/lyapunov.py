"""Eq. (17), dV ≤ 0 along the error of every pair the toolkit runs, and Theorem 1 (V → 0).

Lyapunov function (16) with the ½ on both terms (docs/theory/index.md §2 erratum 2)::

    V(e, v) = ½ vᵀMv + ½ eᵀKe,    e = q₁ − q₂,  v = u₁ − u₂.

Continuous claim (17)::

    dV = −‖v‖²_C̄ dt − ½‖g₁⁻ − g₂⁻‖²_{P_I L_I⁻¹ P_Iᵀ} dη + (γ̄₁ − γ̄₂)ᵀ(Λ₁ − Λ₂) dη ≤ 0.

Pairs (:func:`run_pairs`): the two observers with position jumps (``jump pair``), the two
without (``no-jump pair``), and the master with the observer of each design
(``master–jump``, ``master–no-jump``: the error V that :func:`observer.simulate` and the
report plot, χ from the master).

Discrete identity (Moreau–Jean θ-scheme, :mod:`observer.stepping`). With v_θ = (1−θ)v_k +
θv_{k+1}, v̄ = ½(v_k + v_{k+1}), ΔP the difference of the step impulses, Δv = v_{k+1} − v_k,
Δe = e⁻_{k+1} − e_k (e⁻_{k+1}: before the step's position projections), from
M Δv = −hCv_θ − hKe_θ + WΔP and Δe = h v_θ::

    V_{k+1} − V_k = −h v_θᵀC̄v_θ                        damping     ≤ 0 iff C̄ ⪰ 0
                    + (Wᵀv̄)ᵀΔP                          impulse     no sign in discrete time
                    + ½‖e_{k+1}‖²_K − ½‖e⁻_{k+1}‖²_K       projection
                    − (θ − ½)(‖Δv‖²_M + ‖Δe‖²_K − (WᵀΔv)ᵀΔP)   numerical (0 for θ = ½)

exact up to round-off (``residual``). Projection part in closed form, on the closed set I
with L_I = W_IᵀK⁻¹W_I, Δg⁻ = W_Iᵀe⁻_{k+1}, and r the gap on I of a member that is *not*
projected (the plain master; 0 for a projected one)::

    projection = −½‖Δg⁻‖²_{L_I⁻¹}  (jump part of (17), ≤ 0)  +  ½‖Δr‖²_{L_I⁻¹}  (unprojected gap, ≥ 0)

the second term is nonzero only for the master–jump pair: the plain master penetrates
(Proposition 1's mismatched pair), a discretisation effect that vanishes as h → 0.

Impulse part. On the closed set A, with γ_{k+1} = γ_free + ĜP, Ĝ = W_AᵀÂ⁻¹W_A,
Â = M + hθC + h²θ²K (:mod:`observer.stepping`), E = diag e_A, D = (I − E)(I + E)⁻¹ and
δ = Δγ_free − Δγ_k = W_Aᵀ(Δu_free − v_k) = −W_AᵀÂ⁻¹(hCv_k + hK(e_k + hθv_k)) = O(h).
Newton: both members solve ``0 ≤ y = γ_{k+1} + Eγ_k ⊥ P ≥ 0``, and exactly::

    (Wᵀv̄)ᵀΔP = ½ΔPᵀ(I + D)Δy        complementarity  ≤ 0  (ΔP_iΔy_i = −(y₁P₂ + y₂P₁)_i)
              − ½ΔPᵀDĜΔP            Delassus         ≤ 0 when e is global (sym(DĜ) ⪰ 0)
              − ½ΔPᵀDδ              slack            no sign, O(h); 0 for e = 1

Poisson on several contacts: P is Glocker's map with Ĝ on γ̃ = (γ_free + Eγ_k)/(1+E)
(:func:`observer.impact.poisson_step`); with Glocker's mean velocity γ̄_G = γ̃ + ĜP/2,
exactly ``(Wᵀv̄)ᵀΔP = ΔPᵀΔγ̄_G − ½ΔPᵀDδ``: the first term is the impact map's monotonicity
term (A3; reported as ``impulse_complementarity``, Delassus part 0), the second the same
slack as Newton's. (``impulse_target`` is kept, identically 0, for the columns' stability.)

so in discrete time the impulse term has **no sign**: the slack −(1−e)/(2(1+e))ΔPᵀδ of the
impact law on ``γ_{k+1} + eγ_k`` vanishes only as h → 0 (δ = O(h)) or for e = 1.

:func:`check_lyapunov_decrease` evaluates every part, checks the identity and the signs,
attributes a positive ΔV to the part that caused it, and fits the order in h of the
positive slack by re-running the case at a few step sizes; :func:`check_convergence`
checks the conclusions of Theorem 1 (V → 0, v → 0, e → c = 0 via eqs. (19)-(21)).

Round-off allowance (:func:`roundoff_allowance`). The identity residual of computed states
is ``v_θᵀΔr_u + ē_θᵀKΔr_q`` (θ = ½) with r_u, r_q the residuals of the two step equations;
floating point leaves ``|r_u| ≲ γ κ(Â)(|M||u| + h|C||u| + h|K||q| + h|f̄| + |W||P|)``
(u_{k+1} is formed with the explicit Â⁻¹, hence κ(Â)) and ``|r_q| ≲ γ(|q_k| + |q⁻_{k+1}| +
h|u|)`` componentwise, the projection adds ``γ(|q⁻| + κ(K)|K⁻¹W_I||Σ|)`` (K⁻¹W by a
Cholesky solve), and evaluating V_k = ½vᵀMv + ½eᵀKe costs ``γ(|v|ᵀ|M||v| + |e|ᵀ|K||e|)``.
This last term is what grows with cond(K): for e along a soft mode of a stiff K,
|e|ᵀ|K||e| ≈ cond(K)·eᵀKe. The allowance of step k is the sum of these bounds contracted
with |v_θ|, |Kē_θ| and |Ke_{k+1}|, with ``γ = ROUNDOFF_FACTOR·(n + 2)·eps`` (n + 2 roundings
per inner product, Higham's γ_n, times a safety factor). The float criteria (identity,
closed-form projection, signs) compare the part, minus this allowance, with ``tolerance·V_k``.

The verdict on dV itself does not rest on this allowance: every step that may rise (its
computed ΔV is not below −:func:`evaluation_bound`, a rigorous bound of evaluating ΔV) is
recomputed in exact rational arithmetic on the float states (:mod:`proofs_checks.exact_step`),
where the identity above holds with the states' exact scheme residual as one more term, and
is classified as round-off, discrete slack or violation (:func:`classify_steps`,
:func:`check_lyapunov_decrease`). The allowance only caps what the exact residual may
explain (a larger residual is a wrong scheme or projection, not round-off).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from observer.metrics import decay_rate
from proofs_checks.assumptions import exact_class, not_definite_reason
from proofs_checks.exact_step import ExactSteps, StepVerdict, classify
from proofs_checks.result import CheckResult
from proofs_checks.runs import Run, Trajectory, rerun

EPS = float(np.finfo(float).eps)

ROUNDOFF_FACTOR = 4.0
"""Safety factor of the round-off allowance over γ_{n+2} = (n + 2)·eps (see module docstring)."""

MAX_TARGET_STEPS = 40
"""Poisson steps on several contacts split per pair (the worst positive impulse terms; a
quarter of them in the re-runs of the order fit): each needs Glocker's target of both members."""

MAX_EXACT_STEPS = 300
"""Steps per pair recomputed in exact arithmetic (:mod:`proofs_checks.exact_step`): the
possibly rising ones with the largest float excess over round-off and slack first; the
others are decided by the float bounds (:func:`evaluation_bound`, :func:`roundoff_allowance`)."""

PARTS = ("damping", "impulse", "projection", "numerical")
"""The parts of ΔV (their sum plus the round-off ``residual`` is ΔV)."""

SUBPARTS = ("impulse_complementarity", "impulse_delassus", "impulse_slack", "impulse_target",
            "projection_jump", "projection_unprojected_gap")
"""The signed pieces of the impulse and projection parts (see module docstring)."""

CAUSES = {
    "impulse_slack": "impulse term of the discrete impact law positive: {x}·V at step {k} (t = {t}) in the "
                     "{pair} (ΔV beyond round-off {dV}·V); its slack −½ΔPᵀDδ = {piece}·V (smooth velocity change δ = O(h) within the step, "
                     "D = (1−e)/(1+e)) has no sign in discrete time",
    "impulse_target": "impulse term of the discrete Poisson step positive: {x}·V at step {k} (t = {t}) in the "
                      "{pair} (ΔV beyond round-off {dV}·V); its target term ΔPᵀ(I+E)⁻¹Δr = {piece}·V "
                      "(Glocker's target in the step's LCP, several contacts) is positive",
    "impulse_delassus": "impulse term positive: {x}·V at step {k} (t = {t}) in the {pair}; its Delassus part "
                        "−½ΔPᵀDĜΔP > 0 (per-contact restitution: sym(DĜ) is not positive semi-definite)",
    "impulse_complementarity": "impulse term positive: {x}·V at step {k} (t = {t}) in the {pair}; the step "
                               "impulses violate complementarity 0 ≤ γ_{{k+1}} − τ ⊥ P ≥ 0",
    "projection_unprojected_gap": "projection term positive: {x}·V at step {k} (t = {t}) in the {pair}; the "
                                  "unprojected member (plain master) is not on its closed contacts "
                                  "(½‖Δr‖²_{{L⁻¹}}, Proposition 1's mismatched pair)",
    "projection_jump": "position-jump part positive: {x}·V at step {k} (t = {t}) in the {pair}: "
                       "P_I L_I⁻¹ P_Iᵀ is not PSD",
    "damping": "damping term positive: {x}·V at step {k} (t = {t}) in the {pair}: C̄ is not positive "
               "semi-definite",
    "numerical": "θ-numerical term positive: {x}·V at step {k} (t = {t}) in the {pair} (θ ≠ ½)",
    "residual": "the step does not satisfy the θ-scheme identity: residual {x}·V at step {k} (t = {t}) in "
                "the {pair}",
}
"""Reason for a positive ΔV, by the part that caused it (the largest positive one there)."""


def run_pairs(run: Run) -> list[tuple[str, str, str]]:
    """The pairs ``(label, a, b)`` (e = q_a − q_b) of a run: the jump pair, the no-jump pair and
    the master with the first observer of each design (``b = "master"``)."""
    names = list(run.slaves)
    jump = [n for n in names if run.slaves[n].projected]
    nojump = [n for n in names if not run.slaves[n].projected]
    out = []
    if len(jump) >= 2:
        out.append(("jump pair", jump[0], jump[1]))
    if len(nojump) >= 2:
        out.append(("no-jump pair", nojump[0], nojump[1]))
    if jump:
        out.append(("master–jump", jump[0], "master"))
    if nojump:
        out.append(("master–no-jump", nojump[0], "master"))
    return out


def _traj(run: Run, name: str) -> Trajectory:
    return run.master if name == "master" else run.slaves[name]


def _quad(X: np.ndarray, Q: np.ndarray) -> np.ndarray:
    return np.einsum("ki,ki->k", X @ Q.T, X)


def _iteration_matrix(run: Run) -> np.ndarray:
    """Â = M + hθC + h²θ²K, recomputed from the system (not the stepper's cached factors)."""
    s, h, th = run.system, run.h, run.theta
    return s.M + h * th * s.C + (h * th) ** 2 * s.K


def roundoff_allowance(run: Run, A: Trajectory, B: Trajectory) -> np.ndarray:
    """Per-step round-off allowance (energy units, shape (N,)) of ΔV and of its parts.

    The bound of the module docstring: ``γ·[|v_θ|ᵀ Σ_X ρ_u,X + |Kē_θ|ᵀ Σ_X ρ_q,X +
    |Ke_{k+1}|ᵀ Σ_X ρ_P,X + E_V(k) + E_V(k+1)]`` with γ = ROUNDOFF_FACTOR·(n+2)·eps,
    ρ_u = κ(Â)(|M|(|u_k| + |u_{k+1}|) + h|C|(|u_k| + |u_{k+1}|) + h|K|(|q_k| + |q⁻_{k+1}|) + h|f̄| + |W||P|),
    ρ_q = |q_k| + |q⁻_{k+1}| + h(|u_k| + |u_{k+1}|), ρ_P = |q⁻_{k+1}| + |q_{k+1}| +
    κ(K)|K⁻¹W|(|Σ| + (|W|ᵀ|q⁻| + |ν|)/diag L) on the closed contacts (projected members only:
    the rounding of the gap and of the multiplier) and E_V = |v|ᵀ|M||v| + |e|ᵀ|K||e| (at k, k+1
    and for e⁻_{k+1}).
    """
    s, h, th, t = run.system, run.h, run.theta, run.t
    M, C, K, W = s.M, s.C, s.K, s.W
    n = s.n
    aM, aC, aK, aW = np.abs(M), np.abs(C), np.abs(K), np.abs(W)
    kA = float(np.linalg.cond(_iteration_matrix(run)))
    f = s.f(t)
    af = np.abs((1 - th) * f[:-1] + th * f[1:])
    projected = A.projected or B.projected
    if projected:
        kK = float(np.linalg.cond(K))
        KinvW = np.linalg.solve(K, W)
        aKinvW = np.abs(KinvW)
        Ldiag = np.abs(np.einsum("ij,ij->j", W, KinvW))
        anu = np.abs(s.nu(t))[1:]

    def rho(X: Trajectory) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        au0, au1 = np.abs(X.u[:-1]), np.abs(X.u[1:])
        aq0, aq1 = np.abs(X.q[:-1]), np.abs(X.q_pre[1:])
        ru = kA * ((au0 + au1) @ aM.T + h * (au0 + au1) @ aC.T + h * (aq0 + aq1) @ aK.T
                   + h * af + np.abs(X.P[1:]) @ aW.T)
        rq = aq0 + aq1 + h * (au0 + au1)
        rp = np.zeros_like(rq)
        if X.projected and projected:
            closed = X.active[1:]
            g_terms = np.where(closed, (aq1 @ aW + anu) / np.where(Ldiag > 0, Ldiag, 1.0), 0.0)
            rp = aq1 + np.abs(X.q[1:]) + kK * ((np.abs(X.sigma[1:]) + g_terms) @ aKinvW.T)
        return ru, rq, rp

    (ruA, rqA, rpA), (ruB, rqB, rpB) = rho(A), rho(B)
    v, e, e_pre = A.u - B.u, A.q - B.q, A.q_pre - B.q_pre
    v_th = (1 - th) * v[:-1] + th * v[1:]
    Ke_th = np.abs(((1 - th) * e[:-1] + th * e_pre[1:]) @ K.T)
    EV = _quad(np.abs(v), aM) + _quad(np.abs(e), aK)
    EV_pre = _quad(np.abs(e_pre[1:]), aK)
    total = (np.einsum("ki,ki->k", np.abs(v_th), ruA + ruB) + np.einsum("ki,ki->k", Ke_th, rqA + rqB)
             + np.einsum("ki,ki->k", np.abs(e[1:] @ K.T), rpA + rpB) + EV[:-1] + EV[1:] + EV_pre)
    return ROUNDOFF_FACTOR * (n + 2) * EPS * total


def _projection_parts(run: Run, A: Trajectory, B: Trajectory, out: dict) -> None:
    """Closed-form projection part (jump part and unprojected gap), in the K metric (the steps
    grouped by their closed set I = closed(a) ∩ closed(b), one factorization of L_I each)."""
    s = run.system
    K, W = s.K, s.W
    L = W.T @ np.linalg.solve(K, W)
    L = 0.5 * (L + L.T)
    nu = s.nu(run.t)
    both = A.active[1:] & B.active[1:]
    groups: dict[bytes, list[int]] = {}
    for k in np.flatnonzero(both.any(axis=1)):
        groups.setdefault(both[k].tobytes(), []).append(int(k))
    for ks in groups.values():
        ks = np.asarray(ks)
        I = np.flatnonzero(both[ks[0]])
        gA = A.q_pre[ks + 1] @ W[:, I] + nu[ks + 1][:, I]
        gB = B.q_pre[ks + 1] @ W[:, I] + nu[ks + 1][:, I]
        dg = gA - gB
        dr = (0.0 * gA if A.projected else gA) - (0.0 * gB if B.projected else gB)
        LI = L[np.ix_(I, I)]
        out["projection_jump"][ks] = -0.5 * np.einsum("ki,ki->k", dg, np.linalg.solve(LI, dg.T).T)
        out["projection_unprojected_gap"][ks] = 0.5 * np.einsum("ki,ki->k", dr, np.linalg.solve(LI, dr.T).T)
    out["projection_cf"] = out["projection_jump"] + out["projection_unprojected_gap"]


def _impulse_parts(run: Run, A: Trajectory, B: Trajectory, out: dict, examine: np.ndarray | None) -> None:
    """The exact split of the impulse part (module docstring), per closed set.

    Every part in closed form from the run's states and impulses (Newton, and Poisson on
    one contact, which is Newton's step; Poisson on several contacts through Glocker's mean
    velocity). ``examine`` is accepted for compatibility and no longer needed.
    """
    s, h, th = run.system, run.h, run.theta
    C, K, W = s.C, s.K, s.W
    lu = sla.lu_factor(_iteration_matrix(run))
    e_all = np.asarray(run.stepper.law.restitution, dtype=float)
    newton = run.stepper.law.law == "newton"
    v, e = A.u - B.u, A.q - B.q
    same = np.all(A.active[1:] == B.active[1:], axis=1)
    closed = np.flatnonzero(A.active[1:].any(axis=1) & same)
    out["impulse_set_mismatch"] = np.where(same, 0.0, out["impulse"])
    for key in ("impulse_complementarity", "impulse_delassus", "impulse_slack", "impulse_target"):
        out[key][~same] = np.nan
    groups: dict[bytes, list[int]] = {}
    for k in closed:
        groups.setdefault(A.active[k + 1].tobytes(), []).append(int(k))
    for ks in groups.values():
        ks = np.asarray(ks)
        act = np.flatnonzero(A.active[ks[0] + 1])
        WA = W[:, act]
        E = e_all[act]
        D = (1.0 - E) / (1.0 + E)
        G = WA.T @ sla.lu_solve(lu, WA)
        dP = A.P[ks + 1][:, act] - B.P[ks + 1][:, act]
        dg0, dg1 = v[ks] @ WA, v[ks + 1] @ WA
        delta = -(sla.lu_solve(lu, (h * v[ks] @ C.T + h * (e[ks] + h * th * v[ks]) @ K.T).T).T) @ WA
        out["impulse_delassus"][ks] = -0.5 * np.einsum("ki,ki->k", dP * D, dP @ G.T)
        out["impulse_slack"][ks] = -0.5 * np.einsum("ki,ki->k", dP * D, delta)
        if not newton and act.size > 1:
            # Glocker's map on γ̃ = (γ_free + Eγ_k)/(1+E) with Ĝ (observer.impact.poisson_step):
            # ΔPᵀΔγ̄ = ΔPᵀΔγ̄_G − ½ΔPᵀDδ with γ̄_G = γ̃ + ĜP/2, Δγ̃ = Δγ_k + δ/(1+E)
            dgbar_G = dg0 + delta / (1.0 + E) + 0.5 * dP @ G.T
            out["impulse_complementarity"][ks] = np.einsum("ki,ki->k", dP, dgbar_G)
            out["impulse_delassus"][ks] = 0.0
            out["impulse_target"][ks] = 0.0
            continue
        dy = dg1 + E * dg0
        out["impulse_complementarity"][ks] = 0.5 * np.einsum("ki,ki->k", dP * (1.0 + D), dy)
        out["impulse_target"][ks] = 0.0


def decrement_parts(run: Run, a: str, b: str, examine: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Per-step parts of V_{k+1} − V_k between members ``a`` and ``b`` of ``run`` (``"master"`` allowed).

    Returns arrays of shape (N,) (entry k = step k) unless noted: ``V`` (N+1,), ``total``,
    ``damping``, ``impulse``, ``numerical``, ``projection`` (realized ½‖e⁺‖²_K − ½‖e⁻‖²_K),
    ``projection_cf`` (its closed form) = ``projection_jump`` + ``projection_unprojected_gap``,
    the impulse split ``impulse_complementarity``, ``impulse_delassus``, ``impulse_slack``,
    ``impulse_target`` (NaN where not evaluated: see :func:`_impulse_parts`; ``examine``
    lists the Poisson multi-contact steps to split), ``impulse_set_mismatch`` (the impulse
    part of steps where a and b used different closed sets), ``residual`` (ΔV minus the four
    parts: round-off) and ``roundoff`` (:func:`roundoff_allowance`).
    """
    s = run.system
    M, K, W = s.M, s.K, s.W
    Cbar = 0.5 * (s.C + s.C.T)
    A, B = _traj(run, a), _traj(run, b)
    h, th = run.h, run.theta
    v, e, e_pre = A.u - B.u, A.q - B.q, A.q_pre - B.q_pre
    V = 0.5 * _quad(v, M) + 0.5 * _quad(e, K)
    v_th = (1 - th) * v[:-1] + th * v[1:]
    v_bar = 0.5 * (v[:-1] + v[1:])
    dv, de = v[1:] - v[:-1], e_pre[1:] - e[:-1]
    dP = A.P[1:] - B.P[1:]
    N = V.size - 1
    out = {"V": V, "total": np.diff(V), "damping": -h * _quad(v_th, Cbar),
           "impulse": np.einsum("ki,ki->k", v_bar @ W, dP),
           "numerical": -(th - 0.5) * (_quad(dv, M) + _quad(de, K) - np.einsum("ki,ki->k", dv @ W, dP)),
           "projection": 0.5 * (_quad(e[1:], K) - _quad(e_pre[1:], K))}
    for key in SUBPARTS:
        out[key] = np.zeros(N)
    if A.projected or B.projected:
        _projection_parts(run, A, B, out)
    else:
        out["projection_cf"] = np.zeros(N)
    _impulse_parts(run, A, B, out, examine)
    out["residual"] = out["total"] - out["damping"] - out["impulse"] - out["numerical"] - out["projection"]
    out["roundoff"] = roundoff_allowance(run, A, B)
    return out


def _relative(values: np.ndarray, V: np.ndarray, allowance: np.ndarray) -> np.ndarray:
    """(values − allowance)/V per step (x/0 → ±inf, 0/0 → 0; NaN values → −inf)."""
    x = np.where(np.isnan(values), -np.inf, values - allowance)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(V > 0, x / np.where(V > 0, V, 1.0), np.where(x > 0, np.inf, np.where(x < 0, -np.inf, 0.0)))


def _worst(values: np.ndarray, V: np.ndarray, allowance: np.ndarray) -> tuple[float, int]:
    """max_k (values_k − allowance_k)/V_k and its argmax (see :func:`_relative`)."""
    rel = _relative(values, V, allowance)
    k = int(np.argmax(rel))
    return float(rel[k]), k


def _pair_summary(run: Run, label: str, a: str, b: str) -> dict:
    """Parts of one pair, its criteria and, for a positive ΔV, the part that caused it."""
    p = decrement_parts(run, a, b)
    Vk, r = p["V"][:-1], p["roundoff"]
    # Poisson steps on several contacts: split the impulse term where it is positive
    pos = np.flatnonzero(_relative(p["impulse"], Vk, r) > 0)
    if pos.size and np.any(np.isnan(p["impulse_target"][pos])):
        worst = pos[np.argsort(-_relative(p["impulse"], Vk, r)[pos])[:MAX_TARGET_STEPS]]
        p = decrement_parts(run, a, b, examine=worst)
    A, B = _traj(run, a), _traj(run, b)
    crit = {"dV": _worst(p["total"] - p["projection_unprojected_gap"], Vk, r),
            "identity": _worst(np.abs(p["residual"]), Vk, r),
            "projection": _worst(np.abs(p["projection"] - p["projection_cf"]), Vk, r)
            if (A.projected or B.projected) else (-np.inf, 0),
            "damping_sign": _worst(p["damping"], Vk, r),
            "projection_sign": _worst(p["projection_jump"], Vk, r)}
    worst_parts = {key: _worst(p[key], Vk, np.zeros_like(Vk))[0]
                   for key in PARTS + SUBPARTS + ("residual",)}
    k = crit["dV"][1]
    cause = None
    if crit["dV"][0] > 0:
        cand = {c: p[c][k] for c in ("damping", "numerical", "residual") + SUBPARTS
                if not np.isnan(p[c][k])}
        cause = max(cand, key=cand.get)
        if cand[cause] <= 0:
            cause = None
    return {"label": label, "a": a, "b": b, "parts": p, "crit": crit, "worst_parts": worst_parts,
            "step": k, "cause": cause}


SLACKS = ("impulse_slack", "impulse_target", "projection_unprojected_gap")
"""The pieces of ΔV that can be positive for a correct scheme (discretisation slacks)."""


def slacks_of(parts: dict) -> dict[str, float]:
    """Worst positive value of each slack piece (:data:`SLACKS`) relative to V_k, beyond the
    round-off allowance (0 when never positive)."""
    Vk, r = parts["V"][:-1], parts["roundoff"]
    return {key: max(_worst(parts[key], Vk, r)[0], 0.0) for key in SLACKS}


def positive_slack(run: Run) -> dict[str, float]:
    """:func:`slacks_of` maximized over the pairs of ``run`` (:func:`run_pairs`): the slacks
    whose order in h :func:`check_lyapunov_decrease` fits."""
    out = dict.fromkeys(SLACKS, 0.0)
    for label, a, b in run_pairs(run):
        p = decrement_parts(run, a, b)
        pos = np.flatnonzero(_relative(p["impulse"], p["V"][:-1], p["roundoff"]) > 0)
        if pos.size and np.any(np.isnan(p["impulse_target"][pos])):
            rel = _relative(p["impulse"], p["V"][:-1], p["roundoff"])
            p = decrement_parts(run, a, b, examine=pos[np.argsort(-rel[pos])[:MAX_TARGET_STEPS // 4]])
        for key, val in slacks_of(p).items():
            out[key] = max(out[key], val)
    return out


def fit_order(hs: np.ndarray, values: np.ndarray) -> float:
    """Least-squares slope of log(values) against log(h) over the positive values (NaN if < 2)."""
    hs, values = np.asarray(hs, float), np.asarray(values, float)
    ok = (values > 0) & np.isfinite(values)
    if ok.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(hs[ok]), np.log(values[ok]), 1)[0])


def slack_order(run: Run, base: dict[str, float], factors: tuple[float, ...]) -> dict:
    """Re-run the case at ``h·factors`` and fit the order p of each positive slack, ``slack ∝ h^p``."""
    hs = [run.h * f for f in factors]
    rows = []
    for f, hh in zip(factors, hs):
        rows.append(base if f == 1 else positive_slack(rerun(run, hh)))
    out: dict = {"h": np.array(hs)}
    for key in base:
        vals = np.array([row[key] for row in rows])
        out[f"{key}_slack"] = vals
        out[f"{key}_order"] = fit_order(np.array(hs), vals) if base[key] > 0 else float("nan")
    return out


def evaluation_bound(run: Run, A: Trajectory, B: Trajectory) -> np.ndarray:
    """Rigorous bound (energy units, shape (N,)) of |fl(V_{k+1} − V_k) − (V_{k+1} − V_k)|, the
    error of evaluating ΔV in floating point from the float states.

    Each V = ½vᵀMv + ½eᵀKe is evaluated as ½Σ_k x_k(Qx)_k, two nested inner products of
    length n, so (Higham, *Accuracy and Stability of Numerical Algorithms*, 2nd ed., §3.1, any
    summation order) its computed value is within ``γ_{2n+2}·½(|v|ᵀ|M||v| + |e|ᵀ|K||e|)`` of
    the exact one, γ_j = ju/(1 − ju), u = eps/2; the difference of two such values adds one
    rounding; γ_{n²+4} ≥ γ_{2n+3} covers it with room. The bound returned is
    ``γ_{n²+4}·(E_k + E_{k+1})`` with E = |v|ᵀ|M||v| + |e|ᵀ|K||e| (the dropped ½ covers the
    subtraction and the rounding of the bound itself). A step whose computed ΔV is below
    −bound decreases V exactly; one whose computed ΔV is within ±bound rises by at most
    2·bound.
    """
    s = run.system
    n = s.n
    v, e = A.u - B.u, A.q - B.q
    E = _quad(np.abs(v), np.abs(s.M)) + _quad(np.abs(e), np.abs(s.K))
    j = n * n + 4
    gamma = j * (EPS / 2) / (1 - j * (EPS / 2))
    return gamma * (E[:-1] + E[1:])


EXACT_CAUSES = {"damping": "damping", "numerical": "numerical", "compl_sign": "impulse_complementarity",
                "delassus": "impulse_delassus", "projection_jump": "projection_jump",
                "impulse_unsplit": "impulse_complementarity", "roundoff": "residual"}
"""Sign part of :mod:`proofs_checks.exact_step` → the float part named in :data:`CAUSES`."""


def _float_cause(p: dict, k: int, exclude: tuple = ()) -> str | None:
    """The largest positive part at step k (float parts, but ``exclude``), None when none is positive."""
    cand = {c: p[c][k] for c in ("damping", "numerical", "residual") + SUBPARTS
            if c not in exclude and not np.isnan(p[c][k])}
    if not cand:
        return None
    cause = max(cand, key=cand.get)
    return cause if cand[cause] > 0 else None


def _rel(x: float, V: float) -> float:
    """x/V with x/0 → ±inf and 0/0 → 0."""
    if V > 0:
        return x / V
    return np.inf if x > 0 else -np.inf if x < 0 else 0.0


def classify_steps(run: Run, s: dict, exact: ExactSteps | None, max_exact: int = MAX_EXACT_STEPS) -> dict:
    """Three-valued verdict of every step of one pair (``s`` from :func:`_pair_summary`).

    A step *rises* when ΔV − (unprojected gap, not counted) > 0. It is explained by
    **round-off** when the rise is at most the step's round-off, by the **discrete slack**
    when at most round-off plus the positive impulse slack (−½ΔPᵀDδ, Poisson target), and is
    **violated** otherwise. Decided, per step:

    * computed ΔV < −:func:`evaluation_bound`: no rise, exactly;
    * the other steps in exact rational arithmetic on the float states
      (:class:`proofs_checks.exact_step.ExactSteps`, :func:`proofs_checks.exact_step.classify`:
      the round-off is the states' exact scheme residual, accepted up to the a priori
      :func:`roundoff_allowance`), at most ``max_exact`` of them, the largest float excess
      first;
    * the rest (beyond the budget, or ``exact`` None) by the float parts: round-off if the
      computed rise is at most :func:`roundoff_allowance` + :func:`evaluation_bound`, slack if
      at most that plus the positive float slack.

    Returns
    -------
    dict
        ``unexplained`` (shape (N,), the rise beyond round-off and slack relative to V_k:
        > 0 is a violation), ``kind`` (per step: "none", "roundoff", "slack", "violated"),
        ``exact`` (bool per step), ``verdicts`` ({k: StepVerdict} of the exact steps),
        ``worst`` (argmax of ``unexplained``), ``cause`` (the part behind the worst step when
        it is violated, a key of :data:`CAUSES`), ``slack_step`` (the step with the largest
        slack-explained rise, or -1).
    """
    p = s["parts"]
    A, B = _traj(run, s["a"]), _traj(run, s["b"])
    Vk = p["V"][:-1]
    N = Vk.size
    bound = evaluation_bound(run, A, B) if hasattr(run, "system") else np.zeros(N)   # hand-built parts: 0
    gap = p["projection_unprojected_gap"]
    rise = p["total"] - gap
    slack = np.nan_to_num(p["impulse_slack"]) + np.nan_to_num(p["impulse_target"])
    allow = p["roundoff"] + bound
    unexp_abs = rise - allow - np.maximum(slack, 0.0)
    kind = np.full(N, "none", dtype=object)
    kind[(rise > -bound) & (rise <= allow)] = "roundoff"
    kind[(rise > allow) & (unexp_abs <= 0)] = "slack"
    kind[unexp_abs > 0] = "violated"
    unexplained = np.array([_rel(x, V) for x, V in zip(unexp_abs, Vk)]) if N else np.zeros(0)
    # decided exactly by the float bound: V decreases (p["total"] ≥ rise, the gap is ≥ 0)
    definite = p["total"] < -bound
    unexplained[definite] = np.minimum(unexplained[definite], [_rel(x, V) for x, V in
                                                               zip(p["total"][definite] + bound[definite], Vk[definite])])
    is_exact = np.zeros(N, dtype=bool)
    verdicts: dict[int, StepVerdict] = {}
    if exact is not None:
        cand = np.flatnonzero(~definite)
        order = cand[np.argsort(-unexplained[cand], kind="stable")][:max_exact]
        for k in order:
            vd = classify(exact.parts(A, B, int(k)), float(p["roundoff"][k]))
            verdicts[int(k)] = vd
            kind[k] = vd.kind
            is_exact[k] = True
            unexplained[k] = _rel(float(vd.unexplained), float(Vk[k]))
            if vd.kind == "violated" and unexplained[k] <= 0:     # exact > 0 below float resolution
                unexplained[k] = np.nextafter(0.0, 1.0)
    worst = int(np.argmax(unexplained)) if N else 0
    cause = None
    if N and unexplained[worst] > 0:
        # a violation is a positive sign part (or a residual), never the slack the rise exceeds
        cause = (EXACT_CAUSES[verdicts[worst].cause] if worst in verdicts else _float_cause(p, worst, SLACKS))
    sl = np.flatnonzero(kind == "slack")
    slack_step = int(sl[np.argmax(rise[sl] / np.where(Vk[sl] > 0, Vk[sl], 1.0))]) if sl.size else -1
    return {"unexplained": unexplained, "kind": kind, "exact": is_exact, "verdicts": verdicts,
            "worst": worst, "cause": cause, "slack_step": slack_step}


def _can_recompute(run) -> bool:
    """Whether the run carries what the exact recomputation needs (system, stepper, states)."""
    return all(hasattr(run, a) for a in ("system", "stepper", "master")) and hasattr(run.stepper, "grid")


def check_lyapunov_decrease(run: Run, pairs: list[tuple[str, str, str]] | None = None, *,
                            tolerance: float = 0.0, identity_tolerance: float = 0.0,
                            order_factors: tuple[float, ...] = (1.0, 2.0, 4.0), exact: bool = True,
                            max_exact: int = MAX_EXACT_STEPS) -> CheckResult:
    """dV ≤ 0, eq. (17), on every pair the toolkit runs: a three-valued verdict in discrete time.

    A step *rises* when V_{k+1} − V_k − ½‖Δr‖²_{L⁻¹} > 0 (the master–jump pair's
    unprojected-gap term of the plain master is reported with its order in h but not
    counted: Proposition 1's mismatched pair). Every step is classified
    (:func:`classify_steps`), in exact rational arithmetic on the float states for every step
    that may rise (:mod:`proofs_checks.exact_step`; the rest decrease by the rigorous float
    bound :func:`evaluation_bound`):

    * **holds exactly**: no rise beyond the step's round-off, which is the exact residual of
      the float states in the θ-scheme (``R = v_θᵀρ_u + e_θᵀKρ_q`` plus the residuals of the
      impulse and projection splits), accepted up to the a priori :func:`roundoff_allowance`;
    * **holds up to the discrete slack**: every rise is at most round-off plus the positive
      impulse slack −½ΔPᵀDδ (δ = O(h); the Poisson target term), i.e. the sign parts
      (damping, θ-numerical, complementarity, Delassus, jump part) sum to ≤ 0; the case is then
      re-run at ``h·order_factors`` and the order p of the slack in h fitted (the reason gives
      the slacks at each h and the bound ≈ c·h^p, vanishing as h → 0);
    * **violated**: a rise beyond round-off and slack (``passed`` False), attributed to the
      largest positive sign part (:data:`CAUSES`: damping for C̄ not PSD, Delassus for
      per-contact restitution, the jump part, a residual beyond the a priori bound for a wrong
      scheme or projection metric, ...).

    Besides dV, float criteria with the a priori round-off allowance (evidence "bounded"):

    * ``identity``: ΔV equals damping + impulse + numerical + realized projection part (the
      scheme identity; fails for a scheme that is not the θ-method);
    * ``projection``: the realized projection part equals its closed form in the K metric
      (fails for a wrong projection metric);
    * ``damping_sign``, ``projection_sign``: the damping part and the jump part of (17) are
      ≤ 0 (C̄ ⪰ 0, P_I L_I⁻¹ P_Iᵀ ⪰ 0).

    Parameters
    ----------
    run : Run
        A replay (:func:`proofs_checks.runs.replay`).
    pairs : list of (label, a, b), optional
        Default :func:`run_pairs` (every pair the toolkit runs).
    tolerance, identity_tolerance : float
        Accepted relative rise of V beyond round-off and slack, and relative identity/closed-form
        error, per step (default 0).
    order_factors : tuple of float
        Step factors of the order fit (``()`` skips it; needs ``run.scenario``).
    exact : bool
        Recompute the possibly rising steps exactly (False: float parts and bounds only, for
        hand-built parts; a failure is then "bounded", not "violated").
    max_exact : int
        Budget of exactly recomputed steps per pair (:data:`MAX_EXACT_STEPS`).

    Returns
    -------
    CheckResult
        ``margin = −max`` over pairs and steps of the unexplained rise relative to V_k (dV),
        or of ``(part − allowance)/V_k`` for a failing float criterion; ``evidence`` "bounded"
        for a pass (exact on the recomputed steps, rigorous float bounds elsewhere),
        "violated" when an exactly recomputed rise is unexplained; ``verdict`` "holds exactly:
        ...", "holds up to the discrete slack (order ≈ p)" or "violated: ...". The witness has,
        per pair, the worst value of every criterion and part (``<pair>: max_<part>``), the
        step counts per kind (``steps_roundoff``, ``steps_slack``, ``steps_violated``,
        ``steps_exact``), the exact parts of the worst slack step (``slack_step_exact``), and
        the fitted orders (``slack_order_impulse_slack``, ...) with the slacks at each h.
    """
    name, eq = "lyapunov_decrease", "eq. (17), proof of Theorem 1"
    pairs = run_pairs(run) if pairs is None else list(pairs)
    if not pairs:
        return CheckResult.not_applicable(name, "the run has no pair (needs two observers, or the master and "
                                          "an observer)", eq)
    tols = {"dV": tolerance, "identity": identity_tolerance, "projection": identity_tolerance,
            "damping_sign": identity_tolerance, "projection_sign": identity_tolerance}
    summaries = [_pair_summary(run, *pr) for pr in pairs]
    ex = ExactSteps(run) if exact and _can_recompute(run) else None
    for s in summaries:
        s["steps"] = classify_steps(run, s, ex, max_exact)

    def crit_value(s: dict, c: str) -> float:
        """The criterion's value: for dV the rise not explained by round-off and slack."""
        if c == "dV":
            u = s["steps"]["unexplained"]
            return float(u[s["steps"]["worst"]]) if u.size else -np.inf
        return s["crit"][c][0]

    witness: dict = {"pairs": [s["label"] for s in summaries]}
    failing = []
    counts = dict.fromkeys(("roundoff", "slack", "violated", "exact"), 0)
    for s in summaries:
        p, k = s["parts"], s["step"]
        st = s["steps"]
        pre = s["label"]
        for c, (val, _) in s["crit"].items():
            witness[f"{pre}: max_{c}"] = val
            v = crit_value(s, c)
            if v > tols[c]:
                failing.append((v - tols[c], c, s))
        for key, val in s["worst_parts"].items():
            witness[f"{pre}: max_{key}/V"] = val
        witness[f"{pre}: worst_step"] = k
        witness[f"{pre}: worst_time"] = float(run.t[k])
        witness[f"{pre}: V_at_worst"] = float(p["V"][k])
        witness[f"{pre}: roundoff_at_worst"] = float(p["roundoff"][k])
        for key in ("total",) + PARTS + SUBPARTS:
            witness[f"{pre}: {key}_at_worst"] = float(p[key][k])
        witness[f"{pre}: cause"] = s["cause"] or ""
        # the three-valued verdict of the steps
        witness[f"{pre}: max_dV_unexplained"] = crit_value(s, "dV")
        witness[f"{pre}: unexplained_step"] = st["worst"]
        for kind in ("roundoff", "slack", "violated"):
            nk = int(np.sum(st["kind"] == kind))
            witness[f"{pre}: steps_{kind}"] = nk
            counts[kind] += nk
        witness[f"{pre}: steps_exact"] = int(st["exact"].sum())
        counts["exact"] += int(st["exact"].sum())
        j = st["slack_step"]
        witness[f"{pre}: slack_step"] = j
        if j in st["verdicts"]:
            vd = st["verdicts"][j]
            Vj = float(p["V"][j])
            witness[f"{pre}: slack_step_exact"] = {"rise/V": float(vd.rise) / Vj, "roundoff/V": float(vd.roundoff) / Vj,
                                                   "slack/V": float(vd.slack) / Vj, "signs/V": float(vd.signs) / Vj}
    witness.update({f"steps_{kind}": n for kind, n in counts.items()})
    # the worst criterion gives the margin; a failing dV is reported with its cause
    if failing:
        excess, label, worst = max(failing, key=lambda x: x[0])
    else:
        label = "dV"
        worst = max(summaries, key=lambda s: crit_value(s, "dV"))
    value = crit_value(worst, label)
    witness.update(worst_pair=worst["label"], worst_criterion=label, max_dV_beyond_roundoff=max(
        s["crit"]["dV"][0] for s in summaries), max_dV_unexplained=max(crit_value(s, "dV") for s in summaries))
    base = {key: max(slacks_of(s["parts"])[key] for s in summaries) for key in SLACKS}
    witness.update({f"max_{key}/V": val for key, val in base.items()})
    slack_steps = counts["slack"] > 0
    # the order in h is fitted (re-runs at h·order_factors) only when the slack explains a rise
    bites = slack_steps
    order_note = ""
    for key in SLACKS:
        witness[f"slack_order_{key}"] = float("nan")
    if bites and order_factors:
        try:
            fit = slack_order(run, base, tuple(order_factors))
        except ValueError as exc:
            fit = {"fit_skipped": str(exc)}
        witness.update({f"slack_{k}": v for k, v in fit.items()})
        for key, what in (("impulse_slack", "the discrete impact law"),
                          ("impulse_target", "the Poisson target"),
                          ("projection_unprojected_gap", "the plain master's penetration (master–jump "
                                                         "pair, not counted)")):
            p_ = fit.get(f"{key}_order", float("nan"))
            witness[f"slack_order_{key}"] = p_
            if base[key] > 0 and np.isfinite(p_):
                rows = fit.get(f"{key}_slack")
                bound = "" if rows is None or key == "projection_unprojected_gap" else (
                    " (worst slack " + ", ".join(f"{x:.2g}" for x in rows) + "·V at h = "
                    + ", ".join(f"{x:.3g}" for x in fit["h"]) + f": ≈ {rows[0] / fit['h'][0] ** p_:.2g}·h^{p_:.2g})")
                order_note += ("; " if order_note else "") + (
                    f"dV ≤ 0 holds up to an O(h^{p_:.2g}) slack from {what}, vanishing as h → 0{bound}"
                    if p_ > 0 else f"the positive slack from {what} does not decrease with h over "
                                   f"h ∈ [{fit['h'].min():.3g}, {fit['h'].max():.3g}] (fitted order {p_:.2g}; "
                                   f"not in the asymptotic range?)")
    reasons = []
    texts = {"identity": "the step does not satisfy the θ-scheme energy identity",
             "projection": "the position jumps are not the K-metric projection: the realized jump part "
                           "differs from its closed form −½‖Δg⁻‖²_{P L⁻¹ Pᵀ} (+ unprojected gap)",
             "damping_sign": "the damping part −h v_θᵀC̄v_θ is positive: C̄ is not positive semi-definite",
             "projection_sign": "the jump part is positive: P_I L_I⁻¹ P_Iᵀ is not PSD"}
    seen = set()
    for _, c, s in sorted(failing, key=lambda x: -x[0]):
        if c == "dV":
            kk = s["steps"]["worst"]
            cause = s["steps"]["cause"]
            x = crit_value(s, "dV")
            if cause and cause != "residual":
                Vw = s["parts"]["V"][kk]
                top = "impulse" if cause.startswith("impulse") else "projection" if cause.startswith(
                    "projection") else cause
                rel = (lambda z: z / Vw if Vw > 0 else np.inf)
                text = CAUSES[cause].format(x=f"{rel(s['parts'][top][kk]):+.2g}", k=kk, t=f"{run.t[kk]:.6g}",
                                            pair=s["label"], piece=f"{rel(s['parts'][cause][kk]):+.2g}",
                                            dV=f"{x:+.2g}")
            else:
                text = f"V increases beyond round-off ({x:+.2g}·V at step {kk}) in the {s['label']}"
            key = (c, cause)
        else:
            text, key = f"{texts[c]} ({s['label']})", (c,)
        if key not in seen:
            seen.add(key)
            reasons.append(text)
    reason = "; ".join(reasons)
    verdict, evidence = _verdict(summaries, failing, label, counts, witness, run, tols["dV"])
    if not failing and slack_steps:
        reason = _slack_text(summaries, run, witness)
    if order_note:
        reason = f"{reason}; {order_note}" if reason else order_note
    if not any(run.slaves[n].projected for n in run.slaves):
        reason = (reason + "; " if reason else "") + "observers without position jumps (no K-metric projection was run): no jump part"
    pen = witness.get("max_projection_unprojected_gap/V", 0.0)
    if isinstance(pen, (int, float)) and pen > 0:
        verdict += (f"; the plain master's penetration raises V by up to {pen:.3g}·V "
                    "(master–jump pair, max_projection_unprojected_gap/V: reported, not counted)")
    witness["verdict"] = verdict
    keys = ("worst_pair", "worst_criterion", "max_dV_unexplained", "max_dV_beyond_roundoff", "max_impulse_slack/V",
            "slack_order_impulse_slack", "max_impulse_target/V", "slack_order_impulse_target",
            "max_projection_unprojected_gap/V", "steps_slack", "steps_exact")
    return CheckResult.from_margin(name, -value, tols[label], witness, eq, keys, reason,
                                   evidence=evidence, verdict=verdict)


def _verdict(summaries: list[dict], failing: list, label: str, counts: dict, witness: dict, run: Run,
             tol: float) -> tuple[str, str]:
    """(verdict, evidence) of :func:`check_lyapunov_decrease`: "holds exactly", "holds up to
    the discrete slack (order ≈ p)" (both evidence "bounded": exact on the recomputed steps,
    rigorous float bounds on the others) or "violated" (evidence "violated" when a rise was
    recomputed exactly and is not explained, "bounded" when the failure is a float criterion)."""
    if failing:
        exact_dv = [(e, s) for e, c, s in failing if c == "dV" and s["steps"]["worst"] in s["steps"]["verdicts"]]
        if exact_dv:
            s = max(exact_dv, key=lambda x: x[0])[1]
            k = s["steps"]["worst"]
            return (f"violated: V rises at step {k} (t = {run.t[k]:.6g}, {s['label']}) by more than round-off "
                    f"and the discrete slack, exactly", "")
        what = {"dV": "V rises beyond round-off and slack (float bound)", "identity": "θ-scheme identity",
                "projection": "K-metric projection", "damping_sign": "damping sign",
                "projection_sign": "jump-part sign"}
        crits = list(dict.fromkeys(c for _, c, _ in sorted(failing, key=lambda x: -x[0])))
        return "violated: " + ", ".join(what[c] for c in crits), "bounded"
    if counts["slack"]:
        p_ = witness.get("slack_order_impulse_slack", float("nan"))
        if not np.isfinite(p_):
            p_ = witness.get("slack_order_impulse_target", float("nan"))
        order = (f"order ≈ {p_:.2g}" if np.isfinite(p_) and p_ > 0 else
                 f"fitted order {p_:.2g}: its decrease with h not seen" if np.isfinite(p_) else "order not fitted")
        return f"holds up to the discrete slack ({order})", "bounded"
    return "holds exactly: no rise of V beyond round-off", "bounded"


def _slack_text(summaries: list[dict], run: Run, witness: dict) -> str:
    """The reason of a pass with slack: the worst slack-explained rise, exact where recomputed."""
    best = None
    for s in summaries:
        j = s["steps"]["slack_step"]
        if j < 0:
            continue
        V = float(s["parts"]["V"][j])
        vd = s["steps"]["verdicts"].get(j)
        rise = float(vd.rise) if vd else float(s["parts"]["total"][j] - s["parts"]["projection_unprojected_gap"][j])
        slack = float(vd.slack) if vd else float(s["parts"]["impulse_slack"][j])
        ro = float(vd.roundoff) if vd else float(s["parts"]["roundoff"][j])
        rel = rise / V if V > 0 else np.inf
        if best is None or rel > best[0]:
            best = (rel, s, j, slack / V if V > 0 else np.inf, ro / V if V > 0 else np.inf, vd is not None)
    rel, s, j, sl, ro, ex = best
    n = witness["steps_slack"]
    return (f"V rises on {n} step(s), each by at most round-off plus the impulse slack −½ΔPᵀDδ of the discrete "
            f"impact law (no sign in discrete time, O(h)); worst {rel:+.2g}·V at step {j} (t = {run.t[j]:.6g}) "
            f"in the {s['label']}: slack {sl:+.2g}·V, round-off {ro:+.2g}·V"
            + (" (exact rational recomputation)" if ex else " (float bound)"))


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
    why = not_definite_reason(sys_.K, "V is not a norm of the error; Theorem 1 needs K ≻ 0")
    if why:
        return CheckResult.not_applicable(name, why, eq)
    if exact_class(sys_.C).status == "semidefinite":
        return CheckResult.not_applicable(name, "C̄ is only positive semi-definite (exact: C̄x = 0): "
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
    horizon = _horizon_text(run)
    witness["horizon_source"] = horizon
    if not (rate > 0):
        reason = f"V does not decay (fitted rate {rate:.3g} 1/s)"
        margin = min(margin, -1.0)
    elif margin < 0:
        reason = (f"V fell only {decades:.2f} decades in {t[-1]:.3g} s; " +
                  ("v → 0 but e → c ≠ 0 (c balanced by the averaged constraint force, eq. (21))"
                   if T[-1] < 1e-3 * U[-1] else "v has not decayed (a longer horizon may be needed)"))
    if margin < 0:
        verdict = (f"not shown within the horizon: V fell {decades:.2f} of {np.log10(1 / rho):.2f} decades by "
                   f"t = {t[-1]:.6g} s ({horizon}); a finite run is no counterexample to Theorem 1's limit")
    else:
        verdict = f"V fell {decades:.2f} decades (≥ {np.log10(1 / rho):.2f}) by t = {t[-1]:.6g} s ({horizon})"
    # a finite horizon decides nothing exactly: a failure is evidence "sampled", never "violated"
    return CheckResult.from_margin(name, margin, 0.0, witness, eq, keys, reason, evidence="sampled",
                                   verdict=verdict)


def _horizon_text(run: Run) -> str:
    """Where the run's horizon came from and the option that changes it."""
    st = run.settings if isinstance(getattr(run, "settings", None), dict) else {}
    src = st.get("horizon_source")
    if src:
        return src
    sc = getattr(run, "scenario", None)
    t_end = getattr(sc, "t_end", None)
    return ("horizon set by the run" + (f"; the scenario's t_end = {t_end:g} s" if t_end else "")
            + "; --t-end (CheckSettings.t_end) changes it")


def findings_line(results: list[dict]) -> str:
    """One line on a set of check results (``CheckResult.to_dict()`` rows, e.g. the ``--json``
    output of ``python -m proofs_checks``): whether everything holds and whether the only
    finding is the discrete slack of eq. (17) (``nox -s checks`` prints it)."""
    failed = [r for r in results if r.get("passed") is False]
    scen = sorted({r.get("scenario", "") for r in results})
    if failed:
        return (f"{len(failed)} check(s) violated: "
                + ", ".join(f"{r.get('check', r.get('name'))} on {r['scenario']}" for r in failed))
    slack = [r for r in results if r.get("check", r.get("name")) == "lyapunov_decrease"
             and str(r.get("verdict") or "").startswith("holds up to the discrete slack")]
    head = f"all {len(results)} checks hold on {len(scen)} scenario(s)"
    if not slack:
        return head + "; no finding"
    return (head + "; the only finding is the proven discrete slack of eq. (17): "
            + ", ".join(f"{r['scenario']}: {r['verdict']}" for r in slack)
            + " (every rise of V explained exactly by the impulse slack −½ΔPᵀDδ, vanishing as h → 0)")
