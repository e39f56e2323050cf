"""lfstream on LF video against HEVC and AV1 pseudo-sequences of the same video, at matched rate.

``bench/codec.py`` and ``bench/rd.py`` code one light field at a time; lfstream is an LF *video*
codec, whose frames after the first reuse the first frame's work (the hint's range and axes,
the post-filter choice, the default's check, delta-coded hints and gains). Here the built-in
clip (``lfstream stream``'s source: a moving layered scene, camera pan, sensor noise and
vignetting, 7x7x375x540) is coded whole by:

- lfstream's default (``lfstream.encode(clip)``: what ``lfstream encode`` and ``lfstream
  stream`` do);
- x265 medium, x265 ultrafast and SVT-AV1 (preset 8), each coding every view of every frame as
  one pseudo-sequence (frame after frame, views in raster order, one key frame), searched to
  lfstream's bits per pixel over the whole clip.

Per method: bpp, MPSNR over every frame, MSSIM on every ``--mssim-every``-th frame, encode and
decode milliseconds per frame (the whole clip's time divided by its frames, median of --runs;
one run of each baseline's encode), and lfstream's speed against each baseline measured in the
same run. The first frame's single-frame encode is timed too, for the comparison with
``bench/codec.py``.

    python bench/video_codec.py [--json [FILE]] [--runs N] [--frames T] [--mssim-every K] [--quick]
"""

from __future__ import annotations

import os

import numpy as np
from _harness import emit, parser, timeit

import lfstream
from lfstream.codec.baseline import decode_views, encode_at_bpp, encode_views
from lfstream.metrics import bpp, capped, mpsnr, mssim
from lfstream.stream.sources import synthetic_source

os.environ.setdefault("SVT_LOG", "1")
BASELINES = (("x265 medium", "hevc", "medium"), ("x265 ultrafast", "hevc", "ultrafast"), ("SVT-AV1 p8", "av1", "8"))


def clip_quality(clip: np.ndarray, rec: np.ndarray, mssim_every: int) -> dict:
    return {"mpsnr": float(np.mean([capped(mpsnr(a, b)) for a, b in zip(clip, rec)])),
            "mssim": float(np.mean([mssim(a, b) for a, b in zip(clip[::mssim_every], rec[::mssim_every])])),
            "mssim_frames": list(range(0, len(clip), mssim_every))}


def as_pseudo_lf(clip: np.ndarray) -> np.ndarray:
    """The clip ``(T, U, V, H, W, 3)`` as one grid of ``T * U`` view rows: the baselines' raster
    order then codes frame after frame, each frame's views row by row, in one sequence."""
    t, u, v = clip.shape[:3]
    return clip.reshape(t * u, v, *clip.shape[3:])


def evaluate(clip: np.ndarray, runs: int, mssim_every: int) -> list[dict]:
    t = len(clip)
    label = "built-in clip " + "x".join(map(str, clip.shape[:5]))
    data = lfstream.encode(clip)
    rec = lfstream.decode(data)
    t_enc = timeit(lambda: lfstream.encode(clip), runs=runs)
    t_dec = timeit(lambda: lfstream.decode(data), runs=runs)
    t_one = timeit(lambda: lfstream.encode(clip[0]), runs=runs)
    rows = [{"clip": label, "method": "lfstream (default)", "bytes": len(data), "bpp": bpp(len(data), clip.shape),
             "encode_ms_per_frame": t_enc["median_s"] * 1e3 / t, "decode_ms_per_frame": t_dec["median_s"] * 1e3 / t,
             "first_frame_alone_encode_ms": t_one["median_s"] * 1e3, **clip_quality(clip, rec, mssim_every)}]
    target = rows[0]["bpp"]
    pseudo = as_pseudo_lf(clip)
    for name, codec, preset in BASELINES:
        res = encode_at_bpp(pseudo, codec, target, preset=preset)
        rec = decode_views(res.data, codec, pseudo.shape[:2], pseudo.shape[2:4]).reshape(clip.shape)
        e = timeit(lambda: encode_views(pseudo, codec, res.quality, constant_qp=res.constant_qp, preset=preset),
                   runs=1, warmup=0)
        d = timeit(lambda: decode_views(res.data, codec, pseudo.shape[:2], pseudo.shape[2:4]), runs=runs)
        rows.append({"clip": label, "method": name, "quality_param": res.quality, "bytes": res.bytes, "bpp": res.bpp,
                     "encode_ms_per_frame": e["median_s"] * 1e3 / t, "decode_ms_per_frame": d["median_s"] * 1e3 / t,
                     **clip_quality(clip, rec, mssim_every)})
    ours = rows[0]
    ours["speed"] = {f"encode_vs_{r['method'].replace(' ', '_')}": r["encode_ms_per_frame"] / ours["encode_ms_per_frame"]
                     for r in rows[1:]}
    ours["speed"].update({f"decode_vs_{r['method'].replace(' ', '_')}": r["decode_ms_per_frame"]
                          / ours["decode_ms_per_frame"] for r in rows[1:]})
    for r in rows:
        print(f"{r['method']:20s} {r['bpp']:.5f} bpp  MPSNR {r['mpsnr']:6.2f}  MSSIM {r['mssim']:.4f}  "
              f"enc {r['encode_ms_per_frame']:8.1f} ms/frame  dec {r['decode_ms_per_frame']:6.1f} ms/frame")
    print(f"  lfstream's first frame encoded alone: {ours['first_frame_alone_encode_ms']:.1f} ms")
    print("  speed: " + ", ".join(f"{k} {v:.1f}x" for k, v in ours["speed"].items()))
    return rows


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--frames", type=int, default=12, help="frames of the built-in clip (default 12, as lfstream stream)")
    p.add_argument("--mssim-every", type=int, default=3, help="MSSIM on every K-th frame")
    args = p.parse_args(argv)
    runs = 1 if args.quick else args.runs
    size = (128, 160) if args.quick else (375, 540)
    frames = 3 if args.quick else args.frames
    # the stream's built-in clip, rendered once and cached (lfstream.stream.sources)
    clip = np.ascontiguousarray(np.stack(list(synthetic_source(frames=frames, size=size))))
    return emit(args, evaluate(clip, runs, max(1, args.mssim_every)))


if __name__ == "__main__":
    main()
