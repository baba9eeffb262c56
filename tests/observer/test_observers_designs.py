"""Observer designs from the registry: the projection metric of the position jumps.

The K-metric projection is K-orthogonal, so the jump part of ΔV between two observers is
−½‖Δg⁻‖²_{L_I⁻¹} ≤ 0; in another metric it has no sign (paper section 1: the Euclidean
projection is "non-energy consistent"). Checked here on the mathematics itself (random
matrices, no library code), on the library's runs (the applied jump is the N-metric
projection, recomputed from the returned states), and through the proof check.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import observer
import proofs_checks as pc
from observer.observers import OBSERVER_DESIGNS, ObserverDesign
from proofs_checks.runs import SlaveSpec, replay


def _spd(rng, n):
    A = rng.standard_normal((n, n))
    return A @ A.T + n * np.eye(n)


def _project(q, N, W, c):
    """The N-metric projection of q onto {Wᵀq + c = 0} (numpy only)."""
    NinvW = np.linalg.solve(N, W)
    return q - NinvW @ np.linalg.solve(W.T @ NinvW, W.T @ q + c)


def test_jump_part_has_a_sign_in_the_K_metric_only():
    rng = np.random.default_rng(7)
    worst_K, worst_I = -np.inf, -np.inf
    for _ in range(300):
        n, m = rng.integers(2, 7), 1
        m = int(rng.integers(1, n))
        K, W, c = _spd(rng, n), rng.standard_normal((n, m)), rng.standard_normal(m)
        qa, qb = rng.standard_normal((2, n))
        e0 = qa - qb

        def jump(N):
            e1 = _project(qa, N, W, c) - _project(qb, N, W, c)
            return 0.5 * (e1 @ K @ e1 - e0 @ K @ e0) / (0.5 * e0 @ K @ e0)

        worst_K = max(worst_K, jump(K))
        worst_I = max(worst_I, jump(np.eye(n)))
    assert worst_K <= 1e-12
    assert worst_I > 0.1                  # the identity metric raises V on some draws


@pytest.mark.parametrize("name", [n for n, d in OBSERVER_DESIGNS.items() if d.position_jumps])
def test_applied_jump_is_the_designs_projection(name):
    """From the returned states: after each projected step the closed gaps are zero and
    N(q⁺ − q⁻) lies in range(W_I), N the design's metric (rocking chain: M is not ∝ I)."""
    sc = observer.load_scenario("rocking_chain", {"param.N": 3, "simulation.t_end": 0.4})
    sys_ = sc.system
    d = OBSERVER_DESIGNS[name]
    N = {"K": sys_.K, "mass": sys_.M, "identity": np.eye(sys_.n)}[d.metric]
    spec = SlaveSpec(name, True, sc.q0 + 1e-3, sc.u0, d.metric_matrix(sys_))
    run = replay(sc, slaves=[spec])
    tr = run.slaves[name]
    jumps = 0
    for k in range(1, run.t.size):
        act = np.flatnonzero(tr.active[k])
        if act.size == 0:
            continue
        W = sys_.W[:, act]
        g = tr.q[k] @ W + sys_.nu(run.t[k])[act]
        assert np.max(np.abs(g)) <= 1e-12
        dq = N @ (tr.q[k] - tr.q_pre[k])
        coef = np.linalg.lstsq(W, dq, rcond=None)[0]
        assert np.linalg.norm(dq - W @ coef) <= 1e-9 * max(np.linalg.norm(dq), 1e-300)
        jumps += bool(np.any(tr.q[k] != tr.q_pre[k]))
    assert jumps >= 3


def test_engines_agree_for_every_design():
    sc = observer.load_scenario("rocking_chain", {"param.N": 3, "simulation.t_end": 0.5})
    names = tuple(OBSERVER_DESIGNS)
    co = observer.simulate(sc, observers=names)
    py = observer.simulate(sc, observers=names, engine="python")
    for n in names:
        scale = np.max(np.abs(py.slaves[n].q))
        np.testing.assert_allclose(co.slaves[n].q, py.slaves[n].q, rtol=0, atol=1e-12 * scale)


def test_projection_energy_check_passes_for_K_and_measures_the_others():
    r = pc.run_checks("double_mass", only="projection_energy", t_end=3.0, h=1e-3)[0]
    assert r.passed is True and r.tolerance == 0.0
    jumping = {n for n, d in OBSERVER_DESIGNS.items() if d.position_jumps}
    assert set(r.witness["designs"]) == jumping
    assert r.witness["designs"]["jump"] <= 1e-12
    # double_mass: the mass- and identity-metric jumps raise V by a third at one step
    assert r.witness["designs"]["jump_mass"] > 0.1
    assert r.witness["designs"]["jump_identity"] > 0.1


