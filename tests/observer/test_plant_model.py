"""An observer model distinct from the plant (issue 33, item 1): ``[observer.model]``.

The independent reference of the issue: the plant simulated alone, its closing log
(:func:`observer.switching.log_from_active`) fed to observers of a nominal scenario built
separately (the plant's document with the model's matrices written in by this test, not by
:mod:`observer.plant_model`), the error V recomputed here from the two trajectories with
numpy. The toolkit's mismatch run must equal it (time-stepping, both designs, a one-contact
and a two-contact system, both engines), and a model equal to the plant must give today's
results bit for bit (every built-in).
"""

from __future__ import annotations

import numpy as np
import pytest

import observer
from observer.errors import InputError
from observer.plant_model import perturbed
from observer.scenario import load_scenario
from observer.scenarios import SCENARIOS
from observer.switching import log_from_active
from observer.tomlio import dumps

CASES = {
    # scenario, horizon, the model table, the same model written into the plant's document
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


def _V(M, K, qs, us, qm, um):
    """½vᵀMv + ½eᵀKe per row, written here (not the toolkit's lyapunov)."""
    v, e = us - um, qs - qm
    return 0.5 * np.einsum("ki,ij,kj->k", v, M, v) + 0.5 * np.einsum("ki,ij,kj->k", e, K, e)


def _reference(sc, nominal_overrides, engine):
    """The plant alone, its log, nominal observers from that log (a separate scenario)."""
    plant = observer.simulate(sc, engine=engine)
    log = log_from_active(plant.t, plant.active)
    nominal = load_scenario(sc, nominal_overrides)
    obs = observer.simulate(nominal, observers="scenario", source="log", log=log, engine=engine)
    return plant, obs


@pytest.mark.parametrize("engine", ["python", "compiled"])
@pytest.mark.parametrize("case", list(CASES))
def test_mismatch_run_equals_the_plant_log_fed_to_separately_built_nominal_observers(case, engine):
    name, T, model, written = CASES[case]
    sc = load_scenario(name, {"simulation.t_end": T})
    plant, ref = _reference(sc, written(sc), engine)
    assert (plant.active[1:] & ~plant.active[:-1]).sum(axis=0).min() >= 2     # every contact closes
    res = observer.simulate(sc, observers="scenario", model=model, engine=engine)
    np.testing.assert_array_equal(res.q, plant.q)                # the master is the plant
    np.testing.assert_array_equal(res.active, plant.active)
    today = observer.simulate(sc, observers="scenario", engine=engine)
    M, K = sc.system.M, sc.system.K
    for d in ("jump", "nojump"):
        mine, theirs = res.slaves[d], ref.slaves[d]
        np.testing.assert_allclose(mine.q, theirs.q, rtol=0, atol=1e-13)
        np.testing.assert_allclose(mine.u, theirs.u, rtol=0, atol=1e-12)
        V = _V(M, K, theirs.q, theirs.u, plant.q, plant.u)
        np.testing.assert_allclose(mine.V, V, rtol=1e-12, atol=1e-300)
        assert abs(mine.V[-1] / today.slaves[d].V[-1] - 1) > 1e-3   # the mismatch is seen (near miss)
    meta = res.metadata["observer_model"]
    assert meta["error_metric"] == "plant" and meta["relative_difference"]["M"] == 0.0
    assert meta["relative_difference"]["K"] > 0.0


def test_error_metric_model_measures_V_in_the_models_M_and_K():
    sc = load_scenario("double_mass", {"simulation.t_end": 0.3})
    model = {"K": {"scale": 1.05}, "M": {"factors": [[1.02, 1.0], [1.0, 0.99]]}, "error_metric": "model"}
    res = observer.simulate(sc, observers=["nojump"], model=model, engine="python")
    K, M = 1.05 * sc.system.K, sc.system.M * np.array([[1.02, 1.0], [1.0, 0.99]])
    s = res.slaves["nojump"]
    np.testing.assert_allclose(s.V, _V(M, K, s.q, s.u, res.q, res.u), rtol=1e-13)
    plant_V = _V(sc.system.M, sc.system.K, s.q, s.u, res.q, res.u)
    assert np.max(np.abs(s.V / plant_V - 1)) > 1e-3                # not the plant's metric
    assert res.metadata["observer_model"]["error_metric"] == "model"


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_a_model_equal_to_the_plant_gives_todays_result_bitwise_on_every_builtin(name):
    sc = load_scenario(name)
    sc = load_scenario(sc, {"simulation.t_end": 300 * sc.h})
    obs = tuple((sc.observer or {}).get("observers", ())) or ("nojump",)
    today = observer.simulate(sc, observers=obs)
    again = observer.simulate(sc, observers=obs, model=None)
    same = observer.simulate(sc, observers=obs, model={"K": {"scale": 1.0}})
    for res in (again, same):
        np.testing.assert_array_equal(res.q, today.q)
        np.testing.assert_array_equal(res.active, today.active)
        for d in obs:
            for key in ("q", "u", "P", "V"):
                np.testing.assert_array_equal(getattr(res.slaves[d], key), getattr(today.slaves[d], key))


def test_a_full_matrix_equal_to_the_plants_is_no_mismatch_on_the_python_engine():
    sc = load_scenario("random_system", {"simulation.t_end": 0.4})
    today = observer.simulate(sc, observers="scenario", engine="python")
    same = observer.simulate(sc, observers="scenario", engine="python",
                             model={"K": sc.system.K.tolist(), "gap": {"offset": sc.system.gap.constant.tolist()}})
    for d in today.slaves:
        np.testing.assert_array_equal(same.slaves[d].q, today.slaves[d].q)
        np.testing.assert_array_equal(same.slaves[d].V, today.slaves[d].V)


def test_ensemble_members_loop_carries_the_model_and_equals_single_runs():
    from observer.engines.compiled.members import member_summaries
    from observer.ensemble import member_slaves, sample_errors

    sc = load_scenario("random_system", {"simulation.t_end": 0.6})
    model = {"K": {"relative_std": 0.02, "seed": 5}, "C": {"scale": 0.5}, "gap": {"offset": [0.009, 0.007]},
             "forcing": {"constant": [0.1, 0.0, -0.1]}}
    df = observer.ensemble(sc, n=3, seed=2, model=model, workers=1)
    X, _ = sample_errors(sc, 3, "energy_sphere", np.random.default_rng(2), None)
    slaves = member_slaves(load_scenario(sc, {"observer.model": model}), ("jump", "nojump"), X, range(3))
    fast = member_summaries(load_scenario(sc, {"observer.model": model}), slaves, None, 1)
    assert fast is not None                                    # the members loop took the run
    res = observer.simulate(sc, observers=slaves, model=model)
    today = observer.ensemble(sc, n=3, seed=2, workers=1)
    for d in ("jump", "nojump"):
        for i in range(3):
            row = df[(df.design == d) & (df.member == i)].iloc[0]
            V = res.slaves[f"{d}#{i}"].V
            assert row.V_end == pytest.approx(V[-1], rel=1e-12)
            assert row.V_max == pytest.approx(V.max(), rel=1e-12)
            other = today[(today.design == d) & (today.member == i)].iloc[0]
            assert abs(row.V_end / other.V_end - 1) > 1e-3
    assert df.attrs["metadata"]["observer_model"]["error_metric"] == "plant"


def test_random_perturbation_is_symmetric_keeps_zeros_and_has_the_stated_size():
    A = np.ones((60, 60))
    A[0, 1] = A[1, 0] = 0.0
    sigma = 0.01
    B = perturbed("K", A, {"relative_std": sigma, "seed": 3})
    np.testing.assert_array_equal(B, B.T)
    assert B[0, 1] == 0.0
    np.testing.assert_array_equal(B, perturbed("K", A, {"relative_std": sigma, "seed": 3}))
    assert not np.array_equal(B, perturbed("K", A, {"relative_std": sigma, "seed": 4}))
    z = (B / np.where(A == 0, 1, A) - 1.0)[np.triu_indices(60)] / sigma
    z = z[np.triu(A)[np.triu_indices(60)] != 0]
    assert abs(z.mean()) < 4 / np.sqrt(z.size)                 # N(0, 1) entries, 1829 of them
    assert abs(z.std() - 1.0) < 0.1
    W = perturbed("W", np.ones((4, 3)), {"relative_std": sigma, "seed": 3})
    assert W.shape == (4, 3) and not np.array_equal(W[:3], W[:3].T)


def test_scale_is_the_whole_matrix_times_the_factor():
    sc = load_scenario("double_mass", {"observer.model": {"K": {"scale": 1.01}, "W": {"scale": 2.0}}})
    np.testing.assert_array_equal(sc.model.system.K, 1.01 * sc.system.K)
    np.testing.assert_array_equal(sc.model.system.W, 2.0 * sc.system.W)
    np.testing.assert_array_equal(sc.model.system.M, sc.system.M)


@pytest.mark.parametrize("K", [{"relative_std": 0.01, "seed": 3}, np.array([[101.0, -100.0], [-100.0, 200.0]])],
                         ids=["random", "array"])
def test_the_model_table_round_trips_through_toml(tmp_path, K):
    sc = load_scenario("double_mass", {"observer.model": {"K": K, "impact": {"restitution": np.float64(0.5)}}})
    path = tmp_path / "case.toml"
    path.write_text(dumps(sc.to_dict()))
    back = load_scenario(str(path))
    np.testing.assert_array_equal(back.model.system.K, sc.model.system.K)
    assert back.model.law.restitution.tolist() == [0.5] and sc.law.restitution.tolist() != [0.5]


def test_the_event_engines_mismatch_run_converges_to_the_time_stepped_one_as_h_shrinks():
    """The event engine's observers on the model, switched at the plant's exact times, against
    the time-stepped mismatch run (itself the plant-log reference above) at h, h/2, h/4: the
    largest observer position difference on the grid falls with a fitted order near 1 (the
    order of Moreau–Jean across impacts), and at the finest h the event run without the model
    is farther from it than the error (a model the event engine ignored would fail)."""
    sc = load_scenario("double_mass", {"simulation.t_end": 0.3})
    model = {"K": {"scale": 1.01}}
    hs, errs = [5e-5, 2.5e-5, 1.25e-5], {"jump": [], "nojump": []}
    for h in hs:
        s = load_scenario(sc, {"simulation.h": h})
        ts = observer.simulate(s, observers="scenario", model=model)
        ev = observer.simulate(s, observers="scenario", integrator="event", model=model)
        assert ev.metadata["observer_model"]["error_metric"] == "plant"
        for d in errs:
            errs[d].append(np.max(np.abs(ts.slaves[d].q - ev.slaves[d].q)))
    exact = observer.simulate(s, observers="scenario", integrator="event")
    np.testing.assert_array_equal(ev.q, exact.q)                 # the master is the plant
    for d, e in errs.items():
        order = np.polyfit(np.log(hs), np.log(e), 1)[0]
        assert e[0] > e[1] > e[2] and 0.7 < order < 2.5, (d, e, order)
        assert np.max(np.abs(ts.slaves[d].q - exact.slaves[d].q)) > 10 * e[-1]
        V = _V(sc.system.M, sc.system.K, ev.slaves[d].q, ev.slaves[d].u, ev.q, ev.u)
        np.testing.assert_allclose(ev.slaves[d].V, V, rtol=1e-12)


def test_the_kernel_summary_refuses_a_model_naming_the_field():
    sc = load_scenario("double_mass", {"simulation.t_end": 0.01})
    with pytest.raises(InputError) as info:
        observer.simulate(sc, observers=["jump"], store="summary", model={"K": {"scale": 1.01}})
    assert info.value.field == "store"


def test_a_log_source_and_sparse_rows_give_the_masters_run_on_the_same_rows():
    """χ from the plant's closing log is χ from the plant (the log samples back exactly), and
    ``record_every`` keeps every k-th row of the full mismatch run."""
    sc = load_scenario("double_mass", {"simulation.t_end": 0.3})
    model = {"K": {"scale": 1.01}, "C": {"scale": 0.9}}
    full = observer.simulate(sc, observers="scenario", model=model, engine="python")
    log = log_from_active(full.t, full.active)
    logged = observer.simulate(sc, observers="scenario", model=model, engine="python", source="log", log=log)
    every = observer.simulate(sc, observers="scenario", model=model, engine="python", record_every=7)
    np.testing.assert_array_equal(every.q, full.q[::7])
    for d in full.slaves:
        np.testing.assert_array_equal(logged.slaves[d].q, full.slaves[d].q)
        np.testing.assert_array_equal(every.slaves[d].q, full.slaves[d].q[::7])
        np.testing.assert_array_equal(every.slaves[d].V, full.slaves[d].V[::7])
        assert full.slaves[d].dV_damping is None                 # no ΔV parts with a model


def test_the_nominal_loops_health_is_recorded_not_warned():
    """With a model, loop 2's master is the nominal model, which the plant's χ does not follow:
    its observer-gap bound (premise: χ is that master's closed set) fires on random_system with
    K × 1.5 and must be recorded in ``metadata["observer_model"]``, not warned as if the log
    had lost a closing; the plant's own health is still warned (none here)."""
    import warnings

    from observer.health import RunHealthWarning

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        res = observer.simulate("random_system", observers=["jump", "nojump"], t_end=5.0,
                                model={"K": {"scale": 1.5}})
    assert not [w for w in seen if issubclass(w.category, RunHealthWarning)]
    recorded = res.metadata["observer_model"]["observers_health"]["warnings"]
    assert len(recorded) == 1 and "while χ = 0" in recorded[0]


# --- the compiled engine's one loop with the observers on their model (issue 32, item 2): each
# observer's bundle carries its model's matrices, law and signals (bundles.model_bundle)
def _captured_run(monkeypatch, sc, model):
    """The RunDescription ``simulate`` hands the compiled engine for a model run."""
    from observer.engines import compiled as compiled_pkg

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
    plant, ref = _reference(sc, written(sc), "compiled")
    from observer.engines import compiled as compiled_pkg

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
    from observer.engines.compiled import step

    for name in ("_advance_loop", "_advance_scalar_loop", "advance_members"):
        src = step.SOURCES[name]()
        assert "_o" not in {w[-2:] for w in src.replace("(", " ").split()} and "model" not in src.split("\n")[0]
    src = step.model_source()
    assert "Bu, Bq, Bf, Wp, Wi, Wv, AinvWT, Ghat, code, e = Bu_o" in src and "waves_o[" in src
