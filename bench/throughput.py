"""Throughput per stage and end to end, and run time against error.

1. Per stage (ms/frame): encode (flat, hint), decode (flat, hint, Depth-Net), 16-plane focal
   stack (SaS, RefNet where the grid fits), for 7x7x375x540 (the seed's Lytro crop) and
   larger light fields, so the growth with U*V and H*W is visible. HEVC decode of the same
   views is measured in the same run as the decoder's baseline.
2. End to end: the pipeline on pre-rendered frames (inproc, SaS refocus, no files, no
   metrics), frames/s, and a batch-size sweep of the Depth-Net decoder.
3. The main command: ``lfstream stream`` with no arguments (built-in clip, every output,
   metrics), run --runs times in this process; frames/s of the whole run (kernels warmed
   before the clock, as the command does), against the target of 5; then the same with
   both networks (``--hance on --depth net``), same target.
4. Run time against error on the seahorse sample: every decoder configuration as a point
   (decode ms/frame, MPSNR), the Pareto front, and the default marked (PNG in bench/results).
5. The fast end's targets (``--fast-end`` runs only these): the default decode against PyAV's
   HEVC decode to RGB of the x265-medium pseudo-sequence at the same size, on the synthetic
   clip's first frame and every shared sample, interleaved and best of ``--runs`` (at least
   7) each side, against a ratio of :data:`DECODE_TARGET_RATIO`; ``lfstream stream`` of the
   built-in clip and of a real 7x7x375x540 clip of 24 frames (lytro_translucent's views, a
   375 x 540 window panning over them), three runs each, against
   :data:`STREAM_TARGET_FPS`. Every row names the CPU through the document's metadata.

    python bench/throughput.py [--json [FILE]] [--runs N] [--quick] [--device cuda] [--fast-end]
"""

from __future__ import annotations

import cv2
import numpy as np
from _harness import ROOT, emit, parser, timeit

import lfstream
from lfstream.codec import Decoder, Encoder, decode
from lfstream.codec.bitstream import read_header
from lfstream.metrics import capped, mpsnr
from lfstream.refocus import focal_stack
from lfstream.stream import Pipeline, StreamConfig
from lfstream.synth import synth_clip


