"""observer.observers: the design record's validation and metric matrices, built at test
time (the registry's entries are built at import, before mutmut forks its children, so
only designs constructed inside a test see mutants of ``ObserverDesign``), and the
``[observer] observers`` type error. Written against the mutation run of
``observer/observers.py`` (``tests/mutants/observers.md``).
"""

from __future__ import annotations

import numpy as np
import pytest

import observer
from observer.errors import InputError
from observer.observers import METRICS, ObserverConfig, ObserverDesign


def test_design_validation_at_construction():
    for metric in METRICS:
        assert ObserverDesign("d", True, metric, "d", "k").metric == metric
    assert ObserverDesign("d", False, None, "d", "k").metric is None
    for jumps, metric in ((True, None), (False, "K"), (False, "mass"), (True, "euclid"), (False, "euclid")):
        with pytest.raises(ValueError) as info:
            ObserverDesign("bad", jumps, metric, "b", "k")
        assert str(info.value) == f"observer design 'bad': metric {metric!r} does not match position_jumps={jumps}"


def test_metric_matrices():
    sc = observer.load_scenario("rocking_chain", {"param.N": 1})
    s = sc.system
    assert ObserverDesign("m", True, "mass", "m", "k").metric_matrix(s) is s.M
    eye = ObserverDesign("i", True, "identity", "i", "k").metric_matrix(s)
    assert eye.shape == (s.n, s.n) and np.array_equal(eye, np.eye(s.n))
    assert ObserverDesign("K", True, "K", "K", "k").metric_matrix(s) is None
    assert ObserverDesign("n", False, None, "n", "k").metric_matrix(s) is None


def test_observer_list_must_be_an_array():
    with pytest.raises(InputError) as info:
        ObserverConfig.from_table({"observers": "jump"}, 1, np.zeros(1), np.zeros(1))
    assert info.value.field == "observer.observers"
    assert info.value.problem == "must be an array of design names, got 'jump'"
