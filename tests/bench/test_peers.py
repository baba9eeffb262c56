"""The peer suite (``bench.peers``): Siconos and the toolkit on the same problems.

* Without Siconos the API says so (and how to get it) in its rows and never raises.
* The peer problems are the built-in scenarios: the same matrices, and, for the chain in
  the ground frame, the same continuous system as the built-in moving-ground chain
  (forces and gaps transformed exactly, checked against the built-in's own signals).
* With Siconos installed (``apt-get install python3-siconos``; not a CI requirement, so
  these tests skip without it): the driver reproduces the stored Siconos oracle
  ``generated/two_contact_theta0.5`` and every peer problem's trajectory equals the
  toolkit's to ≤ 1e-9 (Newton law), with contacts closing in the compared window.
"""

from __future__ import annotations

import importlib.util
import json
import sys

import numpy as np
import pytest
from oracles import oracle

import observer
from bench import peers
from bench.results import ResultsFile
from bench.run import results_path, run_suite, unavailable_path
from bench.runners import PEER_REPEATS
from bench.suites import SUITES, Case, Suite
from observer.errors import InputError
from observer.scenarios import rocking_chain

TRAJECTORY_TOL = 1e-9
"""Acceptance of issue 9: trajectories equal to Siconos' to ≤ 1e-9 (Newton law)."""

ORACLE_TOL = 1e-13
"""The driver against its stored oracle run (same Siconos build; measured 2e-15)."""

HAVE_SICONOS, SICONOS_INFO = peers.siconos_available()
needs_siconos = pytest.mark.skipif(not HAVE_SICONOS, reason=f"Siconos not available: {SICONOS_INFO}")


# ------------------------------------------------------------------------ Siconos absent
@pytest.fixture
def no_siconos(monkeypatch):
    monkeypatch.setattr(peers, "SICONOS_PYTHON", "/nonexistent/bin/python3")


def test_missing_interpreter_is_reported_with_how_to_get_it(no_siconos):
    ok, info = peers.siconos_available()
    assert ok is False
    assert "/nonexistent/bin/python3" in info and peers.HOW_TO_GET in info


def test_siconos_record_of_a_missing_interpreter(no_siconos):
    assert peers.siconos_record() == {
        "available": False, "version": None, "python": "/nonexistent/bin/python3",
        "reason": f"no interpreter at /nonexistent/bin/python3; {peers.HOW_TO_GET}",
        "how_to_get": peers.HOW_TO_GET}


def test_siconos_record_probes_once_per_interpreter(monkeypatch):
    """A suite run writes the record at every start: the subprocess runs once per
    interpreter and process, and a caller's changes do not reach the cached answer."""
    calls = []

    def probe(python=None):
        calls.append(python)
        return True, f"1.0 ({python})"
    monkeypatch.setattr(peers, "_RECORDS", {})
    monkeypatch.setattr(peers, "siconos_available", probe)
    first = peers.siconos_record("/a/python3")
    first["version"] = "changed"
    assert peers.siconos_record("/a/python3") == {"available": True, "version": "1.0 (/a/python3)",
                                                  "reason": None, "python": "/a/python3",
                                                  "how_to_get": peers.HOW_TO_GET}
    assert peers.siconos_record("/b/python3")["version"] == "1.0 (/b/python3)"
    assert calls == ["/a/python3", "/b/python3"]


@needs_siconos
def test_siconos_record_of_the_installed_siconos():
    rec = peers.siconos_record()
    assert rec["available"] is True and rec["version"] == SICONOS_INFO and rec["reason"] is None


@pytest.mark.skipif(importlib.util.find_spec("siconos") is not None,
                    reason="the test interpreter itself has Siconos")
def test_interpreter_without_siconos_is_reported():
    ok, info = peers.siconos_available(sys.executable)
    assert ok is False
    assert "cannot import siconos" in info and peers.HOW_TO_GET in info


def test_run_peers_without_siconos_gives_status_rows(no_siconos):
    df = peers.run_peers(steps={name: 10 for name in peers.PROBLEMS}, repeats=1)
    assert list(df["problem"]) == list(peers.PROBLEMS)
    assert list(df.columns) == list(peers.COLUMNS)
    assert df["status"].str.startswith("siconos absent: ").all()
    assert df["status"].str.contains(peers.HOW_TO_GET, regex=False).all()
    timing = df[["siconos_ns_per_step", "toolkit_ns_per_step", "ratio", "max_abs_diff_q"]]
    assert timing.isna().all().all()
    assert list(df["n"]) == [1, 2, 20] and list(df["m"]) == [1, 1, 20]


