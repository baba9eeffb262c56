"""Issue 19: the exact integrator in ordinary coordinates — the four failure classes, as named
tests against closed forms and an independent 50-digit reference (mpmath).

1. contacts at the coordinate origin (gap offset ν = 0);
2. t_end a few ulp past a search-window boundary, t_end = t∞ + 1, t_end = 1e-300;
3. the Zeno limit t∞ for gap offsets up to 100;
4. a shallow crossing (2.7e-8 deep at 3e-4 m/s) on an orbit centred at 1000.
"""

from __future__ import annotations

import re

import mpmath as mp
import numpy as np
import pytest
from hypothesis import Phase, given, settings
from hypothesis import strategies as st

import observer
from observer.event.flow import Flow
from observer.event.roots import WINDOW, FunctionalSet, minimum_enclosure
from observer.event.master import run_master
from observer.model import Harmonic, LinearSystem
from observer.scenario import Scenario

G0 = 9.81
mp.mp.dps = 50


def scenario(M, K, W, f, nu, q0, u0, e, t_end, h=1e-2) -> Scenario:
    n = len(M)
    doc = {"scenario": {"name": "issue19"},
           "system": {"M": M, "C": np.zeros((n, n)).tolist(), "K": K, "W": W,
                      "forcing": {"constant": f}, "gap": {"offset": nu}},
           "impact": {"law": "newton", "restitution": e},
           "initial": {"q": q0, "u": u0},
           "simulation": {"t_end": t_end, "h": h}}
    return Scenario.from_dict(doc)


def ball(height: float, nu: float = 0.0, e: float = 0.5, t_end: float = 1.0, h: float = 1e-2):
    """A ball (W = 1) at gap ``height`` over a ground at offset ν: q0 = height − ν."""
    return scenario([[1.0]], [[0.0]], [[1.0]], [-G0], [nu], [height - nu], [0.0], e, t_end, h)


def no_nan(res) -> bool:
    return not res.frame.drop(columns=[c for c in res.frame if c.startswith("active")]).isna().to_numpy().any()


def ball_impacts(height, e, count):
    """Impact times and speeds of a ball dropped from ``height`` (50 digits)."""
    g = mp.mpf(G0)
    v = mp.sqrt(2 * g * mp.mpf(height))
    t = mp.sqrt(2 * mp.mpf(height) / g)
    out = []
    for _ in range(count):
        out.append((t, v))
        v = mp.mpf(e) * v
        t = t + 2 * v / g
    return out


def ball_t_inf(height, e):
    g = mp.mpf(G0)
    v1 = mp.sqrt(2 * g * mp.mpf(height))
    return mp.sqrt(2 * mp.mpf(height) / g) + 2 * v1 * mp.mpf(e) / (g * (1 - mp.mpf(e)))


# -- class 1: contacts at ν = 0 -----------------------------------------------------------------

def test_two_contacts_at_nu_zero_with_impacts_1e8_apart_both_bounce():
    """Two independent balls on grounds at ν = 0, the second's impact 1e-8 s after the first:
    each bounces at its own closed-form times with γ⁺ = −eγ⁻; no graze, no stop, no NaN."""
    e = 0.5
    t1 = mp.sqrt(2 / mp.mpf(G0))
    h2 = float(mp.mpf(G0) * (t1 + mp.mpf("1e-8")) ** 2 / 2)
    sc = scenario([[1.0, 0.0], [0.0, 1.0]], [[0.0, 0.0], [0.0, 0.0]], [[1.0, 0.0], [0.0, 1.0]],
                  [-G0, -G0], [0.0, 0.0], [1.0, h2], [0.0, 0.0], e, 1.2)
    res = run_master(sc)
    assert res.status.ok and no_nan(res)
    ev = res.events
    assert set(ev["kind"]) == {"impact"}
    for j, height in ((0, 1.0), (1, h2)):
        mine = ev[ev["contact"] == j]
        exact = ball_impacts(height, e, len(mine))
        assert len(mine) == 3
        for (_, row), (t, v) in zip(mine.iterrows(), exact):
            assert abs(row["time"] - float(t)) <= 1e-12
            assert abs(row["gamma_minus"] + float(v)) <= 1e-11
            assert row["gamma_plus"] == pytest.approx(-e * row["gamma_minus"], rel=1e-12)
    first = ev.groupby("contact")["time"].min()
    assert 0.9e-8 <= first[1] - first[0] <= 1.1e-8


