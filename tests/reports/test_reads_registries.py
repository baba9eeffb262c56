"""The report takes names from the toolkit's registries, not from literal lists or from bench:
reports.analysis.micro_loops has one column per engine of observer.ENGINES (a benchmark of any
registered engine is shown), and the default integrator is observer.engines.INTEGRATORS[0],
the one bench.suites.Case defaults to."""

import math

import pandas as pd
import pytest

from observer import ENGINES
from reports.analysis import micro_loops
from reports.registry import default_integrator, is_default_integrator


def _bench(engine: str, median_s: float, steps: int = 100, rounds: int = 5) -> dict:
    return {"kind": "loop", "case": "osc", "scenario": "oscillator", "systems": 1, "steps": steps,
            "n": 1, "m": 1, "engine": engine, "median_s": median_s, "rounds": rounds,
            "compile_time_s": 0.5}


def test_every_registered_engine_has_its_columns():
    out = micro_loops(pd.DataFrame([_bench("compiled", 1e-3)]))
    for engine in ENGINES:
        assert f"{engine}_s" in out.columns and f"rounds_{engine}" in out.columns
    assert "event" in ENGINES                      # the third engine, beside the two time-steppers


def test_times_per_step_and_speedup_by_hand():
    micro = pd.DataFrame([_bench("compiled", 2e-3), _bench("python", 0.5, rounds=3), _bench("event", 4e-2)])
    (r,) = micro_loops(micro).to_dict("records")
    assert r["compiled_s"] == pytest.approx(2e-5) and r["python_s"] == pytest.approx(5e-3)
    assert r["event_s"] == pytest.approx(4e-4)            # a literal ("compiled", "python") loses it
    assert r["speedup"] == pytest.approx(250.0)
    assert r["rounds_python"] == 3


def test_an_engine_without_a_benchmark_is_nan():
    (r,) = micro_loops(pd.DataFrame([_bench("compiled", 2e-3)])).to_dict("records")
    assert math.isnan(r["python_s"]) and math.isnan(r["event_s"]) and math.isnan(r["speedup"])


def test_default_integrator_is_the_suites_default_and_only_it():
    from dataclasses import fields

    from bench.suites import Case

    (field,) = [f for f in fields(Case) if f.name == "integrator"]
    assert default_integrator() == field.default == "time-stepping"
    assert is_default_integrator("time-stepping") and is_default_integrator(None)
    assert is_default_integrator(float("nan")) and is_default_integrator("")
    assert not is_default_integrator("event") and not is_default_integrator("time-steppingx")
