"""The report's first screen and its evidence, built from a quick-suite-like result set with
ensemble rows (synthetic, known answers): claims with CIs first (also in a headless Chromium
screenshot at 1400×1000), at most 8 key numbers, the settling matrix, the proof-check matrix,
collapsible tables with their CSV beside the page, and the discrete artifact with its remedy.
"""

from __future__ import annotations

import math
import re
import time

import numpy as np
import pandas as pd
import pytest

from reports.analysis import paired_settling, rise_distribution
from reports.browser import check_page, find_chromium
from reports.build import build_report
from reports.context import load_rows
from reports.ensemble_view import BAND_Q, member_rows, path_band, settling_matrix
from reports import forest
from reports.sections import artifacts, claims, k_metric_claims
from reports.sections.key_numbers import MAX_ITEMS, headlines
from tests.reports.test_build import _parse, _rows_file, _section_page, _synthetic_rows

pytestmark = pytest.mark.xdist_group("report_ensemble")
"""With ``--dist loadgroup`` the module runs on one worker: its module fixture (the page of the
ensemble rows) is built once, not once per worker. With pytest 9.2 and pytest-xdist 3.8 the group is
ignored (the worker renames the node id through a field pytest no longer reads: pytest-xdist issue
1386); ``--dist loadscope`` keeps a module on one worker meanwhile."""

N = 60
"""Members per design and ensemble."""
RHO_COLS = {1e-3: "0.001", 1e-5: "1e-05", 1e-6: "1e-06", 1e-9: "1e-09"}
SPEEDUP = 2.0
"""nojump's settling times are SPEEDUP × jump's (times a member-wise noise)."""
NEVER = 7
"""Members 0..NEVER−1 of nojump never settle below 1e-9."""
ENSEMBLES = (("double_mass", "time-stepping"), ("double_mass", "event"),
             ("double_mass (projected master)", "time-stepping"),
             ("persistent contact", "time-stepping"), ("persistent contact", "event"))
"""(label, integrator) of the synthetic ensembles: jump's V rises only time-stepped with the
plain master."""
SCENARIO_ENSEMBLES = (("rocking_chain (N = 4)", "rocking_chain"), ("rocking_chain (N = 10)", "rocking_chain"),
                      ("grazing", "grazing"), ("grazing (h = 0.0005)", "grazing"),
                      ("random_system (seed 0, 2 DOF, 1 contact)", "random_system"),
                      ("random_system (seed 1, 3 DOF, 2 contacts)", "random_system"),
                      ("random_system (seed 2, 4 DOF, 3 contacts)", "random_system"))
"""Time-stepped ensembles of other scenarios (label, scenario) for the first screen's claims."""
GAP = 3.2e-5
"""The proof checks' master-penetration term / V in the synthetic witness."""


RATE = 3.0
"""Decay rate (1/s) scale of the synthetic members: member m of a design decays at
RATE·factor·(1 + 0.1 sin(m + len(design))) / base_m, factor SPEEDUP for jump, 1 for nojump
(:data:`RATIOS` where not)."""
RATIOS = {"rocking_chain (N = 4)": {"jump": 1.0, "nojump": 1.0},
          "random_system (seed 1, 3 DOF, 2 contacts)": {"jump": 0.9, "nojump": 1.0}}
"""jump's rate over nojump's where it is not SPEEDUP: the chain at N = 4 runs uncoupled
(identical designs), random seed 1: jump is slower."""
MASTERS = 3
"""Masters of the random systems' and the N = 10 chain's ensembles (member m on master m mod 3)."""
CHAIN_FIT = 0.9
"""Seconds after t_on over which the N = 10 chain's rates are fitted; a floor stops every odd member's fit."""


