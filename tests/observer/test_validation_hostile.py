"""The bad-input matrix (issues 12 and 20): every malformed or hostile input is refused cleanly.

Each row of :data:`CASES` is one malformed input: a scenario document edit, a builder
parameter (``param.*``), a call of the Python API, a command-line option, an output path or
a closing log (χ) CSV, a scenario file (oversized, endless, too deeply nested, a path with
a line break) or a ``bench`` command. For every row

* the Python route raises :class:`observer.errors.InputError` whose ``field`` is the
  offending field and whose message says what is wrong (a ``hint``);
* the command-line route (where there is one) returns exit status 2 with exactly one line
  on stderr, ``error: FIELD: ...``, no traceback, and writes no result file (so no result,
  and no NaN in one, ever reaches the user); ``bench`` rows write no case file.

The command line runs in-process through :func:`observer.cli.main` (fast); a few rows run
in a real subprocess to show that the interpreter prints no traceback either.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
from cli_exit import ExitCode

import observer
from bench.__main__ import main as bench_main
from observer import cli
from observer.errors import InputError
from observer.model import Harmonic, LinearSystem
from observer.scenario import load_scenario
from observer.scenarios import builtin_document
from observer.switching import read_log
from observer.tomlio import dumps

ROOT = Path(__file__).resolve().parents[2]
OUT = "{tmp}/out.csv"
"""Result path of the command-line runs; it must not exist after a refused run."""

NEARLY_DEPENDENT_W = {"system.W": "[[1.0, 1.0], [0.0, 1e-9]]", "system.gap.offset": "[0.25, 0.25]"}
"""σ_min/σ_max = 5e-10 (the issue's case; accepted before, since the check was 1e-12)."""

K_METRIC_DEPENDENT_W = {"system.W": "[[1.0, 1.0], [0.0, 1e-6]]", "system.gap.offset": "[0.25, 0.26]"}
"""σ_min/σ_max = 5e-7 (fine for the contact problems) but cond(WᵀK⁻¹W) ≈ 1e13 (the jump
observer's projection metric)."""

SINGULAR_K = {"system.K": "[[100.0, -100.0], [-100.0, 100.0]]"}
"""PSD but singular: fine for the master and the no-jump observer, not for K-metric jumps."""


@dataclass(frozen=True)
class Bad:
    """One malformed input: its Python route, its command line, the field and a hint."""

    id: str
    field: str
    hint: str
    call: Callable[[Path], Any] | None = None
    argv: list[str] | None = None
    cli_field: str | None = None     # the field the CLI names when it differs (argparse errors)
    files: dict[str, str | bytes] = field(default_factory=dict)   # written to tmp first
    kind: str = "api"                # doc, param, api, cli, log, out, file, bench: its source
    prog: str = "observer"           # the command line: observer or bench


def _set_args(overrides: dict[str, str]) -> list[str]:
    return [a for k, v in overrides.items() for a in ("--set", f"{k}={v}")]


def doc_case(id: str, overrides: dict[str, str], fld: str, hint: str, *,
             observers: str | None = None) -> Bad:
    """A TOML-document edit of ``double_mass`` (values are TOML text, as on the CLI)."""
    obs = ["--observers", observers] if observers else []
    if observers:
        def call(tmp):
            return observer.simulate(load_scenario("double_mass", overrides),
                                     observers=observers.split(","), t_end=0.01)
    else:
        def call(tmp):
            return load_scenario("double_mass", overrides)
    argv = ["run", "double_mass", *_set_args(overrides), *obs, "--t-end", "0.01", "--out", OUT]
    return Bad(id, fld, hint, call, argv, kind="doc")


def param_case(id: str, scenario: str, overrides: dict[str, str], fld: str, hint: str, *,
               observers: str | None = None) -> Bad:
    """A builder parameter of a built-in scenario."""
    def call(tmp):
        sc = load_scenario(scenario, overrides)
        if observers:
            return observer.simulate(sc, observers=observers.split(","), t_end=0.01)
        return sc
    obs = ["--observers", observers] if observers else []
    return Bad(id, fld, hint, call, ["run", scenario, *_set_args(overrides), *obs, "--out", OUT],
               kind="param")


def toml_case(id: str, edit: Callable[[dict], None], fld: str, hint: str) -> Bad:
    """A scenario file written from ``double_mass``'s document after ``edit``."""
    doc = builtin_document("double_mass")
    edit(doc)
    return Bad(id, fld, hint, lambda tmp: load_scenario(str(tmp / "case.toml")),
               ["run", "{tmp}/case.toml", "--out", OUT], files={"case.toml": dumps(doc)}, kind="doc")


def run_case(id: str, kwargs: dict, fld: str, hint: str, argv_opts: list[str] | None = None,
             cli_field: str | None = None) -> Bad:
    """A keyword of :func:`observer.simulate` and its command-line option."""
    argv = None if argv_opts is None else ["run", "double_mass", "--t-end", "0.01", *argv_opts,
                                           "--out", OUT]
    return Bad(id, fld, hint, lambda tmp: observer.simulate("double_mass", **{"t_end": 0.01, **kwargs}),
               argv, cli_field, kind="cli")


LOG_OK = "contact,t_close,t_open\n0,0.001,0.002\n"


def log_case(id: str, content: str | bytes, hint: str) -> Bad:
    """A closing log CSV for ``--source log`` (double_mass has one contact)."""
    return Bad(id, "observer.log", hint, lambda tmp: read_log(tmp / "log.csv", 1),
               ["run", "double_mass", "--observers", "jump", "--source", "log", "--log",
                "{tmp}/log.csv", "--t-end", "0.01", "--out", OUT], files={"log.csv": content}, kind="log")


def out_case(id: str, argv: list[str], hint: str, files: dict | None = None) -> Bad:
    """An unwritable or unsupported output path (checked before any work is done)."""
    return Bad(id, "--out", hint, None, argv, files=files or {}, kind="out")


def _harmonic(dim):
    return Harmonic.build("f", dim)


def _system(**kw):
    args = dict(M=np.eye(2), C=np.zeros((2, 2)), K=np.eye(2), W=[[1.0], [0.0]], forcing=_harmonic(2),
                gap=_harmonic(1))
    args.update(kw)
    return LinearSystem(**args)


def _del(dotted):
    def edit(doc):
        *path, last = dotted.split(".")
        node = doc
        for p in path:
            node = node[p]
        del node[last]
    return edit


def _put(dotted, value):
    def edit(doc):
        *path, last = dotted.split(".")
        node = doc
        for p in path:
            node = node.setdefault(p, {})
        node[last] = value
    return edit


CASES: list[Bad] = [
    # --- scenario document: matrices -----------------------------------------------------
    doc_case("M-wrong-shape", {"system.M": "[[1.0, 0.0]]"}, "system.M", "square"),
    doc_case("M-non-symmetric", {"system.M": "[[1.0, 0.5], [0.0, 1.0]]"}, "system.M", "not symmetric"),
    doc_case("M-indefinite", {"system.M": "[[1.0, 0.0], [0.0, -1.0]]"}, "system.M", "positive definite"),
    doc_case("M-near-singular", {"system.M": "[[1.0, 0.0], [0.0, 1e-17]]"}, "system.M",
             "positive definite"),
    doc_case("M-nan", {"system.M": "[[nan, 0.0], [0.0, 1.0]]"}, "system.M", "NaN"),
    doc_case("M-text", {"system.M": '"heavy"'}, "system.M", "not a numeric array"),
    doc_case("C-non-symmetric", {"system.C": "[[1.0, -1.0], [0.0, 2.0]]"}, "system.C", "not symmetric"),
    doc_case("C-indefinite", {"system.C": "[[1.0, 0.0], [0.0, -1.0]]"}, "system.C", "semi-definite"),
    doc_case("C-inf", {"system.C": "[[inf, 0.0], [0.0, 1.0]]"}, "system.C", "NaN or infinity"),
    doc_case("K-indefinite", {"system.K": "[[-1.0, 0.0], [0.0, 1.0]]"}, "system.K", "semi-definite"),
    doc_case("K-non-symmetric", {"system.K": "[[100.0, -50.0], [-100.0, 200.0]]"}, "system.K",
             "not symmetric"),
    doc_case("K-wrong-shape", {"system.K": "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]"},
             "system.K", "disagree on the number of coordinates"),
    doc_case("K-singular-jump", SINGULAR_K, "system.K", "positive definite", observers="jump"),
    doc_case("K-singular-master-projection", {**SINGULAR_K, "simulation.master_projection": "true"},
             "system.K", "positive definite"),
    doc_case("W-wrong-rows", {"system.W": "[[1.0], [0.0], [0.0]]"}, "system.W", "system.W has 3 rows"),
    doc_case("W-dependent", {"system.W": "[[1.0, 2.0], [0.0, 0.0]]", "system.gap.offset": "[0.25, 0.25]"},
             "system.W", "not linearly independent"),
    doc_case("W-nearly-dependent", NEARLY_DEPENDENT_W, "system.W", "nearly dependent"),
    doc_case("W-nearly-dependent-jump", NEARLY_DEPENDENT_W, "system.W", "nearly dependent",
             observers="jump"),
    doc_case("W-K-metric-dependent-jump", K_METRIC_DEPENDENT_W, "system.W", "cond(WᵀK⁻¹W)",
             observers="jump,nojump"),
    doc_case("W-no-columns", {"system.W": "[[], []]"}, "system.W", "at least one contact"),
    doc_case("W-nan", {"system.W": "[[nan], [0.0]]"}, "system.W", "NaN"),
    # --- scenario document: signals, law, state, settings --------------------------------
    doc_case("forcing-constant-length", {"system.forcing.constant": "[1.0, 2.0, 3.0]"},
             "system.forcing.constant", "wrong shape"),
    doc_case("forcing-omega-negative", {"system.forcing.omega": "-6.0"}, "system.forcing.omega", ">= 0"),
    doc_case("forcing-amplitude-nan", {"system.forcing.amplitude": "[0.0, nan]"},
             "system.forcing.amplitude", "NaN"),
    doc_case("gap-offset-inf", {"system.gap.offset": "[inf]"}, "system.gap.offset", "NaN or infinity"),
    doc_case("gap-omega-nan", {"system.gap.omega": "nan"}, "system.gap.omega", "NaN"),
    doc_case("law-unknown", {"impact.law": '"hertz"'}, "impact.law", "hertz"),
    doc_case("restitution-above-one", {"impact.restitution": "1.5"}, "impact.restitution", "1.5"),
    doc_case("restitution-negative", {"impact.restitution": "-0.1"}, "impact.restitution", "-0.1"),
    doc_case("restitution-nan", {"impact.restitution": "nan"}, "impact.restitution", "NaN"),
    doc_case("restitution-length", {"impact.restitution": "[0.5, 0.5]"}, "impact.restitution",
             "wrong shape"),
    doc_case("initial-q-length", {"initial.q": "[0.0]"}, "initial.q", "wrong shape"),
    doc_case("initial-q-penetrates", {"initial.q": "[-0.3, -0.2]"}, "initial.q", "penetrates"),
    doc_case("initial-u-nan", {"initial.u": "[nan, 0.0]"}, "initial.u", "NaN"),
    doc_case("initial-u-overflowing-energy", {"initial.u": "[1e200, 0.0]"}, "initial.u", "overflows"),
    doc_case("initial-q-overflowing-energy", {"initial.q": "[1e200, 1e200]"}, "initial.q", "overflow"),
    doc_case("h-zero", {"simulation.h": "0.0"}, "simulation.h", "> 0"),
    doc_case("h-negative", {"simulation.h": "-1e-3"}, "simulation.h", "> 0"),
    doc_case("h-nan", {"simulation.h": "nan"}, "simulation.h", "NaN"),
    doc_case("h-text", {"simulation.h": "fast"}, "simulation.h", "not a numeric"),
    doc_case("t-end-zero", {"simulation.t_end": "0.0"}, "simulation.t_end", "> 0"),
    doc_case("t-end-inf", {"simulation.t_end": "inf"}, "simulation.t_end", "NaN or infinity"),
    doc_case("theta-low", {"simulation.theta": "0.3"}, "simulation.theta", ">= 0.5"),
    doc_case("theta-high", {"simulation.theta": "1.5"}, "simulation.theta", "<= 1.0"),
    doc_case("solver-unknown", {"simulation.solver": '"gauss"'}, "simulation.solver", "gauss"),
    doc_case("master-projection-text", {"simulation.master_projection": '"yes"'},
             "simulation.master_projection", "true or false"),
    doc_case("unknown-key", {"simulation.foo": "1"}, "simulation.foo", "unknown key"),
    doc_case("unknown-table", {"extra.x": "1"}, "extra", "unknown key"),
    doc_case("unknown-forcing-key", {"system.forcing.bogus": "1"}, "system.forcing.bogus", "unknown key"),
    doc_case("coupling-reversed", {"observer.coupling": "[5.0, 1.0]"}, "observer.coupling", "t_off",
             observers="nojump"),
    doc_case("source-unknown", {"observer.source": '"radio"'}, "observer.source", "radio",
             observers="nojump"),
    doc_case("observers-unknown", {"observer.observers": '["kalman"]'}, "observer.observers", "kalman",
             observers="nojump"),
    doc_case("observer-q-length", {"observer.q": "[0.0, 0.0, 0.0]"}, "observer.q", "wrong shape",
             observers="jump"),
    toml_case("missing-K", _del("system.K"), "system.K", "required key is missing"),
    toml_case("missing-simulation", _del("simulation"), "simulation.t_end", "required key is missing"),
    toml_case("system-not-a-table", _put("impact", "newton"), "impact", "must be a table"),
    # --- builder parameters -----------------------------------------------------------------
    param_case("param-k1-zero-jump", "double_mass", {"param.k1": "0"}, "param.k1", "cannot be built",
               observers="jump"),
    param_case("param-k1-zero", "double_mass", {"param.k1": "0"}, "param.k1", "Singular"),
    param_case("param-m1-zero", "double_mass", {"param.m1": "0"}, "param.m1", "system.M"),
    param_case("param-m1-negative", "double_mass", {"param.m1": "-1"}, "param.m1", "positive definite"),
    param_case("param-restitution", "double_mass", {"param.restitution": "2"}, "param.restitution",
               "impact.restitution"),
    param_case("param-h-zero", "bouncing_ball", {"param.h": "0"}, "param.h", "simulation.h"),
    param_case("param-F-inf", "double_mass", {"param.F": "inf"}, "param.F", "NaN or infinity"),
    param_case("param-law-unknown", "impact_oscillator", {"param.law": '"hertz"'}, "param.law", "hertz"),
    param_case("param-law-number", "impact_oscillator", {"param.law": "3"}, "param.law", "string"),
    param_case("param-unknown", "double_mass", {"param.N": "3"}, "param.N", "unknown parameter"),
    param_case("param-N-zero", "rocking_chain", {"param.N": "0"}, "param.N", "positive"),
    param_case("param-N-fraction", "rocking_chain", {"param.N": "2.5"}, "param.N", "integer"),
    param_case("param-N-nan", "rocking_chain", {"param.N": "nan"}, "param.N", "NaN"),
    param_case("param-N-text", "rocking_chain", {"param.N": "many"}, "param.N", "must be a number"),
    # --- Python API and command-line options ------------------------------------------------
    run_case("h-option-nan", {"h": float("nan")}, "simulation.h", "NaN", ["--h", "nan"]),
    run_case("h-option-zero", {"h": 0.0}, "simulation.h", "> 0", ["--h", "0"]),
    run_case("h-option-negative", {"h": -1e-4}, "simulation.h", "> 0", ["--h=-1e-4"]),
    run_case("t-end-option-inf", {"t_end": float("inf")}, "simulation.t_end", "NaN or infinity",
             ["--t-end", "inf"]),
    run_case("t-end-option-negative", {"t_end": -1.0}, "simulation.t_end", "> 0", ["--t-end=-1"]),
    run_case("t-end-beyond-any-grid", {"t_end": 1e30}, "simulation.h", "2^53", ["--t-end", "1e30"]),
    run_case("h-tiny", {"h": 1e-150}, "simulation.h", "2^53", ["--h", "1e-150"]),
    Bad("rows-beyond-memory", "--store", "does not fit in memory", None,
        ["run", "double_mass", "--h", "1e-15", "--t-end", "1", "--out", OUT], kind="cli"),
    doc_case("h-boolean", {"simulation.h": "true"}, "simulation.h", "boolean"),
    doc_case("restitution-boolean", {"impact.restitution": "true"}, "impact.restitution", "boolean"),
    doc_case("harmonics-not-tables", {"system.forcing.harmonics": "1"}, "system.forcing.harmonics",
             "array of tables"),
    doc_case("coupling-nan", {"observer.coupling": "[nan, 1.0]"}, "observer.coupling", "NaN",
             observers="jump"),
    run_case("theta-keyword", {"theta": 2.0}, "simulation.theta", "<= 1.0"),
    run_case("solver-option", {"solver": "gauss"}, "simulation.solver", "gauss", ["--solver", "gauss"]),
    run_case("observer-option", {"observers": ["kalman"]}, "observer.observers", "kalman",
             ["--observers", "kalman"]),
    run_case("observer-duplicate", {"observers": ["jump", "jump"]}, "observer.observers", "unique",
             ["--observers", "jump,jump"]),
    run_case("source-option", {"observers": ["jump"], "source": "radio"}, "observer.source", "radio",
             ["--observers", "jump", "--source", "radio"], cli_field="argument --source"),
    run_case("log-source-without-log", {"observers": ["jump"], "source": "log"}, "observer.log",
             "needs a log", ["--observers", "jump", "--source", "log"]),
    run_case("log-file-missing", {"observers": ["jump"], "source": "log", "log": "/nonexistent/log.csv"},
             "observer.log", "not found",
             ["--observers", "jump", "--source", "log", "--log", "/nonexistent/log.csv"]),
    run_case("engine-option", {"engine": "gpu"}, "engine", "gpu", ["--engine", "gpu"],
             cli_field="argument --engine"),
    run_case("record-every-zero", {"record_every": 0}, "record_every", "positive", ["--record-every", "0"]),
    run_case("record-every-negative", {"record_every": -3}, "record_every", "positive",
             ["--record-every=-3"]),
    run_case("store-option", {"store": "everything"}, "store", "everything", ["--store", "everything"],
             cli_field="argument --store"),
    Bad("h-option-text", "argument --h", "invalid float value", None,
        ["run", "double_mass", "--h", "fast", "--out", OUT], kind="cli"),
    Bad("set-without-equals", "--set", "KEY=VALUE", None,
        ["run", "double_mass", "--set", "simulation.h", "--out", OUT], kind="cli"),
    Bad("set-inside-value", "simulation.h.x", "non-table", lambda tmp: load_scenario(
        "double_mass", {"simulation.h.x": 1}), ["run", "double_mass", "--set", "simulation.h.x=1",
                                                "--out", OUT]),
    Bad("set-empty-key", "--set", "empty key", lambda tmp: load_scenario("double_mass", {"": 1}),
        ["run", "double_mass", "--set", "=1", "--out", OUT]),
    Bad("set-empty-component", "simulation..h", "empty key",
        lambda tmp: load_scenario("double_mass", {"simulation..h": 1}),
        ["run", "double_mass", "--set", "simulation..h=1", "--out", OUT]),
    Bad("scenario-empty", "scenario", "empty name", lambda tmp: load_scenario(""),
        ["run", "", "--out", OUT]),
    Bad("scenario-directory", "{tmp}", "is a directory", lambda tmp: load_scenario(str(tmp)),
        ["run", "{tmp}", "--out", OUT]),
    Bad("scenario-file-not-utf8", "{tmp}/bin.toml", "not UTF-8",
        lambda tmp: load_scenario(str(tmp / "bin.toml")), ["run", "{tmp}/bin.toml", "--out", OUT],
        files={"bin.toml": b"\xff\xfe\x00[system]"}),
    Bad("scenario-unknown", "scenario", "neither a built-in", lambda tmp: load_scenario("no_such"),
        ["run", "no_such", "--out", OUT]),
    Bad("scenario-file-missing", "{tmp}/missing.toml", "file not found",
        lambda tmp: load_scenario(str(tmp / "missing.toml")), ["run", "{tmp}/missing.toml", "--out", OUT]),
    Bad("scenario-file-invalid-toml", "{tmp}/bad.toml", "invalid TOML",
        lambda tmp: load_scenario(str(tmp / "bad.toml")), ["run", "{tmp}/bad.toml", "--out", OUT],
        files={"bad.toml": "[system\nM = 1"}),
    Bad("param-on-toml-file", "param.N", "only to built-in",
        lambda tmp: load_scenario(str(tmp / "case.toml"), {"param.N": 3}),
        ["run", "{tmp}/case.toml", "--set", "param.N=3", "--out", OUT],
        files={"case.toml": dumps(builtin_document("double_mass"))}),
    Bad("out-missing", "the following arguments are required", "--out", None, ["run", "double_mass"],
        kind="cli"),
    Bad("subcommand-unknown", "argument command", "invalid choice", None, ["fly"], kind="cli"),
    Bad("api-M-not-square", "system.M", "square", lambda tmp: _system(M=np.ones((2, 3)))),
    Bad("api-forcing-dimension", "system.forcing", "dimension", lambda tmp: _system(forcing=_harmonic(3))),
    Bad("api-gap-dimension", "system.gap", "dimension", lambda tmp: _system(gap=_harmonic(2))),
    Bad("api-K-nan", "system.K", "NaN", lambda tmp: _system(K=[[np.nan, 0.0], [0.0, 1.0]])),
    Bad("api-W-object", "system.W", "not a numeric array", lambda tmp: _system(W=[[{}], [0.0]])),
    # --- closing log (χ) CSV ------------------------------------------------------------------
    doc_case("log-path-not-a-path", {"observer.log": "3", "observer.source": '"log"'}, "observer.log",
             "must be a file path", observers="jump"),
    Bad("log-is-directory", "observer.log", "not a file", lambda tmp: read_log(tmp, 1),
        ["run", "double_mass", "--observers", "jump", "--source", "log", "--log", "{tmp}", "--out", OUT],
        kind="log"),
    log_case("log-empty", "", "not a readable CSV"),
    log_case("log-missing-column", "contact,t_close\n0,0.001\n", "missing column"),
    log_case("log-not-a-number", "contact,t_close,t_open\n0,soon,0.002\n", "not a number"),
    log_case("log-nan", "contact,t_close,t_open\n0,nan,0.002\n", "NaN"),
    log_case("log-inf", "contact,t_close,t_open\n0,0.001,inf\n", "NaN"),
    log_case("log-opens-before-closing", "contact,t_close,t_open\n0,0.002,0.001\n", "t_open < t_close"),
    log_case("log-contact-out-of-range", "contact,t_close,t_open\n3,0.001,0.002\n", "unknown contact index"),
    log_case("log-contact-negative", "contact,t_close,t_open\n-1,0.001,0.002\n", "unknown contact index"),
    log_case("log-contact-fraction", "contact,t_close,t_open\n0.5,0.001,0.002\n", "unknown contact index"),
    log_case("log-overlapping", "contact,t_close,t_open\n0,0.001,0.003\n0,0.002,0.004\n", "overlaps"),
    log_case("log-unsorted", "contact,t_close,t_open\n0,0.003,0.004\n0,0.001,0.002\n", "not sorted"),
    log_case("log-binary", b"\xff\xfe\x00\x81garbage\x00", "not a readable CSV"),
    # --- output paths ------------------------------------------------------------------------
    out_case("out-unsupported", ["run", "double_mass", "--out", "{tmp}/out.txt"], "unsupported file type"),
    out_case("out-no-suffix", ["run", "double_mass", "--out", "{tmp}/out"], "unsupported file type"),
    out_case("out-is-directory", ["run", "double_mass", "--out", "{tmp}/dir.csv"], "is a directory",
             files={"dir.csv/keep": ""}),
    out_case("out-parent-is-file", ["run", "double_mass", "--out", "{tmp}/file/out.csv"],
             "is not a directory", files={"file": "x"}),
    out_case("out-unwritable", ["run", "double_mass", "--out", "/proc/out.csv"], "cannot write"),
    out_case("plot-out-unsupported", ["plot", "{tmp}/r.csv", "--out", "{tmp}/fig.xyz"],
             "unsupported file type", files={"r.csv": "t,q0\n0,1\n"}),
    out_case("log-out-parquet", ["log", "{tmp}/r.csv", "--out", "{tmp}/closings.parquet"],
             "unsupported file type", files={"r.csv": "t,q0\n0,1\n"}),
]

# --- issue 20: ranges, numbers that are strings, bounded files, the API's own arguments -------
HUGE_K = {"system.K": "[[1e308, 0.0], [0.0, 1e308]]"}
TINY_M = {"system.M": "[[1e-310, 0.0], [0.0, 1e-310]]"}
DEEP = "[" * 100 + "1.0" + "]" * 100
"""A value nested 100 deep: parsed by tomllib, refused by the document's validation."""
DEEPER = "[" * 5000 + "]" * 5000
"""A ``--set`` value nested 5000 deep: tomllib would recurse past Python's limit."""


def api_case(id: str, call: Callable[[Path], Any], fld: str, hint: str) -> Bad:
    """A call of the Python API with no command-line counterpart."""
    return Bad(id, fld, hint, call, kind="api")


def file_case(id: str, content: str | bytes | None, fld: str, hint: str, name: str = "case.toml",
              path: str | None = None) -> Bad:
    """A scenario file given by path (written to tmp from ``content`` unless ``path`` is given)."""
    where = path or "{tmp}/" + name
    return Bad(id, fld, hint, lambda tmp: load_scenario(_fill(where, tmp)),
               ["run", where, "--out", OUT], files={} if content is None else {name: content},
               kind="file")


def bench_case(id: str, argv: list[str], fld: str, hint: str, files: dict | None = None) -> Bad:
    """``python -m bench ARGV`` (the smoke suite, results under tmp)."""
    return Bad(id, fld, hint, None, argv, files=files or {}, kind="bench", prog="bench")


def _dm_doc(edit: Callable[[dict], None] | None = None) -> str:
    doc = builtin_document("double_mass")
    if edit:
        edit(doc)
    return dumps(doc)


CASES += [
    doc_case("K-entries-square-overflows", HUGE_K, "system.K", "square overflows"),
    doc_case("M-entries-inverse-overflows", TINY_M, "system.M", "inverse overflows"),
    doc_case("C-entry-square-overflows", {"system.C": "[[1e200, 0.0], [0.0, 1.0]]"}, "system.C",
             "square overflows"),
    doc_case("W-entry-square-overflows", {"system.W": "[[1e300], [0.0]]"}, "system.W",
             "square overflows"),
    doc_case("W-entry-inverse-overflows", {"system.W": "[[1.0], [1e-320]]"}, "system.W",
             "inverse overflows"),
    doc_case("K-huge-with-jump", HUGE_K, "system.K", "square overflows", observers="jump"),
    doc_case("t-end-string", {"simulation.t_end": '"20"'}, "simulation.t_end", "the string '20'"),
    doc_case("h-string-number", {"simulation.h": '"1e-3"'}, "simulation.h", "the string '1e-3'"),
    doc_case("theta-string", {"simulation.theta": '"0.5"'}, "simulation.theta", "string"),
    doc_case("M-entry-string", {"system.M": '[["1.0", 0.0], [0.0, 1.0]]'}, "system.M",
             "entry (0, 0) is the string '1.0'"),
    doc_case("K-entry-boolean", {"system.K": "[[true, 0.0], [0.0, 1.0]]"}, "system.K",
             "entry (0, 0) is a boolean"),
    doc_case("W-entry-string", {"system.W": '[["1"], [0.0]]'}, "system.W", "string"),
    doc_case("initial-q-string-entry", {"initial.q": '["0.1", 0.0]'}, "initial.q", "string"),
    doc_case("initial-u-boolean-entry", {"initial.u": "[false, 0.0]"}, "initial.u", "boolean"),
    doc_case("restitution-string", {"impact.restitution": '"0.5"'}, "impact.restitution", "string"),
    doc_case("forcing-omega-string", {"system.forcing.omega": '"6.0"'}, "system.forcing.omega",
             "string"),
    doc_case("gap-offset-boolean-entry", {"system.gap.offset": "[true]"}, "system.gap.offset",
             "boolean"),
    doc_case("forcing-phase-string", {"system.forcing.phase": '"0"'}, "system.forcing.phase",
             "string"),
    doc_case("coupling-string-entry", {"observer.coupling": '["0", 1.0]'}, "observer.coupling",
             "string", observers="jump"),
    doc_case("observer-q-string-entry", {"observer.q": '["0.0", 0.0]'}, "observer.q", "string",
             observers="jump"),
    doc_case("observer-u-overflowing-energy", {"observer.u": "[1e200, 0.0]"}, "observer.u",
             "overflows", observers="jump"),
    doc_case("forcing-angle-overflows", {"system.forcing.omega": "1e308"}, "system.forcing.omega",
             "angle omega·t + phase overflows"),
    doc_case("gap-harmonic-angle-overflows",
             {"system.gap.harmonics": "[{amplitude = [0.1], omega = 1e308}]"},
             "system.gap.harmonics[0].omega", "overflows"),
    doc_case("t-end-below-h", {"simulation.t_end": "1e-5"}, "simulation.t_end",
             "at least one step"),
    doc_case("law-array", {"impact.law": "[1]"}, "impact.law", "must be one of"),
    doc_case("law-table", {"impact.law": "{a = 1}"}, "impact.law", "must be one of"),
    doc_case("solver-array", {"simulation.solver": "[1]"}, "simulation.solver", "unknown contact solver"),
    doc_case("observers-nested", {"observer.observers": "[[1]]"}, "observer.observers",
             "unknown observer", observers="jump"),
    doc_case("observers-table-entry", {"observer.observers": "[{a = 1}]"}, "observer.observers",
             "unknown observer", observers="jump"),
    doc_case("M-nested-100-deep", {"system.M": DEEP}, "system.M", "nested deeper than 64"),
    doc_case("M-huge-integer", {"system.M": "[[1" + "0" * 400 + ", 0], [0, 1]]"}, "system.M",
             "not a numeric array"),
    Bad("set-value-nested-5000-deep", "--set", "nested deeper", lambda tmp: load_scenario(
        "double_mass", {"system.M": DEEPER}), ["run", "double_mass", "--set", f"system.M={DEEPER}",
                                              "--out", OUT], kind="cli"),
    # --- the API's own arguments -------------------------------------------------------------
    run_case("residual-tol-nan", {"residual_tol": float("nan")}, "residual_tol", "NaN"),
    run_case("residual-tol-negative", {"residual_tol": -1.0}, "residual_tol", "> 0"),
    run_case("residual-tol-zero", {"residual_tol": 0.0}, "residual_tol", "> 0"),
    run_case("residual-tol-string", {"residual_tol": "1e-9"}, "residual_tol", "string"),
    run_case("coupling-reversed-api", {"observers": ["jump"], "coupling": (5.0, 1.0)},
             "observer.coupling", "t_off = 1.0 < t_on = 5.0"),
    run_case("coupling-nan-api", {"observers": ["jump"], "coupling": (float("nan"), 1.0)},
             "observer.coupling", "NaN"),
    run_case("coupling-length-api", {"observers": ["jump"], "coupling": (1.0, 2.0, 3.0)},
             "observer.coupling", "wrong shape"),
    run_case("coupling-string-api", {"observers": ["jump"], "coupling": "soon"},
             "observer.coupling", "string"),
    run_case("record-every-2-to-the-70", {"record_every": 2 ** 70}, "record_every", "2^53",
             ["--record-every", str(2 ** 70)]),
    run_case("record-every-fraction", {"record_every": 2.5}, "record_every", "positive integer"),
    run_case("record-every-boolean", {"record_every": True}, "record_every", "positive integer"),
    run_case("observers-not-iterable", {"observers": 3}, "observer.observers", "design names"),
    run_case("observers-entry-number", {"observers": [3]}, "observer.observers", "design names"),
    run_case("observers-entry-list", {"observers": [["jump"]]}, "observer.observers", "design names"),
    run_case("on-chunk-not-callable", {"on_chunk": 3}, "on_chunk", "callable"),
    run_case("integrator-unknown", {"integrator": "rk4"}, "integrator", "rk4"),
    run_case("integrator-list", {"integrator": ["event"]}, "integrator", "must be one of"),
    run_case("h-keyword-string", {"h": "1e-3"}, "simulation.h", "string"),
    run_case("t-end-keyword-string", {"t_end": "20"}, "simulation.t_end", "string"),
    run_case("t-end-keyword-below-h", {"t_end": 1e-6}, "simulation.t_end", "at least one step",
             ["--t-end", "1e-6"]),
    run_case("theta-keyword-boolean", {"theta": True}, "simulation.theta", "boolean"),
    run_case("event-record-every", {"integrator": "event", "record_every": 5}, "record_every",
             "time-stepping option"),
    api_case("load-scenario-integer-key", lambda tmp: observer.load_scenario("double_mass", {1: 2}),
             "overrides", "dotted strings"),
    api_case("load-scenario-overrides-list", lambda tmp: observer.load_scenario(
        "double_mass", [("simulation.h", 1e-3)]), "overrides", "must be a dict"),
    api_case("load-scenario-complex-entry", lambda tmp: observer.load_scenario(
        "double_mass", {"initial.q": [1j, 0.0]}), "initial.q", "complex"),
    api_case("load-scenario-numpy-strings", lambda tmp: observer.load_scenario(
        "double_mass", {"system.M": np.array([["1", "0"], ["0", "1"]])}), "system.M", "string"),
    api_case("from-dict-not-a-table", lambda tmp: observer.Scenario.from_dict([1, 2]), "scenario",
             "must be a table"),
    # --- closing logs ----------------------------------------------------------------------------
    log_case("log-negative-time", "contact,t_close,t_open\n0,-0.5,0.002\n", "< 0"),
    log_case("log-text-contact", "contact,t_close,t_open\nzero,0.001,0.002\n", "not a number"),
    # --- scenario files ----------------------------------------------------------------------------
    file_case("file-dev-zero", None, "/dev/zero", "16 MiB", path="/dev/zero"),
    file_case("file-oversized", b"# " + b"x" * (16 * 2 ** 20) + b"\n", "{tmp}/case.toml", "16 MiB"),
    file_case("file-nested-100000-deep", "a = " + "[" * 100_000 + "]" * 100_000,
              "{tmp}/case.toml", "nested deeper than 64"),
    file_case("file-tables-nested-deep", "a = " + "{b = " * 3000 + "1" + "}" * 3000,
              "{tmp}/case.toml", "nested deeper than 64"),
    file_case("file-nested-70-deep", "a = " + "[" * 70 + "]" * 70, "{tmp}/case.toml",
              "nested deeper than 64"),
    file_case("file-t-end-string", _dm_doc(_put("simulation.t_end", "20")), "simulation.t_end",
              "the string '20'"),
    file_case("file-M-subnormal", _dm_doc(_put("system.M", [[1e-310, 0.0], [0.0, 1e-310]])),
              "system.M", "inverse overflows"),
    file_case("file-K-huge", _dm_doc(_put("system.K", [[1e308, 0.0], [0.0, 1e308]])), "system.K",
              "square overflows"),
    file_case("file-empty", "", "system.M", "required key is missing"),
    file_case("file-system-array-of-tables", "[[system]]\nM = 1\n", "system", "must be a table"),
    file_case("file-duplicate-key", "[simulation]\nh = 1.0\nh = 2.0\n", "{tmp}/case.toml",
              "invalid TOML"),
    file_case("file-nul-bytes", b"[simulation]\x00\nh = 1\n", "{tmp}/case.toml", "invalid TOML"),
    file_case("file-huge-integer", _dm_doc(_put("simulation.t_end", 10 ** 400)), "simulation.t_end",
              "not a numeric array"),
    file_case("file-path-with-newline", "[system\n", "{tmp}/a\\nb.toml", "invalid TOML",
              name="a\nb.toml"),
    file_case("file-missing-path-with-newline", None, "{tmp}/no\\nsuch.toml", "file not found",
              path="{tmp}/no\nsuch.toml"),
    # --- output paths --------------------------------------------------------------------------
    out_case("out-path-with-newline", ["run", "double_mass", "--out", "{tmp}/a\nb.txt"],
             "unsupported file type"),
    # --- bench ---------------------------------------------------------------------------------
    bench_case("bench-unknown-suite", ["run", "nosuch", "--out", "{tmp}"], "suite", "unknown suite"),
    bench_case("bench-status-unknown-suite", ["status", "nosuch", "--out", "{tmp}"], "suite",
               "unknown suite"),
    bench_case("bench-show-unknown-suite", ["show", "nosuch"], "suite", "unknown suite"),
    bench_case("bench-workers-negative", ["run", "smoke", "--workers=-1", "--out", "{tmp}"],
               "argument --workers", ">= 0"),
    bench_case("bench-workers-text", ["run", "smoke", "--workers", "many", "--out", "{tmp}"],
               "argument --workers", ">= 0"),
    bench_case("bench-limit-text", ["run", "smoke", "--limit", "few", "--out", "{tmp}"],
               "argument --limit", "invalid int"),
    bench_case("bench-limit-negative", ["run", "smoke", "--limit=-1", "--out", "{tmp}"], "--limit",
               ">= 0"),
    bench_case("bench-out-is-a-file", ["run", "smoke", "--out", "{tmp}/file"], "--out",
               "not a directory", files={"file": "x"}),
    bench_case("bench-status-out-is-a-file", ["status", "smoke", "--out", "{tmp}/file"], "--out",
               "not a directory", files={"file": "x"}),
    bench_case("bench-out-empty", ["run", "smoke", "--out", ""], "--out", "results folder"),
    bench_case("bench-scheduler-no-port", ["run", "smoke", "--no-progress", "--scheduler", "nonsense",
                                           "--out", "{tmp}"], "--scheduler", "cannot connect"),
    bench_case("bench-command-unknown", ["fly"], "argument cmd", "invalid choice"),
]


# --- issue 36: inputs a user gets wrong, and hostile ones ---------------------------------------
_THREE = "[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]"
ENSEMBLE = ["ensemble", "double_mass", "--n", "2", "--t-end", "0.01", "--out", "{tmp}/e.parquet"]

CASES += [
    doc_case("matrices-disagree-on-n", {"system.K": _THREE, "system.C": _THREE,
                                        "system.W": "[[1.0], [0.0], [0.0]]"}, "system.M",
             "system.M is 2x2 but system.C is 3x3, system.K is 3x3, system.W has 3 rows"),
    doc_case("K-ragged-row", {"system.K": "[[1.0, 0.0], [0.0]]"}, "system.K",
             "row 1 has 1 entry, expected 2"),
    doc_case("W-ragged-row", {"system.W": "[[1.0], []]"}, "system.W", "row 1 has 0 entries, expected 1"),
    log_case("log-contact-index-as-written", "contact,t_close,t_open\n2,0.001,0.002\n",
             "unknown contact index 2 (the system"),
    log_case("log-negative-time-as-written", "contact,t_close,t_open\n0,-0.5,0.002\n", "t_close = -0.5 < 0"),
    run_case("h-option-negative-own-word", {"h": -1e-4}, "simulation.h", "must be > 0, got -0.0001",
             ["--h", "-1e-4"]),
    run_case("t-end-option-negative-own-word", {"t_end": -2.5}, "simulation.t_end", "must be > 0",
             ["--t-end", "-2.5E+0"]),
    Bad("observers-empty-item", "--observers", "empty item in 'jump,'", None,
        ["run", "double_mass", "--observers", "jump,", "--out", OUT], kind="cli"),
    Bad("observers-empty-middle-item", "--observers", "empty item", None,
        ["run", "double_mass", "--observers", "jump,,nojump", "--out", OUT], kind="cli"),
    Bad("ensemble-designs-empty-item", "--designs", "empty item", None,
        ENSEMBLE + ["--designs", "nojump,"], kind="cli"),
    Bad("ensemble-seed-2-to-the-63", "seed", "at most 2^63 - 1",
        lambda tmp: observer.ensemble("double_mass", n=2, seed=2 ** 63, t_end=0.01),
        ENSEMBLE + ["--seed", str(2 ** 63)], kind="cli"),
    api_case("ensemble-seed-2-to-the-200", lambda tmp: observer.ensemble(
        "double_mass", n=2, seed=2 ** 200, t_end=0.01), "seed", "at most 2^63 - 1"),
    run_case("h-subnormal", {"h": 5e-324}, "simulation.h", "h² underflows", ["--h", "5e-324"]),
    run_case("h-1e-300-short-run", {"h": 1e-300, "t_end": 1e-299}, "simulation.h", "h² underflows",
             ["--h", "1e-300", "--t-end", "1e-299"]),
    run_case("h-1e-200-short-run", {"h": 1e-200, "t_end": 1e-199}, "simulation.h", "h² underflows",
             ["--h", "1e-200", "--t-end", "1e-199"]),
    api_case("M-datetime64", lambda tmp: _system(M=np.array([["2020-01-01", "2020-01-02"]] * 2,
                                                             dtype="datetime64[D]")),
             "system.M", "datetime64"),
    api_case("K-timedelta64", lambda tmp: _system(K=np.eye(2).astype("timedelta64[s]")), "system.K",
             "timedelta64"),
    run_case("t-end-timedelta64", {"t_end": np.timedelta64(5, "s")}, "simulation.t_end",
             "a date or a duration is not a number"),
    api_case("M-masked-entry", lambda tmp: _system(M=np.ma.masked_array(np.eye(2), mask=[[0, 1], [0, 0]])),
             "system.M", "entry (0, 1) is masked"),
    api_case("initial-q-masked", lambda tmp: observer.load_scenario(
        "double_mass", {"initial.q": np.ma.masked_array([0.0, 0.0], mask=[1, 0])}), "initial.q", "masked"),
    param_case("param-N-beyond-memory", "rocking_chain", {"param.N": str(10 ** 15)}, "param.N",
               "GiB to build scenario 'rocking_chain'"),
    api_case("log-dataframe-bad-contact", lambda tmp: observer.simulate(
        "double_mass", t_end=0.01, observers=["jump"], source="log",
        log=__import__("pandas").DataFrame({"contact": [3], "t_close": [0.001], "t_open": [0.002]})),
        "observer.log", "DataFrame given as the log (1 rows): row 1: unknown contact index 3"),
]


# --- issue 33: [observer.sensor], the contact sensor that gives the observers their χ --------------
SENSOR_LOG = {"log.csv": LOG_OK}
CASES += [
    doc_case("sensor-latency-negative", {"observer.sensor.latency": "-1e-3"}, "observer.sensor.latency",
             "must be >= 0.0"),
    doc_case("sensor-threshold-negative", {"observer.sensor.threshold": "-1e-4"},
             "observer.sensor.threshold", "must be >= 0.0"),
    doc_case("sensor-period-zero", {"observer.sensor.sampling_period": "0.0"},
             "observer.sensor.sampling_period", "must be > 0"),
    doc_case("sensor-period-negative", {"observer.sensor.sampling_period": "-1e-3"},
             "observer.sensor.sampling_period", "must be > 0"),
    doc_case("sensor-period-text", {"observer.sensor.sampling_period": '"fast"'},
             "observer.sensor.sampling_period", "string"),
    doc_case("sensor-period-boolean", {"observer.sensor.sampling_period": "true"},
             "observer.sensor.sampling_period", "boolean"),
    doc_case("sensor-missed-above-one", {"observer.sensor.missed": "1.5"}, "observer.sensor.missed",
             "must be <= 1.0"),
    doc_case("sensor-missed-negative", {"observer.sensor.missed": "-0.1"}, "observer.sensor.missed",
             "must be >= 0.0"),
    doc_case("sensor-false-rate-negative", {"observer.sensor.false_rate": "-2.0"},
             "observer.sensor.false_rate", "must be >= 0.0"),
    doc_case("sensor-jitter-nan", {"observer.sensor.jitter": "nan"}, "observer.sensor.jitter", "NaN"),
    doc_case("sensor-seed-fraction", {"observer.sensor.seed": "1.5"}, "observer.sensor.seed",
             "integer ≥ 0"),
    doc_case("sensor-unknown-key", {"observer.sensor.delay": "1e-3"}, "observer.sensor.delay",
             "unknown key"),
    doc_case("sensor-not-a-table", {"observer.sensor": "1e-3"}, "observer.sensor", "must be a table"),
    api_case("sensor-keyword-latency-negative", lambda tmp: observer.simulate(
        "double_mass", t_end=0.01, observers=["jump"], sensor={"latency": -1e-3}),
        "observer.sensor.latency", "must be >= 0.0"),
    api_case("sensor-keyword-without-observers", lambda tmp: observer.simulate(
        "double_mass", t_end=0.01, sensor={"missed": -0.5}), "observer.sensor.missed", "must be >= 0.0"),
    api_case("sensor-keyword-unknown", lambda tmp: observer.simulate(
        "double_mass", t_end=0.01, observers=["jump"], sensor={"lag": 1e-3}),
        "observer.sensor.lag", "unknown key"),
    api_case("sensor-keyword-not-a-dict", lambda tmp: observer.simulate(
        "double_mass", t_end=0.01, observers=["jump"], sensor=1e-3), "observer.sensor", "must be a table"),
    api_case("sensor-ensemble-missed", lambda tmp: observer.ensemble(
        "double_mass", n=2, t_end=0.01, sensor={"missed": 2.0}), "observer.sensor.missed", "must be <= 1.0"),
    api_case("sensor-compare-period", lambda tmp: observer.compare(
        "double_mass", n=2, masters=1, t_end=0.01, sensor={"sampling_period": -1.0}),
        "observer.sensor.sampling_period", "must be > 0"),
    Bad("sensor-threshold-with-a-log", "observer.sensor.threshold", "no gap",
        lambda tmp: observer.simulate("double_mass", t_end=0.01, observers=["jump"], source="log",
                                      log=str(tmp / "log.csv"), sensor={"threshold": 1e-3}),
        ["run", "double_mass", "--observers", "jump", "--source", "log", "--log", "{tmp}/log.csv",
         "--set", "observer.sensor.threshold=1e-3", "--t-end", "0.01", "--out", OUT],
        files=SENSOR_LOG, kind="log"),
    Bad("sensor-self-driven", "observer.sensor", "self-driven",
        lambda tmp: observer.simulate("double_mass", t_end=0.01, observers=["jump"], source="self",
                                      sensor={"latency": 1e-3}),
        ["run", "double_mass", "--observers", "jump", "--source", "self",
         "--set", "observer.sensor.latency=1e-3", "--t-end", "0.01", "--out", OUT], kind="cli"),
    Bad("sensor-event-master", "observer.sensor", "time-stepping",
        lambda tmp: observer.simulate("double_mass", t_end=0.01, observers=["jump"], integrator="event",
                                      sensor={"latency": 1e-3}),
        ["run", "double_mass", "--observers", "jump", "--integrator", "event",
         "--set", "observer.sensor.latency=1e-3", "--t-end", "0.01", "--out", OUT], kind="cli"),
]
# --- issue 33: the observers' own model, [observer.model] -------------------------------------------
CASES += [
    doc_case("model-K-wrong-shape", {"observer.model.K": "[[100.0, -100.0, 0.0], [-100.0, 200.0, 0.0]]"},
             "observer.model.K", "wrong shape"),
    doc_case("model-W-wrong-shape", {"observer.model.W": "[[1.0, 0.0], [0.0, 1.0]]"}, "observer.model.W",
             "wrong shape"),
    doc_case("model-K-factors-wrong-shape", {"observer.model.K": "{factors = [1.0, 1.0]}"},
             "observer.model.K.factors", "wrong shape"),
    doc_case("model-K-factors-indefinite", {"observer.model.K": "{factors = [[1.0, 1.6], [1.6, 1.0]]}"},
             "observer.model.K", "positive semi-definite"),
    doc_case("model-M-random-not-spd", {"observer.model.M": "{relative_std = 1.0, seed = 1}"},
             "observer.model.M", "positive definite"),
    doc_case("model-M-scale-zero", {"observer.model.M": "{scale = 0.0}"}, "observer.model.M.scale", "must be > 0"),
    doc_case("model-K-scale-negative", {"observer.model.K": "{scale = -1.01}"}, "observer.model.K.scale",
             "must be > 0"),
    doc_case("model-K-scale-text", {"observer.model.K": '{scale = "1%"}'}, "observer.model.K.scale", "number"),
    doc_case("model-unknown-key", {"observer.model.stiffness": "1.01"}, "observer.model.stiffness",
             "unknown key"),
    doc_case("model-K-unknown-perturbation-key", {"observer.model.K": "{scale = 1.01, sigma = 2.0}"},
             "observer.model.K.sigma", "unknown key"),
    doc_case("model-K-two-perturbations", {"observer.model.K": "{scale = 1.01, factors = [[1.0, 1.0], [1.0, 1.0]]}"},
             "observer.model.K", "exactly one of scale, factors, relative_std"),
    doc_case("model-K-seed-missing", {"observer.model.K": "{relative_std = 0.01}"}, "observer.model.K.seed",
             "required with relative_std"),
    doc_case("model-K-seed-negative", {"observer.model.K": "{relative_std = 0.01, seed = -3}"},
             "observer.model.K.seed", "non-negative integer"),
    doc_case("model-K-relative-std-negative", {"observer.model.K": "{relative_std = -0.01, seed = 3}"},
             "observer.model.K.relative_std", ">= 0"),
    doc_case("model-error-metric", {"observer.model.error_metric": '"mass"'}, "observer.model.error_metric",
             "must be one of ['plant', 'model']"),
    doc_case("model-restitution-above-1", {"observer.model.impact.restitution": "1.5"},
             "observer.model.impact.restitution", "[0, 1]"),
    doc_case("model-gap-offset-length", {"observer.model.gap.offset": "[0.25, 0.25]"},
             "observer.model.gap.offset", "wrong shape"),
    doc_case("model-not-a-table", {"observer.model": "1.01"}, "observer.model", "must be a table"),
    Bad("model-with-the-kernel-summary", "store", "use store=\"full\"",
        lambda tmp: observer.simulate("double_mass", t_end=0.01, observers=["jump"], store="summary",
                                      model={"K": {"scale": 1.01}}), kind="api"),
]

# --- issue 33: ensembles and comparisons over plants drawn from an uncertainty ---------------------


def _uncertainty(model, **kw):
    return lambda tmp: observer.uncertainty_ensemble("double_mass", model=model, **{"n": 2, "t_end": 0.01, **kw})


def _compare_plants(model, **kw):
    return lambda tmp: observer.compare("double_mass", **{"n": 2, "masters": 1, "t_end": 0.01, "model": model,
                                                           "plants": 2, **kw})


UNCERTAINTY_ARGV = ["uncertainty", "double_mass", "--n", "2", "--t-end", "0.01", "--out", OUT]
COMPARE_ARGV = ["compare", "double_mass", "--n", "2", "--masters", "1", "--t-end", "0.01"]
NOT_SPD = {"K": {"relative_std": 1.0}}
"""σ = 1 on K: the draws of seed 0 leave a plant's K indefinite."""
CASES += [
    Bad("uncertainty-sigma-negative", "model.K.relative_std", "must be >= 0.0",
        _uncertainty({"K": {"relative_std": -0.01}}), [*UNCERTAINTY_ARGV, "--uncertainty", "K=-0.01"],
        cli_field="--uncertainty K", kind="cli"),
    Bad("uncertainty-sigma-text", "model.K.relative_std", "string 'abc'",
        _uncertainty({"K": {"relative_std": "abc"}}), [*UNCERTAINTY_ARGV, "--uncertainty", "K=abc"],
        cli_field="--uncertainty K", kind="cli"),
    Bad("uncertainty-sigma-nan", "model.K.relative_std", "NaN",
        _uncertainty({"K": {"relative_std": float("nan")}}), [*UNCERTAINTY_ARGV, "--uncertainty", "K=nan"],
        cli_field="--uncertainty K", kind="cli"),
    Bad("uncertainty-unknown-matrix", "model.Q", "unknown matrix",
        _uncertainty({"Q": {"relative_std": 0.01}}), [*UNCERTAINTY_ARGV, "--uncertainty", "Q=0.01"],
        cli_field="--uncertainty Q", kind="cli"),
    Bad("uncertainty-plants-zero", "plants", "integer ≥ 1", _uncertainty({"K": {"relative_std": 0.01}}, plants=0),
        [*UNCERTAINTY_ARGV, "--uncertainty", "K=0.01", "--plants", "0"], kind="cli"),
    Bad("uncertainty-not-spd-draw", "model.K", "positive semi-definite", _uncertainty(NOT_SPD, plants=5),
        [*UNCERTAINTY_ARGV, "--uncertainty", "K=1.0", "--plants", "5"], cli_field="--uncertainty K", kind="cli"),
    Bad("uncertainty-level-above-one", "level", "must be below 1",
        _uncertainty({"K": {"relative_std": 0.01}}, level=2.0),
        [*UNCERTAINTY_ARGV, "--uncertainty", "K=0.01", "--level", "2"], kind="cli"),
    Bad("uncertainty-resamples-zero", "n_resamples", "integer ≥ 1",
        _uncertainty({"K": {"relative_std": 0.01}}, n_resamples=0),
        [*UNCERTAINTY_ARGV, "--uncertainty", "K=0.01", "--n-resamples", "0"], kind="cli"),
    Bad("uncertainty-pair-malformed", "--uncertainty", "expected KEY=VALUE", None,
        [*UNCERTAINTY_ARGV, "--uncertainty", "K"], kind="cli"),
    Bad("uncertainty-matrix-twice", "--uncertainty K", "given twice", None,
        [*UNCERTAINTY_ARGV, "--uncertainty", "K=0.01", "--uncertainty", "K=0.02"], kind="cli"),
    Bad("compare-uncertainty-negative", "model.K.relative_std", "must be >= 0.0",
        _compare_plants({"K": {"relative_std": -1.0}}), [*COMPARE_ARGV, "--uncertainty", "K=-1"],
        cli_field="--uncertainty K", kind="cli"),
    Bad("compare-uncertainty-unknown-matrix", "model.Q", "unknown matrix", _compare_plants({"Q": {"relative_std": 0.1}}),
        [*COMPARE_ARGV, "--uncertainty", "Q=0.1"], cli_field="--uncertainty Q", kind="cli"),
    Bad("compare-plants-zero", "plants", "integer ≥ 1", _compare_plants({"K": {"relative_std": 0.01}}, plants=0),
        [*COMPARE_ARGV, "--uncertainty", "K=0.01", "--plants", "0"], kind="cli"),
    Bad("compare-not-spd-draw", "model.K", "positive semi-definite", _compare_plants(NOT_SPD, plants=5),
        [*COMPARE_ARGV, "--uncertainty", "K=1.0", "--plants", "5"], cli_field="--uncertainty K", kind="cli"),
    api_case("compare-plants-without-uncertainty", _compare_plants(None), "model", "plants= draws"),
    Bad("compare-plants-without-uncertainty-cli", "--plants", "give --uncertainty", None,
        [*COMPARE_ARGV, "--plants", "3"], kind="cli"),
    api_case("compare-sample-without-plants", _compare_plants(None, plants=None, sample="model"), "sample",
             "give plants="),
    Bad("compare-sample-without-plants-cli", "--sample", "give --uncertainty", None,
        [*COMPARE_ARGV, "--sample", "model"], kind="cli"),
    Bad("compare-model-seeded-with-plants", "model.K", "the seeds are drawn",
        _compare_plants({"K": {"relative_std": 0.01, "seed": 3}}), kind="api"),
]


def _prepare(case: Bad, tmp: Path) -> None:
    for name, content in case.files.items():
        path = tmp / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if name.endswith("/keep"):
            continue
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content)


