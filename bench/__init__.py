"""Benchmark suites of the observer toolkit: declared grids, tidy resumable results.

A *suite* (:mod:`bench.suites`) is a declared grid of *cases* (scenario × observer ×
contact solver × impact law × step size × seed × ...). Running it (:mod:`bench.run`,
``python -m bench run SUITE``) appends one tidy row per run to an append-only JSON-lines
file (:mod:`bench.results`), so an interrupted suite resumes where it stopped. The
micro-benchmarks (one step, one contact solve) live in ``bench/micro`` and run under
pytest-benchmark. The HTML report is built by :mod:`reports`.

This module imports nothing heavy on purpose: ``python -m bench`` pins the BLAS thread
count before NumPy is imported (see :mod:`bench.__main__`).
"""

RESULTS_DIR = "bench/results"
"""Default output folder (git-ignored), relative to the repository root."""
