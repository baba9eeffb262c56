"""Key numbers: at most :data:`MAX_ITEMS` headlines, the first line each section added (in
page order; built after the others). Every line is kept, collapsed, in
:mod:`reports.sections.more_numbers`."""

from __future__ import annotations

from reports.blocks import Section
from reports.context import ReportContext

TITLE = "Key numbers"
MAX_ITEMS = 8
"""At most this many key numbers."""


def headlines(groups: list[tuple[str, list[str]]], limit: int = MAX_ITEMS) -> list[str]:
    """The first line of each group that has one, then the following lines round-robin, up to
    ``limit`` lines."""
    out: list[str] = []
    depth = 0
    while len(out) < limit and any(len(lines) > depth for _, lines in groups):
        out += [lines[depth] for _, lines in groups if len(lines) > depth][:limit - len(out)]
        depth += 1
    return out


def build(ctx: ReportContext) -> Section:
    """The key-number list: at most :data:`MAX_ITEMS` of the lines in ``ctx.key_groups``."""
    sec = Section("key-numbers", TITLE)
    groups = ctx.key_groups or [("", list(ctx.key_numbers))]
    lines = headlines(groups)
    sec.items(lines or ["No results."])
    if len(ctx.key_numbers) > len(lines):
        sec.p(f"All {len(ctx.key_numbers)} key-number lines: in the collapsible section "
              "\"All key numbers\" below the figures.")
    return sec
