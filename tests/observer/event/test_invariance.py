"""Issue 19: the exact integrator's results are a property of the motion, not of the
coordinates. Hypothesis draws random 1–4-contact systems (as many DOF, singular K allowed,
harmonic forcing) and runs each

(a) translated, q → q + c with ν → ν − Wᵀc and f → f + Kc (the same motion);
(b) with the time origin shifted, t → t + T (harmonic phases φ → φ − ωT);
(c) in other units, lengths × α and times × β (M kept: K/β², C/β, f·α/β², ω/β, ν·α, u·α/β);

and compares the event tables (kinds, contacts, times, velocities, impulses) and the
trajectories on the output grid with the original run's. A last property samples t_end at a
few ulp from a window boundary or an event time: no event is made or lost.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import Phase, example, given, settings
from hypothesis import strategies as st

from observer.event.flow import Flow
from observer.event.master import run_master
from observer.event.roots import WINDOW
from observer.scenario import Scenario

NO_SHRINK = [Phase.explicit, Phase.reuse, Phase.generate]   # a failing example is reported as
SETTINGS = settings(max_examples=200, deadline=None, derandomize=True, database=None,
                    phases=NO_SHRINK)                        # drawn: shrinking costs minutes
T_END = 0.2
STEPS = 4
KINDS_COMPARED = ["kind", "contact"]


def build(p: dict, c=None, T: float = 0.0, alpha: float = 1.0, beta: float = 1.0) -> Scenario:
    """The drawn system ``p``, translated by c, time origin T, units (α, β)."""
    M, K, C, W = p["M"], p["K"], p["C"], p["W"]
    n = M.shape[0]
    c = np.zeros(n) if c is None else np.asarray(c, float)
    f = p["f"] + K @ c
    nu = p["nu"] - W.T @ c
    q0 = p["q0"] + c
    doc = {"scenario": {"name": "invariance"},
           "system": {"M": M.tolist(), "C": (C / beta).tolist(), "K": (K / beta ** 2).tolist(),
                      "W": W.tolist(),
                      "forcing": {"constant": (f * alpha / beta ** 2).tolist(),
                                  "amplitude": (p["a"] * alpha / beta ** 2).tolist(),
                                  "omega": p["w"] / beta, "phase": p["phi"] - p["w"] * T},
                      "gap": {"offset": (nu * alpha).tolist()}},
           "impact": {"law": "newton", "restitution": p["e"]},
           "initial": {"q": (q0 * alpha).tolist(), "u": (p["u0"] * alpha / beta).tolist()},
           "simulation": {"t_end": T_END * beta, "h": T_END * beta / STEPS}}
    return Scenario.from_dict(doc)


@st.composite
def systems(draw, zeno: bool = False) -> dict:
    """Random systems; ``zeno``: one body and one contact (a ball, or a block on a spring,
    damped and weakly forced, on a wall) dropped from 2–10 mm with restitution 0.3–0.5, so
    that its impacts accumulate (t∞) well within T_END and it then rests (two contacts whose
    tails overlap: :func:`two_contact_zeno`)."""
    n = m = draw(st.integers(1, 1 if zeno else 4))  # W must have independent columns
    # no subnormal entries: the scenario refuses a matrix entry whose inverse overflows
    fl = st.floats(-1.0, 1.0, allow_nan=False).map(lambda x: 0.0 if abs(x) < 1e-6 else x)
    M = np.diag([draw(st.floats(0.5, 2.0)) for _ in range(n)])
    B = np.array([[draw(fl) if i == j or not zeno else 0.0 for j in range(n)] for i in range(n)])
    K = (2.0 if zeno else 20.0) * B @ B.T if draw(st.booleans()) else np.zeros((n, n))
    C = np.diag([draw(st.one_of(st.just(0.0), st.floats(1e-3, 0.5))) for _ in range(n)])
    # contact j mostly on DOF j (diagonally dominant W: independent columns); gravity on all
    W = np.eye(n) + 0.3 * np.array([[0.0 if i == j or zeno else draw(fl) for j in range(m)]
                                     for i in range(n)])
    q0 = np.array([draw(fl) for _ in range(n)])
    g0 = np.array([draw(st.floats(0.002, 0.01) if zeno else st.floats(0.03, 0.12))
                   for _ in range(m)])
    nu = g0 - W.T @ q0
    f = -10.0 * np.diag(M)
    weak = 0.1 if zeno else 1.0
    return dict(M=M, K=K, C=C, W=W, q0=q0, u0=weak * np.array([draw(fl) for _ in range(n)]),
                nu=nu, f=f + (K @ q0 if zeno else 0.0), a=weak * np.array([draw(fl) for _ in range(n)]),
                w=draw(st.floats(0.5, 8.0)), phi=draw(st.floats(0.0, 6.0)),
                e=draw(st.floats(0.3, 0.5) if zeno else st.floats(0.6, 0.9)))  # Zeno or none


V_TAIL = 0.05
"""Impacts slower than this (original units; the first impacts are about 1 m/s) belong to a
Zeno tail: how many of them are resolved before the tail is extrapolated depends on how well
the gap is represented in float64 (it grows with |q| and |ν|), so they are not compared; the
accumulation time t∞ and everything after it are."""


def comparable(res, c=None, T: float = 0.0, alpha: float = 1.0, beta: float = 1.0):
    """Events and trajectory mapped back to the original coordinates, and the Zeno tails
    ``[first impact slower than V_TAIL, t∞]``; the stick times (t∞ of an accumulation, or of
    a sequence resolved until the contact sticks) are compared to 1e-8·T_END."""
    ev = res.events
    col = lambda name: ev[name].to_numpy(dtype=float)  # noqa: E731  (float also when empty)
    t = (col("time") - T) / beta
    gm = col("gamma_minus") * beta / alpha
    tab = np.column_stack([t, gm, col("gamma_plus") * beta / alpha,
                           col("impulse") * beta / alpha])
    kinds = ev[KINDS_COMPARED].to_numpy()
    slow = (kinds[:, 0] == "impact") & (np.abs(gm) < V_TAIL)
    tails, start = [], None
    for k in range(len(t)):
        if slow[k] and start is None:
            start = t[k]
        if kinds[k, 0] == "accumulation" and start is not None:
            tails.append((start, t[k]))
            start = None
    keep = ~slow & (kinds[:, 0] != "accumulation")
    acc = t[kinds[:, 0] == "stick"]        # a Zeno run ends at t∞ by a stick (extrapolated or not)
    fr = res.frame
    n = res.scenario.system.n
    q = fr[[f"q{j}" for j in range(n)]].to_numpy() / alpha
    if c is not None:
        q = q - np.asarray(c)
    u = fr[[f"u{j}" for j in range(n)]].to_numpy() * beta / alpha
    tg = (fr["t"].to_numpy() - T) / beta
    return kinds[keep], tab[keep], acc, np.hstack([q, u]), tg, tails, res.status


def assert_same(a, b, scale: float, rtol: float = 1e-7, t_inf_tol: float = 1e-8 * T_END):
    (ka, ta, acc_a, xa, tga, tails_a, sa), (kb, tb, acc_b, xb, tgb, tails_b, sb) = a, b
    assert sa == sb == "ok"
    assert ka.shape == kb.shape and (ka == kb).all(), f"{ka.tolist()} != {kb.tolist()}"
    if ta.size:
        np.testing.assert_allclose(ta[:, 0], tb[:, 0], rtol=0, atol=rtol * T_END)
        np.testing.assert_allclose(ta[:, 1:], tb[:, 1:], rtol=0, atol=rtol * scale)
    np.testing.assert_allclose(acc_a, acc_b, rtol=0, atol=t_inf_tol)
    assert xa.shape == xb.shape and not np.isnan(xa).any() and not np.isnan(xb).any()
    out = np.zeros(tga.size, dtype=bool)
    for t0, t1 in tails_a + tails_b:
        out |= (tga >= t0 - 1e-9) & (tga <= t1 + 1e-9)
    np.testing.assert_allclose(xa[~out], xb[~out], rtol=0, atol=rtol * scale)


T_INF_TOL = 5e-9
"""Two runs' t∞ of the same accumulation in other coordinates: each is within about 1e-9 of
the exact one (where the coordinates' round-off cuts the resolved impacts differs; the tail
is then extrapolated by exact hops), measured up to 2.4e-9 apart."""


def motion_scale(p) -> float:
    return 10.0 * T_END + float(np.max(np.abs(p["u0"]))) + 1.0


@SETTINGS
@given(systems(), st.data())
def test_event_tables_and_trajectories_are_invariant_under_translation_time_shift_and_units(p, data):
    """Translation, time shift and units on the same drawn system; accumulation times (where a
    drawn system's impacts accumulate) to T_INF_TOL as in the Zeno property below (a 4-contact
    system translated by (−100, −7.5, −7.5, −7.5) moved t∞ by 2.035e-9)."""
    base = comparable(run_master(build(p)))
    scale = motion_scale(p)
    n = p["M"].shape[0]
    c = np.array([data.draw(st.sampled_from([-100.0, -7.5, 3.25, 100.0])) for _ in range(n)])
    assert_same(base, comparable(run_master(build(p, c=c)), c=c), scale, rtol=1e-6, t_inf_tol=T_INF_TOL)
    T = data.draw(st.sampled_from([0.1, 1.0, 37.5, 1e3]))
    assert_same(base, comparable(run_master(build(p, T=T), t0=T, t_end=T + T_END), T=T), scale,
                t_inf_tol=T_INF_TOL)
    alpha = data.draw(st.sampled_from([1e-3, 1e3, 2.0 ** 10]))
    beta = data.draw(st.sampled_from([1e-3, 1e3, 0.1]))
    assert_same(base, comparable(run_master(build(p, alpha=alpha, beta=beta)), alpha=alpha,
                                 beta=beta), scale, t_inf_tol=T_INF_TOL)


@SETTINGS
@given(systems(zeno=True), st.data())
def test_zeno_accumulations_are_invariant_under_translation_time_shift_and_units(p, data):
    """The same three properties on systems whose impacts accumulate (a ball or a forced block
    dropped onto a wall, t∞ < T_END), one drawn per example (two runs per example instead of
    four; each of (a)–(c) on about a third of the 200 examples): the impacts above V_TAIL, the
    accumulation times t∞ (to T_INF_TOL) and the trajectory outside the tails agree; every
    drawn system comes to rest on a wall (a stick at t∞). (Composed, a translation by 100 and
    a time shift by 1e3: :func:`test_translation_and_time_shift_composed_move_t_inf_by_less_than_1e9`.)"""
    base = comparable(run_master(build(p)))
    assert base[2].size >= 1                                 # a Zeno accumulation ended
    scale = motion_scale(p)
    n = p["M"].shape[0]
    kind = data.draw(st.sampled_from(["translation", "time shift", "units"]))
    rtol = 1e-7
    if kind == "translation":
        c = np.array([data.draw(st.sampled_from([-100.0, -7.5, 3.25, 100.0])) for _ in range(n)])
        moved = comparable(run_master(build(p, c=c)), c=c)
        rtol = 1e-6
    elif kind == "time shift":
        T = data.draw(st.sampled_from([0.1, 1.0, 37.5, 1e3]))
        moved = comparable(run_master(build(p, T=T), t0=T, t_end=T + T_END), T=T)
    else:
        alpha = data.draw(st.sampled_from([1e-3, 1e3, 2.0 ** 10]))
        beta = data.draw(st.sampled_from([1e-3, 1e3, 0.1]))
        moved = comparable(run_master(build(p, alpha=alpha, beta=beta)), alpha=alpha, beta=beta)
    assert_same(base, moved, scale, rtol=rtol, t_inf_tol=T_INF_TOL)


@settings(max_examples=80, deadline=None, derandomize=True, database=None, phases=NO_SHRINK)
@given(systems(), st.integers(-4, 4), st.sampled_from(["window", "event", "grid"]))
def test_t_end_a_few_ulp_from_a_boundary_makes_and_loses_no_event(p, ulps, where):
    sc = build(p)
    full = run_master(sc)
    times = full.events["time"].to_numpy(dtype=float)
    if where == "window":
        t_b = WINDOW / Flow(sc.system).norm_bound
    elif where == "event" and times.size:
        t_b = float(times[len(times) // 2])
    else:
        t_b = T_END / 2
    t_end = t_b
    for _ in range(abs(ulps)):
        t_end = np.nextafter(t_end, np.inf if ulps > 0 else -np.inf)
    if not 0.0 < t_end <= T_END:
        return
    res = run_master(sc, t_end=t_end)
    assert res.status == "ok"
    assert not res.frame.isna().to_numpy().any()
    k = len(res.events)
    # a prefix of the long run's events; an event within a few ulp of t_end may fall on
    # either side, nothing else
    later = times[k:]
    assert k <= times.size and (later.size == 0 or later[0] >= t_end - 1e-12)
    assert (res.events["kind"].to_numpy() == full.events["kind"].to_numpy()[:k]).all()
    np.testing.assert_allclose(res.events["time"].to_numpy(dtype=float), times[:k], rtol=0,
                               atol=1e-12)
    assert (times[:k] <= t_end + 1e-12).all()


@st.composite
def two_contact_zeno(draw) -> dict:
    """Two masses (weak springs, damping, weak harmonic forcing) on two coupled contacts
    (W = I + off-diagonal entries up to 0.2), dropped from 2–10 mm and from a height up to 30 %
    higher (at least 1 % higher): their accumulations overlap — one contact's tail holds
    the other's impacts, or one is re-launched by the other's impacts and accumulates again
    between them — and resolve by joint tails (:mod:`observer.event.tails`)."""
    n = 2
    tidy = lambda x: 0.0 if abs(x) < 1e-6 else x  # noqa: E731  (no subnormal entries)
    fl = lambda lo, hi: st.floats(lo, hi).map(tidy)  # noqa: E731
    M = np.diag([draw(st.floats(0.5, 2.0)) for _ in range(n)])
    K = np.diag([draw(st.one_of(st.just(0.0), st.floats(0.1, 2.0))) for _ in range(n)])
    C = np.diag([draw(st.one_of(st.just(0.0), st.floats(1e-3, 0.5))) for _ in range(n)])
    W = np.eye(n) + np.array([[0.0, draw(fl(-0.2, 0.2))], [draw(fl(-0.2, 0.2)), 0.0]])
    q0 = np.array([draw(fl(-1.0, 1.0)) for _ in range(n)])
    h = draw(st.floats(0.002, 0.01))
    g0 = np.array([h, h * (1.0 + draw(st.floats(0.01, 0.3)))])
    f = -10.0 * np.diag(M) + K @ q0
    return dict(M=M, K=K, C=C, W=W, q0=q0, u0=np.zeros(n), nu=g0 - W.T @ q0, f=f,
                a=0.1 * np.array([draw(fl(-1.0, 1.0)) for _ in range(n)]),
                w=draw(st.floats(0.5, 8.0)), phi=draw(st.floats(0.0, 6.0)),
                e=draw(st.floats(0.3, 0.5)))


def rest_times(res, T: float = 0.0, beta: float = 1.0) -> dict:
    """Per contact, the time it last came to rest (its last ``stick`` row), in the original
    time."""
    ev = res.events
    t = (ev["time"].to_numpy(dtype=float) - T) / beta
    stick = (ev["kind"] == "stick").to_numpy()
    contact = ev["contact"].to_numpy()
    return {int(c): float(t[stick & (contact == c)].max()) for c in set(contact[stick])}


def fast_impacts(res, T: float = 0.0, alpha: float = 1.0, beta: float = 1.0):
    """Contacts and times (original units and time origin) of the impacts with |γ⁻| ≥ V_TAIL."""
    ev = res.events
    fast = (ev["kind"] == "impact").to_numpy() & (
        np.abs(ev["gamma_minus"].to_numpy(dtype=float)) * beta / alpha >= V_TAIL)
    return ev["contact"].to_numpy()[fast], (ev["time"].to_numpy(dtype=float)[fast] - T) / beta


@st.composite
def transformations(draw, n: int = 2) -> tuple:
    """One of (a)–(c), drawn as the one-contact property draws it: ``("translation", c)``,
    ``("time shift", T)`` or ``("units", (α, β))``."""
    kind = draw(st.sampled_from(["translation", "time shift", "units"]))
    if kind == "translation":
        return kind, tuple(draw(st.sampled_from([-100.0, -7.5, 3.25, 100.0])) for _ in range(n))
    if kind == "time shift":
        return kind, draw(st.sampled_from([0.1, 1.0, 37.5, 1e3]))
    return kind, (draw(st.sampled_from([1e-3, 1e3, 2.0 ** 10])),
                  draw(st.sampled_from([1e-3, 1e3, 0.1])))


OPEN_TWO_CONTACT = dict(
    M=np.diag([0.8, 0.8703055993029942]), K=np.diag([0.42553138192489104, 0.0]),
    C=np.zeros((2, 2)), W=np.array([[1.0, 0.0], [0.12052136511845828, 1.0]]),
    q0=np.array([0.1849652912031005, 0.05]), u0=np.zeros(2),
    nu=np.array([-0.18899135945902343, -0.04798]),
    f=np.array([-7.921291464026205, -8.703055993029942]),
    a=np.array([0.0008108378130396705, 0.024932071164894196]), w=0.5, phi=0.05, e=0.3)
"""A Zeno sequence of Zeno sequences (drawn by :func:`two_contact_zeno`): K = diag(0.43, 0),
W10 = 0.12, forced; each impact of contact 0 re-launches the held contact 1, which
accumulates again before contact 0 lands. It was the open class of issue 19: translated by
(−100, 3.25) the rest time of contact 0 moved by 1.4e-5 s (0.0413289 s against 0.0413428 s;
t∞ = 0.04134832465593 s): the joint tail was not taken after an impact that re-launched a
held contact, and contact 0, 9e-11 m above its contact point and landing 4e-6 s later, was
impacted together with contact 1 (within 1000 motion tolerances)."""

OPEN_T_INF = 0.041348324655931
"""Its accumulation time (both contacts), from the 30-digit reference :mod:`mp_exact`
(contacts held below γ⁺ = 1e-12 m/s: the remaining tail is < 1e-13 s; 14 s of CPU)."""

MERGED = dict(
    M=np.diag([1.11784164, 1.9]), K=np.zeros((2, 2)), C=np.diag([1.0 / 3.0, 0.05307361]),
    W=np.array([[1.0, 0.11795411], [0.02, 1.0]]), q0=np.array([0.002, -0.2217662]),
    u0=np.zeros(2), nu=np.array([0.01047235, 0.22964769]), f=np.array([-11.1784164, -19.0]),
    a=np.array([0.03333333, 0.0054514]), w=0.6277395375790147, phi=1.192092896e-07,
    e=0.3089952346924821)
"""Drawn by :func:`two_contact_zeno` (damped, W01 = 0.12): contact 1 lands at
0.0858280369341292 s and contact 0 at 0.0858280917816226 s, 5.5e-8 s (3e-12 m) later, in the
30-digit reference; both were impacted together at the first (contact 0's gap was within
1000 motion tolerances), and t∞ = 0.085837884620036 s moved by 1.6e-6 s."""

MERGED_T_INF = 0.085837884620036
MERGED_LANDINGS = (0.0858280369341292, 0.0858280917816226)


@pytest.mark.parametrize("p, t_inf, c", [(OPEN_TWO_CONTACT, OPEN_T_INF, None),
                                         (OPEN_TWO_CONTACT, OPEN_T_INF, (-100.0, 3.25)),
                                         (MERGED, MERGED_T_INF, None),
                                         (MERGED, MERGED_T_INF, (-100.0, 100.0))])
def test_a_zeno_sequence_of_zeno_sequences_rests_at_the_30_digit_t_inf_in_any_coordinates(p, t_inf, c):
    """Both contacts come to rest at the reference's t∞, to 2e-9 s at c = 0 and translated by
    100 (measured: 1.1e-11 and 1.7e-9 s, 6.9e-11 and 1.2e-9 s), through a joint tail of both."""
    c = None if c is None else np.array(c)
    res = run_master(build(p, c=c))
    assert res.status == "ok"
    rest = rest_times(res)
    assert set(rest) == {0, 1}
    for k in (0, 1):
        assert abs(rest[k] - t_inf) <= 2e-9, (k, rest[k])
    acc = res.events[res.events["kind"] == "accumulation"]
    assert acc["note"].iloc[-2:].str.startswith("joint tail of contacts (0, 1)").all()


@pytest.mark.parametrize("c", [None, (3.25, -7.5)])
def test_two_landings_55_ns_apart_are_two_impacts_at_their_30_digit_times(c):
    """Issue 19: an open contact joins another's impact only within FLOOR_FACTOR round-offs of
    its gap or what the time resolution hides at its speed, not within 1000 motion tolerances
    (3e-12 m here): the two landings of :data:`MERGED` 5.5e-8 s apart are two impacts, each
    at the reference's time to 1e-9 s (the earlier accumulations' extrapolation errors carry
    over; measured 9e-12 s at c = 0, 2.3e-10 s translated)."""
    c = None if c is None else np.array(c)
    ev = run_master(build(MERGED, c=c)).events
    near = ev[(ev["kind"] == "impact") & (ev["time"] > MERGED_LANDINGS[0] - 1e-7)
              & (ev["time"] < MERGED_LANDINGS[1] + 1e-7)]
    assert near["contact"].tolist() == [1, 0]
    np.testing.assert_allclose(near["time"].to_numpy(dtype=float), MERGED_LANDINGS, rtol=0,
                               atol=1e-9)


WEAK_RELAUNCH = dict(
    M=np.diag([1.14224784, 1.65003208]), K=np.diag([1.89650803, 0.0]), C=np.zeros((2, 2)),
    W=np.array([[1.0, 1e-6], [0.0, 1.0]]), q0=np.array([0.42265559, -0.65355856]), u0=np.zeros(2),
    nu=np.array([-0.41435715, 0.66433655]), f=np.array([-10.62090864, -16.50032081]),
    a=np.array([0.08369917, 0.0692178]), w=1.9600522610938835, phi=4.851329750055934,
    e=0.3399979323709485)
"""Drawn by :func:`two_contact_zeno` (fresh-clone CI of 5a0a900, values rounded to 8 digits):
contact 1's impact at t = 0.0888 s re-launches the held contact 0 through the weak coupling
W01 = 1e-6 (lift-off speed ~1e-6 m/s, hops of ~1e-13 m), and both are resolved by one joint
tail. Shifted by T = 1e3 s the joint tail resolves 77 impacts instead of 182 and contact 0
rests 3.4e-7 s earlier (0.0943131066 s against 0.0943134424 s; contact 1 and every earlier
event agree to 2e-13 s); shifted by 37.5 s, 4.3e-9 s; by 0.1 and 1 s, 1e-15 s."""


@pytest.mark.xfail(strict=True, reason=(
    "open (issue 19): a contact re-launched through a weak coupling (W01 = 1e-6) by the other's "
    "impacts makes hops of ~1e-13 m; under a time shift by 1e3 s the joint tail stops resolving "
    "them earlier and its rest time moves by 3.4e-7 s"))
def test_weakly_relaunched_contact_rests_at_the_same_time_under_a_time_shift_by_1000():
    base = rest_times(run_master(build(WEAK_RELAUNCH)))
    T = 1e3
    moved = rest_times(run_master(build(WEAK_RELAUNCH, T=T), t0=T, t_end=T + T_END), T, 1.0)
    assert set(base) == set(moved) == {0, 1}
    for k in (0, 1):
        assert abs(moved[k] - base[k]) <= T_INF_TOL, (k, moved[k], base[k])


@pytest.mark.xfail(strict=True, reason=(
    "open (issue 19): drawn examples still fail, differently from draw to draw: WEAK_RELAUNCH "
    "shifted by 1e3 s (rest time moved 3.4e-7 s); a damped pair translated by (-100, 100) whose "
    "impact at 0.0703 s is resolved singly at c = 0 and inside a joint tail when translated "
    "(rest times agree to 2e-11 s, the fast-impact lists differ)"))
@settings(max_examples=200, deadline=None, derandomize=True, database=None, phases=NO_SHRINK)
@given(two_contact_zeno(), transformations())
@example(p=WEAK_RELAUNCH, tr=("time shift", 1e3))
def test_two_contact_zeno_tails_are_invariant_under_translation_time_shift_and_units(p, tr):
    """Overlapping accumulations of two contacts (:func:`two_contact_zeno`), one transformation
    drawn per example as in the one-contact property: both contacts come to rest, at the same
    times to T_INF_TOL, with the same fast impacts (|γ⁻| ≥ V_TAIL). Open (strict xfail): the
    known failing member :data:`WEAK_RELAUNCH` runs first as an explicit example, so the xfail
    costs one example; once it passes, the 200 drawn ones run (≈ 0.4 s of CPU each, 2 runs:
    one draw of them passed all 200 on the branch that fixed :data:`OPEN_TWO_CONTACT`, the
    next draw, after an edit of this file, failed on :data:`WEAK_RELAUNCH`, a third on a
    translated damped pair). :data:`OPEN_TWO_CONTACT` and :data:`MERGED`, the members this
    property failed on before, pass their own named tests against the 30-digit reference."""
    base = run_master(build(p))
    rest = rest_times(base)
    assert base.status == "ok" and set(rest) == {0, 1}
    kind, arg = tr
    T, alpha, beta, c = 0.0, 1.0, 1.0, None
    if kind == "translation":
        c = np.array(arg)
        moved = run_master(build(p, c=c))
    elif kind == "time shift":
        T = arg
        moved = run_master(build(p, T=T), t0=T, t_end=T + T_END)
    else:
        alpha, beta = arg
        moved = run_master(build(p, alpha=alpha, beta=beta))
    assert moved.status == "ok"
    other = rest_times(moved, T, beta)
    assert set(other) == {0, 1}
    for k in (0, 1):
        assert abs(other[k] - rest[k]) <= T_INF_TOL, (kind, k, other[k], rest[k])
    ca, ta = fast_impacts(base)
    cb, tb = fast_impacts(moved, T, alpha, beta)
    assert ca.tolist() == cb.tolist()
    np.testing.assert_allclose(tb, ta, rtol=0, atol=1e-7 * T_END)


BLOCK = dict(M=np.array([[0.6723989499213578]]), K=np.zeros((1, 1)),
             C=np.array([[0.48399516877239857]]), W=np.eye(1),
             q0=np.array([-0.9705873900692614]), u0=np.array([0.09623900801326886]),
             nu=np.array([0.008909120721964606 + 0.9705873900692614]),
             f=np.array([-10.0 * 0.6723989499213578]), a=np.array([0.09144203592219272]),
             w=1.6157300917437343, phi=5.8357728829377296, e=0.47798711114410414)
"""A damped, forced block dropped 8.9 mm onto a wall (t∞ ≈ 0.1318 s), the worst of 12 random
ones for the composed translation and time shift."""


def _stick_time(res, T: float = 0.0) -> float:
    ev = res.events
    return float(ev.loc[ev["kind"] == "stick", "time"].iloc[0]) - T


@pytest.mark.parametrize("old_rule", [False, True])
def test_translation_and_time_shift_composed_move_t_inf_by_less_than_1e9(old_rule, monkeypatch):
    """Translated by 100 and with the time origin at 1e3, the block's t∞ − T is within 1e-9 of
    the original's (measured 6.5e-10; each alone 7.5e-10 and 2.4e-11). The noisy-tail cut is
    a multiple of ulp of the run's elapsed time max(t − t0, τ); with the old rule, ulp of
    max(|t|, τ), the origin at 1e3 let 2^13 times more of the translated gap's round-off into
    t∞: 6.2e-9 (the check fails it)."""
    import observer.event.master as master
    if old_rule:
        monkeypatch.setattr(master, "tail_noise_limit",
                            lambda t, t0, tau: master.ZENO_TAIL_RTOL * master.time_ulp(t, tau))
    base = _stick_time(run_master(build(BLOCK)))
    T = 1e3
    both = _stick_time(run_master(build(BLOCK, c=np.array([100.0]), T=T), t0=T, t_end=T + T_END), T)
    assert (abs(both - base) <= 1e-9) != old_rule, abs(both - base)
