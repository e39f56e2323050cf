"""The batched warp on a CUDA device as Triton kernels: the splatting rows marked as holes,
the z-tested forward splat into them, their row-wise hole filling, and the per-pixel warp.

:func:`lfstream.codec.warp.batched.warp_views_batched` written as torch operations moves
every intermediate (tap positions, int64 indices, four gathered taps per channel, float64
gain blends, the splat's scatter and the hole filling's scans) through GPU memory: 130 LF/s
of 7x7x375x540 on an H100. With this module: 1,397 LF/s (30 a
call), 1,774 (120 a call); without the splat (every view from the centre map) 2,306 and
2,696 (``bench/batched_warp.py``; the per-pixel kernel alone lifted the torch path to 355).
Since 2026-11-27 (the splat's rows decided on the device and only those splatted, the
per-pixel kernel's launch settings below): 1,710 LF/s at 30 a call in the harness's timing
(1,506 with the previous launch settings on the same machine; the 2026-11-25 code ran at
1,133 on another H100, alternating with the new rows' code at 1,600).

The per-pixel kernel does a view pixel's whole chain in registers: the view's disparity
(the centre map, a splatted map or Depth-Net's, given as ``maps``), the tap position in
1/1024-pixel fixed point, the four taps of the replicate-padded centre view, the
fixed-point bilinear blend, the shading gain up-sampled from its grid with OpenCV's
INTER_LINEAR taps, and the uint8 store. Same arithmetic as the CPU kernel
(:func:`lfstream.codec.warp.kernels.warp_all_views`) and the torch path; floating-point
contraction is off, so each operation rounds where the torch path rounds (fused
multiply-adds only where the kernel has them). Checked on the H100 against the torch path
and the CPU kernel (tests/codec/warp/test_warp_batched.py: within a level, as the tests bound
the torch path), and in Triton's interpreter against the torch path to the byte.

Triton ships with CUDA builds of torch; without it, or off CUDA, the torch path runs.
"""

from __future__ import annotations

import torch
import triton
import triton.language as tl

#: view pixels per program of the per-pixel warp, and centre pixels per program of the splat
#: (H100, 30 light fields of 7x7x375x540 a call, each setting alternated with the others in
#: one process, 20 rounds: the warp with 256 pixels and 8 warps a program 20.1 -> 17.5 ms a
#: call; 1024 pixels or 2 warps 1.6x slower; the splat's and the row kernels' settings within
#: 1.5 %, their defaults kept; the same bytes with every setting)
_BLOCK = 256
_SPLAT_BLOCK = 512
#: warps per program (Triton's default is 4) of the per-pixel warp, the splat, and the two
#: row kernels (marking a row's holes, filling them)
_WARP_WARPS = 8
_SPLAT_WARPS = 4
_ROW_WARPS = 4


