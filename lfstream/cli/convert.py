"""``lfstream convert``: a light field or LF video from one format to another."""

from __future__ import annotations

import argparse
import time

from lfstream.cli._common import add_read_options, emit, float_in, path_arg

HELP = "convert a light field or LF video to another format (e.g. an .mp4 mosaic to .avi, the quickest to stream)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=path_arg, help="any light field lfstream reads (an .lfs is decoded as lfstream decode does)")
    p.add_argument("output_pos", nargs="?", type=path_arg, metavar="OUTPUT", help="the output (the same as -o)")
    p.add_argument("-o", "--output", type=path_arg, help=".npy (T,U,V,H,W,3), .npz, a mosaic video (lossless: .avi/.nut "
                   "Ut Video, .mp4/.mov x264 RGB, .mkv FFV1, .webm VP9) or a folder of R_C.png views")
    p.add_argument("--lossy", action="store_true", help="a video as yuv420p x264 (VP9 in .webm): plays everywhere, "
                   "not exact")
    p.add_argument("--fps", type=float_in(1e-3, 10000), help="frame rate of a video (default: the input's, else 30)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    add_read_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from lfstream.cli._common import interrupt_after, one_output, read_input
    from lfstream.errors import BitstreamError, LFFormatError, LFValueError
    from lfstream.io import FrameWriter, write_lf
    from lfstream.io.outputs import FOLDER, LF_OUTPUTS, check_output

    args.output = one_output(args)
    check_output(args.output, [args.input], overwrite=args.overwrite, kinds=(*LF_OUTPUTS, FOLDER))
    ext = args.output.suffix.lower()
    # written frame by frame as the frames are read (one in memory): a .npy sized by the
    # frames counted first, a .npz deflated from its frames when closed
    source = read_input(args, count_frames=ext == ".npy")
    if source.present is not None and not source.present.all():
        missing = int((~source.present).sum())
        raise LFValueError(f"{args.input}: {missing} view(s) missing; the formats lfstream writes hold every view, "
                           "and missing ones are never filled silently")
    fps = args.fps or source.fps or 30.0
    t0 = time.perf_counter()
    done, interrupted = 0, False
    # a float light field read whole goes to a .npy or .npz as it is (frame by frame, the
    # writers take 8 bits)
    keeps_dtype = ext in (".npy", ".npz") and source.whole is not None and source.whole.dtype != np.uint8
    # an input's ground-truth disparity (a .npz of write_lf's) goes into a .npz output; the
    # other formats hold none (it was dropped from a .npz too)
    disparity = source.disparity if ext == ".npz" else None
    if keeps_dtype:
        lf = source.whole if source.whole is not None else np.stack(list(source.frames))
        write_lf(args.output, lf, fps=fps, overwrite=args.overwrite, disparity=disparity)
        done = len(lf)
    else:
        writer = FrameWriter(args.output, source.count, fps=fps, lossless=not args.lossy, overwrite=args.overwrite,
                             first_index=args.first_frame,  # a folder's frames keep the source's numbers
                             disparity=disparity)
        damage = None
        try:
            try:
                for lf in source.frames:
                    with interrupt_after():  # a frame is written whole
                        writer.write(_as_written(lf, f"{args.input} frame {done}"))
                        done += 1
            except KeyboardInterrupt:  # Ctrl-C: the frames so far, the output finalised
                interrupted = True
                if not done:
                    raise
            except (LFFormatError, BitstreamError) as exc:  # a video or .lfs damaged part way: the frames
                # before it, as decode keeps
                damage = exc
                if not done:
                    raise
            with interrupt_after():  # finalising is not cut short: the output stays whole
                writer.close(partial=interrupted or damage is not None)
        except BaseException:
            writer.abort()
            raise
        if damage is not None:
            raise type(damage)(f"{damage} ({done} complete frame(s) before it written to {args.output})")
    seconds = time.perf_counter() - t0
    first = source.first
    result = {"input": str(args.input), "output": str(args.output), "frames": done, "views": list(first.shape[:2]),
              "size": list(first.shape[2:4]), "seconds": seconds, "interrupted": interrupted,
              "disparity": disparity is not None}
    emit(args, result, lambda r: f"{done} frame(s) of {r['views'][0]}x{r['views'][1]} views, {r['size'][0]}x{r['size'][1]}, "
         f"in {seconds:.2f} s -> {args.output}" + (" (interrupted)" if interrupted else ""))
    return 130 if interrupted else 0


def _as_written(lf, name: str):
    """A frame as the frame writers store it, 8 bits: a float light field in [0, 1] rounded
    to uint8 (checked finite and in range first: nothing far out of range is clipped
    silently)."""
    import numpy as np

    from lfstream.lightfield import check_finite, check_unit_range, to_uint8

    lf = np.asarray(lf)
    if lf.dtype == np.uint8:
        return np.ascontiguousarray(lf)
    check_finite(lf, name)
    check_unit_range(lf, name)
    return np.ascontiguousarray(to_uint8(lf))
