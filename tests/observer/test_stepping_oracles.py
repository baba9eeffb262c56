"""Moreau–Jean time stepping against exact oracles (docs/theory/scheme.md §7, docs/theory/oracles.md).

External oracle data is resolved by ``tests/oracles.py`` (``../shared/oracles`` from the
project root; a missing oracle fails under ``CI`` and skips otherwise).

Floating-point results are compared with a stated round-off tolerance (they depend on the
BLAS and library versions); bitwise equality is asserted only where it is the property
(structural zeros of an inactive contact, one code path driven two ways). The external
oracles of the scheme (Siconos) and the closed forms are run on every engine that takes the
case (the ``engine`` fixture of tests/conftest.py): the properties of the scheme (its order,
its impact step, its energy balance) on the engines that take a time-stepping case (the numba
kernel, the numpy reference stepper of ``observer/stepping.py``, the toy engine; the event
engine refuses them), the closed-form impact and rest times of the ball and the static
preload of double_mass on the event engine too, each checked on its own with its tolerance.

Oracles used here:

* Siconos' ``BouncingBallTS.ref`` (same scheme, so agreement to round-off);
* Siconos runs generated for this project (``siconos/generated/``: the forced impact
  oscillator at θ = 1, and a 3-DOF system with two coupled contacts at θ = ½, ¾, 1),
  reproduced step by step from their JSON input through the public API;
* the closed-form Zeno bouncing ball (docs/theory/oracles.md §1, ``observer.scenarios.bouncing_ball``);
* an event-driven closed-form solution of the undamped forced impact oscillator
  ``ẍ + x = A cos ωt``, ``x ≤ σ``, ``ẋ⁺ = −r ẋ⁻`` written in this file (docs/theory/oracles.md §2);
* the matrix exponential for contact-free motion (docs/theory/oracles.md §5);
* the single-impact and static-preload identities of docs/theory/models.md §3 and §7.5;
* the exact discrete energy balance of the θ = ½ scheme (docs/theory/index.md §1, stepping.py docstring).
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sla

import observer
from observer.closed_form import ExactImpactOscillator
from observer.scenario import Scenario
from observer.scenarios import bouncing_ball as bb
from observer.stepping import MoreauJean
from oracles import oracle

DATA = Path(__file__).resolve().parents[1] / "data"
SICONOS_TOML = DATA / "siconos_bouncing_ball.toml"

EPS = np.finfo(float).eps

LAWS = ("newton", "poisson")

# bouncing ball of criterion 2 (h0 = 1 m, g0 = 9.81, e = 0.8); the mass is deliberately
# not 1 so that "P/h → m g0" is distinguishable from "P/h → g0"
BALL = dict(m=2.0, g0=9.81, h0=1.0, e=0.8)


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------
def ball_run(engine, law: str, h: float, t_end: float, theta: float = 0.5,
             integrator: str | None = "time-stepping"):
    """The built-in bouncing ball with :data:`BALL` parameters on ``engine`` (the ``engine``
    fixture; ``integrator=None``: the engine's own), cached per module (one run for the
    engine's own integrator however it was named)."""
    return _ball_run(engine, law, h, t_end, theta, integrator or engine.engine.integrator)


@functools.lru_cache(maxsize=None)
def _ball_run(engine, law: str, h: float, t_end: float, theta: float, integrator: str):
    sc = observer.load_scenario("bouncing_ball", {
        "param.m": BALL["m"], "param.g0": BALL["g0"], "param.h0": BALL["h0"],
        "param.restitution": BALL["e"], "param.law": law})
    kw = {"integrator": integrator}
    if theta != 0.5:
        kw["theta"] = theta
    return engine.simulate(sc, h=h, t_end=t_end, **kw)


def impact_rows(P: np.ndarray) -> np.ndarray:
    """Rows i (step i−1 → i) where a new impact starts: P > 0, consecutive rows grouped."""
    rows = np.flatnonzero(P > 0.0)
    if rows.size == 0:
        return rows
    return rows[np.r_[True, np.diff(rows) > 1]]


def ball_impact_times(res, g0: float) -> tuple[np.ndarray, np.ndarray]:
    """Impact times of a ball run: (grid time of the impact step's start, sub-step estimate).

    The sub-step estimate extrapolates the last pre-impact state (q_k, u_k) ballistically
    (the θ = ½ scheme is exact for free flight under constant gravity) to q = 0.
    """
    k = impact_rows(res.P[:, 0]) - 1
    q, u = res.q[k, 0], res.u[k, 0]
    s = (u + np.sqrt(u * u + 2.0 * g0 * np.maximum(q, 0.0))) / g0
    return res.t[k], res.t[k] + s


def fit_order(hs, errs) -> float:
    """Least-squares slope of log(err) against log(h)."""
    return float(np.polyfit(np.log(np.asarray(hs)), np.log(np.asarray(errs)), 1)[0])


def periodic_orbit_11(omega, r, sigma, A=1.0):
    """(1,1) orbit of the non-dimensional impact oscillator (docs/theory/oracles.md §2): (V, t0, T)."""
    T = 2.0 * np.pi / omega
    gf = A / (1.0 - omega ** 2)
    kappa = 0.5 * (1.0 + r) / np.tan(np.pi / omega)
    mu = (1.0 - r) / (2.0 * omega)
    roots = np.roots([kappa ** 2 + mu ** 2, 2.0 * sigma * kappa, sigma ** 2 - gf ** 2]).real
    V = float(roots.max())
    t0 = float(np.arctan2(-mu * V / gf, (sigma + kappa * V) / gf) / omega) % T
    return V, t0, T


def custom_scenario(M, C, K, W, *, q0, u0, h, t_end, theta=0.5, law="newton", e=0.5,
                    offset=None, constant=None, amplitude=None, omega=None, phase=0.0):
    """A scenario document built from matrices (see observer.scenario's TOML format)."""
    M, C, K, W = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (M, C, K, W))
    n, m = W.shape
    forcing = {"constant": list(constant) if constant is not None else [0.0] * n}
    if amplitude is not None:
        forcing.update(amplitude=list(amplitude), omega=omega, phase=phase)
    doc = {
        "system": {"M": M.tolist(), "C": C.tolist(), "K": K.tolist(), "W": W.tolist(),
                   "forcing": forcing,
                   "gap": {"offset": list(offset) if offset is not None else [0.0] * m}},
        "impact": {"law": law, "restitution": e},
        "initial": {"q": list(map(float, q0)), "u": list(map(float, u0))},
        "simulation": {"t_end": t_end, "h": h, "theta": theta},
    }
    return Scenario.from_dict(doc)


