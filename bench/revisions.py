"""The peers suite's oscillator timed on two source trees in one run: this tree and a git revision.

Issue 21's acceptance: "Peers suite in one run, before and after: the oscillator's per-step
time not worse than 5 %", and a bound on the 1-DOF oscillator's time per step for the whole
``simulate`` call. Timings of two trees taken on different days, or one after the other, compare the
machine's load as much as the code (on a shared machine the per-step time of the same tree
moves by ±30 % within minutes). So :func:`compare` times both trees **in one run,
alternating call by call**: each round starts one process per tree, each importing its
tree's ``observer`` (the revision is extracted by ``git archive`` into a temporary directory
and put first on ``PYTHONPATH``; the process reports the file it imports, checked here), and
then asks them in turn for one whole :func:`observer.simulate` call of the peers suite's
oscillator problem (:func:`bench.peers.peer_overrides`: the built-in ``impact_oscillator``
with Newton's law, master alone, default engine) over ``steps`` steps, ``repeats`` calls
each, while the other process waits.

What is timed is the user's whole call, as the peers suite times it
(:func:`bench.peers.run_toolkit`): one warm-up call on 10 steps first (numba compilation or
its cache load, reported apart as ``warmup_s``), then each call with the previous result
freed. Each call gives its wall time (``perf_counter``) and its CPU time (``process_time``,
less sensitive to other processes on the machine) per step, and the loop's own wall time
(``metadata["wall_time_s"]``) per step.

    python -m bench.revisions d26e40e                       # 10⁶ steps, 3 rounds × 7 calls
    python -m bench.revisions d26e40e --steps 200000 --rounds 5 --out osc.csv
    python -m bench.revisions d26e40e --problem ensemble --steps 200000 --rounds 3 --repeats 3

The table (:func:`summary`) gives per tree the median and spread (min, quartiles, max) of the
per-call ns/step, the median of the per-process medians, and the ratio of this tree's median
to the revision's.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from observer.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
"""This source tree (the checkout that holds ``bench/``)."""

PROBLEM = "impact_oscillator"
"""The default timed problem: the peers suite's 1-DOF oscillator."""

PROBLEMS = {
    "oscillator": {"scenario": PROBLEM, "overrides": {"impact.law": "newton"}, "kind": "simulate",
                   "observers": []},
    "double_mass": {"scenario": "double_mass", "overrides": {}, "kind": "simulate", "observers": None},
    "chain": {"scenario": "rocking_chain", "overrides": {"param.N": 100}, "kind": "simulate", "observers": []},
    "ensemble": {"scenario": "double_mass", "overrides": {}, "kind": "ensemble", "observers": None,
                 "members": 1000},
    **{f"event_{name}": {"scenario": base, "overrides": overrides, "kind": "event", "observers": []}
       for name, (base, overrides) in {
           "oscillator": ("impact_oscillator", {}),
           "table": ("bouncing_ball", {"param.h0": 0.0, "param.restitution": 0.5, "param.t_end": 0.5,
                                       "system.gap.amplitude": [-1e-3],
                                       "system.gap.omega": 2.0 * 3.141592653589793 * 20.0}),
           "ball": ("bouncing_ball", {}), "grazing": ("grazing", {}),
           "double_mass": ("double_mass", {})}.items()},
}
"""The timed problems (``--problem``), each one whole public call per timing: ``oscillator`` (the
peers suite's: Newton's law, the master alone), ``double_mass`` with both of its scenario's
observers, the ``chain`` (``rocking_chain``, N = 100, the master alone) and the ``ensemble`` of
1000 members per design of ``double_mass``'s observers (:func:`observer.ensemble`, one worker,
seed 0; its warm-up is one whole call, since the members' loop is compiled for the run's size,
:func:`observer.engines.compiled.members.sizes`). ``observers: None``: the scenario's own. ns/step
is the call's time per grid step.

The ``event_*`` problems are ``simulate(..., integrator="event")`` of the master alone over the
scenario's own t_end (``--steps`` unused): ``event_oscillator``, ``event_ball``,
``event_grazing``, ``event_double_mass`` (the built-ins) and ``event_table``, the ball on a
vibrating table of ``bench/micro/test_event_cost.py`` (``bouncing_ball`` with the gap
``q − A sin ωt``, A = 1 mm, ω = 2π·20 rad/s, e = 0.5, from rest on the table, 0.5 s). Their
"steps" are the call's event rows (impacts, grazes, accumulations, sticks, lift-offs), so that
ns/step reads ns per event; the ``impacts`` column counts the impact rows alone."""

