"""Sphinx configuration of agentsim's documentation.

The command-line reference and the API pages are generated when the build starts (``_generate``): one page per
command and nested command, from the argument parser, and one page per module of the four packages, from the
source tree, so that a command or a module added later gets its page and none can drift.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))

project = "agentsim"
author = "the agentsim authors"
copyright = "2026, the agentsim authors"


def _version() -> str:
    tree = ast.parse((ROOT / "agentsim" / "__init__.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "__version__" for t in node.targets):
            return node.value.value
    return ""


release = version = _version()

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "sphinxarg.ext",
    "sphinx_copybutton",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
napoleon_google_docstring = False
napoleon_numpy_docstring = True
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_typehints = "description"
# names that annotations use unqualified and two modules define
autodoc_type_aliases = {"Track": "agentsim.media.audio.Track"}
napoleon_use_ivar = True  # a dataclass's "Attributes" once, not beside its fields again
# the modules of optional extras import without them
autodoc_mock_imports: list[str] = []
nitpicky = False
# a builtin in a signature (``str | bytes``) is looked up among the documented objects too, and where two classes
# have an attribute of that name (``bytes``) Sphinx says the reference is ambiguous: such references are left
# as plain text. Broken links between pages (ref.doc, myst) stay errors.
suppress_warnings = ["ref.python"]
smartquotes = False  # "--out" stays two hyphens

html_theme = "pydata_sphinx_theme"
html_title = "agentsim"
html_static_path: list[str] = []
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "navbar_align": "left",
    "shorten_urls": False,  # (no forge links to shorten; it cannot parse "https://host[:port]")
}
html_show_sourcelink = False
copybutton_prompt_text = r"\$ "
copybutton_prompt_is_regexp = True

sys.path.insert(0, str(DOCS))


def setup(app):
    from _generate import generate

    app.connect("builder-inited", lambda app: generate(DOCS))
