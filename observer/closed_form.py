"""Closed-form solutions of the built-in scenarios' masters (their ``reference`` metadata).

* :func:`ball_position` — the Zeno bouncing ball (docs/theory/oracles.md §1): piecewise parabolas between
  the closed-form impact times, q = 0 after the accumulation time t_∞.
* :class:`ExactImpactOscillator` — the undamped forced impact oscillator
  ``ẍ + x = A cos(ωt + φ)`` for ``x ≤ σ`` with ``ẋ⁺ = −r ẋ⁻``: free flight in closed form,
  impacts located by a scan + ``brentq`` to 1e-14 (event-driven exact solution).

Each scenario module that has one exposes it as ``reference(scenario, t)``
(:func:`observer.scenarios.info`); the work-precision suite measures errors against it
(:func:`closed_form_position`). The closed forms themselves live in the leaf module
:mod:`observer.scenarios.exact` (the scenario modules import them; this module sits above
the registry) and are re-exported here.
"""

from __future__ import annotations

import numpy as np

from observer.scenarios import SCENARIOS, info
from observer.scenarios.exact import (ExactImpactOscillator, accumulation_time, ball_position,  # noqa: F401
                                      ball_reference, impact_times, oscillator_reference)


def closed_form_position(scenario, t: np.ndarray) -> np.ndarray | None:
    """Exact master position q(t) (shape (N, n)) of a loaded built-in scenario if its module
    declares a closed form (``reference``), else None."""
    if scenario.name not in SCENARIOS or info(scenario.name).reference is None:
        return None
    return info(scenario.name).reference(scenario, t)
