"""The assertion helpers' factory ``proofs_checks.asserts._helper``, called at test time.

The ``assert_*`` helpers are built by ``_helper`` when ``proofs_checks.asserts`` is imported;
mutmut imports the package once before it forks a child per mutant, so a mutant of
``_helper`` never reaches the module-level helpers. These tests build fresh helpers from
``_helper`` itself (name, docstring, the two calling modes, the keywords each mode takes
out, the not-applicable switch), so that its mutants are seen
(``tests/mutants/proofs_checks_small.md``). No simulation: the runner is replaced by a
recorder where only the routing is at stake.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import proofs_checks as pc
from proofs_checks import asserts
from proofs_checks.asserts import _helper
from proofs_checks.assumptions import check_mass_spd
from proofs_checks.result import CheckResult


def _ok(**witness):
    return CheckResult.from_margin("mass_spd", 1.0, 0.0, dict(witness), "eq")


def _Spy(result):
    """A check function (named, documented) that records its calls and returns ``result``."""
    def spy(*args, **kwargs):
        """A spy check."""
        spy.calls.append((args, kwargs))
        return result
    spy.calls = []
    spy.result = result
    return spy


def _recording_runner(monkeypatch, result):
    calls = []

    def fake_run_checks(scenario, only=None, **kwargs):
        calls.append((scenario, only, kwargs))
        return [result]
    monkeypatch.setattr(asserts, "run_checks", fake_run_checks)
    return calls


def test_helper_name_and_full_docstring():
    h = _helper("mass_spd", check_mass_spd)
    assert h.__name__ == "assert_mass_spd" and h.__qualname__ == "assert_mass_spd"
    assert h.__doc__ == (
        "Assert that :func:`proofs_checks.assumptions.check_mass_spd` passes.\n\n"
        "Call it with that function's arguments, or with a scenario (name, TOML path\n"
        "or Scenario) and keyword options; raises AssertionError with the margin and\n"
        "the witness. See :mod:`proofs_checks.asserts`.\n\n"
        "Checked: M = Mᵀ ≻ 0 (section 2, after eq. (1)).")


def test_helper_direct_mode_passes_everything_to_the_check(monkeypatch):
    runner = _recording_runner(monkeypatch, _ok())
    spy = _Spy(_ok())
    h = _helper("mass_spd", spy)
    M = np.eye(2)
    assert h(M, rcond_min=0.5, seed=3) is spy.result
    assert len(spy.calls) == 1 and spy.calls[0][0][0] is M
    assert spy.calls[0][1] == {"rcond_min": 0.5, "seed": 3}          # seed is the check's own here
    # two positional arguments, the first a string: still the check's own arguments
    h("double_mass", "x")
    assert spy.calls[-1] == (("double_mass", "x"), {})
    h()                                                                 # no argument at all
    assert spy.calls[-1] == ((), {})
    assert runner == []


@pytest.mark.parametrize("scenario", ["double_mass", Path("my.toml"), "SC"])
def test_helper_scenario_mode_routes_to_run_checks(monkeypatch, scenario):
    result = _ok(required=0.2)
    runner = _recording_runner(monkeypatch, result)
    spy = _Spy(_ok())
    if scenario == "SC":
        scenario = pc.load("bouncing_ball")
    h = _helper("mass_spd", spy)
    assert h(scenario, seed=3, h=1e-3, t_end=1.0, overrides={"param.m1": 4.0}, rcond_min=0.2) is result
    assert spy.calls == []
    assert runner == [(scenario, ["mass_spd"], {"options": {"mass_spd": {"rcond_min": 0.2}}, "seed": 3,
                                                "h": 1e-3, "t_end": 1.0, "overrides": {"param.m1": 4.0}})]
    # without check options: options=None, and only the run_checks keywords given are passed
    h(scenario, t_end=2.0)
    assert runner[-1] == (scenario, ["mass_spd"], {"options": None, "t_end": 2.0})
    h(scenario)
    assert runner[-1] == (scenario, ["mass_spd"], {"options": None})


def test_helper_scenario_mode_runs_the_registered_check():
    h = _helper("mass_spd", check_mass_spd)
    r = h("double_mass", overrides={"param.m1": 4.0}, rcond_min=0.2)
    assert r.scenario == "double_mass" and r.witness["required"] == 0.2
    assert r.witness["lambda_max"] == pytest.approx(4.0)


def test_helper_raises_on_failure_and_on_not_applicable_when_asked():
    bad = CheckResult.from_margin("mass_spd", -0.5, 0.0, {}, "eq")
    na = CheckResult.not_applicable("mass_spd", "no K")
    with pytest.raises(AssertionError, match=r"^proof check mass_spd failed: margin -0\.5"):
        _helper("mass_spd", _Spy(bad))(np.eye(2))
    h = _helper("mass_spd", _Spy(na))
    assert h(np.eye(2)) is na                                          # default: allowed
    assert h(np.eye(2), allow_not_applicable=True) is na
    with pytest.raises(AssertionError, match=r"^proof check mass_spd is not applicable: no K"):
        h(np.eye(2), allow_not_applicable=False)
    # the switch is the helper's, never forwarded to the check
    spy = _Spy(_ok())
    _helper("mass_spd", spy)(np.eye(2), allow_not_applicable=False)
    assert spy.calls[-1][1] == {}


def test_helper_frames_are_hidden_in_pytest_reports():
    """A failing helper points at the user's test line: pytest's filtered traceback holds no
    frame of proofs_checks/asserts.py (``__tracebackhide__`` in the helper and in assert_result)."""
    bad = CheckResult.from_margin("mass_spd", -0.5, 0.0, {}, "eq")
    h = _helper("mass_spd", _Spy(bad))
    with pytest.raises(AssertionError) as info:
        h(np.eye(2))
    every = [str(e.frame.code.path) for e in info.traceback]
    shown = [str(e.frame.code.path) for e in info.traceback.filter(info)]
    mine = os.path.join("proofs_checks", "asserts.py")
    assert sum(p.endswith(mine) for p in every) == 2                  # the helper, then assert_result
    assert not any(p.endswith(mine) for p in shown)


def test_helper_docstring_from_undocumented_and_indented_checks():
    """A check function without a docstring gets a helper whose docstring ends in an empty
    "Checked: " (it used to raise IndexError at import); a docstring that starts with a
    blank line contributes its first non-blank line, stripped."""
    def bare(*args, **kwargs):
        return _ok()
    bare.__doc__ = None

    def blank(*args, **kwargs):
        return _ok()
    blank.__doc__ = "   \n  "

    def indented(*args, **kwargs):
        """
        First line of the check.

        More text.
        """
        return _ok()
    for fn, last in ((bare, "Checked: "), (blank, "Checked: "), (indented, "Checked: First line of the check.")):
        h = _helper("mass_spd", fn)
        assert h.__doc__.endswith("See :mod:`proofs_checks.asserts`.\n\n" + last)
        assert h.__doc__.splitlines()[0] == f"Assert that :func:`{__name__}.{fn.__name__}` passes."
        assert h().passed is True