def stage_rows(views: int, size: tuple[int, int], runs: int, device: str) -> list[dict]:
    import io

    from lfstream.codec.baseline import decode_views, encode_views

    lf = synth_clip(1, views, size, seed=3, motion=0, camera_pan=0).lf[0]
    label = f"{views}x{views}x{size[0]}x{size[1]}"
    rows = []

    def add(stage, fn, r=runs):
        t = timeit(fn, runs=r)
        rows.append({"lf": label, "stage": stage, "ms_per_frame": t["median_s"] * 1e3, "iqr_ms": t["iqr_s"] * 1e3})
        print(f"{label:18s} {stage:28s} {t['median_s'] * 1e3:9.1f} ms")

    add("encode flat", lambda: Encoder(depth_hint=False).encode_frame(lf, 0, 0))
    add("encode hint (key frame)", lambda: Encoder(depth_hint=True).encode_frame(lf, 0, 0), max(1, runs // 2))
    video = Encoder(depth_hint=True)
    video.encode_frame(lf, 0, 0)
    seq = iter(range(1, 1 << 30))  # the frames after a key hint: its range, no coarse pass
    add("encode hint (video frame)", lambda: video.encode_frame(lf, next(seq), 0))
    flat = lfstream.encode(lf, depth_hint=False)
    hint = lfstream.encode(lf, depth_hint=True)
    for name, data, depth in (("decode flat", flat, "flat"), ("decode hint", hint, "hint"), ("decode Depth-Net", hint, "net")):
        hdr = read_header(io.BytesIO(data))
        dec = Decoder(hdr, depth=depth, hance="off", device=device)
        from lfstream.codec.bitstream import iter_packets

        fh = io.BytesIO(data)
        read_header(fh)
        pk = next(iter_packets(fh, hdr))
        add(name, lambda: dec.decode_packet(pk))
    hevc = encode_views(lf, "hevc", 32, constant_qp=True)
    add("HEVC decode (x265 QP32)", lambda: decode_views(hevc, "hevc", lf.shape[:2], lf.shape[2:4]))
    add("focal stack SaS 16", lambda: focal_stack(lf))
    if views == 7:
        add("focal stack RefNet 16", lambda: focal_stack(lf, method="refnet", device=device))
    return rows


def end_to_end(views: int, size: tuple[int, int], frames: int, batch: int, depth_hint: bool, device: str) -> dict:
    clip = list(synth_clip(frames, views, size, seed=9).lf)
    cfg = StreamConfig(refocus="sas", metrics=False, save=(), batch=batch, depth_hint=depth_hint,
                       depth="net" if batch > 1 else "auto", device=device)
    s = Pipeline(iter(clip), cfg, None).run()
    row = {"lf": f"{views}x{views}x{size[0]}x{size[1]}", "stage": "end to end", "frames": s["frames"], "fps": s["fps"],
           "batch": batch, "depth_hint": depth_hint, "stages": s["stages"]}
    print(f"end to end {row['lf']} hint={depth_hint} batch={batch}: {s['fps']:.2f} frames/s  "
          + " ".join(f"{k} {v['ms_per_frame']:.0f}ms" for k, v in s["stages"].items()))
    return row


def pareto(runs: int, device: str) -> list[dict]:
    sea = ROOT.parent / "shared" / "data" / "seahorse5x5" / "camImagesFlat"
    if not sea.exists():
        return []
    lf = lfstream.read_lf(sea)
    points = []
    for label, hint_on, depth, hance in (("flat", False, "flat", "off"), ("flat + JPEG-Hance", False, "flat", "on"),
                                         ("hint", True, "hint", "off"), ("hint + JPEG-Hance", True, "hint", "on"),
                                         ("Depth-Net", True, "net", "off"), ("Depth-Net + JPEG-Hance", True, "net", "on")):
        # the JPEG path for every configuration (seahorse's default, 5x5, codes an AV1 centre,
        # which JPEG-Hance does not restore): the decoder's options on one kind of stream
        data = lfstream.encode(lf, depth_hint=hint_on, preset="fast")
        rec = decode(data, depth=depth, hance=hance, device=device)[0]
        t = timeit(lambda: decode(data, depth=depth, hance=hance, device=device), runs=runs)
        points.append({"config": label, "decode_ms": t["median_s"] * 1e3, "mpsnr": capped(mpsnr(lf, rec)),
                       "bpp": len(data) * 8 / float(np.prod(lf.shape[:4])), "default": label == "hint"})
    for p in points:
        p["pareto"] = not any(q["decode_ms"] <= p["decode_ms"] and q["mpsnr"] >= p["mpsnr"] and q is not p
                              and (q["decode_ms"] < p["decode_ms"] or q["mpsnr"] > p["mpsnr"]) for q in points)
        print(f"pareto seahorse {p['config']:24s} {p['decode_ms']:8.1f} ms  {p['mpsnr']:6.2f} dB  "
              f"{'front' if p['pareto'] else ''}{' (default)' if p['default'] else ''}")
    plot(points, ROOT / "bench" / "results" / "pareto_seahorse.png")
    return points


def plot(points: list[dict], path) -> None:
    w, h, m = 800, 500, 70
    img = np.full((h, w, 3), 255, np.uint8)
    xs = np.log10([p["decode_ms"] for p in points])
    ys = [p["mpsnr"] for p in points]
    x0, x1, y0, y1 = xs.min() - 0.1, xs.max() + 0.1, min(ys) - 1, max(ys) + 1
    cv2.rectangle(img, (m, m), (w - m, h - m), (0, 0, 0), 1)
    cv2.putText(img, "seahorse: decoder MPSNR (dB) vs decode time (ms, log)", (m, 40), cv2.FONT_HERSHEY_SIMPLEX, 0.55,
                (0, 0, 0), 1)
    for p, x, y in zip(points, xs, ys):
        px = int(m + (x - x0) / (x1 - x0) * (w - 2 * m))
        py = int(h - m - (y - y0) / (y1 - y0) * (h - 2 * m))
        colour = (0, 0, 220) if p["default"] else ((0, 150, 0) if p["pareto"] else (120, 120, 120))
        cv2.circle(img, (px, py), 6, colour, -1, cv2.LINE_AA)
        cv2.putText(img, f"{p['config']} {p['decode_ms']:.0f}ms", (px + 8, py - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.42, colour, 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img)


#: frames/s ``lfstream stream`` should reach, built-in clip and a real 7x7x375x540 clip alike
STREAM_TARGET_FPS = 10.0
#: how many times faster than PyAV's HEVC decode to RGB the default decode should be
DECODE_TARGET_RATIO = 2.0
#: the real clip's length and view size (:func:`real_clip`)
REAL_CLIP_FRAMES, REAL_CLIP_SIZE = 24, (375, 540)


def main_command(runs: int, frames: int | None = None, flags: tuple[str, ...] = (), source: str | None = None,
                 label: str = "built-in clip") -> dict:
    """``lfstream stream`` as a user runs it (into a temporary folder), with ``flags``, of
    ``source`` (a file; ``None``: the built-in clip); every run's frames/s and the median."""
    import contextlib
    import io
    import json
    import tempfile
    from pathlib import Path

    from lfstream.cli import main as cli

    fps, last = [], {}
    for _ in range(runs):
        with tempfile.TemporaryDirectory() as tmp:
            argv = (["stream"] + ([source] if source else []) + ["-o", str(Path(tmp) / "out"), "--json", *flags]
                    + (["--frames", str(frames)] if frames else []))
            buf = io.StringIO()
            with contextlib.redirect_stdout(buf):
                code = cli(argv)
            if code != 0:
                raise SystemExit(f"lfstream stream failed with status {code}")
            last = json.loads(buf.getvalue()[buf.getvalue().index("{"):])
            fps.append(last["fps"])
    what = "lfstream stream" + "".join(f" {f}" for f in flags)
    row = {"lf": label, "stage": f"{what} (main command)", "flags": list(flags), "fps_runs": fps,
           "fps_median": float(np.median(fps)), "target_fps": STREAM_TARGET_FPS,
           "ratio_to_target": float(np.median(fps)) / STREAM_TARGET_FPS, "meets_target": min(fps) >= STREAM_TARGET_FPS,
           "warmup_s": last.get("warmup_s"), "process_cpu_ms_per_frame": 1e3 * last["process_cpu_s"] / max(1, last["frames"]),
           "stages": last.get("stages")}
    print(f"{what} [{label}]: {' '.join(f'{f:.2f}' for f in fps)} frames/s (median {row['fps_median']:.2f}; "
          f"{row['ratio_to_target']:.2f}x the target of {STREAM_TARGET_FPS:g})")
    return row


def decode_vs_hevc(runs: int, quick: bool) -> list[dict]:
    """Per scene (:func:`rd.scenes`): the default decode (quality 50) and PyAV's decode to RGB
    of x265 medium's pseudo-sequence searched to the same size, timed in alternation
    (``runs`` rounds, one call each side a round, so that the host's slow spells fall on
    both); the ratio of the best calls and the median of the per-round ratios."""
    import time

    from rd import scenes

    from lfstream.codec.baseline import decode_views, encode_at_bpp
    from lfstream.metrics import bpp

    rows = []
    for name, lf in scenes(quick, None):
        data = lfstream.encode(lf, quality=50)
        rate = bpp(len(data), lf.shape)
        hevc = encode_at_bpp(lf, "hevc", rate, preset="medium")
        jobs = {"lfstream": lambda: lfstream.decode(data),
                "hevc": lambda: decode_views(hevc.data, "hevc", lf.shape[:2], lf.shape[2:4])}
        times: dict[str, list[float]] = {k: [] for k in jobs}
        for fn in jobs.values():  # warm-up
            fn()
        for _ in range(runs):
            for key, fn in jobs.items():
                t0 = time.perf_counter()
                fn()
                times[key].append(time.perf_counter() - t0)
        ours, theirs = np.array(times["lfstream"]), np.array(times["hevc"])
        per_round = theirs / ours
        best = float(theirs.min() / ours.min())
        row = {"lf": name, "stage": "default decode vs HEVC decode to RGB", "shape": list(lf.shape),
               "bpp": rate, "hevc_bpp": hevc.bpp, "runs": runs, "lfstream_best_ms": 1e3 * float(ours.min()),
               "hevc_best_ms": 1e3 * float(theirs.min()), "ratio_best": best,
               "ratio_median": float(np.median(per_round)),
               "ratio_range": [float(per_round.min()), float(per_round.max())], "target_ratio": DECODE_TARGET_RATIO,
               "meets_target": best >= DECODE_TARGET_RATIO}
        print(f"decode vs HEVC {name:18s} {row['lfstream_best_ms']:7.1f} / {row['hevc_best_ms']:7.1f} ms  "
              f"best {row['ratio_best']:.2f}x  rounds {row['ratio_median']:.2f}x ({per_round.min():.2f}-{per_round.max():.2f})")
        rows.append(row)
    return rows


def real_clip(path) -> bool:
    """Writes a real 7x7 light-field video of :data:`REAL_CLIP_FRAMES` frames of
    :data:`REAL_CLIP_SIZE` to ``path`` (``.npy``): lytro_translucent's views (7x7x430x619), a
    window panning across them a few pixels a frame (real views, real noise and shading, the
    motion made). ``False`` where the sample is not beside the repository."""
    from _harness import SHARED, SHARED_SCENES

    folder = SHARED / SHARED_SCENES["lytro_translucent"]
    if not folder.exists():
        return False
    lf = lfstream.read_lf(folder)
    h, w = REAL_CLIP_SIZE
    u, v, full_h, full_w, c = lf.shape
    out = np.lib.format.open_memmap(path, mode="w+", dtype=np.uint8, shape=(REAL_CLIP_FRAMES, u, v, h, w, c))
    for k in range(REAL_CLIP_FRAMES):
        # a pan that turns back at the edges: 2 px down and 3 px right a frame
        y0 = int(np.abs((2 * k) % (2 * (full_h - h)) - (full_h - h)))
        x0 = int(np.abs((3 * k) % (2 * (full_w - w)) - (full_w - w)))
        out[k] = lf[:, :, full_h - h - y0:full_h - y0, full_w - w - x0:full_w - x0]
    out.flush()
    del out
    return True


def fast_end(runs: int, quick: bool) -> list[dict]:
    """Section 5 of the module docstring."""
    import tempfile
    from pathlib import Path

    rows = decode_vs_hevc(max(runs, 7) if not quick else 2, quick)
    stream_runs = 1 if quick else 3
    rows.append(main_command(stream_runs, frames=3 if quick else None))
    with tempfile.TemporaryDirectory() as tmp:
        clip = Path(tmp) / "translucent_pan.npy"
        if not quick and real_clip(clip):
            rows.append(main_command(stream_runs, source=str(clip),
                                     label=f"real clip 7x7x{REAL_CLIP_SIZE[0]}x{REAL_CLIP_SIZE[1]}, {REAL_CLIP_FRAMES} frames"))
    return rows


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--device", default="cpu")
    p.add_argument("--fast-end", action="store_true", help="only section 5: decode against HEVC, stream frames/s")
    args = p.parse_args(argv)
    runs = 1 if args.quick else args.runs
    if args.fast_end:
        return emit(args, fast_end(args.runs, args.quick))
    sizes = [(7, (128, 160))] if args.quick else [(7, (375, 540)), (9, (512, 512)), (13, (256, 256)), (5, (1080, 1920))]
    results = []
    for views, size in sizes:
        results += stage_rows(views, size, runs, args.device)
    e2e_size = (128, 160) if args.quick else (375, 540)
    frames = 4 if args.quick else 16
    results.append(end_to_end(7, e2e_size, frames, 1, False, args.device))
    results.append(end_to_end(7, e2e_size, frames, 1, True, args.device))
    for b in ((1, 4) if not args.quick else (2,)):
        results.append(end_to_end(7, e2e_size, frames, b if b > 1 else 2, True, args.device))
    results.append(main_command(runs, frames=3 if args.quick else None))
    # Depth-Net and JPEG-Hance in the stream, against the same target
    results.append(main_command(runs, frames=3 if args.quick else None, flags=("--hance", "on", "--depth", "net")))
    results += pareto(runs, args.device)
    return emit(args, results)


if __name__ == "__main__":
    main()
