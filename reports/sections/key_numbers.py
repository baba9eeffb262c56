"""Key numbers: one line per headline the other sections computed (built after them)."""

from __future__ import annotations

from reports.blocks import Section
from reports.context import ReportContext

TITLE = "Key numbers"


def build(ctx: ReportContext) -> Section:
    """The key-number list gathered in ``ctx.key_numbers``."""
    sec = Section("key-numbers", TITLE)
    sec.items(ctx.key_numbers or ["No results."])
    return sec
