"""Sphinx configuration of sphcore's documentation site.

Build (warnings are errors; the gallery's examples run at their small sizes):

    .venv/bin/sphinx-build -W --keep-going -b html docs docs/_build/html

Offline: no intersphinx, nothing fetched at build time. The scene keys and the presets on
scenes.md are generated from sphcore.scene.SCHEMA and sphcore.validate.configs by the local
extension docs/_ext/scene_keys.py, the source `sphcore keys` prints from.
"""
import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS.parent))  # the checkout's sphcore, also where it is not installed

import sphcore  # noqa: E402

os.environ.setdefault("SPHCORE_DOCS_SMALL", "1")  # the examples run small (see examples/README.rst)
os.environ.setdefault("OMP_WAIT_POLICY", "passive")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # the examples' few hundred particles gain nothing from threads

project = "sphcore"
author = "the sphcore developers"
copyright = "2026, the sphcore developers"
version = release = sphcore.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx_gallery.gen_gallery",
    "scene_keys",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "auto_examples/*.ipynb",
                    "auto_examples/*.py", "auto_examples/*.zip", "auto_examples/*.json"]
default_role = "literal"  # `x` in docstrings reads as code, as in the source

# MyST: $math$, ::: fences, definition lists, and anchors for headings down to ### (page.md#a-heading)
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist", "fieldlist"]
myst_heading_anchors = 3

# autodoc: the public names as sphcore exports them, in source order, no private members
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {}  # each directive in api.md lists the members it shows
napoleon_google_docstring = True
napoleon_numpy_docstring = True

# sphinx-gallery: every examples/plot_*.py runs in the build and its figures are kept; a failing
# example fails the build. quickstart.py writes into the working folder and renders offscreen:
# it is the README's script, run by hand, not part of the gallery.
sphinx_gallery_conf = {
    "examples_dirs": str(DOCS.parent / "examples"),
    "gallery_dirs": str(DOCS / "auto_examples"),
    "filename_pattern": r"/plot_",
    "ignore_pattern": r"quickstart\.py|__init__\.py",
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "min_reported_time": 1,
    "show_memory": False,
}

html_theme = "pydata_sphinx_theme"
html_title = f"sphcore {release}"
html_static_path = []
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
}
html_show_sourcelink = False