def _member_rows(label: str, integrator: str, rng, scenario: str = "double_mass") -> list[dict]:
    base = rng.uniform(1.0, 4.0, N)
    rate_of = {"jump_mass": SPEEDUP / 1.3, "jump": SPEEDUP, "nojump": 1.0, **RATIOS.get(label, {})}
    same = rate_of["jump"] == rate_of["nojump"]
    rows = []
    for design, scale in (("jump", 1.0), ("nojump", SPEEDUP), ("jump_mass", 1.3)):
        noise = rng.lognormal(0.0, 0.05, N)
        for m in range(N):
            row = {"kind": "ensemble", "scenario": scenario, "label": label, "design": design,
                   "rate": RATE * rate_of.get(design, 1.0) * (1 + 0.1 * np.sin(m + (0 if same else len(design))))
                   / base[m],
                   "member": m, "integrator": integrator, "h": 2e-4, "t_end": 10.0, "seed": 0,
                   "status": "ok", "V_on": 0.5, "V_max": 0.5, "V_end": 1e-12, "rises": 0,
                   "max_rise_rel": 0.0}
            for i, (rho, key) in enumerate(RHO_COLS.items()):
                t = base[m] * scale * noise[m] * (1 + i)
                if design == "nojump" and rho == 1e-9 and m < NEVER:
                    t = math.inf
                row[f"t_settle_{key}"] = t
                row[f"t_sync_{key}"] = t
            if scenario == "random_system" or label == "rocking_chain (N = 10)":
                row["master"] = m % MASTERS
            if label == "rocking_chain (N = 10)":
                row.update(rate_t_fit=CHAIN_FIT, rate_floor_stop=bool(m % 2))
            if integrator == "time-stepping" and "projected" not in label and design == "jump" \
                    and m % 3 == 0:
                row["max_rise_rel"] = 7000.0 if m == 0 else 2.5
            if design == "jump_mass" and m % 2 == 0:
                row["max_rise_rel"] = 0.4
            rows.append(row)
    return rows


def _trajectory(out, name: str, rises: bool) -> str:
    """V of the jump design falling exponentially, with jumps up once per second when ``rises``."""
    t = np.linspace(0.0, 10.0, 501)
    v = 0.5 * np.exp(-3.0 * t)
    if rises:
        v = np.where((t % 1.0 < 0.015) & (t > 0.5), v * 7000.0, v)      # once per second
    path = out / f"{name}.parquet"
    pd.DataFrame({"t": t, "master_q": np.sin(t), "master_g": np.abs(np.sin(t)), "jump_q": np.sin(t),
                  "jump_g": np.abs(np.sin(t)), "V_jump": v}).to_parquet(path)
    return path.name


def _artifact_rows(out) -> list[tuple[str, list[dict]]]:
    cases = []
    for integ, params, name, rises in (("time-stepping", "", "dm20", True),
                                       ("time-stepping", "simulation.master_projection=True",
                                        "dm20 · projected master", False),
                                       ("event", "", "dm20", False)):
        row = {"kind": "observers", "scenario": "double_mass", "name": name, "observer": "jump",
               "status": "ok", "note": "", "h": 1e-4, "t_end": 20.0, "t_on": 1.0, "t_off": 20.0,
               "law": "newton", "solver": "pivoting", "params": params, "V_on": 0.5,
               "V_min": 1e-25, "V_end_rel": 5e-9 if rises else 1e-24, "integrator": integ,
               "trajectory": _trajectory(out, f"traj_{integ}_{len(params)}", rises),
               "t_settle_1e-09": 19.6 if rises else 9.0}
        cases.append((f"observers:artifact:{integ}:{params}", [row]))
    return cases


PATH_RATES = {"jump": (2.0, 3.0, 4.0, 5.0), "nojump": (1.0, 1.5, 2.0, 2.5)}
"""Stored V(t) paths: member i of a design decays as V_i(0)·exp(−rate_i t)."""


def _paths(out, name: str) -> None:
    t = np.linspace(0.0, 5.0, 51)
    rows = [pd.DataFrame({"design": d, "member": i, "t": t, "V": (i + 1) * 0.1 * np.exp(-k * t)})
            for d, rates in PATH_RATES.items() for i, k in enumerate(rates)]
    pd.concat(rows).to_parquet(out / name)


