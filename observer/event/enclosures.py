"""Three-valued sign decisions from rigorous enclosures (issue 34: no scale heuristics).

A decision of the event engine — is a gap, a contact velocity or a contact force positive,
negative or zero — is taken on an enclosure ``[lower, upper]`` of the exact quantity:
certainly positive (``lower > 0``), certainly negative (``upper < 0``), exactly zero (the
enclosure is the point 0), or undecided. The quantities are linear functionals ``r·z`` of
an augmented state z (paper eqs. (2)-(3)), or of the exact flow ``r·exp(As)z`` from z, with
r, A, z and s float64 data taken as exact (the state the engine carries is the exact
initial state of the next piece of the flow).

The float64 evaluation with its certified error bound is the first try
(:func:`dot_sign`; the Taylor model of :meth:`observer.event.roots.FunctionalSet.enclose`
for a flow; for the sticking LCP, :func:`stick_decisions`' float64 balls). Where it
cannot decide, the same quantity is evaluated from the same data in ball arithmetic
(python-flint ``arb``/``arb_mat``) at :data:`PRECISION_START` bits, the precision doubled
until decided or :data:`PRECISION_CAP`; never by widening a tolerance. What is still
undecided at the cap is returned as such, with its enclosure (:attr:`Decision.note`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import flint
import numpy as np
from numba import njit

from observer.event.kernels import JIT

PRECISION_START = 128
"""Bits of the first ball-arithmetic evaluation after float64 could not decide."""

PRECISION_CAP = 4096
"""Largest precision (bits) tried. A dot product of float64 data is exact at it when its
nonzero products ``r_i z_i`` span fewer than about 3990 binary orders of magnitude (each
product has 106 bits; arb rounds a sum only beyond the working precision) — every state
short of mixing subnormals with values near overflow — so, in practice, only a quantity of
the flow, ``r·exp(As)z``, stays undecided at the cap."""

_U = np.finfo(float).eps / 2.0


@dataclass(frozen=True)
class Decision:
    """A three-valued sign with its enclosure.

    Attributes
    ----------
    sign : int or None
        ``+1`` certainly positive, ``-1`` certainly negative, ``0`` exactly zero, ``None``
        undecided at :data:`PRECISION_CAP`.
    lower, upper : float
        Enclosure of the exact value (floats rounded outwards).
    bits : int
        Precision that decided (53: the float64 path).
    """

    sign: int | None
    lower: float
    upper: float
    bits: int

    @property
    def note(self) -> str:
        """Empty when decided, else the undecided enclosure and the precision reached."""
        if self.sign is not None:
            return ""
        return (f"undecided: sign of a value in [{self.lower:.17g}, {self.upper:.17g}] "
                f"at {self.bits} bits")


def gamma(n: int) -> float:
    """γ_n = n·u/(1 − n·u) (Higham, *Accuracy and Stability*, §3.1)."""
    return n * _U / (1.0 - n * _U)


def dot_error(row: np.ndarray, z: np.ndarray) -> float:
    """Certified bound of ``|fl(row·z) − row·z|`` for float64 data of length N:
    ``Σ|r_j z_j|·γ_{N+1}·(1 + 2γ_{N+1}) + N·2^-1074`` (Higham §3.1; the factor dominates the
    rounding of the bound itself, the last term underflow)."""
    r = np.asarray(row, dtype=float).ravel()
    g = gamma(r.size + 1)
    return float(np.abs(r) @ np.abs(np.asarray(z, dtype=float).ravel())) * g * (1.0 + 2.0 * g) \
        + r.size * 5e-324


def represented_error(rows: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Certified distance of each ``fl(r_i·z)`` to the exact ``r_i·z_exact`` of a float state z
    that represents z_exact to u per component (relative): ``(1 + 2γ_{N+1})(γ_{N+1} + u)·Σ_j|r_ij z_j|``
    (the evaluation and the representation; within it no precision tells the value from zero,
    z being known to no better)."""
    g = gamma(np.asarray(z).size + 1)
    return (1.0 + 2.0 * g) * (g + _U) * (np.abs(rows) @ np.abs(z))