CHILD = r"""
import gc, importlib.util, json, pathlib, sys, time
args = json.loads(sys.argv[1])
origin = importlib.util.find_spec("observer").origin      # located, not imported yet
if not pathlib.Path(origin).resolve().is_relative_to(pathlib.Path(args["tree"]).resolve()):
    print(json.dumps({"file": origin}), flush=True)       # another tree's package: nothing timed
    sys.exit(0)
import observer
sc = observer.load_scenario(args["scenario"], args["overrides"])
event = args["kind"] == "event"
if not event:
    sc = sc.with_overrides({"simulation.t_end": args["steps"] * sc.h})
obs = args["observers"]
if obs is None:
    obs = list((sc.observer or {}).get("observers", ()))
def call(t_end=None):
    if args["kind"] == "ensemble":
        return observer.ensemble(sc, designs=tuple(obs), n=args["members"] if t_end is None else 2, seed=0,
                                 workers=1, t_end=t_end)
    if event:
        return observer.simulate(sc, observers=obs, t_end=t_end, integrator="event")
    return observer.simulate(sc, observers=obs, t_end=t_end)
t0 = time.perf_counter()
res = call() if args["kind"] == "ensemble" else call(10 * sc.h)   # an ensemble's loop is specialized by size
engine = res.metadata.get("engine", "?") if hasattr(res, "metadata") else "ensemble"
print(json.dumps({"file": observer.__file__, "engine": engine, "warmup_s": time.perf_counter() - t0}), flush=True)
for line in sys.stdin:                                    # one timed call per line, until EOF
    res = None
    gc.collect()
    w0, c0 = time.perf_counter(), time.process_time()
    res = call()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    meta = getattr(res, "metadata", {})
    ev = res.events if event else None
    print(json.dumps({"wall_s": wall, "cpu_s": cpu, "loop_s": meta.get("wall_time_s", float("nan")),
                      "steps": len(ev) if event else int(meta.get("steps", args["steps"])),
                      "impacts": int((ev.kind == "impact").sum()) if event else 0}), flush=True)
"""
"""The timing process's script (run with the tree first on ``PYTHONPATH``; public API only,
so that it runs on any revision that has ``load_scenario`` and ``simulate``): it reports the
file it imports and its warm-up, then times one whole call per line read, until its input
closes."""


