"""The scripts in ``examples/`` run as a researcher runs them and produce what they promise.

Each script is run once (``python examples/X.py --quick --out DIR`` from the project root,
in a subprocess), when a test first asks for it (a module fixture, :class:`_Runs`); the
second input of ``my_system.py`` whose numbers are checked (``failing``) is run in this
process (:func:`_run_in_process`: the same script and arguments, without a third interpreter
start-up and import of the toolkit for that script; its default run and its bad input stay
subprocesses). The tests then check the files and the printed
numbers: figures that are real images with the paper's colours, the full proof-check table
with an exit status that matches its verdicts, finite settling times of both observers
under a measured contact log. Interpreter start-up and imports dominate the cost (a few
seconds per script once the numba kernel is cached).
"""

from __future__ import annotations

import ast
import contextlib
import io
import math
import os
import runpy
import subprocess
import sys
from pathlib import Path
from unittest import mock

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
TAB_BLUE, TAB_RED, BLACK = (31, 119, 180), (214, 39, 40), (0, 0, 0)
"""Matplotlib's tab:blue / tab:red (observer with / without jumps) and the master's black."""


def _run(script: str, out: Path, *extra: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env["MPLBACKEND"] = "Agg"
    # the first run on a fresh checkout compiles the numba kernel once: hence the generous timeout
    return subprocess.run([sys.executable, f"examples/{script}", "--quick", "--out", str(out), *extra],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=600)


def _run_in_process(script: str, out: Path, *extra: str) -> subprocess.CompletedProcess:
    """:func:`_run` in this process: the script run as ``__main__`` (:func:`runpy.run_path`)
    from the project root with the same ``sys.argv``; its ``sys.exit`` status, stdout and
    stderr (its warnings under Python's default filters appended, as an interpreter prints
    them). An exception it does not catch propagates (the test errors)."""
    import warnings

    argv = [f"examples/{script}", "--quick", "--out", str(out), *extra]
    stdout, stderr = io.StringIO(), io.StringIO()
    code = 0
    with contextlib.chdir(REPO), mock.patch.object(sys, "argv", argv), \
            contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr), \
            warnings.catch_warnings(record=True) as said:
        warnings.resetwarnings()
        warnings.simplefilter("default")
        plt = sys.modules.get("matplotlib.pyplot")
        open_before = set(plt.get_fignums()) if plt else set()
        try:
            runpy.run_path(argv[0], run_name="__main__")
        except SystemExit as exc:
            code = 0 if exc.code is None else exc.code if isinstance(exc.code, int) else 1
        finally:                                      # the script's figures (its process would end here)
            plt = sys.modules.get("matplotlib.pyplot")
            for num in set(plt.get_fignums()) - open_before if plt else ():
                plt.close(num)
    err = stderr.getvalue() + "".join(warnings.formatwarning(w.message, w.category, w.filename, w.lineno)
                                      for w in said)
    return subprocess.CompletedProcess(argv, code, stdout.getvalue(), err)


def _failing(d: Path) -> tuple[str, ...]:
    """``my_system.py``'s arguments for one rocking block with per-contact Newton restitution
    [0.1, 0.95], exported as TOML by ``python -m observer show`` (in this process: the file
    is the input, not what is tested)."""
    import contextlib
    import io

    from observer.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["show", "rocking_chain", "--set", "param.N=1", "--set", "impact.law=newton",
                     "--set", "impact.restitution=[0.1,0.95]"]) == 0
    (d / "rocking_chain.toml").write_text(buf.getvalue())
    return (str(d / "rocking_chain.toml"),)


def _bad_input(d: Path) -> tuple[str, ...]:
    """``my_system.py``'s arguments for a file with a missing key (``system.C``)."""
    (d / "bad.toml").write_text("[system]\nM = [[1.0]]\nK = [[1.0]]\nW = [[1.0]]\n")
    return (str(d / "bad.toml"),)


RUNS = {"paper_figures.py": ("paper_figures.py", None), "my_system.py": ("my_system.py", None),
        "measured_log.py": ("measured_log.py", None), "compare_designs.py": ("compare_designs.py", None),
        "failing": ("my_system.py", _failing), "bad_input": ("my_system.py", _bad_input)}
