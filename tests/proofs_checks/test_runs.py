"""proofs_checks.runs (the replays of the run-based checks) on 50-step runs of double_mass
and on the two-contact rocking block: the N-metric projector against the KKT conditions of
its minimization (constraint met, correction in the range of N⁻¹W_I), the recorded arrays
against the time-stepping relations they must satisfy (predicted gaps recomputed from the
master's state, the Siconos rule χ = g_pred ≤ 0, q_pre of the θ-method), the observers'
χ, settings and descriptions, ``rerun`` and ``lyapunov_pair`` recomputed by per-step
loops. Written against the mutation run of ``runs.py``
(``tests/mutants/proofs_checks_runs.md``). About 2 s.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import proofs_checks as pc
from observer.errors import InputError
from observer.loop import ENGINES as STEPPING_ENGINES
from observer.stepping import MoreauJean
from proofs_checks import runs as ru
from proofs_checks.runs import SlaveSpec, replay

pytestmark = pytest.mark.filterwarnings("ignore:penetration .* reduce h")

H, T_END = 1e-2, 0.5
STEPS = 50


@pytest.fixture(scope="module")
def sc():
    return pc.load("double_mass", {"impact.law": "newton", "impact.restitution": 0.3})


@pytest.fixture(scope="module")
def specs(sc):
    return [SlaveSpec("a", True, np.array([-0.23, -0.18405]), np.array([0.1, -0.1])),
            SlaveSpec("b", True, np.array([-0.2579, -0.1698]), np.array([-0.0017, 0.0253])),
            SlaveSpec("c", False, np.array([-0.24, -0.17]), np.array([0.0, 0.05]), np.eye(2))]


@pytest.fixture
def run(sc, specs):
    """Function scope: the mutation run maps each test to the code it calls itself."""
    return replay(sc, h=H, t_end=T_END, slaves=specs)


@pytest.fixture(scope="module")
def block():
    return pc.load("rocking_chain", {"param.N": 1})


def stepper_of(scenario, h=H, t_end=T_END):
    return MoreauJean(scenario.system, scenario.law, h, t_end, scenario.theta, solver=scenario.solver)


# ----------------------------------------------------------------------------- projector
def test_projector_kinds_and_descriptions(block):
    st = stepper_of(block)
    K = block.system.K
    proj, desc = ru.make_projector(st, None)
    assert desc == "K (library projection)" and proj == st.project

    def mine(k, q, active):
        return q, np.zeros(active.size)
    assert ru.make_projector(st, mine) == (mine, "mine")

    class Projector:
        def __call__(self, k, q, active):
            return q, np.zeros(active.size)
    obj = Projector()
    assert ru.make_projector(st, obj) == (obj, "custom projector")
    assert ru.make_projector(st, K.copy())[1] == "K (explicit matrix)"
    assert ru.make_projector(st, K.tolist())[1] == "K (explicit matrix)"
    assert ru.make_projector(st, np.eye(2))[1] == "identity (Euclidean)"
    assert ru.make_projector(st, 2 * np.eye(2))[1] == "custom matrix"
    for metric, text in ((None, "K (library projection)"), (K.copy(), "K (explicit matrix)"),
                         (np.eye(2), "identity (Euclidean)"), (np.diag([1.0, 2.0]), "custom matrix")):
        assert ru._metric_description(st, metric) == text


@pytest.mark.parametrize("active", [[0], [1], [0, 1]])
def test_n_metric_projection_meets_the_constraint_in_the_n_metric(block, active):
    st = stepper_of(block)
    W, nu = block.system.W, st.grid.nu
    N = np.array([[3.0, 0.4], [0.4, 0.5]])
    proj, _ = ru.make_projector(st, N)
    q = np.array([-0.3, 0.7])
    a = np.array(active)
    k = 7
    qp, sigma = proj(k, q, a)
    assert sigma.shape == (a.size,)
    # the constraint g_I(q⁺, t_k) = 0 ...
    np.testing.assert_allclose(qp @ W[:, a] + nu[k, a], 0.0, atol=1e-13)
    # ... and stationarity of ½(q⁺ − q)ᵀN(q⁺ − q): N(q⁺ − q) = W_I σ
    np.testing.assert_allclose(N @ (qp - q), W[:, a] @ sigma, rtol=1e-12, atol=1e-13)
    assert np.linalg.norm(qp - q) > 1e-3
    # N = K agrees with the library's projection to round-off
    qk, sk = ru.make_projector(st, block.system.K.copy())[0](k, q, a)
    ql, sl = st.project(k, q, a)
    np.testing.assert_allclose(qk, ql, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(sk, sl, rtol=1e-10, atol=1e-12)


def test_n_metric_projection_of_an_empty_set(block):
    proj, _ = ru.make_projector(stepper_of(block), np.eye(2))
    q = np.array([0.1, 0.2])
    qp, sigma = proj(0, q, np.zeros(0, dtype=int))
    assert qp is q and sigma.shape == (0,)


# ----------------------------------------------------------------------------- replay
def test_replay_grid_and_shapes(run, sc, specs):
    assert run.t.shape == (STEPS + 1,) and run.t[0] == 0.0 and run.t[-1] == pytest.approx(T_END, rel=1e-12)
    np.testing.assert_allclose(np.diff(run.t), H, rtol=1e-9)
    assert run.h == H and run.theta == sc.theta == run.stepper.theta
    assert list(run.slaves) == ["a", "b", "c"]
    for tr in [run.master, *run.slaves.values()]:
        assert tr.q.shape == tr.q_pre.shape == tr.u.shape == (STEPS + 1, 2)
        assert tr.P.shape == tr.sigma.shape == tr.active.shape == (STEPS + 1, 1)
        assert set(tr.as_dict()) == {"q", "u", "P", "sigma"} and tr.as_dict()["q"] is tr.q
    np.testing.assert_array_equal(run.master.q[0], sc.q0)
    np.testing.assert_array_equal(run.master.u[0], sc.u0)
    for s in specs:
        np.testing.assert_array_equal(run.slaves[s.name].q[0], s.q0)
        np.testing.assert_array_equal(run.slaves[s.name].u[0], s.u0)
    assert run.master.name == "master" and run.slaves["a"].name == "a"
    assert run.master.projected is False
    assert [run.slaves[n].projected for n in "abc"] == [True, True, False]
    assert run.system is sc.system and run.scenario is sc


def test_replay_predicted_gaps_and_switching(run, sc):
    """g_pred[k+1] = g(q_k, t_k) + (h/2)γ(u_k, t_k) of the master; χ = g_pred ≤ 0 (Siconos)."""
    s = sc.system
    assert np.all(run.g_pred[0] == 0.0)
    for k in range(STEPS):
        t = run.t[k]
        g = run.master.q[k] @ s.W + s.nu(np.array([t]))[0]
        gamma = run.master.u[k] @ s.W + s.nu_dot(np.array([t]))[0]
        np.testing.assert_allclose(run.g_pred[k + 1], g + 0.5 * H * gamma, rtol=1e-12, atol=1e-15)
    closed = run.g_pred[1:] <= 0.0
    assert 0 < closed.sum() < STEPS
    np.testing.assert_array_equal(run.master.active[1:], closed)
    np.testing.assert_array_equal(run.chi, run.master.active)
    for tr in run.slaves.values():
        assert tr.active is run.chi
    # impulses only on closed contacts
    assert np.all(run.master.P[1:][~closed] == 0.0) and np.any(run.master.P[1:][closed] > 0.0)


def test_replay_q_pre_is_the_theta_step(run, sc):
    th = sc.theta
    for tr in [run.master, *run.slaves.values()]:
        pre = tr.q[:-1] + H * ((1 - th) * tr.u[:-1] + th * tr.u[1:])
        np.testing.assert_allclose(tr.q_pre[1:], pre, rtol=1e-12, atol=1e-15)
    jumps = run.slaves["a"]
    moved = np.any(jumps.q[1:] != jumps.q_pre[1:], axis=1)
    assert moved.any() and np.all(jumps.sigma[1:][~moved] == 0.0)
    np.testing.assert_array_equal(run.master.q, run.master.q_pre)         # no master projection
    np.testing.assert_array_equal(run.slaves["c"].q, run.slaves["c"].q_pre)   # no position jumps


def test_replay_settings_and_metrics(run, sc, specs):
    assert run.metric == "K (library projection)"
    assert run.settings == {"h": H, "t_end": float(run.t[-1]), "theta": sc.theta, "master_projection": False,
                            "metric": None, "system": sc.system, "chi_override": False, "engine": "compiled"}
    assert run.slave_metrics.keys() == {"c"} and run.slave_metrics["c"] is specs[2].metric
    again = ru.slave_specs_of(run)
    assert [(s.name, s.position_jumps, s.metric) for s in again] == \
        [(s.name, s.position_jumps, s.metric) for s in specs]
    for s, t in zip(again, specs):
        np.testing.assert_array_equal(s.q0, t.q0)
        np.testing.assert_array_equal(s.u0, t.u0)


def test_replay_defaults_come_from_the_scenario(sc):
    short = pc.load("double_mass", {"impact.law": "newton", "impact.restitution": 0.3,
                                    "simulation.h": 2e-2, "simulation.t_end": 0.2})
    r = replay(sc, h=2e-2, t_end=0.2)
    assert r.t.size == 11 and r.h == 2e-2 and r.slaves == {}
    np.testing.assert_array_equal(r.chi, r.master.active)
    assert r.chi is not r.master.active
    r2 = replay(short)
    assert r2.t.size == 11 and r2.h == 2e-2
    np.testing.assert_array_equal(r2.master.q, r.master.q)


def test_replay_with_an_explicit_switching_signal(sc, specs, run):
    chi = np.zeros((STEPS + 1, 1), dtype=bool)
    chi[20:30] = True
    r = replay(sc, h=H, t_end=T_END, slaves=specs[:1], chi=chi.astype(int))
    np.testing.assert_array_equal(r.chi[1:], chi[1:])
    assert r.settings["chi_override"] is True and r.slaves["a"].active is r.chi
    assert np.all(r.slaves["a"].P[1:][~chi[1:]] == 0.0) and np.any(r.slaves["a"].P[20:30] != 0.0)
    np.testing.assert_array_equal(r.master.q, run.master.q)               # the master is not driven
    no_obs = replay(sc, h=H, t_end=T_END, chi=chi)
    assert no_obs.chi is chi or np.array_equal(no_obs.chi, chi)
    with pytest.raises(ValueError, match=r"chi has shape \(50, 1\), expected \(51, 1\)"):
        replay(sc, h=H, t_end=T_END, slaves=specs[:1], chi=chi[1:])
    with pytest.raises(ValueError, match=r"^replay takes a metric matrix N \(or None for K\), not a callable$"):
        replay(sc, h=H, t_end=T_END, metric=lambda k, q, a: (q, a))
    with pytest.raises(ValueError, match=r"^the run cannot be repeated at another step \(no scenario, or an explicit χ\)$"):
        ru.rerun(r, H / 2)
    ints = replay(sc, h=H, t_end=T_END, chi=chi.astype(int))
    assert ints.chi.dtype == bool and np.array_equal(ints.chi, chi)


def test_replay_with_a_metric_and_master_projection(sc, specs):
    r = replay(sc, h=H, t_end=T_END, slaves=specs[:1], metric=np.eye(2), master_projection=True)
    assert r.metric == "identity (Euclidean)" and r.master.projected is True
    assert r.settings["master_projection"] is True and np.array_equal(r.settings["metric"], np.eye(2))
    a = r.slaves["a"]
    jumped = np.any(a.q[1:] != a.q_pre[1:], axis=1)
    assert jumped.any()
    for k in np.flatnonzero(jumped):
        d = a.q[k + 1] - a.q_pre[k + 1]                  # identity metric: the jump is along W
        assert abs(d[1]) <= 1e-14 * abs(d[0])
    assert np.any(r.master.q != r.master.q_pre)


def test_replay_python_engine_agrees(sc, specs, run):
    r = replay(sc, h=H, t_end=T_END, slaves=specs, engine="python")
    assert r.settings["engine"] == "python"
    np.testing.assert_allclose(r.slaves["a"].q, run.slaves["a"].q, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(r.chi, run.chi)


# ----------------------------------------------------------------------------- rerun, V
def test_rerun_repeats_the_case(run, sc):
    same = ru.rerun(run, H)
    for name in ("master", "a", "b", "c"):
        x = same.master if name == "master" else same.slaves[name]
        y = run.master if name == "master" else run.slaves[name]
        np.testing.assert_array_equal(x.q, y.q)
        np.testing.assert_array_equal(x.u, y.u)
    half = ru.rerun(run, H / 2)
    assert half.t.size == 2 * STEPS + 1 and half.t[-1] == pytest.approx(T_END)
    assert half.slave_metrics.keys() == {"c"} and half.settings["metric"] is None
    no_scenario = ru.Run(run.system, run.stepper, run.t, run.master, run.slaves, run.chi, run.g_pred)
    with pytest.raises(ValueError, match="no scenario"):
        ru.rerun(no_scenario, H)


def test_rerun_keeps_metric_and_master_projection(sc, specs):
    r = replay(sc, h=H, t_end=0.2, slaves=specs[:1], metric=np.eye(2), master_projection=True)
    again = ru.rerun(r, H)
    assert again.metric == "identity (Euclidean)" and again.master.projected is True
    np.testing.assert_array_equal(again.slaves["a"].q, r.slaves["a"].q)


def test_lyapunov_pair_recomputed(run, sc):
    s = sc.system
    a, b = run.slaves["a"], run.slaves["b"]
    for pre in (False, True):
        V = ru.lyapunov_pair(s, a, b, pre=pre)
        qa, qb = (a.q_pre, b.q_pre) if pre else (a.q, b.q)
        ref = [0.5 * (a.u[k] - b.u[k]) @ s.M @ (a.u[k] - b.u[k]) + 0.5 * (qa[k] - qb[k]) @ s.K @ (qa[k] - qb[k])
               for k in range(STEPS + 1)]
        np.testing.assert_allclose(V, ref, rtol=1e-12)
    assert not np.allclose(ru.lyapunov_pair(s, a, b), ru.lyapunov_pair(s, a, b, pre=True))
    assert np.array_equal(ru.lyapunov_pair(s, a, b), ru.lyapunov_pair(s, a, b, False))


def test_replay_of_a_moving_gap_theta_and_solver(sc):
    """A gap ν(t) = 0.25 + 0.02 sin 5t (so ν̇ ≠ 0), θ = 0.7 and the Lemke solver: the predicted
    gaps and q_pre follow them."""
    from observer.model import Harmonic
    moving = dataclasses.replace(sc.system, gap=Harmonic.build("gap", 1, constant=[0.25], kind="sin",
                                                               terms=[{"amplitude": [0.02], "omega": 5.0}]))
    sc7 = pc.load("double_mass", {"impact.law": "newton", "impact.restitution": 0.3,
                                  "simulation.theta": 0.7, "simulation.solver": "lemke"})
    r = replay(sc7, h=H, t_end=T_END, system=moving, slaves=[SlaveSpec("a", True, sc.q0 + 0.01, sc.u0)])
    assert r.theta == 0.7 and r.stepper.solver.name == "lemke" and r.system is moving
    nu = 0.25 + 0.02 * np.sin(5 * r.t[:-1])
    nu_dot = 0.1 * np.cos(5 * r.t[:-1])
    g = r.master.q[:-1, 0] + nu
    gamma = r.master.u[:-1, 0] + nu_dot
    np.testing.assert_allclose(r.g_pred[1:, 0], g + 0.5 * H * gamma, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(r.master.active[1:], r.g_pred[1:] <= 0.0)
    a = r.slaves["a"]
    np.testing.assert_allclose(a.q_pre[1:], a.q[:-1] + H * (0.3 * a.u[:-1] + 0.7 * a.u[1:]), rtol=1e-12, atol=1e-15)
    jumped = np.flatnonzero(np.any(a.q[1:] != a.q_pre[1:], axis=1))
    assert jumped.size
    for k in jumped:                                  # the K-metric jump meets the moving gap
        if r.chi[k + 1, 0]:
            assert a.q[k + 1, 0] + 0.25 + 0.02 * np.sin(5 * r.t[k + 1]) == pytest.approx(0.0, abs=1e-12)
    # rerun keeps the replaced system
    again = ru.rerun(r, H)
    assert again.system is moving
    np.testing.assert_array_equal(again.master.q, r.master.q)


def test_an_observer_with_its_own_metric(sc):
    """An observer's own metric N = I (replay metric K): its jumps are Euclidean, along W."""
    r = replay(sc, h=H, t_end=T_END, slaves=[SlaveSpec("e", True, sc.q0 + 0.01, sc.u0, np.eye(2)),
                                             SlaveSpec("k", True, sc.q0 + 0.01, sc.u0)])
    e, k = r.slaves["e"], r.slaves["k"]
    assert r.metric == "K (library projection)" and r.slave_metrics.keys() == {"e"}
    jumped = np.flatnonzero(np.any(e.q[1:] != e.q_pre[1:], axis=1))
    assert jumped.size
    for i in jumped:
        d = e.q[i + 1] - e.q_pre[i + 1]
        assert abs(d[1]) <= 1e-14 * abs(d[0])
    dk = k.q[1:] - k.q_pre[1:]
    assert np.any(np.abs(dk[:, 1]) > 1e-6)            # the K-metric jump moves both masses


