"""Benchmark suites (bench/): declared grids, resumable results, perturbed logs, references.

No timing assertions: speed is measured by the suites, not tested here.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import observer
from bench.perturb import KINDS, perturb_log
from observer.closed_form import ExactImpactOscillator, ball_position, closed_form_position
from bench.results import CaseStore, case_key, load_results
from bench.peers import PROBLEMS
from bench.run import results_path, run_suite
from bench.runners import Context, _event_reference, record_every, reference_group, reference_grids
from bench.suites import RANDOM_KINDS, SUITES, Case, Suite, check_scenarios, engine_for, get_suite
from observer.errors import InputError
from observer.scenarios import bouncing_ball as bb
from observer.switching import validate_log

REPO = Path(__file__).resolve().parents[2]
SMOKE = get_suite("smoke")


def smoke_rows_expected() -> int:
    """Rows of the smoke suite: observers 2 per case, robustness one per design and member
    (of every master), else 1 (the checks case writes one row per registered check, counted
    separately)."""
    n = 0
    for c in SMOKE.cases:
        if c.kind != "checks":
            n += {"observers": len(c.observers)}.get(c.kind, 1) if c.kind != "robustness" \
                else len(c.observers) * c.members
    return n


# ----------------------------------------------------------------------------- declarations
def test_case_ids_are_stable_and_unique():
    a = Case("work_precision", "double_mass", law="newton", h=1e-3, t_end=1.0, target="jump",
             observers=("jump",), reference="event solution")
    b = Case("work_precision", "double_mass", law="newton", h=1e-3, t_end=1.0, target="jump",
             observers=("jump",), reference="event solution")
    assert a.case_id == b.case_id
    assert "h=0.001" in a.case_id and "law=newton" in a.case_id
    assert Case("observers", "double_mass").case_id == "observers:double_mass"
    assert Case("observers", "double_mass", integrator="event").case_id == \
        "observers:double_mass:integrator=event"
    for suite in SUITES.values():
        ids = [c.case_id for c in suite.cases]
        assert len(ids) == len(set(ids)), suite.name
    with pytest.raises(ValueError, match="duplicate"):
        Suite("dup", "", (a, b))
    with pytest.raises(KeyError, match="unknown suite"):
        get_suite("nope")


@pytest.mark.parametrize("name", ["quick", "full"])
def test_quick_and_full_cover_every_kind_and_the_issue_grid(name):
    suite = SUITES[name]
    full = name == "full"
    kinds = Counter(c.kind for c in suite.cases)
    expected = {"observers", "work_precision", "robustness", "scaling", "checks", "hard", "ensemble"}
    assert set(kinds) == (expected | {"peers"} if full else expected)
    assert suite.micro is not None
    obs = {c.name for c in suite.of_kind("observers")}
    exact_obs = {c.scenario for c in suite.of_kind("observers") if c.integrator == "event"}
    assert {"double_mass", "bouncing_ball", "impact_oscillator", "grazing"} <= exact_obs
    assert {"double_mass", "rocking_chain", "grazing", "bouncing_ball (Zeno)"} <= obs
    assert any("persistent" in n for n in obs)
    chain = [c for c in suite.of_kind("observers") if c.scenario == "rocking_chain"][0]
    assert dict(chain.params)["param.N"] == 10
    # work-precision: ≥ 5 step sizes per compiled method (full: ≥ 8, down to ≈ 1e-6 s), ≥ 3
    # with the cvxpy/OSQP solver (numpy engine; full: ≥ 5), both laws and both contact solvers
    wp = [c for c in suite.of_kind("work_precision") if c.integrator == "time-stepping"]
    exact = [c for c in suite.of_kind("work_precision") if c.integrator == "event"]
    # the exact integrator: one row per closed-form scenario and law, against the closed form
    assert {(c.scenario, c.law) for c in exact} == {(s, law) for s in ("bouncing_ball", "impact_oscillator")
                                                   for law in ("newton", "poisson")}
    assert all(c.reference == "closed form" for c in exact)
    methods = Counter((c.scenario, c.target, c.law, c.solver) for c in wp)
    assert min(v for k, v in methods.items() if k[3] == "pivoting") >= 5
    assert min(v for k, v in methods.items() if k[3] == "reference") >= (5 if full else 3)
    if full:
        compiled = {k: v for k, v in methods.items() if engine_for(k[3]) == "compiled"}
        assert min(compiled.values()) >= 8
        for key in compiled:
            hs = [c.h for c in wp if (c.scenario, c.target, c.law, c.solver) == key]
            assert min(hs) <= 1e-6 < 2 * min(hs)
    assert {c.law for c in wp} == {"newton", "poisson"}
    # the costly reference-solver sweeps: every law in full, Newton's alone in quick
    ref_laws = {(c.scenario, c.law) for c in wp if c.solver == "reference"}
    assert ref_laws == {(s, law) for s in {c.scenario for c in wp}
                        for law in (("newton", "poisson") if full else ("newton",))}
    assert {c.solver for c in wp} == {"pivoting", "reference"}
    assert {c.target for c in wp} == {"master", "jump", "nojump"}
    for c in wp:           # closed form where one exists, else the exact event-driven solution
        assert c.reference == ("closed form" if c.scenario in ("bouncing_ball", "impact_oscillator")
                               else "event solution")
        if c.h_record is not None:     # the grids of h and h_record nest (powers of two)
            k = max(c.h, c.h_record) / min(c.h, c.h_record)
            assert abs(k - round(k)) < 1e-9 and (round(k) & (round(k) - 1)) == 0
    # robustness: every perturbation kind at ≥ 4 levels spanning ≥ 30×, each level a
    # paired ensemble over ≥ 5 masters (full: 10) × ≥ 4 errors per master, the same seed (so the
    # same masters and errors) at every level
    rob = suite.of_kind("robustness")
    assert {c.perturbation for c in rob} == set(KINDS)
    levels = {k: sorted(c.size for c in rob if c.perturbation == k) for k in KINDS if k != "none"}
    assert all(len(v) >= 4 and v[-1] / v[0] >= 30 - 1e-9 for v in levels.values()), levels
    assert min(c.masters for c in rob) >= (10 if full else 5)
    assert min(c.members // c.masters for c in rob) >= 4
    assert {(c.seed, c.masters, c.members, c.h, c.t_end) for c in rob} == {(0, rob[0].masters, rob[0].members,
                                                                            rob[0].h, rob[0].t_end)}
    assert len({c.case_id for c in rob}) == len(rob)
    # scaling: up to N = 10⁵ in full (issue 23), from N = 5; stored rows bounded at large N
    Ns = [dict(c.params)["param.N"] for c in suite.of_kind("scaling")]
    assert Ns == ([5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10_000, 20_000, 50_000, 100_000]
                  if full else [5, 10, 20, 50, 100, 200])
    for c in suite.of_kind("scaling"):
        N = dict(c.params)["param.N"]
        assert (c.t_end / (c.h_record or c.h) + 1) * 4 * N <= 2 ** 24 + 16 * N
    if full:
        assert [c.scenario for c in suite.of_kind("peers")] == list(PROBLEMS)
        assert {c.scenario for c in suite.of_kind("checks")} == set(check_scenarios())


def test_quick_skips_poisson_reference_runs_where_they_repeat_newtons():
    """Why quick's reference-solver sweeps run Newton's law alone: on its sweeps Poisson's
    trajectory is Newton's to round-off — one contact (double_mass with its impacts) and the
    sweep's chain (N = 4, 1.5 s: several contacts, e = 0.9 on each). Should a law or a
    scenario change this, quick must run both laws again."""
    def run(name, law, **over):
        sc = observer.load_scenario(name, {"impact.law": law, "simulation.h": 1e-3, **over})
        return observer.simulate(sc, observers=(), engine="python", solver="reference")

    for name, over in (("double_mass", {"simulation.t_end": 1.0}),
                       ("rocking_chain", {"param.N": 4, "simulation.t_end": 1.5})):
        a, b = (run(name, law, **over) for law in ("newton", "poisson"))
        assert np.count_nonzero(a.P) > 10
        assert np.max(np.abs(a.q - b.q)) <= 1e-14 * np.max(np.abs(a.q)), name


def test_engine_follows_the_contact_solver():
    """Runs with the pivoting solver use the compiled kernel; the kernel has no other solver,
    so cvxpy/lemke/nnls runs use the numpy engine (they would silently use pivoting)."""
    assert engine_for("pivoting") == "compiled"
    for solver in ("reference", "lemke", "nnls"):
        assert engine_for(solver) == "python"


def test_a_case_declares_its_engine():
    """A case's ``engine`` (as ``simulate``'s) reaches its runs and its row; undeclared, the
    case id is unchanged (resumable suites) and the registry chooses; an unknown name is
    refused naming the field."""
    from bench.runners import engine_kwargs, simulate
    base = Case("observers", "impact_oscillator", t_end=0.05)
    assert "engine" not in base.case_id and engine_kwargs(base) == {}
    assert engine_kwargs(Case("observers", "impact_oscillator", solver="lemke")) == {"engine": "python"}
    assert engine_kwargs(Case("work_precision", "impact_oscillator", integrator="event")) == {}
    pinned = Case("observers", "impact_oscillator", t_end=0.05, engine="python")
    assert pinned.case_id == base.case_id + ":engine=python"
    sc = observer.load_scenario(pinned.scenario, pinned.overrides())
    res, _, _ = simulate(sc, pinned, observers=[])
    assert res.metadata["engine"] == "python"
    res, _, _ = simulate(sc, base, observers=[])
    assert res.metadata["engine"] == "compiled"
    with pytest.raises(InputError) as info:
        Case("observers", "impact_oscillator", engine="numpy")
    assert info.value.field == "engine"


def test_record_every_from_h_record():
    assert record_every(1e-3, None) == 1 and record_every(1e-3, 5e-4) == 1
    assert record_every(2e-3 / 2 ** 11, 2e-3 / 2 ** 6) == 32
    assert record_every(4e-3 / 2 ** 12 / 16, 4e-3 / 2 ** 9) == 128
    with pytest.raises(InputError, match="h_record"):
        record_every(3e-4, 1e-3)


# ----------------------------------------------------------------------------- results file
def test_case_store_write_resume_and_retire(tmp_path):
    store = CaseStore(tmp_path / "s.cases")
    assert store.rows() == [] and store.done_ids() == set() and store.files() == []
    store.write_case("s", "a", [{"x": 1.0, "t": float("inf")}, {"x": 2.0, "t": float("nan")}])
    store.write_case("s", "b", [{"x": 3.0, "note": "text"}])
    assert store.done_ids() == {"a", "b"} and store.has("a") and not store.has("c")
    # one Parquet file per case, named by the hash of its case id, nothing else in the folder
    assert sorted(p.name for p in store.folder.iterdir()) == \
        sorted(f"{case_key(c)}.parquet" for c in ("a", "b"))
    a = pd.read_parquet(store.case_path("a"))
    assert a["case_id"].tolist() == ["a", "a"] and a["row"].tolist() == [0, 1]
    assert a["case_rows"].tolist() == [2, 2] and a["suite"].tolist() == ["s", "s"]
    assert a["t"].iloc[0] == float("inf") and np.isnan(a["t"].iloc[1])
    rows = {(r["case_id"], r["row"]): r for r in store.rows()}
    assert rows[("b", 0)] == {"suite": "s", "case_id": "b", "case_rows": 1, "row": 0, "x": 3.0,
                              "note": "text"}
    # a column with a number in one row and text in another is kept (as text)
    store.write_case("s", "c", [{"x": 4.0, "m": 1.5}, {"x": 5.0, "m": "n/a"}])
    assert pd.read_parquet(store.case_path("c"))["m"].tolist() == ["1.5", "n/a"]
    assert store.retire({"b"}) == 1 and store.done_ids() == {"a", "c"}
    assert (store.folder / "stale" / f"{case_key('b')}.parquet").exists()
    assert store.retire_undeclared({"a"}) == 2 and store.done_ids() == {"a"}
    with pytest.raises(ValueError, match="reserved"):
        store.write_case("s", "d", [{"case_id": "x"}])
    with pytest.raises(ValueError, match="no rows"):
        store.write_case("s", "d", [])
    assert not store.has("d") and not list(store.folder.glob("*.tmp"))
    df = load_results([store.path])
    assert len(df) == 2 and set(df["case_id"]) == {"a"} and (df["results_dir"] == str(tmp_path)).all()


def test_orphaned_temporary_files_are_removed_only_when_old(tmp_path):
    store = CaseStore(tmp_path / "o.cases")
    store.write_case("o", "a", [{"x": 1.0}])
    old, young = store.folder / ".abc.1.tmp", store.folder / ".abc.2.tmp"
    for p in (old, young):
        p.write_bytes(b"PAR1 torn")
    os.utime(old, (time.time() - 7200, time.time() - 7200))
    assert store.remove_orphans(max_age_s=3600) == 1
    assert not old.exists() and young.exists() and store.done_ids() == {"a"}


def test_load_results_concatenates_kinds_and_refuses_other_files(tmp_path):
    store = CaseStore(tmp_path / "k.cases")
    store.write_case("k", "p", [{"kind": "one", "a": 1.0}])
    store.write_case("k", "q", [{"kind": "two", "b": "x"}])
    df = load_results([store.path]).set_index("case_id")
    assert np.isnan(df.loc["q", "a"]) and df.loc["q", "b"] == "x" and df.loc["p", "a"] == 1.0
    assert load_results([]).empty
    with pytest.raises(FileNotFoundError):
        load_results([tmp_path / "none.cases"])
    (tmp_path / "x.txt").write_text("x")
    with pytest.raises(ValueError, match="not a results"):
        load_results([tmp_path / "x.txt"])


# ----------------------------------------------------------------------------- running
@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("smoke")
    summary = run_suite("smoke", out, progress=False)
    return out, summary


def test_smoke_suite_rows_are_tidy_and_complete(smoke_run):
    out, summary = smoke_run
    assert summary.failed == [], summary.failed
    df = load_results([results_path("smoke", out)])
    assert len(df[df["kind"] != "checks"]) == smoke_rows_expected()
    assert (out / "smoke.csv").exists()
    for col in ("suite", "case_id", "kind", "scenario", "solver", "law", "h", "seed", "date",
                "git_commit", "cpu", "v_numpy", "v_observer", "v_python", "status", "cpu_time_s"):
        assert col in df.columns, col
        assert df[col].notna().all() or col == "cpu_time_s", col
    ok = df[df["status"] == "ok"]
    assert (ok["cpu_time_s"] > 0).all()
    obs = df[df["kind"] == "observers"].set_index(["name", "observer"])
    na = obs.loc[("bouncing_ball (Zeno)", "jump")]
    assert na["status"] == "n/a" and "K" in na["note"]
    dm = obs.loc[("double_mass", "jump")]
    assert dm["V_on"] > 0 and np.isfinite(dm["rate"])
    assert (out / dm["trajectory"]).exists()
    traj = pd.read_parquet(out / dm["trajectory"])
    assert {"t", "master_q", "jump_q", "nojump_q", "V_jump", "V_nojump"} <= set(traj.columns)
    wp = df[df["kind"] == "work_precision"]
    assert (wp["err_mean"] > 0).all() and wp["reference"].str.startswith("closed form").all()
    rob = df[df["kind"] == "robustness"]
    assert set(rob["perturbation"]) == {"none", "delay"}
    assert set(rob["master"]) == {0, 1} and (rob["floor"] > 0).all()
    # paired: both designs on the same (master, member) at both levels, the same initial V
    von = rob.pivot_table(index=["master", "member"], columns=["perturbation", "design"], values="V_on")
    assert von.notna().all().all() and np.allclose(von.to_numpy(), von.to_numpy()[:, :1])
    sc = df[df["kind"] == "scaling"]
    assert (sc["peak_mem_mb"] > 0).all() and (sc["cpu_per_step_s"] > 0).all()
    # the whole call (issue 23): load + simulate, at least its load part and the run's own CPU
    assert (sc["load_cpu_s"] > 0).all() and (sc["whole_call_cpu_s"] > sc["load_cpu_s"]).all()
    assert (sc["whole_call_wall_s"] > 0).all()
    # compiled engine everywhere (pivoting solver), compile time measured once and apart
    timed = df[(df["status"] == "ok") & df["kind"].isin(["observers", "work_precision", "scaling"])]
    assert (timed["engine"] == "compiled").all()
    assert (timed["run_compile_time_s"] == 0).all()               # no row paid the compile
    assert df["compile_time_s"].notna().all() and df["compile_time_s"].nunique() == 1
    assert summary.compile_time_s == pytest.approx(df["compile_time_s"].iloc[0])
    assert (timed["loop_time_s"] > 0).all() and (timed["loop_time_s"] <= timed["wall_time_s"]).all()
    # h_record: the h = 5e-4 run keeps every 2nd step, its error is measured on the 1e-3 grid
    rec = wp[wp["h"] == 5e-4].iloc[0]
    full = wp[wp["h"] == 1e-3].iloc[0]
    assert rec["error_grid_s"] == pytest.approx(1e-3) and rec["samples"] == full["samples"]
    assert rec["steps"] == 2 * full["steps"]


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.glob("*.parquet"))}


def test_rerun_of_a_finished_suite_computes_nothing(smoke_run):
    out, _ = smoke_run
    before = _snapshot(results_path("smoke", out))
    summary = run_suite("smoke", out, progress=False, micro=False)
    assert summary.ran == 0 and summary.skipped == summary.total - len(summary.unavailable)
    assert _snapshot(results_path("smoke", out)) == before


def test_interrupted_suite_resumes_without_recomputing(tmp_path, capsys):
    """Kill `python -m bench run smoke` (in-process mode) after its first finished case, then
    rerun (here, through bench's main: the same command without a second interpreter start-up
    and kernel load): the case files written before the kill are kept byte for byte, the rest
    is added, every case exactly once."""
    from bench.__main__ import main

    env = {**os.environ, "PYTHONPATH": str(REPO)}
    args = ["run", "smoke", "--out", str(tmp_path), "--no-progress", "--workers", "0"]
    cmd = [sys.executable, "-m", "bench", *args]
    store = CaseStore(results_path("smoke", tmp_path))
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None and not store.files():
            time.sleep(0.01)
        os.killpg(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    before = _snapshot(store.folder)
    done_before = store.done_ids()
    if len(done_before) >= len(SMOKE.cases) - 1:
        pytest.skip("the suite finished before it could be killed")
    assert len(done_before) >= 1
    capsys.readouterr()
    code = main(args)
    res = capsys.readouterr()
    assert code == 0, res.out + res.err
    after = _snapshot(store.folder)
    assert {k: after[k] for k in before} == before                        # not recomputed
    rows = store.rows()
    keys = [(r["case_id"], r["row"]) for r in rows]
    assert len(keys) == len(set(keys))                                    # no duplicates
    assert {r["case_id"] for r in rows} >= {c.case_id for c in SMOKE.cases if c.kind != "checks"}
    assert f"{len(done_before)} already done" in res.out


def test_limit_runs_only_the_first_cases_then_resume(tmp_path):
    suite = Suite("mini", "two tiny cases", (
        Case("work_precision", "bouncing_ball", law="newton", h=2e-3, t_end=0.5, observers=(),
             reference="closed form"),
        Case("work_precision", "bouncing_ball", law="newton", h=1e-3, t_end=0.5, observers=(),
             reference="closed form")))
    s1 = run_suite(suite, tmp_path, progress=False, limit=1)
    assert (s1.ran, s1.skipped) == (1, 0)
    store = CaseStore(results_path("mini", tmp_path))
    assert store.done_ids() == {suite.cases[0].case_id}
    first = _snapshot(store.folder)
    s2 = run_suite(suite, tmp_path, progress=False)
    assert (s2.ran, s2.skipped) == (1, 1)
    after = _snapshot(store.folder)
    assert {k: after[k] for k in first} == first and len(after) == 2 and len(store.rows()) == 2


def test_reference_solver_runs_on_the_numpy_engine(tmp_path):
    """A work-precision point with the cvxpy/OSQP solver really uses it (numpy engine), and its
    trajectory equals the compiled pivoting run's (both solve the same LCPs exactly)."""
    cases = tuple(Case("work_precision", "bouncing_ball", law="newton", solver=s, h=2e-3, t_end=1.5,
                       observers=(), reference="closed form") for s in ("pivoting", "reference"))
    summary = run_suite(Suite("eng", "", cases), tmp_path, progress=False)
    assert summary.failed == []
    rows = load_results([results_path("eng", tmp_path)]).set_index("solver")
    assert rows.loc["pivoting", "engine"] == "compiled" and rows.loc["reference", "engine"] == "python"
    assert rows.loc["reference", "contact_solves"] > 0
    assert rows.loc["reference", "err_mean"] == pytest.approx(rows.loc["pivoting", "err_mean"], rel=1e-6)


