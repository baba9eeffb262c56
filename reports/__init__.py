"""HTML reports of benchmark suites: ``python -m reports SUITE_OR_RESULTS... --out DIR``.

:func:`reports.build.build_report` turns the tidy results of :mod:`bench` into one
self-contained ``index.html`` (figures inline); :mod:`reports.browser` checks it in a
headless Chromium (every image decoded, no console errors).
"""


def build_report(*args, **kwargs):
    """Lazy alias of :func:`reports.build.build_report`."""
    from reports.build import build_report as _build
    return _build(*args, **kwargs)
