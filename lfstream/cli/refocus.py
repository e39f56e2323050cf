"""``lfstream refocus``: a focal stack as PNGs per plane and an MP4/GIF focal sweep."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from lfstream.cli._common import add_read_options, emit, float_in, interrupt_after, parse_float_list, path_arg, read_input
from lfstream.errors import LFValueError
from lfstream.lightfield import axes_as_list, canonical_views

HELP = "render a focal stack (PNG per plane, MP4 and GIF focal sweep)"
#: Methods of :func:`lfstream.refocus.focal_stack` (kept here so --help does not import torch).
METHODS = ("sas", "fourier", "refnet")


def parse_alphas(text: str) -> list[float] | str:
    """``auto`` (planes fitted to the scene's disparity, the default, as the stream's), ``seed``
    (the seed's sixteen alphas, as ``stream --alphas seed``) or a comma list of alphas."""
    if text.strip().lower() == "auto":
        return "auto"
    if text.strip().lower() == "seed":
        from lfstream.optics import SEED_ALPHAS

        return list(SEED_ALPHAS)
    return parse_float_list(text)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=path_arg, help="light field or LF video to refocus (any format lfstream reads)")
    p.add_argument("-o", "--output", type=path_arg, required=True, help="output folder (created; must be empty unless "
                   "--overwrite)")
    p.add_argument("--overwrite", action="store_true", help="write into a folder that already holds files")
    p.add_argument("--alphas", type=parse_alphas, metavar="auto|seed|A,B,...",
                   help="focal planes: auto (default, as lfstream stream's: fitted to the first frame's disparity "
                        "range), seed (the seed's alpha 0.125,0.25,...,2.0) or a list of alphas")
    p.add_argument("--slopes", type=parse_float_list, help="instead of alphas: shifts in pixels per view step")
    p.add_argument("--slope-range", nargs=3, type=float_in(-1e9, 1e9), metavar=("LO", "HI", "N"),
                   help="N slopes evenly spaced from LO to HI (a focus range in disparity units)")
    p.add_argument("--method", choices=METHODS, default="sas", help="sas (shift-and-sum), fourier (Fourier slice) or refnet")
    p.add_argument("--device", default="cpu", help="where RefNet runs (method refnet)")
    p.add_argument("--aperture", type=float_in(1e-6, 1e6), help="synthetic aperture radius in view steps (default: all views)")
    p.add_argument("--aperture-shape", choices=("circle", "square", "gaussian"), default="circle",
                   help="shape of the synthetic aperture's view weights")
    p.add_argument("--fps", type=float_in(1e-3, 1000), default=8.0, help="frame rate of the focal sweep")
    p.add_argument("--no-sweep", action="store_true", help="skip the MP4/GIF focal sweep")
    p.add_argument("--no-viewer", action="store_true", help="do not write index.html (click-to-focus page)")
    p.add_argument("--axes", choices=("auto", "standard"), default="auto",
                   help="auto: detect a grid whose views run the other way or are stored (V, U), and refocus "
                        "its views in the convention's order; standard: the order as stored")
    add_read_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    from lfstream.io.outputs import FOLDER, OutputFolder, check_output
    from lfstream.refocus import resolve_slopes, slope_range

    given = [x is not None for x in (args.alphas, args.slopes, args.slope_range)]
    if sum(given) > 1:
        raise LFValueError("give one of --alphas, --slopes, --slope-range")
    if args.slope_range:
        lo, hi, n = args.slope_range
        from lfstream.refocus.planes import MAX_PLANES

        if not (n >= 1 and float(n).is_integer()):
            raise LFValueError(f"--slope-range: N is a count of planes, got {n:g}")
        if n > MAX_PLANES:
            raise LFValueError(f"--slope-range: {n:g} planes; at most {MAX_PLANES}")
        slopes = slope_range(lo, hi, int(n))
    elif args.slopes is None and args.alphas in (None, "auto"):
        slopes = None  # fitted to the first frame (the stream's default)
    else:
        slopes = resolve_slopes(args.alphas, args.slopes)
    check_output(args.output, [args.input], overwrite=args.overwrite, kinds=(FOLDER,))
    with OutputFolder(args.output, overwrite=args.overwrite) as claim:
        return _refocus(args, slopes, claim.path)


