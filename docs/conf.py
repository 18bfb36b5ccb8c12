"""Sphinx configuration. The reference pages are generated from survey's declarations at
each build (survey.reference -> docs/_generated/, not versioned); the prose is MyST
Markdown. Build: python -m sphinx -W -b html docs docs/_build/html"""
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import survey                                   # noqa: E402
from survey import reference                   # noqa: E402

reference.write(Path(__file__).parent / "_generated", ROOT)

project = "survey"
author = "the survey developers"
copyright = "2026, the survey developers"
release = survey.__version__
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon",
              "sphinx.ext.mathjax"]
source_suffix = {".md": "markdown"}
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
exclude_patterns = ["_build", "_generated", "bench"]     # the last two: included pages
html_theme = "alabaster"
html_title = "survey"
html_theme_options = {"description": "order and chaos in triplet interactions",
                      "fixed_sidebar": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
suppress_warnings = ["myst.header"]
nitpicky = False


def _plain_docstring(app, what, name, obj, options, lines):
    """survey's docstrings are plain prose (|A| is an area, `x`s a plural), not reST:
    escape what reST would read as markup."""
    import re
    for k, line in enumerate(lines):
        line = line.replace("|", "\\|").replace("*", "\\*")
        lines[k] = re.sub(r"`([^`]+)`(\w)", r"`\1`\\ \2", line)


def setup(app):
    app.connect("autodoc-process-docstring", _plain_docstring)
