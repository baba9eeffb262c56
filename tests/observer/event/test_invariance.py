"""Issue 19: the exact integrator's results are a property of the motion, not of the
coordinates. Hypothesis draws random 1–4-contact systems (as many DOF, singular K allowed,
harmonic forcing) and runs each

(a) translated, q → q + c with ν → ν − Wᵀc and f → f + Kc (the same motion);
(b) with the time origin shifted, t → t + T (harmonic phases φ → φ − ωT);
(c) in other units, lengths × α and times × β (M kept: K/β², C/β, f·α/β², ω/β, ν·α, u·α/β);

and compares the event tables (kinds, contacts, times, velocities, impulses of the rows
:func:`comparable` keeps) and the trajectories on the output grid with the original run's;
two contacts whose accumulations interleave: :func:`two_contact_zeno`. A last property
samples t_end at a few ulp from a window boundary or an event time: no event is made or lost.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import Phase, given, settings
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
    K = 0.5 * (K + K.T)                  # exactly symmetric (the scenario requires it; B Bᵀ may round apart)
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
    ``[first impact slower than V_TAIL, t∞]`` (to the end of the run if t∞ lies beyond it:
    one run may still resolve hops at t_end while the other holds the contact).

    Compared: the impacts not slower than V_TAIL, the lift-offs (a force crossing zero, or a
    re-launch by another contact's impact not slower than V_TAIL) and each contact's last
    rest (its last ``stick``: t∞ of its last accumulation, or of a sequence resolved until it
    sticks; to T_INF_TOL). Not compared: what a Zeno tail resolves before it is extrapolated
    or held — its slow impacts, and the holds and slow re-launches of a contact that another
    contact's impacts keep lifting (the event loop lists an accumulation and a stick for each
    of them, a joint tail a stick; how many are resolved depends on the coordinates'
    round-off and on the time resolution)."""
    ev = res.events
    col = lambda name: ev[name].to_numpy(dtype=float)  # noqa: E731  (float also when empty)
    t = (col("time") - T) / beta
    gm = col("gamma_minus") * beta / alpha
    gp = col("gamma_plus") * beta / alpha
    tab = np.column_stack([t, gm, gp, col("impulse") * beta / alpha])
    kinds = ev[KINDS_COMPARED].to_numpy()
    slow = (kinds[:, 0] == "impact") & (np.abs(gm) < V_TAIL)
    relaunch = (kinds[:, 0] == "liftoff") & (np.abs(gp) > 0.0) & (np.abs(gp) < V_TAIL)
    tails, start = [], None
    for k in range(len(t)):
        if slow[k] and start is None:
            start = t[k]
        if kinds[k, 0] == "accumulation" and start is not None:
            tails.append((start, t[k]))
            start = None
    if start is not None:                   # a tail still open at t_end (its t∞ lies beyond)
        tails.append((start, np.inf))
    stick = kinds[:, 0] == "stick"
    keep = ~slow & ~relaunch & ~stick & (kinds[:, 0] != "accumulation")
    resting = sorted(set(kinds[stick, 1].tolist()))
    acc = np.array([[j, t[stick & (kinds[:, 1] == j)].max()] for j in resting]).reshape(-1, 2)
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
    assert sa.ok and sb.ok
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


KINDS = ("translation", "time shift", "units")
"""The three transformations (a)–(c)."""

