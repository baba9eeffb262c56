"""Closed-form solutions of the built-in scenarios' masters, the math alone (not a scenario).

* :func:`accumulation_time`, :func:`impact_times`, :func:`ball_position` — the Zeno bouncing
  ball (docs/theory/oracles.md §1): piecewise parabolas between the closed-form impact times, q = 0 after
  the accumulation time t_∞;
* :class:`ExactImpactOscillator` — the undamped forced impact oscillator
  ``ẍ + x = A cos(ωt + φ)`` for ``x ≤ σ`` with ``ẋ⁺ = −r ẋ⁻``: free flight in closed form,
  impacts located by a scan + ``brentq`` to 1e-14 (event-driven exact solution);
* :func:`ball_reference`, :func:`oscillator_reference` — the same as master positions of a
  loaded scenario, which :mod:`observer.scenarios.bouncing_ball` and
  :mod:`observer.scenarios.impact_oscillator` declare as ``reference``.

A leaf module (numpy, and scipy when an oscillator is built): the scenario modules import it,
and :mod:`observer.closed_form` re-exports it next to its dispatch over the registry.
"""

from __future__ import annotations

import numpy as np


def accumulation_time(h0: float, g0: float, e: float) -> float:
    """Zeno time t_∞ = sqrt(2h0/g0)(1 + e)/(1 − e)."""
    return float(np.sqrt(2 * h0 / g0) * (1 + e) / (1 - e))


def impact_times(h0: float, g0: float, e: float, count: int) -> np.ndarray:
    """The first ``count`` impact times t_k = t1 + (2v1/g0) e(1 − e^{k−1})/(1 − e)."""
    t1 = np.sqrt(2 * h0 / g0)
    v1 = np.sqrt(2 * g0 * h0)
    k = np.arange(1, count + 1)
    return t1 + (2 * v1 / g0) * e * (1 - e ** (k - 1)) / (1 - e)


def ball_position(t: np.ndarray, h0: float, g0: float, e: float) -> np.ndarray:
    """Exact height of the ball dropped from rest at h0 (Newton/Poisson restitution e).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Times (s).
    h0, g0, e : float
        Drop height (m), gravity (m/s²), restitution.

    Returns
    -------
    ndarray, shape (N,)
        q(t); 0 for t ≥ t_∞ (rest after the Zeno accumulation).
    """
    t = np.asarray(t, dtype=float)
    t_inf = accumulation_time(h0, g0, e)
    count = int(np.ceil(np.log(1e-300) / np.log(e))) if 0 < e < 1 else 1
    tk = impact_times(h0, g0, e, min(count, 2000))
    v1 = np.sqrt(2.0 * g0 * h0)
    k = np.searchsorted(tk, t, side="right")          # impacts strictly before (or at) t
    kk = np.maximum(k, 1)
    dt = t - tk[kk - 1]
    flight = (e ** kk) * v1 * dt - 0.5 * g0 * dt ** 2
    q = np.where(k == 0, h0 - 0.5 * g0 * t ** 2, flight)
    return np.where(t >= t_inf, 0.0, q)


