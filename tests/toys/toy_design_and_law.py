"""A toy observer design and a toy impact law (each one definition plus one registry entry)."""

import numpy as np

from observer.impact import ImpactLawDefinition, newton_impact, newton_step
from observer.observers import ObserverDesign

TOY_DESIGN = ObserverDesign("toy_jump", True, "identity", "toy (identity metric)", "tab:olive", "--")


def plastic_impact(G, gamma_minus, e, solve):
    """Newton's map with every restitution set to 0 (perfectly plastic)."""
    return newton_impact(G, gamma_minus, np.zeros_like(e), solve)


def plastic_step(Ghat, gamma_free, gamma_k, e, solve):
    return newton_step(Ghat, gamma_free, gamma_k, np.zeros_like(e), solve)


TOY_LAW = ImpactLawDefinition("toy_plastic", plastic_impact, plastic_step, None,
                              "toy: perfectly plastic whatever the restitution")