# ------------------------------------------------------------------------ problem builders
@pytest.mark.parametrize("name", peers.PROBLEMS)
def test_problem_has_the_builtin_matrices(name):
    problem = peers.peer_problems()[name]
    builtin = observer.load_scenario(name).system
    for key in ("M", "C", "K", "W"):
        np.testing.assert_array_equal(np.array(problem[key]), getattr(builtin, key), err_msg=key)
    np.testing.assert_array_equal(problem["gap_offset"], builtin.gap.constant)
    np.testing.assert_array_equal(problem["forcing"]["constant"], builtin.forcing.constant)
    assert problem["h"] == observer.load_scenario(name).h


def test_oscillator_problem_is_the_builtin():
    p = peers.peer_problems()["impact_oscillator"]
    sc = observer.load_scenario("impact_oscillator")
    assert sc.law.law == "newton"
    np.testing.assert_array_equal(p["forcing"]["amplitude"], sc.system.forcing.amplitude[0])
    assert p["forcing"]["omega"] == sc.system.forcing.omega[0]
    assert (p["q0"], p["u0"], p["restitution"]) == (sc.q0.tolist(), sc.u0.tolist(), [0.8])
    assert (p["T"], p["theta"]) == (sc.t_end, 0.5)


def test_double_mass_problem_drops_mass_1_from_1mm():
    p = peers.peer_problems()["double_mass"]
    sc = observer.load_scenario("double_mass")
    np.testing.assert_array_equal(p["q0"], sc.q0 + [peers.DROP, 0.0])
    assert p["u0"] == [0.0, 0.0] and p["restitution"] == [0.8]
    np.testing.assert_array_equal(p["forcing"]["amplitude"], [0.0, 5.0])
    assert p["forcing"]["omega"] == 6.0


def _ground(t):
    """Ground height y_g = Y sin Ωt of the built-in chain and its derivatives."""
    Y, Om = (rocking_chain.PARAMETERS[k] for k in ("Y", "Omega"))
    return Y * np.sin(Om * t), Y * Om * np.cos(Om * t), -Y * Om ** 2 * np.sin(Om * t)


def test_ground_frame_chain_is_the_moving_ground_chain():
    """q = q̃ + y_g e: the built-in's force minus M e ÿ_g + C e ẏ_g + K e y_g is the
    ground-frame force, and the built-in's gaps at q equal the ground-frame gaps at q̃."""
    N = 3
    moving = observer.load_scenario("rocking_chain", {"param.N": N}).system
    sc = observer.load_scenario("rocking_chain", peers.chain_ground_frame_overrides(N))
    ground = sc.system
    e = np.tile([1.0, 0.0], N)
    rng = np.random.default_rng(7)
    for t in rng.uniform(0.0, 8.0, 5):
        y, yd, ydd = _ground(t)
        expected = moving.f(t) - moving.M @ e * ydd - moving.C @ e * yd - moving.K @ e * y
        np.testing.assert_allclose(ground.f(t), expected, rtol=0, atol=1e-12)
        q = rng.normal(size=2 * N)
        np.testing.assert_allclose(ground.gaps(q - y * e, t), moving.gaps(q, t), rtol=0, atol=1e-15)
    assert np.all(ground.gap.amplitude == 0.0)
    _, yd0, _ = _ground(0.0)
    moving_sc = observer.load_scenario("rocking_chain", {"param.N": N})
    np.testing.assert_array_equal(sc.q0, moving_sc.q0)
    np.testing.assert_allclose(sc.u0, moving_sc.u0 - yd0 * e, rtol=0, atol=1e-15)


def test_problem_from_scenario_names_what_siconos_cannot_take():
    with pytest.raises(InputError, match="^impact.law"):
        peers.problem_from_scenario(observer.load_scenario("rocking_chain"))
    with pytest.raises(InputError, match="^system.gap"):
        peers.problem_from_scenario(observer.load_scenario("rocking_chain", {"impact.law": "newton"}))
    two = observer.load_scenario("impact_oscillator", {"system.forcing.harmonics": [
        {"amplitude": [0.5], "omega": 1.0, "phase": 0.0}]})
    with pytest.raises(InputError, match="^system.forcing"):
        peers.problem_from_scenario(two)
    with pytest.raises(InputError, match="^problem"):
        peers.peer_problem("grazing")


# ------------------------------------------------------------------------ with Siconos
@needs_siconos
def test_driver_reproduces_the_stored_siconos_run():
    folder = oracle("siconos", "generated")
    problem = json.loads((folder / "two_contact_theta0.5.json").read_text())
    ref = np.loadtxt(folder / "two_contact_theta0.5.csv", delimiter=",", skiprows=1)
    out = peers.run_siconos(problem)
    mine = np.column_stack([out["t"], out["q"], out["u"], out["P"]])
    assert mine.shape == ref.shape
    assert np.max(np.abs(mine - ref)) <= ORACLE_TOL
    assert np.all(np.any(ref[:, 7:] != 0.0, axis=0))     # both contacts carry impulses


