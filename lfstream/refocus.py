"""Classical refocusing: shift-and-sum (SaS) and Fourier slice (FLR) focal stacks.

Definition (seed Eq. 2.3 without the 1/alpha magnification, so every plane keeps the
centre view's framing): the plane at ``slope = 1 - 1/alpha`` is

    E(y, x) = sum_uv w_uv * L_uv(y - slope*(u - u0), x - slope*(v - v0)) / coverage(y, x)

with bilinear interpolation. Points of disparity ``d = slope`` (lfstream's HCI sign) are in
focus. Border handling: a view contributes only where its shifted image exists (no
padding); ``coverage`` is the sum of the weights that do contribute, as in Dansereau's
LFFiltShiftSum. The centre view never moves, so with a non-zero centre weight every pixel
is covered; shifts larger than the image (tiny or huge alpha) leave only views that still
overlap, and the plane tends to the centre view. A pixel no view covers is 0.

Fourier slice refocusing (Ng 2005) takes one 4-D FFT per light field and then, per plane,
a 2-D slice of the spectrum interpolated in the angular frequencies and one inverse 2-D
FFT. It shifts with sinc rather than bilinear interpolation and wraps around (mitigated
by reflect padding), so it approximates SaS; its brightness matches SaS exactly (the DC
term is the weighted mean).
"""

from __future__ import annotations

import functools
import math
from typing import Sequence

import numpy as np
import torch
import torch.nn.functional as F

from lfstream.errors import LFShapeError, LFValueError
from lfstream.lightfield import aperture_weights, check_finite, check_lf, to_network_input
from lfstream.optics import SEED_ALPHAS, alpha_from_slope, slopes_from_alphas

METHODS = ("sas", "fourier", "refnet")


# ----------------------------------------------------------------------------------------
# Parameters


def resolve_slopes(
    alphas: Sequence[float] | None = None,
    slopes: Sequence[float] | None = None,
) -> np.ndarray:
    """Turns the user's alphas or slopes into slopes (float64 ``(K,)``).

    Neither given: the seed's sixteen alphas 0.125 ... 2.0.
    """
    if alphas is not None and slopes is not None:
        raise LFValueError("give alphas or slopes, not both")
    if slopes is not None:
        s = np.asarray(list(slopes), dtype=np.float64).reshape(-1)
        if s.size == 0 or not np.isfinite(s).all():
            raise LFValueError(f"slopes: need at least one finite value, got {list(slopes)!r}")
        return s
    s = slopes_from_alphas(SEED_ALPHAS if alphas is None else alphas)
    if s.size == 0:
        raise LFValueError("alphas: need at least one value")
    return s


def slope_range(lo: float, hi: float, count: int) -> np.ndarray:
    """``count`` evenly spaced slopes from ``lo`` to ``hi`` (a focus range in disparity units)."""
    if count < 1 or not (math.isfinite(lo) and math.isfinite(hi)):
        raise LFValueError(f"slope range needs finite ends and count >= 1, got {lo}, {hi}, {count}")
    return np.linspace(lo, hi, int(count))


def _view_weights(u: int, v: int, weights, present) -> np.ndarray:
    w = np.ones((u, v), np.float32) if weights is None else np.asarray(
        weights.cpu() if isinstance(weights, torch.Tensor) else weights, np.float32
    )
    if w.shape != (u, v):
        raise LFShapeError(f"weights: expected shape ({u}, {v}), got {w.shape}")
    if not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
        raise LFValueError("weights: must be finite, non-negative and not all zero")
    if present is not None:
        w = w * np.asarray(present, bool)
        if w.sum() <= 0:
            raise LFValueError("weights: no present view has a non-zero weight")
    return w