PER_KIND = settings(SETTINGS, max_examples=67)
"""The two-contact property draws one transformation per example: each kind is its own test
of 67 examples (201 in all, as the 200 of one test drawing the kind; each test well within
the suite's per-test budget, and the three spread over the workers)."""


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
    kind = data.draw(st.sampled_from(KINDS))
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
    assert res.status.ok
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
def transformations(draw, kind: str, n: int = 2) -> tuple:
    """A transformation of kind ``kind``, its parameter drawn as the one-contact property draws
    it: ``("translation", c)``, ``("time shift", T)`` or ``("units", (α, β))``."""
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
(contacts held below γ⁺ = 1e-12 m/s: the remaining tail is < 1e-13 s)."""

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
    assert res.status.ok
    rest = rest_times(res)
    assert set(rest) == {0, 1}
    for k in (0, 1):
        assert abs(rest[k] - t_inf) <= 2e-9, (k, rest[k])
    acc = res.events[res.events["kind"] == "accumulation"]
    assert acc["note"].iloc[-2:].str.startswith("joint tail of contacts (0, 1)").all()


@pytest.mark.parametrize("c", [None, (3.25, -7.5)])
def test_two_landings_55_ns_apart_are_two_impacts_at_their_30_digit_times(c):
    """Issue 19: an open contact joins another's impact only within the certified error of its
    gap (or of the accumulated state error) or what the time resolution hides at its speed,
    not within 1000 motion tolerances (3e-12 m here): the two landings of :data:`MERGED` 5.5e-8 s apart are two impacts, each
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
tail. Shifted by T = 1e3 s the joint tail resolves 77 impacts instead of 182 (its time
resolution is 1e4 times coarser), and contact 0 rested 3.4e-7 s earlier (0.0943131066 s
against 0.0943134424 s): a re-launch below the time resolution held contact 0 again at once,
and its rest time stayed at its last resolved hold. Every impact of contact 1 re-launches it
until both rest: a contact lifted and held again at once rests from there."""


def test_weakly_relaunched_contact_rests_at_the_same_time_under_a_time_shift_by_1000():
    """Both contacts of :data:`WEAK_RELAUNCH` rest at the same time, shifted by 1e3 s or not
    (measured: 1.9e-13 s apart; 3.4e-7 s before the rule)."""
    base = rest_times(run_master(build(WEAK_RELAUNCH)))
    T = 1e3
    moved = rest_times(run_master(build(WEAK_RELAUNCH, T=T), t0=T, t_end=T + T_END), T, 1.0)
    assert set(base) == set(moved) == {0, 1}
    assert abs(base[0] - base[1]) <= 1e-12 and abs(moved[0] - moved[1]) <= 1e-12
    for k in (0, 1):
        assert abs(moved[k] - base[k]) <= T_INF_TOL, (k, moved[k], base[k])


def _pair(M, K, C, W, q0, nu, f, a, w, phi, e) -> dict:
    """A member of :func:`two_contact_zeno` (2 DOF, u0 = 0) from its drawn values."""
    return dict(M=np.diag(M), K=np.diag(K), C=np.diag(C), W=np.array(W), q0=np.array(q0),
                u0=np.zeros(2), nu=np.array(nu), f=np.array(f), a=np.array(a), w=w, phi=phi, e=e)


HELD_PAIR = _pair(M=[1.5461177469773209, 1.0946232513459302],
                  K=[1.3191394593315386, 1.3226569922713385],
                  C=[0.18981061917638706, 0.19038113269455376],
                  W=[[1.0, 0.0], [0.06790583415511037, 1.0]], q0=[0.0, -0.7842233913288017],
                  nu=[0.06306484769851957, 0.7961040674081138],
                  f=[-15.461177469773208, -11.983491065503085],
                  a=[-0.08987162701973617, -0.05794407163037251], w=5.476349113029197,
                  phi=3.8900019717906355e-233, e=0.38054161322110996)
"""Drawn by :func:`two_contact_zeno`: both contacts of the 2-DOF system come to rest together
at 0.10829 s. The flow that holds both has no free DOF: the rows and columns of its
generator for the held velocities cancel to ~1e-17, the balancing scaled them by 1e-77 and
1e-164, the certified bound of the forces' third derivative was 1e116, and the root search
stalled 1.7e-11 s after t∞ (200 000 safe steps of 1e-54 s): the run stopped."""


SUBNORMAL_PHASE = _pair(M=[0.5000000000000001, 1.5], K=[0.0, 0.0], C=[0.0, 0.0],
                        W=[[1.0, -0.16689740300328354], [-0.10806561221950861, 1.0]],
                        q0=[-0.5266993444660549, -0.2463215821090292],
                        nu=[0.503921785644615, 0.16290344107828977], f=[-5.000000000000001, -15.0],
                        a=[0.01679827928990424, 0.05044486879050334], w=0.5,
                        phi=2.225073858507203e-309, e=0.3191947463497382)
"""Drawn by :func:`two_contact_zeno`: a forcing phase of 2.2e-309 gives the sine terms of the
generator subnormal entries (4.9e-324 in the held flow, whose other entries of that row
cancel): balanced by 2.2e-162, the search after both contacts rest stalled."""


TINY_PHASE = _pair(M=[1.7061716986606097, 1.1], K=[1.7098978604619472, 0.0], C=[0.001, 0.0],
                   W=[[1.0, 0.0002], [-0.1984156123669675, 1.0]], q0=[0.0002, 0.0002],
                   nu=[0.009556734041782087, 0.00990711841983954],
                   f=[-17.061375007034005, -11.0], a=[0.0, -0.019841561236696753],
                   w=2.273894586042595, phi=3.2541865008425024e-176, e=0.322836174451987)
"""Drawn by :func:`two_contact_zeno`, run in mm and 0.1 s (α = 1000, β = 0.1): once both
contacts rest, the held velocities' rows keep terms of 1e-189 (the sine terms of a phase of
3e-176; exactly 0, but 8e-14 of their own terms after the float solve): balanced by 3e-95,
the search stalled."""


@pytest.mark.parametrize("p, units", [(HELD_PAIR, (1.0, 1.0)), (SUBNORMAL_PHASE, (1.0, 1.0)),
                                      (TINY_PHASE, (1e3, 0.1))],
                         ids=["cancelled", "subnormal", "tiny-phase"])
def test_a_flow_that_holds_every_dof_is_searched_in_ordinary_steps(p, units):
    """Both contacts held: the run goes on to t_end, resting on both (the balancing ignores
    the held accelerations' entries whose exact value is 0, :func:`observer.event.flow.held_zeros`,
    and subnormal entries, :func:`observer.event.flow.balance`)."""
    from observer.event.flow import flow_for
    sc = build(p, alpha=units[0], beta=units[1])
    held = flow_for(sc.system, (0, 1))
    assert np.all(held.scale >= 2.0 ** -20) and np.all(held.scale <= 2.0 ** 20)
    res = run_master(sc)
    assert res.status.ok and not res.frame.isna().to_numpy().any()
    assert res.frame["t"].iloc[-1] == sc.t_end
    rest = rest_times(res)
    assert set(rest) == {0, 1} and max(rest.values()) < sc.t_end
    last = res.frame.iloc[-1]
    q, u = last[["q0", "q1"]].to_numpy(dtype=float), last[["u0", "u1"]].to_numpy(dtype=float)
    alpha, beta = units                         # 1e-14 m and 1e-14 m/s, in the run's units
    np.testing.assert_allclose(sc.system.W.T @ q + sc.system.gap.constant, 0.0, atol=1e-14 * alpha)
    np.testing.assert_allclose(sc.system.W.T @ u, 0.0, atol=1e-14 * alpha / beta)


LATE_PAIR = _pair(M=[0.7068326092333448, 1.3228038143369], K=[1.3163240201328912, 0.0],
                  C=[0.3320101143938919, 0.19107771296598863],
                  W=[[1.0, 0.19107771296598863], [-0.006683345574146099, 1.0]],
                  q0=[0.0, 0.19107771296598863], nu=[0.008340019177338157, -0.1822542712413328],
                  f=[-7.068326092333448, -13.228038143369002],
                  a=[-0.02188593929099565, 0.07950877736630378], w=2.00001,
                  phi=0.05868698420324982, e=0.5)
"""Drawn by :func:`two_contact_zeno`: contact 0 keeps bouncing, re-launching contact 1, which
accumulates again after each of its impacts, the last time at 0.19992 s, 80 µs before t_end.
Translated by (100, 100) the last cycle is one joint tail that runs past t_end; its events
were not listed, and contact 1's last rest was 0.19462 s."""

