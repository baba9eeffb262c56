"""Unit tests of the θ-scheme's building blocks (:mod:`observer.stepping`) and of the error
Lyapunov function and observer configuration (:mod:`observer.observers`).

Every expected value is computed here from the system matrices (or written down by hand),
never taken from the code under test:

* ``Â = M + hθC + h²θ²K`` and the free-velocity update
  ``Â u_free = (M − h(1−θ)C − h²θ(1−θ)K) u − hK q + h f̄`` (the θ-scheme, module docstring);
* the banded build of a chain system agrees with the dense build to round-off;
* ``bandwidth`` and ``to_band`` on matrices whose bands are known;
* the grid's step count and the θ-averaged forcing ``f̄_k = (1−θ)f(t_k) + θf(t_{k+1})``;
* the step's LCP ``0 ≤ γ_{k+1} − τ ⊥ P ≥ 0`` solved here by enumerating active sets;
* the fall-back path: its warning text and counters;
* V = ½vᵀMv + ½eᵀKe and its per-step parts (discrete eq. (17)) on hand-made data.

Round-off tolerances are relative to the size of the numbers compared (a few hundred ulps
for the small, well-conditioned systems used here).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from lcp_enum import lcp_enum as _lcp_enum
from observer.contact.lcp import LCPSolution
from observer.errors import ContactSolverError, InputError
from observer.impact import ImpactLaw
from observer.model import Harmonic, LinearSystem
from observer.observers import ObserverConfig, check_observer_name, lyapunov, lyapunov_decrements
from observer.stepping import (BANDED_MIN_N, Grid, MoreauJean, SchemeMatrices, bandwidth,
                               check_step_parameters, grid_steps, to_band)

RTOL = 1e-12


# ---------------------------------------------------------------------------------------
# helpers: small systems and an enumerating LCP solver
# ---------------------------------------------------------------------------------------
def two_dof(K=None, check=True, C=None) -> LinearSystem:
    """2 DOF, 2 coupled contacts, harmonic forcing and a moving gap offset."""
    M = np.array([[2.0, 0.3], [0.3, 1.0]])
    C = np.array([[0.3, -0.1], [-0.1, 0.2]]) if C is None else C
    K = np.array([[5.0, -2.0], [-2.0, 3.0]]) if K is None else K
    W = np.array([[1.0, 0.5], [0.0, 1.0]])
    forcing = Harmonic.build("system.forcing", 2, constant=[1.0, -2.0],
                             terms=[{"amplitude": [0.5, 0.25], "omega": 2.0, "phase": [0.1, 0.0]}])
    gap = Harmonic.build("system.gap", 2, constant=[0.1, 0.2],
                         terms=[{"amplitude": [0.05, 0.0], "omega": 3.0}], kind="sin")
    return LinearSystem(M, C, K, W, forcing, gap, check=check)


def one_dof(K=4.0, nu=0.0) -> LinearSystem:
    """A unit-ish mass on a spring above the ground, gravity-like constant force."""
    return LinearSystem(np.array([[2.0]]), np.array([[0.0]]), np.array([[K]]), np.array([[1.0]]),
                        Harmonic.build("system.forcing", 1, constant=-9.81),
                        Harmonic.build("system.gap", 1, constant=nu, kind="sin"))


def chain(n: int, m: int = 3) -> LinearSystem:
    """n masses in a line, neighbour and ground springs and dampers (tridiagonal, SPD)."""
    mass = 1.0 + 0.1 * np.arange(n)
    K = np.diag(np.full(n, 3.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1)
    C = 0.01 * np.diag(mass) + 0.002 * K
    W = np.zeros((n, m))
    for j in range(m):
        W[(j * n) // m, j] = 1.0
        W[(j * n) // m + 1, j] = -0.5
    forcing = Harmonic.build("system.forcing", n, constant=np.linspace(-1.0, 1.0, n),
                             terms=[{"amplitude": 0.3, "omega": 1.5}])
    gap = Harmonic.build("system.gap", m, constant=0.05)
    return LinearSystem(np.diag(mass), C, K, W, forcing, gap)


def lcp_enum(G: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The shared brute-force oracle (:mod:`lcp_enum`) with a 1e-12 round-off allowance."""
    return _lcp_enum(G, b, rtol=1e-12)


class EnumSolver:
    """A contact solver built on :func:`lcp_enum` (exact, independent of observer.contact)."""

    name = "enum"

    def __init__(self, residual: float = 0.0, iterations: int = 1, method: str = "enum"):
        self.residual, self.iterations, self.method = residual, iterations, method
        self.calls = 0

    def solve(self, G, b):
        self.calls += 1
        return LCPSolution(lcp_enum(G, b), self.residual, self.iterations, self.method)


class RaisingSolver:
    name = "raising"

    def solve(self, G, b):
        raise ArithmeticError("deliberate failure")


def a_hat(s: LinearSystem, h: float, th: float) -> np.ndarray:
    return s.M + h * th * s.C + h * h * th * th * s.K


def free_velocity(s: LinearSystem, h: float, th: float, q, u, fbar) -> np.ndarray:
    """u_free from the θ-scheme's momentum balance without impulse (solved here)."""
    Ru = s.M - h * (1 - th) * s.C - h * h * th * (1 - th) * s.K
    return np.linalg.solve(a_hat(s, h, th), Ru @ u - h * s.K @ q + h * fbar)


def close(a, b, rtol=RTOL) -> None:
    a, b = np.asarray(a, float), np.asarray(b, float)
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * max(np.abs(b).max(initial=0.0), 1e-300))


