"""Depth-based view synthesis: warp the centre view into every view (seed Eq. 3.3).

``L(x, u) = C(x + (u - u0) * d(x, u))`` with lfstream's disparity sign: a point at ``x`` in
the centre view with disparity ``d`` appears at ``x - d * (u - u0)`` in view ``u``, so
view ``u`` samples the centre view at ``x + d * (u - u0)``. Samples outside the centre view
are clamped to its border.

Occlusion: the per-view maps ``d(x, u)`` are the centre map forward-splatted into each view
with a z-test (the nearer surface wins) and disoccluded holes filled from the background
side, so a foreground edge neither smears into the background nor leaves a crack.
"""

from __future__ import annotations

import numpy as np

from lfstream.errors import LFShapeError, LFValueError
from lfstream.lightfield import MAX_VIEWS_PER_AXIS, check_finite, to_uint8


def warp_views(
    centre: np.ndarray,
    disparity: np.ndarray | float,
    views: tuple[int, int],
    occlusion: bool = True,
) -> np.ndarray:
    """Synthesises a light field from its centre view and the centre view's disparity.

    Args:
        centre: ``(H, W, C)`` uint8 or float in ``[0, 1]``.
        disparity: ``(H, W)`` centre-view disparity in pixels per view step, or a constant.
        views: ``(U, V)`` of the output.
        occlusion: per-view disparity by z-tested forward splatting (see module docstring).

    Shape:
        - output: ``(U, V, H, W, C)`` uint8
    """
    if centre.ndim != 3:
        raise LFShapeError(f"centre: expected (H, W, C), got shape {tuple(centre.shape)}")
    h, w, c = centre.shape
    u, v = views
    if not (1 <= u <= MAX_VIEWS_PER_AXIS and 1 <= v <= MAX_VIEWS_PER_AXIS):
        raise LFValueError(f"views: each in 1..{MAX_VIEWS_PER_AXIS}, got {views}")
    d = np.broadcast_to(np.asarray(disparity, np.float32), (h, w))
    check_finite(d, "disparity")
    if not np.any(d):
        return np.ascontiguousarray(np.broadcast_to(to_uint8(np.asarray(centre)), (u, v, h, w, c)))
    import cv2

    from lfstream.codec._kernels import view_sample_maps

    # numba computes where every view pixel samples the centre view (splatting, z-test and
    # hole filling need per-pixel control); OpenCV's SIMD remap does the bilinear sampling,
    # 1.3x faster than doing both in one numba loop (measured, 7x7x375x540).
    maps = np.empty((u, v, h, w, 2), np.float32)
    view_sample_maps(np.ascontiguousarray(d), u, v, bool(occlusion), maps)
    src = np.ascontiguousarray(to_uint8(np.asarray(centre)))
    out = np.empty((u, v, h, w, c), np.uint8)
    for a in range(u):
        for b in range(v):
            dst = out[a, b] if c > 1 else out[a, b, :, :, 0]
            cv2.remap(src if c > 1 else src[:, :, 0], maps[a, b], None, cv2.INTER_LINEAR, dst=dst,
                      borderMode=cv2.BORDER_REPLICATE)
    return out


def warp_views_per_view(centre: np.ndarray, disparities: np.ndarray) -> np.ndarray:
    """``L(x, u) = C(x + (u - u0) d(x, u))`` with one disparity map per view (Depth-Net's
    output, seed Fig. 3.2): one OpenCV bilinear remap per view, border clamped.

    Args:
        centre: ``(H, W, C)`` uint8 or float in ``[0, 1]``.
        disparities: ``(U, V, H, W)`` px per view step.

    Shape:
        - output: ``(U, V, H, W, C)`` uint8
    """
    import cv2

    if centre.ndim != 3 or disparities.ndim != 4 or disparities.shape[2:] != centre.shape[:2]:
        raise LFShapeError(f"centre (H, W, C) and disparities (U, V, H, W) must agree; got {tuple(centre.shape)} "
                           f"and {tuple(disparities.shape)}")
    check_finite(disparities, "disparities")
    u_n, v_n, h, w = disparities.shape
    c = centre.shape[2]
    src = np.ascontiguousarray(to_uint8(np.asarray(centre)))
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    out = np.empty((u_n, v_n, h, w, c), np.uint8)
    mx = np.empty((h, w), np.float32)
    my = np.empty((h, w), np.float32)
    for a in range(u_n):
        for b in range(v_n):
            d = disparities[a, b].astype(np.float32, copy=False)
            np.multiply(d, np.float32(b - v_n // 2), out=mx)
            mx += xs
            np.multiply(d, np.float32(a - u_n // 2), out=my)
            my += ys
            dst = out[a, b] if c > 1 else out[a, b, :, :, 0]
            cv2.remap(src if c > 1 else src[:, :, 0], mx, my, cv2.INTER_LINEAR, dst=dst,
                      borderMode=cv2.BORDER_REPLICATE)
    return out


__all__ = ["warp_views", "warp_views_per_view"]
