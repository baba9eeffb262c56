"""proofs_checks.assumptions (section 2 model assumptions) and proofs_checks.forcing (A2):
every witness entry, margin, tolerance and text on matrices and signals whose spectra,
singular values, sups and periods are known in closed form. Synthetic inputs only (well
under a second). Written against the mutation runs of ``assumptions.py`` and ``forcing.py``
(``tests/mutants/proofs_checks_small.md``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import proofs_checks as pc
from observer.model import Harmonic
from proofs_checks import forcing as fo

ROT = np.array([[0.6, -0.8], [0.8, 0.6]])           # exact rotation (3-4-5)


def _sym(eigs):
    return ROT @ np.diag(eigs) @ ROT.T


# ----------------------------------------------------------------------------- definiteness
@pytest.mark.parametrize("check,name,label,equation", [
    (pc.check_mass_spd, "mass_spd", "M", "section 2: M = Mᵀ ≻ 0"),
    (pc.check_stiffness_spd, "stiffness_spd", "K", "section 2: K = Kᵀ ≻ 0; eq. (7)"),
])
def test_spd_witness_margin_and_texts(check, name, label, equation):
    A = _sym([2.0, 8.0])
    r = check(A)
    w = r.witness
    assert r.name == name and r.equation == equation and r.passed is True and r.tolerance == 0.0
    assert w["lambda_min"] == pytest.approx(2.0, rel=1e-14) and w["lambda_max"] == pytest.approx(8.0, rel=1e-14)
    assert w["relative_lambda_min"] == pytest.approx(0.25, rel=1e-14) and w["required"] == 0.0
    assert r.margin == pytest.approx(0.25, rel=1e-14) and r.evidence == "proved"
    assert w["exact_class"] == "definite" and w["min_pivot"] > 0
    v = w["eigenvector_min"]
    assert abs(abs(v @ ROT[:, 0]) - 1.0) < 1e-12                  # the eigenvector of λ = 2
    assert w["asymmetry"] == pytest.approx(np.max(np.abs(A - A.T)) / 8.0, abs=1e-17)
    assert r.summary_keys == ("lambda_min", "lambda_max", "relative_lambda_min", "asymmetry")
    if name == "mass_spd":                   # below rcond_min: fails (K: semi-definite, n/a)
        assert check(A, rcond_min=0.3).passed is False
        assert check(A, rcond_min=0.3).margin == pytest.approx(0.25 - 0.3)
        assert check(A, rcond_min=0.3).evidence == "bounded"          # exactly SPD, a float judgement
    else:
        assert check(A, rcond_min=0.3).passed is None
    assert check(A, rcond_min=0.2).passed is True
    # not symmetric: decided exactly, the entry is the witness, the asymmetry the margin
    B = np.array([[1.0, 0.3], [0.0, 2.0]])
    r = check(B)
    assert r.passed is False and r.margin == pytest.approx(-0.15) and r.tolerance == 0.0
    assert r.evidence == "violated" and r.witness["entry"] == [0, 1]
    assert r.reason == (f"{label} is not symmetric: {label}[0, 1] = 0.3 but {label}[1, 0] = 0.0 "
                        "(max|A − Aᵀ|/max|A| = 0.15)")
    assert r.summary_keys[0] == "entry" and r.equation == equation and r.name == name
    # negative definite scale: λ_max < 0, relative λ_min = λ_min/max|λ|
    r = check(-_sym([2.0, 8.0]))
    assert r.witness["relative_lambda_min"] == pytest.approx(-1.0) and r.passed is False
    assert r.evidence == "violated" and r.witness["exact_class"] == "indefinite" and r.witness["exact_xAx"] < 0


def test_stiffness_semidefinite_reason_and_witness():
    # ROT diag(0, 4) ROTᵀ rounded to floats is exactly definite (λ_min ≈ 5.6e-17 over Q)
    assert pc.check_stiffness_spd(_sym([0.0, 4.0])).evidence == "proved"
    r = pc.check_stiffness_spd(np.array([[1.0, 2.0], [2.0, 4.0]]))      # exactly singular, λ = 0, 5
    assert r.passed is None and math.isnan(r.margin) and math.isnan(r.tolerance)
    assert r.reason.startswith("K is only positive semi-definite (λ_min = ") and r.evidence == "n/a"
    assert r.reason.endswith("): free rigid-body mode; the position jumps (K-metric), eqs. (13)-(14) and "
                             "Theorem 1 need K ≻ 0 (docs/theory/index.md §2 erratum 6)")
    assert r.witness["lambda_max"] == pytest.approx(5.0) and r.equation == "section 2: K = Kᵀ ≻ 0; eq. (7)"
    x = r.witness["exact_vector"]
    assert np.all(np.array([[1.0, 2.0], [2.0, 4.0]]) @ x == 0) and np.any(x != 0) and r.witness["exact_xAx"] == 0
    assert r.summary_keys == ("lambda_min", "lambda_max", "relative_lambda_min", "asymmetry")
    # the zero matrix: scale 0 → relative λ_min 0 → semi-definite
    r = pc.check_stiffness_spd(np.zeros((2, 2)))
    assert r.passed is None and r.witness["relative_lambda_min"] == 0.0 and r.witness["asymmetry"] == 0.0
    # decided exactly: a tiny negative eigenvalue is indefinite, a tiny positive one definite,
    # an exactly singular PSD matrix semi-definite; rcond_min (default 0) is the edge on top
    r = pc.check_stiffness_spd(np.diag([-1e-10, 1.0]))
    assert r.passed is False and r.evidence == "violated"
    r = pc.check_stiffness_spd(np.diag([1e-12, 1.0]))
    assert r.passed is True and r.margin == 1e-12 and r.evidence == "proved"
    assert pc.check_stiffness_spd(np.diag([1e-12, 1.0]), rcond_min=1e-12).margin == 0.0
    assert pc.check_stiffness_spd(np.diag([1e-12, 1.0]), rcond_min=2e-12).passed is None
    # the mass matrix has no semi-definite exception
    assert pc.check_mass_spd(np.diag([0.0, 1.0])).passed is False


def test_damping_pd_texts_and_symmetric_part():
    r = pc.check_damping_pd(np.zeros((2, 2)))
    assert r.passed is None and r.name == "damping_pd" and math.isnan(r.margin) and math.isnan(r.tolerance)
    assert r.witness == {"lambda_min": 0.0, "lambda_max": 0.0}
    assert r.reason == "C = 0 (undamped): dV ≤ 0 holds, but Theorem 1's argument v → 0 needs C̄ ≻ 0"
    assert r.equation == "proof of Theorem 1: C̄ ≻ 0, eq. (17)"
    r = pc.check_damping_pd([[0.0, 0.0], [0.0, 1.0]])         # a list, semi-definite
    assert r.passed is None and r.reason.startswith("C̄ is only positive semi-definite (λ_min = 0")
    assert r.reason.endswith(": dV ≤ 0 holds, but Theorem 1's argument v → 0 (after eq. (20)) needs C̄ ≻ 0")
    C = _sym([1.0, 3.0]) + np.array([[0.0, 5.0], [-5.0, 0.0]])  # skew part ignored, no asymmetry entry
    r = pc.check_damping_pd(C)
    assert r.passed is True and "asymmetry" not in r.witness
    assert r.witness["relative_lambda_min"] == pytest.approx(1 / 3)
    assert r.equation == "proof of Theorem 1: C̄ ≻ 0, eq. (17)" and r.name == "damping_pd"


def test_constraints_independent_witness():
    W = np.array([[3.0, 0.0], [0.0, 0.5], [0.0, 0.0]])
    r = pc.check_constraints_independent(W)
    w = r.witness
    assert (w["n"], w["m"]) == (3, 2) and w["sigma_min"] == 0.5 and w["sigma_max"] == 3.0
    assert w["condition_number"] == 6.0 and w["cond_max"] == 1e6
    assert abs(abs(w["null_combination"][1]) - 1.0) < 1e-15
    assert r.margin == pytest.approx(6.0 - math.log10(6.0), rel=1e-14) and r.tolerance == 0.0
    assert r.reason == "" and r.name == "constraints_independent"
    assert r.equation == "section 2: w_i linearly independent; eq. (21)"
    assert r.summary_keys == ("exact_rank", "condition_number", "sigma_min", "sigma_max", "null_combination")
    assert w["exact_rank"] == 2 and r.evidence == "proved"
    assert pc.check_constraints_independent(W, cond_max=6.0).margin == 0.0
    # m > n: σ_min = 0, cond = inf, margin −inf, with the reason
    r = pc.check_constraints_independent([[1.0, 2.0, 0.5]])
    assert r.passed is False and r.margin == -np.inf and r.witness["condition_number"] == np.inf
    assert r.witness["sigma_min"] == 0.0 and r.reason == "more contacts than degrees of freedom (m > n)"
    # exactly dependent columns (m ≤ n): σ_min = 0 → inf, no m > n reason
    W = np.array([[1.0, 1.0], [0.0, 0.0]])
    r = pc.check_constraints_independent(W)
    assert r.witness["condition_number"] == np.inf and r.passed is False
    assert r.reason == "the columns of W are exactly dependent" and r.evidence == "violated"
    assert r.witness["exact_rank"] == 1 and np.all(W @ r.witness["exact_null_combination"] == 0)
    assert np.any(r.witness["exact_null_combination"] != 0)
    # numerically but not exactly dependent: exact rank 2, condition number above cond_max
    near = np.array([[1.0, 1.0], [0.0, 2.0 ** -40]])
    r = pc.check_constraints_independent(near)
    assert r.witness["exact_rank"] == 2 and r.passed is False and r.evidence == "bounded"


# ----------------------------------------------------------------------------- A2: common period
def test_common_period_cases():
    T, ok = fo.common_period(np.array([2.0, 3.0]))
    assert ok is True and T == pytest.approx(2 * math.pi, rel=1e-15)       # cos 2t, cos 3t
    T, ok = fo.common_period(np.array([0.0, -1.0, 4.0]))                  # only ω > 0 count
    assert ok is True and T == pytest.approx(math.pi / 2, rel=1e-15)
    assert fo.common_period(np.array([0.0])) == (1.0, True)
    assert fo.common_period(np.array([])) == (1.0, True)
    T, ok = fo.common_period(np.array([1.0, math.sqrt(2.0)]))
    assert ok is False and T == pytest.approx(400 * math.pi, rel=1e-15)
    # denominators up to max_denominator (default 64)
    assert fo.common_period(np.array([64.0, 65.0]))[1] is True
    T, ok = fo.common_period(np.array([64.0, 65.0]))
    assert T == pytest.approx(2 * math.pi, rel=1e-13)
    assert fo.common_period(np.array([65.0, 66.0]))[1] is False
    T, ok = fo.common_period(np.array([65.0, 66.0]), max_denominator=65)
    assert ok is True and T == pytest.approx(2 * math.pi, rel=1e-13)
    # the 1e-12 relative matching tolerance
    assert fo.common_period(np.array([1.0, 1.0 + 1e-11]))[1] is False
    assert fo.common_period(np.array([1.0, 1.0 + 1e-13]))[1] is True


def test_sup_norm_refines_between_samples():
    f = lambda t: np.stack([np.sin(np.asarray(t, float)), 0 * np.asarray(t, float)], axis=-1)  # noqa: E731
    S, ts = fo._sup_norm(f, 0.0, 3.0, 7)                  # π/2 is not a sample
    assert S == pytest.approx(1.0, abs=1e-12) and ts == pytest.approx(math.pi / 2, abs=1e-5)
    # only the best five samples are refined: a local max in a poor sample region is skipped,
    # the global one (at 5π/2 on [0, 9]) is found
    S, ts = fo._sup_norm(lambda t: np.stack([np.sin(np.asarray(t, float)) * (1 + 0.1 * np.asarray(t, float))],
                                            axis=-1), 0.0, 9.0, 40)
    ref = max(math.sin(x) * (1 + 0.1 * x) for x in np.linspace(7.0, 8.5, 300001))
    assert S == pytest.approx(ref, rel=1e-10) and 7.0 < ts < 8.5
    # a degenerate window: the only sample
    S, ts = fo._sup_norm(f, 1.0, 1.0, 4)
    assert S == pytest.approx(math.sin(1.0), rel=1e-15) and ts == 1.0
    # the sample at the end of the window is refined inside the window only
    S, ts = fo._sup_norm(f, 0.0, 1.0, 3)
    assert S == pytest.approx(math.sin(1.0), rel=1e-12) and ts <= 1.0


# ----------------------------------------------------------------------------- A2: the check
def test_harmonic_witness_and_margin():
    f = Harmonic.build("f", 2, constant=[1.0, 0.0],
                       terms=[{"amplitude": [2.0, 0.0], "omega": 2.0, "phase": 0.0},
                              {"amplitude": [0.0, 1.5], "omega": 3.0, "phase": 0.0}])
    r = pc.check_forcing_bounded(f)
    w = r.witness
    U = math.hypot(3.0, 1.5)                                 # componentwise |c| + Σ|a|
    assert w["analytic_bound"] == pytest.approx(U, rel=1e-15) and w["f_max"] == w["analytic_bound"]
    assert np.allclose(w["componentwise_bound"], [3.0, 1.5], rtol=1e-15)
    assert w["sup_norm"] == pytest.approx(U, rel=1e-9)       # t = 0 reaches it
    assert w["period"] == pytest.approx(2 * math.pi) and w["commensurate"] is True
    assert np.allclose(w["f_at_t_star"], f(w["t_star"]), rtol=1e-15)
    assert r.margin == pytest.approx(1 - w["sup_norm"] / U, abs=1e-15) and r.tolerance == 1e-9
    assert r.passed is True and r.reason == "" and r.name == "forcing_bounded"
    assert r.evidence == "proved"                              # the analytic bound U proves A2
    assert r.equation == "A2: sup‖f(t)‖ ≤ f_max < ∞"
    assert r.summary_keys == ("sup_norm", "analytic_bound", "f_max", "t_star", "period")
    r = pc.check_forcing_bounded(f, f_max=2 * U, tolerance=0.0)
    assert r.witness["f_max"] == 2 * U and r.margin == pytest.approx(0.5, rel=1e-9) and r.tolerance == 0.0
    assert r.evidence == "proved"                              # f_max ≥ U
    r = pc.check_forcing_bounded(f, f_max=0.999 * U)             # below U: only the sampled sup decides
    assert r.passed is False and r.evidence == "sampled"


def test_harmonic_zero_bound_and_incommensurate():
    zero = Harmonic.build("f", 1)
    r = pc.check_forcing_bounded(zero)
    assert r.passed is True and r.margin == 0.0 and r.witness["sup_norm"] == 0.0
    one = Harmonic.build("f", 1, constant=[1.0])
    r = pc.check_forcing_bounded(one, f_max=0.0)
    assert r.passed is False and r.margin == -np.inf
    f = Harmonic.build("f", 1, terms=[{"amplitude": 1.0, "omega": 1.0, "phase": 0.0},
                                      {"amplitude": 1.0, "omega": math.sqrt(2.0), "phase": 0.0}])
    r = pc.check_forcing_bounded(f, samples_per_period=8)
    assert r.witness["commensurate"] is False and r.witness["period"] == pytest.approx(400 * math.pi)
    assert r.reason == "incommensurate frequencies: sup sampled over 200 slow periods"
    # 200·8 samples over 200 slow periods: the sup 2 is approached (t = 0 is a sample)
    assert r.witness["sup_norm"] == pytest.approx(2.0, rel=1e-12)


def test_harmonic_with_nonfinite_amplitude_fails():
    f = Harmonic.build("f", 1, constant=[1.0])
    f = Harmonic(np.array([np.inf]), f.amplitude, f.omega, f.phase) if hasattr(f, "amplitude") else f
    r = pc.check_forcing_bounded(f)
    assert r.passed is False and r.margin == -np.inf and r.tolerance == 1e-9
    assert r.reason == "forcing amplitudes are not finite" and r.name == "forcing_bounded"
    assert r.summary_keys == ("sup_norm", "analytic_bound", "f_max", "t_star", "period")


def test_generic_forcing_windows_and_growth():
    calls = []

    def ramp(t):
        t = np.asarray(t, float)
        calls.append(t.size)
        return np.stack([t, 0 * t], axis=-1)
    r = pc.check_forcing_bounded(ramp, horizon=1.0, windows=3, samples_per_period=16)
    w = r.witness
    assert w["window_lengths"] == [1.0, 2.0, 4.0]
    assert w["window_sups"] == pytest.approx([1.0, 2.0, 4.0], rel=1e-12)
    assert w["growth_last_doubling"] == pytest.approx(1.0, rel=1e-12)
    assert w["sup_norm"] == pytest.approx(4.0) and math.isnan(w["analytic_bound"]) and w["f_max"] is None
    assert w["t_star"] == pytest.approx(4.0)
    assert calls[0] == 17 and 33 in calls and 65 in calls               # samples·2^j + 1
    assert r.passed is False and r.margin == pytest.approx(-1.0) and r.tolerance == 0.05
    assert r.reason == "sup‖f‖ keeps growing with the window (1 → 4): unbounded"
    assert r.summary_keys == ("sup_norm", "growth_last_doubling", "t_star")
    # near miss on growth_tol (default 0.05): sup grows by 4 % / 6 % in the last doubling
    for g, ok in ((0.04, True), (0.06, False)):
        def sat(t, g=g):
            t = np.asarray(t, float)
            return np.stack([np.where(t > 4.0, 1.0 + g, 1.0)], axis=-1)
        r = pc.check_forcing_bounded(sat, horizon=1.0, windows=4, samples_per_period=8)
        assert r.witness["growth_last_doubling"] == pytest.approx(g, rel=1e-9)
        assert r.passed is ok
        assert (r.reason == "no analytic bound: sup sampled over doubling windows") is ok


def test_generic_forcing_with_a_claimed_bound_and_zero_signals():
    f = lambda t: np.stack([np.cos(np.asarray(t, float))], axis=-1)   # noqa: E731
    r = pc.check_forcing_bounded(f, f_max=2.0, horizon=1.0, windows=2)
    assert r.margin == pytest.approx(0.5, rel=1e-12) and r.passed is True and r.tolerance == 1e-9
    assert r.reason == "no analytic bound: sup sampled over a window" and r.witness["f_max"] == 2.0
    assert r.evidence == "sampled"
    assert r.summary_keys == ("sup_norm", "analytic_bound", "f_max", "t_star", "period")
    z = lambda t: np.zeros((np.asarray(t).size, 1))                    # noqa: E731
    r = pc.check_forcing_bounded(z, horizon=1.0, windows=2)
    assert r.witness["growth_last_doubling"] == 0.0 and r.passed is True
    late = lambda t: np.stack([np.where(np.asarray(t, float) > 1.5, 1.0, 0.0)], axis=-1)  # noqa: E731
    r = pc.check_forcing_bounded(late, horizon=1.0, windows=2)
    assert r.witness["growth_last_doubling"] == np.inf and r.passed is False


def test_not_definite_reason_relative_floor_and_text():
    """The exact class decides singular/indefinite; an exactly definite K below the
    toolkit's float64 floor (1e-12·λ_max) is called definite, never singular."""
    from proofs_checks.assumptions import not_definite_reason
    assert not_definite_reason(_sym([2.0, 8.0]), "why") is None
    assert not_definite_reason(np.diag([5.0, 1.0, 1.5e-11]), "why") is None       # 3e-12·λ_max
    tiny = not_definite_reason(np.diag([5.0, 1.0, 5e-12]), "x")
    assert tiny.startswith("K ≻ 0 holds (exact)") and "singular" not in tiny
    assert not_definite_reason(np.diag([5.0, 1.0, 5e-12]), "x", run=False) is None
    assert not_definite_reason(np.diag([5.0, 1.0, 2e-12]), "x") is not None     # floor from λ_max = 5, not 1
    assert not_definite_reason(np.diag([0.2, 0.1]), "x") is None                 # λ_max < 1
    assert not_definite_reason(np.diag([-3.0, -1.0]), "c").startswith("K is indefinite (exact")
    assert not_definite_reason(np.zeros((2, 2)), "c").startswith("K is singular (exact")
    assert not_definite_reason(np.zeros((2, 2)), "c").endswith(": c")
    # the symmetric part decides (a skew part is ignored)
    assert not_definite_reason(np.array([[1.0, 4.0], [-4.0, -2.0]]), "c").startswith("K is indefinite")


