"""The encoder's plane sweep on a torch device against the CPU kernels (the hint's encode on
a GPU).

For the synthetic clip's first frame and every 7x7-or-larger shared sample, the key hint's
map (:func:`lfstream.codec.hint.estimate_hint_map`: luma block means, axes, range pass,
sweep) on the CPU kernels and with its two sweeps on ``--device``
(:mod:`lfstream.codec.hint.sweep_batched`), and the main sweep alone both ways (the luma and
axes before it stay on the CPU either way). Rows: ms per frame (median of ``--runs``), and
how far the device's map is from the kernels' (share of cells within 0.001 px, largest
difference; the tests bound both). On the CPU the tensor path is a reference, not a path:
its gathers cost far more than the fused kernel.

    python bench/hint_sweep.py [--device cuda] [--runs 5] [--json [FILE]] [--quick]
"""

from __future__ import annotations

import numpy as np
import torch
from _harness import emit, parser, timeit
from rd import scenes

from lfstream.codec import hint as hint_mod
from lfstream.codec.hint import HintOptions, estimate_hint_map, sweep_views
from lfstream.lightfield import view_offsets


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    args = p.parse_args(argv)
    runs = 1 if args.quick else args.runs
    device = str(torch.device(args.device))
    sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)
    rows = []
    for name, lf in scenes(args.quick, None):
        if lf.shape[0] * lf.shape[1] < 49:
            continue
        lf = np.ascontiguousarray(lf)
        opts = HintOptions()
        u, v = lf.shape[:2]
        keys = sweep_views(u, v)
        grids = hint_mod._high_pass(hint_mod._grids(lf, [(u // 2, v // 2), *keys], opts.work_scale))
        rows_, cols_ = np.asarray(keys).T
        offsets = np.ascontiguousarray(view_offsets((u, v), np.eye(2, dtype=np.float32))[rows_, cols_])
        ref_map = estimate_hint_map(lf, opts)
        lo, hi = ref_map.search
        on_device = hint_mod.sweeps_on_device

        def tensor_path(d):  # the tensor sweep on any device, "cpu" included (a reference)
            return True

        hint_mod.sweeps_on_device = tensor_path
        try:
            dev_map = estimate_hint_map(lf, opts, device=device)
            t_dev = timeit(lambda: (estimate_hint_map(lf, opts, device=device), sync()), runs=runs)
            s_dev = timeit(lambda: (hint_mod._sweep(grids, offsets, lo, hi, opts.work_scale, opts, device=device),
                                    sync()), runs=runs)
        finally:
            hint_mod.sweeps_on_device = on_device
        t_cpu = timeit(lambda: estimate_hint_map(lf, opts), runs=runs)
        s_cpu = timeit(lambda: hint_mod._sweep(grids, offsets, lo, hi, opts.work_scale, opts), runs=runs)
        diff = np.abs(dev_map.disparity - ref_map.disparity)
        row = {"scene": name, "shape": list(lf.shape), "device": device,
               "hint_map_ms_cpu": t_cpu["median_s"] * 1e3, "hint_map_ms_device": t_dev["median_s"] * 1e3,
               "sweep_ms_cpu": s_cpu["median_s"] * 1e3, "sweep_ms_device": s_dev["median_s"] * 1e3,
               "share_within_1e-3_px": float(np.mean(diff <= 1e-3)), "max_diff_px": float(diff.max())}
        rows.append(row)
        print(f"{name:18s} hint map {row['hint_map_ms_cpu']:7.1f} ms (kernels) {row['hint_map_ms_device']:8.1f} ms "
              f"({device})   sweep {row['sweep_ms_cpu']:6.1f} / {row['sweep_ms_device']:8.1f} ms   "
              f"cells within 0.001 px {row['share_within_1e-3_px']:.4f}, largest {row['max_diff_px']:.2g} px",
              flush=True)
    return emit(args, rows)


if __name__ == "__main__":
    main()
