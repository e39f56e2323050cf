"""``lfstream synth``: a synthetic LF clip with ground-truth disparity."""

from __future__ import annotations

import argparse
import time

from lfstream.cli._common import EXIT_INTERRUPTED, emit, float_in, int_in, parse_grid, parse_size, path_arg
from lfstream.lightfield import MAX_VIEWS_PER_AXIS

HELP = "render a synthetic LF clip with ground-truth disparity"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("output_pos", nargs="?", type=path_arg, metavar="OUTPUT",
                   help="the output (the same as -o): .npz (LF and disparity together), .npy, a video or a folder")
    p.add_argument("-o", "--output", type=path_arg, help="the output: .npz (LF and disparity together), .npy, a video "
                   "or a folder (the disparity beside it as NAME_disparity.npy)")
    p.add_argument("--frames", type=int_in((1, 100000)), default=8, help="frames of video")
    p.add_argument("--grid", type=lambda t: parse_grid(t, "--grid", "7x7"), default=None, metavar="UxV",
                   help="the view grid to render (square: 7 or 7x7; default 7x7)")
    p.add_argument("--views", type=int_in((1, MAX_VIEWS_PER_AXIS)), default=None,
                   help="(older name of --grid N; elsewhere --views K keeps the central KxK views)")
    p.add_argument("--size", type=parse_size, default=(128, 128), help="HxW of each view")
    p.add_argument("--seed", type=int_in((0, 2**63 - 1)), default=0, help="random seed: the same seed gives the same bytes")
    p.add_argument("--layers", type=int_in((0, 64)), default=4, help="textured depth layers in front of the background")
    p.add_argument("--disparity-range", nargs=2, type=float_in(-1000, 1000), metavar=("FAR", "NEAR"), default=(-1.0, 1.5),
                   help="disparity of the farthest and nearest layer, pixels per view step")
    p.add_argument("--motion", type=float_in(0, 1000), default=1.5, help="object speed, pixels per frame")
    p.add_argument("--camera-pan", type=float_in(-1000, 1000), default=0.5, help="camera pan, pixels per frame")
    p.add_argument("--noise", type=float_in(0, 255), default=0.0, help="sensor noise, 8-bit levels at mid-grey")
    p.add_argument("--vignetting", type=float_in(0, 1), default=0.0, help="0..1")
    p.add_argument("--exposure-drift", type=float_in(-1, 1), default=0.0, help="relative exposure change across the view grid")
    p.add_argument("--fps", type=float_in(1e-3, 10000), default=30.0, help="frame rate recorded in video outputs")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from lfstream.cli._common import interrupt_after, one_output
    from lfstream.errors import LFValueError
    from lfstream.io import FrameWriter, write_lf
    from lfstream.io.outputs import FOLDER, LF_OUTPUTS, check_disk, check_memory, check_output
    from lfstream.io.writers import NpyWriter
    from lfstream.synth import SynthConfig, iter_clip, render_clip

    out = one_output(args)
    if args.grid is not None and args.views is not None:
        raise LFValueError("--grid and --views name the same thing; give --grid")
    grid = args.grid or ((args.views, args.views) if args.views is not None else (7, 7))
    if grid[0] != grid[1]:
        raise LFValueError(f"--grid {grid[0]}x{grid[1]}: the synthetic scene renders square grids")
    check_output(out, overwrite=args.overwrite, kinds=(*LF_OUTPUTS, FOLDER))
    cfg = SynthConfig(frames=args.frames, views=grid[0], size=tuple(args.size), seed=args.seed, layers=args.layers,
                      disparity_range=tuple(args.disparity_range), motion=args.motion, camera_pan=args.camera_pan,
                      noise=args.noise, vignetting=args.vignetting, exposure_drift=args.exposure_drift)
    cfg.validate()
    # sizes before anything is allocated: a frame in memory (the whole clip for .npz) and
    # the files on disk (the frames and a float32 disparity per view)
    frame_bytes = cfg.views * cfg.views * cfg.size[0] * cfg.size[1] * 3
    whole = out.suffix.lower() == ".npz"
    check_memory(frame_bytes * (cfg.frames if whole else 1) * (1 + 4 / 3) + frame_bytes * 4, "synth")
    check_disk(out, frame_bytes * cfg.frames * (1 + 4 / 3), "synth")
    written = [str(out)]
    render_s, lo, hi, done, interrupted = 0.0, np.inf, -np.inf, cfg.frames, False
    if out.suffix.lower() == ".npz":  # compressed whole: the clip is rendered in memory
        t0 = time.perf_counter()
        clip = render_clip(cfg)
        render_s = time.perf_counter() - t0
        write_lf(out, clip.lf, disparity=clip.disparity, overwrite=args.overwrite)
        lo, hi = float(clip.disparity.min()), float(clip.disparity.max())
    else:
        # frame by frame: a video, a .npy or a folder as each frame is rendered, and the
        # disparity into a memory-mapped .npy, so a long clip never sits in memory
        disp_path = check_output(out.with_name(out.stem + "_disparity.npy"), overwrite=args.overwrite,
                                 what="the disparity file")
        done = 0
        writer = FrameWriter(out, cfg.frames, fps=args.fps, overwrite=args.overwrite)
        disparity = NpyWriter(disp_path, cfg.frames)
        try:
            t0 = time.perf_counter()
            try:
                for lf, disp in iter_clip(cfg):
                    render_s += time.perf_counter() - t0
                    with interrupt_after():  # a frame and its disparity are written together
                        writer.write(lf)
                        disparity.write(disp[..., None])
                        lo, hi = min(lo, float(disp.min())), max(hi, float(disp.max()))
                        done += 1
                    t0 = time.perf_counter()
            except KeyboardInterrupt:  # Ctrl-C: the frames so far, both files finalised
                interrupted = True
                if not done:
                    raise
            with interrupt_after():  # finalising is not cut short: the output stays whole
                writer.close(partial=interrupted)
            disparity.close(partial=interrupted)
        except BaseException:
            writer.abort()
            disparity.abort()
            raise
        written.append(str(disp_path))
    info = {"output": written, "frames": done, "views": [cfg.views, cfg.views], "size": list(cfg.size),
            "disparity_range": [lo, hi], "render_s": render_s, "interrupted": interrupted}
    emit(args, info, lambda r: f"{done} frames of {cfg.views}x{cfg.views} views, {cfg.size[0]}x{cfg.size[1]}, "
         f"disparity {r['disparity_range'][0]:.2f}..{r['disparity_range'][1]:.2f} -> {', '.join(written)}"
         + (f" (interrupted after {done} of {cfg.frames})" if interrupted else ""))
    return EXIT_INTERRUPTED if interrupted else 0
