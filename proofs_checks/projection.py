"""Eqs. (13)-(14): the constraint forces of the switched geometric constraints in closed form,
and the positive semi-definiteness of ``P_I L_I⁻¹ P_Iᵀ`` for every active set.

From the proof of Proposition 1 (with the erratum I(t) = {i | χ_i = 1}, docs/theory/index.md §2)::

    σ = −P_I L_I⁻¹ P_Iᵀ γ_s     (13)        Σ = −P_I L_I⁻¹ P_Iᵀ g_s⁻     (14)
    L_I = W_Iᵀ K⁻¹ W_I,  and the position jump is q⁺ − q⁻ = K⁻¹ W Σ.

Discrete form (docs/theory/scheme.md §3): the time-stepper realizes both by one K-metric projection per
step onto ``{g_I(q, t_{k+1}) = 0}``: ``q_{k+1} = q⁻_{k+1} + K⁻¹WΣ_k`` with
``Σ_k = −P_I L_I⁻¹ P_Iᵀ g⁻_{k+1}`` (eq. (14) exactly). When every contact of I was already
projected in the previous step (g⁺_{k,I} = 0), ``g⁻_{k+1,I} = h γ̄_I + O(h³)`` and the
step multiplier is the integral of the force of eq. (13): ``Σ_k/h = −P_I L_I⁻¹ P_Iᵀ γ̄`` with
γ̄ = Wᵀ[(1−θ)u_k + θu_{k+1}] + ν̇(t_k + h/2).

:func:`check_projection_closed_form` compares, at every step of a run, the projection the
integrator applied (q⁺ − q⁻ from the run) with these closed forms, always computed in the
K metric (independently of the stepper's cached matrices). A run made with a wrong
projection metric (``replay(..., metric=np.eye(n))``) fails.

:func:`check_projection_psd` *decides* ``P_I L_I⁻¹ P_Iᵀ ⪰ 0`` for every nonempty I in exact
rational arithmetic (:mod:`proofs_checks.exact`): ``L = WᵀK⁻¹W`` is formed exactly from the
float K and W, and ``P_I L_I⁻¹ P_Iᵀ ⪰ 0`` holds iff L_I ≻ 0 (L_I⁻¹ then exists and is ≻ 0;
the padding rows are zero), proved by an exact LDLᵀ of L_I — exhaustively over all
2^m − 1 sets for m ≤ 10, and beyond by one exact LDLᵀ of L: every L_I is a principal
submatrix of L, and a principal submatrix of a positive definite matrix is positive
definite (xᵀL_I x = (P_I x)ᵀ L (P_I x) > 0; Horn & Johnson, *Matrix Analysis*, Obs. 7.1.2).
A failure is an exact witness: for an indefinite L_I a vector y with yᵀL_I y < 0, so that
z = L_I y gives zᵀL_I⁻¹z = yᵀL_I y < 0; for a singular L_I an exact kernel vector.

The margin is still measured in floats (built with linear solves, never an explicit
inverse), exhaustively over all nonempty I for m ≤ 16, and for larger m over all
singletons and pairs, random subsets, the full set and a greedy chain of
worst-conditioned subsets. By Cauchy interlacing, for symmetric L the full set has the
largest condition number and the extreme eigenvalues, so for SPD L the sampled search
cannot miss the worst case.
"""

from __future__ import annotations

import itertools

import flint
import numpy as np
import scipy.linalg as sla

from proofs_checks import exact
from proofs_checks.assumptions import exact_class, not_definite_reason
from proofs_checks.monotonicity import add_set, candidate_sets
from proofs_checks.result import CheckResult
from proofs_checks.runs import Run, Trajectory

EPS = float(np.finfo(float).eps)


def _stiffness_reason(K: np.ndarray) -> str | None:
    """None if K ≻ 0, else why the K-metric checks are not applicable."""
    return not_definite_reason(K, "the K-metric projection, eqs. (13)-(14) and L_I = W_IᵀK⁻¹W_I "
                                  "need K ≻ 0")


