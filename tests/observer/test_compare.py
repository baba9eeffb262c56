"""observer.compare and ``python -m observer compare``: the acceptance of issue 31 on small runs."""

import json
import subprocess
import sys

import numpy as np
import pytest

import observer
from observer.cli import main

SMALL = dict(n=6, masters=2, t_end=4.0, h=1e-3, n_resamples=99)

USER_TOML = """
[scenario]
name = "three_masses"
[system]
M = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0]]
C = [[1.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 2.0]]
K = [[100.0, -100.0, 0.0], [-100.0, 200.0, -100.0], [0.0, -100.0, 250.0]]
W = [[1.0], [0.0], [0.0]]
[system.forcing]
constant = [0.0, 0.0, 0.0]
amplitude = [0.0, 0.0, 4.0]
omega = 5.0
phase = [0.0, 0.0, 0.0]
[system.gap]
offset = [0.05]
[impact]
law = "poisson"
restitution = 0.7
[initial]
q = [0.0, 0.0, 0.0]
u = [0.0, 0.0, 0.0]
[simulation]
t_end = 3.0
h = 0.001
[observer]
q = [0.01, -0.01, 0.005]
u = [0.1, 0.0, -0.1]
"""


def test_cli_double_mass_prints_json_and_report(tmp_path, capsys):
    """The rate ratio with its interval, the censored summary per design and the evidence; JSON
    with rate_ratio {estimate, low, high}; a report that renders in headless Chromium."""
    out = tmp_path / "c.json"
    rc = main(["compare", "double_mass", "--n", "5", "--masters", "2", "--t-end", "4", "--h", "1e-3",
               "--json", str(out), "--report", str(tmp_path / "rep")])
    text = capsys.readouterr().out
    assert rc == 0
    assert "decay-rate ratio jump/nojump:" in text and "5 members x 2 masters" in text
    assert "  jump " in text and "  nojump " in text and "restricted mean" in text
    doc = json.loads(out.read_text())
    rr = doc["pairs"][0]["rate_ratio"]
    assert rr["low"] <= rr["estimate"] <= rr["high"]
    assert set(doc["settling"]) == {"jump", "nojump"} and doc["evidence"] == {
        "members_per_master": 5, "masters": 2, "pairs": 10}
    from reports.browser import check_page, find_chromium
    if find_chromium() is None:
        pytest.skip("chromium is not installed (apt-get install chromium)")
    res = check_page(tmp_path / "rep" / "index.html", tmp_path / "shot.png", width=1400, height=1000)
    assert res.ok and res.screenshot.stat().st_size > 10_000


