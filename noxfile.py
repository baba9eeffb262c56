"""nox sessions.

* ``tests`` (default): the pytest suite on two pytest-xdist workers, dependencies pinned by
  ``constraints.txt``; see ``docs/guide/testing.md``.
* ``tests_latest``: the same suite against the latest releases of every dependency.
* ``mutants -- [MODULE ...]``: mutation testing (mutmut) of the core modules, each against
  its own tests (:data:`MUTATION_TARGETS`); see ``tests/mutants/README.md``.
* ``report``: the main job — run the ``quick`` benchmark suite (resumable) and build the
  self-contained HTML report ``reports/out/quick/index.html``; ``-- SUITE`` for another.
* ``bench -- SUITE``: run a benchmark suite only (rows appended to ``bench/results/SUITE.jsonl``).
* ``checks``: the proof checks on every built-in scenario.
* ``run -- SCENARIO``: simulate one scenario with both observers and plot it.
* ``docs``: build the documentation site into ``docs/_build/html`` (warnings are errors,
  nitpicky cross-references, the gallery's examples run).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import tomllib
from pathlib import Path

import nox

nox.needs_version = ">=2024.3.2"
nox.options.default_venv_backend = "virtualenv"
nox.options.reuse_existing_virtualenvs = True
nox.options.sessions = ["tests"]


ROOT = Path(__file__).resolve().parent
CONSTRAINTS = "constraints.txt"


SINGLE_THREAD_BLAS = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""The tests solve thousands of tiny systems: BLAS threads only add synchronisation (an
``lu_solve`` of a 2×2 took orders of magnitude longer with threaded OpenBLAS on busy cores)."""


WARM_KERNEL = ("import time, observer; from observer.loop import compile_time; "
               "print(f'kernel compiled or loaded in {compile_time():.1f} s')")
"""Compile the time-stepping kernel (its general, lean and scalar loops) once (numba's
on-disk cache, ``__pycache__``) before the test workers start: the workers then only load
it, so no two of them compile (and write) the same entry."""

WARM_OTHERS = ("import time, observer; t = time.perf_counter(); "
               "observer.simulate('bouncing_ball', integrator='event', t_end=0.1); "
               "print(f'event kernels compiled or loaded in {time.perf_counter() - t:.1f} s'); "
               "t = time.perf_counter(); "
               "observer.compare('double_mass', n=2, masters=2, t_end=0.05, h=1e-3, n_resamples=100); "
               "print(f'ensemble members loop compiled or loaded in {time.perf_counter() - t:.1f} s')")
"""The event integrator's kernels (``observer.event.kernels``, through a short event run)
and the members loop of the ensembles (through a small :func:`observer.compare`), compiled
in a second process beside :data:`WARM_KERNEL`: one per core."""

WARM_COLLECT = "import pytest, sys; sys.exit(pytest.main(['--collect-only', '-q', '-p', 'no:cacheprovider']))"
"""Collect the whole suite once: pytest's assertion rewriting of every test module (about
14 CPU s) is then written to ``__pycache__`` (:data:`BYTECODE`) and loaded by each worker,
instead of done by both."""


def warm(collect: bool = True) -> str:
    """The warm-ups at once (the two cores of CI): the kernel, then the collection of the whole
    suite (``collect``: not when pytest is given its own arguments), in one process; the event
    kernels and the members loop in the other; failing if any fails."""
    tests = (f"subprocess.run([sys.executable, '-c', {WARM_COLLECT!r}], stdout=subprocess.DEVNULL).returncode"
             if collect else "0")
    return ("import subprocess, sys; "
            f"others = subprocess.Popen([sys.executable, '-c', {WARM_OTHERS!r}]); "
            f"kernel = subprocess.run([sys.executable, '-c', {WARM_KERNEL!r}]).returncode; "
            f"tests = {tests}; "
            "sys.exit(kernel or tests or others.wait())")


WARM = warm()
"""The whole suite's warm-up (:func:`warm`)."""

BYTECODE = {"PYTHONDONTWRITEBYTECODE": ""}
"""Bytecode caches on (an environment that sets ``PYTHONDONTWRITEBYTECODE`` turns them off, and
with them the cache of pytest's rewritten test modules, so that every worker and every
subprocess would compile them again)."""

