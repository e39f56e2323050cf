"""JPEG-Hance strength maps' kernel, compiled by numba: the per-tile error terms the encoder
chooses each strength from (:mod:`lfstream.codec.centre.hance` calls it)."""

from __future__ import annotations

import numba
import numpy as np

from lfstream.codec._numba import _PARALLEL


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
