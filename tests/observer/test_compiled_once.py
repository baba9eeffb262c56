"""The compiled step written once (issue 32): small signatures, one predictor, one projection.

Inspected on the compiled functions themselves — every numba dispatcher of the modules that
compile code (:data:`COMPILED_MODULES`), the generated ones with the source they were compiled
from (:data:`observer.codegen.GENERATED`):

* no compiled function takes more than :data:`MAX_POSITIONAL` positional parameters;
* Siconos' predictor ``g_k + (h/2)γ_k ≤ 0`` — any product ``0.5 * h`` — is written only in
  :func:`observer.primitives.predicted_term` and :func:`~observer.primitives.predicted_closed`,
  and the generated step loops decide their closed sets by calling the latter;
* the position projection's data (the dense metric stacks ``KinvWT``/``NinvWT`` and ``L``, the
  factored ``Kch``) is indexed only by the projection's definitions
  (:func:`~observer.primitives.project_positions`, :func:`~observer.engines.compiled.kernel.factored_project`
  and the one-contact fragment :data:`observer.primitives.PROJECT_ONE`, which is the body of
  :func:`~observer.primitives.project_one` and is placed verbatim in the step loops).

Each check is first run on a known-bad source (a hand copy of the predictor or of the
projection, a 21-parameter function) to show that it fails there.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import textwrap

import pytest
from numba.core.registry import CPUDispatcher

import observer.codegen as codegen

COMPILED_MODULES = ("observer.primitives", "observer.event.roots", "observer.engines.compiled.step",
                    "observer.engines.compiled.kernel", "observer.engines.compiled.members")
"""Every module of ``observer`` that compiles code (``njit`` or :func:`observer.codegen.compile_function`)."""
MAX_POSITIONAL = 20
PREDICTOR = {"predicted_term", "predicted_closed"}
PROJECTION = {"project_positions", "project_one", "factored_project"}
PROJECTION_DATA = {"KinvWT", "NinvWT", "L", "Kch"}


def dispatchers() -> dict[str, CPUDispatcher]:
    """``module.name`` → every compiled function (each once, under the module that defines it)."""
    out = {}
    for mod in COMPILED_MODULES:
        for name, obj in vars(importlib.import_module(mod)).items():
            if isinstance(obj, CPUDispatcher):
                out.setdefault(f"{obj.py_func.__module__}.{obj.py_func.__name__}", obj)
    return out


def source(key: str, fn: CPUDispatcher) -> str:
    """The source ``fn`` was compiled from."""
    return codegen.GENERATED.get(key) or textwrap.dedent(inspect.getsource(fn.py_func))


def positional(src: str) -> dict[str, int]:
    """Function name → its number of positional parameters, for every def in ``src``."""
    return {f.name: len(f.args.posonlyargs) + len(f.args.args) for f in ast.walk(ast.parse(src))
            if isinstance(f, ast.FunctionDef)}


def writes_predictor(src: str) -> bool:
    """Whether ``src`` holds a product ``0.5 * h`` (the predictor's half step)."""
    return any(isinstance(n, ast.BinOp) and isinstance(n.op, ast.Mult)
               and isinstance(n.left, ast.Constant) and n.left.value == 0.5
               and isinstance(n.right, ast.Name) and n.right.id == "h" for n in ast.walk(ast.parse(src)))


def projection_reads(src: str) -> int:
    """How many subscripts of the projection's data (:data:`PROJECTION_DATA`) ``src`` holds."""
    return sum(isinstance(n, ast.Subscript) and isinstance(n.value, ast.Name) and n.value.id in PROJECTION_DATA
               for n in ast.walk(ast.parse(src)))


def without_fragment(src: str, fragment: str) -> str:
    """``src`` with every placed copy of ``fragment`` (the same lines, any indentation) cut out
    (each replaced by ``pass`` at its indentation)."""
    frag = [line.strip() for line in fragment.strip("\n").splitlines()]
    lines, out, i = src.splitlines(), [], 0
    while i < len(lines):
        if [line.strip() for line in lines[i:i + len(frag)]] == frag:
            out.append(lines[i][:len(lines[i]) - len(lines[i].lstrip())] + "pass")
            i += len(frag)
        else:
            out.append(lines[i])
            i += 1
    return "\n".join(out)


BAD_PREDICTOR = """
def loop(Wp, Wi, Wv, qs, us, nu, nud, h, act):
    a = 0
    for j in range(Wp.shape[0] - 1):
        g = 0.0
        for p in range(Wp[j], Wp[j + 1]):
            g += Wv[p] * (qs[0, Wi[p]] + 0.5 * h * us[0, Wi[p]])
        if g + nu[j] + 0.5 * h * nud[j] <= 0.0:
            act[a] = j
            a += 1
    return a
"""
BAD_PROJECTION = """
def loop(q1, Wp, Wi, Wv, nu, L, KinvWT, slots, s, j, k):
    g = 0.0
    for p in range(Wp[j], Wp[j + 1]):
        g += Wv[p] * q1[Wi[p]]
    l00 = L[slots[s], j, j]
    s1 = -(g + nu[k + 1, j]) / l00 if l00 > 0.0 else 0.0
    for i in range(q1.shape[0]):
        q1[i] += KinvWT[slots[s], j, i] * s1
"""


def test_the_checks_fail_on_hand_copies():
    assert writes_predictor(BAD_PREDICTOR)
    assert not writes_predictor(BAD_PREDICTOR.replace("0.5 * h", "h"))     # the near miss: no half step
    assert projection_reads(BAD_PROJECTION) == 2
    from observer.primitives import PROJECT_ONE
    assert projection_reads(without_fragment(BAD_PROJECTION, PROJECT_ONE)) == 2   # not the fragment
    many = "def f(" + ", ".join(f"a{i}" for i in range(MAX_POSITIONAL + 1)) + "):\n    return a0\n"
    assert positional(many) == {"f": MAX_POSITIONAL + 1}
    assert positional(many.replace(", a20", "")) == {"f": MAX_POSITIONAL}


def test_no_compiled_function_takes_more_than_20_positional_parameters():
    found = dispatchers()
    assert {"observer.engines.compiled.kernel._advance_loop", "observer.engines.compiled.members.advance_members",
            "observer.engines.compiled.kernel._advance_scalar_loop",
            "observer.engines.compiled.kernel.contact_impulse"} <= set(found)
    wide = {key: n for key, fn in found.items() for name, n in positional(source(key, fn)).items()
            if name == fn.py_func.__name__ and n > MAX_POSITIONAL}
    assert wide == {}


def test_the_predictor_has_one_compiled_definition():
    found = dispatchers()
    writers = {key.rpartition(".")[2] for key, fn in found.items() if writes_predictor(source(key, fn))}
    assert writers == PREDICTOR
    assert {key.rpartition(".")[0] for key, fn in found.items() if key.rpartition(".")[2] in PREDICTOR} == {
        "observer.primitives"}
    for loop in ("observer.engines.compiled.kernel._advance_loop", "observer.engines.compiled.members.advance_members",
                 "observer.engines.compiled.kernel._advance_scalar_loop"):
        assert "predicted_closed(" in source(loop, found[loop])


def test_the_projection_has_one_compiled_definition():
    from observer.primitives import PROJECT_ONE

    from observer.engines.compiled import step

    placed = (step.ONE_CONTACT["PROJECT_ONE"], step.MEMBER_ONE["PROJECT_ONE"],                  # in the loops
              codegen.fill(PROJECT_ONE, {"J": "j", "ROW": "k", "SLOT": "slot", "SIGMA": "sig[0] = s1"}))  # project_one

    def outside_the_fragment(src):
        for fragment in placed:
            src = without_fragment(src, fragment)
        return projection_reads(src)

    found = dispatchers()
    readers = {key.rpartition(".")[2] for key, fn in found.items() if outside_the_fragment(source(key, fn)) > 0}
    assert readers == PROJECTION - {"project_one"}        # project_one is the fragment itself
    assert "pass" in without_fragment(source("observer.primitives.project_one",
                                             found["observer.primitives.project_one"]), placed[2])
    for loop, fragment in (("observer.engines.compiled.kernel._advance_loop", placed[0]),
                           ("observer.engines.compiled.members.advance_members", placed[1])):
        src = source(loop, found[loop])
        assert projection_reads(src) == projection_reads(PROJECT_ONE.replace("$", "")) > 0   # the fragment, once
        assert without_fragment(src, fragment) != src
        assert "project_positions(" in src and "factored_project(" in src


@pytest.mark.parametrize("loop", ["_advance_loop", "advance_members"])
def test_both_loops_place_the_same_step(loop):
    """The kernel's and the members' loops hold the step's fragments line for line."""
    from observer.engines.compiled import step

    src = step.SOURCES[loop]()
    one = step.ONE_CONTACT if loop == "_advance_loop" else step.MEMBER_ONE
    for fragment in (step.fill(step.DYNAMICS, one), step.fill(step.CLOSED_SET, {
            "COUPLED": "s > 0 and coupled[kw]" if loop == "_advance_loop" else "COUP[k]",
            "CHI_J": "chi_now[j]" if loop == "_advance_loop" else "CHI[k, j]",
            "AFTER_PREDICTION": step.KERNEL_CHI if loop == "_advance_loop" else ""})):
        assert without_fragment(src, fragment) != src