# ---------------------------------------------------------------------------------------
# 1. Siconos BouncingBallTS
# ---------------------------------------------------------------------------------------
def test_siconos_bouncing_ball_reference(engine):
    """The 3-DOF Siconos ball (tests/data/siconos_bouncing_ball.toml) reproduces
    BouncingBallTS.ref with either engine: t, q[0], v[0], impulse p(1)[0] and λ(1)[0] agree
    to ≤ 1e-10 at every one of the 2001 rows (same scheme, so only round-off may differ)."""
    path = oracle("siconos", "BouncingBallTS.ref")
    with path.open() as fh:
        rows, cols = map(int, fh.readline().split())
    ref = np.loadtxt(path, skiprows=1)
    assert ref.shape == (rows, cols) == (2001, 5)

    res = engine.simulate(str(SICONOS_TOML), integrator="time-stepping")
    assert res.t.shape == (rows,)
    assert res.q.shape == (rows, 3) and res.P.shape == (rows, 1)
    tol = engine.tol.same_scheme
    assert np.max(np.abs(res.t - ref[:, 0])) <= tol
    assert np.max(np.abs(res.q[:, 0] - ref[:, 1])) <= tol
    assert np.max(np.abs(res.u[:, 0] - ref[:, 2])) <= tol
    assert np.max(np.abs(res.P[:, 0] - ref[:, 3])) <= tol
    # for one contact with H = [1, 0, 0], Siconos' λ(1) is the same impulse
    assert np.max(np.abs(res.P[:, 0] - ref[:, 4])) <= tol
    # the unconstrained coordinates never move (round-off of the O(1) motion of q[0])
    assert np.max(np.abs(res.q[:, 1:])) <= 1e-14 and np.max(np.abs(res.u[:, 1:])) <= 1e-14
    # the comparison is not vacuous: many impacts, then persistent contact
    assert impact_rows(res.P[:, 0]).size >= 20
    assert res.active[-100:, 0].all()


# ---------------------------------------------------------------------------------------
# 1b. Siconos runs made for this project: θ ≠ ½ and two coupled contacts
# ---------------------------------------------------------------------------------------
GENERATED_TOL = 1e-10
"""Absolute tolerance on t, q, u and P at every step against a generated Siconos run (same
scheme, active-set rule and Newton law, so only round-off may differ: measured ≤ 5.6e-14 on
values of order 1; the tolerance leaves room for other BLAS/LAPACK builds on both sides)."""

SHARED_GENERATED = ("impact_oscillator_theta1", "two_contact_theta0.5", "two_contact_theta0.75",
                    "two_contact_theta1.0")
CLOSED_GENERATED = ("two_contact_closed_theta0.5", "two_contact_closed_theta0.75",
                    "two_contact_closed_theta1.0")
"""Shipped in tests/data/siconos/ (made by its ``make_two_contact_closed.py`` with Siconos):
the two-contact system preloaded so that both contacts stay closed together."""


def siconos_scenario(spec: dict) -> Scenario:
    """The scenario of a generated Siconos input (``siconos/generated/*.json``), through the
    public document format: f(t) = constant + amplitude·cos(omega t + phase),
    g = Wᵀq + gap_offset, Newton's law with the given restitution on every contact."""
    forcing = spec["forcing"]
    doc = {
        "system": {"M": spec["M"], "C": spec["C"], "K": spec["K"], "W": spec["W"],
                   "forcing": {"constant": forcing["constant"], "amplitude": forcing["amplitude"],
                               "omega": forcing["omega"], "phase": forcing["phase"]},
                   "gap": {"offset": spec["gap_offset"]}},
        "impact": {"law": "newton", "restitution": spec["restitution"]},
        "initial": {"q": spec["q0"], "u": spec["u0"]},
        "simulation": {"t_end": spec["T"], "h": spec["h"], "theta": spec["theta"]},
    }
    return Scenario.from_dict(doc)