PARALLEL = ["-n", "2", "--durations=50"]
"""pytest-xdist over the two cores of CI, with the 50 slowest tests listed; replaced by
whatever follows ``--`` (``nox -s tests -- -n 0 tests/observer`` runs serially). Not
``--dist loadgroup``: with pytest 9.2 and pytest-xdist 3.8 its ``xdist_group`` marks are
ignored (pytest-xdist issue 1386; the marks in tests/reports/ take effect once it is fixed)."""


@nox.session
def tests(session: nox.Session) -> None:
    """Install the package with its test extras, every version pinned by ``constraints.txt``,
    warm the compiled kernel's cache, and run pytest on two workers (pass pytest args after
    --: they replace :data:`PARALLEL`)."""
    session.install("-c", CONSTRAINTS, "-e", ".[test]")
    env = {**SINGLE_THREAD_BLAS, **BYTECODE}
    session.run("python", "-c", warm(collect=not session.posargs), env=env)
    session.run("python", "-m", "pytest", *(session.posargs or PARALLEL), env=env)


@nox.session
def tests_latest(session: nox.Session) -> None:
    """The test suite against the latest release of every dependency (no constraints file):
    the early warning that an upstream release breaks something ``tests`` would not see."""
    session.install("--upgrade", "--upgrade-strategy", "eager", "-e", ".[test]")
    session.run("python", "-m", "pytest", *session.posargs, env=SINGLE_THREAD_BLAS)


