"""Command line: ``python -m observer {scenarios, show, run, ensemble, compare, uncertainty, log, plot}``.

Errors in input exit with status 2 and one line on stderr (``error: FIELD: PROBLEM``),
never a traceback.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from observer.cli_common import Parser, guarded, parse_pairs
from observer.engines import ENGINES
from observer.errors import InputError, printable
from observer.outputs import atomic_write, check_outputs
from observer.validation import check_output_path

_Parser = Parser
"""The former name of :class:`observer.cli_common.Parser`."""

IMAGE_SUFFIXES = (".png", ".svg", ".pdf")
"""Image formats ``plot --out`` writes."""


UNDEFINED = "n/a"
"""How the run's summary tables print a value that is not defined (never ``NaN``)."""


def summary_table(frame) -> str:
    """``frame`` as the terminal table ``run`` prints: three significant digits, a value that
    is not defined as :data:`UNDEFINED`."""
    return frame.to_string(index=False, float_format=lambda x: f"{x:.3g}", na_rep=UNDEFINED)

def cmd_scenarios(args) -> int:
    from observer.scenarios import SCENARIOS
    width = max(len(k) for k in SCENARIOS)
    for name, module in SCENARIOS.items():
        print(f"{name:<{width}}  {module.DESCRIPTION}")
    return 0


def cmd_show(args) -> int:
    from observer.scenario import load_scenario
    from observer.tomlio import dumps
    sc = load_scenario(args.scenario, parse_pairs(args.set))
    header = f"{printable(sc.name)}: {printable(sc.description)}\n"
    module_doc = ""
    from observer.scenarios import SCENARIOS
    if args.scenario in SCENARIOS:
        module_doc = (SCENARIOS[args.scenario].__doc__ or "").strip()
    text = dumps(sc.to_dict(), comments={"scenario": header + module_doc})
    sys.stdout.write(text)
    return 0


def cmd_run(args) -> int:
    from observer.io import SUFFIXES
    from observer.scenario import load_scenario
    from observer.simulate import simulate
    from observer.stream import ChunkWriter, exit_status
    check_outputs({"--out": args.out, "--events": args.events},
                  {"--log": args.log, "scenario": args.scenario})
    check_output_path("--out", args.out, SUFFIXES)
    if args.events is not None:
        check_output_path("--events", args.events, SUFFIXES)
    sc = load_scenario(args.scenario, parse_pairs(args.set))
    with ChunkWriter(args.out) as writer:          # rows written as the loop finishes them
        timed = TimedCalls(writer)
        res = simulate(sc, h=args.h, t_end=args.t_end, solver=args.solver,
                       observers=observer_list(args.observers), source=args.source, log=args.log,
                       on_chunk=timed, **_integrator_options(args))
        in_loop, t0 = timed.seconds, time.perf_counter()
        path = writer.finish(res)
        timed.seconds += time.perf_counter() - t0
    if args.events is not None:
        write_events(res, args.events)
    meta = res.metadata
    if meta.get("integrator") == "event":
        print(f"{printable(sc.name)}: exact event-driven run, {meta['events']} master events, sampled every "
              f"h = {meta['h']:g} ({meta['steps']} rows); status {res.status.state.value}"
              + (f": {res.status.reason}" if res.status.reason else ""))
    else:
        print(_stepping_message(sc, res, in_loop, timed.seconds))
    if res.summary is not None:
        print("synchronization over every step (store=summary; times from t_on; inf = not reached; "
              f"{UNDEFINED} = not defined):")
        cols = [c for c in res.summary.columns if c.startswith(("observer", "V_on", "V_end", "t_sync", "t_settle"))]
        print(summary_table(res.summary[cols]))
    elif res.slaves:
        summary = res.synchronization()
        print("synchronization (times from t_on to V <= rho V(t_on); inf = not reached; "
              f"{UNDEFINED} = not defined, e.g. the rate of a run too short to fit):")
        print(summary_table(summary.drop(columns=["master_closings"])))
    print(f"wrote {path}")
    if res.metadata.get("stopped"):
        print(f"error: {res.status.reason}; {path} holds every step up to there", file=sys.stderr)
    return exit_status(res)


def cmd_ensemble(args) -> int:
    """``ensemble``: n members per design (:func:`observer.ensemble.ensemble`) to a Parquet file."""
    from observer.ensemble import ensemble
    from observer.scenario import load_scenario
    check_outputs({"--out": args.out}, {"scenario": args.scenario})
    check_output_path("--out", args.out, (".parquet",))
    sc = load_scenario(args.scenario, parse_pairs(args.set))
    designs = split_names("--designs", args.designs)
    df = ensemble(sc, designs=designs, n=args.n, seed=args.seed, initial_errors=args.initial_errors,
                  V0=args.V0, h=args.h, t_end=args.t_end, integrator=args.integrator, paths=args.paths,
                  workers=args.workers, out=args.out)
    meta = df.attrs["metadata"]
    print(f"{printable(sc.name)}: {args.n} members x {len(designs)} designs ({meta['integrator']}) in "
          f"{meta['wall_time_s']:.2f} s; median settling times (inf = never):")
    cols = [c for c in df.columns if c.startswith("t_settle")]
    print(df.groupby("design", sort=False)[cols].median().to_string(float_format=lambda x: f"{x:.3g}"))
    print(f"wrote {args.out}")
    return 0


