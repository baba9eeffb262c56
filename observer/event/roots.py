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

A double root (grazing: ψ_i touches zero with ψ_i' = 0) cannot be certified either way in
floating point; when the minimum of ψ_i lies in a window on which ψ_i'' > 0 is certified
(``ψ_i''(a) − B_i s > 0``), ψ_i has exactly one local minimum t_m there, found as the
simple zero of ψ_i'. Its value decides: above the round-off tolerance of ψ_i, the whole
convex window is certified positive; within it, a **touch** (graze) at t_m; below it, a
**cross** before t_m, isolated by the bracket ``[a, t_m]``.

Zeros are refined by safeguarded Newton steps (bisection when a step leaves the bracket)
until the step is below :data:`TIME_RTOL`·max(1, |t|).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from observer.event.flow import Flow

WINDOW = 0.5
"""Window length in units of ``1/‖T⁻¹AT‖``: the growth factor of z over a window is ≤ e^0.5."""

ROUNDOFF = 64.0 * np.finfo(float).eps
"""Round-off tolerance of a functional: ``ROUNDOFF · Σ_j |r_ij z_j|`` (its evaluation error)."""

TOUCH_FACTOR = 1e3
"""A local minimum of ψ_i within ±TOUCH_FACTOR round-off tolerances of zero is a **touch**
(graze): round-off accumulated along a run (about 1e-13 relative after 50 s on the
grazing scenario) must not turn an exact graze into a miss or a crossing. A minimum
above it is a miss, below it a crossing (an impact, however shallow)."""

TIME_RTOL = 2.0 * np.finfo(float).eps
"""Newton refinement stops when the step is below ``TIME_RTOL · max(1, |t|)``."""

MAX_STEPS = 200_000
"""Safe advances per search before :class:`RootIsolationError` (a stalled isolation)."""


class RootIsolationError(RuntimeError):
    """The safe advance stalled (more than :data:`MAX_STEPS` steps in one search)."""


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
    """

    t: float
    index: int
    kind: str
    z: np.ndarray
    value: float
    slope: float
    resume: float


def tolerance(rows: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Round-off tolerance of each functional ``rows @ z``: ROUNDOFF·Σ|r_ij z_j|."""
    return ROUNDOFF * (np.abs(rows) @ np.abs(z)) + np.finfo(float).tiny


def first_cubic_zero(d0: float, d1: float, d2: float, bound: float, width: float) -> float:
    """A safe step: s ≤ the first s in (0, width] where ``L(s) = d0 + d1 s + d2 s²/2 − bound s³/6``
    reaches 0 (width if L stays positive), within a relative 1e-13 below it.

    ``d0 ≥ 0`` is assumed (a leaving functional at zero: d0 = 0 with L increasing first).
    L is split at its critical points into monotone pieces; the first piece whose end is
    not positive holds the zero, isolated by bisection keeping ``L(lo) > 0``.
    """
    if d0 + min(d1, 0.0) * width + min(d2, 0.0) * width * width / 2 - bound * width ** 3 / 6 > 0.0:
        return width
    a3, a2, a1 = -bound / 6.0, d2 / 2.0, d1

    def L(x: float) -> float:
        return ((a3 * x + a2) * x + a1) * x + d0

    crit = [c for c in _quadratic_roots(3.0 * a3, 2.0 * a2, a1) if 0.0 < c < width]
    lo = 0.0
    for hi in sorted(crit) + [width]:
        f_hi = L(hi)
        if f_hi <= 0.0:
            return _illinois(L, lo, hi, L(lo), f_hi)
        lo = hi
    return width


def _illinois(L, lo: float, hi: float, f_lo: float, f_hi: float) -> float:
    """Regula falsi (Illinois variant) on a monotone piece with ``L(lo) ≥ 0 ≥ L(hi)``; returns
    the left end ``lo`` (L(lo) > 0 kept, or lo = the start) once ``hi − lo ≤ 1e-13·hi``."""
    side = 0
    for _ in range(200):
        if hi - lo <= 1e-13 * hi:
            break
        x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo) if f_hi != f_lo else 0.5 * (lo + hi)
        if not lo < x < hi:
            x = 0.5 * (lo + hi)
        fx = L(x)
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


def _quadratic_roots(A: float, B: float, C: float) -> list[float]:
    """Real roots of ``A x² + B x + C`` (numerically stable form)."""
    if A == 0.0:
        return [-C / B] if B != 0.0 else []
    disc = B * B - 4.0 * A * C
    if disc < 0.0:
        return []
    q = -0.5 * (B + np.copysign(np.sqrt(disc), B))
    return [q / A, C / q] if q != 0.0 else [0.0]


