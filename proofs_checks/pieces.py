"""Assumption A3 decided exactly by enumerating the linear pieces of the impact map.

For a closed set A with Delassus matrix G = W_AᵀM⁻¹W_A (SPD, formed exactly from the float
M and W), the Newton map γ⁻ ↦ Λ = LCP(G, (1+e)∘γ⁻) and Glocker's Poisson map (compression
LCP(G, γ⁻), expansion LCP(G, γ_C + G(ε∘Λ_C))) are continuous and piecewise linear: the
solution of an LCP with a P-matrix G is unique for every right-hand side b, and equals
x = −P_J G_JJ⁻¹ P_Jᵀ b on the complementary cone of its support J (Cottle, Pang & Stone,
*The Linear Complementarity Problem*, 1992, ch. 3), so the pieces are indexed by one support
J (Newton) or a pair (J₁, J₂) (Poisson), and each piece is a polyhedral cone on which
Λ = Jγ⁻ for a matrix J.

Uncoupled contacts: when G_A is block diagonal (after a permutation; the exact zero pattern
of G over Q), both laws act block by block and q is the sum of the blocks' q, so A3 on A
holds iff it holds on every connected component of G_A's graph; the pieces are enumerated
per component.

A3 (eq. (6)) asks ``q(γ₁⁻, γ₂⁻) = ΔΛᵀΔγ̄ = ΔΛᵀΔγ⁻ + ½ ΔΛᵀGΔΛ ≤ 0`` for all pairs.

**Theorem used** (proved here; it extends the smooth criterion "F is monotone iff its
Jacobian is positive semidefinite", Facchinei & Pang, *Finite-Dimensional Variational
Inequalities and Complementarity Problems*, 2003, Prop. 2.3.2, to this quadratic form and
to continuous piecewise-linear maps). Let Q(J) = sym(J + ½ JᵀGJ) for a piece's matrix J.
Then q ≤ 0 for all pairs **iff** Q(J) ⪯ 0 for every piece with nonempty interior.
*Necessity*: for γ⁻ interior to a piece and small ±εd the pair stays in the piece and
q = 4ε² dᵀQ(J)d. *Sufficiency*: along a segment γ₂⁻ + t d, t ∈ [0, 1], not contained in a
piece boundary (a dense set of pairs; q is continuous), ΔΛ = J̄d with J̄ = ∫J(t)dt a convex
combination of the pieces' matrices; d ↦ dᵀJ̄d + ½|J̄d|²_G is convex in J̄, so
q ≤ Σ_k w_k dᵀQ(J_k)d ≤ 0 (Jensen). Checking Q ⪯ 0 on *every* index (also pieces with
empty interior) is therefore a sufficient condition, and a failing piece with nonempty
interior gives a real counterexample.

* **Newton**: piece J of set A has J = −P_J G_JJ⁻¹ P_Jᵀ D with D = diag(1+e);
  Q = −½ D H N H D on the J block (H = G_JJ⁻¹), N_J = FG_JJ + G_JJF − G_JJ, F = D⁻¹. So
  Q(J) ⪯ 0 for every J ⊆ A iff N_A = (FG + GF − G)_AA ⪰ 0 (every N_J is a principal
  submatrix of N_A, and J = A is a full-dimensional piece: b = −G·1 lies inside it). One
  exact LDLᵀ per maximal set decides A3, for any m. Global e: N = (1−e)/(1+e) G ⪰ 0.
* **Poisson**: J = −D S₁ − S₂ + S₂ G D S₁ (S_J = P_J G_JJ⁻¹ P_Jᵀ, D = diag(1+ε)) for the
  pair (J₁, J₂); all 4^|A| pairs are enumerated while ``4^|A| ≤ max_pairs``. A failing
  pair is confirmed by an interior point (a float LP, re-checked exactly); a failing pair
  without one leaves A3 undecided here (the caller falls back to sampling).

Every counterexample is re-checked independently: both impulses are recomputed by an exact
LCP solve (:func:`exact_lcp`, least-index principal pivoting, Murty 1974, finite for
P-matrices; its complementarity certificate is checked over Q) and ``ΔΛᵀΔγ̄ > 0`` is
evaluated exactly.
"""

