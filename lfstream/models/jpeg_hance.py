"""JPEG-Hance (seed §3.3.1.1, Fig. 3.1): a residual CNN that removes JPEG artefacts from
the decoded centre view.

Architecture: a 3x3 stem, stages of residual bottleneck blocks (1x1 -> 3x3 -> 1x1, batch
norm + ELU) joined by channel-changing 1x1 convolutions, a long skip from the stem to the
last stage, and a final 3x3 convolution whose tanh-bounded output, scaled by the config's
``strength``, is added to the input.
Images are scaled to ``[-1, 1]`` inside the network; the functions here take and return
float in ``[0, 1]``.

Presets (the same code): ``paper`` (≈ 201k parameters, the seed's size) and ``fast``
(narrower, chosen by measured CPU time; see ``bench/networks.py``). Both restore the
decoder's post-filtered JPEG and run without batch norm (the seed's blocks have it; a
network trained on real views without it kept black backgrounds black).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from lfstream.errors import LFShapeError
from lfstream.lightfield import to_network_input
from lfstream.models.device import inference_precision
from lfstream.models.layers import ELU, Bottleneck, add_, count_params


@dataclass(frozen=True)
class HanceConfig:
    """Widths of JPEG-Hance.

    Attributes:
        stem: channels after the 3x3 stem (and of the long skip).
        stages: ``(channels, blocks)`` per stage; a 1x1 conv changes the width between stages.
        norm: normalisation in the blocks (``"batch"``, ``"instance"``, ``"none"``).
        after_deblock: the network restores the decoder's post-filtered JPEG
            (:func:`lfstream.codec.centre.jpeg.deblock_jpeg`) rather than the plain decoded one; the
            decoder filters first when this is set.
        strength: the share of its trained correction the network applies (the correction
            is trained at 1 and scaled by this where it runs: a network trained on three
            scenes over-corrects scenes it has not seen, and this is the share measured to
            serve scenes left out of its training best; ``tools/hance_strength.py``).
    """

    stem: int = 64
    stages: tuple[tuple[int, int], ...] = ((64, 2), (96, 2), (64, 2))
    norm: str = "batch"
    after_deblock: bool = False
    strength: float = 1.0


HANCE_PRESETS: dict[str, HanceConfig] = {
    # the seed's widths, trained like fast (2026-11-27, on this CPU: 3,000 + 800 steps, 47
    # min): on the decoded LF of the held-out scenes +0.30 / +0.65 / +0.22 dB at q50, where
    # the seed's recipe (batch norm, plain JPEG input, synthetic renders) gave -0.31 / +0.05 / +0.07
    "paper": HanceConfig(stem=64, stages=((64, 2), (100, 4), (64, 2)), norm="none", after_deblock=True),
    # trained on real views after the decoder's post-filter (tools/train.py, recipe in the
    # manifest); no batch norm: its running statistics, taken on textured crops, pushed the
    # mostly black rendered seahorse view to SSIM 0.89 in a held-out test (0.99 without).
    # Four blocks (each output sees 6 pixels around it; two blocks saw 4), affordable with
    # lfstream's ELU kernels (lfstream.models._kernels). Its correction at 0.617, the mean
    # best share on the decoded LF of each training scene left out of a training of the
    # others (tools/hance_strength.py: lytro_bikes 0.637, dino 0.751, toys_array 0.464):
    # at full strength the held-out scenes' decoded LF gained -0.070 / +0.400 / +0.090 dB
    # (seahorse, cotton, lytro_translucent), over-corrected on two of them
    "fast": HanceConfig(stem=24, stages=((24, 4),), norm="none", after_deblock=True, strength=0.617),
}


class JPEGHance(nn.Module):
    """JPEG artefact removal network.

    Shape:
        - input: ``(B, 3, H, W)`` float in ``[0, 1]`` (any H, W)
        - output: same shape, float in ``[0, 1]``
    """

    def __init__(self, config: HanceConfig = HANCE_PRESETS["fast"]) -> None:
        super().__init__()
        self.config = config
        self.stem = nn.Sequential(nn.Conv2d(3, config.stem, 3, padding=1), ELU())
        layers: list[nn.Module] = []
        prev = config.stem
        for channels, blocks in config.stages:
            if channels != prev:
                layers += [nn.Conv2d(prev, channels, 1), ELU()]
            layers += [Bottleneck(channels, max(channels // 2, 4), channels, config.norm, "elu") for _ in range(blocks)]
            prev = channels
        if prev != config.stem:
            layers += [nn.Conv2d(prev, config.stem, 1), ELU()]
        self.body = nn.Sequential(*layers)
        self.head = nn.Conv2d(config.stem, 3, 3, padding=1)
        # Start as the identity: the untrained network returns its input.
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        s = x * 2 - 1
        f = self.stem(s)
        # long skip, bounded correction (at inference the sum into the body's fresh output)
        r = torch.tanh(self.head(add_(self.body(f), f)))
        if self.config.strength != 1.0:
            r = r * self.config.strength
        return ((s + r).clamp(-1, 1) + 1) * 0.5


def jpeg_hance(image: torch.Tensor, model: JPEGHance) -> torch.Tensor:
    """Restores JPEG-decoded images; pure function of ``image`` for a model in eval mode.

    Args:
        image: float in ``[0, 1]``.
        model: a (trained) :class:`JPEGHance`.

    Shape:
        - image: ``(B, 3, H, W)`` or ``(3, H, W)``; output: the same
    """
    if image.ndim not in (3, 4) or image.shape[-3] != 3:
        raise LFShapeError(f"image: expected (B, 3, H, W) or (3, H, W), got {tuple(image.shape)}")
    batched = image if image.ndim == 4 else image[None]
    out = model(batched)
    return out if image.ndim == 4 else out[0]


#: On the CPU, JPEG-Hance runs on row strips whose widest activation takes at most this many
#: bytes (:func:`restore_images`): the whole 375 x 540 view's activations (24 channels, 19 MB
#: each, four or five alive at once) were fresh pages from the kernel at every layer, faulted
#: in and zeroed, where glibc trims its heap above twice its (dynamic) mmap threshold; in a
#: process that has freed light-field-sized arrays (a decoder's) the strips' smaller ones are
#: reused (the same bytes, much less time). In a fresh process, the same time.
HANCE_STRIP_BYTES = 10 << 20


def receptive_radius(config: HanceConfig) -> int:
    """How far (pixels) an output pixel of JPEG-Hance sees: the stem's and the head's 3x3
    convolutions and one 3x3 per bottleneck block (the rest is 1x1 and pointwise)."""
    return 2 + sum(blocks for _, blocks in config.stages)


def _widest(config: HanceConfig) -> int:
    return max(config.stem, *(channels for channels, _ in config.stages))


def restore_in_strips(x: torch.Tensor, model: JPEGHance, rows: int) -> torch.Tensor:
    """``model(x)`` computed ``rows`` output rows at a time, each strip with the context rows
    its receptive field needs (:func:`receptive_radius`): the same values as the whole
    image's forward pass (the convolutions see the same inputs; the image's own top and
    bottom keep their zero padding), not batch- or instance-normalised statistics, which
    a strip would change (an ``"instance"`` norm runs whole).

    Shape:
        - x: ``(B, 3, H, W)``; output: the same
    """
    h = x.shape[-2]
    if rows >= h or model.config.norm == "instance":
        return model(x)
    halo = receptive_radius(model.config)
    out = torch.empty_like(x)
    for y0 in range(0, h, rows):
        y1 = min(h, y0 + rows)
        a, b = max(0, y0 - halo), min(h, y1 + halo)
        out[:, :, y0:y1] = model(x[:, :, a:b])[:, :, y0 - a:y1 - a]
    return out


@torch.inference_mode()
def restore_images(images: np.ndarray, model: JPEGHance, device: str | torch.device = "cpu",
                   precision: str = "auto") -> np.ndarray:
    """JPEG-Hance on decoded uint8 images: one batched forward pass on a GPU; on the CPU image
    by image in row strips of at most :data:`HANCE_STRIP_BYTES` an activation
    (:func:`restore_in_strips`, the same bytes), in bfloat16 where the CPU has it natively
    (``precision``: :func:`lfstream.models.device.inference_precision`; within a level or
    two of float32 on a few per cent of the samples).

    Shape:
        - images: ``(B, H, W, 3)`` uint8; output: the same
    """
    if images.ndim != 4 or images.shape[-1] != 3 or images.dtype != np.uint8:
        raise LFShapeError(f"images: expected (B, H, W, 3) uint8, got {images.dtype} {tuple(images.shape)}")
    x = to_network_input(images, device)
    with inference_precision(str(x.device), precision) as half_width:
        if x.device.type == "cpu":  # image by image (a batch only widens the activations here)
            itemsize = 2 if half_width else 4
            rows = max(8, HANCE_STRIP_BYTES // max(1, _widest(model.config) * x.shape[-1] * itemsize))
            parts = [restore_in_strips(x[k:k + 1], model, rows) for k in range(len(x))]
            y = parts[0] if len(parts) == 1 else torch.cat(parts)
        else:
            y = model(x).float()
    y = y.mul_(255.0).add_(0.5).clamp_(0, 255).to(torch.uint8)
    return np.ascontiguousarray(y.permute(0, 2, 3, 1).cpu().numpy())


def build_jpeg_hance(preset: str = "fast") -> JPEGHance:
    return JPEGHance(HANCE_PRESETS[preset])


__all__ = ["HanceConfig", "HANCE_PRESETS", "JPEGHance", "jpeg_hance", "restore_images", "restore_in_strips",
           "receptive_radius", "HANCE_STRIP_BYTES", "build_jpeg_hance", "count_params"]