def _dm_sweep(hs, target="jump", t_end=0.5):
    """double_mass work-precision cases of one sweep against the event solution."""
    return [Case("work_precision", "double_mass", law="newton", h=h, t_end=t_end,
                 observers=() if target == "master" else (target,), target=target,
                 reference="event solution") for h in hs]


def test_a_sweep_shares_one_event_reference_on_its_finest_grid(tmp_path):
    """The cases of one sweep (scenario, law, horizon, measured trajectory) are one reference
    group whose grid is the finest error grid among them (h, or h_record when coarser); the
    reference is computed once per process on it, and every k-th sample of it equals the
    event-driven run made directly on the coarser grid to round-off (the event integrator
    samples the exact flow at t_k = k·h)."""
    jump = _dm_sweep((4e-3, 2e-3, 1e-3))
    fine = _dm_sweep((4e-3 / 2 ** 4,))[0]
    recorded = replace(fine, h_record=4e-3 / 2 ** 2)          # error grid 1e-3, not h
    master = _dm_sweep((4e-3, 2e-3), target="master")
    grids = reference_grids(jump + [recorded] + master)
    assert grids == {reference_group(jump[0]): pytest.approx(1e-3),
                     reference_group(master[0]): pytest.approx(2e-3)}
    assert reference_group(recorded) == reference_group(jump[0]) != reference_group(master[0])
    assert reference_group(master[0])[-1] == () and reference_group(jump[0])[-1] == ("jump",)

    ctx = Context("t", tmp_path, {}, cache={}, reference_grids=grids)
    coarse = _event_reference(jump[0], 4e-3, ctx)
    assert len(ctx.cache) == 1 and coarse.spacing == pytest.approx(4e-3)
    assert _event_reference(jump[1], 2e-3, ctx).t.size == 251 and len(ctx.cache) == 1  # no new run
    sc = observer.load_scenario("double_mass", {"impact.law": "newton", "simulation.h": 4e-3,
                                                "simulation.t_end": 0.5})
    direct = observer.simulate(sc, observers=("jump",), integrator="event")
    assert coarse.t.shape == direct.t.shape and np.max(np.abs(coarse.t - direct.t)) <= 1e-15
    scale = np.max(np.abs(direct.q))
    assert np.max(np.abs(coarse.q - direct.q)) <= 1e-12 * scale
    assert np.max(np.abs(coarse.slaves["jump"] - direct.slaves["jump"].q)) <= 1e-12 * scale
    # a grid the group's finest one does not divide gets its own run
    odd = _event_reference(replace(jump[0], h=2.5e-3), 2.5e-3, ctx)
    assert odd.spacing == pytest.approx(2.5e-3) and len(ctx.cache) == 2


