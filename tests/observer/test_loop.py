"""Two engines, one answer: the compiled kernel against the numpy reference loop.

* every built-in scenario, with the observers it lists, over its default horizon: the
  trajectories of the master and of every observer agree to 1e-13 relative to the
  trajectory's scale (max |q|, max |u|, max |P|). The two engines sum the same products in
  different orders (BLAS vs. compiled loops), so they agree to round-off, not bitwise; on
  the chaotic rocking chain that round-off grows with the chain's Lyapunov exponent
  (measured 1.1e-13 for the jump observer at 8 s), hence 2e-13 there;
* the Siconos oracles on the compiled engine as on the python one;
* Proposition 1 bitwise on both engines (the matched pairs: plain master + no-jump
  observer, projected master + jump observer);
* ``record_every`` keeps exactly the rows of the full run;
* a step the kernel cannot solve goes to the reference solver, is recorded, and the run
  resumes.
"""

from __future__ import annotations

import time

import numpy as np
import pandas as pd
import pytest

import observer
from observer.loop import ENGINES, compile_time
from observer.observers import Slave
from observer.scenario import Scenario
from observer.scenarios import SCENARIOS

from oracles import oracle, siconos_generated
from cases import nearly_redundant_contacts


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / max(np.abs(a).max(), 1e-300))


@pytest.fixture(scope="module", autouse=True)
def compiled():
    compile_time()


AGREE_STEPS = 20_000
"""Longest horizon (steps) of the engines' agreement run: double_mass (200 000 steps by
default) and the chain (80 000) are cut to their first 2 s, which hold impacts, closed
contacts and coupled observers (asserted below); the numpy engine's full runs would make the
test slow."""


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_engines_agree_on_every_builtin(name):
    sc = observer.load_scenario(name)
    obs = tuple(sc.observer.get("observers", ())) if sc.observer else ()
    t_end = min(sc.t_end, AGREE_STEPS * sc.h)
    a, b = (observer.simulate(sc, t_end=t_end, observers=obs, engine=e) for e in ("python", "compiled"))
    assert a.active.any()                                   # the run holds closed contacts
    tol = 2e-13 if name == "rocking_chain" else 1e-13
    assert a.metadata["engine"] == "python" and b.metadata["engine"] == "compiled"
    assert np.array_equal(a.t, b.t) and np.array_equal(a.active, b.active)
    for x, y in ((a.q, b.q), (a.u, b.u), (a.P, b.P)):
        assert rel(x, y) <= tol
    assert a.slaves.keys() == b.slaves.keys() and len(a.slaves) == len(obs)
    for k in a.slaves:
        assert rel(a.slaves[k].q, b.slaves[k].q) <= tol
        assert rel(a.slaves[k].u, b.slaves[k].u) <= tol
    if obs:
        assert np.array_equal(a.chi, b.chi) and a.chi.any()


def siconos_scenario(name: str) -> tuple[Scenario, pd.DataFrame]:
    """A generated Siconos oracle (``generated/NAME.json``: exact input) as a Scenario."""
    return siconos_generated(name)


@pytest.mark.parametrize("name", ["impact_oscillator_theta1", "two_contact_theta0.5",
                                  "two_contact_theta0.75", "two_contact_theta1.0"])
def test_compiled_engine_reproduces_siconos(name):
    """Both engines reproduce Siconos' q, u and P at every step to 1e-10 (measured ≈ 5e-14)."""
    sc, ref = siconos_scenario(name)
    n, m = sc.system.n, sc.system.m
    for engine in ENGINES:
        res = observer.simulate(sc, engine=engine)
        assert res.t.size == len(ref)
        for key, arr, width in (("q", res.q, n), ("u", res.u, n), ("P", res.P, m)):
            want = ref[[f"{key}{j}" for j in range(width)]].to_numpy()
            np.testing.assert_allclose(arr, want, rtol=0, atol=1e-10 * max(np.abs(want).max(), 1.0))


