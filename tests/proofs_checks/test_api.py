"""proofs_checks' API around the checks: the registry runner (``run_checks``, ``select``,
``results_frame``), the assertion helpers, the command line and the check context
(settings, seeded generators, the observers' initial states), on the algebraic checks only
(no simulation, except one 40-step replay). Written against the mutation runs of
``__init__.py``, ``asserts.py``, ``cli.py`` and ``context.py``
(``tests/mutants/proofs_checks_small.md``).
"""

from __future__ import annotations

import json
import zlib

import numpy as np
import pytest
import scipy.linalg as sla

import proofs_checks as pc
from observer.errors import InputError
from proofs_checks import asserts, cli
from proofs_checks.context import CheckContext, CheckSettings
from proofs_checks.result import CheckResult


# the replays are deliberately coarse (a few hundred steps): the run-health note about the
# penetration at this h is expected, and not what these tests are about
pytestmark = pytest.mark.filterwarnings("ignore:penetration .* reduce h")


# ----------------------------------------------------------------------------- select / run_checks
def test_select_parses_and_validates():
    assert pc.select(None) == list(pc.CHECKS)
    assert pc.select(" mass_spd , ,stiffness_spd") == ["mass_spd", "stiffness_spd"]
    assert pc.select(["damping_pd,mass_spd", "convergence"]) == ["damping_pd", "mass_spd", "convergence"]
    with pytest.raises(InputError) as info:
        pc.select("mass_spd,bogus")
    assert info.value.field == "--only"
    assert info.value.problem == f"unknown check 'bogus'; choose from {', '.join(pc.CHECKS)}"


def test_run_checks_order_settings_progress_and_timing():
    seen = []
    res = pc.run_checks("bouncing_ball", "stiffness_spd,mass_spd", progress=seen.append)
    assert [r.name for r in res] == ["stiffness_spd", "mass_spd"] and seen == res
    assert all(r.scenario == "bouncing_ball" and 0 < r.elapsed < 5 for r in res)
    # options reach the check; overrides reach the scenario
    res = pc.run_checks("double_mass", "mass_spd", options={"mass_spd": {"rcond_min": 1.5}})
    assert res[0].witness["required"] == 1.5 and res[0].passed is False
    res = pc.run_checks("double_mass", "mass_spd", overrides={"param.m1": 4.0})
    assert res[0].witness["lambda_max"] == pytest.approx(4.0)
    # explicit settings win over seed/h/t_end/options
    res = pc.run_checks("double_mass", "mass_spd", options={"mass_spd": {"rcond_min": 1.5}},
                        settings=CheckSettings())
    assert res[0].passed is True
    with pytest.raises(InputError) as info:
        pc.run_checks("double_mass", "mass_spd", options={"nope": {}, "mass_spd": {}})
    assert info.value.field == "options" and info.value.problem.startswith("unknown check(s) ['nope']; choose from ")


def test_a_crashing_check_is_a_failed_result_but_input_errors_propagate(monkeypatch):
    res = pc.run_checks("double_mass", "mass_spd", options={"mass_spd": {"bogus": 1}})
    r = res[0]
    assert r.passed is False and np.isnan(r.margin) and np.isnan(r.tolerance)
    assert r.witness == {"exception": "TypeError"} and r.reason.startswith("raised TypeError: ")
    assert "bogus" in r.reason and r.scenario == "double_mass" and r.name == "mass_spd"

    def bad(ctx):
        raise InputError("system.K", "broken")
    monkeypatch.setitem(pc.CHECKS, "mass_spd", bad)
    with pytest.raises(InputError, match="system.K: broken"):
        pc.run_checks("double_mass", "mass_spd")


