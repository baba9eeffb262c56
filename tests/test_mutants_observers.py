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


def test_projection_part_uses_recorded_pre_jump_states_only_when_both_have_them():
    """ΔV's projection part: ½‖e⁺‖²_K − ½‖e⁻‖²_K with e⁻ from the recorded ``q_pre`` of both
    trajectories (any metric); with one of them missing, from the K-metric multipliers Σ."""
    from observer.observers import lyapunov_decrements
    s = observer.load_scenario("double_mass").system
    rng = np.random.default_rng(3)
    a = {k: rng.standard_normal((3, 2)) for k in ("q", "u", "q_pre")}
    b = {k: rng.standard_normal((3, 2)) for k in ("q", "u", "q_pre")}
    a["P"], b["P"] = rng.standard_normal((3, 1)), rng.standard_normal((3, 1))
    K = s.K
    e, e_pre = a["q"] - b["q"], a["q_pre"] - b["q_pre"]
    expected = [0.5 * (e[k] @ K @ e[k] - e_pre[k] @ K @ e_pre[k]) for k in (1, 2)]
    out = lyapunov_decrements(s, 0.01, a, b)
    assert out["projection"][0] == 0.0 and np.allclose(out["projection"][1:], expected, rtol=1e-12, atol=0)
    # b without q_pre: the K-metric form from Σ (none given: no jump, part 0)
    b_plain = {k: v for k, v in b.items() if k != "q_pre"}
    for x, y in ((a, b_plain), (b_plain, a)):
        out = lyapunov_decrements(s, 0.01, x, y)
        assert np.array_equal(out["projection"], np.zeros(3))
    sig = {**b_plain, "sigma": np.array([[0.0], [0.5], [0.0]])}
    out = lyapunov_decrements(s, 0.01, a, sig)
    ee = a["q"][1] - b["q"][1]
    em = ee + np.linalg.solve(K, s.W @ np.array([0.5]))          # e⁻ = e⁺ − K⁻¹W(Σ_a − Σ_b), Σ_a = 0
    assert out["projection"][1] == pytest.approx(0.5 * (ee @ K @ ee - em @ K @ em), rel=1e-12)