def _checks_row() -> tuple[str, list[dict]]:
    return ("checks:dm", [{"kind": "checks", "scenario": "double_mass", "name": "double_mass",
                           "check": "lyapunov_decrease", "equation": "(17)", "check_status": "PASS",
                           "margin": 0.0, "tolerance": 1e-9, "status": "ok", "reason": "",
                           "witness": f"steps=12; max_{artifacts.GAP_KEY}/V={GAP:g}; max_impulse_slack/V=1e-7; "
                                      "slack_order_impulse_slack=nan; min_open_gap=inf",
                           "evidence": "bounded", "verdict": "holds up to an O(h) slack"}])


def _cases(out) -> list[tuple[str, list[dict]]]:
    rng = np.random.default_rng(22)
    ens = []
    for label, integ in ENSEMBLES:
        ens.append((f"ensemble:{label}:{integ}", _member_rows(label, integ, rng)))
    for label, scenario in SCENARIO_ENSEMBLES:
        ens.append((f"ensemble:{label}", _member_rows(label, "time-stepping", rng, scenario)))
    _paths(out, "paths_dm.parquet")
    for row in ens[0][1]:
        row["paths"] = "paths_dm.parquet"
    return _synthetic_rows() + ens + _artifact_rows(out) + [_checks_row()]


# The page is built with its figures rendered in place (workers=1): the default pool of forked
# renderers costs ≈ 1.5 s CPU a page more and gains no wall time on a test worker that shares two
# cores with another; the pool's path is the smoke page's (tests/reports/test_build.py, built by
# the command line with the default workers) and gives the same PNG bytes
# (tests/reports/test_figure_rendering.py).
@pytest.fixture(scope="module")
def ensemble_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("ens")
    path = _rows_file(out / "quicklike.cases", _cases(out))
    start, cpu = time.perf_counter(), time.process_time()
    index = build_report([path], out / "report", workers=1)
    build_s = time.perf_counter() - start
    print(f"\npage build (measured, reported; not asserted): {build_s:.1f} s wall, "
          f"{time.process_time() - cpu:.1f} s CPU")
    return index, _parse(index), load_rows([path]), build_s


def test_k_metric_claims_are_below_with_their_ci_and_a_link_to_existing_evidence(ensemble_report):
    """The first screen's section comes before the header table and contents; the settling and
    K-metric claims are in their own section below: at most 8, each with a 95 % CI and an
    evidence link whose id exists on the page."""
    index, page, _, _ = ensemble_report
    html = index.read_text(encoding="utf-8")
    first = html.index('<section id="claims"')
    assert first < html.index('class="header-table"') and first < html.index("<nav>")
    first = html.index(f'<section id="{k_metric_claims.ID}"')
    assert first > html.index('class="header-table"')          # below the first screen
    items = page.sections[k_metric_claims.ID].items
    assert 3 <= len(items) <= claims.MAX_CLAIMS
    assert all("95 % CI" in i for i in items), items
    block = html[first:html.index("</section>", first)]
    anchors = re.findall(r'<a href="#([^"]+)">evidence</a>', block)
    assert len(anchors) == len(items)
    for a in set(anchors):
        assert f'id="{a}"' in html, a


def test_speed_claim_is_the_paired_median_with_its_bootstrap_ci(ensemble_report):
    """The speed claim's number is t_nojump / t_jump (median over the members, recomputed here
    from the rows), inside its CI."""
    _, page, rows, _ = ensemble_report
    m = rows[(rows["kind"] == "ensemble") & (rows["label"] == "double_mass")
             & (rows["integrator"] == "time-stepping")]
    tj = m[m["design"] == "jump"].sort_values("member")["t_settle_1e-06"].to_numpy()
    tn = m[m["design"] == "nojump"].sort_values("member")["t_settle_1e-06"].to_numpy()
    speed = 1 / np.median(tj / tn)
    assert speed == pytest.approx(SPEEDUP, rel=0.05)
    item = next(i for i in page.sections[k_metric_claims.ID].items if "sooner" in i and "double_mass" in i)
    nums = [float(x) for x in re.findall(r"(\d+\.\d+)×", item)]
    assert nums and nums[0] == pytest.approx(speed, rel=2e-3)
    lo, hi = (float(x) for x in re.search(r"CI (\d+\.?\d*)–(\d+\.?\d*)", item).groups())
    assert lo <= nums[0] <= hi


