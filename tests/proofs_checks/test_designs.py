"""proofs_checks.designs (the position jump's metric, check ``projection_energy``) on tiny
replays: every witness entry recomputed from independently replayed observer pairs (the
jump part J = ½‖e⁺‖²_K − ½‖e⁻‖²_K and V = ½‖v‖²_M + ½‖e‖²_K by per-step loops), the
margin and verdict from them, the not-applicable cases and the texts. Written against the
mutation run of ``designs.py`` (``tests/mutants/proofs_checks_runs.md``). About 2 s.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import proofs_checks as pc
from observer.observers import OBSERVER_DESIGNS, ObserverDesign
from proofs_checks import designs as de
from proofs_checks.lyapunov import roundoff_allowance
from proofs_checks.runs import SlaveSpec, replay

pytestmark = pytest.mark.filterwarnings("ignore:penetration .* reduce h")

H, T_END = 1e-2, 1.5
TINY = np.finfo(float).tiny


@pytest.fixture(scope="module")
def case():
    sc = pc.load("double_mass", {"impact.law": "newton", "impact.restitution": 0.3})
    specs = pc.CheckContext(sc, pc.CheckSettings(h=H, t_end=T_END)).slave_specs()
    return sc, specs


def _pair_by_hand(sc, design, specs):
    """J_k, allowance_k and V_k of two observers of ``design`` (replayed here, not by the module)."""
    s = sc.system
    N = design.metric_matrix(s)
    pair = [SlaveSpec(f"{design.name}_{x}", True, sp.q0, sp.u0, N) for x, sp in zip("ab", specs[:2])]
    run = replay(sc, h=H, t_end=T_END, slaves=pair, master_projection=sc.master_projection)
    A, B = run.slaves[pair[0].name], run.slaves[pair[1].name]
    steps = run.t.size - 1
    J, V = np.zeros(steps), np.zeros(steps)
    for k in range(steps):
        e1, em = A.q[k + 1] - B.q[k + 1], A.q_pre[k + 1] - B.q_pre[k + 1]
        J[k] = 0.5 * (e1 @ s.K @ e1 - em @ s.K @ em)
        v, e = A.u[k] - B.u[k], A.q[k] - B.q[k]
        V[k] = max(0.5 * v @ s.M @ v + 0.5 * e @ s.K @ e, TINY)
    return J, roundoff_allowance(run, A, B), V, run


def test_witness_and_margin_recomputed_from_the_pairs(case):
    sc, specs = case
    designs = {n: d for n, d in OBSERVER_DESIGNS.items() if n in ("jump", "jump_identity", "nojump")}
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)                 # nothing deprecated on the way
        r = de.check_projection_energy(sc, specs, h=H, t_end=T_END, designs=designs)
    assert set(r.witness["designs"]) == {"jump", "jump_identity"}          # no-jump designs skipped
    assert r.witness["metrics"] == {"jump": "K", "jump_identity": "identity"}
    for name in ("jump", "jump_identity"):
        J, allow, V, run = _pair_by_hand(sc, OBSERVER_DESIGNS[name], specs)
        assert np.any(J != 0)
        assert r.witness["designs"][name] == pytest.approx(np.max(J / V), rel=1e-9, abs=1e-13)
        if name == "jump":
            excess = (J - allow) / V
            k = int(np.argmax(excess))
            assert r.margin == pytest.approx(-excess[k], rel=1e-9)
            assert r.witness["design"] == "jump" and r.witness["step"] == k
            assert r.witness["t"] == run.t[k]
            assert r.witness["J"] == pytest.approx(J[k], rel=1e-9, abs=1e-15)
            assert r.witness["allowance"] == pytest.approx(allow[k], rel=1e-9)
            assert r.witness["V"] == pytest.approx(V[k], rel=1e-9)
    assert r.witness["designs"]["jump_identity"] > 0 and r.margin > 0
    assert r.passed is True and r.tolerance == 0.0 and r.reason == "" and r.name == "projection_energy"
    assert r.evidence == "sampled"                                       # measured along one run
    assert r.equation == de.EQUATION and r.summary_keys == ("designs",)


class _Mislabelled(ObserverDesign):
    """Claims the K metric, projects in the identity metric."""

    def metric_matrix(self, system):
        return np.eye(system.n)


def test_failure_text_tolerance_edge_and_the_worst_K_design(case):
    sc, specs = case
    bad = _Mislabelled("bad", True, "K", "bad", "k")
    r = de.check_projection_energy(sc, specs, h=H, t_end=T_END,
                                   designs={"jump": OBSERVER_DESIGNS["jump"], "bad": bad})
    J, allow, V, run = _pair_by_hand(sc, bad, specs)
    excess = (J - allow) / V
    k = int(np.argmax(excess))
    assert r.passed is False and r.witness["design"] == "bad" and r.witness["step"] == k
    assert r.margin == pytest.approx(-excess[k], rel=1e-9) and r.margin < -0.01
    assert r.reason == (f"a K-metric position jump raised V by {-r.margin:.3g}·V beyond round-off "
                        f"at step {k}")
    # the margin exactly at −tolerance passes
    edge = de.check_projection_energy(sc, specs, h=H, t_end=T_END, designs={"bad": bad}, tolerance=-r.margin)
    assert edge.passed is True and edge.margin == r.margin and edge.reason == ""
    # the K design alone: its own worst step
    ok = de.check_projection_energy(sc, specs, h=H, t_end=T_END, designs={"jump": OBSERVER_DESIGNS["jump"]})
    assert ok.witness["design"] == "jump" and ok.margin > r.margin


def test_not_applicable_cases(case):
    sc, specs = case
    r = de.check_projection_energy(sc, specs, h=H, t_end=T_END, designs={"jump_identity": OBSERVER_DESIGNS["jump_identity"]})
    assert r.passed is None and np.isnan(r.margin) and r.tolerance == 0.0
    assert r.reason == "no registered design projects in the K metric" and r.equation == de.EQUATION
    assert r.name == "projection_energy"
    assert set(r.witness["designs"]) == {"jump_identity"} and r.summary_keys == ("designs",)
    ball = pc.load("bouncing_ball")
    r = de.check_projection_energy(ball, specs, h=H, t_end=T_END, tolerance=0.25)
    assert r.passed is None and np.isnan(r.margin) and r.tolerance == 0.25 and r.witness == {}
    assert r.reason == ("K is singular (exact: Kx = 0, x in stiffness_spd's witness): ½‖e‖²_K is no norm "
                        "and there is no K-metric projection") and r.equation == de.EQUATION and r.name == "projection_energy"


def test_jump_parts_by_hand(case):
    sc, specs = case
    J, allow, V, run = _pair_by_hand(sc, OBSERVER_DESIGNS["jump"], specs)
    Jm, allow_m = de.jump_parts(run, "jump_a", "jump_b")
    assert Jm.shape == J.shape and np.allclose(Jm, J, rtol=1e-12, atol=1e-12 * np.max(V))
    assert np.array_equal(allow_m, allow)


def test_default_registry_and_a_projected_master():
    """designs=None measures every registered design with position jumps; the pairs follow
    the scenario's master (here projected on its own closed set, which changes χ)."""
    sc = pc.load("double_mass", {"impact.law": "newton", "impact.restitution": 0.3,
                                 "simulation.master_projection": True})
    assert sc.master_projection is True
    specs = pc.CheckContext(sc, pc.CheckSettings(h=H, t_end=T_END)).slave_specs()
    r = de.check_projection_energy(sc, specs, h=H, t_end=T_END)
    jumping = {n for n, d in OBSERVER_DESIGNS.items() if d.position_jumps}
    assert set(r.witness["designs"]) == jumping
    J, allow, V, run = _pair_by_hand(sc, OBSERVER_DESIGNS["jump"], specs)
    plain = replay(pc.load("double_mass", {"impact.law": "newton", "impact.restitution": 0.3}), h=H, t_end=T_END)
    assert not np.array_equal(run.master.active, plain.master.active)      # the projection matters here
    excess = (J - allow) / V
    assert r.witness["step"] == int(np.argmax(excess)) and r.margin == pytest.approx(-np.max(excess), rel=1e-9)
    assert r.witness["designs"]["jump"] == pytest.approx(np.max(J / V), rel=1e-9, abs=1e-13)
    # an oblique design's largest J/V follows the projected master's χ (0.028 here; 0.096
    # with the plain master's)
    Ji, _, Vi, _ = _pair_by_hand(sc, OBSERVER_DESIGNS["jump_identity"], specs)
    assert r.witness["designs"]["jump_identity"] == pytest.approx(np.max(Ji / Vi), rel=1e-9)