def _fill(text: str, tmp: Path) -> str:
    return text.replace("{tmp}", str(tmp))


def test_the_matrix_has_at_least_150_distinct_bad_inputs():
    ids = [c.id for c in CASES]
    assert len(set(ids)) == len(ids)
    assert len(CASES) >= 150
    kinds = {k: sum(c.kind == k for c in CASES)
             for k in ("doc", "param", "api", "cli", "log", "out", "file", "bench")}
    assert all(v >= 5 for v in kinds.values()), kinds
    assert sum(kinds.values()) == len(CASES)


@pytest.mark.parametrize("case", [c for c in CASES if c.call is not None], ids=lambda c: c.id)
def test_python_route_raises_input_error_naming_the_field(case, tmp_path):
    _prepare(case, tmp_path)
    with pytest.raises(InputError) as info:
        case.call(tmp_path)
    err = info.value
    msg = str(err)
    assert err.field == _fill(case.field, tmp_path), msg
    assert msg.startswith(f"{err.field}: ") and "\n" not in msg, msg
    assert case.hint in msg, msg


@pytest.mark.parametrize("case", [c for c in CASES if c.argv is not None], ids=lambda c: c.id)
def test_cli_exits_2_with_one_line_naming_the_field(case, tmp_path, capsys, monkeypatch):
    _prepare(case, tmp_path)
    monkeypatch.chdir(tmp_path)
    argv = [_fill(a, tmp_path) for a in case.argv]
    main = bench_main if case.prog == "bench" else cli.main
    with ExitCode() as code:
        code.value = main(argv)
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert code.value == 2, err
    assert len(lines) == 1, err
    expected = _fill(case.cli_field or case.field, tmp_path)
    assert lines[0].startswith(f"error: {expected}"), lines[0]
    assert case.hint in lines[0], lines[0]
    assert "Traceback" not in err and out == ""
    assert not (tmp_path / "out.csv").exists()
    assert not list(tmp_path.rglob("*.parquet"))


