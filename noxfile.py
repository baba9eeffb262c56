"""nox sessions.

* ``tests`` (default): the pytest suite.
* ``report``: the main job — run the ``quick`` benchmark suite (resumable) and build the
  self-contained HTML report ``reports/out/quick/index.html``; ``-- SUITE`` for another.
* ``bench -- SUITE``: run a benchmark suite only (rows appended to ``bench/results/SUITE.jsonl``).
* ``checks``: the proof checks on every built-in scenario.
* ``run -- SCENARIO``: simulate one scenario with both observers and plot it.
"""

from __future__ import annotations

import nox

nox.needs_version = ">=2024.3.2"
nox.options.default_venv_backend = "virtualenv"
nox.options.reuse_existing_virtualenvs = True
nox.options.sessions = ["tests"]


@nox.session
def tests(session: nox.Session) -> None:
    """Install the package with its test extras and run pytest (pass pytest args after --)."""
    session.install("-e", ".[test]")
    session.run("python", "-m", "pytest", *session.posargs)


@nox.session
def checks(session: nox.Session) -> None:
    """Run the proof checks on every built-in scenario (``nox -s checks -- NAME ...`` for one);
    fails when a check fails. Results with full witnesses go to ``out/checks.json``."""
    session.install("-e", ".")
    session.run("python", "-m", "proofs_checks", *(session.posargs or ["all"]),
                "--json", "out/checks.json")


@nox.session
def run(session: nox.Session) -> None:
    """Simulate a built-in scenario with both observers and plot it.

    ``nox -s run -- SCENARIO`` (default ``double_mass``); writes ``out/SCENARIO.csv`` and
    ``out/SCENARIO.png``.
    """
    session.install("-e", ".")
    name = session.posargs[0] if session.posargs else "double_mass"
    extra = session.posargs[1:]
    session.run("python", "-m", "observer", "run", name, "--observers", "jump,nojump",
                "--out", f"out/{name}.csv", *extra)
    session.run("python", "-m", "observer", "plot", f"out/{name}.csv", "--out", f"out/{name}.png")


@nox.session
def bench(session: nox.Session) -> None:
    """Run a benchmark suite: ``nox -s bench -- SUITE [--limit K]`` (default ``quick``).

    Suites: quick, full, observers, work_precision, robustness, scaling, micro, smoke
    (``python -m bench list``). Rows are appended to ``bench/results/SUITE.jsonl`` as runs
    finish; rerunning resumes an interrupted suite without recomputing finished rows.
    """
    session.install("-e", ".[bench]")
    suite = session.posargs[0] if session.posargs else "quick"
    session.run("python", "-m", "bench", "run", suite, *session.posargs[1:])


@nox.session
def report(session: nox.Session) -> None:
    """Build the HTML report of a suite: ``nox -s report -- SUITE`` (default ``quick``).

    Runs the suite first if its results are missing or incomplete (finished rows are
    kept), then writes ``reports/out/SUITE/index.html`` (self-contained; open it in a browser).
    """
    session.install("-e", ".[bench]")
    suite = session.posargs[0] if session.posargs else "quick"
    session.run("python", "-m", "bench", "run", suite, success_codes=[0, 1])
    session.run("python", "-m", "reports", suite, "--out", f"reports/out/{suite}", *session.posargs[1:])


if __name__ == "__main__":
    nox.main()