# ---------------------------------------------------------------------------------------
# bandwidth and band storage
# ---------------------------------------------------------------------------------------
def test_bandwidth_of_known_matrices():
    n = 6
    assert bandwidth(np.eye(n)) == 0
    assert bandwidth(np.zeros((n, n))) == 0
    tri = np.eye(n) + np.diag(np.ones(n - 1), 1)
    assert bandwidth(tri) == 1
    lower = np.eye(n)
    lower[5, 2] = -1.0                         # below the diagonal only: |i − j| counts
    assert bandwidth(lower) == 3
    upper = np.zeros((n, n))
    upper[0, 4] = 1e-300                       # any nonzero entry counts, however small
    assert bandwidth(upper) == 4
    assert bandwidth(tri, lower, np.eye(n)) == 3     # the union of the patterns
    assert bandwidth(np.eye(n), upper) == 4
    assert isinstance(bandwidth(tri), int)


def test_to_band_lower_storage():
    A = np.array([[4.0, 1.0, 7.0, 0.0],
                  [1.0, 5.0, 2.0, 8.0],
                  [7.0, 2.0, 6.0, 3.0],
                  [0.0, 8.0, 3.0, 9.0]])
    expected = np.array([[4.0, 5.0, 6.0, 9.0],
                         [1.0, 2.0, 3.0, 0.0],
                         [7.0, 8.0, 0.0, 0.0]])
    assert np.array_equal(to_band(A, 2), expected)
    assert np.array_equal(to_band(A, 1), expected[:2])
    assert np.array_equal(to_band(A, 0), expected[:1])
    # the layout is ab[d, j] = A[j + d, j]: the lower triangle, also of a non-symmetric A
    B = np.arange(1.0, 10.0).reshape(3, 3)
    assert np.array_equal(to_band(B, 2), np.array([[1.0, 5.0, 9.0], [4.0, 8.0, 0.0], [7.0, 0.0, 0.0]]))


# ---------------------------------------------------------------------------------------
# scheme matrices: dense build
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("theta", [0.5, 0.75, 1.0])
def test_dense_scheme_matrices_from_the_system(theta):
    s, h = two_dof(), 0.05
    S = SchemeMatrices.build(s, h, theta)
    A = a_hat(s, h, theta)
    Ainv = np.linalg.inv(A)
    assert S.h == h and S.theta == theta and S.band is None
    close(S.Bf, h * Ainv)
    close(S.Bq, -h * Ainv @ s.K)
    close(S.Bu, np.eye(2) - Ainv @ (h * s.C + h * h * theta * s.K))
    close(S.AinvW, Ainv @ s.W)
    close(S.Ghat, s.W.T @ Ainv @ s.W)
    close(S.G0, s.W.T @ np.linalg.solve(s.M, s.W))
    close(S.KinvW, np.linalg.solve(s.K, s.W))
    close(S.L, s.W.T @ np.linalg.solve(s.K, s.W))
    assert np.array_equal(S.W, s.W) and np.array_equal(S.WT, s.W.T)
    for G in (S.Ghat, S.G0, S.L):              # symmetrised exactly
        assert np.array_equal(G, G.T)
    # the free velocity of the scheme solves the momentum balance
    q, u, fbar = np.array([0.3, -0.2]), np.array([1.0, 2.0]), np.array([0.5, -1.5])
    close(S.Bu @ u + S.Bq @ q + S.Bf @ fbar, free_velocity(s, h, theta, q, u, fbar))


def test_dense_scheme_with_singular_stiffness_has_no_projection_matrices():
    s = two_dof(K=np.array([[1.0, -1.0], [-1.0, 1.0]]))       # PSD, singular
    S = SchemeMatrices.build(s, 0.01, 0.5)
    assert S.KinvW is None and S.L is None
    close(S.Bq, -0.01 * np.linalg.solve(a_hat(s, 0.01, 0.5), s.K))


def test_dense_scheme_with_non_symmetric_damping_uses_lu():
    C = np.array([[0.3, 0.4], [-0.2, 0.2]])                   # allowed with check=False only
    s = two_dof(C=C, check=False)
    h, th = 0.05, 0.75
    S = SchemeMatrices.build(s, h, th)
    Ainv = np.linalg.inv(a_hat(s, h, th))
    close(S.Bf, h * Ainv)
    close(S.AinvW, Ainv @ s.W)


# ---------------------------------------------------------------------------------------
# scheme matrices: banded build and the structure choice
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("theta", [0.5, 1.0])
def test_banded_build_agrees_with_dense(theta):
    s, h = chain(80), 0.01
    D = SchemeMatrices.build(s, h, theta, "dense")
    B = SchemeMatrices.build(s, h, theta, "banded")
    assert B.Bu is None and B.Bq is None and B.Bf is None
    assert B.band is not None and B.band.bw == 1
    assert B.h == h and B.theta == theta
    for name in ("AinvW", "Ghat", "G0", "KinvW", "L"):
        close(getattr(B, name), getattr(D, name), 1e-11)
        assert getattr(B, name).shape == getattr(D, name).shape
    assert np.array_equal(B.W, s.W) and np.array_equal(B.WT, s.W.T)
    # the banded factors and right-hand sides, checked against the formulas
    Ru = s.M - h * (1 - theta) * s.C - h * h * theta * (1 - theta) * s.K
    close(B.band.Ru, to_band(Ru, 1))
    close(B.band.Rq, to_band(-h * s.K, 1))
    close(B.band.Ru_s.toarray(), Ru)
    close(B.band.Rq_s.toarray(), -h * s.K)
    Lc = np.diag(B.band.Achol[0]) + np.diag(B.band.Achol[1, :-1], -1)
    close(Lc @ Lc.T, a_hat(s, h, theta))
    rng = np.random.default_rng(0)
    q, u, fbar = rng.standard_normal((3, s.n))
    ref = free_velocity(s, h, theta, q, u, fbar)
    close(B.band.free_velocity(h, q, u, fbar), ref, 1e-11)
    close(D.Bu @ u + D.Bq @ q + D.Bf @ fbar, ref, 1e-11)