@functools.lru_cache(maxsize=None)
def generated_oracle(name: str):
    """(input, Siconos columns by header name) of a generated Siconos oracle."""
    if name in CLOSED_GENERATED:
        spec_path, csv_path = DATA / "siconos" / f"{name}.json", DATA / "siconos" / f"{name}.csv.gz"
    else:
        folder = oracle("siconos", "generated")
        spec_path, csv_path = folder / f"{name}.json", folder / f"{name}.csv"
    spec = json.loads(spec_path.read_text())
    return spec, np.genfromtxt(csv_path, delimiter=",", names=True)


@functools.lru_cache(maxsize=None)
def generated_run(name: str):
    """(input, Siconos columns by header name, our run on the default engine) of a generated
    Siconos oracle."""
    spec, table = generated_oracle(name)
    return spec, table, observer.simulate(siconos_scenario(spec))


def siconos_columns(table, prefix: str, count: int) -> np.ndarray:
    """Columns ``prefix0 … prefix{count-1}`` of a generated oracle, as an array (rows, count)."""
    return np.column_stack([table[f"{prefix}{i}"] for i in range(count)])


@pytest.mark.parametrize("name", SHARED_GENERATED + CLOSED_GENERATED)
def test_siconos_generated_runs(name, engine):
    """Each generated Siconos run (one Interaction per contact, MoreauJeanOSI(θ), Lemke) is
    reproduced from its JSON input through the public API, with either engine: t, q, u and
    the impulse P of every step agree to :data:`GENERATED_TOL` (1e-10; measured ≤ 5.6e-14),
    on every one of the T/h + 1 rows. (θ = 1 catches θ and 1 − θ swapped in the position
    update, which θ = ½ cannot see.)"""
    spec, ref = generated_oracle(name)
    res = engine.simulate(siconos_scenario(spec), integrator="time-stepping")
    n, m = np.shape(spec["W"])
    steps = int(round(spec["T"] / spec["h"]))
    assert ref.shape == (steps + 1,) and res.t.shape == (steps + 1,)
    assert res.metadata["theta"] == spec["theta"]
    assert np.max(np.abs(res.t - ref["t"])) <= min(GENERATED_TOL, engine.tol.same_scheme)
    for ours, prefix, count in ((res.q, "q", n), (res.u, "u", n), (res.P, "P", m)):
        err = np.max(np.abs(ours - siconos_columns(ref, prefix, count)))
        assert err <= min(GENERATED_TOL, engine.tol.same_scheme), (prefix, err)


def impact_count(P: np.ndarray) -> int:
    """Number of impacts in an impulse column: groups of consecutive steps with P > 0."""
    return int(np.count_nonzero(np.diff(np.r_[0, (P > 0.0).astype(int)]) == 1))


def test_siconos_generated_oscillator_has_impacts():
    """The θ = 1 oscillator oracle is not vacuous: θ = 1 really (not ½), Siconos' run has
    impacts (measured: 12, one step each), and ours has them on the same steps."""
    spec, ref, res = generated_run("impact_oscillator_theta1")
    assert spec["theta"] == 1.0
    assert impact_count(ref["P0"]) >= 5
    # the same impulse steps (above round-off: 1e-12 of the largest impulse)
    roundoff = 1e-12 * np.max(ref["P0"])
    assert np.array_equal(ref["P0"] > roundoff, res.P[:, 0] > roundoff)
    # each impact is a real one (an impulse of at least 1e-3 of the largest), not grazing
    first = np.flatnonzero(np.diff(np.r_[0, (ref["P0"] > roundoff).astype(int)]) == 1)
    assert first.size == impact_count(ref["P0"])
    assert np.all(ref["P0"][first] >= 1e-3 * np.max(ref["P0"]))


@pytest.mark.parametrize("name", CLOSED_GENERATED)
def test_siconos_two_contacts_closed_together(name):
    """The preloaded two-contact oracle exercises what it is for: impacts on each contact
    (measured 10-12 and 23-28), then both contacts closed together — coupled Delassus
    matrix, off-diagonal w₀ᵀM⁻¹w₁ ≠ 0 — on ≥ 900 steps (measured 1021-1033), with both
    impulses positive there in Siconos' run and in ours."""
    spec, ref, res = generated_run(name)
    W = np.array(spec["W"])
    assert abs(W[:, 0] @ np.linalg.solve(np.array(spec["M"]), W[:, 1])) > 0.1
    ref_P = siconos_columns(ref, "P", 2)
    both = res.active.all(axis=1)
    assert np.count_nonzero(both) >= 900
    assert np.count_nonzero((ref_P > 0).all(axis=1)) >= 900
    assert np.count_nonzero((res.P > 0).all(axis=1)) >= 900
    assert all(impact_count(ref_P[:, j]) >= 5 for j in range(2))


@pytest.mark.parametrize("name", SHARED_GENERATED[1:])
def test_siconos_shared_two_contact_runs_exercise_both_contacts(name):
    """The shared two-contact runs (T = 10 s) have impacts on both contacts (measured 14-15
    and 30-33) and long phases with contact 1 closed (≥ 400 steps with P₁ > 0; measured
    450-468), and a step with both contacts closed (measured 2 only: the long both-closed
    phases are in :data:`CLOSED_GENERATED`)."""
    spec, ref, res = generated_run(name)
    ref_P = siconos_columns(ref, "P", 2)
    assert all(impact_count(ref_P[:, j]) >= 3 for j in range(2))
    assert np.count_nonzero(ref_P[:, 1] > 0) >= 400
    assert np.count_nonzero(res.active.all(axis=1)) >= 1


# ---------------------------------------------------------------------------------------
# 2. bouncing ball against the closed form
# ---------------------------------------------------------------------------------------
H_BALL = 5e-4


