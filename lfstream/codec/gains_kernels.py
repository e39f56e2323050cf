"""The shading gains' kernels, compiled by numba: the samples the encoder fits the gains to
and the gains applied to views (:mod:`lfstream.codec.gains` calls them)."""

from __future__ import annotations

import numba
import numpy as np
from numba.extending import intrinsic

from lfstream.codec._numba import _EXACT_BORROWED


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
    view by view (:func:`lfstream.codec.gains.apply_gains`), in one parallel pass that
    writes each output byte once.

    Args:
        views: (N, H, W * C) uint8, the distinct input views; view ``k`` of the output reads
            ``views[which[k]]`` (the flat decode: one view for all).
        which: (U * V,) int64.
        gains: (U, V, gh, gw, Cg) float32, Cg = 1 or C.
        active: (U * V,) bool, False where a view's map is 1 everywhere: it is copied.
        rows, row_w: (H, 2) int64 grid rows per image row and (H, 2) float32 their weights
            (OpenCV's, :func:`lfstream.codec.gains.resize_taps`); cols, col_w: the same per column.
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
    """The shading gains' samples (:func:`lfstream.codec.gains.measure_gains`): view (a, b)
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