def test_not_definite_reason_one_degree_of_freedom():
    """n = 1: the spectrum has a single entry (no eig[1] or eig[-2] to look at)."""
    from proofs_checks.assumptions import not_definite_reason
    assert not_definite_reason(np.array([[2.0]]), "x") is None
    assert not_definite_reason(np.array([[0.0]]), "x").startswith("K is singular (exact")


def test_constraints_square_and_dependent_without_warnings():
    """m = n independent columns pass with their condition number; a rank-deficient W gives
    cond = inf without a division-by-zero warning."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = pc.check_constraints_independent(np.diag([2.0, 0.5]))
        assert r.passed is True and r.witness["sigma_min"] == 0.5 and r.witness["condition_number"] == 4.0
        assert r.margin == pytest.approx(6.0 - math.log10(4.0), rel=1e-14)
        r = pc.check_constraints_independent(np.array([[1.0, 1.0], [0.0, 0.0]]))
        assert r.witness["condition_number"] == np.inf and r.margin == -np.inf


def test_symmetry_edges_and_input_types():
    """Symmetry is exact (SYMMETRY_RTOL = 0): any asymmetry, however small relative to the
    matrix's scale, is a counterexample; the failure keeps its witness; boolean matrices are
    read as numbers."""
    from proofs_checks.assumptions import SYMMETRY_RTOL
    assert SYMMETRY_RTOL == 0.0
    small = 1e-3 * np.array([[1.0, 1e-9], [0.0, 1.0]])              # relative asymmetry 1e-9
    r = pc.check_mass_spd(small)
    assert r.passed is False and r.witness["asymmetry"] == pytest.approx(1e-9, rel=1e-12)
    assert r.witness["lambda_max"] == pytest.approx(1e-3, rel=1e-6) and r.margin == -r.witness["asymmetry"]
    assert pc.check_mass_spd(np.eye(2, dtype=bool)).passed is True


@pytest.mark.parametrize("check,label", [(pc.check_mass_spd, "M"), (pc.check_stiffness_spd, "K")])
def test_one_ulp_asymmetry_is_violated_exactly(check, label):
    """Issue 36 item 1: an SPD matrix whose transpose differs by one ulp in one entry used to
    pass as "M = Mᵀ ≻ 0 (exact)". Reference (independent of proofs_checks): the entries as
    Fractions, A ≠ Aᵀ exactly at [2, 0]; the exactly symmetric original passes."""
    from fractions import Fraction
    A = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, 0.25], [0.5, 0.25, 2.0]])
    assert check(A).evidence == "proved"
    A[2, 0] = np.nextafter(0.5, 1.0)
    F = [[Fraction(float(x)) for x in row] for row in A]
    asym = [(i, j) for i in range(3) for j in range(3) if F[i][j] != F[j][i]]
    assert asym == [(0, 2), (2, 0)] and F[2][0] - F[0][2] == Fraction(1, 2**53)
    r = check(A)
    assert r.passed is False and r.evidence == "violated" and r.margin < 0
    assert r.witness["entry"] == [0, 2]
    assert Fraction(float(r.witness["transposed_value"])) == F[2][0]
    assert r.verdict == f"{label} ≠ {label}ᵀ (exact): entry [0, 2]"


# ----------------------------------------------------------------------------- A2 near misses
def test_common_period_tolerance_is_relative_and_slow_period_scales():
    # ratio 50 + 1e-11: relative error 2e-13 < 1e-12, commensurate (absolute error 1e-11)
    T, ok = fo.common_period(np.array([1.0, 50.0 + 1e-11]))
    assert ok is True and T == pytest.approx(2 * math.pi, rel=1e-15)
    # incommensurate: 200 periods of the slowest term, 2π/ω_min each
    T, ok = fo.common_period(np.array([2.0, 2.0 * math.sqrt(2.0)]))
    assert ok is False and T == pytest.approx(200 * math.pi, rel=1e-15)


def test_sup_norm_window_not_starting_at_zero():
    """On [−1, 1] with 8 samples the bump at t = 0.1 lies between samples: the refinement
    around the best samples (spacing (t1 − t0)/samples) finds it."""
    f = lambda t: np.stack([1.0 - (np.asarray(t, float) - 0.1) ** 2], axis=-1)    # noqa: E731
    S, ts = fo._sup_norm(f, -1.0, 1.0, 8)
    assert S == pytest.approx(1.0, abs=1e-12) and ts == pytest.approx(0.1, abs=1e-5)


def test_forcing_defaults_small_bounds_and_texts():
    from proofs_checks.forcing import EQUATION
    # the default windows: horizon 10, five doublings, 4096 samples per horizon (a spike on
    # the first grid point after 0 is seen on every window)
    spike = lambda t: (np.abs(np.asarray(t, float) - 10.0 / 4096) < 1e-12).astype(float)[..., None]  # noqa: E731
    r = pc.check_forcing_bounded(spike)
    assert r.witness["window_lengths"] == [10.0, 20.0, 40.0, 80.0, 160.0]
    assert r.witness["window_sups"] == [1.0] * 5 and r.passed is True
    # an analytic bound below 1 is still a relative margin
    half = Harmonic.build("f", 1, constant=[0.5])
    r = pc.check_forcing_bounded(half)
    assert r.witness["analytic_bound"] == 0.5 and r.margin == 0.0 and r.passed is True
    # the claimed-bound and growth results carry their name and equation; the claimed bound
    # is compared with the sup over the longest window
    ramp = lambda t: np.asarray(t, float)[..., None]                               # noqa: E731
    r = pc.check_forcing_bounded(ramp, f_max=100.0, horizon=1.0, windows=5, samples_per_period=4)
    assert (r.name, r.equation) == ("forcing_bounded", EQUATION)
    assert r.witness["window_sups"] == pytest.approx([1, 2, 4, 8, 16]) and r.margin == pytest.approx(0.84)
    r = pc.check_forcing_bounded(ramp, horizon=1.0, windows=2, samples_per_period=4)
    assert (r.name, r.equation) == ("forcing_bounded", EQUATION)
    # zero on the first three windows, then nonzero: infinite growth
    late = lambda t: np.where(np.asarray(t, float) > 50.0, 1.0, 0.0)[..., None]   # noqa: E731
    r = pc.check_forcing_bounded(late, horizon=10.0, windows=4, samples_per_period=64)
    assert r.witness["window_sups"] == [0.0, 0.0, 0.0, 1.0] and r.witness["growth_last_doubling"] == np.inf
    assert r.passed is False
    # growth exactly at growth_tol passes, with the plain reason
    step = lambda t: np.where(np.asarray(t, float) > 1.0, 1.5, 1.0)[..., None]    # noqa: E731
    r = pc.check_forcing_bounded(step, horizon=1.0, windows=2, samples_per_period=8, growth_tol=0.5)
    assert r.witness["growth_last_doubling"] == 0.5 and r.passed is True
    assert r.reason == "no analytic bound: sup sampled over doubling windows"


def test_nonfinite_amplitude_result_keeps_witness_and_equation():
    from proofs_checks.forcing import EQUATION
    f = Harmonic.build("f", 1, constant=[1.0])
    f = Harmonic(np.array([np.inf]), f.amplitude, f.omega, f.phase)
    r = pc.check_forcing_bounded(f)
    assert r.equation == EQUATION and r.witness["analytic_bound"] == np.inf
    assert r.witness["commensurate"] is True


def test_sup_norm_locates_the_sup_to_the_optimizer_precision():
    """The bounded refinement runs to xatol = 1e-12·max(1, t): the time of the sup of sin on
    [0, 3] is found to 1e-8 (the default xatol 1e-5 leaves it ~6e-8 off)."""
    f = lambda t: np.stack([np.sin(np.asarray(t, float))], axis=-1)       # noqa: E731
    for samples in (5, 7):
        S, ts = fo._sup_norm(f, 0.0, 3.0, samples)
        assert abs(ts - math.pi / 2) < 1e-8 and S == pytest.approx(1.0, abs=1e-15)


# ----------------------------------------------------------------------------- defects found by mutmut
def test_more_contacts_than_dofs_witness_is_a_vanishing_combination():
    """m > n: the witness ``null_combination`` is a unit vector c with W c = 0 (the columns'
    dependence the docstring promises), not the right singular vector of the smallest
    *nonzero* σ that the reduced SVD ends with. Checked from W itself: ‖W c‖ against
    round-off of ‖W‖, and for rank n = 2 against the one null direction (1, 1, −1)/√3."""
    W = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])                 # n = 2, m = 3, rank 2
    c = pc.check_constraints_independent(W).witness["null_combination"]
    assert c.shape == (3,) and abs(np.linalg.norm(c) - 1.0) < 1e-15
    assert np.linalg.norm(W @ c) <= 1e-14 * np.linalg.norm(W, 2)
    assert abs(abs(c @ np.array([1.0, 1.0, -1.0])) / math.sqrt(3.0) - 1.0) < 1e-14
    # rank 1, a two-dimensional null space: any unit c in it will do
    W1 = np.array([[1.0, 2.0, 0.5]])
    c = pc.check_constraints_independent(W1).witness["null_combination"]
    assert abs(np.linalg.norm(c) - 1.0) < 1e-15 and abs(W1 @ c).max() <= 1e-14 * np.linalg.norm(W1)


@pytest.mark.parametrize("check", [pc.check_mass_spd, pc.check_stiffness_spd, pc.check_damping_pd])
def test_nested_lists_and_booleans_read_like_float_arrays(check):
    """A nested list is the matrix it spells (it used to raise AttributeError on ``.T``);
    a boolean matrix is read as 0/1 numbers in the witness eigenvector too (with ``A + Aᵀ``
    taken on booleans it is a logical or: the symmetric part of [[1, 1], [0, 0]] would be
    [[½, ½], [½, 0]] instead of [[1, ½], [½, 0]])."""
    cases = ([[2.0, 1.0], [1.0, 3.0]],                                # SPD
             [[1, 0], [0, 1]],                                          # integers
             [[1.0, 0.3], [0.0, 2.0]],                                  # not symmetric
             [[1.0, 2.0], [2.0, 1.0]],                                  # indefinite (−1, 3)
             [[True, True], [False, False]])                            # boolean, not symmetric
    for A in cases:
        got, ref = check(A), check(np.array(A, dtype=float))
        assert (got.passed, got.reason, got.margin) == (ref.passed, ref.reason, ref.margin)
        for key in ("lambda_min", "lambda_max", "relative_lambda_min", "asymmetry"):
            assert got.witness.get(key) == ref.witness.get(key)
        v, u = got.witness["eigenvector_min"], ref.witness["eigenvector_min"]
        assert abs(abs(v @ u) - 1.0) < 1e-14
    # the verdicts themselves, from the spectra: SPD passes, indefinite fails everywhere
    assert check([[2.0, 1.0], [1.0, 3.0]]).passed is True
    r = check([[1.0, 2.0], [2.0, 1.0]])
    assert r.passed is False and r.witness["lambda_min"] == pytest.approx(-1.0, rel=1e-14)
    # the symmetric part of the boolean [[1, 1], [0, 0]] is [[1, ½], [½, 0]]: λ_min = (1 − √2)/2
    lam = (1.0 - math.sqrt(2.0)) / 2.0
    v = check([[True, True], [False, False]]).witness["eigenvector_min"]
    S = np.array([[1.0, 0.5], [0.5, 0.0]])
    assert np.linalg.norm(S @ v - lam * v) < 1e-14
    if check is not pc.check_damping_pd:                               # required symmetric
        assert check([[1.0, 0.3], [0.0, 2.0]]).passed is False
