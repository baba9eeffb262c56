"""proofs_checks.monotonicity (assumption A3, paper eq. (6)) on two-contact systems: the
verdicts on a monotone map (global restitution), a non-monotone one (e = (0.1, 0.95) on the
coupled corners of a rocking block, whose worst ratio is the analytic generalized
eigenvalue) with a near miss, every witness entry recomputed with an independent LCP
solver, the sample and search bookkeeping counted from the documented formulas, and the
helpers (Delassus matrix, candidate sets, sampling distributions) against their
definitions. Written against the mutation run of ``monotonicity.py``
(``tests/mutants/proofs_checks_monotonicity.md``). About 2 s.
"""

from __future__ import annotations

import inspect
import itertools
import warnings

import numpy as np
import pytest
import scipy.linalg as sla

import observer
import proofs_checks as pc
from observer import ImpactLaw, LinearSystem
from observer.model import Harmonic
from observer.impact import newton_impact, poisson_impact
from proofs_checks import monotonicity as mo


def sampler(*args, **kw):
    """The float search of impact_monotone alone (``exact=False``): what these tests examine;
    by default the check decides exactly first and skips it (issue 36 item 3)."""
    return pc.check_impact_monotone(*args, exact=False, **kw)

EPS = np.finfo(float).eps
E_BAD = np.array([0.1, 0.95])
LEMKE = observer.contact.get_solver("lemke").solve


def linear_system(M, W):
    n, m = np.shape(W)
    return LinearSystem(np.asarray(M, dtype=float), np.zeros((n, n)), np.eye(n), np.asarray(W, dtype=float),
                        Harmonic.build("forcing", n), Harmonic.build("gap", m))


def rng(seed: int = 0) -> np.random.Generator:
    return np.random.default_rng(seed)


@pytest.fixture(scope="module")
def pair():
    """Two coupled contacts: the corners of one rocking block (off-diagonal G)."""
    return pc.load("rocking_chain", {"param.N": 1}).system


@pytest.fixture(scope="module")
def uncoupled():
    """Two independent masses, one contact each: G is diagonal (diag(1/2, 1/4))."""
    return linear_system(np.diag([2.0, 4.0]), np.eye(2))


def delassus_ref(system, active):
    W = system.W[:, active]
    return W.T @ np.linalg.solve(system.M, W)


def analytic_rho(G, e):
    """Worst ratio of the all-active Newton region: largest generalized eigenvalue of
    −½ sym((1+E)G⁻¹(1−E)) against G⁻¹."""
    Gi, E, I = np.linalg.inv(G), np.diag(e), np.eye(len(e))
    A = (I + E) @ Gi @ (I - E)
    return sla.eigh(-0.25 * (A + A.T), Gi, eigvals_only=True)[-1]


def ratio_ref(G, law_fn, e, g1, g2):
    """ρ of the module docstring recomputed with Lemke, with its round-off allowance."""
    L1, L2 = law_fn(G, g1, e, LEMKE), law_fn(G, g2, e, LEMKE)
    gb1, gb2 = g1 + 0.5 * G @ L1, g2 + 0.5 * G @ L2
    inner = (L1 - L2) @ (gb1 - gb2)
    w = np.linalg.eigvalsh(G)
    nL = np.linalg.norm(L1) + np.linalg.norm(L2)
    allowance = 8 * EPS * (w[-1] / w[0]) * nL * (np.linalg.norm(gb1) + np.linalg.norm(gb2) + w[-1] * nL)
    Gi = np.linalg.inv(G)
    d = g1 - g2
    denom = d @ Gi @ d + 1e-12 * (g1 @ Gi @ g1 + g2 @ Gi @ g2)
    return (inner - allowance) / denom, dict(L1=L1, L2=L2, gb1=gb1, gb2=gb2, inner=inner, allowance=allowance)


def problem(system, active, e, law="newton", solver="pivoting"):
    G = mo.delassus(system, np.asarray(active))
    return mo._SetProblem(np.asarray(active), G, sla.cho_factor(G), np.asarray(e)[active], law,
                          observer.contact.get_solver(solver).solve)


# ----------------------------------------------------------------------------- helpers
def test_delassus_is_the_symmetric_contact_mass(pair):
    for a in ([0], [1], [0, 1], [1, 0]):
        G = mo.delassus(pair, np.array(a))
        np.testing.assert_allclose(G, delassus_ref(pair, a), rtol=1e-13, atol=1e-15)
        assert np.array_equal(G, G.T)
    assert abs(mo.delassus(pair, np.array([0, 1]))[0, 1]) > 0.5


