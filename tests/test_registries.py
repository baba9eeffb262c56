"""Issue 10 acceptance: a toy scenario, a toy observer design and a toy impact law, each
one module (tests/toys/) plus one registry entry, show up everywhere: the CLI's scenario
list, a simulation, the proof checks, the quick suite's rows and the built report."""

from __future__ import annotations

import numpy as np
import pytest

import observer
import proofs_checks as pc
from observer.cli import main
from observer.impact import IMPACT_LAWS
from observer.observers import OBSERVER_DESIGNS
from observer.scenarios import SCENARIOS
from toys import toy_scenario
from toys.toy_design_and_law import TOY_DESIGN, TOY_LAW


@pytest.fixture
def toys(monkeypatch):
    """The three registry entries (undone after the test)."""
    monkeypatch.setitem(SCENARIOS, "toy", toy_scenario)
    monkeypatch.setitem(OBSERVER_DESIGNS, TOY_DESIGN.name, TOY_DESIGN)
    monkeypatch.setitem(IMPACT_LAWS, TOY_LAW.name, TOY_LAW)


def test_toy_scenario_is_listed_by_the_cli(toys, capsys):
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    assert any(line.split()[0] == "toy" and "forced mass-spring" in line for line in out.splitlines())


def test_toys_simulate_and_the_toy_law_is_plastic(toys):
    res = observer.simulate("toy", observers=("jump", "nojump", "toy_jump"))
    assert {"V_jump", "V_nojump", "V_toy_jump"} <= set(res.to_frame().columns)
    sc = observer.load_scenario("toy", {"impact.law": "toy_plastic", "simulation.theta": 1.0})
    plastic = observer.simulate(sc)
    assert plastic.metadata["engine"] == "python" and "toy_plastic" in plastic.metadata["engine_note"]
    # recomputed from the returned states: after every step with an impulse the contact
    # velocity is 0 (e = 0: γ_{k+1} = 0 ⊥ P > 0), whatever the scenario's restitution 0.5
    gamma = plastic.u @ sc.system.W
    hits = np.flatnonzero(plastic.P[1:, 0] > 0) + 1
    assert hits.size > 0
    assert np.max(np.abs(gamma[hits, 0])) <= 1e-12
    newton = observer.simulate(observer.load_scenario("toy", {"simulation.theta": 1.0}))
    hits_n = np.flatnonzero(newton.P[1:, 0] > 0) + 1
    assert hits_n.size > 0
    assert np.max(np.abs((newton.u @ sc.system.W)[hits_n, 0])) > 1e-3    # Newton rebounds


def test_toys_in_the_proof_checks(toys):
    results = {r.name: r for r in pc.run_checks("toy", only="impact_monotone,projection_energy")}
    assert "toy_jump" in results["projection_energy"].witness["designs"]
    law = {r.name: r for r in pc.run_checks("toy", only="impact_monotone",
                                            overrides={"impact.law": "toy_plastic"})}
    assert law["impact_monotone"].passed is True
    assert law["impact_monotone"].witness["law"] == "toy_plastic"     # the toy law was checked


def test_toys_in_the_quick_suite_rows(toys, tmp_path):
    from bench.runners import Context, run_case
    from bench.suites import SUITES

    quick = SUITES["quick"]
    toy_cases = [c for c in quick.cases if c.scenario == "toy"]
    kinds = {c.kind for c in toy_cases}
    assert {"observers", "work_precision", "checks"} <= kinds
    assert any(c.law == "toy_plastic" for c in toy_cases)
    ctx = Context("quick", tmp_path, {"cpu": "test"})
    obs_case = next(c for c in toy_cases if c.kind == "observers")
    rows = run_case(obs_case, ctx)
    assert {r["observer"] for r in rows} >= {"jump", "nojump", "toy_jump"}
    assert all(r["status"] == "ok" for r in rows)
    wp_cases = [c for c in toy_cases if c.kind == "work_precision" and c.law == "toy_plastic"
                and c.solver == "pivoting"]
    wp_rows = [run_case(c, ctx) for c in wp_cases[:2]]
    assert all(r["law"] == "toy_plastic" and np.isfinite(r["err_mean"]) for (r,) in wp_rows)

    # ... and in the report built from those rows
    from bench.results import CaseStore
    from reports.build import build_report

    store = CaseStore(tmp_path / "quick.cases")
    store.write_case("quick", obs_case.case_id, rows)
    for c, r in zip(wp_cases[:2], wp_rows):
        store.write_case("quick", c.case_id, r)
    page = build_report([store.path], tmp_path / "report").read_text()
    assert "forced mass-spring" in page                        # the toy scenario's description
    assert TOY_DESIGN.label in page                            # the toy design's rows
    assert "toy_plastic" in page                               # the toy law's work-precision rows
