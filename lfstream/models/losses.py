"""Training losses of the three networks, as the seed defines them.

- ``psi(a, b, beta) = beta * (1 - SSIM(a, b)) / 2 + (1 - beta) * |a - b|_1`` (SSIM with an
  11x11 Gaussian window, sigma 1.5, on images in ``[0, 1]``; differentiable torch code —
  :func:`lfstream.metrics.ssim` is the float64 evaluation metric).
- JPEG-Hance pre-training: MSE.
- Depth-Net (unsupervised): ``2 Lp + 100 Lr + 0.02 Lc + 10 Ld`` with beta = 0.15:
  ``Lp`` photometric (seed Eq. 3.6), both warp directions: the centre warped into every view
  by that view's disparity vs the view, and every view warped back onto the centre by the
  centre disparity vs the centre; ``Lr`` defocus (3.7): refocused images (shift-and-sum
  at a few slopes) of the reconstructed LF vs those of the true LF; ``Lc`` depth consistency
  (3.8): each view's disparity vs the centre disparity at the point it samples; ``Ld`` DoF
  (3.9): the full-aperture (all-view mean) image of the reconstruction vs the truth's.
  The split of the seed's terms into these formulas is lfstream's reading of the text.
- RefNet (supervised): ``MSE + psi(beta=0.65) + gamma / PSNR`` with gamma = 500.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from lfstream.metrics import ssim_nchw
from lfstream.models.warp import pixel_grid, sample_bilinear, view_offsets, warp_per_view

DEPTH_WEIGHTS = {"photometric": 2.0, "defocus": 100.0, "consistency": 0.02, "dof": 10.0}
DEPTH_BETA = 0.15
REFNET_BETA = 0.65
REFNET_GAMMA = 500.0


def ssim_torch(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Mean SSIM of two batches in ``[0, 1]`` (:func:`lfstream.metrics.ssim_nchw`; images
    smaller than the 11x11 window fall back to the largest odd window that fits).

    Shape:
        - a, b: ``(B, C, H, W)``; output: scalar
    """
    size = min(11, a.shape[-1], a.shape[-2])
    size -= 1 - size % 2
    return ssim_nchw(a, b, 1.0, window=size).mean()


def psi(a: torch.Tensor, b: torch.Tensor, beta: float) -> torch.Tensor:
    """The seed's image loss ``beta (1 - SSIM) / 2 + (1 - beta) L1``."""
    return beta * (1 - ssim_torch(a, b)) / 2 + (1 - beta) * (a - b).abs().mean()


def hance_loss(restored: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    return F.mse_loss(restored, target)


def refnet_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """``MSE + psi(0.65) + 500 / PSNR`` on ``(B, P, 3, H, W)`` stacks in ``[0, 1]``."""
    mse = F.mse_loss(pred, target)
    psnr = 10 * torch.log10(1.0 / mse.clamp_min(1e-10))
    flat_p, flat_t = pred.flatten(0, 1), target.flatten(0, 1)
    return mse + psi(flat_p, flat_t, REFNET_BETA) + REFNET_GAMMA / psnr.clamp_min(1.0)


def _refocus(lf: torch.Tensor, slope: float) -> torch.Tensor:
    """Shift-and-sum of ``(B, U, V, C, H, W)`` at one slope (px per view step)."""
    b, u_n, v_n, c, h, w = lf.shape
    if slope == 0:
        return lf.mean(dim=(1, 2))
    ys, xs = pixel_grid(h, w, lf.device, lf.dtype)
    du, dv = (t[0] for t in view_offsets(u_n, v_n, lf.device, lf.dtype))
    sy = (ys - slope * du).expand(u_n, v_n, h, w).reshape(1, u_n * v_n, h, w).expand(b, -1, -1, -1)
    sx = (xs - slope * dv).expand(u_n, v_n, h, w).reshape(1, u_n * v_n, h, w).expand(b, -1, -1, -1)
    flat = lf.reshape(b * u_n * v_n, c, h, w)
    out = sample_bilinear(flat, sy.reshape(-1, h, w), sx.reshape(-1, h, w))
    return out.reshape(b, u_n * v_n, c, h, w).mean(1)


def depth_net_loss(centre: torch.Tensor, lf: torch.Tensor, disparity: torch.Tensor,
                   slopes: tuple[float, ...] = (-1.0, 1.0)) -> tuple[torch.Tensor, dict[str, float]]:
    """Unsupervised Depth-Net loss.

    Args:
        centre: the (restored) decoded centre view the decoder warps, ``(B, 3, H, W)``.
        lf: the true light field ``(B, U, V, 3, H, W)`` in ``[0, 1]``.
        disparity: the network's per-view maps ``(B, U, V, H, W)``.
        slopes: refocus slopes of the defocus term.

    Returns:
        the total loss and its terms (floats, for logging).
    """
    b, u_n, v_n, c, h, w = lf.shape
    recon = warp_per_view(centre, disparity)
    lp_fwd = psi(recon.flatten(0, 2), lf.flatten(0, 2), DEPTH_BETA)
    # backward direction: every true view pulled onto the centre with the centre's disparity
    d0 = disparity[:, u_n // 2, v_n // 2]
    ys, xs = pixel_grid(h, w, lf.device, lf.dtype)
    du, dv = view_offsets(u_n, v_n, lf.device, lf.dtype)
    sy = (ys - d0[:, None, None] * du).expand(b, u_n, v_n, h, w).reshape(-1, h, w)
    sx = (xs - d0[:, None, None] * dv).expand(b, u_n, v_n, h, w).reshape(-1, h, w)
    back = sample_bilinear(lf.reshape(-1, c, h, w), sy, sx)
    lp_bwd = psi(back, centre[:, None, None].expand(b, u_n, v_n, c, h, w).reshape(-1, c, h, w), DEPTH_BETA)
    lp = lp_fwd + lp_bwd
    lr = sum((_refocus(recon, s) - _refocus(lf, s)).abs().mean() for s in slopes) / len(slopes)
    # consistency: view (u, v)'s disparity equals the centre disparity where it samples the centre
    sy_v = (ys + disparity * du).reshape(-1, h, w)
    sx_v = (xs + disparity * dv).reshape(-1, h, w)
    d0_at = sample_bilinear(d0[:, None].expand(b, u_n * v_n, h, w).reshape(-1, 1, h, w), sy_v, sx_v)
    lc = (d0_at.reshape(b, u_n, v_n, h, w) - disparity).abs().mean()
    ld = psi(recon.mean(dim=(1, 2)), lf.mean(dim=(1, 2)), DEPTH_BETA)
    wts = DEPTH_WEIGHTS
    total = wts["photometric"] * lp + wts["defocus"] * lr + wts["consistency"] * lc + wts["dof"] * ld
    return total, {"photometric": lp.item(), "defocus": lr.item(), "consistency": lc.item(), "dof": ld.item()}


__all__ = ["psi", "ssim_torch", "hance_loss", "refnet_loss", "depth_net_loss", "warp_per_view",
           "DEPTH_WEIGHTS", "DEPTH_BETA", "REFNET_BETA", "REFNET_GAMMA"]
