"""Assumption A3: monotonicity of the impact map for every reachable active set (paper eq. (6)).

For a closed set A with Delassus matrix ``G = W_Aᵀ M⁻¹ W_A`` (SPD), a pre-impact contact
velocity γ⁻ gives the impulse Λ(γ⁻) of the impact law (:mod:`observer.impact`: generalized
Newton, or Poisson in Glocker's inequality form) and the post-impact velocity
``γ⁺ = γ⁻ + GΛ``. The paper's Definition 1 (eq. (6)) asks, with ``γ̄ = ½(γ⁺ + γ⁻)``::

    (Λ₁ − Λ₂)ᵀ (γ̄₁ − γ̄₂) ≤ 0      for all pairs γ₁⁻, γ₂⁻.

The check measures the dimensionless ratio

    ρ(γ₁⁻, γ₂⁻) = (Λ₁ − Λ₂)ᵀ(γ̄₁ − γ̄₂) / ‖γ₁⁻ − γ₂⁻‖²_{G⁻¹}

(the denominator is twice the kinetic energy of the velocity difference seen by the
contacts, so ρ does not depend on units or on the scale of γ⁻; both maps are positively
homogeneous). A3 holds iff ``sup ρ ≤ 0``; the margin is ``−max ρ``.

Search, for every active set:

1. random pairs from several distributions (contact velocities of random generalized
   velocities, approaching contacts, nearby pairs, pairs with one resting state — the
   energy balance);
2. local worst directions: the maps are piecewise linear, so at a random base point the
   sup of ρ over small pairs ±εd is the largest generalized eigenvalue of the symmetrized
   form ``Jᵀ(I + ½GJ)`` against G⁻¹ (J the Jacobian of Λ, by central differences); the
   pair along that eigenvector is evaluated exactly;
3. an adversarial search: ``scipy.optimize.minimize`` (Nelder–Mead) of −ρ over
   (γ₁⁻, γ₂⁻) ∈ R^{2|A|}, started from the worst pairs of 1.-2., on the sets where they
   came closest to a violation.

**Decided, not sampled, where possible** (:mod:`proofs_checks.pieces`): first, and instead of the search,
A3 is decided in exact rational arithmetic by enumerating the linear pieces of the impact
map per connected component A of the maximal sets' Delassus graphs (Newton: one exact
LDLᵀ of ``N_A = FG_A + G_AF − G_A``; Poisson: all 4^|A| (compression, expansion) support
pairs while 4^|A| ≤ ``exact_max_pairs``, default 4096: six coupled contacts), for
m ≤ ``exact_up_to`` (Newton: any m; the default sets include the full set, whose N
covers every subset). The theorem used and its proof are in :mod:`proofs_checks.pieces`.
The result is ``proved``, or ``violated`` with an exact counterexample (``exact_*`` witness
entries: rational γ₁⁻, γ₂⁻ printed as floats and exactly as strings, exact impulses and
ΔΛᵀΔγ̄ > 0, re-checked by an independent exact LCP solve). Otherwise (larger m, or a Poisson set too large to enumerate)
the search below runs, with evidence ``sampled`` and the reason the enumeration was out of
reach (and the option that extends it) in the verdict; a counterexample it finds is re-checked
in exact arithmetic, and one that vanishes there is reported as round-off, not as a
violation.

This is the *continuous* impact map of eqs. (5)/(9). Its discrete twin, the impulse term
of the Moreau–Jean step, is checked along runs by :func:`proofs_checks.lyapunov.check_lyapunov_decrease`.

Known theory (docs/theory/models.md §3): Newton with a global e and the simple Poisson law are
monotone; the inequality Poisson law has no proof (property-tested). With per-contact
coefficients the map can be non-monotone on coupled contacts (e.g. e = (0.1, 0.95)).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy.optimize import minimize

from observer.contact import get_solver
from observer.impact import ImpactLaw, impact
from observer.model import LinearSystem
from proofs_checks import exact, pieces
from proofs_checks.result import CheckResult

EPS = float(np.finfo(float).eps)
NAME = "impact_monotone"
EQUATION = "A3, Definition 1, eq. (6)"


@dataclass
class _SetProblem:
    """The impact map of one active set."""

    active: np.ndarray
    G: np.ndarray
    chol: tuple
    e: np.ndarray
    law: str
    solve: object
    evals: int = 0

    def impact(self, gamma: np.ndarray) -> np.ndarray:
        """Λ(γ⁻) of the library's impact map (:func:`observer.impact.impact`, no copy of it)."""
        self.evals += 1
        return impact(self.law_obj, self.G, gamma, self.local, self.solve)

    def rho(self, g1: np.ndarray, g2: np.ndarray) -> tuple[float, dict]:
        """Normalized monotonicity ratio ρ and the quantities of eq. (6).

        Round-off is accounted for: the inner product is reduced by an allowance
        ``8 eps cond(G) ‖Λ‖(‖γ̄‖ + ‖G‖‖Λ‖)`` (the accuracy of the LCP solutions), and the
        denominator gets ``1e-12 (‖γ₁⁻‖² + ‖γ₂⁻‖²)_{G⁻¹}`` so that coincident pairs, where
        only round-off is left, cannot produce a spurious ratio."""
        d = g1 - g2
        Gi = self.Ginv
        den = float(d @ Gi @ d)
        scale2 = float(g1 @ Gi @ g1 + g2 @ Gi @ g2)
        L1, L2 = self.impact(g1), self.impact(g2)
        gb1, gb2 = g1 + 0.5 * self.G @ L1, g2 + 0.5 * self.G @ L2
        dL = L1 - L2
        inner = float(dL @ (gb1 - gb2))
        nL = float(np.linalg.norm(L1) + np.linalg.norm(L2))
        allowance = 8.0 * EPS * self.cond * nL * (float(np.linalg.norm(gb1) + np.linalg.norm(gb2))
                                                   + self.norm * nL)
        denom = den + 1e-12 * scale2
        if not denom > 0.0:
            return 0.0, {}
        return (inner - allowance) / denom, {
            "gamma1_minus": g1, "gamma2_minus": g2, "Lambda1": L1, "Lambda2": L2,
            "gamma1_bar": gb1, "gamma2_bar": gb2, "inner_product": inner,
            "roundoff_allowance": allowance, "impulses_differ": bool(np.any(dL != 0.0))}

    def __post_init__(self) -> None:
        self.law_obj = ImpactLaw.build(self.law, self.e, self.G.shape[0])   # restitution of this set
        self.local = np.arange(self.G.shape[0])
        w = np.linalg.eigvalsh(self.G)
        self.cond, self.norm = float(w[-1] / w[0]), float(w[-1])
        # the normalization metric G⁻¹ (SPD, small): from the Cholesky factor
        self.Ginv = sla.cho_solve(self.chol, np.eye(self.G.shape[0]))


