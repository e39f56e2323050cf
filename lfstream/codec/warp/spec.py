"""The warp's arithmetic, written once as the reference every backend is tested against.

Plain numpy, one view at a time, no speed-ups: the fused CPU kernel
(:mod:`lfstream.codec.warp.kernels`), the batched tensor path
(:mod:`lfstream.codec.warp.batched`) and its CUDA kernels (:mod:`lfstream.codec.warp.triton`)
must give these bytes (with gains: within a level on a small share of samples, where a
compiler's choice of float rounding is not reproduced); the differentiable
:mod:`lfstream.models.warp` agrees within its float precision where nothing is occluded.
``tests/codec/warp/test_spec.py`` holds them to it.

For view ``(u, v)`` with displacement ``(du, dv)`` per unit disparity
(:func:`lfstream.lightfield.view_offsets`), pixel ``(y, x)``:

1. **Disparity.** On the rows :func:`lfstream.codec.warp.cpu.splat_rows` names (the
   ``occlusion`` warp), the centre map forward-splatted: centre pixel ``(y, x)`` with
   disparity ``d`` lands on ``(floor(y - d du + 0.5), floor(x - d dv + 0.5))`` (each product
   and sum rounded once to float32, a fused multiply-add), the larger disparity wins; a hole
   run takes its nearest splatted neighbour in the row on the background side (the smaller
   disparity, the left one on a tie; the one neighbour at a row's end; the centre map where
   the row has none). Elsewhere, the centre map at the view pixel.
2. **Position.** ``y + d du`` and ``x + d dv`` (fused multiply-add), times 1024, plus 0.5,
   floored: 1/1024-pixel fixed point; the integer part clamped to ``[-1, H - 1]`` (``[-1,
   W - 1]``) of the centre view padded by one replicated pixel all round.
3. **Sample.** With fractions ``fx, fy`` in 1/1024: each row's pair
   ``((1024 - fx) a + fx b + 64) >> 7``, then ``(1024 - fy) top + fy bottom``: ``2^13``
   times the sample, rounded by ``(+ 4096) >> 13``.
4. **Gains.** Where the frame has gain maps (not all 1), OpenCV's INTER_LINEAR taps up-sample them (along
   x: ``g[c_a] wx + g[c_b] (1 - wx)`` in float64 times ``2^-13``, kept in float32; along y:
   ``top wa + bottom (1 - wa)``, one rounding), the unrounded ``2^13`` sample is multiplied
   by it, plus 0.5, truncated and saturated at 255.
5. The centre view is the centre view (times its gains).
"""

from __future__ import annotations

import numpy as np

from lfstream.codec.warp.cpu import _linear_taps, splat_rows
from lfstream.lightfield import view_offsets

_FRAC = 1024
_TAP_OFFSET = 64 * _FRAC
_HOLE = np.float32(-3.0e38)


def _floor_int(t: np.ndarray, offset: float) -> np.ndarray:
    """floor(t) as int32 by truncating ``t + offset`` in float32 (``t`` clamped to
    ``[1 - offset, 1e9]``)."""
    t = np.clip(t.astype(np.float32), np.float32(1.0 - offset), np.float32(1.0e9))
    return (t + np.float32(offset)).astype(np.int32) - np.int32(offset)


def _fma(a: np.ndarray, b, c) -> np.ndarray:
    """``a * b + c`` rounded once to float32 (the float64 product of float32 values is exact)."""
    return (np.float64(1.0) * np.asarray(a, np.float32) * np.float32(b) + np.asarray(c, np.float32)).astype(np.float32)


def splatted_disparity(d: np.ndarray, du: float, dv: float) -> np.ndarray:
    """Step 1 on every row: the centre map ``d`` (H, W) forward-splatted into a view and its
    holes filled.

    Shape:
        - output: ``(H, W)`` float32
    """
    h, w = d.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    iy = _floor_int(_fma(-d, du, ys) + np.float32(0.5), 1024.0)
    ix = _floor_int(_fma(-d, dv, xs) + np.float32(0.5), 1024.0)
    inside = (iy >= 0) & (iy < h) & (ix >= 0) & (ix < w)
    flat = np.full(h * w, _HOLE, np.float32)
    np.maximum.at(flat, (iy * w + ix)[inside], d[inside])
    out = flat.reshape(h, w)
    for y in range(h):
        row = out[y]
        hole = row <= np.float32(-1.0e38)
        x = 0
        while x < w:
            if not hole[x]:
                x += 1
                continue
            start = x
            while x < w and hole[x]:
                x += 1
            left, right = start - 1, x
            if left < 0 and right >= w:
                row[start:x] = d[y, start:x]
            elif left < 0 or (right < w and row[right] < row[left]):
                row[start:x] = row[right]
            else:
                row[start:x] = row[left]
    return out