def test_compiled_engine_reproduces_siconos_bouncing_ball():
    """BouncingBallTS.ref (Siconos 4.4, θ = ½, h = 5e-3, e = 0.9): q, v, p to 1e-12."""
    ref = np.loadtxt(oracle("siconos", "BouncingBallTS.ref"), skiprows=1)
    sc = Scenario.from_dict({
        "system": {"M": [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 0.004]], "C": [[0.0] * 3] * 3,
                   "K": [[0.0] * 3] * 3, "W": [[1.0], [0.0], [0.0]],
                   "forcing": {"constant": [-9.81, 0.0, 0.0]}, "gap": {"offset": [0.0]}},
        "impact": {"law": "newton", "restitution": 0.9},
        "initial": {"q": [1.0, 0.0, 0.0], "u": [0.0, 0.0, 0.0]},
        "simulation": {"h": 0.005, "t_end": 10.0, "theta": 0.5}}, "siconos ball")
    res = observer.simulate(sc, engine="compiled")
    k = min(len(ref), res.t.size)
    np.testing.assert_allclose(res.q[:k, 0], ref[:k, 1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.u[:k, 0], ref[:k, 2], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.P[:k, 0], ref[:k, 3], rtol=0, atol=1e-12)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", ["double_mass", "rocking_chain"])
def test_proposition1_bitwise_on_both_engines(engine, name):
    """Matched pairs are identical to the last bit: plain master + no-jump observer,
    projected master + jump observer (same initial state, same grid)."""
    sc = observer.load_scenario(name, {"simulation.t_end": 1.0 if name == "rocking_chain" else 3.0,
                                       "simulation.h": 1e-3})
    plain = observer.simulate(sc, observers=[Slave("nojump", False, sc.q0, sc.u0)], engine=engine,
                              coupling=None)
    s = plain.slaves["nojump"]
    assert plain.active.any()
    assert np.array_equal(s.q, plain.q) and np.array_equal(s.u, plain.u) and np.array_equal(s.P, plain.P)
    proj = observer.simulate(sc, master_projection=True, observers=[Slave("jump", True, sc.q0, sc.u0)],
                             engine=engine, coupling=None)
    s = proj.slaves["jump"]
    assert np.array_equal(s.q, proj.q) and np.array_equal(s.u, proj.u)
    assert np.abs(proj.q - plain.q).max() > 1e-9          # the projection did act


@pytest.mark.parametrize("engine", ENGINES)
def test_record_every_keeps_the_rows_of_the_full_run(engine):
    sc = observer.load_scenario("double_mass", {"simulation.t_end": 2.0, "simulation.h": 1e-3})
    full = observer.simulate(sc, observers=("jump", "nojump"), engine=engine)
    thin = observer.simulate(sc, observers=("jump", "nojump"), engine=engine, record_every=7)
    rows = np.arange(0, full.t.size, 7)
    assert np.array_equal(thin.t, full.t[rows])
    for x, y in ((thin.q, full.q), (thin.u, full.u), (thin.P, full.P), (thin.active, full.active)):
        assert np.array_equal(x, y[rows])
    for k in full.slaves:
        assert np.array_equal(thin.slaves[k].q, full.slaves[k].q[rows])
        assert np.array_equal(thin.slaves[k].V, full.slaves[k].V[rows])
        assert thin.slaves[k].dV_impulse is None
    assert thin.metadata["record_every"] == 7


def test_kernel_failure_goes_to_the_reference_solver_and_is_recorded():
    sc = nearly_redundant_contacts()
    py = observer.simulate(sc, engine="python")
    co = observer.simulate(sc, engine="compiled")
    fb = co.metadata["fallback_steps"]
    assert co.metadata["solver_fallbacks"] == len(fb) > 0
    assert all(f["system"] == 0 for f in fb)
    both = set(np.flatnonzero(py.active[1:].all(axis=1)))
    pushed = set(np.flatnonzero(py.P[1:].sum(axis=1) > 0))
    assert {f["step"] for f in fb} == both & pushed        # every two-contact step with an impulse
    # the same motion (the reference solver's accuracy, 1e-9 relative residual)
    np.testing.assert_allclose(co.q, py.q, rtol=0, atol=1e-8)
    np.testing.assert_allclose(co.u, py.u, rtol=0, atol=1e-8)


def test_summary_store_streams_the_full_runs_metrics():
    """store="summary": the kernel's streaming metrics over every step equal those computed
    from the full trajectories (first passage, settling, the sums of the ΔV parts, V at the
    kept rows), the master's closings equal the full run's, the deepest penetration is the
    full run's minimum gap."""
    sc = observer.load_scenario("double_mass", {"simulation.t_end": 6.0, "simulation.h": 5e-4})
    full = observer.simulate(sc, observers=("jump", "nojump"))
    summ = observer.simulate(sc, observers=("jump", "nojump"), store="summary", record_every=10)
    sync = full.synchronization()
    for _, row in summ.summary.iterrows():
        ref = sync[sync.observer == row.observer].iloc[0]
        for rho in (1e-3, 1e-6, 1e-9):
            assert row[f"t_sync_{rho:g}"] == pytest.approx(ref[f"t_sync_{rho:g}"], abs=1e-12)
            assert row[f"t_settle_{rho:g}"] == pytest.approx(ref[f"t_settle_{rho:g}"], abs=1e-12)
        s = full.slaves[row.observer]
        V = s.V
        assert row.V_on == pytest.approx(V[0], rel=1e-14) and row.V_end == pytest.approx(V[-1], rel=1e-9, abs=1e-300)
        assert row.rises == int(np.sum(np.diff(V) > 0))
        for col, part in (("sum_damping", s.dV_damping), ("sum_impulse", s.dV_impulse),
                          ("sum_projection", s.dV_projection)):
            assert row[col] == pytest.approx(part.sum(), rel=1e-9, abs=1e-12 * V[0])
        np.testing.assert_allclose(summ.slaves[row.observer].V, V[::10], rtol=1e-12, atol=0)
    closings = int(np.sum(full.active[1:, 0] & ~full.active[:-1, 0]))
    assert summ.summary.attrs["master_closings"] == [closings]
    assert summ.metadata["min_gap"] == pytest.approx(full.g[1:].min(), rel=1e-12)
    assert summ.t.size == full.t[::10].size


def test_summary_store_refuses_the_python_engine():
    with pytest.raises(observer.InputError, match="store"):
        observer.simulate("bouncing_ball", engine="python", store="summary")


def test_compiled_run_never_builds_the_whole_grid(monkeypatch):
    """The compiled engine advances window by window: a run (full or summary) does not touch
    the stepper's whole-grid signals, so memory does not grow with the horizon beyond the
    kept rows (a 1e8-step summary run of impact_oscillator stays under 200 MB)."""
    from observer.stepping import MoreauJean

    def forbidden(self):
        raise AssertionError("the whole grid was built")

    monkeypatch.setattr(MoreauJean, "grid", property(forbidden))
    res = observer.simulate("double_mass", observers=("jump", "nojump"), t_end=1.0, store="summary")
    assert res.metadata["steps"] == 10_000 and res.summary is not None
    res = observer.simulate("rocking_chain", observers=("jump", "nojump"), t_end=0.5)
    assert res.q.shape[0] == 5001


def test_cli_engine_and_store_options(tmp_path, capsys):
    from observer.cli import main
    out = tmp_path / "run.csv"
    assert main(["run", "double_mass", "--t-end", "1", "--observers", "jump,nojump", "--engine",
                 "python", "--out", str(out)]) == 0
    assert "python engine" in capsys.readouterr().out
    assert main(["run", "double_mass", "--t-end", "1", "--observers", "jump,nojump", "--store",
                 "summary", "--record-every", "10", "--out", str(tmp_path / "s.parquet")]) == 0
    text = capsys.readouterr().out
    assert "compiled engine" in text and "t_settle_1e-06" in text and "of the 1000 kept rows" in text
    assert main(["run", "double_mass", "--store", "summary", "--engine", "python",
                 "--out", str(tmp_path / "x.csv")]) == 2
    assert capsys.readouterr().err.strip() == ('error: engine: the python engine cannot take this run: '
                                               'store="summary" needs the compiled engine')


def test_other_solvers_run_on_the_python_engine_and_say_so():
    res = observer.simulate("bouncing_ball", t_end=0.6, solver="lemke")
    assert res.metadata["engine"] == "python" and res.metadata["solver"] == "lemke"
    assert "python engine" in res.metadata["engine_note"]
    ref = observer.simulate("bouncing_ball", t_end=0.6)
    assert ref.metadata["engine"] == "compiled" and "engine_note" not in ref.metadata
    np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_lean_kernels_are_the_general_kernel_bitwise(name, monkeypatch):
    """The kernel's specializations for the master alone (:func:`observer.loop.specialization`:
    the lean loop, and the scalar loop when n = m = 1) prune branches and hold values in
    registers, not change operations: the master's trajectory of a master-only run equals, bit
    for bit, the master's rows of a run of the general loop (here: the same run with an
    observer)."""
    from observer.loop import specialization
    from observer.kernel import STRUCTURE_BANDED, STRUCTURE_DENSE

    import observer.engines.compiled.kernel as kernel

    calls = []                          # the loop each kernel call took
    advance, advance_scalar = kernel.advance, kernel.advance_scalar
    monkeypatch.setattr(kernel, "advance", lambda *a, **kw: calls.append(
        "lean" if kw["general"] is None else "general") or advance(*a, **kw))
    monkeypatch.setattr(kernel, "advance_scalar",
                        lambda *a, **kw: calls.append("scalar") or advance_scalar(*a, **kw))
    sc = observer.load_scenario(name)
    T = min(sc.t_end, 4000 * sc.h)
    alone = observer.simulate(sc, t_end=T, observers=[])
    alone_calls, calls[:] = set(calls), []
    coupled = observer.simulate(sc, t_end=T, observers=["nojump"])
    assert set(calls) == {"general"}
    stepper = observer.MoreauJean(sc.system, sc.law, sc.h, T, sc.theta)
    structure = STRUCTURE_DENSE if stepper.S.band is None else STRUCTURE_BANDED
    n, m = sc.system.n, sc.system.m
    expected = ("general" if stepper.S.band is not None or sc.master_projection
                else "scalar" if n == m == 1 else "lean")
    assert specialization(1, structure, False, False, sc.master_projection, n, m) == expected
    assert alone_calls == {expected}
    assert specialization(2, structure, False, False, sc.master_projection, n, m) == "general"
    assert alone.metadata["engine"] == coupled.metadata["engine"] == "compiled"
    for x, y in ((alone.q, coupled.q), (alone.u, coupled.u), (alone.P, coupled.P),
                 (alone.active, coupled.active)):
        assert np.array_equal(x, y)
    assert alone.active.any()                            # contacts did close in the window


def test_every_specialization_is_exercised():
    """The built-in scenarios' master-only runs take each specialized loop (the test above then
    compares each with the general loop)."""
    from observer.kernel import STRUCTURE_BANDED, STRUCTURE_DENSE
    from observer.loop import SPECIALIZATIONS, specialization

    seen = set()
    for name in SCENARIOS:
        sc = observer.load_scenario(name)
        stepper = observer.MoreauJean(sc.system, sc.law, sc.h, 10 * sc.h, sc.theta)
        structure = STRUCTURE_DENSE if stepper.S.band is None else STRUCTURE_BANDED
        seen.add(specialization(1, structure, False, False, sc.master_projection, sc.system.n, sc.system.m))
    assert seen >= set(SPECIALIZATIONS) - {"general"}


def test_specialization_selection():
    from observer.kernel import STRUCTURE_BANDED, STRUCTURE_DENSE
    from observer.loop import specialization

    assert specialization(1, STRUCTURE_DENSE, False, False, False, 2, 2) == "lean"
    assert specialization(1, STRUCTURE_DENSE, False, False, False, 1, 1) == "scalar"
    for n, m in ((1, 2), (2, 1)):
        assert specialization(1, STRUCTURE_DENSE, False, False, False, n, m) == "lean"
    for args in ((2, STRUCTURE_DENSE, False, False, False), (1, STRUCTURE_BANDED, False, False, False),
                 (1, STRUCTURE_DENSE, True, False, False), (1, STRUCTURE_DENSE, False, True, False),
                 (1, STRUCTURE_DENSE, False, False, True)):
        for n, m in ((1, 1), (2, 2)):
            assert specialization(*args, n, m) == "general"


@pytest.mark.parametrize("name,S", [("impact_oscillator", 1), ("double_mass", 1), ("double_mass", 2)])
def test_loop_times_are_the_grid(name, S):
    """The compiled loop's row times (every step recorded) are ``stepper.time(rows)`` bit for
    bit, over several windows and after a start time, in each specialization (scalar, lean,
    general); the result's ``t`` is the grid."""
    import observer.loop as loop

    sc = observer.load_scenario(name)
    steps = 2 * loop.WINDOW + 5
    st = observer.MoreauJean(sc.system, sc.law, sc.h, 0.5 + steps * sc.h, sc.theta, t0=0.5)
    inp = loop.LoopInput(st, np.stack([sc.q0] * S), np.stack([sc.u0] * S), np.array([False] * S), False)
    out = loop.run(inp, engine="compiled")
    assert out.t is not None and out.t.shape == (steps + 1,)
    assert np.array_equal(out.t, st.time(out.rows))
    assert np.array_equal(out.t, 0.5 + np.arange(steps + 1) * sc.h)
    assert loop.run(inp, engine="compiled", record_every=3).t is None
    res = observer.simulate(sc, t_end=steps * sc.h, observers=[])
    assert np.array_equal(res.t, np.arange(steps + 1) * sc.h)


def test_one_kernel_specialization_with_and_without_summary():
    """The kernel's arguments have one numba type on every path: the summary's quadratic forms
    were the scenario's read-only M and K, the other runs passed writable placeholders, so a
    summary run after a plain one (or the reverse) compiled a second specialization inside a
    timed run (12–17 s, seen in the bench's observer cases)."""
    from observer import kernel
    from observer.observers import OBSERVER_DESIGNS

    sc = observer.load_scenario("double_mass", {"simulation.t_end": 0.01})
    observer.simulate(sc)
    before = {f: len(getattr(kernel, f).signatures) for f in ("_advance_loop", "summary_start")}
    observer.simulate(sc, store="summary")
    observer.simulate(sc, observers=tuple(OBSERVER_DESIGNS), store="summary")
    observer.simulate(sc, observers=tuple(OBSERVER_DESIGNS))
    assert {f: len(getattr(kernel, f).signatures) for f in before} == before


# --- mutation kills (loop)

def test_compile_time_warms_each_specialization_once(monkeypatch):
    """``compile_time`` runs the three kernel specializations (general with the summary and
    pre-projection rows, lean, scalar) once each as warm-up runs over the whole two-step
    horizon, then marks the kernel compiled; a second call runs nothing."""
    import observer.engines.compiled.driver as loop

    monkeypatch.setattr(loop, "_COMPILED", False)
    specs, runs = [], []
    real_spec, real_run = loop.specialization, loop.run_compiled
    monkeypatch.setattr(loop, "specialization", lambda *a: specs.append(real_spec(*a)) or specs[-1])

    def spy(inp, *args, **kw):
        out = real_run(inp, *args, **kw)
        runs.append((inp.q0.shape, kw.get("warm"), out))
        return out

    monkeypatch.setattr(loop, "run_compiled", spy)
    before = time.perf_counter()
    seconds = loop.compile_time()
    assert 0.0 <= seconds <= time.perf_counter() - before      # the seconds it took
    assert specs == ["general", "lean", "scalar"]
    assert [(shape, warm) for shape, warm, _ in runs] == [((2, 2), True), ((1, 2), True), ((1, 1), True)]
    for _, _, out in runs:                      # each ran its whole horizon (t_end / h = 2 steps)
        assert out.q.shape[1] == 3 and np.isfinite(out.q).all() and np.isfinite(out.u).all()
    assert runs[0][2].q_pre is not None and runs[0][2].summary is not None
    assert loop._COMPILED is True
    assert loop.compile_time() >= 0.0 and len(runs) == 3   # compiled: nothing runs again


@pytest.mark.parametrize("record_every", [1, 3])
def test_failed_steps_of_master_and_observer_are_recorded_as_the_reference_engine(record_every):
    """A step the kernel refuses (the nearly redundant contacts: a singular Delassus matrix),
    for the master and for an observer (coupled, started elsewhere), is re-solved by the
    reference solver and written into every record at its row (thinned rows included): the
    compiled run's positions, velocities, generalized impulses W·P (the split of P between
    two parallel contacts is not unique), closed sets, multipliers, observer signal and V are
    the python engine's."""
    sc = nearly_redundant_contacts(0.4)
    obs = [Slave("nojump", False, sc.q0 + np.array([0.05, 0.0]), sc.u0 + np.array([0.3, 0.0]))]
    py = observer.simulate(sc, engine="python", observers=obs, record_every=record_every)
    co = observer.simulate(sc, engine="compiled", observers=obs, record_every=record_every)
    assert {f["system"] for f in co.metadata["fallback_steps"]} == {0, 1}
    W = sc.system.W
    for a, b in ((co, py), (co.slaves["nojump"], py.slaves["nojump"])):
        np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-8)
        np.testing.assert_allclose(a.u, b.u, rtol=0, atol=1e-8)
        np.testing.assert_allclose(a.P @ W.T, b.P @ W.T, rtol=0, atol=1e-8)
        assert np.array_equal(a.sigma, b.sigma)
    assert np.array_equal(co.active, py.active) and np.array_equal(co.chi, py.chi)
    assert co.active.any(axis=0).all()                  # both contacts closed at some row
    np.testing.assert_allclose(co.slaves["nojump"].V, py.slaves["nojump"].V, rtol=0, atol=1e-12)