def _tap_offsets(slopes: np.ndarray, n: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Integer source offsets and bilinear fractions ``(K, n)`` for views ``0..n-1``.

    The plane samples view ``u`` at ``y - slope*(u - u0)``. Offsets beyond the image are
    clamped to ``size + 1``: the view then lies entirely outside either way, and int64
    cannot overflow for absurd slopes.
    """
    d = np.arange(n) - n // 2
    src = -slopes[:, None] * d[None, :]
    src = np.clip(src, -(size + 1), size + 1)
    i = np.floor(src)
    return i.astype(np.int64), (src - i).astype(np.float32)


def _axis_cover(ints: np.ndarray, fracs: np.ndarray, size: int) -> np.ndarray:
    """``(K, n, size)`` weight of each view's two bilinear taps that fall inside the image."""
    pos = np.arange(size)[None, None, :] + ints[:, :, None]
    inside0 = (pos >= 0) & (pos < size)
    inside1 = (pos + 1 >= 0) & (pos + 1 < size)
    return ((1 - fracs)[:, :, None] * inside0 + fracs[:, :, None] * inside1).astype(np.float32)


def _coverage(y_int, y_frac, x_int, x_frac, w: np.ndarray, h: int, wd: int) -> np.ndarray:
    """Sum of contributing weights per output pixel, ``(K, H, W)`` float32 (separable)."""
    cy = _axis_cover(y_int, y_frac, h)  # (K, U, H)
    cx = _axis_cover(x_int, x_frac, wd)  # (K, V, W)
    return np.einsum("kuh,uv,kvw->khw", cy, w, cx, optimize=True)


# ----------------------------------------------------------------------------------------
# Shift-and-sum


def _sas_frame_numpy(lf: np.ndarray, slopes: np.ndarray, w: np.ndarray) -> np.ndarray:
    from lfstream._kernels import shift_sum_rows

    u, v, h, wd, c = lf.shape
    if lf.dtype not in (np.uint8, np.float32):
        lf = lf.astype(np.float32)
    y_int, y_frac = _tap_offsets(slopes, u, h)
    x_int, x_frac = _tap_offsets(slopes, v, wd)
    # Broadcasting, not einsum: a BLAS call here leaves OpenBLAS threads spinning that then
    # compete with the kernel's threads (measured: 0.18 s instead of 0.12 s).
    col_cover = (w[None, :, :, None] * _axis_cover(x_int, x_frac, wd)[:, None, :, :]).sum(axis=2)
    scale = 255.0 if lf.dtype == np.uint8 else 1.0
    out = np.empty((len(slopes), h, wd * c), np.float32)
    shift_sum_rows(np.ascontiguousarray(lf).reshape(u, v, h, wd * c), c, w, y_int, y_frac, x_int, x_frac,
                   col_cover.astype(np.float32), scale, out)
    return out.reshape(len(slopes), h, wd, c)


def _shift_axis_add(acc: torch.Tensor, src: torch.Tensor, offset: int, frac: float, weight: float, dim: int) -> None:
    """acc += weight * bilinear shift of src along dim (sampling src at i + offset + frac)."""
    n = src.shape[dim]
    for off, wt in ((offset, 1.0 - frac), (offset + 1, frac)):
        if wt == 0.0:
            continue
        lo, hi = max(0, -off), min(n, n - off)
        if hi > lo:
            acc.narrow(dim, lo, hi - lo).add_(src.narrow(dim, lo + off, hi - lo), alpha=weight * wt)


def _sas_frame_torch(lf: torch.Tensor, slopes: np.ndarray, w: np.ndarray) -> torch.Tensor:
    """Separable torch implementation (any device): x-shifts per view, then y-shifts per row."""
    u, v, h, wd, c = lf.shape
    x = lf.float() / 255.0 if lf.dtype == torch.uint8 else lf.float()
    y_int, y_frac = _tap_offsets(slopes, u, h)
    x_int, x_frac = _tap_offsets(slopes, v, wd)
    out = torch.zeros((len(slopes), h, wd, c), dtype=torch.float32, device=lf.device)
    row = torch.empty((h, wd, c), dtype=torch.float32, device=lf.device)
    for k in range(len(slopes)):
        for uu in range(u):
            row.zero_()
            for vv in range(v):
                if w[uu, vv] != 0:
                    _shift_axis_add(row, x[uu, vv], int(x_int[k, vv]), float(x_frac[k, vv]), float(w[uu, vv]), 1)
            _shift_axis_add(out[k], row, int(y_int[k, uu]), float(y_frac[k, uu]), 1.0, 0)
    cov = torch.from_numpy(_coverage(y_int, y_frac, x_int, x_frac, w, h, wd)).to(lf.device)
    norm = torch.where(cov > 1e-6, 1.0 / cov.clamp_min(1e-6), torch.zeros_like(cov))
    return out * norm[..., None]


def shift_and_sum(
    lf: np.ndarray | torch.Tensor,
    slopes: Sequence[float] | np.ndarray,
    weights: np.ndarray | torch.Tensor | None = None,
    present: np.ndarray | None = None,
) -> np.ndarray | torch.Tensor:
    """Shift-and-sum focal stack at the given slopes; float32 in ``[0, 1]``.

    numpy (and CPU tensors) run the fused CPU kernel; CUDA tensors run a separable torch
    implementation on the GPU. Both compute the same numbers (see the module docstring).

    Args:
        lf: ``(U, V, H, W, C)`` or ``(T, U, V, H, W, C)``, uint8 or float in ``[0, 1]``.
        slopes: shift in pixels per view step of each plane.
        weights: ``(U, V)`` synthetic-aperture weights (default: all views equal).
        present: ``(U, V)`` bool mask of views that exist (others get weight 0).

    Shape:
        - output: ``(K, H, W, C)`` or ``(T, K, H, W, C)``
    """
    check_lf(lf)
    check_finite(lf)
    s = np.asarray(slopes, np.float64).reshape(-1)
    if s.size == 0 or not np.isfinite(s).all():
        raise LFValueError("slopes: need at least one finite value")
    u, v = int(lf.shape[-5]), int(lf.shape[-4])
    w = _view_weights(u, v, weights, present)
    frames = lf if lf.ndim == 6 else lf[None]
    if isinstance(lf, torch.Tensor):
        if lf.device.type == "cpu":
            arr = lf.numpy() if lf.dtype in (torch.uint8, torch.float32) else lf.float().numpy()
            return torch.from_numpy(shift_and_sum(arr, s, w))
        res = torch.stack([_sas_frame_torch(f, s, w) for f in frames])
    elif lf.ndim == 5:
        return _sas_frame_numpy(np.asarray(lf), s, w)
    else:
        res = np.stack([_sas_frame_numpy(np.asarray(f), s, w) for f in frames])
    return res if lf.ndim == 6 else res[0]


# ----------------------------------------------------------------------------------------
# Fourier slice


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
    s = np.asarray(slopes, np.float64).reshape(-1)
    if s.size == 0 or not np.isfinite(s).all():
        raise LFValueError("slopes: need at least one finite value")
    u, v, h, wd, c = (int(x) for x in lf.shape[-5:])
    w = _view_weights(u, v, weights, present)
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


# ----------------------------------------------------------------------------------------
# Focal stack API


def focal_stack(
    lf: np.ndarray | torch.Tensor,
    alphas: Sequence[float] | None = None,
    method: str = "sas",
    *,
    slopes: Sequence[float] | None = None,
    aperture: float | None = None,
    aperture_shape: str = "circle",
    weights: np.ndarray | torch.Tensor | None = None,
    present: np.ndarray | None = None,
    **method_options,
) -> np.ndarray | torch.Tensor:
    """Refocused images of a light field, in the input's value range.

    Args:
        lf: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)``; uint8, float16, float32 or float64.
        alphas: refocus parameters (default the seed's sixteen, 0.125 ... 2.0).
        method: ``"sas"`` (exact shift-and-sum), ``"fourier"`` (Fourier slice) or ``"refnet"``
            (the shipped RefNet: the seed's sixteen alphas only, the grid it was trained for;
            option ``device``).
        slopes: instead of alphas, shifts in pixels per view step (= disparity in focus).
        aperture: synthetic aperture radius in view steps (``None``: all views); see
            :func:`lfstream.lightfield.aperture_weights` for ``aperture_shape``.
        weights: explicit ``(U, V)`` view weights (instead of ``aperture``).
        present: ``(U, V)`` mask of views present (e.g. from ``read_lf(return_mask=True)``).
        method_options: passed to :func:`fourier_slice` (``oversample``, ``pad``, ``dtype``).

    Returns:
        ``(K, H, W, 3)`` (or ``(T, K, H, W, 3)``): uint8 for uint8 input, otherwise the
        input's float dtype in ``[0, 1]``; numpy for numpy, torch (same device) for torch.
    """
    s = resolve_slopes(alphas, slopes)
    check_lf(lf)
    u, v = int(lf.shape[-5]), int(lf.shape[-4])
    if weights is not None and aperture is not None:
        raise LFValueError("give aperture or weights, not both")
    if weights is None and aperture is not None:
        weights = aperture_weights((u, v), aperture, aperture_shape)
    if method == "sas":
        if method_options:
            raise LFValueError(f"options {sorted(method_options)} apply to method='fourier' only")
        out = shift_and_sum(lf, s, weights, present)
    elif method == "fourier":
        out = fourier_slice(lf, s, weights, present, **method_options)
    elif method == "refnet":
        if weights is not None or present is not None:
            raise LFValueError("method='refnet' renders the full aperture of a complete light field; "
                               "aperture, weights and missing views need 'sas' or 'fourier'")
        out = refnet_stack(lf, s, **method_options)
    else:
        raise LFValueError(f"method: one of {', '.join(METHODS)}, got {method!r}")
    return _to_input_range(out, lf)


@functools.lru_cache(maxsize=4)
def _shipped_refnet(preset: str, device: str):
    """The shipped RefNet, loaded (and its SHA-256 checked) once per preset and device: the
    pipeline renders a stack per frame. Used in eval mode only; callers must not mutate it."""
    from lfstream.weights import load_model

    return load_model("refnet", preset, device)


def refnet_stack(lf, slopes: np.ndarray, device: str | None = None, preset: str = "fast"):
    """Focal stack by the shipped RefNet (see :mod:`lfstream.refnet`), float in ``[0, 1]``.

    Shape:
        - lf: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)``; output ``(16, H, W, 3)`` or ``(T, 16, H, W, 3)``
    """
    seed = slopes_from_alphas(SEED_ALPHAS)
    if np.shape(slopes) != np.shape(seed) or not np.allclose(slopes, seed, atol=1e-6):
        raise LFValueError("method='refnet' renders the seed's sixteen alphas (0.125 ... 2.0) only")
    is_torch = isinstance(lf, torch.Tensor)
    dev = device or (str(lf.device) if is_torch else "cpu")
    model = _shipped_refnet(preset, str(dev))
    if lf.shape[-1] != 3 or tuple(lf.shape[-5:-3]) != tuple(model.config.views):
        raise LFValueError(f"method='refnet': the shipped RefNet takes {model.config.views[0]}x{model.config.views[1]} "
                           f"RGB views, got {tuple(lf.shape[-5:-3])} with {lf.shape[-1]} channels (train one with "
                           "tools/train.py, or use 'sas')")
    x = to_network_input(lf, dev)
    video = x if x.ndim == 6 else x[None]
    with torch.inference_mode():
        out = model(video).permute(0, 1, 3, 4, 2)
    out = out if x.ndim == 6 else out[0]
    return out if is_torch else out.cpu().numpy()


def _to_input_range(out, like):
    if isinstance(out, torch.Tensor):
        if like.dtype == torch.uint8:
            return (out * 255.0 + 0.5).clamp_(0, 255).to(torch.uint8)
        return out.clamp(0, 1).to(like.dtype) if like.dtype != out.dtype else out.clamp(0, 1)
    if like.dtype == np.uint8:
        return np.clip(out * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return np.clip(out, 0, 1).astype(like.dtype, copy=False)


def all_in_focus(
    lf: np.ndarray,
    disparity: np.ndarray,
    planes: int = 16,
    weights: np.ndarray | None = None,
) -> np.ndarray:
    """All-in-focus image: each pixel from the focal plane at its own disparity.

    A shift-and-sum stack is rendered at ``planes`` slopes spanning the disparity map's
    range and each pixel blends the two planes that bracket its disparity linearly.

    Shape:
        - lf: ``(U, V, H, W, C)``; disparity: ``(H, W)`` of the centre view
        - output: ``(H, W, C)``, the input's value range
    """
    check_lf(lf, allow_video=False)
    d = np.asarray(disparity, np.float64)
    if d.shape != tuple(lf.shape[2:4]):
        raise LFShapeError(f"disparity: expected shape {tuple(lf.shape[2:4])}, got {d.shape}")
    check_finite(d, "disparity")
    lo, hi = float(d.min()), float(d.max())
    if hi - lo < 1e-6:
        stack = shift_and_sum(lf, [lo], weights)
        return _to_input_range(stack[0], lf)
    s = slope_range(lo, hi, max(2, planes))
    stack = shift_and_sum(lf, s, weights)  # (K, H, W, C) float32
    pos = (d - lo) / (hi - lo) * (len(s) - 1)
    k0 = np.clip(np.floor(pos).astype(np.int64), 0, len(s) - 2)
    t = (pos - k0).astype(np.float32)[..., None]
    yy, xx = np.indices(d.shape)
    img = (1 - t) * stack[k0, yy, xx] + t * stack[k0 + 1, yy, xx]
    return _to_input_range(img, lf)


class FocalStack(torch.nn.Module):
    """``nn.Module`` wrapper of :func:`focal_stack` with fixed planes and method.

    Shape:
        - input: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)`` tensor
        - output: ``(K, H, W, 3)`` or ``(T, K, H, W, 3)``
    """

    def __init__(self, alphas: Sequence[float] | None = None, method: str = "sas", slopes=None, **options):
        super().__init__()
        self.slopes = resolve_slopes(alphas, slopes)
        self.method = method
        self.options = options

    def forward(self, lf: torch.Tensor) -> torch.Tensor:
        return focal_stack(lf, method=self.method, slopes=self.slopes, **self.options)


__all__ = [
    "METHODS",
    "resolve_slopes",
    "slope_range",
    "shift_and_sum",
    "fourier_slice",
    "focal_stack",
    "refnet_stack",
    "all_in_focus",
    "FocalStack",
    "alpha_from_slope",
]
