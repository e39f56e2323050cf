"""Building blocks shared by the three networks (JPEG-Hance, Depth-Net, RefNet)."""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
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


def conv_elu(cin: int, cout: int, stride: int = 1, dilation: int = 1) -> nn.Sequential:
    """A 3x3 convolution (padding keeps the size, or halves it with ``stride`` 2) and an ELU."""
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride=stride, padding=dilation, dilation=dilation), ELU())


def add_unet_layers(module: nn.Module, cin: int, widths: tuple[int, int, int, int], fuse: int,
                    deep: tuple[int, ...] = (1,)) -> None:
    """The layers of the small U-Nets (the hint refiner, the seed's Depth-Net) as attributes
    of ``module`` (``full``, ``down1`` .. ``down3``, ``up2``, ``up1``, ``fuse``): ``widths``
    channels at full, 1/2, 1/4 and 1/8 resolution; at 1/8, after the strided convolution, one
    more convolution per entry of ``deep`` (its dilation); :func:`unet_down` and
    :func:`unet_up` run them."""
    w0, w1, w2, w3 = widths
    module.full = conv_elu(cin, w0)
    module.down1 = conv_elu(w0, w1, 2)
    module.down2 = nn.Sequential(conv_elu(w1, w2, 2), conv_elu(w2, w2))
    module.down3 = nn.Sequential(conv_elu(w2, w3, 2), *(conv_elu(w3, w3, dilation=d) for d in deep))
    module.up2 = conv_elu(w3 + w2, w2)
    module.up1 = conv_elu(w2 + w1, w1)
    module.fuse = conv_elu(w1 + w0, fuse)


def unet_down(x: torch.Tensor, multiple: int, full: nn.Module, down1: nn.Module, down2: nn.Module,
              down3: nn.Module) -> tuple[torch.Tensor, ...]:
    """The down-sampling half of the small U-Nets: ``x`` padded (replicated) to a multiple of
    ``multiple``, in channels-last layout (the centre view's own layout, lost in a cat or a pad:
    oneDNN's convolutions of these few channels run several times faster so, outputs within
    1e-7), through the four levels.

    Shape:
        - x: ``(B, C, H, W)``; output: ``(f0, f1, f2, f3)`` at full, 1/2, 1/4 and 1/8 of the padded size
    """
    h, w = x.shape[-2:]
    ph, pw = (-h) % multiple, (-w) % multiple
    if ph or pw:
        x = F.pad(x, (0, pw, 0, ph), mode="replicate")
    f0 = full(x.contiguous(memory_format=torch.channels_last))
    f1 = down1(f0)
    f2 = down2(f1)
    return f0, f1, f2, down3(f2)


def unet_up(features: tuple[torch.Tensor, ...], up2: nn.Module, up1: nn.Module, fuse: nn.Module) -> torch.Tensor:
    """The up-sampling half of the small U-Nets (the hint refiner, the seed's Depth-Net):
    ``features`` ``(f0, f1, f2, f3)`` at full, 1/2, 1/4 and 1/8 resolution; each level
    bilinearly up-sampled to the next and concatenated with it.

    Shape:
        - features: ``(B, C_k, H / 2^k, W / 2^k)``; output: ``fuse``'s at ``(H, W)``
    """
    f0, f1, f2, f3 = features
    y = up2(torch.cat([F.interpolate(f3, size=f2.shape[-2:], mode="bilinear", align_corners=False), f2], 1))
    y = up1(torch.cat([F.interpolate(y, size=f1.shape[-2:], mode="bilinear", align_corners=False), f1], 1))
    return fuse(torch.cat([F.interpolate(y, size=f0.shape[-2:], mode="bilinear", align_corners=False), f0], 1))


def count_params(model: nn.Module) -> int:
    """Parameters (all of them are trainable in lfstream's networks; counted regardless of
    ``requires_grad`` so a frozen network reports the same number)."""
    return sum(p.numel() for p in model.parameters())
