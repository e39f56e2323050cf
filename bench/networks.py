"""Do the networks earn their cost? JPEG-Hance, Depth-Net and RefNet against their
non-learned alternatives, with CPU time (and GPU time with --device cuda).

- JPEG-Hance: PSNR/SSIM gain over plain JPEG and over the decoder's classical post-filter
  (:func:`lfstream.codec.centre.jpeg.deblock_jpeg`) on held-out synthetic centre views and the
  real samples' centre views, per preset, and the gain against JPEG quality (the threshold
  the decoder's ``hance="auto"`` uses); on the decoded LF of each real sample, ``hance="on"``
  against ``"off"``, and with the encoder's strength map (``hance_map=True``).
- Depth-Net: decoded-LF MPSNR/MSSIM with the hint refiner (``depth="net"``) against the bare
  hint, at the default hint resolution and at the coarser one it could buy bits with.
- The seed's pipeline (``--seed``): a JPEG q50 centre view alone, decoded with JPEG-Hance and
  the seed's Depth-Net (``depth="net"`` on a stream without a hint: the disparity from the
  restored centre view, :mod:`lfstream.models.centre_depth`) and flat; lfstream's default
  (centre view and hint); x265 medium and SVT-AV1 preset 4 searched to the seed stream's size:
  bpp, MPSNR, MSSIM, encode and decode time on every shared sample (the scenes as
  ``bench/rd.py`` reads them).
- RefNet: PSNR/SSIM against shift-and-sum on held-out synthetic LFs and the time per
  7x7x375x540 LF of RefNet, SaS and Fourier slice refocusing.
- The networks' ELU at inference (:func:`lfstream.models.layers.elu_`, the CPU kernels)
  against PyTorch's ``elu_`` on the same tensor in the same run (24 x 375 x 540, float32
  and bfloat16; CPU runs only), with their largest difference.

    python bench/networks.py [--json [FILE]] [--runs N] [--quick] [--device cuda] [--seed]

``--seed`` runs the seed comparison alone.
"""

from __future__ import annotations

import numpy as np
import torch
from _harness import SHARED, SHARED_SCENES, emit, parser, timeit

import lfstream
from lfstream.codec import decode
from lfstream.codec.centre.jpeg import deblock_jpeg, decode_jpeg, encode_jpeg, jpeg_quality_scale
from lfstream.codec.hint import HintOptions
from lfstream.lightfield import to_network_input
from lfstream.metrics import capped, mpsnr, mssim, psnr, ssim
from lfstream.models.depth_net import predict_view_disparities
from lfstream.models.device import native_bfloat16
from lfstream.models.jpeg_hance import restore_images
from lfstream.models.registry import load_model, manifest_entry
from lfstream.refocus import focal_stack
from lfstream.synth import synth_clip


def real_lfs(names: tuple[str, ...] = ("seahorse", "dino", "cotton")) -> list[tuple[str, np.ndarray, np.ndarray | None]]:
    out = []
    for name in names:
        if (SHARED / SHARED_SCENES[name]).exists():
            lf, mask = lfstream.read_lf(SHARED / SHARED_SCENES[name], return_mask=True)
            out.append((name, lf, None if mask.all() else mask))
    return out


def trained_on(name: str, preset: str) -> tuple[str, ...]:
    """The real scenes a shipped network was trained on (its manifest recipe): it is judged
    only on the others."""
    entry = manifest_entry(name, preset) or {}
    return tuple(entry.get("recipe", {}).get("scenes", ()))


def timed_precisions(device: str) -> tuple[str, ...]:
    """The inference precisions the timings cover: float32, and bfloat16 where ``device`` has
    it natively (what the decoder's ``"auto"`` then runs; lfstream.models.device)."""
    return ("float32", "bfloat16") if native_bfloat16(device) else ("float32",)


def synthetic_lfs(count: int, size: tuple[int, int], seed: int = 5000) -> list[tuple[str, np.ndarray, np.ndarray]]:
    out = []
    for k in range(count):
        clip = synth_clip(1, 7, size, seed=seed + k, noise=2.0 if k % 2 else 0.0, motion=0, camera_pan=0)
        out.append((f"synthetic {seed + k}", clip.lf[0], clip.disparity[0]))
    return out


