"""One name per concept (issue 35): the old spellings users may have written still work, with a
DeprecationWarning, and mean the same as the registered names."""

from __future__ import annotations

import warnings

import pytest

import observer
from observer.ensemble import _check_options
from observer.observers import DESIGN_ALIASES, OBSERVER_DESIGNS, design_name


def test_the_no_jump_design_has_one_identifier_and_one_label():
    assert "nojump" in OBSERVER_DESIGNS
    assert OBSERVER_DESIGNS["nojump"].label == "no-jump"
    assert not set(DESIGN_ALIASES) & set(OBSERVER_DESIGNS)


@pytest.mark.parametrize("old", ["no_jump", "no-jump", "no jump"])
def test_old_design_spellings_are_read_with_a_deprecation_warning(old):
    with pytest.warns(DeprecationWarning, match="nojump"):
        assert design_name(old) == "nojump"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert design_name("nojump") == "nojump"        # the registered name: no warning


def test_an_old_design_spelling_in_a_scenario_selects_the_nojump_design():
    with pytest.warns(DeprecationWarning):
        sc = observer.load_scenario("double_mass", {"observer.observers": ["jump", "no_jump"]})
        from observer.observers import ObserverConfig
        cfg = ObserverConfig.from_table(sc.observer, sc.system.n, sc.q0, sc.u0)
    assert cfg.observers == ("jump", "nojump")


def test_the_integrator_is_time_stepping_and_the_old_spelling_is_deprecated():
    args = ("summary", 0, 2, 1, None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _check_options("time-stepping", *args)[0] == "time-stepping"
    with pytest.warns(DeprecationWarning, match="time-stepping"):
        assert _check_options("timestepping", *args)[0] == "time-stepping"
    with pytest.raises(observer.InputError, match="integrator"):
        _check_options("time_stepping", *args)