# Mutation testing: module -> (files mutated, tests run against them). Each module is run
# in its own work directory mutants/MODULE/ (mutmut copies the tree into
# mutants/MODULE/mutants/ and runs pytest there, so the tests import the mutated copy).
MUTATION_TARGETS: dict[str, tuple[list[str], list[str]]] = {
    "stepping": (["observer/stepping.py"],
                 ["tests/observer/test_stepping_physics.py", "tests/observer/test_stepping_oracles.py", "tests/observer/test_stepping.py"]),
    "impact": (["observer/impact.py"],
               ["tests/observer/test_stepping_physics.py", "tests/observer/test_contact.py", "tests/observer/test_stepping_oracles.py",
                "tests/observer/test_impact.py", "tests/observer/test_impact.py"]),
    "contact": (["observer/contact/*"], ["tests/observer/test_contact.py"]),
    "observers": (["observer/observers.py"], ["tests/observer/test_observers.py", "tests/observer/test_stepping.py",
                                              "tests/observer/test_observers.py"]),
    "model": (["observer/model.py"], ["tests/observer/test_model_signals.py", "tests/observer/test_stepping.py",
                                      "tests/observer/test_validation.py", "tests/observer/test_scenarios.py",
                                      "tests/observer/test_stepping_oracles.py", "tests/observer/test_loop.py",
                                      "-k", "not subprocess"]),
    # proofs_checks, one entry per group of files, each against the fast tests that reach it
    # (equivalent mutants: tests/mutants/proofs_checks_*.md; overview tests/mutants/proofs_checks.md)
    "proofs_checks_lyapunov": (["proofs_checks/lyapunov.py"],
                               ["tests/proofs_checks/test_checks.py", "tests/proofs_checks/test_lyapunov.py"]),
    "proofs_checks_projection": (["proofs_checks/projection.py"],
                                 ["tests/proofs_checks/test_checks.py", "tests/proofs_checks/test_projection.py",
                                  "tests/proofs_checks/test_checks.py::test_projection_psd_exhaustive_and_sampled",
                                  "tests/proofs_checks/test_checks.py::test_projection_psd_fails_for_indefinite_stiffness",
                                  "tests/proofs_checks/test_checks.py::test_every_default_tolerance_is_pinned"]),
    "proofs_checks_switching": (["proofs_checks/switching.py"],
                                ["tests/proofs_checks/test_checks.py", "tests/proofs_checks/test_checks.py", "-k",
                                 "switching or isolated_switch or projected_master_gap or proofs_checks_mutants"]),
    "proofs_checks_small": (["proofs_checks/assumptions.py", "proofs_checks/forcing.py", "proofs_checks/result.py",
                             "proofs_checks/context.py", "proofs_checks/asserts.py", "proofs_checks/__init__.py",
                             "proofs_checks/cli.py"],
                            ["tests/proofs_checks/test_assumptions.py", "tests/proofs_checks/test_result.py",
                             "tests/proofs_checks/test_api.py", "tests/proofs_checks/test_asserts.py",
                             "tests/proofs_checks/test_cli.py"]),
    "proofs_checks_designs": (["proofs_checks/designs.py"], ["tests/proofs_checks/test_designs.py"]),
    "proofs_checks_proposition": (["proofs_checks/proposition.py"], ["tests/proofs_checks/test_proposition.py"]),
    "proofs_checks_monotonicity": (["proofs_checks/monotonicity.py"], ["tests/proofs_checks/test_monotonicity.py"]),
    "proofs_checks_runs": (["proofs_checks/runs.py"], ["tests/proofs_checks/test_runs.py"]),
    # the pytest plugin, loaded from the work copy (not the installed entry point) so that its
    # mutants are the ones pytest sees
    "proofs_checks_plugin": (["proofs_checks/plugin.py"],
                             ["-p", "no:proofs_checks", "-p", "proofs_checks.plugin",
                              "tests/proofs_checks/test_plugin.py"]),
    # the engines: the compiled kernel (run as plain Python, see PLAIN_PYTHON_TARGETS), the loop
    # drivers and the event engine, each against small cases
    # the fingerprint test (4000 steps per scenario and variant) is too slow as plain Python
    # and the reference-count test inspects numba's compiled code (no such thing without the JIT);
    # the factored (banded, large-n) contact data are reached only by two tests of test_sparse.py
    "kernel": (["observer/kernel.py"], ["tests/observer/test_kernel.py",
                                        "tests/observer/test_sparse.py::test_factored_gram_matches_the_dense_block_and_its_cache_stays_consistent",
                                        "tests/observer/test_sparse.py::test_factored_contact_data_run_the_dense_contact_datas_trajectory",
                                        # an observer's failed step: the loop resumes at system s > 0
                                        "tests/observer/test_loop.py::test_failed_steps_of_master_and_observer_are_recorded_as_the_reference_engine",
                                        "-k", "not bitwise_those_of_main and not hold_no_reference_counts"]),
    # loop.py: the kernel's tests (both engines, short horizons), the fast tests of
    # test_loop.py (its every-builtin and long-horizon tests take minutes each as plain Python)
    # and the non-finite guard's tests (plain Python warns where the compiled kernel overflows
    # silently: PYTEST_ARGS)
    "loop": (["observer/loop.py"], ["tests/observer/test_kernel.py", "tests/observer/test_loop_nonfinite.py",
                                    "tests/observer/test_sparse.py::test_factored_contact_data_run_the_dense_contact_datas_trajectory",
                                    # the residual-exceeded stop of both engines
                                    "tests/observer/test_health.py::test_residual_above_tolerance_stops_the_run",
                                    *(f"tests/observer/test_loop.py::{t}" for t in (
                                        "test_specialization_selection", "test_loop_times_are_the_grid",
                                        "test_summary_store_refuses_the_python_engine",
                                        "test_compile_time_warms_each_specialization_once",
                                        "test_failed_steps_of_master_and_observer_are_recorded_as_the_reference_engine",
                                        "test_engines_agree_on_a_log_driven_observer",
                                        "test_positions_before_the_projection_are_the_same_on_both_engines",
                                        "test_a_residual_equal_to_the_tolerance_does_not_stop_the_run",
                                        "test_replaying_the_recorded_chi_reproduces_the_run")),
                                    "-k", "not bitwise_those_of_main and not hold_no_reference_counts"]),
    "event": (["observer/event/*"], ["tests/observer/event/test_master.py", "tests/observer/event/test_master_exact.py",
                                     "tests/observer/event/test_observers.py", "tests/observer/test_simulate_event.py",
                                     "tests/observer/event/test_nonfinite.py", "tests/observer/event/test_roots.py",
                                     "tests/observer/event/test_joint_tails.py",
                                     "-k", "not signal and not 1e18 and not twenty_seconds"]),
}
PYTEST_ARGS: dict[str, list[str]] = {
    "loop": ["-W", "ignore:overflow encountered:RuntimeWarning",
             "-W", "ignore:invalid value encountered:RuntimeWarning"],
}
"""Extra pytest arguments of a target, for every pytest run of it (mutmut passes the test
selection's options only to its first, whole-selection run; the runs of single mutants get
node ids plus ``pytest_add_cli_args``)."""
PLAIN_PYTHON_TARGETS = frozenset({"kernel", "loop", "event"})
"""Targets run through ``tests/mutants/run_mutmut.py`` with ``NUMBA_DISABLE_JIT=1``: numba's
``@njit`` then returns the plain function, so mutmut may mutate the kernel's decorated
functions (the wrapper allows that one decorator) and its trampolines run; the kernel runs
as Python (orders of magnitude slower, hence the small cases of the tests)."""
MUTMUT_WRAPPER = "tests/mutants/run_mutmut.py"
MUTANTS_DIR = ROOT / "mutants"
EQUIVALENT_DIR = ROOT / "tests" / "mutants"
_COPIED = ("observer", "proofs_checks", "tests")
_EQUIVALENT_NAME = re.compile(r"`([\w.]+__mutmut_\d+)`")


