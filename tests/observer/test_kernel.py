"""The kernel fed by named bundles (issue 21): the same trajectories, bit for bit.

* every built-in scenario, in every compiled loop (lean or scalar, general, projected,
  summary), records exactly the arrays main recorded before the kernel took bundles: the
  sha256 digests in ``tests/data/kernel_fingerprints.json`` were written by
  ``python tests/kernel_fingerprint.py`` on main at d26e40e (positional kernel arguments),
  one per floating-point build it was run on, and are recomputed here on the current kernel;
* every kernel entry point takes at most 12 parameters, and each bundle's fields are the
  ones the loop's constructors fill (by name).
"""

from __future__ import annotations

import inspect
import json
import re

import pytest

from observer import kernel
from observer.loop import compile_time
from observer.scenarios import SCENARIOS

from kernel_fingerprint import PATH, result_digest, variants
import numpy as np
import observer
from observer.observers import Slave
from observer.scenario import Scenario
from oracles import siconos_generated
from cases import nearly_redundant_contacts

STORED = json.loads(PATH.read_text())


@pytest.fixture(scope="module", autouse=True)
def compiled():
    compile_time()


def test_the_table_covers_every_builtin_scenario():
    assert set(STORED) == set(SCENARIOS)
    assert all({"alone", "observers", "summary"} <= set(v) for v in STORED.values())


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_trajectories_are_bitwise_those_of_main(name):
    import observer

    sc = observer.load_scenario(name)
    got = {v: result_digest(observer.simulate(sc, engine="compiled", **kw)) for v, kw in variants(name).items()}
    assert set(got) == set(STORED[name])
    assert {v: d for v, d in got.items() if d not in STORED[name][v]} == {}


@pytest.mark.parametrize("entry", ["advance", "advance_scalar", "summary_start", "project_closed"])
def test_entry_points_take_at_most_12_parameters(entry):
    fn = getattr(kernel, entry)
    fn = getattr(fn, "py_func", fn)              # the compiled ones' Python source
    assert len(inspect.signature(fn).parameters) <= 12


def test_bundles_are_filled_by_name_and_typed_alike():
    """Every field of every bundle is set by its constructor; two runs of different sizes give
    bundles of the same numba types (one specialization per entry point)."""
    import numba
    import numpy as np

    import observer
    import observer.loop as loop

    def bundles(name, S):
        sc = observer.load_scenario(name)
        st = observer.MoreauJean(sc.system, sc.law, sc.h, 10 * sc.h, sc.theta)
        inp = loop.LoopInput(st, np.stack([sc.q0] * S), np.stack([sc.u0] * S), np.array([False] * S), False)
        rec, R = loop._allocate(inp, 1, False)
        sig = loop.signal_tables(st.system)
        return (loop.system_bundle(inp), loop.law_bundle(st), sig, loop.observer_bundle(inp),
                loop.state_bundle(inp), loop.storage_bundle(rec, 1, False, None),
                loop.summary_bundle(inp, False, (1e-3,), R),
                loop.window_bundle(inp, sig, 0, 10, st.time(np.arange(11))))

    a, b = bundles("double_mass", 2), bundles("rocking_chain", 2)
    for x, y in zip(a, b):
        assert type(x) is type(y) and all(f is not None for f in x)
        assert numba.typeof(x) == numba.typeof(y)



# ----------------------------------------------------------------------------------------
# (formerly tests/test_kernel_mutants.py: tests written against the kernel's surviving mutants)
# The compiled kernel (:mod:`observer.kernel`) on small cases: the tests its mutation session
# runs (``nox -s mutants -- kernel``, the kernel as plain Python under ``NUMBA_DISABLE_JIT=1``).
#
# * every specialization of the time loop (scalar, lean, general; dense and banded; with
#   observers, coupling windows, master projection, summary store) against the numpy reference
#   engine (``engine="python"``) on short runs: the same trajectories to round-off, the same
#   closed sets and switching signal, the same kernel statistics;
# * the kernel's linear algebra and LCP helpers against numpy and against complementarity
#   recomputed from their answers;
# * the failure statuses (an LCP the kernel cannot solve goes to the reference solver).
#
# Short horizons keep each test well under a second compiled and a few seconds in plain Python.
# ----------------------------------------------------------------------------------------
def rel(a: np.ndarray, b: np.ndarray) -> float:
    scale = max(np.abs(a).max(), np.abs(b).max(), 1e-300)
    return float(np.abs(a - b).max() / scale)


SHORT = {"bouncing_ball": {"simulation.t_end": 1.5},
         "impact_oscillator": {"simulation.t_end": 3.0},
         "grazing": {"simulation.t_end": 2.0},
         "double_mass": {"simulation.t_end": 1.0, "simulation.h": 1e-3},
         "rocking_chain": {"simulation.t_end": 0.15, "simulation.h": 1e-3}}


def short(name: str, **extra) -> Scenario:
    return observer.load_scenario(name, {**SHORT[name], **extra})


def slaves(sc: Scenario) -> list[Slave]:
    """A jump and a no-jump observer from a perturbed state (different from the master's)."""
    rng = np.random.default_rng(3)
    dq = 0.05 * np.abs(sc.q0).max() * rng.standard_normal(sc.system.n)
    du = 0.1 * rng.standard_normal(sc.system.n)
    jump = sc.system.is_stiffness_definite()        # position jumps need K ≻ 0
    return [Slave("a", jump, sc.q0 + dq, sc.u0 + du), Slave("b", False, sc.q0 - dq, sc.u0 - du)]


def assert_same_run(a, b, tol=1e-13):
    assert a.metadata["engine"] == "python" and b.metadata["engine"] == "compiled"
    assert np.array_equal(a.t, b.t)
    assert np.array_equal(a.active, b.active)
    for x, y in ((a.q, b.q), (a.u, b.u), (a.P, b.P)):
        assert x.shape == y.shape and rel(x, y) <= tol
    assert a.slaves.keys() == b.slaves.keys()
    for k in a.slaves:
        sa, sb = a.slaves[k], b.slaves[k]
        for x, y in ((sa.q, sb.q), (sa.u, sb.u), (sa.P, sb.P)):
            assert rel(x, y) <= tol
        if sa.V is not None:
            assert rel(sa.V, sb.V) <= 1e-11
    if a.slaves:
        assert np.array_equal(a.chi, b.chi)
    ma, mb = a.metadata, b.metadata
    assert ma["min_gap"] == pytest.approx(mb["min_gap"], rel=1e-12, abs=1e-15)
    assert ma["min_gap_t"] == mb["min_gap_t"]
    assert mb["solver_fallbacks"] == 0 and mb["stopped"] is None


