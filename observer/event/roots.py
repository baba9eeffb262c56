"""Certified isolation of the first zero of linear functionals ψ_i(t) = r_i·z(t) of an exact flow.

The gaps g_i (paper eq. (2)) and the persistent-contact forces λ_i of a
:class:`~observer.event.flow.Flow` are linear functionals of the augmented state z, and so
are all their time derivatives: ``ψ_i^{(k)}(t) = r_i A^k z(t)``. On a window
``[a, a + w]`` with ``‖T⁻¹AT‖ w ≤`` :data:`WINDOW` (T the balancing similarity of A),

    |ψ_i'''(a + s)| ≤ B_i := ‖r_i A³ T‖ · exp(‖T⁻¹AT‖ w) · ‖T⁻¹ z(a)‖,

so the cubic ``L_i(s) = ψ_i(a) + ψ_i'(a)s + ψ_i''(a)s²/2 − B_i s³/6`` is a lower bound of
ψ_i(a + s) on the window (Taylor with Lagrange remainder). Advancing a to the first
positive zero of ``min_i L_i`` can never step over a zero of any ψ_i: a transversal zero
is approached monotonically from the safe side, at the rate of Newton's method.

The window, B_i and the growth factors are those of the block of A the functionals depend
on (the closure S of their support under the sparsity of A, :meth:`FunctionalSet._coupled`):
a mode no functional sees (an unconnected spring of any frequency) changes none of them.

Every sign decision is three-valued (issue 34, :mod:`observer.event.enclosures`): ψ_i(a),
ψ_i'(a), ψ_i''(a) certainly positive, certainly negative, exactly zero or undecided, from
the float64 value and its certified error (:meth:`FunctionalSet.errors`) and, where that
cannot decide, from the same data in ball arithmetic. A functional not certainly positive
at a is at a zero unless it is leaving (ψ' > 0, or ψ' = 0 exactly and ψ'' > 0); no
tolerance widens "zero". A certainly positive, approaching functional that safe steps cannot
approach (its value within :data:`STALLED_STATE` certified errors: the float state rounds
back to it) has its zero certified in a bracket and refined from the fixed state.

A double root (grazing: ψ_i touches zero with ψ_i' = 0) cannot be certified either way in
floating point; when the minimum of ψ_i lies in a window on which ψ_i'' > 0 is certified
(``ψ_i''(a) − B_i s > 0``), ψ_i has exactly one local minimum t_m there, found as the
simple zero of ψ_i'. A certified enclosure ``[lower, upper]`` of its value (a Taylor model
with Lagrange remainder and the curvature bound, :func:`minimum_decision`; ball arithmetic
where float64 cannot place it) decides against the touch band δ of ψ_i (:func:`graze_band`,
the stated band of a graze: what the data do not decide about the minimum — the float64
evaluation error of ψ_i there, the run's accumulated state error carried to t_m and the
data's own representation in the user's coordinates, each a certified bound; no time scale,
no count of round-offs): ``lower > δ``, the whole convex window is certified positive;
``upper < −δ``, a **cross** before t_m, isolated by the bracket ``[a, t_m]``; otherwise a
**touch** (graze) at t_m. The guaranteed crossing depth is δ* = δ + (upper − lower): a
deeper minimum is always a cross.

Zeros are refined by safeguarded Newton steps (bisection when a step leaves the bracket)
until the step is below the time resolution :func:`time_resolution` (two ulp of t, no time
scale). A search interval no longer than it is integrated as flow and not searched; zeros
closer than it are taken by their time to zero (and noted when float64 cannot order them).
"""

from __future__ import annotations

from collections import OrderedDict
import math
from dataclasses import dataclass

import numpy as np

from numba import njit

from observer.event import kernels
from observer.event.energy import p_norm_gamma
from observer.event.enclosures import (PRECISION_CAP, PRECISION_START, Decision, coupled, dot_sign,
                                       flow_sign, flow_value, gamma, representation_error)
from observer.event.flow import Flow, exp_upper, norm_upper, spectral_norm_upper, up

WINDOW = 0.5
"""Window length in units of ``1/‖T⁻¹AT‖``: the growth factor of z over a window is ≤ e^0.5."""

TIME_RTOL = 2.0 * np.finfo(float).eps
"""Time resolution ``TIME_RTOL · |t|`` (:func:`time_resolution`): Newton refinement stops at
it, and a search interval no longer than it is integrated as a flow, not searched (a
remainder of a few ulp)."""

TAYLOR_ORDER = 16
"""Degree + 1 of the Taylor model of a functional in :func:`FunctionalSet.enclose`: its
Lagrange remainder over a window (``‖T⁻¹AT‖ s ≤`` :data:`WINDOW`) is at most
``e^0.5·0.5^16/16! ≈ 1.2e-17`` of ``‖r T‖‖T⁻¹z‖``, below round-off."""

_U = np.finfo(float).eps / 2.0
_TINY = np.finfo(float).tiny
"""Unit round-off u. The certified bounds use proved upper bounds of their norms, not
estimates: ``‖T⁻¹AT‖₂`` by Gershgorin in ball arithmetic (:attr:`Flow.certified_norm`),
vector norms with outward rounding (:func:`~observer.event.flow.norm_upper`), ``e^x`` in
ball arithmetic (:func:`~observer.event.flow.exp_upper`); a product of n rounded
non-negative factors is raised by ``(1 + (n + 1)u)`` and one ulp. T is a diagonal of powers
of two (``scipy.linalg.matrix_balance``), so ``r T`` and ``T⁻¹z`` are exact floats (gradual
underflow, below 1e-308, aside)."""

MAX_STEPS = 200_000
"""Safe advances per search before :class:`RootIsolationError` (a stalled isolation)."""


class RootIsolationError(RuntimeError):
    """The safe advance stalled (more than :data:`MAX_STEPS` steps in one search).

    Attributes
    ----------
    t_ok, z_ok : float or None, ndarray or None
        How far the search got: every functional is certified nonzero on ``[t0, t_ok)``
        and ``z_ok`` is the augmented state there (None when unknown), so that a stalled
        run keeps the trajectory up to it.
    """

    def __init__(self, message: str, t_ok: float | None = None, z_ok: np.ndarray | None = None) -> None:
        super().__init__(message)
        self.t_ok, self.z_ok = t_ok, z_ok


STOP_EVERY = 64
"""Safe advances of a search between two looks at its ``should_stop`` (:func:`first_zero`; the
first look after the first advances, so a stopped search always got past its start)."""


class SearchStopped(RootIsolationError):
    """A signal stopped a search (:func:`first_zero` with ``should_stop``): every functional
    is certified nonzero on ``[t0, t_ok)``, so the trajectory up to there is whole.

    Attributes
    ----------
    signal : str
        What ``should_stop`` returned (``"SIGINT"``, ...).
    """

    def __init__(self, signal: str, t_ok: float, z_ok: np.ndarray) -> None:
        super().__init__(f"{signal} during the search, at t = {t_ok!r}", t_ok, z_ok)
        self.signal = signal