def _toml_list(items: list[str]) -> str:
    return "[" + ", ".join(json.dumps(i) for i in items) + "]"


def _mutmut_pyproject(module: str, tests: list[str]) -> str:
    """pyproject.toml of a module's work directory: the project's, with its ``[tool.mutmut]``
    table narrowed to the module's files and tests."""
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    base = tomllib.loads(text)["tool"]["mutmut"]
    # drop the project's [tool.mutmut] table (up to the next table header)
    text = re.sub(r"(?ms)^\[tool\.mutmut\]\n.*?(?=^\[|\Z)", "", text)
    settings = dict(base, only_mutate=MUTATION_TARGETS[module][0],
                    pytest_add_cli_args=[*base["pytest_add_cli_args"], *PYTEST_ARGS.get(module, [])],
                    pytest_add_cli_args_test_selection=tests)
    lines = ["", "[tool.mutmut]"]
    for key, value in settings.items():
        if isinstance(value, list):
            lines.append(f"{key} = {_toml_list([str(v) for v in value])}")
        else:
            lines.append(f"{key} = {json.dumps(value)}")
    return text.rstrip() + "\n" + "\n".join(lines) + "\n"


STALE_NAMES = "<!-- names of older sources below: not read -->"
"""In tests/mutants/MODULE.md, the line after which mutant names refer to an older source
(mutmut numbers the mutants of each function anew when it changes): kept as analysis, not
counted."""


def _equivalent_mutants(module: str) -> set[str]:
    """Mutant names listed (in backticks) in tests/mutants/MODULE.md as equivalent (above the
    :data:`STALE_NAMES` line, if any)."""
    path = EQUIVALENT_DIR / f"{module}.md"
    if not path.exists():
        return set()
    text = path.read_text(encoding="utf-8").split(STALE_NAMES)[0]
    return set(_EQUIVALENT_NAME.findall(text))


def _clopper_pearson(session: nox.Session, caught: int, total: int) -> tuple[float, float]:
    """95 % Clopper–Pearson interval of a proportion caught/total, computed with
    ``scipy.stats.binomtest(...).proportion_ci`` in the session's environment."""
    out = session.run("python", "-c", "import sys; from scipy.stats import binomtest; "
                      "ci = binomtest(int(sys.argv[1]), int(sys.argv[2])).proportion_ci(0.95, 'exact'); "
                      "print(ci.low, ci.high)", str(caught), str(total), silent=True)
    low, high = (float(x) for x in str(out).split()[-2:])
    return low, high


