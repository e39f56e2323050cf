"""Rate-distortion of lfstream against HEVC and AV1 pseudo-sequences, with Bjontegaard deltas.

For every scene (the synthetic clip's first frame and every sample in ../shared/data; the
HCI "star" scenes as their centre 3x3, the only complete square of views they have):

- lfstream's presets (fast = JPEG, balanced / best = AV1 centre view; all with the depth
  hint) and its default (no preset named: the encoder's choice per scene) over a sweep of
  qualities, and lfstream's rate control (``encode(lf, bpp=T)``: the model; the exhaustive
  search it replaces, every preset and hint precision coded and decoded; and
  ``encode(lf, bpp=T, preset="fast")``, the fast preset's quick search) at targets T from
  0.005 to 0.1 bpp;
- x265 preset medium and preset ultrafast, and SVT-AV1 (presets 8 and 4), each coding the views as
  one pseudo-sequence (raster order, one key frame) over a sweep of constant QP / CRF.

Per point: bpp, MPSNR, MSSIM, encode seconds (one timed run after a warm-up) and decode
seconds (the median of --runs, default 5); the same harness and metric code for every
method. Per scene: BD-rate on MPSNR and on MSSIM and BD-PSNR of every method against x265
medium and against SVT-AV1 preset 4 (piecewise cubic over the overlapping range,
lfstream.metrics.bd_rate); rate control's model (the default) beside the exhaustive search it
replaces; a video row (the synthetic clip at ``--bpp 0.02``, bench/rate.py's); every
lfstream point's encode speed against x265 medium's median encode in the same run (the
rate control's speed target at every T) and its decode speed against x265
medium's decode at the same bpp; one PNG with both curves.

    python bench/rd.py [--json [FILE]] [--quick] [--scenes NAME,...] [--png-dir DIR]
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from _harness import ROOT, SHARED, SHARED_SCENES, emit, metadata, parser
from plots import rd_figure

import lfstream
from lfstream.codec.baseline import decode_views, encode_views
from lfstream.errors import LFValueError
from lfstream.metrics import bd_psnr, bd_rate, bpp, capped, mpsnr, mssim
from lfstream.synth import synth_clip

os.environ.setdefault("SVT_LOG", "1")
ANCHOR = "x265 medium"
#: The second anchor of the BD tables: the strongest pseudo-sequence measured here.
SECOND_ANCHOR = "SVT-AV1 p4"
QUALITIES = (10, 25, 40, 55, 70, 85, 95)
TARGETS = (0.005, 0.01, 0.02, 0.04, 0.08, 0.1)
BASELINES = {  # method -> (codec, preset, parameters)
    "x265 medium": ("hevc", "medium", (22, 27, 32, 37, 42, 47)),
    "x265 ultrafast": ("hevc", "ultrafast", (22, 27, 32, 37, 42, 47)),
    "SVT-AV1 p8": ("av1", "8", (20, 30, 40, 50, 60)),
    # the preset rate control's views sequences use (lfstream.codec.encoder.VIEWS_SPEED): the
    # pseudo-sequence anchor with the same codec and effort, so a reader sees what the views
    # modes add over it
    "SVT-AV1 p4": ("av1", "4", (20, 30, 40, 50, 60)),
}
# None: the default (no preset named: lfstream.codec.rate.choose_default picks per scene)
PRESETS = ("fast", "balanced", "best", None)


def scenes(quick: bool, only: set[str] | None) -> list[tuple[str, np.ndarray]]:
    size = (128, 160) if quick else (375, 540)
    out = [("synthetic", synth_clip(1, 7, size, seed=21, noise=2.0, vignetting=0.3, motion=0, camera_pan=0).lf[0])]
    for name, folder in SHARED_SCENES.items():
        if not (SHARED / folder).exists() or (quick and name != "seahorse"):
            continue
        if folder.startswith("hci"):
            lf = lfstream.read_lf(SHARED / folder, return_mask=True)[0][3:6, 3:6]  # the star's only complete square
        else:
            lf = lfstream.read_lf(SHARED / folder)
        out.append((name, lf[:, :, :192, :256] if quick else lf))
    return [(n, np.ascontiguousarray(lf)) for n, lf in out if only is None or n in only]


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _timed_decode(fn, runs: int):
    """``fn()``'s result and the median of ``runs`` timed calls (--runs: a decode takes
    milliseconds, and one timed run moved by up to a third between neighbouring points of
    the same curve)."""
    out, t = _timed(fn)
    times = [t] + [_timed(fn)[1] for _ in range(runs - 1)]
    return out, float(np.median(times))


def _point(lf: np.ndarray, data: bytes, rec: np.ndarray, param, enc_s: float, dec_s: float) -> dict:
    return {"param": param, "bytes": len(data), "bpp": bpp(len(data), lf.shape), "mpsnr": capped(mpsnr(lf, rec)),
            "mssim": float(mssim(lf, rec)), "encode_s": enc_s, "decode_s": dec_s}


def lfstream_curve(lf: np.ndarray, preset: str | None, quick: bool, runs: int) -> list[dict]:
    pts = []
    for q in QUALITIES[::2] if quick else QUALITIES:
        lfstream.encode(lf, quality=q, preset=preset)  # warm (kernels, codec libraries)
        data, t_enc = _timed(lambda: lfstream.encode(lf, quality=q, preset=preset))
        rec, t_dec = _timed_decode(lambda: lfstream.decode(data)[0], runs)
        pts.append(_point(lf, data, rec, q, t_enc, t_dec))
    return pts


def rate_control_curve(lf: np.ndarray, quick: bool, runs: int, preset: str | None = None,
                       search: str | None = None) -> list[dict]:
    """Rate control at every target; ``preset`` named: only that preset (``fast``: the quick
    search); ``search``: one of lfstream.codec.rate.SEARCHES (``None``: the default, the model)."""
    from lfstream.codec.bitstream import split_stream
    from lfstream.codec.rate import choose_rate

    pts = []
    for target in TARGETS[1:5] if quick else TARGETS:
        data, t_enc = _timed(lambda: choose_rate(lf[None], target, 30.0, preset=preset, search=search).stream())
        rec, t_dec = _timed_decode(lambda: lfstream.decode(data)[0], runs)
        header = split_stream(data)[0]
        p = _point(lf, data, rec, target, t_enc, t_dec)
        p.update({"target_bpp": target, "preset": header.meta.get("preset", "fast"), "quality": header.quality,
                  "hint": header.has_hint, "residual": header.meta.get("residual", {}).get("quality"),
                  "residual_mode": header.meta.get("residual", {}).get("mode", "prediction") if header.has_residual
                  else None})
        pts.append(p)
    return pts


def baseline_curve(lf: np.ndarray, codec: str, preset: str, params, runs: int) -> list[dict]:
    pts = []
    for q in params:
        data, t_enc = _timed(lambda: encode_views(lf, codec, q, constant_qp=True, preset=preset))
        rec, t_dec = _timed_decode(lambda: decode_views(data, codec, lf.shape[:2], lf.shape[2:4]), runs)
        pts.append(_point(lf, data, rec, q, t_enc, t_dec))
    return pts


def encode_speed(curves: dict[str, list[dict]]) -> dict[str, list[float]]:
    """Per lfstream curve, x265 medium's median encode time over its curve divided by each
    point's encode time (the speed target's ratio, measured in the same run: > 1 is faster)."""
    anchor = float(np.median([p["encode_s"] for p in curves[ANCHOR]]))
    return {m: [anchor / max(p["encode_s"], 1e-9) for p in c] for m, c in curves.items() if m.startswith("lfstream")}


def decode_speed(curves: dict[str, list[dict]]) -> dict[str, list[float]]:
    """Per lfstream curve, x265 medium's decode time at each point's bpp (interpolated in
    log-bpp along its curve; its nearest end outside it) divided by the point's decode time
    (the decode target at every T: > 1 is faster)."""
    anchor = sorted(curves[ANCHOR], key=lambda p: p["bpp"])
    xs = np.log([p["bpp"] for p in anchor])
    ys = [p["decode_s"] for p in anchor]
    return {m: [float(np.interp(np.log(p["bpp"]), xs, ys)) / max(p["decode_s"], 1e-9) for p in c]
            for m, c in curves.items() if m.startswith("lfstream")}


def bjontegaard(curves: dict[str, list[dict]], anchor: str = ANCHOR) -> dict[str, dict]:
    """Every method against ``anchor``; None (with the reason) where the curves do not overlap."""
    a = curves[anchor]
    out = {}
    for method, b in curves.items():
        if method == anchor:
            continue
        row = {}
        for key, fn, metric in (("bd_rate_psnr_pct", bd_rate, "mpsnr"), ("bd_rate_ssim_pct", bd_rate, "mssim"),
                                ("bd_psnr_db", bd_psnr, "mpsnr")):
            try:
                row[key] = fn([p["bpp"] for p in a], [p[metric] for p in a], [p["bpp"] for p in b], [p[metric] for p in b])
            except LFValueError as exc:
                row[key] = None
                row.setdefault("why", str(exc))
        out[method] = row
    return out


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--scenes", help="comma-separated scene names (default: all found)")
    p.add_argument("--png-dir", type=Path, default=ROOT / "bench" / "results")
    p.add_argument("--skip-full-search", action="store_true", help="leave out the exhaustive search's curve")
    p.add_argument("--no-video", action="store_true", help="leave out the video row (bench/rate.py's)")
    p.add_argument("--skip-presets", action="store_true",
                   help="leave out the fixed-preset lfstream curves (rate control and the baselines only)")
    args = p.parse_args(argv)
    runs = 1 if args.quick else max(1, args.runs)
    only = set(args.scenes.split(",")) if args.scenes else None
    results = []
    meta = metadata()
    machine = f"{meta['device']['cpu']}, {meta['device']['cores']} cores, {meta['time'][:10]}"
    for name, lf in scenes(args.quick, only):
        curves = {} if args.skip_presets else {f"lfstream {preset or 'default'}": lfstream_curve(lf, preset, args.quick, runs)
                                               for preset in PRESETS}
        curves["lfstream --bpp (rate control)"] = rate_control_curve(lf, args.quick, runs)
        if not args.skip_full_search:
            curves["lfstream --bpp (full search)"] = rate_control_curve(lf, args.quick, runs, search="full")
        curves["lfstream --bpp --preset fast"] = rate_control_curve(lf, args.quick, runs, preset="fast")
        for method, (codec, preset, params) in BASELINES.items():
            curves[method] = baseline_curve(lf, codec, preset, params, runs)
        bd = bjontegaard(curves)
        bd_p4 = bjontegaard(curves, SECOND_ANCHOR)
        speed = encode_speed(curves)
        dspeed = decode_speed(curves)
        results.append({"scene": name, "shape": list(lf.shape), "curves": curves, "bjontegaard_vs_x265_medium": bd,
                        "bjontegaard_vs_svt_av1_p4": bd_p4,
                        "encode_speed_vs_x265_medium": speed, "decode_speed_vs_x265_medium": dspeed})
        rd_figure(name, curves, machine, args.png_dir / f"rd_{name}.png")
        for method, row in bd_p4.items():
            cells = [f"{k} {v:+7.1f}" if v is not None else f"{k}    n/a" for k, v in row.items() if k != "why"]
            print(f"{name:18s} {method:30s} vs SVT-AV1 p4: " + "  ".join(cells), flush=True)
        for method, row in bd.items():
            cells = [f"{k} {v:+7.1f}" if v is not None else f"{k}    n/a" for k, v in row.items() if k != "why"]
            print(f"{name:18s} {method:30s} " + "  ".join(cells), flush=True)
        for method, ratios in speed.items():
            print(f"{name:18s} {method:30s} encode speed vs x265 medium (its median encode), per point: "
                  + " ".join(f"{r:.2f}x" for r in ratios), flush=True)
        for method, ratios in dspeed.items():
            print(f"{name:18s} {method:30s} decode speed vs x265 medium at the same bpp, per point: "
                  + " ".join(f"{r:.2f}x" for r in ratios), flush=True)
    extra = {}
    if not args.no_video:
        from rate import video_row

        extra["video"] = video_row(args.quick, 0.02)
        print("video", extra["video"], flush=True)
    return emit(args, results, extra)


if __name__ == "__main__":
    main()
