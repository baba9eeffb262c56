"""The command line ``python -m observer {scenarios, show, run, plot}``.

A module fixture runs the commands once in one temporary directory; the tests then inspect
exit status, stdout, stderr and the files written. ``scenarios`` and the error cases of
:data:`SUBPROCESS_ERRORS` run as real subprocesses (the interpreter's exit status and its
whole stderr: one line, no traceback), a few at a time; the other commands run meanwhile in
this process through :func:`observer.cli.main` (:func:`main_in_process`): a subprocess
would add its start-up (about 0.4 s of CPU) and, for a run, the load of the compiled kernel
(about 1.5 s in all) to the same code. ``test_result_metadata_records_the_command_as_typed`` runs a
result-writing command as a subprocess.
"""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from unittest import mock
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from observer import SCENARIOS, simulate
from observer.result import read_frame

REPO = Path(__file__).resolve().parents[2]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.pop("PYTHONIOENCODING", None)
    return env


def run_cli(args, cwd):
    return subprocess.run([sys.executable, "-m", "observer", *map(str, args)], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=300)


def main_in_process(args, cwd) -> subprocess.CompletedProcess:
    """``python -m observer ARGS`` in ``cwd`` through :func:`observer.cli.main` in this process:
    (status, stdout, stderr, its warnings under Python's default filters appended as an
    interpreter prints them); ``sys.argv`` is the module run's (what the result records)."""
    import warnings

    from observer.cli import main
    args = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.chdir(cwd), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
            mock.patch.object(sys, "argv", [str(REPO / "observer" / "__main__.py"), *args]), \
            warnings.catch_warnings(record=True) as said:
        warnings.resetwarnings()
        warnings.simplefilter("default")
        try:
            rc = main(args)
        except SystemExit as exc:
            rc = exc.code
    text = err.getvalue() + "".join(warnings.formatwarning(w.message, w.category, w.filename, w.lineno)
                                    for w in said)
    return subprocess.CompletedProcess(args, rc, out.getvalue(), text)


# Errors, each with its whole stdout checked: name -> (arguments, text that the error line must
# contain); those of SUBPROCESS_ERRORS run as real subprocesses, the others in-process
ERROR_CASES = {
    "unknown-scenario": (["run", "no_such_scenario", "--out", "e1.csv"], "no_such_scenario"),
    "unknown-set-key": (["run", "rocking_chain", "--set", "param.foo=1", "--out", "e2.csv"],
                        "param.foo"),
    "negative-h": (["run", "bouncing_ball", "--h", "-1", "--out", "e3.csv"], "simulation.h"),
    "missing-toml": (["run", "missing.toml", "--out", "e4.csv"], "missing.toml"),
    "invalid-toml": (["run", "invalid.toml", "--out", "e5.csv"], "invalid TOML"),
    "xlsx": (["run", "bouncing_ball", "--t-end", "0.01", "--out", "e6.xlsx"], ".xlsx"),
}

SUBPROCESS_ERRORS = frozenset({"unknown-scenario", "invalid-toml"})
"""The error cases run as ``python -m observer``: the interpreter's exit status and its whole
stderr (a warning or a traceback printed beside the error line fails them)."""

# More errors, run in-process through observer.cli.main (same code, no interpreter start-up)
INPROCESS_ERROR_CASES = {
    "show-unknown-scenario": (["show", "no_such_scenario"], "no_such_scenario"),
    "unknown-toml-key": (["run", "bouncing_ball", "--set", "simulation.hh=1", "--out", "i1.csv"],
                         "simulation.hh"),
    "set-without-value": (["run", "bouncing_ball", "--set", "param.h0", "--out", "i2.csv"], "--set"),
    "zero-h": (["run", "bouncing_ball", "--h", "0", "--out", "i3.csv"], "simulation.h"),
    "negative-t-end": (["run", "bouncing_ball", "--t-end", "-2", "--out", "i4.csv"],
                       "simulation.t_end"),
    "penetration": (["run", "bouncing_ball", "--set", "initial.q=[-0.5]", "--out", "i5.csv"],
                    "initial.q"),
    "unknown-observer": (["run", "double_mass", "--t-end", "0.01", "--observers", "kalman",
                          "--out", "i6.csv"], "kalman"),
    "unknown-solver": (["run", "bouncing_ball", "--solver", "gauss", "--out", "i7.csv"], "gauss"),
    "param-on-toml": (["run", "bb.toml", "--set", "param.h0=2", "--out", "i8.csv"], "param.h0"),
    "bad-param-N": (["run", "rocking_chain", "--set", "param.N=0", "--out", "i9.csv"], "param.N"),
    "plot-missing-result": (["plot", "missing.csv", "--out", "i10.png"], "missing.csv"),
    "plot-bad-dof": (["plot", "bb.csv", "--dof", "3", "--out", "i11.png"], "--dof"),
}