from __future__ import annotations

import itertools

import flint
import numpy as np

from proofs_checks import exact

Q0 = flint.fmpq(0)


# ----------------------------------------------------------------------------- exact LCP
def _sub(G: flint.fmpq_mat, rows, cols) -> flint.fmpq_mat:
    return flint.fmpq_mat(len(rows), len(cols), [G[i, j] for i in rows for j in cols])


def exact_lcp(G: flint.fmpq_mat, b: list, guess=None, max_iter: int = 10_000) -> list:
    """The solution x of ``0 ≤ Gx + b ⊥ x ≥ 0`` over Q (G a P-matrix, e.g. SPD).

    Least-index principal pivoting (Murty's Bard-type method) from the support ``guess``;
    the returned x satisfies x ≥ 0, Gx + b ≥ 0 and x_i(Gx + b)_i = 0 exactly (checked)."""
    k = G.nrows()
    J = set(guess or ())
    for _ in range(max_iter):
        Js = sorted(J)
        x = [Q0] * k
        if Js:
            sol = _sub(G, Js, Js).solve(flint.fmpq_mat(len(Js), 1, [-b[i] for i in Js]))
            for t, i in enumerate(Js):
                x[i] = sol[t, 0]
        w = [b[i] + sum((G[i, j] * x[j] for j in Js), Q0) for i in range(k)]
        bad = next((i for i in range(k) if (i in J and x[i] < 0) or (i not in J and w[i] < 0)), None)
        if bad is None:
            assert all(xi >= 0 for xi in x) and all(wi >= 0 for wi in w)
            assert all(x[i] * w[i] == 0 for i in range(k))
            return x
        J ^= {bad}
    raise RuntimeError("exact LCP: principal pivoting did not terminate")     # pragma: no cover


def _mv(G: flint.fmpq_mat, x: list) -> list:
    k = G.nrows()
    return [sum((G[i, j] * x[j] for j in range(k)), Q0) for i in range(k)]


def exact_impulse(law: str, G: flint.fmpq_mat, gamma: list, e: list, guess=None) -> list:
    """Λ(γ⁻) of the Newton or (Glocker) Poisson law, in exact arithmetic (see
    :mod:`observer.impact`; the one-contact Poisson closed form is the same LCP)."""
    if law == "newton":
        return exact_lcp(G, [(1 + ei) * gi for ei, gi in zip(e, gamma)], guess)
    if law != "poisson":
        raise ValueError(f"no exact impact map for law {law!r}")
    lam_c = exact_lcp(G, list(gamma), guess)
    Glc = _mv(G, lam_c)
    gamma_c = [g + v for g, v in zip(gamma, Glc)]
    elc = [ei * li for ei, li in zip(e, lam_c)]
    b2 = [gc + v for gc, v in zip(gamma_c, _mv(G, elc))]
    mu = exact_lcp(G, b2)
    return [(1 + ei) * li + mi for ei, li, mi in zip(e, lam_c, mu)]


def exact_pair(law: str, G: flint.fmpq_mat, e: list, g1: list, g2: list) -> dict:
    """Impulses and ``ΔΛᵀΔγ̄`` of a pair, in exact arithmetic (the independent re-check)."""
    L1, L2 = exact_impulse(law, G, g1, e), exact_impulse(law, G, g2, e)
    dL = [a - b for a, b in zip(L1, L2)]
    dg = [a - b for a, b in zip(g1, g2)]
    GdL = _mv(G, dL)
    inner = sum((dl * (d + gd / 2) for dl, d, gd in zip(dL, dg, GdL)), Q0)
    den = (flint.fmpq_mat(len(dg), 1, dg).transpose() * G.solve(flint.fmpq_mat(len(dg), 1, dg)))[0, 0]
    return {"Lambda1": L1, "Lambda2": L2, "inner": inner, "rho": inner / den if den != 0 else Q0}


