"""Impact laws (paper eqs. (5)-(6), (9)): generalized Newton and Poisson (Glocker's inequality form).

For a closed set A with Delassus matrix G = W_Aᵀ M⁻¹ W_A (SPD), pre-impact contact
velocity γ⁻ and impulse Λ ≥ 0, the post-impact velocity is γ⁺ = γ⁻ + GΛ.

* Newton: ``0 ≤ γ⁺ + e∘γ⁻ ⊥ Λ ≥ 0``, i.e. LCP(G, (1+e)∘γ⁻).
* Poisson (inequality form, Glocker 2013): compression ``0 ≤ γ_C ⊥ Λ_C ≥ 0`` with
  γ_C = γ⁻ + GΛ_C, then expansion ``0 ≤ γ_E ⊥ Λ_E − ε∘Λ_C ≥ 0`` with γ_E = γ_C + GΛ_E,
  solved as LCP(G, γ_C + G(ε∘Λ_C)) in μ = Λ_E − ε∘Λ_C; Λ = (1+ε)∘Λ_C + μ, γ⁺ = γ_E ≥ 0.

For one contact the two coincide exactly.

:data:`IMPACT_LAWS` is the registry: each :class:`ImpactLawDefinition` carries the law's
impact map (the continuous law on (G, γ⁻), which the event-driven integrator and the proof
checks call), its step map (the discrete impulse of one Moreau–Jean step, which both
time-stepping engines realise), the integer code of the compiled kernel (None: the kernel
does not have it) and the facts the engines consult (:mod:`observer.engines`): whether it is
Newton's law on one closed contact (the kernel assumes so), whether the event-driven engine
runs it and how it acts there on a closed set with separating contacts. A new law is one
function pair plus one registry entry; an engine that lacks it refuses it by name.

:func:`poisson_step` is the discrete Poisson step of :mod:`observer.stepping`: Glocker's law
with the step's Delassus matrix on the step's pre-impact velocity, equal to the discrete
Newton step for one contact.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from observer.errors import InputError
from observer.validation import broadcast_vector

if TYPE_CHECKING:                    # a type only: the model layer imports no contact solver
    from observer.contact.lcp import LCPSolution

NEWTON, POISSON = 0, 1
"""The compiled kernel's integer codes of the built-in laws."""

KERNEL_LAWS = {NEWTON: "newton", POISSON: "poisson"}
"""The law paths the compiled kernel implements: code → the law it computes."""

EVENT_CLOSED_SETS = ("all", "approaching")