def test_engine_choice_reaches_the_registry(sc, monkeypatch):
    from observer import impact as im
    seen = []
    real = ru.choose

    def spy(run, engine=None):
        chosen, note = real(run, engine)
        seen.append(chosen.name)
        return chosen, note
    monkeypatch.setattr(ru, "choose", spy)
    assert replay(sc, h=H, t_end=0.1, engine="python").settings["engine"] == "python"
    assert replay(sc, h=H, t_end=0.1).settings["engine"] == "compiled"
    # a registered law without a compiled code runs on the python engine
    monkeypatch.setitem(im.IMPACT_LAWS, "newton_py",
                        im.ImpactLawDefinition("newton_py", im.newton_impact, im.newton_step, None, "test law"))
    py = dataclasses.replace(sc, law=im.ImpactLaw.build("newton_py", 0.3, 1))
    assert replay(py, h=H, t_end=0.1).settings["engine"] == "python"
    assert seen == ["python", "compiled", "python"]


RUN_BASED = ("switching_generated", "projection_energy", "proposition1_exact", "proposition1_h_scaling",
             "lyapunov_decrease", "convergence")
"""The checks that run the scenario (the others are algebraic)."""


def _engines_that_ran(monkeypatch) -> list[str]:
    """The names of the engines whose ``run`` is called from now on (in call order)."""
    from observer.engines import ENGINES
    seen: list[str] = []
    for eng in {type(e) for e in ENGINES.values()}:
        def spy(self, run, _real=eng.run):
            seen.append(self.name)
            return _real(self, run)
        monkeypatch.setattr(eng, "run", spy)
    return seen


