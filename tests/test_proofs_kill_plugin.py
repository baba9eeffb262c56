"""proofs_checks.plugin in-process: the fixtures as a user's test sees them (the plugin is
active in this suite through its ``pytest11`` entry point, or ``-p proofs_checks.plugin``),
the command-line option's definition, and the scenario fixtures built by
``_scenario_fixture``. Written against the mutation run of ``plugin.py``. About 1 s.
"""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from proofs_checks import plugin


def test_seed_option_default_and_rng(check_seed, check_rng, request):
    assert request.config.getoption("proofs_checks_seed") == check_seed
    assert check_rng.random() == np.random.default_rng(check_seed).random()


def test_builtin_scenario_fixtures_are_the_cached_scenarios(double_mass_scenario, grazing_scenario,
                                                            load_check_scenario):
    assert double_mass_scenario.name == "double_mass" and grazing_scenario.name == "grazing"
    assert load_check_scenario("double_mass") is double_mass_scenario
    assert load_check_scenario("double_mass", {"impact.restitution": 0.5}) is \
        load_check_scenario("double_mass", {"impact.restitution": 0.5})


def test_scenario_fixture_factory():
    fx = plugin._scenario_fixture("bouncing_ball")
    assert fx.__doc__ == "The built-in scenario ``bouncing_ball`` (loaded once per session)."
    assert set(plugin.BUILTIN_SCENARIOS) >= {"double_mass", "rocking_chain", "bouncing_ball",
                                             "impact_oscillator", "grazing"}


class _Parser:
    """Records ``getgroup``/``addoption`` of :func:`plugin.pytest_addoption`."""

    def __init__(self):
        self.groups, self.options = [], []

    def getgroup(self, name, description=""):
        self.groups.append((name, description))
        return self

    def addoption(self, *names, **kw):
        self.options.append((names, kw))


def test_addoption_defines_the_seed_option():
    p = _Parser()
    plugin.pytest_addoption(p)
    assert p.groups == [("proofs_checks", "numerical proof checks (proofs_checks)")]
    (names, kw), = p.options
    assert names == ("--proofs-checks-seed",)
    assert kw == {"type": int, "default": 0, "dest": "proofs_checks_seed",
                  "help": "seed of the proof checks' random sampling (default 0)"}
    # the definition parses as documented
    ap = argparse.ArgumentParser()
    ap.add_argument(*names, **kw)
    assert ap.parse_args([]).proofs_checks_seed == 0
    assert ap.parse_args(["--proofs-checks-seed", "7"]).proofs_checks_seed == 7


def test_check_system_asserts(check_system):
    results = check_system("bouncing_ball", only="mass_spd,constraints_independent")
    assert [r.passed for r in results] == [True, True]
    with pytest.raises(AssertionError, match="impact_monotone"):
        check_system("rocking_chain", only="impact_monotone",
                     overrides={"param.N": 1, "impact.law": "newton", "impact.restitution": [0.1, 0.95]},
                     options={"impact_monotone": {"samples": 8, "adversarial_sets": 1, "local_samples": 8}})
