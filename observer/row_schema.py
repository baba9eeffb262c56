"""The rows of the benchmark suites, one typed row per case kind, defined once.

``bench.runners`` builds rows and checks each against :func:`check_row` before it is
written; ``reports`` reads the columns named here. A column is declared with its Python
type (``float`` columns may hold NaN or inf; ``int | None`` may be missing as None).
Synchronization columns are named by :func:`observer.metrics.sync_column` and
:func:`observer.metrics.settle_column` over the one threshold list
:data:`observer.metrics.RHOS`.
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from observer.metrics import RHOS, above_column, settle_column, sync_column
from observer.result import RunState

Columns = dict[str, Any]

CASE: Columns = {"kind": str, "scenario": str, "name": str, "params": str, "solver": str,
                 "law": str, "h": float, "t_end": float, "seed": int, "N": (int, type(None)),
                 "n": int, "m": int, "status": str, "note": str}
"""Every row: the case's declared fields and the effective scenario settings
(``bench.runners.base_row``), its status and a note."""

TIMING: Columns = {"cpu_time_s": float, "wall_time_s": float, "cpu_scope": str}

ENGINE: Columns = {"engine": str, "structure": str, "loop_time_s": float,
                   "loop_per_step_s": float, "run_compile_time_s": float, "solver_fallbacks": int}
"""The time loop's engine, structure, own wall time and fallbacks (``bench.runners.engine_columns``)."""

HARD: Columns = {
    "description": str, "stop_reason": str, "has_nan": bool, "steps": int, "store": str,
    "record_every": int, "samples": int, "max_residual": float, "residual_tol": float,
    "residual_held": (bool, type(None)), "penetration_rel": float, "h_omega_max": float,
    "warnings": str, "reference": str, "reference_note": str, "norm": str, "err_max": float,
    "err_mean": float, "ref_cpu_time_s": float,
}
"""The columns of a ``hard`` row (``bench.hard``) beyond :data:`CASE` and :data:`TIMING`,
with their types (:func:`check_row` conventions: ``float`` columns may hold NaN;
``residual_held`` is None for a refused case, which ran no step)."""


HARD_STATES = (*(s.value for s in RunState), "refused")
"""Values of a ``hard`` row's ``status``: the run's :class:`observer.result.RunState`, or
``refused`` (an :class:`~observer.errors.InputError` before the first step)."""


def sync_columns() -> Columns:
    """Per threshold ρ: first passage, settling time, fraction of samples above after passage."""
    out: Columns = {}
    for rho in RHOS:
        out[sync_column(rho)] = float
        out[settle_column(rho)] = float
        out[above_column(rho)] = float
    return out


SYNC: Columns = {"observer": str, "t_on": float, "t_off": float, "V_on": float, "rate": float,
                 "V_end": float, "floor": float, "master_closings": float, "floor_rel": float,
                 "V_end_rel": float, "e_q_end": float, "e_u_end": float, "chi_closings": int,
                 "V_min": float, "master_closed_fraction": float, **sync_columns()}
"""Synchronization of one observer (``bench.runners.sync_metrics``)."""