def test_peer_row_says_what_the_trajectory_difference_is_compared_with():
    """The peer row's difference is only meaningful next to the size of the motion and the
    number of impulse steps (both recomputed here from the toolkit's own run, which the row
    says equals Siconos' to max_abs_diff)."""
    from bench import peers

    ok, why = peers.siconos_available()
    if not ok:
        pytest.skip(f"Siconos absent: {why}")
    problem = peers.peer_problem("impact_oscillator", h=1e-3)
    row = peers.run_peer(problem, steps=3000, repeats=1).iloc[0]
    res = observer.simulate(observer.load_scenario("impact_oscillator", {
        **problem["overrides"], "simulation.t_end": 3000 * 1e-3}))
    tol = row["max_abs_diff_q"] + 1e-15
    assert row["max_abs_q"] == pytest.approx(np.max(np.abs(res.q)), abs=tol) and row["max_abs_q"] > 0.1
    assert row["impulse_steps"] == np.count_nonzero(np.any(res.P != 0.0, axis=1)) > 0


def test_kernel_ready_leaves_nothing_to_compile_for_the_suites_runs():
    """After :func:`bench.run.kernel_ready` no run of a built-in scenario (master alone, with
    its observers, another horizon) adds a compiled signature to any kernel function, so no
    timed case pays numba's compile time. Checked in a fresh process (numba loads from its
    disk cache there; in this process other tests may have compiled everything already)."""
    script = """
import json, observer, observer.engines.compiled.kernel as K, observer.primitives as P
from bench.run import kernel_ready
from observer.scenarios import SCENARIOS
kernel_ready()
count = lambda: {n: len(f.signatures) for m in (K, P) for n, f in vars(m).items() if hasattr(f, "signatures")}
before = count()
for name in SCENARIOS:
    sc = observer.load_scenario(name)
    sc = sc.with_overrides({"simulation.t_end": 37 * sc.h})
    observer.simulate(sc, observers=())
    observer.simulate(sc, observers=(), record_every=4)
    if sc.observer:
        observer.simulate(sc)
print(json.dumps([before, count()]))
"""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    out = subprocess.run([sys.executable, "-c", script], cwd=REPO, env=env, capture_output=True,
                         text=True, check=True).stdout
    before, after = json.loads(out.strip().splitlines()[-1])
    assert sum(before.values()) > 0 and after == before


