"""Structure of reports/: small functions, no hard-coded designs or solvers, no simulation
imports, and a complete, ordered section registry (checked on the source with ``ast``)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from observer.contact import CONTACT_SOLVERS
from observer.observers import OBSERVER_DESIGNS

REPO = Path(__file__).resolve().parents[2]
REPORTS = REPO / "reports"
MAX_LINES = 80


def _modules() -> list[Path]:
    files = sorted(REPORTS.rglob("*.py"))
    assert len(files) >= 15                                   # the sections are found
    return files


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _docstrings(tree: ast.Module) -> set[int]:
    """ids of the string constants that are docstrings (module, class, function)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                out.add(id(body[0].value))
    return out


def test_no_function_in_reports_is_longer_than_80_lines():
    long = []
    for path in _modules():
        for node in ast.walk(_tree(path)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_LINES:
                    long.append(f"{path.relative_to(REPO)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, long


def test_the_line_count_check_sees_a_long_function(tmp_path):
    """The check is not vacuous: an 81-line function is measured as 81 lines."""
    src = "def f():\n" + "    x = 1\n" * 79 + "    return x\n"
    node = ast.parse(src).body[0]
    assert node.end_lineno - node.lineno + 1 == MAX_LINES + 1


@pytest.mark.parametrize("names", [tuple(OBSERVER_DESIGNS),
                                   tuple(s for s in CONTACT_SOLVERS if s != "reference")],
                         ids=["observer designs", "fast contact solvers"])
def test_reports_code_names_no_registered_design_or_solver(names):
    """Designs and solvers come from the registries: no string literal in reports/ code (outside
    docstrings and reports/registry.py, the one adapter) is a registered design or fast solver
    ("reference" is also the name of the work-precision reference column, so it is not checked)."""
    hits = []
    for path in _modules():
        if path.name == "registry.py":
            continue
        tree = _tree(path)
        docs = _docstrings(tree)
        for node in ast.walk(tree):
            if (isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
                    and node.value in names):
                hits.append(f"{path.relative_to(REPO)}:{node.lineno} {node.value!r}")
    assert not hits, hits


def _imports(tree: ast.Module) -> set[str]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            out |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
    return out


def test_reports_never_imports_the_simulation_runners():
    bad = [str(p.relative_to(REPO)) for p in _modules()
           if any(m == "bench.runners" or m.startswith("bench.runners.") for m in _imports(_tree(p)))]
    assert not bad, bad
    code = ("import sys, reports.build, reports.sections, reports.analysis, reports.figures; "
            "sys.exit(int('bench.runners' in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr or "bench.runners was imported"


def test_reports_read_benchmark_storage_in_one_function():
    """Only reports/context.py imports the results loader (observer.results_io), for load_rows."""
    users = []
    for path in _modules():
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.ImportFrom) and node.module in ("bench.results", "observer.results_io") and \
                    any(a.name.startswith("load") for a in node.names):
                users.append(str(path.relative_to(REPO)))
    assert users == ["reports/context.py"]


def test_section_registry_is_complete_ordered_and_unique():
    """Every module of reports/sections has exactly one registry entry (and a TITLE); ids are
    unique; the claims come first on the page, then the key numbers."""
    import importlib

    from reports.sections import SECTIONS

    modules = {p.stem for p in (REPORTS / "sections").glob("*.py") if p.stem != "__init__"}
    registered = {spec.build.__module__.rsplit(".", 1)[1] for spec in SECTIONS}
    assert registered == modules
    ids = [spec.id for spec in SECTIONS]
    assert len(set(ids)) == len(ids) and ids[:2] == ["claims", "key-numbers"]
    for name in modules:
        assert importlib.import_module(f"reports.sections.{name}").TITLE


def test_after_others_sections_are_built_last_but_keep_their_place():
    from reports.blocks import Section
    from reports.sections import SectionSpec, build_sections

    calls = []

    def maker(sid):
        def build(ctx):
            calls.append(sid)
            ctx.append(sid)
            return Section(sid, sid.upper())
        return build

    ctx: list = []
    specs = (SectionSpec("summary", maker("summary"), after_others=True),
             SectionSpec("a", maker("a")), SectionSpec("b", maker("b")))
    out = build_sections(ctx, specs)
    assert calls == ["a", "b", "summary"]
    assert [s.id for s in out] == ["summary", "a", "b"]
