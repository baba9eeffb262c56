"""Non-finite states in the event-driven integrator are a stop, never a traceback or a NaN row
(issue 20).

The reference is the closed form of an unstable system (K = −κ < 0, built with
``check=False`` as in ``tests/observer/test_loop_nonfinite.py``): from q(0) = 1, u(0) = 0 the exact solution
is q = cosh(√κ t), u = √κ sinh(√κ t), so the time where u overflows is known; an observer
started at q = 2 has e = cosh(√κ t), v = √κ sinh(√κ t), whose V overflows long before.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from observer.cli import main
from observer.io import read_result
from observer.model import Harmonic, LinearSystem
from observer.observers import lyapunov
from observer.scenario import Scenario, load_scenario
from observer.simulate import simulate

KAPPA = 100.0              # growth rate √κ = 10
W = np.sqrt(KAPPA)
H = 0.01
BIG = float(np.finfo(float).max)
T_OVERFLOW = float(np.arcsinh(BIG / W) / W)      # u = √κ sinh(√κ t) reaches the largest double
LAW = load_scenario("bouncing_ball").law


def _unstable(t_end: float) -> Scenario:
    """q'' = κq, one contact 1e3 away on the side the motion leaves (it never closes)."""
    system = LinearSystem(np.eye(1), np.zeros((1, 1)), -KAPPA * np.eye(1), np.eye(1),
                          Harmonic.build("f", 1), Harmonic.build("nu", 1, constant=1e3, kind="sin"),
                          check=False)
    return Scenario("unstable", "q'' = κq", system, LAW, np.ones(1), np.zeros(1), t_end, H,
                    observer={"q": [2.0], "u": [0.0]})


def _quiet_simulate(*args, **kwargs):
    """simulate with every warning an error: no RuntimeWarning may reach the user."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return simulate(*args, **kwargs)


def _assert_finite(res) -> None:
    assert np.all(np.isfinite(res.to_frame().to_numpy(dtype=float)))


def test_an_overflowing_master_stops_at_or_before_the_closed_form_overflow():
    res = _quiet_simulate(_unstable(80.0), integrator="event")
    assert res.status.state.value == "stopped"
    reason = res.status.reason
    assert reason.startswith("non-finite ") and "of the master" in reason
    t_bad = float(reason.split(" at t = ")[1].split(";")[0])
    assert res.t[-1] < t_bad <= T_OVERFLOW
    assert f"the output ends at t = {res.t[-1]:.9g}" in reason
    # not absurdly early: within 10 e-foldings (a factor 2e4) of the overflow
    assert res.t[-1] > T_OVERFLOW - 1.0 and np.max(np.abs(res.u)) > 1e300
    _assert_finite(res)
    # the rows are the exact solution (relative error of the flow's round-off)
    np.testing.assert_allclose(res.q[:, 0], np.cosh(W * res.t), rtol=1e-9)
    np.testing.assert_allclose(res.u[1:, 0], W * np.sinh(W * res.t[1:]), rtol=1e-9)
    assert res.metadata["stopped"]["t"] == res.t[-1] and res.metadata["steps"] == res.t.size - 1


def test_a_huge_but_finite_event_run_is_not_stopped():
    """The near miss: up to t = 65 (|u| ≈ 1e283): ok, every row of the grid."""
    res = _quiet_simulate(_unstable(65.0), integrator="event")
    assert res.status.ok and res.t.size == 6501 and "stopped" not in res.metadata
    assert np.max(np.abs(res.u)) > 1e280
    _assert_finite(res)


def test_an_observer_whose_V_overflows_stops_the_event_run_before_that_row():
    sc = _unstable(80.0)
    res = _quiet_simulate(sc, integrator="event", observers=["nojump"])
    assert res.status.state.value == "stopped"
    assert res.status.reason.startswith("non-finite V of observer 'nojump'")
    _assert_finite(res)
    obs = res.slaves["nojump"]
    t = res.t[-1]
    # the observer's exact state: e = cosh(√κ t), v = √κ sinh(√κ t) (no contact ever closes)
    np.testing.assert_allclose(obs.q[-1, 0] - res.q[-1, 0], np.cosh(W * t), rtol=1e-6)
    # one grid step later the closed-form states make V non-finite: the stop is not early
    tn = t + H
    qm, um = np.array([[np.cosh(W * tn)]]), np.array([[W * np.sinh(W * tn)]])
    with np.errstate(all="ignore"):
        assert not np.isfinite(lyapunov(sc.system, 2.0 * qm, 2.0 * um, qm, um)[0])
    assert np.isfinite(lyapunov(sc.system, obs.q[-1:], obs.u[-1:], res.q[-1:], res.u[-1:])[0])


