"""Exact verdicts of proofs_checks (issue 24, part A): model assumptions, projection PSD and A3
decided in rational arithmetic on the given float data.

References are computed here independently with :class:`fractions.Fraction` (determinants,
leading minors, brute-force LCP solutions), never with the code under test. The near-miss
matrices are chosen so that float64 eigenvalues are at the round-off level (relative
~1e-17), where numpy's ``eigvalsh`` may report either sign.
"""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest

import proofs_checks as pc
from observer import ImpactLaw
from proofs_checks import cli, exact, pieces

D = 2.0 ** -52
E_BAD = [0.1, 0.95]


def frac(A):
    return [[Fraction(float(x)) for x in row] for row in np.atleast_2d(np.asarray(A, dtype=float))]


def det(A):
    """Exact determinant by Laplace expansion (small matrices)."""
    n = len(A)
    if n == 1:
        return A[0][0]
    return sum((-1) ** j * A[0][j] * det([row[:j] + row[j + 1:] for row in A[1:]]) for j in range(n))


def leading_minors(A):
    F = frac(A)
    return [det([row[:k] for row in F[:k]]) for k in range(1, len(F) + 1)]


def inv(A):
    """Exact inverse by Gauss–Jordan on Fractions."""
    n = len(A)
    M = [list(row) + [Fraction(int(i == j)) for j in range(n)] for i, row in enumerate(A)]
    for c in range(n):
        p = next(r for r in range(c, n) if M[r][c] != 0)
        M[c], M[p] = M[p], M[c]
        M[c] = [v / M[c][c] for v in M[c]]
        for r in range(n):
            if r != c and M[r][c] != 0:
                M[r] = [a - M[r][c] * b for a, b in zip(M[r], M[c])]
    return [row[n:] for row in M]


def matvec(A, x):
    return [sum(a * b for a, b in zip(row, x)) for row in A]


def quad(A, x):
    return sum(a * b for a, b in zip(x, matvec(A, x)))


# ----------------------------------------------------------------------------- near-miss matrices
TWINS = {
    # 3x3: [[1,2,3],[2,5,7],[3,7,10]] is singular; ±8 ulp(1) on the corner decides (det = ±8·2⁻⁵²)
    "spd3": np.array([[1.0, 2.0, 3.0], [2.0, 5.0, 7.0], [3.0, 7.0, 10.0 + 8 * D]]),
    "indef3": np.array([[1.0, 2.0, 3.0], [2.0, 5.0, 7.0], [3.0, 7.0, 10.0 - 8 * D]]),
    # 2x2: det = 2⁻⁵² > 0, and det = −2⁻¹⁰⁶ < 0 (relative λ_min ≈ 5.6e-17 and ≈ −3e-33)
    "spd2": np.array([[1.0, 1.0], [1.0, 1.0 + D]]),
    "indef2": np.array([[1.0, 1.0 - D / 2], [1.0 - D / 2, 1.0 - D]]),
}


@pytest.mark.parametrize("name", sorted(TWINS))
def test_near_miss_stiffness_classified_exactly(name):
    """K with relative smallest eigenvalue at the float64 round-off level: proved SPD when all
    leading minors are positive over Q (Sylvester), violated with an exact vector x,
    xᵀKx < 0, otherwise, whatever numpy's eigvalsh says."""
    K = TWINS[name]
    minors = leading_minors(K)
    spd = all(mk > 0 for mk in minors)
    assert spd is name.startswith("spd")                    # the reference, over Q
    assert abs(np.linalg.eigvalsh(K)[0]) < 1e-15 * np.linalg.eigvalsh(K)[-1]   # a real near miss
    r = pc.check_stiffness_spd(K)
    if spd:
        assert r.passed is True and r.evidence == "proved" and r.margin > 0
        if r.witness["lambda_min"] <= 0:                     # numpy has the wrong sign: said so
            assert "round-off" in r.reason
    else:
        assert r.passed is False and r.evidence == "violated" and r.margin < 0
        x = [Fraction(v) for v in r.witness["exact_vector_rational"]]
        assert quad(frac(K), x) < 0                          # the witness, re-checked here
    m = pc.check_mass_spd(K)
    assert (m.passed, m.evidence) == ((True, "proved") if spd else (False, "violated"))


