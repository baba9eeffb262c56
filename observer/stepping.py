"""Moreau–Jean θ-scheme for the master and for switched-constraint slaves.

One step from (q_k, u_k) at t_k to t_{k+1} = t_k + h on the closed set A (paper eq. (1)
discretised; Siconos' ``MoreauJeanOSI``)::

    M(u_{k+1} − u_k) = −hC[(1−θ)u_k + θu_{k+1}] − hK[(1−θ)q_k + θq_{k+1}]
                       + h[(1−θ)f(t_k) + θf(t_{k+1})] + W_A P
    q_{k+1} = q_k + h[(1−θ)u_k + θu_{k+1}]

so that ``u_{k+1} = u_free + Â⁻¹W_A P`` with the iteration matrix
``Â = M + hθC + h²θ²K`` and ``γ_{k+1} = γ_free + ĜP`` with ``Ĝ = W_AᵀÂ⁻¹W_A``
(γ = Wᵀu + ν̇). The impulse P comes from the impact law applied, with the step's Delassus
matrix Ĝ, to the step's pre-impact velocity ``γ̃ = (γ_free + e∘γ_k)/(1+e)``:

* Newton (paper eq. (5)): ``0 ≤ ĜP + (1+e)∘γ̃ ⊥ P ≥ 0``, i.e. Siconos' law
  ``0 ≤ γ_{k+1} + e∘γ_k ⊥ P ≥ 0``;
* Poisson (paper eq. (6)), :func:`observer.impact.poisson_step`: Glocker's inequality law on
  γ̃, ``P = Λ_C + Λ_E`` with ``0 ≤ γ̃ + ĜΛ_C ⊥ Λ_C ≥ 0`` (compression) and
  ``0 ≤ γ_E ⊥ Λ_E − ε∘Λ_C ≥ 0``, ``γ_E = γ̃ + ĜP`` (expansion).

Derivation of the Poisson step. Over a step with an impact, P carries the impulsive part and
the smooth contact force of the step together; γ_free = γ_k + δ, with δ = O(h) the step's
smooth velocity change. Newton's discrete law restitutes ``−eγ_k`` and lets δ decide only
whether that target is reached; written as an impact map it is Newton's map on γ̃ with the
Delassus matrix Ĝ. The Poisson step is Glocker's map on the *same* γ̃ and Ĝ. Hence:

* for one contact Glocker's map is Newton's map, so **the Poisson step is the Newton step**
  (returned in Newton's closed form, bitwise); the earlier split (impulse on γ_k first, then
  the smooth force with e = 0) restituted ``ε|γ_k| + δ`` instead, an O(h) energy loss per
  impact whose constant grows like (1+ε)/(1−ε) (bouncing ball, ε = 0.99, h = 1e-3: rest at
  55.7 s instead of 87.0 s);
* with several contacts Glocker's conditions hold exactly on the step's impulse, in γ̃;
* resting contacts (γ_k = 0) have γ̃ = γ_free/(1+ε): with one ε for the touching contacts,
  P = LCP(Ĝ, γ_free), the e = 0 law, so they do not hop;
* monotonicity (the impulse term of eq. (17)): with γ̄ = (γ_k + γ_{k+1})/2 and
  γ̄_G = γ̃ + ĜP/2 (Glocker's mean velocity), ``γ̄ − γ̄_G = −(1−ε)/(2(1+ε))∘δ``, exactly as for
  Newton; so ``ΔPᵀΔγ̄ ≤ ΔPᵀΔγ̄_G + O(h)`` and the discrete impulse term inherits the sign of
  the impact map's (A3) up to an O(h) slack that vanishes as h → 0;
* as h → 0, Ĝ → G₀ = W_AᵀM⁻¹W_A and γ̃ → γ_k: the step's velocity jump tends to Glocker's.

With θ = ½ the difference of two solutions driven by the same A satisfies the identity
``V_{k+1} − V_k = −h v̄ᵀCv̄ + (Wᵀv̄)ᵀΔP`` to round-off, with v̄ = (v_k + v_{k+1})/2 and
V = ½‖v‖²_M + ½‖e‖²_K (the discrete twin of eq. (17)). The damping term is ≤ 0 (C ⪰ 0);
the impulse term has **no sign** in discrete time: it contains
``−(1−e)/(2(1+e)) ΔPᵀΔδ`` with Δδ = O(h), a slack that vanishes as h → 0 (and for e = 1).

The active set of the master is predicted as in Siconos:
``g_k + (h/2)γ_k ≤ 0``. The optional K-metric projection onto ``{g_I(q, t_{k+1}) = 0}``
(paper eqs. (13)-(14)) realises the position jumps of the new observer and of the
position-projected master.

Everything that depends only on (system, h, θ) is computed once in
:class:`SchemeMatrices`; the signals on the grid once in :class:`Grid`. The step uses
plain float arrays and index arrays only, ready for a compiled kernel.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from observer.contact import get_solver
from observer.contact.lcp import LCPSolution
from observer import sparse as sps
from observer.errors import ContactSolverError, InputError
from observer.impact import ImpactLaw
from observer.model import LinearSystem
from observer.validation import as_scalar, check_step_parameters


STRUCTURES = ("dense", "banded", "auto")
"""Matrix structures of :meth:`SchemeMatrices.build`."""

BANDED_MIN_N = 32
"""Smallest n for which a banded structure is used (smaller systems stay dense): measured on the
chain, banded wins from N = 20 blocks (n = 40) and loses slightly at N = 10 (n = 20), per step
in the kernel."""


FACTORED_MIN_N = sps.DENSE_MAX_N + 1
"""Smallest n whose banded structure keeps *factored* contact data: the banded Cholesky
factors of Â, M and K, from which each closed set's ``Â⁻¹W_A``, Ĝ_AA, ``K⁻¹W_A`` and L_AA
are computed when it occurs (O(n·bw) per column), never the n × m ``Â⁻¹W``, ``K⁻¹W`` nor the
m × m Ĝ, G₀, L (:attr:`BandedScheme.factored`; the compiled kernel's
:data:`observer.primitives.CONTACTS_FACTORED`). Below it, the precomputed dense ones (every
system of at most :data:`observer.sparse.DENSE_MAX_N` degrees of freedom runs as before, bit
for bit)."""


def bandwidth(*mats) -> int:
    """Largest |i − j| over the nonzero entries of the given n×n matrices (dense or sparse)."""
    if any(sps.is_sparse(A) for A in mats):
        return sps.bandwidth(*mats)
    pattern = np.zeros_like(mats[0], dtype=bool)
    for A in mats:
        pattern |= A != 0.0
    i, j = np.nonzero(pattern)
    return int(np.max(np.abs(i - j))) if i.size else 0


def to_band(A, bw: int) -> np.ndarray:
    """Lower band storage of symmetric A: ``ab[d, j] = A[j + d, j]`` (LAPACK/scipy layout);
    A dense or sparse."""
    return sps.to_band(A, bw)


dense = sps.dense


@dataclass(frozen=True)
class BandedScheme:
    """Banded form of the free-velocity update: ``Â u_free = R_u u + R_q q + h f̄``.

    ``Achol`` is the lower banded Cholesky factor of ``Â = M + hθC + h²θ²K``;
    ``Ru = M − h(1−θ)C − h²θ(1−θ)K`` and ``Rq = −hK`` are in lower band storage (``Ru_s``,
    ``Rq_s`` the same as sparse matrices, for the numpy engine). ``factored``: the contact
    data are kept as factors (n ≥ :data:`FACTORED_MIN_N`), with ``Mchol`` and ``Kchol`` the
    lower banded Cholesky factors of M and K (``Kchol`` None when K is not positive definite).
    """

    bw: int
    Achol: np.ndarray
    Ru: np.ndarray
    Rq: np.ndarray
    Ru_s: sp.csr_matrix
    Rq_s: sp.csr_matrix
    factored: bool = False
    Mchol: np.ndarray | None = None
    Kchol: np.ndarray | None = None

    def free_velocity(self, h: float, q: np.ndarray, u: np.ndarray, fbar: np.ndarray) -> np.ndarray:
        return sla.cho_solve_banded((self.Achol, True), self.Ru_s @ u + self.Rq_s @ q + h * fbar)


@dataclass(frozen=True)
class SchemeMatrices:
    """h-dependent matrices of the θ-scheme, computed once per run.

    Dense structure: ``u_free = Bu u + Bq q + Bf f̄`` (``band`` is None). Banded structure
    (n ≥ :data:`BANDED_MIN_N`, symmetric M, C, K of bandwidth ≤ n/8, chosen automatically):
    ``Bu = Bq = Bf = None`` and :class:`BandedScheme` gives u_free in O(n·bw²). Always:
    ``AinvW = Â⁻¹W``; ``Ghat = WᵀÂ⁻¹W``; ``G0 = WᵀM⁻¹W``; ``KinvW = K⁻¹W`` and
    ``L = WᵀK⁻¹W`` (None unless K ≻ 0) — except with factored contact data
    (``band.factored``, n ≥ :data:`FACTORED_MIN_N`): then those five are None, W is a sparse
    CSC matrix (``WT`` its CSR transpose) and :meth:`MoreauJean._active_slices` computes each
    closed set's blocks from the factors.
    """

    h: float
    theta: float
    Bu: np.ndarray | None
    Bq: np.ndarray | None
    Bf: np.ndarray | None
    W: np.ndarray
    WT: np.ndarray
    AinvW: np.ndarray
    Ghat: np.ndarray
    G0: np.ndarray
    KinvW: np.ndarray | None
    L: np.ndarray | None
    band: BandedScheme | None = None

    @staticmethod
    def choose_structure(system: LinearSystem) -> str:
        """"banded" for large systems with symmetric, narrowly banded M, C, K; else "dense"."""
        M, C, K = system.M, system.C, system.K
        if system.n < BANDED_MIN_N or not all(sps.exactly_symmetric(A) for A in (C, M, K)):
            return "dense"
        return "banded" if bandwidth(M, C, K) <= system.n // 8 else "dense"

    @staticmethod
    def build(system: LinearSystem, h: float, theta: float, structure: str = "dense") -> "SchemeMatrices":
        """Precompute the scheme; ``structure`` is "dense", "banded" or "auto"."""
        if structure not in STRUCTURES:
            raise InputError("structure", f"must be one of {list(STRUCTURES)}, got {structure!r}")
        if structure == "auto":
            structure = SchemeMatrices.choose_structure(system)
        if structure == "banded":
            return SchemeMatrices._build_banded(system, h, theta)
        M, C, K, W = (dense(A) for A in (system.M, system.C, system.K, system.W))
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

    @staticmethod
    def _build_banded(system: LinearSystem, h: float, theta: float) -> "SchemeMatrices":
        """The banded structure: no dense n×n matrix is formed or multiplied (M, C, K dense or
        sparse; below :data:`FACTORED_MIN_N` W densified, as the kernel's dense Â⁻¹W, K⁻¹W
        are n×m; from it nothing of size n×m or m×m, :meth:`_build_factored`)."""
        M, C, K = system.M, system.C, system.K
        bw = max(bandwidth(M, C, K), 1)
        A_hat = M + h * theta * C + (h * theta) ** 2 * K
        Achol = sla.cholesky_banded(to_band(A_hat, bw), lower=True)
        Ru = M - h * (1.0 - theta) * C - h * h * theta * (1.0 - theta) * K
        Rq = -h * K
        band = BandedScheme(bw, Achol, to_band(Ru, bw), to_band(Rq, bw), sp.csr_matrix(Ru), sp.csr_matrix(Rq))
        if system.n >= FACTORED_MIN_N:
            return SchemeMatrices._build_factored(system, h, theta, band)
        W = dense(system.W)
        Ws = sp.csc_matrix(W)
        AinvW = sla.cho_solve_banded((Achol, True), W)
        Ghat = np.asarray(Ws.T @ AinvW)
        G0 = np.asarray(Ws.T @ sla.cho_solve_banded((sla.cholesky_banded(to_band(M, bw), lower=True), True), W))
        KinvW = L = None
        try:
            Kchol = sla.cholesky_banded(to_band(K, bw), lower=True)
        except np.linalg.LinAlgError:
            Kchol = None
        if Kchol is not None and system.is_stiffness_definite():
            KinvW = sla.cho_solve_banded((Kchol, True), W)
            L = np.asarray(Ws.T @ KinvW)
            L = 0.5 * (L + L.T)
        return SchemeMatrices(h, theta, None, None, None, W, np.ascontiguousarray(W.T), AinvW,
                              0.5 * (Ghat + Ghat.T), 0.5 * (G0 + G0.T), KinvW, L, band)

    @staticmethod
    def _build_factored(system: LinearSystem, h: float, theta: float, band: BandedScheme) -> "SchemeMatrices":
        """Factored contact data: the banded Cholesky factors of M and K next to Â's, W sparse;
        O(n·bw²) time and O(n·bw + nnz(W)) memory."""
        bw = band.bw
        Mchol = sla.cholesky_banded(to_band(system.M, bw), lower=True)
        Kchol = None
        if system.is_stiffness_definite():
            try:
                Kchol = sla.cholesky_banded(to_band(system.K, bw), lower=True)
            except np.linalg.LinAlgError:
                Kchol = None
        band = dataclasses.replace(band, factored=True, Mchol=Mchol, Kchol=Kchol)
        W = sp.csc_matrix(system.W, dtype=np.float64)
        W.sort_indices()
        return SchemeMatrices(h, theta, None, None, None, W, sp.csr_matrix(W.T), None, None, None, None, None,
                              band)

    @property
    def factored(self) -> bool:
        """Whether the contact data are factors (no n×m / m×m matrices; :meth:`_build_factored`)."""
        return self.band is not None and self.band.factored


class ClosedSetProjection:
    """The K-metric projection data of eqs. (13)-(14) for one closed set at a time, in O(n·|I|):
    ``K⁻¹W_I`` and ``L_I = W_IᵀK⁻¹W_I`` from a banded Cholesky factor of K computed once,
    for the closed contacts I only — never the n × m ``K⁻¹W`` nor the m × m ``L``.

    The building block of position jumps on a large sparse system (issue 23): the compiled
    kernel still takes the whole dense ``K⁻¹W`` and ``L``; this gives the same numbers per
    closed set (to round-off: a different summation order than the dense products).

    Parameters
    ----------
    K : ndarray or sparse matrix, shape (n, n)
        Symmetric positive definite, narrowly banded.
    W : ndarray or sparse matrix, shape (n, m)
    """

    def __init__(self, K, W):
        self.bw = max(bandwidth(K), 1)
        try:
            self.chol = sla.cholesky_banded(to_band(K, self.bw), lower=True)
        except np.linalg.LinAlgError:
            raise InputError("system.K", "must be positive definite for the position projection "
                             "(its banded Cholesky factorization failed)") from None
        self.W = sp.csc_matrix(W)

    def matrices(self, closed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(K⁻¹W_I, L_I)`` of the closed contacts ``closed`` (indices), shapes (n, |I|), (|I|, |I|)."""
        WI = self.W[:, np.asarray(closed, dtype=np.int64)]
        KinvWI = sla.cho_solve_banded((self.chol, True), WI.toarray())
        L = np.asarray(WI.T @ KinvWI)
        return KinvWI, 0.5 * (L + L.T)

    def project(self, q: np.ndarray, g: np.ndarray, closed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The projected position ``q + K⁻¹W_I Σ`` with ``L_I Σ = −g_I`` (``g`` the gaps of the
        closed contacts at q) and the multipliers Σ."""
        KinvWI, L = self.matrices(closed)
        sigma = -sla.cho_solve(sla.cho_factor(L), g)
        return q + KinvWI @ sigma, sigma


class NonFiniteState(ArithmeticError):
    """A step met a non-finite value (its free velocity): the loop stops before it
    (:class:`observer.engines.loop.FiniteGuard`), never writing a non-finite row."""


def grid_steps(h: float, t_end: float, t0: float = 0.0) -> int:
    """Number of steps N of the grid t_k = t0 + k h up to t_end: the largest N with
    t_N ≤ t_end (to a relative 10⁻⁹ of h, so that t_end = N·h in floating point counts N),
    at least one; the grid never steps past t_end."""
    steps = int(np.floor((t_end - t0) / h + 1e-9))
    if steps < 1:
        raise InputError("simulation.t_end", f"must exceed t0 = {t0} by at least one step h = {h}")
    return steps


@dataclass(frozen=True)
class Grid:
    """The time grid t_k = t0 + k h (k = k0..k1) and the signals sampled on it.

    ``fbar[i] = (1−θ)f(t_{k0+i}) + θf(t_{k0+i+1})`` (shape (k1−k0, n)); ``nu``, ``nu_dot``
    shape (k1−k0+1, m). :meth:`build` makes the whole grid (k0 = 0); :meth:`window` a part of
    it with bitwise the same values (the signals come from :meth:`observer.model.Harmonic.on_grid`,
    whose anchors sit at absolute grid indices), so that a long run can be advanced window by
    window in bounded memory.
    """

    t: np.ndarray
    fbar: np.ndarray
    nu: np.ndarray
    nu_dot: np.ndarray
    k0: int = 0

    @staticmethod
    def build(system: LinearSystem, h: float, t_end: float, theta: float, t0: float = 0.0) -> "Grid":
        return Grid.window(system, h, theta, t0, 0, grid_steps(h, t_end, t0))

    @staticmethod
    def window(system: LinearSystem, h: float, theta: float, t0: float, k0: int, k1: int) -> "Grid":
        """Steps k0..k1−1 (grid points k0..k1)."""
        t = t0 + np.arange(k0, k1 + 1) * h
        f = system.forcing.on_grid(t0, h, k0, k1)
        fbar = (1.0 - theta) * f[:-1] + theta * f[1:]
        return Grid(t, fbar, system.gap.on_grid(t0, h, k0, k1), system.gap.on_grid(t0, h, k0, k1, True), k0)

    @property
    def steps(self) -> int:
        return self.t.shape[0] - 1


@dataclass
class SolverCounts:
    """Work counters of one stepper's contact solves (solves, pivots, fallbacks, worst
    residual); a run's counters are :class:`observer.result.StepStats`, which the engines
    build from these."""

    contact_solves: int = 0
    iterations: int = 0
    fallbacks: int = 0
    max_residual: float = 0.0


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
    structure : {"dense", "banded", "auto"}
        Matrix structure of the free-velocity update (:meth:`SchemeMatrices.build`).
    """

    def __init__(self, system: LinearSystem, law: ImpactLaw, h: float, t_end: float,
                 theta: float = 0.5, t0: float = 0.0, solver: str = "pivoting",
                 residual_tol: float = 1e-9, structure: str = "dense"):
        h, theta = check_step_parameters(h, theta)
        t_end = as_scalar("simulation.t_end", t_end)
        self.system = system
        self.law = law
        self.solver = get_solver(solver)
        self.residual_tol = residual_tol
        self.S = SchemeMatrices.build(system, h, theta, structure)
        self.t0 = float(t0)
        self.steps = grid_steps(h, t_end, self.t0)
        self._t_end = t_end
        self._grid: Grid | None = None
        self.stats = SolverCounts()
        self._e = np.asarray(law.restitution)
        self._fallback = None
        self._k = 0
        self._slices: dict[bytes, tuple] = {}
        self._half_h = 0.5 * self.S.h
        self._last_free: tuple | None = None

    MAX_CACHED_SETS = 4096
    """Active sets whose matrix slices are kept (cleared when full)."""
    MAX_FACTORED_SETS = 16
    """The same with factored contact data, whose slices are ``n × |A|`` each (bounded memory)."""

    def _active_slices(self, active: np.ndarray) -> tuple:
        """Slices of the precomputed matrices for one active set (cached by the set).

        Returns ``(W_A, Â⁻¹W_A, Ĝ_AA, G₀_AA, K⁻¹W_A, L_AA, e_A)``.
        """
        key = active.tobytes()
        hit = self._slices.get(key)
        if hit is None:
            S = self.S
            if S.factored:
                hit = self._factored_slices(active)
            else:
                ix = np.ix_(active, active)
                hit = (np.ascontiguousarray(S.W[:, active]), np.ascontiguousarray(S.AinvW[:, active]),
                       S.Ghat[ix], S.G0[ix],
                       None if S.KinvW is None else np.ascontiguousarray(S.KinvW[:, active]),
                       None if S.L is None else S.L[ix], self._e[active])
            if len(self._slices) >= (self.MAX_FACTORED_SETS if S.factored else self.MAX_CACHED_SETS):
                self._slices.clear()
            self._slices[key] = hit
        return hit

    def _factored_slices(self, active: np.ndarray) -> tuple:
        """:meth:`_active_slices` from the banded factors (factored contact data): one banded
        solve per closed contact and metric, O(n·bw·|A|); symmetrized like the dense blocks."""
        S, b = self.S, self.S.band
        W_A = S.W[:, np.asarray(active, dtype=np.int64)].toarray()
        sym = lambda G: 0.5 * (G + G.T)  # noqa: E731
        AinvW_A = sla.cho_solve_banded((b.Achol, True), W_A)
        KinvW_A = L_A = None
        if b.Kchol is not None:
            KinvW_A = sla.cho_solve_banded((b.Kchol, True), W_A)
            L_A = sym(W_A.T @ KinvW_A)
        return (W_A, AinvW_A, sym(W_A.T @ AinvW_A), sym(W_A.T @ sla.cho_solve_banded((b.Mchol, True), W_A)),
                KinvW_A, L_A, self._e[active])

    @property
    def grid(self) -> Grid:
        """The whole grid with its signals (built on first use: a compiled run advances
        window by window and never needs it)."""
        if self._grid is None:
            self._grid = Grid.build(self.system, self.S.h, self._t_end, self.S.theta, self.t0)
        return self._grid

    def time(self, k, out: np.ndarray | None = None) -> np.ndarray | float:
        """t_k = t0 + k h (the grid's value, without building the grid); written into ``out``
        when given (an array of k's shape)."""
        if type(k) is int and out is None:             # the loop's step index: no array
            return np.float64(self.t0 + k * self.S.h)
        k = np.asarray(k)
        if k.ndim == 0:
            return self.t0 + k * self.S.h
        t = np.multiply(k, self.S.h, dtype=float, out=out)  # one array, the same values
        t += self.t0
        return t

    @property
    def h(self) -> float:
        return self.S.h

    @property
    def theta(self) -> float:
        return self.S.theta

    # -- contact solves with residual check ------------------------------------------------
    SOLVER_FAILURES = (ContactSolverError, ArithmeticError, ValueError, np.linalg.LinAlgError)
    """Exceptions of a contact solver that are treated like a bad residual (fall back, report)."""

    def _solve(self, G: np.ndarray, b: np.ndarray) -> LCPSolution:
        stats = self.stats
        stats.contact_solves += 1
        try:
            sol = self.solver.solve(G, b)
        except self.SOLVER_FAILURES as exc:
            return self._fall_back(G, b, f"{self.solver.name} raised {type(exc).__name__}: {exc}")
        stats.iterations += sol.iterations
        if not sol.residual <= self.residual_tol:
            return self._fall_back(G, b, f"{sol.method} residual {sol.residual:.3g}")
        if sol.residual > stats.max_residual:
            stats.max_residual = sol.residual
        return sol

    def _fall_back(self, G: np.ndarray, b: np.ndarray, why: str) -> LCPSolution:
        """Re-solve with the reference solver; warn (and count) or raise :class:`ContactSolverError`."""
        t = float(self.time(self._k))
        if self._fallback is None:
            self._fallback = get_solver("reference")
        self.stats.fallbacks += 1
        where = f"contact problem at step {self._k} (t = {t:.6g}) with {b.size} contacts: {why}"
        try:
            sol = self._fallback.solve(G, b)
        except self.SOLVER_FAILURES as exc:
            raise ContactSolverError(f"{where}; the reference solver raised {type(exc).__name__}: {exc}") from exc
        if not sol.residual <= self.residual_tol:
            raise ContactSolverError(
                f"{where}; reference residual {sol.residual:.3g} > tolerance {self.residual_tol:g}")
        warnings.warn(f"{why} at step {self._k} (t = {t:.6g}); "
                      f"fell back to the reference solver (residual {sol.residual:.3g})",
                      RuntimeWarning, stacklevel=3)
        if sol.residual > self.stats.max_residual:
            self.stats.max_residual = sol.residual
        return sol

    # -- the scheme ------------------------------------------------------------------------
    def predicted_active(self, k: int, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Closed set of the step k → k+1 (Siconos rule): ``g_k + (h/2)γ_k ≤ 0``, bool (m,)."""
        S, grid, half_h = self.S, self.grid, self._half_h
        g_pred = S.WT @ (q + half_h * u) + grid.nu[k] + half_h * grid.nu_dot[k]
        return g_pred <= 0.0

    def impulse(self, k: int, u: np.ndarray, u_free: np.ndarray,
                active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Impulse P of the step on ``active`` from u_k and the free velocity.

        Returns ``(P, Λ_C, Λ_E)``: Newton ``P = LCP(Ĝ, γ_free + e∘γ_k)`` (Λ_C, Λ_E empty);
        Poisson :func:`observer.impact.poisson_step` (Glocker's law with Ĝ on
        ``γ̃ = (γ_free + ε∘γ_k)/(1+ε)``; Λ_C, Λ_E its compression and expansion impulses).
        γ_k = W_Aᵀu_k + ν̇_A(t_k), γ_free = W_Aᵀu_free + ν̇_A(t_{k+1}).
        """
        W_A, _, Ghat, _, _, _, e_A = self._active_slices(active)
        nu_dot = self.grid.nu_dot
        gamma_k = u @ W_A + nu_dot[k, active]
        gamma_free = u_free @ W_A + nu_dot[k + 1, active]
        return self.law.definition.step_map(Ghat, gamma_free, gamma_k, e_A, self._solve)

    def last_free_velocity(self, k: int, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """:meth:`free_velocity` of step k from (q, u): the one the last :meth:`step` computed when
        it was that step from these very arrays (unchanged since), else computed anew."""
        last = self._last_free
        if last is not None and last[0] == k and last[1] is q and last[2] is u:
            return last[3]
        return self.free_velocity(k, q, u)

    def free_velocity(self, k: int, q: np.ndarray, u: np.ndarray) -> np.ndarray:
        """u_free of step k (no contact impulse)."""
        S = self.S
        if S.band is None:
            return S.Bu @ u + S.Bq @ q + S.Bf @ self.grid.fbar[k]
        return S.band.free_velocity(S.h, q, u, self.grid.fbar[k])

    def step(self, k: int, q: np.ndarray, u: np.ndarray, active: np.ndarray,
             project: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """Advance one step on the closed set ``active`` (index array).

        Returns ``(q_{k+1}, u_{k+1}, P_A, Σ_A)``: the impulse of the step on the active
        contacts, and, when ``project`` is true, the multiplier ``Σ_A = −L_A⁻¹ g_A⁻`` of the
        K-metric projection (eq. (14)); otherwise ``None``.
        """
        self._k = k
        h, theta = self.S.h, self.S.theta
        u_free = self.free_velocity(k, q, u)
        self._last_free = (k, q, u, u_free)
        if active.size == 0:
            u1 = u_free
            P = np.zeros(0)
        else:
            if not np.isfinite(u_free).all():
                raise NonFiniteState(f"free velocity of step {k} is not finite")
            P = self.impulse(k, u, u_free, active)[0]
            u1 = u_free + self._active_slices(active)[1] @ P
        q1 = q + h * ((1.0 - theta) * u + theta * u1)
        sigma = None
        if project:
            q1, sigma = self.project(k + 1, q1, active)
        return q1, u1, P, sigma

    def project(self, k: int, q: np.ndarray, active: np.ndarray, stacks: tuple | None = None,
                slot: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Projection of q onto ``{W_Iᵀq + ν_I(t_k) = 0}`` in the metric N (paper eqs. (13)-(14)).

        ``q⁺ = q − N⁻¹W_I L_I⁻¹ g_I`` with ``L_I = W_IᵀN⁻¹W_I``; returns (q⁺, Σ_I = −L_I⁻¹g_I).
        N is K, or the metric ``slot`` of ``stacks = ((N⁻¹W)ᵀ, WᵀN⁻¹W)`` stacked over metrics
        (:func:`observer.engines.loop.projection_slots`). Computed by the compiled kernel's own
        projection (:func:`observer.primitives.project_closed`): one implementation for both engines.
        """
        from observer.primitives import OK, project_closed

        if active.size == 0:
            return q, np.zeros(0)
        if self.S.factored:
            return self._project_factored(k, q, active, stacks)
        if stacks is None:
            if self.S.L is None:
                self.system.require_definite_stiffness("the position projection (position jumps)")
            stacks, slot = self._k_stacks, 0
        Wp, Wi, Wv = self.csc
        status, q1, sigma = project_closed(np.ascontiguousarray(q, dtype=np.float64), int(k),
                                           np.ascontiguousarray(active, dtype=np.int64), Wp, Wi, Wv,
                                           self.grid.nu, stacks[0], stacks[1], int(slot))
        if status != OK:
            self.system.require_definite_stiffness("the position projection (position jumps)")
            raise InputError("system.W", f"W_IᵀN⁻¹W_I is not positive definite at step {k - 1} "
                             f"(t = {float(self.time(k - 1)):.6g}): the closed contacts' columns "
                             "of W are dependent in the projection metric")
        return q1, sigma

    def _project_factored(self, k: int, q: np.ndarray, active: np.ndarray, stacks) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`project` with factored contact data: the K metric only, ``K⁻¹W_I`` and L_I from
        the banded factor of K (O(n·bw·|I|), :meth:`_factored_slices`)."""
        if stacks is not None:
            raise InputError("observers", "a projection metric other than K needs the dense contact data "
                             f"(n < {FACTORED_MIN_N}); this system has n = {self.system.n}")
        _, _, _, _, KinvW_A, L_A, _ = self._active_slices(active)
        if KinvW_A is None:
            self.system.require_definite_stiffness("the position projection (position jumps)")
        g = self.S.WT[active] @ q + self.grid.nu[k, active]
        try:
            sigma = -sla.cho_solve(sla.cho_factor(L_A), g)
        except np.linalg.LinAlgError:
            raise InputError("system.W", f"W_IᵀK⁻¹W_I is not positive definite at step {k - 1}: the closed "
                             "contacts' columns of W are dependent in the K metric") from None
        return q + KinvW_A @ sigma, sigma

    @cached_property
    def csc(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """W in the kernel's CSC storage (:func:`observer.primitives.csc_arrays`)."""
        from observer.primitives import csc_arrays

        if sp.issparse(self.S.W):
            W = sp.csc_matrix(self.S.W, dtype=np.float64, copy=True)
            W.eliminate_zeros()
            W.sort_indices()
            return (W.indptr.astype(np.int64), W.indices.astype(np.int64), np.ascontiguousarray(W.data))
        return csc_arrays(self.S.W)

    @cached_property
    def _k_stacks(self) -> tuple[np.ndarray, np.ndarray]:
        """``((K⁻¹W)ᵀ, WᵀK⁻¹W)`` as one-metric stacks (the kernel's layout)."""
        return (np.ascontiguousarray(self.S.KinvW.T)[None], np.ascontiguousarray(self.S.L)[None])
