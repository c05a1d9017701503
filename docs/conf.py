"""Sphinx configuration of the ivobs documentation site.

Build: ``sphinx-build -W --keep-going -b html docs docs/_build/html`` (``pip install ".[docs]"``
first). Why these tools: docs/dev/docs-site.md.
"""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))  # document this checkout, not an installed copy
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import ivobs  # noqa: E402  (after sys.path: this checkout)

project = "ivobs"
author = "ivobs developers"
copyright = "ivobs developers"
release = ivobs.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "sphinxarg.ext",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "**.zip"]

# --- Markdown (the existing docs/*.md pages are used as they are) ---
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# --- API reference ---
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # numpydoc renders the signature; annotations are in the source
autodoc_default_options = {"members": True, "show-inheritance": False}
numpydoc_show_class_members = False  # autodoc's :members: lists them once
numpydoc_validation_checks: set[str] = set()  # docstrings are free prose with numpydoc sections
numpydoc_xref_param_type = False
# Not nitpicky: docstrings name NumPy/SciPy/python-control types in prose (np.ndarray,
# control.StateSpace) and private helpers (:mod:`.rounding`); without intersphinx (it needs the
# network, which CI has not) these have no target. Broken links between the pages still fail.
nitpicky = False
# numpydoc drops a section it does not know (e.g. "Parameters (keyword-only)") with a Python
# warning, not a Sphinx one: make it fail the build too, so that no docstring text goes missing.
warnings.filterwarnings("error", category=UserWarning, module="numpydoc")


# --- gallery of executed examples ---
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples" / "gallery"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",  # every plot_*.py is executed at each build
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "show_memory": False,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "abort_on_example_error": False,
    "only_warn_on_example_error": False,
}

# --- theme ---
html_theme = "pydata_sphinx_theme"
html_title = f"ivobs {release}"
html_theme_options = {
    "navigation_depth": 2,
    "header_links_before_dropdown": 8,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path: list[str] = []


# --- links written for GitHub (paths from the repository root or from docs/) ---
# BENCHMARKS.md and CHANGELOG.md live at the repository root and link to "docs/x.md"; the pages
# in docs/ link to "../BENCHMARKS.md". On the site those are the pages benchmarks, changelog and
# x: rewrite the links as the text is read, so that the files stay right on GitHub too.
_SITE_PAGES = {"../BENCHMARKS.md": "benchmarks.md", "../CHANGELOG.md": "changelog.md"}


def _site_links(text: str, root_file: bool) -> str:
    for github, site in _SITE_PAGES.items():
        text = text.replace(f"]({github}", f"]({site}")
    if root_file:
        text = text.replace("](docs/", "](")
    return text


def _on_source_read(app: Any, docname: str, source: list[str]) -> None:
    source[0] = _site_links(source[0], root_file=False)


def _on_include_read(
    app: Any, relative_path: Path, parent_docname: str, content: list[str]
) -> None:
    content[0] = _site_links(content[0], root_file=relative_path.parent == Path(".."))


# --- docstrings: prose after a Parameters list ---
# numpydoc reads every unindented line of a Parameters section as a new parameter, so a paragraph
# written after the list (without a "Notes" heading) is rendered as parameters named by its
# sentences. Report it as a warning (an error with -W) naming the object.
_SECTIONS = ("Parameters", "Other Parameters", "Returns", "Yields", "Raises", "Attributes")


def _check_sections(
    app: Any, what: str, name: str, obj: Any, options: Any, lines: list[str]
) -> None:
    from numpydoc.docscrape import NumpyDocString
    from sphinx.util import logging

    try:
        doc = NumpyDocString("\n".join(lines))
    except Exception:  # numpydoc itself reports what it cannot parse
        return
    for section in _SECTIONS:
        for param in doc[section]:
            if " " in param.name.strip() and "," not in param.name:
                logging.getLogger(__name__).warning(
                    "%s: the line %r is read as an item of its %s section (give the prose after "
                    "the list a heading such as Notes)",
                    name,
                    param.name[:60],
                    section,
                    type="ivobs",
                    subtype="docstring",
                )


def setup(app: Any) -> None:
    app.connect("source-read", _on_source_read)
    app.connect("include-read", _on_include_read)
    app.connect("autodoc-process-docstring", _check_sections, priority=400)  # before numpydoc
