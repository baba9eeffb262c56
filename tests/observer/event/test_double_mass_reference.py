"""Issue 19: double_mass's event run against an independent 30-digit reference of the same
exact flow (:mod:`mp_exact`: the Taylor series of the matrix exponential between events,
impacts by Newton's law — Poisson's for one contact — and roots refined to 1e-25 s), over its
first second: the lift-off from the static contact equilibrium and the 14 impacts of the
landing that follows (speeds 0.32 → 0.0064 m/s), and the state at t = 1."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

import observer
from observer.event.master import run_master

_spec = importlib.util.spec_from_file_location("mp_exact", Path(__file__).with_name("mp_exact.py"))
mp_exact = importlib.util.module_from_spec(_spec)        # the reference beside this file (the
_spec.loader.exec_module(mp_exact)                       # tests run in importlib mode)
Reference = mp_exact.Reference

T_END = 1.0
TIME_TOL = 1e-12
"""Event times: the engine isolates each root to its time resolution (≈ 1e-16 s here);
measured ≤ 1e-15 s from the reference."""


def test_double_mass_event_times_and_state_at_t1_match_a_30_digit_reference():
    sc = observer.load_scenario("double_mass")
    ref = Reference(sc.system, sc.law.restitution, sc.q0, sc.u0, held=[0])
    ref_events = ref.run(T_END)
    res = run_master(sc, t_end=T_END, h=0.05)
    assert res.status.ok
    ev = res.events
    assert ev["kind"].iloc[0] == "stick" and ev["time"].iloc[0] == 0.0   # starts held
    got = ev.iloc[1:]
    kinds = [k for _, k, *_ in ref_events]
    assert kinds == ["liftoff"] + ["impact"] * 14
    assert got["kind"].tolist() == kinds and set(got["contact"]) == {0}
    t_ref = np.array([float(e[0]) for e in ref_events])
    np.testing.assert_allclose(got["time"].to_numpy(dtype=float), t_ref, rtol=0, atol=TIME_TOL)
    imp = got["kind"].to_numpy() == "impact"
    gm_ref = np.array([float(e[3]) for e in ref_events])[imp]
    gp_ref = np.array([float(e[4]) for e in ref_events])[imp]
    np.testing.assert_allclose(got["gamma_minus"].to_numpy(dtype=float)[imp], gm_ref, rtol=1e-11)
    np.testing.assert_allclose(got["gamma_plus"].to_numpy(dtype=float)[imp], gp_ref, rtol=1e-11)
    x_ref = np.array([float(v) for v in ref.z[:4]])
    np.testing.assert_allclose(res.state(T_END), x_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.frame.iloc[-1][["q0", "q1", "u0", "u1"]].to_numpy(dtype=float),
                               x_ref, rtol=0, atol=1e-12)
