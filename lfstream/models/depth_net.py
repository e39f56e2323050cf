"""Depth-Net (seed §3.3.1.2, Figs. 3.2-3.3): one disparity map per view from the centre view.

Architecture: a 7x7 strided stem, strided down-sampling stages of residual bottleneck
blocks with instance norm, transposed-convolution up-samplers with additive skips from
the encoder, and a 3x3 head with ``U*V`` output channels, ``tanh`` scaled to
``max_disparity``. The input is padded (reflect) to a multiple of the total stride and
the output cropped back. With ``hint=True`` the encoder's depth hint (scaled by
``max_disparity``) is a fourth input channel and the output is the hint plus the predicted
per-view correction (so the untrained network reproduces the hint).

``out_stride`` > 1 (the ``fast`` preset) stops the decoder at that fraction of the input
resolution and upsamples the disparities bilinearly: disparity is smooth where it matters
for warping and the full-resolution layers dominate the CPU time.

The ``fast`` preset is :class:`DepthRefiner`: a refiner that cannot lose. It takes the
restored centre view and the decoded hint, and adds a correction to the per-view maps the
decoder's own warp derives from the hint (:func:`lfstream.codec.warp.cpu.view_disparities`:
splatted with a z-test, holes from the background side); its last layer starts at zero,
so the untrained network decodes exactly what ``depth="hint"`` decodes.

Output convention: ``d[u, v]`` is the disparity of view ``(u, v)`` in pixels per view step
(lfstream's HCI sign); view ``(u, v)`` is synthesised by
``L(x, u) = C(x + (u - u0) * d(x, u))`` (:func:`lfstream.warp.warp_views_per_view`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from lfstream.errors import LFShapeError, LFValueError
from lfstream.lightfield import to_network_input
from lfstream.models.device import inference_precision
from lfstream.models.layers import ELU, Bottleneck, add_, add_unet_layers, count_params, unet_down, unet_up


@dataclass(frozen=True)
class DepthNetConfig:
    """Shape of Depth-Net.

    Attributes:
        views: ``(U, V)``: one output map per view.
        stem: channels of the 7x7 stride-2 stem.
        stages: ``(channels, blocks)`` per encoder stage; each stage halves the resolution.
        expansion: bottleneck width = channels / expansion.
        out_stride: resolution of the predicted maps relative to the input (1, 2, 4, ...).
        max_disparity: output range ``[-max, max]`` px per view step.
        hint: take the depth hint as a fourth input channel.
    """

    views: tuple[int, int] = (7, 7)
    stem: int = 64
    stages: tuple[tuple[int, int], ...] = ((256, 3), (512, 4), (1024, 6), (2048, 3))
    expansion: int = 4
    out_stride: int = 1
    max_disparity: float = 4.0
    hint: bool = False

    @property
    def multiple(self) -> int:
        return 2 ** (1 + len(self.stages))


DEPTH_PRESETS: dict[str, DepthNetConfig] = {
    "paper": DepthNetConfig(stem=64, stages=((256, 3), (512, 4), (1024, 9), (2048, 3))),
}


class DepthNet(nn.Module):
    """Per-view disparity from the centre view (and optionally the depth hint).

    Shape:
        - centre: ``(B, 3, H, W)`` float in ``[0, 1]``; hint: ``(B, 1, H, W)`` px per view step
        - output: ``(B, U, V, H, W)`` float32, px per view step
    """

    def __init__(self, config: DepthNetConfig = DEPTH_PRESETS["paper"]) -> None:
        super().__init__()
        self.config = config
        cin = 4 if config.hint else 3
        self.stem = nn.Sequential(nn.Conv2d(cin, config.stem, 7, stride=2, padding=3, bias=False),
                                  nn.InstanceNorm2d(config.stem, affine=True), ELU())
        self.down = nn.ModuleList()
        prev = config.stem
        widths = [config.stem]
        for channels, blocks in config.stages:
            mid = max(channels // config.expansion, 8)
            stage = [Bottleneck(prev, mid, channels, "instance", "elu", stride=2)]
            stage += [Bottleneck(channels, mid, channels, "instance", "elu") for _ in range(blocks - 1)]
            self.down.append(nn.Sequential(*stage))
            widths.append(channels)
            prev = channels
        # up-samplers: from the deepest level back to the stem's resolution (stride 2), and
        # one more to full resolution only when out_stride == 1
        levels = len(config.stages)
        # the up-samplers end at level log2(out_stride) - 1 (-1: full resolution, 0: the stem's)
        stop = int(round(math.log2(config.out_stride))) - 1
        self.up = nn.ModuleList()
        self.skip_index: list[int] = []
        for level in range(levels - 1, stop - 1, -1):
            target = widths[level] if level >= 0 else max(config.stem // 2, 16)
            self.up.append(nn.Sequential(nn.ConvTranspose2d(prev, target, 2, stride=2), ELU()))
            self.skip_index.append(level)
            prev = target
        self.head = nn.Conv2d(prev, config.views[0] * config.views[1], 3, padding=1)
        nn.init.zeros_(self.head.bias)
        nn.init.normal_(self.head.weight, std=1e-3)  # start near flat disparity

    def forward(self, centre: torch.Tensor, hint: torch.Tensor | None = None) -> torch.Tensor:
        cfg = self.config
        b, _, h, w = centre.shape
        x = centre * 2 - 1
        if cfg.hint:
            if hint is None:
                raise LFShapeError("this Depth-Net takes the depth hint as an input; pass hint=")
            x = torch.cat([x, hint / cfg.max_disparity], 1)
        m = cfg.multiple
        # pad to a multiple of the total stride, and to at least 2 x 2 at the deepest level
        # (instance norm needs more than one spatial element)
        ph, pw = max((-h) % m, 2 * m - h), max((-w) % m, 2 * m - w)
        if ph or pw:
            mode = "reflect" if ph < h and pw < w else "replicate"
            x = F.pad(x, (0, pw, 0, ph), mode=mode)
        feats = [self.stem(x)]
        for stage in self.down:
            feats.append(stage(feats[-1]))
        y = feats[-1]
        for up, level in zip(self.up, self.skip_index):
            y = up(y)
            if level >= 0:  # at inference the sum into the up-sampling's fresh output
                y = add_(y, feats[level])
        d = torch.tanh(self.head(y)) * cfg.max_disparity
        if cfg.out_stride > 1:
            d = F.interpolate(d, scale_factor=cfg.out_stride, mode="bilinear", align_corners=False)
        d = d[:, :, :h, :w]
        if cfg.hint:
            d = d + hint  # the hint variant predicts a per-view correction of the hint
        return d.reshape(b, cfg.views[0], cfg.views[1], h, w)


@dataclass(frozen=True)
class DepthRefinerConfig:
    """Shape of the hint refiner (:class:`DepthRefiner`).

    Attributes:
        widths: channels at full resolution, 1/2, 1/4, 1/8 (a small U-Net).
        fuse: channels of the full-resolution layer that joins the up-sampled features to the
            centre view's own (disparity edges follow image edges at pixel precision).
        max_correction: the correction's range ``[-max, max]`` px per view step.
        hint_scale: the hint is divided by this at the input.
        hint: always ``True`` (the refiner needs the hint); kept so callers can ask any
            Depth-Net whether it takes one.
    """

    widths: tuple[int, int, int, int] = (8, 16, 24, 32)
    fuse: int = 8
    max_correction: float = 1.0
    hint_scale: float = 4.0
    hint: bool = True

    @property
    def multiple(self) -> int:
        return 8


def view_correction(corrections, oy, ox):
    """``c0 + oy * cy + ox * cx``: the refiner's correction of the view displaced by ``(oy,
    ox)`` per unit disparity, from its three maps on axis -3 (numpy or torch; ``oy, ox``
    scalars or arrays that broadcast against a map).

    Shape:
        - corrections: ``(..., 3, H, W)``; output: ``(..., H, W)`` broadcast with ``oy, ox``
    """
    return corrections[..., 0, :, :] + oy * corrections[..., 1, :, :] + ox * corrections[..., 2, :, :]


class DepthRefiner(nn.Module):
    """Per-view disparities as the hint's per-view maps plus a learned correction.

    The correction is three maps ``c0, cy, cx`` (B, 3, H, W); view ``(u, v)`` with
    displacement ``(oy, ox)`` per unit disparity (:func:`lfstream.lightfield.view_offsets`)
    gets ``maps[u, v] + c0 + oy * cy + ox * cx``: a refined disparity plus a first-order
    dependence on the view, so one network serves any view grid and any view axes. The
    head's weights and bias start at zero: untrained, the output is ``maps`` exactly.

    Shape:
        - centre: ``(B, 3, H, W)`` float in ``[0, 1]``; hint: ``(B, 1, H, W)`` px per view step
        - view_maps: ``(B, U, V, H, W)``; offsets: ``(U, V, 2)``
        - output: ``(B, U, V, H, W)`` float32, px per view step
    """

    def __init__(self, config: DepthRefinerConfig = DepthRefinerConfig()) -> None:
        super().__init__()
        self.config = config
        add_unet_layers(self, 4, config.widths, config.fuse)
        self.head = nn.Conv2d(config.fuse, 3, 3, padding=1)
        nn.init.zeros_(self.head.weight)
        nn.init.zeros_(self.head.bias)

    def corrections(self, centre: torch.Tensor, hint: torch.Tensor) -> torch.Tensor:
        """The three correction maps ``(B, 3, H, W)``: ``c0, cy, cx``."""
        b, _, h, w = centre.shape
        x = torch.cat([centre * 2 - 1, hint / self.config.hint_scale], 1)
        f = unet_down(x, self.config.multiple, self.full, self.down1, self.down2, self.down3)
        y = unet_up(f, self.up2, self.up1, self.fuse)
        # (measured and not kept: forcing each map to zero mean over the image, so that only
        # the hint sets the global geometry: held-out seahorse -0.60, translucent -0.11,
        # cotton -0.06 dB against the hint, against -0.25 / -0.12 / -0.32 without)
        return (torch.tanh(self.head(y)) * self.config.max_correction)[:, :, :h, :w]

    @staticmethod
    def apply(corrections: torch.Tensor, view_maps: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
        """``view_maps`` plus :func:`view_correction` per view (shapes as :class:`DepthRefiner`)."""
        oy = offsets[..., 0].to(corrections)[None, :, :, None, None]
        ox = offsets[..., 1].to(corrections)[None, :, :, None, None]
        return view_maps + view_correction(corrections[:, None, None], oy, ox)

    def forward(self, centre: torch.Tensor, hint: torch.Tensor, view_maps: torch.Tensor,
                offsets: torch.Tensor) -> torch.Tensor:
        if view_maps.ndim != 5 or view_maps.shape[-2:] != centre.shape[-2:] or offsets.shape != (
                *view_maps.shape[1:3], 2):
            raise LFShapeError(f"view_maps (B, U, V, H, W) and offsets (U, V, 2) must match the centre view; got "
                               f"{tuple(view_maps.shape)}, {tuple(offsets.shape)}, {tuple(centre.shape)}")
        return self.apply(self.corrections(centre, hint), view_maps, offsets)


def grid_disparities(maps: torch.Tensor | np.ndarray, views: tuple[int, int]):
    """Maps a network's per-view disparities onto another view grid.

    Disparity is per view step, so the view at offset ``(du, dv)`` from the centre takes the
    network's map at the same offset; offsets beyond the network's grid take its outermost
    map on that side (a larger grid than the one trained for).

    Shape:
        - maps: ``(..., Un, Vn, H, W)``; output: ``(..., U, V, H, W)``
    """
    un, vn = maps.shape[-4], maps.shape[-3]
    u, v = views
    iu = [min(max(k - u // 2 + un // 2, 0), un - 1) for k in range(u)]
    iv = [min(max(k - v // 2 + vn // 2, 0), vn - 1) for k in range(v)]
    return maps[..., iu, :, :, :][..., iv, :, :]


@torch.inference_mode()
def predict_view_disparities(centres: np.ndarray, model: nn.Module, views: tuple[int, int],
                             hints: np.ndarray | None = None, device: str | torch.device = "cpu",
                             axes: list[np.ndarray | None] | None = None,
                             out: np.ndarray | None = None, precision: str = "auto") -> np.ndarray:
    """Per-view disparities of a batch of decoded centre views, on the stream's view grid.

    A :class:`DepthRefiner` corrects the per-view maps the decoder's warp derives from each
    hint (with that frame's view ``axes``), into ``out`` where given (a C-contiguous float32
    array of at least ``B`` frames: the first ``B`` are returned); a :class:`DepthNet`
    predicts them on its own grid (:func:`grid_disparities`). The network runs in bfloat16
    where the CPU has it natively (``precision``:
    :func:`lfstream.models.device.inference_precision`; corrections within about 1e-3 px of
    float32's; a zero correction stays exactly zero, so an untrained refiner still
    reproduces the hint).

    Shape:
        - centres: ``(B, H, W, 3)`` uint8; hints: ``(B, H, W)`` float32 (when the model takes one)
        - output: ``(B, U, V, H, W)`` float32
    """
    if centres.ndim != 4 or centres.shape[-1] != 3:
        raise LFShapeError(f"centres: expected (B, H, W, 3), got {tuple(centres.shape)}")
    x = to_network_input(centres, device)
    h = None
    if model.config.hint:
        if hints is None:
            raise LFValueError("this Depth-Net refines the encoder's depth hint, and the stream carries none "
                               "(encode with --depth-hint, or decode with --depth flat)")
        h = torch.from_numpy(np.ascontiguousarray(hints, np.float32)).to(device)[:, None]
    if isinstance(model, DepthRefiner):
        from lfstream.codec.warp.cpu import view_disparities

        axes = list(axes) if axes is not None else [None] * len(centres)
        with inference_precision(str(x.device), precision):
            corr = model.corrections(x, h)
        corr = corr.float().cpu().numpy()
        # DepthRefiner.apply in the kernel that splats the hint's maps, row by row (the same
        # values; 49 numpy sums afterwards took 12 ms at 7x7x375x540)
        if out is not None:
            if len(out) < len(corr):
                raise LFShapeError(f"out: room for {len(out)} frames, the batch has {len(corr)}")
            for k, (c, a) in enumerate(zip(corr, axes)):
                view_disparities(hints[k], views, axes=a, corrections=c, out=out[k])
            return out[: len(corr)]
        maps = [view_disparities(hints[k], views, axes=a, corrections=c) for k, (c, a) in enumerate(zip(corr, axes))]
        return maps[0][None] if len(maps) == 1 else np.stack(maps)
    with inference_precision(str(x.device), precision):
        maps = model(x, h)
    return np.ascontiguousarray(grid_disparities(maps.float().cpu().numpy(), views))


def build_depth_net(preset: str = "fast", views: tuple[int, int] = (7, 7), hint: bool | None = None) -> nn.Module:
    """An untrained Depth-Net: the ``fast`` refiner (any grid: ``views`` and ``hint`` do not
    apply) or a :class:`DepthNet` preset for ``views``."""
    from dataclasses import replace

    if preset == "fast":
        return DepthRefiner()
    cfg = DEPTH_PRESETS[preset]
    return DepthNet(replace(cfg, views=tuple(views), hint=cfg.hint if hint is None else hint))


__all__ = ["DepthNetConfig", "DEPTH_PRESETS", "DepthNet", "DepthRefiner", "DepthRefinerConfig", "view_correction",
           "grid_disparities", "predict_view_disparities", "build_depth_net", "count_params"]
