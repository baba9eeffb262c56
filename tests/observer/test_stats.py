"""observer.stats: estimands checked against closed forms written here, not by the code under test."""

import numpy as np
import pandas as pd
import pytest

from observer import stats


def test_decay_rate_is_the_exponent_and_not_the_floor():
    """V = e^{-2t} + floor: the fit stops SAFETY·floor above the floor, so the rate is 2 to the
    floor's relative size; fitted to the window's end it would be decided by the floor."""
    t = np.linspace(0.0, 10.0, 2001)
    floor = 1e-6
    V = np.vstack([np.exp(-2.0 * t) + floor, 3.0 * np.exp(-0.5 * t)])
    fit = stats.decay_rates(t, V, 0.0, 10.0, stats.fit_levels(V[:, 0], floor))
    assert fit["rate"].iloc[0] == pytest.approx(2.0, rel=1e-3)
    assert fit["rate"].iloc[1] == pytest.approx(0.5, rel=1e-12)      # exact exponential, no level reached
    assert fit["reached_level"].tolist() == [True, False]
    whole = stats.decay_rates(t, V[:1], 0.0, 10.0, np.array([0.0]))["rate"].iloc[0]
    assert whole < 1.6                                                 # what the floor does without the level


def test_floor_path_is_the_running_maximum_over_designs_inside_the_window():
    """Hand-written zero-error V of two designs on 10 samples, window [2, 8]: 0 before t_on (a
    floor there does not count), then the largest value met so far over both designs."""
    t = np.arange(10.0)
    Vz = np.array([[9.0, 9.0, 0.0, 0.0, 1e-8, 0.0, 0.0, 0.0, 3e-8, 0.0],
                   [0.0, 0.0, 0.0, 2e-9, 0.0, 0.0, 5e-8, 0.0, 0.0, 7.0]])
    expected = [0.0, 0.0, 0.0, 2e-9, 1e-8, 1e-8, 5e-8, 5e-8, 5e-8, 5e-8]
    assert stats.floor_path(t, Vz, 2.0, 8.0).tolist() == expected


def test_a_floor_that_appears_late_does_not_stop_the_fit_early():
    """V = e^{-2t}; the zero-error V is 0 until t = 5, 1e-10 on [5, 7), 1e-6 from t = 7. The
    fit stops at the first sample with V ≤ 10³ × the floor met so far: t = 7 (V = e^{-14} <
    10⁻³), rate exactly 2. The window's largest floor used from t_on (the near miss) stops it
    where e^{-2t} = 10⁻³ (t = 3.45)."""
    t = np.linspace(0.0, 10.0, 1001)
    V = np.exp(-2.0 * t)[None, :]
    Vz = np.where(t >= 7.0, 1e-6, np.where(t >= 5.0, 1e-10, 0.0))
    fl = stats.floor_path(t, Vz, 0.0, 10.0)
    fit = stats.decay_rates(t, V, 0.0, 10.0, stats.fit_levels(V[:, 0], fl)).iloc[0]
    assert fit["t_fit"] == pytest.approx(6.99) and fit["reached_level"]
    assert fit["rate"] == pytest.approx(2.0, rel=1e-9)
    whole = stats.decay_rates(t, V, 0.0, 10.0, stats.fit_levels(V[:, 0], fl.max())).iloc[0]
    assert whole["t_fit"] == pytest.approx(0.5 * np.log(1e3), abs=0.01)


def test_kaplan_meier_closed_form():
    """Times 1, 2, 3 and two never (censored at 10): S = .8, .6, .4; median 3; RMST 1 + .8 + .6 + .4·7."""
    df = pd.DataFrame({"design": "a", "cluster": 0, "member": range(5), "t": [1.0, 2.0, 3.0, np.inf, np.inf]})
    r = stats.settling_summary(df, "t", 10.0, n_resamples=99).iloc[0]
    assert r["median"] == 3.0 and r["rmst"] == pytest.approx(5.2) and r["share_settled"] == pytest.approx(0.6)
    assert (r["share_low"], r["share_high"]) == pytest.approx(stats.clopper_pearson(3, 5))


def test_never_settling_never_enters_as_zero_or_infinity():
    """(c) A design that never settles: no median (not reached), no interval end, restricted mean =
    the window; the sign test counts it as later and keeps every pair; a non-decaying baseline
    makes the rate ratio undefined, not 0 or ∞."""
    n = 12
    df = pd.DataFrame({"design": ["a"] * n + ["b"] * n, "cluster": 0, "member": list(range(n)) * 2,
                       "t": [0.5 + i for i in range(n)] + [np.inf] * n})
    s = stats.settling_summary(df, "t", 20.0, n_resamples=99).set_index("design")
    assert np.isnan(s.loc["b", "median"]) and np.isnan(s.loc["b", "median_high"])
    assert s.loc["b", "rmst"] == 20.0 and s.loc["b", "share_settled"] == 0.0
    assert np.isfinite(s.loc["a", "median"]) and s.loc["a", "median"] > 0.0
    o = stats.settle_order(df, "t", "a", "b").iloc[0]
    assert (o["a_first"], o["b_first"], o["ties"]) == (n, 0, 0)
    o = stats.settle_order(df, "t", "b", "a").iloc[0]               # never is later, from either side
    assert (o["a_first"], o["b_first"], o["ties"]) == (0, n, 0)
    rates = df.assign(rate=[1.0] * n + [0.0] * n)
    rr = stats.rate_ratio(rates, "a", "b").iloc[0]
    assert np.isnan(rr["estimate"]) and rr["status"].startswith("undefined")


