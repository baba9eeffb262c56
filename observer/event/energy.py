"""A non-explosive, certified norm for the event engine's accumulated state error (issue 34).

The error ``e = x_exact − x_float`` of a linear flow obeys ``e' = A e`` (the forcing is affine:
it does not act on e). Carried componentwise through ``|exp(A dt)|`` its bound grows like
``exp(‖|A|‖ t)`` even for a conservative oscillation; carried as a scalar in an energy norm
``‖e‖_P = sqrt(eᵀPe)`` it grows like ``exp(μ_P t)`` with μ_P the flow's logarithmic norm in
P, which is ≤ 0 for ``P = blkdiag(K, M)`` and a damping C ⪰ 0 (``d/dt ‖e‖²_P = −2 e_uᵀ C e_u``).
For a singular or soft K the position weight is ``K + αM`` (α > 0, see :func:`energy_matrix`):
then ``μ_P ≤ √α/2``. Every quantity here is a *proved* bound in floating point:

* :func:`certify_positive_definite`: Rump's Cholesky test (``observer.sparse.verification_shift``)
  of a float matrix, widened by a Frobenius bound of the matrix's own computation error;
* :func:`log_norm_bound`: μ with ``μP − sym(PA) ⪰ 0`` (then ``‖exp(A t)‖_P ≤ exp(μ t)``);
* :func:`dual_norm_bound`: b with ``[[b, rᵀ], [r, P]] ⪰ 0``, i.e. ``rᵀP⁻¹r ≤ b``, so that
  ``|r·e| ≤ sqrt(b)·‖e‖_P``;
* :func:`p_norm_bound`: ``‖w‖_P ≤ sqrt(|w|ᵀ|P||w|)`` for a componentwise rounding bound w.

Scalings are by powers of two (exact).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla

from observer.event.enclosures import gamma
from observer.sparse import verification_shift

_U = 2.0 ** -53
_MARGINS = (1e-12, 1e-9, 1e-6, 1e-3, 1e-1, 1.0, 10.0)


def _dense(A) -> np.ndarray:
    return np.asarray(A.toarray() if hasattr(A, "toarray") else A, dtype=float)


def _pow2_scale(d: np.ndarray) -> np.ndarray:
    """Powers of two near ``1/sqrt(d)`` (1 where d is not positive and finite)."""
    ok = np.isfinite(d) & (d > 0.0)
    e = np.where(ok, np.round(-0.5 * np.log2(np.where(ok, d, 1.0))), 0.0)
    return np.ldexp(1.0, e.astype(int))


def certify_positive_definite(S: np.ndarray, err: np.ndarray | None = None) -> bool:
    """Whether every symmetric matrix within ``err`` (entrywise) of the float matrix S is
    positive definite, proved: S is scaled by powers of two D to a unit-ish diagonal, and
    the floating-point Cholesky factorization of ``fl(DSD − c·I)`` must run to completion with
    ``c = verification_shift(n − 1, max diag) + 1.01·‖D·err·D‖_F`` (Rump 2006; a dense matrix
    is a band of width n − 1; Weyl: ``λ_min(S + E) ≥ λ_min(S) − ‖E‖_F``). The lower triangle
    of S is taken as its upper one's mirror (exactly symmetric); their difference joins err."""
    S = np.triu(S) + np.triu(S, 1).T if not np.array_equal(S, S.T) else S
    n = S.shape[0]
    if n == 0 or not np.all(np.isfinite(S)) or not np.all(np.diag(S) > 0.0):
        return False
    d = _pow2_scale(np.diag(S))
    Ss = S * d[:, None] * d[None, :]
    c = verification_shift(max(n - 1, 1), float(np.max(np.diag(Ss))))
    if err is not None:
        c += 1.01 * float(np.linalg.norm(err * d[:, None] * d[None, :]))
    try:
        np.linalg.cholesky(Ss - c * np.eye(n))
    except np.linalg.LinAlgError:
        return False
    return True


def energy_matrix(M, K, alpha: float) -> np.ndarray:
    """``P = blkdiag(sym(K) + αM, M)`` when its position block is proved positive definite,
    else ``blkdiag(αM, M)`` (any positive definite P gives a norm; the growth rate
    :func:`log_norm_bound` is certified for whichever P is used)."""
    M, K = _dense(M), _dense(K)
    n = M.shape[0]
    Ks = np.triu(K) + np.triu(K, 1).T
    Pq = Ks + alpha * M
    # the rounding of Ks + αM and the asymmetry of K are part of the *chosen* P (Pq is the
    # float matrix), no error term: P is any SPD matrix; only its definiteness is proved
    if not certify_positive_definite(Pq):
        Pq = alpha * M
    P = np.zeros((2 * n, 2 * n))
    P[:n, :n], P[n:, n:] = Pq, M
    return np.triu(P) + np.triu(P, 1).T      # exactly symmetric (a norm's Gram matrix)


