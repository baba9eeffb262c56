"""Project-wide fixtures: ``engine``, one test per registered engine (docs/guide/testing.md).

The ``engine`` fixture runs a physics test once on every engine of
:data:`observer.engines.ENGINES` plus the toy engine of ``tests/toys/`` (registered for the
test's duration), each with its own tolerances (:data:`TOLERANCES`, as OSQP's tests give
each backend its own). The test describes its case through :meth:`EngineUnderTest.simulate`;
an engine that refuses the case (:meth:`observer.engines.base.Engine.accepts`) skips with the
refusal as its reason. When every engine refused a test's case (all of its engine variants
skipped by a refusal), the session fails and names the test: a physics test must run
somewhere.

It also registers the per-test CPU budget (``tests/time_budget.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest

import observer
from observer.engines import ENGINES, Engine, describe
from observer.simulate import _scenario, check_arguments
from toys.toy_engine import TOY_ENGINE


@dataclass(frozen=True)
class Tolerances:
    """An engine's tolerances in the physics tests.

    Attributes
    ----------
    same_scheme : float or None
        Largest difference (absolute, on values of order 1) from another implementation of
        the same Moreau–Jean scheme (Siconos, the numpy stepper): round-off only. None for an
        engine of another scheme (it refuses every time-stepping case).
    """

    same_scheme: float | None


TOLERANCES = {"compiled": Tolerances(same_scheme=1e-10), "python": Tolerances(same_scheme=1e-10),
              "toy": Tolerances(same_scheme=1e-10), "event": Tolerances(same_scheme=None)}
"""Per engine (name → :class:`Tolerances`); a registered engine without an entry fails its
tests (KeyError) until it is given one."""

NUMPY_STEPPERS = frozenset({"python", "toy"})
"""Engines that take every step in Python with the numpy stepper (tens of µs a step, about
100× the compiled kernel): a convergence study may give them the coarse end of its step-size
ladder, as many step sizes as its fitted order needs (:attr:`EngineUnderTest.numpy_stepping`;
the test says which)."""

ENGINE_NAMES = (*ENGINES, TOY_ENGINE.name)
REFUSED = "refused by the engine: "
"""Prefix of the skip reason of a refused case (the session's check counts these skips)."""


@dataclass(frozen=True)
class EngineUnderTest:
    """The engine a test runs on: its registry entry, name and tolerances."""

    engine: Engine
    tol: Tolerances

    @property
    def name(self) -> str:
        return self.engine.name

    @property
    def numpy_stepping(self) -> bool:
        """Whether the engine steps in numpy, one Python-level step at a time (:data:`NUMPY_STEPPERS`)."""
        return self.name in NUMPY_STEPPERS

    def refusal(self, scenario, **kwargs):
        """The engine's refusal of ``observer.simulate(scenario, **kwargs)`` on it, or None."""
        kwargs.setdefault("integrator", self.engine.integrator)
        integrator, coupling, residual_tol, observers = check_arguments(
            self.name, kwargs.get("integrator"), kwargs.get("coupling", "scenario"),
            kwargs.get("residual_tol", 1e-9), kwargs.get("record_every"), kwargs.get("observers", ()),
            kwargs.get("on_chunk"))
        sc = _scenario(scenario, **{k: kwargs.get(k) for k in ("h", "t_end", "solver", "theta",
                                                               "master_projection")})
        run = describe(sc, integrator, observers, kwargs.get("source"), coupling, kwargs.get("log"),
                       residual_tol, kwargs.get("record_every"), kwargs.get("store", "full"),
                       kwargs.get("on_chunk"))
        return self.engine.accepts(run)

    def simulate(self, scenario, **kwargs):
        """``observer.simulate`` on this engine (integrator: the engine's own unless given);
        skips the test with the refusal when the engine does not take the case."""
        kwargs.setdefault("integrator", self.engine.integrator)
        why = self.refusal(scenario, **kwargs)
        if why is not None:
            pytest.skip(f"{REFUSED}{self.name}: {why}")
        return observer.simulate(scenario, engine=self.name, **kwargs)


@pytest.fixture(params=ENGINE_NAMES)
def engine(request, monkeypatch) -> EngineUnderTest:
    """Each registered engine and the toy engine, in turn (see the module docstring)."""
    if request.param == TOY_ENGINE.name:
        monkeypatch.setitem(ENGINES, TOY_ENGINE.name, TOY_ENGINE)
    others = {k: v for k, v in request.node.callspec.params.items() if k != "engine"}
    request.node.user_properties.append(
        ("engine_case", f"{request.node.path}::{request.node.originalname}{sorted(others.items())!r}"))
    return EngineUnderTest(ENGINES[request.param], TOLERANCES[request.param])


# ---------------------------------------------------------------------------------------
# every engine-parametrized case runs on at least one engine
# ---------------------------------------------------------------------------------------
_OUTCOMES: dict[str, list[str]] = {}


def _case(report) -> str | None:
    return next((value for key, value in report.user_properties if key == "engine_case"), None)


def pytest_runtest_logreport(report):
    """Collect each engine variant's outcome (on the xdist controller, from every worker)."""
    case = _case(report)
    if case is None:
        return
    if report.when == "call" or (report.when == "setup" and not report.passed):
        refused = report.skipped and REFUSED in str(report.longrepr)
        _OUTCOMES.setdefault(case, []).append("refused" if refused else report.outcome)


def _unrun() -> list[str]:
    """The cases every engine was tried on and every engine refused."""
    return sorted(c for c, seen in _OUTCOMES.items()
                  if len(seen) >= len(ENGINE_NAMES) and all(o == "refused" for o in seen))


def pytest_terminal_summary(terminalreporter, config):
    if hasattr(config, "workerinput"):
        return
    for case in _unrun():
        terminalreporter.write_line(f"FAILED (no engine ran it) {case}", red=True)


def pytest_sessionfinish(session, exitstatus):
    if not hasattr(session.config, "workerinput") and _unrun() and exitstatus == 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


# ---------------------------------------------------------------------------------------
# the per-test CPU budget (tests/time_budget.py)
# ---------------------------------------------------------------------------------------
def pytest_configure(config):
    import time_budget

    if not config.pluginmanager.is_registered(time_budget):
        config.pluginmanager.register(time_budget, "time_budget")