def test_classify_semidefinite_and_indefinite_certificates():
    """Exact LDLᵀ with diagonal pivoting: zero pivots with a nonzero off-diagonal are
    indefinite (e_i ∓ e_j), an all-zero Schur complement is semidefinite with a kernel vector."""
    cases = {"semidefinite": [[1.0, 2.0], [2.0, 4.0]], "indefinite": [[0.0, 1.0], [1.0, 0.0]],
             "definite": [[2.0, -1.0], [-1.0, 2.0]]}
    for status, A in cases.items():
        cert = exact.classify_symmetric(exact.to_fmpq_mat(A))
        assert cert.status == status
        if status != "definite":
            x = [Fraction(int(v.p), int(v.q)) for v in cert.vector]
            value = quad(frac(A), x)
            assert (value < 0) if status == "indefinite" else (value == 0 and matvec(frac(A), x) == [0, 0])
    zero = exact.classify_symmetric(exact.to_fmpq_mat(np.zeros((2, 2))))
    assert zero.status == "semidefinite"
    # the LDLᵀ pivots are the ratios of consecutive leading principal minors (reference: Laplace)
    rng = np.random.default_rng(7)
    X = rng.standard_normal((5, 5))
    Y = X @ X.T + 0.1 * np.eye(5)
    for A in (TWINS["spd3"], 0.5 * (Y + Y.T)):
        cert = exact.classify_symmetric(exact.to_fmpq_mat(A))
        prods = list(itertools.accumulate((Fraction(int(p.p), int(p.q)) for p in cert.pivots),
                                          lambda a, b: a * b))
        assert cert.status == "definite" and prods == leading_minors(A)


def test_ball_arithmetic_path_for_large_matrices():
    """Beyond exact_max_n the verdict comes from the arb congruence certificate (definite) or
    an exactly re-checked eigenvector (indefinite)."""
    rng = np.random.default_rng(3)
    X = rng.standard_normal((6, 6))
    A = X @ X.T + 0.5 * np.eye(6)
    cert = exact.classify_float(A, exact_max_n=3)
    assert cert.status == "definite" and cert.method.startswith("arb ball")
    B = A - (np.linalg.eigvalsh(A)[0] + 0.1) * np.eye(6)       # one negative eigenvalue
    cert = exact.classify_float(B, exact_max_n=3)
    assert cert.status == "indefinite"
    assert quad(frac(B), [Fraction(int(v.p), int(v.q)) for v in cert.vector]) < 0


# ----------------------------------------------------------------------------- projection PSD
@pytest.mark.parametrize("psd", [True, False])
def test_projection_psd_near_miss(psd):
    """K = diag(1, −1, 1) (indefinite, well conditioned) and w₁ = (1, 1 − 2⁻⁵³, 0) or its swap:
    L₁₁ = w₁ᵀK⁻¹w₁ = ±(2⁻⁵² − 2⁻¹⁰⁶), a sign at the round-off level. Proved for all 3 sets,
    or violated with z, zᵀL_I⁻¹z < 0, re-checked here with Fractions."""
    a, b = (1.0, 1.0 - D / 2) if psd else (1.0 - D / 2, 1.0)
    K = np.diag([1.0, -1.0, 1.0])
    W = np.array([[a, 0.0], [b, 0.0], [0.0, 1.0]])
    r = pc.check_projection_psd(K, W, rng=np.random.default_rng(0))
    L = [[sum(Fraction(W[r_, i]) * Fraction(W[r_, j]) / Fraction(K[r_, r_]) for r_ in range(3)) for j in range(2)]
         for i in range(2)]
    assert (L[0][0] > 0) is psd                                # the reference
    if psd:
        assert r.passed is True and r.evidence == "proved" and r.witness["exact_sets_proved"] == 3
        return
    assert r.passed is False and r.evidence == "violated" and r.margin < 0
    I = r.witness["exact_failing_set"]
    LI = [[L[i][j] for j in I] for i in I]
    z = [Fraction(r.witness["exact_vector_rational"][i]) for i in I]
    assert quad(inv(LI), z) < 0 and r.witness["exact_zPz"] < 0


def test_projection_psd_counts_every_active_set():
    sc = pc.load("rocking_chain", {"param.N": 2})          # m = 4: 15 sets, each factored
    r = pc.check_projection_psd(sc.system.K, sc.system.W, rng=np.random.default_rng(0))
    assert r.evidence == "proved" and r.witness["exact_sets_proved"] == 15
    assert r.witness["exact_method"].startswith("exact LDLᵀ of L_I over Q for each of the 15")
    r = pc.check_projection_psd(sc.system.K, sc.system.W, rng=np.random.default_rng(0), exact_exhaustive_up_to=2)
    assert r.evidence == "proved" and "principal submatrix" in r.witness["exact_method"]


# ----------------------------------------------------------------------------- A3
@pytest.fixture(scope="module")
def pair():
    """Two coupled contacts: the corners of one rocking block (off-diagonal G)."""
    return pc.load("rocking_chain", {"param.N": 1}).system