def log_norm_bound(P: np.ndarray, A: np.ndarray) -> float:
    """A proved upper bound μ of the logarithmic norm of A in ``‖·‖_P``: ``μP − H ⪰ 0`` for
    ``H = (PA + AᵀP)/2``, certified by :func:`certify_positive_definite` with the rounding of
    ``fl(PA)`` (``γ_k|P||A|``, Higham §3.5), of its symmetrization and of ``fl(μP − H)``
    (``γ_3(|μP| + |H|)``) as the error. Then ``‖exp(A t)‖_P ≤ exp(μ t)`` for t ≥ 0.
    ``inf`` when no margin in :data:`_MARGINS` certifies."""
    k = A.shape[0]
    PA = P @ A
    H = 0.5 * (PA + PA.T)
    absPA = np.abs(P) @ np.abs(A)
    e_h = gamma(k + 2) * 0.5 * (absPA + absPA.T) + _U * np.abs(H)
    try:
        lam = float(sla.eigh(H, P, eigvals_only=True)[-1])
    except (np.linalg.LinAlgError, ValueError):
        return math.inf
    d = _pow2_scale(np.diag(P))
    scale = float(np.linalg.norm(H * d[:, None] * d[None, :]))
    for rho in _MARGINS:
        mu = lam + rho * (abs(lam) + scale)
        S = mu * P - H
        err = e_h * 1.01 + gamma(3) * (abs(mu) * np.abs(P) + np.abs(H))
        if certify_positive_definite(S, err):
            return float(np.nextafter(mu, np.inf))
    return math.inf


def dual_norm_bound(P: np.ndarray, r: np.ndarray) -> float:
    """A proved upper bound of ``‖r‖_{P⁻¹} = sqrt(rᵀP⁻¹r)``: the float b for which the
    bordered float matrix ``[[b, rᵀ], [r, P]]`` is proved positive definite (its Schur
    complement ``b − rᵀP⁻¹r`` is then positive), b the computed value raised by a margin.
    ``inf`` when none certifies."""
    r = np.asarray(r, dtype=float)
    if not np.any(r):
        return 0.0
    try:
        b0 = float(r @ np.linalg.solve(P, r))
    except np.linalg.LinAlgError:
        return math.inf
    k = r.size
    B = np.zeros((k + 1, k + 1))
    B[1:, 1:], B[0, 1:], B[1:, 0] = P, r, r
    for rho in _MARGINS:
        B[0, 0] = abs(b0) * (1.0 + rho) + rho * float(np.max(np.abs(r))) ** 2 / float(np.max(np.diag(P)))
        if certify_positive_definite(B):
            return float(np.nextafter(np.nextafter(math.sqrt(B[0, 0]), np.inf), np.inf))
    return math.inf


def p_norm_gamma(k: int) -> float:
    """γ of the float ``wᵀ(|P|w)`` of :func:`p_norm_bound` for k components: its k² terms
    are nonnegative, each through at most ``k`` roundings of the inner sum, one product and
    ``k − 1`` of the outer sum (Higham §3.1): ``γ_{2k+1}``."""
    return gamma(2 * k + 1)


def p_norm_bound(absP: np.ndarray, w: np.ndarray) -> float:
    """An upper bound of ``‖δ‖_P`` for every δ with ``|δ| ≤ w``: ``sqrt(wᵀ|P|w)`` (its terms
    are nonnegative: the float sum is within :func:`p_norm_gamma` of the exact one), raised."""
    s = float(w @ (absP @ w)) * (1.0 + p_norm_gamma(w.size))
    return float(np.nextafter(np.nextafter(math.sqrt(s), np.inf), np.inf))