@pytest.mark.parametrize("law", LAWS)
def test_ball_first_impact_step(law, engine):
    """The first step with P > 0 starts at t_k with |t_k − t1| ≤ h/2 + g h²/(8 v1),
    t1 = sqrt(2h0/g): the predicted index set g(q_k + (h/2)u_k) ≤ 0 closes the contact in
    the step whose midpoint is nearest to the exact impact (free flight is exact for θ = ½)."""
    h, g, h0 = H_BALL, BALL["g0"], BALL["h0"]
    res = ball_run(engine, law, h, 5.0)
    t1 = np.sqrt(2 * h0 / g)
    v1 = np.sqrt(2 * g * h0)
    assert t1 == pytest.approx(bb.impact_times(h0, g, BALL["e"], 1)[0], rel=1e-15)
    t_grid, t_sub = ball_impact_times(res, g)
    assert abs(t_grid[0] - t1) <= 0.5 * h + g * h * h / (8 * v1) + 1e-12
    # free flight before the first impact is exact, so the extrapolated impact is too
    assert abs(t_sub[0] - t1) <= 1e-9
    # ... and the first rebound obeys the law u_{k+1} = −e·u_k (for one contact the
    # discrete Poisson step is the Newton step: no smooth sub-step after the reversal)
    k = impact_rows(res.P[:, 0])[0] - 1
    assert res.u[k + 1, 0] == pytest.approx(-BALL["e"] * res.u[k, 0], rel=1e-12)


def test_ball_poisson_is_newton(engine):
    """For one contact Poisson's law is Newton's law, and the discrete Poisson step is the
    discrete Newton step: the two ball runs (θ = ½ and θ = 1, 5 s, several hundred impact
    and contact steps) agree to round-off, 1e-12 relative to the largest |q|, |u|, |P|."""
    for theta in (0.5, 1.0):
        newton, poisson = (ball_run(engine, law, H_BALL, 5.0, theta) for law in LAWS)
        assert impact_rows(newton.P[:, 0]).size >= 20
        for a, b in ((newton.q, poisson.q), (newton.u, poisson.u), (newton.P, poisson.P)):
            assert np.max(np.abs(a - b)) <= 1e-12 * np.max(np.abs(a))


@pytest.mark.parametrize("law", LAWS)
def test_ball_impact_times(law, engine):
    """The first 10 impact times (start of each new group of P > 0 steps) follow the
    closed form t_k = t1 + (2v1/g) e(1 − e^{k−1})/(1 − e): the first two within 2h, all ten
    within 5h (grid quantisation h/2 plus an O(h) per-bounce error that stays small,
    measured ≤ 3h). Both laws: for one contact the discrete Poisson step is Newton's."""
    h, g, h0, e = H_BALL, BALL["g0"], BALL["h0"], BALL["e"]
    res = ball_run(engine, law, h, 5.0, integrator=None)
    t_grid, _ = ball_impact_times(res, g)
    n = 10
    assert t_grid.size > n
    exact = bb.impact_times(h0, g, e, n)
    err = t_grid[:n] - exact
    assert np.all(np.abs(err[:2]) <= 2 * h), err / h
    assert np.all(np.abs(err) <= 5 * h), err / h


@pytest.mark.parametrize("law", LAWS)
def test_ball_rests_after_accumulation(law, engine):
    """After the Zeno time t_∞ = sqrt(2h0/g)(1+e)/(1−e) = 4.0637 s the ball rests:
    |q| ≤ 10h, the contact is closed in every step, and P/h equals the persistent contact
    force m·g0 to a few percent (≤ 5 %) right after t_∞ and to 1e-6 from t_∞ + 0.05 s on."""
    h, g, h0, e, m = H_BALL, BALL["g0"], BALL["h0"], BALL["e"], BALL["m"]
    t_inf = bb.accumulation_time(h0, g, e)
    assert t_inf == pytest.approx(4.0637, abs=1e-4)
    res = ball_run(engine, law, h, 5.0, integrator=None)
    rows = np.flatnonzero(res.t > t_inf)
    assert rows.size > 1000
    assert np.max(np.abs(res.q[rows, 0])) <= 10 * h
    assert res.active[rows, 0].all()
    rel = np.abs(res.P[:, 0] / h / (m * g) - 1.0)
    # Newton's contact velocity still rings (γ_{k+1} = −eγ_k) just after t_∞: 4.6 % at h = 5e-4
    assert np.max(rel[rows]) <= 0.05
    # ... and decays geometrically: 50 ms later P/h = m g0 to 1e-6
    assert np.max(rel[res.t > t_inf + 0.05]) <= 1e-6
    # and no penetration beyond O(h) anywhere in the run
    assert res.g.min() >= -10 * h


def exact_last_time_above(h0, g, e, level):
    """Last time the exact ball is above ``level``: the last rebound k whose apex
    e^{2k}h0 exceeds it falls back through it at t_k + (v_k + sqrt(v_k² − 2g·level))/g."""
    k = int(np.floor(np.log(level / h0) / (2 * np.log(e))))
    assert e ** (2 * k) * h0 > level >= e ** (2 * k + 2) * h0
    tk = bb.impact_times(h0, g, e, k)[k - 1]
    vk = e ** k * np.sqrt(2 * g * h0)
    return k, tk + (vk + np.sqrt(vk * vk - 2 * g * level)) / g


