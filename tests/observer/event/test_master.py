"""Exact event-driven master (issue 11, items 1, 2 and 4): flow, root isolation, event loop.

Every expected value is computed here independently of :mod:`observer.event`: closed forms
(docs/theory/oracles.md §1 bouncing ball, §2 impact oscillator, §5 static contact), the analytic
solution of the grazing oscillator, an analytic one-period map with ``scipy.optimize.brentq``,
and Siconos' event-driven reference outputs (``BouncingBallED.ref``, ``LinearOscillatorED.ref``).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import brentq

import observer
from observer.event.flow import Flow, expm_pade13, flow_for
from observer.event.master import run_master
from observer.event.roots import first_zero
from observer.scenario import Scenario

from oracles import oracle

G0 = 9.81


def siconos_smooth_rows(name: str) -> np.ndarray:
    """The rows of a Siconos event-driven output that are not at an impact (written once)."""
    data = np.loadtxt(oracle("siconos", name), skiprows=1)
    t = data[:, 0]
    at_impact = np.zeros(t.size, dtype=bool)
    at_impact[:-1] |= np.diff(t) == 0.0
    at_impact[1:] |= np.diff(t) == 0.0
    return data[~at_impact]


def siconos_impact_times(name: str) -> np.ndarray:
    """Impact times of a Siconos event-driven output: the rows written twice (pre, post)."""
    data = np.loadtxt(oracle("siconos", name), skiprows=1)
    t = data[:, 0]
    return t[np.flatnonzero(np.diff(t) == 0.0)]


def siconos_ball(mass: float, K: list[float], q0: list[float], e: float, t_end: float) -> Scenario:
    """Siconos' 3-DOF ball (x, y, angle; README of the oracles): M = diag(m, m, I), gap q[0]."""
    inertia = (0.6 if any(K) else 0.4) * mass * 0.1 ** 2
    doc = {"scenario": {"name": "siconos_ball"},
           "system": {"M": np.diag([mass, mass, inertia]).tolist(), "C": np.zeros((3, 3)).tolist(),
                      "K": np.diag(K).tolist(), "W": [[1.0], [0.0], [0.0]],
                      "forcing": {"constant": [-mass * G0, 0.0, 0.0]}, "gap": {"offset": [0.0]}},
           "impact": {"law": "newton", "restitution": e},
           "initial": {"q": q0, "u": [0.0, 0.0, 0.0]},
           "simulation": {"t_end": t_end, "h": 1e-2}}
    return Scenario.from_dict(doc)


# -- the exact flow --------------------------------------------------------------------------

def test_pade_exponential_of_a_rotation_is_exact_to_roundoff():
    w = 316.2277660168379
    for dt in (1e-4, 1e-2, 1.0):
        exact = np.array([[np.cos(w * dt), np.sin(w * dt)], [-np.sin(w * dt), np.cos(w * dt)]])
        assert np.max(np.abs(expm_pade13(np.array([[0.0, w], [-w, 0.0]]) * dt) - exact)) \
            <= 50 * np.finfo(float).eps * max(1.0, w * dt)


def test_free_flow_matches_the_forced_oscillator_closed_form():
    """x'' + x = cos(ωt) from x(0) = −0.5, x'(0) = 0: x = (x0 − γ_f)cos t + γ_f cos ωt."""
    sc = observer.load_scenario("impact_oscillator")
    fl = Flow(sc.system)
    w, gf = 2.8, 1.0 / (1.0 - 2.8 ** 2)
    for t in (0.3, 1.7, 5.0):
        q, u = fl.state(0.0, np.array([-0.5, 0.0]), t)
        assert q == pytest.approx((-0.5 - gf) * np.cos(t) + gf * np.cos(w * t), abs=1e-14)
        assert u == pytest.approx(-(-0.5 - gf) * np.sin(t) - gf * w * np.sin(w * t), abs=1e-14)


def test_free_flow_with_singular_stiffness_is_the_parabola():
    sc = observer.load_scenario("bouncing_ball")
    fl = Flow(sc.system)
    for t in (0.1, 0.45):
        q, u = fl.state(0.0, np.array([1.0, 0.0]), t)
        assert q == pytest.approx(1.0 - G0 * t * t / 2, abs=1e-15)
        assert u == pytest.approx(-G0 * t, abs=1e-15)


def test_constrained_flow_force_is_the_static_preload():
    """double_mass at rest on the ground: λ_s = −g_s/(wᵀK⁻¹w) (docs/theory/oracles.md §5), held for F = 0."""
    sc = observer.load_scenario("double_mass", {"param.F": 0.0})
    K, W = sc.system.K, sc.system.W[:, 0]
    q_s = np.linalg.solve(K, sc.system.forcing.constant)
    lam_s = -(W @ q_s + 0.25) / (W @ np.linalg.solve(K, W))
    fl = flow_for(sc.system, (0,))
    x0 = np.concatenate([sc.q0, sc.u0])
    assert fl.forces(0.0, x0)[0] == pytest.approx(lam_s, rel=1e-13)
    x1 = fl.state(0.0, x0, 3.0)
    assert np.max(np.abs(x1 - x0)) <= 1e-13
    assert fl.force_impulse(0.0, x0, 0.5)[0] == pytest.approx(0.5 * lam_s, rel=1e-12)


