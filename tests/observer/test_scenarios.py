"""Built-in scenarios: the rocking-chain builder, invariances, show/run round trips,
overrides and result I/O.

External numbers come from docs/theory/models.md (§1.2 double mass, §2.3/§2.4 chain).
All runs are short (t_end ≤ 2 s at h = 1e-3, or 0.05 s at the scenario's own h).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.linalg as sla

import observer
from observer import SCENARIOS, InputError, load_scenario, simulate
from observer.contact.lcp import block_principal_pivoting, lcp_residual, lemke
from observer.result import read_frame, write_frame
from observer.scenarios import builtin_document
from observer.scenarios import double_mass as dm_module
from observer.scenarios import rocking_chain as rc_module
from observer.tomlio import dumps

REPO = Path(__file__).resolve().parents[2]
CHAIN = rc_module.PARAMETERS


def chain_matrices(N):
    p = CHAIN
    return rc_module.matrices(N, p["m"], p["b"], p["H"], p["a"], p["k"], p["c"])


def block(A, i, j):
    return A[2 * i:2 * i + 2, 2 * j:2 * j + 2]


# ---------------------------------------------------------------------------------------
# 1. rocking-chain builder
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("N", [1, 3, 10])
def test_chain_matrices_structure(N):
    M, C, K, W, K_int, C_int = chain_matrices(N)
    n = 2 * N
    b, a, k, c, m, H = (CHAIN[x] for x in ("b", "a", "k", "c", "m", "H"))
    for A in (M, C, K, W):
        assert A.shape == (n, n)

    # interface matrices: symmetric pair at ±a gives diag(2k, 2k a²) = diag(2000, 12.8) (docs/theory/models.md §2.4)
    np.testing.assert_allclose(K_int, np.diag([2 * k, 2 * k * a * a]), rtol=1e-15, atol=0)
    np.testing.assert_allclose(K_int, np.diag([2000.0, 12.8]), rtol=1e-14, atol=0)
    np.testing.assert_allclose(C_int, np.diag([10.0, 0.064]), rtol=1e-14, atol=0)

    # M diagonal and positive: (m, J) per block, J = m(4b² + H²)/12 = 4.1667e-3
    assert np.array_equal(M, np.diag(np.diag(M)))
    assert np.all(np.diag(M) > 0)
    J = m * (4 * b * b + H * H) / 12.0
    np.testing.assert_allclose(np.diag(M), np.tile([m, J], N), rtol=1e-15)
    assert J == pytest.approx(4.1667e-3, rel=1e-4)

    # K, C symmetric positive definite
    for A in (K, C):
        np.testing.assert_allclose(A, A.T, rtol=0, atol=1e-14 * np.abs(A).max())
        eig = np.linalg.eigvalsh(A)
        assert eig[0] > 0
        assert eig[0] > 1e-10 * eig[-1]

    # block tridiagonal: K_ii = K_i + K_{i+1} (K_{N+1} := 0), K_{i,i±1} = -K_int, rest exactly 0
    for A, A_int in ((K, K_int), (C, C_int)):
        for i in range(N):
            for j in range(N):
                blk = block(A, i, j)
                if abs(i - j) > 1:
                    assert np.all(blk == 0.0), (i, j)
                elif i == j:
                    want = 2 * A_int if i < N - 1 else A_int
                    np.testing.assert_allclose(blk, want, rtol=1e-15, atol=0)
                else:
                    np.testing.assert_allclose(blk, -A_int, rtol=1e-15, atol=0)

    # W: square, block lower-bidiagonal with B = [[1, 1], [-b, b]], det W = (2b)^N
    B = np.array([[1.0, 1.0], [-b, b]])
    for i in range(N):
        for j in range(N):
            blk = block(W, i, j)
            if i == j:
                assert np.array_equal(blk, B)
            elif i == j - 1:
                assert np.array_equal(blk, -B)
            else:
                assert np.all(blk == 0.0)
    det = np.linalg.det(W)
    np.testing.assert_allclose(det, (2 * b) ** N, rtol=1e-12)
    sign, logdet = np.linalg.slogdet(W)
    assert sign == 1.0
    np.testing.assert_allclose(logdet, N * np.log(2 * b), rtol=1e-12)
    assert np.linalg.matrix_rank(W) == n


def test_chain_default_numbers_match_theory():
    """docs/theory/models.md §2.3/§2.4: ω from 6.68 to 109.6 rad/s, G_(1L,1R) = -1.4, static y_s from
    -0.049 to -0.270 m, unloaded clearances g⁰_L from 0.0511 to 0.0069 m, g⁰_R = g⁰_L + 1 mm."""
    M, C, K, W, _, _ = chain_matrices(10)
    omega = np.sqrt(sla.eigh(K, M, eigvals_only=True))
    assert omega[0] == pytest.approx(6.68, abs=5e-3)
    assert omega[-1] == pytest.approx(109.6, abs=5e-2)
    G = W.T @ np.linalg.solve(M, W)
    assert G[0, 1] == pytest.approx(-1.4, rel=1e-12)

    doc = builtin_document("rocking_chain")
    q_s = np.array(doc["initial"]["q"])
    g0 = np.array(doc["system"]["gap"]["offset"])
    assert q_s[0] == pytest.approx(-0.04905, rel=1e-12)
    assert q_s[-2] == pytest.approx(-0.269775, rel=1e-12)
    assert np.all(q_s[1::2] == 0.0)
    assert g0[0] == pytest.approx(0.05105, rel=1e-12)
    assert g0[-2] == pytest.approx(0.006905, rel=1e-10)
    np.testing.assert_allclose(g0[1::2] - g0[0::2], 0.001, rtol=1e-10)


# ---------------------------------------------------------------------------------------
# 2. zero ground motion: the static state is an equilibrium with all contacts open
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("N", [1, 3, 10])
def test_chain_zero_ground_motion_stays_at_rest(N):
    sc = load_scenario("rocking_chain", {"param.N": N, "param.Y": 0.0})
    s_L, s_R = CHAIN["s_L"], CHAIN["s_R"]
    g_init = sc.system.gaps(sc.q0, 0.0)
    np.testing.assert_allclose(g_init, np.tile([s_L, s_R], N), rtol=0, atol=1e-12)
    assert np.all(sc.u0 == 0.0)

    res = simulate(sc, h=1e-3, t_end=0.5)
    assert res.q.shape == (501, 2 * N)
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.u))
    assert np.max(np.abs(res.q - sc.q0)) <= 1e-12
    assert np.max(np.abs(res.u)) <= 1e-12
    assert not res.active.any()
    assert np.all(res.P == 0.0)
    np.testing.assert_allclose(res.g, np.tile([s_L, s_R], (501, N)), rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------------------
# 3. left/right symmetric layout keeps the rotations at zero
# ---------------------------------------------------------------------------------------
def _symmetric_run(N, solver=None, t_end=2.0):
    sc = load_scenario("rocking_chain", {"param.N": N, "param.s_L": 0.002, "param.s_R": 0.002})
    assert np.all(sc.q0[1::2] == 0.0)
    return sc, simulate(sc, h=1e-3, t_end=t_end, solver=solver)


@pytest.mark.parametrize("N", [3, 10])
def test_chain_symmetric_layout_rotations_stay_zero(N):
    """φ ≡ 0 is invariant (docs/theory/models.md §2.3). Measured: the rotations are not bitwise zero but
    round-off (N=10: max|φ| = 8.7e-17 rad, max|φ̇| = 2.7e-15 rad/s; N=3: 2.7e-18, 2.2e-16),
    first non-zero in the step of a simultaneous L/R impact (block_principal_pivoting solves
    the symmetric 2x2 LCP with LU, which rounds the two equal impulses differently).
    Bounds: max|φ| ≤ 1e-14 max|y|; corner velocity b·max|φ̇| ≤ 1e-14 max|ẏ|."""
    sc, res = _symmetric_run(N)
    b = CHAIN["b"]
    assert res.active.any(), "the run must close contacts for the test to mean anything"
    assert res.active.sum() >= 10
    act = res.active.reshape(len(res.t), N, 2)
    assert np.array_equal(act[:, :, 0], act[:, :, 1]), "left and right corners must close together"
    y, phi = res.q[:, 0::2], res.q[:, 1::2]
    ydot, phidot = res.u[:, 0::2], res.u[:, 1::2]
    assert np.all(np.isfinite(res.q)) and np.all(np.isfinite(res.u))
    assert np.max(np.abs(y)) > 0.04          # the ground moves the chain by centimetres
    assert np.max(np.abs(phi)) <= 1e-14 * np.max(np.abs(y))
    assert b * np.max(np.abs(phidot)) <= 1e-14 * np.max(np.abs(ydot))
    P = res.P.reshape(len(res.t), N, 2)
    assert np.max(np.abs(P[:, :, 0] - P[:, :, 1])) <= 1e-14 * np.max(res.P)


# ---------------------------------------------------------------------------------------
# 4. every built-in: loads, describes itself, simulates, show -> TOML -> run is bit-identical
# ---------------------------------------------------------------------------------------
def test_builtin_registry():
    assert list(SCENARIOS) == ["double_mass", "rocking_chain", "bouncing_ball",
                               "impact_oscillator", "grazing", "random_system"]


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_builtin_loads_describes_and_simulates(name):
    module = SCENARIOS[name]
    desc = module.DESCRIPTION
    assert isinstance(desc, str) and desc.strip() == desc and 10 < len(desc) < 120
    assert "\n" not in desc
    sc = load_scenario(name)
    assert sc.name == name and sc.description == desc
    res = simulate(sc, t_end=0.05)
    steps = int(round(0.05 / sc.h))
    assert res.t.shape == (steps + 1,)
    assert res.t[-1] == pytest.approx(0.05, abs=1e-12)
    assert res.q.shape == res.u.shape == (steps + 1, sc.system.n)
    assert res.P.shape == res.active.shape == (steps + 1, sc.system.m)
    for arr in (res.q, res.u, res.P, res.g):
        assert np.all(np.isfinite(arr))
    assert np.array_equal(res.q[0], sc.q0) and np.array_equal(res.u[0], sc.u0)
    # Moreau–Jean allows a position drift of order h·|γ| (chain: -3.3e-6 m); no gross penetration
    assert res.g.min() >= -1e-4
    assert np.all(res.P >= 0.0)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_builtin_toml_round_trip_bit_identical(name, tmp_path):
    sc = load_scenario(name)
    path = tmp_path / f"{name}.toml"
    path.write_text(dumps(sc.to_dict()))
    sc2 = load_scenario(str(path))
    assert sc2.name == name
    assert sc2.to_dict() == sc.to_dict()
    for attr in ("M", "C", "K", "W"):
        assert np.array_equal(getattr(sc.system, attr), getattr(sc2.system, attr))
    r1 = simulate(sc, t_end=0.05)
    r2 = simulate(sc2, t_end=0.05)
    for attr in ("t", "q", "u", "P", "active"):
        assert np.array_equal(getattr(r1, attr), getattr(r2, attr)), attr


def test_round_trip_preserves_per_contact_restitution_and_harmonics(tmp_path):
    sc = load_scenario("rocking_chain", {"param.N": 2, "impact.restitution": [0.1, 0.2, 0.3, 0.4]})
    assert len(sc.system.forcing.omega) == 2      # cos term plus one [[harmonics]] entry
    path = tmp_path / "chain2.toml"
    path.write_text(dumps(sc.to_dict()))
    sc2 = load_scenario(path)
    assert np.array_equal(sc2.law.restitution, [0.1, 0.2, 0.3, 0.4])
    assert np.array_equal(sc2.system.forcing.amplitude, sc.system.forcing.amplitude)
    assert np.array_equal(sc2.system.forcing.phase, sc.system.forcing.phase)
    r1, r2 = simulate(sc, t_end=0.05), simulate(sc2, t_end=0.05)
    assert np.array_equal(r1.q, r2.q) and np.array_equal(r1.P, r2.P)


def _cli_env():
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def _compare_result_csvs(path_a, path_b, name):
    a_lines = Path(path_a).read_text().splitlines()
    b_lines = Path(path_b).read_text().splitlines()
    assert a_lines[0].startswith("t,") and b_lines[0].startswith("t,")   # a plain header row
    assert len(a_lines) > 2
    assert a_lines == b_lines, name                    # header and every data line
    fa, fb = read_frame(path_a), read_frame(path_b)
    assert fa.attrs["scenario"] == fb.attrs["scenario"] == name
    assert len(fa) == int(round(0.05 / fa.attrs["h"])) + 1
    for col in fa.columns:
        assert np.array_equal(fa[col].to_numpy(), fb[col].to_numpy()), (name, col)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_builtin_cli_show_then_run_identical_in_process(name, tmp_path, capsys, monkeypatch):
    """``show NAME > f.toml; run f.toml`` == ``run NAME`` through observer.cli.main."""
    from observer.cli import main
    monkeypatch.chdir(tmp_path)
    assert main(["show", name]) == 0
    text = capsys.readouterr().out
    assert text.startswith("# " + name + ": ")
    Path("f.toml").write_text(text, encoding="utf-8")
    assert main(["run", "f.toml", "--t-end", "0.05", "--out", "a.csv"]) == 0
    assert main(["run", name, "--t-end", "0.05", "--out", "b.csv"]) == 0
    assert capsys.readouterr().out.count("wrote") == 2
    _compare_result_csvs("a.csv", "b.csv", name)


def test_builtin_cli_show_then_run_identical_subprocess(tmp_path):
    """The same through ``python -m observer`` (real stdout redirection, module docstring
    with non-ASCII comments) for the chain: harmonics, per-contact data and an [observer]
    table. ``show`` and ``run NAME`` run concurrently."""
    cmd = [sys.executable, "-m", "observer"]
    names = ["rocking_chain"]

    def start(args, stdout=subprocess.PIPE):
        return subprocess.Popen(cmd + args, cwd=tmp_path, env=_cli_env(), stdout=stdout,
                                stderr=subprocess.PIPE, text=True)

    def finish(proc):
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 0, err
        assert err == ""
        return out

    wave1 = []
    for name in names:
        fh = open(tmp_path / f"{name}.toml", "w")
        wave1.append((fh, start(["show", name], stdout=fh)))
        wave1.append((None, start(["run", name, "--t-end", "0.05", "--out", f"{name}_b.csv"])))
    for fh, proc in wave1:
        finish(proc)
        if fh is not None:
            fh.close()
    wave2 = [start(["run", f"{name}.toml", "--t-end", "0.05", "--out", f"{name}_a.csv"])
             for name in names]
    for proc in wave2:
        assert "wrote" in finish(proc)
    for name in names:
        text = (tmp_path / f"{name}.toml").read_text(encoding="utf-8")
        assert text.startswith("#") and f'name = "{name}"' in text
        _compare_result_csvs(tmp_path / f"{name}_a.csv", tmp_path / f"{name}_b.csv", name)


# ---------------------------------------------------------------------------------------
# 5. double mass: static contact equilibrium
# ---------------------------------------------------------------------------------------
def test_double_mass_initial_state_is_static_contact_equilibrium():
    sc = load_scenario("double_mass")
    s = sc.system
    g = s.gaps(sc.q0, 0.0)
    assert abs(g[0]) <= 1e-12
    np.testing.assert_allclose(sc.q0, [-0.25, -0.17405], rtol=0, atol=5e-6)   # docs/theory/models.md §1.2
    assert np.all(sc.u0 == 0.0)
    # K q* = f_grav + w λ_s with λ_s = 2.215 N (docs/theory/models.md §1.2, docs/theory/oracles.md §5)
    f_grav = s.forcing.constant
    lam = (s.K @ sc.q0 - f_grav) @ s.W[:, 0]
    np.testing.assert_allclose(s.K @ sc.q0 - f_grav, s.W[:, 0] * lam, rtol=0, atol=1e-12)
    assert lam == pytest.approx(2.215, abs=5e-4)
    q_star, lam2 = dm_module.static_equilibrium(s.M, s.K, s.W, f_grav, 0.25)
    assert np.array_equal(q_star, sc.q0)
    assert lam2 == pytest.approx(lam, rel=1e-12)


def test_double_mass_unforced_rests_with_preload_impulse():
    """F = 0: the static equilibrium persists and P_k/h = λ_s (docs/theory/oracles.md §5)."""
    sc = load_scenario("double_mass", {"param.F": 0.0})
    res = simulate(sc, h=1e-3, t_end=0.2)
    assert res.active[1:].all()
    np.testing.assert_allclose(res.q, np.broadcast_to(sc.q0, res.q.shape), rtol=0, atol=1e-12)
    assert np.max(np.abs(res.u)) <= 1e-12
    np.testing.assert_allclose(res.P[1:, 0] / 1e-3, 2.215, rtol=1e-3)
    lam = (sc.system.K @ sc.q0 - sc.system.forcing.constant)[0]
    np.testing.assert_allclose(res.P[1:, 0] / 1e-3, lam, rtol=1e-9)


# ---------------------------------------------------------------------------------------
# 6. overrides
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("value", [5, "5"])
def test_override_param_N(value):
    sc = load_scenario("rocking_chain", {"param.N": value})
    assert sc.system.n == 10 and sc.system.m == 10
    assert sc.system.W.shape == (10, 10)
    assert sc.q0.shape == (10,)
    np.testing.assert_allclose(np.linalg.det(sc.system.W), 0.2 ** 5, rtol=1e-12)


def test_override_string_values_are_parsed_as_toml():
    sc = load_scenario("bouncing_ball", {"simulation.h": "1e-3", "simulation.t_end": "0.5",
                                         "simulation.theta": "1", "impact.law": "poisson"})
    assert sc.h == 1e-3 and isinstance(sc.h, float)
    assert sc.t_end == 0.5
    assert sc.theta == 1.0
    assert sc.law.law == "poisson"
    sc = load_scenario("bouncing_ball", {"param.h0": "2.0", "param.restitution": 0.5})
    assert sc.q0[0] == 2.0 and sc.law.restitution[0] == 0.5


@pytest.mark.parametrize("value", [[0.1, 0.2, 0.3, 0.4], "[0.1, 0.2, 0.3, 0.4]"])
def test_override_restitution_per_contact(value):
    sc = load_scenario("rocking_chain", {"param.N": 2, "impact.restitution": value})
    assert np.array_equal(sc.law.restitution, [0.1, 0.2, 0.3, 0.4])
    assert not sc.law.is_global
    assert sc.to_dict()["impact"]["restitution"] == [0.1, 0.2, 0.3, 0.4]
    res = simulate(sc, h=1e-3, t_end=0.05)
    assert res.metadata["restitution"] == [0.1, 0.2, 0.3, 0.4]


def test_override_global_restitution_stays_scalar():
    sc = load_scenario("rocking_chain", {"param.N": 2, "impact.restitution": 0.5})
    assert np.array_equal(sc.law.restitution, [0.5] * 4)
    assert sc.law.is_global
    assert sc.to_dict()["impact"]["restitution"] == 0.5


def test_override_unknown_param_names_it():
    with pytest.raises(InputError) as ei:
        load_scenario("rocking_chain", {"param.foo": 1})
    assert ei.value.field == "param.foo"
    assert "param.foo" in str(ei.value) and "unknown parameter" in str(ei.value)


@pytest.mark.parametrize("value, hint", [(0, "positive integer"), (2.5, "must be an integer"),
                                         ("abc", "must be a number"), (True, "must be a number")])
def test_override_bad_param_value(value, hint):
    with pytest.raises(InputError) as ei:
        load_scenario("rocking_chain", {"param.N": value})
    assert ei.value.field == "param.N"
    assert hint in str(ei.value)


def test_override_param_on_toml_file_is_rejected(tmp_path):
    path = tmp_path / "bb.toml"
    path.write_text(dumps(load_scenario("bouncing_ball").to_dict()))
    with pytest.raises(InputError) as ei:
        load_scenario(path, {"param.h0": 2.0})
    assert ei.value.field == "param.h0"
    assert "built-in" in str(ei.value)


def test_override_on_loaded_scenario_and_inside_scalar():
    sc = load_scenario("bouncing_ball")
    sc2 = load_scenario(sc, {"simulation.h": 2e-3})
    assert sc2.h == 2e-3 and sc.h == 1e-3
    with pytest.raises(InputError) as ei:
        load_scenario("bouncing_ball", {"simulation.h.x": 1})
    assert ei.value.field == "simulation.h.x"
    assert "non-table" in str(ei.value)


# ---------------------------------------------------------------------------------------
# 7. result frame and I/O
# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def observed_run():
    return simulate("double_mass", h=1e-3, t_end=0.02, observers=("jump", "nojump"))


def test_to_frame_columns_and_values(observed_run):
    res = observed_run
    df = res.to_frame()
    expected = (["t", "q0", "q1", "u0", "u1", "g0", "P0", "active0", "chi0"]
                + [f"jump_{v}{j}" for v in "qu" for j in range(2)] + ["V_jump"]
                + [f"nojump_{v}{j}" for v in "qu" for j in range(2)] + ["V_nojump"])
    assert list(df.columns) == expected
    assert len(df) == 21
    assert np.array_equal(df["t"].to_numpy(), res.t)
    np.testing.assert_allclose(df["t"].to_numpy(), np.arange(21) * 1e-3, rtol=0, atol=1e-15)
    assert np.array_equal(df["q1"].to_numpy(), res.q[:, 1])
    assert np.array_equal(df["g0"].to_numpy(), res.q[:, 0] + 0.25)
    assert np.array_equal(df["P0"].to_numpy(), res.P[:, 0])
    assert np.array_equal(df["chi0"].to_numpy(), res.chi[:, 0].astype(np.int8))
    assert np.array_equal(df["jump_u0"].to_numpy(), res.slaves["jump"].u[:, 0])
    # V(0) = ½ Δuᵀ M Δu + ½ ΔqᵀK Δq with Δq = (0.02, -0.01), Δu = (0.1, -0.1): 0.01 + 0.05
    assert df["V_jump"].iloc[0] == pytest.approx(0.06, rel=1e-12)
    assert df["V_nojump"].iloc[0] == pytest.approx(0.06, rel=1e-12)
    assert np.all(np.isfinite(df.select_dtypes("number").to_numpy()))


def test_frame_without_observers_has_no_observer_columns():
    df = simulate("bouncing_ball", h=1e-3, t_end=0.01).to_frame()
    assert list(df.columns) == ["t", "q0", "u0", "g0", "P0", "active0"]
    # free fall is exact for the θ = ½ scheme: q = 1 - g t²/2
    np.testing.assert_allclose(df["q0"].to_numpy(), 1 - 9.81 * df["t"].to_numpy() ** 2 / 2,
                               rtol=0, atol=1e-14)


def test_frame_metadata(observed_run):
    attrs = observed_run.to_frame().attrs
    assert attrs["h"] == 1e-3 and attrs["theta"] == 0.5 and attrs["solver"] == "pivoting"
    assert attrs["scenario"] == "double_mass" and attrs["steps"] == 20
    assert attrs["n"] == 2 and attrs["m"] == 1 and attrs["law"] == "poisson"
    assert attrs["observers"] == ["jump", "nojump"] and attrs["source"] == "master"
    v = attrs["versions"]
    assert v["numpy"] == np.__version__ and v["pandas"] == pd.__version__
    assert v["python"] == ".".join(map(str, sys.version_info[:3]))
    json.dumps(attrs)                         # plain JSON types only


@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_result_file_round_trip(observed_run, tmp_path, ext):
    df = observed_run.to_frame()
    path = observed_run.write(tmp_path / "sub" / f"run.{ext}")
    assert path.exists()
    head = path.read_bytes()[:12]
    if ext == "csv":
        assert head.startswith(b"t,")                  # plain header; metadata in run.json
        assert path.with_suffix(".json").exists()
    else:
        assert head.startswith(b"PAR1")
    back = read_frame(path)
    assert list(back.columns) == list(df.columns)
    assert len(back) == len(df)
    for col in df.columns:
        assert np.array_equal(back[col].to_numpy(), df[col].to_numpy()), col
    back.attrs.pop("events_file", None)              # named by streamed writes only
    assert (path.parent / f"run.events.{ext}").exists()   # the run's event table, beside it
    assert back.attrs == df.attrs


def test_csv_is_exact_for_arbitrary_doubles(tmp_path):
    rng = np.random.default_rng(7)
    x = rng.standard_normal(5000) * 10.0 ** rng.integers(-300, 300, 5000)
    x[:4] = [np.pi, 1 / 3, 5e-324, -1.7976931348623157e308]
    df = pd.DataFrame({"t": x})
    df.attrs["h"] = 0.1
    back = read_frame(write_frame(df, tmp_path / "x.csv"))
    assert np.array_equal(back["t"].to_numpy(), x)
    assert back.attrs == {"h": 0.1}


def test_write_frame_rejects_unknown_extension(tmp_path):
    df = pd.DataFrame({"t": [0.0]})
    with pytest.raises(InputError) as ei:
        write_frame(df, tmp_path / "x.xlsx")
    assert ei.value.field == "--out" and ".xlsx" in str(ei.value)
    assert not (tmp_path / "x.xlsx").exists()
    with pytest.raises(InputError):
        read_frame(tmp_path / "missing.csv")


def test_csv_round_trip_keeps_float_dtype(tmp_path):
    res = simulate("bouncing_ball", h=1e-3, t_end=0.01)    # no contact: P0 ≡ 0.0
    df = res.to_frame()
    assert df["P0"].dtype == np.float64
    back = read_frame(res.write(tmp_path / "r.csv"))
    assert back["P0"].dtype == np.float64


# ---------------------------------------------------------------------------------------
# Library problems found while writing these tests (see the report)
# ---------------------------------------------------------------------------------------
def test_source_self_uses_the_observers_own_closed_set():
    """source="self" = every observer uses its own closed set (switching.py docstring).
    Was silently identical to "master" in the committed code; fixed in the working tree."""
    kw = dict(h=1e-3, t_end=1.0, observers=("nojump",))
    r_self = simulate("double_mass", source="self", **kw)
    r_master = simulate("double_mass", source="master", **kw)
    r_free = simulate("double_mass", coupling=(1e9, 1e9), **kw)   # never coupled = own closed set
    assert np.array_equal(r_self.slaves["nojump"].q, r_free.slaves["nojump"].q)
    assert not np.array_equal(r_self.slaves["nojump"].q, r_master.slaves["nojump"].q)


def test_lemke_is_scale_invariant():
    G = np.array([[3.4, -1.4, -3.4], [-1.4, 3.4, 1.4], [-3.4, 1.4, 6.8]])   # from the chain
    for scale in (1.0, 1e-12, 1e-18):
        b = np.array([0.0, 0.0, -1.0]) * scale
        sol = lemke(G, b)
        assert sol is not None
        assert lcp_residual(G, b, sol.x) <= 1e-12, scale


def test_chain_runs_with_lemke_solver():
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = simulate("rocking_chain", h=1e-3, t_end=1.0, solver="lemke")
    assert res.metadata["solver_fallbacks"] == 0
    assert res.metadata["max_contact_residual"] <= 1e-9


# ---------------------------------------------------------------------------------------
# random_system: the seeded family of random systems (issue 22)
# ---------------------------------------------------------------------------------------
RANDOM_SIZES = [(2, 1), (5, 3), (8, 4)]


@pytest.mark.parametrize("dof,contacts", RANDOM_SIZES)
def test_random_system_is_deterministic_per_seed_and_valid(dof, contacts):
    params = {"param.dof": dof, "param.contacts": contacts}
    a, b = (load_scenario("random_system", {**params, "param.seed": 7}) for _ in range(2))
    assert a.to_dict() == b.to_dict()
    c = load_scenario("random_system", {**params, "param.seed": 8})
    assert not np.array_equal(a.system.K, c.system.K) and not np.array_equal(a.system.W, c.system.W)
    s = a.system
    M, K, C, W = (np.asarray(x, float) for x in (s.M, s.K, s.C, s.W))
    assert (s.n, s.m) == (dof, contacts)
    for A, lowest in ((M, 1.0), (K, 100.0), (C, 2.0)):            # scale·(I + BBᵀ/n) ⪰ scale·I
        assert np.array_equal(A, A.T) and np.linalg.eigvalsh(A)[0] >= lowest * (1 - 1e-12)
    assert np.allclose(np.linalg.norm(W, axis=0), 1.0) and np.linalg.matrix_rank(W) == contacts
    g0 = W.T @ a.q0 + np.asarray(a.to_dict()["system"]["gap"]["offset"])
    assert np.all(g0 >= 0.005) and np.all(g0 <= 0.01)              # feasible: clearances s
    forcing = a.to_dict()["system"]["forcing"]
    static = W.T @ np.linalg.solve(K, np.asarray(forcing["amplitude"]))
    np.testing.assert_allclose(static, -2.0 * 0.01, rtol=1e-10)     # lowers every gap by push·s_max
    omega1 = np.sqrt(sla.eigh(K, M, eigvals_only=True)[0])
    assert forcing["omega"] == pytest.approx(0.8 * omega1, rel=1e-14)


def test_random_system_runs_both_observers_and_hits_every_contact():
    sc = load_scenario("random_system", {"param.seed": 3, "param.dof": 4, "param.contacts": 3})
    res = simulate(sc, t_end=3.0, observers=("jump", "nojump"))
    assert res.active[1:].any(axis=0).all()                         # every contact closes
    assert res.g.min() >= -0.01 * 0.01                              # penetration ≤ 1 % of s_max
    for name in ("jump", "nojump"):
        V = res.slaves[name].V
        assert np.all(np.isfinite(V)) and V[-1] < 0.1 * V[0]      # C ⪰ 2I, M: rate ≳ 1/s


@pytest.mark.parametrize("key,value", [("param.dof", 9), ("param.dof", 1), ("param.contacts", 5),
                                       ("param.contacts", 0), ("param.seed", -1), ("param.dof", 2.5)])
def test_random_system_rejects_sizes_outside_the_family(key, value):
    with pytest.raises(InputError) as err:
        load_scenario("random_system", {key: value})
    assert key in str(err.value)


def test_random_system_contacts_at_most_dof():
    with pytest.raises(InputError, match="param.contacts"):
        load_scenario("random_system", {"param.dof": 2, "param.contacts": 3})