def check_projection_closed_form(run: Run, *, slaves: tuple[str, ...] | None = None,
                                 tolerance: float = 1e-8, force_tolerance: float = 1e-6) -> CheckResult:
    """Eqs. (13)-(14): the applied position jumps equal ``K⁻¹W Σ`` with ``Σ = −P_I L_I⁻¹ P_Iᵀ g⁻``.

    Parameters
    ----------
    run : Run
        A replay with observers that have position jumps.
    slaves : tuple of str, optional
        Observers to examine (default: all with position jumps).
    tolerance : float
        Accepted relative error of the jump, ``‖Δq − Δq_cf‖_K / (‖Δq_cf‖_K + r)`` with the
        round-off scale r = 1e-6·max‖q‖_K (eq. (14)): with the default tolerance the
        absolute allowance is 1e-14·max‖q‖_K, about 45 ulps of the positions, which is what
        adding K⁻¹W_IΣ to q in floating point can leave.
    force_tolerance : float
        Accepted error of the continuous part, ``|Σ_k/h − σ_cf| / max|σ_cf|`` on steps whose
        whole set was closed before (eq. (13)); the O(h²) difference between
        (ν_{k+1} − ν_k)/h and ν̇(t_k + h/2) is far below it.

    Returns
    -------
    CheckResult
        ``margin = −(worst relative error of (14))`` (or of (13) when only (13) fails); the
        witness has the worst step (``time`` = t_{k+1}, when the projection acts), its set,
        the applied multiplier (least squares of KΔq = W_IΣ), the closed form, and the
        part of KΔq outside range W_I (nonzero for a projection in another metric).
    """
    system = run.system
    name, eq = "projection_closed_form", "eqs. (13)-(14), proof of Proposition 1"
    reason = _stiffness_reason(system.K)
    if reason:
        return CheckResult.not_applicable(name, reason, eq)
    names = slaves or tuple(n for n, tr in run.slaves.items() if tr.projected)
    if not names:
        return CheckResult.not_applicable(name, "the run has no observer with position jumps", eq)
    K, W = system.K, system.W
    Kc = sla.cho_factor(K)
    KinvW = sla.cho_solve(Kc, W)
    L = W.T @ KinvW
    L = 0.5 * (L + L.T)
    t, h, th = run.t, run.h, run.theta
    nu, nud_mid = system.nu(t), system.nu_dot(0.5 * (t[:-1] + t[1:]))
    worst14 = {"value": -np.inf}
    worst13 = {"value": -np.inf}
    steps_checked = cont_steps = 0
    sig_scale = 0.0
    records13 = []
    for sname in names:
        tr: Trajectory = run.slaves[sname]
        qK = np.sqrt(np.einsum("ki,ij,kj->k", tr.q, K, tr.q))
        r_scale = 1e-6 * float(np.max(qK)) + 1e-300
        prev = np.zeros(system.m, dtype=bool)
        for k in range(t.size - 1):
            act = tr.active[k + 1] if tr.projected else np.zeros(system.m, bool)
            I = np.flatnonzero(act)
            if I.size == 0:
                prev = act
                continue
            steps_checked += 1
            g_pre = tr.q_pre[k + 1] @ W[:, I] + nu[k + 1, I]
            L_I = L[np.ix_(I, I)]
            cI = sla.cho_factor(L_I)
            Sigma_cf = -sla.cho_solve(cI, g_pre)
            dq_cf = KinvW[:, I] @ Sigma_cf
            dq = tr.q[k + 1] - tr.q_pre[k + 1]
            diff = dq - dq_cf
            err = float(np.sqrt(diff @ K @ diff)) / (float(np.sqrt(dq_cf @ K @ dq_cf)) + r_scale)
            Sigma_ls = np.linalg.lstsq(W[:, I], K @ dq, rcond=None)[0]     # applied multiplier
            if err > worst14["value"]:
                resid = K @ dq - W[:, I] @ Sigma_ls
                worst14 = {"value": err, "slave": sname, "step": k, "time": float(t[k + 1]), "active_set": I.tolist(),
                           "g_minus": g_pre, "Sigma_applied": Sigma_ls, "Sigma_closed_form": Sigma_cf,
                           "jump_applied": dq, "jump_closed_form": dq_cf,
                           "jump_not_in_range_KinvW": float(np.linalg.norm(resid)
                                                            / max(np.linalg.norm(K @ dq), 1e-300)),
                           "g_plus_after": tr.q[k + 1] @ W[:, I] + nu[k + 1, I]}
            if np.all(prev[I]):
                cont_steps += 1
                u_th = (1 - th) * tr.u[k] + th * tr.u[k + 1]
                gbar = u_th @ W[:, I] + nud_mid[k, I]
                sigma_cf = -sla.cho_solve(cI, gbar)
                records13.append((np.max(np.abs(Sigma_ls / h - sigma_cf)), sname, k, I, Sigma_ls / h, sigma_cf))
                sig_scale = max(sig_scale, float(np.max(np.abs(sigma_cf))))
            prev = act
    if steps_checked == 0:
        return CheckResult.not_applicable(name, "no step with a closed contact in the run", eq)
    for dev, sname, k, I, s_app, s_cf in records13:
        rel = dev / max(sig_scale, 1e-300)
        if rel > worst13["value"]:
            worst13 = {"value": rel, "slave": sname, "step": k, "time": float(t[k + 1]), "active_set": I.tolist(),
                       "sigma_applied": s_app, "sigma_closed_form": s_cf}
    witness = {"max_jump_error_eq14": worst14["value"], "max_force_error_eq13": worst13["value"]
               if records13 else float("nan"), "projected_steps": steps_checked,
               "persistent_steps": cont_steps, "metric": run.metric}
    witness.update({f"eq14_{k}": v for k, v in worst14.items() if k != "value"})
    witness.update({f"eq13_{k}": v for k, v in worst13.items() if k != "value"})
    keys = ("max_jump_error_eq14", "max_force_error_eq13", "eq14_time", "eq14_active_set",
            "eq14_Sigma_applied", "eq14_Sigma_closed_form", "metric")
    fail14 = worst14["value"] > tolerance
    fail13 = bool(records13) and worst13["value"] > force_tolerance
    reasons = []
    if fail14:
        reasons.append("the applied position jump is not K⁻¹WΣ with Σ = −P_I L_I⁻¹ P_Iᵀ g⁻ (eq. (14))")
    if fail13:
        reasons.append("the continuous constraint force differs from σ = −P_I L_I⁻¹ P_Iᵀ γ (eq. (13))")
    if fail13 and not fail14:
        return CheckResult.from_margin(name, -worst13["value"], force_tolerance, witness, eq, keys,
                                       "; ".join(reasons), evidence="sampled")
    return CheckResult.from_margin(name, -worst14["value"], tolerance, witness, eq, keys, "; ".join(reasons),
                                   evidence="sampled")