def test_force_impulse_is_the_integral_of_the_force():
    sc = observer.load_scenario("double_mass")
    fl = flow_for(sc.system, (0,))
    x0 = np.concatenate([sc.q0, sc.u0])
    s = np.linspace(0.0, 0.08, 401)
    lam = np.array([fl.forces(t, fl.state(0.0, x0, t))[0] for t in s])
    simpson = (s[1] - s[0]) / 3 * (lam[0] + lam[-1] + 4 * lam[1:-1:2].sum() + 2 * lam[2:-1:2].sum())
    assert fl.force_impulse(0.0, x0, 0.08)[0] == pytest.approx(simpson, rel=1e-10)



@pytest.mark.parametrize("dt", [1e-6, 1e-3, 0.05, 0.5])
def test_state_integral_matches_adaptive_quadrature_on_a_stiff_held_flow(dt):
    """∫₀^dt exp(As) z ds of the 4-block chain with three contacts held (entries of A up to
    ~1e5), against scipy's adaptive quadrature of exp(As) z: within 1e-13 of the largest
    component (measured ≤ 1.9e-14; the 2N-block exponential behind ``phi`` gave 1.2e-12)."""
    from scipy.integrate import quad_vec
    sc = observer.load_scenario("rocking_chain", {"param.N": 4})
    fl = flow_for(sc.system, (0, 1, 2))
    x = np.concatenate([sc.q0, sc.u0])
    x[8:] += 0.01
    z = fl.z(0.3, x)
    ref = quad_vec(lambda s: fl.expm(s) @ z, 0.0, dt, epsabs=0.0, epsrel=1e-14, limit=2000)[0]
    assert np.max(np.abs(fl.integral(dt, z) - ref)) <= 1e-13 * np.max(np.abs(ref))


# -- root isolation ----------------------------------------------------------------------------

def test_a_dip_below_zero_shorter_than_any_sampling_step_is_found():
    """Grazing orbit pushed 1e-10·X into the wall: the gap is negative for ~2e-5 s only."""
    sc = observer.load_scenario("grazing", {"param.clearance": -1e-10})
    fl = Flow(sc.system)
    x0 = np.concatenate([sc.q0, sc.u0])
    zero, t, _ = first_zero(fl, fl.gap_rows, 0.0, fl.z(0.0, x0), 20.0)
    zeta, F, w = 0.05, 1.0, 0.8
    X = F / np.hypot(1 - w * w, 2 * zeta * w)
    delta = np.arctan2(2 * zeta * w, 1 - w * w)
    t_cross = (delta - np.arccos(1.0 - 1e-10)) / w
    g = lambda s: X * (1 - 1e-10) - X * np.cos(w * s - delta)   # noqa: E731  the analytic gap
    t_exact = brentq(g, t_cross - 1e-3, delta / w, xtol=1e-15)
    assert zero is not None and zero.kind == "cross"
    assert abs(zero.t - t_exact) <= 1e-10
    grid = np.arange(0.0, 1.0, 1e-3)
    assert np.all(g(grid) > 0.0), "a 1 ms sampling would have missed it"


# -- acceptance: bouncing ball -------------------------------------------------------------------

def test_bouncing_ball_impacts_accumulation_and_rest():
    h0, e = 1.0, 0.8
    res = run_master(observer.load_scenario("bouncing_ball"), h=1e-2)
    assert res.status.ok
    t1, v1 = np.sqrt(2 * h0 / G0), np.sqrt(2 * G0 * h0)
    k = np.arange(1, 31)
    closed_form = t1 + (2 * v1 / G0) * e * (1 - e ** (k - 1)) / (1 - e)
    impacts = res.impact_times(0)
    assert np.max(np.abs(impacts[:30] - closed_form)) <= 1e-12
    t_inf = np.sqrt(2 * h0 / G0) * (1 + e) / (1 - e)
    assert len(res.zeno) == 1 and abs(res.zeno[0]["t_inf"] - t_inf) <= 1e-9
    kinds = res.events["kind"].tolist()
    assert kinds[-2:] == ["accumulation", "stick"]
    rest = res.frame[res.frame["t"] > t_inf + 1e-6]
    assert np.all(rest["q0"].abs() <= 1e-15) and np.all(rest["u0"].abs() <= 1e-15)
    # persistent contact: the impulse per full output step is m g h (λ = m g)
    assert np.allclose(rest["P0"].iloc[1:], G0 * 1e-2, rtol=1e-12)
    # momentum balance on every output step, impacts and the Zeno tail included:
    # m(u_k − u_{k−1}) = −m g h + P_k
    f = res.frame
    balance = np.diff(f["u0"]) + G0 * 1e-2 - f["P0"].to_numpy()[1:]
    assert np.max(np.abs(balance)) <= 1e-12
    # χ: the Zeno tail is closed from the last resolved impact on, for good
    assert res.intervals(0)[-1, 0] == impacts[-1]
    assert np.isinf(res.intervals(0)[-1, 1])
    # the exact state between samples: the free flight after the 3rd impact is a parabola
    t3, v3 = closed_form[2], v1 * e ** 3
    for s in (0.05, 0.2, 0.4):
        q, u = res.state(t3 + s)
        assert q == pytest.approx(v3 * s - G0 * s * s / 2, abs=1e-13)
        assert u == pytest.approx(v3 - G0 * s, abs=1e-13)


