"""Synchronization measures of an observer run: first-passage and settling times of
V ≤ ρ·V(t_on), rates, floors.

Two times per threshold ρ (both measured from t_on, inside the coupling window):

* first passage (:func:`sync_time`): the first sample with V ≤ ρ·V(t_on);
* settling (:func:`settling_time`): the first sample from which V stays ≤ ρ·V(t_on) up to
  the end of the window (``inf`` when V ends above it).
"""

from __future__ import annotations

import numpy as np

RHOS = (1e-3, 1e-5, 1e-6, 1e-9)
"""The synchronization thresholds ρ (fractions of V(t_on)), the one list every result, suite
row and report column uses: :func:`sync_column` and :func:`settle_column` name the columns."""


def sync_column(rho: float) -> str:
    """Column of the first-passage time to ρ·V(t_on): ``t_sync_1e-06``."""
    return f"t_sync_{rho:g}"


def settle_column(rho: float) -> str:
    """Column of the settling time below ρ·V(t_on): ``t_settle_1e-06``."""
    return f"t_settle_{rho:g}"


def above_column(rho: float) -> str:
    """Column of the fraction of window samples after the first passage with V back above
    ρ·V(t_on) (:func:`excursions_after_passage`): ``above_after_1e-06``."""
    return f"above_after_{rho:g}"


def sync_time(t: np.ndarray, V: np.ndarray, rho: float, t_on: float = 0.0,
              t_off: float | None = None) -> float:
    """First-passage time: first sample after t_on at which V ≤ ρ·V(t_on), measured from
    t_on; ``inf`` if never in the window. See :func:`settling_time` for the time after which
    V stays below."""
    window = (t >= t_on) & (t <= (t[-1] if t_off is None else t_off))
    idx = np.flatnonzero(window)
    if idx.size == 0:
        return float("inf")
    V0 = V[idx[0]]
    hit = np.flatnonzero(V[idx] <= rho * V0)
    return float(t[idx[hit[0]]] - t[idx[0]]) if hit.size else float("inf")


def settling_time(t: np.ndarray, V: np.ndarray, rho: float, t_on: float = 0.0,
                  t_off: float | None = None) -> float:
    """Time (from t_on) after which V stays at or below ρ·V(t_on) until the end of the window.

    With the window samples t_{k_on} < … < t_{k_off} (``t_on ≤ t_k ≤ t_off``, ``t_off``
    defaulting to the last sample) and V0 = V(t_{k_on}), let k* be the last window sample
    with V(t_k) > ρ·V0. The settling time is ``t_{k*+1} − t_{k_on}``: from the sample after
    the last excursion above the threshold on, every sample up to t_off satisfies
    V ≤ ρ·V0. It is ``0.0`` when no sample exceeds the threshold and ``inf`` ("never") when
    the last window sample is above it (V ends above ρ·V0) or the window is empty.

    Unlike the first passage (:func:`sync_time`), a V that dips below ρ·V0 and rises above it
    again (the observer with position jumps on double_mass at ρ = 1e-9) is not counted as
    settled until its last excursion is over; ``settling_time ≥ sync_time`` always.

    Parameters
    ----------
    t, V : ndarray, shape (N+1,)
        Time grid and the error Lyapunov function (paper (16)) on it.
    rho : float
        Threshold fraction of V(t_on).
    t_on, t_off : float
        Coupling window (``t_off=None``: the end of the run).

    Returns
    -------
    float
        Seconds from t_on, ``0.0`` or ``inf``.
    """
    window = (t >= t_on) & (t <= (t[-1] if t_off is None else t_off))
    idx = np.flatnonzero(window)
    if idx.size == 0:
        return float("inf")
    Vw = V[idx]
    above = np.flatnonzero(~(Vw <= rho * Vw[0]))          # NaN counts as above
    if above.size == 0:
        return 0.0
    last = above[-1]
    if last == idx.size - 1:
        return float("inf")
    return float(t[idx[last + 1]] - t[idx[0]])


def excursions_after_passage(t: np.ndarray, V: np.ndarray, rho: float, t_on: float = 0.0,
                             t_off: float | None = None) -> float:
    """Fraction of the window samples after the first passage below ρ·V(t_on) at which V is
    back above it (0 when V stays below; NaN when it never gets below)."""
    window = (t >= t_on) & (t <= (t[-1] if t_off is None else t_off))
    Vw = V[np.flatnonzero(window)]
    if Vw.size == 0:
        return float("nan")
    below = np.flatnonzero(Vw <= rho * Vw[0])
    if below.size == 0:
        return float("nan")
    after = Vw[below[0] + 1:]
    return float(np.mean(~(after <= rho * Vw[0]))) if after.size else 0.0


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


def switchings(active: np.ndarray) -> int:
    """Number of 0→1 switches (closings) summed over contacts, for (N+1, m) bool arrays."""
    a = active.astype(np.int8)
    return int(np.sum(np.diff(a, axis=0) == 1))


def window_of(sc) -> tuple[float, float]:
    """The coupling window [t_on, t_off] of the scenario, cut at t_end."""
    t_on, t_off = sc.observer.get("coupling", (0.0, sc.t_end))
    return float(t_on), min(float(t_off), float(sc.t_end))