def test_huge_forcing_through_the_api_with_the_event_integrator():
    sc = load_scenario("double_mass", {"system.forcing.constant": "[1e308,1e308]"})
    res = _quiet_simulate(sc, t_end=0.01, observers="scenario", integrator="event")
    assert res.status.state.value == "stopped" and "non-finite" in res.status.reason
    assert "t = 0;" in res.status.reason and res.t.tolist() == [0.0]
    _assert_finite(res)
    # the near miss: 1e150 stays finite over the run: ok, every row
    sc = load_scenario("double_mass", {"system.forcing.constant": "[1e150,1e150]"})
    res = _quiet_simulate(sc, t_end=0.01, observers="scenario", integrator="event")
    assert res.status.ok and res.t.size == 101
    _assert_finite(res)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_huge_forcing_through_the_cli_with_the_event_integrator(tmp_path, capsys, suffix):
    path = tmp_path / f"dm{suffix}"
    code = main(["run", "double_mass", "--set", "system.forcing.constant=[1e308,1e308]",
                 "--integrator", "event", "--observers", "jump,nojump", "--out", str(path)])
    err = capsys.readouterr().err
    assert code == 1
    assert "Traceback" not in err and "Warning" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: non-finite ")
    assert "gap g0" in lines[0] and "at t = 0;" in lines[0]
    df, meta = read_result(path)
    assert meta["status"]["state"] == "stopped" and meta["stopped"]["step"] == 0
    assert len(df) == 1 and np.all(np.isfinite(df.to_numpy(dtype=float)))