def test_bouncing_ball_matches_siconos_event_driven_impact_times():
    ref = siconos_impact_times("BouncingBallED.ref")
    res = run_master(siconos_ball(1.0, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.9, 8.5))
    ours = res.impact_times(0)
    assert ref.size == 44 and ours.size >= ref.size
    assert np.max(np.abs(ours[:ref.size] - ref)) <= 1e-10
    # the whole trajectory at Siconos' output times (LSODAR at its tolerance)
    rows = siconos_smooth_rows("BouncingBallED.ref")
    x = np.array([res.state(t) for t in rows[:, 0]])
    assert np.max(np.abs(x[:, 0] - rows[:, 1])) <= 1e-11
    assert np.max(np.abs(x[:, 3] - rows[:, 2])) <= 1e-9


def test_linear_oscillator_matches_siconos_up_to_accumulation_then_persistent_contact():
    ref = siconos_impact_times("LinearOscillatorED.ref")
    assert ref.size == 220
    mass = 1e-3
    res = run_master(siconos_ball(mass, [100.0, 100.0, 0.0], [1.0, 0.001, 0.0], 0.9, 1.5), h=1e-2)
    assert res.status.ok
    ours = res.impact_times(0)
    (zeno,) = res.zeno
    resolved = ours.size
    assert resolved >= 150
    assert np.max(np.abs(ours - ref[:resolved])) <= 1e-8
    # Siconos' remaining impacts lie in the extrapolated tail, and both switch to contact there
    assert np.all(ref[resolved:] >= ours[-1] - 1e-8)
    assert np.all(ref[resolved:] <= zeno["t_inf"] + 1e-8)
    assert abs(zeno["t_inf"] - 0.870279) <= 1e-6
    after = res.frame[res.frame["t"] > zeno["t_inf"] + 1e-2]
    assert np.all(after["active0"] == 1) and np.all(np.abs(after["g0"]) <= 1e-15)
    # λ = m g behind the wall at the spring's rest position: Siconos' lambda(2) column
    data = np.loadtxt(oracle("siconos", "LinearOscillatorED.ref"), skiprows=1)
    assert data[-1, 6] == pytest.approx(mass * G0, rel=1e-6)
    # the trajectory at Siconos' output times, x (wall) and y (free spring) coordinates
    rows = siconos_smooth_rows("LinearOscillatorED.ref")
    rows = rows[rows[:, 0] <= 1.5]
    x = np.array([res.state(t) for t in rows[:, 0]])
    assert np.max(np.abs(x[:, 0] - rows[:, 1])) <= 1e-10
    assert np.max(np.abs(x[:, 1] - rows[:, 7])) <= 1e-10
    assert np.max(np.abs(x[:, 4] - rows[:, 8])) <= 1e-7
    assert np.allclose(after["P0"] / 1e-2, data[-1, 6], rtol=1e-6)


# -- acceptance: forced impact oscillator (docs/theory/oracles.md §2) ----------------------------------------

def one_period_map(t_a: float, v_plus: float, w: float, r: float) -> tuple[float, float]:
    """Analytic next impact of x'' + x = cos ωt (x ≤ 0) from x(t_a) = 0, x'(t_a) = v_plus."""
    gf = 1.0 / (1.0 - w * w)
    A = -gf * np.cos(w * t_a)
    B = v_plus + gf * w * np.sin(w * t_a)
    x = lambda t: A * np.cos(t - t_a) + B * np.sin(t - t_a) + gf * np.cos(w * t)  # noqa: E731
    s = np.linspace(t_a + 1e-9, t_a + 4 * np.pi, 40001)
    k = np.flatnonzero(x(s) > 0.0)[0]
    t_b = brentq(x, s[k - 1], s[k], xtol=1e-15, rtol=4 * np.finfo(float).eps)
    v = -A * np.sin(t_b - t_a) + B * np.cos(t_b - t_a) - gf * w * np.sin(w * t_b)
    return t_b, -r * v


