"""The decoder's warp (:func:`lfstream.codec.warp.cpu.warp_views`) as batched tensor operations
on any torch device: several frames at once, every view of a chunk in one pass, no per-view
or per-pixel Python loop. The CPU reference stays the fused numba kernel
(:func:`lfstream.codec.warp.kernels.warp_all_views`); this is the same arithmetic written for a
GPU, checked against it on the CPU (tests/codec/warp/test_warp_batched.py).

The same steps and numbers as the kernel: the centre disparity forward-splatted into each
view (nearest pixel, the larger disparity wins), holes given their nearest splatted
neighbour on the background side (the smaller disparity; a row nothing landed on keeps the
centre map), bilinear sampling in 1/1024-pixel fixed point with the border replicated, the
per-view gain maps bilinearly up-sampled (OpenCV's INTER_LINEAR taps) and multiplied in.
On a CUDA device where Triton imports, the same steps run as three fused kernels.
Integer steps are exact; the splat and tap positions round once, as the kernel's fused
multiply-adds do, so without gains the bytes are the kernel's. In the gain blend not every
choice of the kernel's compiler is reproduced: about one sample in 10^6 moves by a level
(the tests bound it).
"""

from __future__ import annotations

import numpy as np
import torch

from lfstream.codec.warp import cpu as _warp
from lfstream.codec.warp.cpu import _check_views, _linear_taps
from lfstream.errors import LFShapeError, LFValueError
from lfstream.lightfield import view_offsets

_HOLE = -3.0e38  # as the kernel: a view pixel no centre pixel landed on
_HOLE_TEST = -1.0e38
_FRAC_BITS = 10
_FRAC = 1 << _FRAC_BITS
_TAP_OFFSET = 64 * _FRAC  # positions in 1/1024 px from -64 px on (as the kernel)
_SCALE_BITS = 13  # fractional bits of a bilinear sample before rounding (the kernel's _SCALE_BITS)
#: view pixels (frames x views x pixels) per pass: about 2 GiB of intermediates at the peak
#: (int64 tap indices, three int32 channels per tap); 3.3 frames of 7x7x375x540
DEFAULT_CHUNK_PIXELS = 1 << 25


def _floor_int(t: torch.Tensor, offset: float) -> torch.Tensor:
    """floor(t) as the kernel computes it (:func:`lfstream.codec.warp.kernels._floor_int`): the
    truncation of ``t + offset`` in float32, clamped the same way."""
    return (t.clamp(1.0 - offset, 1.0e9) + offset).to(torch.int32) - int(offset)  # a float32 sum