@pytest.mark.parametrize("name", list(SHORT))
def test_engines_agree_with_observers(name):
    """General loop: master, a jump and a no-jump observer from other states, coupled over a
    window inside the run (χ switches on and off)."""
    sc = short(name)
    T = sc.t_end
    obs = slaves(sc)
    a, b = (observer.simulate(sc, observers=obs, coupling=(0.2 * T, 0.7 * T), engine=e)
            for e in ("python", "compiled"))
    assert a.active.any() and b.chi.any() and not b.chi.all()
    assert_same_run(a, b, tol=2e-13 if name == "rocking_chain" else 1e-13)
    assert np.abs(b.slaves["a"].q - b.slaves["b"].q).max() > 0


@pytest.mark.parametrize("name", list(SHORT))
def test_engines_agree_master_alone(name):
    """The lean and scalar loops (master alone) against the reference engine."""
    sc = short(name)
    a, b = (observer.simulate(sc, observers=[], engine=e) for e in ("python", "compiled"))
    assert a.active.any()
    assert_same_run(a, b)
    assert b.metadata["max_contact_residual"] <= 1e-12
    assert b.metadata["health"]["max_residual"] <= 1e-12


@pytest.mark.parametrize("name", ["double_mass", "rocking_chain", "impact_oscillator"])
def test_engines_agree_projected_master(name):
    """Master projection (the projection onto the closed contacts after each step)."""
    sc = short(name)
    a, b = (observer.simulate(sc, master_projection=True, observers=slaves(sc), engine=e, coupling=None)
            for e in ("python", "compiled"))
    plain = observer.simulate(sc, observers=[], coupling=None)
    assert np.abs(b.q - plain.q).max() > 1e-9          # the projection acted
    assert_same_run(a, b, tol=2e-13)
    # projected: no closed contact is left penetrating (up to round-off)
    g = b.g[1:]
    assert g[b.active[1:]].min() >= -1e-12


@pytest.mark.parametrize("name", ["rocking_chain", "double_mass"])
def test_engines_agree_poisson(name):
    sc = short(name, **{"impact.law": "poisson"})
    a, b = (observer.simulate(sc, observers=slaves(sc), engine=e, coupling=None)
            for e in ("python", "compiled"))
    assert_same_run(a, b, tol=2e-13)


def test_engines_agree_self_switching():
    sc = short("double_mass")
    a, b = (observer.simulate(sc, observers=slaves(sc), source="self", engine=e, coupling=None)
            for e in ("python", "compiled"))
    assert_same_run(a, b)


def siconos_two_contact(theta: str, t_end: float):
    return siconos_generated(f"two_contact_theta{theta}", t_end, label="two_contact")


@pytest.mark.parametrize("theta", ["0.5", "1.0"])
def test_two_contacts_reproduce_siconos(theta):
    """Several contacts (the LCP by block pivoting): Siconos' q, u, P at every step."""
    sc, ref = siconos_two_contact(theta, 1.0)
    res = observer.simulate(sc, engine="compiled")
    k = res.t.size
    assert res.active.all(axis=1).any()                   # both contacts closed at once
    for key, arr, width in (("q", res.q, sc.system.n), ("u", res.u, sc.system.n), ("P", res.P, sc.system.m)):
        want = ref[[f"{key}{j}" for j in range(width)]].to_numpy()[:k]
        np.testing.assert_allclose(arr, want, rtol=0, atol=1e-10 * max(np.abs(want).max(), 1.0))


def test_summary_store_matches_the_full_run():
    """store="summary": the kernel's streaming metrics equal those of the full trajectories."""
    sc = short("double_mass", **{"simulation.t_end": 2.0})
    obs = slaves(sc)
    full = observer.simulate(sc, observers=obs)
    summ = observer.simulate(sc, observers=obs, store="summary", record_every=5)
    sync = full.synchronization()
    assert len(summ.summary) == 2
    for _, row in summ.summary.iterrows():
        ref = sync[sync.observer == row.observer].iloc[0]
        for rho in (1e-3, 1e-6, 1e-9):
            for key in (f"t_sync_{rho:g}", f"t_settle_{rho:g}"):
                if np.isnan(ref[key]):
                    assert np.isnan(row[key])
                else:
                    assert row[key] == pytest.approx(ref[key], abs=1e-12)
        s = full.slaves[row.observer]
        V = s.V
        assert row.V_on == pytest.approx(V[0], rel=1e-14)
        assert row.V_end == pytest.approx(V[-1], rel=1e-9, abs=1e-300)
        assert row.rises == int(np.sum(np.diff(V) > 0))
        for col, part in (("sum_damping", s.dV_damping), ("sum_impulse", s.dV_impulse),
                          ("sum_projection", s.dV_projection)):
            assert row[col] == pytest.approx(part.sum(), rel=1e-9, abs=1e-12 * V[0])
        np.testing.assert_allclose(summ.slaves[row.observer].V, V[::5], rtol=1e-12, atol=0)
        np.testing.assert_array_equal(summ.slaves[row.observer].q, s.q[::5])
    closings = int(np.sum(full.active[1:, 0] & ~full.active[:-1, 0]))
    assert summ.summary.attrs["master_closings"] == [closings]
    assert summ.metadata["min_gap"] == pytest.approx(full.g[1:].min(), rel=1e-12)


# ---------------------------------------------------------------------------------------
# the kernel's helpers
# ---------------------------------------------------------------------------------------


def spd(rng, m, cond=10.0):
    Q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    return (Q * np.geomspace(1.0, cond, m)) @ Q.T


