"""observer.uncertainty_ensemble on tiny sizes: the plants are the seeded draws the docstring
states (recomputed here from numpy's generators), and with relative_std = 0 the floors are those
of the exact model (a plain run of the nominal scenario with hand-built observers)."""

from __future__ import annotations

import numpy as np
import pytest

import observer
from observer.observers import OBSERVER_DESIGNS
from observer.uncertainty import uncertainty_ensemble

T_END = 0.5
TAIL = 0.5
DESIGNS = ("jump", "nojump")


def drawn_K(K: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """K ∘ (1 + σZ), Z standard normal from default_rng(seed), its upper triangle mirrored."""
    Z = np.random.default_rng(seed).standard_normal(K.shape)
    Z = np.triu(Z) + np.triu(Z, 1).T
    return K * (1.0 + sigma * Z)


def floors_by_hand(X: np.ndarray, plant_K: np.ndarray | None = None) -> dict[tuple[str, int], tuple[float, float]]:
    """(design, member) → (max V/V(0), max ‖q̂ − q‖) over the last TAIL of [0, T_END], from one
    run of double_mass with the observers built here: the nominal plant and no model table, or
    the plant with stiffness ``plant_K`` and observers carrying the nominal K."""
    sc = observer.load_scenario("double_mass")
    nd = sc.system.n
    model = None
    if plant_K is not None:
        model = {"K": np.asarray(sc.system.K, dtype=float).tolist()}
        sc = sc.with_overrides({"system.K": plant_K.tolist()})
    slaves = [observer.Slave(f"{d}/{i}", OBSERVER_DESIGNS[d].position_jumps, sc.q0 + x[:nd], sc.u0 + x[nd:],
                             OBSERVER_DESIGNS[d]) for d in DESIGNS for i, x in enumerate(X)]
    res = observer.simulate(sc, t_end=T_END, observers=slaves, model=model)
    t = np.asarray(res.t)
    sel = t >= (1.0 - TAIL) * T_END - 1e-12
    out = {}
    for d in DESIGNS:
        for i in range(len(X)):
            s = res.slaves[f"{d}/{i}"]
            V, q = np.asarray(s.V), np.asarray(s.q)
            out[d, i] = (float(V[sel].max() / V[0]),
                         float(np.sqrt(((q[sel] - np.asarray(res.q)[sel]) ** 2).sum(axis=1)).max()))
    return out


def run(sigma: float, sample: str, plants: int = 2, seed: int = 5):
    return uncertainty_ensemble("double_mass", DESIGNS, model={"K": {"relative_std": sigma}}, plants=plants,
                                n=2, seed=seed, sample=sample, t_end=T_END, tail=TAIL, record_every=1,
                                n_resamples=99)


def test_the_plants_are_the_seeded_draws():
    df = run(0.02, "plant", plants=3)
    meta = df.attrs["metadata"]
    K = np.asarray(observer.load_scenario("double_mass").system.K, dtype=float)
    want = np.random.SeedSequence(5).spawn(2)[1].generate_state(3, dtype=np.uint32)
    assert [p["seeds"]["K"] for p in meta["plants"]] == [int(s) for s in want]
    for p in meta["plants"]:
        Kp = drawn_K(K, 0.02, p["seeds"]["K"])
        # the observers carry the nominal K; the master the drawn one: ‖K − K̂p‖ / ‖K̂p‖
        assert p["relative_difference"]["K"] == pytest.approx(np.linalg.norm(K - Kp) / np.linalg.norm(Kp), rel=1e-12)
        other = drawn_K(K, 0.02, p["seeds"]["K"] + 1)            # near miss: the next seed's draw
        assert p["relative_difference"]["K"] != pytest.approx(np.linalg.norm(K - other) / np.linalg.norm(other),
                                                               rel=1e-6)
    first = df.attrs["members"].query("plant == 0")      # the master is plant 0's drawn K
    by_hand = floors_by_hand(np.asarray(meta["initial_errors"]), drawn_K(K, 0.02, meta["plants"][0]["seeds"]["K"]))
    for _, r in first.iterrows():
        assert r["floor_V"] == pytest.approx(by_hand[r["design"], r["member"]][0], rel=1e-9)
    assert list(df["design"]) == list(DESIGNS) and (df["plants"] == 3).all()
    assert (df["floor_V_low"] <= df["floor_V"]).all() and (df["floor_V"] <= df["floor_V_high"]).all()
    members = df.attrs["members"]
    assert len(members) == 3 * 2 * len(DESIGNS) and members["floor_V"].nunique() > len(DESIGNS) * 2


@pytest.mark.parametrize("sample", ["plant", "model"])
def test_with_zero_spread_the_floors_are_the_exact_models(sample):
    df = run(0.0, sample)
    X = np.asarray(df.attrs["metadata"]["initial_errors"])
    exact = floors_by_hand(X)
    for _, r in df.attrs["members"].iterrows():
        fV, fq = exact[r["design"], r["member"]]
        assert r["floor_V"] == pytest.approx(fV, rel=1e-9, abs=1e-15)
        assert r["floor_q"] == pytest.approx(fq, rel=1e-9, abs=1e-15)
    for d in DESIGNS:
        med = np.median([exact[d, i][0] for i in range(len(X))])
        assert float(df.loc[df["design"] == d, "floor_V"].iloc[0]) == pytest.approx(med, rel=1e-9)


def test_a_spread_moves_the_floors_off_the_exact_ones():
    """Near miss of the test above: σ = 1e-3 changes every member's floor."""
    df = run(1e-3, "plant")
    exact = floors_by_hand(np.asarray(df.attrs["metadata"]["initial_errors"]))
    for _, r in df.attrs["members"].iterrows():
        assert r["floor_V"] != pytest.approx(exact[r["design"], r["member"]][0], rel=1e-6)


@pytest.mark.parametrize("kwargs, field", [
    ({"model": {"Q": {"relative_std": 0.1}}}, "model.Q"),
    ({"model": {"K": {"scale": 1.1}}}, "model.K"),
    ({"model": {"K": {"relative_std": -0.1}}}, "model.K.relative_std"),
    ({"model": {"K": {"relative_std": 0.1}}, "sample": "both"}, "sample"),
    ({"model": {"K": {"relative_std": 0.1}}, "plants": 0}, "plants"),
    ({"model": {"K": {"relative_std": 0.1}}, "tail": 1.5}, "tail"),
])
def test_bad_input_names_the_keyword(kwargs, field):
    with pytest.raises(observer.InputError) as exc:
        uncertainty_ensemble("double_mass", **kwargs)
    assert exc.value.field == field


# --- the time to a level (issue 33, item 3) ---------------------------------------------------------
LEVEL_RUN = dict(plants=2, n=3, seed=5, t_end=8.0, h=1e-3, tail=0.5, record_every=1, n_resamples=99)


def km_median(times: np.ndarray) -> float:
    """The Kaplan–Meier median when every censored time (inf) lies after every event: S drops by
    1/N at each event, so the median is the ⌈N/2⌉-th smallest event time, NaN with fewer events."""
    finite = np.sort(times[np.isfinite(times)])
    k = int(np.ceil(times.size / 2))
    return float(finite[k - 1]) if finite.size >= k else float("nan")


def test_with_zero_spread_the_level_times_are_the_plain_ensembles_first_passages():
    """σ = 0 at level 1e-3: every member's time is the plain ensemble's t_sync_0.001 for the same
    initial errors (the kernel's streaming summary, another code path), and a design whose floor
    lies below the level gets the Kaplan–Meier median of those times."""
    df = uncertainty_ensemble("double_mass", DESIGNS, model={"K": {"relative_std": 0.0}}, level=1e-3, **LEVEL_RUN)
    X = np.asarray(df.attrs["metadata"]["initial_errors"])
    plain = observer.ensemble("double_mass", DESIGNS, n=3, initial_errors=X, t_end=8.0, h=1e-3)
    want = plain.set_index(["design", "member"])["t_sync_0.001"]
    members = df.attrs["members"]
    for _, r in members.iterrows():
        assert r["t_level"] == want[r["design"], r["member"]]
    assert not np.allclose(plain["t_sync_0.001"], plain["t_sync_1e-05"])      # the level matters
    s = df.set_index("design")
    assert df.attrs["metadata"]["level"] == 1e-3 and df.attrs["metadata"]["level_rule"] == "given"
    decided = [d for d in DESIGNS if s.loc[d, "floor_V_high"] < 1e-3]
    assert decided, "no design below the level: the test checks nothing"
    for d in DESIGNS:
        if d in decided:
            times = members.loc[members["design"] == d, "t_level"].to_numpy()
            assert s.loc[d, "t_level"] == km_median(times) and s.loc[d, "t_level_status"] == "ok"
            assert s.loc[d, "t_level_low"] <= s.loc[d, "t_level"] <= s.loc[d, "t_level_high"]
        else:
            assert np.isnan(s.loc[d, "t_level"]) and s.loc[d, "t_level_status"].startswith("undecided")


def test_the_default_level_lies_above_every_members_floor():
    """The default: 10 × the largest member floor rounded up to 10^(−k/10); no member is then
    censored, and each design's time is a number."""
    df = uncertainty_ensemble("double_mass", DESIGNS, model={"K": {"relative_std": 1e-3}}, **LEVEL_RUN)
    members = df.attrs["members"]
    F = 10.0 * members["floor_V"].max()
    k = np.floor(-10.0 * np.log10(F) + 1e-9)
    assert df.attrs["metadata"]["level"] == pytest.approx(10.0 ** (-k / 10.0), rel=1e-12)
    assert F <= df.attrs["metadata"]["level"] < F * 10 ** 0.1
    assert np.isfinite(members["t_level"]).all() and (df["t_level_reached"] == len(members) // 2).all()
    assert (df["t_level_status"] == "ok").all() and np.isfinite(df["t_level"]).all()


def test_a_level_below_the_floor_is_undecided_not_a_number():
    df = uncertainty_ensemble("double_mass", DESIGNS, model={"K": {"relative_std": 1e-2}}, level=1e-9, **LEVEL_RUN)
    assert (df["floor_V_high"] >= 1e-9).all()
    assert df["t_level"].isna().all() and df["t_level_status"].str.startswith("undecided").all()


def test_censored_members_enter_the_kaplan_meier_median_as_censored():
    """observer.uncertainty.level_times on members of known times: two of six never reach the level
    (inf): the median is the Kaplan–Meier one (the 3rd smallest time), not the median of the four
    that reach it nor one counting inf as a time; with four of six censored it is "not reached"."""
    import pandas as pd

    from observer.uncertainty import level_times

    times = np.array([0.4, np.inf, 0.1, 0.3, np.inf, 0.2])
    members = pd.DataFrame({"design": "jump", "plant": [0, 0, 1, 1, 2, 2], "member": [0, 1] * 3, "t_level": times})
    floors = pd.DataFrame({"design": ["jump"], "floor_V_high": [1e-4]})
    r = level_times(members, floors, 1e-3, 5.0, n_resamples=199).iloc[0]
    assert r["t_level"] == km_median(times) == 0.3
    assert r["t_level"] != np.median(times[np.isfinite(times)])           # dropping the censored: 0.25
    assert r["t_level_reached"] == 4 and r["t_level_status"] == "ok"
    assert r["t_level_low"] <= 0.3 <= r["t_level_high"]
    worse = members.assign(t_level=np.array([0.4, np.inf, np.inf, 0.3, np.inf, np.inf]))
    r = level_times(worse, floors, 1e-3, 5.0, n_resamples=199).iloc[0]
    assert np.isnan(r["t_level"]) and r["t_level_status"] == "not reached" and r["t_level_reached"] == 2
    r = level_times(members, floors.assign(floor_V_high=1e-3), 1e-3, 5.0).iloc[0]    # at the floor
    assert np.isnan(r["t_level"]) and r["t_level_status"].startswith("undecided")


def test_cli_writes_the_members_and_the_summary_and_never_overwrites_its_input(tmp_path, capsys):
    """``observer uncertainty``: the rows are the API's members (same call), the metadata beside
    them holds the settings and the per-design summary; an --out that is the scenario file is
    refused before any run (exit 2, the file untouched)."""
    import json

    import pandas as pd

    from observer.cli import main

    out = tmp_path / "u.csv"
    argv = ["uncertainty", "double_mass", "--uncertainty", "K=0.001", "--plants", "2", "--n", "3", "--seed", "5",
            "--t-end", "8", "--h", "1e-3", "--tail", "0.5", "--record-every", "1", "--n-resamples", "19",
            "--out", str(out)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "3 members x 2 plants (plant drawn)" in text and f"wrote {out}" in text
    rows, meta = pd.read_csv(out), json.loads(out.with_suffix(".json").read_text())
    api = uncertainty_ensemble("double_mass", DESIGNS, model={"K": {"relative_std": 0.001}}, plants=2, n=3, seed=5,
                               t_end=8.0, h=1e-3, tail=0.5, record_every=1, n_resamples=19)
    members = api.attrs["members"]
    np.testing.assert_array_equal(rows["floor_V"].to_numpy(), members["floor_V"].to_numpy())
    np.testing.assert_array_equal(rows["t_level"].to_numpy(), members["t_level"].to_numpy())
    assert meta["uncertainty"] == {"K": {"relative_std": 0.001}} and meta["level"] == api.attrs["metadata"]["level"]
    assert [r["design"] for r in meta["summary"]] == list(DESIGNS)
    assert meta["summary"][0]["t_level"] == api["t_level"].iloc[0]
    assert meta["summary"][0]["t_level_low"] == api["t_level_low"].iloc[0] and meta["n_resamples"] == 19
    scenario = tmp_path / "s.toml"
    assert main(["show", "double_mass"]) == 0
    scenario.write_text(capsys.readouterr().out)
    before = scenario.read_bytes()
    assert main(["uncertainty", str(scenario), "--uncertainty", "K=0.001", "--out", str(scenario)]) == 2
    assert "would overwrite the input scenario" in capsys.readouterr().err
    assert scenario.read_bytes() == before
