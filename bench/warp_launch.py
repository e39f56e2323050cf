"""Launch settings of the decoder's Triton warp kernels (:mod:`lfstream.codec.warp.triton`:
pixels and warps a program of the per-pixel warp and the splat, warps of the row kernels),
each alternated with the others in one process on the same decoded frames: the time a call
per setting, its ratio to the module's settings, the bytes checked equal to theirs, and the
combination of each dimension's best (where it beats the module's by more than 1 %) raced
against them. It reports; the settings in the module change only by hand (needs a CUDA
device and Triton).

    python bench/warp_launch.py [--batch 30] [--frames 8] [--rounds 20] [--json [FILE]]
"""

from __future__ import annotations

import time

import numpy as np
import torch
from _harness import emit, parser, timeit
from batched_warp import decoded_frames

from lfstream.codec.warp.batched import warp_views_batched

#: the module constants a setting may change, and the values tried besides the module's
CHOICES = {"_BLOCK": (256, 512, 1024), "_WARP_WARPS": (2, 4, 8), "_SPLAT_BLOCK": (256, 512, 1024),
           "_SPLAT_WARPS": (2, 4, 8), "_ROW_WARPS": (1, 2, 4, 8)}


def race(settings: dict[str, dict], call, apply, rounds: int) -> dict[str, list[float]]:
    """Seconds a call of each setting, the settings in a rotating order each round."""
    names = list(settings)
    times: dict[str, list[float]] = {k: [] for k in names}
    for r in range(rounds):
        for k in names[r % len(names):] + names[:r % len(names)]:
            apply(settings[k])
            t = time.perf_counter()
            call()
            times[k].append(time.perf_counter() - t)
    return times


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--batch", type=int, default=30, help="light fields a call")
    p.add_argument("--frames", type=int, default=8, help="distinct frames, repeated to fill the batch")
    p.add_argument("--rounds", type=int, default=20)
    args = p.parse_args(argv)
    if not torch.cuda.is_available():
        print("warp_launch: needs a CUDA device")
        return {}
    try:
        from lfstream.codec.warp import triton as warp_triton
    except ImportError:
        print("warp_launch: needs Triton (CUDA builds of torch bring it)")
        return {}
    views, size = (5, (96, 128)) if args.quick else (7, (375, 540))
    rounds = 3 if args.quick else args.rounds
    frames, _, _ = decoded_frames(max(1, min(args.frames, args.batch)), views, size, 1)
    pick = [frames[k % len(frames)] for k in range(args.batch)]
    dev = torch.device("cuda")
    c = torch.from_numpy(np.stack([f.centre for f in pick])).to(dev)
    d = torch.from_numpy(np.stack([f.disparity for f in pick]).astype(np.float32)).to(dev)
    g = torch.from_numpy(np.stack([f.gains if f.gains is not None else np.ones((views, views, 1, 1, 1), np.float32)
                                   for f in pick])).to(dev)
    module = {k: getattr(warp_triton, k) for k in CHOICES}

    def apply(setting: dict) -> None:
        for k, v in {**module, **setting}.items():
            setattr(warp_triton, k, v)

    def call() -> torch.Tensor:
        out = warp_views_batched(c, d, (views, views), gains=g, axes=pick[0].axes)
        torch.cuda.synchronize()
        return out

    settings: dict[str, dict] = {"module": {}}
    for key, values in CHOICES.items():
        settings.update({f"{key.strip('_').lower()}={v}": {key: v} for v in values if v != module[key]})
    try:
        apply({})
        ref = call().cpu()
        for name, setting in settings.items():  # compiles each, and checks its bytes
            apply(setting)
            if not torch.equal(call().cpu(), ref):
                raise SystemExit(f"warp_launch: {name} changes the bytes")
        times = race(settings, call, apply, rounds)
        base = np.array(times["module"])
        rows = []
        for name, ts in times.items():
            ratio = float(np.median(base / np.array(ts)))
            rows.append({"setting": name, "batch": args.batch, "ms_per_call": float(np.median(ts)) * 1e3,
                         "module_over_this": ratio})
            print(f"{name:20s} {np.median(ts) * 1e3:8.2f} ms a call  module/this {ratio:.3f}")
        best: dict = {}
        for key in CHOICES:
            mine = [r for r in rows if r["setting"] != "module" and key in settings[r["setting"]]]
            top = max(mine, key=lambda r: r["module_over_this"], default=None)
            if top is not None and top["module_over_this"] > 1.01:
                best.update(settings[top["setting"]])
        extra: dict = {"module": module, "combined": best}
        if best:
            both = race({"module": {}, "combined": best}, call, apply, max(rounds, 30))
            ratio = float(np.median(np.array(both["module"]) / np.array(both["combined"])))
            apply(best)
            t = timeit(call, runs=5)
            extra.update(combined_over_module=ratio, combined_lf_per_s=args.batch / t["median_s"])
            print(f"combined {best}: module/combined {ratio:.3f}, {args.batch / t['median_s']:.0f} LF/s")
        apply({})
        t = timeit(call, runs=5)
        extra["module_lf_per_s"] = args.batch / t["median_s"]
        print(f"module settings {module}: {args.batch / t['median_s']:.0f} LF/s")
    finally:
        apply({})
    return emit(args, rows, extra)


if __name__ == "__main__":
    main()
