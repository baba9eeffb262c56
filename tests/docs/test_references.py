"""Nitpicky for real (issue 35): the packages' own cross-references resolve, none is ignored.

``docs/conf.py``'s ``nitpick_ignore_regex`` may list objects of other packages only (no
network here, so no intersphinx inventories); every module of the packages has a page in the
developer API (``docs/api/internals.rst``); the documentation extension resolves a name as
Python reads it where the docstring stands, and nothing else. Cheap: no Sphinx build.
"""

from __future__ import annotations

import importlib
import pkgutil
import re
import runpy
import sys
from pathlib import Path

import pytest

import observer
import proofs_checks

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
sys.path.insert(0, str(DOCS / "_ext"))

import observer_api  # noqa: E402  (the documentation's own Sphinx extension)

PACKAGES = (observer, proofs_checks)


def _modules() -> list[str]:
    names = []
    for package in PACKAGES:
        names.append(package.__name__)
        names += [m.name for m in pkgutil.walk_packages(package.__path__, package.__name__ + ".")
                  if not m.name.endswith("__main__")]
    return sorted(names)


def _own_names() -> list[str]:
    """Real names of the packages as a docstring may write them: each module; each public
    name, qualified by its package, by its defining module, bare, and with one member; each
    name a module defines, qualified and bare."""
    names = set()
    for modname in _modules():
        module = importlib.import_module(modname)
        names.add(modname)
        names.add(modname.rpartition(".")[2])
        for name, obj in vars(module).items():
            if name.startswith("__"):
                continue
            names |= {f"{modname}.{name}", name}
            for member in list(vars(obj))[:40] if isinstance(obj, type) else []:
                if not member.startswith("__"):
                    names |= {f"{modname}.{name}.{member}", f"{name}.{member}"}
    for package in PACKAGES:
        names |= {f"{package.__name__}.{n}" for n in package.__all__}
    return sorted(names)


def _ignored(patterns, name: str, kind: str = "py:func") -> list[str]:
    """The patterns that ignore a missing reference ``kind`` to ``name`` (Sphinx fullmatches)."""
    return [target for role, target in patterns if re.fullmatch(role, kind) and re.fullmatch(target, name)]


@pytest.fixture(scope="module")
def conf() -> dict:
    return runpy.run_path(str(DOCS / "conf.py"))


def test_the_ignore_check_catches_a_pattern_over_own_names():
    """Near misses of an external-only list: a catch-all of bare names and a namespace list
    that slipped in one of the packages are both caught."""
    own = _own_names()
    assert len(own) > 1000 and "observer.engines.loop.FiniteGuard" in own and "SCHEMA" in own
    bad = [[(r"py:.*", r"[A-Za-z_]\w*(\.\w+)?")],
           [(r"py:.*", rf"{p}\..+") for p in ("numpy", "pandas", "proofs_checks")],
           [(r"py:.*", r"(Any|Path|Scenario)")]]
    for patterns in bad:
        assert any(_ignored(patterns, name) for name in own), patterns


def test_nitpick_ignores_name_external_objects_only(conf):
    patterns = conf["nitpick_ignore_regex"]
    assert conf["nitpicky"] is True
    hits = {name: _ignored(patterns, name) for name in _own_names()}
    hits = {name: p for name, p in hits.items() if p}
    assert not hits, f"nitpick_ignore_regex hides names of the packages: {sorted(hits.items())[:20]}"
    for external in ("pandas.DataFrame", "scipy.stats.ecdf", "numpy.ndarray", "pathlib.Path"):
        assert _ignored(patterns, external, "py:class"), external
    assert not conf.get("nitpick_ignore"), "external names go in nitpick_ignore_regex, one per entry"


def test_every_module_has_a_page():
    """A module of the packages is a public page (``observer``, ``proofs_checks``) or one line
    of ``docs/api/internals.rst``, exactly once; the page lists no module that is not there."""
    listed = observer_api.internal_modules()
    assert len(listed) == len(set(listed)), "a module is listed twice in docs/api/internals.rst"
    expected = set(_modules()) - {"observer", "proofs_checks"}
    missing = sorted(expected - set(listed))
    assert not missing, ("modules without a page: add each to an ``internal-modules`` block of "
                         f"docs/api/internals.rst: {missing}")
    assert not sorted(set(listed) - expected), "docs/api/internals.rst lists modules that do not exist"


def test_internal_pages_leave_re_exports_to_the_public_pages_and_show_referenced_names():
    public = observer_api._public_objects()
    model = dict((name, kind) for kind, name in observer_api.module_members("observer.model", public))
    assert "Harmonic" not in model and "LinearSystem" not in model      # observer.Harmonic's page
    assert "grid_wave" in model                                         # not public: here
    scenario = observer_api.internal_page("observer.scenario", public, set(observer_api.public_names()))
    assert ".. autodata:: SCHEMA" in scenario        # no comment of its own, but docstrings cite it
    assert ":no-index:" not in scenario
    simulate = observer_api.internal_page("observer.simulate", public, set(observer_api.public_names()))
    assert ":no-index:" in simulate                  # observer.simulate is the function's name
    assert ".. autofunction:: simulate" not in simulate


@pytest.mark.parametrize("target, where, expected", [
    ("InputError", "observer.scenario", observer.InputError),                 # imported there
    ("observer.engines.ENGINES", None, observer.ENGINES),                     # a re-export
    ("SchemeMatrices.build", "observer.stepping", None),                      # a member (below)
    ("NoSuchName", "observer.scenario", None),
    ("InputError", "proofs_checks.pieces", None),                             # not imported there
])
def test_names_are_read_as_python_reads_them_where_the_docstring_stands(target, where, expected):
    scopes = observer_api._scopes(where, None, None)
    obj, _ = observer_api._lookup(target, scopes)
    if target == "SchemeMatrices.build":
        from observer.stepping import SchemeMatrices
        assert observer_api._same(obj, SchemeMatrices.build)
    elif expected is None:
        assert obj is observer_api._MISSING
    else:
        assert obj is expected


def test_bars_are_escaped_outside_literals_roles_and_literal_blocks():
    lines = ["|A|³ per step, ``|x|`` and :math:`|y|`; |g| ≤ tol::", "", "    a | b", "",
             ">>> 1 | 2", "after |t|"]
    observer_api.escape_bars(None, "function", "f", None, {}, lines)
    assert lines == [r"\|A\|³ per step, ``|x|`` and :math:`|y|`; \|g\| ≤ tol::", "", "    a | b", "",
                     ">>> 1 | 2", r"after \|t\|"]


def test_a_constant_shows_its_own_documentation_not_its_types():
    lines = ["Built-in immutable sequence.", "", "If no argument is given, ..."]
    observer_api.drop_type_docstring(None, "data", "REQUIRED", ("a", "b"), {}, lines)
    assert lines == []
    own = ["The fields a scenario must set (a tuple)."]                    # its own comment stays
    observer_api.drop_type_docstring(None, "data", "REQUIRED", ("a", "b"), {}, own)
    assert own == ["The fields a scenario must set (a tuple)."]