def delassus(system: LinearSystem, active: np.ndarray) -> np.ndarray:
    """``G_A = W_Aᵀ M⁻¹ W_A`` (symmetrized), the Delassus matrix of the impact map."""
    W_A = system.W[:, active]
    G = W_A.T @ sla.cho_solve(sla.cho_factor(system.M), W_A)
    return 0.5 * (G + G.T)


def candidate_sets(m: int, rng: np.random.Generator, *, exhaustive_up_to: int = 10,
                   random_sets: int = 32, visited: list | None = None,
                   min_random_size: int = 3) -> list[np.ndarray]:
    """Active sets to examine: all nonempty subsets for ``m ≤ exhaustive_up_to``; else all
    singletons and pairs, the full set and ``random_sets`` random subsets of random sizes
    (from ``min_random_size`` to m); then the ``visited`` sets (closed sets reached by a
    run). Each set once, sorted, in this order."""
    sets: dict[bytes, np.ndarray] = {}
    for ix in _set_sequence(m, rng, exhaustive_up_to, random_sets, min_random_size):
        add_set(sets, ix)
    for v in visited or []:
        add_set(sets, v)
    return list(sets.values())


def add_set(sets: dict, ix) -> None:
    """Add the sorted nonempty index set ``ix`` to ``sets`` (keyed by its bytes) once."""
    a = np.unique(np.asarray(ix, dtype=np.int64))
    if a.size:
        sets.setdefault(a.tobytes(), a)


