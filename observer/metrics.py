"""Synchronization measures of an observer run: times to reach V ≤ ρ V(t_on), rates, floors."""

from __future__ import annotations

import numpy as np

RHOS = (1e-3, 1e-6, 1e-9)
"""Default fractions ρ for :func:`sync_time`."""


def sync_time(t: np.ndarray, V: np.ndarray, rho: float, t_on: float = 0.0,
              t_off: float | None = None) -> float:
    """First time after t_on at which V ≤ ρ·V(t_on), measured from t_on; ``inf`` if never in the window."""
    window = (t >= t_on) & (t <= (t[-1] if t_off is None else t_off))
    idx = np.flatnonzero(window)
    if idx.size == 0:
        return float("inf")
    V0 = V[idx[0]]
    hit = np.flatnonzero(V[idx] <= rho * V0)
    return float(t[idx[hit[0]]] - t[idx[0]]) if hit.size else float("inf")


def decay_rate(t: np.ndarray, V: np.ndarray, t_on: float = 0.0, t_off: float | None = None,
               floor_fraction: float = 1e-9) -> float:
    """Exponential rate r (1/s) of V ≈ V0 e^{−r(t−t_on)}: least-squares slope of log V over the
    coupling window, up to the first time V reaches ``floor_fraction``·V(t_on)."""
    window = (t >= t_on) & (t <= (t[-1] if t_off is None else t_off)) & (V > 0)
    idx = np.flatnonzero(window)
    if idx.size < 3:
        return float("nan")
    V0 = V[idx[0]]
    below = np.flatnonzero(V[idx] <= floor_fraction * V0)
    if below.size:
        idx = idx[:max(below[0], 3)]
    slope = np.polyfit(t[idx], np.log(V[idx]), 1)[0]
    return float(-slope)


def floor(t: np.ndarray, V: np.ndarray, t_from: float, t_to: float | None = None) -> float:
    """Median of V over [t_from, t_to] (the level V settles at)."""
    sel = (t >= t_from) & (t <= (t[-1] if t_to is None else t_to))
    return float(np.median(V[sel]))


def window_medians(t: np.ndarray, V: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Medians of V over consecutive windows [edges[i], edges[i+1])."""
    return np.array([np.median(V[(t >= a) & (t < b)]) for a, b in zip(edges[:-1], edges[1:])])


def switchings(active: np.ndarray) -> int:
    """Number of 0→1 switches (closings) summed over contacts, for (N+1, m) bool arrays."""
    a = active.astype(np.int8)
    return int(np.sum(np.diff(a, axis=0) == 1))
