"""``lfstream demo``: synthesise one light field, describe it, refocus it two ways."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from lfstream.cli._common import emit, parse_size, path_arg

HELP = "the built-in demo: synthesise a light field, describe it, refocus it"
DEFAULT_OUTPUT = Path("lfstream-demo")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", type=path_arg, help=f"output folder (default ./{DEFAULT_OUTPUT}[-N], never overwritten)")
    p.add_argument("--size", type=parse_size, default=(375, 540), help="view size HxW of the built-in light field")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args: argparse.Namespace) -> int:

    from lfstream.io.outputs import FOLDER, check_output, fresh_output_folder

    if args.output is not None:
        check_output(args.output, overwrite=True, kinds=(FOLDER,))
    # a folder of its own for this run (-o, else -o-2, ...): never one that holds results
    with fresh_output_folder(args.output or DEFAULT_OUTPUT) as claim:
        return _demo(args, claim.path)


def _demo(args: argparse.Namespace, out) -> int:
    from lfstream.cli.info import describe
    from lfstream.io import LoadedLF, write_image, write_lf, write_video
    from lfstream.metrics import psnr
    from lfstream.refocus import focal_stack
    from lfstream.synth import synth_clip

    h, w = args.size
    t0 = time.perf_counter()
    clip = synth_clip(frames=1, views=7, size=(h, w), seed=0, noise=2.0, vignetting=0.3)
    synth_s = time.perf_counter() - t0
    lf = clip.lf[0]
    write_lf(out / "lightfield.npz", lf, disparity=clip.disparity[0])
    info = describe(LoadedLF(lf=lf, format="synthetic", path=out / "lightfield.npz", disparity=clip.disparity[0]))
    t0 = time.perf_counter()
    stack = focal_stack(lf)  # the seed's sixteen alphas by shift-and-sum
    sas_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    flr = focal_stack(lf, method="fourier")
    flr_s = time.perf_counter() - t0
    for k, img in enumerate(stack):
        write_image(out / f"sas_plane_{k:02d}.png", img)
    write_video(out / "focal_sweep.mp4", list(stack), fps=8, lossless=False)
    write_video(out / "focal_sweep.gif", list(stack), fps=8)
    agreement = [float(psnr(a, b)) for a, b in zip(stack, flr)]
    result = {"lightfield": info, "output": str(out), "synth_s": synth_s, "sas_16_planes_s": sas_s,
              "fourier_16_planes_s": flr_s, "fourier_vs_sas_psnr_db": agreement}
    u, v = info["views"]
    emit(args, result, "\n".join([
        f"built-in light field: {u}x{v} views of {info['size'][0]}x{info['size'][1]} RGB, {info['bytes'] / 1e6:.1f} MB, "
        f"disparity {info['disparity_range'][0]:.2f}..{info['disparity_range'][1]:.2f} px/view",
        f"synthesised in {synth_s:.2f} s; 16-plane focal stack: shift-and-sum {sas_s:.3f} s, Fourier slice {flr_s:.3f} s",
        f"Fourier slice vs shift-and-sum PSNR per plane: min {min(agreement):.1f} dB",
        f"wrote {out}/: lightfield.npz, sas_plane_00..15.png, focal_sweep.mp4, focal_sweep.gif",
    ]))
    return 0