SUBPROCESS_CASES = ["h-option-nan", "out-unwritable", "file-dev-zero", "file-nested-100000-deep",
                    "record-every-2-to-the-70", "bench-limit-negative"]


def test_subprocess_prints_one_line_and_no_traceback(tmp_path):
    """The real interpreter: status 2, one stderr line, no traceback (run in parallel)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = {}
    for name in SUBPROCESS_CASES:
        case = next(c for c in CASES if c.id == name)
        tmp = tmp_path / name
        tmp.mkdir()
        _prepare(case, tmp)
        argv = [_fill(a, tmp) for a in case.argv]
        procs[name] = (tmp, case, subprocess.Popen([sys.executable, "-m", case.prog, *argv], cwd=tmp,
                                                   env=env, stdout=subprocess.PIPE,
                                                   stderr=subprocess.PIPE, text=True))
    for name, (tmp, case, proc) in procs.items():
        out, err = proc.communicate(timeout=120)
        assert proc.returncode == 2, (name, err)
        assert "Traceback" not in err, (name, err)
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"error: {_fill(case.field, tmp)}"), (name, err)
        assert not (tmp / "out.csv").exists()


def test_public_api_loads_through_the_checked_loader():
    """``observer.load_scenario`` (the façade, a re-export of ``observer.scenario.load_scenario``)
    refuses a builder failure like the CLI does."""
    with pytest.raises(InputError) as info:
        observer.load_scenario("double_mass", {"param.k1": 0})
    assert info.value.field == "param.k1"


def test_nojump_accepts_what_only_the_jump_observer_refuses():
    """The K-metric checks are specific: the same systems run with the no-jump observer,
    and their results hold no NaN."""
    for overrides in (SINGULAR_K, K_METRIC_DEPENDENT_W):
        res = observer.simulate(load_scenario("double_mass", overrides), observers=["nojump"],
                                t_end=0.05, engine="python")
        frame = res.to_frame()
        assert np.isfinite(frame.to_numpy(dtype=float)).all()
        assert "V_nojump" in frame.columns


# --- issue 20: the same refusal on every route ----------------------------------------------------
PARITY = {
    "h-option-nan": ({"h": float("nan")}, {"simulation.h": "nan"}),
    "t-end-string": ({"t_end": "20"}, {"simulation.t_end": '"20"'}),
    "theta-high": ({"theta": 1.5}, {"simulation.theta": "1.5"}),
    "t-end-below-h": ({"t_end": 1e-5}, {"simulation.t_end": "1e-5"}),
    "solver-unknown": ({"solver": "gauss"}, {"simulation.solver": '"gauss"'}),
    "master-projection-text": ({"master_projection": "yes"}, {"simulation.master_projection": '"yes"'}),
}


@pytest.mark.parametrize("name", sorted(PARITY))
def test_api_keyword_and_toml_field_are_refused_with_the_same_message(name):
    keywords, overrides = PARITY[name]
    with pytest.raises(InputError) as api:
        observer.simulate("double_mass", **keywords)
    with pytest.raises(InputError) as toml:
        load_scenario("double_mass", overrides)
    assert str(api.value) == str(toml.value)


def test_reversed_coupling_window_same_message_from_the_api_and_the_toml_table():
    with pytest.raises(InputError) as api:
        observer.simulate("double_mass", t_end=0.01, observers=["jump"], coupling=(5.0, 1.0))
    with pytest.raises(InputError) as toml:
        observer.simulate(load_scenario("double_mass", {"observer.coupling": "[5.0, 1.0]"}),
                          t_end=0.01, observers=["jump"])
    assert str(api.value) == str(toml.value) == "observer.coupling: t_off = 1.0 < t_on = 5.0"


PROOFS_PARITY = ["file-dev-zero", "file-nested-100000-deep", "file-t-end-string", "file-M-subnormal",
                 "file-K-huge", "file-path-with-newline", "scenario-file-invalid-toml",
                 "scenario-file-not-utf8"]


@pytest.mark.parametrize("name", PROOFS_PARITY)
def test_proofs_checks_refuses_what_observer_run_refuses_with_the_same_line(name, tmp_path, capsys):
    from proofs_checks.cli import main as proofs_main

    case = next(c for c in CASES if c.id == name)
    _prepare(case, tmp_path)
    path = _fill(case.argv[1], tmp_path)
    assert cli.main(["run", path, "--out", str(tmp_path / "out.csv")]) == 2
    run_err = capsys.readouterr().err
    assert proofs_main([path]) == 2
    out, proofs_err = capsys.readouterr()
    assert proofs_err == run_err and len(run_err.splitlines()) == 1 and out == ""
    assert run_err.startswith(f"error: {_fill(case.field, tmp_path)}: ")


def test_an_error_naming_a_path_with_line_breaks_stays_on_one_line():
    for brk in ("\n", "\r", "\x0b", "\x0c", "\x1c", "\x85", "\u2028"):
        err = InputError(f"dir{brk}name.toml", f"problem{brk}text")
        assert len(str(err).splitlines()) == 1 and brk not in str(err)
        assert str(err) == f"dir{brk!r}name.toml: problem{brk!r}text".replace("'", "")


def _tmpfs(path: Path, size: str) -> bool:
    """Mount a small tmpfs at ``path`` (root only; False where mounting is not allowed)."""
    if os.geteuid() != 0 or not Path("/proc/filesystems").read_text().count("tmpfs"):
        return False
    path.mkdir()
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                          capture_output=True).returncode == 0


def test_a_full_disk_is_one_line_naming_the_file(tmp_path, capsys):
    """``observer run`` writing to a 64 KiB tmpfs (a real full disk: root may mount one,
    else a write to /dev/full through a symlink, which fails with the same ENOSPC)."""
    mnt = tmp_path / "small"
    mounted = _tmpfs(mnt, "64k")
    try:
        if not mounted:
            mnt.mkdir()
            (mnt / "out.csv").symlink_to("/dev/full")
        code = cli.main(["run", "double_mass", "--t-end", "0.5", "--out", str(mnt / "out.csv")])
        err = capsys.readouterr().err
        lines = err.splitlines()
        assert code == 2, err
        assert len(lines) == 1 and "Traceback" not in err, err
        assert lines[0].startswith(f"error: {mnt}/") and lines[0].endswith("No space left on device")
    finally:
        if mounted:
            subprocess.run(["umount", str(mnt)], check=True)


def test_a_numerical_library_failure_is_one_line_naming_the_scenario(monkeypatch, capsys, tmp_path):
    """Should an input pass validation and still break a computation, the command line prints
    one line naming the scenario (never a LinAlgError traceback)."""
    def breaks(*args, **kwargs):
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(sys.modules["observer.simulate"], "simulate", breaks)
    code = cli.main(["run", "double_mass", "--out", str(tmp_path / "out.csv")])
    err = capsys.readouterr().err
    assert code == 2 and err.splitlines() == [
        "error: double_mass: the computation failed (LinAlgError: Singular matrix); please report "
        "this input"]
    assert not (tmp_path / "out.csv").exists()


def test_a_numerical_library_failure_in_the_api_is_an_input_error_naming_the_scenario(monkeypatch):
    """The same through :func:`observer.simulate`: an :class:`InputError` naming ``scenario``
    with the library's exception as its cause; a toolkit error or a NumPy MemoryError passes
    unchanged."""
    def singular():
        raise np.linalg.LinAlgError("Singular matrix")

    def too_large():
        return np.empty(2 ** 50)        # 8 PiB, beyond any address space: NumPy's MemoryError

    def toolkit_bug():
        raise KeyError("not a library's")

    failures = iter([singular, too_large, toolkit_bug])

    def breaks(*args, **kwargs):
        return next(failures)()

    monkeypatch.setattr(sys.modules["observer.engines.timestepping"].TimeStepping, "advance", breaks)
    with pytest.raises(InputError) as info:
        observer.simulate("double_mass", t_end=0.01)
    assert str(info.value) == ("scenario: double_mass: the computation failed (LinAlgError: Singular "
                               "matrix); please report this input")
    assert isinstance(info.value.__cause__, np.linalg.LinAlgError)
    with pytest.raises(MemoryError):
        observer.simulate("double_mass", t_end=0.01)
    with pytest.raises(KeyError):
        observer.simulate("double_mass", t_end=0.01)


def test_a_dataframe_log_runs_as_its_csv_file(tmp_path):
    """A closing log given as a DataFrame with the log's columns is the same log as its CSV."""
    import pandas as pd

    log = pd.DataFrame({"contact": [0, 0], "t_close": [0.001, 0.004], "t_open": [0.002, 0.006]})
    log.to_csv(tmp_path / "log.csv", index=False)
    kw = dict(t_end=0.01, observers=["jump"], source="log", engine="python")
    a = observer.simulate("double_mass", log=log, **kw).to_frame()
    b = observer.simulate("double_mass", log=str(tmp_path / "log.csv"), **kw).to_frame()
    assert a.equals(b)


