"""The packages' import graph: no cycles, and every import points down the layers.

The graph is read statically: every module of ``observer``, ``proofs_checks``, ``bench`` and
``reports`` is parsed with :mod:`ast`, and each ``import`` and ``from ... import`` of these
packages, absolute or relative, is an edge, **including the imports inside functions** (a
deferred import is still a dependency, and it is how a cycle hides). ``from pkg import name``
is an edge to the submodule ``pkg.name`` when it is one, else to ``pkg`` (its
``__init__``). Imports under ``if TYPE_CHECKING:`` are for type checkers only and are not
edges.

Layer rules (README, "Layout"):

1. No import cycle among the modules of the four packages.
2. The packages import one way, ``observer ◄ proofs_checks ◄ bench ◄ reports``: a module
   never imports a package to its right.
3. Inside ``observer``, the model (:data:`MODEL`: ``errors``, ``validation``, ``model``,
   ``impact``, ``tomlio``, ``solver_registry``, ``scenario``, ``scenarios/``, ``closed_form``)
   does not import the contact solvers (``observer.contact``), not even through another
   module: the solver registry's names are in :mod:`observer.solver_registry`.
4. A command line (``cli``, ``__main__``) is imported only by its own package: what the
   command lines share is in :mod:`observer.cli_common`.
5. The report reads result rows only: no module of ``reports`` imports ``bench`` (the
   storage's reading side and the rows' schema are :mod:`observer.results_io` and
   :mod:`observer.row_schema`). :data:`REPORTS_STILL_IMPORTING_BENCH` lists the modules not
   yet moved off it, each to be deleted from the list when it is.
"""

from __future__ import annotations

import ast
from collections import deque
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("observer", "proofs_checks", "bench", "reports")
"""Lowest layer first: a package may import those to its left only."""

MODEL = ("observer.errors", "observer.sparse", "observer.validation", "observer.model", "observer.impact",
         "observer.tomlio", "observer.solver_registry", "observer.scenario", "observer.scenarios",
         "observer.closed_form")
"""The model layer of ``observer`` (a name covers its submodules)."""

SOLVERS = "observer.contact"
CLI_NAMES = ("cli", "__main__")

ALLOWED_CYCLE_EDGES: set[tuple[str, str]] = set()
"""Edges left out of the cycle search, each to be deleted when its cycle is broken."""

REPORTS_STILL_IMPORTING_BENCH: frozenset[str] = frozenset()
"""Report modules that still import ``bench``, each to be deleted when what it reads is
written by bench into the results (empty since issue 32, item 3: the peers section reads
Siconos' availability from the suite's metadata)."""


def module_files(root: Path, packages=PACKAGES) -> dict[str, Path]:
    """Dotted module name → file, for every ``.py`` under the packages."""
    out = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _type_checking_only(tree: ast.AST) -> set[int]:
    """ids of the import nodes under ``if TYPE_CHECKING:``."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and ast.unparse(node.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING"):
            skip |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return skip


def _owner(name: str, modules: dict) -> str | None:
    """The longest prefix of ``name`` that is a module (``a.b.C`` → ``a.b``)."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def _targets(module: str, node: ast.AST, modules: dict, packages) -> list[str]:
    if isinstance(node, ast.Import):
        return [t for a in node.names if (t := _owner(a.name, modules))]
    if node.level:
        base = module.split(".")
        if modules[module].name != "__init__.py":
            base = base[:-1]
        base = base[:len(base) - node.level + 1] + ([node.module] if node.module else [])
        base = ".".join(base)
    else:
        base = node.module or ""
    if base.split(".")[0] not in packages:
        return []
    return [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else _owner(base, modules)
            for a in node.names]


def import_graph(root: Path = ROOT, packages=PACKAGES) -> dict[str, dict[str, int]]:
    """module → {imported module: line of the first such import}, within ``packages``."""
    modules = module_files(root, packages)
    graph = {}
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        skip = _type_checking_only(tree)
        deps: dict[str, int] = {}
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in skip:
                for target in _targets(module, node, modules, packages):
                    if target and target != module:
                        deps.setdefault(target, node.lineno)
        graph[module] = deps
    return graph


def find_cycle(graph: dict[str, dict[str, int]], ignore=frozenset()) -> list[str] | None:
    """One import cycle ``[a, b, ..., a]`` of ``graph`` without the ``ignore`` edges, or None."""
    edges = {a: sorted(b for b in deps if (a, b) not in ignore) for a, deps in graph.items()}
    state: dict[str, int] = {}                      # 1: on the path, 2: done
    for start in sorted(edges):
        if start in state:
            continue
        path, stack = [start], [iter(edges[start])]
        state[start] = 1
        while stack:
            nxt = next(stack[-1], None)
            if nxt is None:
                state[path.pop()] = 2
                stack.pop()
            elif state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            elif nxt not in state and nxt in edges:
                state[nxt] = 1
                path.append(nxt)
                stack.append(iter(edges[nxt]))
    return None


def reachable(graph: dict[str, dict[str, int]], start: str) -> dict[str, str]:
    """Modules reachable from ``start`` → the module that imports each on a shortest path."""
    parent, todo = {start: ""}, deque([start])
    while todo:
        a = todo.popleft()
        for b in graph.get(a, {}):
            if b not in parent:
                parent[b] = a
                todo.append(b)
    return parent


