"""The shipped weights' manifest (``weights/manifest.json``), readable without torch.

The stream asks whether a shipped network fits its light field before deciding to run
one; answering that must not cost torch's import (about a second on the development
machine). :mod:`lfstream.models.registry` loads and checks the weights themselves.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from lfstream.errors import WeightsError

WEIGHTS_DIR = Path(__file__).with_name("weights")
MANIFEST = WEIGHTS_DIR / "manifest.json"


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def read_manifest() -> dict:
    if not MANIFEST.exists():
        return {"models": []}
    try:
        return json.loads(MANIFEST.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise WeightsError(f"{MANIFEST}: unreadable weights manifest ({exc})") from exc


def manifest_entry(name: str, preset: str) -> dict | None:
    """The manifest's record of shipped weights ``(name, preset)``, or ``None``."""
    for entry in read_manifest().get("models", []):
        if entry.get("name") == name and entry.get("preset") == preset:
            return entry
    return None


__all__ = ["WEIGHTS_DIR", "MANIFEST", "sha256_file", "read_manifest", "manifest_entry"]