def _mutation_summary(session: nox.Session, module: str, work: Path) -> dict:
    """Read mutmut's per-file verdicts; print the score and the survivors not listed as
    equivalent; return the counts. After a sampled run (``mutants/sample.json``) only the
    sampled mutants count, and the score gets its 95 % Clopper–Pearson interval."""
    verdicts: dict[str, int | None] = {}
    for meta in (work / "mutants").rglob("*.py.meta"):
        verdicts.update(json.loads(meta.read_text())["exit_code_by_key"])
    sample_file = work / "mutants" / "sample.json"
    sample = json.loads(sample_file.read_text()) if sample_file.exists() else None
    if sample is not None:
        verdicts = {name: verdicts.get(name) for name in sample["names"]}
    killed = sum(code in (1, 3) for code in verdicts.values())
    timeout = sum(code in (36, 24, -24, 152, 255) for code in verdicts.values())
    survived = sorted(k for k, code in verdicts.items() if code == 0)
    other = sorted(k for k, code in verdicts.items()
                   if code not in (0, 1, 3, 36, 24, -24, 152, 255))
    equivalent = _equivalent_mutants(module)
    stale = sorted(equivalent - set(verdicts)) if sample is None else []
    unexplained = [k for k in survived if k not in equivalent]
    caught = killed + timeout
    total = len(verdicts)
    listed = len(equivalent & set(survived))
    considered = total - listed
    score = 100.0 * caught / total if total else float("nan")
    adjusted = 100.0 * caught / considered if considered else float("nan")
    what = (f"sample of {total} of {sample['population']} mutants (seed {sample['seed']})"
            if sample else f"{total} mutants")
    session.log(f"[{module}] {what}: {killed} killed, {timeout} timeout, "
                f"{len(survived)} survived ({listed} listed as "
                f"equivalent), {len(other)} other (no tests / suspicious / not checked)")
    session.log(f"[{module}] mutation score {score:.1f} % (caught/total); "
                f"{adjusted:.1f} % excluding listed equivalents")
    interval = None
    if sample is not None and total:
        # the README's rule: a listed equivalent counts as caught; a sampled mutant not checked
        # (a stopped run) is not caught for the lower bound and caught for the upper one
        unchecked = sum(code is None for code in verdicts.values())
        interval = (_clopper_pearson(session, caught + listed, total)[0],
                    _clopper_pearson(session, caught + listed + unchecked, total)[1])
        session.log(f"[{module}] (killed + listed equivalent)/sampled = {caught + listed}/{total} = "
                    f"{100.0 * (caught + listed) / total:.1f} % ({unchecked} not checked), 95 % "
                    f"Clopper–Pearson interval [{100 * interval[0]:.1f} %, {100 * interval[1]:.1f} %]")
    for name in unexplained:
        session.log(f"[{module}]   survived: {name}")
    for name in other:
        session.log(f"[{module}]   {verdicts[name]}: {name}")
    if stale:
        session.warn(f"[{module}] tests/mutants/{module}.md lists mutants that no longer "
                     f"exist (renumbered after a source change?): {', '.join(stale)}")
    return dict(module=module, total=total, killed=killed, timeout=timeout,
                survived=survived, unexplained=unexplained, other=other,
                score=score, score_excluding_equivalents=adjusted,
                sample=sample and dict(seed=sample["seed"], population=sample["population"]),
                interval95=interval)


@nox.session
def mutants(session: nox.Session) -> None:
    """Mutation testing with mutmut: ``nox -s mutants -- [MODULE ...] [--tests T,...]
    [--max-children N] [--sample N --seed S]``.

    MODULE is one of :data:`MUTATION_TARGETS` (default: all, one after the other); each is
    mutated and tested against its own test files only (``--tests`` replaces them), in a
    fresh work directory ``mutants/MODULE/``. Afterwards ``cd mutants/MODULE`` and
    ``mutmut results`` / ``mutmut show NAME`` inspect the survivors. A summary of every
    module goes to ``mutants/summary.json``. ``--sample N --seed S`` (the plain-Python targets
    ``kernel``, ``loop``, ``event``, whose complete runs take hours) runs a uniform random
    sample of N mutants drawn with seed S and reports the score with its 95 % Clopper–Pearson
    interval. See ``tests/mutants/README.md``.
    """
    session.install("-c", CONSTRAINTS, "-e", ".[test]", "mutmut")
    args = list(session.posargs)
    tests_override: list[str] | None = None
    max_children: list[str] = []
    if "--tests" in args:
        i = args.index("--tests")
        tests_override = [t for t in args[i + 1].split(",") if t]
        del args[i:i + 2]
    if "--max-children" in args:
        i = args.index("--max-children")
        max_children = ["--max-children", args[i + 1]]
        del args[i:i + 2]
    sampling: list[str] = []
    for option in ("--sample", "--seed"):
        if option in args:
            i = args.index(option)
            sampling += [option, args[i + 1]]
            del args[i:i + 2]
    modules = args or list(MUTATION_TARGETS)
    unknown = [m for m in modules if m not in MUTATION_TARGETS]
    if unknown:
        session.error(f"unknown module(s) {unknown}; choose from {sorted(MUTATION_TARGETS)}")
    if sampling and not set(modules) <= PLAIN_PYTHON_TARGETS:
        session.error(f"--sample is for the plain-Python targets {sorted(PLAIN_PYTHON_TARGETS)}")
    # tests resolve the oracle data from the project root; the work copy is elsewhere
    env = {"OBSERVER_ORACLES": os.environ.get("OBSERVER_ORACLES",
                                              str(ROOT.parent / "shared" / "oracles"))}
    summaries = []
    for module in modules:
        tests = tests_override or MUTATION_TARGETS[module][1]
        work = MUTANTS_DIR / module
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
        ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".hypothesis", ".benchmarks")
        for name in _COPIED:
            shutil.copytree(ROOT / name, work / name, ignore=ignore)
        (work / "pyproject.toml").write_text(_mutmut_pyproject(module, tests), encoding="utf-8")
        with session.chdir(work):
            if module in PLAIN_PYTHON_TARGETS:
                session.run("python", MUTMUT_WRAPPER, "run", *sampling, *max_children,
                            env={**env, **SINGLE_THREAD_BLAS, "NUMBA_DISABLE_JIT": "1"})
            else:
                session.run("mutmut", "run", *max_children, env={**env, **SINGLE_THREAD_BLAS})
            summaries.append(_mutation_summary(session, module, work))
    (MUTANTS_DIR / "summary.json").write_text(json.dumps(summaries, indent=2))


