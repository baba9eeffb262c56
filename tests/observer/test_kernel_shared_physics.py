"""One physics for the engines: the projection onto the closed contacts and the applied
complementarity residual are the compiled kernel's functions, which the numpy reference calls
too (:meth:`observer.stepping.MoreauJean.project`, :func:`observer.loop.newton_residual`).
Where a second shape remains (the event engine's projection in continuous time, dense numpy),
it is checked against the kernel's on every built-in scenario:

* the position jump ``q⁺ = q⁻ − N⁻¹W_I L_I⁻¹ g_I⁻`` of :func:`observer.kernel.project_closed`
  equals the event engine's (:mod:`observer.event.observers`) to 1e-13 relative to the scale of
  q and of the jump, in the metrics K, M and I, on every single contact and on the first three
  together, and closes the gaps (|g_I(q⁺)| ≤ 1e-12 · scale);
* :func:`observer.kernel.applied_residual` equals the residual's definition evaluated in numpy
  (``max|min(P, b + W_Aᵀδu)| / max(‖b‖_∞, ‖W_Aᵀδu‖_∞)``) to 1e-12 relative.
"""

from __future__ import annotations

import numpy as np
import pytest

import observer
from observer import kernel, primitives
from observer.scenarios import SCENARIOS


def closed_sets(m: int) -> list[np.ndarray]:
    return [np.array([j]) for j in range(m)] + ([np.arange(min(m, 3))] if m > 1 else [])


def metrics(system) -> dict:
    out = {"M": system.M, "I": np.eye(system.n)}
    if np.all(np.linalg.eigvalsh(system.K) > 0):
        out["K"] = system.K
    return out


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_kernel_projection_is_the_event_engines(name):
    from observer.event.observers import _ObserverIntegrator

    sc = observer.load_scenario(name)
    sys_ = sc.system
    W = np.asarray(sys_.W, dtype=float)
    Wp, Wi, Wv = kernel.csc_arrays(W)
    rng = np.random.default_rng(21)
    t = 0.37
    nu = np.ascontiguousarray(np.asarray(sys_.nu(t), dtype=float)[None])
    for label, N in metrics(sys_).items():
        NinvW = np.linalg.solve(N, W)
        L = W.T @ NinvW
        stacks = (np.ascontiguousarray(NinvW.T)[None], np.ascontiguousarray(0.5 * (L + L.T))[None])
        integ = _ObserverIntegrator(sys_, sc.law, N, None)
        integ.sigma = np.zeros((1, sys_.m))
        for act in closed_sets(sys_.m):
            q = rng.normal(size=sys_.n) * max(1.0, float(np.abs(sc.q0).max()))
            status, qk, sig = kernel.project_closed(q, 0, act.astype(np.int64), Wp, Wi, Wv, nu, *stacks, 0)
            assert status == kernel.OK
            qe = integ.project(t, q, frozenset(act.tolist()), 0)
            scale = max(float(np.abs(q).max()), float(np.abs(qe - q).max()))
            assert np.abs(qk - qe).max() <= 1e-13 * scale, (label, act)
            assert np.abs(W[:, act].T @ qk + nu[0, act]).max() <= 1e-12 * scale
            assert np.abs(sig - integ.sigma[0, act]).max() <= 1e-12 * max(1.0, float(np.abs(sig).max()))
            integ.sigma[:] = 0.0


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_applied_residual_is_its_definition(name):
    sc = observer.load_scenario(name)
    st = observer.MoreauJean(sc.system, sc.law, sc.h, 10 * sc.h, sc.theta)
    W = st.S.W
    Wp, Wi, Wv = st.csc
    rng = np.random.default_rng(7)
    for act in closed_sets(sc.system.m):
        a = act.size
        for _ in range(5):
            P = np.abs(rng.normal(size=a)) * (rng.random(a) < 0.7)
            b = rng.normal(size=a)
            du = st.S.AinvW[:, act] @ P
            d = W[:, act].T @ du
            want = np.abs(np.minimum(P, b + d)).max() / max(np.abs(b).max(), np.abs(d).max(), 1e-300)
            got = kernel.applied_residual(Wp, Wi, Wv, act.astype(np.int64), a, du, b, P)
            assert got == pytest.approx(want, rel=1e-12, abs=1e-15)


def test_the_numpy_engine_projects_with_the_kernel(monkeypatch):
    """The python engine's position jumps go through :func:`observer.primitives.project_closed`
    (a failing stand-in stops the run), in the K metric and in a design's own metric."""
    calls = []
    real = primitives.project_closed

    def spy(*args):
        calls.append(args[-1])
        return real(*args)

    monkeypatch.setattr(primitives, "project_closed", spy)
    sc = observer.load_scenario("double_mass", {"simulation.t_end": 0.5})
    py = observer.simulate(sc, observers=("jump",), master_projection=True, engine="python")
    co = observer.simulate(sc, observers=("jump",), master_projection=True, engine="compiled")
    assert calls and py.active.any()
    np.testing.assert_allclose(py.q, co.q, rtol=0, atol=1e-13 * np.abs(co.q).max())
