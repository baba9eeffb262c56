"""Ensemble statistics of reports.analysis (issue 22): properties on synthetic members whose
answers are known by construction (no simulation)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from reports import analysis
from reports.analysis import (DEFAULT_PAIRS, MAX_CLAIMS, ensemble_claims, paired_ratio,
                              paired_settling, rise_distribution)

RHOS = analysis.RHOS


def members(t_base: np.ndarray, t_cand: np.ndarray, *, base="nojump", cand="jump",
            rise_base=None, rise_cand=None, label="toy") -> pd.DataFrame:
    """Members of one ensemble: the same settling time at every ρ (scaled by ρ's index)."""
    n = len(t_base)
    rows = []
    for design, t, rise in ((base, t_base, rise_base), (cand, t_cand, rise_cand)):
        for i in range(n):
            row = {"scenario": "toy", "label": label, "integrator": "timestepping", "design": design,
                   "member": i, "max_rise_rel": 0.0 if rise is None else rise[i]}
            for j, rho in enumerate(RHOS):
                row[analysis.SETTLE[rho]] = t[i] * (j + 1)
            rows.append(row)
    return pd.DataFrame(rows)


def _one(df, rho=RHOS[0]):
    return df[np.isclose(df["rho"], rho)].iloc[0]


def test_half_the_time_gives_ratio_one_half_with_a_tight_ci():
    tb = np.random.default_rng(1).uniform(1.0, 5.0, 200)
    out = paired_settling(members(tb, tb / 2), pairs=[("nojump", "jump")], rng=0, n_resamples=500)
    assert len(out) == len(RHOS)
    for _, r in out.iterrows():
        assert r["n"] == 200 and r["n_ratio"] == 200
        assert r["ratio_median"] == pytest.approx(0.5, rel=1e-12)
        assert r["ratio_q10"] == pytest.approx(0.5, rel=1e-12) and r["ratio_q90"] == pytest.approx(0.5, rel=1e-12)
        assert r["ci_low"] <= 0.5 <= r["ci_high"] and r["ci_high"] - r["ci_low"] < 1e-12
        assert r["frac_candidate_first"] == 1.0
        assert r["never_baseline"] == 0.0 and r["never_candidate"] == 0.0
        assert r["wilcoxon_p"] < 1e-10                       # 200 of 200 differences one-signed


def test_pairing_is_by_member_id_not_row_order():
    rng = np.random.default_rng(2)
    tb = rng.uniform(1.0, 5.0, 100)
    df = members(tb, tb * rng.uniform(0.3, 0.4, 100))
    a = paired_settling(df, pairs=[("nojump", "jump")], rng=5)
    b = paired_settling(df.sample(frac=1.0, random_state=3), pairs=[("nojump", "jump")], rng=5)
    pd.testing.assert_frame_equal(a, b)
    r = _one(a)
    assert 0.3 <= r["ratio_q10"] <= r["ratio_median"] <= r["ratio_q90"] <= 0.4
    assert r["ci_low"] <= r["ratio_median"] <= r["ci_high"]


def test_shuffled_members_break_the_pairing():
    rng = np.random.default_rng(4)
    tb = rng.uniform(1.0, 10.0, 300)
    df = members(tb, tb / 2)
    cand = df["design"] == "jump"
    shuffled = df.copy()
    shuffled.loc[cand, "member"] = rng.permutation(shuffled.loc[cand, "member"].to_numpy())
    r = _one(paired_settling(shuffled, pairs=[("nojump", "jump")], rng=0))
    assert r["ratio_q90"] / r["ratio_q10"] > 3              # paired: exactly 1
    assert r["frac_candidate_first"] < 0.95                 # paired: exactly 1


def test_never_settling_members():
    n = 50
    inf = np.full(n, np.inf)
    r = _one(paired_settling(members(inf, inf), pairs=[("nojump", "jump")], rng=0))
    assert r["never_baseline"] == 1.0 and r["never_candidate"] == 1.0 and r["n_ratio"] == 0
    assert np.isnan(r["ratio_median"]) and np.isnan(r["ci_low"]) and np.isnan(r["ci_high"])
    assert np.isnan(r["wilcoxon_p"]) and "no CI" in r["reason"] and "Wilcoxon" in r["reason"]
    # the candidate settles in 40 of 50, the baseline never: ratio 0 there, NaN never counted
    tc = np.where(np.arange(n) < 40, 2.0, np.inf)
    r = _one(paired_settling(members(inf, tc), pairs=[("nojump", "jump")], rng=0))
    assert r["never_baseline"] == 1.0 and r["never_candidate"] == pytest.approx(0.2)
    assert r["n_ratio"] == 40 and r["ratio_median"] == 0.0
    assert r["frac_candidate_first"] == pytest.approx(0.8)
    # the candidate never settles in 30 of 50 (ratio inf): the median is inf
    tb = np.full(n, 4.0)
    tc = np.where(np.arange(n) < 20, 2.0, np.inf)
    r = _one(paired_settling(members(tb, tc), pairs=[("nojump", "jump")], rng=0))
    assert r["ratio_median"] == np.inf and r["ratio_q10"] == 0.5 and r["never_candidate"] == 0.6


def test_paired_ratio_cases():
    r = paired_ratio([1.0, np.inf, 2.0, np.inf, 0.0], [0.5, 1.0, np.inf, np.inf, 0.0])
    np.testing.assert_array_equal(r, [0.5, 0.0, np.inf, np.nan, 1.0])


def test_bootstrap_is_reproducible_per_seed():
    tb = np.random.default_rng(6).lognormal(0, 1, 80)
    tc = tb * np.random.default_rng(7).lognormal(-0.5, 0.5, 80)
    df = members(tb, tc)
    a, b = (paired_settling(df, pairs=[("nojump", "jump")], rng=11) for _ in range(2))
    pd.testing.assert_frame_equal(a, b)
    c = paired_settling(df, pairs=[("nojump", "jump")], rng=12)
    assert not np.array_equal(a["ci_low"], c["ci_low"]) or not np.array_equal(a["ci_high"], c["ci_high"])


def test_ci_covers_the_population_median_of_lognormal_ratios():
    # log ratio ~ N(log 0.5, 0.3²): the population median is 0.5; a 95 % CI of 400 members
    # misses it with probability 5 %, so 20 seeds have ≥ 16 covering with probability > 0.98
    covered = 0
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        tb = rng.uniform(1, 3, 400)
        r = _one(paired_settling(members(tb, tb * 0.5 * np.exp(0.3 * rng.normal(size=400))),
                                 pairs=[("nojump", "jump")], rhos=RHOS[:1], rng=seed,
                                 n_resamples=500))
        covered += r["ci_low"] <= 0.5 <= r["ci_high"]
    assert covered >= 16


def test_rise_distribution_counts_above_roundoff():
    n = 100
    rise = np.where(np.arange(n) < 25, 0.5, 1e-14)          # 25 members rise by V/2
    df = members(np.ones(n), np.ones(n), base="jump", cand="jump_mass", rise_cand=rise)
    out = rise_distribution(df).set_index("design")
    assert out.loc["jump", "rising"] == 0 and out.loc["jump", "frac_rising"] == 0.0
    m = out.loc["jump_mass"]
    assert m["rising"] == 25 and m["frac_rising"] == 0.25 and m["rise_max"] == 0.5
    assert m["frac_ci_low"] < 0.25 < m["frac_ci_high"] and m["rise_q90"] == 0.5 and m["rise_median"] == 1e-14


def test_claims_carry_numbers_cis_and_at_most_eight_rows():
    rng = np.random.default_rng(8)
    frames = []
    for k, label in enumerate(["a", "b", "c", "d"]):
        tb = rng.uniform(2, 4, 60)
        nj = members(tb, tb / 2, label=label)                           # nojump vs jump: 2× sooner
        jm = members(tb / 2, tb, base="jump", cand="jump_mass", label=label,
                     rise_cand=np.where(np.arange(60) < 30, 1.0, 0.0))  # M metric: half rise, 2× slower
        jm = jm[jm["design"] == "jump_mass"]
        frames += [nj, jm]
    df = pd.concat(frames, ignore_index=True)
    paired = paired_settling(df, pairs=DEFAULT_PAIRS, rng=0, n_resamples=200)
    claims = ensemble_claims(paired, rise_distribution(df), rho=RHOS[0])
    assert 0 < len(claims) <= MAX_CLAIMS
    assert set(claims["kind"]) <= {"speed", "failure", "k_metric", "artifact"}
    speed = claims[claims["kind"] == "speed"]
    assert len(speed) == 2 and np.allclose(speed["value"], 2.0) and (speed["n"] == 60).all()
    assert all("2× sooner" in t and "95 % CI" in t for t in speed["text"])
    km = claims.set_index("claim_id")
    assert km.loc["k_metric:rises:jump_mass", "value"] == 0.5
    assert km.loc["k_metric:rises:jump_mass", "n"] == 240
    assert km.loc["k_metric:speed:jump_mass", "value"] == pytest.approx(2.0)
    assert "jump_identity" not in " ".join(claims["claim_id"])   # no rows, no claim
    assert claims["anchor"].astype(bool).all()


def test_k_metric_summary_pools_by_family_and_master():
    rng = np.random.default_rng(9)
    frames = []
    for label, scenario in (("toy", "toy"), ("toy (projected master)", "toy"),
                            ("random_system (seed 0)", "random_system")):
        tb = rng.uniform(1, 3, 40)
        rise = np.where(np.arange(40) < 10, 2.0, 1e-8)                 # 10 of 40 rise by 2·V
        df = members(tb, 2 * tb, base="jump", cand="jump_mass", rise_cand=rise, label=label)
        frames.append(df.assign(scenario=scenario))
    out = analysis.k_metric_summary(pd.concat(frames, ignore_index=True), rho=RHOS[0], rng=0,
                                    n_resamples=200)
    out = out.set_index(["family", "master", "design"])
    assert set(out.index) == {(f, m, d) for f, m in (("built-in", "plain"), ("built-in", "projected"),
                                                    ("random", "plain")) for d in ("jump", "jump_mass")}
    for key in out.index:
        r = out.loc[key]
        assert r["n"] == 40 and r["ensembles"] == 1 and r["never"] == 0.0
        if key[2] == "jump":
            assert r["rising"] == 0 and r["ratio_median"] == 1.0
        else:
            assert r["rising"] == 10 and r["frac_ci_low"] < 0.25 < r["frac_ci_high"]
            assert r["ratio_median"] == pytest.approx(2.0) and r["ratio_ci_low"] <= 2.0 <= r["ratio_ci_high"]


def test_a_speed_claim_without_a_finite_ratio_states_both_settled_fractions_with_their_cis():
    """The candidate settles in every member, the baseline in 30 of 100: the median ratio is 0
    (t_base = inf), so the claim gives the settled fractions with Clopper–Pearson intervals
    (here 100 % [96.4, 100] and 30 % [21.2, 40.0]) instead of an infinite ratio and CI."""
    tb = np.full(100, np.inf)
    tb[:30] = 2.0
    df = members(tb, np.full(100, 1.0))
    paired = paired_settling(df, pairs=[("nojump", "jump")], rng=0, n_resamples=200)
    claims = ensemble_claims(paired, rise_distribution(df))
    speed = claims[claims["kind"] == "speed"]
    assert len(speed)
    for text, lo, hi in zip(speed["text"], speed["ci_low"], speed["ci_high"]):
        assert "∞" not in text and "inf" not in text
        assert "in 100 % of 100 initial errors (95 % CI 96–100 %)" in text
        assert "in 30 % (95 % CI 21–40 %" in text
        assert lo == pytest.approx(96.378, abs=1e-3) and hi == 100.0
