"""lfstream's codec against HEVC and AV1 pseudo-sequences at matched rate.

For each light field (the synthetic clip and every shared sample; the HCI stars as their centre
3x3): lfstream at quality 50 (the default: the JPEG centre view and the depth hint, or the
views as one AV1 sequence where the encoder finds that warping cannot predict them; and flat),
then x265 medium, x265 ultrafast and SVT-AV1 searched to the default's bits per pixel, with
the speed ratios against x265 and HEVC decode; for all: bpp, MPSNR, MSSIM, the
depth-of-field image's PSNR/SSIM, near/far refocused images' PSNR/SSIM (seed: alpha = 0.15
and 1.5), and encode/decode times measured here by the harness (median of --runs). All
metrics on the 8-bit reconstructions.

    python bench/codec.py [--json [FILE]] [--runs N] [--quick] [--scenes a,b] [--rounds R] [--bpp T]

``--bpp T`` (default 0.02; 0 skips it) adds lfstream's rate control (``encode(lf, bpp=T)``)
and the same three anchors searched to the size it reached.

``--rounds R`` also times the speed ratios interleaved: R rounds, each timing lfstream's default
and then x265 medium and ultrafast (their matched streams; encode and decode, the median of
three calls each), so that the host's slow spells fall on both sides of every ratio; it
reports the median of the R per-round ratios and their range. (The table's times come from
blocks of runs one method after another, minutes apart on a shared host.)

Rate-distortion curves over the whole range, every preset and Bjontegaard deltas: bench/rd.py.
"""

from __future__ import annotations

import os

import numpy as np
from _harness import emit, parser, timeit
from rd import scenes

import lfstream
from lfstream.codec.baseline import decode_views, encode_at_bpp, encode_views
from lfstream.metrics import bpp, capped, dof_psnr, dof_ssim, mpsnr, mssim, psnr, ssim
from lfstream.refocus import focal_stack

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


def interleaved_speed(lf: np.ndarray, present: np.ndarray | None, baselines: list[dict], rounds: int) -> dict:
    """The speed ratios with every round timing lfstream's default and then each baseline's
    matched stream (encode and decode, the median of three calls each): the median of the
    per-round ratios and their range (``--rounds``), and the ratio of the best calls over all
    rounds (``best``: best-of-N, each side's fastest call)."""
    data = lfstream.encode(lf, quality=50, present=present)
    jobs = {"lfstream": (lambda: lfstream.encode(lf, quality=50, present=present), lambda: lfstream.decode(data))}
    for b in baselines:
        codec, preset, res = b["_baseline"]
        jobs[b["method"].split(" @")[0]] = (
            lambda res=res, codec=codec, preset=preset: encode_views(lf, codec, res.quality,
                                                                      constant_qp=res.constant_qp, preset=preset),
            lambda res=res, codec=codec: decode_views(res.data, codec, lf.shape[:2], lf.shape[2:4]))
    for enc, dec in jobs.values():  # warm-up
        enc()
        dec()
    times = {name: {"encode": [], "decode": []} for name in jobs}
    best = {name: {"encode": np.inf, "decode": np.inf} for name in jobs}
    for _ in range(rounds):
        for name, (enc, dec) in jobs.items():
            for what, fn in (("encode", enc), ("decode", dec)):
                t = timeit(fn, runs=3, warmup=0)
                times[name][what].append(t["median_s"])
                best[name][what] = min(best[name][what], t["min_s"])
    out = {}
    for name in jobs:
        if name == "lfstream":
            continue
        key = name.replace(" ", "_")
        for what in ("encode", "decode"):
            ratios = np.array(times[name][what]) / np.array(times["lfstream"][what])
            out[f"{what}_vs_{key}"] = {"median": float(np.median(ratios)), "min": float(ratios.min()),
                                      "max": float(ratios.max()), "rounds": rounds,
                                      "best": float(best[name][what] / best["lfstream"][what])}
    print(f"  interleaved (median of {rounds} rounds, range; best call against best call): "
          + ", ".join(f"{k} {v['median']:.2f}x ({v['min']:.2f}-{v['max']:.2f}; best {v['best']:.2f}x)"
                      for k, v in out.items()))
    return out


