"""pytest plugin (entry point ``pytest11``): fixtures to run the proof checks in users' test suites.

Fixtures
--------
``double_mass_scenario``, ``rocking_chain_scenario``, ``bouncing_ball_scenario``, ``impact_oscillator_scenario``, ``grazing_scenario``
    The built-in scenarios, loaded once per session (:class:`observer.scenario.Scenario`).
``load_check_scenario``
    A function ``(name_or_path, overrides=None) -> Scenario`` (cached per session).
``check_seed``
    The seed of the checks (command-line option ``--proofs-checks-seed``, default 0).
``check_rng``
    A fresh ``numpy.random.Generator`` seeded with ``check_seed`` (one per test).
``check_system``
    A function ``(scenario, only=None, **kwargs) -> list[CheckResult]`` that runs the
    checks with the session seed and raises one readable AssertionError listing every
    failed check (:func:`proofs_checks.assert_checks`).

A user's test of their own system is three lines::

    def test_my_system_satisfies_theorem_1(check_system):
        check_system("tests/my_system.toml")

Without the installed entry point, enable it with ``pytest -p proofs_checks.plugin``.
Importing this module is cheap: the toolkit is imported when a fixture is first used.
"""

from __future__ import annotations

import pytest

from observer.scenarios import SCENARIOS

BUILTIN_SCENARIOS = tuple(SCENARIOS)
"""Names of the built-in scenarios (:data:`observer.SCENARIOS`): one fixture each."""


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("proofs_checks", "numerical proof checks (proofs_checks)")
    group.addoption("--proofs-checks-seed", type=int, default=0, dest="proofs_checks_seed",
                    help="seed of the proof checks' random sampling (default 0)")


@pytest.fixture(scope="session")
def check_seed(request: pytest.FixtureRequest) -> int:
    """Seed of the proof checks (``--proofs-checks-seed``, default 0)."""
    return int(request.config.getoption("proofs_checks_seed", default=0) or 0)


@pytest.fixture
def check_rng(check_seed: int):
    """A ``numpy.random.Generator`` seeded with :func:`check_seed`, fresh for every test."""
    import numpy as np
    return np.random.default_rng(check_seed)


@pytest.fixture(scope="session")
def load_check_scenario():
    """``load(name_or_path, overrides=None) -> Scenario``, cached for the session."""
    import observer
    cache: dict = {}

    def load(name_or_path, overrides: dict | None = None):
        key = (str(name_or_path), tuple(sorted((overrides or {}).items(), key=str)))
        if key not in cache:
            cache[key] = observer.load_scenario(name_or_path, overrides)
        return cache[key]

    return load


@pytest.fixture
def check_system(check_seed: int):
    """Run the proof checks on a scenario and assert that none fails.

    ``check_system(scenario, only=None, allow_not_applicable=True, **run_checks_kwargs)``;
    returns the list of :class:`~proofs_checks.result.CheckResult`.
    """
    import proofs_checks

    def check(scenario, only=None, **kwargs):
        __tracebackhide__ = True
        kwargs.setdefault("seed", check_seed)
        return proofs_checks.assert_checks(scenario, only, **kwargs)

    return check


def _scenario_fixture(name: str):
    @pytest.fixture(scope="session", name=f"{name}_scenario")
    def fixture(load_check_scenario):
        return load_check_scenario(name)

    fixture.__doc__ = f"The built-in scenario ``{name}`` (loaded once per session)."
    return fixture


for _name in BUILTIN_SCENARIOS:
    globals()[f"_{_name}_scenario"] = _scenario_fixture(_name)
del _name
