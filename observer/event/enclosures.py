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
for a flow). Where it cannot decide, the same quantity is evaluated from the same data in
ball arithmetic (python-flint ``arb``/``arb_mat``) at :data:`PRECISION_START` bits, the
precision doubled until decided or :data:`PRECISION_CAP`; never by widening a tolerance.
What is still undecided at the cap is returned as such, with its enclosure
(:attr:`Decision.note`).
"""

from __future__ import annotations

from dataclasses import dataclass

import flint
import numpy as np

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
    kept: a w not certainly positive)."""
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
