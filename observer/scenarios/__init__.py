"""Built-in scenarios, each a small module that builds its system from physical parameters.

Every module defines ``DESCRIPTION`` (one line), ``PARAMETERS`` (defaults) and
``document(**params) -> dict`` (a scenario document, see :mod:`observer.scenario`).
:data:`SCENARIOS` maps the stable names to the modules.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

from observer.errors import InputError
from observer.scenarios import (bouncing_ball, double_mass, grazing, impact_oscillator,
                                rocking_chain)

SCENARIOS: dict[str, ModuleType] = {
    "double_mass": double_mass,
    "rocking_chain": rocking_chain,
    "bouncing_ball": bouncing_ball,
    "impact_oscillator": impact_oscillator,
    "grazing": grazing,
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