class NonFiniteFlow(RootIsolationError):
    """The flow left the floating-point range during a search (issue 20: a stop, never a row).

    Attributes
    ----------
    t : float
        Where the augmented state ``z``, or a derivative of a functional the isolation needs,
        is first not finite.
    t_ok, z_ok : float, ndarray
        The last search point where everything was finite (``t_ok ≤ t``) and its state.
    what : tuple
        ``("state", i)`` for the entry i of z, ``("derivative", k, i)`` for the k-th
        derivative of functional i, ``("bound", 3, i)`` for the certified bound on the third
        derivative of functional i over the search window (the search cannot proceed).
    value : float
        The non-finite value.
    """

    def __init__(self, t: float, t_ok: float, z_ok: np.ndarray, what: tuple, value: float) -> None:
        super().__init__(f"non-finite flow at t = {t!r}", t_ok, z_ok)
        self.t, self.what, self.value = t, what, value


def _check_finite(a: float, za: np.ndarray, d: np.ndarray, t_ok: float, z_ok: np.ndarray) -> None:
    """Raise :class:`NonFiniteFlow` unless the state ``za`` and the derivatives ``d`` at ``a``
    are finite (one vectorised test; the names only on failure)."""
    if np.isfinite(za).all() and np.isfinite(d).all():
        return
    bad = np.flatnonzero(~np.isfinite(za))
    if bad.size:
        raise NonFiniteFlow(a, t_ok, z_ok, ("state", int(bad[0])), float(za[bad[0]]))
    k, i = (int(v[0]) for v in np.nonzero(~np.isfinite(d)))
    raise NonFiniteFlow(a, a, za, ("derivative", k, i), float(d[k, i]))   # the state is finite


@dataclass
class Zero:
    """The first zero of one functional.

    Attributes
    ----------
    t : float
        Time of the zero (``cross``) or of the minimum (``touch``).
    index : int
        Row of the functional.
    kind : {"cross", "touch"}
        ``cross``: ψ_i becomes negative at t; ``touch``: ψ_i has a local minimum at t whose
        value is zero within round-off (a double root: grazing).
    z : ndarray
        Augmented state at t.
    value, slope : float
        ψ_i(t) and ψ_i'(t).
    resume : float
        For a touch, a time after which ψ_i is certified to exceed its round-off again
        (ψ_i is convex in between); t for a cross.
    band : float
        For a touch, the touch band it was decided with (:func:`graze_band`).
    enclosure : tuple
        For a touch, ``(lower, upper)``: the certified enclosure of the minimum's value
        (:func:`minimum_enclosure`); the guaranteed crossing depth there is
        ``band + upper − lower``.
    note : str
        Empty, or how a decision that float64 cannot take was taken (``"unresolved: …"``).
    carried : tuple
        ``(err, eps)``: the search's own accumulated rounding at t (:meth:`SearchCarry.at`),
        componentwise and in the energy norm, for the run to add to its carried error.
    band_data : float
        For a touch, the data's part of ``band`` (:func:`graze_band_parts`: the state's
        distance to the exact trajectory of the data and the data's resolution).
    """

    t: float
    index: int
    kind: str
    z: np.ndarray
    value: float
    slope: float
    resume: float
    band: float = 0.0
    note: str = ""
    enclosure: tuple = ()
    carried: tuple = ()
    band_data: float = 0.0


def first_cubic_zero(d0: float, d1: float, d2: float, bound: float, width: float) -> float:
    """A safe step: s ≤ the first s in (0, width] where ``L(s) = d0 + d1 s + d2 s²/2 − bound s³/6``
    reaches 0 (width if L stays positive), within a relative 1e-13 below it.

    ``d0 ≥ 0`` is assumed (a leaving functional at zero: d0 = 0 with L increasing first).
    L is split at its critical points into monotone pieces; the first piece whose end is
    not positive holds the zero, isolated by regula falsi keeping ``L(lo) > 0``
    (:func:`_cubic_zero`, compiled: the same float64 operations in the same order).
    """
    width = float(width)
    return float(_cubic_zero(float(d0), float(d1), float(d2), float(bound), width, width ** 3))


@njit(cache=True, error_model="numpy", nogil=True)
def _cubic_zero(d0: float, d1: float, d2: float, bound: float, width: float, width3: float
                ) -> float:  # pragma: no cover - compiled (numba); covered through its wrapper
    """Compiled body of :func:`first_cubic_zero` (``width3 = width ** 3``, Python's pow): a hot
    loop (tens of thousands of calls per run, ~15 regula falsi steps each), so one function
    over the pieces of L and no Python-level dispatch; IEEE operations only (no fast-math,
    no contraction), so results are those of the Python arithmetic bit for bit."""
    m1 = d1 if not 0.0 < d1 else 0.0                  # Python's min(d1, 0.0)
    m2 = d2 if not 0.0 < d2 else 0.0
    if d0 + m1 * width + m2 * width * width / 2 - bound * width3 / 6 > 0.0:
        return width
    a3, a2, a1 = -bound / 6.0, d2 / 2.0, d1
    # critical points: roots of 3·a3 x² + 2·a2 x + a1 (numerically stable form)
    A, B, C = 3.0 * a3, 2.0 * a2, a1
    r0, r1, nr = 0.0, 0.0, 0
    if A == 0.0:
        if B != 0.0:
            r0, nr = -C / B, 1
    else:
        disc = B * B - 4.0 * A * C
        if not disc < 0.0:
            q = -0.5 * (B + np.copysign(np.sqrt(disc), B))
            if q != 0.0:
                r0, r1, nr = q / A, C / q, 2
            else:
                r0, nr = 0.0, 1
    c0, c1, nc = 0.0, 0.0, 0
    for k in range(nr):
        c = r0 if k == 0 else r1
        if 0.0 < c < width:
            if nc == 0:
                c0 = c
            else:
                c1 = c
            nc += 1
    if nc == 2 and c1 < c0:                          # sorted(crit)
        c0, c1 = c1, c0
    lo = 0.0
    for k in range(nc + 1):
        hi = c0 if k == 0 and nc > 0 else (c1 if k == 1 and nc > 1 else width)
        f_hi = ((a3 * hi + a2) * hi + a1) * hi + d0
        if f_hi <= 0.0:
            f_lo = ((a3 * lo + a2) * lo + a1) * lo + d0
            return _illinois_cubic(a3, a2, a1, d0, lo, hi, f_lo, f_hi)
        lo = hi
    return width


@njit(cache=True, error_model="numpy", nogil=True)
def _illinois_cubic(a3: float, a2: float, a1: float, d0: float, lo: float, hi: float, f_lo: float,
                    f_hi: float) -> float:  # pragma: no cover - compiled (numba)
    """Regula falsi (Illinois variant) on a monotone piece of ``L(x) = ((a3 x + a2) x + a1) x
    + d0`` with ``L(lo) ≥ 0 ≥ L(hi)``; returns the left end ``lo`` (L(lo) > 0 kept, or lo = the
    start) once ``hi − lo ≤ 1e-13·hi``. Compiled: the inner loop of :func:`_cubic_zero`."""
    side = 0
    for _ in range(200):
        if hi - lo <= 1e-13 * hi:
            break
        x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo) if f_hi != f_lo else 0.5 * (lo + hi)
        if not (lo < x and x < hi):
            x = 0.5 * (lo + hi)
        fx = ((a3 * x + a2) * x + a1) * x + d0
        if fx > 0.0:
            lo, f_lo = x, fx
            if side == -1:
                f_hi *= 0.5
            side = -1
        else:
            hi, f_hi = x, fx
            if side == 1:
                f_lo *= 0.5
            side = 1
    return lo


