"""The gap frame (issue 34): the event engine runs in coordinates whose origin lies on the
contacts, so that a translation of the coordinates costs nothing beyond what float64 forces
on the inputs.

A system translated by c (``q → q + c``, ``ν → ν − Wᵀc``, ``f → f + Kc``) is the same motion,
but its gaps ``g = Wᵀq + ν`` (paper eq. (2)) are then differences of numbers of size |c|: each
evaluation of a gap, each certified enclosure and each touch band carries round-off of
ulp(c), and the impact times ulp(c)/|γ| — ulp(1e6) = 1.2e-10 m, where the motion itself
(the state and its flow) is known to the ulp of its own size. The gap frame moves the origin
back onto the contacts before the run:

* an origin q* (a float vector) with ``Wᵀq* + ν₀ ≈ 0`` for the constant part ν₀ of the gap
  offset: the minimum-norm solution of ``Wᵀq* = −ν₀`` (in the range of W; its columns are
  independent, :class:`observer.model.LinearSystem`), improved by residual correction with
  the exact residual (:func:`origin`);
* the shifted problem in x = q − q* (:meth:`GapFrame.system`, :meth:`GapFrame.state`):
  ``M ẍ + C ẋ + K x = f(t) − K q* + W λ``, gaps ``g = Wᵀx + ν(t) + Wᵀq*``, i.e. the forcing
  constant ``f₀' = f₀ − K q*`` and the gap offset constant ``ν₀' = ν₀ + Wᵀq*`` (each
  computed exactly, then rounded once: :func:`exact_affine`), the initial state
  ``x₀ = q₀ − q*`` (one IEEE subtraction, correctly rounded); the harmonic terms, M, C, K, W,
  the velocities and the observers' errors ``e = q̂ − q`` are unchanged;
* the rows back in q at the end (:meth:`GapFrame.output`: ``q = x + q*``, rounded to the
  output's own ulp); the event rows (times, velocities, impulses, depths) are frame-free.

What holds exactly: for *any* float vector q* the shifted problem is the same mathematical
problem as the given one (a translation is an exact symmetry of eqs. (1)–(6)); the only
roundings are those of ``x₀``, ``f₀'`` and ``ν₀'``, each relative to its *own* size — small
numbers with no cancellation left in them, since Wᵀq* cancels ν₀ to the rounding of q*.
q* itself need not be exact (it is not an input of the problem): its accuracy decides only
how small ν₀' is, not which problem is solved. The output rows ``x + q*`` are rounded to
ulp(q), which is the representation of the answer. No frame (the run unchanged bit for bit)
when ν₀ = 0, or when the frame does not lower the gaps' representation floor at the initial
state (:meth:`GapFrame.for_scenario`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from observer.model import LinearSystem

REFINEMENTS = 3
"""Residual corrections of the origin q* after the least-squares start (each with the exact
residual; one usually leaves ``ν₀ + Wᵀq*`` at the rounding of q*)."""

_SAFE = 2.0 ** 480
"""Magnitude window ``[1/_SAFE, _SAFE]`` of factors whose products :func:`exact_affine`
splits exactly in float64 (Dekker's two-product: no overflow of the split, no underflow of
the error term); outside it the exact rational sum (``fractions``) is used."""


def _two_product(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(p, err)`` with ``p + err = a·b`` exactly (Dekker 1971, Veltkamp's split) for
    factors in the :data:`_SAFE` window."""
    split = 134217729.0                          # 2^27 + 1
    ca, cb = split * a, split * b
    ah, bh = ca - (ca - a), cb - (cb - b)
    al, bl = a - ah, b - bh
    p = a * b
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


def _safe(x: np.ndarray) -> bool:
    ax = np.abs(x[x != 0.0])
    return bool(np.all(np.isfinite(ax)) and np.all((ax >= 1.0 / _SAFE) & (ax <= _SAFE)))