def test_claims_touching_a_rising_k_metric_design_say_why_and_link_the_remedy(ensemble_report):
    """jump (K metric) rises in a third of the time-stepped members, never event-driven: every
    claim naming it on a time-stepped ensemble carries the cause (master penetration,
    ½‖g_m⁻‖²) and the event-driven share; a claim on an event-driven ensemble does not."""
    index, page, _, _ = ensemble_report
    items = [i for i in page.sections[k_metric_claims.ID].items if "jump (K metric)" in i]
    stepped = [i for i in items if "time-stepping" in i]
    assert stepped and len(stepped) < len(items)
    for i in stepped:
        assert "master penetrates" in i and "½‖g_m⁻‖²_{L_I⁻¹}" in i
        assert "up to 33 % of the time-stepped members" in i
        assert "projected master: 0 %, largest 0·V; event-driven: 0 %, largest 0·V" in i
        assert "largest one-step rise 7000·V" in i
    for i in set(items) - set(stepped):
        assert "master penetrates" not in i
    assert 'href="#discrete-artifacts">cause and remedy' in index.read_text(encoding="utf-8")


def test_key_numbers_are_at_most_eight_and_all_lines_are_kept_collapsed(ensemble_report):
    index, page, _, _ = ensemble_report
    shown, every = page.sections["key-numbers"].items, page.sections["all-key-numbers"].items
    assert 1 <= len(shown) <= MAX_ITEMS < len(every)
    assert set(shown) <= set(every)
    html = index.read_text(encoding="utf-8")
    sec = html[html.index('<section id="all-key-numbers">'):]
    assert sec.index("<details>") < sec.index("<li>")
    assert html.index('id="all-key-numbers"') > html.index('id="scenarios"')   # below the figures


def test_headlines_take_each_sections_first_line_then_round_robin():
    groups = [("a", ["a1", "a2", "a3"]), ("b", []), ("c", ["c1"]), ("d", ["d1", "d2"])]
    assert headlines(groups, 4) == ["a1", "c1", "d1", "a2"]
    assert headlines(groups, 10) == ["a1", "c1", "d1", "a2", "d2", "a3"]