def test_engines_agree_on_a_log_driven_observer(tmp_path):
    """χ from a log (``source="log"``): a master run's closed set written as a log drives the
    jump observer; both engines sample the log on the grid (the python engine through the
    same window of χ as the compiled one) and record the same χ and the same observer
    trajectory, to round-off, and χ is the master's own closed set of that run; both report
    the applied residual (no step fell back to a solver)."""
    from observer.switching import log_from_active
    sc = observer.load_scenario("double_mass")
    ref = observer.simulate(sc, h=1e-3, t_end=1.0)
    assert ref.active.any()                                   # the log has contact intervals
    path = tmp_path / "log.csv"
    log_from_active(ref.t, ref.active).to_csv(path, index=False)
    runs = {engine: observer.simulate(sc, h=1e-3, t_end=1.0, observers=("jump",), source="log",
                                      log=path, engine=engine) for engine in ENGINES}
    for e in ENGINES:                  # no step fell back to a solver: the applied residual
        assert runs[e].metadata["health"]["residual_source"] == "applied"
    chi = [runs[e].chi for e in ENGINES]
    np.testing.assert_array_equal(chi[0], chi[1])
    np.testing.assert_array_equal(chi[0][1:], ref.active[1:])
    a, b = (runs[e].slaves["jump"] for e in ENGINES)
    for x, y in [(a.q, b.q), (a.u, b.u)]:
        assert np.max(np.abs(x - y)) <= 1e-12 * max(1.0, np.max(np.abs(y)))


