"""Scenarios shared by several test files (tests/ is on pytest's pythonpath)."""

from __future__ import annotations

import dataclasses

import numpy as np

from observer.model import LinearSystem
from observer.scenario import Scenario


def nearly_redundant_contacts(t_end: float = 0.6) -> Scenario:
    """A point mass whose two contacts are parallel to 1e-9: their Delassus matrix rounds to
    an exactly singular one, which the kernel's Cholesky-based pivoting refuses (status
    LCP_FAILED), while the python engine's pivoting solver passes it to Lemke. Validation
    refuses such a W (σ_min/σ_max ≤ √ε), so the system is built unchecked here, to exercise
    the kernel's fallback path."""
    sc = Scenario.from_dict({
        "system": {"M": [[1.0, 0.0], [0.0, 1.0]], "C": [[0.0, 0.0], [0.0, 0.0]],
                   "K": [[0.0, 0.0], [0.0, 0.0]], "W": [[1.0, 1.0], [0.0, 1e-3]],
                   "forcing": {"constant": [-9.81, 0.0]}, "gap": {"offset": [0.0, 0.0]}},
        "impact": {"law": "newton", "restitution": 0.5},
        "initial": {"q": [0.2, 0.0], "u": [0.0, 0.0]},
        "simulation": {"h": 1e-3, "t_end": t_end}}, "nearly redundant")
    s = sc.system
    W = np.array([[1.0, 1.0], [0.0, 1e-9]])
    return dataclasses.replace(sc, system=LinearSystem(s.M, s.C, s.K, W, s.forcing, s.gap, check=False))