def test_registry_passes_each_checks_ingredients(monkeypatch):
    """Each lambda of the registry hands its check the right ingredient and options."""
    sc = pc.load("double_mass")
    res = {r.name: r for r in pc.run_checks(sc, ["mass_spd", "stiffness_spd", "damping_pd",
                                                 "constraints_independent", "forcing_bounded"],
                                            options={"stiffness_spd": {"rcond_min": 0.5},
                                                     "damping_pd": {"rcond_min": 0.5},
                                                     "constraints_independent": {"cond_max": 0.5},
                                                     "forcing_bounded": {"f_max": 1.0}})}
    s = sc.system
    assert res["mass_spd"].witness["lambda_max"] == pytest.approx(np.linalg.eigvalsh(s.M)[-1])
    assert res["stiffness_spd"].witness["lambda_max"] == pytest.approx(np.linalg.eigvalsh(s.K)[-1])
    assert res["stiffness_spd"].witness["required"] == 0.5
    assert res["damping_pd"].witness["lambda_max"] == pytest.approx(np.linalg.eigvalsh(s.C)[-1])
    assert res["damping_pd"].witness["required"] == 0.5
    assert res["constraints_independent"].witness["cond_max"] == 0.5
    assert res["forcing_bounded"].witness["f_max"] == 1.0


def test_results_frame_columns_and_rows():
    res = pc.run_checks("bouncing_ball", "mass_spd,stiffness_spd")
    df = pc.results_frame(res)
    assert list(df.columns) == ["scenario", "check", "equation", "status", "evidence", "passed", "margin",
                                "tolerance", "verdict", "witness", "reason", "elapsed"]
    assert df.check.tolist() == ["mass_spd", "stiffness_spd"] and df.status.tolist() == ["PASS", "n/a"]
    assert df.evidence.tolist() == ["proved", "n/a"]
    assert pc.results_frame([]).shape == (0, 12)


# ----------------------------------------------------------------------------- assertion helpers
def test_assert_result_messages():
    bad = CheckResult.from_margin("chk", -0.5, 0.125, {"a": 1.0}, "eq", ("a",), "why")
    bad.scenario = "sc"
    with pytest.raises(AssertionError) as info:
        pc.assert_result(bad)
    assert str(info.value) == ("proof check chk failed on sc: margin -0.5 (tolerance 0.125); why | a=1\n"
                               + bad.message())
    bad.scenario = ""
    with pytest.raises(AssertionError, match=r"^proof check chk failed: margin"):
        pc.assert_result(bad)
    na = CheckResult.not_applicable("chk", "no K")
    assert pc.assert_result(na) is na
    with pytest.raises(AssertionError) as info:
        pc.assert_result(na, allow_not_applicable=False)
    assert str(info.value) == "proof check chk is not applicable: no K\n" + na.message()
    ok = CheckResult.from_margin("chk", 1.0, 0.0, {}, "eq")
    assert pc.assert_result(ok, allow_not_applicable=False) is ok


def test_helpers_names_docs_and_scenario_mode():
    h = pc.assert_mass_spd
    assert h.__name__ == h.__qualname__ == "assert_mass_spd"
    assert h.__doc__.startswith("Assert that :func:`proofs_checks.assumptions.check_mass_spd` passes.\n\n")
    assert h.__doc__.endswith("Checked: M = Mᵀ ≻ 0 (section 2, after eq. (1)).")
    assert "See :mod:`proofs_checks.asserts`." in h.__doc__
    r = pc.assert_mass_spd(np.eye(2))                                  # direct mode
    assert r.passed is True and r.scenario == ""
    with pytest.raises(AssertionError):
        pc.assert_mass_spd(np.eye(2), rcond_min=2.0)
    # scenario mode: run_checks keywords are taken out, the rest are the check's options
    r = pc.assert_mass_spd("double_mass", seed=3, h=1e-3, t_end=1.0, overrides={"param.m1": 4.0}, rcond_min=0.2)
    assert r.scenario == "double_mass" and r.witness["required"] == 0.2
    assert r.witness["lambda_max"] == pytest.approx(4.0)
    with pytest.raises(AssertionError, match="mass_spd failed on double_mass"):
        pc.assert_mass_spd(pc.load("double_mass"), rcond_min=2.0)
    from pathlib import Path
    with pytest.raises(InputError):
        pc.assert_mass_spd(Path("no_such_file.toml"))
    r = pc.assert_stiffness_spd("bouncing_ball")
    assert r.passed is None
    assert sorted(n for n in dir(pc) if n.startswith("assert_") and n not in ("assert_checks", "assert_result")) \
        == sorted(f"assert_{n}" for n in pc.CHECKS if hasattr(pc, f"assert_{n}"))