def test_impact_oscillator_one_one_orbit():
    """ω = 2.8, r = 0.8, σ = 0: V from docs/theory/oracles.md §2's quadratic, the period T = 2π/ω.

    The (1,1) orbit is unstable: the multiplier of the analytic one-period map is
    λ ≈ −2.958, so a round-off deviation of ~3e-15 reaches 1e-10 after ten periods, for any
    integrator. Checked: (a) V and T to 1e-10 for the first ten periods, and the deviation
    growing exactly like |λ|^k afterwards (no integration error added); (b) over all 50
    periods, each period of the run equals the analytic one-period map applied to the
    run's own previous impact, to 1e-10 (the event integrator is exact per period).
    """
    w, r = 2.8, 0.8
    gf = 1.0 / (1.0 - w * w)
    kappa, mu = (1 + r) / 2 / np.tan(np.pi / w), (1 - r) / (2 * w)
    V = abs(gf) / np.hypot(kappa, mu)
    phase = np.arctan2(-mu * V / gf, kappa * V / gf)          # ω t0
    T = 2 * np.pi / w
    assert V == pytest.approx(0.336177, abs=1e-6)
    x_star = np.array([phase / w, -r * V])
    t_next, v_next = one_period_map(*x_star, w, r)
    assert abs(t_next - phase / w - T) <= 1e-12 and abs(v_next + r * V) <= 1e-12
    step = 1e-6
    jac = np.column_stack([(np.array(one_period_map(*(x_star + d), w, r)) -
                            np.array(one_period_map(*(x_star - d), w, r))) / (2 * step)
                           for d in (np.array([step, 0.0]), np.array([0.0, step]))])
    lam = np.max(np.abs(np.linalg.eigvals(jac)))
    assert lam > 2.9                                            # unstable
    periods = 50
    sc = observer.load_scenario("impact_oscillator", {
        "system.forcing.phase": float(phase), "initial.q": [0.0], "initial.u": [-r * V],
        "simulation.t_end": (periods + 0.5) * T, "simulation.h": 0.05})
    res = run_master(sc)
    assert res.status.ok
    imp = res.events[res.events["kind"] == "impact"]
    times, g_minus, g_plus = (imp[c].to_numpy() for c in ("time", "gamma_minus", "gamma_plus"))
    k = np.arange(1, times.size + 1)
    dev = np.maximum(np.abs(times - k * T), np.abs(-g_minus - V))
    assert times.size >= periods - 5
    assert np.all(dev[:10] <= 1e-10)
    linear = 1e-14 * lam ** k <= 1e-4
    assert np.all(dev[linear] <= 1e-14 * lam ** k[linear])
    # per period: x = q, g = σ − q, so ẋ⁺ = −γ⁺ and the approach speed is −γ⁻; the run's
    # time is the map's time minus t0 (the forcing phase ωt0)
    t0 = phase / w
    t_prev, v_prev = 0.0, -r * V
    for t_k, gm, gp in zip(times, g_minus, g_plus):
        t_pred, v_pred = one_period_map(t0 + t_prev, v_prev, w, r)
        assert abs(t_pred - t0 - t_k) <= 1e-10
        assert abs(-v_pred / r + gm) <= 1e-10
        t_prev, v_prev = t_k, -gp


# -- acceptance: grazing ------------------------------------------------------------------------

def test_every_graze_of_the_steady_orbit_is_found_at_its_exact_time():
    """Clearance 0: x = X cos(ωt − δ) touches σ = X at ωt − δ = 2πk (analytic), nothing else."""
    zeta, w = 0.05, 0.8
    delta = np.arctan2(2 * zeta * w, 1 - w * w)
    res = run_master(observer.load_scenario("grazing"), h=1e-2, t_end=60.0)
    assert res.status.ok
    exact = (delta + 2 * np.pi * np.arange(0, 20)) / w
    exact = exact[exact <= 60.0]
    ev = res.events
    assert set(ev["kind"]) == {"graze"}
    assert len(ev) == exact.size
    assert np.max(np.abs(ev["time"].to_numpy() - exact)) <= 1e-10
    assert np.all(ev["impulse"] == 0.0)
    assert np.all(res.intervals(0)[:, 0] == res.intervals(0)[:, 1])


def test_a_near_miss_is_no_graze_and_a_shallow_crossing_is_an_impact():
    res = run_master(observer.load_scenario("grazing", {"param.clearance": 1e-7}), h=0.05,
                     t_end=30.0)
    assert res.status.ok and res.events.empty
    res = run_master(observer.load_scenario("grazing", {"param.clearance": -1e-10}), h=0.05,
                     t_end=1.0)
    first = res.events.iloc[0]
    assert first["kind"] == "impact" and first["gamma_minus"] < 0.0
    assert first["gamma_plus"] == pytest.approx(-0.8 * first["gamma_minus"], rel=1e-12)


# -- simultaneous impacts -----------------------------------------------------------------------

