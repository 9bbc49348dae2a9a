"""Sphinx configuration of the abb-gym documentation (``make docs``).

Sphinx rather than MkDocs because the package's docstrings are reStructuredText: roles
(``:func:``, ``:class:``, ``:mod:``, ``:data:``), simple tables and literal blocks, which
autodoc renders and cross-links as they are.  The guide pages are Markdown (MyST).  The
environment, preset, scene and validation pages are generated from the package at build time
(``_ext/abb_gym_pages.py``), so they cannot drift from the code.
"""
from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))

import abb_gym  # noqa: E402

project = "abb-gym"
author = "The abb-gym contributors"
copyright = "the abb-gym contributors (MIT licence)"
release = version = abb_gym.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "abb_gym_pages",
    "abb_gym_docstrings",
    "site_check",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "_ext", "environments/_table.md"]

myst_enable_extensions = ["colon_fence", "deflist", "dollarmath", "attrs_inline"]
myst_heading_anchors = 3

# the few structured docstrings are NumPy style (abb_gym.simulate)
napoleon_google_docstring = False
napoleon_use_rtype = False

autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_format = "short"
autodoc_preserve_defaults = True

# single backticks in a docstring stay emphasis (reStructuredText default)

html_theme = "furo"
html_title = f"abb-gym {release}"
html_static_path = []
