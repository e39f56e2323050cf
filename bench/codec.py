"""lfstream's codec against HEVC and AV1 pseudo-sequences at matched rate.

For each light field: lfstream at JPEG quality 50 (the default, with the depth hint; and flat),
then x265 medium, x265 ultrafast and SVT-AV1 searched to the default's bits per pixel, with
the speed ratios against x265 and HEVC decode; for all: bpp, MPSNR, MSSIM, the
depth-of-field image's PSNR/SSIM, near/far refocused images' PSNR/SSIM (seed: alpha = 0.15
and 1.5), and encode/decode times measured here by the harness (median of --runs). All
metrics on the 8-bit reconstructions.

    python bench/codec.py [--json [FILE]] [--runs N] [--quick] [--no-rd]
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
from _harness import ROOT, emit, parser, timeit

import lfstream
from lfstream.codec.baseline import decode_views, encode_at_bpp, encode_views
from lfstream.errors import LFValueError
from lfstream.metrics import bd_psnr, bd_rate, bpp, capped, dof_psnr, dof_ssim, mpsnr, mssim, psnr, ssim
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


def evaluate(name: str, lf: np.ndarray, runs: int, present: np.ndarray | None = None) -> list[dict]:
    """The default (hint) and flat lfstream at q50, then x265 medium and ultrafast and SVT-AV1
    searched to the default's bpp; each timed here; speed ratios against x265 / HEVC."""
    rows = []
    for label, hint in (("lfstream q50 (default: hint)", True), ("lfstream q50 flat", False)):
        data = lfstream.encode(lf, quality=50, depth_hint=hint, present=present)
        rec = lfstream.decode(data)[0]
        t_enc = timeit(lambda: lfstream.encode(lf, quality=50, depth_hint=hint, present=present), runs=runs)
        t_dec = timeit(lambda: lfstream.decode(data), runs=runs)
        rows.append({"lf": name, "method": label, "bytes": len(data), "bpp": bpp(len(data), lf.shape),
                     "encode_s": t_enc["median_s"], "decode_s": t_dec["median_s"], **quality(lf, rec)})
    target = rows[0]["bpp"]
    for codec, preset in (("hevc", "medium"), ("hevc", "ultrafast"), ("av1", None)):
        res = encode_at_bpp(lf, codec, target, preset=preset)
        rec = decode_views(res.data, codec, lf.shape[:2], lf.shape[2:4])
        t_enc = timeit(lambda: encode_views(lf, codec, res.quality, constant_qp=res.constant_qp, preset=preset),
                       runs=max(1, runs // 2))
        t_dec = timeit(lambda: decode_views(res.data, codec, lf.shape[:2], lf.shape[2:4]), runs=runs)
        label = {"medium": "x265 medium", "ultrafast": "x265 ultrafast"}.get(preset, "SVT-AV1")
        rows.append({"lf": name, "method": f"{label} @ default bpp", "quality_param": res.quality,
                     "bytes": res.bytes, "bpp": res.bpp, "encode_s": t_enc["median_s"], "decode_s": t_dec["median_s"],
                     **quality(lf, rec)})
    ours, x265, fast = rows[0], rows[2], rows[3]
    ours["speed"] = {"encode_vs_x265_medium": x265["encode_s"] / ours["encode_s"],
                     "encode_vs_x265_ultrafast": fast["encode_s"] / ours["encode_s"],
                     "decode_vs_hevc": x265["decode_s"] / ours["decode_s"]}
    for r in rows:
        print(f"{name:22s} {r['method']:30s} {r['bpp']:.4f} bpp  MPSNR {r['mpsnr']:6.2f}  MSSIM {r['mssim']:.4f}  "
              f"DoF {r['dof_psnr']:6.2f}  enc {r['encode_s'] * 1e3:8.1f} ms  dec {r['decode_s'] * 1e3:7.1f} ms")
    print("  speed: " + ", ".join(f"{k} {v:.1f}x" for k, v in rows[0]["speed"].items()))
    return rows


RD_POINTS = {
    "lfstream flat": [10, 25, 50, 75, 95],
    "lfstream hint": [10, 25, 50, 75, 95],
    "hevc": [22, 27, 32, 37, 42, 47],
    "av1": [20, 30, 40, 50, 60],
}


def rd_curves(name: str, lf: np.ndarray) -> dict:
    """Rate-distortion points of every method and Bjontegaard deltas of lfstream against the
    baselines (MPSNR; None where the curves do not overlap)."""
    curves = {}
    for method, params in RD_POINTS.items():
        pts = []
        for q in params:
            if method.startswith("lfstream"):
                data = lfstream.encode(lf, quality=q, depth_hint=method.endswith("hint"))
                rec = lfstream.decode(data)[0]
                n = len(data)
            else:
                data = encode_views(lf, method, q, constant_qp=True)
                rec = decode_views(data, method, lf.shape[:2], lf.shape[2:4])
                n = len(data)
            pts.append({"param": q, "bpp": bpp(n, lf.shape), "mpsnr": capped(mpsnr(lf, rec)), "mssim": float(mssim(lf, rec))})
        curves[method] = pts
    deltas = {}
    for ours in ("lfstream flat", "lfstream hint"):
        for anchor in ("hevc", "av1"):
            a, b = curves[anchor], curves[ours]
            key = f"{ours} vs {anchor}"
            try:
                deltas[key] = {"bd_rate_pct": bd_rate([p["bpp"] for p in a], [p["mpsnr"] for p in a],
                                                      [p["bpp"] for p in b], [p["mpsnr"] for p in b]),
                               "bd_psnr_db": bd_psnr([p["bpp"] for p in a], [p["mpsnr"] for p in a],
                                                     [p["bpp"] for p in b], [p["mpsnr"] for p in b])}
            except LFValueError as exc:
                deltas[key] = {"bd_rate_pct": None, "bd_psnr_db": None, "why": str(exc)}
    return {"lf": name, "curves": curves, "bjontegaard": deltas}


def plot_rd(rd: dict, path: Path) -> None:
    """MPSNR against log bpp, one line per method, drawn with OpenCV (no plotting dependency)."""
    w, h, m = 900, 560, 70
    img = np.full((h, w, 3), 255, np.uint8)
    pts = [p for c in rd["curves"].values() for p in c]
    x0, x1 = np.log10(min(p["bpp"] for p in pts)), np.log10(max(p["bpp"] for p in pts))
    y0, y1 = min(p["mpsnr"] for p in pts) - 1, max(p["mpsnr"] for p in pts) + 1

    def xy(p):
        return (int(m + (np.log10(p["bpp"]) - x0) / max(x1 - x0, 1e-9) * (w - 2 * m)),
                int(h - m - (p["mpsnr"] - y0) / max(y1 - y0, 1e-9) * (h - 2 * m)))

    cv2.rectangle(img, (m, m), (w - m, h - m), (0, 0, 0), 1)
    for k in range(5):
        lx = x0 + k * (x1 - x0) / 4
        ly = y0 + k * (y1 - y0) / 4
        cv2.putText(img, f"{10 ** lx:.3g}", (m + int(k * (w - 2 * m) / 4) - 20, h - m + 20), cv2.FONT_HERSHEY_SIMPLEX,
                    0.45, (0, 0, 0), 1)
        cv2.putText(img, f"{ly:.1f}", (10, h - m - int(k * (h - 2 * m) / 4)), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1)
    cv2.putText(img, f"{rd['lf']}: MPSNR (dB) vs bits per pixel (log)", (m, 40), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1)
    colours = [(200, 60, 20), (20, 140, 20), (20, 20, 200), (160, 20, 160)]
    for k, (method, curve) in enumerate(rd["curves"].items()):
        c = colours[k % len(colours)]
        p = [xy(q) for q in sorted(curve, key=lambda q: q["bpp"])]
        for a, b in zip(p, p[1:]):
            cv2.line(img, a, b, c, 2, cv2.LINE_AA)
        for q in p:
            cv2.circle(img, q, 4, c, -1, cv2.LINE_AA)
        cv2.putText(img, method, (w - m - 170, m + 25 + 22 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.55, c, 2)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img)


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--no-rd", action="store_true", help="skip the rate-distortion curves (slow)")
    args = p.parse_args(argv)
    runs = 1 if args.quick else args.runs
    size = (128, 160) if args.quick else (375, 540)
    cases = [("synthetic noisy", synth_clip(1, 7, size, seed=21, noise=2.0, vignetting=0.3, motion=0, camera_pan=0).lf[0])]
    data = ROOT.parent / "shared" / "data"
    for name, folder in (("seahorse5x5", "seahorse5x5/camImagesFlat"), ("lytro_bikes", "lytro_bikes"),
                         ("lytro_translucent", "lytro_translucent")):
        if (data / folder).exists() and not (args.quick and name != "seahorse5x5"):
            lf = lfstream.read_lf(data / folder)
            cases.append((name, lf[:, :, :256, 128:384] if args.quick else lf))
    results, rd = [], []
    for name, lf in cases:
        results += evaluate(name, lf, runs)
        if args.no_rd:
            continue
        curves = rd_curves(name, lf)
        rd.append(curves)
        plot_rd(curves, ROOT / "bench" / "results" / f"codec_rd_{name.split()[0]}.png")
        for key, d in curves["bjontegaard"].items():
            if d["bd_rate_pct"] is None:
                print(f"{name:22s} {key:26s} BD: curves do not overlap")
            else:
                print(f"{name:22s} {key:26s} BD-rate {d['bd_rate_pct']:+8.1f} %  BD-PSNR {d['bd_psnr_db']:+6.2f} dB")
    return emit(args, results, {"rate_distortion": rd})


if __name__ == "__main__":
    main()
