"""The registry :data:`CHECKS` (name → check of a :class:`~proofs_checks.context.CheckContext`),
in proof order, and the functions that run it: :func:`run_checks`, :func:`select`, :func:`load`,
:func:`results_frame` (re-exported by :mod:`proofs_checks`, whose docstring lists the checks).

Below :mod:`proofs_checks.asserts` and the package's ``__init__``, which import it.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any, Callable, Iterable

import pandas as pd

from observer.engines import check_engine_name
from observer.errors import InputError
from observer.scenario import Scenario
from proofs_checks.assumptions import (check_constraints_independent, check_damping_pd, check_mass_spd,
                                       check_stiffness_spd)
from proofs_checks.context import CheckContext, CheckSettings
from proofs_checks.designs import check_projection_energy
from proofs_checks.forcing import check_forcing_bounded
from proofs_checks.lyapunov import check_convergence, check_lyapunov_decrease
from proofs_checks.monotonicity import check_impact_monotone
from proofs_checks.projection import check_projection_closed_form, check_projection_psd
from proofs_checks.proposition import check_proposition1_exact, check_proposition1_h_scaling
from proofs_checks.result import CheckResult
from proofs_checks.switching import check_switching_generated

Check = Callable[[CheckContext], CheckResult]

CHECKS: dict[str, Check] = {
    "mass_spd": lambda c: check_mass_spd(c.system.M, **c.options("mass_spd")),
    "stiffness_spd": lambda c: check_stiffness_spd(c.system.K, **c.options("stiffness_spd")),
    "damping_pd": lambda c: check_damping_pd(c.system.C, **c.options("damping_pd")),
    "constraints_independent": lambda c: check_constraints_independent(
        c.system.W, **c.options("constraints_independent")),
    "switching_generated": lambda c: check_switching_generated(c.run, **c.options("switching_generated")),
    "forcing_bounded": lambda c: check_forcing_bounded(c.system.forcing, **c.options("forcing_bounded")),
    "impact_monotone": lambda c: check_impact_monotone(
        c.system, c.law, rng=c.rng("impact_monotone"), visited=c.visited_sets(),
        **c.options("impact_monotone")),
    "projection_closed_form": lambda c: check_projection_closed_form(
        c.run, **c.options("projection_closed_form")),
    "projection_psd": lambda c: check_projection_psd(
        c.system.K, c.system.W, rng=c.rng("projection_psd"), **c.options("projection_psd")),
    "projection_energy": lambda c: check_projection_energy(
        c.scenario, c.slave_specs(), h=c.h, t_end=c.t_end, engine=c.engine, **c.options("projection_energy")),
    "proposition1_exact": lambda c: check_proposition1_exact(
        c.scenario, h=c.h, t_end=c.short_t_end, engine=c.engine, **c.options("proposition1_exact")),
    "proposition1_h_scaling": lambda c: check_proposition1_h_scaling(
        c.scenario, h=c.h, t_end=c.short_t_end, engine=c.engine, **c.options("proposition1_h_scaling")),
    "lyapunov_decrease": lambda c: check_lyapunov_decrease(c.run, **c.options("lyapunov_decrease")),
    "convergence": lambda c: check_convergence(c.convergence_run, **c.options("convergence")),
}
"""Registry: stable check name → function of a :class:`CheckContext` returning a :class:`CheckResult`."""


def load(scenario: str | Path | Scenario, overrides: dict[str, Any] | None = None) -> Scenario:
    """A :class:`~observer.scenario.Scenario` from a built-in name, a TOML path or a Scenario."""
    import observer
    return observer.load_scenario(scenario, overrides)


def select(only: str | Iterable[str] | None) -> list[str]:
    """Validated list of check names (all when ``only`` is None); comma-separated strings allowed."""
    if only is None:
        return list(CHECKS)
    items = [only] if isinstance(only, str) else list(only)
    names = [x.strip() for item in items for x in str(item).split(",") if x.strip()]
    for n in names:
        if n not in CHECKS:
            raise InputError("--only", f"unknown check {n!r}; choose from {', '.join(CHECKS)}")
    return names


def run_checks(scenario: str | Path | Scenario, only: str | Iterable[str] | None = None, *,
               overrides: dict[str, Any] | None = None, seed: int = 0, h: float | None = None,
               t_end: float | None = None, options: dict | None = None,
               settings: CheckSettings | None = None, progress: Callable[[CheckResult], None] | None = None,
               engine: str | None = None) -> list[CheckResult]:
    """Run the registered checks on a scenario.

    Parameters
    ----------
    scenario : str, Path or Scenario
        Built-in name, TOML path or loaded scenario.
    only : str or iterable of str, optional
        Check names (comma-separated allowed); default all, in registry order.
    overrides : dict, optional
        Scenario overrides (``{"param.F": 3}``, ``{"impact.restitution": [0.1, 0.95]}``).
    seed, h, t_end, options
        See :class:`CheckSettings` (ignored when ``settings`` is given).
    progress : callable, optional
        Called with each result as soon as it is available.
    engine : str, optional
        The engine of every run of the checks, as :func:`observer.simulate`'s ``engine``
        (:data:`observer.engines.ENGINES`); overrides ``settings.engine``. Default: the first
        time-stepping engine that accepts each run.

    Returns
    -------
    list of CheckResult
        In the order of ``only`` (or of :data:`CHECKS`); a check that raises is reported
        as failed with the exception in ``reason``.
    """
    check_engine_name(engine)
    sc = load(scenario, overrides)
    settings = settings or CheckSettings(seed=seed, h=h, t_end=t_end, options=dict(options or {}))
    if engine is not None:
        settings = dataclasses.replace(settings, engine=engine)
    unknown = [k for k in settings.options if k not in CHECKS]
    if unknown:
        raise InputError("options", f"unknown check(s) {unknown}; choose from {', '.join(CHECKS)}")
    ctx = CheckContext(sc, settings)
    out = []
    for name in select(only):
        t0 = time.perf_counter()
        try:
            res = CHECKS[name](ctx)
        except InputError:
            raise
        except Exception as exc:  # a crashing check is a failed check, with the error as witness
            res = CheckResult(name, False, float("nan"), float("nan"), {"exception": type(exc).__name__},
                              f"raised {type(exc).__name__}: {exc}", evidence="sampled",
                              verdict="the check raised; nothing decided")
        res.scenario = sc.name
        res.elapsed = time.perf_counter() - t0
        out.append(res)
        if progress is not None:
            progress(res)
    return out


def results_frame(results: Iterable[CheckResult]) -> pd.DataFrame:
    """One row per result: scenario, check, equation, status, evidence, passed, margin,
    tolerance, verdict, witness (one-line summary), reason, elapsed (s)."""
    rows = [r.to_row() for r in results]
    cols = ["scenario", "check", "equation", "status", "evidence", "passed", "margin", "tolerance", "verdict",
            "witness", "reason", "elapsed"]
    return pd.DataFrame(rows, columns=cols)
