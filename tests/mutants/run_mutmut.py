"""Run mutmut with numba's ``@njit`` allowed as a decorator (``python run_mutmut.py run ...``).

mutmut 3 does not mutate decorated functions (it keeps the decorators on its trampoline and
on every mutated copy, and a decorator such as ``@app.post("/x")`` may act when it runs
more than once). Every function of :mod:`observer.kernel` is decorated ``@njit(**JIT)``
(sometimes with ``inline="always"``), so none would be mutated. Under
``NUMBA_DISABLE_JIT=1`` numba's ``njit(...)`` returns the plain Python function, so the
trampoline, the original copy and the mutated copies all stay plain functions and the
decorator is harmless. This wrapper (the approach of boxed/mutmut#387) replaces mutmut's
"skip decorated functions" rule by one that lets through a function whose decorators are
all in :data:`ALLOWED_DECORATORS` — ``njit`` or ``njit(...)``, nothing else — and applies
every other skip rule of mutmut unchanged (pragmas, never-mutated names, defaults,
annotations; the decorator's own arguments are still never mutated). It sets
``NUMBA_DISABLE_JIT=1`` before mutmut (and so numba) is imported: a trampoline cannot be
compiled. mutmut forks its workers, so the patch reaches them.
"""

from __future__ import annotations

import os
import sys

os.environ["NUMBA_DISABLE_JIT"] = "1"

import libcst as cst  # noqa: E402
from libcst.metadata import PositionProvider  # noqa: E402
from mutmut.mutation import file_mutation  # noqa: E402

ALLOWED_DECORATORS = frozenset({"njit"})


def _allowed(decorator: cst.Decorator) -> bool:
    d = decorator.decorator
    if isinstance(d, cst.Call):
        d = d.func
    return isinstance(d, cst.Name) and d.value in ALLOWED_DECORATORS


_original_skip = file_mutation.MutationVisitor._skip_node_and_children


def _skip_node_and_children(self, node: cst.CSTNode) -> bool:
    if isinstance(node, cst.FunctionDef) and node.decorators and all(map(_allowed, node.decorators)):
        # the position rules need the node itself (metadata is keyed by node): a pragma
        # "no mutate" on the def line still skips it
        position = self.get_metadata(PositionProvider, node, None)
        if position and position.start.line in self._ignored_node_lines:
            return _original_skip(self, node)
        # every other rule, judged on the function without its (allowed) decorators
        return _original_skip(self, node.with_changes(decorators=[]))
    return _original_skip(self, node)


file_mutation.MutationVisitor._skip_node_and_children = _skip_node_and_children

if __name__ == "__main__":
    from mutmut.__main__ import cli

    sys.argv[0] = "mutmut"
    sys.exit(cli())
