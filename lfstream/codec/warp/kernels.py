"""The decoder's warp, compiled by numba (cached on disk): forward splatting of the centre
view's disparity with a z-test, hole filling, fixed-point bilinear sampling and the shading
gains of a view in one pass, one view per thread, nothing per view materialised beyond the
splatted map (:mod:`lfstream.codec.warp.cpu` calls them). The per-view disparity of an
occlusion-aware warp needs per-pixel control flow that array operations cannot express."""

from __future__ import annotations

import numba
import numpy as np

from lfstream.codec._numba import _PARALLEL, _ROW, _ROW_BORROWED

_HOLE = np.float32(-3.0e38)  # marks view pixels no centre pixel lands on


_HOLE_TEST = np.float32(-1.0e38)


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
    :func:`lfstream.codec.warp.cpu.splat_rows`), so those rows are exactly what splatting every
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
            view's; :func:`lfstream.codec.warp.cpu.splat_rows`).
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