@nox.session
def checks(session: nox.Session) -> None:
    """Run the proof checks on every built-in scenario (``nox -s checks -- NAME ...`` for one);
    fails when a check fails (a violated one, e.g. a rise of V that the discrete slack does
    not explain). Results with full witnesses go to ``out/checks.json``; when every check
    holds, one line says whether the only finding is the discrete slack of eq. (17)."""
    session.install("-e", ".")
    session.run("python", "-m", "proofs_checks", *(session.posargs or ["all"]),
                "--json", "out/checks.json")
    session.run("python", "-c", "import json; from proofs_checks.lyapunov import findings_line; "
                "print(findings_line(json.load(open('out/checks.json'))['results']))")


@nox.session
def run(session: nox.Session) -> None:
    """Simulate a built-in scenario with both observers and plot it.

    ``nox -s run -- SCENARIO`` (default ``double_mass``); writes ``out/SCENARIO.csv`` and
    ``out/SCENARIO.png``.
    """
    session.install("-e", ".")
    name = session.posargs[0] if session.posargs else "double_mass"
    extra = session.posargs[1:]
    session.run("python", "-m", "observer", "run", name, "--observers", "jump,nojump",
                "--out", f"out/{name}.csv", *extra)
    session.run("python", "-m", "observer", "plot", f"out/{name}.csv", "--out", f"out/{name}.png")


@nox.session
def bench(session: nox.Session) -> None:
    """Run a benchmark suite: ``nox -s bench -- SUITE [--limit K]`` (default ``quick``).

    Suites: quick, full, observers, work_precision, robustness, scaling, peers, micro, smoke
    (``python -m bench list``). Rows are appended to ``bench/results/SUITE.jsonl`` as runs
    finish; rerunning resumes an interrupted suite without recomputing finished rows. The
    ``peers`` cases (also in ``full``) need Debian's ``python3-siconos`` under
    ``/usr/bin/python3``; without it they are skipped with a note, nothing fails.
    """
    session.install("-e", ".[bench]")
    suite = session.posargs[0] if session.posargs else "quick"
    session.run("python", "-m", "bench", "run", suite, *session.posargs[1:])


@nox.session
def report(session: nox.Session) -> None:
    """Build the HTML report of a suite: ``nox -s report -- SUITE`` (default ``quick``).

    Runs the suite first if its results are missing or incomplete (finished rows are
    kept), then writes ``reports/out/SUITE/index.html`` (self-contained; open it in a browser).
    The time loops run on the compiled engine; its compile (or numba cache load) time is
    measured once before the cases and reported apart.
    """
    session.install("-e", ".[bench]")
    suite = session.posargs[0] if session.posargs else "quick"
    session.run("python", "-m", "bench", "run", suite, success_codes=[0, 1])
    session.run("python", "-m", "reports", suite, "--out", f"reports/out/{suite}", *session.posargs[1:])


@nox.session
def docs(session: nox.Session) -> None:
    """Build the documentation site: ``docs/_build/html/index.html`` (Sphinx, warnings as
    errors, nitpicky; the gallery runs the examples with ``--quick``)."""
    session.install("-c", CONSTRAINTS, "-e", ".[docs]")
    shutil.rmtree(ROOT / "docs" / "_build", ignore_errors=True)
    shutil.rmtree(ROOT / "docs" / "api" / "generated", ignore_errors=True)
    session.run("python", "-m", "sphinx", "-W", "-n", "--keep-going", "-b", "html", "docs",
                "docs/_build/html", *session.posargs, env={**SINGLE_THREAD_BLAS, "MPLBACKEND": "Agg"})


if __name__ == "__main__":
    nox.main()
