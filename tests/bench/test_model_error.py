"""The stored floor-versus-ε measurement of :mod:`bench.model_error` (issue 33, acceptance 3).

The stored result is what the guide and the report quote; these tests keep it true: its
slopes refit from its own member floors, one of its points recomputed from scratch (ε = 1e-2,
every member over the whole window), and the fit itself checked on an exact power law.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.model_error import DESIGNS, EPSILONS, STORED, bootstrap_slopes, fit_slope, member_floors


@pytest.fixture(scope="module")
def stored() -> dict:
    return json.loads(STORED.read_text())


def test_the_fit_recovers_an_exact_power_law_and_its_interval_is_a_point():
    eps = np.array(EPSILONS)
    floors = 3e-2 * eps[:, None] ** 2 * np.linspace(1.0, 2.0, 5)[None, :]
    slope, intercept = fit_slope(eps, floors)
    assert slope == pytest.approx(2.0, abs=1e-12)
    assert intercept == pytest.approx(np.log10(3e-2 * 1.5), abs=1e-12)
    boot = bootstrap_slopes(eps, floors, 50, np.random.default_rng(0))
    np.testing.assert_allclose(boot, 2.0, atol=1e-12)
    bent = floors * (1.0 + 100.0 * eps[:, None])                 # a near miss: not a power law
    assert abs(fit_slope(eps, bent)[0] - 2.0) > 0.05


def test_the_stored_slopes_refit_from_the_stored_member_floors(stored):
    assert stored["status"] == "ok" and stored["epsilons"] == pytest.approx(list(EPSILONS), rel=1e-15)
    assert min(stored["epsilons"]) == pytest.approx(1e-4) and max(stored["epsilons"]) == pytest.approx(1e-2)
    for d in DESIGNS:
        r = stored["designs"][d]
        F = np.array(r["member_floors"])
        assert F.shape == (len(EPSILONS), stored["members"])
        slope, _ = fit_slope(np.array(EPSILONS), F)
        assert slope == pytest.approx(r["slope"], rel=1e-12)
        lo, hi = r["slope_interval_95"]
        assert lo <= slope <= hi
        np.testing.assert_allclose(r["floor_median"], np.median(F, axis=1), rtol=1e-15)


def test_the_stored_point_at_one_per_cent_is_recomputed(stored):
    again = member_floors(EPSILONS[-1], stored["members"], stored["seed"], stored["t_end"], workers=1)
    for d in DESIGNS:
        np.testing.assert_allclose(again[d], stored["designs"][d]["member_floors"][-1], rtol=1e-9)


def test_the_guide_quotes_the_stored_numbers(stored):
    """docs/guide/model-error.md's table: slope, interval, floor at 1e-2 and without error, as
    stored (to the digits shown)."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "guide" / "model-error.md").read_text()
    for d in DESIGNS:
        row = next(line for line in text.splitlines() if line.startswith(f"| {d} |"))
        cells = [c.strip() for c in row.strip("|").split("|")]
        slope, interval, at_1e2, exact = cells[1], cells[2], cells[3], cells[4]
        r = stored["designs"][d]
        digits = len(slope.split(".")[1])
        assert float(slope) == round(r["slope"], digits), (d, slope)
        lo, hi = (float(x) for x in interval.strip("[]").split(","))
        assert (lo, hi) == (round(r["slope_interval_95"][0], digits), round(r["slope_interval_95"][1], digits))
        assert float(at_1e2) == float(f"{r['floor_median'][-1]:.2g}"), (d, at_1e2)
        assert float(exact) == float(f"{r['exact_floor_median']:.2g}"), (d, exact)


def test_the_sensitivity_table_holds_its_invariants_and_the_guide_quotes_it(stored):
    """K costs most for both designs; the observer without jumps does not see W's scale or the
    gap offset (its floor is the exact one: it uses no gap while coupled and its velocity jump
    depends on the span of W only); the K row is the curve's point at 1e-2; the guide's
    sensitivity table quotes the stored medians (2 digits)."""
    from pathlib import Path

    sens = stored["sensitivity"]
    floors = sens["floor_median"]
    assert sens["eps"] == EPSILONS[-1]
    for d in DESIGNS:
        assert max(floors, key=lambda p: floors[p][d]) == "K"
        assert floors["K"][d] == stored["designs"][d]["floor_median"][-1]
    exact = stored["designs"]["nojump"]["exact_floor_median"]
    for p in ("W", "gap.offset"):
        assert floors[p]["nojump"] == pytest.approx(exact, rel=1e-6)
        assert floors[p]["jump"] > 1e3 * stored["designs"]["jump"]["exact_floor_median"]
    text = (Path(__file__).resolve().parents[2] / "docs" / "guide" / "model-error.md").read_text()
    for p, by_design in floors.items():
        row = next(line for line in text.splitlines() if line.startswith(f"| {p} |"))
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert [float(c) for c in cells[1:]] == [float(f"{by_design[d]:.2g}") for d in DESIGNS], row