def test_banded_build_of_diagonal_system_uses_bandwidth_one():
    n, h = 70, 0.02
    s = LinearSystem(np.eye(n), np.zeros((n, n)), 2.0 * np.eye(n), np.eye(n)[:, :2],
                     Harmonic.build("system.forcing", n), Harmonic.build("system.gap", 2, kind="sin"))
    B = SchemeMatrices.build(s, h, 0.5, "banded")
    assert B.band.bw == 1
    close(B.Ghat, np.eye(2) / (1.0 + h * h * 0.25 * 2.0))
    close(B.L, 0.5 * np.eye(2))


@pytest.mark.parametrize("kind", ["zero", "free chain", "cond 1e13"])
def test_banded_build_with_singular_stiffness(kind):
    """K = 0 (banded Cholesky fails), the free chain's Laplacian (K·1 = 0), or K ≻ 0 with
    cond(K) = 1e13 (Cholesky succeeds, but K is not definite to the toolkit's 1e-12):
    no K⁻¹W, no L, as in the dense build."""
    n = 64
    base = chain(n)
    if kind == "zero":
        K = np.zeros((n, n))
    elif kind == "cond 1e13":
        K = np.diag(np.r_[1e-13, np.ones(n - 1)])
    else:
        K = 2.0 * np.eye(n) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1)
        K[0, 0] = K[-1, -1] = 1.0
    s = LinearSystem(base.M, base.C, K, base.W, base.forcing, base.gap)
    B = SchemeMatrices.build(s, 0.01, 0.5, "banded")
    D = SchemeMatrices.build(s, 0.01, 0.5, "dense")
    assert B.KinvW is None and B.L is None and D.KinvW is None
    close(B.Ghat, D.Ghat, 1e-11)


@pytest.mark.parametrize("wide", ["M", "C", "K"])
def test_banded_bandwidth_covers_every_matrix(wide):
    """One of M, C, K has bandwidth 2 (the others 1): the banded build uses the widest band
    (agrees with the dense build) and the structure choice sees it too."""
    n = 64
    base = chain(n)
    mats = dict(M=base.M.copy(), C=base.C.copy(), K=base.K.copy())
    A = mats[wide]
    A[np.arange(n - 2), np.arange(2, n)] = A[np.arange(2, n), np.arange(n - 2)] = 1e-3
    s = LinearSystem(mats["M"], mats["C"], mats["K"], base.W, base.forcing, base.gap)
    B = SchemeMatrices.build(s, 0.05, 0.5, "banded")
    D = SchemeMatrices.build(s, 0.05, 0.5, "dense")
    assert B.band.bw == 2
    for name in ("AinvW", "Ghat", "G0"):
        close(getattr(B, name), getattr(D, name), 1e-11)
    # bandwidth 9 > n/8 in this matrix alone: dense
    A2 = mats[wide].copy()
    A2[0, 9] = A2[9, 0] = 1e-3
    mats[wide] = A2
    s9 = LinearSystem(mats["M"], mats["C"], mats["K"], base.W, base.forcing, base.gap)
    assert SchemeMatrices.choose_structure(s9) == "dense"