@pytest.mark.parametrize("m", [1, 2, 3, 5])
def test_cholesky_and_solve(m):
    rng = np.random.default_rng(m)
    G = spd(rng, m)
    Lf = np.zeros((m, m))
    assert kernel._cholesky(G, m, Lf)
    L = np.linalg.cholesky(G)
    np.testing.assert_allclose(np.tril(Lf[:m, :m]), L, rtol=0, atol=1e-13)
    rhs = rng.standard_normal(m)
    out = np.zeros(m)
    kernel._cho_solve(Lf, m, rhs.copy(), out)
    np.testing.assert_allclose(out, np.linalg.solve(G, rhs), rtol=1e-12, atol=1e-13)
    # not positive definite: refused
    B = G.copy()
    B[m - 1, m - 1] = -1.0
    assert not kernel._cholesky(B, m, np.zeros((m, m)))


def lcp_buffers(m):
    return (np.zeros(m), np.zeros(m, dtype=np.bool_), np.zeros(m, dtype=np.bool_), np.zeros((m, m)),
            np.zeros(m), np.zeros(m), np.zeros((m, m)))


@pytest.mark.parametrize("m", [1, 2, 3, 4, 6])
def test_solve_lcp_complementarity(m):
    """Random SPD LCPs: x ≥ 0, w = Gx + b ≥ 0, x·w = 0, recomputed from the returned x."""
    rng = np.random.default_rng(10 + m)
    for _ in range(40):
        G = spd(rng, m, cond=100.0)
        b = rng.standard_normal(m)
        x, basic, infeas, Gs, rhs, sol, Lf = lcp_buffers(m)
        it, status, res = kernel.solve_lcp(G, b, m, x, basic, infeas, Gs, rhs, sol, Lf, 100)
        assert status == 0
        w = G @ x + b
        scale = max(np.abs(b).max(), 1.0)
        assert x.min() >= 0.0 and w.min() >= -1e-12 * scale
        assert np.abs(np.minimum(x, w)).max() <= 1e-12 * scale
        assert res == pytest.approx(kernel.lcp_residual(G, b, x, m), abs=1e-15)
        assert res <= 1e-14


@pytest.mark.parametrize("scale", [1e-10, 1.0, 1e10])
def test_solve_lcp_is_positively_homogeneous_in_b(scale):
    """LCP(G, s·b) is solved by s·x for every s > 0. G = [[2, −1], [−1, 2]], b = s·(−1, 0.2):
    the start basis {i : b_i < 0} = {0} leaves w_1 = −0.3 s < 0, so contact 1 must be flipped
    in at every scale (the flip tolerance is relative, 16·a·eps·(|b_i| + (|G||x|)_i)); the
    solution is x = −G⁻¹b = s·(0.6, 0.2), w = 0 (by hand: G⁻¹ = [[2, 1], [1, 2]]/3)."""
    G = np.array([[2.0, -1.0], [-1.0, 2.0]])
    b = scale * np.array([-1.0, 0.2])
    x, basic, infeas, Gs, rhs, sol, Lf = lcp_buffers(2)
    it, status, res = kernel.solve_lcp(G, b, 2, x, basic, infeas, Gs, rhs, sol, Lf, 100)
    assert status == 0
    np.testing.assert_allclose(x, scale * np.array([0.6, 0.2]), rtol=1e-14, atol=0)


def test_solve_lcp_starts_from_the_contacts_with_negative_b():
    """A start basis {i : b_i < 0} that is already the solution takes one iteration: G =
    [[2, 1], [1, 2]], b = (0, −1) gives x = (0, 0.5), w = (0.5, 0). (A start basis that also
    took b_0 = 0 would give x_0 = −1/3 < 0 and need a second iteration.)"""
    G = np.array([[2.0, 1.0], [1.0, 2.0]])
    b = np.array([0.0, -1.0])
    x, basic, infeas, Gs, rhs, sol, Lf = lcp_buffers(2)
    it, status, res = kernel.solve_lcp(G, b, 2, x, basic, infeas, Gs, rhs, sol, Lf, 100)
    assert (it, status) == (1, 0)
    assert x[0] == 0.0 and x[1] == pytest.approx(0.5, rel=1e-15)


def test_lcp_residual_is_the_relative_natural_residual():
    G = np.array([[2.0, 0.5], [0.5, 1.0]])
    b = np.array([-1.0, 3.0])
    x = np.array([0.6, 0.1])
    w = G @ x + b
    want = np.abs(np.minimum(x, w)).max() / max(np.abs(b).max(), np.abs(G @ x).max())
    assert kernel.lcp_residual(G, b, x, 2) == pytest.approx(want, rel=1e-15)


# ---------------------------------------------------------------------------------------
# failure statuses
# ---------------------------------------------------------------------------------------


def test_lcp_failure_goes_to_the_reference_solver():
    sc = nearly_redundant_contacts(0.4)
    py = observer.simulate(sc, engine="python")
    co = observer.simulate(sc, engine="compiled")
    fb = co.metadata["fallback_steps"]
    assert co.metadata["solver_fallbacks"] == len(fb) > 0
    both = set(np.flatnonzero(py.active[1:].all(axis=1)))
    pushed = set(np.flatnonzero(py.P[1:].sum(axis=1) > 0))
    assert {f["step"] for f in fb} == both & pushed
    np.testing.assert_allclose(co.q, py.q, rtol=0, atol=1e-8)
    np.testing.assert_allclose(co.u, py.u, rtol=0, atol=1e-8)


def test_a_one_contact_step_beyond_the_tolerance_stops_both_engines_at_the_same_step():
    """The scalar loop's failure exit (n = m = 1): the ball of mass 3, e = 0.37, whose
    closed-form impulse at its first impact leaves a round-off residual (≈1e-16) above a
    tolerance of 1e-300. Both engines stop there with ContactSolverError naming that step, the
    first grid step after the free fall's impact time √(2h₀/g) (the compiled one after the
    reference solver of its fallback step failed too)."""
    from observer import load_scenario
    from observer.errors import ContactSolverError
    sc = load_scenario("bouncing_ball", {"param.m": 3.0, "param.restitution": 0.37})
    h = 1e-3
    steps = {}
    for engine in ("compiled", "python"):
        with pytest.raises(ContactSolverError) as err:
            observer.simulate(sc, h=h, t_end=0.5, residual_tol=1e-300, engine=engine)
        steps[engine] = int(re.search(r"at step (\d+)", str(err.value)).group(1))
    assert steps["compiled"] == steps["python"] == int(np.ceil(np.sqrt(2 * 1.0 / 9.81) / h))