def test_assert_checks_message(monkeypatch):
    with pytest.raises(AssertionError) as info:
        pc.assert_checks("bouncing_ball", "mass_spd,stiffness_spd", allow_not_applicable=False)
    text = str(info.value)
    assert text.startswith("1 of 2 proof checks failed on bouncing_ball: stiffness_spd\n")
    assert "check" in text.splitlines()[1] and "status" in text.splitlines()[1]
    assert text.count("NOT APPLICABLE") == 1 and "\n\nstiffness_spd [" in text
    assert len(pc.assert_checks("bouncing_ball", "mass_spd,stiffness_spd")) == 2


# ----------------------------------------------------------------------------- command line
def test_format_table_exact():
    a = CheckResult.from_margin("mass_spd", 0.25, 0.0, {"x": 1.0}, "eq", ("x",))
    a.elapsed = 0.04
    b = CheckResult.not_applicable("k", "why")
    b.elapsed = 12.0
    c = CheckResult.from_margin("c", -1.0, 0.0, {"y": 2.0}, "eq", ("y",), evidence="sampled", verdict="v")
    lines = cli.format_table([a, b, c]).splitlines()
    assert lines == [
        "  check     status  evidence      margin       tol    time  verdict | witness",
        "  mass_spd  PASS    sampled         0.25         0    0.0s  x=1",
        "  k         n/a     n/a                -         -   12.0s  not applicable: why",
        "  c         FAIL    sampled           -1         0    0.0s  v | y=2",
    ]
    assert cli._fmt(float("nan")) == "-" and cli._fmt(1234.5) == "1.23e+03"
    assert cli.STATUS_WIDTH == 6 and cli.EVIDENCE_WIDTH == len("violated")


def test_cli_options_parsing():
    assert cli._options(None) == {}
    assert cli._options(["mass_spd.rcond_min=0.5", "mass_spd.x=[1, 2]", "damping_pd.rcond_min=1e-3"]) == {
        "mass_spd": {"rcond_min": 0.5, "x": [1, 2]}, "damping_pd": {"rcond_min": 1e-3}}
    for bad in ("nope.x=1", "mass_spd=1", "mass_spd.=1"):
        with pytest.raises(InputError) as info:
            cli._options([bad])
        assert info.value.field == "--option"
        assert info.value.problem.startswith("expected CHECK.KEYWORD=VALUE with CHECK one of mass_spd, ")
        assert info.value.problem.endswith(f", got {bad.split('=')[0]!r}")


def test_cli_run_output_json_and_codes(tmp_path, capsys):
    out = tmp_path / "a" / "b.json"
    code = cli.main(["double_mass", "--only", "mass_spd", "--only", "stiffness_spd", "--seed", "4",
                     "--h", "0.002", "--t-end", "1.5", "--set", "param.m1=2", "--option",
                     "mass_spd.rcond_min=0.25", "--json", str(out)])
    text = capsys.readouterr()
    assert code == 0 and text.err == ""
    lines = text.out.splitlines()
    assert lines[0] == ("double_mass (double_mass): n = 2, m = 1, poisson law, restitution 0.8 (global); "
                        "seed 4, run h = 0.002")
    assert lines[1].startswith("  check ") and lines[2].startswith("  mass_spd ")
    assert lines[4].startswith("  -> 2 passed, 0 failed, 0 not applicable in ")
    assert lines[-1] == f"wrote {out}"
    doc = json.loads(out.read_text())
    assert doc["settings"] == {"seed": 4, "h": 0.002, "t_end": 1.5, "engine": None,
                               "options": {"mass_spd": {"rcond_min": 0.25}},
                               "overrides": {"param.m1": "2"}, "scenarios": ["double_mass"]}
    assert set(doc) == {"settings", "platform", "python", "wall_time_s", "results"}
    assert doc["wall_time_s"] > 0 and [r["name"] for r in doc["results"]] == ["mass_spd", "stiffness_spd"]
    assert doc["results"][0]["witness"]["required"] == 0.25
    # failure: exit 1 and the count on stderr
    code = cli.main(["double_mass", "bouncing_ball", "--only", "mass_spd,stiffness_spd",
                     "--option", "mass_spd.rcond_min=2"])
    text = capsys.readouterr()
    assert code == 1 and text.err == "2 check(s) FAILED\n"
    assert "  -> 0 passed, 1 failed, 1 not applicable in " in text.out
    assert "bouncing_ball (bouncing_ball): n = 1, m = 1" in text.out
    # per-contact restitution
    cli.main(["rocking_chain", "--set", "param.N=1", "--set", "impact.restitution=[0.5, 0.25]",
              "--only", "mass_spd"])
    assert "restitution [0.5, 0.25]; seed 0, run h = " in capsys.readouterr().out