def _refocus(args: argparse.Namespace, slopes, out: Path) -> int:
    import json

    from lfstream.io import VideoWriter, write_image, write_video
    from lfstream.io._fs import atomic_write_text
    from lfstream.refocus import focal_stack, plane_records

    source = read_input(args, count_frames=True)
    axes = _view_axes(source.first, source.present) if args.axes == "auto" else None
    if slopes is None:
        slopes = _scene_slopes(source.first, source.present, axes)
    extra = {"device": args.device} if args.method == "refnet" else {}
    single = source.count == 1
    files: list[str] = []
    planes = plane_records(slopes)
    records: list[dict] = []
    plane_videos: list = []  # one focal-plane video each, frame after frame (a video input)
    render_s, frames, interrupted = 0.0, 0, False
    # frame by frame: a video's frames are read, refocused and written one at a time (the
    # video and its focal stacks were held whole: 1.2 GB for 20 frames of 7x7x375x540)
    try:
        for t, frame in enumerate(source.frames):
            lf, present = canonical_views(frame, axes, source.present)
            t0 = time.perf_counter()
            stack = focal_stack(np.ascontiguousarray(lf), slopes=slopes, method=args.method, aperture=args.aperture,
                                aperture_shape=args.aperture_shape, present=present, **extra)
            render_s += time.perf_counter() - t0
            if stack.dtype != np.uint8:
                stack = np.clip(stack * 255.0 + 0.5, 0, 255).astype(np.uint8)
            record = None
            if not args.no_viewer:
                # click to focus needs the scene's disparity: the codec's hint estimator, per frame
                from lfstream.codec.hint import estimate_disparity
                from lfstream.viewer import disparity_record

                record = disparity_record(t, estimate_disparity(frame, present=source.present))
            with interrupt_after():  # a frame's planes, video frames and record are written together
                # a range of a video keeps the source's frame numbers
                folder = out if single else out / f"frame_{args.first_frame + t:06d}"
                folder.mkdir(exist_ok=True)
                for k, img in enumerate(stack):
                    name = folder / f"plane_{k:02d}.png"
                    write_image(name, img)
                    files.append(str(name))
                if not args.no_sweep and single:
                    for ext in (".mp4", ".gif"):
                        write_video(out / f"sweep{ext}", list(stack), fps=args.fps, lossless=False)
                        files.append(str(out / f"sweep{ext}"))
                elif not args.no_sweep:
                    if not plane_videos:
                        plane_videos = [VideoWriter(out / f"plane_{k:02d}.mp4", source.fps or 30.0, lossless=False)
                                        for k in range(len(stack))]
                    for writer, img in zip(plane_videos, stack):
                        writer.write(img)
                if record is not None:
                    records.append(record)
                frames += 1
    except KeyboardInterrupt:  # Ctrl-C: the outputs of the frames so far, finalised below
        interrupted = True
    except BaseException:
        for writer in plane_videos:
            writer.abort()
        raise
    for writer in plane_videos:
        with interrupt_after():  # finalising is not cut short: the output stays whole
            writer.close()
        files.append(str(writer.path))
    atomic_write_text(out / "planes.json", json.dumps({"planes": planes, "updates": []}, indent=1))
    viewer = None
    if not args.no_viewer:
        from lfstream.viewer import write_disparity_json, write_viewer

        write_disparity_json(out, records)
        viewer = write_viewer(out, fps=args.fps if single else (source.fps or 30.0))
    summary = {"input": str(args.input), "method": args.method, "frames": frames, "planes": planes,
               "view_axes": axes_as_list(axes),
               "render_s": render_s, "output": str(out), "files": len(files),
               "viewer": str(viewer) if viewer is not None else None, "interrupted": interrupted}
    reordered = "" if axes is None else f" (views reordered to the convention: view axes {axes_as_list(axes, 2)})"
    emit(args, summary, f"{len(slopes)} planes x {frames} frame(s) by {args.method} in {render_s:.3f} s{reordered}"
         f" -> {out}" + (" (interrupted)" if interrupted else "")
         + (f"\nopen {viewer.resolve().as_uri()} to click-to-focus" if viewer is not None else ""))
    return 130 if interrupted else 0


def _scene_slopes(first, present, axes):
    """The stream's default planes (``--alphas auto``): fitted to the first frame's disparity,
    estimated as the encoder's depth hint estimates it."""
    from lfstream.codec.hint import estimate_hint_map
    from lfstream.refocus import scene_slopes

    hint = estimate_hint_map(first, present=present, axes=axes)
    return scene_slopes(hint.disparity, first.shape[:2])


def _view_axes(first: np.ndarray, present: np.ndarray | None) -> np.ndarray | None:
    """The view axes of the input's first frame (:func:`lfstream.codec.hint.estimate_view_axes`),
    ``None`` where they are the convention."""
    from lfstream.codec.hint import estimate_view_axes, is_standard

    axes = estimate_view_axes(first, present=present)
    return None if is_standard(axes) else axes
