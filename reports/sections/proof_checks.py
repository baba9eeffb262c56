"""Proof-step checks (:mod:`proofs_checks`): a matrix scenario × check coloured by the
evidence level (proved, bounded, sampled, violated, n/a; the verdict and witness on hover),
counts per status and per registered observer design, and every check row with its margin,
tolerance and witness (on demand)."""

from __future__ import annotations

import pandas as pd

from reports import analysis, registry
from reports.analysis import CHECK_STATUSES, EVIDENCE_ORDER, check_evidence, check_matrix
from reports.blocks import Section
from reports.context import ReportContext
from reports.tables import Table, fmt, fmt_int, text, witness_text

TITLE = "Proof-step checks (proofs_checks)"
WITNESS_CHARS = 220
"""Longest witness / reason shown in a cell (longer ones end with "…")."""
HOVER_CHARS = 600
"""Longest hover text of a matrix cell."""
MATRIX_TITLE = "Proof-check matrix: evidence level per scenario and check"
EVIDENCE_TEXT = ("proved: decided in exact rational arithmetic (or verified enclosures) on the given matrices; "
                 "bounded: floating point with a rigorous round-off bound (exact where recomputed); "
                 "sampled: random/adversarial search, no counterexample; violated: a counterexample "
                 "re-checked exactly; n/a: the check's hypotheses do not hold. A failure that was not "
                 "re-checked exactly reads \"FAIL (level)\". Hover a cell for its verdict and witness.")


def _why_missing() -> str:
    try:
        import proofs_checks  # noqa: F401
    except Exception as exc:  # pragma: no cover - a broken package is reported, not fatal
        return f"proofs_checks is not importable here ({type(exc).__name__}: {exc})."
    return ("proofs_checks is importable, but these results have no check rows; run the suite "
            "again (finished cases are skipped, the checks are added).")


def _design_of(r: pd.Series) -> str:
    d = r.get("design")
    return registry.label(d) if isinstance(d, str) and d else "—"


def _cut(s: str, n: int) -> str:
    return s if len(s) <= n else s[:n - 1] + "…"


def matrix_cell(r: pd.Series) -> tuple[str, str, str]:
    """(text, CSS class, hover text) of one check in the matrix: the evidence level (a failure
    that is not an exact counterexample: "FAIL (level)"; a row without a level: its status)."""
    st = str(r["check_status"])
    ev = check_evidence(r)
    if ev == "n/a":
        cell, cls = "n/a", "evidence-na"
    elif not ev:
        cell, cls = st, "evidence-unknown"
    elif st == "FAIL" and ev != "violated":
        cell, cls = f"FAIL ({ev})", "evidence-violated"
    else:
        cell, cls = ev, f"evidence-{ev}"
    verdict, reason, wit = text(r.get("verdict")), text(r.get("reason")), witness_text(r.get("witness"))
    body = reason if st == "n/a" else " | ".join(x for x in (verdict, wit or reason) if x)
    hover = f"{r['check']} on {r['scenario']}: {st}" + (f" — {body}" if body else "")
    return cell, cls, _cut(hover, HOVER_CHARS)


def matrix_table(ch: pd.DataFrame) -> Table:
    """Scenario × check, each cell the evidence level, coloured, with its verdict and witness
    as hover text; "—" where a scenario has no row for a check."""
    scenarios, checks, cells = check_matrix(ch)
    t = Table(MATRIX_TITLE, ["scenario", *checks])
    for sc in scenarios:
        row, cls, hov = [sc], [""], [""]
        for c in checks:
            r = cells.get((sc, c))
            if r is None:
                row.append("—"), cls.append(""), hov.append("")
                continue
            cell, k, h = matrix_cell(r)
            row.append(cell), cls.append(k), hov.append(h)
        t.add(row, classes=cls, titles=hov)
    return t


def checks_table(ch: pd.DataFrame) -> Table:
    """Every check row."""
    t = Table("Proof-check table: status, evidence, verdict, margin, tolerance and witness per scenario and check",
              ["scenario", "check", "design", "equation", "status", "evidence", "verdict", "margin", "tolerance",
               "witness / reason"])
    for _, r in ch.iterrows():
        st = str(r["check_status"])
        na = st == "n/a"
        reason, wit = text(r.get("reason")), witness_text(r.get("witness"))
        detail = (reason if na else wit or reason) or "—"
        if len(detail) > WITNESS_CHARS:
            detail = detail[:WITNESS_CHARS - 3] + "…"
        t.add([r["scenario"], r["check"], _design_of(r), text(r.get("equation")) or "—", st,
               check_evidence(r) or "not recorded", text(r.get("verdict")) or "—",
               "n/a" if na else fmt(r["margin"]), "n/a" if na else fmt(r["tolerance"]), detail])
    return t


NO_DESIGN = "n/a (the check rows name no design)"


def design_counts_table(counts: pd.DataFrame, named: bool) -> Table:
    """Check statuses per registered observer design (zeros: no rows for that design); every
    cell n/a when the rows do not say which design a check concerns (``named`` False)."""
    t = Table("Proof checks per observer design (rows whose check concerns that design)",
              ["design", "label", "scenarios", *CHECK_STATUSES])
    for _, r in counts[counts["design"] != "all"].iterrows():
        cells = ([fmt_int(r["scenarios"])] + [fmt_int(r[s]) for s in CHECK_STATUSES] if named
                 else [NO_DESIGN] * (1 + len(CHECK_STATUSES)))
        t.add([r["design"], registry.label(r["design"]), *cells])
    return t


def build(ctx: ReportContext) -> Section:
    """The proof-check section; adds the status counts to the key numbers."""
    sec = Section("proof-checks", TITLE)
    ch = ctx.rows("checks")
    notes = ctx.unavailable_notes("checks:")
    if ch.empty:
        sec.p("No proof-check results. " + _why_missing())
        if notes:
            sec.p("The last suite run skipped the checks:")
            sec.items(notes)
        ctx.key_numbers.append("Proof-step checks: no results (see the proof-check section).")
        return sec
    if notes:
        sec.p("Some check cases were skipped in the last run (shown rows are from earlier runs):")
        sec.items(notes)
    counts = analysis.check_counts(ch)
    total = counts[counts["design"] == "all"].iloc[0]
    sec.p(f"{len(ch)} checks on {total['scenarios']} scenarios: "
          + ", ".join(f"{total[s]} {s}" for s in CHECK_STATUSES) + ". "
          "margin ≥ −tolerance means satisfied; the witness is where the margin is worst. "
          "n/a: the check's hypotheses do not hold for that system (reason given).")
    ctx.key_numbers.append(f"Proof-step checks: {total['PASS']} PASS, {total['FAIL']} FAIL, "
                           f"{total['n/a']} not applicable, over {total['scenarios']} scenarios.")
    levels = ch.apply(check_evidence, axis=1) if len(ch) else pd.Series(dtype=str)
    if levels.astype(bool).any():
        ctx.key_numbers.append("Proof-step evidence: " + ", ".join(
            f"{int((levels == lv).sum())} {lv}" for lv in EVIDENCE_ORDER) + ".")
    sec.p("The proof-check matrix (scenario × check, coloured by evidence level, the verdict "
          "and witness on hover) is shown with the evidence of the claims, above.")
    named = "design" in ch and ch["design"].map(text).astype(bool).any()
    sec.table(design_counts_table(counts, named))
    sec.details(f"Witnesses: all {len(ch)} check rows (status, evidence, margin, tolerance, verdict and witness)",
                checks_table(ch))
    return sec
