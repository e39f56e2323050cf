"""``lfstream info``: format, frames, views, view size, dtype and bytes of a light field."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from lfstream.cli._common import add_read_options, coding_layers, emit, load_from_args, path_arg

HELP = "describe a light field or LF video: format, frames, views, view size, dtype, bytes"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=path_arg, help="file or folder")
    add_read_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


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
        "disparity_range": None,
        "stream": None,
        "video": None,
    }
    if loaded.disparity is not None:
        d = loaded.disparity
        out["disparity_range"] = [float(d.min()), float(d.max())]
    if loaded.format == "lfs":
        out["stream"] = describe_stream(Path(loaded.path), loaded.frames)
    elif loaded.format in ("video", "view-videos"):
        out["video"] = describe_video(Path(loaded.path))
    return out


def describe_video(path: Path) -> dict:
    """How a mosaic video file, or a folder of one video per view, is coded (what decides
    how fast it reads): the (first view's) codec and pixel format, the bytes on disk and,
    for a folder, how many video files."""
    from lfstream.io.video import VIDEO_EXTS, video_info

    files = sorted(p for p in path.iterdir() if p.suffix.lower() in VIDEO_EXTS) if path.is_dir() else [path]
    coded = video_info(files[0])
    out = {"codec": coded.codec, "pixel_format": coded.pixel_format, "file_bytes": sum(p.stat().st_size for p in files)}
    if path.is_dir():
        out["files"] = len(files)
    return out


def describe_stream(path: Path, frames: int) -> dict:
    """What an ``.lfs`` file's header says it carries: format version, the centre view's
    codec and preset, quality, depth hint, residual layer (quality and mode), whether frame 0
    carries a JPEG-Hance strength map (its tiles), file bytes and bits per pixel of the
    light field."""
    from lfstream.codec.bitstream import CODEC_JPEG, CODEC_NAMES, read_header, read_packet
    from lfstream.codec.centre.jpeg import hance_map

    with open(path, "rb") as fh:
        header = read_header(fh)
        first = read_packet(fh, header) if header.has_hint or header.codec == CODEC_JPEG else None
    levels = hance_map(first.image, first.seq) if first is not None and header.codec == CODEC_JPEG else None
    u, v = header.views
    h, w = header.size
    size = path.stat().st_size
    residual = header.meta.get("residual") if header.has_residual else None
    return {"version": header.version, "centre_codec": CODEC_NAMES[header.codec],
            "preset": header.meta.get("preset", "fast"), "quality": header.quality, "depth_hint": header.has_hint,
            "hint_scale": header.meta.get("hint", {}).get("hint_scale") if header.has_hint else None,
            "view_axes": _view_axes(first, header.size),
            "hance_map": None if levels is None else list(levels.shape),
            "residual": None if residual is None else residual.get("quality"),
            "residual_mode": None if residual is None else residual.get("mode", "prediction"),
            "file_bytes": size, "bpp": 8.0 * size / max(frames * u * v * h * w, 1)}


def _view_axes(packet, size: tuple[int, int]) -> list[list[float]] | None:
    """The view axes frame 0's hint carries (:func:`lfstream.codec.hint.is_standard` ones,
    and streams without a hint: ``None``)."""
    from lfstream.codec.hint import HintDecoder, is_standard
    from lfstream.lightfield import axes_as_list

    if packet is None or not packet.hint:
        return None
    axes = HintDecoder().parse(packet.hint, size, packet.seq).axes
    return None if is_standard(axes) else axes_as_list(axes)


def _text(info: dict) -> str:
    u, v = info["views"]
    h, w = info["size"]
    lines = [f"{info['path']}: {info['format']}",
             f"  frames  {info['frames']}" + (f" at {info['fps']:.3g} fps" if info["fps"] else ""),
             f"  views   {u} x {v} (centre {u // 2},{v // 2})",
             f"  size    {h} x {w} x {info['channels']}",
             f"  dtype   {info['dtype']}, {info['bytes'] / 1e6:.1f} MB in memory"]
    if info["missing_views"]:
        lines.append(f"  missing {len(info['missing_views'])} views: "
                     + " ".join(f"{r},{c}" for r, c in info["missing_views"]))
    if info["has_weight"]:
        lines.append("  weight  per-sample alpha weight present")
    if info["has_disparity"]:
        lo, hi = info["disparity_range"]
        lines.append(f"  disparity ground truth, {lo:.3f} .. {hi:.3f} px/view")
    c = info.get("video")
    if c:
        lines.append(f"  coded   {c['codec']} ({c['pixel_format']}), {c['file_bytes'] / 1e6:.1f} MB on disk"
                     + (f" in {c['files']} files" if c.get("files") else ""))
    s = info.get("stream")
    if s:
        layers = coding_layers(s["depth_hint"], s["residual"], s["residual_mode"], s.get("hint_scale"))
        lines.append(f"  stream  .lfs version {s['version']}, {s['preset']} ({s['centre_codec']} centre) q{s['quality']}"
                     f"{layers}; {s['file_bytes']} bytes, {s['bpp']:.5f} bpp")
        if s.get("view_axes"):
            lines.append(f"  axes    the views move along {s['view_axes']} (rows dy, dx; the convention: identity)")
        if s.get("hance_map"):
            rows, cols = s["hance_map"]
            lines.append(f"  hance   a JPEG-Hance strength map of {rows} x {cols} tiles "
                         "(decode --hance auto, the default, or on uses it)")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    emit(args, _describe_input(args), _text)
    return 0


def _describe_input(args: argparse.Namespace) -> dict:
    """:func:`describe` of the input. An LF video (a mosaic video, an ``.lfs``) is described
    from its container or header, its frames counted but none decoded
    (:func:`lfstream.io.open_video_lf`; it was read whole: 3.5 s and 600 MB for 20 frames of
    7x7x375x540, against a few milliseconds); everything else is read."""
    from lfstream.cli._common import read_options
    from lfstream.errors import LFFormatError
    from lfstream.io import VIDEO_EXTS, open_video_lf, reads_lazily, video_folder_format

    if not reads_lazily(args.input):
        return describe(load_from_args(args))
    video = open_video_lf(args.input, read_options(args), count_frames=True)
    if video.damage is not None:  # (an .lfs cut short: decode and convert keep the frames before it)
        raise type(video.damage)(f"{video.damage} ({video.count} complete frame(s) before it)")
    if not video.count:
        raise LFFormatError(f"{args.input}: contains no frames")
    # a folder of frame folders (what decode -o FOLDER writes) was described as view videos,
    # and looking for their codec raised an IndexError
    fmt = video_folder_format(args.input) if args.input.is_dir() else \
        "video" if args.input.suffix.lower() in VIDEO_EXTS else "lfs"
    (u, v), (h, w), frames = video.views, video.size, video.count
    missing = None if video.present is None else [[int(r), int(c)] for r, c in zip(*np.nonzero(~video.present))]
    out = {"path": str(args.input), "format": fmt, "frames": frames, "views": [u, v], "size": [h, w], "channels": 3,
           "dtype": "uint8", "bytes": frames * u * v * h * w * 3, "fps": video.fps, "missing_views": missing,
           "has_weight": False, "has_disparity": False, "disparity_range": None, "stream": None, "video": None}
    if fmt == "lfs":
        out["stream"] = describe_stream(args.input, frames)
    elif fmt in ("video", "view-videos"):
        out["video"] = describe_video(args.input)
    return out
