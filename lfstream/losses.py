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

DEPTH_WEIGHTS = {"photometric": 2.0, "defocus": 100.0, "consistency": 0.02, "dof": 10.0}
DEPTH_BETA = 0.15
REFNET_BETA = 0.65
REFNET_GAMMA = 500.0


def _gaussian_window(channels: int, device, dtype, size: int = 11, sigma: float = 1.5) -> torch.Tensor:
    x = torch.arange(size, device=device, dtype=dtype) - (size - 1) / 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    g = g / g.sum()
    return (g[:, None] * g[None, :]).expand(channels, 1, size, size).contiguous()


def ssim_torch(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Mean SSIM of two batches in ``[0, 1]`` (valid region; images smaller than the window
    fall back to a smaller window).

    Shape:
        - a, b: ``(B, C, H, W)``; output: scalar
    """
    c = a.shape[1]
    size = min(11, a.shape[-1], a.shape[-2])
    size -= 1 - size % 2
    win = _gaussian_window(c, a.device, a.dtype, size)
    c1, c2 = 0.01**2, 0.03**2
    mu_a = F.conv2d(a, win, groups=c)
    mu_b = F.conv2d(b, win, groups=c)
    saa = F.conv2d(a * a, win, groups=c) - mu_a**2
    sbb = F.conv2d(b * b, win, groups=c) - mu_b**2
    sab = F.conv2d(a * b, win, groups=c) - mu_a * mu_b
    s = ((2 * mu_a * mu_b + c1) * (2 * sab + c2)) / ((mu_a**2 + mu_b**2 + c1) * (saa + sbb + c2))
    return s.mean()


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


def _base_grid(h: int, w: int, device, dtype) -> tuple[torch.Tensor, torch.Tensor]:
    ys, xs = torch.meshgrid(torch.arange(h, device=device, dtype=dtype), torch.arange(w, device=device, dtype=dtype),
                            indexing="ij")
    return ys, xs


def _sample(img: torch.Tensor, sy: torch.Tensor, sx: torch.Tensor) -> torch.Tensor:
    """Bilinear sampling with border clamping at pixel coordinates ``(sy, sx)`` of shape (B, H, W)."""
    h, w = img.shape[-2:]
    grid = torch.stack([sx / max(w - 1, 1) * 2 - 1, sy / max(h - 1, 1) * 2 - 1], dim=-1)
    return F.grid_sample(img, grid, mode="bilinear", padding_mode="border", align_corners=True)


def warp_per_view(centre: torch.Tensor, disparity: torch.Tensor) -> torch.Tensor:
    """Differentiable ``L(x, u) = C(x + (u - u0) d(x, u))`` with one map per view.

    Shape:
        - centre: ``(B, C, H, W)``; disparity: ``(B, U, V, H, W)``
        - output: ``(B, U, V, C, H, W)``
    """
    b, u_n, v_n, h, w = disparity.shape
    ys, xs = _base_grid(h, w, centre.device, centre.dtype)
    du = (torch.arange(u_n, device=centre.device, dtype=centre.dtype) - u_n // 2).view(1, u_n, 1, 1, 1)
    dv = (torch.arange(v_n, device=centre.device, dtype=centre.dtype) - v_n // 2).view(1, 1, v_n, 1, 1)
    sy = (ys + disparity * du).reshape(b * u_n * v_n, h, w)
    sx = (xs + disparity * dv).reshape(b * u_n * v_n, h, w)
    src = centre[:, None].expand(b, u_n * v_n, *centre.shape[1:]).reshape(b * u_n * v_n, *centre.shape[1:])
    return _sample(src, sy, sx).reshape(b, u_n, v_n, centre.shape[1], h, w)


def _refocus(lf: torch.Tensor, slope: float) -> torch.Tensor:
    """Shift-and-sum of ``(B, U, V, C, H, W)`` at one slope (px per view step)."""
    b, u_n, v_n, c, h, w = lf.shape
    if slope == 0:
        return lf.mean(dim=(1, 2))
    ys, xs = _base_grid(h, w, lf.device, lf.dtype)
    du = (torch.arange(u_n, device=lf.device, dtype=lf.dtype) - u_n // 2).view(u_n, 1, 1, 1)
    dv = (torch.arange(v_n, device=lf.device, dtype=lf.dtype) - v_n // 2).view(1, v_n, 1, 1)
    sy = (ys - slope * du).expand(u_n, v_n, h, w).reshape(1, u_n * v_n, h, w).expand(b, -1, -1, -1)
    sx = (xs - slope * dv).expand(u_n, v_n, h, w).reshape(1, u_n * v_n, h, w).expand(b, -1, -1, -1)
    flat = lf.reshape(b * u_n * v_n, c, h, w)
    out = _sample(flat, sy.reshape(-1, h, w), sx.reshape(-1, h, w))
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
    ys, xs = _base_grid(h, w, lf.device, lf.dtype)
    du = (torch.arange(u_n, device=lf.device, dtype=lf.dtype) - u_n // 2).view(1, u_n, 1, 1, 1)
    dv = (torch.arange(v_n, device=lf.device, dtype=lf.dtype) - v_n // 2).view(1, 1, v_n, 1, 1)
    sy = (ys - d0[:, None, None] * du).expand(b, u_n, v_n, h, w).reshape(-1, h, w)
    sx = (xs - d0[:, None, None] * dv).expand(b, u_n, v_n, h, w).reshape(-1, h, w)
    back = _sample(lf.reshape(-1, c, h, w), sy, sx)
    lp_bwd = psi(back, centre[:, None, None].expand(b, u_n, v_n, c, h, w).reshape(-1, c, h, w), DEPTH_BETA)
    lp = lp_fwd + lp_bwd
    lr = sum((_refocus(recon, s) - _refocus(lf, s)).abs().mean() for s in slopes) / len(slopes)
    # consistency: view (u, v)'s disparity equals the centre disparity where it samples the centre
    sy_v = (ys + disparity * du).reshape(-1, h, w)
    sx_v = (xs + disparity * dv).reshape(-1, h, w)
    d0_at = _sample(d0[:, None].expand(b, u_n * v_n, h, w).reshape(-1, 1, h, w), sy_v, sx_v)
    lc = (d0_at.reshape(b, u_n, v_n, h, w) - disparity).abs().mean()
    ld = psi(recon.mean(dim=(1, 2)), lf.mean(dim=(1, 2)), DEPTH_BETA)
    wts = DEPTH_WEIGHTS
    total = wts["photometric"] * lp + wts["defocus"] * lr + wts["consistency"] * lc + wts["dof"] * ld
    return total, {"photometric": lp.item(), "defocus": lr.item(), "consistency": lc.item(), "dof": ld.item()}


__all__ = ["psi", "ssim_torch", "hance_loss", "refnet_loss", "depth_net_loss", "warp_per_view",
           "DEPTH_WEIGHTS", "DEPTH_BETA", "REFNET_BETA", "REFNET_GAMMA"]
