"""The depth hint's kernels, compiled by numba: block means of the views, the plane sweep's
cost volume and its sub-pixel winner, the joint bilateral up-sampling of the decoded hint,
and the fit of the rig's view axes (:mod:`lfstream.codec.hint` calls them)."""

from __future__ import annotations

import numba
import numpy as np

from lfstream.codec._numba import _FIT, _NO_REASSOC_BORROWED, _PARALLEL, _ROW, _ROW_BORROWED


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
