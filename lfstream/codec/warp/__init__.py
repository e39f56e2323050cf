"""The warp: every view of a light field from its centre view and disparity.

- :mod:`~lfstream.codec.warp.spec`: the arithmetic written once, in plain numpy (the
  reference every backend is tested against).
- :mod:`~lfstream.codec.warp.cpu`: the decoder's fused CPU warp (numba,
  :mod:`~lfstream.codec.warp.kernels` and :mod:`~lfstream.codec.warp.splat_kernels`).
- :mod:`~lfstream.codec.warp.batched`: the same warp as tensor operations on any torch
  device, batched over frames; its CUDA kernels in :mod:`~lfstream.codec.warp.triton`.
"""

from lfstream.codec.warp.cpu import (
    splat_reach,
    splat_rows,
    splat_views,
    view_disparities,
    warp_views,
    warp_views_at,
    warp_views_per_view,
)

__all__ = ["warp_views", "warp_views_at", "warp_views_per_view", "view_disparities", "splat_views", "splat_rows",
           "splat_reach"]
