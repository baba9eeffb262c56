"""Non-finite quantities are a stop, never a row (issue 20).

The reference for where a run must stop is independent of the loop's guard: an unstable
system (K = −κ < 0, built with ``check=False``) whose state grows like cosh(√κ t), so that
the step where a quantity first overflows is known from the closed form, and the numpy
stepper (:meth:`observer.stepping.MoreauJean.step`) applied to the last row, which must make
the named quantity non-finite. Both engines and the three compiled specializations
(general, lean, scalar) are run.
"""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from observer import loop
from observer.engines import python as python_engine
from observer.engines.compiled import driver
from observer.cli import main
from observer.io import read_result
from observer.loop import LoopInput, specialization
from observer.model import Harmonic, LinearSystem
from observer.observers import lyapunov
from observer.scenario import load_scenario
from observer.simulate import simulate
from observer.stepping import MoreauJean, NonFiniteState

KAPPA = 100.0          # K = −κ: growth rate √κ = 10
H = 0.01
BIG = float(np.finfo(float).max)
LAW = load_scenario("bouncing_ball").law
"""A scenario's impact law (its restitution array read-only, as the kernel's warm-up compiled it:
a writable one would be another numba signature, compiled anew)."""


def _unstable(n: int) -> LinearSystem:
    """n decoupled copies of q'' = κq (no damping), one contact far away (never closes)."""
    return LinearSystem(np.eye(n), np.zeros((n, n)), -KAPPA * np.eye(n), np.eye(n)[:, :1],
                        Harmonic.build("f", n), Harmonic.build("nu", 1, constant=1e3, kind="sin"), check=False)


def _input(n: int, t_end: float, observers: int = 0) -> LoopInput:
    st = MoreauJean(_unstable(n), LAW, H, t_end)
    q0 = [np.ones(n)] + [2.0 * np.ones(n)] * observers          # observers start 1 away
    u0 = [np.zeros(n)] * (observers + 1)
    return LoopInput(st, np.stack(q0), np.stack(u0), np.array([False] + [False] * observers), False)


def _overflow_time(amplitude: float) -> float:
    """Time at which √κ·amplitude·sinh(√κ t) (the exact velocity) reaches the largest double."""
    w = np.sqrt(KAPPA)
    return float(np.arcsinh(BIG / (w * amplitude)) / w)


def _assert_rows_finite(out) -> None:
    for name in ("q", "u", "P", "sigma"):
        assert np.all(np.isfinite(getattr(out, name))), name


def _next_state(inp: LoopInput, out) -> tuple[np.ndarray, np.ndarray]:
    """The numpy stepper's step from the last row (record_every = 1), every system."""
    st, k = inp.stepper, int(out.rows[-1])
    qs, us = [], []
    for s in range(inp.q0.shape[0]):
        q, u = out.q[s, -1], out.u[s, -1]
        act = np.flatnonzero(st.predicted_active(k, q, u))
        with np.errstate(all="ignore"):
            q1, u1, _, _ = st.step(k, q, u, act)
        qs.append(q1)
        us.append(u1)
    return np.stack(qs), np.stack(us)


@pytest.mark.parametrize("n, spec", [(1, "scalar"), (2, "lean")])
@pytest.mark.parametrize("engine", loop.ENGINES)
def test_a_state_overflowing_mid_run_stops_at_the_last_finite_step(monkeypatch, n, spec, engine):
    monkeypatch.setattr(driver, "WINDOW", 1000)                   # the stop is in window 8 of 8
    inp = _input(n, 80.0)
    assert specialization(1, 0, False, False, False, n, 1) == spec
    out = loop.run(inp, engine=engine)
    k = out.stopped_at
    assert k is not None and out.rows[-1] == k and out.rows.size == k + 1
    _assert_rows_finite(out)
    # the step after the last row overflows: the velocity, as the reason says
    q1, u1 = _next_state(inp, out)
    assert not np.all(np.isfinite(u1))
    assert out.stop_reason.startswith("non-finite u0 of the master")
    assert f"at t = {inp.stepper.time(k + 1):.9g} (step {k} of 8000)" in out.stop_reason
    # where the exact solution overflows (the θ-scheme's growth factor is e^{√κh}(1 + O(h³)))
    assert abs(inp.stepper.time(k + 1) - _overflow_time(1.0)) < 0.2


def test_the_engines_stop_at_the_same_step(monkeypatch):
    monkeypatch.setattr(driver, "WINDOW", 1000)
    inp = _input(1, 80.0)
    a, b = loop.run(inp, engine="compiled"), loop.run(inp, engine="python")
    assert a.stopped_at == b.stopped_at and a.stop_reason == b.stop_reason


def test_a_huge_but_finite_run_is_not_stopped():
    """The near miss: the same system up to t = 65 (u ≈ 1e283, past the guard's bound of
    5e299 only in the last steps before overflow, which this run does not reach): ok, whole."""
    inp = _input(1, 65.0)
    out = loop.run(inp)
    assert out.stopped_at is None and out.rows.size == inp.stepper.steps + 1
    assert np.max(np.abs(out.u)) > 1e280
    _assert_rows_finite(out)