SWALLOWED = _pair(M=[1.3500996484075087, 1.1], K=[0.0, 0.0], C=[0.0, 0.0],
                  W=[[1.0, 0.18158659543731942], [-0.0666578921923606, 1.0]], q0=[-0.01, 0.004],
                  nu=[0.014089423813120413, 0.0024994654383741497], f=[-13.500996484075088, -11.0],
                  a=[0.06836695076541326, 0.0], w=3.861470580871234, phi=1.5491721499767115,
                  e=0.3990006536890809)
"""Drawn by :func:`two_contact_zeno`: translated by (−100, 100), the joint tail starts before
contact 1's impact at 0.06726 s (|γ⁻| = 0.05 m/s) and resolves it; it was not listed."""


@pytest.mark.parametrize("p, c", [(LATE_PAIR, (100.0, 100.0)), (SWALLOWED, (-100.0, 100.0))])
def test_a_joint_tail_lists_the_impacts_it_resolves_up_to_the_end_of_the_run(p, c):
    """Where the joint tail starts depends on the coordinates (the gap's round-off); what it
    resolves does not: its impacts, lift-offs and holds are rows (note "exact hop"), also
    when it runs past t_end. The impacts faster than V_TAIL and the rest times agree
    (measured 1.2e-11 and 1.3e-11 s)."""
    c = np.array(c)
    base, moved = run_master(build(p)), run_master(build(p, c=c))
    assert base.status.ok and moved.status.ok
    assert moved.events["note"].str.endswith("exact hop").any()
    for res in (base, moved):                   # one table in time order, tails' rows merged
        assert (np.diff(res.events["time"].to_numpy(dtype=float)) >= 0.0).all()
    ca, ta = fast_impacts(base)
    cb, tb = fast_impacts(moved)
    assert ca.tolist() == cb.tolist()
    np.testing.assert_allclose(tb, ta, rtol=0, atol=1e-9)
    rest_a, rest_b = rest_times(base), rest_times(moved)
    assert set(rest_a) == set(rest_b)
    for k in rest_a:
        assert abs(rest_a[k] - rest_b[k]) <= 1e-9, (k, rest_a[k], rest_b[k])


