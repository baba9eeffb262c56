"""The table at the top of the page: versions, commits, dates and machine of the runs."""

from __future__ import annotations

import platform
from datetime import datetime, timezone

import pandas as pd

from observer.results_io import cpu_model, git_commit, package_versions
from reports.context import ReportContext
from reports.tables import Table

PACKAGES = ("numpy", "scipy", "pandas", "cvxpy", "osqp", "matplotlib")
"""Packages whose versions the header lists."""


def _uniq(df: pd.DataFrame, col: str, default: str = "n/a") -> str:
    if col not in df or df[col].dropna().empty:
        return default
    return ", ".join(str(v) for v in dict.fromkeys(df[col].dropna().astype(str)))


def header_table(ctx: ReportContext) -> Table:
    """Versions (of the runs, else of this interpreter), commits, dates, machine, inputs."""
    df, now = ctx.df, package_versions()
    dates = df["date"].dropna().astype(str) if "date" in df else pd.Series(dtype=str)
    t = Table("Report header: versions, commit, date and machine", ["item", "value"])
    t.add(["toolkit version (observer)", _uniq(df, "v_observer", now.get("observer", "n/a"))])
    t.add(["git commit of the runs", _uniq(df, "git_commit", "unknown")])
    t.add(["git commit of this report", git_commit()])
    t.add(["runs finished (UTC)", f"{dates.min()} … {dates.max()}" if len(dates) else "n/a"])
    t.add(["report built (UTC)", datetime.now(timezone.utc).isoformat(timespec="seconds")])
    t.add(["CPU", _uniq(df, "cpu", cpu_model())])
    t.add(["cores / BLAS threads", f"{_uniq(df, 'cores')} / {_uniq(df, 'blas_threads')}"])
    t.add(["platform", _uniq(df, "platform", platform.platform())])
    t.add(["Python", _uniq(df, "v_python", now["python"])])
    for pkg in PACKAGES:
        t.add([pkg, _uniq(df, f"v_{pkg}", now.get(pkg, "n/a"))])
    t.add(["suites", _uniq(df, "suite")])
    missing = ctx.suites_without_meta()
    t.add(["suite metadata (<suite>.meta.json)",
           f"missing for {', '.join(missing)}: results written before bench recorded it, cases in "
           "case-id order; run the suite again to record it" if missing else "present"])
    t.add(["results files", ", ".join(str(p) for p in ctx.files)])
    t.add(["micro-benchmark file", ctx.micro_meta.get("file", "none")])
    t.add(["rows", str(len(df))])
    return t