@triton.jit
def _warp_kernel(centre_ptr, maps_ptr, out_ptr, du_ptr, dv_ptr, gains_ptr, flags_ptr, rows_ptr, row_w_ptr, cols_ptr,
                 col_w_ptr, d_ptr, splat_ptr, H, W, VIEW0, NV, s_mb, s_mn, s_ob, s_gb, s_gn, s_gh, s_gw,
                 C: tl.constexpr, CP: tl.constexpr, CG: tl.constexpr, HAS_GAINS: tl.constexpr, HAS_ROWS: tl.constexpr,
                 BLOCK: tl.constexpr):
    pid = tl.program_id(0)
    k = tl.program_id(1).to(tl.int64)  # view of this pass (64-bit: offsets past 2^31 elements)
    b = tl.program_id(2).to(tl.int64)  # frame
    p = pid * BLOCK + tl.arange(0, BLOCK)
    inside = p < H * W
    y = p // W
    x = p - y * W
    if HAS_ROWS:  # splatted rows from the maps, the others from the centre map d
        splatted = tl.load(splat_ptr + (b * NV + VIEW0 + k) * H + y, mask=inside, other=0) != 0
        m = tl.where(splatted, tl.load(maps_ptr + b * s_mb + k * s_mn + p, mask=inside & splatted, other=0.0),
                     tl.load(d_ptr + b * H * W + p, mask=inside & ~splatted, other=0.0))
    else:
        m = tl.load(maps_ptr + b * s_mb + k * s_mn + p, mask=inside, other=0.0)
    du = tl.load(du_ptr + VIEW0 + k)
    dv = tl.load(dv_ptr + VIEW0 + k)
    # positions in 1/1024 px, floored from -64 px on (the kernel's _floor_int); * 1024 is exact
    tx = tl.fma(m, dv, x.to(tl.float32)) * 1024.0 + 0.5
    ty = tl.fma(m, du, y.to(tl.float32)) * 1024.0 + 0.5
    ix = (tl.minimum(tl.maximum(tx, 1.0 - 65536.0), 1.0e9) + 65536.0).to(tl.int32) - 65536
    iy = (tl.minimum(tl.maximum(ty, 1.0 - 65536.0), 1.0e9) + 65536.0).to(tl.int32) - 65536
    fx = (ix & 1023)[:, None]
    fy = (iy & 1023)[:, None]
    # the replicate-padded view's taps, as columns/rows of the unpadded one
    xi = tl.minimum(tl.maximum(ix >> 10, -1), W - 1)
    yi = tl.minimum(tl.maximum(iy >> 10, -1), H - 1)
    xa = tl.maximum(xi, 0)
    xb = tl.minimum(xi + 1, W - 1)
    ya = tl.maximum(yi, 0).to(tl.int64)
    yb = tl.minimum(yi + 1, H - 1).to(tl.int64)
    ch = tl.arange(0, CP)
    both = inside[:, None] & (ch < C)[None, :]
    frame = centre_ptr + b * H * W * C + ch[None, :]
    t00 = tl.load(frame + ((ya * W + xa) * C)[:, None], mask=both, other=0).to(tl.int32)
    t01 = tl.load(frame + ((ya * W + xb) * C)[:, None], mask=both, other=0).to(tl.int32)
    t10 = tl.load(frame + ((yb * W + xa) * C)[:, None], mask=both, other=0).to(tl.int32)
    t11 = tl.load(frame + ((yb * W + xb) * C)[:, None], mask=both, other=0).to(tl.int32)
    top = ((1024 - fx) * t00 + fx * t01 + 64) >> 7
    bottom = ((1024 - fx) * t10 + fx * t11 + 64) >> 7
    val = (1024 - fy) * top + fy * bottom  # 2^13 x the sample
    res = (val + 4096) >> 13
    if HAS_GAINS:
        flag = tl.load(flags_ptr + b)
        r0 = tl.load(rows_ptr + y * 2, mask=inside, other=0)
        r1 = tl.load(rows_ptr + y * 2 + 1, mask=inside, other=0)
        wa = tl.load(row_w_ptr + y, mask=inside, other=0.0)[:, None]
        c0 = tl.load(cols_ptr + x * 2, mask=inside, other=0)
        c1 = tl.load(cols_ptr + x * 2 + 1, mask=inside, other=0)
        wx = tl.load(col_w_ptr + x, mask=inside, other=0.0)[:, None]
        if CG > 1:  # a gain per channel
            grid = gains_ptr + b * s_gb + (VIEW0 + k) * s_gn + ch[None, :]
        else:  # one gain for every channel
            grid = gains_ptr + b * s_gb + (VIEW0 + k) * s_gn + ch[None, :] * 0
        gmask = both
        wx64 = wx.to(tl.float64)
        # each grid row blended along x (one float32 product, the rest float64, times 2^-13)
        ga = tl.load(grid + (r0 * s_gh + c0 * s_gw)[:, None], mask=gmask, other=0.0)
        gb = tl.load(grid + (r0 * s_gh + c1 * s_gw)[:, None], mask=gmask, other=0.0)
        g0 = (((ga * wx).to(tl.float64) + gb.to(tl.float64) * (1.0 - wx64)) * (1.0 / 8192.0)).to(tl.float32)
        ga = tl.load(grid + (r1 * s_gh + c0 * s_gw)[:, None], mask=gmask, other=0.0)
        gb = tl.load(grid + (r1 * s_gh + c1 * s_gw)[:, None], mask=gmask, other=0.0)
        g1 = (((ga * wx).to(tl.float64) + gb.to(tl.float64) * (1.0 - wx64)) * (1.0 / 8192.0)).to(tl.float32)
        # then along y: one rounding of g0 * wa + g1 * (1 - wa), the product exact in float64
        g = (g0.to(tl.float64) * wa.to(tl.float64) + (g1 * (1.0 - wa)).to(tl.float64)).to(tl.float32)
        scaled = tl.minimum((val.to(tl.float32) * g + 0.5).to(tl.int32), 255)
        res = tl.where(flag != 0, scaled, res)
    dst = out_ptr + b * s_ob + ((VIEW0 + k) * H * W + p)[:, None] * C + ch[None, :]
    tl.store(dst, res.to(tl.uint8), mask=both)


@triton.jit
def _max(a, b):
    return tl.maximum(a, b)


@triton.jit
def _min(a, b):
    return tl.minimum(a, b)


