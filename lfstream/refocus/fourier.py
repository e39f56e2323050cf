"""Fourier slice refocusing (Ng 2005) takes one 4-D FFT per light field and then, per plane,
a 2-D slice of the spectrum interpolated in the angular frequencies and one inverse 2-D
FFT. It shifts with sinc rather than bilinear interpolation and wraps around (mitigated
by reflect padding), so it approximates SaS; its brightness matches SaS exactly (the DC
term is the weighted mean).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
import torch.nn.functional as F

from lfstream.errors import LFValueError
from lfstream.lightfield import check_finite, check_lf
from lfstream.refocus.planes import check_slopes, view_weights


def fourier_slice(
    lf: np.ndarray | torch.Tensor,
    slopes: Sequence[float] | np.ndarray,
    weights: np.ndarray | torch.Tensor | None = None,
    present: np.ndarray | None = None,
    oversample: int = 2,
    pad: int | None = None,
    dtype: torch.dtype = torch.float32,
) -> np.ndarray | torch.Tensor:
    """Fourier slice refocusing (Ng 2005); float in ``[0, 1]``, same shape as SaS.

    Args:
        lf, slopes, weights, present: as :func:`shift_and_sum`.
        oversample: zero-padding factor of the angular axes before the 4-D FFT; the slice
            is interpolated bilinearly between angular frequency samples, so a larger factor
            is more accurate (1 = Ng's plain grid). Memory grows with its square.
        pad: reflect padding of the views in pixels against wrap-around; default the
            largest shift the stack needs, plus 2.
        dtype: ``torch.float32`` or ``torch.float64`` computation.

    Shape:
        - output: ``(K, H, W, C)`` or ``(T, K, H, W, C)``
    """
    check_lf(lf)
    check_finite(lf)
    if dtype not in (torch.float32, torch.float64):
        raise LFValueError(f"dtype: float32 or float64, got {dtype}")
    if not isinstance(oversample, int) or not 1 <= oversample <= 8:
        raise LFValueError(f"oversample: an integer in 1..8, got {oversample!r}")
    s = check_slopes(slopes)
    u, v, h, wd, c = (int(x) for x in lf.shape[-5:])
    w = view_weights(u, v, weights, present)
    is_torch = isinstance(lf, torch.Tensor)
    t = lf if is_torch else torch.from_numpy(np.ascontiguousarray(lf))
    if pad is None:
        pad = int(min(math.ceil(np.abs(s).max() * max(u // 2, v // 2)) + 2, max(h, wd)))
    frames = t if t.ndim == 6 else t[None]
    outs = [_flr_frame(f, s, w, oversample, int(pad), dtype) for f in frames]
    res = torch.stack(outs).float()
    res = res if t.ndim == 6 else res[0]
    return res if is_torch else res.numpy()


def _flr_frame(lf: torch.Tensor, slopes: np.ndarray, w: np.ndarray, oversample: int, pad: int, dtype) -> torch.Tensor:
    u, v, h, wd, c = lf.shape
    dev = lf.device
    x = (lf.to(dtype) / 255.0) if lf.dtype == torch.uint8 else lf.to(dtype)
    wt = torch.from_numpy(w).to(device=dev, dtype=dtype)
    x = x * (wt / wt.sum())[:, :, None, None, None]
    x = x.permute(0, 1, 4, 2, 3).reshape(u * v * c, 1, h, wd)
    # reflect padding needs pad < size; replicate beyond that
    py, px = min(pad, h - 1), min(pad, wd - 1)
    if py > 0 or px > 0:
        x = F.pad(x, (px, px, py, py), mode="reflect")
    if pad > py or pad > px:
        x = F.pad(x, (pad - px, pad - px, pad - py, pad - py), mode="replicate")
    hp, wp = x.shape[-2:]
    x = x.reshape(u, v, c, hp, wp)
    pu, pv = oversample * u, oversample * v
    grid = torch.zeros((pu, pv, c, hp, wp), dtype=dtype, device=dev)
    du = (torch.arange(u) - u // 2) % pu
    dv = (torch.arange(v) - v // 2) % pv
    grid[du[:, None], dv[None, :]] = x  # centre view at angular index 0
    spec = torch.fft.rfftn(grid, dim=(0, 1, 3, 4))  # (pu, pv, c, hp, wp//2+1)
    del grid
    fy = torch.fft.fftfreq(hp, device=dev, dtype=dtype)
    fx = torch.fft.rfftfreq(wp, device=dev, dtype=dtype)
    yy = torch.arange(hp, device=dev)[:, None]
    xx = torch.arange(fx.numel(), device=dev)[None, :]
    out = torch.empty((len(slopes), h, wd, c), dtype=dtype, device=dev)
    for k, s in enumerate(slopes.tolist()):
        # E(y) = sum_u L_u(y - s*du)  =>  E^(fy) = sum_u L^_u(fy) exp(-2 pi i fy s du):
        # the 4-D spectrum at angular frequency m_u = s * fy * pu (cycles per pu views).
        mu = torch.remainder(s * fy * pu, pu)
        mv = torch.remainder(s * fx * pv, pv)
        mu0 = torch.floor(mu)
        mv0 = torch.floor(mv)
        au = (mu - mu0)[:, None, None]  # (hp, 1, 1) broadcast over (hp, wf, c) after permute
        av = (mv - mv0)[None, :, None]
        mu0 = mu0.long()
        mv0 = mv0.long()
        mu1 = (mu0 + 1) % pu
        mv1 = (mv0 + 1) % pv

        def at(iu, iv):
            return spec[iu[:, None], iv[None, :], :, yy, xx]  # (hp, wf, c)

        sl = (1 - au) * ((1 - av) * at(mu0, mv0) + av * at(mu0, mv1)) + au * (
            (1 - av) * at(mu1, mv0) + av * at(mu1, mv1)
        )
        img = torch.fft.irfft2(sl.permute(2, 0, 1), s=(hp, wp))  # (c, hp, wp)
        out[k] = img[:, pad : pad + h, pad : pad + wd].permute(1, 2, 0)
    return out


__all__ = ["fourier_slice"]
