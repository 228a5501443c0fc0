"""Sphinx configuration of fastvi's documentation (``make docs``).

The pages are the Markdown files of ``docs/`` (myst-parser), the API reference is generated
from the NumPy-style docstrings (autosummary + numpydoc), and ``examples/`` is rendered as a
gallery (sphinx-gallery) without running the scripts: each one compiles numba kernels for
minutes on a fresh install, and their figures are already in ``docs/figures`` (made by the
same scripts at their default settings), which the examples' docstrings show.
"""

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
# importing fastvi only defines numba functions (no compile); keep numba from threading layers
os.environ.setdefault("MPLBACKEND", "Agg")

import fastvi  # noqa: E402

project = "fastvi"
author = "the fastvi developers"
copyright = "2026, the fastvi developers"
release = fastvi.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_templates", "decisions/scripts", "auto_examples/*.ipynb", "**.ipynb",
                    "**.py", "**.zip", "**.md5", "**.json"]

# Markdown: `#anchor` links to headings (`benchmarks.md#compile-and-set-up-time`)
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]

# API reference: one generated page per public object; a class's page documents its
# public methods and properties too (docs/_templates/autosummary/class.rst)
templates_path = ["_templates"]
autosummary_generate = True
autosummary_imported_members = True
numpydoc_show_class_members = False  # autosummary lists the members; numpydoc would repeat them
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    # never execute: the figures come from docs/figures (see the module docstring)
    "plot_gallery": "False",
    "filename_pattern": r"^$",
    # examples/_cli.py and the like: what the scripts share, not an example
    "ignore_pattern": r"(^|[\\/])_[^\\/]*\.py$",
    "download_all_examples": False,
    "show_signature": False,
    # an example's thumbnail is the figure it draws (its `sphinx_gallery_thumbnail_path`
    # comment, a path from docs/), and that comment is left out of the rendered code
    "remove_config_comments": True,
}

html_theme = "furo"
html_title = f"fastvi {release}"
html_static_path = []