def extract(revision: str, dest: Path, repo: Path = ROOT) -> str:
    """Extract ``revision`` of ``repo`` into ``dest`` (``git archive``); return its full hash.

    Raises
    ------
    InputError
        Naming ``revision`` when git does not know it.
    """
    proc = subprocess.run(["git", "-C", str(repo), "rev-parse", "--verify", f"{revision}^{{commit}}"],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise InputError("revision", f"{revision!r} is not a commit of {repo}")
    commit = proc.stdout.strip()
    tar = subprocess.run(["git", "-C", str(repo), "archive", "--format=tar", commit],
                         capture_output=True, check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
        archive.extractall(dest, filter="data")
    return commit


class TreeTimer:
    """A timing process on one source tree (:data:`CHILD`), kept alive between calls so that
    two trees' calls can alternate one by one (each call runs while the other process waits).

    Attributes
    ----------
    file, engine : str
        The ``observer/__init__.py`` the process imported and the engine of its runs.
    warmup_s : float
        Its warm-up call's wall time (compilation or cache load).

    Raises
    ------
    RuntimeError
        The process failed, or would import ``observer`` from outside ``tree`` (checked
        before importing: nothing is timed then).
    """

    def __init__(self, tree: Path, steps: int, python: str = sys.executable, problem: str = "oscillator"):
        env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
               "MKL_NUM_THREADS": "1"}
        arg = json.dumps({**PROBLEMS[problem], "steps": steps, "tree": str(tree)})
        self.tree, self.steps = Path(tree), steps
        self.proc = subprocess.Popen([python, "-c", CHILD, arg], cwd=tree, env=env, text=True,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        head = self._read()
        self.file = head["file"]
        if not Path(self.file).resolve().is_relative_to(self.tree.resolve()):
            self.close()
            raise RuntimeError(f"the timing process imported {self.file}, not the tree {tree}")
        self.engine, self.warmup_s = head["engine"], head["warmup_s"]

    def _read(self) -> dict:
        line = self.proc.stdout.readline()
        if not line:
            err = self.proc.stderr.read().strip().splitlines() or ["no message"]
            self.proc.wait()
            raise RuntimeError(f"timing process on {self.tree} failed (exit {self.proc.returncode}): {err[-1]}")
        return json.loads(line)

    def call(self) -> dict:
        """One timed whole call: ``wall_s``, ``cpu_s``, ``loop_s``, ``steps``."""
        self.proc.stdin.write("call\n")
        self.proc.stdin.flush()
        return self._read()

    def close(self) -> None:
        """Close the process's input (it exits) and wait for it."""
        if self.proc.stdin and not self.proc.stdin.closed:
            self.proc.stdin.close()
        self.proc.wait()

    def __enter__(self) -> "TreeTimer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def compare(revision: str, steps: int = 1_000_000, rounds: int = 3, repeats: int = 7,
            python: str = sys.executable, repo: Path = ROOT, problem: str = "oscillator") -> pd.DataFrame:
    """Time this tree and ``revision`` alternately in one run; one row per timed call.

    Each round starts one process per tree (:class:`TreeTimer`), then alternates their calls
    one by one, ``repeats`` each (the first of each pair swapped every call and every round),
    so that both trees see the same load of the machine. Columns: ``tree`` ("current" or
    "revision"), ``commit`` (the revision's hash; "working tree" for this one), ``round``,
    ``process``, ``call``, ``steps`` (an ``event_*`` problem's: its event rows), ``impacts`` (an
``event_*`` problem's impact rows, else 0), ``ns_per_step`` (wall), ``cpu_ns_per_step``,
    ``loop_ns_per_step`` (the loop's own wall time), ``warmup_s`` (the process's warm-up call:
    compilation or cache load), ``engine``, ``problem`` (:data:`PROBLEMS`).
    """
    if problem not in PROBLEMS:
        raise InputError("problem", f"must be one of {', '.join(PROBLEMS)}, got {problem!r}")
    for name, value in (("steps", steps), ("rounds", rounds), ("repeats", repeats)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise InputError(name, f"must be a positive integer, got {value!r}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-rev-") as tmp:
        commit = extract(revision, Path(tmp), repo)
        trees = {"current": (repo, "working tree"), "revision": (Path(tmp), commit)}
        for r in range(rounds):
            with (TreeTimer(trees["revision"][0], steps, python, problem) as old,
                  TreeTimer(repo, steps, python, problem) as new):
                timers = {"revision": (old, 2 * r), "current": (new, 2 * r + 1)}
                for i in range(repeats):
                    order = ("revision", "current") if (i + r) % 2 == 0 else ("current", "revision")
                    for name in order:
                        timer, process = timers[name]
                        c = timer.call()
                        rows.append({"tree": name, "commit": trees[name][1], "round": r, "process": process,
                                     "call": i, "steps": c["steps"], "impacts": c.get("impacts", 0),
                                     "ns_per_step": 1e9 * c["wall_s"] / c["steps"],
                                     "cpu_ns_per_step": 1e9 * c["cpu_s"] / c["steps"],
                                     "loop_ns_per_step": 1e9 * c["loop_s"] / c["steps"],
                                     "warmup_s": timer.warmup_s, "engine": timer.engine, "problem": problem})
    return pd.DataFrame(rows)


def summary(calls: pd.DataFrame) -> pd.DataFrame:
    """Per tree and measure (wall, CPU, loop ns/step): calls, median, min, quartiles, max, the
    median of the per-process medians, the median warm-up, and ``ratio`` = the tree's median ÷
    the revision's (> 1: slower than the revision)."""
    out = []
    for measure in ("ns_per_step", "cpu_ns_per_step", "loop_ns_per_step"):
        base = float(calls.loc[calls.tree == "revision", measure].median())
        for tree, g in calls.groupby("tree", sort=False):
            x = g[measure].to_numpy(float)
            out.append({"tree": tree, "commit": g["commit"].iloc[0], "measure": measure, "calls": x.size,
                        "median": float(np.median(x)), "min": float(x.min()),
                        "q25": float(np.quantile(x, 0.25)), "q75": float(np.quantile(x, 0.75)),
                        "max": float(x.max()),
                        "median_of_processes": float(g.groupby("process")[measure].median().median()),
                        "warmup_s": float(g.groupby("process")["warmup_s"].first().median()),
                        "ratio": float(np.median(x)) / base})
    return pd.DataFrame(out)


def main(argv: list[str] | None = None) -> int:
    """``python -m bench.revisions REVISION [--steps N] [--rounds R] [--repeats K] [--out CSV]``:
    print :func:`summary`; write every call's row to ``--out`` (CSV) when given."""
    ap = argparse.ArgumentParser(prog="python -m bench.revisions", description=__doc__.splitlines()[0])
    ap.add_argument("revision", help="git revision to compare this tree with (e.g. d26e40e)")
    ap.add_argument("--steps", type=int, default=1_000_000)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--out", type=Path, default=None, help="CSV of every timed call")
    ap.add_argument("--problem", default="oscillator", help=f"the timed problem: {', '.join(PROBLEMS)}")
    args = ap.parse_args(argv)
    try:
        calls = compare(args.revision, args.steps, args.rounds, args.repeats, problem=args.problem)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.out is not None:
        calls.to_csv(args.out, index=False)
    with pd.option_context("display.width", 200, "display.max_columns", 20, "display.precision", 4):
        print(summary(calls).to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