def test_threshold_below_a_floor_is_flagged():
    """(b) ρ·V_on ≤ floor: below_floor counts the members, floor_decided is set."""
    members = pd.DataFrame({"cluster": [0, 0, 1], "design": "jump", "V_on": [1.0, 10.0, 1.0]})
    floors = pd.DataFrame({"cluster": [0, 1], "design": "jump", "floor": [5e-9, 1e-12]})
    f = stats.floor_flags(members, floors, 1e-9).iloc[0]
    assert f["below_floor"] == 1 and f["floor_decided"]
    assert not stats.floor_flags(members, floors.assign(floor=0.0), 1e-9).iloc[0]["floor_decided"]


def test_zero_width_band_is_flagged():
    df = pd.DataFrame({"design": ["g"] * 10 + ["s"] * 10, "t": [8.13] * 10 + list(np.linspace(1, 5, 10))})
    b = stats.band_flags(df, "t", 1e-3).set_index("design")
    assert b.loc["g", "zero_width"] and not b.loc["s", "zero_width"]


def _population(rng, clusters=30, per=8):
    """Two levels: cluster effects shared by a cluster's members; E r_b = 1, E r_a = 2 (ratio 2)."""
    mu = rng.normal(1.0, 0.3, clusters)
    d = rng.normal(0.0, 0.4, clusters)
    c = np.repeat(np.arange(clusters), per)
    rb = mu[c] + rng.normal(0.0, 0.05, c.size)
    ra = 2.0 * mu[c] + d[c] + rng.normal(0.0, 0.05, c.size)
    m = np.tile(np.arange(per), clusters)
    return pd.DataFrame({"cluster": np.concatenate([c, c]), "member": np.concatenate([m, m]),
                         "design": ["a"] * c.size + ["b"] * c.size, "rate": np.concatenate([ra, rb])})


def test_cluster_bootstrap_coverage():
    """(d) The cluster bootstrap of the rate ratio covers the population's ratio 2 in ≥ 0.93 of
    draws at 95 %; resampling the members as if independent (one cluster) covers far less."""
    rng = np.random.default_rng(7)
    hits = hits_iid = 0
    reps = 150
    for _ in range(reps):
        pop = _population(rng)
        r = stats.rate_ratio(pop, "a", "b", n_resamples=199, seed=int(rng.integers(1 << 30))).iloc[0]
        hits += r["low"] <= 2.0 <= r["high"]
        iid = stats.rate_ratio(pop.assign(cluster=0), "a", "b", n_resamples=199).iloc[0]
        hits_iid += iid["low"] <= 2.0 <= iid["high"]
    assert hits / reps >= 0.93
    assert hits_iid / reps < 0.8


def test_a_share_every_cluster_agrees_on_has_the_k_of_m_clusters_interval():
    """Three masters, every member of each settling and settling first: the percentile
    bootstrap gives [1, 1] (every resample is 1); the reported interval is the exact binomial
    interval of 3 successes in 3 trials (members of one master counted as one), computed
    here from its closed form: [(α/2)^(1/3), 1]."""
    rng = np.random.default_rng(4)
    n = 20
    members = pd.DataFrame({"design": np.repeat(["jump", "nojump"], 3 * n),
                            "cluster": np.tile(np.repeat([0, 1, 2], n), 2),
                            "member": np.tile(np.arange(3 * n), 2),
                            "t": np.concatenate([rng.uniform(1, 2, 3 * n), rng.uniform(3, 4, 3 * n)])})
    low_exact = 0.025 ** (1 / 3)                 # Clopper–Pearson lower end of 3/3 at 95 %
    summary = stats.settling_summary(members, "t", 10.0, n_resamples=200).set_index("design")
    assert summary.loc["jump", "share_settled"] == 1.0
    assert summary.loc["jump", "share_low"] == pytest.approx(low_exact, rel=1e-9)
    assert summary.loc["jump", "share_high"] == 1.0
    order = stats.settle_order(members, "t", "jump", "nojump", n_resamples=200).iloc[0]
    assert order["a_first"] == 3 * n and order["share"] == 1.0
    assert order["low"] == pytest.approx(low_exact, rel=1e-9) and order["high"] == 1.0
