"""``lfstream view``: the click-to-focus page for an output folder of stream or refocus."""

from __future__ import annotations

import argparse

from lfstream.cli._common import emit, float_in, path_arg

HELP = "write index.html, a self-contained click-to-focus page, for a folder of focal stacks"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("folder", type=path_arg, help="an output folder of lfstream stream or lfstream refocus")
    p.add_argument("--fps", type=float_in(1e-3, 1000), help="playback rate of a video (default: the stream's, else 8)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    import json

    from lfstream.viewer import write_viewer

    fps = args.fps
    summary = args.folder / "summary.json"
    if fps is None and summary.exists():
        try:
            fps = json.loads(summary.read_text()).get("fps")
        except ValueError:
            fps = None
    path = write_viewer(args.folder, fps=fps)
    emit(args, {"viewer": str(path), "url": path.resolve().as_uri()}, lambda r: f"open {r['url']}")
    return 0
