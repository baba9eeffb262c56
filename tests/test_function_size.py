"""No function in ``observer/`` is longer than 80 lines.

A function's length is ``end_lineno − lineno + 1`` of its ``def`` (decorators excluded,
docstring included), for every function and method at any depth. The one exception is a
compiled hot loop (decorated ``@njit`` or ``@jit``) whose docstring says why it is one
function, in a sentence starting with :data:`HOT_LOOP_MARK`.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_LINES = 80
HOT_LOOP_MARK = "One function because"

ALLOWED: set[str] = set()
"""Long functions in files other branches are rewriting; each entry goes when it is split."""


def functions(path: Path, root: Path = ROOT):
    """``(key, lines, node)`` of every function in ``path``; key ``file::Outer.name``."""
    rel = path.relative_to(root).as_posix()

    def walk(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield f"{rel}::{prefix}{child.name}", child.end_lineno - child.lineno + 1, child
                yield from walk(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                yield from walk(child, f"{prefix}{child.name}.")
            else:
                yield from walk(child, prefix)

    yield from walk(ast.parse(path.read_text(encoding="utf-8")), "")


def is_explained_hot_loop(node: ast.FunctionDef) -> bool:
    """Compiled (``njit``/``jit`` decorator) and its docstring says why it is one function."""
    names = {ast.unparse(d.func if isinstance(d, ast.Call) else d).rpartition(".")[2]
             for d in node.decorator_list}
    return bool(names & {"njit", "jit"}) and HOT_LOOP_MARK in (ast.get_docstring(node) or "")


def long_functions(root: Path = ROOT) -> dict[str, int]:
    """Key → length of every function of ``observer/`` over :data:`MAX_LINES` lines that is not
    an explained hot loop."""
    return {key: n for path in sorted((root / "observer").rglob("*.py"))
            for key, n, node in functions(path, root)
            if n > MAX_LINES and not is_explained_hot_loop(node)}


def test_the_measure_counts_nested_functions_and_exempts_only_explained_compiled_loops(tmp_path):
    def body(indent: str, n: int = 80) -> str:
        return "\n".join(f"{indent}x{i} = {i}" for i in range(n))

    (tmp_path / "observer").mkdir()
    (tmp_path / "observer" / "m.py").write_text(
        f"class A:\n    def f(self):\n        def g():\n{body(' ' * 12)}\n        return g\n\n"
        f"@numba.njit(cache=True)\ndef hot():\n    '''{HOT_LOOP_MARK} numba inlines nothing.'''\n"
        f"{body('    ')}\n\n"
        f"@njit\ndef unexplained():\n    '''A loop.'''\n{body('    ')}\n\n"
        f"def plain():\n    '''{HOT_LOOP_MARK} nothing: not compiled.'''\n{body('    ')}\n\n"
        f"def short():\n{body('    ', 79)}\n")
    assert long_functions(tmp_path) == {"observer/m.py::A.f": 83, "observer/m.py::A.f.g": 81,
                                        "observer/m.py::unexplained": 82, "observer/m.py::plain": 82}


def test_no_function_in_observer_is_longer_than_80_lines():
    over = {k: n for k, n in long_functions().items() if k not in ALLOWED}
    assert not over, f"functions over {MAX_LINES} lines (split them): {over}"


def test_the_allow_list_holds_only_functions_still_too_long():
    stale = ALLOWED - set(long_functions())
    assert not stale, f"no longer over {MAX_LINES} lines (or gone): delete from ALLOWED: {sorted(stale)}"
