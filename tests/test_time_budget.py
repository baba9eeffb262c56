"""The per-test CPU budget (``tests/time_budget.py``): what it measures, whom it names and
when it fails a session."""

from __future__ import annotations

import subprocess
import sys
import time

import time_budget as tb

BURN = "import time\nt = time.process_time()\nwhile time.process_time() - t < 0.4: pass\n"


def test_cpu_seconds_count_waited_subprocesses_and_not_sleep():
    c0 = tb.cpu_seconds()
    subprocess.run([sys.executable, "-c", BURN], check=True)
    burnt = tb.cpu_seconds() - c0
    assert burnt >= 0.4                                  # the child's 0.4 s at least
    c0 = tb.cpu_seconds()
    time.sleep(0.3)
    assert tb.cpu_seconds() - c0 < 0.1                   # waiting is not CPU


def test_over_budget_names_the_tests_above_it_costliest_first():
    spent = {"a": 31.0, "b": 30.0, "c": 45.5, "d": 2.0}
    assert tb.over_budget(spent) == [("c", 45.5), ("a", 31.0)]
    assert tb.over_budget(spent, budget=1.0)[-1] == ("d", 2.0)
    assert tb.over_budget({}) == []


def test_enforced_only_when_asked():
    assert not tb.enforced({}) and not tb.enforced({"CI": "true"})
    for off in ("", "0", "report", "no"):
        assert not tb.enforced({tb.ENFORCE: off}), off
    for on in ("fail", "FAIL", " fail "):
        assert tb.enforced({tb.ENFORCE: on}), on


def test_this_session_measures_every_test(request):
    """The plugin is registered and started this test's clock; the teardown report of an
    earlier test in this process carried its CPU time (when one ran here before)."""
    assert request.config.pluginmanager.get_plugin("time_budget") is tb
    assert tb._START in request.node.stash
    assert tb.cpu_seconds() >= request.node.stash[tb._START]
    assert all(v >= 0.0 for v in tb._SPENT.values())
