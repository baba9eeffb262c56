"""observer.ensemble: n observers per design against one master, paired initial errors.

Each member is checked against an independent computation: a single :func:`observer.simulate`
of that member's initial state (V recomputed by numpy from its full trajectory), the sampler's
level V0 recomputed from the returned errors, the grid summary of a ``store="full"`` run
against the kernel's streaming one.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import observer
from observer import InputError, OBSERVER_DESIGNS, Slave, load_scenario, simulate
from observer.ensemble import ensemble, sample_errors
from observer.metrics import RHOS, settle_column, sync_column
from observer.sparse import dense

SETTINGS = {"h": 2e-4, "t_end": 3.0}


@pytest.fixture(scope="module")
def members():
    """double_mass, 6 members × {jump, nojump}, in two chunks (threads)."""
    return ensemble("double_mass", n=6, seed=11, workers=2, paths=2, **SETTINGS)


def _errors(df: pd.DataFrame, d: str, n: int) -> np.ndarray:
    rows = df[df.design == d].sort_values("member")
    return rows[[f"dq0_{j}" for j in range(n)] + [f"du0_{j}" for j in range(n)]].to_numpy()


def test_exported():
    assert observer.ensemble is ensemble


@pytest.mark.parametrize("member", [0, 3, 5])
def test_member_equals_a_single_run(members, member):
    sc = load_scenario("double_mass")
    for d in ("jump", "nojump"):
        row = members[(members.design == d) & (members.member == member)].iloc[0]
        e = np.array([row["dq0_0"], row["dq0_1"]])
        v = np.array([row["du0_0"], row["du0_1"]])
        slave = Slave("x", OBSERVER_DESIGNS[d].position_jumps, sc.q0 + e, sc.u0 + v, OBSERVER_DESIGNS[d])
        full = simulate(sc, observers=[slave], **SETTINGS)
        V = full.slaves["x"].V                      # numpy's V of the recorded trajectories
        assert row["V_end"] == pytest.approx(V[-1], rel=1e-12, abs=0)
        assert row["V_max"] == pytest.approx(V.max(), rel=1e-12, abs=0)
        assert row["V_on"] == pytest.approx(V[0], rel=1e-12, abs=0)
        alone = simulate(sc, observers=[slave], store="summary", **SETTINGS).summary.iloc[0]
        for c in ("rises", "max_rise_rel", *(f(r) for r in RHOS for f in (settle_column, sync_column))):
            assert row[c] == alone[c], c


def test_pairs_share_their_initial_errors_and_V_on(members):
    X = _errors(members, "jump", 2)
    np.testing.assert_array_equal(X, _errors(members, "nojump", 2))
    assert len(np.unique(X[:, 0])) == 6
    V_on = members.pivot(index="member", columns="design", values="V_on")
    np.testing.assert_array_equal(V_on["jump"], V_on["nojump"])


def test_energy_sphere_level(members):
    sc = load_scenario("double_mass")
    M, K = dense(sc.system.M), dense(sc.system.K)
    x0 = np.concatenate([np.asarray(sc.observer["q"]) - sc.q0, np.asarray(sc.observer["u"]) - sc.u0])
    V0 = 0.5 * x0[:2] @ K @ x0[:2] + 0.5 * x0[2:] @ M @ x0[2:]
    X = _errors(members, "jump", 2)
    V = 0.5 * np.einsum("ki,ij,kj->k", X[:, :2], K, X[:, :2]) + 0.5 * np.einsum("ki,ij,kj->k", X[:, 2:], M, X[:, 2:])
    np.testing.assert_allclose(V, V0, rtol=1e-13, atol=0)
    np.testing.assert_allclose(members.V_on, V0, rtol=1e-13, atol=0)     # coupled from t = 0
    assert members.attrs["metadata"]["V0"] == pytest.approx(V0, rel=1e-15)


def test_seed_reproducibility_and_box():
    sc = load_scenario("double_mass")
    a, _ = sample_errors(sc, 50, "box", np.random.default_rng(3), None)
    b, _ = sample_errors(sc, 50, "box", np.random.default_rng(3), None)
    c, _ = sample_errors(sc, 50, "box", np.random.default_rng(4), None)
    np.testing.assert_array_equal(a, b)
    assert not np.any(a == c)
    x0 = np.concatenate([np.asarray(sc.observer["q"]) - sc.q0, np.asarray(sc.observer["u"]) - sc.u0])
    assert np.all(np.abs(a) <= np.abs(x0))
    assert np.all(np.ptp(a, axis=0) > 1.2 * np.abs(x0))              # spread over the box
    one = ensemble("double_mass", n=3, seed=5, h=1e-3, t_end=0.01, workers=1)
    two = ensemble("double_mass", n=3, seed=np.random.default_rng(5), h=1e-3, t_end=0.01, workers=2)
    np.testing.assert_array_equal(_errors(one, "jump", 2), _errors(two, "jump", 2))
    np.testing.assert_array_equal(one.V_end.to_numpy(), two.V_end.to_numpy())


def test_grid_summary_matches_the_kernel_summary():
    X = sample_errors(load_scenario("double_mass"), 3, "energy_sphere", np.random.default_rng(1), None)[0]
    kern = ensemble("double_mass", n=3, initial_errors=X, workers=1, **SETTINGS)
    grid = ensemble("double_mass", n=3, initial_errors=X, workers=1, store="full", **SETTINGS)
    cols = [f(r) for r in RHOS for f in (settle_column, sync_column)]
    assert np.isfinite(kern[cols].to_numpy()).sum() >= 6
    pd.testing.assert_frame_equal(kern[cols + ["rises"]], grid[cols + ["rises"]])
    for c in ("V_on", "V_max", "V_end", "max_rise_rel"):
        np.testing.assert_allclose(kern[c], grid[c], rtol=1e-12, atol=0)


def test_event_integrator_member_equals_a_single_event_run():
    sc = load_scenario("double_mass")
    X = np.array([[0.01, -0.02, 0.05, 0.1]])
    df = ensemble(sc, designs=("jump",), n=1, initial_errors=X, integrator="event", h=1e-3, t_end=0.5)
    slave = Slave("x", True, sc.q0 + X[0, :2], sc.u0 + X[0, 2:], OBSERVER_DESIGNS["jump"])
    V = simulate(sc, observers=[slave], integrator="event", h=1e-3, t_end=0.5).slaves["x"].V
    assert df.integrator[0] == "event"
    assert df.V_end[0] == pytest.approx(V[-1], rel=1e-12, abs=0)
    assert df.V_max[0] == pytest.approx(V.max(), rel=1e-12, abs=0)


def test_paths_and_parquet(members, tmp_path):
    paths = members.attrs["paths"]
    assert sorted(set(zip(paths.design, paths.member))) == [("jump", 0), ("jump", 1), ("nojump", 0), ("nojump", 1)]
    last = paths.groupby(["design", "member"]).V.last()
    ends = members.set_index(["design", "member"]).V_end
    for key, V in last.items():
        assert V == ends[key]
    from observer.ensemble import write_ensemble
    out = write_ensemble(members, tmp_path / "e.parquet")
    back = pd.read_parquet(out)
    pd.testing.assert_frame_equal(back, members.reset_index(drop=True), check_dtype=False)
    assert len(pd.read_parquet(tmp_path / "e.paths.parquet")) == len(paths)


@pytest.mark.parametrize("kwargs, field", [
    ({"designs": ("jump", "bogus")}, "designs"), ({"designs": ()}, "designs"), ({"n": 0}, "n"),
    ({"n": 2.5}, "n"), ({"initial_errors": "ball"}, "initial_errors"),
    ({"initial_errors": np.zeros((2, 3))}, "initial_errors"), ({"initial_errors": [[np.nan] * 4] * 3}, "initial_errors"),
    ({"integrator": "rk4"}, "integrator"), ({"paths": 4}, "paths"), ({"out": "x.csv"}, "out"),
    ({"V0": -1.0}, "V0"), ({"seed": -1}, "seed"), ({"workers": 0}, "workers"), ({"store": "some"}, "store"),
])
def test_bad_input_names_the_field(kwargs, field):
    with pytest.raises(InputError) as err:
        ensemble("double_mass", **{"n": 3, "t_end": 0.01, **kwargs})
    assert err.value.field == field


def test_no_default_level_without_an_observer_error():
    with pytest.raises(InputError) as err:
        ensemble("impact_oscillator", designs=("nojump",), n=2, t_end=0.01)
    assert err.value.field == "V0"
    with pytest.raises(InputError) as err:
        ensemble("impact_oscillator", designs=("nojump",), n=2, t_end=0.01, initial_errors="box")
    assert err.value.field == "initial_errors"


def test_cli_writes_the_rows_and_refuses_bad_input_in_one_line(tmp_path, capsys):
    from observer.cli import main

    out = tmp_path / "e.parquet"
    assert main(["ensemble", "double_mass", "--n", "2", "--seed", "4", "--h", "1e-3", "--t-end", "0.1",
                 "--workers", "1", "--out", str(out)]) == 0
    back = pd.read_parquet(out)
    direct = ensemble("double_mass", n=2, seed=4, h=1e-3, t_end=0.1, workers=1)
    np.testing.assert_array_equal(back.V_end.to_numpy(), direct.V_end.to_numpy())
    capsys.readouterr()
    assert main(["ensemble", "double_mass", "--designs", "jump,foo", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: designs:")