def test_a_masked_array_without_masked_entries_is_its_data():
    sys_ = _system(M=np.ma.masked_array(2.0 * np.eye(2)))
    assert np.array_equal(sys_.M, 2.0 * np.eye(2))


def test_control_bytes_in_a_scenario_name_are_escaped_and_show_round_trips(tmp_path, capsys):
    name = "bell\x07esc\x1b[31mred"
    doc = builtin_document("double_mass")
    doc["scenario"]["name"] = name
    (tmp_path / "case.toml").write_text(dumps(doc))
    assert cli.main(["run", str(tmp_path / "case.toml"), "--observers", "none", "--t-end", "0.01",
                     "--out", str(tmp_path / "out.csv")]) == 0
    out = capsys.readouterr().out
    assert "\x07" not in out and "\x1b" not in out
    assert out.startswith("bell\\x07esc\\x1b[31mred: ")
    assert cli.main(["show", str(tmp_path / "case.toml")]) == 0
    shown = capsys.readouterr().out
    assert "\x07" not in shown and "\x1b" not in shown
    assert load_scenario_text(shown, tmp_path).name == name


def load_scenario_text(text: str, tmp: Path):
    (tmp / "shown.toml").write_text(text)
    return load_scenario(str(tmp / "shown.toml"))


def test_an_error_line_escapes_control_bytes():
    err = InputError("scenario", "'a\x07b\x1b[2J\x7f\x9b'")
    assert str(err) == "scenario: 'a\\x07b\\x1b[2J\\x7f\\x9b'"


