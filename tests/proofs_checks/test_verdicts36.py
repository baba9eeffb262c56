"""Issue 36 (items 1-3) and issue 31 (item 4): verdicts that say exactly what they decided.

References are written without proofs_checks: exact rationals (``fractions.Fraction``), a
Gaussian elimination over Q for definiteness, and the scenario's own numbers.
"""

from __future__ import annotations

import time
from fractions import Fraction

import numpy as np
import pytest

import proofs_checks as pc
from observer.errors import InputError


def fraction_ldl_definite(A) -> bool:
    """Reference: A (floats, symmetric) ≻ 0 iff every pivot of Gaussian elimination over Q is > 0."""
    S = [[Fraction(float(x)) for x in row] for row in np.asarray(A)]
    n = len(S)
    for k in range(n):
        if S[k][k] <= 0:
            return False
        for i in range(k + 1, n):
            f = S[i][k] / S[k][k]
            for j in range(k, n):
                S[i][j] -= f * S[k][j]
    return True


# ----------------------------------------------------------------------------- item 1
def test_one_ulp_asymmetric_M_is_refused_by_the_loader_and_violated_by_the_check(tmp_path):
    """Through TOML (the loader: InputError naming system.M and the entry) and directly."""
    A = np.array([[2.0, 0.3], [0.3, 1.0]])
    A[1, 0] = np.nextafter(0.3, 1.0)
    assert Fraction(float(A[1, 0])) != Fraction(float(A[0, 1]))
    with pytest.raises(InputError) as ei:
        pc.load("double_mass", {"system.M": A.tolist()})
    assert ei.value.field == "system.M" and "[0, 1]" in str(ei.value)
    r = pc.check_mass_spd(A)
    assert r.passed is False and r.evidence == "violated" and r.witness["entry"] == [0, 1]


# ----------------------------------------------------------------------------- item 2
def _ill_conditioned_K(indefinite: bool) -> np.ndarray:
    """K = [[1, b], [b, b² ± 2⁻⁶⁶]] with b = 2⁻³⁰ (every entry exact in float64):
    det = ±2⁻⁶⁶, so λ_min/λ_max ≈ ±1.4e-20."""
    b = 2.0 ** -30
    d = b * b + (-1.0 if indefinite else 1.0) * 2.0 ** -66
    return np.array([[1.0, b], [b, d]])


@pytest.mark.parametrize("indefinite", [False, True])
def test_every_check_follows_the_exact_class_of_an_ill_conditioned_K(indefinite):
    """Acceptance: K exactly SPD at λ_min/λ_max ≈ 1e-20: no check calls K singular; its
    exactly indefinite twin (L = WᵀK⁻¹W < 0, W = e₁) gets ``violated`` where the
    property fails (stiffness_spd, projection_psd), and no check calls it singular either."""
    K = _ill_conditioned_K(indefinite)
    Kq = [[Fraction(float(x)) for x in row] for row in K]
    det = Kq[0][0] * Kq[1][1] - Kq[0][1] ** 2
    assert (det < 0) is indefinite and abs(float(det)) < 1e-19           # the exact reference
    assert fraction_ldl_definite(K) is (not indefinite)
    L = Kq[1][1] / det                       # W = e₁: L = (K⁻¹)₁₁ = K₂₂/det, the sign of det
    assert (L < 0) is indefinite
    over = {"system.K": K.tolist(), "simulation.t_end": 0.2, "simulation.h": 1e-3}
    results = pc.run_checks("double_mass", overrides=over)
    by = {r.name: r for r in results}
    assert set(by) == set(pc.CHECKS)
    for r in results:
        assert "singular" not in (r.reason + (r.verdict or "")), (r.name, r.reason)
    if indefinite:
        assert by["stiffness_spd"].evidence == "violated"
        assert by["projection_psd"].evidence == "violated" and by["projection_psd"].passed is False
    else:
        assert by["stiffness_spd"].evidence == "proved"
        assert by["projection_psd"].evidence == "proved"
        for name in ("projection_closed_form", "convergence"):
            assert by[name].reason.startswith("K ≻ 0 holds (exact)"), by[name].reason


# ----------------------------------------------------------------------------- issue 31 item 4
def test_convergence_limited_by_its_horizon_says_so_and_is_not_violated():
    (r,) = pc.run_checks("double_mass", only="convergence", t_end=0.5)
    assert r.passed is False and r.evidence == "sampled"
    assert "t = 0.5 s" in r.verdict and "--t-end" in r.verdict and "no counterexample" in r.verdict


def test_convergence_default_horizon_is_the_scenario_t_end():
    sc = pc.load("double_mass")
    (r,) = pc.run_checks(sc, only="convergence")
    assert r.witness["horizon"] == pytest.approx(sc.t_end)
    assert "the scenario's t_end" in r.verdict


# ----------------------------------------------------------------------------- item 3
def _six_coupled_contacts():
    from observer.model import Harmonic, LinearSystem
    rng = np.random.default_rng(3)
    n = 6
    A = rng.standard_normal((n, n))
    M = A @ A.T + n * np.eye(n)
    M = (M + M.T) / 2
    W = np.eye(n) + 0.3 * rng.standard_normal((n, n))          # G = WᵀM⁻¹W full: one component
    return LinearSystem(M, np.eye(n), np.eye(n), W, Harmonic.build("f", n), Harmonic.build("g", n))


def test_impact_monotone_decides_six_coupled_poisson_contacts_exactly_without_sampling():
    """Poisson with a global e is monotone (every piece); on six coupled contacts the default
    enumerates all 4⁶ pieces and runs no float search; with the enumeration limited below
    4⁶ the sampled result says why and names the option."""
    from observer.impact import ImpactLaw
    sys6 = _six_coupled_contacts()
    law = ImpactLaw("poisson", np.full(6, 0.5))
    r = pc.check_impact_monotone(sys6, law, rng=np.random.default_rng(0))
    assert r.evidence == "proved" and r.witness["evaluations"] == 0
    assert r.witness["exact_pieces"] == {"poisson": 4 ** 6}
    s = pc.check_impact_monotone(sys6, law, rng=np.random.default_rng(0), exact_max_pairs=1024, samples=2,
                                 local_samples=4, adversarial_sets=0)
    assert s.evidence == "sampled" and "impact_monotone.exact_max_pairs" in s.verdict


def test_cli_refuses_a_one_ulp_asymmetric_M_naming_the_field_and_the_entry(capsys):
    from proofs_checks.cli import main
    off = float(np.nextafter(0.3, 1.0))
    assert Fraction(off) != Fraction(0.3) and float(repr(off)) == off           # repr round-trips
    rc = main(["double_mass", "--only", "mass_spd", "--set", f"system.M=[[2.0, 0.3], [{off!r}, 1.0]]"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1
    assert "system.M" in err and "[0, 1] = 0.3" in err and f"[1, 0] = {off!r}" in err