# ----------------------------------------------------------------------------- pieces
def _maximal(sets: list) -> list:
    ss = sorted({tuple(sorted(int(i) for i in a)) for a in sets if len(a)}, key=len, reverse=True)
    out: list[tuple] = []
    for s in ss:
        if not any(set(s) <= set(t) for t in out):
            out.append(s)
    return out


def _components(G: flint.fmpq_mat, sets: list) -> list:
    """The connected components of the graph of G (edge i–j when G_ij ≠ 0 exactly)
    restricted to each set, each once, largest first."""
    out: dict = {}
    for A in sets:
        left = set(A)
        while left:
            stack, comp = [min(left)], set()
            while stack:
                i = stack.pop()
                if i in comp:
                    continue
                comp.add(i)
                stack.extend(j for j in left if j not in comp and G[i, j] != 0)
            left -= comp
            out.setdefault(tuple(sorted(comp)), None)
    return _maximal(list(out))


def _piece_matrix(law: str, G: flint.fmpq_mat, D: list, J1: tuple, J2: tuple = ()) -> flint.fmpq_mat:
    """The matrix J of Λ = Jγ⁻ on the piece (k×k, k = size of G)."""
    Dm, S1 = _diag(D), _sref(G, J1)
    if law == "newton":
        return -(S1 * Dm)
    S2 = _sref(G, J2)
    return -(Dm * S1) - S2 + S2 * G * Dm * S1


def _quad_form(J: flint.fmpq_mat, G: flint.fmpq_mat) -> flint.fmpq_mat:
    """Q(J) = sym(J + ½ JᵀGJ): q(γ + εd, γ − εd) = 4ε² dᵀQd on the piece."""
    return exact.sym_part(J) + J.transpose() * G * J / 2


def _quad_form_on(G: flint.fmpq_mat, D: list, J1: tuple, J2: tuple, inv_cache: dict):
    """Q of the Poisson piece (J₁, J₂) on U = J₁ ∪ J₂, where all its nonzero entries lie
    (J has rows and columns in U only), with the inverses G_JJ⁻¹ taken from ``inv_cache``."""
    U = sorted(set(J1) | set(J2))
    if not U:
        return None, U
    pos = {i: t for t, i in enumerate(U)}
    u = len(U)

    def S(J):
        out = flint.fmpq_mat(u, u)
        if J:
            H = inv_cache[J]
            for a, i in enumerate(J):
                for c, j in enumerate(J):
                    out[pos[i], pos[j]] = H[a, c]
        return out

    GU, DU = _sub(G, U, U), _diag([D[i] for i in U])
    S1, S2 = S(J1), S(J2)
    DS1 = DU * S1
    Jm = -DS1 - S2 + S2 * GU * DS1
    return _quad_form(Jm, GU), U


def _cone_rows(G: flint.fmpq_mat, J: tuple) -> flint.fmpq_mat:
    """T with z = T b ≥ 0 ⇔ b in the complementary cone of support J (x_J and w_rest)."""
    k = G.nrows()
    rest = [i for i in range(k) if i not in J]
    T = flint.fmpq_mat(k, k)
    if J:
        H = _sub(G, J, J).inv()
        GrJH = _sub(G, rest, J) * H if rest else None
        for a, i in enumerate(J):
            for c, j in enumerate(J):
                T[a, j] = -H[a, c]
        for r, i in enumerate(rest):
            T[len(J) + r, i] = 1
            for c, j in enumerate(J):
                T[len(J) + r, j] = -GrJH[r, c]
    else:
        for r, i in enumerate(rest):
            T[r, i] = 1
    return T