class FunctionalSet:
    """The functionals ``rows`` of ``flow``, their derivative rows ``r_k = r A^k`` and a
    certified bound on the float64 error of each derivative row.

    The rows ``r̂_k`` are computed in float64; ``err[k] ≥ |r̂_k − r A^k|`` entrywise by the
    a-priori bound of a matrix product (Higham, *Accuracy and Stability*, §3.5):
    ``err_{k+1} = (err_k + γ_N |r̂_k|) |A|``, γ_N = N·u/(1 − N·u), times ``1 + 2γ_N`` to
    dominate the rounding of the bound itself (a sum of non-negative terms). The value
    ``ψ^{(k)} = r̂_k·z`` of a float state z is then known to ``e_k(z) = (err_k + γ_N
    |r̂_k|)·|z|`` (:meth:`errors`), likewise inflated.
    """

    def __init__(self, flow: Flow, rows: np.ndarray) -> None:
        self.flow = flow
        self.rows = np.atleast_2d(np.asarray(rows, dtype=float))
        N = self.rows.shape[1]
        u = np.finfo(float).eps / 2.0
        self.gamma = N * u / (1.0 - N * u)
        self._inflate = 1.0 + 2.0 * self.gamma
        self._absA = np.abs(flow.A)
        self.d = [self.rows]
        self.err = [np.zeros_like(self.rows)]
        self._coupled(flow)
        self._extend(3)
        third = (np.abs(self.d[3]) + self.err[3]) * flow.scale   # ≥ |r_3 T| entrywise
        self.third_norm = np.array([_row_norm(r) for r in third])
        self.abs_d = [np.abs(r) for r in self.d[:3]]
        # per-step rows (:meth:`derivatives`, :meth:`sums`) as 3-D stacks: the derivative rows r̂_0..r̂_3,
        # then |r̂_0..2| (floors) and err_k + γ_N|r̂_k| (errors). A stacked matmul computes each
        # slice as its own matrix-vector product (bit-identical to ``rows_k @ z``; a 2-D
        # ``vstack`` is not: BLAS blocks the rows differently)
        self._d4 = np.stack(self.d[:4])
        self._abs_rows = np.stack(self.abs_d + [self._ecoef(k) for k in range(3)])

    def _coupled(self, flow: Flow) -> None:
        """The block of the flow the functionals depend on (:func:`observer.event.enclosures.coupled`:
        the closure S of their support under the sparsity of A, so that ``A[S, S^c] = 0`` and
        ``r A^k exp(As) z = r_S A_SS^k exp(A_SS s) z_S`` exactly), and its norms: the window
        ``WINDOW/norm_bound`` and the growth factors of the certified bounds are those of the
        block, not of modes the functionals do not see (an unconnected spring of 1e6 rad/s
        must not shrink the windows of a ball's gap). ``support``: indices of S;
        ``norm_bound``: ``‖T_S⁻¹A_SS T_S‖₂`` (float64); :attr:`certified_norm`: a proved
        upper bound of it, cached per flow and block."""
        mask = coupled(flow.A, np.any(self.rows != 0.0, axis=0))
        self.support = np.flatnonzero(mask)
        self._full = bool(mask.all())
        self._screen_support = np.arange(flow.N) if self._full else self.support   # screen()
        if self._full:
            self.norm_bound = flow.norm_bound
        else:
            S = self.support
            self.norm_bound = float(np.linalg.norm(flow._balanced[np.ix_(S, S)], 2))

    @property
    def certified_norm(self) -> float:
        """A proved upper bound of ``‖T_S⁻¹A_SS T_S‖₂`` (:func:`~observer.event.flow.spectral_norm_upper`
        on the coupled block; the flow's own when the block is everything)."""
        if self._full:
            return self.flow.certified_norm
        cache = self.flow.__dict__.setdefault("_block_norms", {})
        key = self.support.tobytes()
        hit = cache.get(key)
        if hit is None:
            S = self.support
            hit = cache[key] = spectral_norm_upper(self.flow.A[np.ix_(S, S)], self.flow.scale[S])
        return hit

    def state_norm(self, z: np.ndarray) -> float:
        """Proved upper bound of ``‖(T⁻¹z)_S‖₂`` (the coupled block's part of the state)."""
        sc = self.flow.scale
        return norm_upper(z / sc if self._full else z[self.support] / sc[self.support])

    def _ecoef(self, k: int) -> np.ndarray:
        """Rows ``err_k + γ_N |r̂_k|`` of the certified error of ``r̂_k·z`` (:meth:`errors`)."""
        return self.err[k] + self.gamma * np.abs(self.d[k])

    def derivatives(self, z: np.ndarray) -> np.ndarray:
        """``ψ^{(k)} = r̂_k·z`` for k = 0..3, all functionals, shape (4, p): one stacked product."""
        return self._d4 @ z

    def sums(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``Σ_j |r̂_kj z_j|`` (the representation floors) and the certified
        errors of :meth:`errors` (kmax = 2), k = 0..2, shape (3, p) each: one stacked product."""
        both = self._abs_rows @ np.abs(z)
        return both[:3], self._inflate * both[3:]

    def screen(self, z: np.ndarray, growth: float, w: float) -> tuple:
        """One safe step's evaluations at z over a window w (:func:`first_zero`): the
        derivatives ψ^{(k)}, k = 0..3 (:meth:`derivatives`), then, in one compiled call
        (:func:`observer.event.kernels.screen_step`, the same floats as the numpy expressions),
        whether z and they are finite, the certified errors e_0..2 (:meth:`sums`), the
        third-derivative bounds ``B_i`` (growth times :meth:`state_norm`) and whether they are
        finite, and the quick test of :func:`_safe_step`. Returns ``(d, finite, errs, bound,
        bound_finite, quick)``."""
        d = self._d4 @ z
        both = self._abs_rows @ np.abs(z)
        out = kernels.screen_step(d, both, z, self.flow.scale, self._screen_support, self._inflate,
                                  self.third_norm, float(growth), float(w), float(w) ** 3)
        return (d,) + out

    def _extend(self, k: int) -> None:
        """Derivative rows and their error bounds up to order k."""
        A = self.flow.A
        while len(self.d) <= k:
            prev, e = self.d[-1], self.err[-1]
            self.d.append(prev @ A)
            self.err.append(self._inflate * ((e + self.gamma * np.abs(prev)) @ self._absA))

    def __len__(self) -> int:
        return self.rows.shape[0]

    def value(self, i: int, k: int, z: np.ndarray) -> float:
        """k-th derivative of functional i at augmented state z."""
        return float(self.d[k][i] @ z)

    def errors(self, z: np.ndarray, kmax: int = 2) -> np.ndarray:
        """Certified bounds ``e_k ≥ |fl(r̂_k·z) − r_k·z|`` for k = 0..kmax, all functionals,
        shape (kmax + 1, p) (z taken as exact data; gradual underflow, below 1e-300, aside)."""
        self._extend(kmax)
        az = np.abs(z)
        return np.array([self._inflate * (self._ecoef(k) @ az) for k in range(kmax + 1)])

    def enclose(self, i: int, j: int, z: np.ndarray, s: float) -> tuple[float, float]:
        """Certified enclosure ``[lo, hi]`` of ``ψ_i^{(j)}(a + s)`` for the exact flow from the
        state z at a (``0 ≤ s``, ``‖T⁻¹AT‖ s ≤`` :data:`WINDOW`), by a Taylor model.

        ``ψ_i^{(j)}(a + s) = Σ_{k<K} r_{k+j}·z s^k/k! + R`` with K = :data:`TAYLOR_ORDER` and
        ``|R| ≤ ‖r_{K+j} T‖₂ e^{‖T⁻¹AT‖ s} ‖T⁻¹z‖₂ s^K/K!`` (Lagrange; ``T⁻¹e^{As}T =
        e^{Bs}``, ``‖e^{Bs}‖ ≤ e^{‖B‖s}``). The coefficients carry their certified errors
        (:meth:`errors`), the polynomial's evaluation its a-priori error γ_{3K}·Σ|terms|,
        and the sum of the bounds is doubled to dominate its own rounding.
        """
        K = TAYLOR_ORDER
        self._extend(K + j)
        flow = self.flow
        az = np.abs(z)
        val, mag, err, term = 0.0, 0.0, 0.0, 1.0
        for k in range(K):
            if k:
                term *= s / k
            c = float(self.d[k + j][i] @ z)
            ec = float((self.err[k + j][i] + self.gamma * np.abs(self.d[k + j][i])) @ az)
            val += c * term
            mag += abs(c) * term
            err += ec * term
        term *= s / K                  # s^K/K! to (1 + u)^{2K}: raised by (1 + (2K + 1)u)
        term = up(term * (1.0 + (2 * K + 1) * _U))
        rest = np.abs(self.d[K + j][i]) + self.err[K + j][i]
        growth = exp_upper(up(self.certified_norm * s * (1.0 + 2.0 * _U)))
        remainder = up(_row_norm(rest * flow.scale) * growth * self.state_norm(z)
                       * term * (1.0 + 5.0 * _U))
        u = np.finfo(float).eps / 2.0
        g3k = 3.0 * K * u / (1.0 - 3.0 * K * u)
        width = 2.0 * (err + g3k * mag + remainder) + np.finfo(float).tiny
        return val - width, val + width


FUNCTIONAL_SETS = 64
"""Functional sets kept per flow by :func:`functional_set` (least recently used dropped)."""


def functional_set(flow: Flow, rows: np.ndarray) -> FunctionalSet:
    """The :class:`FunctionalSet` of ``rows`` along ``flow``, built once per
    flow and reused by every search of the same functionals (a run searches the same gaps
    and forces of a contact set at every event): its derivative rows, their certified
    errors and the proved norms ``‖r_3 T‖`` are constants of the flow. Deterministic, so a
    reused set gives the same bits as a new one."""
    cache = flow.__dict__.setdefault("_functional_sets", OrderedDict())
    rows = np.ascontiguousarray(rows, dtype=float)
    key = (rows.shape, rows.tobytes())
    hit = cache.get(key)
    if hit is None:
        hit = cache[key] = FunctionalSet(flow, rows)
        if len(cache) > FUNCTIONAL_SETS:
            cache.popitem(last=False)
    else:
        cache.move_to_end(key)
    return hit


def time_resolution(t: float) -> float:
    """Time resolution of the search at t: ``TIME_RTOL·|t|`` (two ulp of t; the smallest
    normal float at t = 0): a time step below it does not move t. No time scale of the
    system enters (issue 34): a slow mode anywhere does not coarsen it."""
    return TIME_RTOL * max(abs(float(t)), _TINY)


def _refine(fs: FunctionalSet, i: int, k: int, a: float, za: np.ndarray, lo: float, hi: float,
            tau: float) -> float:
    """Zero of the k-th derivative of ψ_i on the bracket ``[lo, hi]`` (offsets from a), where
    ``ψ_i^{(k)}(lo) ≥ 0 ≥ ψ_i^{(k)}(hi)`` or the reverse; safeguarded Newton from ``tau``,
    stopped at the time resolution (:func:`time_resolution`)."""
    flow = fs.flow
    f_lo = fs.value(i, k, flow.expm(lo) @ za) if lo > 0 else fs.value(i, k, za)
    sign_lo = np.sign(f_lo)
    for _ in range(100):
        z = flow.expm(tau) @ za
        f = fs.value(i, k, z)
        df = fs.value(i, k + 1, z)
        if f == 0.0:
            return tau
        if np.sign(f) == sign_lo:
            lo = tau
        else:
            hi = tau
        step = -f / df if df != 0.0 else np.inf
        new = tau + step
        if not (lo < new < hi) or not np.isfinite(new):
            new = 0.5 * (lo + hi)
            step = new - tau
        tau = new
        res = time_resolution(a + tau)
        if abs(step) <= res or hi - lo <= res:
            return tau
    return tau


def _convex_minimum(fs: FunctionalSet, i: int, a: float, za: np.ndarray, d0: float, d1: float,
                    d2: float, bound: float, width: float, e2: float = 0.0, data=None):
    """Analyse functional i on a window where its minimum is near (d1 < 0 < d2; d1 = 0 for a
    functional not leaving a, :func:`_safe_step`: the minimum at a itself).

    Returns ``None`` when convexity cannot be certified on ``[a, a + 2s_m]`` (s_m = −d1/d2,
    within ``width``; ``curv = d2 − e2 − bound·2s_m > 0`` bounds ψ_i'' below on the span, e2
    the certified error of d2), else ``("positive", certified_until)``, ``("touch", Zero)``
    or ``("cross", Zero)``. ``data``: the data's part of the band (:func:`graze_band`).

    The decision is three-valued on a certified enclosure ``[lower, upper]`` of the minimum
    m of the exact flow from ``za`` (:func:`minimum_decision`: float64 first, ball arithmetic
    where float64 cannot decide) against the touch band δ of ψ_i (:func:`graze_band`):
    ``lower > δ`` a miss,
    ``upper < −δ`` a crossing, anything else a touch whose row states ``m* = ψ_i(t_m)``, δ
    and the enclosure. So a minimum deeper than ``δ* = δ + (upper − lower)`` is always a
    crossing.
    """
    s_m = -d1 / d2
    span = 2.0 * s_m
    curv = d2 - e2 - bound * span               # certified: ψ_i'' ≥ curv > 0 on the span
    if span > width or curv <= 0.0:
        return None
    flow = fs.flow
    tau_m = _refine(fs, i, 1, a, za, 0.0, span, s_m)
    z_m = flow.expm(tau_m) @ za
    m_star = fs.value(i, 0, z_m)
    parts = graze_band_parts(fs, i, z_m, a + tau_m, data)
    touch = parts[0] + parts[1]
    lower, upper, note = minimum_decision(fs, i, za, tau_m, span, curv, touch)
    if lower > touch:
        return "positive", a + span
    t_m = a + tau_m
    if upper >= -touch:
        z_m = _reset(flow, t_m, z_m)
        resume = _resume(fs, i, a, za, tau_m, d2 - e2, bound, width, touch)
        if resume is None:                      # not certified beyond the span: its end
            resume = float(min(t_m + np.sqrt(max(2.0 * (2.0 * touch - lower), 0.0) / curv), a + span))
        return "touch", Zero(t_m, i, "touch", z_m, m_star, fs.value(i, 1, z_m), resume,
                             band=touch, enclosure=(lower, upper), note=note, band_data=parts[1])
    tau = _refine(fs, i, 0, a, za, 0.0, tau_m, 0.5 * tau_m) if d0 > 0.0 else 0.0
    z = _reset(flow, a + tau, flow.expm(tau) @ za)
    return "cross", Zero(a + tau, i, "cross", z, fs.value(i, 0, z), fs.value(i, 1, z), a + tau)


def _resume(fs: FunctionalSet, i: int, a: float, za: np.ndarray, tau_m: float, d2_low: float,
            bound: float, width: float, band: float) -> float | None:
    """A time after the touch at ``a + tau_m`` from which on ψ_i is certified above
    ``2·band`` up to the end of a certified convex span (:func:`_convex_minimum`), or None
    when convexity cannot be certified that far.

    With ψ_i'' ≥ ``curv(S) = d2_low − bound·S > 0`` on ``[a, a + S]`` (d2_low the certified
    lower bound of ψ_i''(a), bound that of the third derivative on the window ``width``) and
    the enclosures ``ψ_i(a + tau_m) ≥ lo0``, ``|ψ_i'(a + tau_m)| ≤ s1``
    (:meth:`FunctionalSet.enclose`): ``ψ_i(a + tau_m + x) ≥ lo0 − s1·x + curv·x²/2``, above
    ``2·band`` for ``x ≥ x_r = (s1 + √(s1² + 2 curv (2·band − lo0)))/curv``. S starts at
    ``tau_m + x_r(d2_low)`` and doubles until ``tau_m + x_r(curv(S)) ≤ S``. The resume,
    ``a + tau_m + x_r`` rounded up, is strictly after the minimum: a touch whose minimum the
    float64 slope cannot place (``−d1/d2`` below the time resolution, or ``d1 = 0``) resumes
    the search after it, not at it (a resume capped at ``a + 2s_m`` equal to the touch's
    time took the same touch again: tests/observer/event/test_touch_resume.py)."""
    lo0, _ = fs.enclose(i, 0, za, tau_m)
    lo1, hi1 = fs.enclose(i, 1, za, tau_m)
    s1 = max(abs(lo1), abs(hi1))
    t_m = a + tau_m

    def reach(curv: float) -> float:
        disc = s1 * s1 + 2.0 * curv * (2.0 * band - lo0)
        return up(up(s1 + np.sqrt(max(disc, 0.0)), 2) / curv, 2)

    span = tau_m + reach(d2_low) if d2_low > 0.0 else np.inf
    while span <= width:
        curv = d2_low - bound * span
        if not curv > 0.0:
            return None
        need = reach(curv)
        if tau_m + need <= span:
            return float(max(up(t_m + need, 1), np.nextafter(t_m, np.inf)))
        span = 2.0 * (tau_m + need)
    return None


def graze_band(fs: FunctionalSet, i: int, z: np.ndarray, t: float = np.nan, data=None) -> float:
    """The touch (graze) band δ of functional i at its minimum, the state z at time t: what
    the data do not decide about ψ_i there, each part a certified bound (issue 34 item 1; no
    time scale and no count of round-offs):

    (a) the error ``e_0`` of the float64 evaluation of ψ_i at z
        (:meth:`FunctionalSet.errors`: a γ_N bound, Higham §3.5);
    (b) the distance of the search's state to the exact trajectory of the scenario's data,
        seen through the row: the accumulated state error of the run carried to t
        (``data``, :meth:`observer.event.master._Run.search_band`);
    (c) the resolution of the data in the user's coordinates: the state and the gap's data
        are floats known to their own representation, ``u·Σ_j|r_ij z_j|`` raised by
        ``1 + 2γ`` (:func:`~observer.event.enclosures.representation_error`), z taken in the
        coordinates the scenario was given in — the gap frame
        (:class:`observer.event.frame.GapFrame`) makes the gaps coordinates and a
        translation c disappear from the arithmetic, not from the data: there ψ_i is known
        to no better than ``u·|c|``, and a minimum within it is undecidable from the data.

    ``data(t, z)`` returns (b) + (c) for every functional (an array: :class:`SearchCarry`,
    the search's own accumulated error plus what the master gives); without it (b) is 0 and
    (c) is taken in the run's coordinates. A minimum certified above δ is a miss, below −δ a
    crossing (an impact, however shallow), otherwise a graze (paper eq. (2): a gap touching
    zero with zero relative velocity)."""
    floor, extra = graze_band_parts(fs, i, z, t, data)
    return floor + extra


def graze_band_parts(fs: FunctionalSet, i: int, z: np.ndarray, t: float = np.nan,
                     data=None) -> tuple[float, float]:
    """``(a, (b) + (c))`` of :func:`graze_band`: the float64 evaluation's part, and the data's
    (the state's distance to the exact trajectory of the data, and the data's resolution)."""
    floor = float(fs.errors(z, 0)[0, i])
    if data is None:
        extra = float(representation_error(fs.rows[i], z))
    else:
        extra = float(data(t, z)[i])
    return floor, extra


def minimum_decision(fs: FunctionalSet, i: int, za: np.ndarray, tau_m: float, span: float,
                     curv: float, band: float) -> tuple[float, float, str]:
    """Certified enclosure ``[lower, upper]`` of ``min ψ_i`` over ``[a, a + span]`` for the
    exact flow from ``za`` at a, where ``ψ_i'' ≥ curv > 0`` is certified, tight enough to
    place the minimum against ``±band`` (three-valued: above, below, or within).

    ``upper`` bounds ψ_i(a + tau_m) from above; convexity with the curvature bound gives
    ``ψ_i(a + s) ≥ ψ_i(a + tau_m) + ψ_i'(a + tau_m)(s − tau_m) + curv (s − tau_m)²/2 ≥
    ψ_i(a + tau_m) − ψ_i'(a + tau_m)²/(2 curv)`` (``lower``). Float64 first
    (:meth:`FunctionalSet.enclose`); where the enclosure meets ±band, ψ_i and ψ_i' at
    ``a + tau_m`` are re-evaluated in ball arithmetic (:func:`observer.event.enclosures.flow_value`)
    from :data:`~observer.event.enclosures.PRECISION_START` bits, doubled while the
    enclosure narrows, up to the cap. The note is empty when decided, else it states the
    enclosure and the precision reached."""
    lo0, hi0 = fs.enclose(i, 0, za, tau_m)
    lo1, hi1 = fs.enclose(i, 1, za, tau_m)
    lower, upper = _convex_bounds(lo0, hi0, lo1, hi1, curv)
    if lower > band or upper < -band or (lower >= -band and upper <= band):
        return lower, upper, ""
    import flint

    A, r = fs.flow.A, fs.rows[i]
    bits, width = PRECISION_START, upper - lower
    while bits <= PRECISION_CAP:
        with flint.ctx.workprec(bits):
            v0, v1 = flow_value(A, r, za, tau_m, 0), flow_value(A, r, za, tau_m, 1)
            b = [float(np.nextafter(float(x), w)) for x, w in
                 ((v0.lower(), -np.inf), (v0.upper(), np.inf), (v1.lower(), -np.inf),
                  (v1.upper(), np.inf))]
        lo, hi = _convex_bounds(*b, curv)
        lower, upper = max(lower, lo), min(upper, hi)
        if lower > band or upper < -band or (lower >= -band and upper <= band):
            return lower, upper, ""
        if upper - lower >= 0.5 * width:          # no longer narrowing: the time resolution
            break
        width, bits = upper - lower, 2 * bits
    return lower, upper, (f"undecided: minimum in [{lower:.17g}, {upper:.17g}] at {bits} bits "
                          f"against the band ±{band:.3g}")


def _convex_bounds(lo0: float, hi0: float, lo1: float, hi1: float, curv: float
                   ) -> tuple[float, float]:
    """``(lo0 − max(|lo1|, |hi1|)²/(2 curv), hi0)`` rounded outwards (:func:`minimum_decision`)."""
    slope = max(abs(lo1), abs(hi1))
    drop = up(slope * slope / (2.0 * curv) * (1.0 + 4.0 * _U), 1) if slope else 0.0
    return float(np.nextafter(lo0 - drop, -np.inf)), float(hi0)


def minimum_enclosure(fs: FunctionalSet, i: int, za: np.ndarray, tau_m: float, span: float
                      ) -> tuple[float, float]:
    """Certified enclosure ``[lower, upper]`` of ``min ψ_i`` over ``[a, a + span]`` for the
    exact flow from ``za`` at a, where ψ_i is certified convex, near its computed minimum
    point ``a + tau_m``: ``upper`` bounds ψ_i(a + tau_m) from above, and by convexity
    ``ψ_i(a + s) ≥ ψ_i(a + tau_m) + ψ_i'(a + tau_m)(s − tau_m)`` gives ``lower`` (both
    from :meth:`FunctionalSet.enclose`; with a curvature bound, :func:`minimum_decision` is
    tighter)."""
    lo0, hi0 = fs.enclose(i, 0, za, tau_m)
    lo1, hi1 = fs.enclose(i, 1, za, tau_m)
    slope = max(abs(lo1), abs(hi1))
    lower = lo0 - slope * max(tau_m, span - tau_m) * (1.0 + 4.0 * np.finfo(float).eps)
    return float(lower), float(hi0)


def _reset(flow: Flow, t: float, z: np.ndarray, copy: bool = True) -> np.ndarray:
    """z with its oscillator states set from t analytically and its constant state 1 (a
    copy; in place with ``copy=False``, for a state just computed)."""
    if copy:
        z = z.copy()
    z[2 * flow.n:-1] = flow.oscillators(t)
    z[-1] = 1.0
    return z


def _zero_now(fs: FunctionalSet, i: int, a: float, za: np.ndarray, d: np.ndarray,
              note: str = "") -> Zero:
    """Functional i is not certified positive at a and not leaving: a cross at a, refined to
    the exact zero when ψ_i(a) > 0 is still approaching."""
    d0, d1 = d[0, i], d[1, i]
    tau = 0.0
    if d0 > 0.0 and d1 < 0.0:
        tau = _refine(fs, i, 0, a, za, 0.0, 4.0 * d0 / -d1, d0 / -d1)
    z = _reset(fs.flow, a + tau, fs.flow.expm(tau) @ za) if tau > 0.0 else za
    return Zero(a + tau, i, "cross", z, fs.value(i, 0, z), fs.value(i, 1, z), a + tau, note=note)


def derivative_sign(fs: FunctionalSet, i: int, k: int, za: np.ndarray, d: float, e: float):
    """Three-valued sign of ``ψ_i^{(k)}`` at the state za (exact flow): float64 ``d ± e``
    (e its certified error, :meth:`FunctionalSet.errors`) first, then ball arithmetic
    (``r·A^k·z`` from the float data, :func:`observer.event.enclosures.flow_sign` at s = 0).
    Returns the :class:`~observer.event.enclosures.Decision`."""
    if d - e > 0.0:
        return Decision(1, d - e, d + e, 53)
    if d + e < 0.0:
        return Decision(-1, d - e, d + e, 53)
    if k == 0:
        return dot_sign(fs.rows[i], za)
    return flow_sign(fs.flow.A, fs.rows[i], za, 0.0, k)


STALLED_STATE = 4.0
"""A positive approaching functional whose value is within this many of its certified errors
(the float64 state's own representation of it) cannot be approached by safe steps — each
step's state rounds back to the same value — so its zero, once certified in a bracket, is
refined from the fixed state (:func:`_near_zero`). Not a tolerance of any decision: the zero
is certified either way."""


def _near_zero(fs: FunctionalSet, i: int, a: float, za: np.ndarray, d: np.ndarray, err: np.ndarray,
               bound: float, w: float, lower0: float) -> Zero | None:
    """A certified first zero of ψ_i near a, refined from the fixed state za, when safe steps
    cannot reach it (:data:`STALLED_STATE`), else None.

    With ψ_i(a) > 0 certain (``lower0`` a lower bound) and ψ_i'(a) < 0 certain, the upper
    cubic ``U(s) = (d0 + e0) + (d1 + e1)s + max(d2 + e2, 0)s²/2 + B s³/6`` bounds ψ_i(a + s)
    above; ``U(s_c) < 0`` at ``s_c = 2(d0 + e0)/|d1 + e1|`` certifies a zero in (0, s_c), and the
    lower cubic's first zero s_lo (:func:`first_cubic_zero`) none before it: the zero in
    ``[s_lo, s_c]`` is refined by :func:`_refine` (Newton on the exact flow from za)."""
    d0, d1, d2 = float(d[0, i]), float(d[1, i]), float(d[2, i])
    e0, e1, e2 = float(err[0, i]), float(err[1, i]), float(err[2, i])
    if not (d1 + e1 < 0.0):
        return None
    res = time_resolution(a)
    s_c = 2.0 * (d0 + e0) / -(d1 + e1)
    if not (s_c <= w and (d0 <= STALLED_STATE * e0 or s_c <= UNRESOLVED_REACH * res)):
        return None
    upper = (d0 + e0) + (d1 + e1) * s_c + max(d2 + e2, 0.0) * s_c * s_c / 2 + bound * s_c ** 3 / 6
    if not upper < 0.0:
        return None
    s_lo = first_cubic_zero(lower0, d1 - e1, d2 - e2, bound, s_c)
    tau = _refine(fs, i, 0, a, za, s_lo, s_c, 0.5 * (s_lo + s_c))
    z = _reset(fs.flow, a + tau, fs.flow.expm(tau) @ za)
    return Zero(a + tau, i, "cross", z, fs.value(i, 0, z), fs.value(i, 1, z), a + tau)


def _safe_step(fs: FunctionalSet, a: float, za: np.ndarray, d: np.ndarray, err: np.ndarray,
               bound: np.ndarray, w: float, certified: dict[int, float], quick: np.ndarray | None = None,
               data=None) -> tuple[float, list[Zero]]:
    """Largest step from a over which no functional is certified to vanish, and the zeros
    found exactly on the way (convex minima, zeros at a). Vectorised quick test first: a
    functional whose cubic lower bound (the derivatives minus their certified errors
    ``err``, :meth:`FunctionalSet.errors`, so that it bounds the exact flow from za) stays
    positive on the whole window needs no more work.

    Every other decision is three-valued (:func:`derivative_sign`): ψ_i(a) certainly
    positive (its certified lower bound starts the cubic), or not — then it is at a zero
    unless leaving (ψ_i' > 0, or ψ_i' = 0 exactly and ψ_i'' > 0); no tolerance. ``quick``:
    the quick test's outcome when already computed (:meth:`FunctionalSet.screen`); ``data``:
    the data's part of the touch bands (:func:`graze_band`)."""
    d0, d1, d2 = d[0], d[1], d[2]
    step = w
    found: list[Zero] = []
    if quick is not None and quick.all():
        return step, found
    l0, l1, l2 = d0 - err[0], d1 - err[1], d2 - err[2]   # certified lower bounds
    if quick is None:
        quick = (l0 > 0.0) & (l0 + np.minimum(l1, 0.0) * w + np.minimum(l2, 0.0) * w * w / 2
                              - bound * w ** 3 / 6 > 0.0)
    todo = np.flatnonzero(~quick).tolist()
    if not todo:
        return step, found
    # per-functional work on Python floats (the same IEEE values; no numpy scalar dispatch)
    D0, D1, D2, E0, E1, E2 = (v.tolist() for v in (d0, d1, d2, err[0], err[1], err[2]))
    L0, L1, L2, BD = (v.tolist() for v in (l0, l1, l2, bound))
    for i in todo:
        until = certified.get(i, -np.inf)
        if until > a:
            step = min(step, until - a)
            continue
        convex = D1[i] < 0.0 < D2[i]
        s0 = derivative_sign(fs, i, 0, za, D0[i], E0[i])
        start = L0[i]
        if s0.sign == 1:
            start = max(start, s0.lower)
            near = _near_zero(fs, i, a, za, d, err, BD[i], w, start)
            if near is not None:
                found.append(near)
                continue
        else:
            s1 = derivative_sign(fs, i, 1, za, D1[i], E1[i])
            leaving = s1.sign == 1 or (s1.sign == 0 and
                                       derivative_sign(fs, i, 2, za, D2[i], E2[i]).sign == 1)
            if not leaving:                    # a float64 slope 0 too: the minimum is at a
                res = _convex_minimum(fs, i, a, za, D0[i], D1[i], D2[i], BD[i], w, E2[i], data) \
                    if D1[i] <= 0.0 < D2[i] else None
                if res is None:
                    found.append(_zero_now(fs, i, a, za, d, s0.note or s1.note))
                elif res[0] == "positive":
                    certified[i] = res[1]
                    step = min(step, res[1] - a)
                else:
                    found.append(res[1])
                continue
        s = first_cubic_zero(max(start, 0.0), L1[i], L2[i], BD[i], w)
        if s < w and convex:
            res = _convex_minimum(fs, i, a, za, D0[i], D1[i], D2[i], BD[i], w, E2[i], data)
            if res is not None:
                if res[0] != "positive":
                    found.append(res[1])
                    continue
                certified[i] = res[1]
                s = res[1] - a
        step = min(step, s)
    return step, found


def _row_norm(v: np.ndarray) -> float:
    """Proved upper bound of ‖v‖₂ for a derivative row, ``inf`` once its squares overflow
    (|v_i| ≥ 2^511; the search then stops as non-finite, as with float64's norm)."""
    return norm_upper(v) if float(np.max(np.abs(v))) < 2.0 ** 511 else np.inf


class SearchCarry:
    """The search's own accumulated state error and the data's part of its touch bands
    (:func:`graze_band` (b) and (c)), for :func:`first_zero`.

    The search advances its float state window by window, ``z ← fl(exp(A s) z)``, each step
    rounding: :attr:`err` bounds ``|z_a − exact flow from z0 at a|`` componentwise (the
    a-priori bound of a matrix-vector product, Higham §3.5, as ``_Run.carry_error``: ``err ←
    |E|·err·(1 + 2γ) + γ·|E|·|z|``, E = exp(A s) as computed), the oscillator states
    reset from ``fl(ω a)`` known to ``u·|ω a|`` plus their own rounding. :meth:`__call__`
    at the minimum ``a + s``: that error carried over s through the rows, ``|r|·|exp(A s)|·err``,
    plus ``data(t, z)`` (the run's carried error and the data's resolution in the user's
    coordinates, given by the master) or, without it, the data's representation in the run's
    coordinates (:func:`~observer.event.enclosures.representation_error`). With ``energy``
    (the run's :class:`~observer.event.energy.EnergyCarry`), the same error of the mechanical
    state is carried in its energy norm too, ``ε ← e^{μ s} ε + ‖w‖_P`` (w the step's rounding
    and what the oscillators' error feeds in), and the smaller enclosure taken: the
    componentwise one grows with ``‖|exp(A s)|‖`` per step, the energy norm's does not.

    Parameters
    ----------
    flow : Flow
    rows : ndarray, shape (p, N)
    a : float
        Start of the search.
    data : callable or None
        See :func:`first_zero`.
    energy : EnergyCarry or None
        See :func:`first_zero`.
    """

    def __init__(self, flow: Flow, rows: np.ndarray, a: float, z: np.ndarray, data=None,
                 energy=None) -> None:
        self.flow, self.rows, self.a, self.data = flow, rows, float(a), data
        self.abs_rows = np.abs(rows)
        self.err = np.zeros(flow.N)
        self.energy, self.eps, self.z = energy, 0.0, z
        self._rate = energy.rate(flow) if energy is not None and energy.valid else math.inf
        self.g = gamma(flow.N + 1)
        self._osc = slice(2 * flow.n, flow.N - 1)
        self._w = np.repeat(np.abs(flow._freq_array), 2).astype(float)
        k = 2 * flow.n
        self._absP = energy.absP if energy is not None else np.zeros((k, k))
        self._gp = p_norm_gamma(k)

    def advance(self, step: float, za: np.ndarray) -> np.ndarray:
        """The state ``step`` after the current one (``a``), with :attr:`err` and :attr:`eps`
        carried (:func:`observer.event.kernels.carry_step`, one compiled call)."""
        flow = self.flow
        E = flow.expm(step)
        self.a = self.a + step
        z = self.z = _reset(flow, self.a, E @ za, copy=False)
        self.err, self.eps = self._step(E, za, z, step, True)
        return z

    def _step(self, E: np.ndarray, za: np.ndarray, z: np.ndarray, step: float, reset: bool):
        flow = self.flow
        return kernels.carry_step(E, za, z, self.err, self.eps, self.g, 2 * flow.n,
                                  self._osc.start, self._osc.stop, self._w, self.a,
                                  self._absP, self._gp, self._rate, step,
                                  self.energy is not None, reset)

    def at(self, t: float) -> tuple[np.ndarray, float]:
        """``(err, eps)`` carried to t ≥ a, the flight from the current state included."""
        s = float(t) - self.a
        if not s > 0.0:
            return self.err.copy(), self.eps
        return self._step(self.flow.expm(s), self.z, self.z, s, False)

    def hand(self, zero: Zero) -> tuple:
        """``(zero, zero.t, zero.z)`` with :attr:`Zero.carried` set (:meth:`at`): what
        :func:`first_zero` returns."""
        zero.carried = self.at(zero.t)
        return zero, zero.t, zero.z

    def __call__(self, t: float, z: np.ndarray) -> np.ndarray:
        """(b) + (c) of :func:`graze_band` for every row at the state z at t ≥ a."""
        s = float(t) - self.a
        absE = np.abs(self.flow.expm(s)) if s > 0.0 else np.eye(self.flow.N)
        own = (self.abs_rows @ (absE @ self.err)) * (1.0 + 2.0 * self.g) ** 2
        if self.energy is not None:               # the smaller of two proved bounds
            k, g = 2 * self.flow.n, self.g
            w = (absE[:k, self._osc] @ self.err[self._osc]) * (1.0 + 2.0 * g)
            eps = self.energy.after(self.flow, max(s, 0.0), w, self.eps)
            osc = (self.abs_rows[:, self._osc] @ self.err[self._osc]) * (1.0 + 2.0 * g)
            own = np.minimum(own, self.energy.through(self.rows[:, :k], eps) + osc)
        rest = representation_error(self.rows, z) if self.data is None else self.data(t, z)
        return own + rest


def first_zero(flow: Flow, rows: np.ndarray, t0: float, z0: np.ndarray, t_end: float,
               certified: dict[int, float] | None = None, should_stop=None, data=None,
               energy=None) -> tuple[Zero | None, float, np.ndarray]:
    """First zero in ``[t0, t_end]`` of any functional ``rows[i]·z(t)`` along ``flow``.

    Decisions are three-valued on certified enclosures (:func:`_safe_step`,
    :func:`minimum_decision`); a search interval no longer than the time resolution
    (:func:`time_resolution`) is integrated as a flow, not searched. The windows and bounds
    are those of the block of the flow the functionals see (:meth:`FunctionalSet._coupled`).

    Parameters
    ----------
    flow : Flow
    rows : ndarray, shape (p, N)
        Functionals ψ_i = rows[i]·z, positive (or leaving zero) at t0.
    t0, z0 : float, ndarray
        Start time and augmented state.
    t_end : float
        End of the search.
    certified : dict, optional
        ``{i: t}``: ψ_i is known to stay positive until t (after a touch).
    should_stop : callable, optional
        A signal name it returns (:func:`_look`) stops the search: :class:`SearchStopped`.
    data : callable, optional
        ``data(t, z)``: per functional, the run's carried error and the data's resolution in
        the user's coordinates at the state z at t (:func:`graze_band` (b), (c)), for the
        touch bands only; without it z0 is exact data in the run's coordinates.
    energy : EnergyCarry, optional
        The run's energy norm: the search's own rounding is carried in it too (:class:`SearchCarry`).

    Returns
    -------
    zero, t, z : Zero or None, float, ndarray
        The first zero (None if there is none before t_end) and the time and augmented
        state where the search stopped (the zero's, or t_end).
    """
    rows = np.atleast_2d(rows)
    a, za = float(t0), np.asarray(z0, dtype=float)
    if rows.shape[0] == 0 or t_end - a <= time_resolution(t_end):
        z = _reset(flow, t_end, flow.expm(t_end - a) @ za) if t_end > a else za
        return None, t_end, z
    fs = functional_set(flow, rows)
    carry = SearchCarry(flow, fs.rows, a, za, data, energy)
    certified = dict(certified or {})
    window = WINDOW / fs.norm_bound if fs.norm_bound > 0.0 else np.inf   # inf: ψ polynomial
    growth = exp_upper(up(fs.certified_norm * min(window, t_end - a) * (1.0 + 2.0 * _U)))
    t_ok, z_ok = a, za                                # the last search point with finite values
    res_end = time_resolution(t_end)
    for count in range(MAX_STEPS):
        _look(should_stop, count, a, za)
        if t_end - a <= res_end:                      # a remainder of a few ulp: flow
            z = _reset(flow, t_end, flow.expm(t_end - a) @ za) if t_end > a else za
            _check_finite(t_end, z, np.zeros((1, 1)), t_ok, z_ok)
            return None, t_end, z
        w = min(window, t_end - a)
        # derivatives, errors, bounds B_i and the quick test in one compiled call
        d, finite, errs, bound, bound_finite, quick = fs.screen(za, growth, w)
        if not finite:
            _check_finite(a, za, d, t_ok, z_ok)       # overflow: a stop (NonFiniteFlow)
        t_ok, z_ok = a, za
        res = time_resolution(a)
        if not bound_finite:                          # the certified bound overflows: no search
            i = int(np.flatnonzero(~np.isfinite(bound))[0])
            raise NonFiniteFlow(a, a, za, ("bound", 3, i), float(bound[i]))
        step, found = (w, []) if quick.all() else _safe_step(fs, a, za, d, errs, bound, w, certified,
                                                              quick, carry)
        # no functional without a found zero vanishes in (a, a + step): the earliest found zero
        # within that reach is the first zero; one beyond it is recomputed later
        if found:
            first = min(found, key=lambda zr: zr.t)
            if first.t <= a + step:
                return carry.hand(first)
        step = max(step, 0.0)
        if step < w and step <= res:
            zero = _unresolved(fs, a, za, d, certified, res)
            if zero is not None:
                return carry.hand(zero)
            step = min(res, w)                       # nothing approaches: time moves on
        a, za = a + step, carry.advance(step, za)
    raise RootIsolationError(f"root isolation stalled near t = {a!r} ({MAX_STEPS} safe steps)", a, za)


def _look(should_stop, count: int, a: float, za: np.ndarray) -> None:
    """:class:`SearchStopped` at (a, za) when ``should_stop``, looked at every
    :data:`STOP_EVERY` advances of :func:`first_zero`, names a signal."""
    if should_stop is not None and count % STOP_EVERY == STOP_EVERY - 1 and (sig := should_stop()):
        raise SearchStopped(sig, a, za)


UNRESOLVED_REACH = 64.0
"""An unresolved zero (:func:`_unresolved`) is taken only among functionals whose first-order
time to zero ψ/|ψ'| is within this many time resolutions of a."""


def _unresolved(fs: FunctionalSet, a: float, za: np.ndarray, d: np.ndarray,
                certified: dict[int, float] | None = None, res: float = np.inf) -> Zero | None:
    """The safe step fell below the time resolution ``res``: some functional reaches zero
    within a few ulp of a, where float64 cannot order the zeros. Taken consistently: the
    approaching functional (ψ' < 0) with the smallest first-order time to zero ``ψ/|ψ'|``;
    None if none approaches within :data:`UNRESOLVED_REACH` resolutions. A functional
    certified nonzero beyond a (a graze just passed, ``certified[i] > a``) is not a
    candidate: its touch is what shrank the step, and another functional far from zero must
    not be taken in its place. The zero's note says so."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ttz = np.where(d[1] < 0.0, np.maximum(d[0], 0.0) / -d[1], np.inf)
    for i, until in (certified or {}).items():
        if until > a:
            ttz[i] = np.inf
    ttz[ttz > UNRESOLVED_REACH * res] = np.inf
    if not np.isfinite(ttz).any():
        return None
    i = int(np.argmin(ttz))
    several = int(np.isfinite(ttz).sum()) > 1     # zeros float64 cannot order: say so
    note = f"unresolved: zeros of {np.flatnonzero(np.isfinite(ttz)).tolist()} within the time " \
           f"resolution of t = {a:.17g}" if several else ""
    return Zero(a, i, "cross", za, float(d[0, i]), float(d[1, i]), a, note=note)