@pytest.mark.parametrize("law", LAWS)
def test_ball_last_time_above_1mm(law, engine):
    """The last time q > 1e-3 m matches the closed form 3.9277 s (docs/theory/oracles.md §1) at h = 1e-4
    to 10h (impact-time error ≤ 5h, plus the sensitivity 0.34 s/(m/s) of the crossing of
    the low 15th apex (1.24 mm) to an O(g h) rebound-speed error); both laws, since for
    one contact the discrete Poisson step is Newton's."""
    h, g, h0, e = 1e-4, BALL["g0"], BALL["h0"], BALL["e"]
    k, t_exact = exact_last_time_above(h0, g, e, 1e-3)
    # docs/theory/oracles.md §1 quotes 3.9278 s; the series gives 3.92770 s (t_15 = 3.90485 s + 22.85 ms)
    assert k == 15 and t_exact == pytest.approx(3.9277, abs=5e-5)
    res = ball_run(engine, law, h, 4.0, integrator=None)
    t_last = res.t[np.flatnonzero(res.q[:, 0] > 1e-3)[-1]]
    assert abs(t_last - t_exact) <= 10 * h, (t_last, t_exact)


# ---------------------------------------------------------------------------------------
# 3. impact oscillator against the event-driven closed form: first-order convergence
# ---------------------------------------------------------------------------------------
OSC = dict(A=1.0, omega=2.8, sigma=0.0, r=0.8)


def test_exact_oscillator_reproduces_periodic_orbit():
    """The event-driven oracle itself: started just after an impact of the (1,1) orbit of
    docs/theory/oracles.md §2 (ω = 2.8, r = 0.8, σ = 0: V = 0.336177, t0 = 1.092635, T = 2.243995) it
    returns impacts at t0 + nT with velocity V (the orbit is unstable, so the agreement
    degrades by ~3× per period from round-off), and x < σ strictly inside each period."""
    V, t0, T = periodic_orbit_11(OSC["omega"], OSC["r"], OSC["sigma"])
    assert V == pytest.approx(0.336177, abs=1e-6)
    assert t0 == pytest.approx(1.092635, abs=1e-6)
    assert T == pytest.approx(2.243995, abs=1e-6)
    ex = ExactImpactOscillator(OSC["A"], OSC["omega"], 0.0, OSC["sigma"], OSC["r"],
                               OSC["sigma"], -OSC["r"] * V, t0, t0 + 4.5 * T)
    assert ex.impacts.shape[0] == 4
    n = np.arange(1, 5)
    assert np.max(np.abs(ex.impacts[:, 0] - (t0 + n * T))) <= 1e-10
    assert np.max(np.abs(ex.impacts[:, 1] - V)) <= 1e-10
    inner = np.linspace(t0 + 0.05 * T, t0 + 0.95 * T, 2001)
    assert ex(inner)[0].max() <= OSC["sigma"] - 0.01


