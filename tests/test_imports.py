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


def _modules() -> dict[str, Path]:
    out = {}
    for path in PKG.rglob("*.py"):
        parts = path.relative_to(PKG.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def _imported(path: Path, name: str, modules: dict[str, Path]) -> set[str]:
    """Every lfstream module ``path`` imports, at module level or inside a function."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("lfstream"):
            for alias in node.names:  # `from lfstream.codec import rate` names a module
                full = f"{node.module}.{alias.name}"
                found.add(full if full in modules else node.module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("lfstream"))
    return {m for m in found if m in modules and m != name}


def test_no_module_imports_itself_back_lazy_imports_included():
    """No circle of imports between lfstream's modules, counting the imports inside
    functions: a lazy import hides a circle from the interpreter, not from a reader."""
    modules = _modules()
    graph = {name: _imported(path, name, modules) for name, path in modules.items()}
    circles = []
    for start in graph:
        # depth-first from each module: a path back to it is a circle
        stack, seen = [(start, (start,))], set()
        while stack:
            node, path = stack.pop()
            for nxt in graph[node]:
                if nxt == start:
                    circles.append(" -> ".join((*path, start)))
                elif nxt not in seen:
                    seen.add(nxt)
                    stack.append((nxt, (*path, nxt)))
    assert not circles, circles[:5]
