"""proofs_checks.proposition (Proposition 1, exact and h → 0) on short runs: every witness
entry recomputed from master/slave pairs simulated here with :func:`observer.simulate`
(the exact pairs' largest differences, first differing time, closed steps, the projected
master's multiplier; the h-scaling's RMS/max of √(2V) and the fitted order by a plain
least-squares formula), the margins, verdicts and texts, the known-bad inputs (a detector
χ with a tolerance, a one-ulp offset) and the not-applicable cases. Written against the
mutation run of ``proposition.py`` (``tests/mutants/proofs_checks_runs.md``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import observer
import proofs_checks as pc
from observer import Slave
from proofs_checks import proposition as pr

pytestmark = pytest.mark.filterwarnings("ignore:penetration .* reduce h")

H, T_END = 2e-3, 0.6


@pytest.fixture(scope="module")
def dm():
    # double_mass hits the wall within the first half second
    return pc.load("double_mass", {"simulation.t_end": T_END, "simulation.h": H})


def _pair(sc, h, t_end, projection, jumps, offset=0.0):
    name = "jump" if jumps else "nojump"
    r = observer.simulate(sc, h=h, t_end=t_end, master_projection=projection, source="master", coupling=None,
                          observers=[Slave(name, jumps, sc.q0 + offset, sc.u0)])
    return r, r.slaves[name]


def _diff(r, s):
    return np.max(np.hstack([np.abs(s.q - r.q), np.abs(s.u - r.u), np.abs(s.P - r.P)]), axis=1)


def test_exact_witness_by_hand(dm):
    r = pr.check_proposition1_exact(dm)
    assert r.passed is True and r.margin == 0.0 and r.tolerance == 0.0 and r.reason == ""
    assert r.evidence == "proved" and r.verdict == "matched pairs bitwise identical on this run"
    assert r.name == "proposition1_exact" and r.equation == "Proposition 1 (discrete, exact); eqs. (12)-(14)"
    w = r.witness
    for label, projection, jumps in (("plain_master__nojump_slave", False, False),
                                     ("projected_master__jump_slave", True, True)):
        res, s = _pair(dm, None, None, projection, jumps)
        assert w[f"{label}_max_diff"] == 0.0 and w[f"{label}_first_diff_time"] is None
        closed = int(sum(res.active[k].any() for k in range(1, res.t.size)))
        assert closed > 0 and w[f"{label}_closed_steps"] == closed
        if projection:
            assert w["projected_master_max_multiplier"] == float(np.max(np.abs(res.sigma))) > 0
    assert w["horizon"] == pytest.approx(T_END) and w["h"] == pytest.approx(H, rel=1e-12)
    assert "chi_tolerance" not in w and "slave_offset" not in w
    assert r.summary_keys == ("plain_master__nojump_slave_max_diff", "plain_master__nojump_slave_closed_steps",
                              "projected_master__jump_slave_max_diff", "projected_master__jump_slave_closed_steps")


def test_exact_near_miss_one_ulp_by_hand(dm):
    ulp = float(np.spacing(np.max(np.abs(dm.q0))))
    r = pr.check_proposition1_exact(dm, h=4e-3, t_end=0.3, slave_offset=ulp)
    worst = 0.0
    for label, projection, jumps in (("plain_master__nojump_slave", False, False),
                                     ("projected_master__jump_slave", True, True)):
        res, s = _pair(dm, 4e-3, 0.3, projection, jumps, ulp)
        d = _diff(res, s)
        assert r.witness[f"{label}_max_diff"] == float(d.max()) > 0
        assert r.witness[f"{label}_first_diff_time"] == float(res.t[np.flatnonzero(d > 0)[0]])
        worst = max(worst, float(d.max()))
    assert r.margin == -worst and r.passed is False and r.witness["slave_offset"] == ulp
    assert r.witness["h"] == pytest.approx(4e-3, rel=1e-12) and r.witness["horizon"] == pytest.approx(0.3)
    assert r.reason == "plain_master__nojump_slave: the slave leaves the master's trajectory"


def test_exact_detector_with_a_tolerance_and_no_K(dm):
    bad = pr.check_proposition1_exact(dm, chi_tolerance=1e-3)
    assert bad.passed is False and bad.witness["chi_tolerance"] == 1e-3 and bad.margin < 0
    assert bad.margin == -max(bad.witness["plain_master__nojump_slave_max_diff"],
                              bad.witness["projected_master__jump_slave_max_diff"])
    ball = pc.load("bouncing_ball", {"simulation.t_end": 1.5})
    r = pr.check_proposition1_exact(ball)
    assert r.witness["projected_master__jump_slave"].startswith("not applicable: K is singular (exact")
    assert "projected_master__jump_slave_max_diff" not in r.witness
    assert r.passed is True and r.reason.startswith("jump pair not applicable: K is singular (exact")
    assert r.witness["plain_master__nojump_slave_closed_steps"] > 0
    off = pr.check_proposition1_exact(ball, slave_offset=1e-9)
    assert off.reason == ("plain_master__nojump_slave: the slave leaves the master's trajectory; "
                          "jump pair not applicable: K is singular (exact: Kx = 0, x in stiffness_spd's witness): "
                          "the pair needs the K-metric projection")


def _fit(hs, y):
    x, z = np.log(hs), np.log(y)
    return float(np.sum((x - x.mean()) * (z - z.mean())) / np.sum((x - x.mean()) ** 2))


def test_h_scaling_witness_by_hand(dm):
    factors = (4.0, 2.0, 1.0)
    r = pr.check_proposition1_h_scaling(dm, h=H, t_end=T_END, factors=factors, min_order=0.25)
    hs = np.array([H * f for f in factors])
    assert np.array_equal(r.witness["h"], hs)
    orders = {}
    for label, projection, jumps in (("plain_master__jump_slave", False, True),
                                     ("projected_master__nojump_slave", True, False)):
        rms, mx, closed = [], [], []
        for hh in hs:
            res, s = _pair(dm, hh, T_END, projection, jumps)
            d = np.sqrt(2.0 * np.maximum(s.V, 0.0))
            rms.append(math.sqrt(float(np.mean(d ** 2))))
            mx.append(float(np.max(d)))
            closed.append(int(sum(res.active[k].any() for k in range(1, res.t.size))))
        assert r.witness[f"{label}_rms"] == pytest.approx(rms, rel=1e-12)
        assert r.witness[f"{label}_max"] == pytest.approx(mx, rel=1e-12)
        assert r.witness[f"{label}_closed_steps"] == closed and min(closed) > 0
        orders[label] = _fit(hs, np.array(rms))
        assert r.witness[f"{label}_order"] == pytest.approx(orders[label], rel=1e-9)
    worst = min(orders, key=orders.get)
    assert r.margin == pytest.approx(orders[worst] - 0.25, rel=1e-9)
    assert r.passed is (orders[worst] >= 0.25) and r.tolerance == 0.0
    assert r.witness["horizon"] == pytest.approx(T_END)
    assert r.name == "proposition1_h_scaling" and r.equation == "Proposition 1 (continuous limit h → 0)"
    assert r.summary_keys == ("plain_master__jump_slave_order", "projected_master__nojump_slave_order",
                              "plain_master__jump_slave_rms", "projected_master__nojump_slave_rms", "h")
    # the verdict's edge and the failure text: min_order just above the worst order
    high = pr.check_proposition1_h_scaling(dm, h=H, t_end=T_END, factors=factors, min_order=orders[worst] + 0.01)
    assert high.passed is False and high.margin == pytest.approx(-0.01, abs=1e-9)
    assert r.evidence == "sampled" and high.evidence == "sampled"         # a fitted order proves nothing
    assert high.reason == (f"{worst}: the difference does not shrink with h (order {orders[worst]:.2f})")
    edge = pr.check_proposition1_h_scaling(dm, h=H, t_end=T_END, factors=factors, min_order=r.witness[f"{worst}_order"])
    assert edge.passed is True and edge.margin == 0.0 and edge.reason == ""


def test_h_scaling_without_contact_and_without_K():
    # the masses fly apart from the wall: no contact in 0.05 s, both pairs identical
    sc = pc.load("double_mass", {"simulation.t_end": 0.05})
    r = pr.check_proposition1_h_scaling(sc, h=5e-3, factors=(2.0, 1.0))
    assert r.passed is True and r.margin == math.inf and r.tolerance == 0.0
    assert r.reason == "no contact event in the horizon: both pairs identical at every h"
    assert r.witness["plain_master__jump_slave_order"] == math.inf
    assert r.witness["plain_master__jump_slave_rms"] == [0.0, 0.0]
    assert r.name == "proposition1_h_scaling" and r.equation == "Proposition 1 (continuous limit h → 0)"
    assert r.summary_keys == ("plain_master__jump_slave_order", "projected_master__nojump_slave_order",
                              "plain_master__jump_slave_rms", "projected_master__nojump_slave_rms", "h")
    na = pr.check_proposition1_h_scaling(pc.load("bouncing_ball"))
    assert na.passed is None and na.reason == ("K is singular (exact: Kx = 0, x in stiffness_spd's witness): "
                                               "both mismatched pairs need the K-metric projection")
    assert na.name == "proposition1_h_scaling" and na.equation == "Proposition 1 (continuous limit h → 0)"


def test_h_scaling_default_step_factors_and_order(dm):
    r = pr.check_proposition1_h_scaling(dm, t_end=0.2)
    assert np.allclose(r.witness["h"], [16 * H, 4 * H, H], rtol=1e-15)
    assert r.witness["horizon"] == pytest.approx(0.2)
    worst = min(r.witness["plain_master__jump_slave_order"], r.witness["projected_master__nojump_slave_order"])
    assert r.margin == pytest.approx(worst - 0.5, rel=1e-12)             # min_order 0.5


def test_the_check_ignores_the_scenarios_observer_source_and_coupling_window(dm):
    """The proposition's slave is driven by the master's χ over the whole run, whatever the
    scenario's [observer] table says (a coupling window; the slave's own χ as source, which
    would make the mismatched pairs' V vanish)."""
    ref = pr.check_proposition1_h_scaling(dm, h=H, t_end=0.3, factors=(2.0, 1.0))
    assert min(ref.witness["plain_master__jump_slave_rms"]) > 0
    for ov in ({"observer.coupling": [0.3, 20.0]}, {"observer.source": "self"}):
        sc = pc.load("double_mass", {"simulation.t_end": T_END, "simulation.h": H, **ov})
        r = pr.check_proposition1_exact(sc)
        assert r.passed is True and r.margin == 0.0, ov
        assert r.witness["plain_master__nojump_slave_closed_steps"] > 0
        r = pr.check_proposition1_h_scaling(sc, h=H, t_end=0.3, factors=(2.0, 1.0))
        for label in ("plain_master__jump_slave_rms", "projected_master__nojump_slave_rms"):
            assert r.witness[label] == pytest.approx(ref.witness[label], rel=1e-6), (ov, label)


