"""The impact laws of :mod:`observer.impact` on their own (paper eqs. (5)-(6), (9)).

Each law is checked against properties recomputed here from its returned impulses and
against LCPs solved here by enumerating active sets (:func:`lcp_enum`), never against the
module's own numbers:

* Newton: ``0 ≤ γ⁺ + e∘γ⁻ ⊥ Λ ≥ 0`` with ``γ⁺ = γ⁻ + GΛ``;
* Poisson (Glocker's inequality form): compression ``0 ≤ γ_C ⊥ Λ_C ≥ 0``, expansion
  ``0 ≤ γ_E ⊥ Λ_E − ε∘Λ_C ≥ 0``; the one-contact closed form agrees with the LCP path;
* the discrete Poisson step: Glocker's law on ``γ̃ = (γ_free + ε∘γ_k)/(1+ε)`` (Newton's
  closed form for one contact, bitwise);
* :meth:`ImpactLaw.build` rejects bad input with an error naming the field.

Tolerance: 1e-12 relative to the size of the velocities and impulses (2×2 and 3×3
well-conditioned problems).
"""

from __future__ import annotations


import numpy as np
import pytest

from lcp_enum import lcp_enum
from observer.contact.lcp import LCPSolution
from observer.errors import InputError
from observer.impact import (LAWS, NEWTON, POISSON, ImpactLaw, impact, newton_impact,
                             poisson_impact, poisson_phases, poisson_step)
from observer.impact import newton_step

TOL = 1e-12


class Recorder:
    """A ``solve`` callable built on :func:`lcp_enum` that records its problems."""

    def __init__(self):
        self.problems = []

    def __call__(self, G, b):
        self.problems.append((G.copy(), b.copy()))
        return LCPSolution(lcp_enum(G, b), 0.0, 1, "enum")


def no_solve(G, b):
    raise AssertionError("the one-contact closed form must not call the LCP solver")


def assert_complementary(x, y, scale, what):
    tol = TOL * max(scale, 1.0)
    assert np.all(x >= -tol), f"{what}: {x}"
    assert np.all(y >= -tol), f"{what}: {y}"
    assert np.all(np.abs(x * y) <= tol * max(scale, 1.0)), f"{what}: {x} ⊥ {y}"


# Two and three coupled contacts (G = WᵀM⁻¹W of small systems) with approach velocities
# chosen so that the impacts interact (some contacts separate after compression).
G2 = np.array([[2.0, 1.2], [1.2, 1.0]])
G3 = np.array([[2.0, 0.9, 0.3], [0.9, 1.5, -0.6], [0.3, -0.6, 1.2]])
CASES = [
    (G2, np.array([-1.0, 0.3]), np.array([0.5, 0.9])),
    (G2, np.array([-1.0, -2.0]), np.array([0.2, 0.7])),
    (G3, np.array([-1.0, -0.2, 0.5]), np.array([0.8, 0.3, 0.6])),
    (G3, np.array([-2.0, -1.0, -0.5]), np.array([0.0, 1.0, 0.4])),
    (G3, np.array([0.5, 0.2, 0.0]), np.array([0.5, 0.5, 0.5])),       # nothing approaches
    (G2, np.array([-1.0, -0.5]), np.array([0.2, 0.9])),               # Poisson ≠ Newton
    # contact 0 approaches but separates after compression (γ_C,0 > 0); expansion μ_1 > 0
    (G3, np.array([-1.5, -0.6, -1.8]), np.array([0.2, 0.1, 0.5])),
]
IDS = ["2-one-approaches", "2-both-approach", "3-mixed", "3-all-approach", "3-separating",
       "2-poisson-not-newton", "3-expansion-lcp"]


# ---------------------------------------------------------------------------------------
# ImpactLaw
# ---------------------------------------------------------------------------------------
def test_build_broadcasts_and_freezes_the_restitution():
    law = ImpactLaw.build("newton", 0.4, 3)
    assert law.law == "newton" and law.restitution.tolist() == [0.4, 0.4, 0.4]
    assert not law.restitution.flags.writeable
    with pytest.raises(ValueError):
        law.restitution[0] = 1.0
    law = ImpactLaw.build("poisson", [0.0, 1.0], 2)           # both ends of [0, 1] accepted
    assert law.restitution.tolist() == [0.0, 1.0]
    assert not law.restitution.flags.writeable


