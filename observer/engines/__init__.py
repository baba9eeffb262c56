"""The engine registry: each engine declares what it accepts and runs a run description.

As ``scipy.integrate``'s ``METHODS`` and cvxpy's solver interfaces: a run is described once
(:class:`~observer.engines.base.RunDescription`, built by :func:`observer.simulate`) and
handed to the requested engine, or to the first engine of its integrator that accepts it
(:func:`choose`); an engine that cannot take a run says why in one line
(:meth:`~observer.engines.base.Engine.accepts`). Every engine returns one
:class:`~observer.result.RunRecord`.

=============  ===============  ==================================================
name           integrator       module
=============  ===============  ==================================================
``compiled``   time-stepping    :mod:`observer.engines.compiled` (numba kernel)
``python``     time-stepping    :mod:`observer.engines.python` (numpy reference)
``event``      event            :mod:`observer.engines.event` (exact event-driven)
=============  ===============  ==================================================

Adding an engine is one module with an :class:`~observer.engines.base.Engine` subclass plus
one entry here (or ``ENGINES[engine.name] = engine`` at run time).
"""

from __future__ import annotations

from observer.engines.base import INTEGRATORS, Engine, Refusal, RunDescription, describe
from observer.engines.compiled import CompiledEngine
from observer.engines.event import EventEngine
from observer.engines.python import PythonEngine
from observer.errors import InputError

ENGINES: dict[str, Engine] = {e.name: e for e in (CompiledEngine(), PythonEngine(), EventEngine())}
"""Registry of engines: name → :class:`~observer.engines.base.Engine`; in order of preference
(the first of an integrator that accepts a run takes it)."""

__all__ = ["ENGINES", "INTEGRATORS", "Engine", "Refusal", "RunDescription", "choose", "describe",
           "check_engine_name"]


def check_engine_name(engine) -> Engine | None:
    """The registered engine named ``engine`` (None for None).

    Raises
    ------
    InputError
        Naming ``engine``, for a name not in :data:`ENGINES`.
    """
    if engine is None:
        return None
    if not isinstance(engine, str) or engine not in ENGINES:
        raise InputError("engine", f"must be one of {list(ENGINES)}, got {engine!r}")
    return ENGINES[engine]


def choose(run: RunDescription, engine: str | None = None) -> tuple[Engine, str | None]:
    """The engine that runs ``run`` and a note on why the preferred one did not (or None).

    ``engine`` given: that engine, or ``InputError("engine")`` with its refusal. Else the
    first engine of ``run.integrator`` that accepts the run; when none does, an
    :class:`InputError` naming the field of the last refusal.
    """
    requested = check_engine_name(engine)
    if requested is not None:
        why = requested.accepts(run)
        if why is not None:
            raise InputError("engine", f"the {requested.name} engine cannot take this run: {why}")
        return requested, None
    refusals = []
    for candidate in ENGINES.values():
        if candidate.integrator != run.integrator:
            continue
        why = candidate.accepts(run)
        if why is None:
            note = (f"{refusals[0][1]}; the run uses the {candidate.name} engine"
                    if refusals else None)
            return candidate, note
        refusals.append((candidate, why))
    if not refusals:
        raise InputError("integrator", f"no registered engine integrates by {run.integrator!r}")
    last = refusals[-1][1]
    raise InputError(getattr(last, "field", "engine"), "; ".join(str(w) for _, w in refusals))
