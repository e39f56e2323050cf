"""Start-up: `import lfstream` and building the CLI parser import neither torch nor numba,
and the package tree keeps the data flow's direction (lower layers never import upper ones)."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "lfstream"


def _heavy_modules_after(code: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys\nprint(' '.join(m for m in ('torch', 'numba') "
                          "if m in sys.modules))"], capture_output=True, text=True, check=True, cwd=ROOT)
    return out.stdout.split()


@pytest.mark.parametrize("code", [
    "import lfstream",
    "import lfstream.io, lfstream.codec, lfstream.stream.config",
    "from lfstream.cli import build_parser; build_parser()",
])
def test_light_imports_do_not_load_torch_or_numba(code):
    assert _heavy_modules_after(code) == []


def test_a_default_stream_runs_without_torch():
    # the stream's decoder, refocus (shift-and-sum) and metrics need no network: torch's
    # import (about a second) must not land inside a timed run
    code = ("from lfstream.stream import Pipeline, StreamConfig\n"
            "from lfstream.synth import synth_clip\n"
            "clip = synth_clip(2, 3, (24, 32), seed=1)\n"
            "s = Pipeline(iter(clip.lf), StreamConfig(), None).run()\n"
            "assert s['frames'] == 2 and s['warmup_s'] > 0, s")
    assert "torch" not in _heavy_modules_after(code)


# Lower layers first. A module may import (at module level) only its own package, lower
# packages and the foundation modules; lazy imports inside functions are not counted.
LAYERS = ["errors", "lightfield", "optics", "metrics", "synth", "io", "codec", "models", "refocus", "viewer", "stream",
          "cluster", "testing", "cli"]


def _top_level_imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    found = set()
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("lfstream."):
            found.add(node.module.split(".")[1])
        elif isinstance(node, ast.Import):
            found.update(a.name.split(".")[1] for a in node.names if a.name.startswith("lfstream."))
    return found


def test_package_layers_point_downwards():
    wrong = []
    for path in PKG.rglob("*.py"):
        rel = path.relative_to(PKG).parts
        own = rel[0].removesuffix(".py")
        if own not in LAYERS:
            continue
        for dep in _top_level_imports(path):
            if dep in LAYERS and LAYERS.index(dep) > LAYERS.index(own):
                wrong.append(f"{'/'.join(rel)} imports lfstream.{dep}")
    assert not wrong, wrong
