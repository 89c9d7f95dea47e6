"""Sphinx configuration: Markdown pages (myst-parser) and an API reference from numpydoc docstrings.

Build the HTML documentation with one command from the repository root::

    python -m sphinx -b html docs docs/_build/html
"""
from __future__ import annotations

import casship

project = "casship"
author = "casship contributors"
release = version = casship.__version__
copyright = "casship contributors"

extensions = [
    "myst_parser",
    "numpydoc",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build"]
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]

autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}
autodoc_typehints = "none"
autosummary_generate = False
numpydoc_show_class_members = False
numpydoc_validation_checks: set = set()
suppress_warnings = ["myst.xref_missing"]

html_theme = "alabaster"
html_title = f"casship {release}"