def test_cli_all_list_and_bad_steps(capsys, monkeypatch):
    from observer.scenarios import SCENARIOS
    assert cli.main(["--list"]) == 0
    assert capsys.readouterr().out.splitlines() == list(pc.CHECKS)
    assert cli.main(["all", "--only", "mass_spd"]) == 0
    out = capsys.readouterr().out
    assert out.count("  -> 1 passed") == len(SCENARIOS)
    for args, text in ((["--h", "0"], "error: --h: must be > 0, got 0.0"),
                       (["--t-end", "-1"], "error: --t-end: must be > 0, got -1.0"),
                       (["--h", "nan"], "error: --h: must be > 0, got nan")):
        assert cli.main(["double_mass", *args]) == 2
        assert capsys.readouterr().err.strip() == text
    assert cli.main([]) == 2
    assert capsys.readouterr().err.strip() == ("error: SCENARIO: give at least one scenario (a built-in name, "
                                               "a .toml file, or 'all')")
    # every scenario is validated before any check runs
    assert cli.main(["double_mass", "no_such_scenario"]) == 2
    assert capsys.readouterr().out == ""
    p = cli.build_parser()
    assert p.prog == "python -m proofs_checks" and ", ".join(pc.CHECKS) in p.description
    assert p.parse_args(["x"]).seed == 0


# ----------------------------------------------------------------------------- context
def test_context_defaults_and_rng_streams():
    sc = pc.load("double_mass")
    ctx = CheckContext(sc)
    assert ctx.settings == CheckSettings() and ctx.h == sc.h
    assert ctx.t_end == min(sc.t_end, 40_000 * sc.h)
    assert ctx.short_t_end == min(sc.t_end, 20_000 * sc.h)
    assert ctx.system is sc.system and ctx.law is sc.law
    ctx = CheckContext(sc, CheckSettings(seed=7, h=1e-3, max_steps=100, short_steps=50,
                                         options={"mass_spd": {"rcond_min": 0.1}}))
    assert ctx.h == 1e-3 and ctx.t_end == pytest.approx(0.1) and ctx.short_t_end == pytest.approx(0.05)
    assert CheckContext(sc, CheckSettings(t_end=0.3)).short_t_end == 0.3
    assert CheckContext(sc, CheckSettings(t_end=0.3)).t_end == 0.3
    opts = ctx.options("mass_spd")
    opts["x"] = 1
    assert ctx.options("mass_spd") == {"rcond_min": 0.1} and ctx.options("other") == {}
    ref = np.random.default_rng([7, zlib.crc32(b"abc")]).random(3)
    assert np.array_equal(ctx.rng("abc").random(3), ref)
    assert not np.array_equal(ctx.rng("abd").random(3), ref)


def _specs_by_hand(sc, seed=0):
    s = sc.system
    n = s.n
    g = np.random.default_rng([seed, zlib.crc32(b"slaves")])
    q_scale = max(np.max(np.abs(sc.q0)), np.max(np.abs(s.nu(0.0))), 1e-3)
    dq = 0.02 * q_scale
    jumps = bool(np.all(np.linalg.eigvalsh(s.K) > 0))
    omega = np.sqrt(max(sla.eigh(s.K, s.M, eigvals_only=True)[0], 0.0)) if jumps else 1.0
    du = dq * max(omega, 1.0)
    z = g.standard_normal((2, 2 * n))
    obs = sc.observer or {}
    qa, ua = np.asarray(obs.get("q", sc.q0), float), np.asarray(obs.get("u", sc.u0), float)
    if np.array_equal(qa, sc.q0) and np.array_equal(ua, sc.u0):
        qa, ua = sc.q0 + dq * z[0, :n], sc.u0 + du * z[0, n:]
    qb, ub = sc.q0 + dq * z[1, :n], sc.u0 + du * z[1, n:]
    return jumps, (qa, ua), (qb, ub)


