"""``lfstream decode``: an ``.lfs`` stream to a light field (``.npy``, folder or video)."""

from __future__ import annotations

import argparse
import sys
import time

from lfstream.cli._common import add_first_frame, emit, int_in, interrupt_after, path_arg
from lfstream.codec.decoder import BATCH_RANGE, DEPTH_MODES, HANCE_MODES, NETWORK_PRESETS
from lfstream.errors import LFValueError
from lfstream.models.device import PRECISIONS

HELP = "decode an .lfs stream to a light field (.npy, folder or video)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=path_arg, help="the .lfs stream to decode")
    p.add_argument("-o", "--output", type=path_arg, required=True, help=".npy (T,U,V,H,W,3), .npz, a video or a folder")
    p.add_argument("--depth", choices=DEPTH_MODES, default="auto",
                   help="disparity source: the stream's hint, flat (zero), or Depth-Net (the hint refined; on a stream without "
                   "a hint, the seed's path: the disparity from the restored centre view alone; default: hint if present)")
    p.add_argument("--no-occlusion", action="store_true", help="warp without occlusion-aware per-view disparity")
    p.add_argument("--no-hance", action="store_true",
                   help="deprecated, the same as --hance off (it goes in the next release)")
    p.add_argument("--hance", choices=HANCE_MODES, default="auto",
                   help="JPEG-Hance: auto (by the stream's JPEG quality, measured threshold; on a stream encoded "
                   "with --hance-map, always), on or off; a stream encoded with --hance-map gets the network's "
                   "correction by the encoder's strength map")
    p.add_argument("--no-deblock", action="store_true",
                   help="skip the post-filter of JPEG centre views (default: on; a residual layer then is not applied)")
    p.add_argument("--device", default="cpu", help="where the networks run: cpu or cuda")
    p.add_argument("--networks", choices=NETWORK_PRESETS, default="fast",
                   help="the networks' shipped weights: fast, or paper (JPEG-Hance at the seed's size: better, "
                   "about 0.4 s a 375x540 view on a 2-core CPU in bfloat16, 0.7 s in float32, milliseconds on a GPU; "
                   "no Depth-Net ships)")
    p.add_argument("--precision", choices=PRECISIONS, default="auto",
                   help="the networks' inference: auto (bfloat16 on a CPU with native bfloat16, as AVX512-BF16; "
                   "float32 elsewhere), float32 (the bytes of a float32 machine, e.g. for regression tests "
                   "shared across CPUs) or bfloat16")
    p.add_argument("--batch", type=int_in(BATCH_RANGE), default=1,
                   help="frames per network batch (and per warp, on a CUDA device)")
    p.add_argument("--disparity-out", type=path_arg, help="folder for the centre-view disparity of each frame (PFM)")
    add_first_frame(p)
    p.add_argument("--max-frames", type=int_in((1, 1 << 30)), help="decode at most this many frames")
    p.add_argument("--synthesize-missing", action="store_true",
                   help="predict the views the source lacked (an --allow-missing input) instead of leaving them out; "
                        "the output then says which were synthesised")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from lfstream.codec.api import iter_decode
    from lfstream.codec.bitstream import count_packets, header_present, read_header
    from lfstream.errors import BitstreamError, LFFileError
    from lfstream.io import FrameWriter, write_lf, write_pfm
    from lfstream.io._fs import prepare_output_dir
    from lfstream.io.outputs import FOLDER, LF_OUTPUTS, check_disk, check_memory, check_output
    from lfstream.lightfield import frames_in_range

    check_output(args.output, [args.input], overwrite=args.overwrite, kinds=(*LF_OUTPUTS, FOLDER))
    if args.disparity_out is not None:
        check_output(args.disparity_out, [args.input, args.output], overwrite=args.overwrite, kinds=(FOLDER,),
                     what="--disparity-out")
        # a new or empty folder (or --overwrite): maps of an earlier decode are not replaced
        # unasked, and a file there is one line, not a traceback
        prepare_output_dir(args.disparity_out, args.overwrite)
    # every output is written frame by frame as the frames are decoded (one frame in memory;
    # a video at the stream's frame rate; a .npy sized by the packets counted first; a .npz
    # deflated from its frames when closed: it held the whole video)
    count, writer, error, write_s, expected, available = 0, None, None, 0.0, None, None
    t0 = time.perf_counter()
    try:
        with open(args.input, "rb") as fh:
            header = read_header(fh)
            fps = header.fps
            if args.output.suffix.lower() == ".npy" or args.first_frame:
                available = count_packets(fh, header)[0]  # the frames up to any damage (none: the decode names it)
                expected = frames_in_range(available, args.first_frame, args.max_frames, args.input) if available else 0
            fh.seek(0)
            # sizes before anything is allocated: a frame's working set in memory, a .npy of
            # every frame on disk
            frame_bytes = header.views[0] * header.views[1] * header.size[0] * header.size[1] * 3
            check_memory(4 * frame_bytes, f"{args.input}: decoding a frame")
            if expected:
                check_disk(args.output, expected * frame_bytes, f"-o {args.output}")
            hance = args.hance
            if args.no_hance:
                if args.hance not in ("auto", "off"):
                    raise LFValueError(f"--no-hance and --hance {args.hance}: give one (--no-hance is --hance off)")
                print("lfstream decode: --no-hance is deprecated; use --hance off", file=sys.stderr)
                hance = "off"
            present = header_present(header)
            # a stream of one frame decodes to one light field (U, V, H, W, 3), as lfstream
            # reads a still; a longer stream's range keeps its frame axis
            if available is None:  # one packet or more is all that is asked
                read_header(fh)
                available = count_packets(fh, header, most=2)[0]
                fh.seek(0)
            still = available == 1
            written = None if args.synthesize_missing else present  # the views a folder gets
            for f in iter_decode(fh, synthesize_missing=args.synthesize_missing, depth=args.depth,
                                 occlusion=not args.no_occlusion, hance=hance,
                                 device=args.device, batch=args.batch, deblock=not args.no_deblock,
                                 first_frame=args.first_frame, max_frames=args.max_frames, preset=args.networks,
                                 precision=args.precision):
                with interrupt_after():  # a frame's outputs are written whole
                    t_write = time.perf_counter()
                    if still:  # one light field in, one out: (U, V, H, W, 3), views in the folder itself
                        write_lf(args.output, f.lf, fps=fps, overwrite=args.overwrite, present=written)
                    else:
                        if writer is None:
                            # a folder's frames keep the stream's numbers, as the maps do
                            writer = FrameWriter(args.output, expected, fps=fps, overwrite=args.overwrite,
                                                 first_index=f.seq, present=written)
                        writer.write(f.lf)
                    write_s += time.perf_counter() - t_write
                    count += 1
                    if args.disparity_out is not None:
                        write_pfm(args.disparity_out / f"frame_{f.seq:06d}.pfm", f.disparity)
    except LFFileError:  # the output (a writer's error names it) or the input, named already
        if writer is not None:
            writer.abort()
        raise
    except OSError as exc:
        if writer is not None:
            writer.abort()
        raise LFFileError(f"{args.input}: cannot read ({exc.strerror or exc})") from exc
    except BitstreamError as exc:
        error = exc
    except KeyboardInterrupt:  # the frames decoded so far, finalised
        if writer is not None:
            with interrupt_after():  # finalising is not cut short: the output stays whole
                writer.close(partial=True)
        raise
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    decode_s = time.perf_counter() - t0 - write_s  # the decoding alone, as for the other outputs
    # a damaged stream still gives a valid output of every frame before the damage
    if writer is not None:
        with interrupt_after():  # finalising is not cut short: the output stays whole
            writer.close(partial=error is not None)
    if error is not None:
        done = (f"{count} complete frame(s) before it written to {args.output}" if count
                else "no complete frame, nothing written")
        raise BitstreamError(f"{args.input}: {error} ({done})")
    result = {"frames": count, "first_frame": args.first_frame, "decode_s": decode_s, "output": str(args.output),
              "missing_views": [] if present is None else [[int(r), int(c)] for r, c in zip(*np.nonzero(~present))],
              "synthesized_views": []}
    if args.synthesize_missing and present is not None:
        result["synthesized_views"] = result["missing_views"]
    which = f" (from frame {args.first_frame})" if args.first_frame else ""
    note = ""
    if result["missing_views"]:
        views = ", ".join(f"({r}, {c})" for r, c in result["missing_views"])
        note = (f"; the source's missing views {views} synthesised (predicted, not captured)" if args.synthesize_missing
                else f"; {len(result['missing_views'])} view(s) the source lacked left out (zero in arrays and videos; "
                     "--synthesize-missing predicts them)")
    emit(args, result, f"{count} frame(s){which} decoded in {decode_s:.3f} s -> {args.output}{note}")
    return 0
