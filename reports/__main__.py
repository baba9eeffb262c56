"""``python -m reports``: build the HTML report of one or more suites.

    python -m reports quick                                   # bench/results/quick.cases
    python -m reports bench/results/quick.cases --out reports/out/quick
    python -m reports quick --check                           # + headless Chromium check

An argument that is not an existing path is taken as a suite name and resolved to its results
under ``--results`` (default ``bench/results``; :func:`reports.context.suite_results`).
``--out`` defaults to ``reports/out/<first suite>``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m reports", description=__doc__.split("\n\n")[0])
    p.add_argument("inputs", nargs="*", default=["quick"],
                   help="results (case folders, .csv, .parquet) or suite names (default: quick)")
    p.add_argument("--out", default=None, help="output folder (default reports/out/<suite>)")
    p.add_argument("--results", default="bench/results", help="folder of suite results")
    p.add_argument("--micro", nargs="*", default=None, help="pytest-benchmark JSON files "
                   "(default: <suite>-micro.json next to each results file)")
    p.add_argument("--command", default=None, help="the 'how to reproduce' command shown")
    p.add_argument("--check", action="store_true",
                   help="open the page in headless Chromium and check images and console")
    args = p.parse_args(argv)

    from reports.context import suite_results

    files = []
    for item in args.inputs:
        path = Path(item)
        if not path.exists() and path.suffix not in (".jsonl", ".csv", ".parquet"):
            path = suite_results(item, args.results)
        if not path.exists():
            print(f"error: no results for {item!r} ({path} does not exist); run "
                  f"`python -m bench run {Path(item).stem}` first", file=sys.stderr)
            return 2
        files.append(path)
    out = Path(args.out) if args.out else Path("reports/out") / files[0].name.split(".")[0]
    from reports.build import build_report
    from observer.errors import InputError
    t0 = time.perf_counter()
    try:
        index = build_report(files, out, micro_files=args.micro, command=args.command)
    except InputError as exc:            # results that are not results, or hold no rows
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:              # a read-only folder, a full disk: no partial index.html left
        where = exc.filename or (out / "index.html")
        print(f"error: {where}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    print(f"report: {index} ({index.stat().st_size / 1e6:.1f} MB, built in "
          f"{time.perf_counter() - t0:.1f} s)")
    if args.check:
        from reports.browser import check_page
        res = check_page(index, out / "screenshot.png")
        print(res.text())
        return 0 if res.ok else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
