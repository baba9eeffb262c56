"""Exact event-driven integration (issue 11): exact flow between events, certified event
isolation, impacts through the time-stepping impact laws, persistent contact, Zeno.

- :mod:`observer.event.flow`: the exact flow (augmented matrix exponential) per active set;
- :mod:`observer.event.roots`: certified isolation of the first zero of a gap or force;
- :mod:`observer.event.master`: the master's event loop, :func:`run_master` (its solution as
  arrays; the DataFrame views are built on first read);
- :mod:`observer.event.observers`: the exact observers driven by the master's χ;
- :mod:`observer.event.frame`: the gap frame, coordinates with their origin on the contacts
  in which the engine runs a translated system (issue 34).

:func:`observer.simulate` reaches them through the ``event`` engine
(:mod:`observer.engines.event`), which runs them in the gap frame and turns their arrays and
status strings into a :class:`~observer.result.RunRecord`.
"""

from observer.event.flow import Flow, flow_for

__all__ = ["Flow", "flow_for", "run_master", "MasterEventResult"]


def __getattr__(name):
    if name in ("run_master", "MasterEventResult"):
        from observer.event import master
        return getattr(master, name)
    raise AttributeError(name)
