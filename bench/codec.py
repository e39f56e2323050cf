"""lfstream's codec against HEVC and AV1 pseudo-sequences at matched rate.

For each light field: lfstream at JPEG quality 50 (flat disparity, and with the depth hint),
then HEVC and AV1 searched to the same bits per pixel; for all: bpp, MPSNR, MSSIM, the
depth-of-field image's PSNR/SSIM, near/far refocused images' PSNR/SSIM (seed: alpha = 0.15
and 1.5), and encode/decode times measured here by the harness (median of --runs). All
metrics on the 8-bit reconstructions.

    python bench/codec.py [--json [FILE]] [--runs N] [--quick]
"""

from __future__ import annotations

import os

import numpy as np

from _harness import ROOT, emit, parser, timeit

import lfstream
from lfstream.baseline import decode_views, encode_at_bpp, encode_views
from lfstream.metrics import bpp, capped, dof_psnr, dof_ssim, mpsnr, mssim, psnr, ssim
from lfstream.refocus import focal_stack
from lfstream.synth import synth_clip

os.environ.setdefault("SVT_LOG", "1")
REFOCUS_ALPHAS = (0.15, 1.5)


def quality(ref: np.ndarray, rec: np.ndarray) -> dict:
    ref_stack = focal_stack(ref, REFOCUS_ALPHAS)
    rec_stack = focal_stack(rec, REFOCUS_ALPHAS)
    return {
        "mpsnr": capped(mpsnr(ref, rec)), "mssim": float(mssim(ref, rec)),
        "dof_psnr": capped(dof_psnr(ref, rec)), "dof_ssim": float(dof_ssim(ref, rec)),
        "refocus_psnr": [capped(psnr(a, b)) for a, b in zip(ref_stack, rec_stack)],
        "refocus_ssim": [float(ssim(a, b)) for a, b in zip(ref_stack, rec_stack)],
    }


def evaluate(name: str, lf: np.ndarray, runs: int) -> list[dict]:
    rows = []
    for label, hint in (("lfstream q50 flat", False), ("lfstream q50 hint", True)):
        data = lfstream.encode(lf, quality=50, depth_hint=hint)
        rec = lfstream.decode(data)[0]
        t_enc = timeit(lambda: lfstream.encode(lf, quality=50, depth_hint=hint), runs=runs)
        t_dec = timeit(lambda: lfstream.decode(data), runs=runs)
        rows.append({"lf": name, "method": label, "bytes": len(data), "bpp": bpp(len(data), lf.shape),
                     "encode_s": t_enc["median_s"], "decode_s": t_dec["median_s"], **quality(lf, rec)})
    target = rows[0]["bpp"]
    for codec in ("hevc", "av1"):
        res = encode_at_bpp(lf, codec, target)
        rec = decode_views(res.data, codec, lf.shape[:2], lf.shape[2:4])
        t_enc = timeit(lambda: encode_views(lf, codec, res.quality, constant_qp=res.constant_qp), runs=max(1, runs // 2))
        t_dec = timeit(lambda: decode_views(res.data, codec, lf.shape[:2], lf.shape[2:4]), runs=runs)
        rows.append({"lf": name, "method": f"{codec} @ lfstream-flat bpp", "quality_param": res.quality,
                     "bytes": res.bytes, "bpp": res.bpp, "encode_s": t_enc["median_s"], "decode_s": t_dec["median_s"],
                     **quality(lf, rec)})
    for r in rows:
        print(f"{name:22s} {r['method']:24s} {r['bpp']:.4f} bpp  MPSNR {r['mpsnr']:6.2f}  MSSIM {r['mssim']:.4f}  "
              f"DoF {r['dof_psnr']:6.2f}  enc {r['encode_s'] * 1e3:8.1f} ms  dec {r['decode_s'] * 1e3:7.1f} ms")
    return rows


def main(argv=None) -> dict:
    args = parser(__doc__).parse_args(argv)
    runs = 1 if args.quick else args.runs
    size = (128, 160) if args.quick else (375, 540)
    cases = [("synthetic noisy", synth_clip(1, 7, size, seed=21, noise=2.0, vignetting=0.3, motion=0, camera_pan=0).lf[0])]
    sea = ROOT.parent / "shared" / "data" / "seahorse5x5" / "camImagesFlat"
    if sea.exists():
        lf = lfstream.read_lf(sea)
        cases.append(("seahorse5x5", lf[:, :, :256, 128:384] if args.quick else lf))
    results = []
    for name, lf in cases:
        results += evaluate(name, lf, runs)
    return emit(args, results)


if __name__ == "__main__":
    main()
