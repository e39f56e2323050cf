"""Fused CPU kernels of the decoder's warp, compiled by numba (cached on disk).

The per-view disparity of an occlusion-aware warp needs forward splatting with a z-test
and hole filling: per-pixel control flow that array operations cannot express.
"""

from __future__ import annotations

import numba
import numpy as np

_PARALLEL = dict(parallel=True, fastmath=True, cache=True, nogil=True)
_HOLE = np.float32(-3.0e38)  # marks view pixels no centre pixel lands on
_HOLE_TEST = np.float32(-1.0e38)


@numba.njit(**_PARALLEL)
def view_sample_maps(disp, n_u, n_v, occlusion, maps):  # pragma: no cover - compiled
    """Where each view pixel samples the centre view: maps[u, v, y, x] = (x_src, y_src).

    The view (u, v) pixel (y, x) samples the centre at (y + d*du, x + d*dv) with d its own
    disparity. With ``occlusion``, d is the centre map forward-splatted into the view
    (nearest pixel, z-test: nearer wins); disoccluded pixels (no centre pixel lands there)
    copy the sampling position of the nearest valid pixel on the background side of their
    row (the neighbour with the smaller disparity), which extends the background instead of
    the occluder. Without it, d is the centre map at the view pixel.

    Args:
        disp: (H, W) float32 centre-view disparity.
        maps: (U, V, H, W, 2) float32, overwritten (x first, as cv2.remap wants).
    """
    h, w = disp.shape
    u0, v0 = n_u // 2, n_v // 2
    for k in numba.prange(n_u * n_v):
        u = k // n_v
        v = k % n_v
        du = np.float32(u - u0)
        dv = np.float32(v - v0)
        m = maps[u, v]
        if not occlusion or (u == u0 and v == v0):
            for y in range(h):
                for x in range(w):
                    d = disp[y, x]
                    m[y, x, 0] = x + d * dv
                    m[y, x, 1] = y + d * du
            continue
        # a finite sentinel, not -inf: fastmath lets LLVM assume no infinities
        dview = np.full((h, w), _HOLE, np.float32)
        for y in range(h):
            for x in range(w):
                d = disp[y, x]
                iy = int(np.floor(y - d * du + 0.5))
                ix = int(np.floor(x - d * dv + 0.5))
                if 0 <= iy < h and 0 <= ix < w and d > dview[iy, ix]:
                    dview[iy, ix] = d
        for y in range(h):
            row = dview[y]
            for x in range(w):
                d = row[x]
                if d > _HOLE_TEST:
                    m[y, x, 0] = x + d * dv
                    m[y, x, 1] = y + d * du
            x = 0
            while x < w:
                if row[x] > _HOLE_TEST:
                    x += 1
                    continue
                start = x
                while x < w and row[x] <= _HOLE_TEST:
                    x += 1
                left = start - 1
                right = x
                if left < 0 and right >= w:
                    for xx in range(start, x):  # a whole row unseen: fall back to the centre map
                        d = disp[y, xx]
                        m[y, xx, 0] = xx + d * dv
                        m[y, xx, 1] = y + d * du
                    continue
                if left < 0:
                    src = right
                elif right >= w:
                    src = left
                else:
                    src = left if row[left] <= row[right] else right
                for xx in range(start, x):
                    m[y, xx, 0] = m[y, src, 0]
                    m[y, xx, 1] = m[y, src, 1]


# The parallel kernels below run one row per prange iteration and do the row's work in a
# plain njit function (one place for the row's scalars, the same code at any thread count).
# Indices derived from uint8 data are computed in signed int32: a difference of unsigned
# values wraps and, without bounds checks, reads far outside a lookup table (a bug found
# here: joint_upsample gave different maps from run to run). tests/codec checks the
# kernels against plain-Python references and across thread counts.
_ROW = dict(fastmath=True, cache=True, nogil=True)


@numba.njit(**_ROW)
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
        ay = sy - fy
        y0 = min(max(int(fy), 0), h - 1)
        y1 = min(max(int(fy) + 1, 0), h - 1)
        r0 = images[1 + j, y0]
        r1 = images[1 + j, y1]
        fxo = np.floor(dx)
        ax = dx - fxo
        ox = int(fxo)
        for x in range(w):
            x0 = min(max(x + ox, 0), w - 1)
            x1 = min(max(x + ox + 1, 0), w - 1)
            top = r0[x0] + ax * (r0[x1] - r0[x0])
            bot = r1[x0] + ax * (r1[x1] - r1[x0])
            acc[x] += abs(top + ay * (bot - top) - centre[x])
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
    for job in numba.prange(n_d * h):
        _sweep_row(images, offsets, shifts[job // h], job % h, cost[job // h, job % h])


@numba.njit(**_ROW)
def _winner_row(cost, shifts, y, out_row):  # pragma: no cover - compiled
    n_d, _, w = cost.shape
    step = shifts[1] - shifts[0]
    for x in range(w):
        best = 0
        c_best = cost[0, y, x]
        for k in range(1, n_d):
            c = cost[k, y, x]
            if c < c_best:
                c_best = c
                best = k
        off = np.float32(0.0)
        if 0 < best < n_d - 1:
            cm = cost[best - 1, y, x]
            cp = cost[best + 1, y, x]
            denom = cm - 2 * c_best + cp
            if denom > 1e-9:
                off = min(max(np.float32(0.5) * (cm - cp) / denom, np.float32(-0.5)), np.float32(0.5))
        out_row[x] = shifts[best] + off * step


@numba.njit(**_PARALLEL)
def winner_subpixel(cost, shifts, out):  # pragma: no cover - compiled
    """Per pixel the cheapest candidate, refined by a parabola through its neighbours.

    Args:
        cost: (D, h, w) float32 aggregated cost, D >= 3.
        shifts: (D,) float32 evenly spaced candidates.
        out: (h, w) float32, overwritten with the refined candidate value.
    """
    for y in numba.prange(cost.shape[1]):
        _winner_row(cost, shifts, y, out[y])


@numba.njit(**_ROW)
def _jbu_row(small, gsmall, guide_row, scale, lut, y, out_row):  # pragma: no cover - compiled
    hs, ws = small.shape
    py = min(max((y + 0.5) / scale - 0.5, 0.0), hs - 1.0)
    ky = int(np.floor(py))
    for x in range(out_row.shape[0]):
        px = min(max((x + 0.5) / scale - 0.5, 0.0), ws - 1.0)
        kx = int(np.floor(px))
        g = np.int32(guide_row[x])  # signed: uint8 differences must not wrap
        acc = np.float32(0.0)
        wsum = np.float32(0.0)
        sacc = np.float32(0.0)
        ssum = np.float32(0.0)
        for iy in range(max(ky - 1, 0), min(ky + 3, hs)):
            wy = np.float32(max(0.0, 1.0 - abs(py - iy) * 0.5))
            for ix in range(max(kx - 1, 0), min(kx + 3, ws)):
                sw = wy * np.float32(max(0.0, 1.0 - abs(px - ix) * 0.5))
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
    picture edges. Where every weight vanishes it falls back to the spatial weights.

    Args:
        small: (hs, ws) float32 map; gsmall: (hs, ws) uint8 block means of the guide.
        guide: (H, W) uint8; scale: float32 map pixel size in output pixels.
        lut: (256,) float32 range weights; out: (H, W) float32, overwritten.
    """
    for y in numba.prange(out.shape[0]):
        _jbu_row(small, gsmall, guide[y], scale, lut, y, out[y])