def test_a_flat_body_at_nu_zero_lands_on_both_corners_at_once():
    """A bar (y, φ) with corners y ∓ Lφ, dropped flat onto grounds at ν = 0: both corners
    impact at the ball's closed-form times with the same γ⁺ = −eγ⁻; φ stays 0."""
    e, L = 0.5, 0.5
    sc = scenario([[1.0, 0.0], [0.0, 0.1]], [[0.0, 0.0], [0.0, 0.0]], [[1.0, 1.0], [-L, L]],
                  [-G0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 0.0], e, 1.2)
    res = run_master(sc)
    assert res.status.ok and no_nan(res)
    ev = res.events
    assert set(ev["kind"]) == {"impact"}
    exact = ball_impacts(1.0, e, 3)
    for j in (0, 1):
        mine = ev[ev["contact"] == j]
        assert len(mine) == 3
        assert np.max(np.abs(mine["time"].to_numpy() - [float(t) for t, _ in exact])) <= 1e-12
        assert np.max(np.abs(mine["gamma_plus"].to_numpy() - [e * float(v) for _, v in exact])) <= 1e-11
    assert np.max(np.abs(res.frame["q1"])) <= 1e-14


def test_the_impact_oscillator_at_the_wall_x0_lifts_off_when_its_contact_force_vanishes():
    """The built-in impact_oscillator (wall at x = 0, ν = 0) with e = 0.5, ω = 0.3: the impacts
    accumulate, the mass sticks to the wall with λ = cos ωt (ẍ = −x + cos ωt − λ at x = 0)
    and lifts off when λ crosses zero, at t = π/(2ω) (50 digits), to 1e-12."""
    sc = observer.load_scenario("impact_oscillator", {"impact.restitution": 0.5,
                                                      "system.forcing.omega": 0.3,
                                                      "simulation.t_end": 6.0})
    res = run_master(sc)
    assert res.status.ok and no_nan(res)
    ev = res.events
    lift = ev[ev["kind"] == "liftoff"]
    stick = ev[ev["kind"] == "stick"]
    assert len(lift) == 1 and len(stick) == 1
    assert stick["time"].iloc[0] < lift["time"].iloc[0]
    assert abs(lift["time"].iloc[0] - float(mp.pi / (2 * mp.mpf("0.3")))) <= 1e-12
    # the same physics with the wall moved to 0.3 runs too (the offset is no special case)
    moved = observer.load_scenario("impact_oscillator", {"impact.restitution": 0.5,
                                                         "system.forcing.omega": 0.3,
                                                         "system.gap.offset": [0.3],
                                                         "initial.q": [-0.2],
                                                         "simulation.t_end": 6.0})
    assert run_master(moved).status.ok


def test_two_dof_singular_stiffness_at_nu_zero_first_impact_against_mpmath():
    """Two unit masses joined by a unit spring (K singular), falling; contact on mass 0 at
    ν = 0: q0(t) = 1.25 − g t²/2 − 0.25 cos(√2 t) until the first impact (mpmath root)."""
    e = 0.5
    sc = scenario([[1.0, 0.0], [0.0, 1.0]], [[1.0, -1.0], [-1.0, 1.0]], [[1.0], [0.0]],
                  [-G0, -G0], [0.0], [1.0, 1.5], [0.0, 0.0], e, 3.0)
    res = run_master(sc)
    assert res.status.ok and no_nan(res)
    q = lambda t: mp.mpf("1.25") - mp.mpf(G0) * t ** 2 / 2 - mp.cos(mp.sqrt(2) * t) / 4  # noqa: E731
    t1 = mp.findroot(q, mp.mpf("0.45"))
    v1 = -mp.diff(q, t1)
    first = res.events.iloc[0]
    assert first["kind"] == "impact" and abs(first["time"] - float(t1)) <= 1e-12
    assert abs(-first["gamma_minus"] - float(v1)) <= 1e-11
    assert len(res.events) >= 5


# -- class 2: ends of runs and of windows --------------------------------------------------------

def window_of(sc) -> float:
    from observer.event.roots import WINDOW
    return WINDOW / Flow(sc.system).norm_bound