def test_user_three_dof_toml(tmp_path, capsys):
    f = tmp_path / "three.toml"
    f.write_text(USER_TOML)
    assert main(["compare", str(f), "--n", "4", "--masters", "2"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("three_masses: 4 members x 2 masters") and "decay-rate ratio" in text


def test_bad_input_names_the_field(capsys):
    assert main(["compare", "double_mass", "--rho", "1e-7"]) == 2
    assert "rho" in capsys.readouterr().err


def test_window_does_not_decide_the_rate_ratio():
    """(a) The same members (same seed) over 10 s and 20 s: the rate-ratio intervals overlap."""
    kw = dict(SMALL, t_end=None)
    a = observer.compare("double_mass", t_end=10.0, **{k: v for k, v in kw.items() if k != "t_end"})
    b = observer.compare("double_mass", t_end=20.0, **{k: v for k, v in kw.items() if k != "t_end"})
    ra, rb = a.rate_ratios.iloc[0], b.rate_ratios.iloc[0]
    assert ra["low"] <= rb["high"] and rb["low"] <= ra["high"]


def test_threshold_below_the_measured_floor_is_flagged():
    """(b) jump's floor with the time-stepped master, measured here by a single zero-error run
    (observer.simulate), against the flag the comparison raises at ρ = 1e-9."""
    from observer.observers import OBSERVER_DESIGNS, Slave
    from observer.scenario import load_scenario

    res = observer.compare("double_mass", rho=1e-9, **SMALL)
    sc = load_scenario("double_mass").with_overrides({"simulation.t_end": 4.0, "simulation.h": 1e-3})
    run = observer.simulate(sc, observers=[Slave("z", True, sc.q0, sc.u0, OBSERVER_DESIGNS["jump"])])
    floor = float(np.max(run.slaves["z"].V))
    assert floor > 0.0
    f = res.floor_flags.set_index("design")
    m0 = res.members[(res.members["cluster"] == 0) & (res.members["design"] == "jump")]
    assert f.loc["jump", "below_floor"] >= int(np.sum(1e-9 * m0["V_on"] <= floor))
    assert res.floors.set_index(["cluster", "design"]).loc[(0, "jump"), "floor"] == pytest.approx(floor, rel=1e-9)
    assert any(w.startswith("floor-decided") and "jump" in w for w in res.warnings)


def test_installed_package_outside_the_clone(tmp_path):
    code = ("import observer, json; r = observer.compare('double_mass', n=3, masters=2, t_end=2.0, h=1e-3, "
            "n_resamples=49); print(json.dumps(r.to_dict()['pairs'][0]['rate_ratio']))")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True)
    assert set(json.loads(out.stdout.strip().splitlines()[-1])) >= {"estimate", "low", "high"}


def test_zeno_ball_reports_position_error_beside_v():
    """K = 0: nojump's V settles, yet its position error at the window's end stays large; the
    comparison says K is singular and reports the position error (recomputed here from a
    single run of member 0)."""
    from observer.ensemble import member_name, member_slaves, sample_errors
    from observer.scenario import load_scenario

    res = observer.compare("bouncing_ball", designs=("jump_mass", "nojump"), n=3, masters=1, V0=0.5,
                           n_resamples=49)
    assert any(w.startswith("K is singular") for w in res.warnings)
    pos = res.positions.set_index("design")
    sc = load_scenario("bouncing_ball")
    X, _ = sample_errors(sc, 3, "energy_sphere", np.random.default_rng(
        int(np.random.SeedSequence(0).spawn(2)[1].generate_state(1)[0])), 0.5)
    run = observer.simulate(sc, observers=member_slaves(sc, ("nojump",), X, range(3)))
    e_end = [abs(run.slaves[member_name("nojump", i)].q[-1, 0] - run.q[-1, 0]) for i in range(3)]
    assert pos.loc["nojump", "median_end"] == pytest.approx(float(np.median(e_end)), rel=1e-9)
    assert pos.loc["nojump", "median_end"] > 0.1



def test_scheduler_runs_the_masters_on_dask_with_the_same_estimands():
    """``scheduler=ADDRESS`` (``--scheduler``): the masters run as tasks on a (one-worker,
    in-process) Dask cluster and give the local run's estimands exactly (same seeds); another
    seed does not (the equality is not vacuous)."""
    import logging

    import distributed

    kw = dict(n=3, masters=2, t_end=2.0, h=1e-3, n_resamples=49)

    def estimands(res):
        doc = res.to_dict()
        return {k: doc[k] for k in ("pairs", "settling", "floors", "evidence", "warnings")}, doc["metadata"]

    local, meta_local = estimands(observer.compare("double_mass", **kw))
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None,
                                  silence_logs=logging.ERROR) as cluster:
        remote, meta_remote = estimands(observer.compare("double_mass", scheduler=cluster.scheduler_address, **kw))
    assert remote == local
    assert meta_remote["master_steps"] == meta_local["master_steps"]
    other, _ = estimands(observer.compare("double_mass", seed=1, **kw))
    assert other["pairs"] != local["pairs"]


# --- issue 33: compare over plants drawn from a stated uncertainty --------------------------------------
PLANTS_RUN = dict(n=3, masters=2, t_end=3.0, h=1e-3, n_resamples=99)


