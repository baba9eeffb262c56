"""Compiled functions generated from source templates: one written source, several compiled places.

A compiled step loop calls no function with array arguments per step (each is a call with
every array's fields passed and, unless numba prunes them, a reference count per array), so
a piece of the step that several loops and a stand-alone function need is written once as a
**fragment** — a statement block with placeholders — and placed by :func:`fill` into each
loop's source and into the function's (:func:`compile_function`), as numba users and pandas'
generated kernels do. An inline ``$NAME`` is replaced by an expression, a line that is only
``$NAME`` by a statement block at that line's indentation.

A **macro** ``$NAME(a, b)`` is an access the loops spell differently — ``$QS(i)``, system s's
position i, is ``qs[s, i]`` in a loop that keeps the states in an array and ``qr`` in one that
keeps its one state in a register — and is left alone by :func:`fill`: :func:`expand` replaces
every macro of a loop's finished source by the loop's spelling (a format string of the
arguments, or a function of them), so that one fragment yields the array and the scalar form.

The generated source is compiled under the name of the file that holds its template, so that
numba's disk cache (keyed by that file, the function's name and line, and its bytecode) keeps
it across processes.
"""

from __future__ import annotations

import re
import textwrap

from numba import njit


GENERATED: dict[str, str] = {}
"""``module.name`` → the source of every function :func:`compile_function` compiled (what
``inspect.getsource`` cannot give for them; read by ``tests/observer/test_compiled_once.py``)."""


def fill(fragment: str, values: dict) -> str:
    """``fragment`` with its placeholders replaced: a line that is only ``$NAME`` by the block
    ``values[NAME]`` at that line's indentation (an empty block: the line goes), an inline
    ``$NAME`` by the expression ``values[NAME]``. A placeholder without a value raises
    KeyError."""
    out = []
    for line in textwrap.dedent(fragment).strip("\n").splitlines():
        alone = re.fullmatch(r"(\s*)\$([A-Z_0-9]+)\s*", line)
        if alone:
            block = textwrap.dedent(values[alone.group(2)]).strip("\n")
            if block:
                out.append(textwrap.indent(block, alone.group(1)))
            continue
        out.append(re.sub(r"\$([A-Z_0-9]+)(?!\w|\()", lambda mt: values[mt.group(1)], line))
    return "\n".join(out)


def expand(source: str, macros: dict) -> str:
    """``source`` with every macro ``$NAME(arg, ...)`` replaced by ``macros[NAME]``: a format
    string (``"qs[s, {0}]"``) or a function of the arguments' texts (split at the commas
    outside brackets). A macro without a spelling raises KeyError."""
    out, i = [], 0
    for mt in re.finditer(r"\$([A-Z_0-9]+)\(", source):
        if mt.start() < i:
            raise ValueError(f"macro inside a macro's arguments at {source[mt.start():mt.end() + 20]!r}")
        depth, j, args, start = 1, mt.end(), [], mt.end()
        while depth:
            c = source[j]
            if c in "([":
                depth += 1
            elif c in ")]":
                depth -= 1
            if (c == "," and depth == 1) or depth == 0:
                args.append(source[start:j].strip())
                start = j + 1
            j += 1
        spell = macros[mt.group(1)]
        out.append(source[i:mt.start()])
        out.append(spell(*args) if callable(spell) else spell.format(*args))
        i = j
    out.append(source[i:])
    return "".join(out)


def compile_function(name: str, source: str, namespace: dict, filename: str, options: dict):
    """The function ``name`` defined by ``source``, compiled by :func:`numba.njit` with
    ``options`` (:data:`observer.primitives.JIT`) in the globals ``namespace`` (copied), its
    code object named after ``filename`` (the template's file: numba's disk cache needs a
    real file)."""
    scope = dict(namespace)
    GENERATED[f"{scope.get('__name__', '')}.{name}"] = source
    exec(compile(source, filename, "exec"), scope)        # noqa: S102 (the package's own templates)
    return njit(**options)(scope[name])
