"""Differentiable view synthesis on any torch device (training losses, GPU paths).

The same model as :mod:`lfstream.codec.warp.cpu` (``L(x, u) = C(x + (u - u0) d(x, u))``,
lfstream's disparity sign, border clamping) through ``grid_sample``; the decoder's
occlusion-aware CPU warp is tested to agree with it where no occlusion occurs.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F


def pixel_grid(h: int, w: int, device, dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """Row and column coordinates ``(H, W)`` each."""
    return torch.meshgrid(torch.arange(h, device=device, dtype=dtype), torch.arange(w, device=device, dtype=dtype),
                          indexing="ij")


def view_offsets(u_n: int, v_n: int, device, dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """``u - u0`` as ``(1, U, 1, 1, 1)`` and ``v - v0`` as ``(1, 1, V, 1, 1)``."""
    du = (torch.arange(u_n, device=device, dtype=dtype) - u_n // 2).view(1, u_n, 1, 1, 1)
    dv = (torch.arange(v_n, device=device, dtype=dtype) - v_n // 2).view(1, 1, v_n, 1, 1)
    return du, dv


def sample_bilinear(img: torch.Tensor, sy: torch.Tensor, sx: torch.Tensor) -> torch.Tensor:
    """Bilinear sampling with border clamping at pixel coordinates.

    Shape:
        - img: ``(N, C, H, W)``; sy, sx: ``(N, H', W')``
        - output: ``(N, C, H', W')``
    """
    h, w = img.shape[-2:]
    grid = torch.stack([sx / max(w - 1, 1) * 2 - 1, sy / max(h - 1, 1) * 2 - 1], dim=-1)
    return F.grid_sample(img, grid, mode="bilinear", padding_mode="border", align_corners=True)


def warp_per_view(centre: torch.Tensor, disparity: torch.Tensor) -> torch.Tensor:
    """``L(x, u) = C(x + (u - u0) d(x, u))`` with one disparity map per view.

    Shape:
        - centre: ``(B, C, H, W)``; disparity: ``(B, U, V, H, W)``
        - output: ``(B, U, V, C, H, W)``
    """
    b, u_n, v_n, h, w = disparity.shape
    ys, xs = pixel_grid(h, w, centre.device, centre.dtype)
    du, dv = view_offsets(u_n, v_n, centre.device, centre.dtype)
    sy = (ys + disparity * du).reshape(b * u_n * v_n, h, w)
    sx = (xs + disparity * dv).reshape(b * u_n * v_n, h, w)
    src = centre[:, None].expand(b, u_n * v_n, *centre.shape[1:]).reshape(b * u_n * v_n, *centre.shape[1:])
    return sample_bilinear(src, sy, sx).reshape(b, u_n, v_n, centre.shape[1], h, w)


def warp_views_torch(centre: torch.Tensor, disparity: torch.Tensor, views: tuple[int, int]) -> torch.Tensor:
    """The centre-view disparity used for every view (no occlusion handling).

    Shape:
        - centre: ``(B, C, H, W)`` float; disparity: ``(B, 1, H, W)``
        - output: ``(B, U, V, C, H, W)``
    """
    b, _, h, w = disparity.shape
    per_view = disparity[:, :, None].expand(b, views[0], views[1], h, w)
    return warp_per_view(centre, per_view)


__all__ = ["pixel_grid", "view_offsets", "sample_bilinear", "warp_per_view", "warp_views_torch"]
