"""Assumption A2: bounded external forcing, ``sup_t ‖f(t)‖ ≤ f_max < ∞``.

For the toolkit's harmonic forcing ``f(t) = c + Σ_j a_j ∘ cos(ω_j t + φ_j)`` the bound is
analytic: componentwise ``|f_i(t)| ≤ |c_i| + Σ_j |a_ji|`` for all t, hence
``‖f(t)‖₂ ≤ U := ‖|c| + Σ_j |a_j|‖₂`` (:meth:`observer.model.Harmonic.bound`). The check also
computes the attained ``S = sup ‖f(t)‖₂`` over one common period (dense sampling refined
by a bounded scalar optimization around the best samples; for incommensurate
frequencies over a long window), which must not exceed U, nor a user-given f_max.

For any other callable f(t) no analytic bound exists; the check then samples the sup over
windows [0, T], [0, 2T], [0, 4T], ... and fails when it keeps growing (e.g. a ramp).
"""

from __future__ import annotations

from fractions import Fraction
from typing import Callable

import numpy as np
from scipy.optimize import minimize_scalar

from observer.model import Harmonic
from proofs_checks.result import CheckResult

NAME = "forcing_bounded"
EQUATION = "A2: sup‖f(t)‖ ≤ f_max < ∞"


def common_period(omegas: np.ndarray, max_denominator: int = 64) -> tuple[float, bool]:
    """A common period of cos(ω_j t) terms and whether the frequencies are commensurate.

    Frequency ratios are matched to fractions with denominators ≤ ``max_denominator``
    (relative error 1e-12); otherwise returns 200 periods of the slowest term and False.
    """
    w = np.asarray([x for x in omegas if x > 0.0], dtype=float)
    if w.size == 0:
        return 1.0, True
    base = float(np.min(w))
    denoms = []
    for x in w / base:
        fr = Fraction(float(x)).limit_denominator(max_denominator)
        if abs(float(fr) - x) > 1e-12 * x:
            return 200 * 2 * np.pi / base, False
        denoms.append(fr.denominator)
    lcm = int(np.lcm.reduce(np.array(denoms, dtype=np.int64)))
    return 2 * np.pi * lcm / base, True


def _sup_norm(f: Callable, t0: float, t1: float, samples: int) -> tuple[float, float]:
    """sup_{t∈[t0,t1]} ‖f(t)‖₂ by sampling and local refinement; returns (sup, argmax t)."""
    t = np.linspace(t0, t1, samples + 1)
    vals = np.linalg.norm(np.atleast_2d(np.asarray(f(t), dtype=float)).reshape(t.size, -1), axis=1)
    best_v, best_t = float(vals.max()), float(t[int(vals.argmax())])
    dt = (t1 - t0) / samples
    for i in np.argsort(vals)[-5:]:
        lo, hi = max(t0, t[i] - dt), min(t1, t[i] + dt)
        if hi <= lo:
            continue
        res = minimize_scalar(lambda s: -float(np.linalg.norm(np.asarray(f(s), dtype=float))),
                              bounds=(lo, hi), method="bounded", options={"xatol": 1e-12 * max(1.0, hi)})
        if -res.fun > best_v:
            best_v, best_t = float(-res.fun), float(res.x)
    return best_v, best_t


def check_forcing_bounded(forcing: Harmonic | Callable, *, f_max: float | None = None,
                          samples_per_period: int = 4096, horizon: float = 10.0, windows: int = 5,
                          growth_tol: float = 0.05, tolerance: float = 1e-9) -> CheckResult:
    """Assumption A2: ``sup_t ‖f(t)‖ ≤ f_max < ∞``.

    Parameters
    ----------
    forcing : Harmonic or callable
        A :class:`~observer.model.Harmonic` (analytic bound) or any ``f(t) -> ndarray``
        accepting a scalar or an array of times (shape (len(t), n) for arrays).
    f_max : float, optional
        The bound the user claims; default: the analytic bound U (harmonic forcing).
    samples_per_period, horizon, windows, growth_tol
        Sampling settings; for a generic callable the sup over ``[0, horizon·2^j]``,
        j < windows, may grow by at most ``growth_tol`` (relative) in the last doubling.
    tolerance : float
        Relative tolerance on ``S ≤ f_max``.

    Returns
    -------
    CheckResult
        Harmonic: ``margin = 1 − S/f_max`` with S the sup over one period and f_max the
        given bound or U. Generic: ``margin = 1 − S/f_max`` if f_max is given, else
        ``−(S_last/S_previous − 1)`` (relative growth of the sup in the last doubling of the
        window) with tolerance ``growth_tol``. The witness has S, U, the time of the sup
        and the value f(t*).
    """
    keys = ("sup_norm", "analytic_bound", "f_max", "t_star", "period")
    if isinstance(forcing, Harmonic):
        U = float(np.linalg.norm(forcing.bound()))
        T, commensurate = common_period(forcing.omega)
        S, t_star = _sup_norm(forcing, 0.0, T, samples_per_period * (1 if commensurate else 200))
        bound = U if f_max is None else float(f_max)
        witness = {"sup_norm": S, "analytic_bound": U, "f_max": bound, "t_star": t_star,
                   "f_at_t_star": forcing(t_star), "period": T, "commensurate": commensurate,
                   "componentwise_bound": forcing.bound()}
        if not np.isfinite(U):
            return CheckResult(NAME, False, -np.inf, tolerance, witness, "forcing amplitudes are not finite",
                               EQUATION, keys, evidence="violated")
        margin = 1.0 - S / bound if bound > 0 else (0.0 if S == 0 else -np.inf)
        reason = "" if commensurate else "incommensurate frequencies: sup sampled over 200 slow periods"
        # A2 itself (sup < ∞, and ≤ f_max when f_max ≥ U) follows from the analytic bound U;
        # a smaller f_max is only compared with the sampled sup
        proved = bound >= U
        return CheckResult.from_margin(NAME, margin, tolerance, witness, EQUATION, keys, reason,
                                       evidence="proved" if proved else "sampled",
                                       verdict=(f"sup‖f‖ ≤ U = {U:.4g} (analytic bound)" if proved else
                                                f"sampled sup {S:.4g} vs f_max {bound:.4g}"))
    sups, lengths = [], []
    for j in range(windows):
        length = horizon * 2 ** j
        S, t_star = _sup_norm(forcing, 0.0, length, samples_per_period * 2 ** j)
        sups.append(S)
        lengths.append(length)
    witness = {"sup_norm": sups[-1], "analytic_bound": float("nan"), "f_max": f_max, "t_star": t_star,
               "window_lengths": lengths, "window_sups": sups}
    if f_max is not None:
        return CheckResult.from_margin(NAME, 1.0 - sups[-1] / float(f_max), tolerance, witness, EQUATION,
                                       keys, "no analytic bound: sup sampled over a window", evidence="sampled")
    growth = sups[-1] / sups[-2] - 1.0 if sups[-2] > 0 else (0.0 if sups[-1] == 0 else np.inf)
    witness["growth_last_doubling"] = growth
    reason = "no analytic bound: sup sampled over doubling windows"
    if growth > growth_tol:
        reason = f"sup‖f‖ keeps growing with the window ({sups[0]:.3g} → {sups[-1]:.3g}): unbounded"
    return CheckResult.from_margin(NAME, -growth, growth_tol, witness, EQUATION,
                                   ("sup_norm", "growth_last_doubling", "t_star"), reason, evidence="sampled")
