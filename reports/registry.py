"""The toolkit's registries as the report sees them — the one place the report learns which
observer designs, ratios, thresholds, scenarios and contact solvers exist.

Every section iterates over these functions instead of naming designs or solvers, so a design
added to :data:`observer.observers.OBSERVER_DESIGNS` (or a solver added to
:data:`observer.contact.CONTACT_SOLVERS`) shows in the report without touching ``reports/``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

from observer import metrics
from observer.contact import CONTACT_SOLVERS
from observer.scenarios import SCENARIOS, info

from observer.observers import OBSERVER_DESIGNS, RATIOS

MASTER = "master"
"""Name of the observed system in trajectories and work-precision rows."""
REFERENCE_SOLVER = "reference"
"""The contact solver the others are compared with (cvxpy + OSQP)."""


def rhos() -> tuple[float, ...]:
    """The synchronization thresholds ρ (the one list, :data:`observer.metrics.RHOS`)."""
    return tuple(metrics.RHOS)


def settle_column(rho: float) -> str:
    """Row column of the settling time below ρ·V(t_on) (named by :mod:`observer.metrics`)."""
    return metrics.settle_column(rho)


def sync_column(rho: float) -> str:
    """Row column of the first-passage time to ρ·V(t_on) (named by :mod:`observer.metrics`)."""
    return metrics.sync_column(rho)


def above_column(rho: float) -> str:
    """Row column: fraction of the window samples after the first passage with V back above
    ρ·V(t_on) (named by :mod:`observer.metrics`)."""
    return metrics.above_column(rho)


@dataclass(frozen=True)
class Look:
    """How a figure or table shows one system: label, colour and line style."""

    name: str
    label: str
    color: str
    linestyle: str

    @property
    def description(self) -> str:
        """Colour and line style in words ("blue, dashed")."""
        styles = {"-": "solid", "--": "dashed", ":": "dotted", "-.": "dash-dotted"}
        return f"{self.color.replace('tab:', '')}, {styles.get(self.linestyle, self.linestyle)}"


def look(name: str) -> Look:
    """The look of ``name``: the master, a registered design, or a grey fallback."""
    if name == MASTER:
        return Look(MASTER, "master", "black", "-")
    d = OBSERVER_DESIGNS.get(name)
    if d is None:
        return Look(name, name, "0.5", "-")
    return Look(name, d.label, d.color, d.linestyle)


def label(name: str) -> str:
    """Display label of an observer design (or of the master)."""
    return look(name).label


def design(name: str):
    """The registered design ``name`` (its ``position_jumps``, ``metric``, ``label``, …)."""
    return OBSERVER_DESIGNS[name]


def designs() -> tuple[str, ...]:
    """Registered observer designs, in registry order."""
    return tuple(OBSERVER_DESIGNS)


def in_registry_order(names: Iterable[str]) -> list[str]:
    """``names`` (without repeats) sorted by registry order; unregistered names last."""
    order = {n: i for i, n in enumerate(OBSERVER_DESIGNS)}
    uniq = list(dict.fromkeys(names))
    return sorted(uniq, key=lambda n: (order.get(n, len(order)), uniq.index(n)))


def ratio_pairs() -> tuple[tuple[str, str], ...]:
    """Declared (baseline, candidate) pairs: the report shows t_baseline / t_candidate."""
    return tuple(RATIOS)


def k_metric_design() -> str:
    """The design the paper analyses: position jumps projected in the metric of K."""
    return next(n for n, d in OBSERVER_DESIGNS.items() if d.position_jumps and d.metric == "K")


def jump_designs() -> tuple[str, ...]:
    """Designs with position jumps (any projection metric), in registry order."""
    return tuple(n for n, d in OBSERVER_DESIGNS.items() if d.position_jumps)


def contact_solvers() -> tuple[str, ...]:
    """Registered contact solvers, in registry order."""
    return tuple(CONTACT_SOLVERS)


def fast_solvers() -> tuple[str, ...]:
    """Contact solvers compared against :data:`REFERENCE_SOLVER`."""
    return tuple(s for s in CONTACT_SOLVERS if s != REFERENCE_SOLVER)


def scenario_description(name: str) -> str:
    """One-line description of a scenario ('' for one that is not registered)."""
    return info(name).description if name in SCENARIOS else ""


def plot_labels(name: str, dof: int, contact: int) -> tuple[str, str]:
    """Axis labels (coordinate, gap) of a scenario's figure (``info(name).labels``); generic
    ones for a scenario that is not registered."""
    if name in SCENARIOS:
        return tuple(info(name).labels)[:2]
    return f"q{dof}", f"gap g{contact} (m)"


def scenario_notes(name: str) -> str:
    """The scenario's own notes (what is drawn, what to watch), '' when it has none."""
    return info(name).notes if name in SCENARIOS else ""


def default_integrator() -> str:
    """The integrator a suite case uses unless it says otherwise: the first of
    :data:`observer.engines.INTEGRATORS` (the default of ``bench.suites.Case``)."""
    from observer.engines import INTEGRATORS

    return INTEGRATORS[0]


def is_default_integrator(value) -> bool:
    """Whether a row's ``integrator`` is the suites' default one (missing counts as default)."""
    default = default_integrator()
    return value is None or value != value or value in ("", default)