def _fma(a: torch.Tensor, b: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
    """``a * b + c`` rounded once to float32, as the kernel's fused multiply-add does (the
    float64 product of two float32 values is exact): with two roundings, 1 to 8 samples in
    3e7 of a 7x7x375x540 warp moved by a level."""
    return (a.double() * b.double() + c.double()).float()


def _splat(d: torch.Tensor, du: torch.Tensor, dv: torch.Tensor) -> torch.Tensor:
    """The centre maps ``d`` (B, 1, H, W) forward-splatted into views with displacements
    ``(du, dv)`` (1, n, 1, 1) per unit disparity, holes marked :data:`_HOLE`.

    Shape:
        - output: ``(B, n, H, W)`` float32
    """
    b, _, h, w = d.shape
    n = du.shape[1]
    dev = d.device
    ys = torch.arange(h, device=dev, dtype=torch.float32).view(1, 1, h, 1)
    xs = torch.arange(w, device=dev, dtype=torch.float32).view(1, 1, 1, w)
    iy = _floor_int(_fma(-d, du, ys) + 0.5, 1024.0)
    ix = _floor_int(_fma(-d, dv, xs) + 0.5, 1024.0)
    inside = (iy >= 0) & (iy < h) & (ix >= 0) & (ix < w)
    base = torch.arange(b * n, device=dev, dtype=torch.int64).view(b, n, 1, 1) * (h * w)
    target = torch.where(inside, base + iy.to(torch.int64) * w + ix, b * n * h * w)  # outside: a spare slot
    flat = torch.full((b * n * h * w + 1,), _HOLE, dtype=torch.float32, device=dev)
    flat.scatter_reduce_(0, target.reshape(-1), d.expand(b, n, h, w).reshape(-1), reduce="amax", include_self=True)
    return flat[:-1].view(b, n, h, w)


def _row_fold_bounds(d: torch.Tensor) -> torch.Tensor:
    """Per frame and row ``(rx, ry)`` of the centre maps ``d`` (B, 1, H, W), as
    :func:`lfstream.codec.warp.splat_kernels.row_fold_bounds` computes them (the same float32
    operations, each rounded once, so the same values; ``ry`` of the last row 0).

    Shape:
        - output: ``(B, 2, H)`` float32
    """
    b, _, h, w = d.shape
    out = torch.zeros((b, 2, h), dtype=torch.float32, device=d.device)
    if w > 1:
        a, c = d[..., :-1], d[..., 1:]
        out[:, 0] = ((c - a).abs() * torch.maximum(a.abs(), c.abs())).amax(dim=-1)[:, 0]
    if h > 1:
        a, c = d[..., :-1, :], d[..., 1:, :]
        out[:, 1, :-1] = ((c - a).abs() * torch.maximum(a.abs(), c.abs())).amax(dim=-1)[:, 0]
    return out


def _window_max(a: torch.Tensor, reach: torch.Tensor) -> torch.Tensor:
    """``out[b, k, y] = max(a[b, y - r : y + r + 1])`` with ``r = reach[b, k]``, the window
    clipped at the ends (:func:`lfstream.codec.warp.cpu._window_max`, every frame and reach at
    once): a sparse table of maxima over runs of 2^j rows, two lookups a window. Maxima are
    exact, so the values are the host's.

    Shape:
        - a: ``(B, H)``; reach: ``(B, N)`` int64; output: ``(B, N, H)``
    """
    b, h = a.shape
    levels = [a]
    span = 1
    while 2 * span <= h:  # levels[j][i] = max(a[i : i + 2^j]), where that run fits
        prev = levels[-1]
        nxt = prev.clone()
        nxt[:, :h - span] = torch.maximum(prev[:, :h - span], prev[:, span:])
        levels.append(nxt)
        span *= 2
    table = torch.stack(levels).reshape(-1)  # (L, B, H) flat
    y = torch.arange(h, device=a.device).view(1, 1, h)
    r = reach.clamp(max=h).unsqueeze(-1)
    lo = (y - r).clamp(min=0)
    hi = (y + r).clamp(max=h - 1)
    length = hi - lo + 1
    j = torch.floor(torch.log2(length.double())).long()  # then corrected: log2 of an int may round
    j = j + (torch.bitwise_left_shift(torch.ones_like(j), j + 1) <= length).long()
    j = j - (torch.bitwise_left_shift(torch.ones_like(j), j) > length).long()
    frame = torch.arange(b, device=a.device).view(b, 1, 1)
    base = (j * b + frame) * h
    return torch.maximum(table[base + lo], table[base + hi - torch.bitwise_left_shift(torch.ones_like(j), j) + 1])


def _splat_rows(d: torch.Tensor, offsets: np.ndarray, tolerance: float) -> torch.Tensor:
    """The view rows each frame splats (:func:`lfstream.codec.warp.cpu.splat_rows`) on the maps'
    device, every frame at once: the same float32 fold bounds as the CPU kernel's, the same
    float64 windows and test (:func:`lfstream.codec.warp.cpu._rows_from_bounds`), and no trip to
    the host.

    Shape:
        - d: ``(B, 1, H, W)`` finite float32; offsets: ``(N, 2)``; output: ``(B, N, H)`` bool
    """
    bounds = _row_fold_bounds(d).double()  # (B, 2, H)
    off = torch.from_numpy(np.abs(np.asarray(offsets, np.float64))).to(d.device)
    du, dv = off[:, 0], off[:, 1]
    dmax = d.abs().flatten(1).amax(dim=1).double()  # float32 max, as splat_reach(float(...)) gets it
    reach = (torch.ceil(torch.clamp(du[None] * dmax[:, None], max=1e9) + 0.5) + 1).long()  # splat_reach
    mx = _window_max(bounds[:, 0], reach)
    my = _window_max(bounds[:, 1], reach)
    a, c = du.view(1, -1, 1), dv.view(1, -1, 1)
    moving = ((du > 0) | (dv > 0)).view(1, -1, 1)
    return moving & (torch.hypot(a, c) * (a * my + c * mx) > tolerance)


def _fill_holes(maps: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """Every hole of the splatted ``maps`` (B, n, H, W) takes its nearest splatted neighbour
    in the row on the background side (the smaller disparity; the left one on a tie), the
    one neighbour a run at the row's end has, or the centre map ``d`` (B, 1, H, W) where the
    row has none (:func:`lfstream.codec.warp.kernels._fill_holes`)."""
    w = maps.shape[-1]
    hole = maps <= _HOLE_TEST
    pos = torch.arange(w, device=maps.device, dtype=torch.int64).expand_as(maps)
    left = torch.where(hole, -1, pos).cummax(dim=-1).values  # nearest splatted pixel at or left of x
    mirrored = torch.where(hole, -1, (w - 1) - pos).flip(-1).cummax(dim=-1).values.flip(-1)
    right = torch.where(mirrored >= 0, (w - 1) - mirrored, w)  # nearest splatted pixel at or right of x
    dl = maps.gather(-1, left.clamp(min=0))
    dr = maps.gather(-1, right.clamp(max=w - 1))
    has_l, has_r = left >= 0, right < w
    fill = torch.where(has_l & has_r, torch.where(dl <= dr, dl, dr),
                       torch.where(has_l, dl, torch.where(has_r, dr, d.expand_as(maps))))
    return torch.where(hole, fill, maps)


def _bilinear(src: torch.Tensor, idx: torch.Tensor, fx: torch.Tensor, fy: torch.Tensor, stride: int) -> torch.Tensor:
    """Bilinear samples of the padded views ``src`` (B, C, (H + 2) * (W + 2)) int32 at the
    top-left taps ``idx`` (B, 1, N) int64 with 1/1024-pixel fractions ``fx, fy`` (B, 1, N...)
    int32, as the kernel computes them (:func:`lfstream.codec.warp.kernels._sample_at`):
    each row's pair rounded to 8 x the value, then the rows blended.

    Shape:
        - output: ``(B, C, N)`` int32, ``2^13`` x the sample
    """
    b, c = src.shape[:2]
    fx = fx.reshape(b, 1, -1)
    fy = fy.reshape(b, 1, -1)

    def tap(offset: int) -> torch.Tensor:
        return src.gather(2, (idx + offset).expand(b, c, -1))

    top = ((_FRAC - fx) * tap(0) + fx * tap(1) + 64) >> 7
    bottom = ((_FRAC - fx) * tap(stride) + fx * tap(stride + 1) + 64) >> 7
    return (_FRAC - fy) * top + fy * bottom


def _gain_columns(gains: torch.Tensor, cols: torch.Tensor, col_w: torch.Tensor) -> torch.Tensor:
    """The gain grids (B, n, gh, gw, Cg) up-sampled along x, times 2^-13 (the sample's
    fixed-point scale), in the kernel's precision (one product in float32, the rest float64).

    Shape:
        - output: ``(B, n, gh, W, Cg)`` float32
    """
    ga = gains[:, :, :, cols[:, 0]]
    gb = gains[:, :, :, cols[:, 1]]
    wx = col_w.view(1, 1, 1, -1, 1)
    blend = (ga * wx).double() + gb.double() * (1.0 - wx.double())
    return (blend * (1.0 / (1 << _SCALE_BITS))).float()


def _fused_warp(device: torch.device):
    """The fused kernels (:mod:`lfstream.codec.warp.triton`: ``splat_maps`` and
    ``warp_pixels``) on a CUDA device where Triton imports (it ships with CUDA builds of
    torch); ``None``: the torch path."""
    if device.type != "cuda":
        return None
    try:
        from lfstream.codec.warp import triton as warp_triton
    except ImportError:
        return None
    return warp_triton


def warp_views_batched(
    centres: torch.Tensor,
    disparities: torch.Tensor,
    views: tuple[int, int],
    occlusion: bool = True,
    gains: torch.Tensor | None = None,
    axes: np.ndarray | None = None,
    view_disparities: torch.Tensor | None = None,
    chunk_pixels: int = DEFAULT_CHUNK_PIXELS,
) -> torch.Tensor:
    """Every view of several light fields from their centre views and centre disparities,
    on the tensors' device (:func:`lfstream.codec.warp.cpu.warp_views`, batched).

    Args:
        centres: ``(B, H, W, C)`` uint8 centre views.
        disparities: ``(B, H, W)`` float32 centre-view disparities, px per view step.
        views: ``(U, V)`` of the output.
        occlusion: per-view disparity by z-tested forward splatting where it can matter
            (as ``warp_views``: the rows :func:`lfstream.codec.warp.cpu.splat_rows` names, per frame).
        gains: ``(B, U, V, gh, gw, 1 or C)`` float32 gain maps, or ``None``; a frame whose
            maps are all within 1e-6 of 1 is warped without gains, as ``warp_views`` does.
        axes: ``(2, 2)`` view axes shared by the frames; ``None``: the convention.
        view_disparities: ``(B, U, V, H, W)`` float32 per-view maps (Depth-Net's) used in place
            of the splatted ones (as :func:`lfstream.codec.warp.cpu.warp_views_per_view`).
        chunk_pixels: view pixels (frames x views x pixels) per pass, to bound memory (the
            fused CUDA kernels hold a sixteenth as much per pixel: 16 x as many a pass, and
            one pass where nothing splats).

    Shape:
        - output: ``(B, U, V, H, W, C)`` uint8 on the device of ``centres``
    """
    if centres.ndim != 4 or centres.dtype != torch.uint8:
        raise LFShapeError(f"centres: expected (B, H, W, C) uint8, got {centres.dtype} {tuple(centres.shape)}")
    b, h, w, c = centres.shape
    if tuple(disparities.shape) != (b, h, w):
        raise LFShapeError(f"disparities: expected {(b, h, w)}, got {tuple(disparities.shape)}")
    u, v = _check_views(views)
    dev = centres.device
    if b == 0:  # an empty batch: nothing to warp (no frame maxima to take)
        return torch.empty((0, u, v, h, w, c), dtype=torch.uint8, device=dev)
    d = disparities.to(dev, torch.float32).reshape(b, 1, h, w)
    if not torch.isfinite(d).all():
        raise LFValueError("disparities: NaN or Inf")
    if view_disparities is not None:
        if tuple(view_disparities.shape) != (b, u, v, h, w):
            raise LFShapeError(f"view_disparities: expected {(b, u, v, h, w)}, got {tuple(view_disparities.shape)}")
        view_disparities = view_disparities.to(dev, torch.float32).reshape(b, u * v, h, w)
    grid_offsets = view_offsets((u, v), axes).reshape(-1, 2)
    offsets = torch.from_numpy(grid_offsets).to(dev)
    has_gains = None  # (B,) bool: the frames warped with their gains
    if gains is not None:
        gains = gains.to(dev, torch.float32)
        if gains.ndim != 6 or tuple(gains.shape[:3]) != (b, u, v) or gains.shape[5] not in (1, c):
            raise LFShapeError(f"gains: expected ({b}, {u}, {v}, gh, gw, 1 or {c}), got {tuple(gains.shape)}")
        has_gains = ((gains - 1.0).abs() >= 1e-6).flatten(1).any(dim=1)
        if not bool(has_gains.any()):  # one test here, not one (a device sync) per pass
            has_gains = None
        rows, row_w = (torch.from_numpy(a).to(dev) for a in _linear_taps(h, gains.shape[3]))
        cols, col_w = (torch.from_numpy(a).to(dev) for a in _linear_taps(w, gains.shape[4]))
        gains = gains.reshape(b, u * v, *gains.shape[3:])
    # (B, U*V, H) bool, the rows each view splats, and (B, U*V) bool, the views that splat any
    # (on the host: which passes need the splat, read once, not one device sync a pass)
    splat_host = splat_rows = splat_views = None
    if occlusion and view_disparities is None:
        splat_rows = _splat_rows(d, grid_offsets, _warp.SPLAT_TOLERANCE_PX)
        splat_views = splat_rows.any(dim=-1)
        splat_host = splat_views.cpu().numpy()
    out = torch.empty((b, u * v, h, w, c), dtype=torch.uint8, device=dev)
    step = max(1, chunk_pixels // max(1, b * h * w))
    fused = _fused_warp(dev)
    src = None
    if fused is not None:
        centres = centres.contiguous()
        if gains is not None:
            gains = gains.contiguous()
        if splat_host is None or not splat_host.any():  # no per-pass intermediates to bound: one launch
            step = u * v
        else:  # 4 bytes a view pixel (its map) where the tensor path holds about 64: as much memory
            step = max(1, 16 * chunk_pixels // max(1, b * h * w))
    ys = torch.arange(h, device=dev, dtype=torch.float32).view(1, 1, h, 1)
    xs = torch.arange(w, device=dev, dtype=torch.float32).view(1, 1, 1, w)
    for k0 in range(0, u * v, step):
        k1 = min(u * v, k0 + step)
        n = k1 - k0
        du = offsets[k0:k1, 0].view(1, n, 1, 1)
        dv = offsets[k0:k1, 1].view(1, n, 1, 1)
        read_rows = None  # the fused warp: the rows of `maps` it reads (the centre map elsewhere)
        if view_disparities is not None:
            maps = view_disparities[:, k0:k1]
        elif splat_host is not None and splat_host[:, k0:k1].any():
            if fused is not None:  # the splatted rows only
                maps, read_rows = fused.splat_maps(d, offsets, splat_rows, splat_views, k0, n), splat_rows
            else:
                maps = _fill_holes(_splat(d, du, dv), d)
                maps = torch.where(splat_rows[:, k0:k1, :, None], maps, d)  # rows not splatted: the centre map
        else:
            maps = d.expand(b, n, h, w)
        if fused is not None:
            fused.warp_pixels(centres, maps, out, offsets, k0, gains, has_gains,
                              None if gains is None else (rows, row_w), None if gains is None else (cols, col_w),
                              centre_maps=None if read_rows is None else d, splat_rows=read_rows)
            continue
        if src is None:  # the padded centre views, one int32 plane per channel, flat: a tap is one index
            padded = torch.nn.functional.pad(centres.permute(0, 3, 1, 2).float(), (1, 1, 1, 1), mode="replicate")
            src = padded.to(torch.int32).reshape(b, c, (h + 2) * (w + 2))
        ix = _floor_int(_fma(maps, dv, xs) * float(_FRAC) + 0.5, float(_TAP_OFFSET))
        iy = _floor_int(_fma(maps, du, ys) * float(_FRAC) + 0.5, float(_TAP_OFFSET))
        fx = ix & (_FRAC - 1)
        fy = iy & (_FRAC - 1)
        x0 = (ix >> _FRAC_BITS).clamp(-1, w - 1) + 1  # column in the padded view
        y0 = (iy >> _FRAC_BITS).clamp(-1, h - 1) + 1
        idx = (y0.to(torch.int64) * (w + 2) + x0).reshape(b, 1, -1)  # the top-left tap in the padded view
        val = _bilinear(src, idx, fx, fy, w + 2).view(b, c, n, h, w)  # 2^13 x the sample
        res = (val + (1 << (_SCALE_BITS - 1))) >> _SCALE_BITS
        if has_gains is not None:
            gc = _gain_columns(gains[:, k0:k1], cols, col_w)
            wa = row_w.view(1, 1, h, 1, 1)
            wb = 1.0 - wa
            g = _fma(gc[:, :, rows[:, 0]], wa, gc[:, :, rows[:, 1]] * wb)  # (B, n, H, W, Cg)
            g = g.permute(0, 4, 1, 2, 3)  # (B, Cg, n, H, W)
            scaled = (val.float() * g + 0.5).to(torch.int32).clamp(max=255)
            res = torch.where(has_gains.view(b, 1, 1, 1, 1), scaled, res)
        out[:, k0:k1] = res.to(torch.uint8).permute(0, 2, 3, 4, 1)
    return out.view(b, u, v, h, w, c)


__all__ = ["DEFAULT_CHUNK_PIXELS", "warp_views_batched"]