def test_an_ascii_terminal_gets_escapes_not_unicode_errors(tmp_path):
    """``LANG=C`` without UTF-8 coercion: stdout is ASCII; ``show`` writes ``§`` as ``\\u00a7``
    (a TOML string reads it back as ``§``) and exits 0, and its output runs unchanged."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONIOENCODING", "PYTHONUTF8")}
    env.update(PYTHONPATH=str(ROOT), LC_ALL="C", LANG="C", PYTHONCOERCECLOCALE="0", PYTHONUTF8="0")
    proc = subprocess.run([sys.executable, "-m", "observer", "show", "double_mass"], env=env,
                          capture_output=True, timeout=120)
    assert proc.returncode == 0 and b"Traceback" not in proc.stderr, proc.stderr
    assert max(proc.stdout) < 128 and b"\\u00a7" in proc.stdout
    sc = load_scenario_text(proc.stdout.decode("ascii"), tmp_path)
    assert sc.to_dict() == load_scenario("double_mass").to_dict()


def test_a_missing_gap_offset_warns_naming_the_field_and_its_effect():
    from observer.errors import InputWarning

    doc = builtin_document("double_mass")
    del doc["system"]["gap"]
    doc["initial"]["q"] = [0.1, 0.2]
    with pytest.warns(InputWarning, match=r"system.gap.offset: not given, so every contact's offset is 0"):
        sc = observer.Scenario.from_dict(doc)
    assert np.array_equal(sc.system.nu(0.0), [0.0])
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        observer.Scenario.from_dict(builtin_document("double_mass"))


def test_an_on_chunk_callback_that_raises_is_reported_as_the_callbacks():
    """The user's own exception, unchanged and noted as the callback's; never "the
    computation failed ... please report this input"."""
    def callback(chunk):
        raise ZeroDivisionError("the user's bug")

    from observer.loop import ENGINES                  # the registry's time-stepping engines
    for engine in ENGINES:
        with pytest.raises(ZeroDivisionError, match="the user's bug") as info:
            observer.simulate("double_mass", t_end=0.01, on_chunk=callback, engine=engine)
        assert any("on_chunk callback" in n for n in info.value.__notes__)


