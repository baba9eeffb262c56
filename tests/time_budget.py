"""The per-test budget (issue 32, item 5: no single test over 30 s), as a pytest plugin that
``tests/conftest.py`` registers.

Every test's CPU time is measured: setup, call and teardown, of the process running it and
of the subprocesses it waited for (:func:`os.times`). The tests over :data:`BUDGET_S` are
listed at the end of the run (on the pytest-xdist controller, from every worker); with
``OBSERVER_TEST_BUDGET=fail`` in the environment (:data:`ENFORCE`) they also fail the
session. Not by default, not even under CI: the event engine's invariance properties
(tests/observer/event/test_invariance.py, 200 examples that the issues fix) take about that
budget each, and a run that fails for them would hide every other result.

CPU time, not wall time: on a shared machine a test takes several times its idle wall time
while its CPU time hardly moves, so the limit can fail a run without failing it for the
neighbours' load. A module fixture is charged to the first test that uses it (the cost of
running that test alone); a test that waits for a subprocess it never reaps is charged for
its own process only.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import pytest

BUDGET_S = 30.0
"""CPU seconds allowed to one test (setup + call + teardown)."""

KEY = "cpu_s"
"""Name of the user property that carries a test's CPU seconds on its teardown report."""

_START = pytest.StashKey[float]()
_SPENT: dict[str, float] = {}


def cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and of its children it waited for."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def over_budget(spent: Mapping[str, float], budget: float = BUDGET_S) -> list[tuple[str, float]]:
    """The tests of ``spent`` (node id → CPU seconds) over ``budget``, the costliest first."""
    return sorted(((k, v) for k, v in spent.items() if v > budget), key=lambda kv: -kv[1])


ENFORCE = "OBSERVER_TEST_BUDGET"
"""Environment variable: ``fail`` makes a test over the budget fail the session."""


def enforced(environ: Mapping[str, str] = os.environ) -> bool:
    """Whether a test over the budget fails the session (:data:`ENFORCE` is ``fail``)."""
    return environ.get(ENFORCE, "").strip().lower() == "fail"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    item.stash[_START] = cpu_seconds()
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    if call.when == "teardown" and _START in item.stash:
        outcome.get_result().user_properties.append((KEY, cpu_seconds() - item.stash[_START]))


def pytest_runtest_logreport(report):
    if report.when == "teardown":
        for key, value in report.user_properties:
            if key == KEY:
                _SPENT[report.nodeid] = float(value)


def pytest_terminal_summary(terminalreporter, config):
    if hasattr(config, "workerinput"):
        return
    for nodeid, cpu in over_budget(_SPENT):
        terminalreporter.write_line(f"OVER BUDGET {cpu:.1f} s CPU > {BUDGET_S:g} s: {nodeid}",
                                    red=enforced())


def pytest_sessionfinish(session, exitstatus):
    if (not hasattr(session.config, "workerinput") and enforced() and over_budget(_SPENT)
            and exitstatus == 0):
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