def test_the_uncertainty_ensemble_is_recomputed_and_the_guide_quotes_it(stored):
    """Draw 0 of the sampled models recomputed from scratch; the median, range and fraction
    follow from the stored draws; the guide's table and fraction quote them."""
    from pathlib import Path

    from bench.model_error import DRAW_STD

    u = stored["uncertainty"]
    again = member_floors(0.0, stored["members"], stored["seed"], stored["t_end"], workers=1,
                          model={"K": {"relative_std": DRAW_STD, "seed": 0}})
    text = (Path(__file__).resolve().parents[2] / "docs" / "guide" / "model-error.md").read_text()
    for d in DESIGNS:
        draws = np.array(u["draw_floor_median"][d])
        assert draws.size == u["draws"]
        assert draws[0] == pytest.approx(float(np.median(again[d])), rel=1e-9)
        assert u["floor_median_over_draws"][d] == float(np.median(draws))
        assert u["floor_range_95"][d] == [float(x) for x in np.percentile(draws, [2.5, 97.5])]
        rows = [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines()
                if line.startswith(f"| {d} | ")]
        row = cells = next(r for r in rows if len(r) == 3)          # the uncertainty table's row
        assert float(cells[1]) == float(f"{u['floor_median_over_draws'][d]:.2g}"), row
        lo, hi = (float(x) for x in cells[2].strip("[]").split(","))
        assert (lo, hi) == tuple(float(f"{x:.2g}") for x in u["floor_range_95"][d]), row
    fraction = np.mean(np.array(u["draw_floor_median"]["nojump"]) < np.array(u["draw_floor_median"]["jump"]))
    assert u["nojump_lower_fraction"] == fraction
    assert f"lower floor in {round(100 * fraction)} % of the draws" in text


def test_the_scenario_floors_are_the_double_mass_floors_on_double_mass():
    """bench.model_error_parameters.scenario_floors (any scenario) on double_mass gives
    bench.model_error.member_floors' floors bitwise (a short horizon, two members, M off by 1 %)."""
    from bench.model_error_parameters import scenario_floors

    a = scenario_floors("double_mass", 1e-2, 2, 0, 2.0, 1, "M")
    b = member_floors(1e-2, 2, 0, 2.0, 1, "M")
    assert a == b and a["jump"] != member_floors(0.0, 2, 0, 2.0, 1, "M")["jump"]


def _other_scenarios() -> list:
    from bench.model_error_parameters import STORED as PARAMS

    return sorted(p for p in PARAMS.parent.glob("model_error_parameters_*.json") if p != PARAMS)


@pytest.mark.parametrize("path", _other_scenarios(), ids=lambda p: p.stem)
def test_the_stored_point_of_a_one_per_cent_stiffness_error_is_recomputed_on_each_other_scenario(path):
    """The K curve's point at ε = 1e-2 of each stored scenario but double_mass (whose M point
    tests/bench/test_stored_floor_curves.py recomputes), from the settings the file states."""
    from bench.model_error_parameters import EPSILONS, SCENARIOS, scenario_floors

    stored = json.loads(path.read_text())
    s = stored["settings"]
    assert {k: v for k, v in s.items() if v is not None} == SCENARIOS[stored["scenario"]]
    rec = next(r for r in stored["curves"] if r["key"] == "K")
    i = rec["sizes"].index(1e-2)
    assert rec["sizes"] == list(EPSILONS)
    again = scenario_floors(stored["scenario"], 1e-2, stored["members"], stored["seed"], s["t_end"], 1, "K",
                            s["h"], s["V0"])
    for d, r in rec["designs"].items():
        np.testing.assert_allclose(again[d], r["member_floors"][i], rtol=1e-9)
        assert not np.allclose(again[d], r["member_floors"][i - 1], rtol=1e-3)


def test_an_unknown_scenario_is_one_line_and_exit_2(capsys):
    from bench.model_error_parameters import main

    assert main(["--scenario", "no_such_scenario"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: --scenario:") and "no_such_scenario" in err
