"""Moved: each time-stepping engine owns its loop. What the loops share is
:mod:`observer.engines.loop`; the compiled engine's driver and bundles are
:mod:`observer.engines.compiled.driver` and :mod:`observer.engines.compiled.bundles`, the numpy
engine's loop :mod:`observer.engines.python`. This module keeps ``observer.loop.NAME`` and
:func:`run` working for code written against the old layout.
"""

from __future__ import annotations

import observer.engines.compiled.bundles as _bundles
import observer.engines.compiled.driver as _driver
import observer.engines.loop as _loop
import observer.engines.python as _python
from observer.engines import ENGINES as _REGISTRY
from observer.engines import check_engine_name
from observer.engines.timestepping import TimeStepping
from observer.errors import InputError

_HOMES = (_loop, _driver, _bundles, _python)
_RENAMED = {"_Stopper": "Stopper", "_emitter": "emitter", "_finish": "finish", "_allocate": "allocate_records",
            "_python_step": "python_step", "_stop_text": "stopped_text", "_run_compiled": "run_compiled",
            "_CompiledRun": "CompiledRun", "_fallback_step": "fallback_step",
            "_reference_stepper": "reference_stepper", "_run_python": "run_python"}


def _stepping_engines() -> tuple[str, ...]:
    """The registered time-stepping engines' names, in the registry's order."""
    return tuple(name for name, e in _REGISTRY.items() if isinstance(e, TimeStepping))


def __getattr__(name: str):
    """``NAME`` from its new home; ``ENGINES``: the registry's time-stepping engines."""
    if name == "ENGINES":
        return _stepping_engines()
    name = _RENAMED.get(name, name)
    for home in _HOMES:
        if name in vars(home):
            return vars(home)[name]
    raise AttributeError(f"module 'observer.loop' has no attribute {name!r}")


def run(inp, engine: str = "compiled", record_every: int = 1, record_pre: bool = False, store: str = "full",
        rhos: tuple | None = None, on_chunk=None):
    """``ENGINES[engine].advance(inp, ...)``
    (:meth:`observer.engines.timestepping.TimeStepping.advance`).

    Raises
    ------
    InputError
        Naming ``engine`` for a name not registered or an engine without a time-stepping loop.
    """
    chosen = check_engine_name(engine)
    if not isinstance(chosen, TimeStepping):
        raise InputError("engine", f"must be one of {list(_stepping_engines())}, got {engine!r}")
    return chosen.advance(inp, record_every, record_pre, store, rhos, on_chunk)