class ExactImpactOscillator:
    """Event-driven closed-form solution of the undamped forced impact oscillator.

    ``ẍ + x = A cos(ωt + φ)`` while ``x ≤ σ``; at ``x = σ`` with ``ẋ > 0`` the velocity is
    reversed, ``ẋ⁺ = −r ẋ⁻``. Between impacts ``x = x_p + c₁cos(t − t_s) + c₂sin(t − t_s)``
    with ``x_p = A cos(ωt + φ)/(1 − ω²)``. The next impact is the first root of x − σ,
    bracketed on a scan of spacing ``scan`` and refined by ``brentq`` (xtol 1e-14).

    Parameters
    ----------
    A, omega, phase, sigma, r : float
        Forcing amplitude, frequency (ω ≠ 1), phase, wall position, restitution.
    x0, v0 : float
        State at ``t_start``.
    t_start, t_end : float
    scan : float
        Bracketing grid spacing; an excursion to the wall shorter than this is missed
        (grazing), which the built-in parameters never produce.
    """

    def __init__(self, A: float, omega: float, phase: float, sigma: float, r: float, x0: float,
                 v0: float, t_start: float, t_end: float, scan: float = 1e-3):
        if abs(1.0 - omega ** 2) < 1e-12:
            raise ValueError("resonant forcing (ω = 1) has no bounded particular solution")
        self.A, self.omega, self.phase, self.sigma, self.r = A, omega, phase, sigma, r
        from scipy.optimize import brentq      # here: `import observer` loads no scipy.optimize

        self.gf = A / (1.0 - omega ** 2)
        starts, c1s, c2s, impacts = [], [], [], []
        ts, x, v = t_start, x0, v0
        while len(impacts) < 100_000:
            c1, c2 = x - self._xp(ts), v - self._vp(ts)
            starts.append(ts)
            c1s.append(c1)
            c2s.append(c2)

            def gap(t, ts=ts, c1=c1, c2=c2):
                return self._xp(t) + c1 * np.cos(t - ts) + c2 * np.sin(t - ts) - sigma

            grid = np.arange(ts + scan, t_end + scan, scan)
            above = np.flatnonzero(gap(grid) >= 0.0)
            if above.size == 0:
                break
            i = above[0]
            lo = grid[i - 1] if i > 0 else ts + 0.5 * scan
            ti = brentq(gap, lo, grid[i], xtol=1e-14, rtol=4 * np.finfo(float).eps, maxiter=200)
            vi = self._vp(ti) - c1 * np.sin(ti - ts) + c2 * np.cos(ti - ts)
            impacts.append((ti, vi))
            ts, x, v = ti, sigma, -r * vi
        self.starts, self.c1, self.c2 = np.array(starts), np.array(c1s), np.array(c2s)
        self.impacts = np.array(impacts).reshape(-1, 2)

    def _xp(self, t):
        return self.gf * np.cos(self.omega * t + self.phase)

    def _vp(self, t):
        return -self.gf * self.omega * np.sin(self.omega * t + self.phase)

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(x(t), ẋ(t))``; at an impact instant the post-impact segment is used."""
        t = np.asarray(t, dtype=float)
        j = np.clip(np.searchsorted(self.starts, t, side="right") - 1, 0, None)
        dt = t - self.starts[j]
        x = self._xp(t) + self.c1[j] * np.cos(dt) + self.c2[j] * np.sin(dt)
        v = self._vp(t) - self.c1[j] * np.sin(dt) + self.c2[j] * np.cos(dt)
        return x, v


def ball_reference(scenario, t: np.ndarray) -> np.ndarray | None:
    """The bouncing ball's closed form (any h0, g0, e) as positions (N, 1)."""
    s = scenario.system
    m = s.M[0, 0]
    g0 = -s.forcing.constant[0] / m
    e = float(scenario.law.restitution[0])
    return ball_position(t, float(scenario.q0[0]), float(g0), e)[:, None]


def oscillator_reference(scenario, t: np.ndarray) -> np.ndarray | None:
    """The undamped impact oscillator with one harmonic forcing term, as positions (N, 1);
    None for other settings (damping, constant forcing, several terms, moving wall)."""
    s = scenario.system
    terms = s.forcing.terms()
    if s.C[0, 0] != 0.0 or s.forcing.constant[0] != 0.0 or len(terms) != 1 or s.gap.terms():
        return None
    term = terms[0]
    A = float(np.ravel(term["amplitude"])[0])
    omega = float(term["omega"])
    phase = float(np.ravel(term.get("phase", 0.0))[0])
    sigma = float(s.gap.constant[0])
    r = float(scenario.law.restitution[0])
    ex = ExactImpactOscillator(A, omega, phase, sigma, r, float(scenario.q0[0]),
                               float(scenario.u0[0]), float(t[0]), float(t[-1]))
    return ex(t)[0][:, None]
