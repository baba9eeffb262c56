"""The numpy time-stepping engine: the readable reference loop of :mod:`observer.loop`."""

from __future__ import annotations

from observer.engines.base import Refusal, RunDescription
from observer.engines.timestepping import TimeStepping


class PythonEngine(TimeStepping):
    """Moreau–Jean in numpy, step by step: every registered contact solver and impact law
    (through its step map), dense matrices; the oracle of the compiled kernel."""

    name = "python"
    loop = "python"
    structure = "dense"
    description = "Moreau–Jean time-stepping in numpy (the reference)"

    def refuses(self, run: RunDescription) -> Refusal | None:
        """The streaming summary is computed by the kernel only."""
        if run.store == "summary":
            return Refusal('store="summary" needs the compiled engine', "store")
        return None