@pytest.mark.parametrize("name,ov", [("double_mass", {}), ("bouncing_ball", {}),
                                     ("double_mass", {"observer.q": None})])
def test_slave_specs_by_hand(name, ov):
    if ov:
        sc = pc.load(name)
        sc = pc.load(name, {"observer.q": sc.q0.tolist(), "observer.u": sc.u0.tolist()})
    else:
        sc = pc.load(name)
    specs = CheckContext(sc, CheckSettings(seed=0)).slave_specs()
    jumps, (qa, ua), (qb, ub) = _specs_by_hand(sc)
    names = (["jump_a", "jump_b"] if jumps else []) + ["nojump_a", "nojump_b"]
    assert [s.name for s in specs] == names
    assert [s.position_jumps for s in specs] == [n.startswith("jump") for n in names]
    for s in specs:
        q, u = (qa, ua) if s.name.endswith("_a") else (qb, ub)
        assert np.allclose(s.q0, q, rtol=1e-14, atol=1e-15) and np.allclose(s.u0, u, rtol=1e-14, atol=1e-15)
    if ov:
        assert not np.array_equal(specs[0].q0, sc.q0)            # perturbed away from the master


def test_shared_run_and_visited_sets():
    sc = pc.load("rocking_chain", {"param.N": 1, "initial.u": [-0.5, 0.3]})
    ctx = CheckContext(sc, CheckSettings(h=2e-3, t_end=0.6))
    run = ctx.run
    assert ctx.run is run and run.h == 2e-3 and run.t[-1] == pytest.approx(0.6)
    assert list(run.slaves) == ["jump_a", "jump_b", "nojump_a", "nojump_b"]
    act = run.master.active[1:]
    expected = {tuple(np.flatnonzero(r)) for r in act if r.any()}
    got = ctx.visited_sets()
    assert {tuple(x) for x in got} == expected and len(got) == len(expected) >= 2
    assert all(x.dtype.kind == "i" for x in got)


def test_cli_help_text(capsys):
    """The --help page: every option with its metavar and help (the user's documentation)."""
    with pytest.raises(SystemExit) as info:
        cli.main(["--help"])
    assert info.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for piece in (
            "usage: python -m proofs_checks [-h] [--set KEY=VALUE] [--only NAME] [--option CHECK.KEY=VALUE] "
            "[--seed SEED] [--h H] [--t-end T_END] [--engine NAME] [--json FILE] [--list] [SCENARIO ...]",
            "Numerically verify the steps of Proposition 1 and Theorem 1 on a scenario. Checks: mass_spd,",
            "SCENARIO built-in name, .toml path, or 'all' (every built-in scenario)",
            "--set KEY=VALUE scenario override (param.NAME for builder parameters, else dotted TOML key)",
            "--only NAME run only these checks (repeat or comma-separate)",
            "--option CHECK.KEY=VALUE keyword option of one check, e.g. impact_monotone.samples=200",
            "--seed SEED seed of all random sampling (default 0)",
            "--h H step of the run-based checks (default: the scenario's)",
            "--t-end T_END horizon of the run-based checks (default: min(t_end, 40000 h); convergence: the "
            "scenario's t_end within a memory budget)",
            "--engine NAME engine of the checks' runs, as simulate's engine (default: the first time-stepping "
            "engine that accepts each run)",
            "--json FILE write all results (with full witnesses) as JSON",
            "--list list the checks and exit"):
        assert piece in text, piece
    args = cli.build_parser().parse_args(["a", "b", "--only", "x", "--only", "y", "--set", "k=v", "--h", "0.5",
                                          "--t-end", "2", "--seed", "3", "--json", "f", "--option", "c.k=1"])
    assert (args.scenarios, args.only, args.set, args.h, args.t_end, args.seed, args.json, args.option,
            args.list) == (["a", "b"], ["x", "y"], ["k=v"], 0.5, 2.0, 3, "f", ["c.k=1"], False)
    assert cli.build_parser().parse_args([]).scenarios == []