def _interior_pair(G: flint.fmpq_mat, D: list, J1: tuple, J2: tuple, d: list):
    """An exact pair (γ₀ + εd, γ₀ − εd) strictly inside the Poisson piece (J₁, J₂): γ₀ from a
    float LP (max t with every cone coordinate ≥ t), kept only if its coordinates are > 0
    over Q; ε halves the distance to the nearest face. None if no such point is found."""
    from scipy.optimize import linprog
    k = G.nrows()
    T1 = _cone_rows(G, J1)                                   # compression: γ in cone(J₁)
    B = _identity(k) - G * _diag(D) * _sref(G, J1)           # b₂ = (I − G D S₁) γ
    rows = _stack(T1, _cone_rows(G, J2) * B)                 # expansion: b₂ in cone(J₂)
    R = exact.to_array(rows)
    n_r = R.shape[0]
    A_ub = np.hstack([-R, np.ones((n_r, 1))])
    res = linprog(np.r_[np.zeros(k), -1.0], A_ub=A_ub, b_ub=np.zeros(n_r),
                  bounds=[(-1, 1)] * k + [(None, 1)], method="highs")
    if res.status != 0 or not res.x[-1] > 1e-9:
        return None
    g0 = [exact.to_fmpq(v) for v in res.x[:k]]
    z0 = [(rows * flint.fmpq_mat(k, 1, g0))[i, 0] for i in range(n_r)]
    if not all(z > 0 for z in z0):
        return None
    dz = [(rows * flint.fmpq_mat(k, 1, d))[i, 0] for i in range(n_r)]
    ratios = [z / abs(v) for z, v in zip(z0, dz) if v != 0]
    eps = min(ratios) / 2 if ratios else flint.fmpq(1)
    return [a + eps * b for a, b in zip(g0, d)], [a - eps * b for a, b in zip(g0, d)]


def _diag(D):
    k = len(D)
    out = flint.fmpq_mat(k, k)
    for i in range(k):
        out[i, i] = D[i]
    return out


def _identity(k):
    return _diag([flint.fmpq(1)] * k)


def _sref(G, J):
    """S_J = P_J G_JJ⁻¹ P_Jᵀ (k×k, zero outside J)."""
    k = G.nrows()
    out = flint.fmpq_mat(k, k)
    if J:
        H = _sub(G, J, J).inv()
        for a, i in enumerate(J):
            for c, j in enumerate(J):
                out[i, j] = H[a, c]
    return out


def _stack(A, B):
    return flint.fmpq_mat(A.nrows() + B.nrows(), A.ncols(),
                          [A[i, j] for i in range(A.nrows()) for j in range(A.ncols())]
                          + [B[i, j] for i in range(B.nrows()) for j in range(B.ncols())])


def delassus_exact(M: np.ndarray, W: np.ndarray) -> flint.fmpq_mat:
    """``G = WᵀM⁻¹W`` over Q from the float M and W (symmetrized exactly)."""
    Mq, Wq = exact.to_fmpq_mat(0.5 * (np.asarray(M, float) + np.asarray(M, float).T)), exact.to_fmpq_mat(W)
    return exact.sym_part(Wq.transpose() * Mq.solve(Wq))


