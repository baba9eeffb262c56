"""Hard cases (issue 12 item 5): per case the run's status and stop reason, whether it
returned NaN, whether its complementarity residual (recomputed from the applied impulse)
held its tolerance, its health numbers, and its error against the reference (or why there is
none), from the ``hard`` rows of :mod:`bench.hard`."""

from __future__ import annotations

import pandas as pd

from observer.row_schema import HARD_STATES
from reports.blocks import Section
from reports.context import ReportContext, schema_columns
from reports.tables import Table, fmt, fmt_int, text

TITLE = "Hard cases: status, NaN, residual and error against the reference"

KIND = "hard"
"""Row kind of :mod:`bench.hard`."""

INTRO = ("Each hard case runs the master alone with the compiled time-stepping engine "
         "(θ = ½). The acceptance line of issue 12: every hard case runs to the end or stops with "
         "a clear status, none returns NaN, and its error against the reference is reported. "
         "Status: ok (ran to the end), fallback (some contact problems re-solved by the reference "
         "solver), stopped (the loop stopped, with the reason), refused (the input was rejected "
         "before any step with an error naming the field). The residual is the largest "
         "complementarity residual recomputed from the impulse the step applied, against the run's "
         "tolerance; the penetration is relative to the scenario's length scale. Error: on the "
         "recorded rows t_k, e_k = max_i |q_i(t_k) − q_ref,i(t_k)|; 'max' is max_k e_k, 'mean' "
         "its time average. References: the closed form where the scenario has one, else the "
         "exact event-driven integrator sampled on the run's grid.")


def hard_rows(ctx: ReportContext) -> pd.DataFrame:
    """The ``hard`` rows with every column the row schema declares for them
    (:data:`observer.row_schema.ROWS`; NaN where a row lacks one), in the order of ``ctx.df``
    (the suite's declared order)."""
    df = ctx.df
    rows = df[df["kind"] == KIND].copy() if "kind" in df else pd.DataFrame()
    for c in schema_columns(KIND):
        if c not in rows:
            rows[c] = float("nan")
    return rows.reset_index(drop=True)


def clear_outcome(row) -> bool:
    """The case ran to the end (status ok) or stopped with a stated reason (any other known
    status and a non-empty stop reason)."""
    status = text(row.get("status"))
    return status == "ok" or (status in HARD_STATES and text(row.get("stop_reason")) != "")


def has_reference(row) -> bool:
    """The row has an error against a reference (finite err_max)."""
    v = row.get("err_max")
    return v is not None and pd.notna(v)


def verdict(rows: pd.DataFrame) -> dict[str, int]:
    """Counts over the rows: cases, clear outcomes, refused, NaN, residual held among those
    that ran, errors reported."""
    ran = rows[rows["status"].astype(str) != "refused"]
    return {"cases": len(rows),
            "clear": int(sum(clear_outcome(r) for _, r in rows.iterrows())),
            "refused": int((rows["status"].astype(str) == "refused").sum()),
            "nan": int(rows["has_nan"].fillna(True).astype(bool).sum()),
            "ran": len(ran),
            "residual_held": int(ran["residual_held"].fillna(False).astype(bool).sum()),
            "with_error": int(sum(has_reference(r) for _, r in rows.iterrows()))}


def key_sentence(v: dict[str, int]) -> str:
    """The hard-case key number, from :func:`verdict`."""
    return (f"Hard cases: {v['clear']} of {v['cases']} ran to the end or stopped with a clear "
            f"status ({v['refused']} refused with an input error), {v['nan']} returned NaN, the "
            f"complementarity residual held in {v['residual_held']} of the {v['ran']} that ran, "
            f"error against a reference reported for {v['with_error']} of {v['cases']}")


def _yes_no(x) -> str:
    return "n/a" if x is None or (isinstance(x, float) and x != x) else ("yes" if bool(x) else "no")


def _reason(row) -> str:
    """Stop reason and health warnings of a row, '—' when there are none."""
    parts = [p for p in (text(row.get("stop_reason")), text(row.get("warnings"))) if p]
    return "; ".join(parts) or "—"


def _error(row, col: str) -> str:
    return fmt(row.get(col)) if has_reference(row) else "n/a (no reference)"


def cases_table(rows: pd.DataFrame) -> Table:
    """One row per hard case."""
    t = Table("Hard cases: outcome, health and error against the reference",
              ["case", "what makes it hard (and how to read its error)", "status",
               "stop reason / warnings", "NaN in result", "steps", "CPU (s)", "max residual", "tolerance",
               "residual held", "penetration / ℓ", "h·ω_max", "reference", "error max",
               "error mean"])
    for _, r in rows.iterrows():
        ran = text(r.get("status")) != "refused"
        ref = text(r.get("reference")) or "none"
        t.add([text(r.get("name")), text(r.get("description")) or "—", text(r.get("status")),
               _reason(r), _yes_no(r.get("has_nan")), fmt_int(r.get("steps")),
               fmt(r.get("cpu_time_s")),
               fmt(r.get("max_residual")) if ran else "n/a (refused)",
               fmt(r.get("residual_tol")) if ran else "n/a (refused)",
               _yes_no(r.get("residual_held")) if ran else "n/a (refused)",
               fmt(r.get("penetration_rel")) if ran else "n/a (refused)",
               fmt(r.get("h_omega_max")) if ran else "n/a (refused)",
               ref if has_reference(r) else f"none: {text(r.get('reference_note')) or 'not given'}",
               _error(r, "err_max"), _error(r, "err_mean")])
    return t


def build(ctx: ReportContext) -> Section:
    """The hard-cases section; adds its key number."""
    sec = Section("hard-cases", TITLE)
    rows = hard_rows(ctx)
    if rows.empty:
        sec.p("No hard-case runs in these results (python -m bench run hard).")
        return sec
    sec.p(INTRO)
    sec.table(cases_table(rows))
    msg = key_sentence(verdict(rows))
    sec.p(msg + ".")
    ctx.key_numbers.append(msg + ".")
    return sec