def test_add_set_sorts_and_deduplicates():
    sets = {}
    mo.add_set(sets, [2, 0, 2])
    mo.add_set(sets, np.array([0, 2]))
    mo.add_set(sets, [])
    mo.add_set(sets, [1])
    mo.add_set(sets, np.array([3.0, 1.0]))            # indices read back as floats (e.g. from JSON)
    assert [s.tolist() for s in sets.values()] == [[0, 2], [1], [1, 3]]
    assert all(s.dtype == np.int64 for s in sets.values())


def test_candidate_sets_exhaustive_in_order():
    got = [s.tolist() for s in mo.candidate_sets(3, rng())]
    assert got == [[0], [1], [2], [0, 1], [0, 2], [1, 2], [0, 1, 2]]
    # the bound is inclusive; visited sets come after, once
    got = [s.tolist() for s in mo.candidate_sets(3, rng(), exhaustive_up_to=3, visited=[[2, 1], [0, 2, 1]])]
    assert len(got) == 7 and got[-1] == [0, 1, 2]
    assert len(mo.candidate_sets(4, rng(), exhaustive_up_to=4, random_sets=0)) == 15
    assert len(mo.candidate_sets(4, rng(), exhaustive_up_to=3, random_sets=0)) == 4 + 6 + 1


def test_candidate_sets_beyond_the_exhaustive_bound():
    m = 6
    got = [s.tolist() for s in mo.candidate_sets(m, rng(4), exhaustive_up_to=5, random_sets=40,
                                                  visited=[np.array([5, 3]), np.array([5, 4, 0, 1])],
                                                  min_random_size=4)]
    head = [[i] for i in range(m)] + [list(c) for c in itertools.combinations(range(m), 2)] + [list(range(m))]
    assert got[:len(head)] == head
    rest = got[len(head):]
    assert [0, 1, 4, 5] in rest and rest == sorted(rest, key=rest.index)
    assert all(4 <= len(s) < m for s in rest)            # sizes from min_random_size; the full set already in
    assert {len(s) for s in rest} == {4, 5}
    assert all(s == sorted(s) and len(set(s)) == len(s) for s in rest)
    # default: random sizes from 3
    got = mo.candidate_sets(12, rng(1), random_sets=60)
    sizes = {s.size for s in got[12 + 66 + 1:]}
    assert min(sizes) == 3 and max(sizes) <= 11
    assert len(mo.candidate_sets(12, rng(1), random_sets=0)) == 12 + 66 + 1