def test_failed_case_is_reported_and_retried(tmp_path):
    bad = Case("work_precision", "double_mass", law="newton", h=1e-3, t_end=0.1, observers=(),
               reference="closed form")                                   # no closed form exists
    summary = run_suite(Suite("bad", "", (bad,)), tmp_path, progress=False)
    assert summary.ran == 0 and len(summary.failed) == 1
    assert "closed form" in summary.failed[0][1]
    assert CaseStore(results_path("bad", tmp_path)).done_ids() == set()


def test_cli_list_show_status(tmp_path, capsys):
    """``list`` and ``status`` through bench's main (in this process), the refused suite as
    ``python -m bench`` in a subprocess (the interpreter's exit status)."""
    from bench.__main__ import main

    capsys.readouterr()
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "quick" in out and "full" in out and "smoke" in out
    assert main(["status", "smoke", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"0/{len(SMOKE.cases)}" in out
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    bad = subprocess.run([sys.executable, "-m", "bench", "run", "nope"], cwd=REPO, env=env,
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "unknown suite" in bad.stderr


@pytest.mark.parametrize("value", ["-1", "two"])
def test_cli_refuses_a_bad_worker_count(value, capsys):
    from bench.__main__ import main

    with pytest.raises(SystemExit) as ei:
        main(["run", "smoke", "--workers", value])
    assert ei.value.code == 2
    assert "--workers" in capsys.readouterr().err


# ----------------------------------------------------------------------------- perturbations
@pytest.fixture
def log():
    rows = [(0, 0.10, 0.10), (0, 0.50, 0.50), (0, 1.00, 1.60), (0, 2.00, 2.00), (0, 2.40, 2.40),
            (0, 3.00, 3.00), (1, 0.70, 0.70), (1, 1.20, 1.90), (1, 2.50, 2.50), (1, 3.30, 3.30)]
    return pd.DataFrame(rows, columns=["contact", "t_close", "t_open"])


def _perturb(log, kind, size, seed=0):
    return perturb_log(log, kind, size, seed=seed, m=2, t_end=4.0, h=1e-3)


def test_delay_shifts_every_interval(log):
    out = _perturb(log, "delay", 0.05)
    assert np.allclose(out["t_close"] - log["t_close"], 0.05)
    assert np.allclose(out["t_open"] - log["t_open"], 0.05)


def test_jitter_is_seeded_and_valid(log):
    a, b, c = _perturb(log, "jitter", 0.2, 3), _perturb(log, "jitter", 0.2, 3), _perturb(log, "jitter", 0.2, 4)
    pd.testing.assert_frame_equal(a, b)
    assert not a.equals(c)
    validate_log(a, 2)                                  # sorted, no overlaps, t_open ≥ t_close
    assert a["t_close"].min() >= 0 and a["t_open"].max() <= 4
    assert not np.allclose(a["t_close"].to_numpy()[:3], log["t_close"].to_numpy()[:3])


def test_missed_drops_closings_and_impacts_alike(log):
    """p = 1 sees nothing, p = 0 everything; in between the kept rows are rows of the log
    (a persistent closing can be missed too: the sensor's probability per closing)."""
    assert len(_perturb(log, "missed", 1.0)) == 0
    pd.testing.assert_frame_equal(_perturb(log, "missed", 0.0), log.astype({"t_close": float, "t_open": float}))
    kept = [_perturb(log, "missed", 0.5, seed) for seed in range(20)]
    rows = set(map(tuple, log.to_numpy()))
    assert all(set(map(tuple, k.to_numpy())) <= rows for k in kept)
    persistent = log[(log["t_open"] - log["t_close"]) > 1e-3]
    assert any(len(k.merge(persistent)) < len(persistent) for k in kept)


def test_false_closings_only_where_the_contact_is_open(log):
    out = _perturb(log, "false", 20.0, 2)
    assert len(out) > len(log)
    validate_log(out, 2)
    extra = out.merge(log, how="left", indicator=True)
    extra = extra[extra["_merge"] == "left_only"]
    assert (extra["t_open"] == extra["t_close"]).all()
    for _, r in extra.iterrows():
        mine = log[log["contact"] == r["contact"]]
        assert not ((mine["t_close"] <= r["t_close"]) & (r["t_close"] <= mine["t_open"])).any()


def test_unknown_perturbation_is_an_error(log):
    with pytest.raises(ValueError, match="unknown perturbation"):
        _perturb(log, "noise", 1.0)


def _legacy_perturb(log, kind, size, rng, m, t_max, h):
    """The robustness suite's perturbations before they became sensor settings (issue 33),
    written out again: delay, jitter and false closings (the draws in the same order), then
    clipping to [0, t_max] and merging per contact."""
    tc, to = log["t_close"].to_numpy(float).copy(), log["t_open"].to_numpy(float).copy()
    c = log["contact"].to_numpy()
    if kind == "delay":
        tc, to = tc + size, to + size
    elif kind == "jitter":
        d_close = rng.normal(0.0, size, tc.shape)
        d_open = np.where((to - tc) <= h, d_close, rng.normal(0.0, size, to.shape))
        tc, to = tc + d_close, np.maximum(to + d_open, tc + d_close)
    elif kind == "false":
        count = rng.poisson(size * t_max)
        times, contacts = np.sort(rng.uniform(0.0, t_max, count)), rng.integers(0, m, count)
        add = [(j, t) for t, j in zip(times, contacts)
               if not np.any((c == j) & (log["t_close"].to_numpy() <= t) & (t <= log["t_open"].to_numpy()))]
        c = np.concatenate([c, [j for j, _ in add]]).astype(int)
        tc = np.concatenate([tc, [t for _, t in add]])
        to = np.concatenate([to, [t for _, t in add]])
    rows = []
    for j in sorted(set(c.tolist())):
        iv = sorted(zip(np.clip(tc[c == j], 0.0, t_max), np.clip(to[c == j], 0.0, t_max)), key=lambda x: x[0])
        merged = []
        for a, b in iv:
            if merged and a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        rows += [(j, a, b) for a, b in merged]
    return pd.DataFrame(rows, columns=["contact", "t_close", "t_open"])


def test_the_suite_s_delay_jitter_and_false_logs_are_those_before_the_sensor():
    """The robustness suite's delay, jitter and false-closing logs (its quick levels, seeds 0–2,
    on a master's own log of double_mass) are, to the bit, those of its perturbations before
    they were sensor settings: its results are unchanged there. (``missed`` changed meaning:
    a probability per closing, no longer a fraction of the impacts.)"""
    from bench.suites import ROBUSTNESS_LEVELS
    from observer.switching import log_from_active

    res = observer.simulate("double_mass", h=1e-3, t_end=4.0)
    base = log_from_active(res.t, res.active)
    assert len(base) > 10
    checked = 0
    for kind in ("delay", "jitter", "false"):
        sizes = ROBUSTNESS_LEVELS["quick"].get(kind, ROBUSTNESS_LEVELS["full"][kind])
        for size in sizes:
            for seed in range(3 if kind in RANDOM_KINDS else 1):
                new = perturb_log(base, kind, size, seed=seed, m=1, t_end=4.0, h=1e-3)
                old = _legacy_perturb(base, kind, size, np.random.default_rng(seed), 1, 4.0, 1e-3)
                assert np.array_equal(new.to_numpy(), old.to_numpy()), (kind, size, seed)
                checked += 1
    assert checked >= 6
    moved = perturb_log(base, "jitter", 1e-3, seed=0, m=1, t_end=4.0, h=1e-3)
    nudged = _legacy_perturb(base, "jitter", 1e-3, np.random.default_rng(1), 1, 4.0, 1e-3)
    assert not np.array_equal(moved.to_numpy(), nudged.to_numpy())     # a near miss: another seed


# ----------------------------------------------------------------------------- references
def test_ball_closed_form():
    h0, g, e = 1.0, 9.81, 0.8
    tk = bb.impact_times(h0, g, e, 8)
    assert np.allclose(ball_position(tk, h0, g, e), 0.0, atol=1e-12)
    t = np.array([0.0, 0.2])
    assert np.allclose(ball_position(t, h0, g, e), h0 - 0.5 * g * t ** 2)
    apex = tk[0] + e * np.sqrt(2 * g * h0) / g                 # apex after the first rebound
    assert ball_position(np.array([apex]), h0, g, e)[0] == pytest.approx(e ** 2 * h0, rel=1e-12)
    assert ball_position(np.array([bb.accumulation_time(h0, g, e) + 0.1]), h0, g, e)[0] == 0.0


def test_exact_impact_oscillator_reproduces_the_periodic_orbit():
    """docs/theory/oracles.md §2: ω = 2.8, r = 0.8, σ = 0 has the (1,1) orbit V = 0.336177, t0 = 1.092635,
    T = 2π/ω. Started just after an impact on it, the exact solution hits again after T
    with the same velocity."""
    om, r, V, t0 = 2.8, 0.8, 0.336177, 1.092635
    T = 2 * np.pi / om
    ex = ExactImpactOscillator(1.0, om, 0.0, 0.0, r, 0.0, -r * V, t0, t0 + 3.5 * T)
    assert ex.impacts.shape[0] == 3
    # the orbit data have 6 digits, and the orbit amplifies that error a little per period
    assert abs(ex.impacts[0, 0] - (t0 + T)) <= 2e-6 and abs(ex.impacts[0, 1] - V) <= 2e-6
    assert np.allclose(np.diff(np.r_[t0, ex.impacts[:, 0]]), T, atol=2e-5)
    assert np.allclose(ex.impacts[:, 1], V, atol=2e-5)
    x, v = ex(np.array([t0 + 0.5 * T]))
    assert x[0] < 0.0                                            # inside the admissible set


def test_closed_form_position_dispatch():
    import observer
    assert closed_form_position(observer.load_scenario("double_mass"), np.linspace(0, 1, 3)) is None
    sc = observer.load_scenario("impact_oscillator", {"simulation.t_end": 2.0})
    q = closed_form_position(sc, np.linspace(0, 2, 5))
    assert q.shape == (5, 1) and q[0, 0] == pytest.approx(sc.q0[0])


# ----------------------------------------------------------------------------- micro
def test_micro_benchmarks_run_as_tests():
    """The micro-benchmarks are also correctness tests (each asserts its residual); run them
    once each with timing disabled."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    res = subprocess.run([sys.executable, "-m", "pytest", "bench/micro", "-q", "-p", "no:cacheprovider",
                          "--benchmark-disable"], cwd=REPO, env=env, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert " passed" in res.stdout


# ----------------------------------------------------------------------------- settling times
def _settling_by_loop(t, V, rho, t_on, t_off):
    """Settling time by its definition, sample by sample: the earliest window sample from which
    every later window sample has V ≤ ρ·V(t_on)."""
    window = [k for k in range(len(t)) if t_on <= t[k] <= t_off]
    level = rho * V[window[0]]
    for pos, k in enumerate(window):
        if all(V[j] <= level for j in window[pos:]):
            return t[k] - t[window[0]]
    return float("inf")


def test_settling_time_waits_for_the_last_excursion():
    """V = e^{−t} with a bump back above 1e-3 on [9, 9.5): the first passage of 1e-3 is at
    ln(1000) ≈ 6.91 s, the settling time at 9.5 s; below 1e-5 V never gets before the bump
    and settles after it; ρ above V's end value but below its bump → the bump's end."""
    from observer.metrics import excursions_after_passage, settling_time, sync_time

    t = np.round(np.arange(0.0, 20.0 + 1e-9, 0.01), 10)
    V = np.exp(-t)
    bump = (t >= 9.0) & (t < 9.5)
    V[bump] = 2e-3
    assert sync_time(t, V, 1e-3) == pytest.approx(np.ceil(np.log(1e3) * 100) / 100)
    assert settling_time(t, V, 1e-3) == pytest.approx(9.5)
    assert settling_time(t, V, 1e-5) == pytest.approx(np.ceil(np.log(1e5) * 100) / 100)
    # the fraction of samples after the first passage that are above: the 50 bump samples
    after = t[t > sync_time(t, V, 1e-3)].size
    assert excursions_after_passage(t, V, 1e-3) == pytest.approx(50 / after)
    assert excursions_after_passage(t, V, 1e-5) == 0.0
    assert np.isnan(excursions_after_passage(t, V, 1e-12))
    # ends above the threshold: never; never above (ρ ≥ 1): 0
    assert settling_time(t, V, 1e-12) == np.inf
    assert settling_time(t, V, 1.0) == 0.0
    # window: from t_on = 2 (V0 = e^{-2}) to t_off = 9.2 (inside the bump): never settles
    assert settling_time(t, V, 1e-3, 2.0, 9.2) == np.inf
    # window [2, 12]: V0 = e^{-2}, first passage at 2 + ln(1000), settled after the bump
    assert sync_time(t, V, 1e-3, 2.0, 12.0) == pytest.approx(np.ceil(np.log(1e3) * 100) / 100)
    assert settling_time(t, V, 1e-3, 2.0, 12.0) == pytest.approx(9.5 - 2.0)
    assert settling_time(t, V, 1e-3, 2.0, 8.0) == np.inf      # not even reached by t_off
    for rho in (1e-2, 1e-3, 1e-5, 1e-9):
        for t_on, t_off in ((0.0, 20.0), (2.0, 9.2), (1.0, 15.0)):
            assert settling_time(t, V, rho, t_on, t_off) == pytest.approx(
                _settling_by_loop(t, V, rho, t_on, t_off), abs=1e-9)


def test_observer_rows_carry_settling_times_recomputed_from_V(tmp_path):
    """On a real run (double_mass, jump observer, coupled from t_on = 0.1 s), every t_settle
    and t_sync column of the row equals the definition applied sample by sample to V."""
    import observer
    from bench.runners import sync_metrics

    sc = observer.load_scenario("double_mass", {"simulation.h": 2e-3, "simulation.t_end": 2.0,
                                                "observer.coupling": [0.1, 1.8]})
    res = observer.simulate(sc, observers=["jump"])
    row = sync_metrics(res, "jump")
    assert (row["t_on"], row["t_off"]) == (0.1, 1.8)
    V = res.slaves["jump"].V
    win = [k for k in range(res.t.size) if 0.1 <= res.t[k] <= 1.8]
    reached = 0
    for rho in (1e-3, 1e-5, 1e-6, 1e-9):
        first = next((res.t[k] - res.t[win[0]] for k in win if V[k] <= rho * V[win[0]]), np.inf)
        assert row[f"t_sync_{rho:g}"] == pytest.approx(first, abs=1e-12)
        assert row[f"t_settle_{rho:g}"] == pytest.approx(
            _settling_by_loop(res.t, V, rho, 0.1, 1.8), abs=1e-12)
        assert row[f"t_settle_{rho:g}"] >= row[f"t_sync_{rho:g}"]
        reached += np.isfinite(row[f"t_settle_{rho:g}"])
    assert reached >= 1                        # not a comparison of two infinities only


def _write_with_checksum(frame: pd.DataFrame, path: Path) -> None:
    """``frame`` as a case file whose checksum matches (:func:`bench.results.content_digest`)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from bench.results import CHECKSUM_KEY, content_digest

    table = pa.Table.from_pandas(frame, preserve_index=False).replace_schema_metadata(None)
    pq.write_table(table.replace_schema_metadata({CHECKSUM_KEY: content_digest(table).encode()}), path)


def test_rows_without_settling_times_are_rerun(tmp_path):
    """An observers case written before the settling columns existed is moved to the stale
    file and run again; other cases are kept."""
    obs = Case("observers", "double_mass", h=2e-3, t_end=0.2)
    wp = Case("work_precision", "bouncing_ball", law="newton", h=2e-3, t_end=0.2, observers=(),
              reference="closed form")
    suite = Suite("old", "", (obs, wp))
    run_suite(suite, tmp_path, progress=False, micro=False)
    store = CaseStore(results_path("old", tmp_path))
    path = store.case_path(obs.case_id)
    old = pd.read_parquet(path)
    old = old.drop(columns=[c for c in old.columns if c.startswith(("t_settle_", "above_after_"))])
    _write_with_checksum(old, path)          # whole, as that version wrote it: not damaged
    wp_bytes = store.case_path(wp.case_id).read_bytes()
    summary = run_suite(suite, tmp_path, progress=False, micro=False)
    assert summary.ran == 1 and summary.skipped == 1 and summary.stale_rows == 2
    new = store.rows()
    assert all("t_settle_1e-09" in r for r in new if r["kind"] == "observers")
    assert store.case_path(wp.case_id).read_bytes() == wp_bytes          # kept as it was
    stale = pd.read_parquet(store.folder / "stale" / path.name)
    assert len(stale) == 2 and not any(c.startswith("t_settle_") for c in stale.columns)


def test_ensembles_cover_the_paper_scenarios_at_its_sizes():
    """Issue 31: the chain's ensemble at the paper's N = 10 (full: N swept 4, 6, 8, 10), the
    ball on a spring (K > 0) beside the K = 0 ball, grazing on more than one step h, and the
    random family; at N = 4 the master closes no contact in the window, so the quick suite has
    no chain ensemble there."""
    import observer

    for name, Ns in (("quick", {10}), ("full", {4, 6, 8, 10})):
        ens = get_suite(name).of_kind("ensemble")
        chain = [c for c in ens if c.scenario == "rocking_chain"]
        assert {dict(c.params)["param.N"] for c in chain} == Ns, name
        assert all(f"N = {dict(c.params)['param.N']}" in c.label for c in chain)
        balls = {c.label: c for c in ens if c.scenario == "bouncing_ball"}
        spring = [c for c in balls.values() if dict(c.params).get("param.k", 0.0) > 0.0]
        assert len(spring) == 1 and "bouncing_ball (Zeno)" in balls, name
        sc = observer.load_scenario("bouncing_ball", spring[0].overrides())
        assert sc.system.is_stiffness_definite()
        assert not observer.load_scenario("bouncing_ball", balls["bouncing_ball (Zeno)"].overrides()) \
            .system.is_stiffness_definite()
        assert len({c.h for c in ens if c.scenario == "grazing"}) >= 2, name
        assert len({c.label for c in ens if c.scenario == "random_system"}) >= 4, name
