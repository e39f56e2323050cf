"""The ``lfstream`` command line. Every subcommand is reachable as ``main(argv)``.

Library code raises :class:`~lfstream.errors.LFStreamError`; only this layer turns it into
one line on stderr and a non-zero exit status, and only this layer sets process-wide state
(torch threads).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from lfstream.errors import LFStreamError, LFValueError

Handler = Callable[[argparse.Namespace], int]
_COMMANDS: dict[str, tuple[Callable[[argparse.ArgumentParser], None], Handler, str]] = {}


def command(name: str, help: str):
    """Registers a subcommand; the decorated function adds its arguments."""

    def wrap(fn: Callable[[argparse.ArgumentParser], Handler]):
        if name in _COMMANDS:
            raise RuntimeError(f"duplicate CLI command {name!r}")
        _COMMANDS[name] = (fn, None, help)  # type: ignore[assignment]
        return fn

    return wrap


def parse_grid(text: str) -> tuple[int, int]:
    """Parses ``UxV`` (or ``N``) into a view grid."""
    try:
        parts = [int(p) for p in text.lower().split("x")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"grid must look like 7x7, got {text!r}") from None
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2 or min(parts) < 1:
        raise argparse.ArgumentTypeError(f"grid must look like 7x7, got {text!r}")
    return parts[0], parts[1]


def parse_size(text: str) -> tuple[int, int]:
    """Parses ``HxW``."""
    return parse_grid(text)


def parse_float_list(text: str) -> list[float]:
    try:
        return [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list of numbers, got {text!r}") from None


def add_read_options(p: argparse.ArgumentParser) -> None:
    """Options every command that reads a light field shares."""
    g = p.add_argument_group("reading")
    g.add_argument("--angular", type=int, help="microlens size in pixels of a lenslet (ESLF) image (Lytro Illum: 14)")
    g.add_argument("--views", "--crop", dest="crop", type=int, help="keep the central N x N views")
    g.add_argument("--grid", type=parse_grid, help="view grid UxV of a mosaic image or video without metadata")
    g.add_argument("--flip-u", action="store_true", help="reverse the order of view rows")
    g.add_argument("--flip-v", action="store_true", help="reverse the order of view columns")
    g.add_argument("--allow-missing", action="store_true", help="load a folder with missing views, with a mask")
    g.add_argument("--max-frames", type=int, help="read at most this many frames")


def load_from_args(args: argparse.Namespace):
    from lfstream.io import load_lf

    return load_lf(
        args.input,
        angular=args.angular,
        crop=args.crop,
        grid=args.grid,
        flip_u=args.flip_u,
        flip_v=args.flip_v,
        allow_missing=args.allow_missing,
        max_frames=args.max_frames,
    )


def emit_json(obj: object) -> None:
    print(json.dumps(obj, indent=2, default=_json_default))


def _json_default(o: object):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


# ----------------------------------------------------------------------------------------
# info


@command("info", "describe a light field or LF video: format, frames, views, view size, dtype, bytes")
def _info_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("input", type=Path, help="file or folder")
    add_read_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    return _info


def describe(loaded) -> dict:
    """The ``info`` summary of a :class:`~lfstream.io.LoadedLF` as a JSON-ready dict."""
    lf = loaded.lf
    out = {
        "path": str(loaded.path),
        "format": loaded.format,
        "frames": loaded.frames,
        "views": list(loaded.views),
        "size": list(loaded.size),
        "channels": int(lf.shape[-1]),
        "dtype": str(lf.dtype),
        "bytes": int(lf.nbytes),
        "fps": loaded.fps,
        "missing_views": None
        if loaded.present is None
        else [[int(r), int(c)] for r, c in zip(*np.nonzero(~loaded.present))],
        "has_weight": loaded.weight is not None,
        "has_disparity": loaded.disparity is not None,
    }
    if loaded.disparity is not None:
        d = loaded.disparity
        out["disparity_range"] = [float(d.min()), float(d.max())]
    return out


def _info(args: argparse.Namespace) -> int:
    info = describe(load_from_args(args))
    if args.json:
        emit_json(info)
        return 0
    u, v = info["views"]
    h, w = info["size"]
    print(f"{info['path']}: {info['format']}")
    print(f"  frames  {info['frames']}" + (f" at {info['fps']:.3g} fps" if info["fps"] else ""))
    print(f"  views   {u} x {v} (centre {u // 2},{v // 2})")
    print(f"  size    {h} x {w} x {info['channels']}")
    print(f"  dtype   {info['dtype']}, {info['bytes'] / 1e6:.1f} MB in memory")
    if info["missing_views"]:
        print(f"  missing {len(info['missing_views'])} views: " + " ".join(f"{r},{c}" for r, c in info["missing_views"]))
    if info["has_weight"]:
        print("  weight  per-sample alpha weight present")
    if info["has_disparity"]:
        lo, hi = info["disparity_range"]
        print(f"  disparity ground truth, {lo:.3f} .. {hi:.3f} px/view")
    return 0


# ----------------------------------------------------------------------------------------


def _load_command_modules() -> None:
    """Imports the modules that register further subcommands."""
    import importlib

    for mod in ("lfstream.commands",):
        importlib.import_module(mod)


def build_parser() -> argparse.ArgumentParser:
    _load_command_modules()
    parser = argparse.ArgumentParser(
        prog="lfstream",
        description="Light-field video: read, simulate, compress, reconstruct and refocus.",
    )
    from lfstream import __version__

    parser.add_argument("--version", action="version", version=f"lfstream {__version__}")
    parser.add_argument("--threads", type=int, help="torch intra-op threads (default: torch's choice)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (add_args, _, help_text) in _COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        handler = add_args(p)
        p.set_defaults(_handler=handler)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the CLI; returns the exit status (0 success, 2 error, 130 interrupted)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_handler", None):
        parser.print_help()
        return 2
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    # SVT-AV1 prints its configuration banner at info level; the CLI keeps stderr for errors
    os.environ.setdefault("SVT_LOG", "1")
    try:
        return int(args._handler(args) or 0)
    except LFStreamError as exc:
        print(f"lfstream {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"lfstream {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


def entry() -> None:
    """Console-script entry point."""
    sys.exit(main())


__all__ = ["main", "entry", "command", "add_read_options", "load_from_args", "describe", "LFValueError"]