@triton.jit
def _init_kernel(maps_ptr, splat_ptr, H, W, VIEW0, NV, N, BLOCK_W: tl.constexpr):
    """The rows of one view that splat marked as holes (the others are never read)."""
    y = tl.program_id(0)
    k = tl.program_id(1)
    b = tl.program_id(2).to(tl.int64)
    pos = tl.arange(0, BLOCK_W)
    splatted = tl.load(splat_ptr + (b * NV + VIEW0 + k) * H + y) != 0
    tl.store(maps_ptr + ((b * N + k) * H + y) * W + pos, tl.full((BLOCK_W,), -3.0e38, tl.float32),
             mask=(pos < W) & splatted)


@triton.jit
def _splat_kernel(d_ptr, maps_ptr, du_ptr, dv_ptr, flags_ptr, splat_ptr, H, W, VIEW0, NV, N, BLOCK: tl.constexpr):
    """Every centre pixel to its nearest view pixel in a row that splats; the larger disparity
    wins (an atomic max: the result does not depend on the order). Views whose flag is 0 are
    left alone."""
    pid = tl.program_id(0)
    k = tl.program_id(1)
    b = tl.program_id(2).to(tl.int64)
    flag = tl.load(flags_ptr + b * NV + VIEW0 + k)
    p = pid * BLOCK + tl.arange(0, BLOCK)
    inside = p < H * W
    y = p // W
    x = p - y * W
    m = tl.load(d_ptr + b * H * W + p, mask=inside, other=0.0)
    du = tl.load(du_ptr + VIEW0 + k)
    dv = tl.load(dv_ptr + VIEW0 + k)
    ty = tl.fma(-m, du, y.to(tl.float32)) + 0.5
    tx = tl.fma(-m, dv, x.to(tl.float32)) + 0.5
    iy = (tl.minimum(tl.maximum(ty, 1.0 - 1024.0), 1.0e9) + 1024.0).to(tl.int32) - 1024
    ix = (tl.minimum(tl.maximum(tx, 1.0 - 1024.0), 1.0e9) + 1024.0).to(tl.int32) - 1024
    ok = inside & (flag != 0) & (iy >= 0) & (iy < H) & (ix >= 0) & (ix < W)
    ok = ok & (tl.load(splat_ptr + (b * NV + VIEW0 + k) * H + iy, mask=ok, other=0) != 0)
    tl.atomic_max(maps_ptr + (b * N + k) * H * W + iy * W + ix, m, mask=ok)


@triton.jit
def _fill_kernel(d_ptr, maps_ptr, splat_ptr, H, W, VIEW0, NV, N, BLOCK_W: tl.constexpr):
    """One row of one view that splats: each hole takes its nearest splatted neighbour on the
    background side (the smaller disparity, the left one on a tie), the one neighbour it has,
    or the centre map where the row has none. Rows that do not splat are left alone."""
    y = tl.program_id(0)
    k = tl.program_id(1)
    b = tl.program_id(2).to(tl.int64)
    pos = tl.arange(0, BLOCK_W)
    inside = (pos < W) & (tl.load(splat_ptr + (b * NV + VIEW0 + k) * H + y) != 0)
    row = maps_ptr + ((b * N + k) * H + y) * W
    centre = tl.load(d_ptr + (b * H + y) * W + pos, mask=inside, other=0.0)
    val = tl.load(row + pos, mask=inside, other=-3.0e38)
    hole = val <= -1.0e38
    left = tl.associative_scan(tl.where(hole, -1, pos), 0, _max)
    right = tl.associative_scan(tl.where(hole, W, pos), 0, _min, reverse=True)
    has_l = left >= 0
    has_r = right < W
    dl = tl.load(row + tl.maximum(left, 0), mask=inside, other=0.0)
    dr = tl.load(row + tl.minimum(right, W - 1), mask=inside, other=0.0)
    fill = tl.where(has_l & has_r, tl.where(dl <= dr, dl, dr), tl.where(has_l, dl, tl.where(has_r, dr, centre)))
    tl.store(row + pos, tl.where(hole, fill, val), mask=inside)