def drawn_K(K: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """K ∘ (1 + σZ), Z standard normal from default_rng(seed), its upper triangle mirrored."""
    Z = np.random.default_rng(seed).standard_normal(K.shape)
    return K * (1.0 + sigma * (np.triu(Z) + np.triu(Z, 1).T))


def test_with_zero_spread_every_plant_repeats_the_plain_comparison():
    """σ = 0: each plant's runs are the plain comparison's (same masters, same members, the plant
    the nominal one), so the rate ratio is the plain one and resampling identical plants gives a
    zero-width interval."""
    plain = observer.compare("double_mass", **PLANTS_RUN)
    res = observer.compare("double_mass", model={"K": {"relative_std": 0.0}}, plants=2, **PLANTS_RUN)
    assert res.cluster_level == "plants" and res.evidence == {"members_per_master": 3, "masters": 2, "plants": 2,
                                                              "pairs": 12}
    for j in range(2):
        for k in range(2):
            mine = res.members[(res.members["plant"] == j) & (res.members["master"] == k)]
            theirs = plain.members[plain.members["cluster"] == k]
            np.testing.assert_array_equal(mine.sort_values(["design", "member"])[["V_on", "rate"]].to_numpy(),
                                          theirs.sort_values(["design", "member"])[["V_on", "rate"]].to_numpy())
    rr, pr = res.rate_ratios.iloc[0], plain.rate_ratios.iloc[0]
    assert rr["estimate"] == pytest.approx(pr["estimate"], rel=1e-12)
    assert rr["low"] == pytest.approx(rr["estimate"], rel=1e-12) == rr["high"]
    assert rr["clusters"] == 2                                           # plants, not the 4 runs


def test_the_plants_are_the_seeded_draws_and_the_clusters_resampled():
    """σ = 1e-2 over 3 plants: the plants' K seeds are the SeedSequence(seed, spawn_key=(2**31,))
    draws (recomputed with numpy), plant 1's master-0 members are those of a plain comparison on a
    plant with that drawn K and observers carrying the nominal K, and the rate-ratio interval is
    the cluster bootstrap over plants (recomputed with observer.stats.cluster_ci on the plant
    labels; resampling the 6 runs instead gives another interval)."""
    from observer.stats import cluster_ci

    res = observer.compare("double_mass", model={"K": {"relative_std": 1e-2}}, plants=3, seed=4, **PLANTS_RUN)
    want = np.random.SeedSequence(4, spawn_key=(2 ** 31,)).spawn(2)[1].generate_state(3, dtype=np.uint32)
    meta = res.metadata
    assert [p["seeds"]["K"] for p in meta["plants"]] == [int(s) for s in want]
    assert meta["sample"] == "plant" and meta["cluster_level"] == "plants"
    sc = observer.load_scenario("double_mass")
    K = np.asarray(sc.system.K, dtype=float)
    Kp = drawn_K(K, 1e-2, int(want[1]))
    assert meta["plants"][1]["relative_difference"]["K"] == pytest.approx(
        np.linalg.norm(K - Kp) / np.linalg.norm(Kp), rel=1e-12)
    alone = observer.compare(sc.with_overrides({"system.K": Kp.tolist()}), model={"K": K.tolist()},
                             **{**PLANTS_RUN, "masters": 1, "seed": 4})
    mine = res.members[(res.members["plant"] == 1) & (res.members["master"] == 0)]
    np.testing.assert_array_equal(mine.sort_values(["design", "member"])[["V_on", "rate"]].to_numpy(),
                                  alone.members.sort_values(["design", "member"])[["V_on", "rate"]].to_numpy())
    m = res.members.assign(member=res.members["master"] * 3 + res.members["member"])
    w = m.pivot_table(index=["plant", "member"], columns="design", values="rate", aggfunc="first")
    ra, rb, plant = w["jump"].to_numpy(), w["nojump"].to_numpy(), w.index.get_level_values("plant").to_numpy()
    stat = lambda i: float(ra[i].sum() / rb[i].sum())  # noqa: E731
    lo, hi, unit = cluster_ci(stat, plant, n_resamples=99, seed=4)
    rr = res.rate_ratios.iloc[0]
    assert (rr["low"], rr["high"], rr["clusters"]) == (lo, hi, 3) and unit == "clusters"
    runs = m.pivot_table(index=["cluster", "member"], columns="design", values="rate", aggfunc="first")
    lo6, hi6, _ = cluster_ci(lambda i: float(runs["jump"].to_numpy()[i].sum() / runs["nojump"].to_numpy()[i].sum()),
                             runs.index.get_level_values("cluster").to_numpy(), n_resamples=99, seed=4)
    assert (lo6, hi6) != (lo, hi)
    doc = res.to_dict()
    assert doc["pairs"][0]["rate_ratio"]["resampled"] == "plants" and doc["pairs"][0]["faster_plants"]["m"] == 3
    assert doc["evidence"]["plants"] == 3


def test_sample_model_draws_the_observers_model_and_keeps_the_plant():
    res = observer.compare("double_mass", model={"K": {"relative_std": 1e-2}}, plants=2, sample="model", seed=4,
                           **{**PLANTS_RUN, "masters": 1})
    K = np.asarray(observer.load_scenario("double_mass").system.K, dtype=float)
    for p in res.metadata["plants"]:
        Km = drawn_K(K, 1e-2, p["seeds"]["K"])                         # the observers' K; the plant's is K
        assert p["relative_difference"]["K"] == pytest.approx(np.linalg.norm(Km - K) / np.linalg.norm(K), rel=1e-12)
    assert res.metadata["sample"] == "model"


def test_cli_compare_over_plants_writes_the_plants_in_the_json(tmp_path, capsys):
    out = tmp_path / "c.json"
    rc = main(["compare", "double_mass", "--uncertainty", "K=0.01", "--plants", "2", "--n", "3", "--masters", "2",
               "--t-end", "3", "--h", "1e-3", "--json", str(out)])
    text = capsys.readouterr().out
    assert rc == 0
    assert "3 members x 2 masters x 2 plants (plant drawn: K relative_std 0.01)" in text
    assert "(resampling plants)" in text and "of 2 plants" in text
    doc = json.loads(out.read_text())
    assert doc["metadata"]["uncertainty"] == {"K": {"relative_std": 0.01}} and len(doc["metadata"]["plants"]) == 2
    assert doc["evidence"] == {"members_per_master": 3, "masters": 2, "plants": 2, "pairs": 12}