# ----------------------------------------------------------------------------- near misses (mutation review)
def test_cli_malformed_pairs_name_their_flag(capsys):
    with pytest.raises(InputError) as info:
        cli._options(["mass_spd.rcond_min"])
    assert (info.value.field, info.value.problem) == ("--option", "expected KEY=VALUE, got 'mass_spd.rcond_min'")
    # the keyword is everything after the first dot (passed to the check as given)
    assert cli._options(["mass_spd.a.b=1"]) == {"mass_spd": {"a.b": 1}}
    assert cli.main(["double_mass", "--set", "param.m1"]) == 2
    assert capsys.readouterr().err.strip() == "error: --set: expected KEY=VALUE, got 'param.m1'"


def test_cli_t_end_bounds_json_of_several_scenarios_and_times(tmp_path, capsys):
    import time
    assert cli.main(["double_mass", "--only", "mass_spd", "--t-end", "0"]) == 2
    assert capsys.readouterr().err.strip() == "error: --t-end: must be > 0, got 0.0"
    out = tmp_path / "a" / "b" / "c.json"                      # parents created
    t0 = time.perf_counter()
    code = cli.main(["double_mass", "bouncing_ball", "--only", "mass_spd", "--t-end", "0.5",
                     "--json", str(out)])
    wall = time.perf_counter() - t0
    text = capsys.readouterr().out
    assert code == 0
    doc = json.loads(out.read_text())
    assert [(r["scenario"], r["name"]) for r in doc["results"]] == [("double_mass", "mass_spd"),
                                                                     ("bouncing_ball", "mass_spd")]
    assert doc["settings"]["t_end"] == 0.5 and 0 < doc["wall_time_s"] <= wall
    times = [float(line.rsplit(" in ", 1)[1].split()[0]) for line in text.splitlines() if line.startswith("  -> ")]
    assert len(times) == 2 and all(0 <= x <= wall + 0.05 for x in times)
    # an existing directory is fine
    assert cli.main(["double_mass", "--only", "mass_spd", "--json", str(tmp_path / "d.json")]) == 0
    assert json.loads((tmp_path / "d.json").read_text())["results"][0]["name"] == "mass_spd"


def test_format_table_cuts_the_witness_at_140_characters():
    r = CheckResult.from_margin("c", 1.0, 0.0, {}, "e", (), "w" * 200)
    line = cli.format_table([r]).splitlines()[1]
    assert line.endswith("  " + "w" * 137 + "...")
    r = CheckResult.from_margin("c", 1.0, 0.0, {}, "e", (), "w" * 140)
    assert cli.format_table([r]).splitlines()[1].endswith("  " + "w" * 140)


def test_assert_result_hides_its_frame_and_cuts_the_summary_at_200():
    bad = CheckResult.from_margin("chk", -1.0, 0.0, {}, "eq", (), "y" * 300)
    with pytest.raises(AssertionError) as info:
        pc.assert_result(bad)
    first = str(info.value).splitlines()[0]
    assert first == "proof check chk failed: margin -1 (tolerance 0); " + "y" * 197 + "..."
    # pytest's report leaves out the helper's own frame (__tracebackhide__)
    shown = [entry.frame.code.path for entry in info.traceback.filter(info)]
    assert not any(str(p).endswith("asserts.py") for p in shown)
    assert any(str(p).endswith("asserts.py") for p in (e.frame.code.path for e in info.traceback))


def test_assert_checks_forwards_keywords_and_formats_the_table(monkeypatch):
    with pytest.raises(AssertionError, match=r"^1 of 1 proof checks failed on double_mass: mass_spd\n"):
        pc.assert_checks("double_mass", "mass_spd", options={"mass_spd": {"rcond_min": 2.0}})
    # one failing check only: the scenario is the first result's
    with pytest.raises(AssertionError, match=r"^1 of 1 proof checks failed on bouncing_ball: stiffness_spd\n"):
        pc.assert_checks("bouncing_ball", "stiffness_spd", allow_not_applicable=False)
    a = CheckResult.from_margin("first", -0.123456, 0.0, {}, "e", (), "z" * 100)
    b = CheckResult.from_margin("second", -2.0, 0.0, {}, "e", (), "why")
    for r in (a, b):
        r.scenario = "sc"
    monkeypatch.setattr(asserts, "run_checks", lambda *args, **kw: [a, b])
    with pytest.raises(AssertionError) as info:
        pc.assert_checks("sc")
    text = str(info.value)
    lines = text.splitlines()
    assert lines[0] == "2 of 2 proof checks failed on sc: first, second"
    assert lines[1].split() == ["check", "status", "margin", "tolerance", "witness"]      # no index column
    assert lines[2].split()[:4] == ["first", "FAIL", "-0.123", "0"]                      # 3 significant digits
    assert lines[2].rstrip().endswith(" " + "z" * 67 + "...")                            # witness cut at 70
    assert lines[3].split()[:4] == ["second", "FAIL", "-2", "0"]
    assert text.endswith("\n\n" + a.message() + "\n\n" + b.message())