class _MislabelledDesign(ObserverDesign):
    """A buggy design: claims the K metric, projects in another one."""

    def metric_matrix(self, system):
        return self.wrong


def _mislabelled(N):
    d = _MislabelledDesign("bad", True, "K", "bad", "k")
    object.__setattr__(d, "wrong", N)
    return d


def test_projection_energy_check_fails_on_a_wrong_metric_and_a_near_miss():
    sc = observer.load_scenario("double_mass", {"simulation.t_end": 3.0, "simulation.h": 1e-3})
    specs = pc.CheckContext(sc).slave_specs()
    bad = pc.check_projection_energy(sc, specs, h=1e-3, t_end=3.0,
                                     designs={"bad": _mislabelled(np.eye(2))})
    assert bad.passed is False and bad.margin < -0.1 and "raised V" in bad.reason
    # near miss: the metric K·diag(1 + 1e-3, 1 − 1e-3), 0.1 % off K: a jump raises V by less
    # one part in a million of V (measured 9.6e-7), far above round-off, far below the
    # identity metric's third
    K = sc.system.K
    near = K @ np.diag([1 + 1e-3, 1 - 1e-3])
    near = 0.5 * (near + near.T)
    r = pc.check_projection_energy(sc, specs, h=1e-3, t_end=3.0, designs={"bad": _mislabelled(near)})
    assert r.passed is False and -1e-2 < r.margin < 0


def test_toy_design_runs_everywhere_from_one_registry_entry(monkeypatch):
    toy = ObserverDesign("toy_jump", True, "identity", "toy", "tab:olive", "-")
    monkeypatch.setitem(OBSERVER_DESIGNS, "toy_jump", toy)
    res = observer.simulate("double_mass", t_end=1.0, observers=("toy_jump",))
    assert "V_toy_jump" in res.to_frame().columns
    r = pc.run_checks("double_mass", only="projection_energy", t_end=1.0, h=1e-3)[0]
    assert "toy_jump" in r.witness["designs"]


def test_design_registry_rejects_a_metric_without_jumps():
    with pytest.raises(ValueError, match="metric"):
        ObserverDesign("x", False, "K", "x", "k")
    with pytest.raises(ValueError, match="metric"):
        dataclasses.replace(OBSERVER_DESIGNS["jump"], metric="euclid")


@pytest.mark.parametrize("name, K_energy", [("bouncing_ball", False), ("random_system", True)])
def test_summary_run_splits_dV_of_other_metrics_from_the_states_before_the_jump(name, K_energy):
    """A short summary run keeps every step and splits ΔV into its damping, impulse and jump
    parts. In the mass metric the jump moves q by M⁻¹WΣ, not K⁻¹WΣ: the jump part must come from
    the recorded pre-jump states (as in a full run), so the three parts add up to ΔV per step
    to round-off. Before the fix a summary run used the K formula: a singular K (the ball)
    failed with LinAlgError, an SPD one gave a jump part that did not add up."""
    sc = observer.load_scenario(name, {"simulation.t_end": 0.5})
    n = sc.system.n
    rng = np.random.default_rng(3)
    X = np.hstack([0.05 * rng.standard_normal(n), 0.05 * rng.standard_normal(n)])
    slaves = [observer.Slave("jump_mass#0", True, sc.q0 + X[:n], sc.u0 + X[n:],
                             OBSERVER_DESIGNS["jump_mass"])]
    runs = {store: observer.simulate(sc, observers=slaves, store=store) for store in ("summary", "full")}
    for store, res in runs.items():
        s = res.slaves["jump_mass#0"]
        resid = np.diff(s.V) - s.dV_damping[1:] - s.dV_impulse[1:] - s.dV_projection[1:]
        assert np.abs(resid).max() <= 1e-12 * max(s.V.max(), 1e-300), (store, np.abs(resid).max())
    # K = 0 (the ball): the jumps carry no K energy, their part is 0; else the jumps move V
    assert np.any(runs["summary"].slaves["jump_mass#0"].dV_projection != 0.0) == K_energy
    np.testing.assert_allclose(runs["summary"].slaves["jump_mass#0"].dV_projection,
                               runs["full"].slaves["jump_mass#0"].dV_projection, rtol=0, atol=1e-15)
