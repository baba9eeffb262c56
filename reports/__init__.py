"""HTML reports of benchmark suites: ``python -m reports SUITE_OR_RESULTS... --out DIR``.

:func:`reports.build.build_report` turns the tidy results of :mod:`bench` into one
self-contained ``index.html`` (figures inline): it loads a :class:`reports.context.ReportContext`
once and builds the sections of the ordered registry :data:`reports.sections.SECTIONS` (one
module each). :mod:`reports.analysis` computes every table as a DataFrame, :mod:`reports.registry`
is the one place the report learns the designs, ratios, thresholds, scenarios and solvers, and
:mod:`reports.browser` checks the page in a headless Chromium (every image decoded, no console
errors).
"""


def build_report(*args, **kwargs):
    """Lazy alias of :func:`reports.build.build_report`."""
    from reports.build import build_report as _build
    return _build(*args, **kwargs)