@pytest.mark.parametrize("ulps", [-3, -1, 0, 1, 2, 5])
@pytest.mark.parametrize("where", ["one", "window", "two_windows"])
def test_free_flight_has_no_event_for_t_end_ulps_from_a_boundary(where, ulps):
    """A ball 10 m up flies freely for 1.4 s: for t_end a few ulp from 1.0 or from the first
    (second) search-window boundary, no event, status ok, no NaN, and the last row is the
    parabola (closed form)."""
    base = ball(10.0, t_end=1.0, h=0.25)
    t_b = {"one": 1.0, "window": window_of(base), "two_windows": 2.0 * window_of(base)}[where]
    t_end = t_b
    for _ in range(abs(ulps)):
        t_end = np.nextafter(t_end, np.inf if ulps > 0 else -np.inf)
    res = run_master(base, t_end=t_end)
    assert res.status.ok and res.events.empty and no_nan(res)
    t = res.frame["t"].to_numpy()
    assert np.allclose(res.frame["q0"], 10.0 - G0 * t ** 2 / 2, rtol=0, atol=1e-13)


def test_t_end_1e300_is_one_row_in_free_flight():
    res = run_master(ball(10.0), t_end=1e-300)
    assert res.status.ok and res.events.empty and no_nan(res)
    assert res.frame["q0"].iloc[-1] == 10.0


@pytest.mark.parametrize("offset", [1.0, 0.25])
def test_a_ball_at_rest_after_zeno_has_no_false_liftoff_at_t_end(offset):
    """t_end = t∞ + offset: the ball lands (accumulation) and rests; no lift-off, no stop."""
    e = 0.5
    t_inf = float(ball_t_inf(1.0, e))
    res = run_master(ball(1.0, e=e, t_end=t_inf + offset))
    assert res.status.ok and no_nan(res)
    kinds = res.events["kind"].tolist()
    assert "liftoff" not in kinds and kinds[-2:] == ["accumulation", "stick"]
    assert abs(res.frame["q0"].iloc[-1]) <= 1e-15 and abs(res.frame["u0"].iloc[-1]) <= 1e-15


@pytest.mark.parametrize("ulps", [-2, 0, 2])
def test_t_end_at_ulps_from_an_impact_time_adds_no_event(ulps):
    """t_end a few ulp around the second impact: the events are a prefix of the long run's."""
    full = run_master(ball(1.0, t_end=1.2))
    t2 = full.events["time"].iloc[1]
    t_end = t2
    for _ in range(abs(ulps)):
        t_end = np.nextafter(t_end, np.inf if ulps > 0 else -np.inf)
    res = run_master(ball(1.0, t_end=1.2), t_end=t_end)
    assert res.status.ok and no_nan(res)
    k = len(res.events)
    assert k in (1, 2)
    assert np.array_equal(res.events["kind"].to_numpy(), full.events["kind"].to_numpy()[:k])
    assert np.max(np.abs(res.events["time"].to_numpy() - full.events["time"].to_numpy()[:k])) <= 1e-15


# -- class 3: the Zeno limit -------------------------------------------------------------------

@pytest.mark.parametrize("nu", [0.0, 1.0, 100.0, -100.0])
def test_zeno_limit_to_1e9_for_any_gap_offset(nu):
    """Ball dropped from gap 1 m over a ground at offset ν: t∞ (50-digit closed form,
    docs/theory/oracles.md §1) to 1e-9 whatever ν is."""
    e = 0.5
    res = run_master(ball(1.0, nu=nu, e=e, t_end=2.0))
    assert res.status.ok and len(res.zeno) == 1
    assert abs(res.zeno[0]["t_inf"] - float(ball_t_inf(1.0, e))) <= 1e-9


# -- class 4: shallow crossings --------------------------------------------------------------------

def centred_orbit(centre: float, depth: float, e: float = 0.8) -> Scenario:
    """ẍ = −(x − centre) from x = centre − A at rest (A = 5/3), a wall at centre + A − depth:
    the orbit crosses the wall ``depth`` deep at speed √(A² − (A − depth)²) = 3e-4 m/s."""
    A = 0.09e-6 / (2 * 2.7e-8)
    return scenario([[1.0]], [[1.0]], [[-1.0]], [centre], [centre + A - depth], [centre - A],
                    [0.0], e, 7.0, h=0.05)


