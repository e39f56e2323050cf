"""Rate control (``encode(lf, bpp=T)``) against x265 medium and SVT-AV1 preset 4 at the same size.

For every 7x7 scene (the synthetic scene and the real Lytro captures in ../shared/data) and
target T: each search of :data:`lfstream.codec.rate.SEARCHES` (``model``, the default, and
under ``--preset balanced``; ``full``, every configuration coded and decoded; ``quick`` under
the ``fast`` preset) is timed (one run
after a warm-up), decoded (median of ``--runs``) and measured. The anchors code the views as
one pseudo-sequence over a sweep of constant QP / CRF; their MPSNR, MSSIM, encode and decode
time at each lfstream point's size are read off their curves (linear in log-bpp). A video row
codes the synthetic clip at ``--bpp`` and reports the achieved rate, the largest frame's and
the encode time a frame against x265 medium's a frame.

    python bench/rate.py [--json [FILE]] [--quick] [--scenes NAME,...] [--rows model,full,...]
"""

from __future__ import annotations

import os
import time

import numpy as np
from _harness import SHARED, SHARED_SCENES, emit, parser

import lfstream
from lfstream.codec.baseline import decode_views, encode_views
from lfstream.codec.bitstream import split_stream
from lfstream.codec.rate import choose_rate
from lfstream.metrics import bpp, capped, mpsnr, mssim
from lfstream.synth import synth_clip

os.environ.setdefault("SVT_LOG", "1")
TARGETS = (0.01, 0.02, 0.04, 0.08)
# QP / CRF sweeps wide enough that every lfstream point lies inside each curve
ANCHORS = {"x265 medium": ("hevc", "medium", (27, 32, 37, 42, 47, 51)),
           "SVT-AV1 p4": ("av1", "4", (25, 35, 45, 53, 59, 63))}
SCENES_7X7 = ("lytro_bikes", "lytro_translucent")


def scenes(quick: bool, only: set[str] | None) -> list[tuple[str, np.ndarray]]:
    size = (128, 160) if quick else (375, 540)
    out = [("synthetic", synth_clip(1, 7, size, seed=21, noise=2.0, vignetting=0.3, motion=0, camera_pan=0).lf[0])]
    for name in SCENES_7X7:
        if (SHARED / SHARED_SCENES[name]).exists() and not quick:
            out.append((name, lfstream.read_lf(SHARED / SHARED_SCENES[name])))
    return [(n, np.ascontiguousarray(lf)) for n, lf in out if only is None or n in only]


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _decode_s(fn, runs: int) -> tuple[np.ndarray, float]:
    out, t = _timed(fn)
    times = [t] + [_timed(fn)[1] for _ in range(runs - 1)]
    return out, float(np.median(times))


def anchor_curve(lf: np.ndarray, codec: str, preset: str, params, runs: int) -> list[dict]:
    pts = []
    for q in params:
        data, t_enc = _timed(lambda: encode_views(lf, codec, q, constant_qp=True, preset=preset))
        rec, t_dec = _decode_s(lambda: decode_views(data, codec, lf.shape[:2], lf.shape[2:4]), runs)
        pts.append({"param": q, "bpp": bpp(len(data), lf.shape), "mpsnr": capped(mpsnr(lf, rec)),
                    "mssim": float(mssim(lf, rec)), "encode_s": t_enc, "decode_s": t_dec})
    return sorted(pts, key=lambda p: p["bpp"])


def at_size(curve: list[dict], rate: float, key: str) -> float:
    """``key`` of an anchor's curve at ``rate`` (linear in log-bpp; its nearest end outside)."""
    return float(np.interp(np.log(rate), np.log([p["bpp"] for p in curve]), [p[key] for p in curve]))


#: The rows: label -> (search, preset).
ROWS = {"model": ("model", None), "model balanced": ("model", "balanced"), "full": ("full", None),
        "quick": ("quick", "fast")}