# Known CLI contract violations (an uncaught exception / several lines instead of one
# "error:" line), run in-process
MORE_ERROR_CASES = {
    "plot-bad-image-extension": (["plot", "bb.csv", "--out", "x1.xyz"], "xyz"),
    "plot-result-not-csv": (["plot", "figs/obs.png", "--out", "x2.png"], "obs.png"),
    "run-out-under-a-file": (["run", "bouncing_ball", "--t-end", "0.01", "--out",
                              "afile.txt/x3.csv"], "afile.txt"),
    "set-non-numeric-restitution": (["run", "bouncing_ball", "--t-end", "0.01", "--set",
                                     "impact.restitution=high", "--out", "x4.csv"],
                                    "impact.restitution"),
    "argparse-bad-float": (["run", "bouncing_ball", "--h", "abc", "--out", "x5.csv"], "--h"),
}


@pytest.fixture(scope="module")
def cli(tmp_path_factory):
    """Run every command once (module docstring); returns (working directory, {key: CompletedProcess})."""
    d = tmp_path_factory.mktemp("cli")
    (d / "invalid.toml").write_text("[simulation]\nh = [1e-3,\n")
    (d / "afile.txt").write_text("not a directory\n")
    subprocesses = {"scenarios": ["scenarios"], **{k: ERROR_CASES[k][0] for k in SUBPROCESS_ERRORS}}
    in_process = {                      # in order: the plot reads obs.csv
        **{k: v[0] for k, v in ERROR_CASES.items() if k not in SUBPROCESS_ERRORS},
        "run-csv": ["run", "bouncing_ball", "--h", "1e-3", "--t-end", "0.05", "--out", "bb.csv"],
        "run-parquet": ["run", "bouncing_ball", "--h", "1e-3", "--t-end", "0.05",
                        "--out", "out/bb.parquet"],
        "run-set-N": ["run", "rocking_chain", "--set", "param.N=2", "--set", "simulation.h=1e-3",
                      "--t-end", "0.5", "--out", "chain2.csv"],
        "run-observers": ["run", "double_mass", "--h", "1e-3", "--t-end", "1.0",
                          "--observers", "jump,nojump", "--out", "obs.csv"],
        "plot": ["plot", "obs.csv", "--out", "figs/obs.png"],
    }
    with ThreadPoolExecutor(max_workers=3) as pool:
        futures = {key: pool.submit(run_cli, args, d) for key, args in subprocesses.items()}
        results = {key: main_in_process(args, d) for key, args in in_process.items()}
        results.update({key: f.result() for key, f in futures.items()})
    return d, results


def run_main(args, cwd, capsys, monkeypatch):
    """observer.cli.main in-process: (status, stdout, stderr); SystemExit gives its code."""
    from observer.cli import main
    monkeypatch.chdir(cwd)
    capsys.readouterr()
    try:
        rc = main([str(a) for a in args])
    except SystemExit as exc:
        rc = exc.code
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(args, rc, out, err)


def assert_ok(proc):
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr


def assert_one_error_line(proc, hint):
    assert proc.returncode != 0
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: "), lines[0]
    assert hint in lines[0], lines[0]


# ---------------------------------------------------------------------------------------
def test_scenarios_lists_builtins_with_descriptions(cli):
    _, res = cli
    proc = res["scenarios"]
    assert_ok(proc)
    lines = proc.stdout.splitlines()
    assert len(lines) == len(SCENARIOS) == 6
    for line, (name, module) in zip(lines, SCENARIOS.items()):
        got_name, desc = line.split(None, 1)
        assert got_name == name
        assert desc.strip() == module.DESCRIPTION


