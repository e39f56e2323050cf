"""Memory over a long stream with a slow sink: resident set size every 50 frames.

    python bench/memory.py [--frames 500] [--sink-delay 0.1] [--json [FILE]]

The source cycles one pre-rendered frame (so the producer is never the bottleneck) and the
sink sleeps ``--sink-delay`` per frame (about 10x the pipeline's own per-frame time at the
default size): with bounded queues the producer is throttled and the RSS stays flat.
"""

from __future__ import annotations

import os
import threading
import time

from _harness import emit, parser

from lfstream.stream import Pipeline, StreamConfig
from lfstream.synth import synth_clip


def rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--frames", type=int, default=500)
    p.add_argument("--sink-delay", type=float, default=0.1)
    p.add_argument("--size", type=int, nargs=2, default=(128, 160))
    args = p.parse_args(argv)
    frame = synth_clip(1, 7, tuple(args.size), seed=1).lf[0]

    def source():
        for _ in range(args.frames):
            yield frame

    pipe = Pipeline(source(), StreamConfig(refocus="sas", metrics=False, save=(), depth_hint=False), None,
                    sink_delay_s=args.sink_delay)
    samples = []

    def watch():
        while not done.is_set():
            samples.append({"sink_frames": pipe.stats["sink"].frames, "producer_frames": pipe.stats["producer"].frames,
                            "rss_mb": round(rss_mb(), 1)})
            time.sleep(1.0)

    done = threading.Event()
    t = threading.Thread(target=watch, daemon=True)
    t.start()
    summary = pipe.run()
    done.set()
    t.join()
    after_warmup = [s["rss_mb"] for s in samples if s["sink_frames"] >= 20]
    result = {"frames": summary["frames"], "fps": summary["fps"], "rss_first_mb": after_warmup[0] if after_warmup else None,
              "rss_max_mb": max(after_warmup) if after_warmup else None,
              "max_producer_lead": max(s["producer_frames"] - s["sink_frames"] for s in samples), "samples": samples}
    print(f"{result['frames']} frames at {result['fps']} fps; RSS after warm-up {result['rss_first_mb']} MB, "
          f"max {result['rss_max_mb']} MB; producer at most {result['max_producer_lead']} frames ahead of the sink")
    return emit(args, [result])


if __name__ == "__main__":
    main()
