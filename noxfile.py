"""nox sessions: ``tests`` (default), ``run`` (the main job on a built-in scenario)."""

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


if __name__ == "__main__":
    nox.main()
