"""observer: impact-time state observers for linear multibody systems with unilateral contacts.

Public API (a contract relied on by the benchmarks, reports and users):

* :func:`load_scenario` — a built-in scenario by name or a TOML file, with overrides;
* :func:`simulate` — Moreau–Jean simulation of the master and its observers;
* :func:`ensemble` — n observers per design from n initial errors against one master run;
* :func:`compare` — paired designs against several masters: rate ratio, censored settling, floors;
* :func:`uncertainty_ensemble` — the designs' floors over plants drawn from a model uncertainty;
* :data:`SCENARIOS`, :data:`OBSERVER_DESIGNS`, :data:`IMPACT_LAWS`, :data:`CONTACT_SOLVERS`, :data:`ENGINES` —
  registries (add an entry, and it runs everywhere);
* :class:`LinearSystem`, :class:`ImpactLaw`, :class:`Scenario`, :class:`MoreauJean`,
  :class:`SimulationResult`, :class:`Slave`.
"""

from observer.compare import Comparison, compare
from observer.contact import CONTACT_SOLVERS
from observer.engines import ENGINES
from observer.ensemble import ensemble
from observer.errors import ContactSolverError, InputError
from observer.impact import IMPACT_LAWS, ImpactLaw
from observer.model import Harmonic, LinearSystem
from observer.observers import OBSERVER_DESIGNS, ObserverDesign, Slave, lyapunov
from observer.result import SimulationResult, read_frame, read_result
from observer.scenario import Scenario
from observer.scenarios import SCENARIOS
from observer.simulate import load_scenario, simulate
from observer.stepping import MoreauJean
from observer.uncertainty import uncertainty_ensemble
from observer.version import __version__

__all__ = ["CONTACT_SOLVERS", "ContactSolverError", "ENGINES", "Harmonic", "IMPACT_LAWS", "ImpactLaw", "InputError",
           "LinearSystem", "MoreauJean", "OBSERVER_DESIGNS", "ObserverDesign", "SCENARIOS", "Scenario", "SimulationResult",
           "Slave", "Comparison", "compare", "ensemble", "load_scenario", "lyapunov", "read_frame", "read_result", "simulate", "uncertainty_ensemble",
           "__version__"]