@pytest.mark.parametrize("centre", [0.0, 1000.0])
def test_a_crossing_27nm_deep_at_3e4_gets_its_impulse_wherever_the_orbit_is(centre):
    A = mp.mpf("0.09e-6") / (2 * mp.mpf("2.7e-8"))
    depth = mp.mpf("2.7e-8")
    v = mp.sqrt(A ** 2 - (A - depth) ** 2)          # speed at the wall (energy)
    t_hit = mp.pi - mp.acos((A - depth) / A)         # x − centre = −A cos t = A − depth
    res = run_master(centred_orbit(centre, 2.7e-8))
    ev = res.events
    assert res.status.ok and len(ev) >= 1
    first = ev.iloc[0]
    assert first["kind"] == "impact"
    # the gap near x = 1000 is known to δg ≈ 16 eps·(|x| + |ν|): the crossing time to δg/v,
    # the crossing speed to |ẍ|δg/v (|ẍ| = A): representation, not the integrator
    dg = 16 * np.finfo(float).eps * (1.0 + 2.0 * centre)
    assert abs(first["gamma_minus"] + float(v)) <= 1e-12 + float(A) * dg / float(v)
    assert first["gamma_plus"] == pytest.approx(-0.8 * first["gamma_minus"], rel=1e-9)
    assert abs(first["time"] - float(t_hit)) <= 1e-12 + dg / float(v)
    assert abs(first["impulse"] - 1.8 * float(v)) <= 1e-12 + 1.8 * float(A) * dg / float(v)


@pytest.mark.parametrize("centre", [0.0, 1000.0])
def test_a_near_miss_27nm_below_the_wall_is_no_event(centre):
    """The same orbit with the wall 2.7e-8 above its top: no contact at all."""
    res = run_master(centred_orbit(centre, -2.7e-8))
    assert res.status.ok and res.events.empty


def test_a_graze_row_states_its_depth_within_the_touch_band():
    """The grazing scenario (clearance 0): every row is a graze whose depth is within its
    stated band, and the band is far below the 2.7e-8 crossing above."""
    res = run_master(observer.load_scenario("grazing"), h=1e-2, t_end=20.0)
    ev = res.events
    assert len(ev) >= 2 and set(ev["kind"]) == {"graze"}
    band = ev["note"].str.extract(r"±([0-9.e+-]+)")[0].astype(float)
    assert np.all(np.abs(ev["depth"]) <= band) and np.all(band < 1e-10)


# -- the guaranteed crossing depth δ* (README: band + the certified enclosure's width) ------------

EPS = np.finfo(float).eps


def data_resolution(centre: float, A: float) -> float:
    """What the data decide about the gap g = ν − x at the orbit's top, independently of the
    engine: x and ν ≈ centre + A are floats known to their own representation, so g to
    ``u·(|x| + |ν|)`` (part (c) of the touch band, :func:`observer.event.roots.graze_band`)."""
    return EPS / 2 * 2 * abs(centre + A)


def stated_band(centre: float) -> tuple[float, float]:
    """``(δ, δ*)``: the touch band and the guaranteed crossing depth a graze row states for the
    orbit with the wall at its top (depth 0): its evaluation error, the run's carried error
    and the data's resolution (issue 34: no longer 1000·64·eps over the motion's time scale)."""
    row = run_master(centred_orbit(centre, 0.0)).events.iloc[0]
    assert row["kind"] == "graze"
    band = float(re.search(r"±([0-9.e+-]+);", row["note"]).group(1))
    star = float(re.search(r"guaranteed crossing depth ([0-9.e+-]+)", row["note"]).group(1))
    return band, star


@pytest.mark.parametrize("centre", [0.0, 1000.0])
@pytest.mark.parametrize("factor", [1.5, 1.05, 0.5, -0.5, -1.5])
def test_crossings_near_the_guaranteed_depth_are_impacts_grazes_or_nothing(centre, factor):
    """The orbit x = centre − A cos t against a wall ``factor·δ*`` below its top (δ* the stated
    guaranteed crossing depth, :func:`stated_band`, which holds the data's own resolution,
    :func:`data_resolution`): deeper than δ* (1.5, 1.05) an impact at the 50-digit crossing
    time and speed (computed from the float inputs), within ±δ/2 a graze row whose depth is
    the true minimum ν − x_max, clearance beyond δ* no event."""
    A = 0.09e-6 / (2 * 2.7e-8)
    band, star = stated_band(centre)
    assert data_resolution(centre, A) <= band <= star < 1e-3 * 2.7e-8   # far below class 4's
    offset = factor * (star if abs(factor) > 1.0 else band)
    sc = centred_orbit(centre, offset)
    c, x0, wall = (mp.mpf(float(v)) for v in (sc.system.forcing.constant[0], sc.q0[0],
                                               sc.system.gap.constant[0]))
    amp = c - x0                                       # x = c − amp·cos t (exact from the floats)
    depth = c + amp - wall                             # true penetration at the top (t = π)
    res = run_master(sc)
    ev = res.events
    assert res.status.ok and no_nan(res)
    dg = 16 * EPS * 2 * abs(centre + A)                # the gap's representation error
    if factor > 1.0:
        assert float(depth) > star                     # the case: beyond δ* from the float inputs
        t_hit = mp.pi - mp.acos((amp - depth) / amp)
        v = amp * mp.sin(t_hit)
        first = ev.iloc[0]
        assert first["kind"] == "impact"
        assert abs(first["time"] - float(t_hit)) <= 4 * dg / float(v) + 1e-12
        assert abs(-first["gamma_minus"] - float(v)) <= 4 * float(amp) * dg / float(v) + 1e-15
    elif factor > -1.0:
        assert abs(float(depth)) <= band               # the case: inside the band
        assert len(ev) >= 1 and ev["kind"].iloc[0] == "graze" and ev["impulse"].iloc[0] == 0.0
        assert abs(ev["time"].iloc[0] - float(mp.pi)) <= 1e-6
        assert abs(ev["depth"].iloc[0] - float(-depth)) <= 4 * dg + 1e-15
        assert "guaranteed crossing depth" in ev["note"].iloc[0]
    else:
        assert float(depth) < -star
        assert ev.empty


