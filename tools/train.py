"""Train lfstream's networks on synthetic light fields (seed stages, resumable, CPU or GPU).

Stages, as in the seed: ``jpeg_hance`` (MSE on JPEG crops), ``depth_net`` (unsupervised
loss, JPEG-Hance frozen in front of it), ``refnet`` (SaS focal-stack labels). ``all`` runs
the three in order (Depth-Net uses the JPEG-Hance just trained). JPEG-Hance (both presets)
and Depth-Net fast train on the real samples instead (``../shared/data``): JPEG-Hance in
two phases, MSE on crops of every view, then the light field the decoder warps from the
restored centre view (:func:`hance_lf_loss`; ``--objective image`` stops after the first,
``--init shipped|FILE`` runs only the second from those weights), Depth-Net fast as the
hint refiner (:func:`refiner_batch_loss`).

    python tools/train.py all --preset fast --device cuda --out runs/fast --ship
    python tools/train.py depth_net --steps 4000 --resume --out runs/fast
    python tools/train.py jpeg_hance --init shipped --out runs/lf --ship
    # JPEG-Hance fast as shipped (12 min on the 2-core CPU), and the share of its correction
    # it applies (HanceConfig.strength; three folds, 38 min): each training scene left out
    python tools/train.py jpeg_hance --preset fast --out runs/fast-hance --ship
    python tools/hance_strength.py --out runs/hance_strength
    # JPEG-Hance paper as shipped (47 min on the 2-core CPU; --steps sets both phases' steps,
    # so the phases run apart here: 3,000 and 800)
    python tools/train.py jpeg_hance --preset paper --objective image --steps 3000 --out runs/paper
    python tools/train.py jpeg_hance --preset paper --init runs/paper/jpeg_hance-paper.pt --steps 800 \
        --out runs/paper-lf --ship

Every run is seeded; checkpoints (model, optimiser, step) are written every
``--checkpoint-every`` steps to ``OUT/NAME-PRESET.ckpt`` and ``--resume`` continues from
them; losses and validation metrics go to ``OUT/NAME-PRESET.log.jsonl``. ``--ship`` writes
the final weights into ``lfstream/weights/`` with their SHA-256, recipe and validation
metrics (the manifest the package loads from).

No dataset is downloaded: the training set is rendered by :mod:`lfstream.synth` (layered
textured scenes with occlusion, noise and vignetting), augmented with contrast, brightness
and hue jitter; validation uses held-out synthetic scenes and, when present, the real
samples in ``../shared/data``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
for path in (ROOT, ROOT / "bench"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

from _harness import SHARED, SHARED_SCENES, TRAINING_SCENES  # noqa: E402  (the shared samples' tables)

from lfstream.codec import jpeg_roundtrip  # noqa: E402
from lfstream.errors import LFStreamError  # noqa: E402
from lfstream.lightfield import to_network_input  # noqa: E402
from lfstream.models.losses import depth_net_loss, hance_loss, refnet_loss  # noqa: E402
from lfstream.models.registry import MODEL_NAMES, load_model, save_checkpoint, ship_weights, spec  # noqa: E402
from lfstream.models.warp import pixel_grid, sample_bilinear  # noqa: E402


@dataclass
class Recipe:
    """Everything that determines a training run (recorded beside shipped weights)."""

    model: str
    preset: str = "fast"
    steps: int = 2000
    batch: int = 16
    lr: float = 1e-3
    crop: int = 64
    samples: int = 256
    views: int = 7
    size: int = 128
    quality: int = 50
    seed: int = 0
    time_limit_s: float = 0.0  # stop early (and record the steps done) when > 0
    # "synthetic": the renderer; "real": every view of `scenes` in ../shared/data (JPEG-Hance
    # trained after the post-filter), JPEG at a quality drawn from `qualities`, MSE loss
    data: str = "synthetic"
    scenes: tuple[str, ...] = ()
    qualities: tuple[int, ...] = ()
    # JPEG-Hance on real data: "image" (MSE on augmented crops of every view) or "lf" (what
    # the decoder makes of the restored centre view: :func:`hance_lf_loss`, plus
    # `image_weight` times the image term); `margin`: restored context around each LF crop
    objective: str = "image"
    image_weight: float = 0.0
    margin: int = 0
    # the weights training started from: None (from scratch) or {"sha256", "recipe"} of them
    init: dict | None = None
    # the hint refiner's photometric loss: "mse" (pooled over the batch, one scene's frame)
    # or "log_mse" (its logarithm: every scene weighs by its dB, as MPSNR does)
    loss: str = "mse"
    # the hint refiner's crops mirrored at random ("flips": up-down and left-right;
    # "dihedral": and transposed), the views' offsets with them (:func:`transformed_sample`)
    flips: str = "none"


DEFAULT_STEPS = {"jpeg_hance": 3000, "depth_net": 3000, "depth_centre": 1500, "refnet": 3000}
#: Real scenes the hint refiner (Depth-Net fast) and a post-filter JPEG-Hance train on: one
#: Lytro capture, one HCI render, the camera array; seahorse, cotton and lytro_translucent
#: stay out: the held-out test.
DEPTH_TRAIN_SCENES = HANCE_TRAIN_SCENES = ("lytro_bikes", "dino", "toys_array")
#: JPEG qualities the refiner trains at.
DEPTH_QUALITIES = (30, 50, 70)
#: The refiner's loss and augmentation (3,000 steps each on the CPU,
#: held-out decoded LF against the hint at the 1/4 hint, seahorse / cotton / translucent):
#: the MSE pooled over every scene (the recipe before) -0.156 / -0.137 / -0.085 dB, the
#: high-error scene (toys_array, 19 dB) setting the corrections; its log -0.128 / -0.050 /
#: -0.043; the log with the crops mirrored -0.055 / -0.023 / -0.058; mirrored and
#: transposed -0.031 / -0.025 / -0.015 (the trained-on scenes' gains shrink with each step:
#: +0.21 / +0.08 / +0.02 on bikes / dino / toys with the log alone, +0.03 / +0.01 / +0.01)
DEPTH_REFINER_LOSS = {"loss": "log_mse", "flips": "dihedral"}
#: JPEG qualities a post-filter JPEG-Hance trains at: around the default (50) and where rate
#: control goes.
HANCE_QUALITIES = (30, 40, 50, 60, 70)
#: The second phase of JPEG-Hance fast (``--objective lf``): fine-tuned on the decoded light
#: field (:func:`hance_lf_loss`) from the image phase's weights, at half the image phase's
#: rate, 96-pixel crops with 24 pixels of restored context, 6 views each, plus half the
#: image term (chosen on the trained-on scenes' logged ``lf_gain_db``).
HANCE_LF_PHASE = {"objective": "lf", "steps": 1500, "batch": 8, "lr": 5e-4, "crop": 96, "margin": 24, "views": 6,
                  "image_weight": 0.5}
DEFAULT_BATCH = {"jpeg_hance": 32, "depth_net": 8, "depth_centre": 8, "refnet": 8}
DEFAULT_CROP = {"jpeg_hance": 64, "depth_net": 96, "depth_centre": 96, "refnet": 128}
#: The seed's Depth-Net (``depth_centre``): the real scenes it trains on (``--scenes`` names
#: others; a leave-one-out run drops the scene it is judged on), at the qualities the decoder
#: meets, unsupervised (:func:`centre_depth_batch_loss`).
CENTRE_DEPTH_SCENES = (*SHARED_SCENES, *TRAINING_SCENES)
CENTRE_DEPTH_RECIPE = {"data": "real", "qualities": (30, 50, 70), "batch": 8, "crop": 96, "views": 6, "samples": 0,
                       "loss": "log_mse", "flips": "dihedral"}
#: Weight of the edge-aware smoothness term of the seed's Depth-Net's loss.
CENTRE_DEPTH_SMOOTHNESS = 0.02


# ---------------------------------------------------------------------------------------
# data


def _render_sample(args: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """One synthetic LF and the depth hint the codec would send for it (encoded, decoded)."""
    from lfstream.codec.hint import HintOptions, decode_hint, encode_hint, estimate_disparity
    from lfstream.synth import SynthConfig, render_clip

    seed, views, size = args
    rng = np.random.default_rng(seed)
    far, near = -rng.uniform(0.3, 2.5), rng.uniform(0.3, 2.5)
    cfg = SynthConfig(frames=1, views=views, size=(size, size), layers=int(rng.integers(1, 7)),
                      disparity_range=(float(far), float(near)), slanted_background=bool(rng.random() < 0.5),
                      motion=0.0, camera_pan=0.0, noise=float(rng.choice([0.0, 1.0, 3.0])),
                      vignetting=float(rng.choice([0.0, 0.0, 0.3])), seed=seed)
    lf = render_clip(cfg).lf[0]
    opts = HintOptions()
    centre = jpeg_roundtrip(np.ascontiguousarray(lf[views // 2, views // 2]), 50)
    hint = decode_hint(encode_hint(estimate_disparity(lf, opts), opts), (size, size), guide=centre)
    return lf, hint.astype(np.float32)


def render_dataset(count: int, views: int, size: int, seed: int, workers: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` synthetic LFs ``(N, U, V, H, W, 3)`` uint8 and their decoded depth hints ``(N, H, W)``."""
    jobs = [(seed * 100003 + k, views, size) for k in range(count)]
    if workers > 1:
        with ProcessPoolExecutor(workers) as pool:
            out = list(pool.map(_render_sample, jobs, chunksize=4))
    else:
        out = [_render_sample(j) for j in jobs]
    return np.stack([o[0] for o in out]), np.stack([o[1] for o in out])


