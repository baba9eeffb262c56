"""The documentation stays true to the code (issue 35).

Cheap checks of the sources (no build): every public name has a docstring and a page, every
CLI subcommand a help text and a reference, the TOML reference lists exactly the validator's
fields, no file cites a file that is not in the repository, the README stays a front door.
The built site (``nox -s docs``, run by ``.ci/run`` before the tests) is opened in headless
Chromium and every internal link of it is resolved.
"""

from __future__ import annotations

import ast
import io
import os
import re
import subprocess
import sys
import tokenize
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

import observer
import proofs_checks

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
SITE = DOCS / "_build" / "html"
sys.path.insert(0, str(DOCS / "_ext"))

import observer_docs  # noqa: E402  (the documentation's own Sphinx extension)


def _api_sources() -> str:
    return "\n".join(p.read_text(encoding="utf-8") for p in sorted((DOCS / "api").glob("*.rst")))


def _listed(source: str) -> set[str]:
    """Names listed in the autosummary tables of the API pages (indented single words)."""
    return set(re.findall(r"^   ([A-Za-z_][\w]*)\s*$", source, flags=re.M))


@pytest.mark.parametrize("package", [observer, proofs_checks], ids=lambda m: m.__name__)
def test_every_public_name_has_a_docstring_and_an_api_page(package):
    source = _api_sources()
    assert f".. currentmodule:: {package.__name__}" in source
    page = (DOCS / "api" / f"{package.__name__}.rst").read_text(encoding="utf-8")
    listed = _listed(page)
    missing = [n for n in package.__all__ if n not in listed]
    assert not missing, f"public names of {package.__name__} without an API page entry: {missing}"
    unknown = sorted(listed - set(package.__all__))
    assert not unknown, f"API page of {package.__name__} lists names it does not export: {unknown}"
    for name in package.__all__:
        obj = getattr(package, name)
        if callable(obj) and not isinstance(obj, dict):
            assert (obj.__doc__ or "").strip(), f"{package.__name__}.{name} has no docstring"
    registries = [n for n in package.__all__ if isinstance(getattr(package, n), dict)]
    for name in registries:           # data: documented by the attribute docstring in its module
        assert name.isupper()


@pytest.mark.parametrize("module", ["observer.cli", "proofs_checks.cli"])
def test_every_cli_subcommand_has_help_and_a_reference(module):
    assert f".. cli-reference:: {module}" in (DOCS / "cli" / "index.rst").read_text(encoding="utf-8")
    subs = observer_docs.cli_subcommands(module)
    import argparse, importlib
    parser = importlib.import_module(module).build_parser()
    helps = {}
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
    for name in subs:
        assert (helps.get(name) or "").strip(), f"{module} subcommand {name!r} has no help text"
    if module == "observer.cli":
        assert {"scenarios", "show", "run", "ensemble", "log", "plot"} <= set(subs)


def test_toml_reference_lists_exactly_the_fields_the_validator_accepts():
    from observer.scenario import REQUIRED, SCHEMA, check_keys
    rows = observer_docs.toml_reference_rows()
    documented = {(t, f) for t, f, *_ in rows}
    # the fields check_keys accepts, found by walking the schema independently of schema_fields
    accepted = set()

    def walk(schema, table):
        for key, sub in schema.items():
            if sub is None:
                accepted.add((f"[{table}]", key))
            elif isinstance(sub, list):
                for k in sub[0]:
                    accepted.add((f"[[{table}.{key}]]", k))
            else:
                walk(sub, f"{table}.{key}" if table else key)
    walk(SCHEMA, "")
    assert documented == accepted
    defaults = {f"{t.strip('[]')}.{f}": d for t, f, _, _, d, _ in rows}
    assert {k for k, d in defaults.items() if d == "required"} == set(REQUIRED)
    # every documented field is accepted by the validator, a field not documented is refused
    for table, field, *_ in rows:
        path = table.strip("[]").split(".")
        doc: dict = {}
        node = doc
        for part in path[:-1]:
            node = node.setdefault(part, {})
        leaf = {field: 1.0}
        node[path[-1]] = [leaf] if table.startswith("[[") else leaf
        check_keys(doc, SCHEMA)
    with pytest.raises(observer.InputError, match="simulation.dt"):
        check_keys({"simulation": {"dt": 1.0}}, SCHEMA)


