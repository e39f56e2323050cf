"""The seed's Depth-Net path: the centre view's disparity from the decoded centre view alone.

The dissertation's decoder receives only the (JPEG) centre view, restores it (JPEG-Hance)
and predicts every view's disparity with Depth-Net. :class:`CentreDepthNet` is that network
at a size a CPU decoder can run: a small U-Net with a global-context branch (the scene's
overall depth is a property of the whole picture, not of a patch) that predicts one map,
the centre view's disparity in pixels per view step (lfstream's HCI sign). The decoder then
derives each view's map and warps exactly as it does with the encoder's hint
(:func:`lfstream.codec.warp.warp_views`: forward splatting with a z-test, holes from the
background side), so one network serves any view grid and any view axes.

Trained without ground truth (``tools/train.py centre_depth``): the decoded centre view is
warped by the predicted disparity into every view and compared with the true views
(photometric L1 with an edge-aware smoothness term), on the shared real captures and the
synthetic generator's clips.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from lfstream.models.layers import ELU, add_unet_layers, unet_down, unet_up


@dataclass(frozen=True)
class CentreDepthConfig:
    """Shape of :class:`CentreDepthNet`.

    Attributes:
        max_disparity: the output range ``[-max, max]`` px per view step.
        widths: channels at full resolution, 1/2, 1/4, 1/8.
        fuse: channels of the full-resolution layer that joins the up-sampled features to the
            centre view's own.
        hint: always ``False`` (the network takes the centre view alone); kept so callers can
            ask any Depth-Net whether it takes the hint.
    """

    max_disparity: float = 8.0
    widths: tuple[int, int, int, int] = (12, 24, 32, 48)
    fuse: int = 12
    hint: bool = False


class CentreDepthNet(nn.Module):
    """The centre view's disparity from the centre view alone.

    Shape:
        - centre: ``(B, 3, H, W)`` float in ``[0, 1]``
        - output: ``(B, 1, H, W)`` float32, px per view step, within ``±max_disparity``
    """

    def __init__(self, config: CentreDepthConfig = CentreDepthConfig()) -> None:
        super().__init__()
        self.config = config
        w3 = config.widths[3]
        add_unet_layers(self, 3, config.widths, config.fuse, deep=(2, 4))  # dilated: a wider view at 1/8
        self.context = nn.Sequential(nn.Linear(w3, w3), ELU())  # the whole picture's features
        self.head = nn.Conv2d(config.fuse, 1, 3, padding=1)
        nn.init.zeros_(self.head.weight)  # untrained: disparity 0 everywhere (the flat decode)
        nn.init.zeros_(self.head.bias)

    def forward(self, centre: torch.Tensor) -> torch.Tensor:
        b, _, h, w = centre.shape
        # padded to a multiple of 8: the three strided levels
        f0, f1, f2, f3 = unet_down(centre * 2 - 1, 8, self.full, self.down1, self.down2, self.down3)
        f3 = f3 + self.context(f3.mean(dim=(2, 3)))[:, :, None, None]
        y = unet_up((f0, f1, f2, f3), self.up2, self.up1, self.fuse)
        return (torch.tanh(self.head(y)) * self.config.max_disparity)[:, :, :h, :w]


def predict_centre_disparity(centres, model: CentreDepthNet, device: str = "cpu", precision: str = "auto"):
    """The centre views' disparities, batched: ``centres`` ``(B, H, W, 3)`` uint8 (numpy) to
    ``(B, H, W)`` float32 numpy, finite.

    Shape:
        - centres: ``(B, H, W, 3)``; output: ``(B, H, W)``
    """
    import numpy as np

    from lfstream.models.device import inference_precision

    x = torch.from_numpy(np.ascontiguousarray(centres)).to(device).permute(0, 3, 1, 2).float() / 255.0
    with torch.inference_mode(), inference_precision(device, precision):
        d = model(x)
    out = d[:, 0].float().cpu().numpy()
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)


__all__ = ["CentreDepthConfig", "CentreDepthNet", "predict_centre_disparity"]