def test_choose_structure():
    n = BANDED_MIN_N
    assert SchemeMatrices.choose_structure(chain(n)) == "banded"
    assert SchemeMatrices.choose_structure(chain(n - 1)) == "dense"
    assert SchemeMatrices.build(chain(n), 0.01, 0.5, "auto").band is not None
    assert SchemeMatrices.build(chain(n - 1), 0.01, 0.5, "auto").band is None
    assert SchemeMatrices.build(chain(n), 0.01, 0.5).band is None        # default: dense
    base = chain(n)

    def with_(name, value, check=False):
        mats = dict(M=base.M, C=base.C, K=base.K)
        mats[name] = value
        return LinearSystem(mats["M"], mats["C"], mats["K"], base.W, base.forcing, base.gap, check=check)

    # bandwidth n/8 = 8 is still banded, 9 is not
    for bw, kind in ((n // 8, "banded"), (n // 8 + 1, "dense")):
        K = base.K.copy()
        K[0, bw] = K[bw, 0] = -1e-3
        assert SchemeMatrices.choose_structure(with_("K", K, check=True)) == kind
    # any non-symmetric matrix keeps the dense (LU) build
    for name in ("M", "C", "K"):
        A = getattr(base, name).copy()
        A[1, 0] += 1e-3
        assert SchemeMatrices.choose_structure(with_(name, A)) == "dense", name


# ---------------------------------------------------------------------------------------
# the grid
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("t_end,h,t0,steps", [(1.0, 0.1, 0.0, 10), (1.05, 0.1, 0.0, 10),
                                              (0.3, 0.1, 0.0, 3), (2.0, 0.25, 1.0, 4),
                                              (1.0 + 1e-8, 0.1, 0.0, 10), (1.0 - 1e-8, 0.1, 0.0, 9),
                                              (0.1, 0.1, 0.0, 1), (0.19, 0.1, 0.0, 1)])
def test_grid_step_count(t_end, h, t0, steps):
    """The grid ends at the last t_k ≤ t_end (t_end = N·h in floating point counts N): it never
    steps past t_end."""
    g = Grid.build(two_dof(), h, t_end, 0.5, t0)
    assert g.steps == steps and g.t.shape == (steps + 1,)
    close(g.t, t0 + h * np.arange(steps + 1))
    assert g.t[0] == t0
    assert t0 + steps * h <= t_end * (1 + 1e-12) and t0 + (steps + 1) * h > t_end


@pytest.mark.parametrize("t_end", [0.05, 0.0999])
def test_a_horizon_shorter_than_one_step_is_refused(t_end):
    with pytest.raises(InputError) as ei:
        Grid.build(two_dof(), 0.1, t_end, 0.5)
    assert ei.value.field == "simulation.t_end"


def test_grid_steps_default_start_time_is_zero():
    assert grid_steps(0.1, 1.0) == 10 and grid_steps(0.1, 1.0, 0.5) == 5


def test_grid_window_is_a_bitwise_slice_of_the_grid():
    s, h, th = two_dof(), 0.1, 0.75
    g = Grid.build(s, h, 1.5, th, 0.5)
    w = Grid.window(s, h, th, 0.5, 3, 6)
    assert g.k0 == 0 and w.k0 == 3 and w.steps == 3
    assert np.array_equal(w.t, g.t[3:7])
    assert np.array_equal(w.fbar, g.fbar[3:6])
    assert np.array_equal(w.nu, g.nu[3:7]) and np.array_equal(w.nu_dot, g.nu_dot[3:7])


def test_stepper_keeps_its_law_and_step_count_with_a_start_time():
    law = ImpactLaw.build("newton", 0.5, 2)
    st = MoreauJean(two_dof(), law, 0.1, 1.0, t0=0.5)
    assert st.law is law and st.steps == 5 and st.t0 == 0.5
    assert st.grid.steps == 5 and st.grid.t[0] == 0.5


def test_fallback_before_any_step_reports_step_zero():
    st = stepper(system=one_dof(), e=(0.5,), h=0.1)
    st.solver = EnumSolver(residual=1.0, method="fake")
    st._fallback = EnumSolver()
    with pytest.warns(RuntimeWarning, match=r"^fake residual 1 at step 0 \(t = 0\);"):
        st.impulse(3, np.array([-2.0]), np.array([-2.1]), np.array([0]))


@pytest.mark.parametrize("t_end,t0", [(0.0, 0.0), (1.0, 1.0), (0.5, 1.0)])
def test_grid_needs_one_step(t_end, t0):
    with pytest.raises(InputError, match="must exceed t0") as info:
        Grid.build(two_dof(), 0.1, t_end, 0.5, t0)
    assert info.value.field == "simulation.t_end"


@pytest.mark.parametrize("theta", [0.5, 0.8, 1.0])
def test_grid_theta_averaged_forcing_and_gap_signals(theta):
    s, h = two_dof(), 0.1
    g = Grid.build(s, h, 1.0, theta)
    t = h * np.arange(11)
    f = np.stack([[1.0 + 0.5 * np.cos(2.0 * tk + 0.1), -2.0 + 0.25 * np.cos(2.0 * tk)] for tk in t])
    assert g.fbar.shape == (10, 2)
    close(g.fbar, (1 - theta) * f[:-1] + theta * f[1:])
    nu = np.stack([[0.1 + 0.05 * np.sin(3.0 * tk), 0.2] for tk in t])
    nud = np.stack([[0.15 * np.cos(3.0 * tk), 0.0] for tk in t])
    close(g.nu, nu)
    close(g.nu_dot, nud)


def test_step_parameters_are_validated():
    assert check_step_parameters(1e-3, 0.5) == (1e-3, 0.5)
    assert check_step_parameters(np.float32(0.5), 1) == (0.5, 1.0)
    with pytest.raises(InputError, match="the string '0.01'") as info:   # a number, not text (issue 20)
        check_step_parameters("0.01", 1)
    assert info.value.field == "simulation.h"
    assert isinstance(check_step_parameters(1, 1)[1], float)
    for h in (0.0, -1e-3):
        with pytest.raises(InputError) as info:
            check_step_parameters(h, 0.5)
        assert info.value.field == "simulation.h"
    for th in (0.49, 1.01):
        with pytest.raises(InputError) as info:
            check_step_parameters(0.01, th)
        assert info.value.field == "simulation.theta"
    with pytest.raises(InputError) as info:
        MoreauJean(two_dof(), ImpactLaw.build("newton", 0.5, 2), 0.1, "later")
    assert info.value.field == "simulation.t_end"


# ---------------------------------------------------------------------------------------
# the step
# ---------------------------------------------------------------------------------------
def stepper(law="newton", e=(0.3, 0.8), theta=0.5, h=0.05, system=None, **kw) -> MoreauJean:
    s = two_dof() if system is None else system
    st = MoreauJean(s, ImpactLaw.build(law, list(e)[:s.m], s.m), h, 1.0, theta, **kw)
    st.solver = EnumSolver()
    return st


def test_stepper_exposes_h_theta_and_its_grid():
    st = stepper(theta=0.75, h=0.05)
    assert st.h == 0.05 and st.theta == 0.75
    assert st.grid.steps == 20
    assert st.stats.contact_solves == 0 and st.stats.fallbacks == 0


def test_predicted_active_set_rule():
    """Closed iff g_k + (h/2)γ_k ≤ 0, with g = Wᵀq + ν(t_k), γ = Wᵀu + ν̇(t_k)."""
    st = stepper(h=0.1)
    s = st.system
    k = 3
    t = st.grid.t[k]
    nu, nud = s.nu(t), s.nu_dot(t)
    u = np.array([-1.0, 0.5])
    gamma = u @ s.W + nud
    # q such that g_pred = (−1e-3, +1e-3) exactly enough to be classified
    target = np.array([-1e-3, 1e-3]) - nu - 0.05 * gamma
    q = np.linalg.solve(s.W.T, target)
    assert st.predicted_active(k, q, u).tolist() == [True, False]
    target = np.array([1e-3, -1e-3]) - nu - 0.05 * gamma
    assert st.predicted_active(k, np.linalg.solve(s.W.T, target), u).tolist() == [False, True]
    # the boundary g_pred = 0 counts as closed (1 DOF, exact arithmetic)
    one = stepper(system=one_dof(nu=0.25), h=0.5)
    assert one.predicted_active(0, np.array([-0.5]), np.array([1.0])).tolist() == [True]
    assert one.predicted_active(0, np.array([-0.5]), np.array([1.0 + 1e-12])).tolist() == [False]


def step_data(st: MoreauJean, k: int, q, u, A):
    """u_free, Ĝ_A, γ_k and γ_free of step k on A, computed here from the system."""
    s, h, th = st.system, st.h, st.theta
    fbar = (1 - th) * s.f(st.grid.t[k]) + th * s.f(st.grid.t[k + 1])
    uf = free_velocity(s, h, th, q, u, fbar)
    W = s.W[:, A]
    G = W.T @ np.linalg.solve(a_hat(s, h, th), W)
    return uf, G, u @ W + s.nu_dot(st.grid.t[k])[A], uf @ W + s.nu_dot(st.grid.t[k + 1])[A]


def test_newton_impulse_includes_the_gap_velocity():
    """Newton: P = LCP(Ĝ, γ_free + e∘γ_k), with ν̇ in both contact velocities."""
    st = stepper(law="newton", e=(0.3, 0.8))
    q, u, k = np.array([0.01, 0.02]), np.array([-1.0, 0.4]), 2
    for A in (np.array([0, 1]), np.array([1]), np.array([0])):
        uf, G, gk, gf = step_data(st, k, q, u, A)
        P, lc, le = st.impulse(k, u, st.free_velocity(k, q, u), A)
        close(P, lcp_enum(G, gf + np.array([0.3, 0.8])[A] * gk))
        assert lc.size == 0 and le.size == 0
    close(st.free_velocity(k, q, u), uf)


def test_poisson_impulse_one_contact_is_newtons():
    st = stepper(law="poisson", e=(0.3, 0.8))
    newton = stepper(law="newton", e=(0.3, 0.8))
    q = np.array([0.01, 0.02])
    for u in (np.array([-1.0, 0.4]), np.array([1.0, 0.4]), np.array([-0.2, 0.0])):
        uf, G, gk, gf = step_data(st, 1, q, u, np.array([0]))
        P, lc, le = st.impulse(1, u, st.free_velocity(1, q, u), np.array([0]))
        close(P, [max(0.0, -(gf[0] + 0.3 * gk[0]) / G[0, 0])])
        close(P, newton.impulse(1, u, newton.free_velocity(1, q, u), np.array([0]))[0])
        close(lc, P / 1.3)
        close(le, 0.3 * P / 1.3)


def test_poisson_impulse_two_contacts_is_glockers_law_on_the_step_velocity():
    st = stepper(law="poisson", e=(0.3, 0.8))
    q, u = np.array([0.01, 0.02]), np.array([-1.0, -0.2])
    A = np.array([0, 1])
    uf, G, gk, gf = step_data(st, 0, q, u, A)
    eps = np.array([0.3, 0.8])
    gt = (gf + eps * gk) / (1 + eps)
    lc = lcp_enum(G, gt)
    mu = lcp_enum(G, gt + G @ lc + G @ (eps * lc))
    P, lam_c, lam_e = st.impulse(0, u, st.free_velocity(0, q, u), A)
    close(lam_c, lc)
    close(lam_e, eps * lc + mu)
    close(P, (1 + eps) * lc + mu)
    assert np.any(lc > 0)


@pytest.mark.parametrize("law", ["newton", "poisson"])
@pytest.mark.parametrize("theta", [0.5, 1.0])
def test_step_solves_the_scheme_and_its_lcp(law, theta):
    """q_{k+1}, u_{k+1}, P from one step equal the θ-scheme with the impulse solved here."""
    st = stepper(law=law, theta=theta, h=0.05)
    s, h = st.system, 0.05
    q, u = np.array([0.02, -0.01]), np.array([-1.5, -0.7])
    k = 4
    A = np.array([0, 1])
    e = np.array([0.3, 0.8])
    uf, G, gk, gf = step_data(st, k, q, u, A)
    if law == "newton":
        P = lcp_enum(G, gf + e * gk)
    else:
        gt = (gf + e * gk) / (1 + e)
        lc = lcp_enum(G, gt)
        P = (1 + e) * lc + lcp_enum(G, gt + G @ lc + G @ (e * lc))
    u1 = uf + np.linalg.solve(a_hat(s, h, theta), s.W @ P)
    q1 = q + h * ((1 - theta) * u + theta * u1)
    q1s, u1s, Ps, sig = st.step(k, q, u, A)
    assert sig is None
    close(Ps, P)
    close(u1s, u1)
    close(q1s, q1)
    assert np.all(P > 0)                        # both contacts are pushed
    if law == "newton":                         # complementarity from the returned state
        g1 = u1s @ s.W + s.nu_dot(st.grid.t[k + 1])
        assert np.all(g1 + e * gk >= -1e-12)
        assert np.all(np.abs((g1 + e * gk) * Ps) <= 1e-12 * np.abs(Ps).max())


def test_step_without_contact_is_the_free_motion_and_projection_on_a_subset():
    st = stepper(h=0.05, theta=0.5)
    s, h = st.system, 0.05
    q, u = np.array([0.02, -0.01]), np.array([0.3, -0.7])
    fbar = 0.5 * (s.f(st.grid.t[0]) + s.f(st.grid.t[1]))
    uf = free_velocity(s, h, 0.5, q, u, fbar)
    q1, u1, P, sig = st.step(0, q, u, np.zeros(0, dtype=int))
    close(u1, uf)
    close(q1, q + 0.5 * h * (u + uf))
    assert P.shape == (0,) and sig is None
    assert st.stats.contact_solves == 0
    q1p, u1p, _, sig = st.step(0, q, u, np.zeros(0, dtype=int), project=True)
    assert np.array_equal(q1p, q1) and sig.shape == (0,)
    # with one active contact and the projection: the gap (with a moving ν) is closed at t_k+1
    k = 2
    q1, u1, P, _ = st.step(k, q, np.array([-2.0, 0.0]), np.array([0]))
    q1p, u1p, Pp, sig = st.step(k, q, np.array([-2.0, 0.0]), np.array([0]), project=True)
    assert np.array_equal(u1p, u1) and np.array_equal(Pp, P)
    g = q1p @ s.W[:, 0] + s.nu(st.grid.t[k + 1])[0]
    assert abs(g) <= 1e-15 and sig.shape == (1,)
    close(q1p, q1 + np.linalg.solve(s.K, s.W[:, 0]) * sig[0])


@pytest.mark.parametrize("law", ["newton", "poisson"])
@pytest.mark.parametrize("theta", [0.5, 1.0])
def test_banded_step_agrees_with_dense_step(law, theta):
    """The same steps of an 80-DOF chain with the banded and the dense build (with contacts,
    projection and the free motion) agree to round-off."""
    s = chain(80)
    law_ = ImpactLaw.build(law, 0.5, s.m)
    dense = MoreauJean(s, law_, 0.01, 1.0, theta, structure="dense")
    band = MoreauJean(s, law_, 0.01, 1.0, theta, structure="banded")
    assert band.S.band is not None and dense.S.band is None
    rng = np.random.default_rng(1)
    q, u = 0.01 * rng.standard_normal(s.n), rng.standard_normal(s.n) - 3.0 * s.W.sum(axis=1)
    for k, A, proj in ((3, np.array([0, 2]), False), (4, np.array([1]), True), (5, np.zeros(0, dtype=int), False)):
        out_d = dense.step(k, q, u, A, project=proj)
        out_b = band.step(k, q, u, A, project=proj)
        for a, b in zip(out_b, out_d):
            if b is None:
                assert a is None
            else:
                close(a, b, 1e-11)
        ref = free_velocity(s, 0.01, theta, q, u, dense.grid.fbar[k])
        if A.size == 0:
            close(out_b[1], ref, 1e-11)
        else:
            assert np.any(out_b[2] > 0)


def test_projection_one_and_several_contacts():
    """Σ = −L⁻¹g, q⁺ = q + K⁻¹WΣ, with L = WᵀK⁻¹W built here; one contact: Σ = −g/L."""
    st = stepper()
    s = st.system
    q = np.array([0.3, -0.4])
    k = 5
    nu = s.nu(st.grid.t[k])
    Kinv = np.linalg.inv(s.K)
    for A in (np.array([0]), np.array([1]), np.array([0, 1])):
        W = s.W[:, A]
        g = q @ W + nu[A]
        L = W.T @ Kinv @ W
        sigma = -np.linalg.solve(L, g)
        qp, sig = st.project(k, q, A)
        close(sig, sigma)
        close(qp, q + Kinv @ W @ sigma)
        assert np.max(np.abs(qp @ W + nu[A])) <= 1e-15
    qp, sig = st.project(k, q, np.zeros(0, dtype=int))
    assert qp is q and sig.shape == (0,)


def test_projection_needs_definite_stiffness():
    s = two_dof(K=np.array([[1.0, -1.0], [-1.0, 1.0]]))
    st = stepper(system=s)
    with pytest.raises(InputError, match=r"for the position projection \(position jumps\) \(smallest") as info:
        st.project(0, np.zeros(2), np.array([0]))
    assert info.value.field == "system.K"


def test_active_slices_cache_is_bounded():
    st = stepper()
    st.MAX_CACHED_SETS = 2
    W0, AinvW0, Ghat0, G00, KinvW0, L0, e0 = st._active_slices(np.array([0]))
    assert np.array_equal(W0, st.system.W[:, [0]]) and e0.tolist() == [0.3]
    close(Ghat0, st.S.Ghat[:1, :1])
    close(L0, st.S.L[:1, :1])
    st._active_slices(np.array([1]))
    assert len(st._slices) == 2
    st._active_slices(np.array([0, 1]))
    assert len(st._slices) == 1                # cleared when full, then the new set kept
    assert st._active_slices(np.array([0, 1])) is st._active_slices(np.array([0, 1]))


# ---------------------------------------------------------------------------------------
# contact solves: residual check, fall-back, counters
# ---------------------------------------------------------------------------------------
def one_contact_step(st: MoreauJean, k: int = 3):
    """A step of the 1-DOF system that hits the ground (returns P)."""
    return st.step(k, np.array([0.0]), np.array([-2.0]), np.array([0]))[2]


def test_good_solutions_are_counted_and_the_worst_residual_kept():
    st = stepper(system=one_dof(), e=(0.5,))
    for r, it in ((1e-12, 3), (1e-10, 4), (1e-11, 5), (1e-9, 6)):     # 1e-9 == tolerance: accepted
        st.solver = EnumSolver(residual=r, iterations=it)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            one_contact_step(st)
    assert st.stats.contact_solves == 4 and st.stats.iterations == 18
    assert st.stats.fallbacks == 0 and st.stats.max_residual == 1e-9


def test_one_contact_impulse_analytic():
    """1 DOF, θ = ½: P = max(0, −(γ_free − τ)/Ĝ) with Ĝ = 1/(M + h²K/4)."""
    h, e = 0.05, 0.5
    st = stepper(system=one_dof(K=4.0), e=(e,), h=h)
    Ahat = 2.0 + h * h * 0.25 * 4.0
    uf = ((2.0 - h * h * 0.25 * 4.0) * -2.0 + h * -9.81) / Ahat
    P = one_contact_step(st)
    close(P, [-(uf + e * -2.0) * Ahat])


@pytest.mark.parametrize("bad", [1e-3, float("nan")])
def test_bad_residual_falls_back_with_a_warning(bad):
    st = stepper(system=one_dof(), e=(0.5,), h=0.1)
    st.solver = EnumSolver(residual=bad, iterations=7, method="fake")
    ref = stepper(system=one_dof(), e=(0.5,), h=0.1)
    ref.solver = EnumSolver()
    st._fallback = EnumSolver(residual=2e-10, method="refsolve")
    with pytest.warns(RuntimeWarning) as rec:
        P = one_contact_step(st, k=3)
    msg = str(rec[0].message)
    assert msg.startswith(f"fake residual {bad:.3g} at step 3 (t = 0.3); "
                          "fell back to the reference solver (residual 2e-10)"), msg
    close(P, one_contact_step(ref))
    assert st.stats.contact_solves == 1 and st.stats.fallbacks == 1
    assert st.stats.iterations == 7 and st.stats.max_residual == 2e-10
    assert st._fallback.calls == 1


def test_fallback_uses_the_reference_solver_by_default():
    st = stepper(system=one_dof(), e=(0.5,), h=0.1)
    st.solver = EnumSolver(residual=1.0)
    assert st._fallback is None
    with pytest.warns(RuntimeWarning, match="fell back to the reference solver"):
        P = one_contact_step(st)
    assert st._fallback.name == "reference"
    ref = stepper(system=one_dof(), e=(0.5,), h=0.1)
    close(P, one_contact_step(ref), 1e-8)
    assert st.stats.max_residual <= 1e-9


def test_solver_exception_falls_back():
    st = stepper(system=one_dof(), e=(0.5,), h=0.1)
    st.solver = RaisingSolver()
    st._fallback = EnumSolver(residual=0.0)
    with pytest.warns(RuntimeWarning, match=r"^raising raised ArithmeticError: deliberate failure at step 2 \(t = 0.2\)"):
        one_contact_step(st, k=2)
    assert st.stats.fallbacks == 1 and st.stats.contact_solves == 1 and st.stats.iterations == 0


def test_reference_failures_raise():
    st = stepper(system=one_dof(), e=(0.5,), h=0.1, residual_tol=1e-6)
    st.solver = EnumSolver(residual=1e-3, method="fake")
    st._fallback = EnumSolver(residual=2e-6)
    with pytest.raises(ContactSolverError) as info:
        one_contact_step(st, k=4)
    assert str(info.value) == ("contact problem at step 4 (t = 0.4) with 1 contacts: fake residual 0.001; "
                               "reference residual 2e-06 > tolerance 1e-06")
    st._fallback = EnumSolver(residual=1e-6)                 # == tolerance: accepted
    with pytest.warns(RuntimeWarning, match="fell back"):
        one_contact_step(st, k=4)
    st._fallback = RaisingSolver()
    with pytest.raises(ContactSolverError) as info:
        one_contact_step(st, k=4)
    assert str(info.value).endswith("; the reference solver raised ArithmeticError: deliberate failure")
    assert isinstance(info.value.__cause__, ArithmeticError)
    assert st.stats.fallbacks == 3


# ---------------------------------------------------------------------------------------
# observers: V, its per-step parts, the observer table
# ---------------------------------------------------------------------------------------
def tiny_system() -> LinearSystem:
    return LinearSystem(np.diag([2.0, 1.0]), np.array([[0.5, 0.0], [0.0, 0.25]]),
                        np.array([[3.0, -1.0], [-1.0, 2.0]]), np.array([[1.0], [2.0]]),
                        Harmonic.build("system.forcing", 2), Harmonic.build("system.gap", 1, kind="sin"))


def test_lyapunov_hand_computed():
    s = tiny_system()
    q_s = np.array([[1.0, 0.0], [0.0, 1.0]])
    u_s = np.array([[1.0, 1.0], [0.0, 0.0]])
    zero = np.zeros((2, 2))
    # row 0: v = (1, 1): ½(2 + 1) = 1.5; e = (1, 0): ½·3 = 1.5  → 3.0
    # row 1: v = 0;  e = (0, 1): ½·2 = 1.0                        → 1.0
    assert lyapunov(s, q_s, u_s, zero, zero).tolist() == [3.0, 1.0]
    # the master is subtracted: the same numbers with both shifted
    shift = np.array([[0.5, -2.0], [4.0, 1.0]])
    assert lyapunov(s, q_s + shift, u_s - shift, shift, -shift).tolist() == [3.0, 1.0]


def test_lyapunov_decrements_hand_computed():
    """1 DOF: M = 2, C = 0.5, K = 3, W = 1, h = 0.1; every part written out by hand."""
    s = LinearSystem(np.array([[2.0]]), np.array([[0.5]]), np.array([[3.0]]), np.array([[1.0]]),
                     Harmonic.build("system.forcing", 1), Harmonic.build("system.gap", 1, kind="sin"))
    a = dict(q=np.array([[1.0], [0.5], [0.0]]), u=np.array([[2.0], [0.0], [-1.0]]),
             P=np.array([[0.0], [1.0], [0.5]]), sigma=np.array([[0.0], [0.3], [0.0]]))
    b = dict(q=np.zeros((3, 1)), u=np.zeros((3, 1)), P=np.array([[0.0], [0.25], [1.0]]))
    out = lyapunov_decrements(s, 0.1, a, b)
    # V = u² + 1.5 q²: 4 + 1.5 = 5.5; 0 + 0.375 = 0.375; 1 + 0 = 1
    assert out["total"].tolist() == pytest.approx([0.0, -5.125, 0.625], abs=1e-15)
    # v̄ = 1, −0.5; damping −h·C·v̄² = −0.05, −0.0125
    assert out["damping"].tolist() == pytest.approx([0.0, -0.05, -0.0125], abs=1e-15)
    # impulse v̄·ΔP = 1·0.75, −0.5·(−0.5)
    assert out["impulse"].tolist() == pytest.approx([0.0, 0.75, 0.25], abs=1e-15)
    # Δσ = 0.3 at row 1: e⁻ = 0.5 − 0.3/3 = 0.4; ½·3·(0.25 − 0.16) = 0.135; row 2: 0
    assert out["projection"].tolist() == pytest.approx([0.0, 0.135, 0.0], abs=1e-15)
    assert out["residual"].tolist() == pytest.approx(
        [0.0, -5.125 + 0.05 - 0.75 - 0.135, 0.625 + 0.0125 - 0.25], abs=1e-15)
    # sigma on both sides cancels; None on both means no projection part
    b2 = dict(b, sigma=a["sigma"])
    assert lyapunov_decrements(s, 0.1, a, b2)["projection"].tolist() == [0.0, 0.0, 0.0]
    a3 = {k: v for k, v in a.items() if k != "sigma"}
    out3 = lyapunov_decrements(s, 0.1, a3, b)
    assert out3["projection"].tolist() == [0.0, 0.0, 0.0]
    assert set(out3) == {"damping", "impulse", "projection", "total", "residual"}


def test_lyapunov_decrements_identity_on_scheme_trajectories():
    """Two trajectories of the θ = ½ scheme on the same closed sets: ΔV = damping + impulse
    + projection to round-off (discrete eq. (17)), with position jumps on one of them."""
    st = stepper(law="newton", e=(0.3, 0.8), h=0.02)
    s = st.system
    N = 30
    trajs = []
    for q0, proj in ((np.array([0.05, 0.02]), True), (np.array([0.01, -0.01]), False)):
        q, u = q0, np.array([-1.0, -0.5])
        Q, U, P, S = [q], [u], [np.zeros(2)], [np.zeros(2)]
        for k in range(N):
            A = np.array([0, 1]) if 10 <= k < 20 else np.zeros(0, dtype=int)
            q, u, p, sig = st.step(k, q, u, A, project=proj and A.size > 0)
            Pk, Sk = np.zeros(2), np.zeros(2)
            Pk[A] = p
            if sig is not None:
                Sk[A] = sig
            Q.append(q), U.append(u), P.append(Pk), S.append(Sk)
        trajs.append(dict(q=np.array(Q), u=np.array(U), P=np.array(P), sigma=np.array(S)))
    a, b = trajs
    assert not np.any(b.pop("sigma"))           # the plain trajectory: no sigma at all
    out = lyapunov_decrements(s, 0.02, a, b)
    V = lyapunov(s, a["q"], a["u"], b["q"], b["u"])
    assert np.max(np.abs(out["residual"])) <= 1e-12 * V.max()
    assert np.any(out["projection"] != 0.0) and np.any(out["impulse"] != 0.0)
    assert np.all(out["damping"][1:] < 0.0)


def test_observer_config_defaults_and_validation(tmp_path):
    qm, um = np.array([1.0, 2.0]), np.array([0.0, -1.0])
    cfg = ObserverConfig.from_table({}, 2, qm, um)
    assert np.array_equal(cfg.q0, qm) and np.array_equal(cfg.u0, um)
    assert cfg.q0 is not qm and cfg.u0 is not um           # copies, not views of the master
    assert cfg.coupling is None and cfg.source == "master" and cfg.log is None
    assert cfg.observers == ("jump", "nojump")
    cfg = ObserverConfig.from_table({"q": [3, 4], "u": [5, 6], "coupling": [1.0, 1.0],
                                     "source": "self", "observers": ["jump"]},
                                    2, qm, um)
    assert cfg.q0.tolist() == [3.0, 4.0] and cfg.u0.tolist() == [5.0, 6.0]
    assert cfg.coupling == (1.0, 1.0) and isinstance(cfg.coupling[0], float)
    assert cfg.source == "self" and cfg.observers == ("jump",)
    assert ObserverConfig.from_table({"coupling": [0.5, 2.0]}, 2, qm, um).coupling == (0.5, 2.0)
    bad = [({"q": [1.0]}, "observer.q"), ({"u": [1, 2, 3]}, "observer.u"),
           ({"coupling": [2.0, 1.0]}, "observer.coupling"), ({"coupling": [1.0]}, "observer.coupling"),
           ({"source": "oracle"}, "observer.source"), ({"source": "log"}, "observer.log"),
           ({"source": "log", "log": ""}, "observer.log"),
           ({"observers": ["jump", "fast"]}, "observer.observers"),
           ({"observers": "jump"}, "observer.observers")]
    for table, field in bad:
        with pytest.raises(InputError) as info:
            ObserverConfig.from_table(table, 2, qm, um)
        assert info.value.field == field, table
    with pytest.raises(InputError, match=r"t_off = 1.0 < t_on = 2.0"):
        ObserverConfig.from_table({"coupling": [2.0, 1.0]}, 2, qm, um)
    with pytest.raises(InputError, match=r"must be one of \['master', 'log', 'self'\], got 'oracle'"):
        ObserverConfig.from_table({"source": "oracle"}, 2, qm, um)
    with pytest.raises(InputError, match=r'^observer.log: source = "log" needs a log file path$'):
        ObserverConfig.from_table({"source": "log"}, 2, qm, um)


def test_observer_config_resolves_the_log_beside_the_scenario(tmp_path, monkeypatch):
    qm = um = np.zeros(1)
    (tmp_path / "run.csv").write_text("contact,t_close,t_open\n")
    monkeypatch.chdir(tmp_path.parent)
    cfg = ObserverConfig.from_table({"source": "log", "log": "run.csv"}, 1, qm, um, base_dir=str(tmp_path))
    assert cfg.log == str(tmp_path / "run.csv")
    cfg = ObserverConfig.from_table({"source": "log", "log": "run.csv"}, 1, qm, um)
    assert cfg.log == "run.csv"                              # no base directory: as given
    cfg = ObserverConfig.from_table({}, 1, qm, um, base_dir=str(tmp_path))
    assert cfg.log is None                                   # no log: nothing to resolve
    cfg = ObserverConfig.from_table({"source": "log", "log": "other.csv"}, 1, qm, um, base_dir=str(tmp_path))
    assert cfg.log == "other.csv"                            # not found beside it: as given
    absolute = str(tmp_path.parent / "run.csv")
    cfg = ObserverConfig.from_table({"log": absolute}, 1, qm, um, base_dir=str(tmp_path))
    assert cfg.log == absolute                               # absolute paths are kept
    # found from the cwd as well as beside the scenario: kept as given
    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir(), there.mkdir()
    (here / "run.csv").write_text("contact,t_close,t_open\n")
    (there / "run.csv").write_text("contact,t_close,t_open\n")
    monkeypatch.chdir(here)
    cfg = ObserverConfig.from_table({"source": "log", "log": "run.csv"}, 1, qm, um, base_dir=str(there))
    assert cfg.log == "run.csv"


def test_observer_names():
    check_observer_name("jump")
    check_observer_name("nojump")
    with pytest.raises(InputError, match=r"unknown observer 'slow'; choose from \['jump', 'jump_identity', "
                                         r"'jump_mass', 'nojump'\]") as info:
        check_observer_name("slow")
    assert info.value.field == "observer.observers"