# ---------------------------------------------------------------------------------------
# banded structure (the kernel's banded free velocity)
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["rocking_chain", "spring_chain"])
@pytest.mark.parametrize("S", [1, 3])
def test_banded_structure_is_the_dense_one(S, name):
    """The rocking chain (tridiagonal M, C, K) stepped with the banded scheme through
    :func:`observer.loop.run`: the same trajectories as the dense scheme (and the python
    engine) to round-off, with and without observers."""
    from observer import loop

    sc = short("rocking_chain", **{"simulation.t_end": 0.1}) if name == "rocking_chain" else spring_chain()
    q0 = np.stack([sc.q0] + [sc.q0 * (1 + 0.1 * i) for i in range(1, S)])
    u0 = np.stack([sc.u0] + [sc.u0 + 0.05 * i for i in range(1, S)])
    jumps = np.array([False] + [i % 2 == 1 for i in range(1, S)])
    out = {}
    for structure, engine in (("banded", "compiled"), ("dense", "compiled"), ("dense", "python")):
        st = observer.MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, structure=structure)
        assert (st.S.band is not None) == (structure == "banded")
        out[structure, engine] = loop.run(loop.LoopInput(st, q0, u0, jumps, False), engine=engine)
    b = out["banded", "compiled"]
    assert b.active.any()
    for ref in (out["dense", "compiled"], out["dense", "python"]):
        assert np.array_equal(ref.active, b.active)
        for x, y in ((ref.q, b.q), (ref.u, b.u), (ref.P, b.P)):
            assert x.shape == y.shape and rel(x, y) <= 1e-13


# ---------------------------------------------------------------------------------------
# the streaming summary over a coupling window, against the full run's V
# ---------------------------------------------------------------------------------------


def summary_oracle(res, name, k_on, k_off, rhos, h):
    """The summary row of observer ``name`` recomputed in numpy from the full run's V and its
    parts (row kg = step kg−1 → kg; window steps kg−1 ≥ k_on, kg ≤ k_off; samples k_on..k_off)."""
    s = res.slaves[name]
    V = s.V
    win = np.arange(k_on + 1, k_off + 1)
    dV = V[win] - V[win - 1]
    prev = V[win - 1]
    rise_rel = np.where((dV > 0) & (prev > 0), dV / np.where(prev > 0, prev, 1.0), 0.0)
    imp_rel = np.where(prev > 0, s.dV_impulse[win] / np.where(prev > 0, prev, 1.0), 0.0)
    Vw = V[k_on:k_off + 1]
    row = {"V_on": V[k_on], "V_max": Vw.max(), "V_end": V[-1], "rises": int(np.sum(dV > 0)),
           "max_rise_rel": max(rise_rel.max(), 0.0), "max_impulse_rel": max(imp_rel.max(), 0.0),
           "sum_damping": s.dV_damping[win].sum(), "sum_impulse": s.dV_impulse[win].sum(),
           "sum_projection": s.dV_projection[win].sum()}
    for rho in rhos:
        below = Vw <= rho * V[k_on]
        first = np.flatnonzero(below)
        above = np.flatnonzero(~below)
        row[f"t_sync_{rho:g}"] = first[0] * h if first.size else np.inf
        row[f"t_settle_{rho:g}"] = (0.0 if not above.size else np.inf if above[-1] + k_on >= k_off
                                    else (above[-1] + 1) * h)
    return row


@pytest.mark.parametrize("name,window", [("double_mass", (0.3, 0.8)), ("impact_oscillator", (0.5, 2.5)),
                                         ("rocking_chain", (0.03, 0.12)), ("two_contact", (0.1, 0.95))])
def test_summary_over_a_coupling_window(name, window):
    """store="summary" with a coupling window inside the run: every field of the summary row
    (V_on, V_max, V_end, rises, largest rise, the three sums, the largest impulse part, first
    passage and settling per ρ) equals its numpy recomputation from the full run."""
    sc = siconos_two_contact("0.5", 1.0)[0] if name == "two_contact" else short(name)
    obs = slaves(sc)
    full = observer.simulate(sc, observers=obs, coupling=window)
    summ = observer.simulate(sc, observers=obs, coupling=window, store="summary", record_every=1)
    h = sc.h
    checked = 0
    for _, row in summ.summary.iterrows():
        k_on, k_off = round(row.t_on / h), round(row.t_off / h)
        assert (k_on * h, k_off * h) == pytest.approx(window, abs=h)
        want = summary_oracle(full, row.observer, k_on, k_off, (1e-3, 1e-6, 1e-9), h)
        scale = max(abs(want["V_on"]), 1e-300)
        for key, value in want.items():
            if key == "rises":
                assert row[key] == value
            elif np.isinf(value):
                assert np.isinf(row[key]), key
            elif key.startswith("t_"):
                assert row[key] == pytest.approx(value, abs=1e-9), key
            elif key.startswith("max_"):
                assert row[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key
            else:
                assert row[key] == pytest.approx(value, rel=1e-9, abs=1e-12 * scale), key
        checked += 1
        np.testing.assert_allclose(summ.slaves[row.observer].V, full.slaves[row.observer].V, rtol=1e-12,
                                   atol=1e-14 * scale)
    assert checked == 2


def spring_chain(n: int = 8) -> Scenario:
    """n unit-ish masses in a line, neighbours joined by springs and dampers (tridiagonal M,
    C, K: the first subdiagonal is nonzero), two of them above a ground, under gravity."""
    K = 40.0 * (2 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1))
    M = np.diag(1.0 + 0.1 * np.arange(n)) + 0.05 * (np.eye(n, k=1) + np.eye(n, k=-1))
    W = np.zeros((n, 2))
    W[2, 0] = W[n - 3, 1] = 1.0
    q0 = 0.01 * np.arange(n)
    return Scenario.from_dict({
        "system": {"M": M.tolist(), "C": (0.01 * K).tolist(), "K": K.tolist(), "W": W.tolist(),
                   "forcing": {"constant": [-9.81] * n}, "gap": {"offset": [0.0, 0.0]}},
        "impact": {"law": "newton", "restitution": 0.5},
        "initial": {"q": q0.tolist(), "u": [0.0] * n},
        "simulation": {"h": 1e-3, "t_end": 0.3}}, "spring chain")