def real_views(scenes: tuple[str, ...]) -> list[np.ndarray]:
    """Every present view of ``scenes`` (``SHARED_SCENES`` keys), each ``(H, W, 3)`` uint8."""
    from lfstream.io import read_lf

    out = []
    for name in scenes:
        lf, mask = read_lf(SHARED / SHARED_SCENES[name], return_mask=True)
        out += [np.ascontiguousarray(lf[u, v]) for u, v in zip(*np.nonzero(mask))]
    return out


def real_hance_batch(views: list[np.ndarray], recipe: Recipe, rng: np.random.Generator
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Crops of real views on the 8x8 JPEG grid, (input, target) uint8 ``(B, c, c, 3)``.

    Augmented for what the training scenes lack: 30 % darkened (scale 0..0.5, minus up to 20
    levels: black backgrounds such as the rendered seahorse's), 9 % flat colour with 0..2
    levels of noise, half mirrored; then JPEG at a random recipe quality and the post-filter
    the encoder chooses for the crop (:func:`lfstream.codec.centre.jpeg.jpeg_roundtrip`), as the
    decoder would apply it.
    """
    c = recipe.crop
    xs, ys = [], []
    for _ in range(recipe.batch):
        img = views[int(rng.integers(len(views)))]
        h, w = img.shape[:2]
        y0, x0 = int(rng.integers(0, (h - c) // 8 + 1)) * 8, int(rng.integers(0, (w - c) // 8 + 1)) * 8
        crop = img[y0:y0 + c, x0:x0 + c].astype(np.float32)
        r = rng.random()
        if r < 0.3:
            crop = crop * rng.uniform(0.0, 0.5) - rng.uniform(0, 20)
        elif r < 0.39:
            crop = crop * 0 + rng.uniform(0, 255, 3) + rng.normal(0, rng.uniform(0, 2), crop.shape)
        if rng.random() < 0.5:
            crop = crop[:, ::-1]
        crop = np.ascontiguousarray(np.clip(crop + 0.5, 0, 255).astype(np.uint8))
        xs.append(jpeg_roundtrip(crop, int(rng.choice(recipe.qualities)), deblock=True))
        ys.append(crop)
    return np.stack(xs), np.stack(ys)


def augment(batch: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Contrast, brightness and hue jitter (the seed's augmentations), per item, uint8 in/out.

    Shape: ``(B, ..., 3)``; the same jitter applies to every view of an item.
    """
    out = np.empty_like(batch)
    for i, item in enumerate(batch):
        x = item.astype(np.float32) / 255.0
        contrast, bright, hue = rng.uniform(0.7, 1.3), rng.uniform(-0.1, 0.1), rng.uniform(-0.3, 0.3)
        mean = x.mean()
        x = (x - mean) * contrast + mean + bright
        # hue: rotate the chroma plane of YIQ by `hue` radians
        yiq = np.array([[0.299, 0.587, 0.114], [0.596, -0.274, -0.322], [0.211, -0.523, 0.312]], np.float32)
        c, s = math.cos(hue), math.sin(hue)
        rot = np.array([[1, 0, 0], [0, c, -s], [0, s, c]], np.float32)
        m = np.linalg.inv(yiq) @ rot @ yiq
        x = x @ m.T.astype(np.float32)
        out[i] = np.clip(x * 255.0 + 0.5, 0, 255).astype(np.uint8)
    return out


def _to_tensor(img: np.ndarray, device) -> torch.Tensor:
    """``(..., H, W, 3)`` uint8 to ``(..., 3, H, W)`` float32 in [0, 1]."""
    return to_network_input(img, device)


@dataclass
class DepthSample:
    """One decoded frame of a real scene with what the refiner sees and what it is judged on."""

    name: str
    centre: np.ndarray  # (H, W, 3) uint8, decoded and post-filtered as the decoder does
    hint: np.ndarray  # (H, W) float32, the decoded hint
    view_maps: np.ndarray  # (U, V, H, W) float32, the warp's per-view maps of the hint
    offsets: np.ndarray  # (U, V, 2) float32
    gains: np.ndarray  # (U, V, H, W, 1 or 3) float32, full resolution (ones: none)
    truth: np.ndarray  # (U, V, H, W, 3) uint8
    present: np.ndarray  # (U, V) bool


def decoded_parts(lf: np.ndarray, present: np.ndarray | None, quality: int, hint_scale: int):
    """The default encode of one frame at ``quality`` with the hint at ``1 / hint_scale``,
    decoded: the :class:`lfstream.codec.decoder.DecodedFrame` with centre, hint, axes, gains."""
    import io

    import lfstream
    from lfstream.codec.api import iter_decode
    from lfstream.codec.hint import HintOptions

    # the JPEG centre the networks restore (the default codes grids under 7x7 with AV1)
    data = lfstream.encode(lf, quality=quality, present=present, hint_options=HintOptions(hint_scale=hint_scale),
                           preset="fast")
    return next(iter_decode(io.BytesIO(data), hance="off"))


def depth_sample(name: str, lf: np.ndarray, present: np.ndarray, quality: int, hint_scale: int) -> DepthSample:
    """One LF (``(U, V, H, W, 3)`` uint8, the views ``present`` marks real) through the
    default encode at ``quality`` with the hint at ``1 / hint_scale``, decoded
    (:func:`decoded_parts`), with the per-view maps and full-resolution gains the warp uses."""
    from lfstream.codec.gains import upsample_gain
    from lfstream.codec.warp.cpu import view_disparities
    from lfstream.lightfield import view_offsets

    u, v, h, w, _ = lf.shape
    fr = decoded_parts(lf, None if present.all() else present, quality, hint_scale)
    gains = np.ones((u, v, h, w, 1), np.float32)
    if fr.gains is not None:
        gains = np.stack([np.stack([upsample_gain(fr.gains[a, b], (h, w)) for b in range(v)]) for a in range(u)])
    return DepthSample(name, fr.centre, fr.disparity.astype(np.float32),
                       view_disparities(fr.disparity, (u, v), axes=fr.axes), view_offsets((u, v), fr.axes), gains,
                       lf, present)


def real_depth_samples(scenes: tuple[str, ...], qualities: tuple[int, ...],
                       hint_scales: tuple[int, ...] = (4, 8)) -> list[DepthSample]:
    """Every scene at every quality and hint resolution, decoded (:func:`depth_sample`)."""
    from lfstream.io import read_lf

    out = []
    for name in scenes:
        lf, present = read_lf(SHARED / {**SHARED_SCENES, **TRAINING_SCENES}[name], return_mask=True)
        out += [depth_sample(f"{name} q{q} 1/{scale}", lf, present, q, scale)
                for q in qualities for scale in hint_scales]
    return out


def transformed_sample(sample: DepthSample, flip_y: bool, flip_x: bool, transpose: bool) -> DepthSample:
    """``sample`` mirrored up-down and/or left-right, then transposed (views of its arrays,
    no copies): every image and map of it alike, and the views' offsets with them (a mirror
    negates that axis's offset; a transpose swaps the two), so each view is still the centre
    warped by its map: the same light field seen in a mirror, with the same disparities."""
    sy, sx = (-1 if flip_y else 1), (-1 if flip_x else 1)
    centre, hint = sample.centre[::sy, ::sx], sample.hint[::sy, ::sx]
    maps, gains, truth = sample.view_maps[..., ::sy, ::sx], sample.gains[..., ::sy, ::sx, :], sample.truth[..., ::sy, ::sx, :]
    offsets = sample.offsets * np.array([sy, sx], np.float32)
    if transpose:
        centre, hint, maps = centre.swapaxes(0, 1), hint.swapaxes(0, 1), maps.swapaxes(-1, -2)
        gains, truth, offsets = gains.swapaxes(-2, -3), truth.swapaxes(-2, -3), offsets[..., ::-1]
    return replace(sample, centre=centre, hint=hint, view_maps=maps, gains=gains, truth=truth,
                   offsets=np.ascontiguousarray(offsets))


def random_crops(sample: DepthSample, recipe: Recipe, rng: np.random.Generator, device):
    """``recipe.batch`` random ``recipe.crop``-pixel crops of ``sample``'s decoded centre view,
    the sample first mirrored as ``recipe.flips`` says: ``(sample, ys, xs, centre, crops)``
    with the whole centre view ``(1, 3, H, W)`` and the crops ``(B, 3, c, c)``."""
    if recipe.flips != "none":
        flip_y, flip_x = (bool(f) for f in rng.integers(0, 2, 2))
        sample = transformed_sample(sample, flip_y, flip_x, recipe.flips == "dihedral" and bool(rng.integers(0, 2)))
    c = recipe.crop
    h, w = sample.hint.shape
    ys = rng.integers(0, h - c + 1, recipe.batch)
    xs = rng.integers(0, w - c + 1, recipe.batch)
    centre_full = _to_tensor(sample.centre, device)[None]
    return sample, ys, xs, centre_full, torch.stack([centre_full[0, :, y:y + c, x:x + c] for y, x in zip(ys, xs)])


def refiner_batch_loss(model, sample: DepthSample, recipe: Recipe, rng: np.random.Generator, device,
                       zero: bool = False) -> tuple[torch.Tensor, dict]:
    """Photometric loss of the views the refined maps synthesise: ``recipe.batch`` crops of
    ``sample`` (mirrored as ``recipe.flips`` says), ``recipe.views`` random present views
    each (the centre excluded), bilinear sampling of the whole centre view (no crop border),
    the shading gains multiplied in; MSE, or its log (``recipe.loss``). ``zero``: the same
    with the corrections at zero (the hint)."""
    from lfstream.models.depth_net import view_correction

    sample, ys, xs, centre_full, crops = random_crops(sample, recipe, rng, device)
    c = recipe.crop
    hints = torch.stack([torch.from_numpy(np.ascontiguousarray(sample.hint[y:y + c, x:x + c]))
                         for y, x in zip(ys, xs)])[:, None].to(device)
    corr = model.corrections(crops, hints)
    if zero:
        corr = corr * 0
    gy, gx = pixel_grid(c, c, device, torch.float32)
    sy_all, sx_all = [], []
    picks = crop_views(sample, ys, xs, c, recipe.views, rng, with_centre=False)
    for view in picks:
        d = torch.from_numpy(np.ascontiguousarray(view.disparity)).to(device) \
            + view_correction(corr[view.crop], view.oy, view.ox)
        sy_all.append(gy + int(ys[view.crop]) + d * view.oy)
        sx_all.append(gx + int(xs[view.crop]) + d * view.ox)
    n = len(sy_all)
    # one sampling call on the un-replicated centre view: the n crops stacked along y
    warped = sample_bilinear(centre_full, torch.cat(sy_all)[None], torch.cat(sx_all)[None])
    warped = warped.reshape(3, n, c, c).transpose(0, 1)
    warped = warped * torch.from_numpy(np.stack([v.gain for v in picks])).permute(0, 3, 1, 2).to(device)
    target = _to_tensor(np.stack([v.target for v in picks]), device)
    # MSE alone: an SSIM term (11x11 Gaussian moments of every crop) tripled the step time
    mse = torch.mean((warped - target) ** 2)
    return (torch.log(mse + 1e-8) if recipe.loss == "log_mse" else mse), {}


def centre_depth_batch_loss(model, sample: DepthSample, recipe: Recipe, rng: np.random.Generator, device
                            ) -> tuple[torch.Tensor, dict]:
    """The seed's Depth-Net, unsupervised: ``recipe.batch`` crops of the decoded centre view,
    the disparity predicted from each crop alone, the whole centre view sampled at ``x + d *
    offset`` for ``recipe.views`` random present views (the gains multiplied in) against the
    true views: the log of the mean squared error, plus :data:`CENTRE_DEPTH_SMOOTHNESS` times
    the disparity's gradient where the picture has none (edge-aware smoothness)."""
    sample, ys, xs, centre_full, crops = random_crops(sample, recipe, rng, device)
    c = recipe.crop
    d = model(crops)[:, 0]
    gy, gx = pixel_grid(c, c, device, torch.float32)
    picks = crop_views(sample, ys, xs, c, recipe.views, rng, with_centre=False)
    sy = torch.cat([gy + int(ys[v.crop]) + d[v.crop] * v.oy for v in picks])
    sx = torch.cat([gx + int(xs[v.crop]) + d[v.crop] * v.ox for v in picks])
    warped = sample_bilinear(centre_full, sy[None], sx[None]).reshape(3, len(picks), c, c).transpose(0, 1)
    warped = warped * torch.from_numpy(np.stack([v.gain for v in picks])).permute(0, 3, 1, 2).to(device)
    target = _to_tensor(np.stack([v.target for v in picks]), device)
    photometric = torch.log(torch.mean((warped - target) ** 2) + 1e-8)
    grey = crops.mean(dim=1)
    smooth = (torch.mean(torch.abs(d[:, :, 1:] - d[:, :, :-1]) * torch.exp(-10 * torch.abs(grey[:, :, 1:] - grey[:, :, :-1])))
              + torch.mean(torch.abs(d[:, 1:] - d[:, :-1]) * torch.exp(-10 * torch.abs(grey[:, 1:] - grey[:, :-1]))))
    return photometric + CENTRE_DEPTH_SMOOTHNESS * smooth, {"smooth": round(float(smooth.detach()), 5)}


def _real_depth_run(recipe: Recipe, out: Path, device: str, resume: bool, hint_scales: tuple[int, ...] = (4, 8)):
    """What a Depth-Net run on real scenes starts from: the decoded frames
    (:func:`real_depth_samples`), the network, its :class:`Run` and the run's generator."""
    t0 = time.perf_counter()
    samples = real_depth_samples(recipe.scenes, recipe.qualities, hint_scales)
    print(f"{recipe.model}: {len(samples)} decoded frames of {', '.join(recipe.scenes)} "
          f"({time.perf_counter() - t0:.0f} s)", flush=True)
    model = spec(recipe.model, recipe.preset).build().to(device)
    run = Run(out, recipe, model, resume)
    return samples, model, run, np.random.default_rng(recipe.seed + run.step)


def train_centre_depth(recipe: Recipe, out: Path, device: str, resume: bool, checkpoint_every: int
                       ) -> tuple[torch.nn.Module, dict]:
    """The seed's Depth-Net (``depth_centre``) on real scenes, unsupervised: decoded frames of
    ``recipe.scenes`` at ``recipe.qualities`` (:func:`real_depth_samples`; their hints are not
    used), photometric loss (:func:`centre_depth_batch_loss`)."""
    samples, model, run, rng = _real_depth_run(recipe, out, device, resume, hint_scales=(4,))

    def batch_loss() -> tuple[torch.Tensor, dict]:
        return centre_depth_batch_loss(model, samples[int(rng.integers(len(samples)))], recipe, rng, device)

    t0 = time.perf_counter()
    run_steps(run, batch_loss, checkpoint_every)
    model.eval()
    return finish_run(run, {}, t0, device)


@dataclass
class CropView:
    """One view of one training crop: what the decoder's warp samples it with."""

    crop: int  # index of the crop in the batch
    oy: float  # displacement per unit disparity
    ox: float
    disparity: np.ndarray  # (c, c) float32: the view's map over the crop
    target: np.ndarray  # (c, c, 3) uint8: the true view over the crop
    gain: np.ndarray  # (c, c, 1 or 3) float32: its shading gains


def crop_views(sample: DepthSample, ys: np.ndarray, xs: np.ndarray, c: int, count: int,
               rng: np.random.Generator, with_centre: bool) -> list[CropView]:
    """``count`` random present views (the centre one only ``with_centre``) for each ``c x c``
    crop at ``(ys[k], xs[k])`` of ``sample``, the crops in order."""
    u_n, v_n = sample.present.shape
    cand = [(a, b) for a, b in zip(*np.nonzero(sample.present)) if with_centre or (a, b) != (u_n // 2, v_n // 2)]
    out = []
    for k, (y, x) in enumerate(zip(ys, xs)):
        for i in rng.choice(len(cand), min(count, len(cand)), replace=False):
            a, b = cand[i]
            oy, ox = sample.offsets[a, b]
            out.append(CropView(k, float(oy), float(ox), sample.view_maps[a, b, y:y + c, x:x + c],
                                sample.truth[a, b, y:y + c, x:x + c], sample.gains[a, b, y:y + c, x:x + c]))
    return out


def hance_lf_loss(model, sample: DepthSample, recipe: Recipe, rng: np.random.Generator, device
                  ) -> tuple[torch.Tensor, dict]:
    """JPEG-Hance judged by the light field the decoder makes of its output: ``recipe.batch``
    crops of the decoded centre view with ``recipe.margin`` pixels of context (on the 8x8
    JPEG grid) restored, each warped to ``recipe.views`` random present views (the centre
    included) through the decoded hint's per-view maps, the gains multiplied in. The loss is
    the mean log MSE over (crop, view) pairs: minus the mean PSNR gain up to a constant, the
    metric that counts (MPSNR averages per-view PSNR), and scale-free across scenes
    whose prediction error differs by 20 dB. Samples that fall outside the restored context
    are left out. Logged: ``lf_gain_db``, the mean PSNR gain over the unrestored input."""
    c, m = recipe.crop, recipe.margin
    side = c + 2 * m
    h, w = sample.hint.shape
    y0 = rng.integers(0, (h - side) // 8 + 1, recipe.batch) * 8
    x0 = rng.integers(0, (w - side) // 8 + 1, recipe.batch) * 8
    centre = _to_tensor(sample.centre, device)
    context = torch.stack([centre[:, y:y + side, x:x + side] for y, x in zip(y0, x0)])
    restored = model(context)
    picks = crop_views(sample, y0 + m, x0 + m, c, recipe.views, rng, with_centre=True)
    gy, gx = pixel_grid(c, c, device, torch.float32)
    d = torch.from_numpy(np.stack([v.disparity for v in picks])).to(device)
    oy = torch.tensor([v.oy for v in picks], device=device)[:, None, None]
    ox = torch.tensor([v.ox for v in picks], device=device)[:, None, None]
    sy, sx = gy + m + d * oy, gx + m + d * ox
    inside = ((sy >= 0) & (sy <= side - 1) & (sx >= 0) & (sx <= side - 1)).float()[:, None]
    gains = torch.from_numpy(np.stack([v.gain for v in picks])).permute(0, 3, 1, 2).to(device)
    target = _to_tensor(np.stack([v.target for v in picks]), device)
    index = torch.tensor([v.crop for v in picks], device=device)
    count = inside.sum(dim=(1, 2, 3)) * 3 + 1e-6

    def view_mse(src: torch.Tensor) -> torch.Tensor:
        err = (sample_bilinear(src[index], sy, sx) * gains - target) ** 2
        return (err * inside).sum(dim=(1, 2, 3)) / count

    mse = view_mse(restored)
    with torch.no_grad():
        gain_db = float(torch.mean(10 * torch.log10((view_mse(context) + 1e-6) / (mse.detach() + 1e-6))))
    return torch.log(mse + 1e-6).mean(), {"lf_gain_db": round(gain_db, 4)}


def train_depth_refiner(recipe: Recipe, out: Path, device: str, resume: bool, checkpoint_every: int
                        ) -> tuple[torch.nn.Module, dict]:
    """The hint refiner (Depth-Net fast) on real scenes, unsupervised: decoded frames of
    ``recipe.scenes`` at ``recipe.qualities`` with the hint at 1/4 and 1/8 resolution
    (:func:`real_depth_samples`), photometric loss (:func:`refiner_batch_loss`). Logged
    every 50 steps: the loss against the same batch with the corrections at zero."""
    samples, model, run, rng = _real_depth_run(recipe, out, device, resume)

    def batch_loss() -> tuple[torch.Tensor, dict]:
        sample = samples[int(rng.integers(len(samples)))]
        state = rng.bit_generator.state
        loss, terms = refiner_batch_loss(model, sample, recipe, rng, device)
        if run.step % 50 == 49:  # the same crops and views with the corrections at zero
            probe = np.random.default_rng()
            probe.bit_generator.state = state
            with torch.no_grad():
                base, _ = refiner_batch_loss(model, sample, recipe, probe, device, zero=True)
            terms["hint_loss"] = float(base)
        return loss, terms

    t0 = time.perf_counter()
    run_steps(run, batch_loss, checkpoint_every)
    model.eval()
    return finish_run(run, {}, t0, device)


# ---------------------------------------------------------------------------------------
# validation


def _psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    mse = float(torch.mean((a.double() - b.double()) ** 2))
    return 100.0 if mse == 0 else 10 * math.log10(1.0 / mse)


def real_centre_views() -> list[tuple[str, np.ndarray]]:
    """Centre views of the real samples when ``../shared/data`` is present."""
    out = []
    try:
        from lfstream.io import read_lf

        for scene, folder in SHARED_SCENES.items():
            if (SHARED / folder).exists():
                lf, _ = read_lf(SHARED / folder, return_mask=True)
                out.append((scene, lf[lf.shape[0] // 2, lf.shape[1] // 2]))
    except Exception as exc:  # validation on real data is optional (e.g. on the GPU machine)
        print(f"real samples unavailable: {exc}", file=sys.stderr)
    return out


@torch.no_grad()
def validate_hance(model, val_views: np.ndarray, quality: int, device) -> dict:
    model.eval()
    res = {}
    sets = [("synthetic", list(val_views))] + [(n, [v]) for n, v in real_centre_views()]
    for name, views in sets:
        gain_p = [_hance_gain(model, view, quality, device) for view in views]
        res[f"{name}_psnr_gain_db"] = round(float(np.mean(gain_p)), 3)
    model.train()
    return res


@torch.no_grad()
def _hance_gain(model, view: np.ndarray, quality: int, device) -> float:
    """PSNR gain (dB) of ``model`` (in eval mode) over its input on one view at ``quality``:
    the plain JPEG, or the post-filtered one for a network trained after the filter."""
    h, w = (view.shape[0] // 8) * 8, (view.shape[1] // 8) * 8
    view = np.ascontiguousarray(view[:h, :w])
    dec = _to_tensor(jpeg_roundtrip(view, quality, deblock=model.config.after_deblock), device)[None]
    ref = _to_tensor(view, device)[None]
    return _psnr(model(dec), ref) - _psnr(dec, ref)


@torch.no_grad()
def validate_depth(model, hance, val_lf: np.ndarray, val_hints: np.ndarray, quality: int, device) -> dict:
    model.eval()
    from lfstream.models.warp import warp_per_view

    net_p, flat_p, hint_p = [], [], []
    for lf, hint in zip(val_lf, val_hints):
        centre = _to_tensor(jpeg_roundtrip(lf[lf.shape[0] // 2, lf.shape[1] // 2], quality), device)[None]
        centre = hance(centre) if hance is not None else centre
        truth = _to_tensor(lf, device)[None]
        h = torch.from_numpy(hint)[None, None].to(device)
        d = model(centre, h if model.config.hint else None)
        net_p.append(_psnr(warp_per_view(centre, d), truth))
        flat_p.append(_psnr(warp_per_view(centre, torch.zeros_like(d)), truth))
        hint_p.append(_psnr(warp_per_view(centre, h[:, :, None].expand_as(d[:, :1]).expand_as(d)), truth))
    model.train()
    return {"synthetic_mpsnr_net_db": round(float(np.mean(net_p)), 3),
            "synthetic_mpsnr_flat_db": round(float(np.mean(flat_p)), 3),
            "synthetic_mpsnr_hint_db": round(float(np.mean(hint_p)), 3)}


@torch.no_grad()
def validate_refnet(model, val_lf: np.ndarray, val_labels: np.ndarray, device) -> dict:
    model.eval()
    ps = []
    for lf, label in zip(val_lf, val_labels):
        pred = model(_to_tensor(lf, device)[None])
        ps.append(_psnr(pred, _to_tensor(label, device)[None]))
    model.train()
    return {"synthetic_psnr_vs_sas_db": round(float(np.mean(ps)), 3)}


# ---------------------------------------------------------------------------------------
# training loops


class Run:
    """Checkpointing and logging of one model's training."""

    def __init__(self, out: Path, recipe: Recipe, model, resume: bool) -> None:
        self.out = out
        self.recipe = recipe
        self.model = model
        self.tag = f"{recipe.model}-{recipe.preset}"
        self.opt = torch.optim.Adam(model.parameters(), lr=recipe.lr)
        warm = max(1, recipe.steps // 20)
        # linear warm-up, then cosine decay to 2 % of the peak rate
        self.sched = torch.optim.lr_scheduler.LambdaLR(
            self.opt,
            lambda k: min(1.0, (k + 1) / warm)
            * (0.02 + 0.98 * 0.5 * (1 + math.cos(math.pi * min(k, recipe.steps) / recipe.steps))))
        self.step = 0
        self.ckpt = out / f"{self.tag}.ckpt"
        self.log_path = out / f"{self.tag}.log.jsonl"
        if resume and self.ckpt.exists():
            state = torch.load(self.ckpt, map_location="cpu", weights_only=False)
            if state["recipe"] != asdict(recipe):
                raise SystemExit(f"{self.ckpt}: recipe differs from this run's; refusing to resume")
            model.load_state_dict(state["model"])
            self.opt.load_state_dict(state["opt"])
            self.sched.load_state_dict(state["sched"])
            self.step = state["step"]
            print(f"resumed {self.tag} at step {self.step}")

    def save(self) -> None:
        tmp = self.ckpt.with_suffix(".tmp")
        torch.save({"model": self.model.state_dict(), "opt": self.opt.state_dict(), "sched": self.sched.state_dict(),
                    "step": self.step, "recipe": asdict(self.recipe)}, tmp)
        os.replace(tmp, self.ckpt)

    def log(self, record: dict) -> None:
        with open(self.log_path, "a") as fh:
            fh.write(json.dumps({"step": self.step, **record}) + "\n")

    def update(self, loss: torch.Tensor) -> None:
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.model.parameters(), 1.0)
        self.opt.step()
        self.sched.step()
        self.step += 1


def train(recipe: Recipe, out: Path, device: str, resume: bool, workers: int, checkpoint_every: int,
          hance=None, init: torch.nn.Module | None = None) -> tuple[torch.nn.Module, dict]:
    torch.manual_seed(recipe.seed)
    rng = np.random.default_rng(recipe.seed)
    t0 = time.perf_counter()
    if init is not None and not (recipe.data == "real" and recipe.model == "jpeg_hance"):
        raise SystemExit(f"--init: only JPEG-Hance trained on real views starts from given weights, not {recipe.model}")
    if recipe.data == "real" and recipe.model == "depth_net":
        return train_depth_refiner(recipe, out, device, resume, checkpoint_every)
    if recipe.model == "depth_centre":
        return train_centre_depth(recipe, out, device, resume, checkpoint_every)
    if recipe.data == "real":
        return train_real_hance(recipe, out, device, resume, checkpoint_every, init)
    data, hints = render_dataset(recipe.samples, recipe.views, recipe.size, recipe.seed, workers)
    val, val_hints = render_dataset(max(8, recipe.samples // 16), recipe.views, recipe.size, recipe.seed + 7919, workers)
    print(f"{recipe.model}: rendered {len(data)}+{len(val)} LFs in {time.perf_counter() - t0:.1f} s", flush=True)
    overrides = {"views": (recipe.views, recipe.views)} if recipe.model != "jpeg_hance" else {}
    model = spec(recipe.model, recipe.preset).build(**overrides).to(device)
    run = Run(out, recipe, model, resume)
    labels = val_labels = None
    if recipe.model == "refnet":
        from lfstream.refocus import focal_stack

        labels = np.stack([focal_stack(lf) for lf in data])  # (N, 16, H, W, 3) uint8, SaS
        val_labels = np.stack([focal_stack(lf) for lf in val])
    n, u, v, h, w, _ = data.shape
    c = recipe.crop

    def batch_loss() -> tuple[torch.Tensor, dict]:
        idx = rng.integers(0, n, recipe.batch)
        if recipe.model == "jpeg_hance":
            # one random view per item, crop on the 8x8 JPEG grid, JPEG round trip
            imgs = data[idx, rng.integers(0, u, recipe.batch), rng.integers(0, v, recipe.batch)]
            ys, xs = rng.integers(0, (h - c) // 8 + 1, recipe.batch) * 8, rng.integers(0, (w - c) // 8 + 1, recipe.batch) * 8
            crops = augment(np.stack([im[y:y + c, x:x + c] for im, y, x in zip(imgs, ys, xs)]), rng)
            dec = np.stack([jpeg_roundtrip(cr, recipe.quality) for cr in crops])
            return hance_loss(model(_to_tensor(dec, device)), _to_tensor(crops, device)), {}
        if recipe.model == "depth_net":
            ys, xs = rng.integers(0, (h - c) // 8 + 1, recipe.batch) * 8, rng.integers(0, (w - c) // 8 + 1, recipe.batch) * 8
            lfs = augment(np.stack([data[i, :, :, y:y + c, x:x + c] for i, y, x in zip(idx, ys, xs)]), rng)
            centres = np.stack([jpeg_roundtrip(np.ascontiguousarray(lf[u // 2, v // 2]), recipe.quality) for lf in lfs])
            centre = _to_tensor(centres, device)
            if hance is not None:
                with torch.no_grad():
                    centre = hance(centre)
            hint = None
            if model.config.hint:
                hint = torch.from_numpy(np.stack([hints[i, y:y + c, x:x + c] for i, y, x in zip(idx, ys, xs)]))
                hint = hint[:, None].to(device)
            return depth_net_loss(centre, _to_tensor(lfs, device), model(centre, hint))
        lfs = _to_tensor(data[idx], device)
        return refnet_loss(model(lfs), _to_tensor(labels[idx], device)), {}

    t0 = time.perf_counter()
    run_steps(run, batch_loss, checkpoint_every)
    if recipe.model == "jpeg_hance":
        metrics = validate_hance(model, val[:, u // 2, v // 2], recipe.quality, device)
    elif recipe.model == "depth_net":
        metrics = validate_depth(model, hance, val, val_hints, recipe.quality, device)
    else:
        metrics = validate_refnet(model, val, val_labels, device)
    return finish_run(run, metrics, t0, device)


def run_steps(run: Run, batch_loss, checkpoint_every: int) -> None:
    """The optimiser loop every model shares: ``batch_loss()`` gives a batch's loss and its
    logged terms; stops at the recipe's steps or time limit, refuses a non-finite loss,
    logs every 50 steps and checkpoints every ``checkpoint_every``."""
    recipe = run.recipe
    t0 = time.perf_counter()
    while run.step < recipe.steps:
        if recipe.time_limit_s and time.perf_counter() - t0 > recipe.time_limit_s:
            print(f"{run.tag}: time limit reached at step {run.step}", flush=True)
            run.save()
            break
        loss, terms = batch_loss()
        if not torch.isfinite(loss):
            raise SystemExit(f"{run.tag}: non-finite loss at step {run.step}")
        run.update(loss)
        if run.step % 50 == 0 or run.step == recipe.steps:
            run.log({"loss": loss.item(), **terms, "elapsed_s": round(time.perf_counter() - t0, 1)})
        if run.step % checkpoint_every == 0 or run.step == recipe.steps:
            run.save()
            print(f"{run.tag} step {run.step} loss {loss.item():.6f} ({time.perf_counter() - t0:.0f} s)", flush=True)


def finish_run(run: Run, metrics: dict, t0: float, device: str) -> tuple[torch.nn.Module, dict]:
    """Records the run's time, steps and device with its validation metrics (log and stdout)."""
    metrics["train_s"] = round(time.perf_counter() - t0, 1)
    metrics["steps_done"] = run.step
    metrics["device"] = torch.cuda.get_device_name() if device.startswith("cuda") else "cpu"
    run.log({"validation": metrics})
    print(f"{run.tag} validation {metrics}", flush=True)
    return run.model.eval(), metrics


def train_real_hance(recipe: Recipe, out: Path, device: str, resume: bool, checkpoint_every: int,
                     init: torch.nn.Module | None = None) -> tuple[torch.nn.Module, dict]:
    """JPEG-Hance after the post-filter, on real views (:func:`real_hance_batch`, MSE loss) or
    on what the decoder makes of them (``recipe.objective == "lf"``: :func:`hance_lf_loss`),
    starting from ``init``'s weights where given (``recipe.init`` records them); validated
    on the centre views of the real scenes it did not train on (and, marked ``train_``, on
    those it did), as the gain over the post-filter at quality 50."""
    views = real_views(recipe.scenes)
    print(f"{recipe.model}: {len(views)} real views of {', '.join(recipe.scenes)}", flush=True)
    samples = real_depth_samples(recipe.scenes, recipe.qualities) if recipe.objective == "lf" else []
    shipped = spec(recipe.model, recipe.preset).config
    model = spec(recipe.model, recipe.preset).build(strength=1.0).to(device)  # trains the whole correction
    if init is not None:
        model.load_state_dict(init.state_dict())
    run = Run(out, recipe, model, resume)
    rng = np.random.default_rng(recipe.seed + run.step)  # a resumed run draws new crops

    def batch_loss() -> tuple[torch.Tensor, dict]:
        if recipe.objective == "image":
            x, y = real_hance_batch(views, recipe, rng)
            return torch.mean((model(_to_tensor(x, device)) - _to_tensor(y, device)) ** 2), {}
        loss, terms = hance_lf_loss(model, samples[int(rng.integers(len(samples)))], recipe, rng, device)
        if recipe.image_weight > 0:  # the augmented crops of every view (dark, flat) keep it general
            x, y = real_hance_batch(views, replace(recipe, batch=2 * recipe.batch, crop=64), rng)
            mse = torch.mean((model(_to_tensor(x, device)) - _to_tensor(y, device)) ** 2, dim=(1, 2, 3))
            loss = loss + recipe.image_weight * torch.log(mse + 1e-6).mean()
        return loss, terms

    t0 = time.perf_counter()
    run_steps(run, batch_loss, checkpoint_every)
    model.eval()
    model.config = shipped  # the preset's strength, as it runs (and is saved)
    metrics = {f"{'train_' if name in recipe.scenes else ''}{name}_q50_psnr_gain_db":
               round(_hance_gain(model, view, 50, device), 3) for name, view in real_centre_views()}
    return finish_run(run, metrics, t0, device)


def _initial_weights(name: str, preset: str, init: str, device: str) -> tuple[torch.nn.Module, dict]:
    """The weights ``--init`` names (``"shipped"`` or a checkpoint file) and what the recipe
    records of them: their SHA-256 and, for shipped ones, the recipe that made them."""
    from lfstream.models.manifest import manifest_entry, sha256_file

    if init == "shipped":
        model = load_model(name, preset, device)  # a WeightsError where none ship
        entry = manifest_entry(name, preset)
        return model, {"sha256": entry["sha256"], "recipe": entry["recipe"]}
    path = Path(init)
    return load_model(name, preset, device, path=path), {"sha256": sha256_file(path), "recipe": None}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("model", choices=[*MODEL_NAMES, "all"])
    p.add_argument("--preset", default="fast", choices=["fast", "paper"])
    p.add_argument("--steps", type=int, help="optimiser steps (default per model; each phase)")
    p.add_argument("--batch", type=int)
    p.add_argument("--samples", type=int, default=256, help="synthetic LFs rendered for training")
    p.add_argument("--lr", type=float, help="peak learning rate (default 1e-3; the LF phase 5e-4)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="cpu")
    p.add_argument("--workers", type=int, default=max(1, (os.cpu_count() or 2) - 1))
    p.add_argument("--out", type=Path, default=Path("runs"))
    p.add_argument("--resume", action="store_true")
    p.add_argument("--checkpoint-every", type=int, default=250)
    p.add_argument("--time-limit", type=float, default=0.0, help="seconds per model; stop early and ship")
    p.add_argument("--objective", choices=["image", "lf"], default="lf",
                   help="JPEG-Hance: 'lf' (default) adds the decoded-LF fine-tuning phase after the "
                        "image phase; 'image' stops after the image phase")
    p.add_argument("--init", metavar="shipped|FILE",
                   help="start from these weights (a checkpoint this tool wrote, or the shipped ones); "
                        "JPEG-Hance then runs only the phase --objective names")
    p.add_argument("--ship", action="store_true", help="write the final weights into lfstream/weights/")
    p.add_argument("--scenes", help="comma-separated real scenes the real-data phases train on (default: "
                   f"{','.join(HANCE_TRAIN_SCENES)}; tools/hance_strength.py leaves one out)")
    args = p.parse_args(argv)
    known = {**SHARED_SCENES, **TRAINING_SCENES}
    unknown = [x for x in (args.scenes or "").split(",") if x and x not in known]
    if unknown:
        p.error(f"--scenes: {', '.join(unknown)} not among {', '.join(known)}")
    from lfstream.models.registry import REGISTRY

    # "all": every network the preset has (the seed's Depth-Net comes in the fast size only)
    names = [n for n in MODEL_NAMES if (n, args.preset) in REGISTRY] if args.model == "all" else [args.model]
    if (names[0], args.preset) not in REGISTRY:
        p.error(f"{names[0]}: no {args.preset} preset")
    if args.init and (names != ["jpeg_hance"] or not spec("jpeg_hance", args.preset).config.after_deblock):
        p.error("--init: only jpeg_hance (trained on real views) starts from given weights")
    try:
        return _train_all(args, names)
    except LFStreamError as exc:  # a bad --init file, missing samples: one line, not a traceback
        print(f"train: {exc}", file=sys.stderr)
        return 2


def _train_all(args: argparse.Namespace, names: list[str]) -> int:
    args.out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(max(1, os.cpu_count() or 1))
    hance = None
    scenes = tuple(x for x in (args.scenes or "").split(",") if x)
    for name in names:
        recipe = Recipe(model=name, preset=args.preset, steps=args.steps or DEFAULT_STEPS[name],
                        batch=args.batch or DEFAULT_BATCH[name], lr=args.lr or 1e-3, crop=DEFAULT_CROP[name],
                        samples=args.samples, seed=args.seed, time_limit_s=args.time_limit)
        init, init_record = _initial_weights(name, args.preset, args.init, args.device) if args.init else (None, None)
        phases = [recipe]
        if name == "jpeg_hance" and spec(name, args.preset).config.after_deblock:
            image = replace(recipe, data="real", scenes=scenes or HANCE_TRAIN_SCENES, qualities=HANCE_QUALITIES,
                            steps=args.steps or 4000, batch=args.batch or 16)
            lf = replace(image, **{**HANCE_LF_PHASE, "steps": args.steps or HANCE_LF_PHASE["steps"],
                                   "batch": args.batch or HANCE_LF_PHASE["batch"],
                                   "lr": args.lr or HANCE_LF_PHASE["lr"]})
            phases = [image] if args.objective == "image" else [lf] if init is not None else [image, lf]
        if name == "depth_centre":  # the seed's Depth-Net, on real scenes
            phases = [replace(recipe, scenes=scenes or CENTRE_DEPTH_SCENES, **CENTRE_DEPTH_RECIPE)]
        if name == "depth_net" and args.preset == "fast":  # the hint refiner, on real scenes
            phases = [replace(recipe, data="real", scenes=scenes or DEPTH_TRAIN_SCENES, qualities=DEPTH_QUALITIES,
                              steps=args.steps or 3000, batch=args.batch or 8, crop=128, views=8, samples=0,
                              **DEPTH_REFINER_LOSS)]
        elif name == "depth_net" and hance is None:
            try:
                hance = load_model("jpeg_hance", args.preset, device=args.device)
            except Exception as exc:
                print(f"depth_net trains without JPEG-Hance in front ({exc})", file=sys.stderr)
        for k, phase in enumerate(phases):
            phase = replace(phase, init=init_record)
            # each phase checkpoints under its own folder: --resume continues the one it was in
            out = args.out / f"phase{k + 1}" if len(phases) > 1 else args.out
            out.mkdir(exist_ok=True)
            model, metrics = train(phase, out, args.device,
                                   args.resume, args.workers, args.checkpoint_every,
                                   hance=hance if name == "depth_net" else None, init=init)
            digest = save_checkpoint(model, name, args.preset, args.out / f"{name}-{args.preset}.pt")
            init, init_record = model, {"sha256": digest, "recipe": asdict(phase)}
        if name == "jpeg_hance":
            hance = model
            for prm in hance.parameters():
                prm.requires_grad_(False)
        if args.ship:
            entry = ship_weights(model.cpu(), name, args.preset, asdict(phase), metrics)
            model.to(args.device)
            print(f"shipped {entry['file']} sha256 {entry['sha256'][:16]}... params {entry['params']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
