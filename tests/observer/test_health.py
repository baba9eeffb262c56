"""Health in every run (issue 12, item 2): residual recomputed from the returned state, deepest
penetration against the scenario's length scale, smallest eigenvalue of L_I met, h·ω_max,
energy growth of unforced runs; warnings when a run leaves the regime where its numbers mean
anything; a run whose residual exceeds its tolerance stops there with truncated records.

Expected values are analytic (eigenvalues of 2×2 matrices, the built-ins' initial data) or
recomputed here from the returned states with the system matrices, never read back from the
code under test.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import observer.loop as loop
from observer.health import (ENERGY_ROUNDOFF, H_OMEGA_MAX, PENETRATION_MAX_REL, RunHealthWarning,
                             energy_growth)
from observer.loop import LoopInput
from observer.scenario import load_scenario
from observer.stepping import MoreauJean

# double_mass: M = I, K = [[100, -100], [-100, 200]], W = e_0 → ω_max² = 150 + 50√5,
# L = WᵀK⁻¹W = (K⁻¹)_00 = 200/10000; ℓ = |ν| = |q0_0| = 0.25 (the clearance)
DM_OMEGA = np.sqrt(150.0 + 50.0 * np.sqrt(5.0))
DM_L = 0.02
DM_ELL = 0.25


def _inp(name: str, t_end: float, h: float | None = None, jumps=(), tol: float = 1e-9, **kw):
    over = {"simulation.t_end": t_end, **({"simulation.h": h} if h else {})}
    sc = load_scenario(name, over)
    st = MoreauJean(sc.system, sc.law, sc.h, sc.t_end, sc.theta, residual_tol=tol)
    q0 = [sc.q0] + [np.asarray(sc.observer["q"], float) for _ in jumps]
    u0 = [sc.u0] + [np.asarray(sc.observer["u"], float) for _ in jumps]
    return LoopInput(st, np.stack(q0), np.stack(u0), np.array([False, *jumps]), False, **kw)


def _quiet_run(inp, **kw):
    """A run that must emit no health warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RunHealthWarning)
        return loop.run(inp, **kw)


def _gaps(inp, out) -> np.ndarray:
    st = inp.stepper
    return st.system.gaps(out.q[0], st.time(out.rows))


@pytest.mark.parametrize("engine", loop.ENGINES)
def test_in_regime_run_is_quiet_and_measured(engine):
    """double_mass at its h with the jump observer: no warning; the metrics are the analytic
    values and the deepest recorded gap."""
    inp = _inp("double_mass", 1.0, jumps=(True,))
    out = _quiet_run(inp, engine=engine)
    hl = out.health
    assert hl.warnings == ()
    assert hl.h_omega_max == pytest.approx(1e-4 * DM_OMEGA, rel=1e-12)
    assert hl.min_eig_L == pytest.approx(DM_L, rel=1e-12)
    assert hl.length_scale == DM_ELL
    g = _gaps(inp, out)
    assert hl.penetration == -g.min() > 0                       # every step recorded
    assert hl.penetration_rel == pytest.approx(-g.min() / DM_ELL, rel=1e-15)
    assert hl.max_residual <= inp.stepper.residual_tol
    assert out.stopped_at is None


@pytest.mark.parametrize("engine", loop.ENGINES)
def test_coarse_step_warns_penetration_and_h_omega(engine):
    """The issue's case: double_mass at h = 0.1 penetrates centimetres of a 25 cm clearance and
    h·ω_max = 1.62 > 1: both warned, on stderr (RunHealthWarning) and in the record."""
    inp = _inp("double_mass", 2.0, h=0.1)
    with pytest.warns(RunHealthWarning) as caught:
        out = loop.run(inp, engine=engine)
    hl = out.health
    msgs = [str(w.message) for w in caught]
    assert hl.h_omega_max == pytest.approx(0.1 * DM_OMEGA, rel=1e-12) and hl.h_omega_max > H_OMEGA_MAX
    pen = -_gaps(inp, out).min()
    assert pen / DM_ELL > PENETRATION_MAX_REL
    assert hl.penetration == pen
    assert any(m.startswith("h·ω_max = 1.62 > 1") for m in msgs)
    assert any(m.startswith(f"penetration {pen:.3g} = ") for m in msgs)
    assert set(msgs) == set(hl.warnings)


def test_chain_at_coarse_step_is_flagged():
    """The issue's other case: the chain at h = 1e-2 (V_jump jumps at coupling onset) is outside
    the regime: h·ω_max > 1 and penetration above 1 % of its length scale."""
    inp = _inp("rocking_chain", 1.0, h=1e-2)
    with pytest.warns(RunHealthWarning):
        out = loop.run(inp)
    sys_ = inp.stepper.system
    w_max = np.sqrt(np.max(np.linalg.eigvals(np.linalg.solve(sys_.M, sys_.K)).real))
    assert out.health.h_omega_max == pytest.approx(1e-2 * w_max, rel=1e-9)
    assert out.health.h_omega_max > H_OMEGA_MAX
    assert any(m.startswith("h·ω_max") for m in out.health.warnings)


