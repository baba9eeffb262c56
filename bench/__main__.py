"""``python -m bench``: run, list and inspect benchmark suites.

    python -m bench list
    python -m bench show quick
    python -m bench run quick [--out bench/results] [--limit K] [--no-progress] [--no-micro]
    python -m bench run full                              # a local Dask cluster, one worker per core (≤ 4)
    python -m bench run full --workers 2                  # a local Dask cluster of 2 workers
    python -m bench run full --scheduler tcp://host:8786  # an existing Dask scheduler
    python -m bench run quick --workers 0                 # in this process, no Dask
    python -m bench status quick

Each finished case is written at once (``OUT/<suite>.cases/<key>.parquet``): a killed worker,
a killed ``python -m bench run`` or a restarted sweep loses no finished case and computes none
twice.

The BLAS thread count is pinned to 1 (unless already set) before NumPy is imported: the
systems are small, and threaded BLAS on small matrices only adds contention and noise to
the timings (measured: several times slower per step for the N = 50 … 200 chain on 2
shared cores).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

from bench import RESULTS_DIR  # noqa: E402


def _workers(text: str) -> int:
    """``--workers``: an integer ≥ 0."""
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return n


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and run the command; bad input (an unknown suite, an unusable ``--out``,
    a full disk) is one ``error: ...`` line on stderr and exit status 2, never a traceback."""
    from observer.cli_common import Parser, guarded

    p = Parser(prog="python -m bench", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True, parser_class=Parser)
    sub.add_parser("list", help="list the suites")
    s = sub.add_parser("show", help="list the cases of a suite")
    s.add_argument("suite")
    for name, helptext in (("run", "run a suite (resumes: finished cases are skipped)"),
                           ("status", "how many cases of a suite are done")):
        s = sub.add_parser(name, help=helptext)
        s.add_argument("suite", nargs="?", default="quick")
        s.add_argument("--out", default=RESULTS_DIR, help="results folder (default %(default)s)")
        if name == "run":
            s.add_argument("--limit", type=int, default=None,
                           help="run at most K of the remaining cases")
            s.add_argument("--no-progress", action="store_true", help="no progress bar")
            s.add_argument("--no-micro", action="store_true", help="skip the micro-benchmarks")
            s.add_argument("--workers", type=_workers, default=None,
                           help="worker processes of the local Dask cluster (default: one per "
                                "core, at most 4; 0: run in this process without Dask)")
            s.add_argument("--scheduler", default=None, metavar="ADDRESS",
                           help="run on an existing Dask scheduler (e.g. tcp://host:8786) "
                                "instead of a local cluster")
    args = p.parse_args(argv)
    return guarded(_main, args)


def _out_folder(out: str) -> str:
    """``--out``: a results folder (created if missing), not a file."""
    from observer.errors import InputError

    path = Path(out)
    if not str(out).strip():
        raise InputError("--out", "expected a results folder, got ''")
    if path.exists() and not path.is_dir():
        raise InputError("--out", f"{out!r} is not a directory")
    return out


def _main(args) -> int:
    from bench.suites import SUITES, get_suite
    from observer.errors import InputError

    if args.cmd == "list":
        for name, suite in SUITES.items():
            kinds = Counter(c.kind for c in suite.cases)
            micro = " + micro" if suite.micro else ""
            print(f"{name:15s} {len(suite.cases):4d} cases "
                  f"({', '.join(f'{k} {v}' for k, v in kinds.items()) or 'none'}{micro}): "
                  f"{suite.description}")
        return 0
    try:
        suite = get_suite(args.suite)
    except KeyError as exc:
        raise InputError("suite", exc.args[0]) from None
    if args.cmd == "show":
        for c in suite.cases:
            print(c.case_id)
        return 0
    from bench.results import CaseStore
    from bench.run import results_path, run_suite
    _out_folder(args.out)
    if args.cmd == "status":
        store = CaseStore(results_path(suite.name, args.out))
        n_done = sum(store.has(c.case_id) for c in suite.cases)
        print(f"{suite.name}: {n_done}/{len(suite.cases)} cases done "
              f"({results_path(suite.name, args.out)})")
        for path, reason in store.damaged():
            print(f"damaged case file {path.name} {reason} (not counted; the next run moves it "
                  "aside and computes its case again)")
        return 0
    from bench.run import default_workers
    if args.limit is not None and args.limit < 0:
        raise InputError("--limit", f"must be >= 0, got {args.limit}")
    workers = default_workers() if args.workers is None and args.scheduler is None else args.workers
    summary = run_suite(suite, args.out, progress=not args.no_progress, limit=args.limit,
                        micro=not args.no_micro, workers=workers, scheduler=args.scheduler)
    print(summary.text())
    micro_failed = summary.micro_status.startswith("failed")
    return 1 if summary.failed or micro_failed else 0


if __name__ == "__main__":
    sys.exit(main())