"""Run name → (script, function writing its input files into the run's folder and returning
its extra arguments): the four scripts, plus ``my_system.py`` on one rocking block whose
impact map is not monotone on the coupled contacts (``failing``: A3 is violated) and on a
file with a missing key (``bad_input``)."""

IN_PROCESS = frozenset({"failing"})
"""Runs of :data:`RUNS` made by :func:`_run_in_process` (every script has a subprocess run)."""


class _Runs:
    """name → (CompletedProcess, output directory) of :data:`RUNS`, each script run once, when
    a test first asks for it: a test waits for its own script only (not for all six), and a
    pytest-xdist worker runs only the scripts of the tests it was given."""

    def __init__(self, tmp_path_factory):
        self._factory, self._done = tmp_path_factory, {}

    def __getitem__(self, name: str) -> tuple[subprocess.CompletedProcess, Path]:
        if name not in self._done:
            script, inputs = RUNS[name]
            d = self._factory.mktemp(name.removesuffix(".py"))
            run = _run_in_process if name in IN_PROCESS else _run
            self._done[name] = (run(script, d, *(inputs(d) if inputs else ())), d)
        return self._done[name]


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> _Runs:
    """The example runs of :data:`RUNS` (:class:`_Runs`), shared by the module's tests."""
    return _Runs(tmp_path_factory)


def _table(stdout: str, first_col: str) -> pd.DataFrame:
    """The whitespace-separated table of ``stdout`` whose header row starts with ``first_col``
    (the last column may contain spaces); it ends at the first line with fewer cells."""
    lines = stdout.splitlines()
    start = next(i for i, line in enumerate(lines) if line.split()[:1] == [first_col])
    header = lines[start].split()
    rows = []
    for line in lines[start + 1:]:
        cells = line.split(None, len(header) - 1)
        if len(cells) != len(header):
            break
        rows.append(cells)
    return pd.DataFrame(rows, columns=header)


def _numeric(df: pd.DataFrame, cols) -> pd.DataFrame:
    return df.assign(**{c: df[c].astype(float) for c in cols})


def _pixels_near(path: Path, rgb: tuple[int, int, int], tol: int = 40) -> int:
    """Number of pixels of the PNG within ``tol`` (per channel, 0-255) of ``rgb``."""
    import matplotlib.image as mpimg
    img = mpimg.imread(path)[..., :3]
    img = np.round(img * 255) if img.dtype.kind == "f" else img
    return int(np.sum(np.all(np.abs(img - np.array(rgb)) <= tol, axis=-1)))


def _assert_png(path: Path, min_size: tuple[int, int] = (300, 500)) -> None:
    assert path.is_file(), f"{path.name} was not written"
    assert path.read_bytes()[:8] == PNG_MAGIC, f"{path.name} is not a PNG"
    import matplotlib.image as mpimg
    img = mpimg.imread(path)
    assert img.shape[0] >= min_size[0] and img.shape[1] >= min_size[1], img.shape
    assert float(np.std(img[..., :3])) > 0.05, f"{path.name} is (nearly) blank"


def _ok(runs, script) -> tuple[subprocess.CompletedProcess, Path]:
    proc, out = runs[script]
    assert proc.returncode in (0, 1), f"{script} crashed:\n{proc.stderr[-3000:]}"
    return proc, out


# --- paper_figures.py ----------------------------------------------------------------------

def test_paper_figures_writes_both_figures_with_the_papers_colours(runs):
    proc, out = _ok(runs, "paper_figures.py")
    assert proc.returncode == 0, proc.stderr[-3000:]
    fig2, fig3 = out / "figure2_lyapunov.png", out / "figure3_first_mass.png"
    for fig in (fig2, fig3):
        _assert_png(fig)
        # both observers drawn: blue (with position jumps) and red (without), as in the paper
        assert _pixels_near(fig, TAB_BLUE) > 300, fig.name
        assert _pixels_near(fig, TAB_RED) > 300, fig.name
    assert _pixels_near(fig3, BLACK, tol=30) > 1000, "figure 3 lacks the master (black)"


