"""Build the self-contained HTML report of one or more suite results.

``build_report(result_files, out_dir)`` is a thin driver: it loads the rows once into a
:class:`reports.context.ReportContext`, builds every section of the ordered registry
:data:`reports.sections.SECTIONS` (one module per section; numbers from
:mod:`reports.analysis`, figures from :mod:`reports.figures`) and renders
``templates/report.html`` into ``out_dir/index.html`` (figures inline).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

from reports.blocks import Section
from reports.context import load_context
from reports.figures import parallel_rendering, resolve
from reports.header import header_table
from reports.sections import build_sections
from reports.tables import Table

TEMPLATES = Path(__file__).resolve().parent / "templates"


RENDER_WORKERS = 2
"""Processes rendering the figures while the page is built (:func:`reports.figures.parallel_rendering`):
the machines the reports are built on have 2 cores or more; more workers than figures in
flight only cost their start."""


def build_report(result_files: Iterable[str | Path], out_dir: str | Path, *,
                 micro_files: Iterable[str | Path] | None = None, command: str | None = None,
                 title: str | None = None, workers: int | None = None) -> Path:
    """Build ``out_dir/index.html`` from results files and return its path.

    Parameters
    ----------
    result_files : iterable of path
        Results written by :mod:`bench` (read through :func:`reports.context.load_rows`).
    out_dir : path
        Output folder (created).
    micro_files : iterable of path, optional
        pytest-benchmark JSON files; default: ``<suite>-micro.json`` next to each results file.
    command : str, optional
        The "how to reproduce" command (default derived from the suite names).
    title : str, optional
    workers : int, optional
        Processes rendering the figures (default :data:`RENDER_WORKERS`, at most the CPU count;
        1: each figure rendered where it is made).
    """
    workers = min(RENDER_WORKERS, os.cpu_count() or 1) if workers is None else workers
    with parallel_rendering(workers):      # forked before the rows are read
        ctx = load_context(result_files, out_dir, micro_files=micro_files, command=command)
        ctx.out_dir.mkdir(parents=True, exist_ok=True)
        sections = build_sections(ctx)
        resolve_figures(sections)
    page = render(title=title or f"Observer toolkit benchmark report: {', '.join(ctx.suites)}",
                  header=header_table(ctx), sections=[s for s in sections if not s.lead],
                  command=ctx.command, lead=[s for s in sections if s.lead])
    from observer.outputs import atomic_write

    return atomic_write(ctx.out_dir / "index.html", lambda tmp: tmp.write_text(page, encoding="utf-8"))


def resolve_figures(sections: list[Section]) -> None:
    """Every figure of ``sections`` (and their subsections) with its data URI
    (:func:`reports.figures.resolve`)."""
    for sec in sections:
        for b in sec.blocks:
            if b.kind == "figure":
                b.content = resolve(b.content)
        resolve_figures(sec.subsections)


def render(*, title: str, header: Table, sections: list[Section], command: str,
           lead: list[Section] | None = None) -> str:
    """Render the jinja2 template ``templates/report.html``; the ``lead`` sections come first,
    before the header (the page's first screen)."""
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)),
                             autoescape=jinja2.select_autoescape(["html"]), trim_blocks=True,
                             lstrip_blocks=True, undefined=jinja2.StrictUndefined)
    return env.get_template("report.html").render(title=title, header=header, sections=sections,
                                                  command=command, lead=lead or [])
