"""The stored per-parameter curve (bench/model_error_parameters.py): one point recomputed."""

from __future__ import annotations

import json

import numpy as np

from bench.model_error import member_floors
from bench.model_error_parameters import EPSILONS, STORED


def test_the_stored_point_of_a_ten_per_cent_mass_error_is_recomputed():
    stored = json.loads(STORED.read_text())
    rec = next(r for r in stored["curves"] if r["key"] == "M")
    assert rec["sizes"] == list(EPSILONS) and stored["status"] and stored["versions"]
    again = member_floors(EPSILONS[-1], stored["members"], stored["seed"], stored["t_end"], workers=1, parameter="M")
    for d, r in rec["designs"].items():
        np.testing.assert_allclose(again[d], r["member_floors"][-1], rtol=1e-9)
        assert not np.allclose(again[d], r["member_floors"][-2], rtol=1e-3)     # the neighbouring ε differs


def test_the_stored_point_of_a_millisecond_of_jitter_is_recomputed():
    from bench import sensor_floor

    stored = json.loads(sensor_floor.STORED.read_text())
    rec = next(r for r in stored["curves"] if r["key"] == "jitter")
    i = rec["sizes"].index(1e-3)
    s = stored["settings"]
    again = sensor_floor.member_floors({"jitter": 1e-3, "seed": s["sensor_seed"]}, s["members"], s["t_end"])
    for d, r in rec["designs"].items():
        np.testing.assert_allclose(again[d], r["member_floors"][i], rtol=1e-9)
        assert not np.allclose(again[d], r["member_floors"][i - 1], rtol=1e-3)
