"""Shift-and-sum (SaS) refocusing: the exact focal stack, fused on CPU, separable on GPU.

Definition (seed Eq. 2.3 without the 1/alpha magnification, so every plane keeps the
centre view's framing): the plane at ``slope = 1 - 1/alpha`` is

    E(y, x) = sum_uv w_uv * L_uv(y - slope*(u - u0), x - slope*(v - v0)) / coverage(y, x)

with bilinear interpolation. Points of disparity ``d = slope`` (lfstream's HCI sign) are in
focus. Border handling: a view contributes only where its shifted image exists (no
padding); ``coverage`` is the sum of the weights that do contribute, as in Dansereau's
LFFiltShiftSum. The centre view never moves, so with a non-zero centre weight every pixel
is covered; shifts larger than the image (tiny or huge alpha) leave only views that still
overlap, and the plane tends to the centre view. A pixel no view covers is 0.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from lfstream.lightfield import check_finite, check_lf, is_tensor, read_only
from lfstream.refocus.planes import check_slopes, view_weights

if TYPE_CHECKING:
    import torch


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



#: Row bands per frame in the CPU kernel (parallel tasks; each adds one row of work per plane).
_BANDS = 8


def _sas_frame_numpy(lf: np.ndarray, slopes: np.ndarray, w: np.ndarray, to_uint8: bool = False) -> np.ndarray:
    """One frame by the fused CPU kernel: float32 in ``[0, 1]``, or with ``to_uint8`` (uint8
    input only) the 8-bit values ``round(255 * value)`` written directly."""
    from lfstream.refocus._kernels import shift_sum_separable

    u, v, h, wd, c = lf.shape
    if lf.dtype not in (np.uint8, np.float32):
        lf = lf.astype(np.float32)
    to_uint8 = to_uint8 and lf.dtype == np.uint8
    y_int, y_frac = _tap_offsets(slopes, u, h)
    x_int, x_frac = _tap_offsets(slopes, v, wd)
    # Broadcasting, not einsum: a BLAS call here leaves OpenBLAS threads spinning that then
    # compete with the kernel's threads (measured: 0.18 s instead of 0.12 s).
    col_cover = (w[None, :, :, None] * _axis_cover(x_int, x_frac, wd)[:, None, :, :]).sum(axis=2)
    scale = 255.0 if lf.dtype == np.uint8 else 1.0
    out = np.empty((len(slopes), h, wd * c), np.uint8 if to_uint8 else np.float32)
    shift_sum_separable(read_only(np.ascontiguousarray(lf).reshape(u, v, h, wd * c)), c, w, y_int, y_frac, x_int, x_frac,
                        col_cover.astype(np.float32), scale, to_uint8, min(_BANDS, h), out)
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
    import torch

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
    uint8_out: bool = False,
) -> np.ndarray | torch.Tensor:
    """Shift-and-sum focal stack at the given slopes; float32 in ``[0, 1]``, or with
    ``uint8_out`` and a uint8 light field on the CPU, uint8 ``round(255 * value)`` straight
    from the kernel (what :func:`~lfstream.refocus.focal_stack` returns for uint8 input).

    numpy (and CPU tensors) run the fused CPU kernel; CUDA tensors run a separable torch
    implementation on the GPU. Both compute the same numbers (see the module docstring).

    Args:
        lf: ``(U, V, H, W, C)`` or ``(T, U, V, H, W, C)``, uint8 or float in ``[0, 1]``.
        slopes: shift in pixels per view step of each plane.
        weights: ``(U, V)`` synthetic-aperture weights (default: all views equal).
        present: ``(U, V)`` bool mask of views that exist (others get weight 0).

    Returns:
        One refocused image per slope (and frame).

    Shape:
        - output: ``(K, H, W, C)`` or ``(T, K, H, W, C)``
    """
    check_lf(lf)
    check_finite(lf)
    s = check_slopes(slopes)
    u, v = int(lf.shape[-5]), int(lf.shape[-4])
    w = view_weights(u, v, weights, present)
    frames = lf if lf.ndim == 6 else lf[None]
    if is_tensor(lf):
        import torch

        if lf.device.type == "cpu":
            arr = lf.numpy() if lf.dtype in (torch.uint8, torch.float32) else lf.float().numpy()
            return torch.from_numpy(shift_and_sum(arr, s, w, uint8_out=uint8_out))
        res = torch.stack([_sas_frame_torch(f, s, w) for f in frames])
    elif lf.ndim == 5:
        return _sas_frame_numpy(np.asarray(lf), s, w, uint8_out)
    else:
        res = np.stack([_sas_frame_numpy(np.asarray(f), s, w, uint8_out) for f in frames])
    return res if lf.ndim == 6 else res[0]


__all__ = ["shift_and_sum"]