def lcp_bruteforce(G, b):
    """The unique solution of 0 ≤ Gx + b ⊥ x ≥ 0 (G SPD) by trying every support."""
    k = len(b)
    for r in range(k + 1):
        for J in itertools.combinations(range(k), r):
            x = [Fraction(0)] * k
            if J:
                sol = matvec(inv([[G[i][j] for j in J] for i in J]), [-b[i] for i in J])
                for t, i in enumerate(J):
                    x[i] = sol[t]
            w = [a + c for a, c in zip(matvec(G, x), b)]
            if all(v >= 0 for v in x) and all(v >= 0 for v in w):
                return x
    raise AssertionError("no LCP solution")


def impulse_ref(law, G, g, e):
    if law == "newton":
        return lcp_bruteforce(G, [(1 + ei) * gi for ei, gi in zip(e, g)])
    lc = lcp_bruteforce(G, g)
    gc = [a + b for a, b in zip(g, matvec(G, lc))]
    mu = lcp_bruteforce(G, [a + b for a, b in zip(gc, matvec(G, [ei * li for ei, li in zip(e, lc)]))])
    return [(1 + ei) * li + mi for ei, li, mi in zip(e, lc, mu)]


def delassus_ref(system):
    M, W = frac(system.M), frac(system.W)
    MiW = [list(col) for col in zip(*[matvec(inv(M), list(c)) for c in zip(*W)])]
    return [[sum(W[r][i] * MiW[r][j] for r in range(len(W))) for j in range(len(W[0]))] for i in range(len(W[0]))]


@pytest.mark.parametrize("law", ["newton", "poisson"])
@pytest.mark.parametrize("e", [E_BAD, [1.0, 1.0 - D]])
def test_a3_violated_with_exact_witness(pair, law, e):
    """Per-contact restitution on coupled contacts, including the near miss e = (1, 1 − 2⁻⁵²)
    whose violation (ρ ~ 1e-17) no float search can see: violated, and the rational witness
    pair really violates eq. (6) when recomputed here by brute-force LCPs over Q."""
    r = pc.check_impact_monotone(pair, ImpactLaw.build(law, e, 2), rng=np.random.default_rng(0),
                                 samples=4, local_samples=4, adversarial_sets=0)
    assert r.passed is False and r.evidence == "violated" and r.margin < 0
    w = r.witness
    G = delassus_ref(pair)
    ef = [Fraction(float(v)) for v in e]
    g1 = [Fraction(s) for s in w["exact_gamma1_minus_rational"]]
    g2 = [Fraction(s) for s in w["exact_gamma2_minus_rational"]]
    L1, L2 = impulse_ref(law, G, g1, ef), impulse_ref(law, G, g2, ef)
    dL = [a - b for a, b in zip(L1, L2)]
    dgbar = [a - b + c / 2 for a, b, c in zip(g1, g2, matvec(G, dL))]
    inner = sum(a * b for a, b in zip(dL, dgbar))
    assert inner > 0 and inner == Fraction(w["exact_inner_product_rational"])


@pytest.mark.parametrize("law", ["newton", "poisson"])
@pytest.mark.parametrize("e", [0.0, 0.7, 1.0])
def test_a3_proved_for_global_restitution(pair, law, e):
    r = pc.check_impact_monotone(pair, ImpactLaw.build(law, e, 2), rng=np.random.default_rng(0),
                                 samples=4, local_samples=4, adversarial_sets=0)
    assert r.passed is True and r.evidence == "proved" and r.margin >= 0
    assert r.witness["exact_pieces"] == {law: 3 if law == "newton" else 16}


def test_a3_proved_on_four_contacts_and_newton_criterion():
    """Two blocks, four contacts: all 4⁴ Poisson pieces and the Newton matrix N = FG + GF − G
    (global e: N = (1 − e)/(1 + e) G, checked against the reference G)."""
    s = pc.load("rocking_chain", {"param.N": 2}).system
    for law, npieces in (("poisson", 256), ("newton", 15)):
        d = pieces.decide_a3(law, s.M, s.W, [0.9] * 4, [list(range(4))])
        assert d["status"] == "proved" and d["pieces"] == npieces


def test_sampled_counterexample_rechecked_exactly(pair):
    """Without the exact decision the search is 'sampled'; its counterexample is re-checked
    over Q (violated), and a 'counterexample' that is only round-off (forced here by a
    negative tolerance: the worst pair is a separating one, ΔΛ = 0 exactly) is not one."""
    bad = pc.check_impact_monotone(pair, ImpactLaw.build("newton", E_BAD, 2), rng=np.random.default_rng(0),
                                   samples=4, local_samples=16, adversarial_sets=0, exact=False)
    assert bad.passed is False and bad.evidence == "violated" and bad.witness["exact_inner_product"] > 0
    good = pc.check_impact_monotone(pair, ImpactLaw.build("newton", 0.7, 2), rng=np.random.default_rng(0),
                                    samples=4, local_samples=4, adversarial_sets=0, exact=False, tolerance=-1.0)
    assert good.passed is True and good.evidence == "sampled" and "round-off" in good.reason
    assert good.witness["exact_inner_product"] <= 0
    # the same float 'failure' with the exact decision on: proved, the sampled ρ called round-off
    proved = pc.check_impact_monotone(pair, ImpactLaw.build("newton", 0.7, 2), rng=np.random.default_rng(0),
                                      samples=4, local_samples=4, adversarial_sets=0, tolerance=-1.0)
    # decided exactly first: the float search (and its spurious failure) is not run at all
    assert proved.passed is True and proved.evidence == "proved" and proved.witness["evaluations"] == 0


