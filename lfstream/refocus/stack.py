"""Focal stacks: one entry point over shift-and-sum, Fourier slice and RefNet, and the
all-in-focus image."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from lfstream.errors import LFShapeError, LFValueError
from lfstream.lightfield import aperture_weights, check_finite, check_lf, check_samples, is_tensor, to_network_input
from lfstream.optics import SEED_ALPHAS, slopes_from_alphas
from lfstream.refocus.planes import resolve_slopes, slope_range
from lfstream.refocus.shift_sum import shift_and_sum

if TYPE_CHECKING:
    import torch

METHODS = ("sas", "fourier", "refnet")


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

    Shape:
        - lf: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)``; weights, present: ``(U, V)``
        - output: ``(K, H, W, 3)`` or ``(T, K, H, W, 3)``, K the number of planes
    """
    s = resolve_slopes(alphas, slopes)
    check_lf(lf)
    check_samples(lf)  # an int16 light field came back as a stack of ones
    u, v = int(lf.shape[-5]), int(lf.shape[-4])
    if weights is not None and aperture is not None:
        raise LFValueError("give aperture or weights, not both")
    if weights is None and aperture is not None:
        weights = aperture_weights((u, v), aperture, aperture_shape)
    if method == "sas":
        if method_options:
            raise LFValueError(f"options {sorted(method_options)} apply to method='fourier' only")
        # uint8 in, uint8 out: the kernel rounds as it writes (no float stack to convert)
        out = shift_and_sum(lf, s, weights, present, uint8_out=True)
        if str(out.dtype) in ("uint8", "torch.uint8"):
            return out
    elif method == "fourier":
        from lfstream.refocus.fourier import fourier_slice  # torch's FFT

        out = fourier_slice(lf, s, weights, present, **method_options)
    elif method == "refnet":
        if weights is not None or present is not None:
            raise LFValueError("method='refnet' renders the full aperture of a complete light field; "
                               "aperture, weights and missing views need 'sas' or 'fourier'")
        out = refnet_stack(lf, s, **method_options)
    else:
        raise LFValueError(f"method: one of {', '.join(METHODS)}, got {method!r}")
    return _to_input_range(out, lf)


def refnet_stack(lf, slopes: np.ndarray, device: str | None = None, preset: str = "fast"):
    """Focal stack by the shipped RefNet (see :mod:`lfstream.models.refnet`), float in ``[0, 1]``.

    Shape:
        - lf: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)``; output ``(16, H, W, 3)`` or ``(T, 16, H, W, 3)``
    """
    seed = slopes_from_alphas(SEED_ALPHAS)
    if np.shape(slopes) != np.shape(seed) or not np.allclose(slopes, seed, atol=1e-6):
        raise LFValueError("method='refnet' renders the seed's sixteen alphas (0.125 ... 2.0) only")
    import torch

    is_torch = isinstance(lf, torch.Tensor)
    dev = device or (str(lf.device) if is_torch else "cpu")
    from lfstream.models.registry import shipped_model

    model = shipped_model("refnet", preset, str(dev))
    if lf.shape[-1] != 3 or tuple(lf.shape[-5:-3]) != tuple(model.config.views):
        raise LFValueError(f"method='refnet': the shipped RefNet takes {model.config.views[0]}x{model.config.views[1]} "
                           f"RGB views, got {tuple(lf.shape[-5:-3])} with {lf.shape[-1]} channels (train one with "
                           "tools/train.py, or use 'sas')")
    from lfstream.models.refnet import INFERENCE_DTYPE

    x = to_network_input(lf, dev)
    video = x if x.ndim == 6 else x[None]
    reduced = INFERENCE_DTYPE != torch.float32
    with torch.inference_mode(), torch.autocast(torch.device(dev).type, dtype=INFERENCE_DTYPE, enabled=reduced):
        out = model(video).float().permute(0, 1, 3, 4, 2)
    out = out if x.ndim == 6 else out[0]
    return out if is_torch else out.cpu().numpy()


def _to_input_range(out, like):
    if is_tensor(out):
        import torch

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

    Args:
        lf: the light field, uint8 or float in ``[0, 1]``.
        disparity: the centre view's disparity, pixels per view step.
        planes: how many focal planes the stack has.
        weights: ``(U, V)`` view weights (``None``: all views alike).

    Returns:
        The image, in the input's value range.

    Shape:
        - lf: ``(U, V, H, W, C)``; disparity: ``(H, W)`` of the centre view
        - output: ``(H, W, C)``
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


__all__ = [
    "METHODS",
    "focal_stack",
    "refnet_stack",
    "all_in_focus",
]
