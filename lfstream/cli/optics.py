"""``lfstream optics``: plenoptic camera -> equivalent camera array, refocus distance, DoF."""

from __future__ import annotations

import argparse

import numpy as np

from lfstream.cli._common import emit, float_in, int_in
from lfstream.lightfield import MAX_VIEWS_PER_AXIS

HELP = "plenoptic camera -> equivalent camera array, refocus distance and depth of field"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--focal-length", type=float_in(1e-3, 1e6), required=True, metavar="MM", help="main-lens focal length")
    p.add_argument("--f-number", type=float_in(0.1, 1000), required=True, help="main-lens f-number")
    p.add_argument("--microlenses", type=int_in((1, 1 << 20)), required=True, metavar="M", help="microlenses per axis")
    p.add_argument("--pixels-per-lens", type=int_in((1, MAX_VIEWS_PER_AXIS)), required=True, metavar="N",
                   help="pixels per axis under a microlens")
    p.add_argument("--pixel-pitch", type=float_in(1e-9, 1e3), metavar="MM", help="default: microlens pitch / N")
    p.add_argument("--microlens-pitch", type=float_in(1e-9, 1e3), metavar="MM", help="default: aperture / M")
    p.add_argument("--focus-distance", type=float, default=float("inf"), metavar="M",
                   help="main-lens focus in metres (default infinity)")
    p.add_argument("--slope", type=float_in(-1e6, 1e6), nargs="+", action="extend", default=[], metavar="S",
                   help="refocus shifts in pixels per view step (Hahne's a)")
    p.add_argument("--alpha", type=float_in(-1e6, 1e6), nargs="+", action="extend", default=[], metavar="A",
                   help="refocus parameters alpha (slope = 1 - 1/alpha)")
    p.add_argument("--json", action="store_true", help="one JSON object; infinite distances are null")


def _finite_or_none(x: float | None) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


def run(args: argparse.Namespace) -> int:
    from lfstream.optics import PlenopticCamera, camera_array, refocus_plane, slope_from_alpha

    spc = PlenopticCamera(focal_length_mm=args.focal_length, f_number=args.f_number, microlenses=args.microlenses,
                          pixels_per_lens=args.pixels_per_lens, microlens_pitch_mm=args.microlens_pitch,
                          pixel_pitch_mm=args.pixel_pitch, focus_distance_m=args.focus_distance)
    array = camera_array(spc)
    slopes = list(args.slope) + [slope_from_alpha(a) for a in args.alpha]
    planes = [refocus_plane(spc, s) for s in slopes]
    result = {
        "camera_array": array.as_dict(),
        "plenoptic_camera": {"aperture_mm": spc.aperture_mm, "microlens_pitch_mm": spc.lens_pitch_mm,
                             "pixel_pitch_mm": spc.pitch_mm, "microlens_focal_length_mm": spc.microlens_focal_length_mm,
                             "image_distance_mm": spc.image_distance_mm},
        "refocus": [{"slope": p.slope, "alpha": p.alpha, "focus_m": _finite_or_none(p.focus_m),
                     "dof_near_m": _finite_or_none(p.dof_near_m), "dof_far_m": _finite_or_none(p.dof_far_m)}
                    for p in planes],
    }
    n = array.cameras[0]
    lines = [
        f"plenoptic camera: F = {spc.focal_length_mm:g} mm, f/{spc.f_number:g} (aperture {spc.aperture_mm:g} mm), "
        f"{spc.microlenses}x{spc.microlenses} microlenses of {spc.lens_pitch_mm:g} mm, "
        f"{n}x{n} pixels of {spc.pitch_mm:g} mm each",
        f"equivalent camera array: {n}x{n} cameras, aperture {array.camera_aperture_mm:g} mm, "
        f"focal length {array.camera_focal_length_mm:g} mm, field of view {array.camera_fov_deg:.2f} deg, "
        f"{array.camera_resolution[0]}x{array.camera_resolution[1]} pixels, baseline {array.baseline_mm:g} mm, "
        f"centred on the main lens (outer cameras at {array.positions_mm[0][0][0]:g} .. {array.positions_mm[-1][-1][0]:g} mm)",
    ]
    for p in planes:
        alpha = f"{p.alpha:.4g}" if p.alpha is not None else "-"
        lines.append(f"  slope {p.slope:+.4g} (alpha {alpha}): focus {p.focus_m:.3g} m, "
                     f"depth of field {p.dof_near_m:.3g} .. {p.dof_far_m:.3g} m")
    emit(args, result, "\n".join(lines))
    return 0