# ----------------------------------------------------------------------------- command line
def test_cli_acceptance(capsys):
    """double_mass: the assumption checks, projection PSD and A3 proved, exit 0; per-contact
    restitution on two contacts: A3 violated, exit 1."""
    mine = "mass_spd,stiffness_spd,damping_pd,constraints_independent,impact_monotone,projection_psd"
    assert cli.main(["double_mass", "--only", mine]) == 0
    out = capsys.readouterr().out
    assert out.count(" proved ") == 6 and "(6 proved, 0 bounded, 0 sampled, 0 violated)" in out
    code = cli.main(["rocking_chain", "--set", "param.N=1", "--set", "impact.restitution=[0.1, 0.95]",
                     "--only", "impact_monotone", "--option", "impact_monotone.adversarial_sets=0"])
    text = capsys.readouterr()
    assert code == 1 and "impact_monotone  FAIL    violated" in text.out


def test_a3_uncoupled_components_decided_separately(pair):
    """G block diagonal: A3 holds iff it holds on each component. Ten independent contacts
    with alternating restitution are monotone (products of scalar maps; 10·4 Poisson
    pieces, not 4¹⁰); a rocking block plus a free contact is monotone when the block's two
    coefficients agree, whatever the third, and violated on the block otherwise."""
    M, W = np.diag([2.0, 4.0, 3.0, 5.0, 1.0, 2.0, 7.0, 3.0, 2.0, 1.0]), np.eye(10)
    d = pieces.decide_a3("poisson", M, W, [0.1, 0.95] * 5, [list(range(10))])
    assert d["status"] == "proved" and d["pieces"] == 40
    n, m = pair.M.shape[0], pair.m
    M3 = np.zeros((n + 1, n + 1))
    M3[:n, :n], M3[n, n] = pair.M, 2.0
    W3 = np.zeros((n + 1, m + 1))
    W3[:n, :m], W3[n, m] = pair.W, 1.0
    assert pieces.decide_a3("poisson", M3, W3, [0.7, 0.7, 0.2], [[0, 1, 2]])["status"] == "proved"
    bad = pieces.decide_a3("newton", M3, W3, [0.1, 0.95, 0.2], [[0, 1, 2]])
    assert bad["status"] == "violated" and bad["active_set"] == [0, 1] and bad["inner"] > 0


def test_a3_beyond_the_enumeration_budget_is_sampled(pair):
    """A Poisson set with more pieces than exact_max_pairs is not decided exactly: the check
    says so and falls back to the search, labelled 'sampled'."""
    d = pieces.decide_a3("poisson", pair.M, pair.W, [0.7, 0.7], [[0, 1]], max_pairs=15)
    assert d["status"] == "undecided" and "16 Poisson pieces" in d["reason"]
    r = pc.check_impact_monotone(pair, ImpactLaw.build("poisson", 0.7, 2), rng=np.random.default_rng(0),
                                 samples=4, local_samples=4, adversarial_sets=0, exact_max_pairs=15)
    assert r.passed is True and r.evidence == "sampled" and "exact_pieces" not in r.witness
    assert "exceed max_pairs = 15" in r.witness["exact_undecided"]


def test_a3_newton_decided_beyond_ten_contacts():
    """Six blocks, twelve contacts: Newton is decided for any m by N = FG + GF − G on the full
    set (covering all 2¹² − 1 supports); one differing coefficient makes it violated."""
    s = pc.load("rocking_chain", {"param.N": 6}).system
    kw = dict(rng=np.random.default_rng(0), samples=2, local_samples=2, adversarial_sets=0)
    r = pc.check_impact_monotone(s, ImpactLaw.build("newton", 0.9, 12), **kw)
    assert r.passed is True and r.evidence == "proved" and r.witness["exact_pieces"] == {"newton": 4095}
    r = pc.check_impact_monotone(s, ImpactLaw.build("newton", [0.9] * 11 + [0.5], 12), **kw)
    assert r.passed is False and r.evidence == "violated" and r.witness["exact_inner_product"] > 0
    r = pc.check_impact_monotone(s, ImpactLaw.build("poisson", 0.9, 12), **kw)
    assert r.evidence == "sampled"                                     # Poisson beyond m = 10