# ----------------------------------------------------------------------------- ρ of one pair
@pytest.mark.parametrize("law,fn", [("newton", newton_impact), ("poisson", poisson_impact)])
def test_rho_recomputed(pair, law, fn):
    prob = problem(pair, [0, 1], E_BAD, law)
    G = delassus_ref(pair, [0, 1])
    g1, g2 = np.array([-1.0, -0.2]), np.array([-0.3, -0.9])
    r, info = prob.rho(g1, g2)
    ref, q = ratio_ref(G, fn, E_BAD, g1, g2)
    assert q["allowance"] > 0
    assert r == pytest.approx(ref, rel=1e-9, abs=1e-14)
    np.testing.assert_allclose(info["Lambda1"], q["L1"], rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(info["Lambda2"], q["L2"], rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(info["gamma1_bar"], q["gb1"], rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(info["gamma2_bar"], q["gb2"], rtol=1e-10, atol=1e-14)
    assert info["inner_product"] == pytest.approx(q["inner"], rel=1e-9)
    assert info["roundoff_allowance"] == pytest.approx(q["allowance"], rel=1e-6)
    assert info["gamma1_minus"] is g1 and info["gamma2_minus"] is g2
    assert info["impulses_differ"] is True
    assert prob.evals == 2


def test_rho_of_separating_and_coincident_pairs(pair):
    prob = problem(pair, [0, 1], [0.5, 0.5])
    r, info = prob.rho(np.array([1.0, 2.0]), np.array([0.5, 0.1]))     # both separating: Λ = 0
    assert r == 0.0 and info["impulses_differ"] is False and info["inner_product"] == 0.0
    assert info["roundoff_allowance"] == 0.0
    assert prob.rho(np.zeros(2), np.zeros(2)) == (0.0, {})
    # coincident impacting pair: the regularized denominator keeps the ratio at round-off
    g = np.array([-1.0, -0.5])
    r, info = prob.rho(g, g.copy())
    assert r <= 0.0 and info["impulses_differ"] is False


def test_set_problem_metric(pair):
    prob = problem(pair, [0, 1], E_BAD)
    G = delassus_ref(pair, [0, 1])
    np.testing.assert_allclose(prob.Ginv, np.linalg.inv(G), rtol=1e-10)
    w = np.linalg.eigvalsh(G)
    assert prob.cond == pytest.approx(w[1] / w[0], rel=1e-12) and prob.norm == pytest.approx(w[1], rel=1e-12)
    assert prob.law_obj.law == "newton" and list(prob.law_obj.restitution) == list(E_BAD)
    assert list(prob.local) == [0, 1]


# ----------------------------------------------------------------------------- sampling
def test_sample_distributions(pair):
    prob = problem(pair, [0, 1], E_BAD)
    pairs = mo._samples(prob, rng(2), 40)
    assert len(pairs) == 40 and all(a.shape == (2,) and b.shape == (2,) for a, b in pairs)
    approach = pairs[1::4]
    assert all(np.all(a <= 0) and np.all(b <= 0) for a, b in approach)
    for a, b in pairs[2::4]:                           # nearby pairs
        assert np.linalg.norm(b - a) == pytest.approx(1e-3 * np.linalg.norm(a), rel=1e-9)
    assert any(np.all(a <= 0) for a, _ in pairs[2::4]) and any(np.any(a > 0) for a, _ in pairs[2::4])
    for a, b in pairs[3::4]:                           # against rest
        assert np.array_equal(b, np.zeros(2))
    free = np.array([p for pr in pairs[0::4] for p in pr])
    assert np.any(free > 0) and np.any(free < 0)
    # contact velocities of standard normal u: covariance G (40 draws of z per kind-0 pair... check scale)
    z = np.array([p for pr in mo._samples(prob, rng(3), 4000)[0::4] for p in pr])
    np.testing.assert_allclose(np.cov(z.T), delassus_ref(pair, [0, 1]), rtol=0.15, atol=0.03)


def test_sample_distributions_of_one_contact(pair):
    """One contact, G = g: nearby pairs start half the time from an approaching velocity
    (−|z|), half from z ~ N(0, g); the pair against rest is −|z₁| + 0.3 z₂, of mean
    −√(2g/π) and variance g(1 − 2/π + 0.09)."""
    prob = problem(pair, [0], E_BAD)
    g = float(delassus_ref(pair, [0])[0, 0])
    pairs = mo._samples(prob, rng(11), 8000)
    near = np.array([a[0] for a, _ in pairs[2::4]])
    assert np.mean(near <= 0) == pytest.approx(0.75, abs=0.04)
    rest = np.array([a[0] for a, _ in pairs[3::4]])
    assert np.mean(rest) == pytest.approx(-np.sqrt(2 * g / np.pi), rel=0.05)
    assert np.var(rest) == pytest.approx(g * (1 - 2 / np.pi + 0.09), rel=0.1)


def test_local_pairs_follow_the_worst_direction(pair):
    prob = problem(pair, [0, 1], E_BAD)
    assert mo._local_pairs(prob, rng(), 0) == []
    one = mo._local_pairs(prob, rng(), 1)
    assert len(one) == 1 and np.linalg.norm(one[0][0] - one[0][1]) == pytest.approx(2e-4, rel=1e-9)
    prob.evals = 0
    assert mo._local_pairs(problem(pair, [1], E_BAD), rng(), 5) == []
    count = 16
    out = mo._local_pairs(prob, rng(5), count)
    assert len(out) == count and prob.evals == 4 * count
    centres = np.array([(a + b) / 2 for a, b in out])
    np.testing.assert_allclose(np.linalg.norm(centres, axis=1), 1.0, rtol=1e-12)
    ang = np.sort(np.mod(np.arctan2(centres[:, 1], centres[:, 0]), 2 * np.pi))
    np.testing.assert_allclose(np.diff(ang), 2 * np.pi / count, rtol=1e-9)
    for a, b in out:
        assert np.linalg.norm(a - b) == pytest.approx(2e-4, rel=1e-9)
    # in the all-active region (both Newton impulses positive) the pair attains the analytic ratio
    G = delassus_ref(pair, [0, 1])
    rho_star = analytic_rho(G, E_BAD)
    inside = [(a, b) for a, b in out
              if np.all(newton_impact(G, (a + b) / 2, E_BAD, LEMKE) > 1e-3)]
    assert inside
    for a, b in inside:
        # (the denominator's 1e-12 regularization costs ~5e-5 relative at a pair 2e-4 apart,
        # and a base point near a region's edge a little more)
        assert ratio_ref(G, newton_impact, E_BAD, a, b)[0] == pytest.approx(rho_star, rel=1e-3)


def test_local_pairs_three_contacts():
    sys3 = linear_system(np.diag([1.0, 2.0, 3.0]), [[1.0, 0.3, 0.0], [0.0, 1.0, 0.2], [0.1, 0.0, 1.0]])
    prob = problem(sys3, [0, 1, 2], [0.2, 0.9, 0.5])
    out = mo._local_pairs(prob, rng(1), 6)
    assert len(out) == 6 and prob.evals == 6 * 6
    for a, b in out:
        assert np.linalg.norm((a + b) / 2) == pytest.approx(1.0, rel=1e-12)
        assert np.linalg.norm(a - b) == pytest.approx(2e-4, rel=1e-9)


# ----------------------------------------------------------------------------- the check
@pytest.mark.parametrize("law", ["newton", "poisson"])
def test_global_restitution_passes(pair, law):
    r = sampler(pair, ImpactLaw.build(law, 0.7, 2), rng=rng(1), samples=8,
                                 local_samples=8, adversarial_sets=1, starts=1, maxiter=40)
    assert r.passed is True and r.name == "impact_monotone" and r.equation == "A3, Definition 1, eq. (6)"
    assert r.witness["max_rho"] <= 1e-9 and r.margin == -r.witness["max_rho"]
    assert r.witness["max_rho_impacting_pairs"] <= 1e-9
    assert r.witness["sets_checked"] == 3 and r.witness["largest_set"] == 2
    assert r.witness["law"] == law and r.reason == ""
    # impacting pairs of a strictly dissipative map (e < 1) have ρ < 0: the sup 0 is only
    # attained by separating pairs
    assert -1.0 < r.witness["max_rho_impacting_pairs"] < 0.0
    assert all(k in r.witness for k in r.summary_keys)
    assert "max_rho_per_law" not in r.witness


@pytest.mark.parametrize("law,fn", [("newton", newton_impact), ("poisson", poisson_impact)])
def test_per_contact_counterexample_witness(pair, law, fn):
    G = delassus_ref(pair, [0, 1])
    rho_star = analytic_rho(G, E_BAD)
    r = pc.check_impact_monotone(pair, ImpactLaw.build(law, E_BAD, 2), rng=rng(0), samples=8,
                                 local_samples=48, adversarial_sets=1, starts=1, maxiter=60, exact=False)
    w = r.witness
    assert r.passed is False and r.reason == "per-contact restitution: the impact map is not monotone on coupled contacts"
    assert w["max_rho"] == pytest.approx(rho_star, rel=1e-3) and r.margin == -w["max_rho"]
    assert w["max_rho"] <= rho_star * (1 + 1e-6)
    assert w["active_set"] == [0, 1] and w["restitution"] == list(E_BAD) and w["law"] == law
    np.testing.assert_allclose(w["G"], G, rtol=1e-12)
    ref, q = ratio_ref(G, fn, E_BAD, np.asarray(w["gamma1_minus"]), np.asarray(w["gamma2_minus"]))
    assert ref == pytest.approx(w["max_rho"], rel=1e-8)
    assert q["inner"] > 0 and w["inner_product"] == pytest.approx(q["inner"], rel=1e-8)
    np.testing.assert_allclose(w["Lambda1"], q["L1"], rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(w["gamma2_bar"], q["gb2"], rtol=1e-9, atol=1e-13)
    assert w["max_rho_impacting_pairs"] == w["max_rho"]
    assert w["found_by"] in ("random sample", "adversarial search")
    assert w["sets_checked"] == 3
    assert r.summary_keys == ("max_rho", "law", "active_set", "restitution", "gamma1_minus", "gamma2_minus",
                              "inner_product", "found_by", "max_rho_impacting_pairs", "sets_checked")
    assert all(k in w for k in r.summary_keys)


def test_per_contact_near_miss(pair):
    law = ImpactLaw.build("newton", E_BAD, 2)
    rho_star = analytic_rho(delassus_ref(pair, [0, 1]), E_BAD)
    for factor, ok in ((0.999, False), (1.001, True)):
        r = pc.check_impact_monotone(pair, law, rng=rng(), active_sets=[np.array([0, 1])], samples=4,
                                     local_samples=16, adversarial_sets=0, tolerance=factor * rho_star,
                                     exact=False)
        assert r.passed is ok, (factor, r.witness["max_rho"])
        assert r.tolerance == factor * rho_star
        assert (r.reason != "") is (not ok)
        assert r.witness["found_by"] == "random sample" and r.witness["sets_checked"] == 1


def test_adversarial_search_goes_to_the_most_promising_set(pair):
    """Of the three sets, the search goes to the one with the largest sampled ρ (the coupled
    pair, sampled at 0.014 here) and climbs to ρ*; no optimizer warning (options all known)."""
    law = ImpactLaw.build("newton", E_BAD, 2)
    rho_star = analytic_rho(delassus_ref(pair, [0, 1]), E_BAD)
    kw = dict(active_sets=[[0], [1], [0, 1]], samples=4, local_samples=0)
    r0 = sampler(pair, law, rng=rng(3), adversarial_sets=0, **kw)
    assert 0.0 < r0.witness["max_rho"] < 0.7 * rho_star and r0.witness["active_set"] == [0, 1]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r1 = sampler(pair, law, rng=rng(3), adversarial_sets=1, starts=1, maxiter=400, **kw)
    assert r1.witness["max_rho"] == pytest.approx(rho_star, rel=1e-6)
    assert r1.witness["found_by"] == "adversarial search" and r1.witness["active_set"] == [0, 1]
    # ranked by sampled ρ first, coupling second: here the contact-1 singleton sampled the
    # largest ρ (< 0), so the search goes there (not to the more strongly coupled pair)
    r2 = sampler(pair, law, rng=rng(0), active_sets=[[0], [1], [0, 1]], samples=2,
                                  local_samples=0, adversarial_sets=1, starts=1, maxiter=400)
    assert r2.witness["active_set"] == [1] and r2.witness["found_by"] == "adversarial search"
    assert r2.witness["max_rho"] < 0.0


def test_a_search_without_pairs_finds_nothing(pair):
    r = pc.check_impact_monotone(pair, ImpactLaw.build("newton", E_BAD, 2), rng=rng(), laws=("poisson", "newton"),
                                 samples=0, local_samples=0, adversarial_sets=2, exact=False)
    w = r.witness
    assert w["max_rho"] == -np.inf and r.margin == np.inf and r.passed is True
    assert w["law"] == "poisson" and w["found_by"] == "" and w["evaluations"] == 0
    assert w["max_rho_impacting_pairs"] == -np.inf and "active_set" not in w


def test_documented_defaults():
    """The defaults the reports rely on (the search budget of the check and of the sets)."""
    sig = inspect.signature(pc.check_impact_monotone).parameters
    assert {k: sig[k].default for k in ("samples", "local_samples", "adversarial_sets", "starts", "maxiter",
                                        "exhaustive_up_to", "tolerance", "solver", "laws")} == \
        {"samples": 24, "local_samples": 48, "adversarial_sets": 6, "starts": 3, "maxiter": 300,
         "exhaustive_up_to": 10, "tolerance": 1e-9, "solver": "pivoting", "laws": None}
    # candidate sets: exhaustive up to 10 contacts inclusive, then 32 random sets
    assert len(mo.candidate_sets(10, rng())) == 2 ** 10 - 1
    assert len(mo.candidate_sets(11, rng(), random_sets=0)) == 11 + 55 + 1
    a, b = mo.candidate_sets(12, rng(1)), mo.candidate_sets(12, rng(1), random_sets=32)
    assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b))
    c = mo.candidate_sets(12, rng(1), random_sets=33)
    assert len(c) == len(a) + 1


def test_default_search_budget(pair):
    """Called with its defaults the check runs the documented budget: the same search, pair
    for pair (same evaluation count), as with the values spelled out."""
    law = ImpactLaw.build("newton", 0.7, 2)
    a = pc.check_impact_monotone(pair, law, rng=rng(), exact=False)
    b = pc.check_impact_monotone(pair, law, rng=rng(), samples=24, local_samples=48, adversarial_sets=6, starts=3,
                                 maxiter=300, exhaustive_up_to=10, tolerance=1e-9, solver="pivoting",
                                 laws=("newton",), exact=False)
    assert a.witness["evaluations"] == b.witness["evaluations"] > 1000
    assert a.witness["max_rho"] == b.witness["max_rho"] and a.tolerance == 1e-9 and a.evidence == "sampled"
    assert a.verdict.endswith("not decided exactly: exact=False")
    # issue 36 item 3: decided exactly first, the float search is not run at all
    c = pc.check_impact_monotone(pair, law, rng=rng())
    assert c.tolerance == 0.0 and c.evidence == "proved" and c.witness["evaluations"] == 0
    assert c.witness["sampled_search"] == "skipped: decided exactly by piece enumeration"


def test_only_impacting_pairs_count_as_impacting(pair):
    """Monotone map, sampling only: sup ρ = 0 comes from separating pairs (Λ₁ = Λ₂ = 0); the
    impacting pairs stay strictly below."""
    r = sampler(pair, ImpactLaw.build("newton", 0.7, 2), rng=rng(0), samples=12, local_samples=4,
                                 adversarial_sets=0)
    assert r.witness["max_rho"] == 0.0 and r.witness["inner_product"] == 0.0
    assert -1.0 < r.witness["max_rho_impacting_pairs"] < -1e-3


def test_random_sets_of_the_check_with_visited_sets():
    """Five contacts, exhaustive only up to 2: singletons, pairs, the full set, random sets
    of 3-5 contacts (from the check's rng) and the visited sets."""
    W = np.eye(5) + 0.2 * np.eye(5, k=1)
    sys5 = linear_system(np.diag([1.0, 2.0, 3.0, 1.5, 2.5]), W)
    law = ImpactLaw.build("newton", 0.5, 5)
    kw = dict(samples=1, local_samples=0, adversarial_sets=0, exhaustive_up_to=2)
    r = pc.check_impact_monotone(sys5, law, rng=rng(2), **kw)
    n = r.witness["sets_checked"]
    expected = mo.candidate_sets(5, rng(2), exhaustive_up_to=2)
    assert n == len(expected) < 31 and r.witness["largest_set"] == 5
    missing = next(s for s in itertools.combinations(range(5), 3)
                   if not any(e.tolist() == list(s) for e in expected))
    r = pc.check_impact_monotone(sys5, law, rng=rng(2), visited=[np.array(missing[::-1])], **kw)
    assert r.witness["sets_checked"] == n + 1
    assert pc.check_impact_monotone(sys5, law, rng=rng(2), **dict(kw, exhaustive_up_to=5)).witness["sets_checked"] == 31


def test_adversarial_search_improves_a_poor_sample(pair):
    """Two random pairs alone stay well below ρ*; Nelder–Mead from them climbs to it."""
    law = ImpactLaw.build("newton", E_BAD, 2)
    rho_star = analytic_rho(delassus_ref(pair, [0, 1]), E_BAD)
    kw = dict(rng=rng(7), active_sets=[np.array([0, 1])], samples=2, local_samples=0)
    r0 = sampler(pair, law, adversarial_sets=0, **kw)
    kw["rng"] = rng(7)
    r1 = sampler(pair, law, adversarial_sets=1, starts=2, maxiter=400, **kw)
    assert r0.witness["max_rho"] < 0.9 * rho_star
    assert r1.witness["found_by"] == "adversarial search"
    assert r1.witness["max_rho"] == pytest.approx(rho_star, rel=1e-3)
    assert r1.witness["evaluations"] > r0.witness["evaluations"] + 2 * 2 * 20
    # maxiter bounds the search
    kw["rng"] = rng(7)
    r2 = sampler(pair, law, adversarial_sets=1, starts=1, maxiter=5, **kw)
    assert r2.witness["evaluations"] <= r0.witness["evaluations"] + 2 * (5 * 3 + 8)


def test_evaluation_count_follows_the_sampling_plan(pair, uncoupled):
    """Without the adversarial search: 2 impact evaluations per random pair, 2k + 2 per
    local pair (central differences, then ρ); k = 2 gets ``local_samples`` local pairs,
    k = 1 none; a diagonal G (every single contact) at most 8 random pairs and no local pairs."""
    law = ImpactLaw.build("newton", 0.5, 2)
    r = sampler(pair, law, rng=rng(), samples=10, local_samples=6, adversarial_sets=0)
    # the singletons are diagonal too: 8 pairs each; the coupled pair 10 random + 6 local
    assert r.witness["evaluations"] == 2 * 2 * 8 + 2 * 10 + 6 * (2 * 2 + 2)
    r = sampler(uncoupled, law, rng=rng(), samples=10, local_samples=6, adversarial_sets=0)
    assert r.witness["evaluations"] == 3 * 2 * 8 and r.passed is True
    r = sampler(uncoupled, law, rng=rng(), samples=5, local_samples=6, adversarial_sets=0)
    assert r.witness["evaluations"] == 3 * 2 * 5
    # the uncoupled map with per-contact restitution is a product of scalar maps: monotone
    r = sampler(uncoupled, ImpactLaw.build("newton", E_BAD, 2), rng=rng(), samples=8,
                                 adversarial_sets=1, starts=1, maxiter=30)
    assert r.passed is True and r.reason == ""


def test_evaluation_count_three_contacts():
    """k = 3: max(4, 2·local_samples // 3) local pairs of 2·3 + 2 evaluations each."""
    sys3 = linear_system(np.diag([1.0, 2.0, 3.0]), [[1.0, 0.3, 0.0], [0.0, 1.0, 0.2], [0.1, 0.0, 1.0]])
    law = ImpactLaw.build("newton", 0.5, 3)
    full = [np.array([0, 1, 2])]
    for local, n in ((9, 6), (3, 4), (1, 4)):
        r = sampler(sys3, law, rng=rng(), active_sets=full, samples=4,
                                     local_samples=local, adversarial_sets=0)
        assert r.witness["evaluations"] == 2 * 4 + n * (2 * 3 + 2), local
        assert r.witness["largest_set"] == 3


def test_several_laws_and_visited_sets(pair):
    law = ImpactLaw.build("newton", E_BAD, 2)
    rho_star = analytic_rho(delassus_ref(pair, [0, 1]), E_BAD)
    kw = dict(samples=4, local_samples=16, adversarial_sets=0)
    r = sampler(pair, law, rng=rng(1), laws=("poisson", "newton"), visited=[np.array([1, 0])], **kw)
    per = r.witness["max_rho_per_law"]
    assert set(per) == {"newton", "poisson"}
    assert r.witness["max_rho"] == max(per.values()) == per["newton"]
    assert per["newton"] == pytest.approx(rho_star, rel=1e-3) and per["poisson"] < per["newton"]
    assert r.witness["law"] == "newton"                     # the worse law, though listed second
    assert r.witness["sets_checked"] == 3
    # the evaluations of both laws add up (each law alone: the plan of the evaluation-count test)
    one = 2 * 2 * 4 + 2 * 4 + 16 * (2 * 2 + 2)
    assert r.witness["evaluations"] == 2 * one
    # active_sets replaces the candidate and visited sets
    r = sampler(pair, law, rng=rng(), active_sets=[[1]], samples=4, adversarial_sets=0,
                                 visited=[np.array([0, 1])])
    assert r.witness["sets_checked"] == 1 and r.witness["largest_set"] == 1 and r.passed is True
    assert r.witness["active_set"] == [1] and r.witness["restitution"] == [0.95]
    f = sampler(pair, law, rng=rng(), active_sets=[np.array([1.0])], samples=4, adversarial_sets=0)
    assert f.witness["active_set"] == [1] and f.witness["max_rho"] == r.witness["max_rho"]


def test_solver_choice_and_unknown_solver(pair):
    law = ImpactLaw.build("newton", E_BAD, 2)
    kw = dict(rng=rng(), active_sets=[np.array([0, 1])], samples=4, local_samples=8, adversarial_sets=0)
    a = sampler(pair, law, solver="lemke", **kw)
    kw["rng"] = rng()
    b = sampler(pair, law, **kw)
    assert a.witness["max_rho"] == pytest.approx(b.witness["max_rho"], rel=1e-9)
    with pytest.raises(Exception, match="nope"):
        sampler(pair, law, solver="nope", **kw)