def decide_a3(law: str, M: np.ndarray, W: np.ndarray, restitution, sets: list, *,
              max_pairs: int = 4096) -> dict:
    """Decide A3 for ``law`` on the given active sets (their maximal ones suffice).

    Returns
    -------
    dict
        ``status``: ``"proved"``, ``"violated"`` or ``"undecided"``; ``pieces`` (number of
        piece matrices checked), ``method``; for ``"violated"`` the exact counterexample:
        ``active_set``, ``piece``, ``gamma1_minus``, ``gamma2_minus`` (lists of fmpq),
        ``Lambda1``, ``Lambda2``, ``inner`` (ΔΛᵀΔγ̄ > 0) and ``rho`` (fmpq); for
        ``"undecided"`` a ``reason``.
    """
    Gf = delassus_exact(M, W)
    e_all = [exact.to_fmpq(v) for v in np.asarray(restitution, float)]
    pieces = 0
    cache: dict = {}
    for A in _components(Gf, _maximal(sets)):
        G = _sub(Gf, A, A)
        e = [e_all[i] for i in A]
        D = [1 + ei for ei in e]
        k = len(A)
        if law == "newton":
            F = _diag([1 / di for di in D])
            N = F * G + G * F - G
            cert = exact.classify_symmetric(N)
            pieces += 2 ** k - 1
            if cert.status != "indefinite":
                continue
            y = flint.fmpq_mat(k, 1, cert.vector)
            dvec = F * G * y
            d = [dvec[i, 0] for i in range(k)]
            ymax = max(abs(v) for v in cert.vector)
            g0 = [-(F * G * flint.fmpq_mat(k, 1, [1] * k))[i, 0] for i in range(k)]   # x = 1 > 0
            eps = 1 / (2 * ymax)
            pair = ([a + eps * b for a, b in zip(g0, d)], [a - eps * b for a, b in zip(g0, d)])
            piece = {"support": list(A)}
        elif law == "poisson":
            if 4 ** k > max_pairs:
                return {"status": "undecided", "pieces": pieces, "method": "piece enumeration",
                        "reason": f"{4 ** k} Poisson pieces on a set of {k} contacts exceed max_pairs = {max_pairs} (the option impact_monotone.exact_max_pairs)"}
            subsets = [c for r in range(k + 1) for c in itertools.combinations(range(k), r)]
            inv_cache = {J: _sub(G, J, J).inv() for J in subsets if J}
            pair = None
            undecided = None
            for J1 in subsets:
                for J2 in subsets:
                    pieces += 1
                    Qm, U = _quad_form_on(G, D, J1, J2, inv_cache)
                    if not U:
                        continue
                    cert = exact.classify_symmetric(-Qm)
                    if cert.status != "indefinite":
                        continue
                    d = [Q0] * k
                    for t, i in enumerate(U):
                        d[i] = cert.vector[t]
                    cand = _interior_pair(G, D, J1, J2, d)
                    if cand is None:
                        undecided = (tuple(A[i] for i in J1), tuple(A[i] for i in J2))
                        continue
                    pair, piece = cand, {"compression_support": [A[i] for i in J1],
                                         "expansion_support": [A[i] for i in J2]}
                    break
                if pair is not None:
                    break
            if pair is None:
                if undecided is not None:
                    return {"status": "undecided", "pieces": pieces, "method": "piece enumeration",
                            "reason": f"piece {undecided} has Q ⋠ 0 but no interior point was found"}
                continue
        else:
            return {"status": "undecided", "pieces": pieces, "method": "none",
                    "reason": f"no exact piece enumeration for law {law!r}"}
        check = exact_pair(law, G, e, pair[0], pair[1])
        if not check["inner"] > 0:                                       # pragma: no cover
            raise AssertionError("A3 counterexample did not survive its exact re-check")
        return {"status": "violated", "pieces": pieces, "active_set": list(A), "piece": piece,
                "gamma1_minus": pair[0], "gamma2_minus": pair[1], "Lambda1": check["Lambda1"],
                "Lambda2": check["Lambda2"], "inner": check["inner"], "rho": check["rho"],
                "method": _method(law)}
    return {"status": "proved", "pieces": pieces, "method": _method(law)}


def _method(law: str) -> str:
    if law == "newton":
        return "exact LDLᵀ of N_A = FG_A + G_AF − G_A ⪰ 0 (F = diag(1/(1+e))) per maximal set"
    return "exact LDLᵀ of Q(J) ⪯ 0 for every (compression, expansion) support pair"
