"""Fills the generated blocks of the docs pages (``<!-- generated:NAME -->`` ...
``<!-- /generated -->``) from ``tools/docgen.py`` when Sphinx reads a page, so the CLI
reference and the results tables are made from the parsers and the bench JSON at every
build."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))

import docgen  # noqa: E402 - tools/ is not a package


def _fill(app, docname: str, source: list[str]) -> None:
    source[0] = docgen.render(source[0], docgen.docs_blocks())


def setup(app):
    app.connect("source-read", _fill)
    return {"parallel_read_safe": True, "version": "1"}