def oscillator_x(k: float, c: float, F0: float, a: float, w: float, x0: float, u0: float):
    """50-digit closed form ``(x(t), ẋ(t))`` of ẍ + cẋ + kx = F0 + a cos ωt, x(0) = x0,
    ẋ(0) = u0 (analytic derivatives: no numerical differentiation)."""
    k, c, F0, a, w = (mp.mpf(v) for v in (k, c, F0, a, w))
    H = a / (k - w * w + 1j * c * w)                   # particular: Re(H e^{iωt})
    p2 = F0 / 2 if k == 0 and c == 0 else 0            # particular of F0: F0/k, F0 t/c, F0 t²/2
    p1 = F0 / c if k == 0 and c > 0 else 0
    p0 = F0 / k if k > 0 else 0
    xp = lambda t: p0 + p1 * t + p2 * t * t + mp.re(H * mp.expj(w * t))  # noqa: E731
    vp = lambda t: p1 + 2 * p2 * t + mp.re(1j * w * H * mp.expj(w * t))  # noqa: E731
    r0, r1 = mp.mpf(x0) - xp(0), mp.mpf(u0) - vp(0)
    if k == 0 and c == 0:
        return lambda t: (xp(t) + r0 + r1 * t, vp(t) + r1)
    disc = mp.sqrt(mp.mpc(c * c - 4 * k))
    l1, l2 = (-c + disc) / 2, (-c - disc) / 2
    C2 = (r1 - l1 * r0) / (l2 - l1)
    C1 = r0 - C2
    return lambda t: (xp(t) + mp.re(C1 * mp.exp(l1 * t) + C2 * mp.exp(l2 * t)),
                      vp(t) + mp.re(C1 * l1 * mp.exp(l1 * t) + C2 * l2 * mp.exp(l2 * t)))


@settings(max_examples=200, deadline=None, derandomize=True, database=None,
          phases=[Phase.explicit, Phase.reuse, Phase.generate])
@given(k=st.one_of(st.just(0.0), st.floats(0.1, 50.0)), c=st.one_of(st.just(0.0), st.floats(0.01, 2.0)),
       F0=st.floats(-20.0, 20.0), a=st.floats(0.0, 5.0), w=st.floats(0.3, 8.0),
       x0=st.floats(-2.0, 2.0), u0=st.floats(-3.0, 3.0), nu=st.sampled_from([0.0, 0.7, -100.0, 1e3]),
       sign=st.sampled_from([1.0, -1.0]), frac=st.floats(0.0, 1.0))
def test_the_certified_enclosure_of_a_gap_and_its_rate_holds_the_50_digit_value(
        k, c, F0, a, w, x0, u0, nu, sign, frac):
    """FunctionalSet.enclose (the Taylor model with certified remainder behind δ*) against the
    closed form: for g = ±x + ν on a random forced oscillator (K, C possibly 0) and any
    offset s in the window, ``lo ≤ g^{(j)}(s) ≤ hi`` (j = 0, 1), the width within 1e-13 of the
    terms' size."""
    if abs(k - w * w) < 0.05 or abs(c * c - 4 * k) < 1e-3:
        return                                          # resonance, critical damping: no closed form here
    forcing = Harmonic.build("f", 1, constant=F0, terms=[{"amplitude": a, "omega": w}])
    system = LinearSystem([[1.0]], [[c]], [[k]], [[sign]], forcing,
                          Harmonic.build("nu", 1, constant=nu, kind="sin"))
    fl = Flow(system)
    fs = FunctionalSet(fl, fl.gap_rows)
    z = fl.z(0.0, np.array([x0, u0]))
    s = frac * WINDOW / fl.norm_bound
    x = oscillator_x(k, c, F0, a, w, x0, u0)
    size = abs(nu) + abs(x0) + abs(u0) + abs(F0) + a + 1.0
    for j in (0, 1):
        exact = sign * x(mp.mpf(s))[j] + (nu if j == 0 else 0)
        lo, hi = fs.enclose(0, j, z, s)
        ref = 1e-40 * size * (1 + fl.norm_bound) ** j     # the 50-digit reference's own error
        assert lo - ref <= exact <= hi + ref and hi - lo <= 1e-13 * size * (1 + fl.norm_bound) ** j