def _newton_residuals(inp, out) -> np.ndarray:
    """Per closed step: |min(P, γ_{k+1} + eγ_k)| / max(|γ_free + eγ_k|, |ĜP|) from the returned
    states, with Ĝ = Wᵀ(M + hθC + h²θ²K)⁻¹W built here (single-contact scenarios)."""
    st = inp.stepper
    sys_, h, th = st.system, st.h, st.theta
    A = sys_.M + h * th * sys_.C + h * h * th * th * sys_.K
    G = sys_.W.T @ np.linalg.solve(A, sys_.W)
    t = st.time(out.rows)
    gam = sys_.contact_velocities(out.u[0], t)
    e = st.law.restitution
    P, act = out.P[0][1:], out.active[1:]
    GP = P @ G.T
    w = gam[1:] + e * gam[:-1]
    b = w - GP                                                  # γ_free + eγ_k
    r = np.abs(np.minimum(P, w)) / np.maximum(np.maximum(np.abs(b), np.abs(GP)), 1e-300)
    return r[act]


@pytest.mark.parametrize("engine", loop.ENGINES)
def test_residual_is_recomputed_from_the_state(engine):
    """impact_oscillator (Newton, one contact): the recorded max residual is round-off, like
    the residual recomputed here from u_k, u_{k+1}, P."""
    inp = _inp("impact_oscillator", 20.0)
    out = _quiet_run(inp, engine=engine)
    mine = _newton_residuals(inp, out)
    assert mine.size > 10
    assert mine.max() < 1e-12 and out.health.max_residual < 1e-12


@pytest.mark.parametrize("engine", loop.ENGINES)
def test_residual_above_tolerance_stops_the_run(engine):
    """A step whose applied impulse violates the law (Â⁻¹W applied 1.5× the Delassus matrix the
    LCP used: a broken scheme the solver's own residual cannot see) stops the run at that
    step: records truncated to the last complete step, no NaN, the reason named."""
    inp = _inp("bouncing_ball", 2.0)
    st = inp.stepper
    clean = loop.run(inp, engine=engine)
    k_hit = int(np.flatnonzero(clean.active[:, 0])[0]) - 1      # first closed step
    st.S = dataclasses.replace(st.S, AinvW=1.5 * st.S.AinvW)
    st._slices.clear()
    out = loop.run(inp, engine=engine)
    assert out.stopped_at == k_hit
    assert "complementarity residual" in out.stop_reason and f"step {k_hit}" in out.stop_reason
    assert out.rows.size == k_hit + 1 and np.all(np.isfinite(out.q)) and np.all(np.isfinite(out.u))
    assert np.array_equal(out.q, clean.q[:, :k_hit + 1])
    # one contact, C = K = 0: Ĝ = WᵀM⁻¹W, P = −b/Ĝ; applied 1.5ĜP = −1.5b, so
    # γ_{k+1} + eγ_k = b − 1.5b = −0.5b and the residual is min(|b|/Ĝ, 0.5|b|) / (1.5|b|)
    G = (st.system.W.T @ np.linalg.solve(st.system.M, st.system.W)).item()
    assert out.health.max_residual == pytest.approx(min(1.0 / G, 0.5) / 1.5, rel=1e-9)


def test_energy_of_an_unforced_run_does_not_grow():
    """bouncing_ball (gravity only, e = 0.8): the master's energy never rises above E_0 beyond
    the stated bound; recomputed here as ½uᵀMu − f_cᵀq."""
    inp = _inp("bouncing_ball", 6.0)
    out = _quiet_run(inp)
    sys_ = inp.stepper.system
    q, u = out.q[0], out.u[0]
    E = 0.5 * np.einsum("ki,ij,kj->k", u, sys_.M, u) - q @ sys_.forcing.constant
    assert E[-1] < 0.5 * E[0]                                  # impacts dissipated energy
    assert out.health.energy_growth is not None
    assert out.health.energy_growth <= out.health.energy_bound
    assert np.max(E - E[0]) <= 1e-12 * np.max(np.abs(E))


def test_energy_growth_metric_sees_a_rise():
    """The metric on states with a known rise: impact_oscillator's system (unforced part
    f_c = 0) at rest with its displacement growing from a to 1.1a: E from ½Ka² to ½K(1.1a)²,
    a growth of 0.21/1.21 of the energy scale; a falling energy is no growth."""
    sys_ = load_scenario("impact_oscillator").system
    assert not np.any(sys_.forcing.constant)
    K = sys_.K[0, 0]
    q = np.linspace(0.3, 0.33, 50)[:, None]
    u = np.zeros_like(q)
    assert energy_growth(sys_, q, u) == pytest.approx(0.21 / 1.21, rel=1e-12)
    assert energy_growth(sys_, q[::-1], u) == 0.0
    assert K > 0 and ENERGY_ROUNDOFF < 1e-6


def test_summary_store_gets_health_too():
    """store="summary" keeps every 10th row; health still covers every step (kernel)."""
    inp = _inp("double_mass", 1.0, jumps=(True,))
    full = _quiet_run(inp)
    summ = _quiet_run(inp, store="summary", record_every=10)
    assert summ.health.penetration == full.health.penetration
    assert summ.health.max_residual == full.health.max_residual
