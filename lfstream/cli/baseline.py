"""``lfstream baseline``: the views as an HEVC or AV1 pseudo-sequence, for comparison."""

from __future__ import annotations

import argparse
import time

import numpy as np

from lfstream.cli._common import add_read_options, emit, float_in, load_from_args, path_arg
from lfstream.codec.baseline import CODECS, ORDERS
from lfstream.errors import LFValueError

HELP = "code the views as a pseudo-sequence with HEVC (x265) or AV1 (SVT-AV1) for comparison"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=path_arg, help="light field or LF video to code (any format lfstream reads)")
    p.add_argument("--codec", choices=tuple(CODECS), default="hevc", help="hevc (x265) or av1 (SVT-AV1)")
    rate = p.add_mutually_exclusive_group()
    rate.add_argument("--qp", type=float_in(0, 63), help="HEVC: constant QP 0..51; AV1: CRF 1..63 (default 34)")
    rate.add_argument("--bpp", type=float_in(1e-6, 24), help="search the quality parameter for this bits per pixel")
    p.add_argument("--order", choices=ORDERS, default="raster", help="the order the views enter the pseudo-sequence")
    p.add_argument("-o", "--output", type=path_arg, help="write the decoded light field (.npy, folder or video)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    add_read_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    from lfstream.codec.baseline import decode_views, encode_at_bpp, encode_views
    from lfstream.io import write_lf
    from lfstream.io.outputs import FOLDER, LF_OUTPUTS, check_output
    from lfstream.metrics import bpp, capped, mpsnr, mssim

    if args.output is not None:
        check_output(args.output, [args.input], overwrite=args.overwrite, kinds=(*LF_OUTPUTS, FOLDER))
    lo, hi = CODECS[args.codec].quality_range
    if args.qp is not None and not lo <= args.qp <= hi:
        raise LFValueError(f"--qp: {args.codec} takes {lo:g}..{hi:g}, got {args.qp:g}")
    loaded = load_from_args(args)
    frames = loaded.lf if loaded.lf.ndim == 6 else loaded.lf[None]
    u, v, h, w = frames.shape[1:5]
    total, params, enc_s, dec_s, recon = 0, [], 0.0, 0.0, []
    for frame in frames:
        t0 = time.perf_counter()
        if args.bpp is not None:
            res = encode_at_bpp(frame, args.codec, args.bpp, args.order)
            data, q = res.data, res.quality
        else:
            q = 34.0 if args.qp is None else args.qp
            data = encode_views(frame, args.codec, q, args.order, constant_qp=True)
        enc_s += time.perf_counter() - t0
        t0 = time.perf_counter()
        recon.append(decode_views(data, args.codec, (u, v), (h, w), args.order))
        dec_s += time.perf_counter() - t0
        total += len(data)
        params.append(q)
    rec = np.stack(recon)
    result = {"codec": args.codec, "order": args.order, "frames": len(frames), "quality": params, "bytes": total,
              "bpp": bpp(total, frames.shape),
              # over the views that exist only: zero-filled stand-ins would inflate the score
              "mpsnr": [capped(x) for x in np.atleast_1d(mpsnr(frames, rec, present=loaded.present))],
              "mssim": [float(x) for x in np.atleast_1d(mssim(frames, rec, present=loaded.present))],
              "views_measured": int(loaded.present.sum()) if loaded.present is not None else u * v,
              "encode_s": enc_s, "decode_s": dec_s,
              "note": "encode_s includes the parameter search when --bpp is given", "output": None}
    if args.output is not None:
        write_lf(args.output, rec if loaded.lf.ndim == 6 else rec[0], overwrite=args.overwrite)
        result["output"] = str(args.output)
    emit(args, result, f"{args.codec} ({args.order}) at QP/CRF {', '.join(f'{q:g}' for q in params)}: {total} bytes, "
         f"{result['bpp']:.5f} bpp, MPSNR {np.mean(result['mpsnr']):.2f} dB, MSSIM {np.mean(result['mssim']):.4f}, "
         f"encode {enc_s:.2f} s, decode {dec_s:.3f} s")
    return 0
