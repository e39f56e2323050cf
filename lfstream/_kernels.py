"""Fused CPU kernels of :mod:`lfstream.metrics`, compiled by numba (cached on disk).

SSIM needs five Gaussian-filtered moments per channel and a per-pixel formula. OpenCV's
float64 filter plus numpy's element-wise formula made 15 full passes over memory per view
(1.6 s for a 7x7x375x540 light field on the 2-core development machine); this kernel does
the horizontal pass of the five moments of a row into a ring buffer of the last 11 rows,
the vertical pass and the formula from it, in float32 (sums in float64), one view per
thread: 0.2 s, within 2e-6 of the float64 result.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(parallel=True, fastmath=True, cache=True, nogil=True)
def ssim_images(ref, test, channels, g, scale, c1, c2, out):  # pragma: no cover - compiled
    """Mean SSIM over the valid region and channels of image pairs (Wang et al. 2004).

    Args:
        ref, test: (N, H, W*C) uint8 or float32 images, rows flattened channels-last.
        channels: C.
        g: (K,) float32 normalised 1-D Gaussian (K odd, K <= H, W; symmetric: ``g[t] == g[K-1-t]``).
        scale: multiplies the samples into the unit range (1/255 for uint8).
        c1, c2: the stabilising constants (K1**2, K2**2 for a unit range).
        out: (N,) float64, overwritten.
    """
    n, h, wc = ref.shape
    k = g.shape[0]
    r = k // 2
    c = channels
    wv = wc - 2 * r * c  # valid columns times channels
    hv = h - 2 * r
    for i in numba.prange(n):
        # the horizontal pass of the last k rows lives in a ring buffer (5 x k rows, a few
        # hundred KB: cache-resident) instead of a full (5, H, W) image per view
        ring = np.empty((5, k, wv), np.float32)
        rows = np.empty((5, wc), np.float32)
        acc = np.empty((5, wv), np.float32)
        total = 0.0
        for y in range(h):
            ra = ref[i, y]
            rb = test[i, y]
            fa, fb, faa, fbb, fab = rows[0], rows[1], rows[2], rows[3], rows[4]
            for j in range(wc):
                a = np.float32(ra[j]) * scale
                b = np.float32(rb[j]) * scale
                fa[j] = a
                fb[j] = b
                faa[j] = a * a
                fbb[j] = b * b
                fab[j] = a * b
            slot = y % k
            # tap-outer loops over slices indexed from 0: no negative-index checks, so LLVM
            # vectorises them (a computed index j + offset kept them scalar, 8x slower)
            # the Gaussian is symmetric: taps t and k - 1 - t share a weight, so each pass adds
            # a pair of rows
            for m in range(5):
                dst = ring[m, slot]
                src = rows[m, r * c : r * c + wv]
                gr = g[r]
                for j in range(wv):
                    dst[j] = gr * src[j]
                for t in range(r):
                    gt = g[t]
                    s0 = rows[m, t * c : t * c + wv]
                    s1 = rows[m, (k - 1 - t) * c : (k - 1 - t) * c + wv]
                    for j in range(wv):
                        dst[j] += gt * (s0[j] + s1[j])
            if y < k - 1:
                continue
            top = y - (k - 1)  # the output row's window is rows top .. y
            for m in range(5):
                dst = acc[m]
                src = ring[m, (top + r) % k]
                gr = g[r]
                for j in range(wv):
                    dst[j] = gr * src[j]
                for t in range(r):
                    gt = g[t]
                    s0 = ring[m, (top + t) % k]
                    s1 = ring[m, (top + k - 1 - t) % k]
                    for j in range(wv):
                        dst[j] += gt * (s0[j] + s1[j])
            row = 0.0
            a0, a1, a2, a3, a4 = acc[0], acc[1], acc[2], acc[3], acc[4]
            for j in range(wv):
                ma = a0[j]
                mb = a1[j]
                va = a2[j] - ma * ma
                vb = a3[j] - mb * mb
                cv = a4[j] - ma * mb
                # the denominators as the numerators plus what vanishes for equal images
                # ((ma - mb)^2 and va + vb - 2 cv): SSIM(a, a) is 1 whatever the rounding
                num1 = 2 * ma * mb + c1
                num2 = 2 * cv + c2
                den1 = num1 + (ma - mb) * (ma - mb)
                den2 = num2 + (va + vb - 2 * cv)
                row += (num1 * num2) / (den1 * den2)
            total += row
        out[i] = total / (hv * wv)