@pytest.mark.parametrize("what", ["toml-file", "empty-folder"])
def test_reports_on_a_non_result_is_one_line_exit_2(what, tmp_path, capsys, monkeypatch):
    from reports.__main__ import main as reports_main

    monkeypatch.chdir(tmp_path)
    if what == "toml-file":
        (tmp_path / "x.toml").write_text("a = 1\n")
        arg, field = "x.toml", "x.toml"
    else:
        (tmp_path / "empty").mkdir()
        arg, field = "empty", "empty"
    assert reports_main([arg, "--out", str(tmp_path / "page")]) == 2
    out, err = capsys.readouterr()
    assert err.splitlines() == [err.strip()] and err.startswith(f"error: {field}: ")
    assert "Traceback" not in err and not (tmp_path / "page").exists()


def _result_with_sidecar(tmp: Path) -> Path:
    assert cli.main(["run", "double_mass", "--observers", "none", "--engine", "python", "--t-end", "0.001",
                     "--out", str(tmp / "r.csv")]) == 0
    return tmp / "r.csv"


@pytest.mark.parametrize("what", ["sidecar-nested-100000-deep", "sidecar-link-to-dev-zero",
                                  "result-link-to-dev-zero"])
def test_a_hostile_sidecar_or_result_is_one_line_naming_the_file(what, tmp_path, capsys):
    """Issue 36, item 20: read at most a bounded amount, never recurse without bound, and
    name the file (was a RecursionError "computation failed", or the kernel's kill at /dev/zero)."""
    result = _result_with_sidecar(tmp_path)
    capsys.readouterr()
    side = tmp_path / "r.json"
    if what == "sidecar-nested-100000-deep":
        side.write_text("[" * 100_000 + "]" * 100_000)
        name, hint = side, "nested too deep"
    elif what == "sidecar-link-to-dev-zero":
        side.unlink()
        side.symlink_to("/dev/zero")
        name, hint = side, "not a regular file"
    else:
        result = tmp_path / "z.csv"
        result.symlink_to("/dev/zero")
        name, hint = result, "not a regular file"
    code = cli.main(["log", str(result), "--out", str(tmp_path / "closings.csv")])
    out, err = capsys.readouterr()
    assert code == 2 and err.splitlines() == [err.rstrip("\n")], err
    assert err.startswith(f"error: {name}: ") and hint in err, err
    assert not (tmp_path / "closings.csv").exists() and out == ""