def test_toml_reference_refuses_an_undocumented_field(monkeypatch):
    from sphinx.errors import ExtensionError

    import observer.scenario as scenario
    fields = dict(scenario.FIELDS)
    del fields["simulation.theta"]
    monkeypatch.setattr(scenario, "FIELDS", fields)
    with pytest.raises(ExtensionError, match="simulation.theta"):
        observer_docs.toml_reference_rows()


def _tracked_files() -> list[Path]:
    out = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True)
    if out.returncode != 0:
        pytest.skip("not a git checkout")
    return [REPO / f for f in out.stdout.splitlines() if (REPO / f).is_file()]


PLACEHOLDER = re.compile(r"/(?:[A-Z_]+|[a-zA-Z])\.\w+$|/[A-Z_]+/|my_system\.toml$")
"""Paths that stand for a family (``tests/mutants/MODULE.md``, ``examples/X.py``) or a user's
own file in a usage example."""
TEXT_SUFFIXES = {".py", ".md", ".rst", ".toml", ".txt", ".html", ".j2", ".cfg", ".yml", ".yaml"}
OUTSIDE_NOTES = "THEO" + "RY"          # the internal notes the project must not cite
CITED_PATH = re.compile(r"(?<![\w/.])((?:docs|tests|observer|proofs_checks|bench|reports|examples)"
                        r"/[\w/.-]*\w\.(?:md|rst|py|toml))\b")


def test_no_file_cites_the_outside_notes_or_a_missing_file():
    outside, missing = [], []
    files = _tracked_files()
    tracked = {f.relative_to(REPO).as_posix() for f in files}
    for f in files:
        if f.suffix not in TEXT_SUFFIXES:
            continue
        text = f.read_text(encoding="utf-8", errors="replace")
        rel = f.relative_to(REPO).as_posix()
        if re.search(OUTSIDE_NOTES + r"(\.md)?\s*§|" + OUTSIDE_NOTES + r"\.md", text):
            outside.append(rel)
        for match in CITED_PATH.finditer(text):
            cited = match.group(1)
            before = text[max(0, match.start() - 12):match.start()]
            if "formerly" in before or PLACEHOLDER.search(cited) or "*" in cited:
                continue                   # a former name, or a pattern such as tests/mutants/MODULE.md
            if not any((base / cited).exists() for base in (REPO, REPO / "tests")):
                missing.append(f"{rel}: {cited}")
    assert not outside, f"files citing notes that are not in the repository: {outside}"
    assert not missing, "files citing paths that are not in the repository:\n" + "\n".join(missing)


MACHINE_TIMING = re.compile(
    r"\d[\d.]*\s?(?:ns|µs|μs)\b"                                  # a machine's scale, not a system's
    r"|\d[\d.]*\s?(?:ns|µs|μs|ms)\s?(?:/|per\s)\s?(?:step|call|point|impulse|contact|observer)"
    r"|\d[\d.]*\s?[×x]\s+(?:faster|slower)|\d\s?%\s+(?:faster|slower)"
    r"|\d[\d.]*\s?(?:ms|s|min|h)\s+(?:of\s+)?(?:wall|CPU)\b"     # "116 s wall", "55 s of CPU"
    r"|\d\s?min\s+\d+\s?s\b"                                # "2 min 48 s"
    r"|\bat\s+load\s+\d|\bload\s+\d+(?:\.\d+)?\s?[–-]\s?\d"  # "at load 9", "load 9–11"
    r"|\b(?:took|takes)\s+(?:~|about\s+)?\d[\d.]*\s?(?:ms|s|min)\b")
"""Machine timings in prose: time per step or call, speed-ups, wall or CPU seconds, a run's
duration, the load it ran at. Times of a simulated system (``t_end``, impact times, "within
9 ms of the first impact") do not match: they are seconds of the model, not of the machine."""
TIMED_TREES = ("observer", "proofs_checks", "bench", "reports")


def machine_timings(source: str) -> list[tuple[int, str]]:
    """(line, text) of every machine timing in the docstrings and comments of ``source``."""
    found = []
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            found += [(tok.start[0], m.group(0)) for m in MACHINE_TIMING.finditer(tok.string)]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc is None:
                continue
            start = node.body[0].lineno
            found += [(start + doc.count("\n", 0, m.start()), m.group(0))
                      for m in MACHINE_TIMING.finditer(doc)]
    for node in ast.walk(ast.parse(source)):               # attribute docstrings (``X = 1`` then a string)
        body = getattr(node, "body", None)
        if not isinstance(body, list):
            continue
        for prev, stmt in zip(body, body[1:]):
            if (isinstance(prev, (ast.Assign, ast.AnnAssign)) and isinstance(stmt, ast.Expr)
                    and isinstance(stmt.value, ast.Constant) and isinstance(stmt.value.value, str)):
                doc = stmt.value.value
                found += [(stmt.lineno + doc.count("\n", 0, m.start()), m.group(0))
                          for m in MACHINE_TIMING.finditer(doc)]
    return sorted(found)