def bench_hance(device: str, runs: int, quick: bool) -> list[dict]:
    rows = []
    views = [(n, lf[lf.shape[0] // 2, lf.shape[1] // 2]) for n, lf, _ in synthetic_lfs(2 if quick else 6, (128, 128))]
    views += [(n, lf[lf.shape[0] // 2, lf.shape[1] // 2]) for n, lf, _ in real_lfs(tuple(SHARED_SCENES))]
    for preset in ("fast", "paper"):
        if manifest_entry("jpeg_hance", preset) is None:
            continue
        model = load_model("jpeg_hance", preset, device)
        seen = trained_on("jpeg_hance", preset)
        for q in (10, 30, 50, 60, 70, 90) if not quick else (50,):
            for name, view in views:
                data = encode_jpeg(view, q)
                dec = decode_jpeg(data, view.shape[:2])
                # the non-learned alternative the decoder runs by default
                filt = deblock_jpeg(dec, jpeg_quality_scale(data) or 0.0)
                # a network trained after the post-filter restores the filtered view
                rest = restore_images((filt if model.config.after_deblock else dec)[None], model, device)[0]
                rows.append({"model": "jpeg_hance", "preset": preset, "lf": name, "quality": q,
                             "held_out": name not in seen,
                             "jpeg_psnr": capped(psnr(view, dec)), "hance_psnr": capped(psnr(view, rest)),
                             "deblock_psnr": capped(psnr(view, filt)),
                             "jpeg_ssim": float(ssim(view, dec)), "hance_ssim": float(ssim(view, rest)),
                             "deblock_ssim": float(ssim(view, filt))})
        img = np.ascontiguousarray(np.broadcast_to(views[-1][1][:1, :1], (375, 540, 3)))
        img = (np.random.default_rng(0).random((375, 540, 3)) * 255).astype(np.uint8) if img.std() == 0 else img
        for precision in timed_precisions(device):
            t = timeit(lambda: restore_images(img[None], model, device, precision), runs=runs)
            rows.append({"model": "jpeg_hance", "preset": preset, "timing": "375x540", "device": device,
                         "precision": precision, **t})
    rows += hance_lf_rows(device, quick)
    for r in rows:
        if "quality" in r and r["quality"] == 50:
            label = r["lf"] + ("" if r["held_out"] else " (train)")
            print(f"JPEG-Hance {r['preset']:5s} {label:26s} q50: {r['jpeg_psnr']:6.2f} -> {r['hance_psnr']:6.2f} dB "
                  f"(post-filter {r['deblock_psnr']:6.2f}), SSIM {r['jpeg_ssim']:.4f} -> {r['hance_ssim']:.4f} "
                  f"(post-filter {r['deblock_ssim']:.4f})")
        elif "timing" in r:
            print(f"JPEG-Hance {r['preset']:5s} 375x540 on {device} ({r['precision']}): {r['median_s'] * 1e3:.1f} ms")
    return rows


def decoded_quality(data: bytes, ref: np.ndarray, mask: np.ndarray | None, preset: str = "fast",
                    **decode_options) -> tuple[float, float]:
    """MPSNR (capped) and MSSIM of the first frame of ``data`` decoded with
    ``decode_options`` and the networks of ``preset``, over the views ``mask`` marks present
    (``ref``: those views)."""
    rec = decode(data, preset=preset, **decode_options)[0]
    rec = rec if mask is None else rec[mask][:, None]
    return capped(mpsnr(ref, rec)), float(mssim(ref, rec))


def hance_lf_rows(device: str, quick: bool) -> list[dict]:
    """What counts: the default encode of each real LF (its JPEG centre) decoded
    with JPEG-Hance of each shipped preset (``hance="on"``) against without it (``"off"``:
    the post-filter), MPSNR and MSSIM over the views present, scenes the network trained on
    marked; for the fast preset also with the encoder's strength map."""
    from lfstream.codec.centre.hance import HANCE_MAP_PRESET

    rows = []
    lfs = real_lfs(tuple(SHARED_SCENES)[:1] if quick else tuple(SHARED_SCENES))
    streams = {name: lfstream.encode(lf, present=mask, preset="fast")  # a JPEG centre (seahorse's default is AV1)
               for name, lf, mask in lfs}
    for preset in ("fast", "paper"):
        if manifest_entry("jpeg_hance", preset) is None:
            continue
        seen = trained_on("jpeg_hance", preset)
        for name, lf, mask in lfs:
            data = streams[name]
            ref = lf if mask is None else lf[mask][:, None]
            row = {"model": "jpeg_hance", "preset": preset, "lf": name, "held_out": name not in seen,
                   "decoded_lf": "default encode"}
            for mode in ("off", "on"):
                row[f"{mode}_mpsnr"], row[f"{mode}_mssim"] = decoded_quality(data, ref, mask, preset, hance=mode,
                                                                             device=device)
            line = (f"JPEG-Hance {preset:5s} LF {name + ('' if row['held_out'] else ' (train)'):26s} default "
                    f"encode: MPSNR {row['off_mpsnr']:.3f} -> {row['on_mpsnr']:.3f} dB "
                    f"({row['on_mpsnr'] - row['off_mpsnr']:+.3f}), MSSIM {row['off_mssim']:.4f} -> "
                    f"{row['on_mssim']:.4f}")
            if preset == HANCE_MAP_PRESET:
                # the same encode with the encoder's strength map (lfstream.codec.centre.hance), decoded with the network
                mapped = lfstream.encode(lf, present=mask, preset="fast", hance_map=True)
                row["map_bytes"] = len(mapped) - len(data)
                row["map_mpsnr"], row["map_mssim"] = decoded_quality(mapped, ref, mask, preset, hance="on",
                                                                     device=device)
                line += (f"; with the strength map ({row['map_bytes']} bytes) {row['map_mpsnr']:.3f} dB "
                         f"({row['map_mpsnr'] - row['off_mpsnr']:+.3f}), MSSIM {row['map_mssim']:.4f}")
            rows.append(row)
            print(line)
    return rows


def bench_depth(device: str, runs: int, quick: bool) -> list[dict]:
    """Depth-Net fast (the hint refiner) through the decoder: each real scene's default encode,
    with the hint at 1/4 and at 1/8 resolution (about a third of the hint bytes; the default
    encode chooses between the two per stream, lfstream.codec.rate.HINT_COARSEN_MAX_LOSS_DB),
    decoded with ``depth="hint"`` and ``depth="net"`` (JPEG-Hance off in both); scenes it was
    trained on are marked. The two ways to win: net over hint at the same bits, or
    net on the 1/8 hint at the quality of the 1/4 hint."""
    import io

    from lfstream.codec.bitstream import iter_packets, read_header

    rows = []
    if manifest_entry("depth_net", "fast") is None:
        return rows
    seen = trained_on("depth_net", "fast")
    for name, lf, mask in real_lfs(tuple(SHARED_SCENES)[:1] if quick else tuple(SHARED_SCENES)):
        ref = lf if mask is None else lf[mask][:, None]
        for scale in (4, 8):
            data = lfstream.encode(lf, present=mask, hint_options=HintOptions(hint_scale=scale), preset="fast")
            fh = io.BytesIO(data)
            header = read_header(fh)
            hint_bytes = sum(len(p.hint) for p in iter_packets(fh, header))
            row = {"model": "depth_net", "preset": "fast", "lf": name, "held_out": name not in seen,
                   "hint_scale": scale, "bytes": len(data), "hint_bytes": hint_bytes}
            for mode in ("hint", "net"):
                row[f"{mode}_mpsnr"], row[f"{mode}_mssim"] = decoded_quality(data, ref, mask, depth=mode, hance="off",
                                                                             device=device)
            rows.append(row)
            print(f"Depth-Net fast {name + ('' if row['held_out'] else ' (train)'):26s} hint 1/{scale} "
                  f"({hint_bytes:5d} of {len(data):6d} B): hint {row['hint_mpsnr']:.3f}/{row['hint_mssim']:.4f}  "
                  f"net {row['net_mpsnr']:.3f}/{row['net_mssim']:.4f} ({row['net_mpsnr'] - row['hint_mpsnr']:+.3f} dB)")
    net = load_model("depth_net", "fast", device)
    c = (np.random.default_rng(0).random((1, 375, 540, 3)) * 255).astype(np.uint8)
    h = np.zeros((1, 375, 540), np.float32)
    for precision in timed_precisions(device):
        t = timeit(lambda: predict_view_disparities(c, net, (7, 7), h, device, precision=precision), runs=runs)
        rows.append({"model": "depth_net", "preset": "fast", "timing": "7x7x375x540", "device": device,
                     "precision": precision, **t})
        print(f"Depth-Net fast 375x540 -> 49 maps on {device} ({precision}): {t['median_s'] * 1e3:.1f} ms")
    return rows


def _decode_with(data: bytes, depth: str, hance: str, device: str) -> np.ndarray:
    return decode(data, depth=depth, hance=hance, device=device)[0]


def bench_seed(device: str, runs: int, quick: bool) -> list[dict]:
    """The seed's pipeline against lfstream's default and the anchors at the seed stream's
    size (see the module docstring). Times: the median of ``runs`` calls after one warm-up."""
    from rd import scenes

    from lfstream.codec.baseline import decode_views, encode_at_bpp, encode_views
    from lfstream.metrics import bpp

    rows = []
    for name, lf in scenes(quick, None):
        if name == "synthetic":
            continue
        lf = np.ascontiguousarray(lf)

        def add(method: str, data: bytes, rec: np.ndarray, enc: dict, dec: dict) -> None:
            rows.append({"bench": "seed", "lf": name, "method": method, "bpp": round(bpp(len(data), lf.shape), 5),
                         "mpsnr": round(capped(mpsnr(lf, rec)), 3), "mssim": round(float(mssim(lf, rec)), 4),
                         "encode_ms": round(enc["median_s"] * 1e3, 1), "decode_ms": round(dec["median_s"] * 1e3, 1)})
            print(f"seed table {name:18s} {method:34s} {rows[-1]['bpp']:.4f} bpp  {rows[-1]['mpsnr']:6.2f} dB  "
                  f"{rows[-1]['mssim']:.4f}  enc {rows[-1]['encode_ms']:7.1f} ms  dec {rows[-1]['decode_ms']:7.1f} ms")

        def seed_encode() -> bytes:
            return lfstream.encode(lf, quality=50, depth_hint=False, preset="fast")

        seed = seed_encode()
        enc = timeit(seed_encode, runs=runs)
        for method, depth in (("seed: JPEG q50 + Depth-Net", "net"), ("seed's stream, flat", "flat")):
            add(method + " (JPEG-Hance on)", seed, _decode_with(seed, depth, "on", device), enc,
                timeit(lambda depth=depth: _decode_with(seed, depth, "on", device), runs=runs))
        default = lfstream.encode(lf, quality=50)
        add("lfstream default (centre + hint)", default, decode(default)[0], timeit(lambda: lfstream.encode(lf, quality=50),
                                                                                  runs=runs),
            timeit(lambda: decode(default), runs=runs))
        target = bpp(len(seed), lf.shape)
        for codec, preset, label in (("hevc", "medium", "x265 medium"), ("av1", "4", "SVT-AV1 p4")):
            res = encode_at_bpp(lf, codec, target, preset=preset)
            shape = (lf.shape[:2], lf.shape[2:4])
            add(f"{label} at the seed's size", res.data, decode_views(res.data, codec, *shape),
                timeit(lambda res=res, codec=codec, preset=preset: encode_views(
                    lf, codec, res.quality, constant_qp=res.constant_qp, preset=preset), runs=1, warmup=0),
                timeit(lambda res=res, codec=codec: decode_views(res.data, codec, *shape), runs=runs))
    return rows


def bench_refnet(device: str, runs: int, quick: bool) -> list[dict]:
    rows = []
    if manifest_entry("refnet", "fast") is None:
        return rows
    net = load_model("refnet", "fast", device)

    def against_sas(name: str, ref: np.ndarray, out: np.ndarray) -> None:
        rows.append({"model": "refnet", "lf": name, "psnr_vs_sas": capped(float(np.mean(psnr(ref, out)))),
                     "ssim_vs_sas": float(np.mean(ssim(ref, out)))})
        print(f"RefNet {name:18s} vs SaS: {rows[-1]['psnr_vs_sas']:.2f} dB / {rows[-1]['ssim_vs_sas']:.4f}")

    for name, lf, _ in synthetic_lfs(2 if quick else 6, (128, 128), seed=9000):
        x = to_network_input(lf, device)[None]
        with torch.inference_mode():
            out = (net(x)[0].permute(0, 2, 3, 1).mul(255).add(0.5).clamp(0, 255).byte().cpu().numpy())
        against_sas(name, focal_stack(lf), out)
    # the real 7x7 captures (the target: within 35 dB of SaS on real LFs), whole views
    for name, lf, mask in real_lfs(("lytro_bikes", "lytro_translucent")):
        if mask is None and lf.shape[:2] == tuple(net.config.views):
            against_sas(name, focal_stack(lf), focal_stack(lf, method="refnet", device=device))
    size = (128, 160) if quick else (375, 540)
    lf = synth_clip(1, 7, size, seed=1).lf[0]
    x = to_network_input(lf, device)[None]

    def refnet():
        with torch.inference_mode():
            net(x)
            if device.startswith("cuda"):
                torch.cuda.synchronize()

    methods = [("refnet fast", refnet, device), ("sas", lambda: focal_stack(lf), "cpu"),
               ("fourier", lambda: focal_stack(lf, method="fourier"), "cpu")]
    if device.startswith("cuda"):  # RefNet is compared with SaS on the same GPU
        lf_dev = torch.from_numpy(lf).to(device)

        def sas_on_device():
            focal_stack(lf_dev)
            torch.cuda.synchronize()

        methods.append(("sas (torch)", sas_on_device, device))
    for method, fn, dev in methods:
        t = timeit(fn, runs=runs)
        rows.append({"model": "refnet", "timing": f"7x7x{size[0]}x{size[1]}", "method": method, "device": dev, **t})
        print(f"focal stack 16 planes {method:12s} ({dev}): {t['median_s'] * 1e3:8.1f} ms")
    return rows


def bench_elu(runs: int, quick: bool) -> list[dict]:
    """lfstream's ELU kernels against PyTorch's ``elu_`` on one JPEG-Hance fast activation
    (24 channels of a 375 x 540 view), timed alternately in this run."""
    from lfstream.models.layers import elu_

    size = (96, 128) if quick else (375, 540)
    x = torch.randn(1, 24, *size, generator=torch.Generator().manual_seed(0)) * 2
    rows = []
    for dtype in (torch.float32, torch.bfloat16):
        src = x.to(dtype)
        work = src.clone()
        with torch.inference_mode():
            ours = timeit(lambda: elu_(work.copy_(src)), runs=max(runs, 5) * 4)
            theirs = timeit(lambda: torch.nn.functional.elu(work.copy_(src), inplace=True), runs=max(runs, 5) * 4)
            copy = timeit(lambda: work.copy_(src), runs=max(runs, 5) * 4)
            diff = float((elu_(src.clone()).double() - torch.nn.functional.elu(src.double()).to(dtype).double()).abs().max())
        name = str(dtype).removeprefix("torch.")
        rows.append({"model": "elu", "dtype": name, "shape": list(x.shape), "lfstream_s": ours["median_s"],
                     "torch_s": theirs["median_s"], "copy_s": copy["median_s"], "max_abs_diff": diff})
        print(f"ELU 24x{size[0]}x{size[1]} {name:8s}: lfstream {ours['median_s'] * 1e3:6.3f} ms, PyTorch "
              f"{theirs['median_s'] * 1e3:6.3f} ms ({theirs['median_s'] / ours['median_s']:.1f}x; a copy "
              f"{copy['median_s'] * 1e3:.3f} ms in both), largest difference {diff:.2g}")
    return rows


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--device", default="cpu")
    p.add_argument("--seed", action="store_true", help="the seed comparison alone")
    args = p.parse_args(argv)
    runs = 1 if args.quick else args.runs
    if args.seed:
        return emit(args, bench_seed(args.device, runs, args.quick))
    results = bench_elu(runs, args.quick) if args.device == "cpu" else []
    results += bench_hance(args.device, runs, args.quick) + bench_depth(args.device, runs, args.quick)
    results += bench_refnet(args.device, runs, args.quick)
    return emit(args, results)


if __name__ == "__main__":
    main()