@pytest.mark.parametrize("name", ["rocking_chain", "spring_chain"])
def test_banded_summary_is_the_dense_one(name):
    """The summary's quadratic forms in band storage (:func:`observer.kernel._quad`): the same
    fields as the dense structure, observers coupled over a window."""
    from observer import loop

    sc = short("rocking_chain", **{"simulation.t_end": 0.08}) if name == "rocking_chain" else spring_chain()
    obs = slaves(sc)
    q0 = np.stack([sc.q0] + [o.q0 for o in obs])
    u0 = np.stack([sc.u0] + [o.u0 for o in obs])
    jumps = np.array([False] + [o.position_jumps for o in obs])
    out = {}
    for structure in ("banded", "dense"):
        st = observer.MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, structure=structure)
        inp = loop.LoopInput(st, q0, u0, jumps, False, coupling=(0.25 * sc.t_end, 0.75 * sc.t_end))
        out[structure] = loop.run(inp, engine="compiled", store="summary", record_every=2)
    b, d = out["banded"], out["dense"]
    fb, fd = b.summary["fields"], d.summary["fields"]
    assert fb.shape == fd.shape and np.abs(fd[1:, :9]).max() > 0
    np.testing.assert_allclose(fb, fd, rtol=1e-11, atol=1e-13 * np.abs(fd[1:, 0]).max())
    np.testing.assert_allclose(b.V, d.V, rtol=1e-11, atol=0)


# ---------------------------------------------------------------------------------------
# the position projection of eqs. (13)-(14)
# ---------------------------------------------------------------------------------------


def csc(W):
    m = W.shape[1]
    Wp, Wi, Wv = [0], [], []
    for j in range(m):
        rows = np.flatnonzero(W[:, j])
        Wi.extend(rows)
        Wv.extend(W[rows, j])
        Wp.append(len(Wi))
    return np.array(Wp, dtype=np.int64), np.array(Wi, dtype=np.int64), np.array(Wv, dtype=float)


