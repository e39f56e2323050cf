"""Focal-stack speed: exact shift-and-sum against naive baselines and Fourier slice.

Target: 16 planes of a 7x7x375x540 RGB light field in <= 0.25 s on the 2-core
CPU, reported as a ratio to a naive per-view grid_sample loop timed in the same run.

    python bench/refocus.py [--json [FILE]] [--runs N] [--quick]
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from _harness import emit, parser, timeit

from lfstream.metrics import psnr
from lfstream.optics import SEED_ALPHAS, slopes_from_alphas
from lfstream.refocus import fourier_slice, shift_and_sum
from lfstream.synth import synth_clip


def naive_grid_sample(lf: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    """The obvious torch implementation: one grid_sample per view and plane."""
    u_n, v_n, h, w, _ = lf.shape
    x = torch.from_numpy(lf).permute(0, 1, 4, 2, 3).float() / 255.0
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    out = []
    for s in slopes:
        acc = torch.zeros(3, h, w)
        for u in range(u_n):
            for v in range(v_n):
                gy = (ys - s * (u - u_n // 2)) / (h - 1) * 2 - 1
                gx = (xs - s * (v - v_n // 2)) / (w - 1) * 2 - 1
                grid = torch.stack([gx, gy], -1)[None]
                acc += F.grid_sample(x[u, v][None], grid, mode="bilinear", padding_mode="zeros", align_corners=True)[0]
        out.append(acc / (u_n * v_n))
    return torch.stack(out).permute(0, 2, 3, 1).numpy()


def cv2_warp_loop(lf: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    """A per-view cv2.warpAffine loop, accumulating in float32."""
    import cv2

    u_n, v_n, h, w, _ = lf.shape
    out = np.empty((len(slopes), h, w, 3), np.float32)
    for k, s in enumerate(slopes):
        acc = np.zeros((h, w, 3), np.float32)
        for u in range(u_n):
            for v in range(v_n):
                m = np.float32([[1, 0, -s * (v - v_n // 2)], [0, 1, -s * (u - u_n // 2)]])
                acc += cv2.warpAffine(lf[u, v], m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
        out[k] = acc / (255.0 * u_n * v_n)
    return out


def main(argv=None) -> dict:
    args = parser(__doc__).parse_args(argv)
    size = (120, 180) if args.quick else (375, 540)
    runs = 2 if args.quick else args.runs
    lf = synth_clip(1, 7, size, seed=0).lf[0]
    slopes = slopes_from_alphas(SEED_ALPHAS)
    results = []

    def record(name, fn, runs_=runs):
        r = {"name": name, "planes": len(slopes), "lf_shape": list(lf.shape), **timeit(fn, runs=runs_)}
        results.append(r)
        print(f"{name:28s} {r['median_s'] * 1000:9.1f} ms  (IQR {r['iqr_s'] * 1000:.1f} ms)")
        return r

    naive = record("naive_grid_sample_loop", lambda: naive_grid_sample(lf, slopes), runs_=max(1, runs // 2))
    record("cv2_warpaffine_loop", lambda: cv2_warp_loop(lf, slopes))
    sas = record("sas_fused", lambda: shift_and_sum(lf, slopes))
    flr = record("fourier_slice", lambda: fourier_slice(lf, slopes))
    ref = shift_and_sum(lf, slopes)
    got = fourier_slice(lf, slopes)
    flr["psnr_vs_sas_db"] = [float(psnr(got[k], ref[k], data_range=1.0)) for k in range(len(slopes))]
    sas["speedup_vs_naive"] = naive["median_s"] / sas["median_s"]
    sas["target_s"] = 0.25
    sas["meets_target"] = bool(sas["median_s"] <= 0.25) if not args.quick else None
    # Fourier slice: fixed 4-D FFT cost plus a per-plane cost; find where it beats SaS.
    many = np.linspace(slopes.min(), slopes.max(), 64)
    flr64 = timeit(lambda: fourier_slice(lf, many), runs=max(1, runs // 2))["median_s"]
    sas64 = timeit(lambda: shift_and_sum(lf, many), runs=max(1, runs // 2))["median_s"]
    per_plane_flr = (flr64 - flr["median_s"]) / 48
    setup_flr = flr["median_s"] - 16 * per_plane_flr
    per_plane_sas = sas64 / 64
    crossover = setup_flr / (per_plane_sas - per_plane_flr) if per_plane_sas > per_plane_flr else None
    summary = {"sas_ms_per_plane": per_plane_sas * 1e3, "flr_setup_ms": setup_flr * 1e3,
               "flr_ms_per_plane": per_plane_flr * 1e3, "flr_beats_sas_from_planes": crossover}
    print(f"SaS {sas['median_s']:.3f} s for 16 planes: {sas['speedup_vs_naive']:.1f}x the naive loop")
    verdict = f"FLR faster from {crossover:.0f} planes" if crossover else "FLR never faster (its per-plane cost is higher)"
    print(f"FLR setup {setup_flr * 1e3:.0f} ms + {per_plane_flr * 1e3:.1f} ms/plane; "
          f"SaS {per_plane_sas * 1e3:.1f} ms/plane; {verdict}")
    return emit(args, results, {"summary": summary})


if __name__ == "__main__":
    main()