def test_settling_matrix_is_recomputed_and_written_beside_the_page(ensemble_report):
    """The CSV beside the page holds, per (scenario, integrator, design), the median and the
    10/90 % quantiles of the settling times (inf kept) and the never-settling share."""
    index, page, rows, _ = ensemble_report
    csv = pd.read_csv(index.parent / "settling_matrix.csv")
    m = rows[rows["kind"] == "ensemble"]
    assert len(csv) == m.groupby(["label", "integrator", "design"]).ngroups == 3 * (len(ENSEMBLES) + len(SCENARIO_ENSEMBLES))
    for _, r in csv.iterrows():
        t = m[(m["label"] == r["label"]) & (m["integrator"] == r["integrator"])
              & (m["design"] == r["design"])]["t_settle_1e-06"].to_numpy()
        assert r["median"] == pytest.approx(np.sort(t)[(len(t) - 1) // 2], rel=1e-12)
        assert r["q10"] == pytest.approx(np.sort(t)[math.ceil(BAND_Q[0] * len(t)) - 1], rel=1e-12)
        assert r["never"] == 0.0
    html = index.read_text(encoding="utf-8")
    for name in ("settling_matrix.csv", "paired_settling.csv", "rise_distribution.csv"):
        assert f'<a href="{name}">' in html and (index.parent / name).exists()
    assert page.table("ensemble", "Proof-check matrix").rows
    assert any(img["alt"].startswith("settling matrix")
               for img in re.findall(r'<img [^>]*alt="([^"]+)"', html) for img in [{"alt": img}])


def test_settling_matrix_counts_members_that_never_settle():
    rows = pd.DataFrame([{"kind": "ensemble", "scenario": "s", "design": "d", "member": i,
                          "t_settle_1e-06": math.inf if i < 3 else float(i)} for i in range(10)])
    mat = settling_matrix(member_rows(rows))
    assert mat["never"].iloc[0] == pytest.approx(0.3) and mat["q90"].iloc[0] == math.inf
    assert mat["median"].iloc[0] == 7.0 and mat["q10"].iloc[0] == 3.0     # sorted 3..9, ∞, ∞, ∞


def test_paired_csv_is_the_analysis_of_the_member_rows(ensemble_report):
    index, _, rows, _ = ensemble_report
    members = member_rows(rows)
    csv = pd.read_csv(index.parent / "paired_settling.csv")
    ref = paired_settling(members, (("nojump", "jump"), ("jump", "jump_mass")),
                          rng=np.random.default_rng(1), n_resamples=200)
    merged = csv.merge(ref, on=["label", "integrator", "baseline", "candidate", "rho"])
    assert len(merged) == len(ref) == 2 * (len(ENSEMBLES) + len(SCENARIO_ENSEMBLES)) * len(RHO_COLS)
    assert np.allclose(merged["ratio_median_x"], merged["ratio_median_y"], rtol=1e-12)
    rises = pd.read_csv(index.parent / "rise_distribution.csv")
    assert rises["frac_rising"].tolist() == pytest.approx(rise_distribution(members)["frac_rising"].tolist())


def test_discrete_artifact_shows_the_remedy_side_by_side(ensemble_report):
    """The artifact section: V jumps up under time-stepping (×7000 in one recorded sample), not
    with a projected master nor event-driven; the proof checks' penetration term is quoted."""
    index, page, _, _ = ensemble_report
    sec = page.sections["discrete-artifacts"]
    table = sec.tables[0]
    assert [c.split(":")[0] for c in table.columns[2:]] == list(artifacts.VARIANTS)
    row = table.dicts()[0]
    ts, proj, ev = (row[c] for c in table.columns[2:])
    jumps, factor = 10, 7000.0 * np.exp(-3.0 * 0.02)         # t = 1..10 s; V decays one sample
    assert ts.startswith(f"5.00e−9 · {jumps} (×{factor:.0f})")
    assert proj.startswith("1.00e−24 · 0 (×0.942)") and ev.startswith("1.00e−24 · 0 (×0.942)")
    assert "19.6 s" in ts and "9 s" in proj
    text = sec.text()
    assert "master-penetration term at up to 3.20e−5·V" in text and "master penetrates" in text
    html = index.read_text(encoding="utf-8")
    assert 'alt="dm20: V of jump (K metric): V under time-stepping' in html


def test_ensemble_artifact_table_puts_the_master_variants_side_by_side(ensemble_report):
    """double_mass: time-stepped, projected master and event-driven ensembles in one row per
    design with jumps; the rising shares are those of the member rows."""
    _, page, rows, _ = ensemble_report
    table = page.table("discrete-artifacts", "Ensembles: rises of V").dicts()
    row = next(r for r in table if (r["scenario"], r["design"]) == ("double_mass", "jump (K metric)"))
    ts, proj, ev = (row[f"{v}: members rising · largest rise · median settling"] for v in artifacts.VARIANTS)
    m = rows[(rows["kind"] == "ensemble") & (rows["label"] == "double_mass") & (rows["design"] == "jump")
             & (rows["integrator"] == "time-stepping")]
    share = (m["max_rise_rel"] > 1e-10).mean()
    assert ts.startswith(f"{100 * share:.0f} % · 7000·V") and proj.startswith("0 % · 0·V")
    assert ev.startswith("0 % · 0·V")
    pc = next(r for r in table if (r["scenario"], r["design"]) == ("persistent contact", "jump (K metric)"))
    assert pc[f"{artifacts.VARIANTS[1]}: members rising · largest rise · median settling"] == "n/a (not run)"


def test_ensemble_band_is_the_quantiles_of_the_stored_paths(ensemble_report):
    """The scenario with stored paths gets its V(t) band figure; path_band's median and 10–90 %
    at a time are those of V_i(t)/V_i(0) = exp(−rate_i t) over the members."""
    index, page, _, _ = ensemble_report
    html = index.read_text(encoding="utf-8")
    assert 'id="ens-double-mass"' in html
    assert 'alt="double_mass · time-stepping: ensemble band of V"' in html
    assert 'id="ens-persistent-contact"' not in html            # no paths stored there
    paths = pd.read_parquet(index.parent.parent / "paths_dm.parquet")
    band = path_band(paths)
    for design, rates in PATH_RATES.items():
        at = band[(band["design"] == design) & np.isclose(band["t"], 2.0)].iloc[0]
        rel = np.exp(-np.array(rates) * 2.0)
        assert at["median"] == pytest.approx(np.median(rel), rel=1e-12)
        assert (at["q10"], at["q90"]) == pytest.approx(tuple(np.quantile(rel, BAND_Q)), rel=1e-12)


def test_artifact_rises_count_jumps_up():
    assert artifacts.rises(np.array([1.0, 0.5, 4.0, 3.0, 30.0])) == (2, 10.0)
    assert artifacts.rises(np.array([1.0, 0.9, 0.8]))[0] == 0


def test_no_ensemble_rows_says_so(tmp_path):
    path = _rows_file(tmp_path / "plain.cases", _synthetic_rows()[:3])
    page = _parse(_section_page([path], tmp_path / "r", "claims"))
    assert page.sections["claims"].paragraphs[0].startswith("No claims: no ensemble results")
    assert page.sections["claims"].items == []


def _claim(page, key: str) -> str:
    titles = {c.key: c.title for c in forest.SCENARIOS}
    found = [i for i in page.sections["claims"].items if i.startswith(titles[key])]
    assert len(found) == 1, (key, page.sections["claims"].items)
    return found[0]


def _numbers(item: str) -> tuple[float, float, float]:
    m = re.search(r"(\d+\.?\d*) \(95 % CI (\d+\.?\d*)–(\d+\.?\d*)\)", item)
    assert m, item
    return tuple(float(x) for x in m.groups())


def _rate_ratio(rows, label: str, integrator: str) -> float:
    m = rows[(rows["kind"] == "ensemble") & (rows["label"] == label) & (rows["integrator"] == integrator)]
    rj = m[m["design"] == "jump"].sort_values("member")["rate"].to_numpy(float)
    rn = m[m["design"] == "nojump"].sort_values("member")["rate"].to_numpy(float)
    return rj.mean() / rn.mean()


def test_first_screen_claims_one_per_scenario_with_estimand_interval_and_evidence(ensemble_report):
    """The lead section holds one figure and at most 8 claims, one per scenario the paper names
    that the results hold; each states its interval and its evidence (members × masters)."""
    _, page, _, _ = ensemble_report
    items = page.sections["claims"].items
    assert 0 < len(items) <= claims.MAX_CLAIMS
    heads = [next(c.key for c in forest.SCENARIOS if i.startswith(c.title)) for i in items]
    assert heads == ["double_mass", "grazing", "chain", "random"]          # the synthetic rows' scenarios
    for i in items:
        assert "95 % CI" in i and re.search(r"\d+ members × \d+ (master|systems)", i), i
    html = ensemble_report[0].read_text(encoding="utf-8")
    start = html.index('<section id="claims"')
    lead = html[start:html.index("</section>", start)]
    assert lead.count("<img ") == 1 and "forest plot" in lead
    assert html.index('<section id="claims"') < html.index('class="header-table"')


def test_double_mass_claim_is_the_exact_masters_paired_rate_ratio(ensemble_report):
    """The double-mass claim uses the exact (event-driven) master where present; its number is
    mean rate of jump / mean rate of nojump over the same members, recomputed from the rows,
    inside its interval."""
    _, page, rows, _ = ensemble_report
    item = _claim(page, "double_mass")
    est, lo, hi = _numbers(item)
    ratio = _rate_ratio(rows, "double_mass", "event")
    assert est == pytest.approx(ratio, rel=5e-3) and lo <= ratio <= hi
    assert ratio == pytest.approx(SPEEDUP, rel=0.05)
    assert "exact event-driven master" in item and f"{N} members × 1 master" in item


def test_chain_claim_is_at_n_10_where_the_designs_differ(ensemble_report):
    """The chain claim speaks of N = 10 (the largest N), not N = 4 where both designs' V are
    identical (no closing in the window)."""
    _, page, rows, _ = ensemble_report
    item = _claim(page, "chain")
    assert "N = 10" in item and "N = 4" not in item and "identical" not in item
    assert _numbers(item)[0] == pytest.approx(_rate_ratio(rows, "rocking_chain (N = 10)", "time-stepping"),
                                              rel=5e-3)
    assert _rate_ratio(rows, "rocking_chain (N = 4)", "time-stepping") == 1.0
    per = N // MASTERS
    assert f"{per} members × {MASTERS} masters, masters resampled" in item
    assert f"rates fitted over a median {CHAIN_FIT:g} s after t_on" in item
    assert f"stopped by a discretisation floor in {N // 2} of {N} members" in item


def test_an_ensemble_on_several_masters_resamples_masters():
    """The forest row of an ensemble with a ``master`` column is observer.stats.rate_ratio with
    the masters as clusters (k of m masters); without it, one master (members resampled)."""
    from observer import stats

    rng = np.random.default_rng(3)
    rows = pd.DataFrame(_member_rows("random_system (seed 0, 2 DOF, 1 contact)", "time-stepping", rng,
                                     "random_system"))
    r = forest.forest_rows(rows).iloc[0]
    long = rows[rows["design"].isin(["jump", "nojump"])].rename(columns={"master": "cluster"})
    ref = stats.rate_ratio(long, "jump", "nojump", n_resamples=forest.RESAMPLES, seed=forest.SEED).iloc[0]
    assert (r["masters"], r["clusters"], r["unit"]) == (MASTERS, MASTERS, "clusters")
    assert (r["low"], r["high"]) == (ref["low"], ref["high"])
    one = forest.forest_rows(rows.drop(columns="master")).iloc[0]
    assert (one["masters"], one["unit"]) == (1, "members") and (one["low"], one["high"]) != (r["low"], r["high"])


def test_random_claim_pools_systems_and_names_where_jump_is_not_faster(ensemble_report):
    """The random-systems claim resamples systems (3 clusters), says in how many jump's rate is
    larger, and names the system where jump is slower (rate ratio 0.9, CI below 1)."""
    _, page, rows, _ = ensemble_report
    item = _claim(page, "random")
    assert f"{N // MASTERS} members × {MASTERS} masters × 3 systems, systems resampled" in item
    assert "'s rate larger in 2 of 3 systems" in item
    assert "slower (CI below 1) in 1 of 3" in item and "is NOT faster on (seed 1, 3 DOF, 2 contacts)" in item


def test_grazing_claim_shows_the_grid_sensitivity(ensemble_report):
    _, page, rows, _ = ensemble_report
    item = _claim(page, "grazing")
    assert item.startswith("Grazing — grazing:") and "grid sensitivity: h = 0.0005 →" in item


FORBIDDEN = re.compile(r"(?<![\w.])((?i:nan|inf)|None)(?![\w.])|0 \[0, 0\]")
"""What no table cell may read (the Python spelling None; "none", a perturbation kind, is a word)."""


def test_no_table_cell_prints_nan_inf_none_or_zero_intervals(ensemble_report):
    """No cell of any table of the page reads "nan", "inf", "None" or "0 [0, 0]"."""
    _, page, _, _ = ensemble_report
    cells = [c for sec in page.sections.values() for t in sec.tables for row in t.rows for c in row]
    assert cells
    bad = [c for c in cells if FORBIDDEN.search(str(c))]
    assert not bad, bad[:10]
    assert FORBIDDEN.search("0 [0, 0]") and FORBIDDEN.search("median nan") and not FORBIDDEN.search("infinite")
    assert FORBIDDEN.search("Inf") and FORBIDDEN.search("None") and not FORBIDDEN.search("none (exact χ)")
    assert FORBIDDEN.search("slack_order=nan")                     # the synthetic witness's, before it is shown


def test_a_witness_value_that_is_no_number_reads_like_a_table_cell():
    from reports.tables import witness_text

    assert witness_text("a=nan; b=1e-3; c=inf; d=-inf; e=None; nanny=2; f=nan2") == \
        "a=n/a; b=1e-3; c=∞; d=−∞; e=n/a; nanny=2; f=nan2"


@pytest.mark.skipif(find_chromium() is None, reason="chromium is not installed (apt-get install chromium)")
def test_first_screen_in_headless_chromium_holds_the_forest_plot_and_the_claims(ensemble_report, tmp_path):
    """At 1400×1000 the screenshot's first screen shows the forest plot and the per-scenario
    claims: the browser reports the bottom of both above 1000 px (the image decoded), and the
    screenshot is not blank there."""
    from PIL import Image

    index, page, _, _ = ensemble_report
    probe = index.read_text(encoding="utf-8").replace(
        "</body>", "<script>window.addEventListener('load', function () {"
        "var s = document.querySelector('section#claims');"
        "var r = s.querySelector('ol.claims').getBoundingClientRect();"
        "var f = s.querySelector('figure img');"
        "document.body.setAttribute('data-claims-bottom', String(r.bottom));"
        "document.body.setAttribute('data-figure-bottom', String(f.getBoundingClientRect().bottom));"
        "document.body.setAttribute('data-figure-width', String(f.naturalWidth));"
        "document.body.setAttribute('data-claims-items', String("
        "s.querySelectorAll('ol.claims li').length));});</script></body>")
    probe_path = index.parent / "probe.html"
    probe_path.write_text(probe, encoding="utf-8")
    res = check_page(probe_path, tmp_path / "first.png", width=1400, height=1000)
    assert res.script_ran and not res.page_errors, res.text()
    assert res.screenshot is not None
    img = np.asarray(Image.open(res.screenshot).convert("L"), dtype=float)
    assert img.shape == (1000, 1400)
    bottom = float(res.attrs["data-claims-bottom"])
    assert int(res.attrs["data-claims-items"]) == len(page.sections["claims"].items) >= 4
    assert 0 < bottom < 1000
    assert 0 < float(res.attrs["data-figure-bottom"]) < bottom and int(res.attrs["data-figure-width"]) > 300
    assert (img[:int(bottom)] < 128).mean() > 0.01      # text drawn where the claims are


def test_where_jump_is_faster_counts_faster_not_different_and_slower_ensembles():
    """Hand-made forest rows: the exact master's row replaces the time-stepped one of the same
    ensemble; projected-master and pooled rows are left out; the interval's position decides."""
    from reports.tables import fmt

    rows = [("double_mass", "event", 2.0, 1.8, 2.2), ("double_mass", "time-stepping", 2.5, 2.3, 2.7),
            ("grazing", "time-stepping", 3.0, 2.9, 3.1), ("rocking_chain (N = 4)", "time-stepping", 1.0, 1.0, 1.0),
            ("random_system (seed 1)", "time-stepping", 0.9, 0.85, 0.95),
            ("double_mass (projected master)", "time-stepping", 9.0, 8.0, 10.0),
            ("random_system (all 2 systems)", "time-stepping", 0.95, 0.5, 1.5)]
    f = pd.DataFrame(rows, columns=["label", "integrator", "estimate", "low", "high"])
    text = forest.where_faster(f)
    assert "over these 4 ensembles: faster (95 % CI above 1) in 2" in text
    assert f"decaying {fmt(2.0)}–{fmt(3.0)}× as fast (lowest CI end {fmt(1.8)})" in text
    assert "not different (CI contains 1) in 1 (rocking_chain (N = 4))" in text
    assert f"slower (CI below 1) in 1 (random_system (seed 1): {fmt(0.9)})" in text
    assert forest.where_faster(f[f["label"] == "grazing"]).count("in 0") == 2     # near miss: no slower row
