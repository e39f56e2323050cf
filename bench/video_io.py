"""LF video files: writing and reading a lossless mosaic video, and the commands that read one.

1. The lossless mosaic formats lfstream writes (:data:`lfstream.io.video.LOSSLESS_CODECS`):
   ``.mp4`` (x264 RGB, QP 0, :data:`lfstream.io.video.LOSSLESS_X264`: CAVLC) against its
   settings before (``veryfast``, CABAC), ``.mkv`` (FFV1) and ``.avi`` (Ut Video), on the
   same frames in the same run: ms a frame to write, ms a frame of wall and CPU time to read
   (decode and RGB conversion), MB a frame.
2. ``lfstream stream``, ``encode``, ``decode -o clip.mp4`` and ``info`` on the ``.mp4`` clip,
   and ``lfstream stream`` on the ``.avi`` one, each in a fresh process: seconds and peak
   memory.

The clip is the synthetic renderer's, 7x7x375x540 unless ``--quick``.

    python bench/video_io.py [--frames N] [--json [FILE]] [--quick]
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _harness import ROOT, emit, parser

from lfstream.io import VideoWriter, grid_metadata, iter_video_frames
from lfstream.lightfield import to_mosaic
from lfstream.synth import SynthConfig, iter_clip

#: What the lossless .mp4 writer used before CAVLC.
PREVIOUS_X264 = {"qp": "0", "preset": "veryfast"}


def write(path: Path, mosaics: list[np.ndarray], options: dict, fps: float = 30.0) -> float:
    """Seconds a frame to write ``mosaics`` as a lossless mosaic video with x264 ``options``."""
    import av

    t0 = time.perf_counter()
    with av.open(str(path), "w") as out:
        stream = out.add_stream("libx264rgb", rate=int(fps), options=options)
        stream.width, stream.height, stream.pix_fmt = mosaics[0].shape[1], mosaics[0].shape[0], "rgb24"
        for k, v in grid_metadata((7, 7)).items():
            out.metadata[k] = v
        for img in mosaics:
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    return (time.perf_counter() - t0) / len(mosaics)


def write_lossless(path: Path, mosaics: list[np.ndarray], fps: float = 30.0) -> float:
    """Seconds a frame to write ``mosaics`` through lfstream's lossless writer for the extension."""
    t0 = time.perf_counter()
    with VideoWriter(path, fps, lossless=True, metadata=grid_metadata((7, 7))) as w:
        for m in mosaics:
            w.write(m)
    return (time.perf_counter() - t0) / len(mosaics)


def read(path: Path, mosaics: list[np.ndarray]) -> tuple[float, float]:
    """Wall and CPU seconds a frame to read ``path`` back to RGB (checked equal to ``mosaics``)."""
    t0, c0 = time.perf_counter(), time.process_time()
    frames = list(iter_video_frames(path))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if len(frames) != len(mosaics) or not all(np.array_equal(a, b) for a, b in zip(frames, mosaics)):
        raise SystemExit(f"{path}: not lossless")
    return wall / len(frames), cpu / len(frames)


def command(argv: list[str]) -> dict:
    """Seconds and peak memory (MB) of one ``lfstream`` command in a fresh process."""
    # the peak of the command's own memory (VmHWM: getrusage's maximum carries the forking
    # parent's over exec)
    code = ("import sys; from lfstream.cli import main; rc = main(sys.argv[1:]); "
            "print([l.split()[1] for l in open('/proc/self/status') if l.startswith('VmHWM')][0], file=sys.stderr); "
            "sys.exit(rc)")
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"lfstream {' '.join(argv)}: {done.stderr.strip()}")
    peak_kb = int(done.stderr.strip().splitlines()[-1])
    return {"s": seconds, "peak_mb": peak_kb / 1024, "stdout": done.stdout.strip().splitlines()[:1]}


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--frames", type=int, default=12)
    args = p.parse_args(argv)
    frames, size = (3, (64, 96)) if args.quick else (args.frames, (375, 540))
    cfg = SynthConfig(frames=frames, views=7, size=size, layers=4, motion=1.0, camera_pan=0.4, noise=1.5,
                      vignetting=0.2, seed=2024)
    mosaics = [to_mosaic(lf) for lf, _ in iter_clip(cfg)]
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        clips = {}
        for name, ext, options in (("lossless mp4, previous (veryfast, CABAC)", ".mp4", PREVIOUS_X264),
                                   ("lossless mp4 (x264 faster, CAVLC)", ".mp4", None),
                                   ("lossless mkv (FFV1)", ".mkv", None), ("lossless avi (Ut Video)", ".avi", None)):
            path = folder / f"{len(results)}{ext}"
            write_s = write(path, mosaics, options) if options is not None else write_lossless(path, mosaics)
            read_wall, read_cpu = read(path, mosaics)
            row = {"name": name, "write_ms": write_s * 1e3, "read_wall_ms": read_wall * 1e3,
                   "read_cpu_ms": read_cpu * 1e3, "mb_per_frame": path.stat().st_size / len(mosaics) / 1e6}
            results.append(row)
            if options is None:
                clips.setdefault(ext, path)
            print(f"{row['name']:42s} write {row['write_ms']:7.1f} ms  read {row['read_wall_ms']:7.1f} ms wall, "
                  f"{row['read_cpu_ms']:7.1f} ms CPU  {row['mb_per_frame']:.2f} MB a frame")
        old, new = results[:2]
        print(f"  the mp4 writer's settings: reading {old['read_cpu_ms'] / new['read_cpu_ms']:.2f}x less CPU, writing "
              f"{old['write_ms'] / new['write_ms']:.2f}x faster, {new['mb_per_frame'] / old['mb_per_frame'] - 1:+.1%} bytes")
        del mosaics
        clip, fast = clips[".mp4"], clips[".avi"]
        runs = [("info", ["info", str(clip)]),
                ("encode", ["encode", str(clip), "-o", str(folder / "clip.lfs")]),
                ("decode -o .mp4", ["decode", str(folder / "clip.lfs"), "-o", str(folder / "back.mp4")]),
                ("stream", ["stream", str(clip), "-o", str(folder / "out"), "--json"]),
                ("stream .avi", ["stream", str(fast), "-o", str(folder / "out_avi"), "--json"])]
        for name, cmd in runs:
            r = command(cmd)
            row = {"name": f"lfstream {name}", "frames": frames, "s": r["s"], "peak_mb": r["peak_mb"]}
            if name.startswith("stream"):
                import json

                summary = json.loads((Path(cmd[3]) / "summary.json").read_text())
                row["fps"] = summary.get("fps")
            results.append(row)
            print(f"lfstream {name:16s} {r['s']:6.2f} s  peak {r['peak_mb']:7.0f} MB"
                  + (f"  {row['fps']:.2f} frames/s" if row.get("fps") else ""))
    return emit(args, results, {"clip": {"frames": frames, "views": [7, 7], "size": list(size)},
                                "max_rss_mb_bench": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024})


if __name__ == "__main__":
    main()
