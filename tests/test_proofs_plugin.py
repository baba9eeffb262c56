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

REPO = Path(__file__).resolve().parents[1]

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