def rate_point(lf: np.ndarray, target: float, row: str, runs: int) -> dict:
    search, preset = ROWS[row]
    choice, t_enc = _timed(lambda: choose_rate(lf[None], target, 30.0, preset=preset, search=search))
    data = choice.stream()
    rec, t_dec = _decode_s(lambda: lfstream.decode(data)[0], runs)
    header = split_stream(data)[0]
    return {"row": row, "search": search, "effort": preset, "target_bpp": target, "bpp": bpp(len(data), lf.shape),
            "mpsnr": capped(mpsnr(lf, rec)),
            "mssim": float(mssim(lf, rec)), "encode_s": t_enc, "decode_s": t_dec, "preset": choice.preset,
            "quality": header.quality, "residual": choice.residual,
            "family": ("centre" if choice.residual is None else choice.residual_mode),
            "candidates": [c for c in choice.candidates if "family" in c] if search == "model" else len(choice.candidates)}


def video_row(quick: bool, target: float) -> dict:
    size = (128, 160) if quick else (375, 540)
    clip = np.ascontiguousarray(synth_clip(8, 7, size, seed=5, noise=2.0, vignetting=0.3).lf)
    choice, t_enc = _timed(lambda: choose_rate(clip, target, 30.0))
    data = choice.stream()
    frame_bpp = [bpp(p.size(choice.header.version), clip.shape[1:]) for p in choice.packets]
    x265 = [_timed(lambda f=f: encode_views(f, "hevc", 37, constant_qp=True, preset="medium"))[1] for f in clip[:3]]
    return {"frames": len(clip), "shape": list(clip.shape), "target_bpp": target, "bpp": bpp(len(data), clip.shape),
            "max_frame_over_target": max(frame_bpp) / target, "encode_s_per_frame": t_enc / len(clip),
            "x265_medium_s_per_frame": float(np.median(x265)), "family": choice.residual_mode if choice.residual else "centre"}


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--scenes", help="comma-separated scene names (default: every 7x7 scene found)")
    p.add_argument("--rows", default=",".join(ROWS), help=f"comma-separated rows to run ({', '.join(ROWS)})")
    p.add_argument("--video-bpp", type=float, default=0.02, help="the video row's target (0: no video row)")
    args = p.parse_args(argv)
    runs = 1 if args.quick else max(1, args.runs)
    only = set(args.scenes.split(",")) if args.scenes else None
    rows = args.rows.split(",")
    results = []
    for name, lf in scenes(args.quick, only):
        choose_rate(lf[None], 0.02, 30.0)  # warm: kernels, codec libraries
        anchors = {m: anchor_curve(lf, c, pr, params, runs) for m, (c, pr, params) in ANCHORS.items()}
        points = []
        for target in TARGETS:
            for row in rows:
                pt = rate_point(lf, target, row, runs)
                for m, curve in anchors.items():
                    pt[f"vs {m}"] = {"mpsnr_db": pt["mpsnr"] - at_size(curve, pt["bpp"], "mpsnr"),
                                     "mssim": pt["mssim"] - at_size(curve, pt["bpp"], "mssim"),
                                     "encode_speed": at_size(curve, pt["bpp"], "encode_s") / pt["encode_s"],
                                     "decode_speed": at_size(curve, pt["bpp"], "decode_s") / pt["decode_s"]}
                points.append(pt)
                v265, vp4 = pt["vs x265 medium"], pt["vs SVT-AV1 p4"]
                print(f"{name:18s} T={target:<5} {row:14s} bpp {pt['bpp']:.4f} {pt['family']:10s} "
                      f"{pt['mpsnr']:6.2f} dB  vs x265 {v265['mpsnr_db']:+5.2f} dB {v265['mssim']:+.4f}  "
                      f"vs p4 {vp4['mpsnr_db']:+5.2f} dB {vp4['mssim']:+.4f}  encode {pt['encode_s']:.2f}s "
                      f"({v265['encode_speed']:.2f}x x265)  decode {v265['decode_speed']:.2f}x HEVC", flush=True)
        results.append({"scene": name, "shape": list(lf.shape), "anchors": anchors, "points": points})
    extra = {}
    if args.video_bpp > 0:
        extra["video"] = video_row(args.quick, args.video_bpp)
        print("video", extra["video"], flush=True)
    return emit(args, results, extra)


if __name__ == "__main__":
    main()