def test_run_writes_csv_with_one_row_per_grid_point(cli):
    d, res = cli
    proc = res["run-csv"]
    assert_ok(proc)
    assert proc.stdout.rstrip().endswith("wrote bb.csv")
    path = d / "bb.csv"
    assert path.read_text().startswith("t,q0,u0,g0,P0,active0\n")     # a plain header row
    plain = pd.read_csv(path)                                             # any CSV reader
    assert list(plain.columns) == ["t", "q0", "u0", "g0", "P0", "active0"]
    df = read_frame(path)
    assert len(df) == 50 + 1
    assert list(df.columns) == ["t", "q0", "u0", "g0", "P0", "active0"]
    np.testing.assert_allclose(df["t"].to_numpy(), np.arange(51) * 1e-3, rtol=0, atol=1e-15)
    assert df["t"].iloc[-1] == pytest.approx(0.05, abs=1e-15)
    # free fall from 1 m, exact for the θ = ½ scheme: q(0.05) = 1 - 9.81·0.05²/2 = 0.98773750
    assert df["q0"].iloc[-1] == pytest.approx(0.9877375, abs=1e-14)
    assert df["u0"].iloc[-1] == pytest.approx(-0.4905, abs=1e-14)
    ref = simulate("bouncing_ball", h=1e-3, t_end=0.05)
    assert np.array_equal(df["q0"].to_numpy(), ref.q[:, 0])
    assert np.array_equal(df["u0"].to_numpy(), ref.u[:, 0])
    a = df.attrs
    assert a["scenario"] == "bouncing_ball" and a["h"] == 1e-3 and a["steps"] == 50
    assert a["t_end"] == 0.05 and a["theta"] == 0.5 and a["solver"] == "pivoting"
    assert a["versions"]["numpy"] == np.__version__
    assert "run bouncing_ball" in a["argv"] or "observer" in a["argv"]


def test_run_writes_parquet(cli):
    d, res = cli
    assert_ok(res["run-parquet"])
    path = d / "out" / "bb.parquet"
    assert path.read_bytes()[:4] == b"PAR1"
    df = pd.read_parquet(path)
    assert len(df) == 51
    csv = read_frame(d / "bb.csv")
    assert list(df.columns) == list(csv.columns)
    for col in ("t", "q0", "u0", "g0", "P0"):
        assert np.array_equal(df[col].to_numpy(), csv[col].to_numpy()), col
    back = read_frame(path)
    assert back.attrs["h"] == 1e-3 and back.attrs["scenario"] == "bouncing_ball"


def test_run_set_param_N_on_rocking_chain(cli):
    d, res = cli
    assert_ok(res["run-set-N"])
    df = read_frame(d / "chain2.csv")
    assert df.attrs["n"] == 4 and df.attrs["m"] == 4 and df.attrs["h"] == 1e-3
    assert len(df) == 501
    for prefix in ("q", "u", "g", "P", "active"):
        assert [c for c in df.columns if c.rstrip("0123456789") == prefix] == \
               [f"{prefix}{j}" for j in range(4)]
    # static start: gaps s_L = 2 mm, s_R = 3 mm; the moving ground then closes contacts
    np.testing.assert_allclose(df.loc[0, ["g0", "g1", "g2", "g3"]].to_numpy(dtype=float),
                               [0.002, 0.003, 0.002, 0.003], rtol=0, atol=1e-12)
    assert df[[f"active{j}" for j in range(4)]].to_numpy().any()
    assert np.all(np.isfinite(df.to_numpy(dtype=float)))


@pytest.mark.parametrize("case", list(ERROR_CASES))
def test_errors_give_one_line_and_nonzero_status(cli, case):
    d, res = cli
    args, hint = ERROR_CASES[case]
    proc = res[case]
    assert_one_error_line(proc, hint)
    assert proc.returncode == 2
    assert proc.stdout == ""
    out = args[args.index("--out") + 1]
    assert not (d / out).exists()                 # nothing half-written


@pytest.mark.parametrize("case", list(INPROCESS_ERROR_CASES))
def test_more_errors_in_process(cli, case, capsys, monkeypatch):
    d, res = cli
    assert_ok(res["run-csv"])                     # bb.csv is an input of some cases
    (d / "bb.toml").write_text("[scenario]\n")      # only its name matters for param-on-toml
    args, hint = INPROCESS_ERROR_CASES[case]
    proc = run_main(args, d, capsys, monkeypatch)
    assert_one_error_line(proc, hint)
    assert proc.returncode == 2
    if "--out" in args:
        assert not (d / args[args.index("--out") + 1]).exists()