@pytest.mark.parametrize("law,e,m,field,match", [
    ("newtonian", 0.5, 1, "impact.law", r"must be one of \['newton', 'poisson'\], got 'newtonian'"),
    (None, 0.5, 1, "impact.law", "got None"),
    ("newton", -0.01, 2, "impact.restitution", r"must lie in \[0, 1\], got \[-0.01, -0.01\]"),
    ("poisson", [0.5, 1.01], 2, "impact.restitution", r"must lie in \[0, 1\], got \[0.5, 1.01\]"),
    ("newton", [0.5, -1e-12], 2, "impact.restitution", "must lie in"),
    ("newton", [0.5, 0.5, 0.5], 2, "impact.restitution", "shape"),
    ("newton", "much", 2, "impact.restitution", None),
])
def test_build_rejects_bad_input_naming_the_field(law, e, m, field, match):
    with pytest.raises(InputError, match=match) as info:
        ImpactLaw.build(law, e, m)
    assert info.value.field == field


def test_law_codes_and_global_restitution():
    assert LAWS == ("newton", "poisson") and (NEWTON, POISSON) == (0, 1)
    assert ImpactLaw.build("newton", 0.5, 2).code == NEWTON
    assert ImpactLaw.build("poisson", 0.5, 2).code == POISSON
    assert ImpactLaw.build("newton", [0.3, 0.3, 0.3], 3).is_global is True
    assert ImpactLaw.build("newton", [0.3, 0.3, 0.4], 3).is_global is False
    assert ImpactLaw.build("newton", [0.4, 0.3, 0.3], 3).is_global is False
    assert ImpactLaw.build("poisson", [0.7], 1).is_global is True


# ---------------------------------------------------------------------------------------
# Newton
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("G,gm,e", CASES, ids=IDS)
def test_newton_impulse_satisfies_the_law(G, gm, e):
    lam = newton_impact(G, gm, e, Recorder())
    gp = gm + G @ lam
    scale = np.abs(gm).max() + np.abs(G @ lam).max()
    assert_complementary(gp + e * gm, lam, scale, "Newton")
    np.testing.assert_allclose(lam, lcp_enum(G, (1 + e) * gm), rtol=0, atol=TOL * scale)


def test_newton_one_contact_closed_form():
    for gm, e in ((-2.0, 0.5), (-1.0, 0.0), (-0.5, 1.0), (0.7, 0.5)):
        lam = newton_impact(np.array([[4.0]]), np.array([gm]), np.array([e]), Recorder())
        assert lam[0] == pytest.approx(max(0.0, -(1 + e) * gm / 4.0), abs=1e-15)


# ---------------------------------------------------------------------------------------
# Poisson
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("G,gm,eps", CASES, ids=IDS)
def test_poisson_phases_satisfy_glockers_conditions(G, gm, eps):
    rec = Recorder()
    lam_c, lam_e = poisson_phases(G, gm, eps, rec)
    assert lam_c.shape == lam_e.shape == gm.shape
    gc = gm + G @ lam_c
    ge = gc + G @ lam_e
    scale = np.abs(gm).max() + np.abs(G).max() * (np.abs(lam_c).max() + np.abs(lam_e).max())
    assert_complementary(gc, lam_c, scale, "compression")
    assert_complementary(ge, lam_e - eps * lam_c, scale, "expansion")
    # the same impulses from the two LCPs solved here
    lc = lcp_enum(G, gm)
    mu = lcp_enum(G, gm + G @ lc + G @ (eps * lc))
    np.testing.assert_allclose(lam_c, lc, rtol=0, atol=TOL * scale)
    np.testing.assert_allclose(lam_e, eps * lc + mu, rtol=0, atol=TOL * scale)
    lam = poisson_impact(G, gm, eps, Recorder())
    np.testing.assert_allclose(lam, (1 + eps) * lc + mu, rtol=0, atol=TOL * scale)
    # the two problems handed to the solver: (G, γ⁻), then (G, γ_C + G(ε∘Λ_C))
    assert len(rec.problems) == 2
    np.testing.assert_array_equal(rec.problems[0][1], gm)
    np.testing.assert_allclose(rec.problems[1][1], gc + G @ (eps * lam_c), rtol=0, atol=TOL * scale)


def test_the_cases_exercise_every_branch():
    """The CASES above contain a separating-after-compression contact and an active
    expansion LCP (μ > 0), so both phases of the multi-contact law are exercised."""
    G, gm, eps = CASES[6]
    lc = lcp_enum(G, gm)
    gc = gm + G @ lc
    mu = lcp_enum(G, gc + G @ (eps * lc))
    assert gm[0] < 0 and gc[0] > 0.1 and mu[1] > 0.1