@pytest.mark.parametrize("engine", loop.ENGINES)
def test_an_observer_whose_V_overflows_stops_before_that_row(monkeypatch, engine):
    """The general loop (an observer): its states stay finite long after V = ½v² − ½κe²
    (v ≈ 10 sinh(10t), e = cosh(10t) from a unit offset) overflows at |v| ≈ 1.9e154."""
    monkeypatch.setattr(driver, "WINDOW", 1000)
    inp = _input(1, 80.0, observers=1)
    out = loop.run(inp, engine=engine)
    k = out.stopped_at
    assert k is not None and out.rows[-1] == k
    _assert_rows_finite(out)
    assert "V of observer 'obs1'" in out.stop_reason
    V = lyapunov(inp.stepper.system, out.q[1], out.u[1], out.q[0], out.u[0])
    assert np.all(np.isfinite(V))
    q1, u1 = _next_state(inp, out)
    assert np.all(np.isfinite(q1)) and np.all(np.isfinite(u1))      # V, not the state
    with np.errstate(all="ignore"):
        assert not np.isfinite(lyapunov(inp.stepper.system, q1[1:], u1[1:], q1[:1], u1[:1])[0])
    v_over = np.sqrt(BIG)                                            # v·v = the largest double
    assert abs(inp.stepper.time(k + 1) - np.arcsinh(v_over / 10.0) / 10.0) < 0.2


def test_record_every_keeps_only_finite_rows(monkeypatch):
    monkeypatch.setattr(driver, "WINDOW", 1000)
    inp = _input(1, 80.0)
    full = loop.run(inp)
    out = loop.run(inp, record_every=7)
    assert out.stopped_at == full.stopped_at
    assert out.rows[-1] <= out.stopped_at < out.rows[-1] + 7
    _assert_rows_finite(out)
    assert np.array_equal(out.q[0], full.q[0, ::7])


def test_the_summary_store_stops_with_a_finite_summary(monkeypatch):
    monkeypatch.setattr(driver, "WINDOW", 1000)
    inp = _input(1, 80.0, observers=1)
    full = loop.run(inp)
    out = loop.run(inp, store="summary", record_every=10)
    assert out.stopped_at == full.stopped_at
    assert np.all(np.isfinite(out.summary["fields"])) and np.all(np.isfinite(out.V))
    _assert_rows_finite(out)



@pytest.mark.parametrize("engine", loop.ENGINES)
def test_a_streamed_run_reports_a_signal_only_when_one_stopped_it(monkeypatch, engine):
    """A streamed run (``on_chunk``: the SIGINT/SIGTERM handler installed) stopped by the
    overflow reports no signal (``stop_signal is None``, not an empty name); the same run with
    SIGINT sent from its first chunk stops after that window and names SIGINT."""
    monkeypatch.setattr(driver, "WINDOW", 1000)
    monkeypatch.setattr(python_engine, "PYTHON_CHUNK", 1000)
    inp = _input(1, 80.0)
    out = loop.run(inp, engine=engine, on_chunk=lambda c: None)
    assert out.stopped_at is not None and out.stop_reason.startswith("non-finite u0")
    assert out.stop_signal is None
    sent = []

    def on_chunk(c):
        if not sent:
            sent.append(int(c.rows[-1]))
            os.kill(os.getpid(), signal.SIGINT)

    before = signal.getsignal(signal.SIGINT)
    out = loop.run(inp, engine=engine, on_chunk=on_chunk)
    assert signal.getsignal(signal.SIGINT) is before
    assert out.stop_signal == "SIGINT" and out.stopped_at == sent[0] == 1000
    assert out.stop_reason.startswith(f"SIGINT at t = {inp.stepper.time(1000):.9g}")


def test_the_numpy_stepper_refuses_a_non_finite_free_velocity():
    st = MoreauJean(_unstable(1), LAW, H, 1.0)
    with pytest.raises(NonFiniteState):
        st.step(0, np.array([1.0]), np.array([np.inf]), np.array([0]))
    q1, u1, _, _ = st.step(0, np.array([1.0]), np.array([0.0]), np.array([0]))   # finite: a step
    assert np.isfinite(q1).all() and np.isfinite(u1).all()


# ---------------------------------------------------------------------------------------
# the case: a finite but huge forcing, through the CLI and the API
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("engine", loop.ENGINES)
def test_huge_forcing_is_a_stop_not_nan_rows(tmp_path, capsys, engine):
    path = tmp_path / "dm.csv"
    code = main(["run", "double_mass", "--set", "system.forcing.constant=[1e308,1e308]",
                 "--t-end", "0.01", "--engine", engine, "--out", str(path)])
    err = capsys.readouterr().err
    assert code == 1
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "non-finite V of observer 'jump'" in lines[0] and "t = 0.0001" in lines[0]
    assert "Traceback" not in err
    df, meta = read_result(path)
    assert meta["status"]["state"] == "stopped" and meta["stopped"]["step"] == 0
    assert len(df) == 1 and np.all(np.isfinite(df.to_numpy(dtype=float)))


def test_huge_forcing_through_the_api():
    sc = load_scenario("double_mass", {"system.forcing.constant": "[1e308,1e308]"})
    res = simulate(sc, t_end=0.01, observers="scenario")
    assert res.status.state.value == "stopped" and "non-finite" in res.status.reason
    assert np.all(np.isfinite(res.to_frame().to_numpy(dtype=float)))
    # the near miss: 1e150 keeps V finite (|u| ≈ 1e146 after a step): ok, every row
    sc = load_scenario("double_mass", {"system.forcing.constant": "[1e150,1e150]"})
    res = simulate(sc, t_end=0.01, observers="scenario")
    assert res.status.ok and res.t.size == 101
    assert np.all(np.isfinite(res.to_frame().to_numpy(dtype=float)))
