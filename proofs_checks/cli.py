"""Command line: ``python -m proofs_checks SCENARIO [SCENARIO ...] [options]``.

Runs the proof checks on built-in or TOML scenarios (``all`` = every built-in), prints one
table per scenario (check, status, evidence level, margin, tolerance, time, verdict and
witness summary) and exits
with status 0 when no check failed (not-applicable checks do not fail), 1 when a check
failed, and 2 with one line ``error: ...`` on stderr for bad input.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

from observer.cli_common import Parser, guarded, parse_pairs
from observer.errors import InputError

STATUS_WIDTH = 6
EVIDENCE_WIDTH = 8


def _options(items: list[str] | None) -> dict:
    from observer.scenario import parse_value
    from proofs_checks import CHECKS
    out: dict = {}
    for key, value in parse_pairs(items, "--option").items():
        check, _, kw = key.partition(".")
        if check not in CHECKS or not kw:
            raise InputError("--option", f"expected CHECK.KEYWORD=VALUE with CHECK one of "
                             f"{', '.join(CHECKS)}, got {key!r}")
        out.setdefault(check, {})[kw] = parse_value(value)
    return out


def _fmt(x: float) -> str:
    if x != x:                                                  # NaN
        return "-"
    return f"{x:.3g}"


def format_table(results) -> str:
    """The per-scenario table printed by the CLI."""
    w = max(len(r.name) for r in results)
    lines = [f"  {'check':<{w}}  {'status':<{STATUS_WIDTH}}  {'evidence':<{EVIDENCE_WIDTH}}  {'margin':>10}  "
             f"{'tol':>8}  {'time':>6}  verdict | witness"]
    for r in results:
        text = r.summary(140) if not r.verdict else (r.verdict + " | " + r.summary(10_000))
        text = text if len(text) <= 140 else text[:137] + "..."
        lines.append(f"  {r.name:<{w}}  {r.status:<{STATUS_WIDTH}}  {r.evidence:<{EVIDENCE_WIDTH}}  "
                     f"{_fmt(r.margin):>10}  {_fmt(r.tolerance):>8}  {r.elapsed:5.1f}s  {text}")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    from proofs_checks import CHECKS
    p = Parser(                           # one-line argparse errors, as observer's CLI
        prog="python -m proofs_checks",
        description="Numerically verify the steps of Proposition 1 and Theorem 1 on a scenario. "
                    f"Checks: {', '.join(CHECKS)}.")
    p.add_argument("scenarios", nargs="*", metavar="SCENARIO",
                   help="built-in name, .toml path, or 'all' (every built-in scenario)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="scenario override (param.NAME for builder parameters, else dotted TOML key)")
    p.add_argument("--only", action="append", metavar="NAME",
                   help="run only these checks (repeat or comma-separate)")
    p.add_argument("--option", action="append", metavar="CHECK.KEY=VALUE",
                   help="keyword option of one check, e.g. impact_monotone.samples=200")
    p.add_argument("--seed", type=int, default=0, help="seed of all random sampling (default 0)")
    p.add_argument("--h", type=float, help="step of the run-based checks (default: the scenario's)")
    p.add_argument("--t-end", type=float, help="horizon of the run-based checks (default: min(t_end, 40000 h); convergence: the scenario's t_end within a memory budget)")
    p.add_argument("--engine", default=None, metavar="NAME",
                   help="engine of the checks' runs, as simulate's engine (default: the first "
                        "time-stepping engine that accepts each run)")
    p.add_argument("--json", metavar="FILE", help="write all results (with full witnesses) as JSON")
    p.add_argument("--list", action="store_true", help="list the checks and exit")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return guarded(_main, args)


def _main(args) -> int:
    import proofs_checks
    from observer.engines import check_engine_name
    from observer.scenarios import SCENARIOS
    from proofs_checks import CHECKS, EVIDENCE_LEVELS, CheckSettings, run_checks, select

    if args.list:
        for name, fn in CHECKS.items():
            print(name)
        return 0
    if not args.scenarios:
        raise InputError("SCENARIO", "give at least one scenario (a built-in name, a .toml file, or 'all')")
    names = [s for item in args.scenarios for s in (SCENARIOS if item == "all" else [item])]
    only = select(args.only) if args.only else None
    overrides = parse_pairs(args.set, "--set")
    check_engine_name(args.engine)
    settings = CheckSettings(seed=args.seed, h=args.h, t_end=args.t_end, options=_options(args.option),
                             engine=args.engine)
    _check_run_option("--h", settings.h)
    _check_run_option("--t-end", settings.t_end)
    scenarios = [proofs_checks.load(n, overrides) for n in names]   # validate all inputs first
    all_results = []
    failed = 0
    t_start = time.perf_counter()
    for name, sc in zip(names, scenarios):
        t0 = time.perf_counter()
        results = run_checks(sc, only, settings=settings)
        ctx_h = settings.h or sc.h
        print(f"{sc.name} ({name}): n = {sc.system.n}, m = {sc.system.m}, {sc.law.law} law, "
              f"restitution {_restitution(sc)}; seed {settings.seed}, run h = {ctx_h:g}")
        print(format_table(results))
        nfail = sum(r.passed is False for r in results)
        nna = sum(r.passed is None for r in results)
        levels = ", ".join(f"{sum(r.evidence == lv for r in results)} {lv}" for lv in EVIDENCE_LEVELS)
        print(f"  -> {len(results) - nfail - nna} passed, {nfail} failed, {nna} not applicable "
              f"in {time.perf_counter() - t0:.1f} s ({levels})\n")
        failed += nfail
        all_results += results
    if args.json:
        path = Path(args.json)
        path.parent.mkdir(parents=True, exist_ok=True)
        doc = {"settings": {"seed": settings.seed, "h": settings.h, "t_end": settings.t_end, "engine": settings.engine,
                            "options": settings.options, "overrides": overrides, "scenarios": names},
               "platform": platform.platform(), "python": platform.python_version(),
               "wall_time_s": time.perf_counter() - t_start,
               "results": [r.to_dict() for r in all_results]}
        path.write_text(json.dumps(doc, indent=1))
        print(f"wrote {path}")
    if failed:
        print(f"{failed} check(s) FAILED", file=sys.stderr)
    return 1 if failed else 0


def _check_run_option(flag: str, value: float | None) -> None:
    """``--h`` / ``--t-end``: a finite number > 0 whose inverse is finite (as observer's
    ranges: 1e-320 would overflow 1/h)."""
    from observer.validation import INV_MIN
    if value is not None and not value > 0:
        raise InputError(flag, f"must be > 0, got {value!r}")
    if value is not None and not INV_MIN <= value < float("inf"):
        raise InputError(flag, f"must be finite with a finite inverse, got {value!r}")


def _restitution(sc) -> str:
    e = sc.law.restitution
    return f"{e[0]:g} (global)" if sc.law.is_global else "[" + ", ".join(f"{x:g}" for x in e) + "]"