PEER_WINDOWS = {"impact_oscillator": dict(h=1e-3, steps=2000),
                "double_mass": dict(h=1e-4, steps=2000),
                "rocking_chain": dict(h=1e-3, steps=2000)}
"""Short windows (≤ 2000 steps) in which contacts close: the oscillator's first impact,
double_mass' landing Zeno sequence, the chain's first rocking (from t ≈ 1 s)."""


@needs_siconos
@pytest.mark.parametrize("name", peers.PROBLEMS)
def test_toolkit_trajectory_equals_siconos(name):
    w = PEER_WINDOWS[name]
    problem = peers.peer_problem(name, h=w["h"], t_end=w["steps"] * w["h"], N=4)
    sic = peers.run_siconos(problem)
    sc = observer.load_scenario(name, problem["overrides"])
    res = observer.simulate(sc)
    assert res.t.shape == (w["steps"] + 1,) and np.array_equal(res.t, sic["t"])
    assert np.count_nonzero(sic["P"]) > 0                 # contacts closed in the window
    assert np.max(np.abs(res.q - sic["q"])) <= TRAJECTORY_TOL
    assert np.max(np.abs(res.u - sic["u"])) <= TRAJECTORY_TOL
    assert np.max(np.abs(res.P - sic["P"])) <= TRAJECTORY_TOL


@needs_siconos
def test_run_peer_row():
    problem = peers.peer_problem("impact_oscillator", h=1e-3)
    row = peers.run_peer(problem, steps=2000, repeats=1).iloc[0]
    assert row["status"] == "ok" and row["steps"] == 2000 and row["h"] == 1e-3
    assert row["siconos_ns_per_step"] > 0 and row["toolkit_ns_per_step"] > 0
    assert row["ratio"] == pytest.approx(row["siconos_ns_per_step"] / row["toolkit_ns_per_step"])
    assert row["siconos_forcing"] == "fExt written every step"
    assert row["siconos_run_ns_per_step"] > 0
    assert row["max_abs_diff_q"] <= TRAJECTORY_TOL and row["max_abs_diff_u"] <= TRAJECTORY_TOL
    assert row["siconos_version"] == SICONOS_INFO


# ------------------------------------------------------------------------ the bench suite
PEER_CASE = Case("peers", "impact_oscillator", observers=(), law="newton", h=1e-3, t_end=2.0)


def test_peers_suite_declares_the_three_problems():
    cases = SUITES["peers"].cases
    assert [c.scenario for c in cases] == list(peers.PROBLEMS)
    assert all(c.kind == "peers" and c.law == "newton" and c.observers == () for c in cases)
    assert dict(cases[-1].params)["param.N"] == 10
    assert [c.case_id for c in SUITES["full"].of_kind("peers")] == [c.case_id for c in cases]


def test_peer_case_without_siconos_writes_no_row_and_says_how_to_get_it(no_siconos, tmp_path):
    summary = run_suite(Suite("pe", "", (PEER_CASE,)), tmp_path, progress=False)
    assert summary.ran == 0 and summary.failed == []
    (cid, msg), = summary.unavailable
    assert cid == PEER_CASE.case_id and msg.startswith("Siconos absent") and peers.HOW_TO_GET in msg
    folder = results_path("pe", tmp_path)              # at most the case's lock, no case file
    assert not folder.exists() or not list(folder.glob("*.parquet*"))
    assert peers.HOW_TO_GET in unavailable_path("pe", tmp_path).read_text()


@needs_siconos
def test_peer_case_row(tmp_path):
    """One suite row per peer case: both timings, their ratio recomputed, the trajectory
    difference within the acceptance, the compiled engine on the toolkit side."""
    summary = run_suite(Suite("pe", "", (PEER_CASE,)), tmp_path, progress=False)
    assert summary.failed == [] and summary.unavailable == [] and summary.ran == 1
    row = ResultsFile(results_path("pe", tmp_path)).rows()[0]
    assert row["kind"] == "peers" and row["problem"] == "impact_oscillator" and row["status"] == "ok"
    assert row["steps"] == 2000 and row["repeats"] == PEER_REPEATS
    assert row["toolkit_engine"] == "compiled"
    assert row["ratio"] == pytest.approx(row["siconos_ns_per_step"] / row["toolkit_ns_per_step"])
    assert 0 < row["toolkit_loop_ns_per_step"] <= row["toolkit_ns_per_step"]
    assert max(row["max_abs_diff_q"], row["max_abs_diff_u"]) <= TRAJECTORY_TOL
    assert row["compile_time_s"] >= 0