@pytest.mark.slow
@pytest.mark.parametrize("law", LAWS)
def test_impact_oscillator_first_order(law, engine):
    """Built-in ``impact_oscillator`` (M = K = 1, C = 0, f = A cos(ωt + φ), g = σ − q,
    Newton/Poisson r = 0.8) started mid-flight on the (1,1) orbit and run over 3¼ forcing
    periods (4 well-separated impacts, |ẋ⁻| = 0.34) converges to the event-driven exact
    solution with order 1 ± 0.2 in max_k |q_k − x(t_k)|.

    The step sizes are h = T/N (N = 1000 … 16000; 500 … 4000 on the numpy steppers, which
    take 40 µs and more a step) and the grid is shifted (via the initial state and the forcing
    phase) so that every exact impact falls at the same fraction 0.3 of a step for every h:
    the O(h) impact error depends on that fraction, and fixing it removes the sawtooth
    scatter that otherwise blurs the fitted order (errs/h = 5.51 … 5.43 from N = 500 to
    16000, so that any three doublings fit the order to ±0.01: 1.007 on 500 … 4000, 1.003
    on 1000 … 16000).
    """
    A, om, sig, r = OSC["A"], OSC["omega"], OSC["sigma"], OSC["r"]
    V, t0, T = periodic_orbit_11(om, r, sig)
    ex = ExactImpactOscillator(A, om, 0.0, sig, r, sig, -r * V, t0, t0 + 5 * T)
    phi = 0.3
    Ns = np.array([500, 1000, 2000, 4000] if engine.numpy_stepping else [1000, 2000, 4000, 8000, 16000])
    hs = T / Ns
    errs, n_impacts = [], []
    for N, h in zip(Ns, hs):
        m = N // 2
        tau0 = t0 + T - (m + phi) * h          # physical time of grid point t = 0
        x0, v0 = ex(tau0)
        sc = observer.load_scenario("impact_oscillator", {
            "param.A": A, "param.omega": om, "param.sigma": sig, "param.restitution": r,
            "param.zeta": 0.0, "param.law": law, "param.q0": float(x0), "param.u0": float(v0),
            "system.forcing.phase": om * tau0})
        res = engine.simulate(sc, h=h, t_end=(m + 3 * N + N // 4) * h, integrator="time-stepping")
        x_exact, _ = ex(res.t + tau0)
        errs.append(np.max(np.abs(res.q[:, 0] - x_exact)))
        n_impacts.append(impact_rows(res.P[:, 0]).size)
    errs = np.array(errs)
    assert n_impacts == [4] * len(Ns)
    order = fit_order(hs, errs)
    assert abs(order - 1.0) <= 0.2, (order, errs / hs)
    assert errs[-1] <= 10 * hs[-1]          # measured 5.4h (both laws: one contact)


# ---------------------------------------------------------------------------------------
# 4. free response against the matrix exponential: second order (θ = ½), first (θ = 1)
# ---------------------------------------------------------------------------------------
M2 = np.array([[2.0, 0.3], [0.3, 1.0]])
K2 = np.array([[30.0, -10.0], [-10.0, 20.0]])
C2 = 0.02 * K2 + 0.05 * M2
F2 = np.array([1.0, -2.0])
W2 = np.array([[1.0], [0.5]])


def free_response_errors(engine, theta, hs, t_end=2.0):
    """Max state error on the grid vs expm of the augmented system [q, u, 1]."""
    n = 2
    q0, u0 = np.array([0.1, -0.05]), np.array([0.3, 0.2])
    Minv = np.linalg.inv(M2)
    Aug = np.zeros((2 * n + 1, 2 * n + 1))
    Aug[:n, n:2 * n] = np.eye(n)
    Aug[n:2 * n, :n] = -Minv @ K2
    Aug[n:2 * n, n:2 * n] = -Minv @ C2
    Aug[n:2 * n, 2 * n] = Minv @ F2
    x0 = np.r_[q0, u0, 1.0]
    errs = []
    for h in hs:
        # the wall is 100 m away: the contact is never reached
        sc = custom_scenario(M2, C2, K2, W2, q0=q0, u0=u0, h=h, t_end=t_end, theta=theta,
                             offset=[100.0], constant=F2)
        res = engine.simulate(sc, integrator="time-stepping")
        assert not res.active.any() and not res.P.any()
        Phi = sla.expm(Aug * h)
        X = np.empty((res.t.size, 2 * n + 1))
        X[0] = x0
        for k in range(res.t.size - 1):
            X[k + 1] = Phi @ X[k]
        # a single expm at the final time guards the propagated reference
        assert np.allclose(X[-1], sla.expm(Aug * res.t[-1]) @ x0, rtol=0, atol=1e-12)
        errs.append(np.max(np.abs(np.c_[res.q, res.u] - X[:, :2 * n])))
    return np.array(errs)


def test_free_response_second_order_theta_half(engine):
    """Contact-free 2-DOF damped system with constant forcing (non-diagonal M, C, K):
    the θ = ½ scheme converges to expm of [[0, I], [−M⁻¹K, −M⁻¹C]] (state augmented by
    the constant forcing) with fitted order 2 ± 0.2 over h = 2e-2 … 1.25e-3."""
    hs = np.array([2e-2, 1e-2, 5e-3, 2.5e-3, 1.25e-3])
    errs = free_response_errors(engine, 0.5, hs)
    order = fit_order(hs, errs)
    assert abs(order - 2.0) <= 0.2, (order, errs)
    assert errs[-1] <= 1e-5


def test_free_response_first_order_theta_one(engine):
    """θ = 1 (fully implicit) runs and, as backward Euler, converges with order 1 ± 0.2
    on the same contact-free problem."""
    hs = np.array([1e-2, 5e-3, 2.5e-3, 1.25e-3])
    errs = free_response_errors(engine, 1.0, hs)
    order = fit_order(hs, errs)
    assert abs(order - 1.0) <= 0.2, (order, errs)


# ---------------------------------------------------------------------------------------
# 5. a single impact: exact restitution and energy loss
# ---------------------------------------------------------------------------------------
def single_impact_system(kind: str):
    """(M, w, u0) of a K = C = 0 system without forces approaching the wall (γ⁻ < 0)."""
    if kind == "1dof":
        return np.array([[1.7]]), np.array([1.0]), np.array([-0.9])
    rng = np.random.default_rng(20240611)
    B = rng.normal(size=(2, 2))
    M = B @ B.T + 0.5 * np.eye(2)
    w = np.array([np.cos(0.6), np.sin(0.6)]) * 1.3      # not along a coordinate
    u0 = rng.normal(size=2)
    gamma = w @ u0
    u0 = u0 - (gamma + 0.8) / (w @ w) * w               # make γ⁻ = −0.8
    return M, w, u0


@pytest.mark.parametrize("kind", ["1dof", "2dof"])
@pytest.mark.parametrize("e", [0.0, 0.5, 0.8, 1.0])
@pytest.mark.parametrize("law", LAWS)
def test_single_impact(law, e, kind, engine):
    """K = C = 0, f = 0, one contact approached with γ⁻ < 0 so that exactly one step
    carries an impulse: γ⁺ = −eγ⁻ to round-off, the kinetic energy changes by exactly
    −(1−e²)(γ⁻)²/(2G) with G = wᵀM⁻¹w (relative 1e-12 of the kinetic energy), the impulse
    is (1+e)|γ⁻|/G, and the velocity only changes along M⁻¹w.

    "Exactly one step" allows round-off elsewhere: after a plastic impact (e = 0) the
    contact stays closed with γ = O(ε|γ⁻|) of either sign (measured −3.8e-17), so the
    following steps may carry an impulse of that order (measured 2.5e-17); every other
    step's |P| must stay below 100ε times the impact's impulse (|γ⁻|/G)."""
    h = 1e-3
    M, w, u0 = single_impact_system(kind)
    n = M.shape[0]
    gamma_minus = float(w @ u0)
    assert gamma_minus < 0
    N = 10
    gap0 = abs(gamma_minus) * h * (N + 0.45)   # contact predicted closed in step N exactly
    sc = custom_scenario(M, np.zeros((n, n)), np.zeros((n, n)), w[:, None], q0=np.zeros(n),
                         u0=u0, h=h, t_end=30 * h, law=law, e=e, offset=[gap0])
    res = engine.simulate(sc, integrator="time-stepping")
    G = float(w @ np.linalg.solve(M, w))
    roundoff = 100 * EPS * abs(gamma_minus) / G
    rows = np.flatnonzero(np.abs(res.P[:, 0]) > roundoff)
    assert rows.tolist() == [N + 1]
    if e > 0:
        assert np.flatnonzero(res.active[:, 0]).tolist() == [N + 1]
    else:  # e = 0: the contact stays closed, with zero impulse after the impact
        assert np.all(res.active[N + 1:, 0]) and not res.active[:N + 1, 0].any()
    k = N
    gm, gp = res.gamma[k, 0], res.gamma[k + 1, 0]
    assert gm == pytest.approx(gamma_minus, rel=1e-14)
    assert abs(gp + e * gm) <= 1e-12 * abs(gm)
    T0 = 0.5 * u0 @ M @ u0
    T = 0.5 * np.einsum("ki,ij,kj->k", res.u, M, res.u)
    dT = T[k + 1] - T[k]
    expected = -(1 - e * e) * gm * gm / (2 * G)
    assert abs(dT - expected) <= 1e-12 * T0
    if e < 1:
        assert dT == pytest.approx(expected, rel=1e-12)
    assert res.P[k + 1, 0] == pytest.approx((1 + e) * abs(gm) / G, rel=1e-12)
    du = res.u[k + 1] - res.u[k]
    dir_ = np.linalg.solve(M, w)
    assert np.allclose(du, (du @ dir_) / (dir_ @ dir_) * dir_, rtol=0, atol=1e-14)
    # energy is constant before and after the impact step (free flight, no forces)
    assert np.allclose(T[:k + 1], T0, rtol=1e-13, atol=0)
    assert np.allclose(T[k + 1:], T[k + 1], rtol=1e-13, atol=0)


# ---------------------------------------------------------------------------------------
# 6. static preload of double_mass
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("law", LAWS)
def test_double_mass_static_preload(law, engine):
    """``double_mass`` with F = 0 started at its static contact equilibrium stays in
    persistent contact: the contact is closed in every step, P_k/h equals the static force
    λ_s = −g_s/(wᵀK⁻¹w) (g_s = wᵀK⁻¹f_const + ν₀, computed here from the loaded M, K, W,
    forcing constant and gap offset; 2.215 N) to ≤ 1e-6 relative, and the state stays put."""
    h = 1e-3
    sc = observer.load_scenario("double_mass", {"param.F": 0.0, "param.law": law})
    s = sc.system
    assert np.allclose(s.f(np.linspace(0, 3, 7)), s.forcing.constant)  # F = 0 really
    w = s.W[:, 0]
    q_s = np.linalg.solve(s.K, s.forcing.constant)
    g_s = w @ q_s + s.nu(0.0)[0]
    Kinv_w = np.linalg.solve(s.K, w)
    lam_s = -g_s / (w @ Kinv_w)
    assert g_s < 0
    assert lam_s == pytest.approx(2.215, rel=1e-9)
    # the default initial state is that equilibrium
    assert np.allclose(sc.q0, q_s + Kinv_w * lam_s, rtol=0, atol=1e-12)
    assert np.all(sc.u0 == 0.0)

    res = engine.simulate(sc, h=h, t_end=2.0)
    assert res.active[1:, 0].all()
    rel = np.abs(res.P[1:, 0] / h / lam_s - 1.0)
    assert np.max(rel) <= 1e-6
    assert np.max(np.abs(res.q - sc.q0)) <= 1e-12
    assert np.max(np.abs(res.u)) <= 1e-12
    assert np.max(np.abs(res.g)) <= 1e-12


# ---------------------------------------------------------------------------------------
# 7. Newton vs Poisson at trajectory level: both first order to the closed form
# ---------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("law", LAWS)
def test_ball_impact_times_first_order(law, engine):
    """Both laws converge to the same closed-form impact times with order 1 ± 0.2: RMS
    error of the first 8 impact times (sub-step estimate from the last pre-impact state)
    over h = 2e-3 … 6.25e-5 (… 1.25e-4 on the numpy steppers: half the steps; fitted
    order 0.94 and 0.91), with the same constant (≤ 5h at the finest h)."""
    g, h0, e = BALL["g0"], BALL["h0"], BALL["e"]
    n = 8
    exact = bb.impact_times(h0, g, e, n)
    hs = 2e-3 * 2.0 ** -np.arange(5 if engine.numpy_stepping else 6)
    errs = []
    for h in hs:
        res = ball_run(engine, law, h, float(exact[-1] + 0.1))
        _, t_sub = ball_impact_times(res, g)
        assert t_sub.size >= n
        errs.append(np.sqrt(np.mean((t_sub[:n] - exact) ** 2)))
    errs = np.array(errs)
    order = fit_order(hs, errs)
    assert abs(order - 1.0) <= 0.2, (order, errs / hs)
    assert errs[-1] <= 5 * hs[-1]


# ---------------------------------------------------------------------------------------
# 8. θ: fully implicit runs; θ = ½ has the exact discrete energy balance
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("law", LAWS)
def test_theta_one_bouncing_ball_runs(law, engine):
    """θ = 1 is accepted, reported in the metadata, and gives a sane impacting run: the
    first impact within h of t1, P ≥ 0, no deep penetration, and the ball ends at rest
    with P/h = m g0."""
    h, g, m = 1e-3, BALL["g0"], BALL["m"]
    res = ball_run(engine, law, h, 5.0, theta=1.0)
    assert res.metadata["theta"] == 1.0
    assert np.all(np.isfinite(res.q)) and np.all(res.P >= 0)
    t_grid, _ = ball_impact_times(res, g)
    # θ = 1 lags the free-flight position by g h t/2, i.e. the impact by h/2, plus h/2 grid
    assert abs(t_grid[0] - np.sqrt(2 * BALL["h0"] / g)) <= h + 1e-9
    assert res.g.min() >= -10 * h
    tail = slice(-200, None)
    assert res.active[tail, 0].all()
    assert np.allclose(res.P[tail, 0] / h, m * g, rtol=1e-6)


@pytest.mark.parametrize("forced", [False, True])
def test_theta_half_exact_energy_balance(forced, engine):
    """Contact-free damped 2-DOF system, θ = ½: E = ½uᵀMu + ½qᵀKq obeys
    E_{k+1} − E_k = −h ūᵀCū + h f̄ᵀū (ū = (u_k+u_{k+1})/2, f̄ = (f_k+f_{k+1})/2) to
    round-off at every step — with zero forcing and with harmonic forcing."""
    h, t_end = 2e-3, 3.0
    q0, u0 = np.array([0.2, -0.1]), np.array([-0.5, 0.8])
    kw = dict(amplitude=[1.5, -0.7], omega=3.3, phase=0.4) if forced else {}
    sc = custom_scenario(M2, C2, K2, W2, q0=q0, u0=u0, h=h, t_end=t_end, offset=[100.0], **kw)
    res = engine.simulate(sc, integrator="time-stepping")
    assert not res.active.any()
    E = res.system.energy(res.q, res.u)
    ubar = 0.5 * (res.u[1:] + res.u[:-1])
    f = res.system.f(res.t)
    fbar = 0.5 * (f[1:] + f[:-1])
    predicted = -h * np.einsum("ki,ij,kj->k", ubar, C2, ubar) + h * np.einsum("ki,ki->k", fbar, ubar)
    resid = np.diff(E) - predicted
    assert np.max(np.abs(resid)) <= 1e-13 * np.max(E)
    # not vacuous: damping removes a visible amount of energy
    assert np.sum(np.abs(predicted)) >= 1e-2 * np.max(E)
    if not forced:
        assert np.all(np.diff(E) < 0)


def test_moreau_jean_step_matches_simulate():
    """Driving :class:`MoreauJean` by hand (``predicted_active`` then ``step``) reproduces
    ``simulate(engine="python")`` — the same stepper driven by the loop — bit for bit on
    the bouncing ball (Newton, θ = ½): one code path, so bitwise equality is the property."""
    h = 1e-3
    sc = observer.load_scenario("bouncing_ball", {
        "param.m": BALL["m"], "param.g0": BALL["g0"], "param.h0": BALL["h0"],
        "param.restitution": BALL["e"], "param.law": "newton"})
    res = observer.simulate(sc, h=h, t_end=5.0, theta=0.5, engine="python")
    stepper = MoreauJean(sc.system, sc.law, h, 5.0, theta=0.5)
    q, u = sc.q0.copy(), sc.u0.copy()
    for k in range(stepper.grid.steps):
        idx = np.flatnonzero(stepper.predicted_active(k, q, u))
        q, u, P, _ = stepper.step(k, q, u, idx)
        assert np.array_equal(q, res.q[k + 1]) and np.array_equal(u, res.u[k + 1])
        assert res.active[k + 1, 0] == (idx.size == 1)
        if idx.size:
            assert P[0] == res.P[k + 1, 0]


def test_stepping_events_table_matches_the_trajectory():
    """The time-stepped master's event table, recomputed from the returned trajectory: one row
    per change of a contact's closed state, γ⁻/γ⁺ the contact velocities Wᵀu + ν̇ of the rows
    before and after the step, the step's impulse, and the kind from the change and the
    impulse."""
    sc = observer.load_scenario("impact_oscillator")
    res = observer.simulate(sc)
    ev = res.events
    act = res.active
    changes = np.argwhere(act[1:] != act[:-1])
    assert len(ev) == len(changes) > 4
    gamma = res.u @ sc.system.W + sc.system.nu_dot(res.t)
    for (k, j), row in zip(changes, ev.itertuples()):
        assert row.time == res.t[k] and row.contact == j
        kind = "liftoff" if act[k, j] else ("impact" if res.P[k + 1, j] > 0 else "stick")
        assert row.kind == kind
        scale = max(abs(gamma[k, j]), abs(gamma[k + 1, j]), 1e-300)
        assert abs(row.gamma_minus - gamma[k, j]) <= 1e-14 * scale
        assert abs(row.gamma_plus - gamma[k + 1, j]) <= 1e-14 * scale
        assert row.impulse == res.P[k + 1, j]
    assert set(ev["kind"]) >= {"impact", "liftoff"}
