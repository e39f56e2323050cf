"""``lfstream encode``: a light field or LF video to an ``.lfs`` stream."""

from __future__ import annotations

import argparse
import dataclasses
import time

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
from lfstream.codec.encoder import DEFAULT_PRESET
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
    from lfstream.codec.api import with_default_hance_map
    from lfstream.codec.bitstream import with_present
    from lfstream.codec.encoder import Encoder, encode_file, write_stream_file
    from lfstream.codec.rate import RATE_CONTROL_CHOOSES, choose_default, rate_control_conflict, uses_default_choice
    from lfstream.errors import LFValueError
    from lfstream.io.outputs import check_output
    from lfstream.metrics import bpp
    from lfstream.models.device import check_device

    check_output(args.output, [args.input], overwrite=args.overwrite, kinds=(".lfs",))
    check_device(args.device)  # a bad device fails before any reading or encoding
    # options that do not go together fail before the input is read (whole, for --bpp)
    if args.bpp is not None:
        conflict = rate_control_conflict(args.residual, args.residual_mode, hance_map=args.hance_map)
        if conflict:
            flag = "--" + conflict.replace("_", "-")
            raise LFValueError(f"{flag}: rate control (--bpp) {RATE_CONTROL_CHOOSES[conflict]}")
    if args.residual_mode != "prediction" and args.residual is None:
        raise LFValueError("--residual-mode: needs --residual Q (the layer's quality)")
    # rate control (--bpp) encodes every frame while it searches: it reads the input whole
    source = read_input(args, whole=args.bpp is not None)
    frames, present, views, size = source.frames, source.present, source.first.shape[:2], source.first.shape[2:4]
    fps = args.fps or source.fps or 30.0
    quality, depth_hint, rate, preset = args.quality, args.depth_hint, None, args.preset or DEFAULT_PRESET
    residual, residual_mode = args.residual, args.residual_mode
    prediction_db = None  # the default's check of its own prediction (rate.choose_default)
    stop = None  # Ctrl-C / SIGTERM: the frames encoded so far are kept (not under --bpp's search)
    hance_mapped = False  # strength maps sent (not where the default codes the views themselves)
    hint_scale = HintOptions().hint_scale  # the hint's resolution divisor (the default may double it)
    if args.bpp is not None:
        from lfstream.codec.rate import choose_rate

        # rate control encodes every frame while it searches: its stream is written as it is
        t0 = time.perf_counter()
        rate = choose_rate(source.whole, args.bpp, fps, present, preset=args.preset)
        quality, depth_hint, preset, residual = rate.quality, rate.depth_hint, rate.preset, rate.residual
        residual_mode = rate.residual_mode
        hint_scale = rate.header.meta.get("hint", {}).get("hint_scale", hint_scale)
        stats = write_stream_file(args.output, with_present(rate.header, present), rate.packets)
        stats.encode_s = time.perf_counter() - t0  # the search included
    elif uses_default_choice(args.preset, depth_hint, residual, residual_mode):
        # the default: the centre's coding by the number of views, or the views themselves
        # where the prediction misses them
        t0 = time.perf_counter()
        choice = choose_default(source.first, quality, present, device=args.device)
        enc, first = choice.encoder, choice.first
        if args.hance_map:
            first = with_default_hance_map(enc, first, source.first, present)
        hance_mapped = enc.hance_map
        first_s = time.perf_counter() - t0
        preset, depth_hint, residual, residual_mode = enc.preset, enc.depth_hint, enc.residual, enc.residual_mode
        with FrameBoundaryStop() as stop:
            stats = encode_file(stop.frames(frames), args.output, views, size, enc, fps=fps, present=present,
                                first=first)
        stats.encode_s += first_s  # frame 0's fast encode and the check
        prediction_db = choice.prediction_db
        hint_scale = enc.hint_options.hint_scale
    else:
        with FrameBoundaryStop() as stop:
            stats = encode_file(stop.frames(frames), args.output, views, size,
                                Encoder(quality=quality, depth_hint=depth_hint, preset=preset, residual=residual,
                                        residual_mode=residual_mode, device=args.device, hance_map=args.hance_map),
                                fps=fps, present=present)
        hance_mapped = args.hance_map
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