def _chain(parent: dict[str, str], end: str) -> str:
    out = [end]
    while parent[out[-1]]:
        out.append(parent[out[-1]])
    return " → ".join(reversed(out))


def _within(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def _describe(graph, cycle: list[str]) -> str:
    return " → ".join(f"{a} (line {graph[a][b]})" for a, b in zip(cycle, cycle[1:])) + f" → {cycle[-1]}"


@pytest.fixture(scope="module")
def graph() -> dict[str, dict[str, int]]:
    return import_graph()


def test_walker_sees_deferred_and_relative_imports_and_finds_their_cycle(tmp_path):
    pkg = tmp_path / "observer"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                              "    from observer import c\n"
                              "def f():\n    from .sub import b\n    return b\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "b.py").write_text("import numpy\nfrom ..a import f\n")
    (pkg / "c.py").write_text("import observer.a\n")
    g = import_graph(tmp_path, ("observer",))
    assert g["observer.a"] == {"observer.sub.b": 5}           # deferred, relative; not c
    assert g["observer.sub.b"] == {"observer.a": 2}           # two levels up; numpy ignored
    assert g["observer.c"] == {"observer.a": 1}
    assert find_cycle(g) in (["observer.a", "observer.sub.b", "observer.a"],
                             ["observer.sub.b", "observer.a", "observer.sub.b"])
    assert find_cycle(g, {("observer.sub.b", "observer.a")}) is None


def test_no_import_cycles(graph):
    cycle = find_cycle(graph, ALLOWED_CYCLE_EDGES)
    assert cycle is None, f"import cycle: {_describe(graph, cycle)}"


def test_allowed_cycle_edges_still_exist_and_still_close_a_cycle(graph):
    for a, b in ALLOWED_CYCLE_EDGES:
        assert b in graph.get(a, {}), f"{a} → {b} is gone: delete it from ALLOWED_CYCLE_EDGES"
        assert a in reachable(graph, b), f"{a} → {b} closes no cycle: delete it from ALLOWED_CYCLE_EDGES"


def test_packages_import_one_way(graph):
    rank = {p: i for i, p in enumerate(PACKAGES)}
    bad = [f"{a} → {b} (line {line})" for a, deps in graph.items() for b, line in deps.items()
           if rank[b.split(".")[0]] > rank[a.split(".")[0]]]
    assert not bad, "imports of a higher layer (observer ◄ proofs_checks ◄ bench ◄ reports):\n" + "\n".join(bad)


def test_model_does_not_import_the_contact_solvers(graph):
    model = [m for m in graph if any(_within(m, p) for p in MODEL)]
    assert "observer.model" in model and "observer.scenarios.bouncing_ball" in model
    bad = []
    for m in model:
        parent = reachable(graph, m)
        bad += [_chain(parent, s) for s in parent if _within(s, SOLVERS)]
    assert not bad, "the model reaches the contact solvers:\n" + "\n".join(bad)


def test_command_lines_are_imported_only_by_their_own_package(graph):
    clis = [m for m in graph if m.rpartition(".")[2] in CLI_NAMES]
    assert {"observer.cli", "proofs_checks.cli", "bench.__main__"} <= set(clis)
    bad = [f"{a} → {b} (line {graph[a][b]})" for a in graph for b in graph[a]
           if b in clis and a.split(".")[0] != b.split(".")[0]]
    assert not bad, "a command line imports another package's:\n" + "\n".join(bad)


def _reports_importing_bench(graph) -> dict[str, list[str]]:
    """Module of ``reports`` → its imports of ``bench`` (``"bench.x (line n)"``)."""
    out: dict[str, list[str]] = {}
    for a, deps in graph.items():
        if _within(a, "reports"):
            hits = [f"{b} (line {line})" for b, line in deps.items() if _within(b, "bench")]
            if hits:
                out[a] = hits
    return out


def test_walker_finds_a_report_module_importing_bench_even_deferred(tmp_path):
    for pkg in ("bench", "reports"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "bench" / "suites.py").write_text("BAND = 1\n")
    (tmp_path / "reports" / "ok.py").write_text("import json\nfrom reports import bad\n")
    (tmp_path / "reports" / "bad.py").write_text("def f():\n    from bench.suites import BAND\n    return BAND\n")
    g = import_graph(tmp_path, ("bench", "reports"))
    assert _reports_importing_bench(g) == {"reports.bad": ["bench.suites (line 2)"]}


def test_reports_do_not_import_bench(graph):
    found = _reports_importing_bench(graph)
    bad = [f"{a} → {', '.join(hits)}" for a, hits in sorted(found.items())
           if a not in REPORTS_STILL_IMPORTING_BENCH]
    assert not bad, ("a report module imports bench (the report reads result rows only: "
                     "observer.results_io, observer.row_schema):\n" + "\n".join(bad))


def test_reports_still_importing_bench_still_do(graph):
    found = _reports_importing_bench(graph)
    assert REPORTS_STILL_IMPORTING_BENCH <= set(graph), "a listed report module no longer exists"
    gone = sorted(REPORTS_STILL_IMPORTING_BENCH - set(found))
    assert not gone, f"no longer import bench: delete from REPORTS_STILL_IMPORTING_BENCH: {gone}"