@pytest.mark.parametrize("alpha", [1.0, 1e3, 1e-3])
@pytest.mark.parametrize("nu", [0.0, 100.0])
def test_initial_contact_is_a_property_of_the_motion_not_of_units_or_origin(alpha, nu):
    """A ball at rest 1e-10 m above the ground is open at t0 in metres, millimetres and
    kilometres, with the ground at ν = 0 or 100 (the old rule, 1e-9·max(1, |q| + |ν|), closed
    it in metres and opened it in millimetres): it first lands at √(2δ/g) (50 digits, to the
    gap's representation error over the speed); the same ball on the ground (gap 0) sticks
    at t0 whatever the units."""
    def drop(gap):
        return scenario([[1.0]], [[0.0]], [[1.0]], [-G0 * alpha], [nu * alpha],
                        [(gap - nu) * alpha], [0.0], 0.5, 0.01, h=1e-3)
    res = run_master(drop(1e-10))
    first = res.events.iloc[0]
    t1 = mp.sqrt(2 * mp.mpf(1e-10) / G0)
    dg = 4 * EPS * (1e-10 + 2 * nu)                   # the gap's representation error (metres)
    assert res.status.ok and first["kind"] == "impact"
    assert abs(first["time"] - float(t1)) <= dg / float(G0 * t1) + 1e-15
    rest = run_master(drop(0.0))
    assert rest.status.ok and rest.events["kind"].tolist() == ["stick"]
    assert rest.events["time"].iloc[0] == 0.0 and abs(rest.frame["u0"]).max() == 0.0


# -- the certified norms behind δ* are proved bounds (no relative margin) ----------------------

def _mp_spectral_norm(A, s):
    """‖T⁻¹AT‖₂ to 50 digits (mpmath SVD of the exact balanced matrix)."""
    with mp.workdps(50):
        N = A.shape[0]
        B = mp.matrix([[mp.mpf(A[i, j]) * mp.mpf(s[j]) / mp.mpf(s[i]) for j in range(N)]
                       for i in range(N)])
        return max(mp.svd_r(B, compute_uv=False))


@pytest.mark.parametrize("seed", range(6))
def test_the_certified_spectral_norm_is_a_tight_upper_bound_of_the_50_digit_norm(seed):
    """Flow.certified_norm (Gershgorin on V⁻¹BᵀBV in ball arithmetic) ≥ the 50-digit ‖T⁻¹AT‖₂
    and within 1e-13 of it, for random generators spanning 6 decades, a matrix with a
    repeated singular value (two equal rotations) and a built-in scenario."""
    from observer.event.flow import spectral_norm_upper
    rng = np.random.default_rng(seed)
    if seed == 0:
        A = np.kron(np.eye(2), np.array([[0.0, 3.0], [-3.0, 0.0]]))
        s = np.ones(4)
    elif seed == 1:
        fl = Flow(observer.load_scenario("double_mass").system)
        A, s = fl.A, fl.scale
    else:
        N = int(rng.integers(3, 9))
        A = rng.normal(size=(N, N)) * 10.0 ** rng.integers(-3, 4, size=(N, N))
        s = 2.0 ** rng.integers(-5, 6, size=N)
    exact = _mp_spectral_norm(A, s)
    bound = spectral_norm_upper(A, s)
    assert exact <= bound <= exact * (1 + 1e-13)


