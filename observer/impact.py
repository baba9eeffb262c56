"""Impact laws (paper eqs. (5)-(6), (9)): generalized Newton and Poisson (Glocker's inequality form).

For a closed set A with Delassus matrix G = W_Aᵀ M⁻¹ W_A (SPD), pre-impact contact
velocity γ⁻ and impulse Λ ≥ 0, the post-impact velocity is γ⁺ = γ⁻ + GΛ.

* Newton: ``0 ≤ γ⁺ + e∘γ⁻ ⊥ Λ ≥ 0``, i.e. LCP(G, (1+e)∘γ⁻).
* Poisson (inequality form, Glocker 2013): compression ``0 ≤ γ_C ⊥ Λ_C ≥ 0`` with
  γ_C = γ⁻ + GΛ_C, then expansion ``0 ≤ γ_E ⊥ Λ_E − ε∘Λ_C ≥ 0`` with γ_E = γ_C + GΛ_E,
  solved as LCP(G, γ_C + G(ε∘Λ_C)) in μ = Λ_E − ε∘Λ_C; Λ = (1+ε)∘Λ_C + μ, γ⁺ = γ_E ≥ 0.

For one contact the two coincide exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from observer.contact.lcp import LCPSolution
from observer.errors import InputError
from observer.validation import broadcast_vector

LAWS = ("newton", "poisson")
NEWTON, POISSON = 0, 1

Solve = Callable[[np.ndarray, np.ndarray], LCPSolution]


@dataclass(frozen=True)
class ImpactLaw:
    """Impact law and restitution coefficients, one per contact.

    Parameters
    ----------
    law : {"newton", "poisson"}
    restitution : ndarray, shape (m,)
        Coefficients in [0, 1] (a scalar is broadcast by :meth:`build`).
    """

    law: str
    restitution: np.ndarray

    @staticmethod
    def build(law: Any, restitution: Any, m: int) -> "ImpactLaw":
        """Validate the law name and broadcast/validate the restitution to m contacts."""
        if law not in LAWS:
            raise InputError("impact.law", f"must be one of {list(LAWS)}, got {law!r}")
        e = broadcast_vector("impact.restitution", restitution, m)
        if np.any(e < 0.0) or np.any(e > 1.0):
            raise InputError("impact.restitution", f"must lie in [0, 1], got {e.tolist()}")
        e.setflags(write=False)
        return ImpactLaw(law, e)

    @property
    def code(self) -> int:
        """Integer code used inside the time loop (NEWTON = 0, POISSON = 1)."""
        return NEWTON if self.law == "newton" else POISSON

    @property
    def is_global(self) -> bool:
        """True when every contact has the same restitution (the monotone case of A3)."""
        return bool(np.all(self.restitution == self.restitution[0]))


def newton_impact(G: np.ndarray, gamma_minus: np.ndarray, e: np.ndarray, solve: Solve) -> np.ndarray:
    """Generalized Newton impulse: solve ``0 ≤ γ⁻ + GΛ + e∘γ⁻ ⊥ Λ ≥ 0`` for Λ."""
    return solve(G, (1.0 + e) * gamma_minus).x


def poisson_impact(G: np.ndarray, gamma_minus: np.ndarray, eps: np.ndarray, solve: Solve) -> np.ndarray:
    """Generalized Poisson impulse in Glocker's inequality form (compression, then expansion)."""
    lam_c = solve(G, gamma_minus).x
    gamma_c = gamma_minus + G @ lam_c
    mu = solve(G, gamma_c + G @ (eps * lam_c)).x
    return (1.0 + eps) * lam_c + mu


def impact(law: ImpactLaw, G: np.ndarray, gamma_minus: np.ndarray, active: np.ndarray,
           solve: Solve) -> np.ndarray:
    """Impulse Λ of ``law`` on the contacts ``active`` (index array) for Delassus matrix G."""
    e = law.restitution[active]
    fn = newton_impact if law.code == NEWTON else poisson_impact
    return fn(G, gamma_minus, e, solve)
