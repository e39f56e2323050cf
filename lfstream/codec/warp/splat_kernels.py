"""The per-view disparity maps outside the warp, compiled by numba: every view's map
forward-splatted with Depth-Net's corrections, and the bounds of where a map folds over
(:mod:`lfstream.codec.warp.cpu` calls them)."""

from __future__ import annotations

import numba
import numpy as np

from lfstream.codec._numba import _EXACT_BORROWED, _PARALLEL, _ROW
from lfstream.codec.warp.kernels import _fill_holes, _hole_scratch, _splat_view


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
    (:func:`lfstream.codec.warp.cpu.splat_views`). One pass; float32 products, each rounded once,
    as the batched torch path computes them.

    Args:
        disp: (H, W) float32.
    """
    h = disp.shape[0]
    rx = np.empty(h, np.float32)
    ry = np.empty(h, np.float32)
    row_fold_bounds(disp, rx, ry)
    return rx.max(), ry.max()  # maxima of the rows' maxima: the same float32 values