class FunctionalSet:
    """The functionals ``rows`` of ``flow`` and their derivative rows (k = 0..3)."""

    def __init__(self, flow: Flow, rows: np.ndarray) -> None:
        self.flow = flow
        self.rows = np.atleast_2d(np.asarray(rows, dtype=float))
        A = flow.A
        self.d = [self.rows]
        for _ in range(3):
            self.d.append(self.d[-1] @ A)
        self.third_norm = np.linalg.norm(self.d[3] * flow.scale, axis=1)
        self.abs_d = [np.abs(r) for r in self.d[:3]]

    def __len__(self) -> int:
        return self.rows.shape[0]

    def value(self, i: int, k: int, z: np.ndarray) -> float:
        """k-th derivative of functional i at augmented state z."""
        return float(self.d[k][i] @ z)


def _refine(fs: FunctionalSet, i: int, k: int, a: float, za: np.ndarray, lo: float, hi: float,
            tau: float) -> float:
    """Zero of the k-th derivative of ψ_i on the bracket ``[lo, hi]`` (offsets from a), where
    ``ψ_i^{(k)}(lo) ≥ 0 ≥ ψ_i^{(k)}(hi)`` or the reverse; safeguarded Newton from ``tau``."""
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
        if abs(step) <= TIME_RTOL * max(1.0, abs(a + tau)) or hi - lo <= TIME_RTOL * max(1.0, abs(a + tau)):
            return tau
    return tau


def _convex_minimum(fs: FunctionalSet, i: int, a: float, za: np.ndarray, d0: float, d1: float,
                    d2: float, bound: float, width: float, tol: float):
    """Analyse functional i on a window where its minimum is near (d1 < 0 < d2).

    Returns ``None`` when convexity cannot be certified on ``[a, a + 2s_m]`` (s_m = −d1/d2,
    within ``width``), else ``("positive", certified_until)``, ``("touch", Zero)`` or
    ``("cross", Zero)``.
    """
    s_m = -d1 / d2
    span = 2.0 * s_m
    if span > width or d2 - bound * span <= 0.0:
        return None
    flow = fs.flow
    tau_m = _refine(fs, i, 1, a, za, 0.0, span, s_m)
    z_m = flow.expm(tau_m) @ za
    m_star = fs.value(i, 0, z_m)
    touch = TOUCH_FACTOR * tol
    if m_star > touch:
        return "positive", a + span
    t_m = a + tau_m
    if m_star >= -touch:
        z_m = _reset(flow, t_m, z_m)
        # ψ ≥ m* + (ψ''_min/2)(t − t_m)² with ψ''_min ≥ d2 − bound·span > 0: above 2·touch after
        curv = d2 - bound * span
        resume = t_m + np.sqrt(max(2.0 * (2.0 * touch - m_star), 0.0) / curv)
        return "touch", Zero(t_m, i, "touch", z_m, m_star, fs.value(i, 1, z_m), float(resume))
    tau = _refine(fs, i, 0, a, za, 0.0, tau_m, 0.5 * tau_m) if d0 > 0.0 else 0.0
    z = _reset(flow, a + tau, flow.expm(tau) @ za)
    return "cross", Zero(a + tau, i, "cross", z, fs.value(i, 0, z), fs.value(i, 1, z), a + tau)


def _reset(flow: Flow, t: float, z: np.ndarray) -> np.ndarray:
    z = z.copy()
    z[2 * flow.n:-1] = flow.oscillators(t)
    z[-1] = 1.0
    return z


def _zero_now(fs: FunctionalSet, i: int, a: float, za: np.ndarray, d: np.ndarray) -> Zero:
    """Functional i is at zero (within round-off) at a and not leaving: a cross at a, refined."""
    d0, d1 = d[0, i], d[1, i]
    tau = 0.0
    if d0 > 0.0 and d1 < 0.0:
        tau = _refine(fs, i, 0, a, za, 0.0, 4.0 * d0 / -d1, d0 / -d1)
    z = _reset(fs.flow, a + tau, fs.flow.expm(tau) @ za) if tau > 0.0 else za
    return Zero(a + tau, i, "cross", z, fs.value(i, 0, z), fs.value(i, 1, z), a + tau)