Solve = Callable[[np.ndarray, np.ndarray], "LCPSolution"]
ImpactMap = Callable[[np.ndarray, np.ndarray, np.ndarray, Solve], np.ndarray]
StepMap = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Solve],
                   tuple[np.ndarray, np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class ImpactLawDefinition:
    """One registered impact law.

    Attributes
    ----------
    name : str
    impact_map : callable ``(G, γ⁻, e, solve) -> Λ``
        The impact law on a closed set with Delassus matrix G (paper eqs. (5)/(6)).
    step_map : callable ``(Ĝ, γ_free, γ_k, e, solve) -> (P, Λ_C, Λ_E)``
        The impulse of one time step with the step's Delassus matrix Ĝ (Λ_C, Λ_E the phases
        where the law has them, else empty).
    code : int or None
        Integer code of the compiled kernel's path for this law (:data:`KERNEL_LAWS`); None:
        the kernel does not have it (the compiled engine refuses it).
    description : str
    is_newton : bool
        The step is Newton's discrete law ``0 ≤ γ_{k+1} + e∘γ_k ⊥ P ≥ 0`` on any closed set
        (the engines then judge a step by Newton's recomputed residual).
    single_contact_is_newton : bool
        On one closed contact the law is Newton's (impact and step map): the compiled kernel
        computes every one-contact step in Newton's closed form, and the event engine's Zeno
        tail uses Newton's hop sequence. A law with a kernel code must declare it (else the
        compiled engine refuses it).
    event_engine : bool
        The event-driven engine runs it (through ``impact_map``); False: it refuses the law.
    event_closed_set : {"all", "approaching"}
        How the event engine's observers apply the impact map on a closed set I with some
        separating contacts (γ_i⁻ > 0): ``"all"`` on I (the map keeps γ⁺ ≥ 0 by construction,
        as Poisson's inequality form does); ``"approaching"`` on J = {γ_i⁻ ≤ 0}, a separating
        contact the impulse drives below 0 joining J with e = 0 (Newton's law would else
        let it leave with γ⁺ = −eγ⁻ < 0).
    """

    name: str
    impact_map: ImpactMap
    step_map: StepMap
    code: int | None
    description: str
    is_newton: bool = False
    single_contact_is_newton: bool = False
    event_engine: bool = True
    event_closed_set: str = "all"

    def __post_init__(self):
        if self.event_closed_set not in EVENT_CLOSED_SETS:
            raise InputError("impact.law", f"{self.name}: event_closed_set must be one of "
                             f"{list(EVENT_CLOSED_SETS)}, got {self.event_closed_set!r}")

    def newton_on(self, closed: int) -> bool:
        """True when a step on ``closed`` closed contacts is Newton's discrete law (its
        recomputed residual then judges the step)."""
        return self.is_newton or (closed == 1 and self.single_contact_is_newton)


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
        if not isinstance(law, str) or law not in IMPACT_LAWS:
            raise InputError("impact.law", f"must be one of {list(IMPACT_LAWS)}, got {law!r}")
        e = broadcast_vector("impact.restitution", restitution, m)
        if np.any(e < 0.0) or np.any(e > 1.0):
            raise InputError("impact.restitution", f"must lie in [0, 1], got {e.tolist()}")
        e.setflags(write=False)
        return ImpactLaw(law, e)

    @property
    def definition(self) -> ImpactLawDefinition:
        """The registered law (:data:`IMPACT_LAWS`)."""
        return IMPACT_LAWS[self.law]

    @property
    def code(self) -> int | None:
        """Integer code of the compiled kernel's path (None: the kernel does not have it)."""
        return self.definition.code

    @property
    def is_global(self) -> bool:
        """True when every contact has the same restitution (the monotone case of A3)."""
        return bool(np.all(self.restitution == self.restitution[0]))


def newton_impact(G: np.ndarray, gamma_minus: np.ndarray, e: np.ndarray, solve: Solve) -> np.ndarray:
    """Generalized Newton impulse (paper eq. (5)): solve ``0 ≤ γ⁻ + GΛ + e∘γ⁻ ⊥ Λ ≥ 0`` for Λ."""
    return solve(G, (1.0 + e) * gamma_minus).x


def poisson_phases(G: np.ndarray, gamma_minus: np.ndarray, eps: np.ndarray,
                   solve: Solve) -> tuple[np.ndarray, np.ndarray]:
    """Compression and expansion impulses (Λ_C, Λ_E) of Poisson's law (paper eq. (6), Glocker's form).

    Compression ``0 ≤ γ_C ⊥ Λ_C ≥ 0`` with ``γ_C = γ⁻ + GΛ_C``; expansion
    ``0 ≤ γ_E ⊥ Λ_E − ε∘Λ_C ≥ 0`` with ``γ_E = γ_C + GΛ_E``, solved as the LCP in
    ``μ = Λ_E − ε∘Λ_C``: ``0 ≤ Gμ + (γ_C + G(ε∘Λ_C)) ⊥ μ ≥ 0``.

    For one contact the closed form is used: ``Λ_C = max(0, −γ⁻/G)``, ``Λ_E = εΛ_C``
    (so that ``γ_E = −εγ⁻`` for γ⁻ < 0, Newton's value).
    """
    if gamma_minus.shape[0] == 1:
        lam_c = np.maximum(-gamma_minus / G[0, 0], 0.0)
        return lam_c, eps * lam_c
    lam_c = solve(G, gamma_minus).x
    gamma_c = gamma_minus + G @ lam_c
    mu = solve(G, gamma_c + G @ (eps * lam_c)).x
    return lam_c, eps * lam_c + mu


def poisson_impact(G: np.ndarray, gamma_minus: np.ndarray, eps: np.ndarray, solve: Solve) -> np.ndarray:
    """Generalized Poisson impulse Λ = Λ_C + Λ_E in Glocker's inequality form (:func:`poisson_phases`)."""
    lam_c, lam_e = poisson_phases(G, gamma_minus, eps, solve)
    return lam_c + lam_e


def poisson_step(G: np.ndarray, gamma_free: np.ndarray, gamma_k: np.ndarray, eps: np.ndarray,
                 solve: Solve) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Impulse of the discrete Poisson step: Glocker's law with the step's Delassus matrix.

    The step's pre-impact velocity is ``γ̃ = (γ_free + ε∘γ_k)/(1+ε)``; the impulse is
    ``P = Λ_C + Λ_E`` with (Λ_C, Λ_E) = :func:`poisson_phases` (G, γ̃, ε), so that
    ``0 ≤ γ̃ + GΛ_C ⊥ Λ_C ≥ 0`` and ``0 ≤ γ̃ + GP ⊥ Λ_E − ε∘Λ_C ≥ 0`` hold exactly. Newton's
    discrete law is ``P = LCP(G, γ_free + e∘γ_k) = LCP(G, (1+e)∘γ̃)``, the Newton map on the same
    γ̃; for one contact the two maps coincide, and the one-contact impulse is returned in
    Newton's closed form ``max(0, −(γ_free + εγ_k)/G)`` (bitwise the Newton step).

    Returns
    -------
    P, lam_c, lam_e : ndarray
    """
    if gamma_k.shape[0] == 1:
        b = gamma_free + eps * gamma_k
        P = np.array([-b[0] / G[0, 0]]) if b[0] < 0.0 else np.zeros(1)
        lam_c = P / (1.0 + eps)
        return P, lam_c, P - lam_c
    gamma_t = (gamma_free + eps * gamma_k) / (1.0 + eps)
    lam_c, lam_e = poisson_phases(G, gamma_t, eps, solve)
    return lam_c + lam_e, lam_c, lam_e


def newton_step(G: np.ndarray, gamma_free: np.ndarray, gamma_k: np.ndarray, e: np.ndarray,
                solve: Solve) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Impulse of the discrete Newton step (Siconos' law ``0 ≤ γ_{k+1} + e∘γ_k ⊥ P ≥ 0``):
    ``P = LCP(G, γ_free + e∘γ_k)``; no phases (empty Λ_C, Λ_E)."""
    return solve(G, gamma_free + e * gamma_k).x, np.zeros(0), np.zeros(0)


IMPACT_LAWS: dict[str, ImpactLawDefinition] = {d.name: d for d in (
    ImpactLawDefinition("newton", newton_impact, newton_step, NEWTON,
                        "generalized Newton: 0 ≤ γ⁺ + e∘γ⁻ ⊥ Λ ≥ 0 (eq. (5))", is_newton=True,
                        single_contact_is_newton=True, event_closed_set="approaching"),
    ImpactLawDefinition("poisson", poisson_impact, poisson_step, POISSON,
                        "generalized Poisson, Glocker's inequality form (eq. (6))",
                        single_contact_is_newton=True),
)}
"""Registry of impact laws: name → :class:`ImpactLawDefinition`."""

LAWS = tuple(IMPACT_LAWS)
"""The registered law names (derived from :data:`IMPACT_LAWS`)."""


def impact(law: ImpactLaw, G: np.ndarray, gamma_minus: np.ndarray, active: np.ndarray,
           solve: Solve) -> np.ndarray:
    """Impulse Λ of ``law`` on the contacts ``active`` (index array) for Delassus matrix G."""
    return law.definition.impact_map(G, gamma_minus, law.restitution[active], solve)