# ---------------------------------------------------------------------------------------
# Ctrl-C / SIGTERM during `observer run --integrator event --out`: the finished rows, whole
# ---------------------------------------------------------------------------------------
ROOT = Path(__file__).resolve().parents[3]


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a running process (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _run_command(path, t_end, observers):
    return [sys.executable, "-m", "observer", "run", "double_mass", "--set", f"param.t_end={t_end}",
            "--integrator", "event", "--t-end", t_end, "--h", "1e-3", "--observers", observers,
            "--out", str(path)]


def _cpu_of_a_whole_run(path, observers) -> float:
    """CPU seconds (user + system) of the same command run to t_end = 1 s, to its exit:
    imports, numba's cache (compiled here first, so a fresh clone's cold cache does not eat
    the measured run), the master and the observer over the first second, the file."""
    simulate("double_mass", t_end=0.05, integrator="event")   # fills numba's cache
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(_run_command(path, "1", observers), env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    assert proc.returncode == 0
    return usage.ru_utime + usage.ru_stime


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize("sig, ext, observers, t_end, margin", [
    (signal.SIGINT, "parquet", "none", "200", 1.0),        # in the master's run (far from its end)
    (signal.SIGTERM, "csv", "nojump", "200", 1.0)])        # in the master's run: the observer up to there
def test_a_signal_during_an_event_run_leaves_a_readable_stopped_file(tmp_path, sig, ext, observers,
                                                                     t_end, margin):
    """The signal is sent when the process has used ``margin`` CPU seconds more than the
    same command run to t = 1 s takes to its exit (measured first, on this machine, with
    numba's cache warm): the master's run is then past t = 1 s, whatever the imports and
    the cache cost here, and long before its end at t_end = 200 s (the test asserts that
    the stop lies in between). The output is sampled at h = 1e-3: what follows the signal
    (the observer up to there, the file, reading it back) costs in proportion to the rows,
    ten times fewer than at double_mass's own h = 1e-4."""
    path = tmp_path / f"exact.{ext}"
    cpu = _cpu_of_a_whole_run(tmp_path / f"first_second.{ext}", observers) + margin
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(_run_command(path, t_end, observers),
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while _cpu_seconds(proc.pid) < cpu:       # past t = 1 s of the master's run
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.05)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    name = signal.Signals(sig).name
    assert proc.returncode == 128 + int(sig), err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1 and name in err
    df, meta = read_result(path)                  # verified against its checksums
    assert meta["status"]["state"] == "stopped" and name in meta["status"]["reason"]
    assert meta["stopped"]["signal"] == name and len(df) == meta["stopped"]["step"] + 1
    assert 1.0 < df["t"].iloc[-1] < float(t_end) and np.all(np.isfinite(df.to_numpy(dtype=float)))
    # the rows are those of an uninterrupted run (recomputed over the first second)
    ref = simulate(load_scenario("double_mass", {"param.t_end": t_end}), h=1e-3, t_end=1.0, integrator="event",
                   observers=[] if observers == "none" else observers.split(",")).to_frame()
    assert list(df.columns) == list(ref.columns)
    np.testing.assert_allclose(df.iloc[:len(ref)].to_numpy(dtype=float), ref.to_numpy(dtype=float),
                               rtol=1e-9, atol=1e-12)


def test_a_signal_during_the_event_observers_keeps_the_rows_every_system_reached(monkeypatch):
    """SIGTERM while the first observer runs (sent by the process to itself once that
    observer has passed t = 2, after the whole master): it stops at its next switching, the
    second observer runs up to the same row, the result ends there, equal to a run to there."""
    from observer.event import observers as event_observers

    flow_until = event_observers._ObserverIntegrator._flow_until
    sent = []

    def signalling_flow(self, t, *args):
        out = flow_until(self, t, *args)
        if not sent and out[2] > 2.0:             # out[2]: the time reached
            sent.append(out[2])
            os.kill(os.getpid(), signal.SIGTERM)
        return out

    monkeypatch.setattr(event_observers._ObserverIntegrator, "_flow_until", signalling_flow)
    sc = load_scenario("double_mass", {"param.t_end": 5})
    res = simulate(sc, integrator="event", observers=["jump", "nojump"], on_chunk=lambda chunk: None)
    assert sent and res.status.state.value == "stopped"
    assert res.status.reason.startswith(f"SIGTERM at t = {res.t[-1]:.9g}")
    assert res.metadata["stopped"]["signal"] == "SIGTERM" and res.metadata["master_status"] == "ok"
    assert 2.0 < res.t[-1] < 5.0 and res.t[-1] - sent[0] < 0.5     # the next switching
    _assert_finite(res)
    monkeypatch.setattr(event_observers._ObserverIntegrator, "_flow_until", flow_until)
    ref = simulate(sc, t_end=float(res.t[-1]), integrator="event", observers=["jump", "nojump"])
    assert ref.status.ok and ref.t.size == res.t.size
    np.testing.assert_allclose(res.to_frame().to_numpy(dtype=float), ref.to_frame().to_numpy(dtype=float),
                               rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("what,keys,text", [
    (("state", 0), [], "q0 of the master (inf)"),
    (("state", 3), [], "u1 of the master (inf)"),
    (("state", 5), [], "exogenous state z5 of the master (inf)"),
    (("derivative", 0, 1), [("g", 0), ("l", 1)], "contact force λ1 of the master (inf)"),
    (("derivative", 2, 0), [("g", 0), ("l", 1)], "derivative 2 of the master's gap g0 (inf)"),
    (("bound", 3, 1), [("g", 0), ("l", 1)],
     "bound on derivative 3 of the master's contact force λ1 over the search window (inf)"),
])
def test_a_non_finite_flow_names_its_quantity(what, keys, text):
    """The stop text of a non-finite flow names the quantity (n = 2): z = (q0, q1, u0, u1,
    then the exogenous states), a gap g_j or a contact force λ_j (the functional's kind), its
    derivative or the bound on its third derivative over the search window."""
    from types import SimpleNamespace
    from observer.event.master import _flow_quantity
    from observer.event.roots import NonFiniteFlow
    exc = NonFiniteFlow(1.0, 0.5, np.zeros(6), what, np.inf)
    assert _flow_quantity(SimpleNamespace(n=2), keys, exc) == text