@pytest.mark.parametrize("law", ["newton", "poisson"])
def test_flat_bar_hits_two_supports_at_once_and_comes_to_rest_on_both(law):
    """A bar (y, φ) dropped flat onto supports at x = ±b: both gaps close together, the
    multi-contact law gives γ⁺ = −eγ⁻ on both (G's row sums are equal), the bounces are
    the ball's (docs/theory/oracles.md §1 with h0 = d), then both contacts carry λ = m g/2 and φ ≡ 0."""
    m, b, H, d, e = 1.0, 0.1, 0.1, 0.05, 0.5
    J = m * (4 * b * b + H * H) / 12
    doc = {"scenario": {"name": "flat_bar"},
           "system": {"M": [[m, 0.0], [0.0, J]], "C": [[0.0, 0.0], [0.0, 0.0]],
                      "K": [[0.0, 0.0], [0.0, 0.0]], "W": [[1.0, 1.0], [-b, b]],
                      "forcing": {"constant": [-m * G0, 0.0]}, "gap": {"offset": [d, d]}},
           "impact": {"law": law, "restitution": e},
           "initial": {"q": [0.0, 0.0], "u": [0.0, 0.0]},
           "simulation": {"t_end": 1.2, "h": 1e-2}}
    res = run_master(Scenario.from_dict(doc))
    assert res.status.ok
    ev = res.events
    first = ev[ev["time"] == ev["time"].iloc[0]]
    assert sorted(first["contact"]) == [0, 1] and set(first["kind"]) == {"impact"}
    assert np.allclose(first["gamma_plus"], -e * first["gamma_minus"], rtol=1e-13)
    t1, v1 = np.sqrt(2 * d / G0), np.sqrt(2 * G0 * d)
    k = np.arange(1, 11)
    closed_form = t1 + (2 * v1 / G0) * e * (1 - e ** (k - 1)) / (1 - e)
    for j in (0, 1):
        assert np.max(np.abs(res.impact_times(j)[:10] - closed_form)) <= 1e-12
    (zeno,) = res.zeno
    assert zeno["contact"] == (0, 1)
    assert abs(zeno["t_inf"] - t1 * (1 + e) / (1 - e)) <= 1e-9
    rest = res.frame[res.frame["t"] > zeno["t_inf"] + 2e-2]
    assert np.allclose(rest[["P0", "P1"]], m * G0 / 2 * 1e-2, rtol=1e-12)
    # symmetry: φ stays zero up to round-off (the held flow's generator is exact only to
    # round-off, so u_φ drifts by ~1e-14 per second of contact)
    assert np.max(np.abs(res.frame[["q1", "u1"]].to_numpy())) <= 1e-13


@pytest.mark.parametrize("c", [100.0, 1e3])
def test_flat_bar_translated_reaches_its_closed_form_t_inf_within_1e9(c):
    """The flat bar of the test above with its coordinate translated by c (q₀ = −c, gap offset
    d + c): its two contacts' geometric run is cut where the impact times' location errors
    (the translated gaps' representation over the speed) would put the budget's worth of
    noise into the geometric tail (``_Run.noisy_tail``), and t∞ stays within 1e-9 of the
    closed form t₁(1 + e)/(1 − e). Cut by the hop size alone (as before), the run went on
    until the last ratio was noise: 7.5e-9 s off at c = 100, 1.4e-8 s at c = 1e3."""
    m, b, H, d, e = 1.0, 0.1, 0.1, 0.05, 0.5
    J = m * (4 * b * b + H * H) / 12
    doc = {"scenario": {"name": "flat_bar"},
           "system": {"M": [[m, 0.0], [0.0, J]], "C": [[0.0, 0.0], [0.0, 0.0]],
                      "K": [[0.0, 0.0], [0.0, 0.0]], "W": [[1.0, 1.0], [-b, b]],
                      "forcing": {"constant": [-m * G0, 0.0]}, "gap": {"offset": [d + c, d + c]}},
           "impact": {"law": "newton", "restitution": e},
           "initial": {"q": [-c, 0.0], "u": [0.0, 0.0]},
           "simulation": {"t_end": 1.2, "h": 1e-2}}
    res = run_master(Scenario.from_dict(doc))
    assert res.status.ok
    (zeno,) = res.zeno
    assert zeno["contact"] == (0, 1)
    t1 = np.sqrt(2 * d / G0)
    assert abs(zeno["t_inf"] - t1 * (1 + e) / (1 - e)) <= 1e-9


# -- double mass ----------------------------------------------------------------------------------