def exact_affine(b: np.ndarray, A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``b + A x`` with each component the exact value rounded once to float64.

    Every product ``A_ij x_j`` is split exactly into two floats (:func:`_two_product`) and
    each row summed by ``math.fsum`` (correctly rounded sum of its float terms, Shewchuk's
    algorithm); factors outside the :data:`_SAFE` window go through exact rationals.

    Parameters
    ----------
    b : ndarray, shape (r,)
    A : ndarray, shape (r, k)
    x : ndarray, shape (k,)

    Returns
    -------
    ndarray, shape (r,)
    """
    b, A, x = (np.asarray(v, dtype=float) for v in (b, A, x))
    if not (_safe(A) and _safe(x) and np.all(np.isfinite(b))):
        return np.array([float(Fraction(bi) + sum((Fraction(a) * Fraction(xj)
                                                   for a, xj in zip(row, x) if a and xj),
                                                  Fraction(0)))
                         for bi, row in zip(b, A)])
    p, err = _two_product(A, x[None, :])
    return np.array([math.fsum(np.concatenate(([bi], pi[pi != 0.0], ei[ei != 0.0])))
                     for bi, pi, ei in zip(b, p, err)])


def origin(W: np.ndarray, nu0: np.ndarray) -> np.ndarray:
    """A float origin q* with ``Wᵀq* + ν₀ ≈ 0``: the minimum-norm least-squares solution of
    ``Wᵀq* = −ν₀`` (``numpy.linalg.lstsq``), then up to :data:`REFINEMENTS` corrections by the
    same solve on the exact residual ``ν₀ + Wᵀq*`` (:func:`exact_affine`); the origin with the
    smallest residual (max-norm) is kept.

    Parameters
    ----------
    W : ndarray, shape (n, m)
        The contact directions (independent columns).
    nu0 : ndarray, shape (m,)
        The constant part of the gap offset.

    Returns
    -------
    ndarray, shape (n,)
        Zeros when ν₀ = 0.
    """
    W, nu0 = np.asarray(W, dtype=float), np.asarray(nu0, dtype=float)
    q = np.zeros(W.shape[0])
    if not np.any(nu0):
        return q
    best, best_res = q, np.max(np.abs(nu0))
    for _ in range(REFINEMENTS + 1):
        res = exact_affine(nu0, W.T, q)
        size = np.max(np.abs(res))
        if size < best_res:
            best, best_res = q, size
        if size == 0.0 or not np.all(np.isfinite(res)):
            break
        q = q + np.linalg.lstsq(W.T, -res, rcond=None)[0]
    return best


_KEPT = 8
"""Systems whose frame and shifted system are kept (a run of one of them again reuses its
flows); the caches are emptied when full (each entry holds its system's matrices)."""

_FRAMES: dict = {}
"""``id(system) → (system, frame)`` (:meth:`GapFrame.of`)."""

_SHIFTED: dict = {}
"""``(id(system), q*) → (system, shifted system)`` (:meth:`GapFrame.system`)."""


@dataclass(frozen=True)
class GapFrame:
    """Coordinates ``x = q − q*`` with the origin q* on the contacts (module docstring).

    Attributes
    ----------
    origin : ndarray, shape (n,)
        q* (float64).
    """

    origin: np.ndarray

    @staticmethod
    def of(system: LinearSystem) -> "GapFrame | None":
        """The frame of ``system`` (its W and constant gap offset), or None when its origin
        is 0 (ν₀ = 0: the run is left as it is). Kept per system object, with the shifted
        system (:meth:`system`), so that runs of one scenario share the shifted system's
        flows (:func:`observer.event.flow.flow_for` caches them per system)."""
        hit = _FRAMES.get(id(system))
        if hit is not None and hit[0] is system:
            return hit[1]
        q = origin(system.W, system.gap.constant)
        frame = GapFrame(q) if np.any(q) else None
        if len(_FRAMES) >= _KEPT:
            _FRAMES.clear()
        _FRAMES[id(system)] = (system, frame)
        return frame

    @staticmethod
    def for_scenario(sc) -> "GapFrame | None":
        """The frame a run of ``sc`` (a :class:`observer.scenario.Scenario`) takes: that of its
        system (:meth:`of`) when it lowers the gaps' representation floor at the initial
        state, ``Σ_j (Σ_i |W_ij q_i| + |ν_j|)`` — the sum the engine's certified evaluation
        errors and touch bands scale with
        (:func:`observer.event.enclosures.represented_error`) — else None (a motion
        away from its contacts, a spring's rest position 10 m off the wall, is left in its
        coordinates: there the frame would only move the state away from its origin)."""
        frame = GapFrame.of(sc.system)
        if frame is None:
            return None
        W, nu0 = np.abs(np.asarray(sc.system.W)), sc.system.gap.constant
        x0 = frame.state(sc.q0)
        nu1 = exact_affine(nu0, np.asarray(sc.system.W).T, frame.origin)
        given = float(np.sum(np.abs(sc.q0) @ W + np.abs(nu0)))
        shifted = float(np.sum(np.abs(x0) @ W + np.abs(nu1)))
        return frame if shifted < given else None

    def state(self, q: np.ndarray) -> np.ndarray:
        """``x = q − q*`` (correctly rounded per component)."""
        return np.asarray(q, dtype=float) - self.origin

    def output(self, x: np.ndarray) -> np.ndarray:
        """Rows ``q = x + q*`` (shape (N, n) or (n,)): the run's coordinates again."""
        return np.asarray(x, dtype=float) + self.origin

    def system(self, system: LinearSystem) -> LinearSystem:
        """``system`` in the frame: forcing constant ``f₀ − K q*`` and gap offset constant
        ``ν₀ + Wᵀq*``, each exact then rounded once (:func:`exact_affine`); M, C, K, W and the
        harmonic terms as they are (already validated: not checked again). One shifted
        system per system and origin (kept: its flows are cached on it)."""
        key = (id(system), self.origin.tobytes())
        hit = _SHIFTED.get(key)
        if hit is not None and hit[0] is system:
            return hit[1]
        shifted = self._shift(system)
        if len(_SHIFTED) >= _KEPT:
            _SHIFTED.clear()
        _SHIFTED[key] = (system, shifted)
        return shifted

    def _shift(self, system: LinearSystem) -> LinearSystem:
        """The shifted system, built (:meth:`system` keeps it)."""
        f0 = exact_affine(system.forcing.constant, -np.asarray(system.K), self.origin)
        nu0 = exact_affine(system.gap.constant, np.asarray(system.W).T, self.origin)
        shifted = dataclasses.replace(
            system, forcing=dataclasses.replace(system.forcing, constant=f0),
            gap=dataclasses.replace(system.gap, constant=nu0), check=False)
        fields = {f.name for f in dataclasses.fields(system)}
        for key, value in system.__dict__.items():     # what the checks found: M, C, K, W only
            if key not in fields:
                object.__setattr__(shifted, key, value)
        return shifted

    def scenario(self, sc):
        """The scenario ``sc`` (a :class:`observer.scenario.Scenario`) in the frame: its
        system (:meth:`system`) and initial position (:meth:`state`); the rest as it is."""
        return dataclasses.replace(sc, system=self.system(sc.system), q0=self.state(sc.q0))
