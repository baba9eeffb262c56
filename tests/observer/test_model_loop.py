"""The compiled engine's one loop with the observers on a model of their own (issue 32, item 2):
each observer's bundle carries its model's matrices, law and signals
(:func:`observer.engines.compiled.bundles.model_bundle`), the master is the plant.

Against the independent reference of ``test_plant_model.py``: the plant alone, its closing log
fed to observers of a nominal scenario written separately (by this test). And the loops of a run
without a model are generated from the same template unchanged by the model's blocks.
"""

from __future__ import annotations

import numpy as np
import pytest

import observer
from observer.engines import compiled as compiled_pkg
from observer.engines.compiled import step
from observer.scenario import load_scenario
from observer.switching import log_from_active

CASES = {
    "double_mass-K+1%": ("double_mass", 0.5, {"K": {"scale": 1.01}},
                         lambda sc: {"system.K": (1.01 * sc.system.K).tolist()}),
    "random_system-KC-gap": ("random_system", 1.0,
                             {"K": {"factors": [[1.02, 0.97, 1.0], [0.97, 1.0, 1.05], [1.0, 1.05, 0.99]]},
                              "C": {"scale": 1.5}, "gap": {"offset": [0.0087, 0.0075]}},
                             lambda sc: {"system.K": (sc.system.K * np.array([[1.02, 0.97, 1.0], [0.97, 1.0, 1.05],
                                                                              [1.0, 1.05, 0.99]])).tolist(),
                                         "system.C": (1.5 * sc.system.C).tolist(),
                                         "system.gap.offset": [0.0087, 0.0075]}),
}


def _captured_run(monkeypatch, sc, model):
    """The RunDescription ``simulate`` hands the compiled engine for a model run."""
    seen = []
    original = compiled_pkg.CompiledEngine.run_with_model

    def spy(self, run):
        seen.append(run)
        return original(self, run)

    monkeypatch.setattr(compiled_pkg.CompiledEngine, "run_with_model", spy)
    observer.simulate(sc, observers="scenario", model=model, engine="compiled")
    return seen[0]


@pytest.mark.parametrize("case", list(CASES))
def test_one_model_loop_equals_the_plant_log_fed_to_separately_built_nominal_observers(case, monkeypatch):
    name, T, model, written = CASES[case]
    sc = load_scenario(name, {"simulation.t_end": T})
    plant = observer.simulate(sc, engine="compiled")
    log = log_from_active(plant.t, plant.active)
    ref = observer.simulate(load_scenario(sc, written(sc)), observers="scenario", source="log", log=log,
                            engine="compiled")
    run = _captured_run(monkeypatch, sc, model)
    out = compiled_pkg.CompiledEngine().model_loop(run)
    np.testing.assert_array_equal(out.q[0], plant.q)             # the master is the plant
    np.testing.assert_array_equal(out.active, plant.active)
    for i, s in enumerate(run.slaves, start=1):
        np.testing.assert_allclose(out.q[i], ref.slaves[s.name].q, rtol=0, atol=1e-13)
        np.testing.assert_allclose(out.u[i], ref.slaves[s.name].u, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out.P[i], ref.slaves[s.name].P, rtol=0, atol=1e-12)
    today = observer.simulate(sc, observers="scenario", engine="compiled")
    assert np.max(np.abs(out.q[1] - today.slaves[run.slaves[0].name].q)) > 1e-6   # the model is seen


def test_the_loops_without_a_model_carry_none_of_its_blocks():
    """The model's per-system binding and second signal tables are only in the model loop."""
    for name in ("_advance_loop", "_advance_scalar_loop", "advance_members"):
        src = step.SOURCES[name]()
        assert "_o" not in {w[-2:] for w in src.replace("(", " ").split()} and "model" not in src.split("\n")[0]
    src = step.model_source()
    assert "Bu, Bq, Bf, Wp, Wi, Wv, AinvWT, Ghat, code, e = Bu_o" in src and "waves_o[" in src