# -- issue 36, item 24: a loaded scenario edited, and sizes bounded up front -----------------------
@pytest.mark.parametrize("name, index", [("q0", 0), ("u0", 1)])
def test_a_loaded_scenarios_initial_state_edited_to_nan_is_refused_at_simulate_time(name, index):
    """``sc.q0[0] = nan`` after loading (the arrays are plain numpy arrays): the run refuses
    it naming ``initial.q`` / ``initial.u`` instead of returning a NaN first row."""
    sc = load_scenario("double_mass", {"simulation.t_end": 0.01})
    getattr(sc, name)[index] = np.nan
    field_name = {"q0": "initial.q", "u0": "initial.u"}[name]
    for integrator in ("time-stepping", "event"):
        with pytest.raises(InputError) as exc:
            observer.simulate(sc, integrator=integrator)
        assert exc.value.field == field_name and "NaN" in str(exc.value)


def test_a_loaded_scenarios_initial_state_edited_to_an_overflowing_one_is_refused():
    sc = load_scenario("double_mass", {"simulation.t_end": 0.01})
    sc.u0[:] = 1e200                                  # finite, but ½uᵀMu overflows
    with pytest.raises(InputError) as exc:
        observer.simulate(sc)
    assert exc.value.field == "initial.u"


HUGE_TOML = """[scenario]
name = "huge"
[system]
M = {shape = [1000000000, 1000000000], offsets = [0], diagonals = [{pattern = [1.0]}], symmetric = true}
K = {shape = [1000000000, 1000000000], offsets = [0, -1], diagonals = [{pattern = [2.0]}, {pattern = [-1.0]}], symmetric = true}
C = {shape = [1000000000, 1000000000], offsets = [0], diagonals = [{pattern = [0.01]}], symmetric = true}
W = {shape = [1000000000, 1], rows = [0], cols = [0], values = [1.0]}
[system.gap]
offset = [0.1]
[impact]
law = "newton"
restitution = 0.5
[initial]
q = {n = 1000000000, pattern = [0.0]}
u = {n = 1000000000, pattern = [0.0]}
[simulation]
t_end = 1.0
h = 0.001
"""
"""A system of 10⁹ degrees of freedom in compact notation (banded tables, periodic vectors)."""