def test_poisson_differs_from_newton_on_coupled_contacts():
    """A case where Glocker's Poisson law is not Newton's (so the dispatch is observable)."""
    G, gm, e = CASES[5]
    newton = newton_impact(G, gm, e, Recorder())
    poisson = poisson_impact(G, gm, e, Recorder())
    assert np.max(np.abs(newton - poisson)) > 1e-3


@pytest.mark.parametrize("gm", [-2.0, -1e-3, 0.0, 0.5])
@pytest.mark.parametrize("eps", [0.0, 0.35, 1.0])
def test_poisson_one_contact_closed_form_equals_the_lcp_path(gm, eps):
    """One contact: Λ_C = max(0, −γ⁻/G), Λ_E = εΛ_C, without a solver call; the same
    contact embedded in a decoupled 2-contact problem (LCP path) gives the same impulses."""
    G1 = np.array([[2.5]])
    lam_c, lam_e = poisson_phases(G1, np.array([gm]), np.array([eps]), no_solve)
    assert lam_c[0] == pytest.approx(max(0.0, -gm / 2.5), abs=1e-15)
    assert lam_e[0] == pytest.approx(eps * max(0.0, -gm / 2.5), abs=1e-15)
    assert lam_c.shape == lam_e.shape == (1,)
    G2d = np.array([[2.5, 0.0], [0.0, 1.0]])
    lc2, le2 = poisson_phases(G2d, np.array([gm, 1.0]), np.array([eps, 0.5]), Recorder())
    assert lc2[0] == pytest.approx(lam_c[0], abs=1e-15) and lc2[1] == 0.0
    assert le2[0] == pytest.approx(lam_e[0], abs=1e-15) and le2[1] == 0.0
    # the post-impact velocity is Newton's: −εγ⁻ when approaching, γ⁻ otherwise
    ge = gm + 2.5 * (lam_c[0] + lam_e[0])
    assert ge == pytest.approx(-eps * gm if gm < 0 else gm, abs=1e-15)
    lam = poisson_impact(G1, np.array([gm]), np.array([eps]), no_solve)
    assert lam[0] == pytest.approx((1 + eps) * max(0.0, -gm / 2.5), abs=1e-15)


def gamma_free_of(gk: np.ndarray) -> np.ndarray:
    """A free velocity γ_free = γ_k + δ with an O(h)-like smooth change δ of mixed signs."""
    return gk + 0.05 * np.array([-1.0, 0.5, -0.25])[:gk.size]


@pytest.mark.parametrize("G,gk,eps", CASES, ids=IDS)
def test_poisson_step_is_glockers_law_on_the_step_velocity(G, gk, eps):
    """P = Λ_C + Λ_E with Glocker's conditions in γ̃ = (γ_free + ε∘γ_k)/(1+ε):
    ``0 ≤ γ̃ + GΛ_C ⊥ Λ_C ≥ 0`` and ``0 ≤ γ̃ + GP ⊥ Λ_E − ε∘Λ_C ≥ 0``."""
    gf = gamma_free_of(gk)
    P, lam_c, lam_e = poisson_step(G, gf, gk, eps, Recorder())
    gt = (gf + eps * gk) / (1.0 + eps)
    lc = lcp_enum(G, gt)
    mu = lcp_enum(G, gt + G @ lc + G @ (eps * lc))
    scale = np.abs(gk).max() + np.abs(G).max() * (np.abs(lc).max() + np.abs(mu).max()) * 3
    np.testing.assert_allclose(lam_c, lc, rtol=0, atol=TOL * scale)
    np.testing.assert_allclose(lam_e, eps * lc + mu, rtol=0, atol=TOL * scale)
    np.testing.assert_allclose(P, (1 + eps) * lc + mu, rtol=0, atol=TOL * scale)
    assert_complementary(gt + G @ lam_c, lam_c, scale, "compression in γ̃")
    assert_complementary(gt + G @ P, lam_e - eps * lam_c, scale, "expansion in γ̃")


@pytest.mark.parametrize("G,gk,eps", CASES, ids=IDS)
def test_poisson_step_without_smooth_change_is_the_poisson_impact(G, gk, eps):
    """δ = 0 (γ_free = γ_k): γ̃ = γ_k, so the step's impulse is Glocker's impact impulse."""
    P, _, _ = poisson_step(G, gk.copy(), gk, eps, Recorder())
    lc = lcp_enum(G, gk)
    mu = lcp_enum(G, gk + G @ lc + G @ (eps * lc))
    np.testing.assert_allclose(P, (1 + eps) * lc + mu, rtol=0, atol=1e-13)