def test_positions_before_the_projection_are_the_same_on_both_engines():
    """``record_pre=True`` (the proof checks build their known-bad integrators from it): the
    jump observer of the double mass, started elsewhere, records its positions before the
    projection; both engines record the same rows, which differ from the projected positions
    exactly on the steps with a projection multiplier σ ≠ 0."""
    from observer import loop
    from observer.stepping import MoreauJean
    sc = observer.load_scenario("double_mass")
    st = MoreauJean(sc.system, sc.law, 1e-3, 1.0)
    q0 = np.stack([sc.q0, sc.q0 + 0.05])
    u0 = np.stack([sc.u0, sc.u0 - 0.2])
    out = {engine: loop.run(loop.LoopInput(st, q0, u0, np.array([False, True]), False), engine,
                            record_pre=True) for engine in ENGINES}
    a, b = (out[e] for e in ENGINES)
    assert np.max(np.abs(a.q_pre - b.q_pre)) <= 1e-12 * max(1.0, np.abs(b.q_pre).max())
    moved = np.any(a.q_pre[1] != a.q[1], axis=1)
    projected = np.any(a.sigma[1] != 0.0, axis=1)
    assert projected.any() and np.array_equal(moved, projected)


@pytest.mark.filterwarnings("ignore:mechanical energy grew")     # the broken scheme's, expected
@pytest.mark.parametrize("engine", ENGINES)
def test_a_residual_equal_to_the_tolerance_does_not_stop_the_run(engine):
    """The residual tolerance is inclusive (a step stops the run only if its residual exceeds
    ``residual_tol``): bouncing_ball with Â⁻¹W applied 1.5× (the broken scheme of
    test_health's residual test, residuals ≈ 1/3) run with its own largest residual r as the
    tolerance runs to the end with the same records; with the next double below r it stops
    at a step of residual r, its records the free run's up to that step."""
    import dataclasses

    from observer.loop import LoopInput
    from observer.stepping import MoreauJean

    sc = observer.load_scenario("bouncing_ball", {"simulation.t_end": 1.0})

    def run(tol):
        st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, residual_tol=tol)
        st.S = dataclasses.replace(st.S, AinvW=1.5 * st.S.AinvW)
        st._slices.clear()
        inp = LoopInput(st, sc.q0[None, :], sc.u0[None, :], np.array([False]), False)
        return observer.loop.run(inp, engine=engine)

    free = run(1.0)
    r = free.health.max_residual
    assert free.stopped_at is None and 0.1 < r < 1.0
    at = run(r)
    assert at.stopped_at is None and at.health.max_residual == r
    assert np.array_equal(at.q, free.q) and np.array_equal(at.u, free.u)
    below = run(float(np.nextafter(r, 0.0)))
    k = below.stopped_at
    assert k is not None and "complementarity residual" in below.stop_reason
    assert below.health.max_residual == r and np.array_equal(below.q, free.q[:, :k + 1])   # r stopped it


@pytest.mark.parametrize("engine", ENGINES)
def test_replaying_the_recorded_chi_reproduces_the_run(engine):
    """double_mass with a jump and a no-jump observer: the χ each step used (the master's
    closed set, recorded in ``chi``) given back as an explicit χ array (``LoopInput.chi``,
    row k = step k) runs the same steps: every record equal, on either engine."""
    import dataclasses

    from observer.loop import LoopInput
    from observer.stepping import MoreauJean

    sc = observer.load_scenario("double_mass", {"simulation.t_end": 0.15})
    st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta)
    obs_q, obs_u = np.asarray(sc.observer["q"], float), np.asarray(sc.observer["u"], float)
    inp = LoopInput(st, np.stack([sc.q0, obs_q, obs_q]), np.stack([sc.u0, obs_u, obs_u]),
                    np.array([False, True, False]), False)
    ref = observer.loop.run(inp, engine=engine)
    assert ref.chi[1:].any() and not ref.chi[1:].all()          # contacts open and close
    again = observer.loop.run(dataclasses.replace(inp, chi=ref.chi[1:].copy()), engine=engine)
    for name in ("q", "u", "P", "sigma", "active", "chi"):
        assert np.array_equal(getattr(again, name), getattr(ref, name)), name
