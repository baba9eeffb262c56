"""How to reproduce: the one command, the same in two steps, and the commands of the rows."""

from __future__ import annotations

import pandas as pd

from reports.blocks import Section
from reports.context import ReportContext

TITLE = "How to reproduce"


def build(ctx: ReportContext) -> Section:
    """The reproduce section."""
    sec = Section("reproduce", TITLE)
    sec.p("One command (runs the suite if its results are missing or incomplete, then builds this page):")
    sec.pre(ctx.command)
    files = " ".join(str(p) for p in ctx.files)
    sec.p("The same in two steps, without nox:")
    sec.pre(f"python -m bench run {ctx.suites[0]}\npython -m reports {files} --out {ctx.out_dir}")
    commands = ctx.df.get("command", pd.Series(dtype=str)).dropna()
    sec.p("Commands that produced these results: "
          + ", ".join(dict.fromkeys(str(c) for c in commands)) + ".")
    return sec
