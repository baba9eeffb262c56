"""The error norm of the work-precision and hard suites, below both (:mod:`bench.runners`,
:mod:`bench.hard`): on the recorded rows t_k, ``e_k = max_i |q_i(t_k) − q_ref,i(t_k)|``."""

from __future__ import annotations

import numpy as np


def trajectory_error(t: np.ndarray, q: np.ndarray, q_ref: np.ndarray) -> dict[str, float]:
    """``err_mean`` (time average of the max-over-coordinates error), ``err_max``, ``err_end``."""
    e = np.max(np.abs(q - q_ref), axis=1)
    T = t[-1] - t[0]
    return {"err_mean": float(np.trapezoid(e, t) / T), "err_max": float(e.max()),
            "err_end": float(e[-1])}