INTERLEAVED = _pair(M=[0.5, 0.5832297231040848], K=[0.0, 0.0], C=[0.0, 0.0],
                    W=[[1.0, 0.0], [0.007363149116057202, 1.0]], q0=[0.0, 0.007363149116057202],
                    nu=[0.001945784035094706, -0.005343149116057202], f=[-5.0, -5.832297231040848],
                    a=[0.0007363149116057202, 0.029854389869287675], w=0.5,
                    phi=0.7051671172256166, e=0.3)
"""Drawn by :func:`two_contact_zeno`: the two contacts' impacts interleave from 1e-3 m/s down;
the 30-digit reference (:mod:`mp_exact`) rests both at INTERLEAVED_T_INF."""

INTERLEAVED_T_INF = 0.03747446322866563


@pytest.mark.parametrize("c", [None, (-100.0, 3.25)])
def test_interleaved_accumulations_rest_at_the_30_digit_t_inf_translated_by_100(c):
    """Translated by (−100, 3.25), the event loop located each impact to the translated gap's
    round-off over its speed (~1e-13 m / 1e-4 m/s), and the interleaved contacts carried
    those errors into each other's flights: t∞ was 5.8e-9 s late. A cluster of k contacts now
    starts its joint tail once one contact's location error reaches its share 1/k² of the
    stated accuracy (:func:`observer.event.tails.joint_due`): within 1e-9 s of the reference."""
    c = None if c is None else np.array(c)
    rest = rest_times(run_master(build(INTERLEAVED, c=c)))
    assert set(rest) == {0, 1}
    for k in (0, 1):
        assert abs(rest[k] - INTERLEAVED_T_INF) <= 1e-9, (k, rest[k])


def transformed(p: dict, kind: str, arg) -> tuple:
    """The run of ``p`` under one of (a)–(c) and the map back, ``(result, T, α, β)``."""
    if kind == "translation":
        return run_master(build(p, c=np.array(arg))), 0.0, 1.0, 1.0
    if kind == "time shift":
        return run_master(build(p, T=arg), t0=arg, t_end=arg + T_END), arg, 1.0, 1.0
    return run_master(build(p, alpha=arg[0], beta=arg[1])), 0.0, arg[0], arg[1]


PAIR_TOL = 2e-8
"""Rest times of two coupled contacts whose accumulations interleave, in other coordinates:
each landing decides the other's re-launch and amplifies the round-off of the state (a
joint tail continued by the 30-digit reference from the engine's own float64 start state
rested 1.0e-8 s away from the engine's t∞; scans of 1700 drawn pairs on the final code
moved rest times by up to 9.8e-9 s under translations: one pair whose rest times at every
translation agreed within 3.5e-9 s sat 6e-9 to 9.8e-9 s from the untranslated run's)."""

PROBE = 2.0 ** -7
"""Relative change of a transformation's parameter for the conditioning probes."""

PROBE_FACTOR = 4.0
"""An ill-conditioned accumulation is compared to PROBE_FACTOR times its probes' spread."""


def conditioned_tolerance(p: dict, kind: str, arg, moved: dict) -> float:
    """PAIR_TOL, or PROBE_FACTOR times the spread of the rest times ``moved`` under the same
    kind of transformation with its parameter changed by ±PROBE (the same round-off, another
    realisation of it), whichever is larger.

    Interleaved accumulations of two coupled contacts can be ill-conditioned: the 30-digit
    reference (:mod:`mp_exact`) continued from the float64 state at the start of a joint tail
    rests 1.2e-7 s away from its own t∞ for a pair translated by (3.25, 3.25), whose state
    there carried 1.9e-14 m of accumulated round-off (40 ulp of 3.25): each contact's landing
    decides the other's re-launch, and a phase error doubles per cycle. No float64 run is
    closer to t∞ than its round-off allows; a transformation that moves t∞ by more than the
    round-off of its own kind does (a coordinate-dependent decision: a hold at a time
    resolution that depends on |t|, a swallowed impact) is still caught: its probes share it."""
    spread = 0.0
    for f in (1.0 + PROBE, 1.0 - PROBE):
        arg_f = tuple(f * a for a in arg) if isinstance(arg, tuple) else f * arg
        res, T, _, beta = transformed(p, kind, arg_f)
        other = rest_times(res, T, beta)
        if set(other) != set(moved):
            return PAIR_TOL
        spread = max(spread, *(abs(other[k] - moved[k]) for k in moved))
    return max(PAIR_TOL, PROBE_FACTOR * spread)