def _safe_step(fs: FunctionalSet, a: float, za: np.ndarray, d: np.ndarray, tols, bound: np.ndarray,
               w: float, certified: dict[int, float]) -> tuple[float, list[Zero]]:
    """Largest step from a over which no functional is certified to vanish, and the zeros
    found exactly on the way (convex minima, zeros at a). Vectorised quick test first: a
    functional whose cubic bound stays positive on the whole window needs no more work."""
    tol, tol1, tol2 = tols
    d0, d1, d2 = d
    step = w
    found: list[Zero] = []
    with np.errstate(divide="ignore", invalid="ignore"):
        s_min = np.where((d1 < 0.0) & (d2 > 0.0), -d1 / d2, np.inf)
        near_touch = (s_min <= w) & (d0 - d1 * d1 / (2.0 * d2) <= 2.0 * TOUCH_FACTOR * tol)
    quick = (d0 > tol) & ~near_touch & (
        d0 + np.minimum(d1, 0.0) * w + np.minimum(d2, 0.0) * w * w / 2 - bound * w ** 3 / 6 > 0.0)
    for i in np.flatnonzero(~quick):
        i = int(i)
        until = certified.get(i, -np.inf)
        if until > a:
            step = min(step, until - a)
            continue
        leaving = d1[i] > tol1[i] or (abs(d1[i]) <= tol1[i] and d2[i] > tol2[i])
        convex = d1[i] < 0.0 < d2[i]
        if d0[i] <= tol[i] and not leaving:
            res = _convex_minimum(fs, i, a, za, d0[i], d1[i], d2[i], bound[i], w, tol[i]) \
                if convex else None
            if res is None:
                found.append(_zero_now(fs, i, a, za, d))
            elif res[0] == "positive":
                certified[i] = res[1]
                step = min(step, res[1] - a)
            else:
                found.append(res[1])
            continue
        s = first_cubic_zero(max(d0[i], 0.0), d1[i], d2[i], bound[i], w)
        if (s < w or near_touch[i]) and convex:
            res = _convex_minimum(fs, i, a, za, d0[i], d1[i], d2[i], bound[i], w, tol[i])
            if res is not None:
                if res[0] != "positive":
                    found.append(res[1])
                    continue
                certified[i] = res[1]
                s = res[1] - a
        step = min(step, s)
    return step, found


def first_zero(flow: Flow, rows: np.ndarray, t0: float, z0: np.ndarray, t_end: float,
               certified: dict[int, float] | None = None) -> tuple[Zero | None, float, np.ndarray]:
    """First zero in ``[t0, t_end]`` of any functional ``rows[i]·z(t)`` along ``flow``.

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

    Returns
    -------
    zero, t, z : Zero or None, float, ndarray
        The first zero (None if there is none before t_end) and the time and augmented
        state where the search stopped (the zero's, or t_end).
    """
    rows = np.atleast_2d(rows)
    if rows.shape[0] == 0:
        z = _reset(flow, t_end, flow.expm(t_end - t0) @ z0) if t_end > t0 else z0
        return None, t_end, z
    fs = FunctionalSet(flow, rows)
    certified = dict(certified or {})
    window = WINDOW / max(flow.norm_bound, 1e-300)
    a, za = float(t0), np.asarray(z0, dtype=float)
    growth = np.exp(WINDOW)
    for _ in range(MAX_STEPS):
        if a >= t_end:
            return None, t_end, za
        w = min(window, t_end - a)
        d = np.array([fs.d[k] @ za for k in range(3)])
        az = np.abs(za)
        tol, tol1, tol2 = (ROUNDOFF * (r @ az) + np.finfo(float).tiny for r in fs.abs_d)
        bound = fs.third_norm * growth * np.linalg.norm(za / flow.scale) * (1.0 + 1e-12)
        step, found = _safe_step(fs, a, za, d, (tol, tol1, tol2), bound, w, certified)
        # no functional without a found zero vanishes in (a, a + step): the earliest found zero
        # within that reach is the first zero; one beyond it is recomputed later
        if found:
            first = min(found, key=lambda zr: zr.t)
            if first.t <= a + step:
                return first, first.t, first.z
        step = max(step, 0.0)
        zero = _earliest_pending(fs, a, za, step, d, tol)
        if zero is not None:
            return zero, zero.t, zero.z
        a, za = a + step, _reset(flow, a + step, flow.expm(step) @ za)
    raise RootIsolationError(f"root isolation stalled near t = {a!r} ({MAX_STEPS} safe steps)")


def _earliest_pending(fs: FunctionalSet, a: float, za: np.ndarray, step: float, d: np.ndarray,
                      tol: np.ndarray) -> Zero | None:
    """Guard against a step that makes no progress (step below the time resolution): the
    functional with the smallest value is then at its zero within round-off."""
    if step > TIME_RTOL * max(1.0, abs(a)):
        return None
    ratio = d[0] / tol
    i = int(np.argmin(ratio))
    return Zero(a, i, "cross", za, float(d[0, i]), float(d[1, i]), a)
