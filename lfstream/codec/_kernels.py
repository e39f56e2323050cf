"""Fused CPU kernels of the codec (the encoder's plane sweep, the decoder's hint
up-sampling and warp), compiled by numba (cached on disk).

The per-view disparity of an occlusion-aware warp needs forward splatting with a z-test
and hole filling: per-pixel control flow that array operations cannot express. The warp
does splatting, hole filling, bilinear sampling and the shading gains of a view in one
pass, one view per thread, with nothing per view materialised beyond the splatted map.
"""

from __future__ import annotations

import numba
import numpy as np
from numba.core.cpu import CPUTargetOptions
from numba.extending import intrinsic

_PARALLEL = dict(parallel=True, fastmath=True, cache=True, nogil=True)
_HOLE = np.float32(-3.0e38)  # marks view pixels no centre pixel lands on
_HOLE_TEST = np.float32(-1.0e38)
# The parallel kernels run one row (or view) per prange iteration and do the row's work in
# plain njit functions (one place for the row's scalars, the same code at any thread count).
# Indices derived from uint8 data are computed in signed int32: a difference of unsigned
# values wraps and, without bounds checks, reads far outside a lookup table (a bug found
# here: joint_upsample gave different maps from run to run). tests/codec checks the
# kernels against plain-Python references and across thread counts.
_ROW = dict(fastmath=True, cache=True, nogil=True)
# Row helpers that allocate nothing run without numba's reference counting (``_nrt=False``):
# with it, every array argument of a call that LLVM does not inline is counted up on entry
# and down on each exit with atomic instructions, a dozen or more a row through the warp's
# helpers, a sixth of a decode's CPU under perf (NRT_incref and NRT_decref the two hottest
# instructions); their callers hold the arrays meanwhile.
# ``_nrt`` is an option numba's CPU target knows but does not document: where a numba
# without it would refuse the kernels, they count as before.
_BORROW = {"_nrt": False} if hasattr(CPUTargetOptions, "_nrt") else {}
_ROW_BORROWED = dict(_ROW, **_BORROW)
# OpenCV's arithmetic reproduced: no fastmath (a fused multiply-add or a reordered sum would
# round differently from OpenCV's separate float32 multiplies and adds)
_EXACT = dict(cache=True, nogil=True)
_EXACT_BORROWED = dict(_EXACT, **_BORROW)  # (see _ROW_BORROWED)


# Fixed-point bilinear sampling: positions in 1/1024 pixel (OpenCV 5's remap interpolates
# in float; 1/32 pixel, as older releases did, was measurably coarser on sharp edges).
# Up to three channels are sampled at once in 21-bit lanes of one uint64: one load and one
# multiply per tap instead of three. The horizontal pass leaves 1024 * value (18 bits) per
# lane, rounded to 8 * value (11 bits) so that the vertical pass's 1024 * 8 * value still
# fits 21 bits; the result carries 13 fractional bits (:data:`_SCALE_BITS`).
_FRAC_BITS = 10
_FRAC = 1 << _FRAC_BITS
_MID_SHIFT = 7
_SCALE_BITS = 2 * _FRAC_BITS - _MID_SHIFT
_LANE = 21
_LANE_MASK = (1 << _LANE) - 1
_MID_MASK = (1 << (_LANE - _MID_SHIFT)) - 1
_LANES = 3
# positions in 1/1024 pixel from -64 pixels on (anything further left reads the border)
_TAP_OFFSET = 64 * _FRAC


@numba.njit(fastmath=True, cache=True, nogil=True, inline="always")
def _lerp_lanes(a, b, fx):  # pragma: no cover - compiled
    """The horizontal step of the bilinear blend on packed lanes: ``(1024 - fx) * a + fx * b``
    per lane, rounded to ``8 * value`` (:data:`_MID_SHIFT`) so that the vertical step fits."""
    f = np.uint64(_FRAC)
    r = np.uint64((1 << (_MID_SHIFT - 1)) * (1 | (1 << _LANE) | (1 << (2 * _LANE))))
    m = np.uint64(_MID_MASK | (_MID_MASK << _LANE) | (_MID_MASK << (2 * _LANE)))
    return (((f - fx) * a + fx * b + r) >> np.uint64(_MID_SHIFT)) & m


#: adds half a unit in each lane before the shift that rounds to 8 bits
_HALF_LANES = (1 << (_SCALE_BITS - 1)) * (1 | (1 << _LANE) | (1 << (2 * _LANE)))


#: Which taps a view's samples need (:func:`_row_accs`): all four; only the row's two (a view
#: on the centre's row: no vertical displacement, the vertical fraction is 0 for every
#: pixel); only the column's two (a view on the centre's column: the horizontal fraction is 0)
_TAPS_ALL, _TAPS_ROW, _TAPS_COLUMN = 0, 1, 2


@numba.njit(**_ROW)
def _floor_int(t, offset):  # pragma: no cover - compiled
    """floor(t) as the truncation of a positive float32 (vectorises; a libm floor call or a
    correction for negatives does not); exact while ``offset + t`` keeps the fractional bits
    that matter (offset 1024: 1/8192 of a unit), clamped to ``[1 - offset, 1e9]`` so that a
    huge disparity cannot overflow the conversion (callers clamp or bound-check the result)."""
    return np.int32(min(max(t, np.float32(1.0) - offset), np.float32(1.0e9)) + offset) - np.int32(offset)


@numba.njit(**_PARALLEL)
def pack_lanes(img, ch0, n_ch, packed):  # pragma: no cover - compiled
    """``packed[(y + 1) * (W + 2) + x + 1]`` = channels ch0 .. ch0 + n_ch - 1 of ``img[y, x]``
    in 21-bit lanes, with a border of one replicated pixel all round: a bilinear tap at a
    position clamped to ``[-1, W - 1]`` then reads exactly what clamping each of its two
    taps to ``[0, W - 1]`` would, so a sample needs one index instead of four.

    A row's interior is packed one channel at a time (loops that vectorise; a clamped
    loop over every padded pixel took 6 ns a pixel), then its two border pixels copied; rows
    in parallel.

    Args:
        img: (H, W, C) uint8; packed: ((H + 2) * (W + 2),) uint64, overwritten.
    """
    h, w, c = img.shape
    w2 = w + 2
    flat = img.reshape(h, w * c)
    for yy in numba.prange(h + 2):  # independent rows
        row = flat[min(max(yy - 1, 0), h - 1)]
        dst = packed[yy * w2 + 1: yy * w2 + 1 + w]
        for x in range(w):
            dst[x] = np.uint64(row[x * c + ch0])
        for j in range(1, n_ch):
            shift = np.uint64(_LANE * j)
            for x in range(w):
                dst[x] |= np.uint64(row[x * c + ch0 + j]) << shift
        packed[yy * w2] = dst[0]
        packed[yy * w2 + w + 1] = dst[w - 1]


@numba.njit(**_ROW)
def _splat_view(disp, cols, du, dv, dview, targets, rows, reach, counts):  # pragma: no cover - compiled
    """Forward-splats the centre disparity into view (du, dv): nearest pixel, nearer wins.

    Per row, the target pixels first (a loop that vectorises: ``cols`` is ``x`` as float32,
    since converting the int64 loop counter does not vectorise on AVX2), then the scattered
    z-tested stores; ``targets`` (W,) int32 scratch, -1 where the pixel lands outside.

    Only the view rows ``rows`` (H,) bool are wanted: a centre row is splatted where one of
    them lies within ``reach`` rows of it (no centre pixel lands further from its own row,
    :func:`lfstream.codec.warp.splat_rows`), so those rows are exactly what splatting every
    row gives; the others may hold partial results. ``counts`` (H + 1,) int32 scratch.
    """
    h, w = disp.shape
    h32, w32 = np.int32(h), np.int32(w)
    flat = dview.ravel()
    for i in range(h * w):
        flat[i] = _HOLE
    counts[0] = 0
    for y in range(h):
        counts[y + 1] = counts[y] + (1 if rows[y] else 0)
    for y in range(h):
        if counts[min(y + reach + 1, h)] == counts[max(y - reach, 0)]:
            continue  # no wanted row within reach
        row = disp[y]
        fy = np.float32(y)
        for x in range(w):
            d = row[x]
            iy = _floor_int(fy - d * du + np.float32(0.5), np.float32(1024.0))
            ix = _floor_int(cols[x] - d * dv + np.float32(0.5), np.float32(1024.0))
            inside = (np.uint32(iy) < np.uint32(h32)) & (np.uint32(ix) < np.uint32(w32))
            targets[x] = iy * w32 + ix if inside else np.int32(-1)
        for x in range(w):
            j = targets[x]
            if j >= 0 and row[x] > flat[j]:
                flat[j] = row[x]


