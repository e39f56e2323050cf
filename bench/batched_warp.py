"""The decoder's warp batched on a torch device against the fused CPU kernel, in light fields
per second: the seed's GPU measurement (30 light fields of 7x7x375x540 in under 0.02 s, i.e.
1500 LF/s or more) as lfstream does it.

Decoded centre views, disparities (the hint, edge-aware up-sampled) and gain maps of the
default encode of distinct frames of the built-in synthetic clip are warped into every view
(:func:`lfstream.codec.warp.batched.warp_views_batched`), ``--batch`` frames per call, on
``--device``; in the same run the CPU kernel (:func:`lfstream.codec.warp.cpu.warp_views`, all
cores) warps the same frames one by one. Rows: LF/s of each, the device's both with the
frames already on it and with the host-to-device copy of the inputs and the copy of the light
fields back, and the largest difference from the kernel's bytes (the tests bound it to one
level). The centre-view and hint decodes that precede the warp run on the CPU either way
(ms per frame, reported): on a GPU they bound the whole decode's rate unless spread over
cores or streams.

    python bench/batched_warp.py [--device cuda] [--batch 30] [--frames 4] [--runs 5] [--json [FILE]]
"""

from __future__ import annotations

import io

import numpy as np
import torch
from _harness import emit, parser, timeit

import lfstream
from lfstream.codec.api import iter_decode
from lfstream.codec.bitstream import iter_packets, read_header
from lfstream.codec.decoder import Decoder
from lfstream.codec.hint import HintDecoder
from lfstream.codec.warp.batched import warp_views_batched
from lfstream.codec.warp.cpu import warp_views
from lfstream.synth import synth_clip


def decoded_frames(frames: int, views: int, size: tuple[int, int], runs: int) -> tuple[list, float, bytes]:
    """The default encode of ``frames`` distinct frames, decoded (the warp's inputs), and the
    CPU's time for a frame's part before the warp: the centre view (JPEG and post-filter) and
    the hint (edge-aware up-sampling), in ms, and the stream."""
    clip = synth_clip(frames, views, size, seed=21, noise=2.0, vignetting=0.3)
    data = lfstream.encode(clip.lf)
    fh = io.BytesIO(data)
    header = read_header(fh)
    packet = next(iter_packets(fh, header))
    decoder = Decoder(header, hance="off")

    def before_warp():
        centre = decoder.decode_centres([packet])[0]
        HintDecoder().decode_with_axes(packet.hint, header.size, guide=centre, frame=packet.seq)

    return list(iter_decode(io.BytesIO(data), hance="off")), timeit(before_warp, runs=runs)["median_s"] * 1e3, data


def main(argv=None) -> dict:
    p = parser(__doc__)
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--batch", type=int, help="light fields per call (default 30 on CUDA, 2 on the CPU)")
    p.add_argument("--frames", type=int, default=4, help="distinct frames, repeated to fill the batch")
    args = p.parse_args(argv)
    quick = args.quick
    views, size = (5, (96, 128)) if quick else (7, (375, 540))
    device = torch.device(args.device)
    cuda = device.type == "cuda"
    batch = args.batch or (30 if cuda else 2)
    runs = 1 if quick else args.runs
    frames, before_ms, stream = decoded_frames(max(1, min(args.frames, batch)), views, size, runs)
    pick = [frames[k % len(frames)] for k in range(batch)]
    label = f"{batch} x {views}x{views}x{size[0]}x{size[1]}"
    shape = (views, views)

    def gains_of(fr):
        return fr.gains if fr.gains is not None else np.ones((views, views, 1, 1, 1), np.float32)

    centres = torch.from_numpy(np.stack([fr.centre for fr in pick]))
    disps = torch.from_numpy(np.stack([fr.disparity for fr in pick]).astype(np.float32))
    gains = torch.from_numpy(np.stack([gains_of(fr) for fr in pick]))
    sync = torch.cuda.synchronize if cuda else (lambda: None)

    def kernel():
        for fr in pick:
            warp_views(fr.centre, fr.disparity, shape, gains=fr.gains, axes=fr.axes)

    on_device = [x.to(device) for x in (centres, disps, gains)]

    def resident():
        warp_views_batched(*on_device[:2], shape, gains=on_device[2], axes=pick[0].axes)
        sync()

    def resident_flat():  # every view with the centre map: the splat's share of the time
        warp_views_batched(*on_device[:2], shape, gains=on_device[2], axes=pick[0].axes, occlusion=False)
        sync()

    def round_trip():
        c, d, g = (x.to(device, non_blocking=True) for x in (centres, disps, gains))
        warp_views_batched(c, d, shape, gains=g, axes=pick[0].axes).cpu()

    # page-locked host buffers: the copies run at the bus's rate (a pageable copy is staged)
    pinned_in = [x.pin_memory() for x in (centres, disps, gains)] if cuda else None
    pinned_out = torch.empty((batch, *shape, *size, 3), dtype=torch.uint8, pin_memory=True) if cuda else None

    def pinned_trip():
        c, d, g = (x.to(device, non_blocking=True) for x in pinned_in)
        pinned_out.copy_(warp_views_batched(c, d, shape, gains=g, axes=pick[0].axes), non_blocking=True)
        sync()

    def whole_decode():  # the stream's frames in one batch: centre and hint on the CPU, the warp on the device
        list(iter_decode(io.BytesIO(stream), hance="off", device=str(device), batch=len(frames)))

    ref = warp_views(pick[0].centre, pick[0].disparity, shape, gains=pick[0].gains, axes=pick[0].axes)
    got = warp_views_batched(*on_device[:2], shape, gains=on_device[2], axes=pick[0].axes)[0].cpu().numpy()
    max_diff = int(np.abs(got.astype(int) - ref.astype(int)).max())
    rows = []
    for name, fn, dev in (("kernel (numba, all cores)", kernel, "cpu"), ("batched, inputs on the device", resident,
                                                                          str(device)),
                          ("batched, inputs on the device, no splat", resident_flat, str(device)),
                          ("batched, with the copies", round_trip, str(device)),
                          *((("batched, copies via pinned buffers", pinned_trip, str(device)),) if cuda else ()),
                          (f"whole decode of the {len(frames)}-frame stream", whole_decode, str(device))):
        t = timeit(fn, runs=runs)
        lfs = (len(frames) if name.startswith("whole") else batch) / t["median_s"]
        rows.append({"lf": label, "stage": f"warp: {name}", "device": dev, "lf_per_s": lfs,
                     "ms_per_call": t["median_s"] * 1e3, "iqr_ms": t["iqr_s"] * 1e3})
        print(f"{label:24s} warp: {name:32s} {dev:6s} {lfs:9.1f} LF/s  ({t['median_s'] * 1e3:.1f} ms a call)")
    print(f"centre view and hint decode on the CPU (before the warp, either way): {before_ms:.1f} ms a frame; "
          f"largest difference from the kernel's bytes: {max_diff} level(s)")
    speedup = rows[1]["lf_per_s"] / rows[0]["lf_per_s"]
    print(f"batched on {device} vs the CPU kernel: {speedup:.2f}x (inputs on the device)")
    return emit(args, rows, {"max_level_difference": max_diff, "cpu_before_warp_ms_per_frame": before_ms,
                             "speedup_vs_kernel": speedup})


if __name__ == "__main__":
    main()