def anchors_at(name: str, lf: np.ndarray, target: float, runs: int, suffix: str) -> list[dict]:
    """x265 medium, x265 ultrafast and SVT-AV1 searched to ``target`` bpp, each timed here."""
    rows = []
    for codec, preset in (("hevc", "medium"), ("hevc", "ultrafast"), ("av1", None)):
        res = encode_at_bpp(lf, codec, target, preset=preset)
        rec = decode_views(res.data, codec, lf.shape[:2], lf.shape[2:4])
        t_enc = timeit(lambda: encode_views(lf, codec, res.quality, constant_qp=res.constant_qp, preset=preset),
                       runs=max(1, runs // 2))
        t_dec = timeit(lambda: decode_views(res.data, codec, lf.shape[:2], lf.shape[2:4]), runs=runs)
        label = {"medium": "x265 medium", "ultrafast": "x265 ultrafast"}.get(preset, "SVT-AV1 p8")
        rows.append({"lf": name, "method": f"{label} @ {suffix}", "quality_param": res.quality,
                     "bytes": res.bytes, "bpp": res.bpp, "encode_s": t_enc["median_s"], "decode_s": t_dec["median_s"],
                     **quality(lf, rec), "_baseline": (codec, preset, res)})
    return rows


def rate_controlled(name: str, lf: np.ndarray, target: float, runs: int) -> list[dict]:
    """lfstream's rate control at ``target`` bpp (one timed encode: it is a search), then the
    anchors at the size it reached."""
    data = lfstream.encode(lf, bpp=target)
    t_enc = timeit(lambda: lfstream.encode(lf, bpp=target), runs=1, warmup=0)
    rec = lfstream.decode(data)[0]
    t_dec = timeit(lambda: lfstream.decode(data), runs=runs)
    ours = {"lf": name, "method": f"lfstream --bpp {target:g}", "target_bpp": target, "bytes": len(data),
            "bpp": bpp(len(data), lf.shape), "encode_s": t_enc["median_s"], "decode_s": t_dec["median_s"],
            **quality(lf, rec)}
    rows = [ours, *anchors_at(name, lf, ours["bpp"], runs, "--bpp bpp")]
    ours["speed"] = {"encode_vs_x265_medium": rows[1]["encode_s"] / ours["encode_s"],
                     "decode_vs_hevc": rows[1]["decode_s"] / ours["decode_s"]}
    for r in rows:
        print(f"{name:22s} {r['method']:30s} {r['bpp']:.4f} bpp  MPSNR {r['mpsnr']:6.2f}  MSSIM {r['mssim']:.4f}  "
              f"enc {r['encode_s'] * 1e3:8.1f} ms  dec {r['decode_s'] * 1e3:7.1f} ms")
        r.pop("_baseline", None)
    return rows


def evaluate(name: str, lf: np.ndarray, runs: int, present: np.ndarray | None = None, rounds: int = 0) -> list[dict]:
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
    rows += anchors_at(name, lf, rows[0]["bpp"], runs, "default bpp")
    ours, x265, fast = rows[0], rows[2], rows[3]
    ours["speed"] = {"encode_vs_x265_medium": x265["encode_s"] / ours["encode_s"],
                     "encode_vs_x265_ultrafast": fast["encode_s"] / ours["encode_s"],
                     "decode_vs_hevc": x265["decode_s"] / ours["decode_s"]}
    for r in rows:
        print(f"{name:22s} {r['method']:30s} {r['bpp']:.4f} bpp  MPSNR {r['mpsnr']:6.2f}  MSSIM {r['mssim']:.4f}  "
              f"DoF {r['dof_psnr']:6.2f}  enc {r['encode_s'] * 1e3:8.1f} ms  dec {r['decode_s'] * 1e3:7.1f} ms")
    print("  speed: " + ", ".join(f"{k} {v:.1f}x" for k, v in rows[0]["speed"].items()))
    if rounds:
        ours["interleaved_speed"] = interleaved_speed(lf, present, rows[2:4], rounds)
    for r in rows:
        r.pop("_baseline", None)
    return rows


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--scenes", help="comma-separated scene names (default: all)")
    p.add_argument("--rounds", type=int, default=0, help="also time the speed ratios interleaved, R rounds")
    p.add_argument("--bpp", type=float, default=0.02, help="also lfstream's rate control at this target (0: skip)")
    args = p.parse_args(argv)
    runs = 1 if args.quick else args.runs
    # the synthetic clip and every shared sample (rd.py's scenes: HCI stars as their centre 3x3)
    cases = scenes(args.quick, set(args.scenes.split(",")) if args.scenes else None)
    results = []
    for name, lf in cases:
        results += evaluate(name, lf, runs, rounds=max(0, args.rounds))
        if args.bpp > 0:
            results += rate_controlled(name, lf, args.bpp, runs)
    return emit(args, results)


if __name__ == "__main__":
    main()