def test_paper_figures_observer_with_jumps_synchronises_first(runs):
    """The claim of the paper's Fig. 2: V of the observer with position jumps falls faster."""
    proc, _ = _ok(runs, "paper_figures.py")
    table = _table(proc.stdout, "observer").set_index("observer")
    cols = [c for c in table.columns if c.startswith("t_sync_")]
    assert cols and {"jump", "nojump"} <= set(table.index)
    t = table[cols].astype(float)
    first = cols[0]                                          # the loosest threshold, ρ = 1e-3
    assert math.isfinite(t.loc["jump", first]) and math.isfinite(t.loc["nojump", first])
    assert 0.0 < t.loc["jump", first] < t.loc["nojump", first]


# --- my_system.py --------------------------------------------------------------------------

def test_my_system_prints_every_proof_check_and_exits_by_the_verdicts(runs):
    from proofs_checks import CHECKS
    proc, out = _ok(runs, "my_system.py")
    table = _table(proc.stdout, "check")
    table = table[table["status"].isin(["PASS", "FAIL", "n/a"])]     # not the summary line after it
    assert list(table["check"]) == list(CHECKS), "the table must list every registered check, in order"
    failed = (table["status"] == "FAIL").any()
    assert proc.returncode == (1 if failed else 0), "exit status must follow the verdicts"
    saved = pd.read_csv(out / "three_masses_checks.csv")
    assert list(saved["check"]) == list(CHECKS)
    assert list(saved["status"].fillna("n/a")) == list(table["status"])


def test_my_system_exits_1_and_explains_a_failed_check(runs):
    from proofs_checks import CHECKS
    proc, out = runs["failing"]
    table = _table(proc.stdout, "check")
    table = table[table["status"].isin(["PASS", "FAIL", "n/a"])]
    assert list(table["check"]) == list(CHECKS)
    failed = list(table.loc[table["status"] == "FAIL", "check"])
    assert failed, ("per-contact restitution on two coupled contacts is expected to violate A3 "
                    f"(impact_monotone); no check failed:\n{proc.stdout}")
    assert proc.returncode == 1, proc.stderr[-3000:]
    for name in failed:                          # each failure printed with its witness
        assert any(line.startswith(f"FAIL {name}: ") and len(line) > 40 for line in proc.stdout.splitlines())
    assert proc.stdout.rstrip().splitlines()[-1].endswith(f"failed: {failed}")
    assert (out / "rocking_chain.png").is_file()


def test_my_system_bad_input_exits_2_naming_the_field(runs):
    proc, out = runs["bad_input"]
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: system.C"), proc.stderr   # the missing key
    assert "Traceback" not in proc.stderr and proc.stdout == ""


def test_my_system_simulates_both_contacts_and_plots(runs):
    proc, out = _ok(runs, "my_system.py")
    header = proc.stdout.splitlines()[0]
    assert header.startswith("three_masses: n = 3 DOF, m = 2 contacts, newton law"), header
    line = next(x for x in proc.stdout.splitlines() if x.startswith("master closings per contact:"))
    counts = ast.literal_eval(line.split(":", 1)[1].strip())
    assert len(counts) == 2 and min(counts.values()) > 0, f"both contacts of the example must close: {line}"
    sync = _table(proc.stdout, "observer").set_index("observer").loc[["jump", "nojump"]]
    assert np.all(sync["rate"].astype(float) > 0), "V must decay for both observers"
    png = out / "three_masses.png"
    _assert_png(png)
    assert _pixels_near(png, TAB_BLUE) > 300 and _pixels_near(png, TAB_RED) > 300


# --- measured_log.py -----------------------------------------------------------------------

def _measured_table(runs) -> pd.DataFrame:
    proc, _ = _ok(runs, "measured_log.py")
    assert proc.returncode == 0, proc.stderr[-3000:]
    df = _table(proc.stdout, "sigma_s")
    settle = [c for c in df.columns if c.startswith("settle_")]
    return _numeric(df, ["sigma_s", "floor", *settle])