def test_poisson_step_on_uncoupled_contacts_is_newtons():
    """G diagonal: each contact on its own, P_i = max(0, −(γ_free,i + ε_iγ_k,i)/G_ii)."""
    G = np.diag([2.0, 0.5, 1.0])
    gk = np.array([-1.0, 0.4, -0.2])
    gf = np.array([-1.1, 0.3, 0.5])
    eps = np.array([0.3, 0.6, 0.9])
    P, lam_c, lam_e = poisson_step(G, gf, gk, eps, Recorder())
    newton = np.maximum(0.0, -(gf + eps * gk) / np.diag(G))
    np.testing.assert_allclose(P, newton, rtol=0, atol=1e-15)
    np.testing.assert_allclose(lam_c, newton / (1 + eps), rtol=0, atol=1e-15)
    assert newton[0] > 0 and newton[1] == 0.0 and newton[2] == 0.0


@pytest.mark.parametrize("gk,gf", [(-1.3, -1.2), (-1.3, 0.2), (0.0, -0.1), (0.8, 0.7), (0.8, -0.5),
                                   (0.4, 0.1)])
def test_poisson_step_one_contact_is_bitwise_newtons(gk, gf):
    """One contact: Newton's closed form ``max(0, −(γ_free + εγ_k)/G)`` to the last bit,
    without a solver call; Λ_C = P/(1+ε), Λ_E = P − Λ_C."""
    eps = np.array([0.45])
    G = np.array([[3.0]])
    P, lam_c, lam_e = poisson_step(G, np.array([gf]), np.array([gk]), eps, no_solve)
    b = gf + 0.45 * gk
    expected = -b / 3.0 if b < 0.0 else 0.0
    assert P.shape == lam_c.shape == lam_e.shape == (1,)
    assert P[0] == expected
    assert lam_c[0] == expected / 1.45
    assert lam_e[0] == expected - expected / 1.45
    assert lam_e[0] == pytest.approx(0.45 * lam_c[0], abs=1e-15)


# ---------------------------------------------------------------------------------------
# dispatch
# ---------------------------------------------------------------------------------------
def test_impact_dispatches_on_the_law_and_slices_the_restitution():
    e = [0.2, 0.5, 0.9]
    G, gm = CASES[5][0], CASES[5][1]
    active = np.array([0, 2])
    e_A = np.array([0.2, 0.9])
    lam_n = impact(ImpactLaw.build("newton", e, 3), G, gm, active, Recorder())
    np.testing.assert_allclose(lam_n, lcp_enum(G, (1 + e_A) * gm), rtol=0, atol=1e-13)
    lam_p = impact(ImpactLaw.build("poisson", e, 3), G, gm, active, Recorder())
    lc = lcp_enum(G, gm)
    mu = lcp_enum(G, gm + G @ lc + G @ (e_A * lc))
    np.testing.assert_allclose(lam_p, (1 + e_A) * lc + mu, rtol=0, atol=1e-13)
    assert np.max(np.abs(lam_n - lam_p)) > 1e-3


# ----------------------------------------------------------------------------------------
# (formerly tests/test_mutants_impact.py)
# observer.impact.newton_step: the documented return (P, Λ_C, Λ_E) with empty phases, P
# the LCP solution for G and γ_free + e∘γ_k checked by complementarity recomputed here.
# Written against the mutation run of ``observer/impact.py`` (``tests/mutants/impact.md``).
# ----------------------------------------------------------------------------------------
def test_newton_step_returns_the_lcp_impulse_and_no_phases():
    G = np.array([[2.0, 0.5], [0.5, 1.0]])
    gamma_free, gamma_k, e = np.array([-1.0, 0.4]), np.array([-2.0, 0.1]), np.array([0.5, 0.25])
    seen = []

    def solve(A, b):
        seen.append(b.copy())
        return LCPSolution(lcp_enum(A, b), 0.0, 1, "enum")
    P, lam_c, lam_e = newton_step(G, gamma_free, gamma_k, e, solve)
    assert np.array_equal(seen[0], gamma_free + e * gamma_k)
    w = G @ P + gamma_free + e * gamma_k                   # γ_{k+1} + e∘γ_k
    assert np.all(P >= 0) and np.all(w >= -1e-12) and abs(P @ w) <= 1e-12
    assert P[0] > 0
    assert lam_c.shape == (0,) and lam_e.shape == (0,)