def test_run_checks_builds_its_settings_from_the_keywords(monkeypatch):
    seen = []

    def spy(ctx):
        seen.append(ctx.settings)
        return CheckResult.from_margin("mass_spd", 1.0, 0.0, {}, "eq")
    monkeypatch.setitem(pc.CHECKS, "mass_spd", spy)
    pc.run_checks("double_mass", "mass_spd")
    assert seen[-1] == CheckSettings(seed=0, h=None, t_end=None, options={})
    pc.run_checks("double_mass", "mass_spd", seed=5, h=2e-3, t_end=0.5, options={"mass_spd": {"x": 1}})
    assert seen[-1] == CheckSettings(seed=5, h=2e-3, t_end=0.5, options={"mass_spd": {"x": 1}})
    with pytest.raises(InputError) as info:
        pc.run_checks("double_mass", "mass_spd", options={"nope": {}})
    assert info.value.problem == f"unknown check(s) ['nope']; choose from {', '.join(pc.CHECKS)}"


@pytest.mark.parametrize("name,ov", [
    ("grazing", {}),                                                     # |ν(0)| > |q0| sets the scale
    ("rocking_chain", {"param.N": 1, "initial.q": [0.0, 0.0]}),         # time-varying ν, M ≠ I
    ("impact_oscillator", {"initial.q": [0.0]}),                        # q0 = ν = 0: the 1e-3 floor
    ("double_mass", {"param.m1": 0.05}),                               # generalized ω_min > 1 from (K, M)
])
def test_slave_specs_scales(name, ov):
    sc = pc.load(name, ov)
    specs = CheckContext(sc, CheckSettings(seed=2)).slave_specs()
    jumps, (qa, ua), (qb, ub) = _specs_by_hand(sc, seed=2)
    assert not np.array_equal(qb, sc.q0)
    _by_hand_matches_seed(sc, specs, 2)


def _by_hand_matches_seed(sc, specs, seed):
    jumps, (qa, ua), (qb, ub) = _specs_by_hand(sc, seed=seed)
    assert [s.name for s in specs] == (["jump_a", "jump_b"] if jumps else []) + ["nojump_a", "nojump_b"]
    for s in specs:
        q, u = (qa, ua) if s.name.endswith("_a") else (qb, ub)
        assert s.q0.dtype == np.float64 and s.u0.dtype == np.float64
        assert np.allclose(s.q0, q, rtol=1e-14, atol=1e-15) and np.allclose(s.u0, u, rtol=1e-14, atol=1e-15)


def test_slave_specs_keep_a_partly_different_observer_state_as_floats():
    sc = pc.load("bouncing_ball")
    # the observer's position equals the master's, its velocity does not: state a is kept
    sc2 = pc.load("bouncing_ball", {"observer.q": [1], "observer.u": [3]})
    assert np.array_equal(np.asarray(sc2.observer["q"], float), sc.q0)
    specs = CheckContext(sc2).slave_specs()
    a = [s for s in specs if s.name == "nojump_a"][0]
    assert a.q0.dtype == np.float64 and a.u0.dtype == np.float64
    assert a.q0.tolist() == [1.0] and a.u0.tolist() == [3.0]


def test_visited_sets_include_the_first_step():
    """The ball starts on the ground moving down: its only contact is at step 1."""
    sc = pc.load("bouncing_ball", {"initial.q": [0.0], "initial.u": [-1.0]})
    ctx = CheckContext(sc, CheckSettings(h=1e-3, t_end=0.05))
    act = ctx.run.master.active
    assert act[1, 0] and not act[2:].any()
    assert [x.tolist() for x in ctx.visited_sets()] == [[0]]