def cmd_uncertainty(args) -> int:
    """``uncertainty``: the designs' floors and times to a level over plants drawn from
    ``--uncertainty`` (:func:`observer.uncertainty.uncertainty_ensemble`); the rows (one per
    plant, design and member) to ``--out`` with the metadata and the per-design summary
    (``metadata["summary"]``) beside them (:func:`observer.io.write_frame`)."""
    from observer.io import SUFFIXES, write_frame
    from observer.scenario import load_scenario
    from observer.uncertainty import flag_names, parse_uncertainty, uncertainty_ensemble
    check_outputs({"--out": args.out}, {"scenario": args.scenario})
    check_output_path("--out", args.out, SUFFIXES)
    table = parse_uncertainty(args.uncertainty)
    if table is None:
        raise InputError("--uncertainty", "give the relative uncertainty of at least one matrix, e.g. "
                                          "--uncertainty K=0.01")
    sc = load_scenario(args.scenario, parse_pairs(args.set))
    with flag_names():
        df = uncertainty_ensemble(sc, split_names("--designs", args.designs), model=table, plants=args.plants,
                                  n=args.n, seed=args.seed, sample=args.sample, h=args.h, t_end=args.t_end,
                                  tail=args.tail, record_every=args.record_every, level=args.level,
                                  n_resamples=args.n_resamples)
    meta = df.attrs["metadata"]
    rows = df.attrs["members"].copy()
    rows.attrs = {**meta, "summary": df.to_dict("records")}
    write_frame(rows, args.out)
    print(f"{printable(sc.name)}: {meta['n']} members x {len(meta['plants'])} plants ({meta['sample']} drawn) "
          f"per design; floors of V/V(t_on) over the window's last {meta['tail']:g}, medians with "
          f"{int(100 * meta['confidence'])} % intervals over plants; time to V <= {_level(meta['level'])} "
          f"V(t_on) ({meta['level_rule']}):")
    cols = ["design", "floor_V", "floor_V_low", "floor_V_high", "floor_q", "t_level", "t_level_low",
            "t_level_high", "t_level_reached", "t_level_status"]
    print(summary_table(df[cols]))
    print(f"wrote {args.out}")
    return 0


def _level(level) -> str:
    return UNDEFINED if level is None else f"{level:.3g}"


def observer_list(text: str | None):
    """``--observers``: absent → the scenario's ``[observer] observers``; ``none`` → the master
    alone; else comma-separated design names."""
    if text is None:
        return "scenario"
    if text.strip().lower() == "none":
        return []
    return split_names("--observers", text)


def split_names(flag: str, text: str) -> list[str]:
    """A comma-separated list of names (``--observers``, ``--designs``); an empty item
    (``jump,``, ``jump,,nojump``, ``""``) is an error naming ``flag``."""
    names = [o.strip() for o in text.split(",")]
    if not all(names):
        raise InputError(flag, f"empty item in {text!r}: give comma-separated names such as "
                               "jump,nojump")
    return names


def _integrator_options(args) -> dict:
    """The run's integrator and, for time-stepping, its engine, row and storage options
    (refused with the event-driven integrator, which samples on the grid t_k = k·h)."""
    if args.integrator == "event":
        for flag, value in (("--engine", args.engine), ("--record-every", args.record_every),
                            ("--store", args.store)):
            if value is not None:
                raise InputError(flag, "is a time-stepping option; --integrator event samples "
                                       "the exact solution on the grid t_k = k·h")
        return {"integrator": "event"}
    return {"engine": args.engine, "integrator": args.integrator, "record_every": args.record_every,
            "store": args.store or "full"}


def write_events(res, path: str) -> None:
    """The result's events table to ``path`` (CSV or Parquet by suffix)."""
    if res.events is None:
        raise InputError("--events", "this run kept no event table (time-stepping builds it "
                                     "from every step: drop --record-every / --store summary)")
    p = Path(path)
    if p.suffix.lower() == ".parquet":
        atomic_write(p, lambda tmp: res.events.to_parquet(tmp, index=False))
    else:
        atomic_write(p, lambda tmp: res.events.to_csv(tmp, index=False, float_format="%.17g"))
    print(f"wrote {p}: {len(res.events)} events")


