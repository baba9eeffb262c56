"""observer.engines: what each engine accepts, the refusals by name, the default choice and its
note, the run record, an impact law's declared engine facts; the toy engine (tests/toys/
toy_engine.py) and the toy law (tests/toys/toy_design_and_law.py) through simulate, the CLI,
the proof checks, a quick suite and the report."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

import observer
from observer.cli import main
from observer.engines import ENGINES, choose, describe
from observer.impact import IMPACT_LAWS, NEWTON
from observer.result import EventTable, LazyFrame, RunState
from toys.toy_design_and_law import TOY_LAW
from toys.toy_engine import TOY_ENGINE

T_END = 0.05


@pytest.fixture
def toys(monkeypatch):
    """The toy engine and the toy law registered (one entry each; undone after the test)."""
    monkeypatch.setitem(ENGINES, TOY_ENGINE.name, TOY_ENGINE)
    monkeypatch.setitem(IMPACT_LAWS, TOY_LAW.name, TOY_LAW)


def plastic(t_end=0.6):
    return observer.load_scenario("bouncing_ball", {"impact.law": "toy_plastic",
                                                    "simulation.t_end": t_end})


def test_registry_integrators_and_default_order():
    assert {n: e.integrator for n, e in ENGINES.items()} == {
        "compiled": "time-stepping", "python": "time-stepping", "event": "event"}
    run = describe(observer.load_scenario("bouncing_ball"), "time-stepping", (), None, "scenario",
                   None, 1e-9, None, "full", None)
    assert choose(run) == (ENGINES["compiled"], None)
    assert "event" in ENGINES["event"].accepts(run)          # integrates by event, not time-stepping


def test_an_explicit_engine_that_cannot_take_the_run_is_refused_by_name():
    with pytest.raises(observer.InputError) as info:
        observer.simulate("bouncing_ball", t_end=T_END, solver="lemke", engine="compiled")
    assert info.value.field == "engine" and "block pivoting" in str(info.value)
    assert "\n" not in str(info.value)
    with pytest.raises(observer.InputError, match="engine: must be one of .*'event'"):
        observer.simulate("bouncing_ball", t_end=T_END, engine="rk45")
    # the default falls back and says why; the same run asked of the python engine has no note
    fell = observer.simulate("bouncing_ball", t_end=T_END, solver="lemke")
    asked = observer.simulate("bouncing_ball", t_end=T_END, solver="lemke", engine="python")
    assert fell.metadata["engine"] == asked.metadata["engine"] == "python"
    assert "block pivoting" in fell.metadata["engine_note"] and "engine_note" not in asked.metadata
    np.testing.assert_array_equal(fell.q, asked.q)


def test_engine_event_selects_the_event_integrator():
    by_engine = observer.simulate("bouncing_ball", t_end=0.5, engine="event")
    by_integrator = observer.simulate("bouncing_ball", t_end=0.5, integrator="event")
    assert by_engine.metadata["integrator"] == "event" == by_integrator.metadata["integrator"]
    np.testing.assert_array_equal(by_engine.q, by_integrator.q)
    with pytest.raises(observer.InputError) as info:
        observer.simulate("bouncing_ball", t_end=0.5, engine="event", record_every=2)
    assert info.value.field == "engine" and "record_every is a time-stepping option" in str(info.value)


def test_the_event_engine_builds_its_result_from_arrays():
    res = observer.simulate("bouncing_ball", t_end=1.0, integrator="event")
    lazy = res.__dict__["_events_frame"]                # not built until read
    assert isinstance(lazy, LazyFrame) and isinstance(lazy.args[0], EventTable)
    table = lazy.args[0]
    assert len(table) >= 1 and set(table.kind) == {"impact"}
    ev = res.events                                     # built now, from those arrays
    np.testing.assert_array_equal(ev["time"].to_numpy(), table.time)
    # each impact's impulse is the jump of the master's momentum at that sample row
    k = np.searchsorted(res.t, ev["time"].to_numpy())
    np.testing.assert_allclose(res.P[k, ev["contact"].to_numpy()], ev["impulse"].to_numpy(), rtol=1e-12)
    assert res.status.state is RunState.OK


def test_the_event_observers_do_not_import_the_facade():
    tree = ast.parse(Path(observer.__file__).with_name("event").joinpath("observers.py").read_text())
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert "observer.simulate" not in names and "observer.engines" not in names


def test_toy_law_runs_on_python_and_event_and_is_refused_by_compiled(toys):
    sc = plastic()
    with pytest.raises(observer.InputError) as info:
        observer.simulate(sc, engine="compiled")
    assert info.value.field == "engine" and "'toy_plastic'" in str(info.value)
    py = observer.simulate(sc)                                     # the default falls back
    assert py.metadata["engine"] == "python" and "toy_plastic" in py.metadata["engine_note"]
    hits = np.flatnonzero(py.P[1:, 0] > 0) + 1
    assert hits.size and np.max(np.abs((py.u @ sc.system.W)[hits, 0])) <= 1e-12   # γ_{k+1} = 0
    ev = observer.simulate(sc, integrator="event").events
    impacts = ev[ev.kind == "impact"]
    assert len(impacts) == 1                      # plastic: the ball lands once and stays
    assert impacts.gamma_minus.iloc[0] < 0 and abs(impacts.gamma_plus.iloc[0]) <= 1e-12


def test_a_law_is_refused_by_the_engine_lacking_it(monkeypatch):
    no_event = dataclasses.replace(TOY_LAW, name="toy_no_event", event_engine=False)
    undeclared = dataclasses.replace(TOY_LAW, name="toy_undeclared", code=NEWTON)
    for law in (no_event, undeclared):
        monkeypatch.setitem(IMPACT_LAWS, law.name, law)
    with pytest.raises(observer.InputError) as info:
        observer.simulate(observer.load_scenario("bouncing_ball", {"impact.law": "toy_no_event"}),
                          t_end=T_END, integrator="event")
    assert info.value.field == "impact.law" and "'toy_no_event'" in str(info.value)
    sc = observer.load_scenario("bouncing_ball", {"impact.law": "toy_undeclared"})
    with pytest.raises(observer.InputError, match="single_contact_is_newton"):
        observer.simulate(sc, t_end=T_END, engine="compiled")
    res = observer.simulate(sc, t_end=T_END)                     # a kernel code alone is not enough
    assert res.metadata["engine"] == "python" and "single_contact_is_newton" in res.metadata["engine_note"]


def test_builtin_laws_declare_the_kernels_assumption():
    for law in IMPACT_LAWS.values():
        if law.code is not None:
            assert law.single_contact_is_newton, law.name
    assert IMPACT_LAWS["newton"].newton_on(3) and IMPACT_LAWS["poisson"].newton_on(1)
    assert not IMPACT_LAWS["poisson"].newton_on(2)


def test_toy_engine_through_simulate_and_the_cli(toys, tmp_path, capsys):
    sc = observer.load_scenario("bouncing_ball", {"simulation.t_end": 0.6})
    toy = observer.simulate(sc, engine="toy")
    ref = observer.simulate(sc, engine="python")
    assert toy.metadata["engine"] == "toy" and toy.status.ok
    assert np.flatnonzero(ref.P[:, 0] > 0).size > 0
    np.testing.assert_allclose(toy.q, ref.q, rtol=0, atol=1e-13)
    np.testing.assert_array_equal(toy.active, ref.active)
    assert observer.simulate(sc).metadata["engine"] == "compiled"     # registered last: not the default
    with pytest.raises(observer.InputError) as info:
        observer.simulate(sc, engine="toy", observers=("jump_identity",))
    assert info.value.field == "engine" and "K metric only" in str(info.value)
    both = dict(observers=("jump", "nojump"), coupling=None, t_end=2.0)
    osc = observer.load_scenario("impact_oscillator")                 # K ≻ 0: the jumps are defined
    toy_obs, py_obs = (observer.simulate(osc, engine=e, **both) for e in ("toy", "python"))
    assert np.any(toy_obs.slaves["jump"].q != toy_obs.slaves["nojump"].q)    # the observers jumped
    for name in both["observers"]:
        np.testing.assert_allclose(toy_obs.slaves[name].q, py_obs.slaves[name].q, rtol=0, atol=1e-13)
        np.testing.assert_allclose(toy_obs.slaves[name].V, py_obs.slaves[name].V, rtol=0, atol=1e-13)
    np.testing.assert_array_equal(toy_obs.chi, py_obs.chi)
    out = tmp_path / "toy.csv"
    assert main(["run", "bouncing_ball", "--t-end", "0.6", "--engine", "toy", "--observers", "none",
                 "--out", str(out)]) == 0
    assert "toy engine" in capsys.readouterr().out
    np.testing.assert_allclose(observer.read_frame(out)["q0"].to_numpy(), ref.q[:, 0], rtol=0, atol=1e-13)
    assert main(["run", "bouncing_ball", "--t-end", "0.6", "--engine", "toy", "--observers", "jump_identity",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "engine: the toy engine cannot take this run" in err


def test_toy_law_through_the_cli_on_the_event_engine(toys, tmp_path, capsys):
    import pandas as pd

    out, events = tmp_path / "ev.csv", tmp_path / "events.csv"
    assert main(["run", "bouncing_ball", "--t-end", "0.6", "--set", "impact.law=toy_plastic",
                 "--integrator", "event", "--observers", "none", "--events", str(events),
                 "--out", str(out)]) == 0
    assert "exact event-driven run" in capsys.readouterr().out
    impacts = pd.read_csv(events).query("kind == 'impact'")
    assert len(impacts) == 1 and abs(impacts.gamma_plus.iloc[0]) <= 1e-12   # plastic: no rebound
    assert main(["run", "bouncing_ball", "--t-end", "0.6", "--set", "impact.law=toy_plastic",
                 "--engine", "compiled", "--out", str(out)]) == 2
    assert "'toy_plastic' has no code in the compiled kernel" in capsys.readouterr().err


def test_a_preferred_toy_engine_takes_the_quick_suites_master_runs_into_the_report(monkeypatch, tmp_path):
    """Registered first, the toy engine is the first that accepts a run of the master alone:
    the quick suite's work-precision cases run on it (no change to bench/), the runs it
    refuses (a summary store) stay on the compiled engine, and the report is built from
    those rows."""
    from bench.results import CaseStore
    from bench.runners import Context, run_case
    from bench.suites import SUITES
    from reports.build import build_report
    from observer.scenarios import SCENARIOS
    from toys import toy_scenario

    monkeypatch.setitem(SCENARIOS, "toy", toy_scenario)
    preferred = {TOY_ENGINE.name: TOY_ENGINE, **ENGINES}
    monkeypatch.setattr("observer.engines.ENGINES", preferred)
    cases = [c for c in SUITES["quick"].cases if c.scenario == "toy"]
    wp = [c for c in cases if c.kind == "work_precision" and c.solver == "pivoting"
          and c.law == "newton"][:2]
    ctx = Context("quick", tmp_path, {"cpu": "test"})
    rows = [run_case(c, ctx)[0] for c in wp]
    assert [r["engine"] for r in rows] == ["toy", "toy"]
    assert all(r["status"] == "ok" for r in rows)
    assert rows[1]["err_mean"] < rows[0]["err_mean"] < 1e-2      # converges as h halves
    assert observer.simulate("toy", t_end=T_END, store="summary").metadata["engine"] == "compiled"
    store = CaseStore(tmp_path / "quick.cases")
    for c, r in zip(wp, rows):
        store.write_case("quick", c.case_id, [r])
    assert set(store.frame()["engine"]) == {"toy"}
    page = build_report([store.path], tmp_path / "report").read_text()
    assert "toy · master · newton · pivoting" in page          # the toy engine's points, tabled


def test_the_python_engine_judges_a_step_by_newtons_residual_only_where_the_law_declares_it(monkeypatch):
    """The same Newton maps without the declared facts: same trajectory, but the step is no
    longer judged by Newton's recomputed residual (the solver's own is counted)."""
    plain = dataclasses.replace(IMPACT_LAWS["newton"], name="newton_plain", code=None, is_newton=False,
                                single_contact_is_newton=False)
    monkeypatch.setitem(IMPACT_LAWS, plain.name, plain)
    declared = observer.simulate("bouncing_ball", t_end=1.0, engine="python")
    undeclared = observer.simulate(observer.load_scenario("bouncing_ball", {"impact.law": "newton_plain"}),
                                   t_end=1.0)
    assert undeclared.metadata["engine"] == "python"
    np.testing.assert_array_equal(declared.q, undeclared.q)
    assert declared.metadata["health"]["residual_source"] == "applied"
    assert undeclared.metadata["health"]["residual_source"] == "applied+solver"


RUN_CHECKS = "switching_generated,projection_closed_form,proposition1_exact,lyapunov_decrease,convergence"


def test_toy_engine_and_toy_law_through_the_proof_checks(toys, monkeypatch):
    """Registered first, the toy engine takes every run of the proof checks (their replays ask
    for the positions before projection, which it records; the observers it projects in K):
    on the toy law the checks give what the python engine gives, where the compiled engine,
    lacking the law, is not chosen."""
    from proofs_checks import run_checks
    from proofs_checks.context import CheckSettings
    from toys.toy_engine import ToyEngine

    # t_end: every run of the checks 150 steps of h = 1e-4, the convergence run too (without it
    # that run takes the scenario's 20 s within the check's memory budget: 2·10⁵ numpy steps
    # of five systems per engine, minutes)
    settings = CheckSettings(seed=0, t_end=0.015, max_steps=150, short_steps=100)
    over = {"impact.law": "toy_plastic"}
    ref = run_checks("double_mass", RUN_CHECKS, overrides=over, settings=settings)
    ran = []
    monkeypatch.setattr(TOY_ENGINE, "run", lambda run: ran.append(len(run.slaves)) or ToyEngine.run(TOY_ENGINE, run))
    monkeypatch.setattr("observer.engines.ENGINES", {TOY_ENGINE.name: TOY_ENGINE, **ENGINES})
    toy = run_checks("double_mass", RUN_CHECKS, overrides=over, settings=settings)
    assert ran[0] == 4 and 1 in ran    # the shared replay (4 observers), Proposition 1's simulate pairs
    assert [r.name for r in toy] == RUN_CHECKS.split(",")
    for a, b in zip(ref, toy):
        assert "exception" not in b.witness, (b.name, b.reason)
        assert a.passed == b.passed, a.name
        np.testing.assert_allclose(b.margin, a.margin, rtol=1e-9, atol=1e-15, err_msg=a.name)
    assert toy[0].passed and toy[-2].passed                # χ generated; V never rises


def test_the_proof_checks_replay_refuses_an_engine_without_pre_projection_positions(toys, monkeypatch):
    """An engine that does not record q_pre is refused by the replay, naming the field, and
    passed over when not named; a metric the toy engine lacks likewise."""
    from proofs_checks.runs import SlaveSpec, replay
    from toys.toy_engine import ToyEngine

    class NoPre(ToyEngine):
        name, extras = "toy_nopre", frozenset({"chi"})

    monkeypatch.setattr("observer.engines.ENGINES", {"toy_nopre": NoPre(), **ENGINES})
    sc = observer.load_scenario("double_mass")
    with pytest.raises(observer.InputError) as info:
        replay(sc, t_end=T_END, engine="toy_nopre")
    assert info.value.field == "engine" and "(q_pre)" in str(info.value) and "\n" not in str(info.value)
    assert replay(sc, t_end=T_END).settings["engine"] == "compiled"
    assert NoPre().accepts(describe(sc, "time-stepping", (), None, "scenario", None, 1e-9, None, "full",
                                    None)) is None          # simulate asks for no extra
    spec = [SlaveSpec("e", True, sc.q0 + 0.01, sc.u0)]
    with pytest.raises(observer.InputError, match="projection metric other than K"):
        replay(sc, t_end=T_END, slaves=spec, metric=np.eye(2), engine="toy")
    refusal = TOY_ENGINE.accepts(dataclasses.replace(
        describe(sc, "time-stepping", (), None, "scenario", None, 1e-9, None, "full", None), metric=np.eye(2)))
    assert refusal.field == "metric"