ROWS: dict[str, Columns] = {
    "observers": {**CASE, **SYNC, **ENGINE, **TIMING, "steps": int, "steps_per_s": float,
                  "contact_solves": int, "integrator": str, "plot_dof": int, "plot_contact": int,
                  "trajectory": str},
    "work_precision": {**CASE, **ENGINE, **TIMING, "target": str, "integrator": str, "method": str,
                       "norm": str,
                       "err_mean": float, "err_max": float, "err_end": float, "reference": str,
                       "h_ref": (float, type(None)), "ref_cpu_time_s": float, "steps": int,
                       "steps_per_s": float, "contact_solves": int, "samples": int,
                       "error_grid_s": float},
    "robustness": {**CASE, **TIMING, "design": str, "member": int, "master": int, "members": int,
                   "masters": int, "perturbation": str, "size": float, "setting": str,
                   "sensor_seed": int, "tail": float, "V_on": float, "floor": float, "peak": float,
                   "V_end": float, "log_intervals": float, **{settle_column(r): float for r in RHOS}},
    "scaling": {**CASE, **ENGINE, **TIMING, "steps": int, "setup_steps": int, "setup_cpu_time_s": float,
                "cpu_per_step_s": float, "cpu_per_step_total_s": float, "wall_per_step_s": float,
                "steps_per_s": float, "contact_solves": int, "closed_step_fraction": float,
                "mean_active": float, "max_active": int, "peak_mem_mb": float,
                "trajectory_mb": float, "whole_call_cpu_s": float, "whole_call_wall_s": float,
                "load_cpu_s": float},
    "checks": {**CASE, **TIMING, "check": str, "equation": str, "check_status": str,
               "passed": (bool, type(None)), "margin": float, "tolerance": float, "witness": str,
               "reason": str, "check_elapsed_s": float, "evidence": str, "verdict": str},
    "hard": {**CASE, **TIMING, **HARD},
    "ensemble": {**CASE, **TIMING, "label": str, "design": str, "member": int, "members": int,
                 "integrator": str, "perturbation": str, "size": float, "V_on": float,
                 "V_max": float, "V_end": float, "rises": int, "max_rise_rel": float,
                 "rate": float, "rate_points": int, "rate_t_fit": float, "rate_floor_stop": bool, "master": int, "floor": float, **{c(r): float for r in RHOS for c in (settle_column, sync_column)}, "paths": str},
}
"""Kind → the columns of its rows and their types (``peers`` rows are declared by
``bench.peers``, whose columns depend on the peer's run). An ``ensemble`` row is one
(design, member) of :func:`observer.ensemble` (its members' initial errors ``dq0_j``, ``du0_j``
as extra columns). A ``robustness`` row is one (design, master, member) of a paired ensemble
with χ from a contact sensor (``bench.perturb``): its ``floor`` is the median of V/V(t_on) over
the window's last ``tail``."""

OPTIONAL: dict[str, frozenset] = {
    "observers": frozenset(SYNC) | frozenset(ENGINE) | frozenset(
        {"steps", "steps_per_s", "contact_solves", "integrator", "plot_dof", "plot_contact", "trajectory",
         "cpu_time_s", "wall_time_s", "cpu_scope"}),
    "scaling": frozenset({"peak_mem_mb", "trajectory_mb", "whole_call_cpu_s", "whole_call_wall_s",
                          "load_cpu_s"}),
    "checks": frozenset({"evidence", "verdict"}),
    "ensemble": frozenset({"paths", "rate_t_fit", "rate_floor_stop", "master"}),
}
"""Columns a row of the kind may lack: an observers row of a design that does not apply
(status "n/a") has no synchronization, engine or timing columns; a scaling case declared
with ``memory=False`` has no memory columns, one written before issue 23 no whole-call columns; a checks row written before the evidence levels
has no ``evidence`` and ``verdict``; an ensemble row keeps no V(t) ``paths`` unless its case asks
for them, and one written before several masters per ensemble no ``master``, ``rate_t_fit`` and ``rate_floor_stop``."""


def _is(value: Any, typ) -> bool:
    """``value`` fits the declared type (numpy scalars included; a bool is no number)."""
    types = typ if isinstance(typ, tuple) else (typ,)
    if isinstance(value, (bool, np.bool_)):
        return bool in types
    if float in types and isinstance(value, numbers.Real):
        return True
    if int in types and isinstance(value, numbers.Integral):
        return True
    return isinstance(value, types)


def check_row(row: dict) -> dict:
    """Return ``row`` if it has every column its kind declares, with the declared types
    (extra columns, such as the environment's, are allowed); raise ``ValueError`` naming the
    kind and the columns otherwise. Kinds without a declared schema pass unchecked."""
    kind = row.get("kind")
    cols = ROWS.get(kind)
    if cols is None:
        return row
    optional = OPTIONAL.get(kind, frozenset())
    missing = [c for c in cols if c not in row and c not in optional]
    wrong = [f"{c} ({type(row[c]).__name__})" for c, typ in cols.items()
             if c in row and row[c] is not None and not _is(row[c], typ)]
    wrong += [c for c, typ in cols.items() if c in row and row[c] is None
              and not (isinstance(typ, tuple) and type(None) in typ)]
    if missing or wrong:
        raise ValueError(f"{kind} row of {row.get('name', '?')!r}: missing {missing}, "
                         f"wrong type {wrong}")
    return row
