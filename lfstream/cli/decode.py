"""``lfstream decode``: an ``.lfs`` stream to a light field (``.npy``, folder or video)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from lfstream.cli._common import add_first_frame, emit, int_in, interrupt_after
from lfstream.codec.decoder import BATCH_RANGE, DEPTH_MODES, HANCE_MODES, NETWORK_PRESETS
from lfstream.models.device import PRECISIONS

HELP = "decode an .lfs stream to a light field (.npy, folder or video)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=Path, help="the .lfs stream to decode")
    p.add_argument("-o", "--output", type=Path, required=True, help=".npy (T,U,V,H,W,3), .npz, a video or a folder")
    p.add_argument("--depth", choices=DEPTH_MODES, default="auto",
                   help="disparity source: the stream's hint, flat (zero), or Depth-Net (default: hint if present)")
    p.add_argument("--no-occlusion", action="store_true", help="warp without occlusion-aware per-view disparity")
    p.add_argument("--no-hance", action="store_true", help="skip JPEG-Hance (default: run it where it helps)")
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
    p.add_argument("--disparity-out", type=Path, help="folder for the centre-view disparity of each frame (PFM)")
    add_first_frame(p)
    p.add_argument("--max-frames", type=int_in((1, 1 << 30)), help="decode at most this many frames")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    from lfstream.codec.bitstream import count_packets, read_header
    from lfstream.codec.decoder import iter_decode
    from lfstream.errors import BitstreamError, LFFileError
    from lfstream.io import FrameWriter, write_pfm
    from lfstream.io._fs import check_new_file, prepare_output_dir
    from lfstream.lightfield import frames_in_range

    check_new_file(args.output, args.overwrite)
    if args.disparity_out is not None:
        # a new or empty folder (or --overwrite): maps of an earlier decode are not replaced
        # unasked, and a file there is one line, not a traceback
        prepare_output_dir(args.disparity_out, args.overwrite)
    # every output is written frame by frame as the frames are decoded (one frame in memory;
    # a video at the stream's frame rate; a .npy sized by the packets counted first; a .npz
    # deflated from its frames when closed: it held the whole video)
    count, writer, error, write_s, expected = 0, None, None, 0.0, None
    t0 = time.perf_counter()
    try:
        with open(args.input, "rb") as fh:
            header = read_header(fh)
            fps = header.fps
            if args.output.suffix.lower() == ".npy" or args.first_frame:
                available = count_packets(fh, header)[0]  # the frames up to any damage (none: the decode names it)
                expected = frames_in_range(available, args.first_frame, args.max_frames, args.input) if available else 0
            fh.seek(0)
            hance = "off" if args.no_hance else args.hance
            for f in iter_decode(fh, depth=args.depth, occlusion=not args.no_occlusion, hance=hance,
                                 device=args.device, batch=args.batch, deblock=not args.no_deblock,
                                 first_frame=args.first_frame, max_frames=args.max_frames, preset=args.networks,
                                 precision=args.precision):
                with interrupt_after():  # a frame's outputs are written whole
                    t_write = time.perf_counter()
                    if writer is None:
                        # a folder's frames keep the stream's numbers, as the maps do
                        writer = FrameWriter(args.output, expected, fps=fps, overwrite=args.overwrite,
                                             first_index=f.seq)
                    writer.write(f.lf)
                    write_s += time.perf_counter() - t_write
                    count += 1
                    if args.disparity_out is not None:
                        write_pfm(args.disparity_out / f"frame_{f.seq:06d}.pfm", f.disparity)
    except OSError as exc:
        if writer is not None:
            writer.abort()
        raise LFFileError(f"{args.input}: cannot read ({exc.strerror or exc})") from exc
    except BitstreamError as exc:
        error = exc
    except KeyboardInterrupt:  # the frames decoded so far, finalised
        if writer is not None:
            writer.close(partial=True)
        raise
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    decode_s = time.perf_counter() - t0 - write_s  # the decoding alone, as for the other outputs
    # a damaged stream still gives a valid output of every frame before the damage
    if writer is not None:
        writer.close(partial=error is not None)
    if error is not None:
        done = (f"{count} complete frame(s) before it written to {args.output}" if count
                else "no complete frame, nothing written")
        raise BitstreamError(f"{args.input}: {error} ({done})")
    result = {"frames": count, "first_frame": args.first_frame, "decode_s": decode_s, "output": str(args.output)}
    which = f" (from frame {args.first_frame})" if args.first_frame else ""
    emit(args, result, f"{count} frame(s){which} decoded in {decode_s:.3f} s -> {args.output}")
    return 0
