"""The compiled time-stepping engine: the numba kernel (:mod:`observer.kernel`)."""

from __future__ import annotations

from observer.engines.base import Refusal, RunDescription
from observer.engines.timestepping import TimeStepping
from observer.impact import KERNEL_LAWS


class CompiledEngine(TimeStepping):
    """Moreau–Jean in the numba kernel: block pivoting for the contact problems, the impact
    laws of :data:`observer.impact.KERNEL_LAWS`, banded matrices where they pay."""

    name = "compiled"
    loop = "compiled"
    structure = "auto"
    description = "Moreau–Jean time-stepping in the compiled (numba) kernel"

    def refuses(self, run: RunDescription) -> Refusal | None:
        """The kernel's contact solver is block pivoting; its laws those it has a path for
        which are Newton's on one closed contact (the kernel computes such steps so)."""
        sc = run.scenario
        if sc.solver != "pivoting":
            return Refusal(f"solver {sc.solver!r}: the compiled kernel has block pivoting only",
                           "simulation.solver")
        law = sc.law.definition
        if law.code not in KERNEL_LAWS:
            return Refusal(f"impact law {law.name!r} has no code in the compiled kernel", "impact.law")
        if not law.single_contact_is_newton:
            return Refusal(f"impact law {law.name!r} does not declare single_contact_is_newton (the "
                           "compiled kernel computes every one-contact step by Newton's law)", "impact.law")
        return None