@PER_KIND
@pytest.mark.parametrize("kind", KINDS)
@given(data=st.data())
def test_two_contact_zeno_tails_are_invariant_under_translation_time_shift_and_units(kind, data):
    """Overlapping accumulations of two contacts (:func:`two_contact_zeno`), one transformation
    per example as in the one-contact property (each kind on 67 examples, :data:`PER_KIND`):
    the same contacts come to rest (in most draws both; :data:`LATE_PAIR`'s contact 0 still
    bounces at T_END), at the same times to PAIR_TOL (or, for a worse-conditioned accumulation,
    to the spread of its :func:`conditioned_tolerance` probes), with the same fast impacts
    (|γ⁻| ≥ V_TAIL). :data:`WEAK_RELAUNCH` and :data:`LATE_PAIR`, members it failed on:
    :func:`test_the_two_contact_members_it_failed_on_stay_invariant`."""
    assert_two_contact_invariant(data.draw(two_contact_zeno(), label="p"),
                                 data.draw(transformations(kind), label="tr"))


@pytest.mark.parametrize("p, tr", [(WEAK_RELAUNCH, ("time shift", 1e3)),
                                   (LATE_PAIR, ("translation", (100.0, 100.0)))],
                         ids=["WEAK_RELAUNCH", "LATE_PAIR"])
def test_the_two_contact_members_it_failed_on_stay_invariant(p, tr):
    """The explicit examples of the two-contact property (they ran first in it)."""
    assert_two_contact_invariant(p, tr)


def assert_two_contact_invariant(p: dict, tr: tuple) -> None:
    """The two-contact property on one system and one transformation."""
    base = run_master(build(p))
    rest = rest_times(base)
    assert base.status.ok and rest
    kind, arg = tr
    moved, T, alpha, beta = transformed(p, kind, arg)
    assert moved.status.ok
    other = rest_times(moved, T, beta)
    assert set(other) == set(rest)
    ca, ta = fast_impacts(base)
    cb, tb = fast_impacts(moved, T, alpha, beta)
    assert ca.tolist() == cb.tolist()
    np.testing.assert_allclose(tb, ta, rtol=0, atol=1e-7 * T_END)
    worst = max(abs(other[k] - rest[k]) for k in rest)
    if worst > PAIR_TOL:
        tol = conditioned_tolerance(p, kind, arg, other)
        assert worst <= tol, (kind, arg, worst, tol, other, rest)


def test_the_conditioning_probes_do_not_excuse_a_coordinate_dependent_rest_time(monkeypatch):
    """The near miss of :func:`conditioned_tolerance`: with the hold rule of before (a contact
    re-launched below the time resolution, which grows with |t|, kept its earlier rest time)
    :data:`WEAK_RELAUNCH` shifted by 1e3 s rests 3.4e-7 s early, and its probes (shifted by
    1e3·(1 ± 2^-7) s) share the error: the tolerance stays far below it."""
    import observer.event.tails as tails
    real = tails._hop_impact

    def old_rule(*args):
        x, held, _ = real(*args)
        return x, held, []                       # no re-launch counted: the old rest time
    monkeypatch.setattr(tails, "_hop_impact", old_rule)
    rest = rest_times(run_master(build(WEAK_RELAUNCH)))
    moved, T, _, beta = transformed(WEAK_RELAUNCH, "time shift", 1e3)
    other = rest_times(moved, T, beta)
    worst = max(abs(other[k] - rest[k]) for k in (0, 1))
    assert worst > 1e-7
    assert conditioned_tolerance(WEAK_RELAUNCH, "time shift", 1e3, other) < worst / 10


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
    the original's. The noisy-tail cut is ``zeno_time_rtol`` of the run's elapsed time t − t0
    (:func:`observer.event.master.zeno_time_budget`); with a budget on |t| instead, the origin
    at 1e3 lets ~8e3 times more of the translated gap's round-off into t∞ (the check fails it)."""
    import observer.event.master as master
    if old_rule:
        monkeypatch.setattr(master, "zeno_time_budget", lambda t, t0, rtol: rtol * abs(t))
    base = _stick_time(run_master(build(BLOCK)))
    T = 1e3
    both = _stick_time(run_master(build(BLOCK, c=np.array([100.0]), T=T), t0=T, t_end=T + T_END), T)
    assert (abs(both - base) <= 1e-9) != old_rule, abs(both - base)
