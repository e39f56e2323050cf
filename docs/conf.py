"""Sphinx configuration of the lfstream documentation (``make docs``; strict in CI: ``-W``).

Sphinx with MyST: the pages are Markdown, the API comes from the docstrings (autodoc with
napoleon for their Google style), and the CLI reference and every results table are
generated at build time by ``tools/docgen.py`` (``docs/_ext/lfstream_docs.py``).
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).parent / "_ext"))

project = "lfstream"
author = "the lfstream developers"
copyright = "the lfstream developers"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "lfstream_docs",
]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "results", "figures/README.md"]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
html_theme = "furo"
html_title = "lfstream"
autodoc_typehints = "description"
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True  # dataclass fields are documented by autodoc; an Attributes section would repeat them
napoleon_custom_sections = [("Shape", "params_style")]
# docstrings cross-reference many internal names with :mod:/:class:; those outside the
# documented API are not targets
suppress_warnings = ["ref.python", "myst.xref_missing"]
nitpicky = False
