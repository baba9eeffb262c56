"""Built-in scenarios, each a small module that builds its system from physical parameters.

Every module defines ``DESCRIPTION`` (one line), ``PARAMETERS`` (defaults) and
``document(**params) -> dict`` (a scenario document, see :mod:`observer.scenario`), and may
declare its metadata (read by :func:`info`, with defaults):

* ``PLOT`` — ``dict(dof=0, contact=0, labels=("q (m)", "gap (m)"))``: the coordinate and
  contact the figures draw, and their axis labels;
* ``reference(scenario, t) -> q`` and ``REFERENCE_TEXT`` — a closed form of the master, if
  one exists (the work-precision suite measures errors against it);
* ``NOTES`` — what the scenario shows, for the report;
* ``SUITE`` — its default benchmark settings: ``observers`` (a list of case settings:
  ``label``, ``params``, ``h`` and ``t_end`` as (quick, full) pairs, ``slave_offset``),
  ``work_precision`` (``h0``, ``t_end``, ``targets``, and optionally ``params``: builder
  overrides of the sweep, ``sizes``: ``dict(quick=…, full=…)`` step sizes), ``checks`` (``"quick"``: in every
  suite, ``"full"``: only in the full one, ``None``: never), ``exact`` (False: no observer
  rows of the exact event-driven integrator, e.g. for dense impact clusters).

:data:`SCENARIOS` maps the stable names to the modules: adding a scenario is one module
plus one entry there, and every list of scenarios (CLI, proof checks, suites, report)
derives from it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, Callable

from observer.errors import InputError
from observer.scenarios import (bouncing_ball, double_mass, grazing, impact_oscillator,
                                random_system, rocking_chain)

SCENARIOS: dict[str, ModuleType] = {
    "double_mass": double_mass,
    "rocking_chain": rocking_chain,
    "bouncing_ball": bouncing_ball,
    "impact_oscillator": impact_oscillator,
    "grazing": grazing,
    "random_system": random_system,
}


def builtin_document(name: str, params: dict[str, Any] | None = None) -> dict:
    """Document of built-in scenario ``name`` with builder parameters ``params`` overridden."""
    module = SCENARIOS[name]
    params = dict(params or {})
    for key in params:
        if key not in module.PARAMETERS:
            raise InputError(f"param.{key}", f"unknown parameter of scenario {name!r} "
                             f"(known: {', '.join(module.PARAMETERS)})")
        default = module.PARAMETERS[key]
        if isinstance(default, (int, float)) and not isinstance(default, bool):
            if isinstance(params[key], bool) or not isinstance(params[key], (int, float)):
                raise InputError(f"param.{key}", f"must be a number, got {params[key]!r}")
    return module.document(**params)


@dataclass(frozen=True)
class ScenarioInfo:
    """What a scenario module declares about itself (see the module docstring)."""

    name: str
    description: str
    parameters: dict
    dof: int = 0
    contact: int = 0
    labels: tuple[str, str] = ("q (m)", "gap (m)")
    reference: Callable | None = None
    reference_text: str = ""
    notes: str = ""
    suite: dict = field(default_factory=dict)


DEFAULT_SUITE = {"observers": [{}], "work_precision": None, "checks": "quick"}
"""Benchmark settings of a scenario that declares none: one observers case at its own h and
t_end, no work-precision sweep, its proof checks in every suite."""


def info(name: str) -> ScenarioInfo:
    """The metadata of built-in scenario ``name``."""
    if name not in SCENARIOS:
        raise InputError("scenario", f"unknown scenario {name!r}; choose from {', '.join(SCENARIOS)}")
    mod = SCENARIOS[name]
    plot = {"dof": 0, "contact": 0, "labels": ("q (m)", "gap (m)"), **getattr(mod, "PLOT", {})}
    suite = {**DEFAULT_SUITE, **getattr(mod, "SUITE", {})}
    return ScenarioInfo(name, mod.DESCRIPTION, dict(mod.PARAMETERS), int(plot["dof"]),
                        int(plot["contact"]), tuple(plot["labels"]), getattr(mod, "reference", None),
                        getattr(mod, "REFERENCE_TEXT", ""), getattr(mod, "NOTES", ""), suite)
