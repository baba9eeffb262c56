"""Sphinx configuration of the observer-toolkit documentation (``nox -s docs``)."""

from __future__ import annotations

import os
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
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "**/GALLERY_HEADER.rst", "auto_examples/*.ipynb",
                    "auto_examples/*.py", "auto_examples/*.zip", "auto_examples/*.json"]
root_doc = "index"
nitpicky = True
suppress_warnings = ["config.cache"]   # the gallery's argv function cannot be pickled
# Nitpicky: every cross-reference of the pages and of the public API's docstrings must resolve,
# except (for now) those into the packages' internal modules, which the reference does not
# document yet (lower-case module paths and bare names relative to one).
nitpick_ignore_regex = [(r"py:.*", r"(observer|proofs_checks)\.[a-z_]+(\..*)?"),
                        (r"py:.*", r"[A-Za-z_]\w*(\.\w+)?"),(r"py:.*", r"(np|numpy|pd|pandas|sp|scipy|nx|flint|fmpq|mpmath|dask|distributed|argparse|pathlib)\..*"),
                        (r"py:.*", r"(Any|Callable|Iterable|Iterator|Mapping|Sequence|Path|ndarray|DataFrame|Series|Fraction)")]

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