def test_the_timing_scan_finds_machine_timings_and_not_the_models_times():
    bad = ('"""One call: 114 → 67 ns per call; 4-6× slower; 55 s of CPU\n(116 s wall at load 7.7–8.0)."""\n'
           'X = 1\n"""Measured: 2.9 µs per step."""\n'
           'def f():\n    """The report took 2 min 48 s."""\n    return 1  # ~190 ns of 240\n')
    assert [line for line, _ in machine_timings(bad)] == [1, 1, 1, 2, 2, 4, 6, 7]
    good = ('"""Impacts accumulate within 9 ms of the first one; t_end = 60 s; h = 1e-3 s per step;\n'
            'the loop is 1.5× the Delassus matrix; 10 s at h = 2e-4."""\n# first 10 s: 2.2e-3\n')
    assert machine_timings(good) == []


def test_no_docstring_or_comment_quotes_a_machine_timing():
    """Issue 35: a timing in prose is true on one machine at one load; no test keeps it. The
    stored benchmark results and the report carry the measurements, with their machine."""
    hits = []
    for tree in TIMED_TREES:
        for f in sorted((REPO / tree).rglob("*.py")):
            rel = f.relative_to(REPO).as_posix()
            hits += [f"{rel}:{line}: {text}" for line, text in machine_timings(f.read_text(encoding="utf-8"))]
    assert not hits, "machine timings in docstrings or comments:\n" + "\n".join(hits)


def test_readme_is_a_front_door():
    lines = (REPO / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 150
    text = "\n".join(lines)
    assert "python3 -m pip install nox && python3 -m nox -s report" in text
    assert "python3 -m nox -s tests" in text
    for image in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        assert (REPO / image).is_file(), image


# ---------------------------------------------------------------------------------------
# the built site
# ---------------------------------------------------------------------------------------
def _site() -> Path:
    if not (SITE / "index.html").is_file():
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("CI: the documentation must be built first (python3 -m nox -s docs)")
        pytest.skip("docs/_build/html is absent: build it with `python3 -m nox -s docs`")
    return SITE


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        for key, value in attrs:
            if key == "id" and value:
                self.ids.add(value)
            if key in ("href", "src") and value and tag in ("a", "link", "img", "script"):
                self.links.append(value)


def _parse(path: Path, cache: dict) -> _Links:
    """The links and ids of a page, each page parsed once."""
    if path not in cache:
        cache[path] = _Links()
        cache[path].feed(path.read_text(encoding="utf-8", errors="replace"))
    return cache[path]


def test_every_internal_link_of_the_site_resolves():
    site = _site()
    pages = {p.resolve(): None for p in site.rglob("*.html")}
    parsed: dict[Path, _Links] = {}
    bad = []
    for page in pages:
        links = _parse(page, parsed).links
        for link in links:
            parts = urlsplit(link)
            if parts.scheme or parts.netloc or link.startswith(("mailto:", "javascript:", "data:")):
                continue
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.exists():
                bad.append(f"{page.relative_to(site)} -> {link}")
                continue
            if parts.fragment and target.suffix == ".html":
                ids = _parse(target, parsed).ids
                if unquote(parts.fragment) not in ids:
                    bad.append(f"{page.relative_to(site)} -> {link} (no such anchor)")
    assert len(pages) > 20
    assert not bad, f"{len(bad)} broken internal links:\n" + "\n".join(bad[:40])


@pytest.mark.parametrize("page", ["index.html", "api/generated/observer.simulate.html"])
def test_site_pages_open_in_chromium_without_console_errors(page, tmp_path):
    from reports.browser import check_page, find_chromium
    site = _site()
    if find_chromium() is None:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("CI: chromium is needed for the documentation's browser check")
        pytest.skip("no chromium installed")
    shot = tmp_path / (Path(page).stem + ".png")
    result = check_page(site / page, shot, height=1600)
    assert result.screenshot is not None and shot.stat().st_size > 10_000
    assert not result.console_errors, result.console_errors
