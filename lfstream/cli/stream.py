"""``lfstream stream``: an LF video (default: the built-in clip) through the whole pipeline."""

from __future__ import annotations

import argparse

from lfstream.cli import _pipeline
from lfstream.cli._common import add_coding_options, add_read_options, int_in, path_arg, read_options
from lfstream.stream.config import TRANSPORTS

#: Frames of the built-in clip ``lfstream stream`` streams without an input (``--frames``).
BUILTIN_FRAMES = 12

HELP = "stream an LF video (default: the built-in synthetic clip) through the whole pipeline"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=path_arg, nargs="?", help="LF video / light field (default: built-in synthetic clip)")
    p.add_argument("--transport", choices=TRANSPORTS, default="inproc",
                   help="how packets travel from encoder to decoder: in process, through a file, or over loopback TCP")
    p.add_argument("--to", help="HOST:PORT of an `lfstream serve`: send there instead of decoding here")
    add_coding_options(p)
    p.add_argument("--no-depth-hint", action="store_true", help="send only the centre view")
    p.add_argument("--frames", type=int_in((1, 1 << 20)), default=None,
                   help=f"frames of the built-in clip (default {BUILTIN_FRAMES}; an input file takes --max-frames)")
    _pipeline.add_pipeline_options(p)
    add_read_options(p)


def run(args: argparse.Namespace) -> int:
    from lfstream.io.outputs import FOLDER, OutputFolder, check_output, fresh_output_folder
    from lfstream.stream.transport import TcpSender, parse_address

    _pipeline.check_output_folder(args.output)
    sender, out, claim = None, None, None
    if args.to:
        sender = TcpSender(*parse_address(args.to))
    else:
        # the folder first, claimed by this run (a second run naming it is refused): a Ctrl-C
        # at any moment after this still leaves a labelled summary
        if args.output is not None:
            check_output(args.output, [args.input], overwrite=True, kinds=(FOLDER,))
            claim = OutputFolder(args.output, overwrite=args.overwrite)
        else:
            claim = fresh_output_folder("lfstream-out")
        out = claim.path
    try:
        return _stream(args, sender, out)
    finally:
        if claim is not None:
            claim.release()


def _stream(args: argparse.Namespace, sender, out) -> int:
    from lfstream.errors import LFFormatError, LFValueError
    from lfstream.stream import Pipeline, Source, file_source, render_builtin_clip, synthetic_source
    from lfstream.stream.report import stopped_summary
    from lfstream.stream.sources import PRERENDER_MAX_FRAMES

    try:
        if args.input is None:
            if args.first_frame or args.max_frames is not None:
                raise LFValueError("--first-frame, --max-frames: they choose the frames of an input file; the "
                                   "built-in clip takes --frames N")
            args.frames = BUILTIN_FRAMES if args.frames is None else args.frames
            # rendered into its cache while the kernels load, where it is not there yet
            # (and not so long that the wait would outlast them: PRERENDER_MAX_FRAMES)
            ahead = args.frames <= PRERENDER_MAX_FRAMES
            source = Source(synthetic_source(frames=args.frames), None, None, args.frames,
                            prepare=(lambda stop: render_builtin_clip(frames=args.frames, stop=stop)) if ahead
                            else None)
        else:
            if args.frames is not None:  # (it was ignored: every frame of the input streamed)
                raise LFValueError("--frames: the built-in clip's length; an input file's frames are chosen "
                                   "by --max-frames N (and --first-frame K)")
            source = file_source(args.input, read_options(args))
        cfg = _pipeline.pipeline_config(args, quality=args.quality, bpp=args.bpp,
                                        depth_hint=not args.no_depth_hint, preset=args.preset,
                                        residual=args.residual, residual_mode=args.residual_mode,
                                        hance_map=args.hance_map, transport=args.transport,
                                        fps=source.fps or 30.0)
        with _pipeline.single_threaded_opencv(), _pipeline.frozen_garbage_collector() as on_warm:
            pipe = Pipeline(source.frames, cfg, out, sender=sender, progress=_pipeline.progress_callback(args),
                            stream_file=(out / "stream.lfs") if out is not None else None, total_frames=source.total,
                            present=source.present, prepare=source.prepare, on_warm=on_warm)
            summary = pipe.run()
    except KeyboardInterrupt:
        # Ctrl-C before the stages ran (reading the input, loading kernels)
        summary = stopped_summary("tcp" if args.to else args.transport)
    # the stream numbers its own frames from 0 (summary's per_frame, frames/): where it started
    # in the input, for relating them to the source's
    summary["first_frame"] = args.first_frame
    viewer = _pipeline.write_page(args, summary, out)
    _pipeline.report(args, summary, out)
    if viewer is not None and not args.json:
        print(f"open {viewer.resolve().as_uri()} to click-to-focus the result")
    if summary.get("input_error"):  # the frames before the damage streamed, their outputs written
        where = f"; their outputs in {out}" if out is not None else ""
        raise LFFormatError(f"{summary['input_error']} (the stream ended there: {summary['frames']} frame(s) "
                            f"before it streamed{where})")
    return 130 if summary["interrupted"] else 0