def test_measured_log_settling_times_finite_for_both_observers(runs):
    df = _measured_table(runs)
    settle = [c for c in df.columns if c.startswith("settle_")]
    assert len(settle) >= 1 and set(df["observer"]) == {"jump", "nojump"}
    small = df[df["sigma_s"] <= 1e-4]            # the exact log and a 0.1 ms timing error
    assert len(small) == 4
    assert np.all(np.isfinite(small[settle].to_numpy())) and np.all(small[settle].to_numpy() > 0)
    exact = df[df["sigma_s"] == 0].set_index("observer")
    assert exact.loc["jump", settle[0]] < exact.loc["nojump", settle[0]], \
        "with the exact log the observer with position jumps must settle first"


def test_measured_log_timing_errors_raise_the_floor(runs):
    df = _measured_table(runs)
    assert np.all(df["floor"] > 0) and np.all(np.isfinite(df["floor"]))
    worst = df["sigma_s"].max()
    for name, grp in df.groupby("observer"):
        by_sigma = grp.set_index("sigma_s")["floor"]
        assert by_sigma[worst] > 10 * by_sigma[0.0], f"{name}: jitter must leave a larger error"


def test_measured_log_exact_log_is_the_masters_closings(runs):
    """The σ = 0 log has one interval per closing of the master (recounted here), and every
    written log is valid: sorted, non-overlapping per contact."""
    import observer
    _, out = _ok(runs, "measured_log.py")
    master = observer.simulate("double_mass", h=1e-3, t_end=10.0)       # the script's --quick
    closings = int(np.sum(np.diff(master.active[:, 0].astype(int)) == 1))
    exact = pd.read_csv(out / "log_sigma_0.csv")
    assert list(exact.columns) == ["contact", "t_close", "t_open"]
    assert len(exact) == closings > 0
    for path in sorted(out.glob("log_sigma_*.csv")):
        log = pd.read_csv(path)
        for _, grp in log.groupby("contact"):
            tc, to = grp["t_close"].to_numpy(), grp["t_open"].to_numpy()
            assert np.all(to >= tc) and np.all(np.diff(tc) >= 0) and np.all(tc[1:] >= to[:-1]), path.name
    _assert_png(out / "measured_log.png")


# --- compare_designs.py --------------------------------------------------------------------

def _interval(text: str) -> tuple[float, float, float]:
    """(estimate, low, high) of ``"2.09 [1.32, 3.25]"`` at the start of ``text``."""
    import re
    m = re.match(r"\s*([-+\d.eE]+)\s*\[([-+\d.eE]+),\s*([-+\d.eE]+)\]", text)
    assert m, f"no 'estimate [low, high]' in {text!r}"
    return tuple(float(x) for x in m.groups())


def test_compare_designs_interval_says_jumps_decay_faster(runs):
    """The paper's claim (Fig. 2) with its interval: the decay-rate ratio jump/nojump is above
    1 over the resampled masters, and the printed interval contains its estimate."""
    proc, _ = _ok(runs, "compare_designs.py")
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("double_mass: 6 members x 3 masters per design"), lines[0]   # --quick
    ratio = next(x for x in lines if x.startswith("decay-rate ratio jump/nojump:"))
    est, low, high = _interval(ratio.split(":", 1)[1])
    assert low <= est <= high and math.isfinite(high)
    assert low > 1.0, ratio


def test_compare_designs_settling_shares_and_figure(runs):
    proc, out = _ok(runs, "compare_designs.py")
    shares = {}
    for line in proc.stdout.splitlines():
        cells = line.split()
        if cells[:2] in (["jump", "settled"], ["nojump", "settled"]):
            share, low, high = _interval(line.split("settled", 1)[1].replace("%", ""))
            assert 0 <= low <= share <= high <= 100, line
            shares[cells[0]] = share
    assert set(shares) == {"jump", "nojump"}, proc.stdout
    assert shares["jump"] > shares["nojump"], "with position jumps more members settle in the window"
    png = out / "compare_designs.png"
    _assert_png(png)
    assert _pixels_near(png, TAB_BLUE) > 300 and _pixels_near(png, TAB_RED) > 300
