"""proofs_checks: tests written against the surviving mutants of the mutation run
(``tests/mutants/proofs_checks.md``).

Each test asserts a property of a helper or a check on inputs whose answer is known
independently: analytic slopes, hand-built pair lists, the stated conventions of x/0 and
NaN, tolerance pins just inside / just outside a threshold. No expected value is computed
by the code under test. All inputs are synthetic (no simulation), so the file runs in
well under a second.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from proofs_checks import lyapunov as ly


# ----------------------------------------------------------------------------- fit_order
def test_fit_order_recovers_an_exact_power_law():
    """values = c·h^p, c < 1 so every value is below 1: the slope is p (degree-1 fit, slope
    coefficient, not the intercept log c, not a quadratic term)."""
    hs = np.array([1e-3, 2e-3, 4e-3, 8e-3])
    assert ly.fit_order(hs, 3e-2 * hs ** 1.5) == pytest.approx(1.5, abs=1e-12)
    # plain lists of floats are accepted
    assert ly.fit_order(list(hs), list(7.0 * hs ** 0.5)) == pytest.approx(0.5, abs=1e-12)


def test_fit_order_uses_only_the_positive_finite_values():
    """Zero, negative, inf and NaN values are dropped: the slope of the two remaining points."""
    hs = np.array([1.0, 2.0, 4.0, 8.0, 16.0, 32.0])
    vals = np.array([0.0, 0.25 * 2.0 ** 2, np.inf, -1.0, 0.25 * 16.0 ** 2, np.nan])
    assert ly.fit_order(hs, vals) == pytest.approx(2.0, abs=1e-12)       # from h = 2 and h = 16


def test_fit_order_needs_two_points():
    assert ly.fit_order([1.0, 2.0], [0.5, 0.25]) == pytest.approx(-1.0, abs=1e-12)   # exactly two
    assert math.isnan(ly.fit_order([1.0, 2.0, 4.0], [0.0, 0.3, -1.0]))               # one positive
    assert math.isnan(ly.fit_order([1.0, 2.0], [0.0, 0.0]))


# ----------------------------------------------------------------------------- _relative / _worst
def test_relative_conventions():
    """(values − allowance)/V; NaN → −inf; over V = 0: x > 0 → +inf, x < 0 → −inf, 0 → 0."""
    values = np.array([3.0, np.nan, 1.0, -1.0, 0.5, 2.0, 5.0])
    V = np.array([2.0, 1.0, 0.0, 0.0, 0.0, 4.0, 0.5])
    allowance = np.array([1.0, 0.0, 0.0, 0.0, 0.5, 2.0, 0.0])
    with np.errstate(all="raise"):                        # no warning escapes the helper
        rel = ly._relative(values, V, allowance)
    assert rel.tolist() == [1.0, -np.inf, np.inf, -np.inf, 0.0, 0.0, 10.0]


def test_relative_near_miss_on_the_allowance():
    """A value just above / at / just below its allowance over V = 0 and V > 0."""
    a = np.array([1e-20, 1e-20, 1e-20, 1e-20])
    vals = np.array([1.5e-20, 0.5e-20, 1.5e-20, 1e-20])
    V = np.array([0.0, 0.0, 1e-10, 0.0])
    rel = ly._relative(vals, V, a)
    assert rel[0] == np.inf and rel[1] == -np.inf and rel[3] == 0.0
    assert rel[2] == pytest.approx(0.5e-20 / 1e-10, rel=1e-12)


def test_worst_returns_the_max_and_its_step():
    values = np.array([1.0, 5.0, 3.0, np.nan])
    V = np.array([1.0, 2.0, 1.0, 1.0])
    allowance = np.array([0.0, 1.0, 0.0, 0.0])
    val, k = ly._worst(values, V, allowance)
    assert (val, k) == (3.0, 2) and isinstance(val, float) and isinstance(k, int)


# ----------------------------------------------------------------------------- slacks_of
def test_slacks_of_is_the_worst_positive_excess_and_zero_otherwise():
    V = np.array([2.0, 4.0, 1.0, 3.0])                      # V_k = V[:-1]; V[-1] must not be used
    parts = {"V": V, "roundoff": np.array([0.1, 0.0, 0.2]),
             "impulse_slack": np.array([0.5, 0.4, 0.2]),          # (0.4/2, 0.4/4, 0/1) → 0.2
             "impulse_target": np.array([-1.0, -2.0, -0.1]),      # negative → 0
             "projection_unprojected_gap": np.array([0.0, 0.0, 0.7])}   # (0.7 − 0.2)/1 = 0.5
    assert ly.slacks_of(parts) == {"impulse_slack": pytest.approx(0.2), "impulse_target": 0.0,
                                   "projection_unprojected_gap": pytest.approx(0.5)}
    small = dict(parts, impulse_slack=np.array([0.4, 0.0, 0.0]))  # 0.3/2 = 0.15 < 1 (no floor at 1)
    assert ly.slacks_of(small)["impulse_slack"] == pytest.approx(0.15)


# ----------------------------------------------------------------------------- run_pairs
def _fake_run(projected: dict[str, bool]) -> SimpleNamespace:
    return SimpleNamespace(slaves={n: SimpleNamespace(projected=p) for n, p in projected.items()},
                           master=SimpleNamespace(projected=False))


def test_run_pairs_labels_and_members():
    run = _fake_run({"n1": False, "j1": True, "n2": False, "j2": True, "j3": True, "n3": False})
    assert ly.run_pairs(run) == [("jump pair", "j1", "j2"), ("no-jump pair", "n1", "n2"),
                                 ("master–jump", "j1", "master"), ("master–no-jump", "n1", "master")]


def test_run_pairs_with_one_observer_of_each_design():
    run = _fake_run({"j": True, "n": False})
    assert ly.run_pairs(run) == [("master–jump", "j", "master"), ("master–no-jump", "n", "master")]
    assert ly.run_pairs(_fake_run({})) == []
    assert ly.run_pairs(_fake_run({"a": False, "b": False})) == [("no-jump pair", "a", "b"),
                                                               ("master–no-jump", "a", "master")]


def test_traj_resolves_master_and_observers():
    run = _fake_run({"master2": True})
    assert ly._traj(run, "master") is run.master
    assert ly._traj(run, "master2") is run.slaves["master2"]


# ----------------------------------------------------------------------------- _quad / Â
def test_quad_is_the_row_wise_quadratic_form():
    X = np.array([[1.0, 2.0], [-3.0, 0.5]])
    Q = np.array([[2.0, 1.0], [0.0, 5.0]])                  # not symmetric on purpose
    expected = [2 * 1 + 1 * 2 + 5 * 4, 2 * 9 + 1 * (-3 * 0.5) + 5 * 0.25]
    assert ly._quad(X, Q).tolist() == expected


def test_iteration_matrix_is_M_plus_h_theta_C_plus_h2_theta2_K():
    M, C, K = np.diag([2.0, 3.0]), np.array([[1.0, 0.5], [0.5, 4.0]]), np.array([[7.0, -1.0], [-1.0, 9.0]])
    run = SimpleNamespace(system=SimpleNamespace(M=M, C=C, K=K), h=0.1, theta=0.75)
    expected = M + 0.075 * C + 0.075 ** 2 * K
    assert np.allclose(ly._iteration_matrix(run), expected, rtol=1e-15, atol=0)


# ----------------------------------------------------------------------------- slack_order
def test_slack_order_reruns_at_h_times_factors_and_fits_each_positive_slack(monkeypatch):
    """The base row is reused at factor 1, every other factor is re-run at h·f; a slack that
    is zero at the base step gets no order (NaN), even if the coarser re-runs show it."""
    calls = []

    def fake_rerun(run, h):
        calls.append(h)
        return SimpleNamespace(h=h)

    def fake_positive_slack(r):
        return {"impulse_slack": 0.3 * r.h, "impulse_target": 5.0 * r.h, "projection_unprojected_gap": 2.0 * r.h ** 2}

    monkeypatch.setattr(ly, "rerun", fake_rerun)
    monkeypatch.setattr(ly, "positive_slack", fake_positive_slack)
    run = SimpleNamespace(h=1e-2)
    base = {"impulse_slack": 0.3 * 1e-2, "impulse_target": 0.0, "projection_unprojected_gap": 2.0 * 1e-4}
    out = ly.slack_order(run, base, (1.0, 2.0, 4.0))
    assert calls == [2e-2, 4e-2]
    assert np.allclose(out["h"], [1e-2, 2e-2, 4e-2], rtol=1e-15)
    assert np.allclose(out["impulse_slack_slack"], [3e-3, 6e-3, 1.2e-2], rtol=1e-15)
    assert out["impulse_slack_order"] == pytest.approx(1.0, abs=1e-9)
    assert out["projection_unprojected_gap_order"] == pytest.approx(2.0, abs=1e-9)
    assert math.isnan(out["impulse_target_order"])
    assert np.allclose(out["impulse_target_slack"], [0.0, 0.1, 0.2], rtol=1e-15, atol=0)


# ============================================================================= switching.py (A1)
from proofs_checks import switching as sw  # noqa: E402

EPS = float(np.finfo(float).eps)


def _system(W, nu, nu_dot):
    """A stand-in for LinearSystem with the fields check_switching_generated uses."""
    W = np.asarray(W, float)
    return SimpleNamespace(W=W, n=W.shape[0], m=W.shape[1], nu=nu, nu_dot=nu_dot,
                           gaps=lambda q, t: q @ W + nu(t))


def _run(system, t, q, u, chi, active=None, theta=0.5):
    chi = np.asarray(chi, bool)
    master = SimpleNamespace(q=np.asarray(q, float), u=np.asarray(u, float),
                             active=chi.copy() if active is None else np.asarray(active, bool))
    return SimpleNamespace(system=system, t=np.asarray(t, float), h=float(t[1] - t[0]), theta=theta,
                           master=master, chi=chi)


def test_predicted_gaps_and_band_follow_the_documented_formula():
    """g_pred = Wᵀ(q + (h/2)u) + ν(t) + (h/2)ν̇(t); band = 4(n+2)·eps·(|Wᵀ|(|q| + (h/2)|u|) + |ν| + (h/2)|ν̇|),
    with a time-varying ν so that every term counts."""
    rng = np.random.default_rng(3)
    W = rng.standard_normal((3, 2))
    nu = lambda t: np.stack([np.sin(3 * t), 0.3 * t ** 2 - 1], axis=-1)          # noqa: E731
    nud = lambda t: np.stack([3 * np.cos(3 * t), 0.6 * t], axis=-1)              # noqa: E731
    t = np.linspace(0.0, 2.0, 9)
    h = t[1] - t[0]
    q, u = rng.standard_normal((9, 3)), 10 * rng.standard_normal((9, 3))
    gp, band = sw.predicted_gaps(_system(W, nu, nud), q, u, t, h)
    expected = np.array([W.T @ (q[k] + 0.5 * h * u[k]) + nu(t[k]) + 0.5 * h * nud(t[k]) for k in range(9)])
    assert np.allclose(gp, expected, rtol=1e-13, atol=1e-13)
    scale = np.array([np.abs(W).T @ (np.abs(q[k]) + 0.5 * h * np.abs(u[k])) + np.abs(nu(t[k]))
                      + 0.5 * h * np.abs(nud(t[k])) for k in range(9)])
    assert np.allclose(band, 4.0 * (3 + 2) * EPS * scale, rtol=1e-12, atol=0)


def test_switch_off_intervals_by_hand():
    """Only χ = 0 runs with a closed step on both sides count (not at the start or the end)."""
    cols = [[0, 1, 0, 1, 1, 0, 0, 1, 0],       # (0,0) at start, (2,2) and (5,6) inside, (8,8) at end
            [1, 0, 1, 1, 0, 1, 1, 0, 1],       # (1,1), (4,4), (7,7): next to both ends
            [0, 0, 1, 0, 1, 1, 1, 1, 1]]       # (0,1) at start (last entry closed), (3,3) inside
    chi = np.array(cols, dtype=bool).T
    assert sw.switch_off_intervals(chi) == [(0, 2, 2), (0, 5, 6), (1, 1, 1), (1, 4, 4), (1, 7, 7), (2, 3, 3)]


# A run with ν(t) = a·t whose predicted gaps are G (rows 0..N−1) and whose states satisfy the
# θ = ½ scheme exactly up to round-off: gp_{k+1} − gp_k = h·u_{k+1} + a·h.
G = np.array([-0.01, -0.02, -0.01, 0.004, -0.02, -0.03, 0.02, 0.01, -0.01, -0.02])
A_NU, H = 0.3, 0.01


def _g_run(chi_s=None, flip_recorded=True):
    N = G.size
    t = H * np.arange(N + 1)
    u = np.empty(N + 1)
    u[1:N] = np.diff(G) / H - A_NU
    u[0], u[N] = 0.7, u[N - 1]
    q = np.empty(N + 1)
    q[0] = G[0] - 0.5 * H * u[0] - 0.5 * H * A_NU
    for k in range(N):
        q[k + 1] = q[k] + 0.5 * H * (u[k] + u[k + 1])
    system = _system([[1.0]], lambda t: A_NU * np.asarray(t)[..., None] * np.ones(1),
                     lambda t: A_NU * np.ones_like(np.asarray(t))[..., None])
    closed = (G <= 0)[:, None]
    chi = np.zeros((N + 1, 1), bool)
    chi[1:] = closed if chi_s is None else np.asarray(chi_s, bool)[:, None]
    active = np.zeros((N + 1, 1), bool)
    active[1:] = closed
    if flip_recorded:
        active[4, 0] = not active[4, 0]
    return _run(system, t, q[:, None], u[:, None], chi, active), q, t


def test_switching_witness_on_a_hand_built_run():
    run, q, t = _g_run()
    r = sw.check_switching_generated(run)
    assert r.passed is True and r.reason == "" and r.tolerance == 1e-9
    assert r.name == "switching_generated" and r.equation == "A1, Definition 2, eq. (12)"
    w = r.witness
    assert w["mismatched_steps"] == 0 and w["steps"] == G.size
    assert w["steps_within_roundoff_band"] == 0 and w["mismatches_within_roundoff_band"] == 0
    assert w["min_open_predicted_gap"] == pytest.approx(0.004, rel=1e-9)
    assert w["recorded_closed_set_differs"] == 1
    assert w["closed_steps"] == 7
    assert w["switch_off_intervals_in_closed_phases"] == 2 and w["one_step_switch_offs"] == 1
    assert w["min_open_gap_of_one_step_switch_offs"] == pytest.approx(0.004, rel=1e-9)
    g = q + A_NU * t                                       # gaps of W = 1, ν = a·t
    assert w["gap_scale"] == pytest.approx(max(np.max(np.abs(G)), np.max(np.abs(g))), rel=1e-12)
    assert w["gap_scale"] < 1.0
    assert w["max_gap_jump"] <= 1e-15                      # the states follow the scheme exactly
    assert set(r.summary_keys) <= set(w) and len(r.summary_keys) == 6


@pytest.mark.parametrize("rows,k,isolated,text", [
    ((0, 9), 0, True, "χ = 0 at an isolated instant where the gap is closed"),
    ((9,), 9, True, "χ = 0 at an isolated instant where the gap is closed"),
    ((4,), 4, False, "χ = 0 where the gap is closed"),
    ((1, 2), 1, False, "χ = 0 where the gap is closed"),
    ((0, 1), 0, False, "χ = 0 where the gap is closed"),     # the next step, not the one after
    ((3,), 3, False, "χ = 1 where the gap is open"),
])
def test_switching_mismatch_witness_and_reason(rows, k, isolated, text):
    chi_s = G <= 0
    for j in rows:
        chi_s[j] = not chi_s[j]
    run, _, t = _g_run(chi_s)
    r = sw.check_switching_generated(run)
    assert r.passed is False and r.tolerance == 0.0
    assert r.reason == "χ is not generated by the master's gap: " + text
    assert r.name == "switching_generated" and r.equation == "A1, Definition 2, eq. (12)"
    assert r.margin == pytest.approx(-len(rows) / G.size, rel=1e-15)
    w = r.witness
    assert (w["first_mismatch_contact"], w["first_mismatch_step"]) == (0, k)
    assert w["first_mismatch_time"] == t[k] and w["chi_there"] is bool(chi_s[k])
    assert w["predicted_gap_there"] == pytest.approx(G[k], rel=1e-9)
    lo, hi = max(k - 2, 0), min(k + 3, G.size)
    assert np.allclose(w["predicted_gap_neighbours"], G[lo:hi], rtol=1e-9)
    assert w["chi_neighbours"].tolist() == chi_s[lo:hi].astype(int).tolist()
    assert w["master_closed_neighbours"].tolist() == (G[lo:hi] <= 0).astype(int).tolist()
    assert w["chi_neighbours"].dtype.kind == "i" and w["master_closed_neighbours"].dtype.kind == "i"
    assert set(r.summary_keys) <= set(w) and len(r.summary_keys) == 7


def _band_run():
    """Predicted gaps δ·eps computed exactly (dyadic data) next to the band 48·eps (rows 1-5);
    row 0 has a wider band (72·eps) and an open gap."""
    h = 0.125
    delta = np.array([0, 41, 55, 44, -44, -52, 0])
    q = 1.0 + delta * EPS
    q[0] = 3.0
    u = np.full(7, 8.0)
    t = h * np.arange(7)
    system = _system([[1.0]], lambda t: np.full(np.shape(t) + (1,), -2.0),
                     lambda t: np.full(np.shape(t) + (1,), 8.0))
    chi = np.zeros((7, 1), bool)
    chi[1:, 0] = [False, True, False, False, True, True]   # row 1 (open, inside the band) flipped
    return _run(system, t, q[:, None], u[:, None], chi)


def test_switching_roundoff_band_near_miss():
    """|g_pred| ≤ band counts rows at 41 and 44 ulps (band 48 ulps), not 52 or 55: pins the
    factor 4(n+2) and each term of the band as it is used by the check."""
    w = sw.check_switching_generated(_band_run()).witness
    assert w["steps_within_roundoff_band"] == 3
    assert w["mismatched_steps"] == 1 and w["mismatches_within_roundoff_band"] == 1
    assert w["min_open_predicted_gap"] == 55 * EPS


def test_switching_all_zero_gaps():
    """Gaps identically 0: every step is closed and on the band edge (0 ≤ 0), the scale is the
    floor 1e-300 and no open gap exists."""
    t = 0.1 * np.arange(6)
    system = _system([[1.0]], lambda t: np.zeros(np.shape(t) + (1,)), lambda t: np.zeros(np.shape(t) + (1,)))
    run = _run(system, t, np.zeros((6, 1)), np.zeros((6, 1)), np.ones((6, 1), bool))
    r = sw.check_switching_generated(run)
    assert r.passed is True and r.witness["mismatched_steps"] == 0
    assert r.witness["steps_within_roundoff_band"] == 5
    assert r.witness["gap_scale"] == 1e-300 and r.witness["max_gap_jump"] == 0.0
    assert math.isnan(r.witness["min_open_predicted_gap"])
    assert math.isnan(r.witness["min_open_gap_of_one_step_switch_offs"])


def test_switching_gap_jump_exact_tolerance_pin():
    """A position jump J = 0.5 on the last step (u = 0, ν = 0): the relative jump is J/scale = 1
    exactly; jump_tolerance = 1 passes (margin = −tolerance is inside), 0.5 fails."""
    t = 0.1 * np.arange(6)
    system = _system([[1.0]], lambda t: np.zeros(np.shape(t) + (1,)), lambda t: np.zeros(np.shape(t) + (1,)))
    q = np.zeros((6, 1))
    q[-1] = 0.5
    run = _run(system, t, q, np.zeros((6, 1)), np.ones((6, 1), bool))
    ok = sw.check_switching_generated(run, jump_tolerance=1.0)
    assert ok.passed is True and ok.reason == "" and ok.margin == -1.0
    assert ok.witness["max_gap_jump"] == 0.5 and ok.witness["gap_jump_time"] == t[4]
    assert ok.witness["gap_scale"] == 0.5                 # the last gap, outside the predicted rows
    bad = sw.check_switching_generated(run, jump_tolerance=0.5)
    assert bad.passed is False and bad.reason == "the master's gap jumps (not absolutely continuous)"
    assert bad.name == "switching_generated" and bad.equation == "A1, Definition 2, eq. (12)"


def test_switching_scale_from_the_predicted_gaps():
    """u = (0, 0, 0, U, −U, 0) with θ = ½: q = (0, 0, 0, hU/2, hU/2, 0); the largest predicted
    gap (hU, step 3) exceeds every gap (hU/2)."""
    h, U = 0.125, 4.0
    t = h * np.arange(6)
    u = np.zeros((6, 1))
    u[3], u[4] = U, -U
    q = np.zeros((6, 1))
    q[3] = q[4] = 0.5 * h * U
    system = _system([[1.0]], lambda t: np.zeros(np.shape(t) + (1,)), lambda t: np.zeros(np.shape(t) + (1,)))
    chi = np.zeros((6, 1), bool)
    chi[1:, 0] = [True, True, True, False, True]          # predicted gaps (0, 0, 0, hU, 0)
    r = sw.check_switching_generated(_run(system, t, q, u, chi))
    assert r.witness["gap_scale"] == h * U
    assert r.witness["mismatched_steps"] == 0 and r.passed is True
    assert r.witness["max_gap_jump"] == 0.0


# ============================================================================= projection.py
import itertools  # noqa: E402

from proofs_checks import projection as pj  # noqa: E402

PSD_EQ = "P_I L_I⁻¹ P_Iᵀ ⪰ 0, after eq. (14); eq. (17)"


@pytest.mark.parametrize("eigs,applicable", [
    ((1.0, 2.0), True), ((0.1, 0.5), True),             # λ_max < 1 is fine
    ((1e-12, 1.0), False),                               # exactly at the 1e-12 relative floor
    ((2e-12, 1.0), True),                                # just above it
    ((5e-10, 1e3), False),                               # relative, not absolute
    ((1e-11, 1.0, 100.0), False),                        # relative to λ_max, not to a middle one
    ((1e-13, 1.0, 1.0), False), ((-1.0, 1.0), False), ((0.0, 0.0), False),
])
def test_stiffness_reason_relative_floor(eigs, applicable):
    Q = np.linalg.qr(np.random.default_rng(1).standard_normal((len(eigs),) * 2))[0]
    K = Q @ np.diag(eigs) @ Q.T if max(eigs) < 1e2 else np.diag(eigs)
    reason = pj._stiffness_reason(np.diag(eigs) if min(eigs) == 1e-12 else K)
    if applicable:
        assert reason is None
    else:
        assert reason.startswith("K is not positive definite") and reason.endswith("L_I = W_IᵀK⁻¹W_I need K ≻ 0")


def _K_W(L: np.ndarray, kdiag=(2.0, 3.0, 5.0)):
    """K = diag(kdiag) and W with WᵀK⁻¹W = L exactly up to round-off (W = K^½ V, VᵀV = L)."""
    V = np.linalg.cholesky(L).T                          # VᵀV = L
    V = np.vstack([V, np.zeros((len(kdiag) - V.shape[0], V.shape[1]))])
    return np.diag(kdiag), np.sqrt(np.diag(kdiag)) @ V


def _expected_psd(L: np.ndarray):
    """Every non-empty I, by explicit inverses: (min relative eigenvalue, its set, eigenvalues,
    largest cond(L_I), its set)."""
    best, cond = None, None
    m = L.shape[0]
    for k in range(1, m + 1):
        for I in itertools.combinations(range(m), k):
            LI = L[np.ix_(I, I)]
            w = np.linalg.eigvalsh(np.linalg.inv(LI))
            rel = w[0] / np.max(np.abs(w))
            c = np.linalg.cond(LI)
            if best is None or rel < best[0] - 1e-12:
                best = (rel, list(I), w)
            if cond is None or c > cond[0] * (1 + 1e-12):
                cond = (c, list(I))
    return best, cond


def test_projection_psd_witness_recomputed_independently():
    L = np.array([[1.0, 0.5, 0.2], [0.5, 2.0, -0.3], [0.2, -0.3, 4.0]])
    K, W = _K_W(L)
    r = pj.check_projection_psd(K, W, rng=np.random.default_rng(0))
    (rel, I, w), (c, Ic) = _expected_psd(L)
    assert r.passed is True and r.reason == "" and r.name == "projection_psd" and r.equation == PSD_EQ
    x = r.witness
    assert x["min_relative_eigenvalue"] == pytest.approx(rel, rel=1e-10) and x["worst_set"] == I
    assert np.allclose(x["eigenvalues_L_I_inv"], w, rtol=1e-10)
    assert x["min_eigenvalue_P_Linv_PT"] == pytest.approx(w[0], rel=1e-10)
    assert x["max_condition_L_I"] == pytest.approx(c, rel=1e-10) and x["max_condition_set"] == Ic
    assert (x["sets_examined"], x["exhaustive"], x["m"]) == (7, True, 3)
    assert x["K_lambda_min"] == pytest.approx(2.0, rel=1e-14)
    assert set(r.summary_keys) <= set(x) and len(r.summary_keys) == 5


def test_projection_psd_ties_keep_the_first_set_and_the_exact_tolerance_edge():
    """L = I: every set has relative eigenvalue exactly 1 and condition 1: the first set [0]
    is reported for both; margin = 1 = −tolerance passes (the edge is inside)."""
    K, W = np.eye(3), np.eye(3)
    r = pj.check_projection_psd(K, W, rng=np.random.default_rng(0))
    assert r.witness["worst_set"] == [0] and r.witness["max_condition_set"] == [0]
    edge = pj.check_projection_psd(K, W, rng=np.random.default_rng(0), tolerance=-1.0)
    assert edge.passed is True and edge.reason == "" and edge.margin == 1.0


def test_projection_psd_indefinite_reason():
    K = np.diag([1.0, -2.0, 3.0])
    W = np.eye(3)[:, :2] + 0.1
    r = pj.check_projection_psd(K, W, rng=np.random.default_rng(0))
    assert r.passed is False and r.name == "projection_psd" and r.equation == PSD_EQ
    assert r.reason == "L_I is indefinite: P_I L_I⁻¹ P_Iᵀ has a negative eigenvalue"


@pytest.mark.parametrize("kdiag", [(1e-12, 1.0), (5e-10, 1e3), (0.0, 1.0)])
def test_projection_psd_not_applicable_near_singular_K(kdiag):
    r = pj.check_projection_psd(np.diag(kdiag), np.eye(2), rng=np.random.default_rng(0))
    assert r.passed is None and r.name == "projection_psd" and r.equation == PSD_EQ
    assert r.reason.startswith("K is singular") and r.reason.endswith("does not exist (needs K ≻ 0)")


def test_projection_psd_small_K_is_applicable():
    """λ_min/λ_max = 1e-10: applicable whatever the absolute size (1e-13 ≪ 1)."""
    r = pj.check_projection_psd(np.diag([1e-13, 1e-3]), np.eye(2), rng=np.random.default_rng(0))
    assert r.passed is True


def test_projection_psd_default_exhaustive_limit_is_16():
    L = np.eye(17) + 0.01 * np.ones((17, 17))
    r = pj.check_projection_psd(np.eye(17), np.linalg.cholesky(L).T, rng=np.random.default_rng(0), samples=0)
    assert r.witness["exhaustive"] is False


def test_subsets_exhaustive_edge_and_sampled_counts():
    L = np.array([[1.0, 0.3, 0.0, 0.1], [0.3, 2.0, 0.2, 0.0], [0.0, 0.2, 3.0, 0.5], [0.1, 0.0, 0.5, 4.0]])
    sets, exhaustive = pj._subsets(2, np.random.default_rng(0), 2, 0, L[:2, :2])
    assert exhaustive and sorted(map(tuple, sets)) == [(0,), (0, 1), (1,)]
    # m = 4 > 2, no samples: 4 singles + 6 pairs + the full set + one new triple of the greedy chain
    sets, exhaustive = pj._subsets(4, np.random.default_rng(0), 2, 0, L)
    assert not exhaustive and len(sets) == 12
    assert sum(s.size == 3 for s in sets) == 1 and sum(s.size == 2 for s in sets) == 6
    # enough samples of every size cover all 2⁵ − 1 sets
    L5 = np.eye(5) + 0.1 * np.ones((5, 5))
    sets, _ = pj._subsets(5, np.random.default_rng(0), 2, 400, L5)
    assert len(sets) == 31


def test_projection_closed_form_not_applicable_reasons():
    K_bad = np.diag([1.0, -1.0])
    sys_bad = SimpleNamespace(K=K_bad, W=np.eye(2))
    r = pj.check_projection_closed_form(SimpleNamespace(system=sys_bad, slaves={}))
    assert r.passed is None and r.name == "projection_closed_form"
    assert r.equation == "eqs. (13)-(14), proof of Proposition 1" and "K ≻ 0" in r.reason
    good = SimpleNamespace(K=np.eye(2), W=np.eye(2))
    r = pj.check_projection_closed_form(SimpleNamespace(system=good, slaves={"a": SimpleNamespace(projected=False)}))
    assert r.passed is None and r.name == "projection_closed_form"
    assert r.equation == "eqs. (13)-(14), proof of Proposition 1"
    assert r.reason == "the run has no observer with position jumps"


def test_projection_psd_with_singular_contact_block_reports_instead_of_crashing():
    """K = I and two identical contact directions: L_{01} = [[1, 1], [1, 1]] is singular. The
    check returns a verdict with its witness (the least-squares block) instead of raising."""
    import numpy as np
    from proofs_checks.projection import check_projection_psd
    K = np.eye(3)
    W = np.array([[1.0, 1.0], [0.0, 0.0], [0.0, 0.0]])
    r = check_projection_psd(K, W, rng=np.random.default_rng(0))
    assert r.name == "projection_psd"
    assert r.witness["sets_examined"] == 3
    assert np.isfinite(r.witness["min_eigenvalue_P_Linv_PT"])