class EnergyCarry:
    """The scalar bound ε of a run's accumulated state error in ``‖·‖_P``,
    ``P = energy_matrix(M, K, α)`` with ``α = 1/T²`` for the run's duration T (a weight of
    the norm, no tolerance: every α gives a proved bound; with it the free growth rate is
    at most ``√α/2 = 1/(2T)``, a factor ``e^{1/2}`` over the run, and a velocity error δu
    reaches the gaps as ``‖r‖_{P⁻¹}·‖δu‖_M ≈ T·|δu|``, its true effect over the run).

    * :meth:`flight`: ``ε ← exp(μ dt)·ε + ‖w‖_P``, μ = :func:`log_norm_bound` of the
      flow's mechanical block (cached per contact set), w the flight's componentwise rounding;
    * :meth:`jump`: an impact's velocity map is M-non-expansive on velocities when it is
      averaged — Newton's law with one e ∈ [0, 1] on the impacted set,
      ``u⁺ = (1+e)·Π_C(u) − e·u`` with Π_C the M-projection onto ``{Wᵀu ≥ 0}`` (a convex
      cone, shifted by the gaps' own velocities: ``2Π_C − I`` is non-expansive, and ``u⁺``
      is its average with I); Poisson's with one ε, ``u⁺ = Π_C((1+ε)Π_C(u) − ε·u)`` (its
      compression ``Λ_C`` makes ``Π_C(u)``, its expansion LCP is again the M-projection onto
      C: a composition of non-expansive maps); P's velocity block is M, positions do not jump: ``ε`` is kept
      and the jump's rounding added; any other jump sets ε = inf (no bound claimed);
    * :meth:`through`: ``|r·e| ≤ ‖r‖_{P⁻¹}·ε`` per row (:func:`dual_norm_bound`, cached).

    The scope is the componentwise bound's (``_Run.carry_error``): the propagator and the
    impulses as computed are the flow's and the law's.
    """

    def __init__(self, system, duration: float) -> None:
        T = float(duration)
        inv = 1.0 / T if np.isfinite(T) and T > 0.0 else 1.0
        alpha = min(max(inv * inv, 1e-300), 1e300)   # any α > 0 gives a proved bound
        self.n = system.n
        M = _dense(system.M)
        self.P = energy_matrix(M, system.K, alpha)
        self.absP = np.abs(self.P)
        self.valid = certify_positive_definite(self.P)
        self.m_symmetric = bool(np.array_equal(M, M.T))
        self.eps = 0.0 if self.valid else math.inf
        self._rates: dict[tuple, float] = {}
        self._dual: dict[bytes, np.ndarray] = {}

    def rate(self, flow) -> float:
        """The proved growth rate μ of ``‖exp(A t)‖_P`` for the flow's mechanical block."""
        key = tuple(flow.active)
        if key not in self._rates:
            k = 2 * self.n
            A = np.asarray(flow.A[:k, :k], dtype=float)
            self._rates[key] = log_norm_bound(self.P, A) if np.all(np.isfinite(A)) else math.inf
        return self._rates[key]

    def flight(self, flow, dt: float, w: np.ndarray) -> None:
        """Carry ε over a flight of dt along flow; w bounds the flight's new rounding."""
        if not math.isfinite(self.eps):
            return
        x = self.rate(flow) * dt
        growth = math.exp(x) * (1.0 + 4.0 * _U) if x < 700.0 else math.inf
        self.eps = (self.eps * growth + p_norm_bound(self.absP, w)) * (1.0 + 4.0 * _U)

    def after(self, flow, dt: float, w: np.ndarray, eps: float | None = None) -> float:
        """The ε a flight of dt along flow with new rounding w would give (:meth:`flight`)
        from ε = ``eps`` (default the run's), which is left unchanged."""
        eps = self.eps if eps is None else eps
        if not (math.isfinite(eps) and self.valid):
            return math.inf
        x = self.rate(flow) * dt
        growth = math.exp(x) * (1.0 + 4.0 * _U) if x < 700.0 else math.inf
        return (eps * growth + p_norm_bound(self.absP, w)) * (1.0 + 4.0 * _U)

    def jump(self, averaged: bool, w: np.ndarray) -> None:
        """Carry ε through an impact (see the class); w bounds the jump's rounding."""
        if not (averaged and self.m_symmetric):
            self.eps = math.inf
        if math.isfinite(self.eps):
            self.eps = (self.eps + p_norm_bound(self.absP, w)) * (1.0 + 4.0 * _U)

    def shift(self, w: np.ndarray) -> None:
        """Add a move of the state bounded componentwise by w to ε (a move of the float
        state within the data's error, not through the law's map)."""
        if math.isfinite(self.eps):
            self.eps = (self.eps + p_norm_bound(self.absP, w)) * (1.0 + 4.0 * _U)

    def through(self, rows: np.ndarray, eps: float | None = None) -> np.ndarray:
        """``‖r‖_{P⁻¹}·ε`` for every row r (inf where no bound is proved); ``eps``: another ε
        (:meth:`after`) than the run's."""
        eps = self.eps if eps is None else eps
        if not math.isfinite(eps):
            return np.full(rows.shape[0], math.inf)
        key = rows.tobytes()
        dual = self._dual.get(key)
        if dual is None:
            dual = self._dual[key] = np.array([dual_norm_bound(self.P, r) for r in rows])
        with np.errstate(invalid="ignore"):
            out = dual * eps * (1.0 + 4.0 * _U)
        return np.where(np.isnan(out), math.inf, out)