@pytest.mark.parametrize("case", list(MORE_ERROR_CASES))
def test_errors_without_traceback_more_cases(cli, case, capsys, monkeypatch):
    d, res = cli
    assert_ok(res["plot"])                        # inputs: bb.csv and figs/obs.png
    args, hint = MORE_ERROR_CASES[case]
    proc = run_main(args, d, capsys, monkeypatch)
    assert_one_error_line(proc, hint)


def test_run_with_observers_and_plot(cli):
    d, res = cli
    proc = res["run-observers"]
    assert_ok(proc)
    assert proc.stdout.rstrip().endswith("wrote obs.csv")
    df = read_frame(d / "obs.csv")
    for col in ("chi0", "jump_q0", "jump_u1", "V_jump", "nojump_q1", "V_nojump"):
        assert col in df.columns
    assert df["V_jump"].iloc[0] == pytest.approx(0.06, rel=1e-12)
    assert df["V_nojump"].iloc[0] == pytest.approx(0.06, rel=1e-12)
    assert df["V_jump"].iloc[-1] < 0.06                  # the observer converges
    assert len(df) == 1001
    assert df.attrs["observers"] == ["jump", "nojump"]
    plot = res["plot"]
    assert_ok(plot)
    assert "wrote" in plot.stdout
    png = d / "figs" / "obs.png"
    data = png.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 10_000
    assert data[12:16] == b"IHDR"
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    assert width >= 500 and height >= 500                # three stacked panels


def test_help_lists_commands(capsys, monkeypatch, tmp_path):
    proc = run_main(["--help"], tmp_path, capsys, monkeypatch)
    assert proc.returncode == 0
    for cmd in ("scenarios", "show", "run", "plot"):
        assert cmd in proc.stdout


def test_log_command_feeds_source_log(tmp_path, capsys):
    """`log` writes a run's closings; an observer driven by that log on the same grid sees
    exactly the master's closed sets (χ from the log equals the master's active set)."""
    from observer.cli import main
    run_csv, log_csv, obs_csv = tmp_path / "run.csv", tmp_path / "log.csv", tmp_path / "obs.csv"
    assert main(["run", "double_mass", "--t-end", "1.5", "--h", "1e-3", "--out", str(run_csv)]) == 0
    assert main(["log", str(run_csv), "--out", str(log_csv)]) == 0
    log = pd.read_csv(log_csv)
    assert list(log.columns) == ["contact", "t_close", "t_open"] and (log.t_open == log.t_close).sum() > 5
    assert main(["run", "double_mass", "--t-end", "1.5", "--h", "1e-3", "--observers", "jump,nojump",
                 "--source", "log", "--log", str(log_csv), "--out", str(obs_csv)]) == 0
    df = pd.read_csv(obs_csv, comment="#")
    chi = df[[c for c in df.columns if c.startswith("chi")]].to_numpy()[1:]
    active = df[[c for c in df.columns if c.startswith("active")]].to_numpy()[1:]
    assert np.array_equal(chi, active)
    assert main(["log", str(log_csv), "--out", str(tmp_path / "x.csv")]) == 2
    assert "error:" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------
# issue 10/11: files any tool reads, the scenario's observers, the event integrator
# ---------------------------------------------------------------------------------------
DOCUMENTED = ["t", "q0", "q1", "u0", "u1", "g0", "P0", "active0", "chi0",
              "jump_q0", "jump_q1", "jump_u0", "jump_u1", "V_jump",
              "nojump_q0", "nojump_q1", "nojump_u0", "nojump_u1", "V_nojump"]


@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_run_double_mass_honours_the_scenarios_observers_in_plain_files(tmp_path, ext):
    from observer.cli import main
    out = tmp_path / f"run.{ext}"
    assert main(["run", "double_mass", "--t-end", "0.5", "--h", "1e-3", "--out", str(out)]) == 0
    df = pd.read_csv(out) if ext == "csv" else pd.read_parquet(out)      # plain readers
    assert list(df.columns) == DOCUMENTED
    ref = simulate("double_mass", t_end=0.5, h=1e-3, observers=("jump", "nojump"))
    assert np.array_equal(df["V_jump"].to_numpy(), ref.slaves["jump"].V)
    assert np.array_equal(df["V_nojump"].to_numpy(), ref.slaves["nojump"].V)
    back, meta = __import__("observer").read_result(out)
    assert meta["observers"] == ["jump", "nojump"] and meta["scenario"] == "double_mass"