def _set_sequence(m: int, rng: np.random.Generator, exhaustive_up_to: int, random_sets: int,
                  min_random_size: int):
    if m <= exhaustive_up_to:
        for k in range(1, m + 1):
            yield from itertools.combinations(range(m), k)
        return
    for i in range(m):
        yield [i]
    yield from itertools.combinations(range(m), 2)
    yield range(m)
    for _ in range(random_sets):
        k = int(rng.integers(min_random_size, m + 1))
        yield rng.choice(m, size=k, replace=False)


def _samples(prob: _SetProblem, rng: np.random.Generator, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random pairs (γ₁⁻, γ₂⁻) from a mixture of distributions (see module docstring)."""
    k = prob.active.size
    Lc = np.linalg.cholesky(prob.G)
    pairs = []
    for j in range(count):
        z1, z2 = Lc @ rng.standard_normal(k), Lc @ rng.standard_normal(k)
        kind = j % 4
        if kind == 0:                                   # contact velocities of random u
            pairs.append((z1, z2))
        elif kind == 1:                                 # approaching contacts
            pairs.append((-np.abs(z1), -np.abs(z2)))
        elif kind == 2:                                 # nearby pair (local monotonicity)
            base = -np.abs(z1) if rng.random() < 0.5 else z1
            pairs.append((base, base + 1e-3 * np.linalg.norm(base) * z2 / max(np.linalg.norm(z2), 1e-300)))
        else:                                           # against a resting state (energy balance)
            pairs.append((-np.abs(z1) + 0.3 * z2, np.zeros(k)))
    return pairs


def _local_pairs(prob: _SetProblem, rng: np.random.Generator, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Pairs along the worst direction of the locally linear map at ``count`` base points.

    At a point where the impact map is linear, Λ ≈ Λ₀ + J d, γ̄ ≈ γ̄₀ + (I + ½GJ) d, so for
    a small pair ±εd the ratio is the Rayleigh quotient ``dᵀ sym(Jᵀ(I + ½GJ)) d / dᵀG⁻¹d``.
    J is taken by central differences; the generalized eigenvector of the largest
    eigenvalue gives the pair. The maps are positively homogeneous, so their linear pieces
    are cones: base points are directions, stratified in angle for two contacts (every
    cone wider than 2π/count is hit), uniform on the sphere otherwise."""
    k = prob.active.size
    if k < 2 or count <= 0:
        return []
    if k == 2:
        ang = 2 * np.pi * (np.arange(count) + rng.random()) / count
        bases = np.column_stack([np.cos(ang), np.sin(ang)])
    else:
        bases = rng.standard_normal((count, k))
        bases /= np.linalg.norm(bases, axis=1, keepdims=True)
    out = []
    for g0 in bases:
        eps = 1e-6
        J = np.empty((k, k))
        for j in range(k):
            dj = np.zeros(k)
            dj[j] = eps
            J[:, j] = (prob.impact(g0 + dj) - prob.impact(g0 - dj)) / (2 * eps)
        S = J.T @ (np.eye(k) + 0.5 * prob.G @ J)
        S = 0.5 * (S + S.T)
        try:
            w, V = sla.eigh(S, prob.Ginv)
        except (np.linalg.LinAlgError, ValueError):
            continue
        d = V[:, -1] * 1e-4 / max(np.linalg.norm(V[:, -1]), 1e-300)
        out.append((g0 + d, g0 - d))
    return out


def check_impact_monotone(system: LinearSystem, law: ImpactLaw, *, rng: np.random.Generator,
                          active_sets: list | None = None, visited: list | None = None,
                          samples: int = 24, local_samples: int = 48, adversarial_sets: int = 6,
                          starts: int = 3, maxiter: int = 300,
                          exhaustive_up_to: int = 10, tolerance: float = 1e-9,
                          solver: str = "pivoting", laws: tuple[str, ...] | None = None,
                          exact: bool = True, exact_up_to: int = 10,
                          exact_max_pairs: int = 4096) -> CheckResult:
    """Assumption A3 (eq. (6)): the impact map of every reachable active set is monotone.

    Parameters
    ----------
    system : LinearSystem
        Supplies M and W (``G_A = W_AᵀM⁻¹W_A``).
    law : ImpactLaw
        Law and per-contact restitution (the map of set A uses ``e_A``).
    rng : numpy.random.Generator
        Source of all random samples and starts.
    active_sets : list of index arrays, optional
        Sets to check (default: :func:`candidate_sets`, plus ``visited``).
    visited : list of index arrays, optional
        Closed sets reached by a run (added to the default sets).
    samples, local_samples : int
        Random pairs per set, and local worst-direction pairs for two-contact sets
        (``max(4, 2·local_samples/|A|)`` for larger sets; none for single contacts). Sets
        whose G is diagonal (uncoupled contacts: the map is a product of scalar maps) get
        at most 8 random pairs and no local pairs.
    adversarial_sets, starts, maxiter : int
        The adversarial search runs on the ``adversarial_sets`` sets with the largest
        sampled ρ (ties: the most strongly coupled G), from their ``starts`` worst pairs,
        with Nelder–Mead limited to ``maxiter`` iterations.
    tolerance : float
        Accepted ``max ρ`` (round-off of the LCP solutions).
    laws : tuple of str, optional
        Check these laws with the same restitution (default: ``(law.law,)``).
    exact, exact_up_to, exact_max_pairs
        Decide A3 exactly by piece enumeration (:mod:`proofs_checks.pieces`) when
        ``exact`` and m ≤ ``exact_up_to`` (Poisson: sets with 4^|A| ≤ ``exact_max_pairs``);
        Newton (one matrix per maximal set) for any m.
        The exact decision does not use ``tolerance`` (there is no round-off to allow for):
        the result then has ``tolerance = 0``.

    Returns
    -------
    CheckResult
        Evidence ``proved``/``violated`` (exact decision) or ``sampled``.
        ``margin = −max ρ`` (for an exact decision: made ≥ 0 when proved, and
        −max(ρ sampled, ρ of the exact counterexample) when violated); the witness holds the worst pair: active set, e_A, G_A,
        γ₁⁻, γ₂⁻, Λ₁, Λ₂, γ̄₁, γ̄₂ and the inner product of eq. (6). A monotone map has
        max ρ = 0 (attained by pairs of separating velocities, Λ₁ = Λ₂ = 0);
        ``max_rho_impacting_pairs`` is the largest ρ over pairs with different impulses.
    """
    solve = get_solver(solver).solve
    m = system.m
    sets = [np.asarray(a, dtype=np.int64) for a in active_sets] if active_sets is not None else \
        candidate_sets(m, rng, exhaustive_up_to=exhaustive_up_to, visited=visited)
    laws = tuple(laws or (law.law,))
    decisions = {}
    if exact and (m <= exact_up_to or all(lname == "newton" for lname in laws)):   # Newton: any m
        for lname in laws:
            decisions[lname] = pieces.decide_a3(lname, system.M, system.W, law.restitution, sets,
                                                max_pairs=exact_max_pairs)
    if decisions and all(d["status"] != "undecided" for d in decisions.values()):
        # decided exactly: the float search would add nothing (and cost far more)
        skipped = CheckResult(NAME, True, 0.0, 0.0, {
            "sets_checked": len(sets), "largest_set": int(max(a.size for a in sets)), "evaluations": 0,
            "sampled_search": "skipped: decided exactly by piece enumeration"}, "", EQUATION,
            ("sets_checked", "largest_set"), evidence="proved")
        return _exact_result(skipped, decisions, law)
    why = ("exact=False" if not exact else
           f"m = {m} > exact_up_to = {exact_up_to} (raise impact_monotone.exact_up_to)" if not decisions else
           "; ".join(f"{k}: {d.get('reason', '')}" for k, d in decisions.items() if d["status"] == "undecided"))
    res = _sampled(system, law, laws, sets, solve, rng, samples, local_samples, adversarial_sets, starts,
                   maxiter, tolerance)
    res.witness["exact_undecided"] = why
    res = _recheck_sampled(res, system, law)
    if res.evidence == "sampled":
        res.verdict = f"{res.verdict}; not decided exactly: {why}"
    return res


def _fl(v) -> np.ndarray:
    return np.array([exact.to_float(x) for x in v])


def _exact_result(res: CheckResult, decisions: dict, law: ImpactLaw) -> CheckResult:
    """The sampled result ``res`` with passed/evidence/margin from the exact decisions."""
    w = res.witness
    w["exact_pieces"] = {k: d["pieces"] for k, d in decisions.items()}
    w["exact_method"] = {k: d["method"] for k, d in decisions.items()}
    bad = next(((k, d) for k, d in decisions.items() if d["status"] == "violated"), None)
    if bad is None:
        note = ""
        if res.passed is False:
            note = (f"the sampled ρ = {w['max_rho']:.3g} > tolerance vanished in exact arithmetic "
                    "(round-off): every piece is proved monotone")
        n = sum(d["pieces"] for d in decisions.values())
        return CheckResult(res.name, True, max(res.margin, 0.0), 0.0, w, note, res.equation, res.summary_keys,
                           evidence="proved", verdict=f"A3 holds: {n} piece{'' if n == 1 else 's'} of the impact map checked (exact)")
    lname, d = bad
    rho = exact.to_float(d["rho"])
    w.update(exact_law=lname, exact_active_set=d["active_set"], exact_piece=d["piece"],
             exact_gamma1_minus=_fl(d["gamma1_minus"]), exact_gamma2_minus=_fl(d["gamma2_minus"]),
             exact_gamma1_minus_rational=[str(x) for x in d["gamma1_minus"]],
             exact_gamma2_minus_rational=[str(x) for x in d["gamma2_minus"]],
             exact_Lambda1=_fl(d["Lambda1"]), exact_Lambda2=_fl(d["Lambda2"]),
             exact_inner_product=exact.to_float(d["inner"]), exact_inner_product_rational=str(d["inner"]),
             exact_rho=rho)
    w.setdefault("max_rho", rho)           # no float search ran: the worst ρ known is the exact one
    reason = res.reason or ("per-contact restitution: the impact map is not monotone on coupled contacts"
                            if not law.is_global else "the impact map is not monotone")
    margin = -max(rho, w.get("max_rho", -np.inf))
    keys = res.summary_keys[:1] + ("exact_active_set", "exact_gamma1_minus", "exact_gamma2_minus",
                                   "exact_inner_product") + res.summary_keys[1:]
    return CheckResult(res.name, False, margin, 0.0, w, reason, res.equation, keys, evidence="violated",
                       verdict=f"A3 violated ({lname}): exact counterexample on set {d['active_set']}")


def _recheck_sampled(res: CheckResult, system: LinearSystem, law: ImpactLaw) -> CheckResult:
    """Evidence ``sampled`` for a pass; a sampled counterexample is re-checked exactly:
    ``violated`` if ΔΛᵀΔγ̄ > 0 holds over Q, else round-off (passed, ``sampled``)."""
    w = res.witness
    if res.passed is not False:
        res.evidence = "sampled"
        res.verdict = f"no counterexample in {w.get('evaluations', 0)} impact-map evaluations (sampled)"
        return res
    A = w.get("active_set")
    lname = w.get("law", law.law)
    if A is None or lname not in ("newton", "poisson"):
        res.evidence = "sampled"
        res.verdict = "float counterexample, not re-checked exactly"
        return res
    G = pieces.delassus_exact(system.M, system.W[:, A])
    e = [exact.to_fmpq(v) for v in np.asarray(law.restitution, float)[A]]
    g1 = [exact.to_fmpq(v) for v in np.asarray(w["gamma1_minus"], float)]
    g2 = [exact.to_fmpq(v) for v in np.asarray(w["gamma2_minus"], float)]
    chk = pieces.exact_pair(lname, G, e, g1, g2)
    w.update(exact_inner_product=exact.to_float(chk["inner"]), exact_rho=exact.to_float(chk["rho"]))
    if chk["inner"] > 0:
        res.evidence = "violated"
        res.verdict = f"A3 violated: the sampled pair re-checked exactly (ΔΛᵀΔγ̄ = {w['exact_inner_product']:.3g} > 0)"
        return res
    return CheckResult(res.name, True, 0.0, res.tolerance, w,
                       f"the sampled counterexample (ρ = {w['max_rho']:.3g}) vanishes in exact arithmetic: "
                       "round-off", res.equation, res.summary_keys, evidence="sampled",
                       verdict="round-off, not a counterexample (re-checked exactly); otherwise sampled")


def _sampled(system, law, laws, sets, solve, rng, samples, local_samples, adversarial_sets, starts, maxiter,
             tolerance) -> CheckResult:
    """The random + local + adversarial search of the module docstring (float)."""
    worst = {"rho": -np.inf}
    worst_impacting = -np.inf
    evals = 0
    per_law = {}
    for lname in laws:
        probs = []
        for a in sets:
            G = delassus(system, a)
            probs.append(_SetProblem(a, G, sla.cho_factor(G), np.asarray(law.restitution)[a], lname, solve))
        scored = []
        law_worst = {"rho": -np.inf}
        for prob in probs:
            best = []
            k = prob.active.size
            Dg = np.sqrt(np.diag(prob.G))
            coupling = float(np.max(np.abs(prob.G / np.outer(Dg, Dg) - np.eye(k))))
            n_local = local_samples if k == 2 else max(4, 2 * local_samples // max(k, 1))
            n_rand = samples
            if coupling < 1e-12:          # diagonal G: a product of scalar maps, few samples suffice
                n_local, n_rand = 0, min(samples, 8)
            for g1, g2 in _samples(prob, rng, n_rand) + _local_pairs(prob, rng, n_local):
                r, info = prob.rho(g1, g2)
                best.append((r, g1, g2))
                if r > law_worst["rho"]:
                    law_worst = {"rho": r, "prob": prob, "info": info, "how": "random sample"}
                if info.get("impulses_differ") and r > worst_impacting:
                    worst_impacting = r
            best.sort(key=lambda x: -x[0])
            scored.append((best[0][0] if best else -np.inf, coupling, prob, best[:starts]))
        scored.sort(key=lambda x: (-x[0], -x[1]))
        for _, _, prob, best in scored[:adversarial_sets]:
            k = prob.active.size
            x0s = [np.concatenate([g1, g2]) for _, g1, g2 in best]
            for x0 in x0s:
                res = minimize(lambda x: -prob.rho(x[:k], x[k:])[0], x0, method="Nelder-Mead",
                               options={"maxiter": maxiter, "xatol": 1e-12, "fatol": 1e-15})
                r, info = prob.rho(res.x[:k], res.x[k:])
                if r > law_worst["rho"]:
                    law_worst = {"rho": r, "prob": prob, "info": info, "how": "adversarial search"}
                if info.get("impulses_differ") and r > worst_impacting:
                    worst_impacting = r
        evals += sum(p.evals for p in probs)
        per_law[lname] = float(law_worst["rho"])
        if law_worst["rho"] > worst["rho"]:
            worst = dict(law_worst, law=lname)
    witness: dict = {"max_rho": float(worst["rho"]), "law": worst.get("law", laws[0]),
                     "sets_checked": len(sets), "largest_set": int(max(a.size for a in sets)),
                     "evaluations": int(evals), "found_by": worst.get("how", ""),
                     "max_rho_impacting_pairs": float(worst_impacting)}
    if len(laws) > 1:
        witness["max_rho_per_law"] = per_law
    prob = worst.get("prob")
    if prob is not None:
        witness.update(active_set=prob.active.tolist(), restitution=prob.e.tolist(), G=prob.G)
        witness.update(worst["info"])
    keys = ("max_rho", "law", "active_set", "restitution", "gamma1_minus", "gamma2_minus",
            "inner_product", "found_by", "max_rho_impacting_pairs", "sets_checked")
    note = ""
    if not law.is_global and worst["rho"] > tolerance:
        note = "per-contact restitution: the impact map is not monotone on coupled contacts"
    return CheckResult.from_margin(NAME, 0.0 - worst["rho"], tolerance, witness, EQUATION, keys, note)
