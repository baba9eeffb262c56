"""Compiled functions generated from source templates: one written source, several compiled places.

A compiled step loop calls no function with array arguments per step (each is a call with
every array's fields passed and, unless numba prunes them, a reference count per array), so
a piece of the step that several loops and a stand-alone function need is written once as a
**fragment** — a statement block with placeholders — and placed by :func:`fill` into each
loop's source and into the function's (:func:`compile_function`), as numba users and pandas'
generated kernels do. An inline ``$NAME`` is replaced by an expression, a line that is only
``$NAME`` by a statement block at that line's indentation.

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
        out.append(re.sub(r"\$([A-Z_0-9]+)", lambda mt: values[mt.group(1)], line))
    return "\n".join(out)


def compile_function(name: str, source: str, namespace: dict, filename: str, options: dict):
    """The function ``name`` defined by ``source``, compiled by :func:`numba.njit` with
    ``options`` (:data:`observer.primitives.JIT`) in the globals ``namespace`` (copied), its
    code object named after ``filename`` (the template's file: numba's disk cache needs a
    real file)."""
    scope = dict(namespace)
    GENERATED[f"{scope.get('__name__', '')}.{name}"] = source
    exec(compile(source, filename, "exec"), scope)        # noqa: S102 (the package's own templates)
    return njit(**options)(scope[name])