def sample(centre: np.ndarray, d: np.ndarray, du: float, dv: float) -> np.ndarray:
    """Steps 2-3: the centre view (H, W, C) uint8 sampled at ``(y + d du, x + d dv)``,
    ``2^13`` times the sample.

    Shape:
        - d: ``(H, W)``; output: ``(H, W, C)`` int64
    """
    h, w, _ = centre.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    ix = _floor_int(_fma(d, dv, xs) * np.float32(_FRAC) + np.float32(0.5), float(_TAP_OFFSET))
    iy = _floor_int(_fma(d, du, ys) * np.float32(_FRAC) + np.float32(0.5), float(_TAP_OFFSET))
    fx = (ix & (_FRAC - 1)).astype(np.int64)[..., None]
    fy = (iy & (_FRAC - 1)).astype(np.int64)[..., None]
    x0 = np.clip(ix >> 10, -1, w - 1) + 1
    y0 = np.clip(iy >> 10, -1, h - 1) + 1
    padded = np.pad(centre, ((1, 1), (1, 1), (0, 0)), mode="edge").astype(np.int64)
    top = ((_FRAC - fx) * padded[y0, x0] + fx * padded[y0, x0 + 1] + 64) >> 7
    bottom = ((_FRAC - fx) * padded[y0 + 1, x0] + fx * padded[y0 + 1, x0 + 1] + 64) >> 7
    return (_FRAC - fy) * top + fy * bottom


def gain_field(gains: np.ndarray, size: tuple[int, int], channels: int) -> np.ndarray:
    """Step 4's up-sampled gain map of one view, times ``2^-13``: ``gains`` (gh, gw, Cg).

    Shape:
        - output: ``(H, W, C)`` float32
    """
    h, w = size
    rows, row_w = _linear_taps(h, gains.shape[0])
    cols, col_w = _linear_taps(w, gains.shape[1])
    wx = col_w[None, :, None]
    gc = ((gains[:, cols[:, 0]] * wx).astype(np.float64) + gains[:, cols[:, 1]].astype(np.float64) * (1.0 - wx))
    gc = (gc * (1.0 / (1 << 13))).astype(np.float32)  # (gh, W, Cg)
    wa = row_w[:, None, None]
    field = _fma(gc[rows[:, 0]], wa, gc[rows[:, 1]] * (np.float32(1.0) - wa))
    return np.broadcast_to(field, (h, w, channels))


def warp_views_spec(centre: np.ndarray, disparity: np.ndarray, views: tuple[int, int], occlusion: bool = True,
                    gains: np.ndarray | None = None, axes: np.ndarray | None = None) -> np.ndarray:
    """Every view by steps 1-5 (:func:`lfstream.codec.warp.cpu.warp_views`'s contract).

    Args:
        centre: ``(H, W, C)`` uint8; disparity: ``(H, W)`` finite, px per view step.
        views: ``(U, V)``; occlusion: splat where :func:`~lfstream.codec.warp.cpu.splat_rows` says.
        gains: ``(U, V, gh, gw, 1 or C)`` or ``None``; axes: ``(2, 2)`` or ``None``.

    Shape:
        - output: ``(U, V, H, W, C)`` uint8
    """
    h, w, c = centre.shape
    d = np.ascontiguousarray(disparity, np.float32)
    offsets = view_offsets(views, axes)
    rows = splat_rows(d, offsets) if occlusion else np.zeros((*views, h), bool)
    if gains is not None and np.all(np.abs(gains - 1.0) < 1e-6):
        gains = None  # all 1: none
    out = np.empty((*views, h, w, c), np.uint8)
    for u in range(views[0]):
        for v in range(views[1]):
            du, dv = (float(o) for o in offsets[u, v])
            if du == 0 and dv == 0:
                val = centre.astype(np.int64) << 13
            else:
                dview = np.where(rows[u, v][:, None], splatted_disparity(d, du, dv), d) if rows[u, v].any() else d
                val = sample(centre, dview, du, dv)
            if gains is not None:
                scaled = val.astype(np.float32) * gain_field(gains[u, v], (h, w), c) + np.float32(0.5)
                out[u, v] = np.minimum(scaled.astype(np.int32), 255)
            else:
                out[u, v] = (val + 4096) >> 13
    return out


__all__ = ["warp_views_spec", "splatted_disparity", "sample", "gain_field"]
