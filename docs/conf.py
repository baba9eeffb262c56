"""Sphinx configuration of the observer-toolkit documentation (``nox -s docs``)."""

from __future__ import annotations

import os
import re
import sys
import tempfile
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS / "_ext"))
os.environ.setdefault("MPLBACKEND", "Agg")

import observer  # noqa: E402

project = "observer-toolkit"
author = "the observer-toolkit authors"
copyright = "2026, " + author
release = version = observer.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "observer_docs",
    "observer_api",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "**/GALLERY_HEADER.rst", "auto_examples/*.ipynb",
                    "auto_examples/*.py", "auto_examples/*.zip", "auto_examples/*.json"]
root_doc = "index"
nitpicky = True
suppress_warnings = ["config.cache"]   # the gallery's argv function cannot be pickled
# Nitpicky: every cross-reference of the pages and of the docstrings resolves. The packages'
# own names all do (the public API's pages, the developer API of docs/api/internals.rst, and
# docs/_ext/observer_api.py's resolution of re-exports and module-relative names); what is
# left are objects of other packages, whose inventories cannot be fetched here (no network, so
# no intersphinx). Each entry names one external object or one external package's namespace;
# none may match a name of observer or proofs_checks (tests/docs/test_references.py checks it).
EXTERNAL_NAMESPACES = [
    "numpy", "scipy", "pandas", "numba", "matplotlib", "dask", "distributed", "flint", "cvxpy",
    "osqp", "pyarrow", "pytest",
]
"""Other packages whose names the docstrings cite (``pandas.DataFrame``, ``scipy.stats.ecdf``)."""
EXTERNAL_STDLIB = [
    r"argparse\.ArgumentParser", r"enum\.Enum", r"str\.splitlines", r"shlex\.join",
    r"pathlib\.Path", r"fractions\.Fraction",
]
"""Objects of Python's standard library the docstrings cite."""
nitpick_ignore_regex = ([(r"py:.*", rf"{re.escape(package)}\..+") for package in EXTERNAL_NAMESPACES]
                        + [(r"py:.*", name) for name in EXTERNAL_STDLIB])

myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

autosummary_generate = True
autodoc_typehints = "none"
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "show-inheritance": False}
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

templates_path = ["_templates"]
html_theme = "furo"
html_title = "observer-toolkit"
html_static_path = ["_static"]

_gallery_out = Path(tempfile.mkdtemp(prefix="observer-gallery-"))


def _gallery_argv(gallery_conf: dict, script_vars: dict) -> list[str]:
    """Each example runs as in its tests: short horizon, its files in a scratch directory."""
    out = _gallery_out / Path(script_vars["src_file"]).stem
    return ["--quick", "--out", str(out)]


sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"(paper_figures|my_system|measured_log|compare_designs)\.py$",
    "ignore_pattern": r"__init__\.py",
    "reset_argv": _gallery_argv,
    "download_all_examples": False,
    "remove_config_comments": True,
    "plot_gallery": "True",
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "show_memory": False,
    "min_reported_time": 1e9,          # run times vary with the machine: none is printed
    "write_computation_times": False,
}
