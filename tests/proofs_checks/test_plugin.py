"""The pytest plugin of proofs_checks, exercised as a user would: a separate pytest run of a
user's test file with the plugin enabled (``-p proofs_checks.plugin``; entry-point
autoloading is disabled in that run so the test also works once the ``pytest11`` entry
point is installed)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import observer
from proofs_checks import plugin
import argparse
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]

USER_TESTS = textwrap.dedent('''
    import numpy as np
    import proofs_checks

    def test_builtin_fixtures(double_mass_scenario, rocking_chain_scenario, bouncing_ball_scenario,
                              impact_oscillator_scenario, grazing_scenario):
        assert double_mass_scenario.name == "double_mass"
        assert rocking_chain_scenario.system.m == 20
        assert bouncing_ball_scenario.system.n == 1
        assert grazing_scenario.name == "grazing" and impact_oscillator_scenario.name == "impact_oscillator"

    def test_seed_and_rng(check_seed, check_rng):
        assert check_seed == 7
        assert check_rng.random() == np.random.default_rng(7).random()

    def test_my_system_three_lines(check_system):
        results = check_system("bouncing_ball", only="mass_spd,constraints_independent,impact_monotone")
        assert [r.passed for r in results] == [True, True, True]

    def test_assert_helper_on_fixture(rocking_chain_scenario, check_rng):
        sc = rocking_chain_scenario
        proofs_checks.assert_projection_psd(sc.system.K, sc.system.W, rng=check_rng, samples=50)

    def test_known_bad_system_fails(check_system):
        check_system("rocking_chain", only="impact_monotone",
                     overrides={"param.N": 1, "impact.law": "newton", "impact.restitution": [0.1, 0.95]},
                     options={"impact_monotone": {"samples": 8, "adversarial_sets": 2}})
''')


def test_plugin_fixtures_in_a_user_suite(tmp_path):
    (tmp_path / "test_user.py").write_text(USER_TESTS)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env["PYTEST_DISABLE_PLUGIN_AUTOLOAD"] = "1"
    p = subprocess.run([sys.executable, "-m", "pytest", "-p", "proofs_checks.plugin", "-p", "no:cacheprovider",
                        "--proofs-checks-seed", "7", "-q", "test_user.py"],
                       cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    out = p.stdout
    assert "1 failed, 4 passed" in out, out + p.stderr
    assert "test_known_bad_system_fails" in out
    # the failure message carries the table, the margin and the witness
    assert "1 of 1 proof checks failed on rocking_chain" in out
    assert "margin" in out and "max_rho" in out and "gamma1_minus" in out


def test_plugin_lists_every_builtin_scenario():
    assert plugin.BUILTIN_SCENARIOS == tuple(observer.SCENARIOS)


# ----------------------------------------------------------------------------------------
# (formerly tests/test_proofs_kill_plugin.py)
# proofs_checks.plugin in-process: the fixtures as a user's test sees them (the plugin is
# active in this suite through its ``pytest11`` entry point, or ``-p proofs_checks.plugin``),
# the command-line option's definition, and the scenario fixtures built by
# ``_scenario_fixture``. Written against the mutation run of ``plugin.py``. About 1 s.
# ----------------------------------------------------------------------------------------
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
