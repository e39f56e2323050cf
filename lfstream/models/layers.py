"""Building blocks shared by the three networks (JPEG-Hance, Depth-Net, RefNet)."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


def norm_layer(kind: str, channels: int) -> nn.Module:
    """``"batch"``, ``"instance"`` (affine, no running stats: finite on constant images) or ``"none"``."""
    if kind == "batch":
        return nn.BatchNorm2d(channels)
    if kind == "instance":
        return nn.InstanceNorm2d(channels, affine=True, track_running_stats=False)
    if kind == "none":
        return nn.Identity()
    raise ValueError(f"unknown norm {kind!r}")


def elu_(x: torch.Tensor) -> torch.Tensor:
    """ELU with alpha 1, in place; returns ``x``. Dense float32 and bfloat16 tensors on the
    CPU go through lfstream's kernels (:mod:`lfstream.models._kernels`: about 3x faster than
    PyTorch's, whose ``expm1`` does not vectorise; float32 within 4e-7 relative, bfloat16
    rounded from it as PyTorch rounds its own); anything else through PyTorch's ``elu_``.
    No gradient flows through the kernels: for inference (tensors that do not require one).

    Shape:
        - x: any; output: the same tensor
    """
    if x.device.type != "cpu" or x.dtype not in (torch.float32, torch.bfloat16) or x.requires_grad:
        return nn.functional.elu(x, 1.0, inplace=True)
    if x.is_contiguous():
        flat = x.view(-1)
    elif x.ndim == 4 and x.is_contiguous(memory_format=torch.channels_last):
        flat = x.permute(0, 2, 3, 1).reshape(-1)  # a view: the permuted tensor is contiguous
    else:
        return nn.functional.elu(x, 1.0, inplace=True)
    from lfstream.models._kernels import elu_bfloat16_, elu_float32_

    if x.dtype == torch.float32:
        elu_float32_(flat.numpy())
    else:
        elu_bfloat16_(flat.view(torch.int16).numpy().view(np.uint16))
    return x


class ELU(nn.ELU):
    """``nn.ELU`` that overwrites its input where no gradient is recorded (inference), with
    :func:`elu_` (alpha 1): no new tensor per activation, and on the CPU the fused kernels;
    out of place through PyTorch where autograd records (training). Every use in lfstream's
    networks follows a layer whose output nothing else reads (a convolution, a norm, a
    residual sum), so overwriting it is safe. Measured on two CPU cores, JPEG-Hance fast on a
    375 x 540 view: 57.8 -> 39.3 ms in place (float32, the output equal to the bit); the
    kernels then took the bfloat16 network from 45-59 to 30-31 ms and float32 from 74-78 to
    59-63 (with :class:`Bottleneck`'s sum in place, 47-49), the uint8 outputs equal to the bit
    on a lytro_bikes view."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if torch.is_grad_enabled() and x.requires_grad:
            return nn.functional.elu(x, self.alpha)
        if self.alpha != 1.0:
            return nn.functional.elu(x, self.alpha, inplace=True)
        return elu_(x)


def activation(kind: str) -> nn.Module:
    return {"elu": ELU, "relu": nn.ReLU, "softplus": nn.Softplus}[kind]()


class Bottleneck(nn.Module):
    """Residual bottleneck ``1x1 (in -> mid) -> 3x3 (mid -> mid, stride) -> 1x1 (mid -> out)``,
    norm + activation after each conv, a 1x1 projection on the skip when the shape changes.

    Shape:
        - input: ``(B, in, H, W)``; output: ``(B, out, H / stride, W / stride)``
    """

    def __init__(self, cin: int, mid: int, cout: int, norm: str, act: str, stride: int = 1) -> None:
        super().__init__()
        bias = norm == "none"
        self.body = nn.Sequential(
            nn.Conv2d(cin, mid, 1, bias=bias), norm_layer(norm, mid), activation(act),
            nn.Conv2d(mid, mid, 3, stride=stride, padding=1, bias=bias), norm_layer(norm, mid), activation(act),
            nn.Conv2d(mid, cout, 1, bias=bias), norm_layer(norm, cout),
        )
        self.skip = (nn.Identity() if cin == cout and stride == 1 else
                     nn.Sequential(nn.Conv2d(cin, cout, 1, stride=stride, bias=bias), norm_layer(norm, cout)))
        self.out_act = activation(act)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # at inference the sum goes into the body's fresh output (a new 24 x 375 x 540 tensor
        # per block was fresh pages from the kernel: 10 of JPEG-Hance fast's 50 ms a view)
        return self.out_act(add_(self.body(x), self.skip(x)))


def add_(y: torch.Tensor, other: torch.Tensor) -> torch.Tensor:
    """``y + other``: into ``y`` where no gradient is recorded for either and ``y`` can hold
    the sum (same shape and dtype, not a view of ``other``), else a new tensor (always while
    autograd records, as in training). For a ``y`` nothing else reads (a layer's fresh output).

    Shape:
        - y, other: broadcastable; output: their broadcast shape
    """
    if torch.is_grad_enabled() and (y.requires_grad or other.requires_grad):
        return y + other
    if y.shape == torch.broadcast_shapes(y.shape, other.shape) and y.dtype == torch.result_type(y, other) \
            and not (y.untyped_storage().data_ptr() == other.untyped_storage().data_ptr()):
        return y.add_(other)
    return y + other


def count_params(model: nn.Module) -> int:
    """Parameters (all of them are trainable in lfstream's networks; counted regardless of
    ``requires_grad`` so a frozen network reports the same number)."""
    return sum(p.numel() for p in model.parameters())