@pytest.mark.parametrize("act", [[1], [0, 2], [3, 1, 0]])
def test_project_positions_closes_the_gaps_in_the_K_metric(act):
    """``q1 ← q1 + K⁻¹W_A Σ`` with ``g_A(q1) = 0`` afterwards (the gaps of the closed contacts
    vanish), Σ the solution of ``(W_AᵀK⁻¹W_A)Σ = −g_A``; the open contacts' columns untouched."""
    rng = np.random.default_rng(len(act))
    n, m = 5, 4
    K = spd(rng, n, cond=20.0)
    W = rng.standard_normal((n, m))
    W[rng.random((n, m)) < 0.3] = 0.0
    Wp, Wi, Wv = csc(W)
    KinvW = np.linalg.solve(K, W)
    KinvWT = KinvW.T[None].copy()
    L = (W.T @ KinvW)[None].copy()
    nu = rng.standard_normal((3, m))
    k = 2
    q0 = rng.standard_normal(n)
    q1 = q0.copy()
    a = len(act)
    sig = np.zeros(m)
    status = kernel.project_positions(k, np.array(act + [0] * (m - a), dtype=np.int64), a, 0, Wp, Wi, Wv,
                                      nu, KinvWT, L, q1, sig, np.zeros(m), np.zeros(m), np.zeros((m, m)),
                                      np.zeros((m, m)))
    assert status == kernel.OK
    A = np.array(act)
    np.testing.assert_allclose(W[:, A].T @ q1 + nu[k, A], 0.0, atol=1e-12)
    want = np.linalg.solve(L[0][np.ix_(A, A)], -(W[:, A].T @ q0 + nu[k, A]))
    np.testing.assert_allclose(sig[:a], want, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(q1, q0 + KinvW[:, A] @ want, rtol=1e-12, atol=1e-13)
    if a == 1:                                   # the one-contact helper: the same answer
        q2, sig2 = q0.copy(), np.zeros(1)
        assert kernel.project_one(k, act[0], 0, Wp, Wi, Wv, nu, KinvWT, L, q2, sig2) == kernel.OK
        np.testing.assert_allclose(q2, q1, rtol=1e-14, atol=1e-15)
        assert sig2[0] == pytest.approx(sig[0], rel=1e-14)
    # a metric that is not positive definite on A: refused, q1 untouched beyond this point
    Lbad = L.copy()
    Lbad[0][A[-1], A[-1]] = -1.0 if a == 1 else -abs(Lbad[0][A[-1], A[-1]])
    q3 = q0.copy()
    status = kernel.project_positions(k, np.array(act + [0] * (m - a), dtype=np.int64), a, 0, Wp, Wi, Wv,
                                      nu, KinvWT, Lbad, q3, np.zeros(m), np.zeros(m), np.zeros(m),
                                      np.zeros((m, m)), np.zeros((m, m)))
    assert status == kernel.PROJECTION_FAILED
    np.testing.assert_array_equal(q3, q0)
    if a == 1:                                   # negative or exactly zero: refused
        for bad in (-1.0, 0.0):
            Lbad[0][A[0], A[0]] = bad
            q4, sig4 = q0.copy(), np.full(1, 7.0)
            assert kernel.project_one(k, act[0], 0, Wp, Wi, Wv, nu, KinvWT, Lbad, q4, sig4) \
                == kernel.PROJECTION_FAILED
            np.testing.assert_array_equal(q4, q0)        # like project_positions: q untouched
            assert sig4[0] == 0.0
            q5 = q0.copy()
            assert kernel.project_positions(k, np.array(act + [0] * (m - a), dtype=np.int64), a, 0, Wp, Wi, Wv,
                                            nu, KinvWT, Lbad, q5, np.zeros(m), np.zeros(m), np.zeros(m),
                                            np.zeros((m, m)), np.zeros((m, m))) == kernel.PROJECTION_FAILED
            np.testing.assert_array_equal(q5, q0)
        # a stiffer metric (K → 1000 K): L_jj < 1 is still positive definite, the same gap closed
        q6 = q0.copy()
        assert L[0][A[0], A[0]] / 1e3 < 1.0
        assert kernel.project_positions(k, np.array(act + [0] * (m - a), dtype=np.int64), a, 0, Wp, Wi, Wv,
                                        nu, KinvWT / 1e3, L / 1e3, q6, np.zeros(m), np.zeros(m), np.zeros(m),
                                        np.zeros((m, m)), np.zeros((m, m))) == kernel.OK
        np.testing.assert_allclose(q6, q1, rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("theta", ["1.0"])
def test_two_contacts_projected_master_engines_agree(theta):
    """The projection on two closed contacts at once (a Cholesky solve), both engines."""
    sc, _ = siconos_two_contact(theta, 1.0)
    if not sc.system.is_stiffness_definite():
        pytest.skip("K singular")
    a, b = (observer.simulate(sc, master_projection=True, engine=e) for e in ("python", "compiled"))
    assert b.active.all(axis=1).any()
    assert_same_run(a, b, tol=1e-13)


# ---------------------------------------------------------------------------------------
# the scalar loop (n = m = 1, master alone): signals, several windows, thinned records
# ---------------------------------------------------------------------------------------


def scalar_with_signals(t_end: float) -> Scenario:
    """A damped 1-DOF oscillator with two forcing harmonics and a moving obstacle
    ν(t) = o + Σ aᵢ sin(ωᵢt + φᵢ) (two terms), so f, ν and ν̇ all vary in the kernel."""
    return Scenario.from_dict({
        "system": {"M": [[1.0]], "C": [[0.1]], "K": [[100.0]], "W": [[1.0]],
                   "forcing": {"constant": [-25.0], "amplitude": [7.0], "omega": 2.3, "phase": 0.4,
                               "harmonics": [{"amplitude": [3.0], "omega": 5.1, "phase": -0.2}]},
                   "gap": {"offset": [0.2], "amplitude": [0.05], "omega": 3.0, "phase": 0.2,
                           "harmonics": [{"amplitude": [0.02], "omega": 7.0, "phase": 0.0}]}},
        "impact": {"law": "newton", "restitution": 0.8},
        "initial": {"q": [0.5], "u": [0.0]},
        "simulation": {"h": 1e-3, "t_end": t_end}}, "scalar with signals")


@pytest.mark.parametrize("record_every", [1, 3])
def test_scalar_loop_with_signals_over_several_windows(record_every, monkeypatch):
    """The scalar specialization over more than two windows (:data:`observer.loop.WINDOW`,
    shortened here to 700 steps), every signal varying, every row or every third: the python
    engine's rows."""
    import observer.loop as loop
    monkeypatch.setattr(loop, "WINDOW", 700)
    sc = scalar_with_signals(2 * 700 * 1e-3 + 0.037)
    a, b = (observer.simulate(sc, engine=e, record_every=record_every) for e in ("python", "compiled"))
    full = observer.simulate(sc, engine="compiled")
    assert full.active.sum() >= 4 and full.P.max() > 0            # several impacts
    assert_same_run(a, b, tol=1e-12)
    np.testing.assert_array_equal(b.q, full.q[::record_every])
    np.testing.assert_array_equal(b.t, full.t[::record_every])
    assert full.metadata["min_gap"] == pytest.approx(full.g[1:].min(), rel=1e-12)


@pytest.mark.parametrize("coupling", [None, (0.2, 0.7)])
def test_summary_thresholds_are_the_first_and_last_samples(coupling):
    """The summary's per-threshold fields (first sample with V ≤ ρV(t_on), last with
    V > ρV(t_on)) and V_max, on thresholds that are all crossed (ρ = 1 is met at t_on itself),
    recomputed from the kernel's own V at every step."""
    from observer import loop
    from observer.kernel import F_VMAX, F_VON, SUMMARY_FIELDS

    sc = short("double_mass")
    obs = slaves(sc)
    st = observer.MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta)
    inp = loop.LoopInput(st, np.stack([sc.q0] + [o.q0 for o in obs]), np.stack([sc.u0] + [o.u0 for o in obs]),
                         np.array([False] + [o.position_jumps for o in obs]), False, coupling=coupling)
    rhos = (1.0, 0.9, 0.5, 1e-3)
    out = loop.run(inp, engine="compiled", store="summary", rhos=rhos)
    f, k_on, k_off = out.summary["fields"], out.summary["k_on"], out.summary["k_off"]
    assert (k_on == 0) == (coupling is None)
    nr = len(rhos)
    for s in (1, 2):
        V = np.asarray(out.V[s], dtype=float)
        Vw = V[k_on:k_off + 1]
        assert f[s, F_VON] == V[k_on] and f[s, F_VMAX] == Vw.max()
        for i, rho in enumerate(rhos):
            below = Vw <= rho * V[k_on]
            first = np.flatnonzero(below)
            last = np.flatnonzero(~below)
            assert f[s, SUMMARY_FIELDS + i] == (first[0] + k_on if first.size else -1), (s, rho)
            assert f[s, SUMMARY_FIELDS + nr + i] == (last[-1] + k_on if last.size else -1), (s, rho)
        assert f[s, SUMMARY_FIELDS] == k_on                   # ρ = 1: met at t_on
        assert f[s, SUMMARY_FIELDS + 2] > k_on                # ρ = ½: met later


@pytest.mark.parametrize("observers", [(), ("a",)])
def test_a_ball_resting_on_the_ground_stays_exactly_there(observers):
    """A unit mass at rest on the ground (g = 0, u = 0) under gravity: the predicted gap is
    exactly 0, the contact is closed (``≤ 0``), and each step's impulse h·9.81 cancels gravity
    exactly: q = u = 0 at every step, bit for bit (scalar loop, and general loop with an observer)."""
    sc = Scenario.from_dict({
        "system": {"M": [[1.0]], "C": [[0.0]], "K": [[0.0]], "W": [[1.0]],
                   "forcing": {"constant": [-9.81]}, "gap": {"offset": [0.0]}},
        "impact": {"law": "newton", "restitution": 0.5},
        "initial": {"q": [0.0], "u": [0.0]},
        "simulation": {"h": 1e-3, "t_end": 0.05}}, "resting ball")
    obs = [Slave(name, False, np.array([0.0]), np.array([0.0])) for name in observers]
    py, res = (observer.simulate(sc, observers=obs, engine=e) for e in ("python", "compiled"))
    assert_same_run(py, res)                     # min_gap 0 first reached at the first step
    assert res.metadata["min_gap"] == 0.0 and res.metadata["min_gap_t"] == pytest.approx(1e-3, abs=1e-15)
    # one closed-form contact solve per system and step, no pivoting iterations
    assert res.metadata["contact_solves"] == 50 * (1 + len(observers))
    assert res.metadata["solver_iterations"] == 0
    # every step's applied residual is exactly 0: no step is named the worst
    assert res.metadata["health"]["max_residual"] == 0.0 and res.metadata["health"]["max_residual_t"] is None
    assert np.all(res.q == 0.0) and np.all(res.u == 0.0)
    assert res.active[1:].all()
    np.testing.assert_allclose(res.P[1:], 9.81e-3, rtol=1e-15)
    for s in res.slaves.values():
        assert np.all(s.q == 0.0) and np.all(s.u == 0.0)


@pytest.mark.parametrize("observers", [(), ("a",)])
def test_a_moving_obstacle_closes_the_contact_on_the_midpoint_prediction(observers):
    """A free unit mass at rest, hit by an obstacle ν(t) = sin(10t + 1.6) that sweeps through it
    at speed 10: the contact closes at the first step whose predicted mid-step gap
    ``g_k + ν_k + ½hν̇_k`` (Siconos' predictor) is ≤ 0, recomputed here from ν's formula; the
    python engine agrees row for row (scalar loop, and general loop with an observer)."""
    h, w, phi = 1e-3, 10.0, 1.6
    sc = Scenario.from_dict({
        "system": {"M": [[1.0]], "C": [[0.0]], "K": [[0.0]], "W": [[1.0]],
                   "forcing": {"constant": [0.0]},
                   "gap": {"offset": [0.0], "amplitude": [1.0], "omega": w, "phase": phi}},
        "impact": {"law": "newton", "restitution": 0.5},
        "initial": {"q": [0.0], "u": [0.0]},
        "simulation": {"h": h, "t_end": 0.2}}, "moving obstacle")
    obs = [Slave(name, False, np.array([0.0]), np.array([0.0])) for name in observers]
    a, b = (observer.simulate(sc, observers=obs, engine=e) for e in ("python", "compiled"))
    assert_same_run(a, b)
    t = np.arange(200) * h
    pred = np.sin(w * t + phi) + 0.5 * h * w * np.cos(w * t + phi)     # q = u = 0 before the impact
    k = int(np.flatnonzero(pred <= 0.0)[0])
    assert abs(pred[k]) > 1e-9 and abs(pred[k - 1]) > 1e-9            # not a tie
    first = int(np.flatnonzero(b.active[:, 0])[0])
    assert first == k + 1                                               # row k+1 = step k
    assert b.P[first, 0] > 0 and np.all(b.q[:first] == 0.0)


def awkward_oscillator(t_end: float) -> Scenario:
    """1-DOF, 1 contact, with entries that are not powers of two: the applied residual of an
    impact step is round-off, not exactly 0."""
    return Scenario.from_dict({
        "system": {"M": [[3.3]], "C": [[0.17]], "K": [[7.1]], "W": [[0.73]],
                   "forcing": {"constant": [-9.7], "amplitude": [2.1], "omega": 2.3, "phase": 0.4},
                   "gap": {"offset": [0.31]}},
        "impact": {"law": "newton", "restitution": 0.77},
        "initial": {"q": [0.5], "u": [0.1]},
        "simulation": {"h": 1.1e-3, "t_end": t_end}}, "awkward oscillator")


def test_applied_residual_statistics_are_the_reference_engines():
    """The largest applied residual and its step, the smallest gap and its step: bitwise the
    python engine's, in the scalar loop (master alone) and the general loop (an observer in
    the master's state)."""
    sc = awkward_oscillator(3.0)
    runs = [observer.simulate(sc, engine=e, observers=obs) for e in ("python", "compiled")
            for obs in ([], [Slave("x", False, sc.q0, sc.u0)])]
    ref = runs[0].metadata
    assert ref["health"]["max_residual"] > 0.0 and runs[0].active.any()
    for r in runs[1:]:
        md = r.metadata
        for key in ("min_gap", "min_gap_t", "max_contact_residual"):
            assert md[key] == ref[key], key
        for key in ("max_residual", "max_residual_t"):
            assert md["health"][key] == ref["health"][key], key



@pytest.mark.parametrize("observers", [(), ("a",)])
def test_a_mass_at_rest_on_the_ground_without_force(observers):
    """No force, at rest on the ground: every step's contact problem is ``b = 0`` (zero
    impulse, exactly solved: residual 0, not 0/0); no step goes to the reference solver."""
    sc = Scenario.from_dict({
        "system": {"M": [[1.0]], "C": [[0.0]], "K": [[0.0]], "W": [[1.0]],
                   "forcing": {"constant": [0.0]}, "gap": {"offset": [0.0]}},
        "impact": {"law": "newton", "restitution": 0.5},
        "initial": {"q": [0.0], "u": [0.0]},
        "simulation": {"h": 1e-3, "t_end": 0.01}}, "mass at rest")
    obs = [Slave(name, False, np.array([0.0]), np.array([0.0])) for name in observers]
    res = observer.simulate(sc, observers=obs)
    assert res.metadata["solver_fallbacks"] == 0 and res.metadata["stopped"] is None
    assert res.active[1:].all() and np.all(res.P == 0.0) and np.all(res.q == 0.0)
    assert res.metadata["max_contact_residual"] == 0.0


def _impulse_case(seed, n=4, m=3):
    """Random one-contact impulse arguments (a contact that closes, CSC W with a zero)."""
    rng = np.random.default_rng(seed)
    W = rng.standard_normal((n, m))
    W[0, 1] = 0.0
    Wp, Wi, Wv = csc(W)
    A = spd(rng, n, cond=10.0)
    AinvWT = np.linalg.solve(A, W).T.copy()
    Ghat = W.T @ AinvWT.T
    us = rng.standard_normal((2, n))
    uf = rng.standard_normal(n)
    nu_dot = rng.standard_normal((2, m))
    e = rng.uniform(0.0, 1.0, m)
    return Wp, Wi, Wv, AinvWT, Ghat, us, uf, nu_dot, e


@pytest.mark.parametrize("seed", range(6))
def test_impulse_one_is_the_general_path_bit_for_bit(seed):
    """The one-contact closed form writes the same u_{k+1}, P and statistics, bit for bit, as
    :func:`kernel.contact_impulse` on the closed set {j} (its general path), and returns the
    same status, also when the residual tolerance refuses the step."""
    Wp, Wi, Wv, AinvWT, Ghat, us, uf, nu_dot, e = _impulse_case(seed)
    n, m = uf.shape[0], e.shape[0]
    j = seed % m
    Wj = np.zeros(n)
    Wj[Wi[Wp[j]:Wp[j + 1]]] = Wv[Wp[j]:Wp[j + 1]]
    b = Wj @ uf + nu_dot[1, j] + e[j] * (Wj @ us[1] + nu_dot[0, j])
    if b > 0.0:                                  # b is linear in the velocities: make it close
        us, uf, nu_dot, b = -us, -uf, -nu_dot, -b
    for tol in (1e-9, 0.0 if seed % 2 else -1.0):
        st1, st2 = np.array([3.0, 0, 1e-17, 0, 0, 0, 0, 5e-18]), np.array([3.0, 0, 1e-17, 0, 0, 0, 0, 5e-18])
        u1a, u1b, Pa, Pb = np.full(n, 9.0), np.full(n, 9.0), np.zeros(m), np.zeros(m)
        sa = kernel.impulse_one(0, 1, us, uf, j, Wp, Wi, Wv, nu_dot, AinvWT, Ghat, e, tol, st1, u1a, Pa)
        work = (*[np.zeros(m) for _ in range(8)], np.zeros(m, np.bool_), np.zeros(m, np.bool_), np.zeros(n))
        mats = (np.zeros((m, m)), np.zeros((m, m)), np.zeros((m, m)))
        sb = kernel.contact_impulse(0, 1, us, uf, np.array([j] + [0] * (m - 1)), 1, 0, (Wp, Wi, Wv), nu_dot,
                                    AinvWT, Ghat, e, tol, st2, work, mats, u1b, Pb)
        assert sa == sb
        if sa == kernel.OK:
            assert Pa[0] == pytest.approx(-b / Ghat[j, j], rel=1e-12)      # max(0, −b/Ĝ_jj), b < 0
            np.testing.assert_allclose(u1a, uf + AinvWT[j] * Pa[0], rtol=1e-13, atol=1e-15)
            np.testing.assert_array_equal(u1a, u1b)
            assert Pa[0] == Pb[0]
            np.testing.assert_array_equal(st1[[0, 2, 7]], st2[[0, 2, 7]])
        assert st1[0] == 4.0


def _own_ir(fn, args):
    """The LLVM IR of ``fn``'s own body (not its Python wrappers), compiled afresh (the cached
    build cannot be inspected)."""
    import numba

    fresh = numba.njit(error_model="numpy", nogil=True)(fn.py_func)
    fresh(*args)
    (ir,) = fresh.inspect_llvm().values()
    bodies = {re.search(r"@([\w.$]+)\(", b).group(1): b for b in ir.split("\ndefine ")[1:]}
    own = [b for name, b in bodies.items() if name.startswith("_ZN8observer") and fn.__name__ in name]
    assert len(own) == 1
    return own[0]


def test_the_one_contact_calls_hold_no_reference_counts():
    """:func:`kernel.impulse_one` and :func:`kernel.project_one`, called on every contact step
    of every system, compile without an ``NRT_incref``/``NRT_decref`` (each an atomic
    operation per array per call: 9 pairs per impulse before)."""
    Wp, Wi, Wv, AinvWT, Ghat, us, uf, nu_dot, e = _impulse_case(0)
    n, m = uf.shape[0], e.shape[0]
    imp = _own_ir(kernel.impulse_one, (0, 1, us, uf, 1, Wp, Wi, Wv, nu_dot, AinvWT, Ghat, e, 1e-9,
                                       np.zeros(8), np.zeros(n), np.zeros(m)))
    proj = _own_ir(kernel.project_one, (0, 1, 0, Wp, Wi, Wv, nu_dot, AinvWT[None].copy(), Ghat[None].copy(),
                                        uf.copy(), np.zeros(m)))
    for ir in (imp, proj):
        assert "@NRT_incref" not in ir and "@NRT_decref" not in ir
    assert "fdiv double" in imp                  # the body is the function's (its −b/Ĝ_jj)


@pytest.mark.parametrize("k0,k1", [(0, 0), (5, 5), (127, 128), (0, 16_383), (300, 1_000), (16_384, 32_767),
                                   (1_000_001, 1_000_900)])
def test_compiled_waves_are_grid_wave_bit_for_bit(k0, k1):
    """:func:`observer.loop.wave_table` (anchors by numpy, combined by the compiled
    :func:`kernel.fill_waves`) holds :func:`observer.model.grid_wave`'s values bit for bit, for
    every function, on windows inside one block, across blocks and far from t = 0; and they
    are the waves (to the rounding bound of grid_wave's docstring)."""
    from observer.loop import wave_table
    from observer.model import grid_wave

    rng = np.random.default_rng(k0 + 7 * k1)
    t0, h = float(rng.uniform(-1.0, 1.0)), float(rng.choice([1e-4, 2e-4, 1e-3]))
    omega = np.concatenate([rng.uniform(0.0, 60.0, 5), [0.0]])
    phase = rng.uniform(-3.0, 3.0, 6)
    function = np.array([kernel.WAVE_COS, kernel.WAVE_SIN, kernel.WAVE_MINUS_SIN, kernel.WAVE_SIN,
                         kernel.WAVE_COS, kernel.WAVE_MINUS_SIN])
    tab = wave_table(t0, h, k0, k1, omega, phase, function)
    assert tab.shape == (6, k1 - k0 + 1)
    want = np.stack([grid_wave(t0, h, k0, k1, w, ph, kernel.WAVE_NAMES[f]) for w, ph, f in zip(omega, phase, function)])
    np.testing.assert_array_equal(tab.view(np.int64), want.view(np.int64))
    x = np.multiply.outer(omega, t0 + np.arange(k0, k1 + 1) * h) + phase[:, None]
    direct = np.stack([[np.cos, np.sin, lambda z: -np.sin(z)][f](x[p]) for p, f in enumerate(function)])
    assert np.abs(tab - direct).max() <= 4.0 * (60.0 * (abs(t0) + (k1 + 128) * h) + 4.0) * np.finfo(float).eps
