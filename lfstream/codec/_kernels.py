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