def _subsets(m: int, rng: np.random.Generator, exhaustive_up_to: int, samples: int,
             L: np.ndarray) -> tuple[list[np.ndarray], bool]:
    if m <= exhaustive_up_to:
        return candidate_sets(m, rng, exhaustive_up_to=exhaustive_up_to), True
    sets = {}
    for a in candidate_sets(m, rng, exhaustive_up_to=exhaustive_up_to, random_sets=samples,
                            min_random_size=1):
        add_set(sets, a)
    # greedy chain of worst-conditioned subsets: grow from the worst pair
    def cond(ix):
        w = np.linalg.eigvalsh(L[np.ix_(ix, ix)])
        return abs(w[-1]) / abs(w[0]) if w[0] != 0 else np.inf

    pair = max(itertools.combinations(range(m), 2), key=lambda c: cond(list(c)))
    cur = list(pair)
    while len(cur) < m:
        rest = [j for j in range(m) if j not in cur]
        j = max(rest, key=lambda j: cond(cur + [j]))
        cur = cur + [j]
        add_set(sets, cur)
    return list(sets.values()), False


EXACT_EXHAUSTIVE_UP_TO = 10
"""Largest m for which every active set's L_I is factored exactly (2^m − 1 sets)."""


def exact_metric(K: np.ndarray, W: np.ndarray) -> flint.fmpq_mat:
    """``L = WᵀK⁻¹W`` exactly over Q from the float K and W (ZeroDivisionError when K is
    exactly singular)."""
    Kq, Wq = exact.to_fmpq_mat(K), exact.to_fmpq_mat(W)
    return exact.sym_part(Wq.transpose() * Kq.solve(Wq))