def test_double_mass_runs_twenty_seconds_with_liftoff_zeno_and_rest():
    sc = observer.load_scenario("double_mass")
    res = run_master(sc, h=0.05, t_end=20.0)
    assert res.status.ok
    frame, ev = res.frame, res.events
    assert not frame.isna().any().any()
    assert frame["g0"].min() >= -1e-14
    counts = ev["kind"].value_counts()
    assert counts["liftoff"] >= 15 and counts["accumulation"] >= 15
    # each landing ends in an accumulation and persistent contact, each contact phase in a lift-off
    kinds = ev[ev["kind"].isin(["stick", "liftoff"])]["kind"].tolist()
    assert all(a != b for a, b in zip(kinds, kinds[1:]))
    # the impacts obey the law: γ⁺ = −ε γ⁻ (one contact: Newton's value)
    imp = ev[ev["kind"] == "impact"]
    assert np.allclose(imp["gamma_plus"], -0.8 * imp["gamma_minus"], rtol=1e-12, atol=1e-15)
    # the sampled frame (block products of exp(Ah)) is the exact solution at the samples
    for k in (1, 57, 200, 399):
        x = res.state(frame["t"].iloc[k])
        assert np.max(np.abs(x - frame[["q0", "q1", "u0", "u1"]].iloc[k].to_numpy())) <= 1e-12
    # closed intervals are ordered and disjoint
    iv = res.intervals(0)
    assert np.all(iv[:, 1] >= iv[:, 0]) and np.all(iv[1:, 0] >= iv[:-1, 1])


def test_zeno_extrapolation_does_not_depend_on_where_the_impact_run_is_cut(monkeypatch):
    """double_mass's first landing: cutting the resolved impacts earlier (hops 1e4 round-offs
    of g) or later (1e2) changes the extrapolated t_∞ by less than 5e-9, while the tails
    themselves last 8.6e-5 s and 7.4e-6 s: a tail model that dropped or misjudged the tail
    would move t_∞ by about the tail's duration. What remains is round-off in the timing of
    the resolved sub-round-off hops: t_∞ drifts monotonically with the number of resolved
    impacts (measured, numpy 2.4.6 / scipy 1.17.1: cuts 1e5, 1e4, 1e3, 1e2, 1e1 give
    t_∞ = 2.904291771587, …1777, …2197, …3035, …4695; 1.26e-9 between 1e4 and 1e2)."""
    import observer.event.master as master
    sc = observer.load_scenario("double_mass")
    t_default = run_master(sc, h=0.05, t_end=3.0).zeno[0]["t_inf"]   # cut by noisy_tail
    t_inf = []
    for hop in (1e4, 1e2):       # the cut at ``hop`` round-offs 64·eps·Σ|r z| of the gap
        monkeypatch.setattr(master._Run, "hop_error", lambda run, fl, idx, z, hop=hop: hop * 64.0
                            * np.finfo(float).eps * (np.abs(fl.gap_rows[idx]) @ np.abs(z)))
        res = run_master(sc, h=0.05, t_end=3.0, zeno_time_rtol=np.inf)   # only the hop cut-off
        t_inf.append(res.zeno[0]["t_inf"])
        resolved = res.zeno[0]["impacts_resolved"]
        assert res.zeno[0]["tail_time"] < 1e-3
    assert resolved > 40
    assert abs(t_inf[0] - t_inf[1]) <= 5e-9 and abs(t_default - t_inf[1]) <= 5e-9


def test_event_cap_stops_with_a_clear_status():
    res = run_master(observer.load_scenario("bouncing_ball"), h=1e-2, max_events=10)
    assert str(res.status).startswith("stopped: event cap 10")
    # the output ends at the stop (the 11th impact), never with NaN rows
    t_stop = float(str(res.status).split("t = ")[1])
    t = res.frame["t"].to_numpy()
    assert not res.frame.isna().to_numpy().any()
    assert t[-1] < t_stop <= t[-1] + 1e-2 and res.frame.attrs["t_stop"] == t_stop


def test_safe_step_never_passes_the_first_zero_of_the_cubic_bound():
    """first_cubic_zero against dense sampling of the cubic, on random coefficients."""
    from observer.event.roots import first_cubic_zero
    rng = np.random.default_rng(11)
    for _ in range(300):
        d0 = abs(rng.normal()) * 10.0 ** rng.integers(-12, 1)
        d1, d2 = rng.normal(size=2) * 10.0 ** rng.integers(-3, 2, size=2)
        bound, width = abs(rng.normal()) * 10.0 ** rng.integers(-2, 3), 10.0 ** rng.uniform(-3, 0)
        s = first_cubic_zero(d0, d1, d2, bound, width)
        grid = np.linspace(0.0, width, 20001)
        L = d0 + d1 * grid + d2 * grid ** 2 / 2 - bound * grid ** 3 / 6
        below = np.flatnonzero(L <= 0.0)
        first = grid[below[0]] if below.size else width
        assert 0.0 <= s <= first + 1e-12 * width
        # and not needlessly short: the sampled zero is within one grid cell after s
        assert s >= first - width / 20000 * 1.0001 or s == width