@pytest.mark.filterwarnings("ignore::observer.health.RunHealthWarning")     # the coarse h of the h-scaling
@pytest.mark.parametrize("engine", STEPPING_ENGINES)
def test_run_checks_runs_every_check_on_the_engine_named(sc, monkeypatch, engine):
    """``run_checks(engine=...)``, as ``simulate(engine=...)``: every run of every run-based
    check (the shared run, the Proposition 1 pairs at each h, the designs' pairs, the
    convergence run) is made by the engine named; ``--engine`` of the command line too."""
    seen = _engines_that_ran(monkeypatch)
    res = pc.run_checks(sc, RUN_BASED, h=H, t_end=0.2, engine=engine)
    assert [r.name for r in res] == list(RUN_BASED)
    assert not [r for r in res if "exception" in r.witness], [r.witness for r in res]
    assert len(seen) >= 8 and set(seen) == {engine}, seen
    seen.clear()
    from proofs_checks import cli
    cli.main(["double_mass", "--only", "proposition1_exact", "--h", str(H), "--t-end", "0.2",
              "--engine", engine])
    assert len(seen) == 2 and set(seen) == {engine}, seen


def test_run_checks_without_an_engine_takes_the_registry_default(sc, monkeypatch):
    """The near miss of the test above: without ``engine`` the runs go to the registry's first
    time-stepping engine that accepts them (the compiled one for double_mass)."""
    seen = _engines_that_ran(monkeypatch)
    pc.run_checks(sc, "proposition1_exact", h=H, t_end=0.2)
    assert seen == ["compiled", "compiled"]


def test_run_checks_refuses_an_unknown_engine(sc, capsys):
    from proofs_checks import cli
    with pytest.raises(InputError) as info:
        pc.run_checks(sc, "mass_spd", engine="numpy")
    assert info.value.field == "engine" and "'numpy'" in str(info.value)
    assert cli.main(["double_mass", "--only", "mass_spd", "--engine", "numpy"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "engine" in err[0] and "numpy" in err[0]