def exact_projection_psd(K: np.ndarray, W: np.ndarray, *,
                         exhaustive_up_to: int = EXACT_EXHAUSTIVE_UP_TO,
                         L: flint.fmpq_mat | None = None) -> dict:
    """Exact decision of ``P_I L_I⁻¹ P_Iᵀ ⪰ 0`` for every nonempty I (module docstring).

    Returns
    -------
    dict
        ``holds`` (bool), ``method``, ``sets_proved`` (number of active sets covered),
        and for a failure ``failing_set``, ``failing_class`` ("indefinite"/"semidefinite"
        for L_I) and ``exact_vector`` z (floats of the exact vector, padded to m) with
        ``exact_zPz`` = zᵀ P_I L_I⁻¹ P_Iᵀ z < 0 (indefinite) or the kernel vector of L_I.
    """
    L = exact_metric(K, W) if L is None else L
    m = L.nrows()
    if m <= exhaustive_up_to:
        sets = [list(c) for k in range(1, m + 1) for c in itertools.combinations(range(m), k)]
        method = f"exact LDLᵀ of L_I over Q for each of the {len(sets)} active sets"
    else:
        sets = [list(range(m))]
        method = ("exact LDLᵀ of L = WᵀK⁻¹W over Q; every L_I is a principal submatrix of L ≻ 0 "
                  f"(covers all {2**m - 1} active sets)")
    for I in sets:
        LI = flint.fmpq_mat(len(I), len(I), [L[i, j] for i in I for j in I])
        cert = exact.classify_symmetric(LI)
        if cert.status == "definite":
            continue
        z = [flint.fmpq(0)] * m
        if cert.status == "indefinite":
            y = flint.fmpq_mat(len(I), 1, cert.vector)
            zy = LI * y                                       # z = L_I y:  zᵀL_I⁻¹z = yᵀL_I y
            value = (zy.transpose() * LI.solve(zy))[0, 0]
            assert value < 0                                 # exact re-check
        else:
            zy = flint.fmpq_mat(len(I), 1, cert.vector)       # L_I zy = 0: L_I⁻¹ does not exist
            value = flint.fmpq(0)
        for t, i in enumerate(I):
            z[i] = zy[t, 0]
        return {"holds": False, "method": method, "sets_proved": 0, "failing_set": I,
                "failing_class": cert.status, "vector": np.array([exact.to_float(v) for v in z]),
                "vector_rational": [str(v) for v in z], "zPz": exact.to_float(value)}
    return {"holds": True, "method": method, "sets_proved": 2**m - 1}


