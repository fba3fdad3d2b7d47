"""Sphinx configuration of negstiff's documentation.

The stack is the one our anchors use (scikit-learn, pysindy, emcee, arviz): Sphinx with the PyData
theme, numpydoc for the API reference, sphinx-gallery for executed examples, sphinx-copybutton; pages
are Markdown (MyST), like the design documents the code cites. Build from the repository root with
``sphinx-build -W --keep-going -b html docs docs/_build/html``: warnings are errors.
"""

from __future__ import annotations

import os
from pathlib import Path

import negstiff

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("NEGSTIFF_THREADS", "2")

project = "negstiff"
author = "the negstiff developers"
copyright = "2026, the negstiff developers"
release = version = negstiff.__version__

extensions = [
    "myst_parser",
    "numpydoc",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx_copybutton",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "auto_examples/*.zip"]
myst_enable_extensions = ["dollarmath", "deflist"]
myst_heading_anchors = 3
suppress_warnings = ["myst.header"]  # the design notes jump from # to ### in places: kept as written

autosummary_generate = True
autodoc_default_options = {"members": True, "inherited-members": False}
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

examples = Path(__file__).resolve().parent.parent / "examples"
sphinx_gallery_conf = {
    "examples_dirs": str(examples),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",  # every example is executed
    "ignore_pattern": r"__init__\.py",
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
    "within_subsection_order": "FileNameSortKey",
    "show_memory": False,
    "matplotlib_animations": False,
    "parallel": True,  # the examples in as many processes as sphinx-build -j gives
}

html_theme = "pydata_sphinx_theme"
html_title = "negstiff"
html_theme_options = {
    "navigation_depth": 2,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path: list[str] = []