def test_the_vector_norm_and_exponential_bounds_are_upper_bounds_at_50_digits():
    """norm_upper ≥ ‖v‖₂ (50 digits) within 1e-15 relative, including entries near overflow
    and underflow; exp_upper ≥ eˣ within 1e-15."""
    from observer.event.flow import exp_upper, norm_upper
    rng = np.random.default_rng(7)
    for scale in (1.0, 1e300, 1e-300, 1e-160):
        for _ in range(50):
            v = rng.normal(size=int(rng.integers(1, 30))) * scale
            with mp.workdps(50):
                exact = mp.sqrt(mp.fsum(mp.mpf(x) ** 2 for x in v))
            b = norm_upper(v)
            assert exact <= b <= exact * (1 + 1e-14) + 1e-320
    for x in np.linspace(0.0, 0.6, 61):
        with mp.workdps(50):
            ex = mp.exp(mp.mpf(x))
        assert ex <= exp_upper(x) <= ex * (1 + 1e-15)


def _enclosure_failures(order, monkeypatch):
    """Number of (state, offset, j) where a Taylor model of degree ``order − 1`` fails to
    hold the 50-digit value of g^{(j)} for the forced oscillator x'' + 0.3x' + 4x = 2 cos 1.3t
    (so that the Lagrange remainder, not round-off, dominates the enclosure's width)."""
    from observer.event import roots
    monkeypatch.setattr(roots, "TAYLOR_ORDER", order)
    k, c, F0, a, w = 4.0, 0.3, 0.0, 2.0, 1.3
    forcing = Harmonic.build("f", 1, constant=F0, terms=[{"amplitude": a, "omega": w}])
    system = LinearSystem([[1.0]], [[c]], [[k]], [[1.0]], forcing,
                          Harmonic.build("nu", 1, constant=0.5, kind="sin"))
    fl = Flow(system)
    fs = FunctionalSet(fl, fl.gap_rows)
    fails = 0
    for phase in np.linspace(0.0, 2 * np.pi, 12, endpoint=False):
        x0, u0 = np.cos(phase), 2.0 * np.sin(phase)
        x = oscillator_x(k, c, F0, a, w, x0, u0)
        z = fl.z(0.0, np.array([x0, u0]))
        for frac in (0.25, 0.5, 0.75, 1.0):
            s = frac * WINDOW / fl.norm_bound
            for j in (0, 1):
                exact = x(mp.mpf(s))[j] + (0.5 if j == 0 else 0)
                lo, hi = fs.enclose(0, j, z, s)
                fails += not (lo <= exact <= hi)
    return fails


@pytest.mark.parametrize("order", [3, 5, 16])
def test_a_low_order_taylor_model_is_held_by_its_certified_remainder(order, monkeypatch):
    """With degree 2, 4 or 15 the enclosure holds the 50-digit value at every state and offset
    (the remainder bound is what holds it at low degree) ..."""
    assert _enclosure_failures(order, monkeypatch) == 0


@pytest.mark.parametrize("bad", ["no remainder", "norms 4x too small"])
def test_the_enclosure_check_fails_a_bound_without_its_remainder_or_with_small_norms(bad, monkeypatch):
    """... and the same check fails a known-bad bound: the remainder dropped (growth 0) or the
    norms of ``r A^K T`` and ``T⁻¹z`` taken 4 times too small."""
    from observer.event import roots
    if bad == "no remainder":
        monkeypatch.setattr(roots, "exp_upper", lambda x: 0.0)
    else:
        real = roots.norm_upper
        monkeypatch.setattr(roots, "norm_upper", lambda v: 0.25 * real(v))
    assert _enclosure_failures(3, monkeypatch) > 0


# -- the Zeno cut-offs depend on the time origin only through ulp(t) -------------------------------

def _zeno_cuts(origins, nu=0.0):
    """(impacts resolved, tail time, t∞ − T) of the ball dropped from 1 m (e = 0.5) at t0 = T."""
    out = []
    for T in origins:
        z = run_master(ball(1.0, nu=nu, e=0.5, t_end=2.0), t0=T, t_end=T + 2.0).zeno[0]
        out.append((z["impacts_resolved"], z["tail_time"], z["t_inf"] - T))
    return out


def test_zeno_cut_is_the_same_for_time_origins_in_one_binade_of_ulp_t():
    """The Zeno cut-offs depend on the run's elapsed time and on the gap's certified error, not
    on the time origin: time origins 1100, 1500 and 2000 (t in [1024, 2048)) resolve the same
    impacts and give the same tail and t∞ − T bit for bit; origins 0 and 1e5 + 100 resolve the
    same number of impacts too (the time resolution, two ulp of t, enters the noise of an
    impact's location but is far below the noise budget there), and t∞ − T stays within 1e-9
    of the 50-digit closed form. (The old interval cut-off, 2^16 ulp(max(|t|, τ)), cut the
    run at 1e5 + 100 earlier than at 0: this check fails it.)"""
    same = _zeno_cuts([1100.0, 1500.0, 2000.0])
    assert same[0] == same[1] == same[2]
    exact = float(ball_t_inf(1.0, 0.5))
    others = _zeno_cuts([0.0, 1e5 + 100.0])
    assert {cut[0] for cut in same + others} == {same[0][0]}
    for _, _, t_inf in same + others:
        assert abs(t_inf - exact) <= 1e-9


