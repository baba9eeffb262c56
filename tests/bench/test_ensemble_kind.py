"""The bench's ``ensemble`` case kind (issue 22): suites sized for ensembles, the runner's
rows (one per design and member, paired, schema-checked) and robustness as ensembles."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

import observer
from bench.runners import Context, run_case
from observer.row_schema import check_row
from bench.suites import Case, get_suite, random_family
from observer.ensemble import energy_metric
from observer.observers import OBSERVER_DESIGNS
from observer.scenarios import SCENARIOS

DESIGNS = ("jump", "nojump", "jump_mass", "jump_identity")


@pytest.mark.parametrize("suite,members,systems", [("quick", 100, 2), ("full", 1000, 50)])
def test_suites_hold_ensembles_of_every_builtin_and_design(suite, members, systems):
    cases = get_suite(suite).of_kind("ensemble")
    assert set(DESIGNS) <= set(OBSERVER_DESIGNS)
    plain = [c for c in cases if c.perturbation == "none" and c.scenario != "random_system"]
    assert {c.scenario for c in plain} == set(SCENARIOS) - {"random_system"}
    for c in plain:
        assert c.members >= members and set(DESIGNS) <= set(c.observers)
    family = {dict(c.params)["param.seed"] for c in cases if c.scenario == "random_system"}
    assert len(family) >= systems
    assert all(c.members >= 100 for c in cases)
    perturbed = Counter(c.perturbation for c in cases if c.perturbation != "none")
    assert perturbed and all(c.members >= 100 for c in cases if c.perturbation != "none")


def test_random_family_stays_inside_the_builder_ranges():
    fam = random_family(50)
    assert [s for s, _, _ in fam] == list(range(50))
    assert {d for _, d, _ in fam} == set(range(2, 9))
    assert all(1 <= m <= min(4, d) for _, d, m in fam)
    assert {m for _, _, m in fam} == {1, 2, 3, 4}


def _ctx(tmp_path):
    return Context("t", tmp_path, {}, cache={})


def test_ensemble_rows_are_paired_checked_and_on_the_energy_sphere(tmp_path):
    case = Case("ensemble", "double_mass", observers=DESIGNS, h=1e-3, t_end=1.0, members=6, seed=3)
    rows = run_case(case, _ctx(tmp_path))
    assert len(rows) == 6 * len(DESIGNS)
    assert Counter((r["design"]) for r in rows) == {d: 6 for d in DESIGNS}
    for r in rows:
        check_row(r)
        assert r["kind"] == "ensemble" and r["seed"] == 3 and r["members"] == 6 and r["status"] == "ok"
    sc = observer.load_scenario("double_mass")
    A = energy_metric(sc)
    x_own = np.concatenate([np.asarray(sc.observer["q"]) - sc.q0, np.asarray(sc.observer["u"]) - sc.u0])
    V0 = 0.5 * x_own @ A @ x_own
    by_member = {}
    for r in rows:
        x = np.array([r["dq0_0"], r["dq0_1"], r["du0_0"], r["du0_1"]])
        by_member.setdefault(r["member"], []).append(x)
        assert 0.5 * x @ A @ x == pytest.approx(V0, rel=1e-12)     # V(0) = V0 on the sphere
        assert r["V_on"] == pytest.approx(V0, rel=1e-12)          # coupled from t = 0
    assert all(np.array_equal(xs[0], x) for xs in by_member.values() for x in xs)   # paired
    assert len({tuple(xs[0]) for xs in by_member.values()}) == 6   # distinct members


def test_k_singular_leaves_the_k_jump_out_and_says_so(tmp_path):
    case = Case("ensemble", "bouncing_ball", observers=DESIGNS, h=1e-3, t_end=0.5, members=3,
                slave_offset=((0.2,), (-1.0,)))
    rows = run_case(case, _ctx(tmp_path))
    assert {r["design"] for r in rows} == set(DESIGNS) - {"jump"}
    assert all("jump" in r["note"] and "K singular" in r["note"] for r in rows)


def test_perturbed_chi_samples_the_log_and_the_errors(tmp_path):
    ctx = _ctx(tmp_path)
    kw = dict(observers=("jump", "nojump"), h=1e-3, t_end=2.0, members=4)
    clean = run_case(Case("ensemble", "double_mass", **kw), ctx)
    a, b = (run_case(Case("ensemble", "double_mass", perturbation="missed", size=0.5, seed=s, **kw), ctx)
            for s in (0, 1))
    assert len(list((tmp_path / "t" / "logs").glob("*.csv"))) == 2
    err = lambda rows: [r["dq0_0"] for r in rows]
    assert err(a) != err(b) and err(a) == err(clean)             # errors follow the seed
    settle = lambda rows: [r["V_end"] for r in rows]
    assert settle(a) != settle(clean)                            # the χ the observers saw differs


def test_stored_paths_are_the_members_own_thinned_runs(tmp_path):
    """A case with ``paths`` keeps V(t) of its first members of every design, thinned to
    PATH_POINTS samples from t = 0 to t_end; each path is that member's run: its first and
    last samples are the member's row's V(t_on) (coupled from t = 0) and V_end."""
    from bench.runners import PATH_POINTS
    import pandas as pd

    case = Case("ensemble", "double_mass", observers=("jump", "nojump"), h=1e-3, t_end=1.0, members=5,
                seed=1, paths=3)
    rows = run_case(case, _ctx(tmp_path))
    rels = {r["paths"] for r in rows}
    assert len(rels) == 1
    p = pd.read_parquet(tmp_path / rels.pop())
    assert set(p["design"]) == {"jump", "nojump"} and set(p["member"]) == {0, 1, 2}
    for (d, i), g in p.groupby(["design", "member"]):
        g = g.sort_values("t")
        assert len(g) == PATH_POINTS
        assert g["t"].iloc[0] == 0.0 and g["t"].iloc[-1] == pytest.approx(1.0, abs=1e-12)
        row = next(r for r in rows if r["design"] == d and r["member"] == i)
        assert g["V"].iloc[0] == pytest.approx(row["V_on"], rel=1e-12)
        assert g["V"].iloc[-1] == pytest.approx(row["V_end"], rel=1e-12)
    assert p.groupby("design")["V"].apply(lambda v: v.nunique()).min() > 2 * PATH_POINTS  # distinct members


def test_paths_of_a_singular_k_scenario(tmp_path):
    """bouncing_ball (K = 0, the K-metric jump left out) keeps its paths too."""
    import pandas as pd

    case = Case("ensemble", "bouncing_ball", observers=DESIGNS, h=1e-3, t_end=0.5, members=3,
                slave_offset=((0.2,), (-1.0,)), paths=2)
    rows = run_case(case, _ctx(tmp_path))
    p = pd.read_parquet(tmp_path / rows[0]["paths"])
    assert set(p["design"]) == set(DESIGNS) - {"jump"} and set(p["member"]) == {0, 1}


def test_an_ensemble_on_several_masters_splits_its_members_over_them(tmp_path):
    """``masters = 2``, 5 members: members 0–2 on the scenario's own master, 3–4 on a master
    started elsewhere; every error on the scenario's energy sphere; the rows of master 0 are
    what observer.ensemble gives against the scenario itself with those errors, those of
    master 1 are not (their master moved)."""
    import pandas as pd

    case = Case("ensemble", "double_mass", observers=("jump", "nojump"), h=1e-3, t_end=1.0, members=5,
                masters=2, seed=2)
    rows = pd.DataFrame(run_case(case, _ctx(tmp_path)))
    for r in rows.to_dict("records"):
        check_row(r)
    jump = rows[rows["design"] == "jump"].sort_values("member")
    assert jump["member"].tolist() == [0, 1, 2, 3, 4] and jump["master"].tolist() == [0, 0, 0, 1, 1]
    sc = observer.load_scenario("double_mass", {"simulation.h": 1e-3, "simulation.t_end": 1.0})
    A = energy_metric(sc)
    x_own = np.concatenate([np.asarray(sc.observer["q"]) - sc.q0, np.asarray(sc.observer["u"]) - sc.u0])
    X = jump[["dq0_0", "dq0_1", "du0_0", "du0_1"]].to_numpy()
    assert np.einsum("ij,jk,ik->i", X, A, X) == pytest.approx(np.full(5, x_own @ A @ x_own), rel=1e-12)
    own = observer.ensemble(sc, ("jump",), n=5, initial_errors=X).sort_values("member")
    same = np.isclose(own["V_end"].to_numpy(), jump["V_end"].to_numpy(), rtol=1e-12, atol=0.0)
    assert same.tolist() == [True, True, True, False, False]
