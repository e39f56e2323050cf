"""Subcommands beyond ``info``; importing this module registers them with the CLI."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from lfstream.cli import Handler, add_read_options, command, emit_json, load_from_args, parse_float_list
from lfstream.errors import LFFileError, LFValueError


# ----------------------------------------------------------------------------------------
# refocus


@command("refocus", "render a focal stack (PNG per plane, MP4 and GIF focal sweep)")
def _refocus_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("input", type=Path)
    p.add_argument("-o", "--output", type=Path, required=True, help="output folder (created; must be empty)")
    p.add_argument("--alphas", type=parse_float_list, help="refocus parameters alpha (default 0.125,0.25,...,2.0)")
    p.add_argument("--slopes", type=parse_float_list, help="instead of alphas: shifts in pixels per view step")
    p.add_argument("--slope-range", nargs=3, type=float, metavar=("LO", "HI", "N"),
                   help="N slopes evenly spaced from LO to HI (a focus range in disparity units)")
    p.add_argument("--method", choices=("sas", "fourier", "refnet"), default="sas")
    p.add_argument("--device", default="cpu", help="where RefNet runs (method refnet)")
    p.add_argument("--aperture", type=float, help="synthetic aperture radius in view steps (default: all views)")
    p.add_argument("--aperture-shape", choices=("circle", "square", "gaussian"), default="circle")
    p.add_argument("--fps", type=float, default=8.0, help="frame rate of the focal sweep")
    p.add_argument("--no-sweep", action="store_true", help="skip the MP4/GIF focal sweep")
    add_read_options(p)
    p.add_argument("--json", action="store_true")
    return _refocus


def _refocus(args: argparse.Namespace) -> int:
    from lfstream.io import write_image, write_video
    from lfstream.refocus import focal_stack, resolve_slopes, slope_range
    from lfstream.optics import alpha_from_slope

    given = [x is not None for x in (args.alphas, args.slopes, args.slope_range)]
    if sum(given) > 1:
        raise LFValueError("give one of --alphas, --slopes, --slope-range")
    if args.slope_range:
        lo, hi, n = args.slope_range
        slopes = slope_range(lo, hi, int(n))
    else:
        slopes = resolve_slopes(args.alphas, args.slopes)
    out = args.output
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise LFFileError(f"{out}: already exists and is not an empty folder")
    loaded = load_from_args(args)
    t0 = time.perf_counter()
    extra = {"device": args.device} if args.method == "refnet" else {}
    stack = focal_stack(loaded.lf, slopes=slopes, method=args.method, aperture=args.aperture,
                        aperture_shape=args.aperture_shape, present=loaded.present, **extra)
    render_s = time.perf_counter() - t0
    if stack.dtype != np.uint8:
        stack = np.clip(stack * 255.0 + 0.5, 0, 255).astype(np.uint8)
    out.mkdir(parents=True, exist_ok=True)
    video = stack if stack.ndim == 5 else stack[None]
    files: list[str] = []
    planes = []
    for k, s in enumerate(slopes):
        alpha = alpha_from_slope(s) if s < 1 else None
        planes.append({"index": k, "slope": float(s), "alpha": alpha})
    for t, frame_stack in enumerate(video):
        folder = out if len(video) == 1 else out / f"frame_{t:06d}"
        folder.mkdir(exist_ok=True)
        for k, img in enumerate(frame_stack):
            name = folder / f"plane_{k:02d}.png"
            write_image(name, img)
            files.append(str(name))
    if not args.no_sweep:
        if len(video) == 1:
            for ext in (".mp4", ".gif"):
                write_video(out / f"sweep{ext}", list(video[0]), fps=args.fps, lossless=False)
                files.append(str(out / f"sweep{ext}"))
        else:
            for k in range(video.shape[1]):
                path = out / f"plane_{k:02d}.mp4"
                write_video(path, list(video[:, k]), fps=loaded.fps or 30.0, lossless=False)
                files.append(str(path))
    summary = {"input": str(args.input), "method": args.method, "frames": len(video), "planes": planes,
               "render_s": render_s, "output": str(out), "files": len(files)}
    if args.json:
        emit_json(summary)
    else:
        print(f"{len(slopes)} planes x {len(video)} frame(s) by {args.method} in {render_s:.3f} s -> {out}")
    return 0


# ----------------------------------------------------------------------------------------
# synth


@command("synth", "render a synthetic LF clip with ground-truth disparity")
def _synth_args(p: argparse.ArgumentParser) -> Handler:
    from lfstream.cli import parse_size

    p.add_argument("output", type=Path, help=".npz (LF and disparity together) or any write_lf target")
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--views", type=int, default=7)
    p.add_argument("--size", type=parse_size, default=(128, 128), help="HxW of each view")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--layers", type=int, default=4)
    p.add_argument("--disparity-range", nargs=2, type=float, metavar=("FAR", "NEAR"), default=(-1.0, 1.5))
    p.add_argument("--motion", type=float, default=1.5, help="object speed, pixels per frame")
    p.add_argument("--camera-pan", type=float, default=0.5, help="camera pan, pixels per frame")
    p.add_argument("--noise", type=float, default=0.0, help="sensor noise, 8-bit levels at mid-grey")
    p.add_argument("--vignetting", type=float, default=0.0, help="0..1")
    p.add_argument("--exposure-drift", type=float, default=0.0)
    p.add_argument("--fps", type=float, default=30.0)
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--json", action="store_true")
    return _synth


def _synth(args: argparse.Namespace) -> int:
    from lfstream.io import write_lf
    from lfstream.synth import SynthConfig, render_clip

    cfg = SynthConfig(frames=args.frames, views=args.views, size=tuple(args.size), seed=args.seed, layers=args.layers,
                      disparity_range=tuple(args.disparity_range), motion=args.motion, camera_pan=args.camera_pan,
                      noise=args.noise, vignetting=args.vignetting, exposure_drift=args.exposure_drift)
    t0 = time.perf_counter()
    clip = render_clip(cfg)
    render_s = time.perf_counter() - t0
    out = args.output
    written = [str(out)]
    if out.suffix.lower() == ".npz":
        write_lf(out, clip.lf, disparity=clip.disparity, overwrite=args.overwrite)
    else:
        disp_path = out.with_name(out.stem + "_disparity.npy")
        if disp_path.exists() and not args.overwrite:
            raise LFFileError(f"{disp_path}: already exists (pass --overwrite)")
        write_lf(out, clip.lf, fps=args.fps, overwrite=args.overwrite)
        write_lf(disp_path, clip.disparity[..., None], overwrite=True)
        written.append(str(disp_path))
    info = {"output": written, "frames": cfg.frames, "views": [cfg.views, cfg.views], "size": list(cfg.size),
            "disparity_range": [float(clip.disparity.min()), float(clip.disparity.max())], "render_s": render_s}
    if args.json:
        emit_json(info)
    else:
        print(f"{cfg.frames} frames of {cfg.views}x{cfg.views} views, {cfg.size[0]}x{cfg.size[1]}, "
              f"disparity {info['disparity_range'][0]:.2f}..{info['disparity_range'][1]:.2f} -> {', '.join(written)}")
    return 0


# ----------------------------------------------------------------------------------------
# demo


DEFAULT_OUTPUT = Path("lfstream-out")


def fresh_output_dir(base: Path) -> Path:
    """``base`` if it is absent or empty, else ``base-2``, ``base-3``, ...: never overwrite a run."""
    candidate, n = base, 1
    while candidate.exists() and (not candidate.is_dir() or any(candidate.iterdir())):
        n += 1
        candidate = base.with_name(f"{base.name}-{n}")
    return candidate


@command("demo", "the built-in demo: synthesise a light field, describe it, refocus it")
def _demo_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("-o", "--output", type=Path, help=f"output folder (default {DEFAULT_OUTPUT}/demo, never overwritten)")
    p.add_argument("--size", default="375x540", help="view size HxW of the built-in light field")
    p.add_argument("--json", action="store_true")
    return _demo


def _demo(args: argparse.Namespace) -> int:
    from lfstream.cli import describe, parse_size
    from lfstream.io import LoadedLF, write_image, write_lf, write_video
    from lfstream.metrics import psnr
    from lfstream.refocus import focal_stack
    from lfstream.synth import synth_clip

    out = fresh_output_dir(args.output or DEFAULT_OUTPUT / "demo")
    h, w = parse_size(args.size)
    t0 = time.perf_counter()
    clip = synth_clip(frames=1, views=7, size=(h, w), seed=0, noise=2.0, vignetting=0.3)
    synth_s = time.perf_counter() - t0
    lf = clip.lf[0]
    out.mkdir(parents=True, exist_ok=True)
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
    if args.json:
        emit_json(result)
        return 0
    u, v = info["views"]
    print(f"built-in light field: {u}x{v} views of {info['size'][0]}x{info['size'][1]} RGB, "
          f"{info['bytes'] / 1e6:.1f} MB, disparity {info['disparity_range'][0]:.2f}..{info['disparity_range'][1]:.2f} px/view")
    print(f"synthesised in {synth_s:.2f} s; 16-plane focal stack: shift-and-sum {sas_s:.3f} s, Fourier slice {flr_s:.3f} s")
    print(f"Fourier slice vs shift-and-sum PSNR per plane: min {min(agreement):.1f} dB")
    print(f"wrote {out}/: lightfield.npz, sas_plane_00..15.png, focal_sweep.mp4, focal_sweep.gif")
    return 0


# ----------------------------------------------------------------------------------------
# optics


@command("optics", "plenoptic camera -> equivalent camera array, refocus distance and depth of field")
def _optics_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("--focal-length", type=float, required=True, metavar="MM", help="main-lens focal length")
    p.add_argument("--f-number", type=float, required=True)
    p.add_argument("--microlenses", type=int, required=True, metavar="M", help="microlenses per axis")
    p.add_argument("--pixels-per-lens", type=int, required=True, metavar="N", help="pixels per axis under a microlens")
    p.add_argument("--pixel-pitch", type=float, metavar="MM", help="default: microlens pitch / N")
    p.add_argument("--microlens-pitch", type=float, metavar="MM", help="default: aperture / M")
    p.add_argument("--focus-distance", type=float, default=float("inf"), metavar="M",
                   help="main-lens focus in metres (default infinity)")
    p.add_argument("--slope", type=float, nargs="+", action="extend", default=[], metavar="S",
                   help="refocus shifts in pixels per view step (Hahne's a)")
    p.add_argument("--alpha", type=float, nargs="+", action="extend", default=[], metavar="A",
                   help="refocus parameters alpha (slope = 1 - 1/alpha)")
    p.add_argument("--json", action="store_true", help="one JSON object; infinite distances are null")
    return _optics


def _finite_or_none(x: float | None) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


def _optics(args: argparse.Namespace) -> int:
    from lfstream.optics import PlenopticCamera, camera_array, refocus_plane, slope_from_alpha

    spc = PlenopticCamera(focal_length_mm=args.focal_length, f_number=args.f_number, microlenses=args.microlenses,
                          pixels_per_lens=args.pixels_per_lens, microlens_pitch_mm=args.microlens_pitch,
                          pixel_pitch_mm=args.pixel_pitch, focus_distance_m=args.focus_distance)
    array = camera_array(spc)
    slopes = list(args.slope) + [slope_from_alpha(a) for a in args.alpha]
    planes = [refocus_plane(spc, s) for s in slopes]
    if args.json:
        emit_json({
            "camera_array": array.as_dict(),
            "plenoptic_camera": {"aperture_mm": spc.aperture_mm, "microlens_pitch_mm": spc.lens_pitch_mm,
                                 "pixel_pitch_mm": spc.pitch_mm, "microlens_focal_length_mm": spc.microlens_focal_length_mm,
                                 "image_distance_mm": spc.image_distance_mm},
            "refocus": [{"slope": p.slope, "alpha": p.alpha, "focus_m": _finite_or_none(p.focus_m),
                         "dof_near_m": _finite_or_none(p.dof_near_m), "dof_far_m": _finite_or_none(p.dof_far_m)}
                        for p in planes],
        })
        return 0
    n = array.cameras[0]
    print(f"plenoptic camera: F = {spc.focal_length_mm:g} mm, f/{spc.f_number:g} (aperture {spc.aperture_mm:g} mm), "
          f"{spc.microlenses}x{spc.microlenses} microlenses of {spc.lens_pitch_mm:g} mm, {n}x{n} pixels of {spc.pitch_mm:g} mm each")
    print(f"equivalent camera array: {n}x{n} cameras, aperture {array.camera_aperture_mm:g} mm, "
          f"focal length {array.camera_focal_length_mm:g} mm, field of view {array.camera_fov_deg:.2f} deg, "
          f"{array.camera_resolution[0]}x{array.camera_resolution[1]} pixels, baseline {array.baseline_mm:g} mm, "
          f"centred on the main lens (outer cameras at {array.positions_mm[0][0][0]:g} .. {array.positions_mm[-1][-1][0]:g} mm)")
    for p in planes:
        alpha = f"{p.alpha:.4g}" if p.alpha is not None else "-"
        print(f"  slope {p.slope:+.4g} (alpha {alpha}): focus {p.focus_m:.3g} m, depth of field {p.dof_near_m:.3g} .. {p.dof_far_m:.3g} m")
    return 0


# ----------------------------------------------------------------------------------------
# encode / decode


@command("encode", "encode a light field or LF video to an .lfs stream (JPEG centre view)")
def _encode_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("input", type=Path)
    p.add_argument("-o", "--output", type=Path, required=True, help="the .lfs file (never overwritten without --overwrite)")
    p.add_argument("--quality", type=int, default=50, help="JPEG quality of the centre view (default 50)")
    p.add_argument("--depth-hint", action="store_true", help="also send the encoder's disparity estimate")
    p.add_argument("--fps", type=float, help="frame rate to record (default: the input's, else 30)")
    p.add_argument("--overwrite", action="store_true")
    add_read_options(p)
    p.add_argument("--json", action="store_true")
    return _encode


def _encode(args: argparse.Namespace) -> int:
    from lfstream.codec import Encoder, encode_file
    from lfstream.metrics import bpp

    if args.output.exists() and not args.overwrite:
        raise LFFileError(f"{args.output}: already exists (pass --overwrite to replace it)")
    loaded = load_from_args(args)  # with --allow-missing, only the centre view must exist
    frames = loaded.lf if loaded.lf.ndim == 6 else loaded.lf[None]
    enc = Encoder(quality=args.quality, depth_hint=args.depth_hint)
    stats = encode_file(frames, args.output, tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), enc,
                        fps=args.fps or loaded.fps or 30.0, present=loaded.present)
    stats.update({"output": str(args.output), "bpp": bpp(stats["bytes"], frames.shape),
                  "hint_bpp": bpp(stats["hint_bytes"], frames.shape), "quality": args.quality})
    if args.json:
        emit_json(stats)
    else:
        print(f"{stats['frames']} frame(s) -> {args.output}: {stats['bytes']} bytes, {stats['bpp']:.5f} bpp"
              + (f" (hint {stats['hint_bpp']:.5f} bpp)" if args.depth_hint else "")
              + f", encoded in {stats['encode_s']:.3f} s")
    return 0


@command("decode", "decode an .lfs stream to a light field (.npy, folder or video)")
def _decode_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("input", type=Path)
    p.add_argument("-o", "--output", type=Path, required=True, help=".npy (T,U,V,H,W,3), .npz, a video or a folder")
    p.add_argument("--depth", choices=("auto", "hint", "flat", "net"), default="auto",
                   help="disparity source: the stream's hint, flat (zero), or Depth-Net (default: hint if present)")
    p.add_argument("--no-occlusion", action="store_true", help="warp without occlusion-aware per-view disparity")
    p.add_argument("--no-hance", action="store_true", help="skip JPEG-Hance (default: run it where it helps)")
    p.add_argument("--hance", choices=("auto", "on", "off"), default="auto",
                   help="JPEG-Hance: auto (by the stream's JPEG quality, measured threshold), on or off")
    p.add_argument("--device", default="cpu", help="where the networks run: cpu or cuda")
    p.add_argument("--batch", type=int, default=1, help="frames per network batch")
    p.add_argument("--disparity-out", type=Path, help="folder for the centre-view disparity of each frame (PFM)")
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--json", action="store_true")
    return _decode


def _decode(args: argparse.Namespace) -> int:
    from lfstream.codec import iter_decode
    from lfstream.errors import BitstreamError
    from lfstream.io import write_lf, write_pfm

    if args.output.exists() and not args.overwrite:
        raise LFFileError(f"{args.output}: already exists (pass --overwrite to replace it)")
    if args.disparity_out is not None:
        args.disparity_out.mkdir(parents=True, exist_ok=True)
    frames, error = [], None
    t0 = time.perf_counter()
    try:
        with open(args.input, "rb") as fh:
            hance = "off" if args.no_hance else args.hance
            for f in iter_decode(fh, depth=args.depth, occlusion=not args.no_occlusion, hance=hance,
                                 device=args.device, batch=args.batch):
                frames.append(f.lf)
                if args.disparity_out is not None:
                    write_pfm(args.disparity_out / f"frame_{f.seq:06d}.pfm", f.disparity)
    except OSError as exc:
        raise LFFileError(f"{args.input}: cannot read ({exc.strerror or exc})") from exc
    except BitstreamError as exc:
        error = exc
    decode_s = time.perf_counter() - t0
    if frames:
        # a damaged stream still gives a valid output of every frame before the damage
        write_lf(args.output, np.stack(frames), overwrite=args.overwrite)
    if error is not None:
        raise BitstreamError(f"{args.input}: {error} ({len(frames)} complete frame(s) before it written to {args.output})")
    result = {"frames": len(frames), "decode_s": decode_s, "output": str(args.output)}
    if args.json:
        emit_json(result)
    else:
        print(f"{len(frames)} frame(s) decoded in {decode_s:.3f} s -> {args.output}")
    return 0


# ----------------------------------------------------------------------------------------
# baseline


@command("baseline", "code the views as a pseudo-sequence with HEVC (x265) or AV1 (SVT-AV1) for comparison")
def _baseline_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("input", type=Path)
    p.add_argument("--codec", choices=("hevc", "av1"), default="hevc")
    rate = p.add_mutually_exclusive_group()
    rate.add_argument("--qp", type=float, help="HEVC: constant QP 0..51; AV1: CRF 1..63 (default 34)")
    rate.add_argument("--bpp", type=float, help="search the quality parameter for this bits per pixel")
    p.add_argument("--order", choices=("raster", "serpentine", "spiral"), default="raster")
    p.add_argument("-o", "--output", type=Path, help="write the decoded light field (.npy, folder or video)")
    p.add_argument("--overwrite", action="store_true")
    add_read_options(p)
    p.add_argument("--json", action="store_true")
    return _baseline


def _baseline(args: argparse.Namespace) -> int:
    from lfstream.baseline import decode_views, encode_at_bpp, encode_views
    from lfstream.io import write_lf
    from lfstream.metrics import bpp, capped, mpsnr, mssim

    if args.output is not None and args.output.exists() and not args.overwrite:
        raise LFFileError(f"{args.output}: already exists (pass --overwrite to replace it)")
    loaded = load_from_args(args)
    frames = loaded.lf if loaded.lf.ndim == 6 else loaded.lf[None]
    u, v, h, w = frames.shape[1:5]
    total, params, enc_s, dec_s, recon = 0, [], 0.0, 0.0, []
    for frame in frames:
        t0 = time.perf_counter()
        if args.bpp is not None:
            res = encode_at_bpp(frame, args.codec, args.bpp, args.order)
            data, q = res.data, res.quality
        else:
            q = 34.0 if args.qp is None else args.qp
            data = encode_views(frame, args.codec, q, args.order, constant_qp=True)
        enc_s += time.perf_counter() - t0
        t0 = time.perf_counter()
        recon.append(decode_views(data, args.codec, (u, v), (h, w), args.order))
        dec_s += time.perf_counter() - t0
        total += len(data)
        params.append(q)
    rec = np.stack(recon)
    result = {"codec": args.codec, "order": args.order, "frames": len(frames), "quality": params, "bytes": total,
              "bpp": bpp(total, frames.shape),
              "mpsnr": [capped(x) for x in np.atleast_1d(mpsnr(frames, rec))],
              "mssim": [float(x) for x in np.atleast_1d(mssim(frames, rec))],
              "encode_s": enc_s, "decode_s": dec_s,
              "note": "encode_s includes the parameter search when --bpp is given"}
    if args.output is not None:
        write_lf(args.output, rec if loaded.lf.ndim == 6 else rec[0], overwrite=args.overwrite)
        result["output"] = str(args.output)
    if args.json:
        emit_json(result)
    else:
        print(f"{args.codec} ({args.order}) at QP/CRF {', '.join(f'{q:g}' for q in params)}: {total} bytes, "
              f"{result['bpp']:.5f} bpp, MPSNR {np.mean(result['mpsnr']):.2f} dB, MSSIM {np.mean(result['mssim']):.4f}, "
              f"encode {enc_s:.2f} s, decode {dec_s:.3f} s")
    return 0


# ----------------------------------------------------------------------------------------
# models


@command("models", "list the networks, their presets, parameter counts and shipped weights")
def _models_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("--json", action="store_true")
    return _models


def _models(args: argparse.Namespace) -> int:
    from lfstream.weights import list_models

    models = list_models()
    if args.json:
        emit_json({"models": models})
    else:
        for m in models:
            print(f"{m['name']:11s} {m['preset']:6s} {m['params']:>11,d} params  weights: {m['weights'] or '-'}")
    return 0


# ----------------------------------------------------------------------------------------
# stream / serve


def _add_pipeline_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", type=Path, help="output folder (default: a new ./lfstream-out[-N])")
    p.add_argument("--refocus", choices=("auto", "refnet", "sas", "fourier", "none"), default="auto",
                   help="focal-stack renderer (auto: picked per device by measured speed and error)")
    p.add_argument("--device", default="cpu", help="where the networks run: cpu or cuda")
    p.add_argument("--batch", type=int, default=1, help="frames per network batch in the decoder")
    p.add_argument("--depth", choices=("auto", "hint", "flat", "net"), default="auto")
    p.add_argument("--hance", choices=("auto", "on", "off"), default="auto")
    p.add_argument("--save", default="mp4", help="comma list of mp4 (one per focal plane), png, sweep, lf")
    p.add_argument("--no-skip-static", action="store_true", help="always recompute the disparity")
    p.add_argument("--skip-planes", action="store_true",
                   help="render focal planes outside the scene's disparity range by a cheap path")
    p.add_argument("--mssim-every", type=int, default=10, help="MSSIM on every N-th frame (0: never; MPSNR on all)")
    p.add_argument("--queue-size", type=int, default=4)
    p.add_argument("--progress", action="store_true", help="a status line on stderr (default when it is a terminal)")
    p.add_argument("--json", action="store_true")


def _pipeline_config(args: argparse.Namespace, **extra):
    from lfstream.pipeline import StreamConfig

    return StreamConfig(refocus=args.refocus, device=args.device, batch=args.batch, depth=args.depth, hance=args.hance,
                        save=tuple(s for s in args.save.split(",") if s), skip_static=not args.no_skip_static,
                        skip_planes=args.skip_planes, mssim_every=args.mssim_every, queue_size=args.queue_size, **extra)


def _report(args: argparse.Namespace, summary: dict, out: Path | None) -> None:
    import sys

    from lfstream.pipeline import write_summary

    if out is not None:
        write_summary(out, summary)
    if args.json:
        emit_json(summary)
        return
    sys.stderr.write("\n")
    print(f"{summary['frames']} frame(s), {summary['fps']} frames/s end to end"
          + (f", {summary['bpp']:.5f} bpp" if summary.get("bpp") else "")
          + (f", MPSNR {summary['mpsnr']:.2f} dB" if summary.get("mpsnr") is not None else "")
          + (f", MSSIM {summary['mssim']:.4f}" if summary.get("mssim") is not None else "")
          + f", lost {summary['lost']}" + (" (interrupted)" if summary.get("interrupted") else ""))
    for name, s in summary.get("stages", {}).items():
        print(f"  {name:9s} {s['frames']:5d} frames  {s['ms_per_frame'] or 0:8.1f} ms/frame")
    if summary.get("refocus"):
        print(f"  refocus: {summary['refocus']['method']} ({summary['refocus']['why']})")
    if out is not None:
        print(f"  outputs in {out} (summary.json)")


@command("stream", "stream an LF video (default: the built-in synthetic clip) through the whole pipeline")
def _stream_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("input", type=Path, nargs="?", help="LF video / light field (default: built-in synthetic clip)")
    p.add_argument("--transport", choices=("inproc", "file", "tcp"), default="inproc")
    p.add_argument("--to", help="HOST:PORT of an `lfstream serve`: send there instead of decoding here")
    p.add_argument("--quality", type=int, default=50)
    p.add_argument("--no-depth-hint", action="store_true", help="send only the JPEG centre view")
    p.add_argument("--frames", type=int, default=12, help="frames of the built-in clip")
    _add_pipeline_options(p)
    add_read_options(p)
    return _stream


def _stream(args: argparse.Namespace) -> int:
    import sys

    from lfstream.pipeline import Pipeline, default_output, file_source, prepare_output, stderr_progress, synthetic_source
    from lfstream.transport import TcpSender, parse_address

    fps = 30.0
    if args.input is None:
        source = synthetic_source(frames=args.frames)
    else:
        source, src_fps = file_source(args.input, max_frames=args.max_frames, angular=args.angular, crop=args.crop,
                                      grid=args.grid, flip_u=args.flip_u, flip_v=args.flip_v)
        fps = src_fps or fps
    cfg = _pipeline_config(args, quality=args.quality, depth_hint=not args.no_depth_hint, transport=args.transport,
                           fps=fps)
    sender, out = None, None
    if args.to:
        sender = TcpSender(*parse_address(args.to))
    else:
        out = prepare_output(args.output) if args.output else prepare_output(default_output())
    progress = stderr_progress if (args.progress or (sys.stderr.isatty() and not args.json)) else None
    pipe = Pipeline(source, cfg, out, sender=sender, progress=progress,
                    stream_file=(out / "stream.lfs") if out is not None else None)
    summary = pipe.run()
    _report(args, summary, out)
    return 130 if summary["interrupted"] else 0


@command("serve", "receive a stream over TCP, decode, refocus and write the outputs")
def _serve_args(p: argparse.ArgumentParser) -> Handler:
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default loopback only)")
    p.add_argument("--port", type=int, default=7820)
    p.add_argument("--keep-open", action="store_true", help="serve one sender after another until Ctrl-C")
    p.add_argument("--timeout", type=float, default=300.0, help="seconds to wait for a sender or for data")
    _add_pipeline_options(p)
    return _serve


def _serve(args: argparse.Namespace) -> int:
    import sys

    from lfstream.pipeline import Pipeline, default_output, prepare_output, stderr_progress
    from lfstream.transport import TcpReceiver

    base = args.output or default_output("lfstream-serve")
    n = 0
    while True:
        out = prepare_output(base if n == 0 else base.with_name(f"{base.name}-{n}"))
        receiver = TcpReceiver(args.host, args.port, timeout_s=args.timeout)
        if not args.json:
            print(f"listening on {receiver.address[0]}:{receiver.address[1]} -> {out}", file=sys.stderr)
        progress = stderr_progress if (args.progress or (sys.stderr.isatty() and not args.json)) else None
        summary = Pipeline(None, _pipeline_config(args), out, receiver=receiver, progress=progress).run()
        _report(args, summary, out)
        n += 1
        if not args.keep_open or summary["interrupted"]:
            return 130 if summary["interrupted"] else 0