def representation_error(rows: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The resolution of the data ``r_i·z`` beyond its evaluation: a float state z (and
    float rows) known to their own representation, u per component, leave ``r_i·z`` known
    to ``u·Σ_j|r_ij z_j|``, raised by ``1 + 2γ_{N+1}`` to dominate the rounding of the bound
    (the representation part of :func:`represented_error`)."""
    g = gamma(np.asarray(z).size + 1)
    return (1.0 + 2.0 * g) * _U * (np.abs(rows) @ np.abs(z))


def dot_sign(row: np.ndarray, z: np.ndarray) -> Decision:
    """Sign of the exact dot product ``row·z`` of float64 data.

    Float64 first: ``|fl(r·z) − r·z| ≤ γ_N Σ|r_i z_i|`` (Higham §3.1), raised by ``1 + 2γ_N``
    to dominate the rounding of the bound, plus N·2^-1074 for underflow; decided when 0 lies
    outside ``fl(r·z) ± bound``. Else :func:`arb_dot` at doubling precision (exact for
    float64 data at :data:`PRECISION_CAP` but for extreme exponent ranges: a zero ball of
    radius 0 is then a certain zero)."""
    r = np.asarray(row, dtype=float).ravel()
    v = np.asarray(z, dtype=float).ravel()
    N = r.size
    val = float(r @ v)
    mag = float(np.abs(r) @ np.abs(v))
    if np.isfinite(val) and np.isfinite(mag):
        err = dot_error(r, v)
        if val - err > 0.0:
            return Decision(1, val - err, val + err, 53)
        if val + err < 0.0:
            return Decision(-1, val - err, val + err, 53)
        if mag == 0.0:
            return Decision(0, 0.0, 0.0, 53)
    return _refine(lambda: arb_dot(r, v))


def arb_dot(row, z) -> flint.arb:
    """``row·z`` in ball arithmetic at the current precision (``flint.ctx.prec``)."""
    s = flint.arb(0)
    for a, b in zip(np.asarray(row, dtype=float).tolist(), np.asarray(z, dtype=float).tolist()):
        if a != 0.0 and b != 0.0:
            s += flint.arb(a) * flint.arb(b)
    return s


def flow_sign(A: np.ndarray, row: np.ndarray, z: np.ndarray, s: float, k: int = 0,
              start: int = PRECISION_START) -> Decision:
    """Sign of ``ψ^{(k)}(s) = row·A^k·exp(A s)·z``, the functional ``row`` (k-th derivative) of
    the exact flow ż = Az from z after the time s (float64 data taken as exact), in ball
    arithmetic from ``start`` bits, doubled until decided or :data:`PRECISION_CAP`."""
    return _refine(lambda: flow_value(A, row, z, s, k), start)


def flow_value(A: np.ndarray, row: np.ndarray, z: np.ndarray, s: float, k: int = 0) -> flint.arb:
    """Ball enclosure of ``row·A^k·exp(A s)·z`` at the current precision (``flint.ctx.prec``):
    ``arb_mat.exp`` is rigorous, and only the block of A that the functional depends on
    (:func:`coupled`) is exponentiated (``r·exp(As)z = r_S·exp(A_SS s)z_S``)."""
    A = np.asarray(A, dtype=float)
    r = np.asarray(row, dtype=float).ravel()
    v = np.asarray(z, dtype=float).ravel()
    keep = np.flatnonzero(coupled(A, r != 0.0))
    Aa = flint.arb_mat(A[np.ix_(keep, keep)].tolist())
    w = (Aa * flint.arb(float(s))).exp() * flint.arb_mat([[b] for b in v[keep].tolist()])
    for _ in range(int(k)):
        w = Aa * w
    return sum((flint.arb(a) * w[i, 0] for i, a in enumerate(r[keep].tolist()) if a != 0.0),
               flint.arb(0))


def coupled(A: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Boolean mask of the closure of ``seed`` (a mask of components) under the sparsity of
    A: l joins when ``A[j, l] ≠ 0`` for some j already in (the components that the
    functionals supported on ``seed`` and all their derivatives ``r A^k`` depend on)."""
    nz = np.asarray(A) != 0.0
    mask = np.asarray(seed, dtype=bool).copy()
    while True:
        grown = mask | nz[mask].any(axis=0)
        if np.array_equal(grown, mask):
            return mask
        mask = grown


def _refine(value, start: int = PRECISION_START) -> Decision:
    """Evaluate ``value()`` (an arb) at ``start`` bits, doubled until its sign is decided or
    :data:`PRECISION_CAP` is passed."""
    bits = max(int(start), 2)
    x = None
    while bits <= PRECISION_CAP:
        with flint.ctx.workprec(bits):
            x = value()
            if x.is_zero():
                return Decision(0, 0.0, 0.0, bits)
            lo, hi = _outward(x)
            if x > 0:
                return Decision(1, lo, hi, bits)
            if x < 0:
                return Decision(-1, lo, hi, bits)
        bits *= 2
    lo, hi = _outward(x)
    return Decision(None, lo, hi, bits // 2)


def _outward(x: flint.arb) -> tuple[float, float]:
    """Float bounds of the ball x, rounded outwards (arf → float may round either way)."""
    lo, hi = float(x.lower()), float(x.upper())
    return float(np.nextafter(lo, -np.inf)), float(np.nextafter(hi, np.inf))


def polish_lcp(M: np.ndarray, W: np.ndarray, b: np.ndarray, x: np.ndarray,
               start: int = PRECISION_START, cache: dict | None = None) -> np.ndarray | None:
    """The solution of the LCP ``0 ≤ Gλ + b ⊥ λ ≥ 0``, ``G = Wᵀ M⁻¹ W`` (the Delassus matrix
    of paper eq. (5), formed exactly from the system's data M, W, not from its float64
    product), on the active set of the float64 solution ``x`` (``S = {x > 0}``), solved in
    ball arithmetic and rounded to float64 (ball midpoints), or None when it does not
    certify: a component of λ_S not certainly positive, or ``(Gλ + b)_i`` of an inactive i
    certainly negative, at :data:`PRECISION_CAP`.

    Why: the float64 solve of a symmetric multi-contact impact (a bar landing flat on two
    supports, a plate on three legs) returns impulses that differ in their last bits, and
    the body starts to rotate by round-off (issue 34, item 3). The exact solution of
    exactly symmetric data is symmetric, and its rounding too: equal exact values round to
    the same float, so a symmetry of the data survives every impact. ``cache``: a dict kept
    by the caller for one (M, W), holding the exact G per precision (a constant of the
    system's contact set)."""
    S = [i for i, v in enumerate(np.asarray(x, dtype=float).tolist()) if v > 0.0]
    if not S:
        return np.zeros(len(x))
    R = [i for i in range(len(x)) if i not in S]
    bits = max(int(start), 2)
    while bits <= PRECISION_CAP:
        with flint.ctx.workprec(bits):
            G = exact_delassus(M, W, bits, cache)
            ba = [flint.arb(v) for v in np.asarray(b, dtype=float).tolist()]
            lam = flint.arb_mat([[G[i, j] for j in S] for i in S]).solve(
                flint.arb_mat([[-ba[i]] for i in S]))
            ok = all(lam[k, 0] > 0 for k in range(len(S)))
            w_ok = all(not (sum((G[i, j] * lam[k, 0] for k, j in enumerate(S)), ba[i]) < 0)
                       for i in R)
            if ok and w_ok:
                out = np.zeros(len(x))
                for k, i in enumerate(S):
                    out[i] = float(lam[k, 0].mid())
                return out
        bits *= 2
    return None


def exact_delassus(M: np.ndarray, W: np.ndarray, bits: int, cache: dict | None = None):
    """``Wᵀ M⁻¹ W`` as an ``arb_mat`` at the current precision, from the float64 data M, W
    (exact), kept in ``cache`` per precision (a constant of the system's contact set)."""
    G = None if cache is None else cache.get(bits)
    if G is None:
        Ma = flint.arb_mat(np.asarray(M, dtype=float).tolist())
        Wa = flint.arb_mat(np.asarray(W, dtype=float).tolist())
        G = Wa.transpose() * Ma.solve(Wa)
        if cache is not None:
            cache[bits] = G
    return G


def _free_accelerations(vrows, A, z):
    """``r_v·A·z`` as an ``arb_mat`` column at the current precision, exact from the float
    data (the same for every active set tried)."""
    Az = flint.arb_mat(np.asarray(A, dtype=float).tolist()) * \
        flint.arb_mat([[v] for v in np.asarray(z, dtype=float).tolist()])
    return flint.arb_mat(np.asarray(vrows, dtype=float).tolist()) * Az


def _stick_balls(G, V, radius, S, R):
    """(λ_S, w_R, w_R of radius 0) in ball arithmetic at the current precision: ``b = V``
    (:func:`_free_accelerations`) widened by ``radius``; ``λ_S = −G_SS⁻¹ b_S``,
    ``w_R = G_RS λ_S + b_R``; None when G_SS is not certainly invertible."""
    out = []
    for rad in (radius, np.zeros(len(radius))):
        b = [V[i, 0] + flint.arb(0, float(r)) if r > 0.0 else V[i, 0]
             for i, r in enumerate(np.asarray(rad, dtype=float).tolist())]
        try:
            lam = flint.arb_mat([[G[i, j] for j in S] for i in S]).solve(
                flint.arb_mat([[-b[i]] for i in S])) if S else None
        except ZeroDivisionError:
            return None
        lam_S = [lam[k, 0] for k in range(len(S))] if S else []
        w_R = [sum((G[i, j] * lam_S[k] for k, j in enumerate(S)), b[i]) for i in R]
        out.append((lam_S, w_R))
    return out[0][0], out[0][1], out[1][1]


def _stick_status(balls, S, R, bits):
    """(status, lift, notes) of the active set S from its balls: status ``1`` certified
    (every λ_S > 0, every w_R ≥ 0 or exactly 0 on the exact float state), ``-1`` refuted
    (some λ_S or w_R certainly negative: not the LCP's active set), ``0`` undecided."""
    lam_S, w_R, w_exact = balls
    if any(v < 0 for v in lam_S) or any(v < 0 for v in w_R):
        return -1, set(), {}
    notes, lift = {}, set()
    for k, i in enumerate(S):
        if not lam_S[k] > 0:
            lo, hi = _outward(lam_S[k])
            notes[i] = f"undecided stick: force in [{lo:.17g}, {hi:.17g}] at {bits} bits"
    for k, i in enumerate(R):
        if w_R[k] > 0:
            lift.add(i)
        elif not (w_exact[k].is_zero() or w_R[k] >= 0):
            lo, hi = _outward(w_R[k])
            notes[i] = (f"undecided stick: relative acceleration in [{lo:.17g}, {hi:.17g}] "
                        f"at {bits} bits")
    return (0 if notes else 1), lift, notes


def _active_sets(lam) -> list[list[int]]:
    """The float64 solution's active set first, then (up to 10 contacts) every other one."""
    n = len(lam)
    first = [i for i, v in enumerate(np.asarray(lam, dtype=float).tolist()) if v > 0.0]
    if n > 10:
        return [first]
    others = [[i for i in range(n) if k >> i & 1] for k in range(2 ** n)]
    return [first] + [S for S in others if S != first]


_UP = 1.0 + 2.0 ** -20
"""Factor raising a float64 bound of nonnegative terms over the rounding of its own
evaluation (a few γ_n of n < 2^20 terms) and over arb's radius arithmetic (``mag_t``, 30
bits, rounded up: a relative 2^-28 per operation at most)."""

_TINY = 64 * 5e-324
"""An absolute term of a float64 bound covering underflow (multiples of 2^-1074)."""

_LU_ROWS = 7
"""Largest active set of the float64 try of :func:`stick_decisions` (arb's classical LU)."""

_PIVOT_PATHS = 64
"""Most pivot sequences of arb's LU followed by the float64 try of :func:`stick_decisions`
(beyond: declined)."""


def _up(x: float) -> float:
    """An upper bound of a nonnegative expression evaluated in float64 (:data:`_UP`, and
    underflow)."""
    return x * _UP + _TINY


def _mat_bound(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``fl(A @ B)`` and a certified entrywise bound of its distance to the exact product
    (Higham §3.1, as :func:`dot_error`, raised by :data:`_UP`)."""
    g = gamma(A.shape[-1] + 1)
    return A @ B, (np.abs(A) @ np.abs(B)) * (g * (1.0 + 2.0 * g) * _UP) + A.shape[-1] * _TINY


def _float_delassus(M: np.ndarray, W: np.ndarray, cache: dict | None = None):
    """Balls ``(G, E)`` (arrays): float64 ``G ≈ Wᵀ M⁻¹ W`` with a certified
    entrywise bound E of ``|Wᵀ M⁻¹ W − G|`` (M, W float data taken as exact, the matrix of
    :func:`exact_delassus`), or None when not certified. With ``R ≈ M⁻¹``,
    ``C = I − R M`` (α ≥ ‖C‖_∞ < 1/2 bounded), ``X = fl(R W)``, the residual
    ``ρ = W − M X``: ``M⁻¹W − X = (I − C)⁻¹ R ρ``, so ``|M⁻¹W − X| ≤ T + α·max_col T/(1 − α)``
    with ``T = |R||ρ|`` (entrywise upper); then ``G = Wᵀ(X + D)``. Kept in ``cache`` under
    ``"float64"``."""
    if cache is not None and "float64" in cache:
        return cache["float64"]
    M, W = np.asarray(M, dtype=float), np.asarray(W, dtype=float)
    out = None
    with np.errstate(all="ignore"):
        try:
            R = np.linalg.inv(M)
        except np.linalg.LinAlgError:
            R = None
        if R is not None and np.all(np.isfinite(R)):
            RM, e_rm = _mat_bound(R, M)
            C = np.abs(np.eye(len(M)) - RM) * (1.0 + 2.0 * _U) + e_rm
            alpha = _up(float(np.max(C.sum(axis=1))))
            X, _ = _mat_bound(R, W)
            MX, e_mx = _mat_bound(M, X)
            rho = np.abs(W - MX) * (1.0 + 2.0 * _U) + e_mx
            T = _mat_bound(np.abs(R), rho)[0] * _UP + _TINY
            D = _up(1.0) * (T + alpha * T.max(axis=0) / (1.0 - alpha))
            G, e_g = _mat_bound(W.T, X)
            E = e_g + _mat_bound(np.abs(W.T), D)[0] * _UP + _TINY
            E = E * _UP + _TINY
            if alpha < 0.5 and np.all(np.isfinite(G)) and np.all(np.isfinite(E)):
                out = (np.ascontiguousarray(G), E)
    if cache is not None:
        cache["float64"] = out
    return out


# Midpoint-radius balls (m, r) in float64, compiled. Each operation's radius covers the exact
# result for every point of the operands' balls (Rump's midpoint-radius bounds, the
# midpoint's own rounding 2u|m|) and, evaluated with the majorants |m| + 2r of arb's
# midpoints, arb's radius of the same operation on balls of radius ≤ r around the same exact
# values (arb_add, arb_mul, arb_addmul, arb_div; see _stick_fast).

@njit(**JIT)
def _b_add(xm, xr, ym, yr):  # pragma: no cover - compiled (numba); covered through _stick_fast
    m = xm + ym
    return m, (xr + yr) * _UP + _TINY + 2.0 * _U * abs(m)


@njit(**JIT)
def _b_mul(xm, xr, ym, yr):  # pragma: no cover - compiled (numba)
    m = xm * ym
    r = (abs(xm) + 2.0 * xr) * yr + (abs(ym) + 2.0 * yr) * xr + xr * yr
    return m, r * _UP + _TINY + 2.0 * _U * abs(m)


@njit(**JIT)
def _b_div(xm, xr, ym, yr):  # pragma: no cover - compiled (numba)
    """Radius inf when ``|m_y| ≤ 3 r_y`` (arb's divisor might hold 0). arb_div's radius is
    ``(|x| r_y + |y| r_x)/(|y|(|y| − r_y))``, or on its fast path that with ``|y|²`` below,
    raised by ``1 + 2^-16``: hence the factor ``1 + 2^-14``."""
    ay = abs(ym)
    if not ay > 3.0 * yr:
        return 0.0, np.inf
    m = xm / ym
    num = (abs(xm) + 2.0 * xr) * yr + (ay + 2.0 * yr) * xr
    den = (ay - 2.0 * yr) * (ay - 3.0 * yr)
    return m, num / den * (1.0 + 2.0 ** -14) * _UP + _TINY + 2.0 * _U * abs(m)


@njit(**JIT)
def _ball_pivot(Am, Ar, c, k):  # pragma: no cover - compiled (numba)
    """(row, count): the k-th (in row order) of the ``count`` rows that
    arb_mat_find_pivot_partial may pick at column c on arb's balls (it takes the largest
    |midpoint| among the entries whose ball excludes 0): every row j with
    ``|m_j| + 2r_j ≥ t``, t the largest ``|m_i| − 2r_i`` of a certainly nonzero entry
    (``|m_i| > 3r_i``); row −1 when none is."""
    n = Am.shape[0]
    t = -np.inf
    for i in range(c, n):
        if abs(Am[i, c]) > 3.0 * Ar[i, c]:
            t = max(t, abs(Am[i, c]) - 2.0 * Ar[i, c])
    row, count = -1, 0
    if t == -np.inf:
        return row, count
    for j in range(c, n):
        if abs(Am[j, c]) + 2.0 * Ar[j, c] >= t:
            if count == k:
                row = j
            count += 1
    return row, count


@njit(**JIT)
def _ball_lu(Am, Ar, P, choice, count):  # pragma: no cover - compiled (numba)
    """arb_mat_lu_classical's steps (partial pivoting, in place: L below the diagonal, U on
    and above, the row permutation in P) on balls, the pivot of column c the
    ``choice[c]``-th that arb may pick (their number into ``count[c]``); False when none is
    certainly nonzero."""
    n = Am.shape[0]
    for c in range(n):
        p, count[c] = _ball_pivot(Am, Ar, c, choice[c])
        if p < 0:
            return False
        for k in range(n):
            Am[c, k], Am[p, k] = Am[p, k], Am[c, k]
            Ar[c, k], Ar[p, k] = Ar[p, k], Ar[c, k]
        P[c], P[p] = P[p], P[c]
        for j in range(c + 1, n):
            em, er = _b_div(Am[j, c], Ar[j, c], Am[c, c], Ar[c, c])
            for k in range(c + 1, n):
                pm, pr = _b_mul(-em, er, Am[c, k], Ar[c, k])
                Am[j, k], Ar[j, k] = _b_add(Am[j, k], Ar[j, k], pm, pr)
            Am[j, c], Ar[j, c] = em, er
    return True


@njit(**JIT)
def _ball_certify(Gm, Gr, bm, br, S, R, choice, count):  # pragma: no cover - compiled
    """True when the balls of the arb path's steps at 128 bits (arb_mat_solve for n ≤ 7:
    arb_mat_lu_classical, then arb_mat_solve_lu_precomp's substitutions on ``−b_S``; then
    ``w_i = b_i + Σ_k G_ik λ_k`` in order), along the pivots ``choice`` (:func:`_ball_lu`),
    all have ``m > 3r``, from balls (Gm, Gr) of G and (bm, br) of b; False otherwise."""
    s = S.size
    Am, Ar = np.empty((s, s)), np.empty((s, s))
    for i in range(s):
        for j in range(s):
            Am[i, j], Ar[i, j] = Gm[S[i], S[j]], Gr[S[i], S[j]]
    P = np.arange(s)
    if not _ball_lu(Am, Ar, P, choice, count):
        return False
    xm, xr = np.empty(s), np.empty(s)
    for i in range(s):
        xm[i], xr[i] = -bm[S[P[i]]], br[S[P[i]]]
    for i in range(1, s):
        for j in range(i):
            pm, pr = _b_mul(-Am[i, j], Ar[i, j], xm[j], xr[j])
            xm[i], xr[i] = _b_add(xm[i], xr[i], pm, pr)
    for i in range(s - 1, -1, -1):
        for j in range(i + 1, s):
            pm, pr = _b_mul(-Am[i, j], Ar[i, j], xm[j], xr[j])
            xm[i], xr[i] = _b_add(xm[i], xr[i], pm, pr)
        xm[i], xr[i] = _b_div(xm[i], xr[i], Am[i, i], Ar[i, i])
        if not xm[i] > 3.0 * xr[i]:
            return False
    for i in R:
        wm, wr = bm[i], br[i]
        for k in range(s):
            pm, pr = _b_mul(Gm[i, S[k]], Gr[i, S[k]], xm[k], xr[k])
            wm, wr = _b_add(wm, wr, pm, pr)
        if not wm > 3.0 * wr:
            return False
    return True


@njit(**JIT)
def _free_balls(V, A, z, radius, g):  # pragma: no cover - compiled (numba)
    """Balls (bm, br) of ``b = r_v·A·z`` (exact from the float data) widened by ``radius`` (as
    arb's ``arb(0, r)``, its radius rounded up to 30 bits, then added):
    ``|fl(V fl(Az)) − V A z| ≤ (2γ + γ²)|V||A||z|`` (γ = γ_{N+1}, Higham §3.1, in any
    summation order) plus the underflow of both products."""
    N = z.size
    eta = N * _TINY
    Az, Aza = np.zeros(N), np.zeros(N)
    for i in range(N):
        for j in range(N):
            Az[i] += A[i, j] * z[j]
            Aza[i] += abs(A[i, j]) * abs(z[j])
    m = V.shape[0]
    bm, br = np.zeros(m), np.zeros(m)
    for i in range(m):
        e = 0.0
        for j in range(N):
            bm[i] += V[i, j] * Az[j]
            e += abs(V[i, j]) * (Aza[j] * (g * (2.0 + 3.0 * g)) + eta)
        br[i] = (e + eta) * _UP + radius[i] * (1.0 + 2.0 ** -26)
    return bm, br


@njit(**JIT)
def _stick_certify(Gm, Gr, V, A, z, radius, x, g):  # pragma: no cover - compiled (numba)
    """:func:`_ball_certify` on the active set ``S = {x > 0}`` of the float64 solution x, the
    balls of b from :func:`_free_balls`, along every sequence of pivots arb may take (an
    exact tie of |G| entries is two; at most :data:`_PIVOT_PATHS` sequences): True when all
    certify. A non-finite value fails (an infinite midpoint has an infinite radius, NaN
    compares false)."""
    bm, br = _free_balls(V, A, z, radius, g)
    S, R = np.flatnonzero(x > 0.0), np.flatnonzero(~(x > 0.0))
    choice, count = np.zeros(S.size, np.int64), np.zeros(S.size, np.int64)
    for _ in range(_PIVOT_PATHS):
        if not _ball_certify(Gm, Gr, bm, br, S, R, choice, count):
            return False
        c = S.size - 1
        while c >= 0 and choice[c] + 1 >= count[c]:
            c -= 1
        if c < 0:
            return True
        choice[c] += 1
        choice[c + 1:] = 0
    return False


def _stick_fast(M, W, vrows, A, z, radius, lam, cache=None):
    """The float64 first try of :func:`stick_decisions`: its answer ``(keep, {})`` when the
    float64 solution's active set S certainly has every λ_S > 0 and every w_R > 0 for every
    b in the ball, else None (the arb path decides).

    The balls of λ_S and w_R are those of the arb path's own steps at
    :data:`PRECISION_START` bits (:func:`_ball_certify`; flint's arb_mat_solve takes
    arb_mat_solve_lu there for n < 13, arb_mat_lu_classical for n < 8, hence
    :data:`_LU_ROWS`) in float64 midpoint-radius arithmetic, from certified balls of G
    (:func:`_float_delassus`) and b (:func:`_free_balls`): they contain the exact values
    (rigorous), and their radii dominate arb's (each operation's radius bound is monotone
    in the operands' radii and midpoints' magnitudes, evaluated on majorants of arb's; G's
    and b's float64 error bounds, of the order of float64's rounding, dominate arb's
    128-bit radii). Then arb's midpoint lies within 2r of ours and its radius is ≤ r, so
    ``m > 3r`` for every ball means arb's balls are certainly positive too: the arb path
    would certify S at its first precision, lift every contact of R (w > 0) and keep S,
    with no notes — the same answer."""
    x = np.asarray(lam, dtype=float)
    n = x.size
    if int(np.count_nonzero(x > 0.0)) > _LU_ROWS:
        return None
    balls = _float_delassus(M, W, cache) if x.max(initial=0.0) > 0.0 else \
        (np.zeros((n, n)), np.zeros((n, n)))
    if balls is None:
        return None
    zf = np.asarray(z, dtype=float)
    if _stick_certify(balls[0], balls[1], np.asarray(vrows, dtype=float),
                      np.asarray(A, dtype=float), zf, np.asarray(radius, dtype=float), x,
                      gamma(zf.size + 1)):
        return (x > 0.0).tolist(), {}
    return None


def stick_decisions(M, W, vrows, A, z, radius, lam, cache: dict | None = None,
                    start: int = PRECISION_START) -> tuple[list[bool], dict[int, str]]:
    """Which contacts of a candidate set stay closed under the acceleration LCP
    ``0 ≤ λ ⊥ w = Gλ + b ≥ 0`` (``G = Wᵀ M⁻¹ W`` exact, ``b = r_v·A·z`` exact from the float
    data, widened by ``radius``), three-valued; see
    :meth:`observer.event.master._Run.sticking`.

    An active set S (the float64 solution's ``{lam > 0}`` first, then the others) is
    certified when every ``λ_S = −G_SS⁻¹ b_S`` is certainly positive and every
    ``w_R = G_RS λ_S + b_R`` (R the rest) certainly ≥ 0 or exactly 0 on the exact float
    state, for every b in the ball: then S solves the LCP for all of them (G a P-matrix:
    the solution is unique), k ∈ S keeps a positive force (kept), i ∈ R with w_i > 0 lifts
    off, i ∈ R with w_i exactly 0 on the float state (identically closed: no force, no
    relative acceleration, structurally — the state error alone cannot lift it) is kept.
    A set with a λ or w certainly negative is refuted (not the LCP's). Precision is
    doubled up to :data:`PRECISION_CAP`. Returns the keep flags and, when nothing
    certified, the first undecided set's notes (its contacts with an enclosure holding 0,
    kept: a w not certainly positive).

    Float64 first (``_stick_fast``): where the float64 solution's active set has every
    λ_S and every w_R certainly positive in float64 ball arithmetic whose balls dominate
    arb's, its answer is the arb path's and arb is not called; anything else (a w exactly 0
    on the float state, a sign not certain, another active set, ``start`` other than
    :data:`PRECISION_START`) is decided by the arb path."""
    if int(start) == PRECISION_START:
        fast = _stick_fast(M, W, vrows, A, z, radius, lam, cache)
        if fast is not None:
            return fast
    return _stick_arb(M, W, vrows, A, z, radius, lam, cache, start)


def _stick_arb(M, W, vrows, A, z, radius, lam, cache: dict | None = None,
               start: int = PRECISION_START) -> tuple[list[bool], dict[int, str]]:
    """The ball-arithmetic path of :func:`stick_decisions` (its docstring), from ``start``
    bits."""
    n = len(lam)
    bits, fallback = max(int(start), 2), None
    while bits <= PRECISION_CAP:
        with flint.ctx.workprec(bits):
            G = exact_delassus(M, W, bits, cache)
            V = _free_accelerations(vrows, A, z)
            for S in _active_sets(lam):
                R = [i for i in range(n) if i not in S]
                balls = _stick_balls(G, V, radius, S, R)
                if balls is None:
                    continue
                status, lift, notes = _stick_status(balls, S, R, bits)
                if status == 1:
                    return [i not in lift for i in range(n)], {}
                if status == 0:
                    fallback = (lift, notes)
                    break
        bits *= 2
    lift, notes = fallback if fallback is not None else (set(), {
        i: "undecided stick: no active set certified" for i in range(n)})
    return [i not in lift for i in range(n)], notes
