"""Moreau–Jean θ-scheme for the master and for switched-constraint slaves.

One step from (q_k, u_k) at t_k to t_{k+1} = t_k + h on the closed set A (paper eq. (1)
discretised; Siconos' ``MoreauJeanOSI``)::

    M(u_{k+1} − u_k) = −hC[(1−θ)u_k + θu_{k+1}] − hK[(1−θ)q_k + θq_{k+1}]
                       + h[(1−θ)f(t_k) + θf(t_{k+1})] + W_A P
    q_{k+1} = q_k + h[(1−θ)u_k + θu_{k+1}]

so that ``u_{k+1} = u_free + Â⁻¹W_A P`` with the iteration matrix
``Â = M + hθC + h²θ²K``. The impulse P comes from

* Newton: ``0 ≤ γ_{k+1} + e∘γ_k ⊥ P ≥ 0`` (γ = Wᵀu + ν̇), an LCP with ``Ĝ = W_AᵀÂ⁻¹W_A``;
* Poisson (impulsive split): the impact law of :mod:`observer.impact` on the pre-impact
  velocity γ_k with ``G₀ = W_AᵀM⁻¹W_A`` gives P_I; then the smooth part with e = 0,
  ``0 ≤ γ_{k+1} ⊥ P_S ≥ 0``; P = P_I + P_S. The position update keeps the pre-impact
  u_k in its (1−θ) term, and so do the damping and stiffness averages.

With θ = ½ the difference of two solutions driven by the same A satisfies exactly
``V_{k+1} − V_k = −h v̄ᵀCv̄ + (Wᵀv̄)ᵀΔP`` with v̄ = (v_k + v_{k+1})/2 and
V = ½‖v‖²_M + ½‖e‖²_K (the discrete twin of eq. (17)).

The active set of the master is predicted as in Siconos:
``g_k + (h/2)γ_k ≤ 0``. The optional K-metric projection onto ``{g_I(q, t_{k+1}) = 0}``
(paper eqs. (13)-(14)) realises the position jumps of the new observer and of the
position-projected master.

Everything that depends only on (system, h, θ) is computed once in
:class:`SchemeMatrices`; the signals on the grid once in :class:`Grid`. The step uses
plain float arrays and index arrays only, ready for a compiled kernel.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from observer.contact import get_solver
from observer.contact.lcp import LCPSolution
from observer.errors import ContactSolverError, InputError
from observer.impact import NEWTON, ImpactLaw, poisson_impact
from observer.model import LinearSystem
from observer.validation import as_scalar


@dataclass(frozen=True)
class SchemeMatrices:
    """h-dependent matrices of the θ-scheme, computed once per run.

    ``u_free = Bu u + Bq q + Bf f̄``; ``AinvW = Â⁻¹W``; ``Ghat = WᵀÂ⁻¹W``;
    ``G0 = WᵀM⁻¹W``; ``KinvW = K⁻¹W`` and ``L = WᵀK⁻¹W`` (None unless K ≻ 0).
    """

    h: float
    theta: float
    Bu: np.ndarray
    Bq: np.ndarray
    Bf: np.ndarray
    W: np.ndarray
    WT: np.ndarray
    AinvW: np.ndarray
    Ghat: np.ndarray
    G0: np.ndarray
    KinvW: np.ndarray | None
    L: np.ndarray | None

    @staticmethod
    def build(system: LinearSystem, h: float, theta: float) -> "SchemeMatrices":
        M, C, K, W = system.M, system.C, system.K, system.W
        n = system.n
        A_hat = M + h * theta * C + (h * theta) ** 2 * K
        if np.array_equal(A_hat, A_hat.T):
            Ainv = sla.cho_solve(sla.cho_factor(A_hat), np.eye(n))
        else:                        # a non-symmetric C (allowed by the paper, check=False only)
            Ainv = sla.lu_solve(sla.lu_factor(A_hat), np.eye(n))
        Bu = np.eye(n) - Ainv @ (h * C + h * h * theta * K)
        Bq = -h * (Ainv @ K)
        Bf = h * Ainv
        AinvW = Ainv @ W
        Ghat = W.T @ AinvW
        G0 = W.T @ sla.cho_solve(sla.cho_factor(M), W)
        KinvW = L = None
        if system.is_stiffness_definite():
            KinvW = sla.cho_solve(sla.cho_factor(K), W)
            L = W.T @ KinvW
            L = 0.5 * (L + L.T)
        return SchemeMatrices(h, theta, Bu, Bq, Bf, W, np.ascontiguousarray(W.T), AinvW,
                              0.5 * (Ghat + Ghat.T), 0.5 * (G0 + G0.T), KinvW, L)


@dataclass(frozen=True)
class Grid:
    """The time grid t_k = t0 + k h (k = 0..N) and the signals sampled on it.

    ``fbar[k] = (1−θ)f(t_k) + θf(t_{k+1})`` (shape (N, n)); ``nu``, ``nu_dot`` shape (N+1, m).
    """

    t: np.ndarray
    fbar: np.ndarray
    nu: np.ndarray
    nu_dot: np.ndarray

    @staticmethod
    def build(system: LinearSystem, h: float, t_end: float, theta: float, t0: float = 0.0) -> "Grid":
        steps = int(np.ceil((t_end - t0) / h - 1e-9))
        if steps < 1:
            raise InputError("simulation.t_end", f"must exceed t0 = {t0} by at least one step h = {h}")
        t = t0 + np.arange(steps + 1) * h
        f = system.f(t)
        fbar = (1.0 - theta) * f[:-1] + theta * f[1:]
        return Grid(t, fbar, system.nu(t), system.nu_dot(t))

    @property
    def steps(self) -> int:
        return self.t.shape[0] - 1


@dataclass
class StepStats:
    """Work counters of one stepper (contact solves, pivots, fallbacks, worst residual)."""

    contact_solves: int = 0
    iterations: int = 0
    fallbacks: int = 0
    max_residual: float = 0.0


def check_step_parameters(h: float, theta: float) -> tuple[float, float]:
    """Validate the step size and θ; return them as floats."""
    h = as_scalar("simulation.h", h, positive=True)
    theta = as_scalar("simulation.theta", theta, low=0.5, high=1.0)
    return h, theta


class MoreauJean:
    """Moreau–Jean θ-stepper for one :class:`LinearSystem` with an :class:`ImpactLaw`.

    Holds no trajectory state: :meth:`step` maps (k, q_k, u_k, A) to (q_{k+1}, u_{k+1}, P).
    Several systems (a master and its slaves) can share one stepper.

    Parameters
    ----------
    system, law
        The model and its impact law.
    h, t_end, theta, t0
        Step size, horizon, θ ∈ [½, 1] (default ½), start time.
    solver : str
        Name in :data:`observer.contact.CONTACT_SOLVERS`.
    residual_tol : float
        Largest accepted relative complementarity residual of a contact solve; a worse
        solution is re-solved by the reference solver (a ``RuntimeWarning`` says so)
        and, if still worse, raises :class:`ContactSolverError`.
    """

    def __init__(self, system: LinearSystem, law: ImpactLaw, h: float, t_end: float,
                 theta: float = 0.5, t0: float = 0.0, solver: str = "pivoting",
                 residual_tol: float = 1e-9):
        h, theta = check_step_parameters(h, theta)
        t_end = as_scalar("simulation.t_end", t_end)
        self.system = system
        self.law = law
        self.solver = get_solver(solver)
        self.residual_tol = residual_tol
        self.S = SchemeMatrices.build(system, h, theta)
        self.grid = Grid.build(system, h, t_end, theta, t0)
        self.stats = StepStats()
        self._law_code = law.code
        self._e = np.asarray(law.restitution)
        self._fallback = None
        self._k = 0
        self._slices: dict[bytes, tuple] = {}

    MAX_CACHED_SETS = 4096
    """Active sets whose matrix slices are kept (cleared when full)."""

    def _active_slices(self, active: np.ndarray) -> tuple:
        """Slices of the precomputed matrices for one active set (cached by the set).

        Returns ``(W_A, Â⁻¹W_A, Ĝ_AA, G₀_AA, K⁻¹W_A, L_AA, e_A)``.
        """
        key = active.tobytes()
        hit = self._slices.get(key)
        if hit is None:
            S = self.S
            ix = np.ix_(active, active)
            hit = (np.ascontiguousarray(S.W[:, active]), np.ascontiguousarray(S.AinvW[:, active]),
                   S.Ghat[ix], S.G0[ix],
                   None if S.KinvW is None else np.ascontiguousarray(S.KinvW[:, active]),
                   None if S.L is None else S.L[ix], self._e[active])
            if len(self._slices) >= self.MAX_CACHED_SETS:
                self._slices.clear()
            self._slices[key] = hit
        return hit

    @property
    def h(self) -> float:
        return self.S.h

    @property
    def theta(self) -> float:
        return self.S.theta

    # -- contact solves with residual check ------------------------------------------------
    def _solve(self, G: np.ndarray, b: np.ndarray) -> LCPSolution:
        sol = self.solver.solve(G, b)
        stats = self.stats
        stats.contact_solves += 1
        stats.iterations += sol.iterations
        if not sol.residual <= self.residual_tol:
            sol = self._fall_back(G, b, sol)
        if sol.residual > stats.max_residual:
            stats.max_residual = sol.residual
        return sol

    def _fall_back(self, G: np.ndarray, b: np.ndarray, bad: LCPSolution) -> LCPSolution:
        t = self.grid.t[self._k]
        if self._fallback is None:
            self._fallback = get_solver("reference")
        self.stats.fallbacks += 1
        sol = self._fallback.solve(G, b)
        if not sol.residual <= self.residual_tol:
            raise ContactSolverError(
                f"contact problem at step {self._k} (t = {t:.6g}) with {b.size} contacts: "
                f"{bad.method} residual {bad.residual:.3g}, reference residual {sol.residual:.3g} "
                f"> tolerance {self.residual_tol:g}")
        warnings.warn(f"{bad.method} residual {bad.residual:.3g} at step {self._k} (t = {t:.6g}); "
                      f"fell back to the reference solver (residual {sol.residual:.3g})",
                      RuntimeWarning, stacklevel=3)
        return sol

    # -- the scheme ------------------------------------------------------------------------
    def predicted_active(self, k: int, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Closed set of the step k → k+1 (Siconos rule): ``g_k + (h/2)γ_k ≤ 0``, bool (m,)."""
        S, grid = self.S, self.grid
        g_pred = S.WT @ (q + 0.5 * S.h * u) + grid.nu[k] + 0.5 * S.h * grid.nu_dot[k]
        return g_pred <= 0.0

    def step(self, k: int, q: np.ndarray, u: np.ndarray, active: np.ndarray,
             project: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Advance one step on the closed set ``active`` (index array).

        Returns ``(q_{k+1}, u_{k+1}, P_A, Σ_A)``: the impulse of the step on the active
        contacts, and, when ``project`` is true, the multiplier ``Σ_A = −L_A⁻¹ g_A⁻`` of the
        K-metric projection (eq. (14)); otherwise ``None``.
        """
        self._k = k
        S, grid = self.S, self.grid
        h, theta = S.h, S.theta
        u_free = S.Bu @ u + S.Bq @ q + S.Bf @ grid.fbar[k]
        if active.size == 0:
            u1 = u_free
            P = np.zeros(0)
        else:
            W_A, AinvW_A, Ghat, G0, _, _, e_A = self._active_slices(active)
            gamma_k = u @ W_A + grid.nu_dot[k, active]
            gamma_free = u_free @ W_A + grid.nu_dot[k + 1, active]
            if self._law_code == NEWTON:
                P = self._solve(Ghat, gamma_free + e_A * gamma_k).x
            else:
                P_imp = poisson_impact(G0, gamma_k, e_A, self._solve)
                P = P_imp + self._solve(Ghat, gamma_free + Ghat @ P_imp).x
            u1 = u_free + AinvW_A @ P
        q1 = q + h * ((1.0 - theta) * u + theta * u1)
        sigma = None
        if project:
            q1, sigma = self.project(k + 1, q1, active)
        return q1, u1, P, sigma

    def project(self, k: int, q: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """K-metric projection of q onto ``{W_Iᵀq + ν_I(t_k) = 0}`` (paper eqs. (13)-(14)).

        ``q⁺ = q − K⁻¹W_I L_I⁻¹ g_I`` with ``L_I = W_IᵀK⁻¹W_I``; returns (q⁺, Σ_I = −L_I⁻¹g_I).
        """
        S = self.S
        if active.size == 0:
            return q, np.zeros(0)
        if S.L is None:
            self.system.require_definite_stiffness("the position projection (position jumps)")
        W_I, _, _, _, KinvW_I, L_I, _ = self._active_slices(active)
        g = q @ W_I + self.grid.nu[k, active]
        if active.size == 1:
            sigma = -g / L_I[0, 0]
        else:
            sigma = -np.linalg.solve(L_I, g)
        return q + KinvW_I @ sigma, sigma