def _detector_pair(sc, h, t_end, projection, jumps, tol):
    """The known-bad detector χ_i = [g_pred,i ≤ δ] of the projected/plain master, by hand."""
    from proofs_checks.runs import SlaveSpec, replay
    master = replay(sc, h=h, t_end=t_end, master_projection=projection)
    chi = np.zeros(master.chi.shape, dtype=bool)
    for k in range(1, chi.shape[0]):
        chi[k] = master.g_pred[k] <= tol
    r = replay(sc, h=h, t_end=t_end, master_projection=projection, chi=chi,
               slaves=[SlaveSpec("s", jumps, sc.q0.copy(), sc.u0.copy())])
    return r, r.slaves["s"], r.master, chi


def test_detector_with_a_tolerance_by_hand(dm):
    # δ = 1e-4 on a grid other than the scenario's: the plain and the projected master's
    # detectors differ here, and so does the jump pair's largest difference (1e-4 vs 1e-3)
    tol, h, t_end = 1e-4, 4e-3, 0.5
    r = pr.check_proposition1_exact(dm, h=h, t_end=t_end, chi_tolerance=tol)
    assert r.witness["h"] == pytest.approx(h, rel=1e-12) and r.witness["horizon"] == pytest.approx(t_end)
    for label, projection, jumps in (("plain_master__nojump_slave", False, False),
                                     ("projected_master__jump_slave", True, True)):
        run, s, m, chi = _detector_pair(dm, h, t_end, projection, jumps, tol)
        assert chi.any()
        d = np.max(np.hstack([np.abs(s.q - m.q), np.abs(s.u - m.u), np.abs(s.P - m.P)]), axis=1)
        bad = np.flatnonzero(d > 0)
        assert r.witness[f"{label}_max_diff"] == float(d.max())
        assert r.witness[f"{label}_first_diff_time"] == (float(run.t[bad[0]]) if bad.size else None)
        if projection:
            assert bad.size and bad[0] > 1                # identical at first, then apart
            assert r.witness["projected_master_max_multiplier"] == float(np.max(np.abs(m.sigma))) > 0
    # the h-scaling through the detector: V of the detector pairs, by hand
    hs = pr.check_proposition1_h_scaling(dm, h=h, t_end=t_end, factors=(2.0, 1.0), chi_tolerance=tol)
    clean = pr.check_proposition1_h_scaling(dm, h=h, t_end=t_end, factors=(2.0, 1.0))
    run, s, m, _ = _detector_pair(dm, h, t_end, False, True, tol)
    e, v = s.q - m.q, s.u - m.u
    V = 0.5 * np.einsum("ki,ij,kj->k", v, dm.system.M, v) + 0.5 * np.einsum("ki,ij,kj->k", e, dm.system.K, e)
    rms = math.sqrt(float(np.mean(2.0 * np.maximum(V, 0.0))))
    assert hs.witness["plain_master__jump_slave_rms"][1] == pytest.approx(rms, rel=1e-9)
    assert hs.witness["plain_master__jump_slave_rms"] != clean.witness["plain_master__jump_slave_rms"]


def test_worst_pair_is_the_one_with_the_lower_order():
    """restitution 0.2: the projected pair converges more slowly (order ≈ 1.06 against 2.2)."""
    sc = pc.load("double_mass", {"impact.restitution": 0.2, "simulation.t_end": T_END})
    r = pr.check_proposition1_h_scaling(sc, h=H, factors=(4.0, 2.0, 1.0), min_order=1.5)
    po, pp = r.witness["plain_master__jump_slave_order"], r.witness["projected_master__nojump_slave_order"]
    assert pp < 1.5 < po
    assert r.margin == pytest.approx(pp - 1.5, rel=1e-12) and r.passed is False
    assert r.reason.startswith("projected_master__nojump_slave: the difference does not shrink")
