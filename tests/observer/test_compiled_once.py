"""The compiled step written once (issue 32): small signatures, one predictor, one projection.

Inspected on the compiled functions themselves — every numba dispatcher of the modules that
compile code (:data:`COMPILED_MODULES`), the generated ones with the source they were compiled
from (:data:`observer.codegen.GENERATED`):

* no compiled function takes more than :data:`MAX_POSITIONAL` positional parameters;
* Siconos' predictor ``g_k + (h/2)γ_k ≤ 0`` — any product ``0.5 * h`` — is written only in
  :func:`observer.primitives.predicted_term` and :func:`~observer.primitives.predicted_closed`,
  and the generated step loops decide their closed sets by calling the latter;
* ``duplicates`` (the tree's duplicate finder, a command on PATH) finds no pair of places in the
  files that hold compiled code (:data:`COMPILED_FILES`): the loops' templates and the compiled
  functions;
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
import re
import shutil
import subprocess
import textwrap
from pathlib import Path

import pytest
from numba.core.registry import CPUDispatcher

import observer.codegen as codegen

COMPILED_MODULES = ("observer.primitives", "observer.codegen", "observer.event.roots", "observer.event.kernels",
                    "observer.event.enclosures", "observer.engines.compiled.step",
                    "observer.engines.compiled.kernel", "observer.engines.compiled.members")
"""Every module of ``observer`` that compiles code (``njit`` or :func:`observer.codegen.compile_function`):
kept whole by :func:`test_every_compiling_module_is_inspected`."""
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


COMPILERS = {"njit", "jit", "vectorize", "guvectorize", "cfunc", "stencil", "compile_function", "build"}
"""numba's compiling decorators and the code generator's entry points
(:func:`observer.codegen.compile_function`, :func:`observer.engines.compiled.step.build`)."""


def compiling_modules(root: Path) -> set[str]:
    """The modules of the package at ``root`` that import a compiler (:data:`COMPILERS`) from
    numba or from the code generator, or ``numba`` itself to call ``numba.njit``/``numba.jit``."""
    out = set()
    for path in root.rglob("*.py"):
        text = path.read_text()
        if "numba" not in text and "build" not in text and "compile_function" not in text:
            continue
        for node in ast.walk(ast.parse(text)):
            source = isinstance(node, ast.ImportFrom) and ((node.module or "").split(".")[0] == "numba" or node.module in (
                "observer.codegen", "observer.engines.compiled.step"))
            if (source and any(a.name in COMPILERS for a in node.names)) or (
                    isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "numba"
                    and node.attr in COMPILERS):
                out.add(".".join(path.relative_to(root.parent).with_suffix("").parts))
    return out


def test_every_compiling_module_is_inspected(tmp_path):
    pkg = tmp_path / "observer"
    (pkg / "engines").mkdir(parents=True)
    (pkg / "engines" / "fast.py").write_text("from numba import njit\n")
    (pkg / "loops.py").write_text("from observer.engines.compiled.step import build\n")
    (pkg / "attr.py").write_text("import numba\nf = numba.njit(lambda x: x)\n")
    (pkg / "plain.py").write_text("from observer.plant_model import build_model\nfrom numba.core import config\n")
    assert compiling_modules(pkg) == {"observer.engines.fast", "observer.loops", "observer.attr"}   # a known-bad tree
    assert compiling_modules(Path(codegen.__file__).parent) == set(COMPILED_MODULES)


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
    assert projection_reads(source("observer.engines.compiled.kernel._advance_scalar_loop",
                                   found["observer.engines.compiled.kernel._advance_scalar_loop"])) == 0
    for loop, fragment in (("observer.engines.compiled.kernel._advance_loop", placed[0]),
                           ("observer.engines.compiled.members.advance_members", placed[1])):
        src = source(loop, found[loop])
        assert projection_reads(src) == projection_reads(PROJECT_ONE.replace("$", "")) > 0   # the fragment, once
        assert without_fragment(src, fragment) != src
        assert "project_positions(" in src and "factored_project(" in src


LOOPS = ("_advance_loop", "_advance_scalar_loop", "advance_members")


def placed_fragments(loop: str) -> dict:
    """The step's fragments as ``loop`` places them: filled for its form and its one-contact
    pieces, its accesses expanded (arrays, or the scalar loop's registers)."""
    from observer.engines.compiled import step

    kernel, scalar = loop == "_advance_loop", loop == "_advance_scalar_loop"
    one = step.MEMBER_ONE if loop == "advance_members" else step.SCALAR_ONE if scalar else step.ONE_CONTACT
    form = step.SCALAR_FORM if scalar else step.ARRAY_FORM
    closed = {"COUPLED": "False" if scalar else "s > 0 and coupled[kw]" if kernel else "COUP[k]",
              "CHI_J": "False" if scalar else "chi_now[j]" if kernel else "CHI[k, j]",
              "AFTER_PREDICTION": step.KERNEL_CHI if kernel else ""}
    macros = step.REGISTERS if scalar else step.ARRAYS
    return {"DYNAMICS": step.expand(step.step_source(one, form), macros),
            "CLOSED_SET": step.expand(step.fill(step.CLOSED_SET, closed), macros),
            "IMPULSE_ONE": step.expand(one["IMPULSE_ONE"], macros)}


@pytest.mark.parametrize("loop", LOOPS)
def test_every_loop_places_the_same_step(loop):
    """The kernel's, the scalar and the members' loops hold the step's fragments line for line
    (the scalar loop: the same lines with its registers for the arrays)."""
    from observer.engines.compiled import step

    src = step.SOURCES[loop]()
    for name, fragment in placed_fragments(loop).items():
        assert without_fragment(src, fragment) != src, name
    assert src.count("predicted_closed(") == 1


def test_the_scalar_loop_is_the_kernel_loop_in_registers():
    """The scalar loop is :data:`KERNEL_LOOP` with the lean flags as literals and the arrays'
    accesses as registers: once CPython has dropped the literal branches, the names it reads
    are its arguments, its registers and the buffers — no observer's, projection's, summary's
    or banded array, and no row of the state or signal arrays (but the one-element buffers of
    its call of ``impulse_one`` on a contact step)."""
    import dis

    from observer.engines.compiled import kernel, step

    src = step.scalar_source()
    read = {i.argval for i in dis.get_instructions(compile(src, "<scalar>", "exec").co_consts[0])
            if i.opname in ("LOAD_FAST", "LOAD_GLOBAL", "LOAD_NAME")}
    for name in ("jumps", "KinvWT", "L", "Kch", "slots", "summ", "Mq", "Ru_b", "Ach_b", "coupled", "chi_now",
                 "rec_qpre", "rec_sig", "rec_chi", "fsig", "nu", "fbar", "contact_impulse",
                 "factored_impulse", "project_positions", "banded_free_velocity"):
        assert name not in read, name
    assert {"qr", "ur", "q1r", "u1r", "fs1", "nv0", "nd0", "fbr", "predicted_closed", "rec_t"} <= read
    assert step.expand(step.KERNEL_LOOP, step.ARRAYS) != step.expand(step.KERNEL_LOOP, step.REGISTERS)
    assert kernel._advance_scalar_loop.py_func.__name__ == "_advance_scalar_loop"


ROOT = Path(__file__).resolve().parents[2]
COMPILED_FILES = ("observer/primitives.py", "observer/codegen.py", "observer/engines/compiled/step.py",
                  "observer/engines/compiled/kernel.py", "observer/engines/compiled/members.py")
"""The files that hold the compiled code: the step's template and fragments, the loops' assembly
and every compiled function of the time-stepping engines."""
needs_duplicates = pytest.mark.skipif(shutil.which("duplicates") is None, reason="no `duplicates` on PATH")


def duplicate_pairs(files, tmp_path) -> list[str]:
    """The pairs ``duplicates`` reports among ``files`` (copied alone into ``tmp_path``, so that
    only their pairs with each other are read), one row each."""
    for f in files:
        name = str(Path(f).relative_to(ROOT)) if Path(f).is_relative_to(ROOT) else Path(f).name
        shutil.copy(f, tmp_path / name.replace("/", "__"))
    out = subprocess.run(["duplicates", "--repo", str(tmp_path), "--most", "200", "--seconds", "60"],
                         capture_output=True, text=True, timeout=120).stdout
    assert "incomplete" not in out and f"({len(files)} files read)" in out, out
    return re.findall(r"^D\d+ .*$", out, re.M)


@needs_duplicates
def test_duplicates_finds_no_pair_in_the_compiled_code(tmp_path):
    files = [ROOT / f for f in COMPILED_FILES]
    (tmp_path / "bad").mkdir()
    from observer.engines.compiled import kernel

    copy = tmp_path / "hand_copy.py"                                  # a compiled loop written twice
    copy.write_text(inspect.getsource(kernel._band_cho_solve.py_func).replace("_band_cho_solve", "solve_again"))
    bad = duplicate_pairs([*files, copy], tmp_path / "bad")
    assert any("hand_copy" in row and "kernel.py" in row for row in bad), bad
    (tmp_path / "good").mkdir()
    assert duplicate_pairs(files, tmp_path / "good") == []
