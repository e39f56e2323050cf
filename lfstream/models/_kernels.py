"""Fused CPU kernels of the networks' inference, compiled by numba (cached on disk).

ELU: PyTorch's CPU ``elu_`` does not vectorise its ``expm1`` (a ``relu_`` costs a twentieth
of it), and JPEG-Hance fast spent half its time in its 13 ELUs under the torch profiler.
These kernels compute ``expm1`` of the negative side as a polynomial on ``x / 32`` doubled
back five times (``e(2r) = e(r) (e(r) + 2)``), which vectorises, in either dtype
(``bench/networks.py`` times both).

Accuracy (alpha 1): float32 within 4e-7 of the true value relative (PyTorch's own is within
about 1e-7); bfloat16 rounds the float32 result to nearest even, as PyTorch does from its
float32 one: the two differ only where that result lies within a few float32 units of a
bfloat16 rounding boundary (none in 2.6 million normal samples).
"""

from __future__ import annotations

import numba
import numpy as np

#: Elements a thread's job covers (a chunk of bfloat16 widened to float32 stays in L1).
_CHUNK = 4096


@numba.njit(inline="always", fastmath=True)
def _elu1(x):  # pragma: no cover - compiled
    """ELU with alpha 1 of one float32: ``x`` where positive, else ``expm1(x)``."""
    # below -20 expm1 is -1 to float32's precision
    r = np.float32((x if x > np.float32(-20.0) else np.float32(-20.0)) * np.float32(1.0 / 32.0))
    # expm1 on [-0.625, 0]: Taylor to r^8 (truncation below 5e-8 relative)
    p = r * (np.float32(1.0) + r * (np.float32(1.0 / 2) + r * (np.float32(1.0 / 6) + r * (
        np.float32(1.0 / 24) + r * (np.float32(1.0 / 120) + r * (np.float32(1.0 / 720) + r * (
            np.float32(1.0 / 5040) + r * np.float32(1.0 / 40320))))))))
    # expm1(2 t) = expm1(t) (expm1(t) + 2), five times: no cancellation on the negative side
    p = p * (p + np.float32(2.0))
    p = p * (p + np.float32(2.0))
    p = p * (p + np.float32(2.0))
    p = p * (p + np.float32(2.0))
    p = p * (p + np.float32(2.0))
    return x if x > np.float32(0.0) else p


@numba.njit(parallel=True, fastmath=True, cache=True, nogil=True)
def elu_float32_(x):  # pragma: no cover - compiled
    """ELU (alpha 1) of a 1-D float32 array, in place."""
    n = x.size
    for c in numba.prange((n + _CHUNK - 1) // _CHUNK):
        lo = c * _CHUNK
        seg = x[lo:min(n, lo + _CHUNK)]
        for j in range(seg.size):
            seg[j] = _elu1(seg[j])


@numba.njit(parallel=True, fastmath=True, cache=True, nogil=True)
def elu_bfloat16_(bits):  # pragma: no cover - compiled
    """ELU (alpha 1) of a 1-D array of bfloat16 values (their uint16 bit patterns), in
    place: each widened to float32 (the bits shifted up), the float32 ELU, and rounded back
    to nearest even."""
    n = bits.size
    for c in numba.prange((n + _CHUNK - 1) // _CHUNK):
        lo = c * _CHUNK
        seg = bits[lo:min(n, lo + _CHUNK)]
        m = seg.size
        wide = np.empty(m, np.uint32)
        for j in range(m):
            wide[j] = np.uint32(seg[j]) << np.uint32(16)
        values = wide.view(np.float32)
        for j in range(m):
            values[j] = _elu1(values[j])
        for j in range(m):
            u = wide[j]
            seg[j] = np.uint16((u + np.uint32(0x7FFF) + ((u >> np.uint32(16)) & np.uint32(1))) >> np.uint32(16))