def test_first_zero_is_the_earliest_of_many_functionals():
    """Random functionals of the impact oscillator's augmented state against dense sampling
    plus brentq: the returned zero is the earliest sign change of any of them (never a
    later one found first in row order, never a missed one)."""
    sc = observer.load_scenario("impact_oscillator")
    fl = Flow(sc.system)
    z0 = fl.z(0.0, np.array([-0.5, 0.3]))
    dt, horizon = 1e-3, 6.0
    step = fl.expm(dt)
    zs = [z0]
    for _ in range(int(horizon / dt)):
        z = step @ zs[-1]
        zs.append(z)
    zs = np.array(zs)
    ts = dt * np.arange(zs.shape[0])
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(40):
        rows = rng.normal(size=(3, fl.N))
        rows[:, -1] += rng.uniform(0.05, 1.0, size=3) - rows @ z0      # ψ_i(0) ∈ [0.05, 1]
        psi = zs @ rows.T
        firsts = [np.flatnonzero(psi[:, i] <= 0.0) for i in range(3)]
        firsts = [ts[f[0]] if f.size else np.inf for f in firsts]
        i_min = int(np.argmin(firsts))
        if not np.isfinite(firsts[i_min]):
            continue
        k = int(round(firsts[i_min] / dt))
        if min(abs(psi[k, i_min]), abs(psi[k - 1, i_min])) < 1e-6 or np.any(
                np.abs(psi[max(k - 2, 0):k + 2]) < 1e-6):
            continue                                              # ambiguous for the sampler
        exact = brentq(lambda t: rows[i_min] @ fl.expm(t) @ z0, ts[k - 1], ts[k], xtol=1e-15)
        zero, _, _ = first_zero(fl, rows, 0.0, z0, horizon)
        assert zero is not None and zero.index == i_min
        assert abs(zero.t - exact) <= 1e-9
        checked += 1
    assert checked >= 20


def test_first_zero_returns_the_earlier_zero_of_a_later_row():
    """Ball thrown up (q = 0.5t − g t²/2): ψ_0 = 0.01 − q crosses at 0.02733 before its
    minimum (a convex window), ψ_1 = u − u_B crosses earlier, at exactly 0.02."""
    fl = Flow(observer.load_scenario("bouncing_ball").system)
    z0 = fl.z(0.0, np.array([0.0, 0.5]))
    u_b = 0.5 - G0 * 0.02
    rows = np.array([[-1.0, 0.0, 0.01], [0.0, 1.0, -u_b]])
    zero, _, _ = first_zero(fl, rows, 0.0, z0, 1.0)
    assert zero.index == 1 and abs(zero.t - 0.02) <= 1e-15
    zero, _, _ = first_zero(fl, rows[:1], 0.0, z0, 1.0)
    assert abs(zero.t - (0.5 - np.sqrt(0.25 - 2 * G0 * 0.01)) / G0) <= 1e-15


def test_held_contacts_follow_a_moving_ground_with_the_force_of_newtons_law():
    """One rocking block on the harmonically moving ground, both corners held: g = γ = 0 stay
    zero, and λ equals W⁻¹(M u̇ − f + Kq + Cu) with u̇ = −W⁻ᵀν̈ (W square, exact kinematics)."""
    sc = observer.load_scenario("rocking_chain", {"param.N": 1})
    sysm = sc.system
    fl = flow_for(sysm, (0, 1))
    Wt_inv = np.linalg.inv(sysm.W.T)
    (omega,) = sysm.gap.omega                      # ν = ν_0 + a sin(Ωt): ν̈ = −Ω²(ν − ν_0)
    nu_ddot = lambda t: -omega ** 2 * (sysm.nu(t) - sysm.gap.constant)   # noqa: E731
    x0 = np.concatenate([-Wt_inv @ sysm.nu(0.0), -Wt_inv @ sysm.nu_dot(0.0)])
    for t in (0.3, 0.7, 1.9):
        x = fl.state(0.0, x0, t)
        q, u = x[:2], x[2:]
        assert np.max(np.abs(sysm.gaps(q, t))) <= 1e-13
        assert np.max(np.abs(sysm.contact_velocities(u, t))) <= 1e-12
        u_dot = -Wt_inv @ nu_ddot(t)
        lam = np.linalg.solve(sysm.W, sysm.M @ u_dot - sysm.f(t) + sysm.K @ q + sysm.C @ u)
        assert np.allclose(fl.forces(t, x), lam, rtol=1e-10, atol=1e-10)


def test_double_mass_lifts_off_when_the_contact_force_of_the_pinned_system_vanishes():
    """Independent oracle: with mass 1 pinned on the ground (q1 = −d0), mass 2 is a forced
    damped oscillator (solve_ivp, rtol 1e-12) and λ = m1 g + k1(q1 − q2) − c1 u2 (row 1 of
    M u̇ = f − Cu − Kq + Wλ); the first lift-off is λ's first zero."""
    from scipy.integrate import solve_ivp
    m1, m2, k1, k2, c1, c2, d0, F, Om = 1.0, 1.0, 100.0, 100.0, 1.0, 1.0, 0.25, 5.0, 6.0
    sc = observer.load_scenario("double_mass")
    q1 = -d0

    def rhs(t, y):
        q2, u2 = y
        return [u2, (-m2 * G0 + F * np.cos(Om * t) + k1 * q1 - (k1 + k2) * q2 - (c1 + c2) * u2) / m2]

    sol = solve_ivp(rhs, (0.0, 0.5), [sc.q0[1], 0.0], method="DOP853", rtol=1e-13, atol=1e-15,
                    dense_output=True)
    lam = lambda t: m1 * G0 + k1 * (q1 - sol.sol(t)[0]) - c1 * sol.sol(t)[1]   # noqa: E731
    assert lam(0.0) == pytest.approx(2.215, abs=1e-3)          # docs/theory/oracles.md §5 preload
    s = np.linspace(0.0, 0.5, 5001)
    k = np.flatnonzero(np.array([lam(t) for t in s]) <= 0.0)[0]
    t_liftoff = brentq(lam, s[k - 1], s[k], xtol=1e-14)
    res = run_master(sc, h=0.05, t_end=0.5)
    ev = res.events
    first = ev[ev["kind"] == "liftoff"]["time"].iloc[0]
    assert abs(first - t_liftoff) <= 1e-9
    assert res.intervals(0)[0, 0] == 0.0 and res.intervals(0)[0, 1] == first