def splat_maps(d: torch.Tensor, offsets: torch.Tensor, splat_rows: torch.Tensor, splat_views: torch.Tensor,
               view0: int, n: int) -> torch.Tensor:
    """Views ``view0 ... view0 + n - 1``'s disparity maps in the rows ``splat_rows`` names: the
    centre maps ``d`` forward-splatted (z-tested) and hole-filled
    (:func:`lfstream.codec.warp.batched._splat` and ``_fill_holes``, in three kernels); the
    other rows are left unwritten (:func:`warp_pixels` reads ``d`` there).

    Args:
        d: ``(B, 1, H, W)`` float32 centre maps.
        offsets: ``(U*V, 2)`` float32 displacement per unit disparity.
        splat_rows: ``(B, U*V, H)`` bool, the rows each view of each frame splats, and
            ``splat_views`` ``(B, U*V)`` bool, the views that splat any (``splat_rows.any(-1)``).

    Shape:
        - output: ``(B, n, H, W)`` float32
    """
    b, _, h, w = d.shape
    maps = torch.empty((b, n, h, w), dtype=torch.float32, device=d.device)
    rows = splat_rows.contiguous().view(torch.int8)
    flags = splat_views.to(torch.int8)
    nv = rows.shape[1]
    d = d.contiguous()
    du = offsets[:, 0].contiguous()
    dv = offsets[:, 1].contiguous()
    # the rows are the cheap axis of the grid: the x dimension takes any count
    _init_kernel[(h, n, b)](maps, rows, h, w, view0, nv, n, BLOCK_W=triton.next_power_of_2(w), num_warps=_ROW_WARPS)
    _splat_kernel[(triton.cdiv(h * w, _SPLAT_BLOCK), n, b)](d, maps, du, dv, flags, rows, h, w, view0, nv, n,
                                                              BLOCK=_SPLAT_BLOCK, enable_fp_fusion=False,
                                                              num_warps=_SPLAT_WARPS)
    _fill_kernel[(h, n, b)](d, maps, rows, h, w, view0, nv, n, BLOCK_W=triton.next_power_of_2(w), num_warps=_ROW_WARPS)
    return maps


def warp_pixels(centres: torch.Tensor, maps: torch.Tensor, out: torch.Tensor, offsets: torch.Tensor, view0: int,
                gains: torch.Tensor | None = None, has_gains: torch.Tensor | None = None,
                row_taps: tuple[torch.Tensor, torch.Tensor] | None = None,
                col_taps: tuple[torch.Tensor, torch.Tensor] | None = None, centre_maps: torch.Tensor | None = None,
                splat_rows: torch.Tensor | None = None) -> None:
    """Views ``view0 ... view0 + n - 1`` of every frame, written into ``out``.

    Args:
        centres: ``(B, H, W, C)`` uint8, contiguous.
        maps: ``(B, n, H, W)`` float32, each ``(H, W)`` plane contiguous (an expanded centre
            map is fine: its view stride is 0): the disparity each view pixel samples with.
        out: ``(B, U*V, H, W, C)`` uint8, contiguous.
        offsets: ``(U*V, 2)`` float32 displacement per unit disparity ``(du, dv)``.
        view0: the first view of this pass.
        gains: ``(B, U*V, gh, gw, 1 or C)`` float32 gain grids (last dimension contiguous), and
            ``has_gains`` ``(B,)`` bool, the frames they apply to; ``row_taps`` / ``col_taps``:
            OpenCV's INTER_LINEAR taps ``((H, 2) int64, (H,) float32)`` and the same along x.
        centre_maps, splat_rows: ``(B, 1, H, W)`` float32 and ``(B, U*V, H)`` bool: rows of
            ``maps`` (from :func:`splat_maps`) are read where ``splat_rows`` is set, the
            centre map elsewhere; ``None``: ``maps`` everywhere.

    Shape:
        - out: ``(B, U*V, H, W, C)``
    """
    b, h, w, c = centres.shape
    n = maps.shape[1]
    if b == 0 or n == 0:
        return
    if maps.stride(3) != 1 or maps.stride(2) != w:  # the kernel reads each view's plane as one run
        maps = maps.contiguous()
    du = offsets[:, 0].contiguous()
    dv = offsets[:, 1].contiguous()
    with_gains = gains is not None and has_gains is not None
    if with_gains:
        rows, row_w = row_taps
        cols, col_w = col_taps
        flags = has_gains.to(torch.int32)
        gstride = gains.stride()
        cg = gains.shape[-1]
    else:  # unused pointers
        rows = cols = flags = torch.zeros(2, dtype=torch.int64, device=centres.device)
        row_w = col_w = gains = torch.zeros(2, dtype=torch.float32, device=centres.device)
        gstride = (0, 0, 0, 0)
        cg = 1
    with_rows = splat_rows is not None and centre_maps is not None
    if with_rows:
        d = centre_maps.contiguous()
        splatted = splat_rows.contiguous().view(torch.int8)
        nv = splatted.shape[1]
    else:  # unused pointers
        d, splatted, nv = maps, flags, 0
    grid = (triton.cdiv(h * w, _BLOCK), n, b)
    _warp_kernel[grid](centres, maps, out, du, dv, gains, flags, rows, row_w, cols, col_w, d, splatted, h, w, view0, nv,
                       maps.stride(0), maps.stride(1), out.stride(0), *gstride[:4],
                       C=c, CP=triton.next_power_of_2(c), CG=cg, HAS_GAINS=with_gains, HAS_ROWS=with_rows,
                       BLOCK=_BLOCK, enable_fp_fusion=False, num_warps=_WARP_WARPS)