class TimedCalls:
    """A callable passing its calls to ``func`` and adding up the seconds they take
    (:attr:`seconds`): the time ``run`` spends writing rows inside the loop."""

    def __init__(self, func):
        self.func, self.seconds = func, 0.0

    def __call__(self, *args, **kwargs):
        t0 = time.perf_counter()
        try:
            return self.func(*args, **kwargs)
        finally:
            self.seconds += time.perf_counter() - t0


def _stepping_message(sc, res, in_loop_s: float = 0.0, write_s: float = 0.0) -> str:
    """One line on a time-stepped run: steps, the loop's time and speed without the writing of
    rows inside it (``in_loop_s``), the whole writing time (``write_s``) said apart, engine,
    closed steps, residual, fallbacks."""
    meta = res.metadata
    loop_s = max(meta['wall_time_s'] - in_loop_s, 0.0)
    speed = f"{meta['steps'] / loop_s:.0f}" if loop_s > 0 else "inf"
    return (f"{printable(sc.name)}: {meta['steps']} steps of h = {meta['h']:g} in {loop_s:.2f} s "
            f"({speed} steps/s; writing the output {write_s:.2f} s; {meta['engine']} engine"
            + (f", compiled in {meta['compile_time_s']:.1f} s" if meta['compile_time_s'] > 0.05 else "")
            + f"), {int(res.active[1:].any(axis=1).sum())} "
            + ("steps" if meta["record_every"] == 1 else f"of the {res.t.size - 1} kept rows")
            + f" with closed contacts, max contact residual {meta['max_contact_residual']:.1e}"
            + (f", {meta['solver_fallbacks']} steps re-solved by the reference solver"
               if meta['solver_fallbacks'] else "")
            + (f" ({meta['engine_note']})" if meta.get("engine_note") else ""))


def cmd_plot(args) -> int:
    from observer.plotting import plot_run
    from observer.result import read_frame
    check_outputs({"--out": args.out}, {"result": args.result})
    check_output_path("--out", args.out, IMAGE_SUFFIXES)
    df = read_frame(args.result)
    path = atomic_write(args.out, lambda tmp: plot_run(df, tmp, dof=args.dof))
    print(f"wrote {path}")
    return 0