def test_rocking_chain_impacts_satisfy_newtons_law_recomputed_from_the_events():
    """Ten rocking blocks (20 corner contacts, coupled Delassus matrix), Newton law: at every
    impact instant, 0 ≤ γ⁺ + eγ⁻ ⊥ Λ ≥ 0 recomputed from the recorded velocities and
    impulses, γ⁺ ≥ 0, and no gap is negative at any sample (no penetration)."""
    sc = observer.load_scenario("rocking_chain", {"param.law": "newton", "simulation.t_end": 0.3})
    res = run_master(sc, h=1e-2, max_events=2000)
    assert res.status.ok
    ev = res.events[res.events["kind"].isin(["impact", "graze"])]
    assert len(ev) >= 10
    e = 0.9
    scale = np.abs(ev["gamma_minus"]).max()
    for _, group in ev.groupby("time"):
        gm, gp, lam = (group[c].to_numpy() for c in ("gamma_minus", "gamma_plus", "impulse"))
        slack = gp + e * gm
        assert np.all(slack >= -1e-12 * scale) and np.all(lam >= 0.0)
        assert np.all(np.abs(slack * lam) <= 1e-12 * scale * max(lam.max(), 1e-300))
        assert np.all(gp >= -1e-12 * scale)
    gaps = res.frame.filter(regex=r"^g\d+$").to_numpy()
    assert gaps.min() >= -1e-12


@pytest.mark.parametrize("law", ["newton", "poisson"])
def test_velocity_tail_is_the_balls_closed_form_for_one_contact_and_none_for_several(law):
    """The tail model of one contact under constant acceleration (α₁ = 0) is docs/theory/oracles.md §1's
    geometric sum 2γ⁺/(α₀(1 − e)) (for one contact Poisson's law is Newton's); for a key of
    several contacts there is no such model (None), whatever the law."""
    from types import SimpleNamespace

    from observer.event.master import _Run
    from observer.impact import ImpactLaw
    e, v, g = 0.5, 0.8, G0
    run = SimpleNamespace(law=ImpactLaw.build(law, e, 2))
    tail = _Run.velocity_tail(run, (1,), np.array([v]), np.array([-g]), np.array([0.0]))
    assert tail == pytest.approx(2 * v / (g * (1 - e)), rel=1e-14)
    assert _Run.velocity_tail(run, (0, 1), np.array([v, v]), np.array([-g, -g]), np.zeros(2)) is None


def test_a_hop_under_zero_acceleration_has_no_tail():
    """A ball leaving its contact at γ⁺ = 0.8 with no force on it (g'' ≡ 0) never falls back:
    :meth:`_Run.hop_tail` adds no tail (0, the state after the hop the state itself), not the
    falling-back formula 2γ⁺/(|γ̇|(1 − e)), which has no meaning (and divides by zero) at
    γ̇ = 0."""
    from types import SimpleNamespace

    from observer.event.master import HOP_ORDER, _Run
    from observer.impact import ImpactLaw
    from observer.model import Harmonic
    sc = siconos_ball(1.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.5, 1.0)
    system = dataclasses.replace(sc.system, forcing=Harmonic.build("system.forcing", 3))
    held = flow_for(system, ())
    x = np.array([0.0, 0.0, 0.0, 0.8, 0.0, 0.0])
    z = held.z(0.0, x)
    Minv = np.linalg.inv(system.M)
    run = SimpleNamespace(law=ImpactLaw.build("newton", 0.5, 1), n=3, Minv=Minv, system=system,
                          delassus=lambda idx: system.W[:, idx].T @ Minv @ system.W[:, idx])
    assert HOP_ORDER >= 2 and (held.velocity_rows[0] @ held.A) @ z == 0.0     # g''(0) = 0
    assert _Run.hop_tail(run, 0, 0.0, z, held, guess=1.0) == 0.0
    c, t, t_end, x_end = run.hop_end
    assert (c, t, t_end) == (0, 0.0, 0.0) and np.array_equal(x_end, x)
