"""Batch encoding on Ray: frames/s with 1 and 2 workers and the scaling efficiency.

A collection of synthetic LF videos (7x7 views) is encoded by ``lfstream.batch`` with the
local engine and with Ray at 1 and 2 workers (a local cluster per run; its start-up is
counted, as a user of ``lfstream batch --engine ray`` pays it). Efficiency = frames/s at
2 workers / (2 x frames/s at 1 worker).

    python bench/batch.py [--json [FILE]] [--quick]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from _harness import emit, parser

from lfstream.cluster import batch
from lfstream.synth import synth_clip


def main(argv=None) -> dict:
    args = parser(__doc__).parse_args(argv)
    videos, frames, size = (2, 6, (96, 128)) if args.quick else (4, 12, (188, 270))
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        paths = []
        for k in range(videos):
            p = tmp / f"video{k}.npy"
            np.save(p, synth_clip(frames, 7, size, seed=k, motion=0.5).lf)
            paths.append(p)
        volume = sum(p.stat().st_size for p in paths)
        for engine, workers in (("local", 1), ("ray", 1), ("ray", 2)):
            r = batch(paths, tmp / f"out-{engine}-{workers}", engine=engine, workers=workers, group_frames=4)
            row = {"engine": engine, "workers": workers, "videos": videos, "frames": r.frames,
                   "input_mb": round(volume / 1e6, 1), "wall_s": round(r.wall_s, 2), "fps": round(r.frames / r.wall_s, 2)}
            results.append(row)
            print(f"{engine:5s} workers {workers}: {r.frames} frames ({row['input_mb']} MB) in {r.wall_s:.2f} s, "
                  f"{row['fps']:.2f} frames/s")
    one, two = results[1]["fps"], results[2]["fps"]
    efficiency = two / (2 * one) if one else None
    print(f"scaling efficiency 1 -> 2 workers: {efficiency:.2f}")
    return emit(args, results, {"scaling_efficiency": efficiency})


if __name__ == "__main__":
    main()
