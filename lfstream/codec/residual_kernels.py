"""The residual layer's kernel, compiled by numba: decoded 4:2:0 residual planes added to
(or stored in) the predicted views in one pass (:mod:`lfstream.codec.residual` calls it)."""

from __future__ import annotations

import numba
import numpy as np

from lfstream.codec._numba import _PARALLEL, _ROW_BORROWED

# YCbCr -> RGB (BT.601 full range, the inverse of lfstream.codec.centre.av1.rgb_to_i420) in
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