def cmd_log(args) -> int:
    import numpy as np

    from observer.result import read_frame
    from observer.switching import log_from_active
    check_outputs({"--out": args.out}, {"result": args.result})
    out = check_output_path("--out", args.out, (".csv",))
    df = read_frame(args.result)
    cols = sorted((c for c in df.columns if c.startswith("active")), key=lambda c: int(c[6:]))
    if not cols:
        raise InputError(args.result, "no active0.. columns: not a result written by 'run'")
    log = log_from_active(df["t"].to_numpy(), df[cols].to_numpy().astype(bool))
    atomic_write(out, lambda tmp: log.to_csv(tmp, index=False, float_format="%.17g"))
    impacts = int(np.sum(log["t_open"] == log["t_close"]))
    print(f"wrote {out}: {len(log)} closed intervals ({impacts} impacts of zero length) "
          f"over {len(cols)} contacts")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="python -m observer",
                                description="Impact-time state observers for nonsmooth mechanical systems.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    s = sub.add_parser("scenarios", help="list the built-in scenarios")
    s.set_defaults(func=cmd_scenarios)
    s = sub.add_parser("show", help="print a scenario as an editable TOML file")
    s.add_argument("scenario", help="built-in name or .toml path")
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override (param.NAME for builder parameters, else dotted TOML key)")
    s.set_defaults(func=cmd_show)
    s = sub.add_parser("run", help="simulate a scenario and write the result (CSV or Parquet)")
    s.add_argument("scenario", help="built-in name or .toml path")
    s.add_argument("--h", type=float, help="step size")
    s.add_argument("--t-end", type=float, help="final time")
    s.add_argument("--solver", help="contact solver (pivoting, lemke, nnls, reference)")
    s.add_argument("--observers", help="comma-separated observer designs, e.g. jump,nojump; "
                                       "'none' runs the master alone (default: the scenario's "
                                       "[observer] observers)")
    s.add_argument("--integrator", choices=["time-stepping", "event"], default=None,
                   help="Moreau–Jean time-stepping (default, or the --engine's) or the exact "
                        "event-driven integrator")
    s.add_argument("--events", metavar="FILE", help="also write the events table (.csv or .parquet)")
    s.add_argument("--source", choices=["master", "log", "self"], help="switching signal source")
    s.add_argument("--log", help="closing log CSV (contact,t_close,t_open) for --source log")
    s.add_argument("--engine", choices=list(ENGINES), default=None,
                   help="a registered engine: compiled (the numba kernel), python (the numpy "
                        "reference), event, ... (default: the first that accepts the run)")
    s.add_argument("--record-every", type=int, default=None, metavar="K",
                   help="keep every K-th step (default 1; about 10 000 rows with --store summary)")
    s.add_argument("--store", choices=["full", "summary"], default=None,
                   help="summary: V, its parts and the synchronization times computed over every "
                        "step in the kernel, trajectories kept only every K-th step")
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override (param.NAME for builder parameters, else dotted TOML key)")
    s.add_argument("--out", required=True, help="output file (.csv or .parquet)")
    s.set_defaults(func=cmd_run)
    s = sub.add_parser("ensemble", help="n observers per design from sampled initial errors, "
                                        "one row per (design, member), to a Parquet file")
    s.add_argument("scenario", help="built-in name or .toml path")
    s.add_argument("--n", type=int, default=1000, help="members per design (default 1000)")
    s.add_argument("--designs", default="jump,nojump", help="comma-separated observer designs")
    s.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    s.add_argument("--initial-errors", choices=["energy_sphere", "box"], default="energy_sphere",
                   help="sampler of the initial errors (default energy_sphere)")
    s.add_argument("--V0", type=float, default=None, help="level of the energy sphere (default: "
                                                          "V of the scenario's observer error)")
    s.add_argument("--h", type=float, help="step size")
    s.add_argument("--t-end", type=float, help="final time")
    s.add_argument("--integrator", choices=["time-stepping", "event", "timestepping"], default="time-stepping",
                   help="Moreau–Jean time-stepping (default) or the exact event-driven integrator "
                        "('timestepping': old spelling, deprecated)")
    s.add_argument("--paths", type=int, default=0, help="keep V(t) of the first K members per design")
    s.add_argument("--workers", type=int, default=None, help="threads (default: the machine's cores)")
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override (param.NAME for builder parameters, else dotted TOML key)")
    s.add_argument("--out", required=True, help="output file (.parquet)")
    s.set_defaults(func=cmd_ensemble)
    from observer.compare import add_parser as add_compare
    add_compare(sub)
    _add_uncertainty(sub)
    s = sub.add_parser("log", help="write the closing log (contact,t_close,t_open) of a run, "
                                   "the input of --source log")
    s.add_argument("result", help="result file written by run")
    s.add_argument("--out", required=True, help="closing log CSV")
    s.set_defaults(func=cmd_log)
    s = sub.add_parser("plot", help="draw the paper-style figures of a run")
    s.add_argument("result", help="result file written by run")
    s.add_argument("--out", required=True, help="image file (.png, .svg, .pdf)")
    s.add_argument("--dof", type=int, default=0, help="coordinate to plot (default 0)")
    s.set_defaults(func=cmd_plot)
    return p


def _add_uncertainty(sub) -> None:
    """The ``uncertainty`` subcommand's arguments."""
    s = sub.add_parser("uncertainty", help="the designs' floors and times to a level over plants drawn "
                                           "from a relative uncertainty of the matrices, to a CSV or Parquet file")
    s.add_argument("scenario", help="built-in name or .toml path")
    s.add_argument("--uncertainty", action="append", metavar="NAME=SIGMA", required=True,
                   help="relative uncertainty of matrix NAME (M, C, K, W), e.g. K=0.01; repeatable")
    s.add_argument("--plants", type=int, default=20, help="plants drawn (default 20)")
    s.add_argument("--n", type=int, default=20, help="paired members per design (default 20)")
    s.add_argument("--designs", default="jump,nojump", help="comma-separated observer designs")
    s.add_argument("--seed", type=int, default=0, help="seed of the plants and the initial errors (default 0)")
    s.add_argument("--sample", choices=["plant", "model"], default="plant",
                   help="draw the master's plant (default; observers nominal) or the observers' model")
    s.add_argument("--level", type=float, default=None, help="level of V/V(t_on) whose first-passage time is "
                                                              "summarized (default: 10x the largest member floor)")
    s.add_argument("--tail", type=float, default=0.25, help="floors over this last fraction of the window")
    s.add_argument("--n-resamples", type=int, default=999, help="bootstrap resamples of the intervals (default 999)")
    s.add_argument("--h", type=float, help="step size")
    s.add_argument("--t-end", type=float, help="final time")
    s.add_argument("--record-every", type=int, default=None, metavar="K", help="record every K-th step")
    s.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override (param.NAME for builder parameters, else dotted TOML key)")
    s.add_argument("--out", required=True, help="output file (.csv or .parquet)")
    s.set_defaults(func=cmd_uncertainty)


def main(argv: list[str] | None = None) -> int:
    import warnings
    warnings.formatwarning = lambda msg, cat, *a, **k: f"warning: {msg}\n"
    args = build_parser().parse_args(argv)
    return guarded(args.func, args)
