"""``lfstream encode``: a light field or LF video to an ``.lfs`` stream."""

from __future__ import annotations

import argparse
import dataclasses

from lfstream.cli._common import (
    EXIT_INTERRUPTED,
    FrameBoundaryStop,
    add_coding_options,
    add_read_options,
    emit,
    float_in,
    path_arg,
    read_input,
)
from lfstream.codec.hint import HintOptions

HELP = "encode a light field or LF video to an .lfs stream (JPEG or AV1 centre view + depth hint)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", type=path_arg, help="light field or LF video to encode (any format lfstream reads)")
    p.add_argument("-o", "--output", type=path_arg, required=True, help="the .lfs file (never overwritten without --overwrite)")
    add_coding_options(p)
    hint = p.add_mutually_exclusive_group()
    hint.add_argument("--depth-hint", dest="depth_hint", action="store_true", default=True,
                      help="send the encoder's disparity estimate (the default)")
    hint.add_argument("--no-depth-hint", dest="depth_hint", action="store_false",
                      help="send only the JPEG centre view (fewest bits, flat reconstruction)")
    p.add_argument("--fps", type=float_in(1e-3, 10000), help="frame rate to record (default: the input's, else 30)")
    p.add_argument("--device", default="cpu", help="where the hint's plane sweep runs: cpu (the default) or cuda "
                   "(rate control, --bpp, sweeps on the cpu)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    add_read_options(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:
    from lfstream.codec.rate import RATE_CONTROL_CHOOSES, rate_control_conflict
    from lfstream.codec.stream_encoder import CodingOptions, StreamEncoder, encode_file
    from lfstream.errors import LFValueError
    from lfstream.io.outputs import check_output
    from lfstream.metrics import bpp
    from lfstream.models.device import check_device

    check_output(args.output, [args.input], overwrite=args.overwrite, kinds=(".lfs",))
    check_device(args.device)  # a bad device fails before any reading or encoding
    # options that do not go together fail before the input is read
    if args.bpp is not None:
        conflict = rate_control_conflict(args.residual, args.residual_mode, hance_map=args.hance_map)
        if conflict:
            flag = "--" + conflict.replace("_", "-")
            raise LFValueError(f"{flag}: rate control (--bpp) {RATE_CONTROL_CHOOSES[conflict]}")
    if args.residual_mode != "prediction" and args.residual is None:
        raise LFValueError("--residual-mode: needs --residual Q (the layer's quality)")
    source = read_input(args)
    frames, present = source.frames, source.present
    fps = args.fps or source.fps or 30.0
    stream = StreamEncoder(CodingOptions(quality=args.quality, bpp=args.bpp, preset=args.preset,
                                         depth_hint=args.depth_hint, residual=args.residual,
                                         residual_mode=args.residual_mode, hance_map=args.hance_map,
                                         device=args.device), fps, present)
    # Ctrl-C / SIGTERM: the frames encoded so far are kept
    with FrameBoundaryStop() as stop:
        stats = encode_file(stop.frames(frames), args.output, stream)
    if stream.frames == 0:  # stopped before the first frame: nothing was written
        emit(args, {"output": None, "frames": 0, "interrupted": True},
             lambda r: "interrupted before the first frame: nothing written")
        return EXIT_INTERRUPTED
    enc, rate = stream.encoder, stream.rate
    coding = stream.coding()
    quality, depth_hint, preset = coding["quality"], coding["depth_hint"], coding["preset"]
    residual, residual_mode = coding["residual"], coding["residual_mode"] or args.residual_mode
    hint_scale = coding["hint_scale"] or HintOptions().hint_scale
    if rate is not None:  # what rate control chose on the first frame (the follower moves it later)
        quality, depth_hint, preset, residual, residual_mode = (rate.quality, rate.depth_hint, rate.preset,
                                                                rate.residual, rate.residual_mode)
    hance_mapped = enc.hance_map
    prediction_db = stream.prediction_db
    shape = (stats.frames, *source.first.shape)  # a video read frame by frame: as many as were encoded
    result = dataclasses.asdict(stats)
    result.update({"output": str(args.output), "bpp": bpp(stats.bytes, shape),
                   "hint_bpp": bpp(stats.hint_bytes, shape), "quality": quality, "depth_hint": depth_hint,
                   "hint_scale": hint_scale if depth_hint else None,
                   "preset": preset, "residual": residual, "residual_mode": residual_mode if residual is not None else None,
                   "residual_bpp": bpp(stats.residual_bytes, shape), "hance_map": bool(hance_mapped)})
    # the same keys whatever was chosen (null where a key does not apply)
    result["prediction_db"] = prediction_db
    result["rate_control"] = None if rate is None else {"target_bpp": args.bpp, "candidates": list(rate.candidates)}
    result["interrupted"] = bool(stop is not None and stop.stopped)
    emit(args, result, lambda r: f"{r['frames']} frame(s) -> {args.output}: {r['bytes']} bytes, {r['bpp']:.5f} bpp"
         + (f" (hint 1/{hint_scale} {r['hint_bpp']:.5f} bpp)" if depth_hint else "") + f", {preset} q{quality}"
         + (f", residual q{residual} {residual_mode} ({r['residual_bpp']:.5f} bpp)" if residual is not None else "")
         + f", encoded in {r['encode_s']:.3f} s" + (" (interrupted: the frames before it kept)" if r["interrupted"] else ""))
    return EXIT_INTERRUPTED if result["interrupted"] else 0