def test_observers_none_runs_the_master_alone(tmp_path):
    from observer.cli import main
    out = tmp_path / "m.csv"
    assert main(["run", "double_mass", "--t-end", "0.2", "--observers", "none", "--out", str(out)]) == 0
    assert list(pd.read_csv(out).columns) == ["t", "q0", "q1", "u0", "u1", "g0", "P0", "active0"]


def test_event_integrator_and_events_file(tmp_path, capsys):
    from observer.cli import main
    out, ev = tmp_path / "ball.csv", tmp_path / "ev.parquet"
    assert main(["run", "bouncing_ball", "--integrator", "event", "--events", str(ev),
                 "--out", str(out)]) == 0
    events = pd.read_parquet(ev)
    assert list(events.columns) == ["time", "contact", "kind", "gamma_minus", "gamma_plus", "impulse"]
    assert (events.kind == "accumulation").sum() == 1 and (events.kind == "impact").sum() >= 30
    assert "exact event-driven run" in capsys.readouterr().out
    capsys.readouterr()
    assert main(["run", "bouncing_ball", "--integrator", "event", "--engine", "python",
                 "--out", str(tmp_path / "x.csv")]) == 2    # a time-stepping option: refused
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--engine" in err and not (tmp_path / "x.csv").exists()


def test_events_without_an_event_table_is_one_line(tmp_path, capsys):
    from observer.cli import main
    assert main(["run", "bouncing_ball", "--t-end", "0.1", "--record-every", "2", "--events",
                 str(tmp_path / "e.csv"), "--out", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: --events:")
    assert not (tmp_path / "e.csv").exists()


def test_run_reports_the_loop_time_apart_from_writing_the_output(tmp_path, capsys, monkeypatch):
    """Issue 36, item 13: a slow output (here a writer that takes 0.5 s more to finish) is
    said as writing time; the loop's time and speed do not include it."""
    import re
    import time

    from observer import cli, stream

    finish = stream.ChunkWriter.finish

    def slow_finish(self, res):
        time.sleep(0.5)
        return finish(self, res)

    monkeypatch.setattr(stream.ChunkWriter, "finish", slow_finish)
    assert cli.main(["run", "double_mass", "--observers", "none", "--t-end", "0.05",
                     "--out", str(tmp_path / "r.csv")]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    m = re.search(r"500 steps of h = 0.0001 in ([0-9.]+) s \(([0-9.]+|inf) steps/s; writing the output "
                  r"([0-9.]+) s;", line)
    assert m, line
    loop_s, write_s = float(m.group(1)), float(m.group(3))
    assert write_s >= 0.5 and loop_s < 0.5, line


def test_result_metadata_records_the_command_as_typed(tmp_path):
    """Issue 36, item 14: ``argv`` in a result is the command a user types (``python -m
    observer run ...``), never the interpreter's or the package's absolute path."""
    from observer.result import read_frame, typed_command

    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    proc = subprocess.run([sys.executable, "-m", "observer", "run", "double_mass", "--observers", "none",
                           "--engine", "python", "--t-end", "0.001", "--out", "r.parquet"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    argv = read_frame(tmp_path / "r.parquet").attrs["argv"]
    assert argv == ("python -m observer run double_mass --observers none --engine python "
                    "--t-end 0.001 --out r.parquet")
    assert typed_command(["/opt/venv/bin/observer", "run", "a b.toml"]) == "observer run 'a b.toml'"
    assert typed_command(["examples/my_system.py", "--x"]) == "python examples/my_system.py --x"


def test_the_run_summary_table_prints_no_nan():
    """A run stopped before its first step has no decay rate: the table says n/a, not NaN."""
    import pandas as pd

    from observer.cli import UNDEFINED, summary_table

    text = summary_table(pd.DataFrame({"observer": ["jump"], "rate": [float("nan")], "V_end": [0.06]}))
    assert "nan" not in text.lower() and UNDEFINED in text and "0.06" in text
