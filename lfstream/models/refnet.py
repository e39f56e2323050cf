"""RefNet (seed ch. 4, Figs. 4.1-4.2): a residual CNN mapping a light field to a focal stack.

The LF is reshaped to ``(U*V*3, H, W)``; a 3x3 convolution to ``F`` channels + ReLU, residual
blocks (1x1 F -> 3x3 F/2 -> 1x1 F, softplus + instance norm, a 1x1 projection on the skip
when the width changes), two 3x3 convolutions with ReLU and a 3x3 output convolution give
``planes * 3`` channels, reshaped to ``planes`` RGB images. The output is a residual on the
mean of all views (the refocused image at alpha = 1), so an untrained network starts from
a plausible image.

``unshuffle`` > 1 (the ``fast`` preset) runs the network on a space-to-depth rearrangement
(``pixel_unshuffle``) of the input and rearranges back at the end: 1/s^2 of the spatial
work and s times the receptive field, which large |slope| planes need.

Any ``U x V`` works: the grid is a constructor argument (a network is trained for one grid).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from lfstream.errors import LFShapeError
from lfstream.models.layers import Bottleneck, count_params
from lfstream.optics import SEED_ALPHAS

# RefNet runs in float32: bfloat16 autocast on CPU lost 0.106 dB PSNR against SaS on a
# synthetic 7x7x48x64 LF (budget 0.1 dB; tests/test_stability.py).
INFERENCE_DTYPE = torch.float32


@dataclass(frozen=True)
class RefNetConfig:
    """Shape of RefNet.

    Attributes:
        views: ``(U, V)`` the network is built (and trained) for.
        planes: refocused images per LF (16: alpha = 0.125 .. 2.0).
        widths: output width of each residual block (the first conv maps to ``widths[0]``).
        head: width of the two convolutions after the blocks.
        unshuffle: space-to-depth factor (1 = full resolution).
        kernel: kernel size of the entry and output convolutions (1 keeps the wide
            unshuffled entry and exit cheap).
    """

    views: tuple[int, int] = (7, 7)
    planes: int = len(SEED_ALPHAS)
    widths: tuple[int, ...] = (192,) * 11
    head: int = 192
    unshuffle: int = 1
    kernel: int = 3


REFNET_PRESETS: dict[str, RefNetConfig] = {
    "paper": RefNetConfig(widths=(192, 256, 384, 512, 640, 736, 736, 640, 512, 384, 192), head=192),
    "fast": RefNetConfig(widths=(48, 48, 48, 48), head=48, unshuffle=4, kernel=1),
}


class RefNet(nn.Module):
    """Light field to focal stack.

    Shape:
        - input: ``(B, U, V, 3, H, W)`` float in ``[0, 1]``
        - output: ``(B, planes, 3, H, W)`` float in ``[0, 1]``
    """

    def __init__(self, config: RefNetConfig = REFNET_PRESETS["fast"]) -> None:
        super().__init__()
        self.config = config
        s = config.unshuffle
        cin = config.views[0] * config.views[1] * 3 * s * s
        f0 = config.widths[0]
        k = config.kernel
        self.entry = nn.Sequential(nn.Conv2d(cin, f0, k, padding=k // 2), nn.ReLU())
        blocks = []
        prev = f0
        for width in config.widths:
            blocks.append(Bottleneck(prev, max(width // 2, 4), width, "instance", "softplus"))
            prev = width
        self.blocks = nn.Sequential(*blocks)
        self.tail = nn.Sequential(nn.Conv2d(prev, config.head, 3, padding=1), nn.ReLU(),
                                  nn.Conv2d(config.head, config.head, 3, padding=1), nn.ReLU(),
                                  nn.Conv2d(config.head, config.planes * 3 * s * s, k, padding=k // 2))
        nn.init.zeros_(self.tail[-1].weight)
        nn.init.zeros_(self.tail[-1].bias)

    def forward(self, lf: torch.Tensor) -> torch.Tensor:
        cfg = self.config
        if lf.ndim != 6 or tuple(lf.shape[1:3]) != tuple(cfg.views) or lf.shape[3] != 3:
            raise LFShapeError(f"RefNet built for {cfg.views[0]}x{cfg.views[1]} RGB views: expected "
                               f"(B, {cfg.views[0]}, {cfg.views[1]}, 3, H, W), got {tuple(lf.shape)}")
        b, u, v, c, h, w = lf.shape
        s = cfg.unshuffle
        ph, pw = (-h) % s, (-w) % s
        x = lf.reshape(b, u * v * c, h, w)
        if ph or pw:
            x = F.pad(x, (0, pw, 0, ph), mode="replicate")
        base = lf.mean(dim=(1, 2))  # alpha = 1 image
        if s > 1:
            x = F.pixel_unshuffle(x, s)
        y = self.tail(self.blocks(self.entry(x)))
        if s > 1:
            y = F.pixel_shuffle(y, s)
        y = y[:, :, :h, :w].reshape(b, cfg.planes, 3, h, w)
        return (base[:, None] + y).clamp(0, 1)


def build_refnet(preset: str = "fast", views: tuple[int, int] = (7, 7)) -> RefNet:
    from dataclasses import replace

    return RefNet(replace(REFNET_PRESETS[preset], views=tuple(views)))


__all__ = ["INFERENCE_DTYPE", "RefNetConfig", "REFNET_PRESETS", "RefNet", "build_refnet", "count_params"]