def _memory(monkeypatch, nbytes: int) -> None:
    """Whatever the machine: the memory the size checks see."""
    import observer.memory as memory
    monkeypatch.setattr(memory, "available_memory", lambda: nbytes)


AS_LIMIT = 4 * 2 ** 30
"""Address space of the subprocesses below (``RLIMIT_AS``): a regression allocates into a
MemoryError there instead of into the machine's memory (the toolkit's estimate counts it)."""


def _limited(argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (AS_LIMIT, AS_LIMIT))
    return subprocess.run([sys.executable, "-m", "observer", *argv], capture_output=True, text=True,
                          cwd=cwd, env={**os.environ, "PYTHONPATH": str(ROOT)}, preexec_fn=limit, timeout=120)


def test_a_small_file_declaring_a_billion_dofs_is_refused_naming_the_matrix(tmp_path):
    """Issue 36, item 24: under 1 KiB of TOML, 10⁹ DOF: refused before anything is expanded,
    one line naming system.M and the memory (the address space left by a 4 GiB limit), no
    result (it was a MemoryError reported as the --store line)."""
    path = tmp_path / "huge.toml"
    path.write_text(HUGE_TOML)
    assert path.stat().st_size < 1024
    proc = _limited(["run", str(path), "--out", str(tmp_path / "r.csv")], tmp_path)
    err = proc.stderr
    assert proc.returncode == 2 and err.count("\n") == 1 and err.startswith("error: system.M: "), err
    assert "1000000000 × 1000000000" in err and "GiB are available" in err
    assert not (tmp_path / "r.csv").exists()


@pytest.mark.parametrize("form", ["vector", "banded", "triplet"])
def test_a_compact_declaration_is_expanded_up_to_the_memory_available(form, monkeypatch):
    """Near miss of the bound: with exactly the estimated bytes available the table is
    expanded; one byte fewer and it is refused naming the field (estimates: 16 bytes per
    vector entry; 48 per banded entry plus 8 per row pointer; 16 per row pointer and 40 per
    triplet)."""
    from observer.sparse import banded_matrix
    from observer.validation import triplet_matrix
    n = 1000
    if form == "vector":
        need, build = 16 * n, lambda: observer.validation.as_array("initial.q", {"n": n, "pattern": [0.5]}, (n,))
    elif form == "banded":
        need = 48 * (n + 2 * (n - 1)) + 8 * (n + 1)   # main diagonal + the sub-diagonal and its mirror
        build = lambda: banded_matrix("system.K", {"shape": [n, n], "offsets": [0, -1], "symmetric": True,
                                                   "diagonals": [{"pattern": [2.0]}, {"pattern": [-1.0]}]})
    else:
        need = 16 * (n + 1) + 40 * 2
        build = lambda: triplet_matrix("system.W", {"shape": [n, 1], "rows": [0, 5], "cols": [0, 0],
                                                    "values": [1.0, 2.0]})
    _memory(monkeypatch, need)
    assert build().shape[0] == n
    _memory(monkeypatch, need - 1)
    with pytest.raises(InputError) as exc:
        build()
    assert exc.value.field in ("initial.q", "system.K", "system.W") and "GiB" in str(exc.value)


def test_an_ensemble_of_ten_million_members_is_refused_up_front(tmp_path):
    """``ensemble --n 10000000``: one line naming n and the memory, at once (it ran for minutes
    before running out of memory), no output."""
    proc = _limited(["ensemble", "double_mass", "--n", "10000000", "--out", str(tmp_path / "e.parquet")],
                    tmp_path)
    err = proc.stderr
    assert proc.returncode == 2 and err.count("\n") == 1 and err.startswith("error: n: 10000000 members"), err
    assert list(tmp_path.iterdir()) == []


def test_the_ensemble_memory_bound_is_sharp(monkeypatch):
    from observer.ensemble import MEMBER_BYTES, check_member_memory
    need = 1000 * 2 * (MEMBER_BYTES + 32 * 2)
    _memory(monkeypatch, need)
    check_member_memory(1000, 2, 2)
    _memory(monkeypatch, need - 1)
    with pytest.raises(InputError, match="1000 members") as exc:
        check_member_memory(1000, 2, 2)
    assert exc.value.field == "n"