@numba.njit(**_ROW)
def _hole_scratch(w):  # pragma: no cover - compiled
    """The zeroed mask :func:`_fill_holes` needs for rows of ``w`` pixels: a byte a pixel,
    padded to whole uint64 words (the padding stays zero)."""
    return np.zeros((w + 7) // 8 * 8, np.uint8)


@numba.njit(**_ROW_BORROWED)
def _fill_holes(disp, dview, y, mask, words):  # pragma: no cover - compiled
    """Fills the holes of one splatted view row in place: a hole run takes the disparity of
    its nearest splatted neighbour on the background side (the smaller disparity), so the
    background is extended, not the occluder; a row nothing landed on falls back to the
    centre map. Every pixel then samples at its own position with its disparity.

    Most holes are one-pixel cracks where a surface stretches between views, not
    disocclusions: sampling them at their own position interpolates the surface, where
    repeating the neighbour's sample position (the rule before) duplicated a pixel. Measured
    at the default encode: MPSNR +0.07 (synthetic) … +0.34 dB (lytro_bikes) on all six
    scenes, toys_array's disocclusions included (+0.24 dB, MSSIM +0.016).

    In place is exact: a run's neighbours are splatted pixels, never a run filled before.
    The holes are found through ``mask`` (:func:`_hole_scratch`), set a byte a pixel by a loop
    that vectorises and scanned as uint64 words, so the scan passes eight splatted pixels per
    test: about 2.5 % of a view's pixels are holes, spread over most rows, and a test per
    pixel took 0.45 ms a 375 x 540 view, this 0.2 ms (a per-16-pixel minimum of the floats,
    tried before, was slower than the test per pixel). ``words``: ``mask`` as uint64, made
    once by the caller. Row ``y`` of the maps is indexed in place (see :func:`_row_accs`).
    """
    w = disp.shape[1]
    any_hole = np.uint8(0)
    for x in range(w):
        hole = np.uint8(dview[y, x] <= _HOLE_TEST)
        mask[x] = hole
        any_hole |= hole
    if any_hole == 0:
        return
    x = 0
    while x < w:
        if (x & 7) == 0 and words[x >> 3] == 0:
            x += 8
            continue
        if mask[x] == 0:
            x += 1
            continue
        start = x
        while x < w and mask[x] != 0:
            x += 1
        left, right = start - 1, x
        if left < 0 and right >= w:
            for xx in range(start, x):
                dview[y, xx] = disp[y, xx]
            continue
        if left < 0:
            src = right
        elif right >= w:
            src = left
        else:
            src = left if dview[y, left] <= dview[y, right] else right
        for xx in range(start, x):
            dview[y, xx] = dview[y, src]


@numba.njit(**_ROW_BORROWED)
def _row_taps(dmap, cols, y, du, dv, h, idx, fxs, fys):  # pragma: no cover - compiled
    """Flat index of the top-left bilinear tap in the padded centre view (:func:`pack_lanes`)
    and the 1/1024-pixel fractions of view row ``y``; pixel x samples at column ``cols[x] +
    dmap[y, x] * dv`` (``cols``: x as float32; a float array, not the loop counter, keeps the
    loop vectorised)."""
    w = dmap.shape[1]
    fy = np.float32(y)
    for x in range(w):
        d = dmap[y, x]
        ix = _floor_int((cols[x] + d * dv) * np.float32(_FRAC) + np.float32(0.5), np.float32(_TAP_OFFSET))
        iy = _floor_int((fy + d * du) * np.float32(_FRAC) + np.float32(0.5), np.float32(_TAP_OFFSET))
        fxs[x] = ix & (_FRAC - 1)
        fys[x] = iy & (_FRAC - 1)
        x0 = min(max(ix >> _FRAC_BITS, -1), w - 1) + 1  # column in the padded view
        y0 = min(max(iy >> _FRAC_BITS, -1), h - 1) + 1
        idx[x] = y0 * (w + 2) + x0


@numba.njit(fastmath=True, cache=True, nogil=True, inline="always")
def _gather_pair(packed, idx, offset, gathered, first, second):  # pragma: no cover - compiled
    """``gathered[first, x] = packed[idx[x]]``, ``gathered[second, x] = packed[idx[x] +
    offset]``: a row's two taps, loads alone (:func:`_row_accs`)."""
    for x in range(idx.shape[0]):
        i = np.uint32(idx[x])
        gathered[first, x] = packed[i]
        gathered[second, x] = packed[i + offset]


@numba.njit(**_ROW_BORROWED)
def _row_accs(packed, stride, idx, fxs, fys, taps, gathered, accs):  # pragma: no cover - compiled
    """Bilinear interpolation of the packed lanes for one view row: ``accs[x]`` (each lane
    then holds ``2**_SCALE_BITS * value``) from the taps at ``idx[x]``, the top-left one in
    the padded centre view (:func:`pack_lanes`), and its right and lower neighbours
    (unsigned indices: no checks), with the fractions ``fxs[x]``, ``fys[x]``. ``taps``
    (:data:`_TAPS_ROW`, :data:`_TAPS_COLUMN`) skips the two taps a zero fraction weights by
    0 (the fraction passed as the constant 0, so the compiler drops those products): the
    same integers, half the loads and multiplies (a row view 39 %, a column view 25 %
    faster, the taps included).

    The taps are gathered into ``gathered`` (4, W) uint64 scratch by a loop of loads alone,
    then blended by a loop over contiguous rows: LLVM does not vectorise gathers for this
    CPU, so with the loads and the arithmetic in one loop both stayed scalar; apart, the
    arithmetic runs eight pixels a vector instruction. Integer arithmetic: the same values in any order.
    """
    w = idx.shape[0]
    f = np.uint64(_FRAC)
    zero = np.uint64(0)
    # the four tap rows indexed in place, not taken as row views (see _ROW_BORROWED)
    g = gathered
    one = np.uint32(1)
    if taps == _TAPS_ROW:
        _gather_pair(packed, idx, one, g, 0, 1)
        for x in range(w):
            accs[x] = f * _lerp_lanes(g[0, x], g[1, x], np.uint64(fxs[x]))
        return
    if taps == _TAPS_COLUMN:
        _gather_pair(packed, idx, stride, g, 0, 2)
        for x in range(w):
            fy = np.uint64(fys[x])
            accs[x] = (f - fy) * _lerp_lanes(g[0, x], g[0, x], zero) + fy * _lerp_lanes(g[2, x], g[2, x], zero)
        return
    for x in range(w):
        i = np.uint32(idx[x])
        g[0, x] = packed[i]
        g[1, x] = packed[i + one]
        g[2, x] = packed[i + stride]
        g[3, x] = packed[i + stride + one]
    for x in range(w):
        fx = np.uint64(fxs[x])
        fy = np.uint64(fys[x])
        accs[x] = (f - fy) * _lerp_lanes(g[0, x], g[1, x], fx) + fy * _lerp_lanes(g[2, x], g[3, x], fx)


@numba.njit(**_ROW_BORROWED)
def _row_sample3(packed, stride, idx, fxs, fys, taps, gathered, accs, dst, y):  # pragma: no cover - compiled
    """Bilinear samples of one view row of three channels, rounded to uint8 into row ``y``
    of ``dst`` (H, W * 3); ``gathered`` (4, W) and ``accs`` (W,) uint64 scratch
    (:func:`_row_accs`), whose lanes a second loop unpacks."""
    _row_accs(packed, stride, idx, fxs, fys, taps, gathered, accs)
    m = np.uint64(255)
    half = np.uint64(_HALF_LANES)
    for x in range(accs.shape[0]):
        acc = (accs[x] + half) >> np.uint64(_SCALE_BITS)
        k = np.uint32(3 * x)  # unsigned: no negative-index check in the loop
        dst[y, k] = np.uint8(acc & m)
        dst[y, k + np.uint32(1)] = np.uint8((acc >> np.uint64(_LANE)) & m)
        dst[y, k + np.uint32(2)] = np.uint8((acc >> np.uint64(2 * _LANE)) & m)


@numba.njit(**_ROW_BORROWED)
def _row_sample(packed, stride, idx, fxs, fys, taps, c, ch0, n_ch, gathered, accs, dst, y):  # pragma: no cover - compiled
    """Bilinear samples of one view row (any channel layout), rounded to uint8 into row ``y``
    of ``dst``; ``gathered`` and ``accs`` scratch (:func:`_row_accs`)."""
    _row_accs(packed, stride, idx, fxs, fys, taps, gathered, accs)
    m = np.uint64(255)
    half = np.uint64(_HALF_LANES)
    for x in range(accs.shape[0]):
        acc = (accs[x] + half) >> np.uint64(_SCALE_BITS)
        for j in range(n_ch):
            dst[y, x * c + ch0 + j] = np.uint8((acc >> np.uint64(_LANE * j)) & m)


@numba.njit(**_ROW_BORROWED)
def _row_gain_apply(vals, gcols, top, bottom, wa, dst, y):  # pragma: no cover - compiled
    """dst[y, j] = vals[j] * (wa * gcols[top, j] + (1 - wa) * gcols[bottom, j]), rounded and
    saturated to uint8: contiguous, so LLVM vectorises it (the same arithmetic inside the
    sampling loop, whose gathers keep it scalar, cost a third of the warp)."""
    wb = np.float32(1.0) - wa
    half = np.float32(0.5)
    for j in range(vals.shape[0]):
        dst[y, j] = min(np.int32(np.float32(vals[j]) * (gcols[top, j] * wa + gcols[bottom, j] * wb) + half), 255)


@numba.njit(**_ROW_BORROWED)
def _row_sample_gain(packed, stride, idx, fxs, fys, taps, c, ch0, n_ch, gcols, top, bottom, wa, gathered, accs,
                     vals, dst, y):  # pragma: no cover
    """Bilinear samples of one view row times the gain ``wa * gcols[top] + (1 - wa) *
    gcols[bottom]`` (gain rows (W * n_ch,) that include the fixed-point scale), rounded and
    saturated to uint8 into row ``y`` of ``dst``; ``gathered``, ``accs``
    (:func:`_row_accs`) and ``vals`` (W * n_ch,) int32 scratch."""
    _row_accs(packed, stride, idx, fxs, fys, taps, gathered, accs)
    m = np.uint64(_LANE_MASK)
    for x in range(accs.shape[0]):
        acc = accs[x]
        for j in range(n_ch):
            vals[x * n_ch + j] = np.int32((acc >> np.uint64(_LANE * j)) & m)
    _row_gain_store(vals, c, ch0, n_ch, gcols, top, bottom, wa, dst, y)


@numba.njit(**_ROW_BORROWED)
def _row_gain_store(vals, c, ch0, n_ch, gcols, top, bottom, wa, dst, y):  # pragma: no cover - compiled
    """:func:`_row_gain_apply` into channels ch0 .. ch0 + n_ch - 1 of a row of ``c``."""
    if n_ch == c:
        _row_gain_apply(vals, gcols, top, bottom, wa, dst, y)
        return
    wb = np.float32(1.0) - wa
    for x in range(vals.shape[0] // n_ch):
        for j in range(n_ch):
            k = x * n_ch + j
            dst[y, x * c + ch0 + j] = min(np.int32(np.float32(vals[k]) * (gcols[top, k] * wa + gcols[bottom, k] * wb)
                                                   + np.float32(0.5)), 255)


@numba.njit(**_ROW_BORROWED)
def _row_centre(packed, start, c, ch0, n_ch, has_gains, gcols, top, bottom, wa, vals, dst, y):  # pragma: no cover
    """One row of the centre view (displacement 0): every sample position is a pixel's own,
    whatever the disparity, so the bilinear samples are the pixels bit for bit (``2**13 *
    value`` in each lane) and are read straight from the packed row that starts at
    ``start``, with the gains applied as for any view: the same bytes as sampling, in a loop
    that vectorises."""
    w = dst.shape[1] // c
    m = np.uint64(255)
    if has_gains:
        for x in range(w):
            p = packed[start + x]
            for j in range(n_ch):
                vals[x * n_ch + j] = np.int32((p >> np.uint64(_LANE * j)) & m) << _SCALE_BITS
        _row_gain_store(vals, c, ch0, n_ch, gcols, top, bottom, wa, dst, y)
        return
    if n_ch == 3 and c == 3:
        for x in range(w):
            p = packed[start + x]
            k = np.uint32(3 * x)  # unsigned: no negative-index check in the loop
            dst[y, k] = np.uint8(p & m)
            dst[y, k + np.uint32(1)] = np.uint8((p >> np.uint64(_LANE)) & m)
            dst[y, k + np.uint32(2)] = np.uint8((p >> np.uint64(2 * _LANE)) & m)
        return
    for x in range(w):
        p = packed[start + x]
        for j in range(n_ch):
            dst[y, x * c + ch0 + j] = np.uint8((p >> np.uint64(_LANE * j)) & m)


@numba.njit(**_ROW_BORROWED)
def _row_sample3_gain(packed, stride, idx, fxs, fys, taps, gcols, top, bottom, wa, gathered, accs, vals, dst,
                      y):  # pragma: no cover
    """:func:`_row_sample_gain` for three channels: the lanes unpacked into ``vals`` by
    unsigned index, then the gain pass over the contiguous row. Both unrolled samplers earn
    their place in the full kernel: with the general ones alone the warp took 20-35 % longer
    (interleaved runs, 7x7x375x540), though a row-by-row micro-benchmark shows no gap."""
    _row_accs(packed, stride, idx, fxs, fys, taps, gathered, accs)
    m = np.uint64(_LANE_MASK)
    for x in range(accs.shape[0]):
        acc = accs[x]
        k = np.uint32(3 * x)
        vals[k] = np.int32(acc & m)
        vals[k + np.uint32(1)] = np.int32((acc >> np.uint64(_LANE)) & m)
        vals[k + np.uint32(2)] = np.int32((acc >> np.uint64(2 * _LANE)) & m)
    _row_gain_apply(vals, gcols, top, bottom, wa, dst, y)


@numba.njit(**_PARALLEL)
def warp_all_views(packed, channels, ch0, n_ch, disp, view_disp, offsets, splat, reach, gains, g_rows, g_row_w,
                   g_cols, g_col_w, order, starts, out):  # pragma: no cover - compiled
    """Every view of a light field from its centre view and disparity, in one parallel pass.

    View (u, v) pixel (y, x) samples the centre at ``(y + d * du, x + d * dv)``, ``(du, dv) =
    offsets[u, v]`` (:func:`lfstream.lightfield.view_offsets`; bilinear,
    1/1024-pixel fixed point, border replicated), where ``d`` is the centre
    map forward-splatted into the view with a z-test, holes given the background side's
    disparity (in the view rows where ``splat[u, v, y]``; :func:`_fill_holes`), or the centre
    map at the view pixel; the sample is multiplied by the
    view's gain map, bilinearly up-sampled (OpenCV's INTER_LINEAR resize), and rounded.

    Args:
        packed: ((H + 2) * (W + 2),) uint64 centre view with a replicated border, channels
            ch0 .. ch0 + n_ch - 1 in lanes (:func:`pack_lanes`).
        channels: C of the output; ch0, n_ch: the channels this call writes (n_ch <= 3).
        disp: (H, W) float32 centre-view disparity.
        view_disp: (U, V, H, W) float32 per-view disparities (Depth-Net's maps), used in
            place of splatting ``disp``; shape (0, 0, 1, 1): none.
        offsets: (U, V, 2) float32 displacement of each view per unit disparity.
        splat: (U, V, H) bool, the view rows whose disparity is splatted (never the centre
            view's; :func:`lfstream.codec.warp.splat_rows`).
        reach: (U, V) int64, how many rows from its own a centre pixel can land in each view.
        gains: (U, V, gh, gw, Cg) float32 gain maps (Cg = 1 or C), or shape (0, 0, 1, 1, 1): none.
        g_rows, g_row_w: (H, 2) int64 grid rows per image row and the weight of the first.
        g_cols, g_col_w: (W, 2) and (W,) the same per column.
        order: (N,) int64 flat view indices ``u * V + v``, task by task; starts: (tasks + 1,)
            int64, task ``t`` warps ``order[starts[t]:starts[t + 1]]`` (:func:`deal_views`).
        out: (U, V, H, W*C) uint8; channels ch0 .. ch0 + n_ch - 1 are overwritten.
    """
    h, w = disp.shape
    n_v = offsets.shape[1]
    has_gains = gains.shape[0] > 0
    # one task per thread, views dealt by the caller: the scratch maps are allocated once per
    # task (an 800 KB allocation per view was mmap'ed and page-faulted afresh: measured
    # 15 % of a stream's CPU in the kernel zeroing pages)
    for task in numba.prange(starts.shape[0] - 1):
        dview = np.empty((h, w), np.float32)
        cols = np.arange(w).astype(np.float32)
        targets = np.empty(w, np.int32)
        holes = _hole_scratch(w)
        words = holes.view(np.uint64)
        idx = np.empty(w, np.int32)
        fxs = np.empty(w, np.int32)
        fys = np.empty(w, np.int32)
        gh = gains.shape[2] if has_gains else 1
        gcols = np.ones((gh, w * n_ch), np.float32)
        vals = np.empty(w * n_ch, np.int32)
        gathered = np.empty((4, w), np.uint64)
        accs = np.empty(w, np.uint64)
        counts = np.empty(h + 1, np.int32)
        for i in range(starts[task], starts[task + 1]):
            k = order[i]
            _warp_view(packed, channels, ch0, n_ch, disp, view_disp, offsets, k // n_v, k % n_v, splat, reach, gains,
                       g_rows, g_row_w, g_cols, g_col_w, dview, cols, targets, holes, words, counts, idx, fxs, fys,
                       gcols, gathered, accs, vals, out)


@numba.njit(**_ROW)
def _warp_view(packed, channels, ch0, n_ch, disp, view_disp, offsets, u, v, splat, reach, gains, g_rows, g_row_w,
               g_cols, g_col_w, dview, cols, targets, holes, words, counts, idx, fxs, fys, gcols, gathered, accs,
               vals, out):  # pragma: no cover
    """One view of :func:`warp_all_views`, in the caller's scratch buffers. The view's rows
    are passed to the row helpers as (array, row index), never as row views: each view
    counts the array's memory record up and down with atomic instructions, 10-16 % of a
    decode's CPU when every row made several (:func:`_row_accs`)."""
    h, w = disp.shape
    has_gains = gains.shape[0] > 0
    per_view = view_disp.shape[0] > 0
    cg = gains.shape[4]
    du = offsets[u, v, 0]
    dv = offsets[u, v, 1]
    stride = np.uint32(w + 2)  # a row of the padded centre view
    # a view on the centre's row samples at y exactly (y + d * 0: the vertical fraction is 0
    # for every pixel, whatever d), one on its column at x exactly: two taps suffice
    taps = _TAPS_ROW if du == 0 else (_TAPS_COLUMN if dv == 0 else _TAPS_ALL)
    rows = splat[u, v]
    splatted = not (du == 0 and dv == 0) and not per_view and rows.any()
    if splatted:
        _splat_view(disp, cols, du, dv, dview, targets, rows, reach[u, v], counts)
    # the gain map up-sampled along x once per view (gh rows); each image row then
    # blends two of them
    gh = gcols.shape[0]
    if has_gains:
        scale = np.float32(1.0 / (1 << _SCALE_BITS))
        for r in range(gh):
            for x in range(w):
                ca, cb, wx = g_cols[x, 0], g_cols[x, 1], g_col_w[x]
                for j in range(n_ch):
                    cc = ch0 + j if cg > 1 else 0
                    gcols[r, x * n_ch + j] = (gains[u, v, r, ca, cc] * wx + gains[u, v, r, cb, cc] * (1 - wx)) * scale
    dst = out[u, v]
    if du == 0 and dv == 0:
        for y in range(h):
            _row_centre(packed, (y + 1) * (w + 2) + 1, channels, ch0, n_ch, has_gains, gcols, g_rows[y, 0],
                        g_rows[y, 1], g_row_w[y], vals, dst, y)
        return
    own = view_disp[u, v] if per_view else disp
    for y in range(h):
        if per_view:
            _row_taps(own, cols, y, du, dv, h, idx, fxs, fys)
        elif splatted and rows[y]:
            _fill_holes(disp, dview, y, holes, words)  # the splat's scratch row, in place
            _row_taps(dview, cols, y, du, dv, h, idx, fxs, fys)
        else:
            _row_taps(disp, cols, y, du, dv, h, idx, fxs, fys)
        if has_gains and channels == 3:
            _row_sample3_gain(packed, stride, idx, fxs, fys, taps, gcols, g_rows[y, 0], g_rows[y, 1], g_row_w[y],
                              gathered, accs, vals, dst, y)
        elif has_gains:
            _row_sample_gain(packed, stride, idx, fxs, fys, taps, channels, ch0, n_ch, gcols, g_rows[y, 0],
                             g_rows[y, 1], g_row_w[y], gathered, accs, vals, dst, y)
        elif channels == 3:
            _row_sample3(packed, stride, idx, fxs, fys, taps, gathered, accs, dst, y)
        else:
            _row_sample(packed, stride, idx, fxs, fys, taps, channels, ch0, n_ch, gathered, accs, dst, y)


@numba.njit(**_EXACT_BORROWED)
def _add_view_correction(dst, c0, cy, cx, oy, ox):  # pragma: no cover - compiled
    """``dst += (c0 + oy * cy) + ox * cx`` along one row, in float32 and in numpy's order
    (no fused multiply-add: exact, whatever the caller's fastmath)."""
    for x in range(dst.shape[0]):
        dst[x] = dst[x] + ((c0[x] + oy * cy[x]) + ox * cx[x])


@numba.njit(parallel=True, cache=True, nogil=True)  # no fastmath: the corrections' sums as numpy's
def splat_all_views(disp, offsets, splat, reach, corr, out):  # pragma: no cover - compiled
    """The per-view disparities :func:`warp_all_views` samples with: ``disp`` forward-splatted
    into each view and its holes filled (in the rows where ``splat[u, v, y]``), or ``disp``
    itself; warping with these as ``view_disp`` gives the same views, bit for bit. With
    ``corr`` (Depth-Net's refiner), each view's row then gets its correction
    (:func:`lfstream.models.depth_net.view_correction`) while it is in cache.

    Args:
        disp: (H, W) float32 centre-view disparity.
        offsets: (U, V, 2) float32 displacement of each view per unit disparity.
        splat: (U, V, H) bool, the view rows to splat; reach: (U, V) int64 (:func:`warp_all_views`).
        corr: (3, H, W) float32 correction maps ``c0, cy, cx``, or (0, H, W): none.
        out: (U, V, H, W) float32, overwritten.
    """
    h, w = disp.shape
    n_v = offsets.shape[1]
    n_views = offsets.shape[0] * n_v
    for k in numba.prange(n_views):
        u, v = k // n_v, k % n_v
        du = offsets[u, v, 0]
        dv = offsets[u, v, 1]
        dview = out[u, v]
        rows = splat[u, v]
        correct = corr.shape[0] == 3
        if du == 0 and dv == 0 or not rows.any():
            for y in range(h):
                dview[y] = disp[y]
                if correct:
                    _add_view_correction(dview[y], corr[0, y], corr[1, y], corr[2, y], du, dv)
            continue
        cols = np.arange(w).astype(np.float32)
        targets = np.empty(w, np.int32)
        holes = _hole_scratch(w)
        words = holes.view(np.uint64)
        counts = np.empty(h + 1, np.int32)
        _splat_view(disp, cols, du, dv, dview, targets, rows, reach[u, v], counts)
        for y in range(h):
            if rows[y]:
                _fill_holes(disp, dview, y, holes, words)
            else:
                dview[y] = disp[y]
            if correct:
                _add_view_correction(dview[y], corr[0, y], corr[1, y], corr[2, y], du, dv)


@numba.njit(**_EXACT_BORROWED)
def _gain_map_row(gain, r, cols, col_w, n_ch, dst):  # pragma: no cover - compiled
    """Row ``r`` of one view's gain map ``(gh, gw, Cg)`` resized along x, as OpenCV's
    INTER_LINEAR horizontal pass computes it (``S[sx] * a0 + S[sx + 1] * a1`` in float32), for
    ``n_ch`` channels interleaved (a single-channel map repeated)."""
    cg = gain.shape[2]
    for x in range(cols.shape[0]):
        a, b = cols[x, 0], cols[x, 1]
        w0, w1 = col_w[x, 0], col_w[x, 1]
        for j in range(n_ch):
            cc = j if cg > 1 else 0
            dst[x * n_ch + j] = gain[r, a, cc] * w0 + gain[r, b, cc] * w1


@numba.njit(**_EXACT_BORROWED)
def _gain_apply_row(src_row, top, bottom, b0, b1, dst_row):  # pragma: no cover - compiled
    """``dst = saturate(rint(src * (top * b0 + bottom * b1)))``: OpenCV's vertical resize
    pass and its ``multiply`` of uint8 by float32 into uint8 (float32 product, round half to
    even); contiguous rows, so the loop vectorises."""
    lo, hi = np.float32(0.0), np.float32(255.0)
    for j in range(src_row.shape[0]):
        g = top[j] * b0 + bottom[j] * b1
        dst_row[j] = np.uint8(min(max(np.rint(np.float32(src_row[j]) * g), lo), hi))


@numba.njit(parallel=True, cache=True, nogil=True)
def apply_view_gains(views, which, gains, active, rows, row_w, cols, col_w, out):  # pragma: no cover - compiled
    """Each view times its gain map bilinearly up-sampled, rounded to uint8, with OpenCV's
    arithmetic for ``cv2.multiply(view, cv2.resize(gain, (W, H), INTER_LINEAR), dtype=CV_8U)``
    view by view (:func:`lfstream.codec.shading.apply_gains`), in one parallel pass that
    writes each output byte once.

    Args:
        views: (N, H, W * C) uint8, the distinct input views; view ``k`` of the output reads
            ``views[which[k]]`` (the flat decode: one view for all).
        which: (U * V,) int64.
        gains: (U, V, gh, gw, Cg) float32, Cg = 1 or C.
        active: (U * V,) bool, False where a view's map is 1 everywhere: it is copied.
        rows, row_w: (H, 2) int64 grid rows per image row and (H, 2) float32 their weights
            (OpenCV's, :func:`lfstream.codec.shading.resize_taps`); cols, col_w: the same per column.
        out: (U, V, H, W * C) uint8, overwritten.
    """
    n_u, n_v = gains.shape[0], gains.shape[1]
    h = out.shape[2]
    gh = gains.shape[2]
    n_ch = out.shape[3] // cols.shape[0]
    for k in numba.prange(n_u * n_v):
        u, v = k // n_v, k % n_v
        src = views[which[k]]
        dst = out[u, v]
        if not active[k]:
            for y in range(h):
                dst[y, :] = src[y]
            continue
        gcols = np.empty((gh, out.shape[3]), np.float32)
        for r in range(gh):
            _gain_map_row(gains[u, v], r, cols, col_w, n_ch, gcols[r])
        for y in range(h):
            _gain_apply_row(src[y], gcols[rows[y, 0]], gcols[rows[y, 1]], row_w[y, 0], row_w[y, 1], dst[y])


@numba.njit(**_PARALLEL)
def strength_error_terms(plain, restored, ref, present, cross, square):  # pragma: no cover - compiled
    """Per pixel, over the views ``present`` marks and the channels, the two terms of the
    squared error of ``plain + s * (restored - plain)`` against ``ref`` that depend on the
    strength ``s``: ``cross`` the sum of ``(plain - ref) * (restored - plain)`` and
    ``square`` the sum of ``(restored - plain) ** 2`` (integers: exact, in any order; rows in
    parallel).

    Args:
        plain, restored, ref: (U, V, H, W, C) uint8; present: (U, V) bool.
        cross, square: (H, W) int64, overwritten.
    """
    n_u, n_v, h, w, c = plain.shape
    for y in numba.prange(h):
        cr, sq = cross[y], square[y]
        for x in range(w):
            cr[x] = 0
            sq[x] = 0
        # a view's terms along the row: at most 255 * 255 each, so int32
        acc_c = np.empty(w * c, np.int32)
        acc_s = np.empty(w * c, np.int32)
        for a in range(n_u):
            for b in range(n_v):
                if not present[a, b]:
                    continue
                p = plain[a, b, y].ravel()
                r = restored[a, b, y].ravel()
                q = ref[a, b, y].ravel()
                for k in range(w * c):
                    e = np.int32(p[k]) - np.int32(q[k])
                    d = np.int32(r[k]) - np.int32(p[k])
                    acc_c[k] = e * d
                    acc_s[k] = d * d
                for x in range(w):
                    sc = np.int64(0)
                    ss = np.int64(0)
                    for j in range(c):
                        sc += acc_c[x * c + j]
                        ss += acc_s[x * c + j]
                    cr[x] += sc
                    sq[x] += ss


@numba.njit(**_PARALLEL)
def row_fold_bounds(disp, rx, ry):  # pragma: no cover - compiled
    """:func:`fold_bounds` per row: ``rx[y]`` the largest ``|d(y, x+1) - d(y, x)| *
    max(|d(y, x)|, |d(y, x+1)|)`` of row ``y``, ``ry[y]`` the same between rows ``y`` and
    ``y + 1`` (0 for the last row); the same float32 products.

    Args:
        disp: (H, W) float32; rx, ry: (H,) float32, overwritten.
    """
    h, w = disp.shape
    for y in numba.prange(h):  # rows are independent: the same values at any thread count
        row = disp[y]
        mx = np.float32(0.0)
        for x in range(w - 1):
            a, b = row[x], row[x + 1]
            mx = max(mx, abs(b - a) * max(abs(a), abs(b)))
        rx[y] = mx
        my = np.float32(0.0)
        if y + 1 < h:
            nxt = disp[y + 1]
            for x in range(w):
                a, b = row[x], nxt[x]
                my = max(my, abs(b - a) * max(abs(a), abs(b)))
        ry[y] = my


@numba.njit(**_ROW)
def fold_bounds(disp):  # pragma: no cover - compiled
    """``(max |d(y, x+1) - d(y, x)| * max(|d(y, x)|, |d(y, x+1)|), the same along y)``: how
    far the disparity changes between neighbours, weighted by how far it moves them
    (:func:`lfstream.codec.warp.splat_views`). One pass; float32 products, each rounded once,
    as the batched torch path computes them.

    Args:
        disp: (H, W) float32.
    """
    h = disp.shape[0]
    rx = np.empty(h, np.float32)
    ry = np.empty(h, np.float32)
    row_fold_bounds(disp, rx, ry)
    return rx.max(), ry.max()  # maxima of the rows' maxima: the same float32 values


@numba.njit(**_ROW_BORROWED)
def _block_mean_row(grey, i, scale, acc, out_row):  # pragma: no cover - compiled
    """Block row ``i`` of :func:`block_means` for one image; ``acc`` (W,) int32 scratch.
    The block's rows are added column by column first (contiguous: the loop vectorises),
    then each block's columns once per block row."""
    h, w = grey.shape
    ws = out_row.shape[0]
    y1 = min((i + 1) * scale, h)
    if scale == 2 and y1 - 2 * i == 2 and ws == w // 2:
        # the encoder's working scale: two rows summed in one pass and pairs of columns
        # (a constant stride the loop vectorises), the same sums and roundings as below
        r0, r1 = grey[2 * i], grey[2 * i + 1]
        for x in range(w):
            acc[x] = np.int32(r0[x]) + np.int32(r1[x])
        for j in range(ws):
            out_row[j] = (np.float32(acc[2 * j] + acc[2 * j + 1]) * np.float32(0.25)) * np.float32(1.0 / 255.0)
        return
    acc[:] = 0
    for y in range(i * scale, y1):
        row = grey[y]
        for x in range(w):
            acc[x] += np.int32(row[x])
    rows = y1 - i * scale
    inv_full = np.float32(1.0 / (rows * scale))  # hoisted: a division per block cost more than the sums
    full = min(ws, w // scale)  # blocks that lie wholly inside the image's width
    for j in range(full):
        total = np.int32(0)
        for k in range(scale):
            total += acc[j * scale + k]
        out_row[j] = (np.float32(total) * inv_full) * np.float32(1.0 / 255.0)
    for j in range(full, ws):
        x0, x1 = j * scale, min((j + 1) * scale, w)
        total = np.int32(0)
        for x in range(x0, x1):
            total += acc[x]
        out_row[j] = (np.float32(total) * np.float32(1.0 / (rows * (x1 - x0)))) * np.float32(1.0 / 255.0)


@numba.njit(**_PARALLEL)
def block_means(grey, scale, out):  # pragma: no cover - compiled
    """Block means of 8-bit images, divided by 255: OpenCV's area resampling of them to the
    bit (integer sums, one rounding); a block an image ends inside (an image smaller than
    one block) averages the pixels it has, as area resampling does. One block row per task.

    Args:
        grey: (N, H, W) uint8; scale: block size in pixels.
        out: (N, max(1, H // scale), max(1, W // scale)) float32 in [0, 1], overwritten.
    """
    n_img, hs, ws = out.shape
    for job in numba.prange(n_img * hs):
        n, i = job // hs, job % hs
        _block_mean_row(grey[n], i, scale, np.empty(grey.shape[2], np.int32), out[n, i])


# The sweep's column loops are inlined into the row (numba IR inlining): three calls per view
# and row of every candidate plane cost 15 % of the sweep (lytro_bikes' 28 planes: 2.6 -> 2.2 ms,
# the same costs to the bit); the warp's per-row helpers, measured the same way, gained nothing.
@numba.njit(fastmath=True, cache=True, nogil=True, inline="always")
def _sweep_edge(r0, r1, centre, ax, ay, ox, lo, hi, acc):  # pragma: no cover - compiled
    """Columns ``lo..hi`` of one view's sweep cost where a tap leaves the row (replicated)."""
    w = r0.shape[0]
    for x in range(lo, hi):
        x0 = min(max(x + ox, 0), w - 1)
        x1 = min(max(x + ox + 1, 0), w - 1)
        top = r0[x0] + ax * (r0[x1] - r0[x0])
        bot = r1[x0] + ax * (r1[x1] - r1[x0])
        acc[x] += abs(top + ay * (bot - top) - centre[x])


@numba.njit(fastmath=True, cache=True, nogil=True, inline="always")
def _sweep_span(r0, r1, centre, ax, ay, ox, lo, hi, acc):  # pragma: no cover - compiled
    """Columns ``lo..hi`` where both taps lie inside the row: contiguous slices, no
    clamping, so the loop vectorises (about 4x faster than the clamped loop; the same
    arithmetic, so the same cost to the bit)."""
    a0 = r0[lo + ox: hi + ox]
    a1 = r0[lo + ox + 1: hi + ox + 1]
    b0 = r1[lo + ox: hi + ox]
    b1 = r1[lo + ox + 1: hi + ox + 1]
    c = centre[lo:hi]
    out = acc[lo:hi]
    for i in range(hi - lo):
        top = a0[i] + ax * (a1[i] - a0[i])
        bot = b0[i] + ax * (b1[i] - b0[i])
        out[i] += abs(top + ay * (bot - top) - c[i])


# The spans of views on the centre's row or column (8 of the 12 sweep views of a 7x7 grid):
# one interpolation instead of three, half the loads (the fine sweep 12 % faster). Their
# costs equal _sweep_span's to the bit: fast-math without reassociation (and not inlined
# into the caller, whose flags would apply), written in the order the compiler evaluates
# _sweep_span with a zero weight; any other order moved hint maps by 2e-7 and changed the
# stream bytes of three of the seven shared scenes. tests/codec/test_hint.py compares.
_NO_REASSOC = dict(fastmath={"nnan", "ninf", "nsz", "arcp", "contract", "afn"}, cache=True, nogil=True)
_NO_REASSOC_BORROWED = dict(_NO_REASSOC, **_BORROW)  # (see _ROW_BORROWED)


@numba.njit(**_NO_REASSOC_BORROWED)
def _sweep_span_row(r0, centre, ax, ox, lo, hi, acc):  # pragma: no cover - compiled
    """:func:`_sweep_span` where the vertical weight is 0 (one row's two taps)."""
    a0 = r0[lo + ox: hi + ox]
    a1 = r0[lo + ox + 1: hi + ox + 1]
    c = centre[lo:hi]
    out = acc[lo:hi]
    for i in range(hi - lo):
        out[i] += abs(a0[i] + ax * (a1[i] - a0[i]) - c[i])


@numba.njit(**_NO_REASSOC_BORROWED)
def _sweep_span_col(r0, r1, centre, ay, ox, lo, hi, acc):  # pragma: no cover - compiled
    """:func:`_sweep_span` where the horizontal weight is 0 (one column's two taps)."""
    a0 = r0[lo + ox: hi + ox]
    b0 = r1[lo + ox: hi + ox]
    c = centre[lo:hi]
    out = acc[lo:hi]
    for i in range(hi - lo):
        out[i] += abs((a0[i] - c[i]) + ay * (b0[i] - a0[i]))


@numba.njit(**_ROW_BORROWED)
def _sweep_row(images, offsets, s, y, acc):  # pragma: no cover - compiled
    n_j = offsets.shape[0]
    h, w = images.shape[1], images.shape[2]
    for x in range(w):
        acc[x] = 0.0
    centre = images[0, y]
    for j in range(n_j):
        sy = np.float32(y) - s * offsets[j, 0]
        dx = -s * offsets[j, 1]
        fy = np.floor(sy)
        ay = np.float32(sy - fy)
        y0 = min(max(int(fy), 0), h - 1)
        y1 = min(max(int(fy) + 1, 0), h - 1)
        r0 = images[1 + j, y0]
        r1 = images[1 + j, y1]
        fxo = np.floor(dx)
        ax = np.float32(dx - fxo)
        ox = int(fxo)
        lo = min(max(-ox, 0), w)  # the first column whose left tap is inside the row
        hi = max(min(w - 1 - ox, w), lo)  # the first column whose right tap is not
        _sweep_edge(r0, r1, centre, ax, ay, ox, 0, lo, acc)
        if ay == 0.0:
            # a view on the centre's row (8 of the 12 sweep views of a 7x7 grid are on its
            # row or column): no vertical interpolation; top + 0 * (bot - top) is top
            # exactly, so the same cost to the bit at half the loads
            _sweep_span_row(r0, centre, ax, ox, lo, hi, acc)
        elif ax == 0.0:  # on the centre's column: no horizontal interpolation (same argument)
            _sweep_span_col(r0, r1, centre, ay, ox, lo, hi, acc)
        else:
            _sweep_span(r0, r1, centre, ax, ay, ox, lo, hi, acc)
        _sweep_edge(r0, r1, centre, ax, ay, ox, hi, w, acc)
    inv = np.float32(1.0 / n_j)
    for x in range(w):
        acc[x] *= inv


@numba.njit(**_PARALLEL)
def sweep_cost(images, offsets, shifts, cost):  # pragma: no cover - compiled
    """Plane-sweep matching cost of a centre image against shifted views, fused over views.

    ``cost[k, y, x] = mean_j |I_j(y - s_k * du_j, x - s_k * dv_j) - I_0(y, x)|``: view j sampled
    (bilinear, border replicated) where a point of the centre image at (y, x) with the k-th
    candidate shift appears (lfstream's disparity sign).

    Args:
        images: (1 + J, h, w) float32; images[0] is the centre.
        offsets: (J, 2) float32 view offsets (u - u0, v - v0).
        shifts: (D,) float32 candidate disparities in pixels of ``images`` per view step.
        cost: (D, h, w) float32, overwritten.
    """
    n_d = shifts.shape[0]
    h = images.shape[1]
    # row-major jobs: a thread's consecutive jobs are every candidate of one row, which read
    # the same few rows of each view from its cache (candidate-major, each candidate streamed
    # all views again: 11-14 % slower, the same costs)
    for job in numba.prange(n_d * h):
        y = job // n_d
        k = job % n_d
        _sweep_row(images, offsets, shifts[k], y, cost[k, y])


@numba.njit(**_ROW_BORROWED)
def _winner_row(cost, shifts, y, best, c_best, out_row):  # pragma: no cover - compiled
    """One row of :func:`winner_subpixel`; ``best`` (w,) int32 and ``c_best`` (w,) float32
    scratch. The candidates are the outer loop, so each pass reads one contiguous cost
    row and vectorises (the first minimum wins, as in a per-pixel scan)."""
    n_d, _, w = cost.shape
    step = shifts[1] - shifts[0]
    row0 = cost[0, y]
    for x in range(w):
        best[x] = 0
        c_best[x] = row0[x]
    for k in range(1, n_d):
        row = cost[k, y]
        kk = np.int32(k)
        for x in range(w):
            c = row[x]
            better = c < c_best[x]
            c_best[x] = c if better else c_best[x]
            best[x] = kk if better else best[x]
    for x in range(w):
        b = best[x]
        off = np.float32(0.0)
        if 0 < b < n_d - 1:
            cm = cost[b - 1, y, x]
            cp = cost[b + 1, y, x]
            denom = cm - 2 * c_best[x] + cp
            if denom > 1e-9:
                off = min(max(np.float32(0.5) * (cm - cp) / denom, np.float32(-0.5)), np.float32(0.5))
        out_row[x] = shifts[b] + off * step


@numba.njit(**_PARALLEL)
def winner_subpixel(cost, shifts, out):  # pragma: no cover - compiled
    """Per pixel the cheapest candidate, refined by a parabola through its neighbours.

    Args:
        cost: (D, h, w) float32 aggregated cost, D >= 3.
        shifts: (D,) float32 evenly spaced candidates.
        out: (h, w) float32, overwritten with the refined candidate value.
    """
    w = cost.shape[2]
    for y in numba.prange(cost.shape[1]):
        _winner_row(cost, shifts, y, np.empty(w, np.int32), np.empty(w, np.float32), out[y])


@numba.njit(**_ROW)
def _jbu_taps(n_out, n_small, scale):  # pragma: no cover - compiled
    """Per output sample of one axis: the first of its four map samples (``k - 1``, may be
    -1) and their tent weights (radius 2 map pixels; 0 for samples outside the map).
    Computed once per axis instead of per tap: the same float64 expressions as the per-tap
    form, so the weights (and the output) are identical to the bit."""
    first = np.empty(n_out, np.int64)
    weights = np.zeros((n_out, 4), np.float32)
    for i in range(n_out):
        p = min(max((i + 0.5) / scale - 0.5, 0.0), n_small - 1.0)
        k = int(np.floor(p))
        first[i] = k - 1
        for t in range(4):
            j = k - 1 + t
            if 0 <= j < n_small:
                weights[i, t] = np.float32(max(0.0, 1.0 - abs(p - j) * 0.5))
    return first, weights


@numba.njit(**_ROW_BORROWED)
def _jbu_row(small, gsmall, guide_row, lut, y0, wy, x0, wx, out_row):  # pragma: no cover - compiled
    hs, ws = small.shape
    for x in range(out_row.shape[0]):
        g = np.int32(guide_row[x])  # signed: uint8 differences must not wrap
        acc = np.float32(0.0)
        wsum = np.float32(0.0)
        sacc = np.float32(0.0)
        ssum = np.float32(0.0)
        kx = x0[x]
        for ty in range(4):
            iy = y0 + ty
            if iy < 0 or iy >= hs:
                continue
            for tx in range(4):
                ix = kx + tx
                if ix < 0 or ix >= ws:
                    continue
                sw = wy[ty] * wx[x, tx]
                val = small[iy, ix]
                diff = g - np.int32(gsmall[iy, ix])
                wt = sw * lut[diff if diff >= 0 else -diff]
                acc += wt * val
                wsum += wt
                sacc += sw * val
                ssum += sw
        out_row[x] = acc / wsum if wsum > 1e-4 else sacc / ssum


@numba.njit(**_PARALLEL)
def joint_upsample(small, gsmall, guide, scale, lut, out):  # pragma: no cover - compiled
    """Joint bilateral upsampling of a low-resolution map guided by a full-resolution image.

    Each output pixel averages the 4 x 4 nearest map samples, weighted by a tent of radius 2
    map pixels around its position and by ``lut[|guide - gsmall|]``, the similarity of its
    grey level to the grey level of the block each sample came from: depth edges snap to
    picture edges. Where every weight vanishes it falls back to the spatial weights. The
    tent weights are computed once per row and per column (:func:`_jbu_taps`).

    Args:
        small: (hs, ws) float32 map; gsmall: (hs, ws) uint8 block means of the guide.
        guide: (H, W) uint8; scale: float32 map pixel size in output pixels.
        lut: (256,) float32 range weights; out: (H, W) float32, overwritten.
    """
    hs, ws = small.shape
    y0, wy = _jbu_taps(out.shape[0], hs, scale)
    x0, wx = _jbu_taps(out.shape[1], ws, scale)
    for y in numba.prange(out.shape[0]):
        _jbu_row(small, gsmall, guide[y], lut, y0[y], wy[y], x0, wx, out[y])


# YCbCr -> RGB (BT.601 full range, the inverse of lfstream.codec.intra.rgb_to_i420) in
# 14-bit fixed point, as OpenCV's 8-bit conversion does
_YCC_BITS = 14
_CR_R = int(round(1.403 * (1 << _YCC_BITS)))
_CR_G = int(round(0.714 * (1 << _YCC_BITS)))
_CB_G = int(round(0.344 * (1 << _YCC_BITS)))
_CB_B = int(round(1.773 * (1 << _YCC_BITS)))


@numba.njit(**_ROW_BORROWED)
def _i420_residual_row(dst_row, flat, y, height, width, offset, store, vcb, vcr, hcb, hcr):  # pragma: no cover
    """One row of ``dst = rgb(planes)`` (``store``) or ``dst += rgb(planes) - offset``,
    saturated to 8 bits. Chroma is up-sampled bilinearly with the centre-aligned phase of
    2x2 means (OpenCV's INTER_LINEAR resize): at 2x the taps are always 3/4 and 1/4, so the
    whole interpolation is integer: (9a + 3b + 3c + d + 8) / 16. The row's chroma is
    up-sampled first, in loops over contiguous arrays that LLVM vectorises; then one loop
    converts each pixel and stores (or adds) it in place, clipping with min/max.

    Args:
        dst_row: ``(W * 3,)`` uint8 output row. flat: PyAV's (3H/2, W) yuv420p layout
            flattened (H*W luma, then Cb, then Cr). vcb, vcr: ``(W / 2,)`` int32 scratch;
            hcb, hcr: ``(W,)`` int32 scratch.
    """
    ch, cw = height // 2, width // 2
    cb0 = height * width
    cr0 = cb0 + ch * cw
    m = y >> 1
    if y & 1:  # output row 2m+1 sits between chroma rows m (3/4) and m+1 (1/4)
        near, far = m, min(m + 1, ch - 1)
    else:  # output row 2m: chroma rows m (3/4) and m-1 (1/4)
        near, far = m, max(m - 1, 0)
    near *= cw
    far *= cw
    # the rows as slices, indexed by the loop counter: an index the compiler cannot prove
    # non-negative (flat[cb0 + near + n]) keeps numba's wrap-around test in the loop, which
    # stopped it vectorising (the whole row 2.2x slower, the same values)
    cb_near, cb_far = flat[cb0 + near:cb0 + near + cw], flat[cb0 + far:cb0 + far + cw]
    cr_near, cr_far = flat[cr0 + near:cr0 + near + cw], flat[cr0 + far:cr0 + far + cw]
    for n in range(cw):  # the vertical blend once per chroma column
        vcb[n] = 3 * np.int32(cb_near[n]) + np.int32(cb_far[n])
        vcr[n] = 3 * np.int32(cr_near[n]) + np.int32(cr_far[n])
    # horizontal: output column 2n takes chroma columns n (3/4) and n-1, 2n+1 takes n and
    # n+1, clamped at the ends
    hcb[0] = ((4 * vcb[0] + 8) >> 4) - 128
    hcr[0] = ((4 * vcr[0] + 8) >> 4) - 128
    for n in range(cw - 1):
        hcb[2 * n + 1] = ((3 * vcb[n] + vcb[n + 1] + 8) >> 4) - 128
        hcr[2 * n + 1] = ((3 * vcr[n] + vcr[n + 1] + 8) >> 4) - 128
        hcb[2 * n + 2] = ((3 * vcb[n + 1] + vcb[n] + 8) >> 4) - 128
        hcr[2 * n + 2] = ((3 * vcr[n + 1] + vcr[n] + 8) >> 4) - 128
    hcb[2 * cw - 1] = ((4 * vcb[cw - 1] + 8) >> 4) - 128
    hcr[2 * cw - 1] = ((4 * vcr[cw - 1] + 8) >> 4) - 128
    half = np.int32(1 << (_YCC_BITS - 1))
    zero, top = np.int32(0), np.int32(255)
    w = dst_row.shape[0] // 3
    luma_row = flat[y * width:y * width + w]
    one, two = np.uint32(1), np.uint32(2)
    for x in range(w):
        luma = np.int32(luma_row[x])
        r = min(max(luma + ((_CR_R * hcr[x] + half) >> _YCC_BITS), zero), top)
        g = min(max(luma + ((half - _CR_G * hcr[x] - _CB_G * hcb[x]) >> _YCC_BITS), zero), top)
        b = min(max(luma + ((_CB_B * hcb[x] + half) >> _YCC_BITS), zero), top)
        k = np.uint32(3 * x)  # unsigned: no wrap-around test in the loop
        if store:  # the branch is the same for the whole loop: LLVM takes it out
            dst_row[k] = np.uint8(r)
            dst_row[k + one] = np.uint8(g)
            dst_row[k + two] = np.uint8(b)
        else:  # min/max saturation, no branches (random residual signs made branches cost 2x)
            dst_row[k] = np.uint8(min(max(np.int32(dst_row[k]) + r - offset, zero), top))
            dst_row[k + one] = np.uint8(min(max(np.int32(dst_row[k + one]) + g - offset, zero), top))
            dst_row[k + two] = np.uint8(min(max(np.int32(dst_row[k + two]) + b - offset, zero), top))


_I420_ROWS = 16  # rows per parallel job (one set of scratch rows each)


@numba.njit(**_PARALLEL)
def add_i420_residual(lf, planes, positions, offset, store):  # pragma: no cover - compiled
    """Decoded residual frames into their views, in place: view ``positions[n]`` of ``lf``
    gets ``rgb(planes[n]) - offset`` added, saturated to 8 bits, or (``store``) is
    overwritten with ``rgb(planes[n])`` (a residual of the views themselves: no read of
    ``lf``, no zeroing first).

    Shapes: lf (U, V, H, W, 3) uint8, C-contiguous; planes (N, 3 * PH / 2, PW) uint8
    (PyAV's yuv420p layout, PH, PW the even-padded size); positions (N, 2) int64; offset: int.
    """
    h = lf.shape[2]
    w3 = lf.shape[3] * 3
    ph = planes.shape[1] * 2 // 3
    pw = planes.shape[2]
    n = positions.shape[0]
    blocks = (h + _I420_ROWS - 1) // _I420_ROWS
    for job in numba.prange(n * blocks):
        k = job // blocks
        y0 = (job % blocks) * _I420_ROWS
        vcb = np.empty(pw // 2, np.int32)
        vcr = np.empty(pw // 2, np.int32)
        hcb = np.empty(pw, np.int32)
        hcr = np.empty(pw, np.int32)
        flat = planes[k].ravel()
        view = lf[positions[k, 0], positions[k, 1]].reshape(h, w3)
        for y in range(y0, min(y0 + _I420_ROWS, h)):
            _i420_residual_row(view[y], flat, y, ph, pw, np.int32(offset), store, vcb, vcr, hcb, hcr)


@intrinsic
def _prefetch(typingctx, arr, index):  # pragma: no cover - compiled
    """A hint to the CPU to load ``arr.flat[index]``'s cache line (LLVM's ``prefetch``: for
    reading, kept in every cache level); nothing else happens, whatever the index."""
    from llvmlite import ir

    def codegen(context, builder, signature, args):
        ary = context.make_array(signature.args[0])(context, builder, args[0])
        i8p = ir.PointerType(ir.IntType(8))
        i32 = ir.IntType(32)
        # the name mangled for the pointer type by llvmlite (typed or opaque pointers)
        fn = builder.module.declare_intrinsic("llvm.prefetch", [i8p], ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]))
        address = builder.bitcast(builder.gep(ary.data, [args[1]]), i8p)
        builder.call(fn, [address, ir.Constant(i32, 0), ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return numba.types.void(arr, index), codegen


#: Sample rows :func:`gain_samples` asks the CPU to fetch ahead of the row it reads.
_GAIN_PREFETCH_ROWS = 2


@numba.njit(cache=True, nogil=True, inline="always")
def _gain_sample_at(ys, xs, d_samples, i, j, oy, ox, h, w, c):  # pragma: no cover - compiled
    """Where :func:`gain_samples` reads sample ``(i, j)`` of a view displaced by ``(oy, ox)``
    per unit disparity: the flat index of its first channel in the ``(h, w, c)`` view
    (unsigned: numba's wrap-around test on each signed index cost most of the kernel)."""
    zero = np.float32(0.0)
    dd = d_samples[i, j]
    sy = np.uint64(min(max(np.rint(ys[i] - dd * oy), zero), np.float32(h - 1)))
    sx = np.uint64(min(max(np.rint(xs[j] - dd * ox), zero), np.float32(w - 1)))
    return (sy * np.uint64(w) + sx) * np.uint64(c)


# Not fastmath: the sample positions must round exactly as numpy's float32 expression
# ``rint(y - d * off)`` does (no fused multiply-add), so the gains are the same to the bit.
@numba.njit(parallel=True, cache=True, nogil=True)
def gain_samples(lf, ys, xs, d_samples, offsets, scale, out):  # pragma: no cover - compiled
    """The shading gains' samples (:func:`lfstream.codec.shading.measure_gains`): view (a, b)
    read at ``(ys[i], xs[j]) - d_samples[i, j] * offsets[a, b]`` (rounded half to even,
    clamped to the view), times ``scale``; the views' sample grids stacked along the rows.

    Args:
        lf: (U, V, H, W, C) uint8 or float; ys (n_y,), xs (n_x,) float32 sample rows and
            columns; d_samples: (n_y, n_x) float32 disparity there (zeros: no compensation);
            offsets: (U, V, 2) float32 (:func:`lfstream.lightfield.view_offsets`); scale:
            float32 factor.
        out: (U * V * n_y, n_x, C) float32, overwritten; view (a, b) in rows
            ``(a * V + b) * n_y ...``.
    """
    n_u, n_v, h, w, c = lf.shape
    n_y = ys.shape[0]
    n_x = xs.shape[0]
    uc = np.uint64(c)
    for k in numba.prange(n_u * n_v):
        a, b = k // n_v, k % n_v
        oy = offsets[a, b, 0]
        ox = offsets[a, b, 1]
        # flat rows and unsigned indices (_gain_sample_at): numba's wrap-around test on each
        # of the three signed indices of view[sy, sx, ch] cost most of the kernel
        view = lf[a, b].reshape(h * w * c)
        # the samples are a few per cache line of rows far apart, in a frame the encoder has
        # mostly not read yet (36 of 49 views): each row's lines are requested two sample
        # rows ahead, so the misses overlap (the kernel on a cold 7x7x375x540 frame 0.97 ->
        # 0.27-0.35 ms, the same samples)
        for i in range(-_GAIN_PREFETCH_ROWS, n_y):
            ahead = i + _GAIN_PREFETCH_ROWS
            if ahead < n_y:
                for j in range(n_x):
                    _prefetch(view, _gain_sample_at(ys, xs, d_samples, ahead, j, oy, ox, h, w, c))
            if i < 0:
                continue
            out_row = out[k * n_y + i].reshape(n_x * c)
            for j in range(n_x):
                src = _gain_sample_at(ys, xs, d_samples, i, j, oy, ox, h, w, c)
                dst = np.uint64(j) * uc
                for ch in range(c):
                    out_row[dst + np.uint64(ch)] = np.float32(view[src + np.uint64(ch)]) * scale


# The view axes' fit (lfstream.codec.hint._fit_axes) on a few thousand flow samples. Its
# numpy version made about sixty calls on small arrays, on the lane whose end the hint waits
# for; these kernels give the same axes to the bit (tests/codec/test_hint.py). Samples are rows
# of ``flows``: ``(dy_0, dx_0, dy_1, dx_1, ...)``, one pair per view. fastmath lets the
# per-sample sums vectorise (2 ns an element without it); they round like numpy's to well
# under the float32 the axes are returned in.
_FIT = dict(fastmath=True, cache=True, nogil=True)


@numba.njit(**_FIT)
def axes_moments(flows, weight, n, out):  # pragma: no cover - compiled
    """``out`` = the weighted second moments ``sum_c weight[c]^2 flows[c] flows[c]^T`` of the
    first ``n`` samples."""
    m = flows.shape[1]
    cols = np.empty((m, n))  # one contiguous row per flow component: the sums below vectorise
    w2 = np.empty(n)
    for c in range(n):
        w2[c] = weight[c] * weight[c]
        for i in range(m):
            cols[i, c] = flows[c, i]
    for i in range(m):
        for j in range(i + 1):
            s = 0.0
            for c in range(n):
                s += w2[c] * cols[i, c] * cols[j, c]
            out[i, j] = s
            out[j, i] = s


@numba.njit(**_FIT)
def axes_residuals(g, flows, n, out):  # pragma: no cover - compiled
    """``out[c]``: the distance of sample ``c`` (of the first ``n``) from the line along
    ``g``, of any length (a zero ``g`` leaves each sample's own length)."""
    m = flows.shape[1]
    norm = np.sqrt(np.sum(g * g))
    unit = g / (norm if norm > 0.0 else 1.0)
    for c in range(n):
        dot = 0.0
        for i in range(m):
            dot += unit[i] * flows[c, i]
        s = 0.0
        for i in range(m):
            e = flows[c, i] - unit[i] * dot
            s += e * e
        out[c] = np.sqrt(s)


@numba.njit(**_FIT)
def axes_prune(g, flows, weight, n, r, factor, min_kept):  # pragma: no cover - compiled
    """Drops the samples (of the first ``n``) further from the line along ``g`` than
    ``factor`` times their median distance (plus 1e-6), compacting ``flows`` and ``weight``
    in place; returns how many are kept, or 0 (nothing changed) where fewer than
    ``min_kept`` would be."""
    axes_residuals(g, flows, n, r)
    limit = factor * np.median(r[:n]) + 1e-6
    kept = 0
    for c in range(n):
        if r[c] <= limit:
            kept += 1
    if kept < min_kept:
        return 0
    k = 0
    for c in range(n):
        if r[c] <= limit:
            if k != c:
                flows[k, :] = flows[c, :]
                weight[k] = weight[c]
            k += 1
    return k


@numba.njit(**_FIT)
def axes_moved(flows, n, change, out):  # pragma: no cover - compiled
    """``out[c]``: the longest flow of sample ``c`` (of the first ``n``), view ``j``'s
    length weighted by ``change[j]``."""
    for c in range(n):
        best = 0.0
        for j in range(change.shape[0]):
            dy, dx = flows[c, 2 * j], flows[c, 2 * j + 1]
            d = np.sqrt(dy * dy + dx * dx) * change[j]  # np.hypot: 10x the kernel's time
            if d > best or j == 0:
                best = d
        out[c] = best
