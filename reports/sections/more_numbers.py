"""All key numbers: every line the sections added, collapsed (built after the others; the
key-number section shows at most eight of them)."""

from __future__ import annotations

from reports.blocks import Section
from reports.context import ReportContext

TITLE = "All key numbers"


def build(ctx: ReportContext) -> Section:
    """Every key-number line, in a collapsible list."""
    sec = Section("all-key-numbers", TITLE)
    sec.details_list(f"{len(ctx.key_numbers)} lines, one or more per section", ctx.key_numbers
                     or ["No results."])
    return sec