def test_zeno_run_at_a_time_origin_of_1e7_is_cut_while_its_times_are_resolved():
    """At t0 = 1e7 the impact times are resolved only to ulp(1e7) ≈ 1.9e-9 s: the noise of an
    impact's location includes the time resolution (``_Run.noisy_tail``), so the run is
    extrapolated while its intervals still shrink geometrically, and t∞ − T is within
    4 ulp(1e7) of the 50-digit closed form. (Without that term the hops fell below the time
    resolution, the intervals were no longer geometric, and the run stopped at the event cap.)"""
    T = 1e7
    res = run_master(ball(1.0, e=0.5, t_end=2.0), t0=T, t_end=T + 2.0)
    assert res.status.ok
    (z,) = res.zeno
    assert abs(z["t_inf"] - T - float(ball_t_inf(1.0, 0.5))) <= 4 * np.spacing(T)


def test_zeno_cut_check_fails_a_cut_off_proportional_to_t(monkeypatch):
    """... and the same check fails a noise budget proportional to the absolute time |t|
    instead of the elapsed time (continuous in t, so a shift of the time origin within a
    binade moves the cut; scaled by 1e-3 to the elapsed budget's size at t ≈ 1e3; the ball
    with ν = 100, whose gap's representation makes the noise budget the cut-off that decides)."""
    import observer.event.master as master
    monkeypatch.setattr(master, "zeno_time_budget", lambda t, t0, rtol: rtol * abs(t) * 1e-3)
    same = _zeno_cuts([1100.0, 1500.0, 2000.0], nu=100.0)
    assert not same[0] == same[1] == same[2]


def _ball_cuts(nu: float, rtols) -> list[tuple[int, float, float]]:
    """(impacts resolved, |t∞ − closed form|, t∞) of the ball dropped from 1 m (e = 0.5) on a
    ground at ν, for each ``zeno_time_rtol``; t∞ = t₁ + 2v₁e/(g(1 − e)) in 50 digits."""
    exact = ball_t_inf(1.0, 0.5)
    out = []
    for rtol in rtols:
        res = run_master(ball(1.0, nu=nu, e=0.5, t_end=2.0), zeno_time_rtol=rtol)
        assert res.status.ok
        (z,) = res.zeno
        out.append((z["impacts_resolved"], abs(float(mp.mpf(z["t_inf"]) - exact)), z["t_inf"]))
    return out


@pytest.mark.parametrize("nu", [100.0, 1e3])
def test_a_tighter_zeno_time_rtol_cuts_earlier_and_gives_a_t_inf_as_accurate(nu):
    """``zeno_time_rtol`` is the stated accuracy of t∞ relative to the elapsed time: on the
    ball over a ground at ν = 100 and 1e3 (the gap's representation, ~eps·ν, makes this the
    cut-off that decides), each tighter value (2^-26, 2^-30, 2^-34) resolves fewer impacts
    (the comparison is the decision: a cut never comes later) and gives a t∞ no farther from
    the closed form, and t∞ is within ``zeno_time_rtol·(t∞ − t0)`` of it (at e = 0.5 the
    impacts resolved before the cut add no more than the cut's own error)."""
    rtols = [2.0 ** -26, 2.0 ** -30, 2.0 ** -34]
    cuts = _ball_cuts(nu, rtols)
    impacts, errors = [c[0] for c in cuts], [c[1] for c in cuts]
    assert impacts[0] > impacts[1] > impacts[2], impacts
    assert errors[0] >= errors[1] >= errors[2], errors
    for rtol, (_, err, t_inf) in zip(rtols, cuts):
        assert err <= rtol * t_inf, (rtol, err)


@pytest.mark.parametrize("bad", [0.0, -1e-9, float("nan"), "1e-9x"])
def test_a_bad_zeno_time_rtol_is_refused_naming_the_parameter(bad):
    with pytest.raises(ValueError, match="zeno_time_rtol"):
        run_master(ball(1.0, e=0.5, t_end=2.0), zeno_time_rtol=bad)
