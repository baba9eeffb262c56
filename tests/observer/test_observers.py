"""Observers (issue 3): discrete Proposition 1, Theorem 1, the paper's rate claims, the
persistent-contact capability, the h² floor, log-driven switching and sensitive dependence.

Expensive runs are module-scoped fixtures shared by several tests. Numbers quoted in
docstrings were measured with h as in the built-in scenarios.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import observer
from observer import Slave
from observer.errors import InputError
from observer.metrics import decay_rate, floor, sync_time
from observer.observers import lyapunov, lyapunov_decrements
from observer.switching import log_from_active, read_log, sample_log
from observer.observers import METRICS, ObserverConfig, ObserverDesign


def _pair(res, a, b):
    A, B = res.slaves[a], res.slaves[b]
    ta = dict(q=A.q, u=A.u, P=A.P, sigma=A.sigma)
    tb = dict(q=B.q, u=B.u, P=B.P, sigma=B.sigma)
    return ta, tb


# ---------------------------------------------------------------- Proposition 1 (discrete, exact)
@pytest.mark.slow
@pytest.mark.parametrize("name", ["double_mass", "rocking_chain"])
def test_proposition1_matched_pairs_identical_to_last_bit(name):
    """Same IC and χ = the master's closed set: (plain master, nojump) and (projected master,
    jump) are bitwise identical over the whole horizon, with many contact events in it."""
    sc = observer.load_scenario(name)
    sc = sc.with_overrides({"observer.coupling": [0.0, sc.t_end]})
    plain = observer.simulate(sc, observers=[Slave("nojump", False, sc.q0, sc.u0)])
    s = plain.slaves["nojump"]
    assert plain.active[1:].any(axis=1).sum() > 300          # many closed steps
    assert np.array_equal(s.q, plain.q) and np.array_equal(s.u, plain.u)
    assert np.array_equal(s.P, plain.P)
    proj = observer.simulate(sc, master_projection=True,
                             observers=[Slave("jump", True, sc.q0, sc.u0)])
    s = proj.slaves["jump"]
    assert np.array_equal(s.q, proj.q) and np.array_equal(s.u, proj.u)
    # the projection did act on the master (it is not the plain run)
    assert np.max(np.abs(proj.q - plain.q)) > 1e-6
    # ... and the mismatched pair is not identical (the property is not trivial)
    mixed = observer.simulate(sc, observers=[Slave("jump", True, sc.q0, sc.u0)], t_end=1.0)
    assert np.max(np.abs(mixed.slaves["jump"].q - mixed.q)) > 0


def test_zero_initial_error_stays_zero_nojump_short():
    """Invariant (cheap version): zero initial error stays exactly zero for nojump."""
    sc = observer.load_scenario("double_mass", {"simulation.t_end": 1.0})
    res = observer.simulate(sc, observers=[Slave("nojump", False, sc.q0, sc.u0)])
    assert np.all(res.slaves["nojump"].V == 0.0)


# ---------------------------------------------------------------- Theorem 1 (V between two slaves)
@pytest.fixture(scope="module")
def two_slave_pairs():
    sc = observer.load_scenario("double_mass", {"simulation.t_end": 10.0})
    rng = np.random.default_rng(7)
    n = sc.system.n
    qa, ua = sc.q0 + 0.01 * rng.standard_normal(n), 0.1 * rng.standard_normal(n)
    qb, ub = sc.q0 - 0.01 * rng.standard_normal(n), 0.1 * rng.standard_normal(n)
    slaves = [Slave("ja", True, qa, ua), Slave("jb", True, qb, ub),
              Slave("na", False, qa, ua), Slave("nb", False, qb, ub)]
    return sc, observer.simulate(sc, observers=slaves)


@pytest.mark.parametrize("a,b", [("ja", "jb"), ("na", "nb")])
def test_theorem1_V_between_slaves(two_slave_pairs, a, b):
    """Two slaves of one kind driven by the same χ (discrete eq. (17), θ = ½).

    What holds exactly in discrete time: ΔV = damping + impulse + projection to round-off;
    damping ≤ 0; projection ≤ 0 (to round-off). The impulse part has no sign in discrete
    time (an O(h) slack of the discrete impact law), so V may rise on an impact step, but
    only by what the impulse part allows; V still decays.
    Measured (h = 1e-4): largest relative rise 1.2e-9 (nojump), impulse part ≤ 1e-8·V."""
    sc, res = two_slave_pairs
    ta, tb = _pair(res, a, b)
    V = lyapunov(sc.system, ta["q"], ta["u"], tb["q"], tb["u"])
    parts = lyapunov_decrements(sc.system, sc.h, ta, tb)
    Vk = V[:-1]
    roundoff = 1e-9 * Vk + 1e-14 * V[0]
    # exact identity up to round-off (relative to V, plus an absolute round-off floor)
    assert np.all(np.abs(parts["residual"][1:]) <= roundoff)
    assert np.all(parts["damping"] <= 0.0)
    assert np.max(parts["projection"][1:] / Vk) <= 1e-12
    # every rise of V is paid for by the impulse part alone
    assert np.all(np.diff(V) <= np.maximum(parts["impulse"][1:], 0.0) + roundoff)
    # the impulsive part is reported separately; it is small relative to V
    assert np.max(parts["impulse"][1:] / Vk) <= 1e-7
    assert np.any(parts["impulse"] < 0)                      # impacts do dissipate
    assert V[-1] <= 1e-4 * V[0]
    assert decay_rate(res.t, V) > 0.5


# ---------------------------------------------------------------- rate claims
@pytest.fixture(scope="module")
def double_mass_run():
    return observer.simulate("double_mass", t_end=10.0, observers=("jump", "nojump"))


def test_double_mass_jump_observer_faster(double_mass_run):
    """double_mass coupled from t = 0: V_jump reaches 1e-6·V(0) at least 1.5× as fast as
    V_nojump (measured 4.51 s vs 7.51 s, ratio 1.67, Poisson law, h = 1e-4)."""
    res = double_mass_run
    t_jump = sync_time(res.t, res.slaves["jump"].V, 1e-6)
    t_nojump = sync_time(res.t, res.slaves["nojump"].V, 1e-6)
    assert np.isfinite(t_jump) and np.isfinite(t_nojump)
    assert t_nojump / t_jump >= 1.5
    # the jump observer's floor lies far below the threshold
    V = res.slaves["jump"].V
    assert floor(res.t, V, 8.0) <= 1e-8 * V[0]


@pytest.fixture(scope="module")
def chain_run():
    return observer.simulate("rocking_chain", observers=("jump", "nojump"))


@pytest.mark.slow
def test_rocking_chain_jump_observer_twice_as_fast(chain_run):
    """Chain N = 10, coupled 4 ≤ t ≤ 8: V_jump falls below 1e-5·V(4) inside the window at
    least twice as fast as V_nojump (measured 2.37 s; the no-jump observer never does) and
    its floor (the plain master's discretisation floor, docs/theory/scheme.md §6; measured 6.1e-6·V(4))
    stays below that level."""
    res = chain_run
    t_jump = sync_time(res.t, res.slaves["jump"].V, 1e-5, 4.0, 8.0)
    t_nojump = sync_time(res.t, res.slaves["nojump"].V, 1e-5, 4.0, 8.0)
    assert t_jump <= 3.0
    assert t_nojump >= 2.0 * t_jump                          # inf when it never gets there
    V = res.slaves["jump"].V
    V4 = V[np.searchsorted(res.t, 4.0)]
    assert floor(res.t, V, 7.5, 8.0) <= 1e-5 * V4             # the floor stays below 1e-5·V(4)


@pytest.mark.slow
def test_uncoupled_chain_sensitive_dependence(chain_run):
    """Before coupling (t < 4) both slaves are ordinary copies started 1e-6 away: V grows
    by at least six decades, so synchronization really comes from the coupling. Both
    slaves are bitwise identical while uncoupled."""
    res = chain_run
    t, Vj, Vn = res.t, res.slaves["jump"].V, res.slaves["nojump"].V
    before = t < 4.0
    assert np.array_equal(Vj[before], Vn[before])
    assert np.max(Vj[(t >= 3.0) & before]) >= 1e6 * Vj[0]


# ---------------------------------------------------------------- persistent contact
def test_persistent_contact_only_jump_observer_converges():
    """double_mass with F = 0: the master rests (χ ≡ 1); slaves 1 cm off along W. The
    no-jump observer cannot move the slave along W and stalls; the jump observer
    projects and converges (measured V/V0: 0.5 vs 2e-18 at t = 20 s)."""
    sc = observer.load_scenario("double_mass", {"param.F": 0.0})
    q = sc.q0.copy()
    q[0] += 0.01
    res = observer.simulate(sc, observers=[Slave("jump", True, q, sc.u0),
                                           Slave("nojump", False, q, sc.u0)])
    assert res.active[1:].all()
    Vj, Vn = res.slaves["jump"].V, res.slaves["nojump"].V
    assert np.min(Vn) >= 1e-4 * Vn[0]
    assert Vj[-1] <= 1e-12 * Vj[0]


# ---------------------------------------------------------------- the discretisation floor
def test_jump_floor_scales_like_h_squared():
    """Plain master: V_jump levels off at a floor ∝ h². Median of V over t ∈ [10, 20] for
    h = 1e-3, 5e-4, 2.5e-4 (measured 7.0e-10, 2.6e-10, 5.0e-11; slope 1.90)."""
    hs = np.array([1e-3, 5e-4, 2.5e-4])
    floors = []
    for h in hs:
        res = observer.simulate("double_mass", h=h, observers=("jump",))
        floors.append(floor(res.t, res.slaves["jump"].V, 10.0, 20.0))
    slope = np.polyfit(np.log(hs), np.log(floors), 1)[0]
    assert 1.5 <= slope <= 2.5, (floors, slope)


# ---------------------------------------------------------------- log-driven switching
@pytest.fixture(scope="module")
def fine_log(tmp_path_factory):
    sc = observer.load_scenario("double_mass", {"simulation.t_end": 8.0})
    fine = observer.simulate(sc, h=2.5e-5)
    log = log_from_active(fine.t, fine.active)
    d = tmp_path_factory.mktemp("logs")
    full = d / "full.csv"
    log.to_csv(full, index=False)
    imp = log[(log.t_open == log.t_close) & (log.t_close > 1.0)].index[0]
    deleted = d / "deleted.csv"
    log.drop(index=imp).to_csv(deleted, index=False)
    return sc, full, deleted, float(log.loc[imp, "t_close"])


def test_log_driven_observer_converges_and_missed_impact_delays(fine_log):
    """χ from a log written by a master run at h/4: the jump observer converges to a floor
    (≤ 1e-7·V0); with one impact deleted from the log it still converges, later
    (measured: 1e-6·V0 at 4.46 s vs 6.50 s, 2.0 s later)."""
    sc, full, deleted, t_deleted = fine_log
    res = observer.simulate(sc, observers=("jump",), source="log", log=full)
    V = res.slaves["jump"].V
    t_full = sync_time(res.t, V, 1e-6)
    assert t_full < 6.0
    assert floor(res.t, V, 7.0) <= 1e-7 * V[0]
    res_d = observer.simulate(sc, observers=("jump",), source="log", log=deleted)
    Vd = res_d.slaves["jump"].V
    t_del = sync_time(res_d.t, Vd, 1e-6)
    assert np.isfinite(t_del)
    delay = t_del - t_full
    assert 0.5 <= delay <= 4.0, delay
    # identical until the deleted impact
    before = res.t < t_deleted - 1e-3
    assert np.array_equal(V[before], Vd[before])


def test_log_round_trip_reproduces_master_chi():
    """log_from_active → sample_log on the same grid gives the master's closed sets back exactly."""
    res = observer.simulate("double_mass", t_end=3.0)
    log = log_from_active(res.t, res.active)
    chi = sample_log(log, res.t, res.system.m)
    assert np.array_equal(chi, res.active[1:])
    assert (log.t_open == log.t_close).sum() > 10               # impacts are zero-length


@pytest.mark.parametrize("rows,problem", [
    ([(3, 0.1, 0.2)], "unknown contact index"),
    ([(0, 0.3, 0.2)], "t_open < t_close"),
    ([(0, 0.5, 0.6), (0, 0.1, 0.2)], "not sorted"),
    ([(0, 0.1, 0.5), (0, 0.4, 0.6)], "overlaps"),
    ([(0, float("nan"), 0.2)], "NaN"),
])
def test_bad_logs_are_rejected(tmp_path, rows, problem):
    path = tmp_path / "log.csv"
    pd.DataFrame(rows, columns=["contact", "t_close", "t_open"]).to_csv(path, index=False)
    with pytest.raises(InputError, match=problem) as info:
        read_log(path, m=1)
    assert info.value.field == "observer.log"


# ---------------------------------------------------------------- projection and errors
def test_projection_is_the_K_metric_closest_point():
    """After the projection g_I = 0 to round-off, and q⁺ minimises ‖q − q⁻‖_K on {g_I = 0}
    (compared with the KKT solution of the equality-constrained QP)."""
    sc = observer.load_scenario("rocking_chain", {"param.N": 3})
    stepper = observer.MoreauJean(sc.system, sc.law, 1e-3, 0.01)
    rng = np.random.default_rng(3)
    K, W = sc.system.K, sc.system.W
    for active in (np.array([0]), np.array([1, 2]), np.array([0, 3, 4, 5])):
        q = sc.q0 + 1e-3 * rng.standard_normal(sc.system.n)
        qp, sigma = stepper.project(0, q, active)
        g = qp @ W[:, active] + sc.system.nu(0.0)[active]
        assert np.max(np.abs(g)) <= 1e-14
        n, k = sc.system.n, active.size
        kkt = np.block([[K, W[:, active]], [W[:, active].T, np.zeros((k, k))]])
        rhs = np.concatenate([K @ q, -sc.system.nu(0.0)[active]])
        q_ref = np.linalg.solve(kkt, rhs)[:n]
        assert np.max(np.abs(qp - q_ref)) <= 1e-12
        assert np.allclose(sigma, np.linalg.solve(stepper.S.L[np.ix_(active, active)], -(q @ W[:, active] + sc.system.nu(0.0)[active])))


def test_jump_observer_needs_definite_stiffness():
    """The bouncing ball has K = 0: asking for the jump observer is a clear error on system.K."""
    with pytest.raises(InputError, match="positive definite") as info:
        observer.simulate("bouncing_ball", t_end=0.1, observers=("jump",))
    assert info.value.field == "system.K"
    res = observer.simulate("bouncing_ball", t_end=0.1, observers=("nojump",))
    assert "V_nojump" in res.to_frame().columns


def test_slave_may_start_penetrating_and_self_source_is_uncoupled():
    """Slaves accept any initial state (g < 0 allowed); with source = "self" each slave
    uses its own closed set, so a slave started on the master's state reproduces it."""
    sc = observer.load_scenario("double_mass", {"simulation.t_end": 1.0})
    q = sc.q0.copy()
    q[0] -= 0.05                                            # 5 cm into the ground
    res = observer.simulate(sc, observers=[Slave("jump", True, q, sc.u0)])
    assert res.slaves["jump"].V[-1] < res.slaves["jump"].V[0]
    res = observer.simulate(sc, observers=[Slave("twin", False, sc.q0, sc.u0)], source="self")
    assert np.array_equal(res.slaves["twin"].q, res.q)


def test_synchronization_summary_matches_metrics(double_mass_run):
    """The per-observer summary reports the same times as the metric functions, inf where a
    threshold is not reached in the window, and a positive rate."""
    res = double_mass_run
    summary = res.synchronization().set_index("observer")
    for name in ("jump", "nojump"):
        V = res.slaves[name].V
        assert summary.loc[name, "t_sync_1e-06"] == sync_time(res.t, V, 1e-6)
        assert summary.loc[name, "rate"] > 0.5
    assert summary.loc["nojump", "t_sync_1e-09"] == np.inf    # needs 13.7 s; the run is 10 s
    assert summary.loc["jump", "t_sync_1e-09"] < 10.0
    assert summary.loc["jump", "V_on"] == res.slaves["jump"].V[0]


# ----------------------------------------------------------------------------------------
# (formerly tests/test_mutants_observers.py)
# observer.observers: the design record's validation and metric matrices, built at test
# time (the registry's entries are built at import, before mutmut forks its children, so
# only designs constructed inside a test see mutants of ``ObserverDesign``), and the
# ``[observer] observers`` type error. Written against the mutation run of
# ``observer/observers.py`` (``tests/mutants/observers.md``).
# ----------------------------------------------------------------------------------------
def test_design_validation_at_construction():
    for metric in METRICS:
        assert ObserverDesign("d", True, metric, "d", "k").metric == metric
    assert ObserverDesign("d", False, None, "d", "k").metric is None
    for jumps, metric in ((True, None), (False, "K"), (False, "mass"), (True, "euclid"), (False, "euclid")):
        with pytest.raises(ValueError) as info:
            ObserverDesign("bad", jumps, metric, "b", "k")
        assert str(info.value) == f"observer design 'bad': metric {metric!r} does not match position_jumps={jumps}"


def test_metric_matrices():
    sc = observer.load_scenario("rocking_chain", {"param.N": 1})
    s = sc.system
    assert ObserverDesign("m", True, "mass", "m", "k").metric_matrix(s) is s.M
    eye = ObserverDesign("i", True, "identity", "i", "k").metric_matrix(s)
    assert eye.shape == (s.n, s.n) and np.array_equal(eye, np.eye(s.n))
    assert ObserverDesign("K", True, "K", "K", "k").metric_matrix(s) is None
    assert ObserverDesign("n", False, None, "n", "k").metric_matrix(s) is None


def test_observer_list_must_be_an_array():
    with pytest.raises(InputError) as info:
        ObserverConfig.from_table({"observers": "jump"}, 1, np.zeros(1), np.zeros(1))
    assert info.value.field == "observer.observers"
    assert info.value.problem == "must be an array of design names, got 'jump'"


def test_projection_part_uses_recorded_pre_jump_states_only_when_both_have_them():
    """ΔV's projection part: ½‖e⁺‖²_K − ½‖e⁻‖²_K with e⁻ from the recorded ``q_pre`` of both
    trajectories (any metric); with one of them missing, from the K-metric multipliers Σ."""
    from observer.observers import lyapunov_decrements
    s = observer.load_scenario("double_mass").system
    rng = np.random.default_rng(3)
    a = {k: rng.standard_normal((3, 2)) for k in ("q", "u", "q_pre")}
    b = {k: rng.standard_normal((3, 2)) for k in ("q", "u", "q_pre")}
    a["P"], b["P"] = rng.standard_normal((3, 1)), rng.standard_normal((3, 1))
    K = s.K
    e, e_pre = a["q"] - b["q"], a["q_pre"] - b["q_pre"]
    expected = [0.5 * (e[k] @ K @ e[k] - e_pre[k] @ K @ e_pre[k]) for k in (1, 2)]
    out = lyapunov_decrements(s, 0.01, a, b)
    assert out["projection"][0] == 0.0 and np.allclose(out["projection"][1:], expected, rtol=1e-12, atol=0)
    # b without q_pre: the K-metric form from Σ (none given: no jump, part 0)
    b_plain = {k: v for k, v in b.items() if k != "q_pre"}
    for x, y in ((a, b_plain), (b_plain, a)):
        out = lyapunov_decrements(s, 0.01, x, y)
        assert np.array_equal(out["projection"], np.zeros(3))
    sig = {**b_plain, "sigma": np.array([[0.0], [0.5], [0.0]])}
    out = lyapunov_decrements(s, 0.01, a, sig)
    ee = a["q"][1] - b["q"][1]
    em = ee + np.linalg.solve(K, s.W @ np.array([0.5]))          # e⁻ = e⁺ − K⁻¹W(Σ_a − Σ_b), Σ_a = 0
    assert out["projection"][1] == pytest.approx(0.5 * (ee @ K @ ee - em @ K @ em), rel=1e-12)
