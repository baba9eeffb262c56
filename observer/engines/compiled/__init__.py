"""The compiled time-stepping engine: Moreau–Jean in a numba kernel.

The package owns its loop: :mod:`~observer.engines.compiled.driver` (the run, window by
window), :mod:`~observer.engines.compiled.bundles` (the kernel's arguments by name),
:mod:`~observer.engines.compiled.kernel` (the compiled step loops) and
:mod:`~observer.engines.compiled.members` (an ensemble's members over one recorded master); the
primitives it shares with the numpy engine are in :mod:`observer.primitives`.
"""

from __future__ import annotations

from observer.engines.base import Refusal, RunDescription
from observer.engines.timestepping import TimeStepping
from observer.impact import KERNEL_LAWS


class CompiledEngine(TimeStepping):
    """Moreau–Jean in the numba kernel: block pivoting for the contact problems, the impact
    laws of :data:`observer.impact.KERNEL_LAWS`, banded matrices where they pay."""

    name = "compiled"
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

    def loop(self, inp, record_every: int, record_pre: bool, store: str, rhos: tuple | None, on_chunk,
             stopper):
        """:func:`observer.engines.compiled.driver.run_compiled` (the kernel compiled or loaded on
        first use; ``rhos``: the summary's thresholds, default :data:`observer.metrics.RHOS`)."""
        from observer.engines.compiled.driver import run_compiled
        from observer.metrics import RHOS

        return run_compiled(inp, record_every, record_pre, store == "summary", tuple(RHOS if rhos is None else rhos),
                            on_chunk=on_chunk, stopper=stopper)

    def model_loop(self, run: RunDescription, record_every: int = 1):
        """The master (the plant) and the observers on their own model (``run.scenario.model``)
        in one loop of the kernel (:func:`observer.engines.compiled.kernel.advance_model`):
        each observer's bundle carries its model's matrices, law and signals, χ_k is the
        plant's; returns the :class:`~observer.engines.loop.LoopOutput` (row 0 the plant; V
        not computed: measure it against row 0 in the metric the model names).
        ``store="full"``, dense schemes only (:func:`observer.engines.compiled.bundles.model_bundle`)."""
        import dataclasses

        from observer.engines.compiled.driver import run_compiled
        from observer.engines.loop import Stopper, check_record_every
        from observer.engines.timestepping import loop_input
        from observer.plant_model import model_scenario
        from observer.stepping import MoreauJean

        sc = run.scenario
        nominal = dataclasses.replace(run, scenario=model_scenario(sc))
        steppers = [MoreauJean(s.system, s.law, s.h, s.t_end, s.theta, solver=s.solver,
                               residual_tol=run.residual_tol, structure="dense") for s in (sc, nominal.scenario)]
        other_metric = any(s.position_jumps and s.metric != "K" for s in run.slaves)
        with Stopper(False) as stopper:
            return run_compiled(loop_input(run, steppers[0]), check_record_every(record_every),
                                run.record_pre or other_metric, stopper=stopper,
                                model=loop_input(nominal, steppers[1]))