def check_projection_psd(K: np.ndarray, W: np.ndarray, *, rng: np.random.Generator,
                         exhaustive_up_to: int = 16, samples: int = 2000,
                         tolerance: float = 1e-12,
                         exact_exhaustive_up_to: int = EXACT_EXHAUSTIVE_UP_TO) -> CheckResult:
    """``P_I L_I⁻¹ P_Iᵀ ⪰ 0`` for every active set I (proof of Proposition 1, after eq. (14); eq. (17)).

    ``L = WᵀK⁻¹W`` is formed exactly over Q and rounded once; for every examined I the m×m matrix
    ``P_I L_I⁻¹ P_Iᵀ`` is formed as ``P_I X`` with ``X = solve(L_I, P_Iᵀ)`` and symmetrized.
    Its eigenvalues are those of the I block plus exact zeros for the rows not in I, so
    the margin is taken on the block.

    ``passed`` and the evidence come from :func:`exact_projection_psd` (``proved`` for all
    2^m − 1 sets, or ``violated`` with an exact witness); ``exact_exhaustive_up_to`` is its
    limit for set-by-set factorization.

    Returns
    -------
    CheckResult
        ``margin = min_I λ_min(L_I⁻¹)/λ_max(L_I⁻¹)`` (relative smallest eigenvalue, ≥ 0 for
        PSD; its sign is the exact one); the witness has the worst set, its eigenvalues, the
        largest condition number of L_I and its set, how many sets were examined in floats
        (exhaustively or not), and the exact decision (``exact_method``,
        ``exact_sets_proved`` or the failing set and exact vector). Not applicable only when K is exactly singular
        (:func:`proofs_checks.assumptions.exact_class`): L is formed exactly, so an exactly
        definite but ill-conditioned K is decided, and an indefinite nonsingular K is decided
        on its own L (``violated`` where some L_I is not positive definite).
    """
    name, eq = "projection_psd", "P_I L_I⁻¹ P_Iᵀ ⪰ 0, after eq. (14); eq. (17)"
    K = np.asarray(K, dtype=float)
    W = np.asarray(W, dtype=float)
    eigK = np.linalg.eigvalsh(0.5 * (K + K.T))
    if exact_class(K).status == "semidefinite":
        return CheckResult.not_applicable(name, "K is singular (exact: Kx = 0, x in stiffness_spd's witness): "
                                          "L_I = W_IᵀK⁻¹W_I does not exist (needs K nonsingular)", eq)
    Lq = exact_metric(K, W)              # exact, so the float margin below needs no solve with K
    L = exact.to_array(Lq)
    m = W.shape[1]
    sets, exhaustive = _subsets(m, rng, exhaustive_up_to, samples, L)
    worst = (np.inf, None, None)
    worst_cond = (0.0, None)
    by_size: dict[int, list[np.ndarray]] = {}
    for s in sets:
        by_size.setdefault(s.size, []).append(s)
    for k, group in by_size.items():
        idx = np.array(group)                                         # (B, k)
        LI = L[idx[:, :, None], idx[:, None, :]]                      # (B, k, k)
        eyeB = np.broadcast_to(np.eye(k), LI.shape)
        try:
            X = np.linalg.solve(LI, eyeB)                             # L_I⁻¹ P_Iᵀ P_I block, by solves
        except np.linalg.LinAlgError:
            X = np.stack([np.linalg.lstsq(a, np.eye(k), rcond=None)[0] for a in LI])
        X = 0.5 * (X + np.swapaxes(X, 1, 2))
        wX = np.linalg.eigvalsh(X)                                    # (B, k)
        wL = np.linalg.eigvalsh(LI)
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = wX[:, 0] / np.max(np.abs(wX), axis=1)
            cond = np.abs(wL[:, -1]) / np.abs(wL[:, 0])
        j = int(np.argmin(rel))
        if rel[j] < worst[0]:
            worst = (float(rel[j]), idx[j], wX[j])
        jc = int(np.argmax(cond))
        if cond[jc] > worst_cond[0]:
            worst_cond = (float(cond[jc]), idx[jc])
    I = worst[1]
    S = np.zeros((m, m))
    S[np.ix_(I, I)] = np.linalg.lstsq(L[np.ix_(I, I)], np.eye(I.size), rcond=None)[0]   # L_I may be singular
    witness = {"min_relative_eigenvalue": worst[0], "worst_set": I.tolist(), "eigenvalues_L_I_inv": worst[2],
               "min_eigenvalue_P_Linv_PT": float(np.linalg.eigvalsh(0.5 * (S + S.T))[0]),
               "max_condition_L_I": worst_cond[0], "max_condition_set": worst_cond[1].tolist(),
               "sets_examined": len(sets), "exhaustive": exhaustive, "m": m,
               "K_lambda_min": float(eigK[0])}
    keys = ("min_relative_eigenvalue", "worst_set", "max_condition_L_I", "sets_examined", "exhaustive")
    ex = exact_projection_psd(K, W, exhaustive_up_to=exact_exhaustive_up_to, L=Lq)
    witness.update({f"exact_{k}": v for k, v in ex.items() if k != "holds"})
    margin = worst[0]
    if ex["holds"]:
        note = ("" if margin >= -tolerance else f"float relative eigenvalue {margin:.3g} < 0: round-off, "
                "the exact LDLᵀ proves every L_I ≻ 0")
        margin = max(margin, 0.0)                     # float round-off cannot flip an exact PSD
        return CheckResult(name, True, margin, tolerance, witness, note, eq, keys, evidence="proved",
                           verdict=f"P_I L_I⁻¹ P_Iᵀ ⪰ 0 for all {ex['sets_proved']} active sets (exact)")
    reason = ("L_I is indefinite: P_I L_I⁻¹ P_Iᵀ has a negative eigenvalue" if ex["failing_class"] == "indefinite"
              else "L_I is singular: L_I⁻¹ does not exist")
    if not margin < -tolerance:
        margin = min(margin, ex["zPz"]) if ex["zPz"] < 0 else -np.inf
    if not margin < -tolerance:
        margin = -np.inf
    return CheckResult(name, False, margin, tolerance, witness, reason, eq, keys + ("exact_failing_set",),
                       evidence="violated", verdict=f"L_I {ex['failing_class']} for I = {ex['failing_set']} (exact)")
