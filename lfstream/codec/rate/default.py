"""The default encode's choice (no ``bpp``, no preset named), made on a stream's first frame.

:func:`choose_default` codes the first frame with the hint, its centre view by the number
of views (:func:`default_preset`: JPEG from 7x7 views up, AV1 with fewer), and checks, at the
hint's resolution, how well the centre view and the hint predict the outer
views (:func:`prediction_psnr`); where they miss by far (a camera array whose views are
tens of pixels apart, a rig that is not a grid) no warp can carry the scene, and the
stream codes the views themselves instead (``views``, the ``balanced`` preset: one AV1
sequence keyed by the centre view). Where a hint at half the resolution predicts as well for
the bytes it saves, it is sent instead (:func:`coarsening_allowance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfstream.codec.bitstream import Packet
from lfstream.codec.centre.av1 import av1_fits
from lfstream.codec.encoder import Encoder
from lfstream.codec.gains import measure_gains
from lfstream.codec.hint import HintOptions, key_payload
from lfstream.errors import LFValueError
from lfstream.lightfield import to_uint8

#: The default encode's floor on :func:`prediction_psnr` (dB): below it the stream codes the
#: views. Measured (at the hint's 1/4 resolution, luma): 33.1-47.5 dB on every shared sample
#: but toys_array, 30.0-38.5 on 12 synthetic 7x7 scenes with noise and vignetting at 375x540,
#: 27.0 and up at 40x48 and 64x96; toys_array 19.0 (~7.5 px of disparity per view step:
#: disocclusions everywhere), 20.4 at half size.
PREDICTION_FLOOR_DB = 22.0


#: Views whose hint grid is smaller than this many cells a side are not checked (the fast
#: preset): on a handful of cells the check measures borders, not the scene (a 5x5x40x48 clip
#: measured 24.5 dB, and 26.0 at 64x96, a scene the warp predicts).
PREDICTION_CHECK_MIN_CELLS = 16


#: The default sends its hint at twice the scale (1/8 of the view instead of 1/4) where that
#: predicts the outer ring, on the same 1/4-resolution luma, within this many dB of the finer
#: hint. Measured at quality 50: the hint is 9-34 % of a default frame, and at 1/8 seahorse,
#: dino, cotton and lytro_translucent need 13-21 % fewer bits for the same MPSNR (within 0.04
#: dB; +0.43...+0.61 dB at about equal bits on the first three), synthetic +0.05 dB at equal
#: bits; lytro_bikes' thin structures lose 0.43 dB at equal bits. The check's loss: bikes
#: -0.38 dB, the other five -0.08...+0.04.
HINT_COARSEN_MAX_LOSS_DB = 0.2


#: ... and only where the bytes it saves are worth more than the check's loss: at most this
#: many dB per percent of frame 0's bytes saved (log ratio). What a percent of bytes buys
#: when the centre view's quality spends it, measured on the decoded light field at quality
#: 40-60 (hint at 1/4): 0.013-0.068 dB on nine scenes (the synthetic clip, seahorse, cotton,
#: lytro_bikes, lytro_translucent, four synthetic 256x320 scenes), median 0.03. Without
#: this, scenes whose hint is a small share of the frame traded real quality for almost no
#: bytes (synthetic seeds 5, 6, 10 at 256x320: -0.24 / -0.62 / -0.14 dB of MPSNR for 0.9 /
#: 1.3 / 1.3 % fewer bytes; the check's loss there 0.08-0.10 dB); on the shared samples the
#: choice is unchanged.
HINT_COARSEN_DB_PER_PERCENT = 0.03


#: The default's centre coding by the number of views: (most views, preset). With few views the
#: centre view is a large share of the stream, and JPEG's intra coding loses to HEVC's. Measured
#: at q50 against x265 medium at the same size (MPSNR / MSSIM differences), centre crops of the
#: samples: 3x3 fast -0.67...-2.40 dB / -0.0025...-0.0217 on synthetic, seahorse, bikes,
#: translucent (dino -1.39 / -0.0235), balanced -0.07 / -0.0038 on dino, best +0.41...+8.21 dB /
#: +0.0016...+0.0500 (dino +0.63 / +0.0051); 5x5 fast -1.22 / -0.0092 on synthetic (+0.0004...
#: +0.0077 on seahorse, bikes, translucent), balanced +0.42...+2.16 dB / +0.0050...+0.0589;
#: 7x7 and up, fast meets x265 medium on every 7x7 sample (bench/codec.py).
DEFAULT_PRESET_BY_VIEWS = ((9, "best"), (48, "balanced"))


@dataclass(frozen=True)
class DefaultChoice:
    """What the default encode chose on a stream's first frame (:func:`choose_default`).

    Attributes:
        encoder: the stream's encoder; where ``first`` is set it has coded frame 0 already.
        first: frame 0's packet, or ``None`` when the encoder still has to code it.
        prediction_db: :func:`prediction_psnr` of frame 0 (``None``: not measured).
    """

    encoder: object  # lfstream.codec.encoder.Encoder (imported lazily: rate is imported by it)
    first: Packet | None
    prediction_db: float | None

    @property
    def codes_views(self) -> bool:
        """Whether the stream codes the views themselves (the prediction missed)."""
        return bool(self.encoder.codes_views)


def prediction_psnr(lf: np.ndarray, hint, gains: np.ndarray | None = None, present: np.ndarray | None = None,
                    ring_luma: np.ndarray | None = None, grid_scale: int | None = None) -> float:
    """How well the centre view and a hint predict the outer ring of views: the mean PSNR
    (dB) of the decoder's warp (:func:`lfstream.codec.warp.cpu.warp_views_at`) against those
    views, on luma block means at the hint's resolution (where sensor and coding noise are
    small, so a noisy capture is not mistaken for an unpredictable one). About 2 ms for a
    7x7x375x540 frame.

    Args:
        lf: one frame ``(U, V, H, W, 3)`` uint8, C-contiguous.
        hint: the hint as the decoder rebuilds it (:class:`lfstream.codec.hint.QuantisedHint`).
        gains: ``(U, V, gh, gw, C)`` gain maps the stream sends (their channel mean is
            applied to the luma), or ``None``.
        present: ``(U, V)`` mask of the views that exist.
        ring_luma: those block means of the centre and the ring views where the caller has
            them; ``None``:
            computed here.
        grid_scale: the block size of those means (a divisor of the hint's scale); ``None``:
            the hint's own. A coarser hint is up-sampled bilinearly to them, so hints of two
            resolutions are judged on the same pixels.
    """
    from lfstream.codec.hint import _grids, _ring_views, _upsample
    from lfstream.codec.warp.cpu import warp_views_at
    from lfstream.metrics import psnr

    u, v = lf.shape[:2]
    ring = _ring_views(u, v, present)
    if not ring:
        return float("inf")
    scale = hint.scale if grid_scale is None else int(grid_scale)
    if scale < 1 or hint.scale % scale:
        raise LFValueError(f"grid_scale: a divisor of the hint's scale {hint.scale}, got {grid_scale!r}")
    shape = (1 + len(ring), max(1, lf.shape[2] // scale), max(1, lf.shape[3] // scale))
    if ring_luma is not None and ring_luma.shape == shape:
        grids = ring_luma
    else:
        grids = _grids(lf, [(u // 2, v // 2), *ring], scale)  # (1 + J, H // s, W // s) in [0, 1]
    values = hint.values()
    if hint.scale != scale:
        values = _upsample(values, hint.scale // scale, grids.shape[1:])
    disparity = np.ascontiguousarray(values[: grids.shape[1], : grids.shape[2]]) / np.float32(scale)
    if gains is not None:
        gains = np.asarray(gains, np.float32).mean(axis=-1, keepdims=True)
    pred = warp_views_at(grids[0][..., None], disparity, (u, v), ring, gains, hint.axes)
    return float(np.mean(psnr(grids[1:, ..., None], pred.astype(np.float32) / np.float32(255.0), 1.0)))


def default_preset(views: tuple[int, int], size: tuple[int, int]) -> str:
    """The default's preset for ``views`` ``(U, V)`` of ``size`` ``(H, W)``
    (:data:`DEFAULT_PRESET_BY_VIEWS`; ``fast`` where the views are too small for AV1)."""
    n = int(views[0]) * int(views[1])
    if av1_fits(size):
        for most, preset in DEFAULT_PRESET_BY_VIEWS:
            if n <= most:
                return preset
    return "fast"


def uses_default_choice(preset: str | None, depth_hint: bool, residual: int | None,
                        residual_mode: str = "prediction") -> bool:
    """Whether an encode is the default one :func:`choose_default` configures: no preset
    named, the hint on, no residual layer asked for (and no target: rate control's is its own)."""
    return preset is None and bool(depth_hint) and residual is None and residual_mode == "prediction"


def choose_default(frame: np.ndarray, quality: int = 50, present: np.ndarray | None = None,
                   hint_options: HintOptions | None = None, gain_grid: int = 4, views_hint: bool = False,
                   post_filter: bool = True, preset: str | None = None, device: str = "cpu") -> DefaultChoice:
    """The default encode's configuration for a stream whose first frame is ``frame``: the
    hint and the centre view coded by :func:`default_preset` (the fast JPEG from 7x7 views
    up, AV1 with fewer; ``preset`` names another; ``device``: where the hint's sweep runs,
    :attr:`lfstream.codec.encoder.Encoder.device`), unless the prediction of the views misses by far
    (:data:`PREDICTION_FLOOR_DB`), then the views coded as one AV1 sequence keyed by the
    centre view (``balanced`` preset, ``views`` at ``quality``; the hint only with
    ``views_hint``). The fast encoder's work on frame 0 is kept (``first``): the check costs
    a few milliseconds on top of it, once per stream.

    Shape:
        - frame: ``(U, V, H, W, 3)``
    """


    opts = hint_options or HintOptions()
    enc = Encoder(quality=quality, depth_hint=True, hint_options=opts, gain_grid=gain_grid,
                  preset=preset or default_preset(frame.shape[:2], frame.shape[2:4]), post_filter=post_filter,
                  device=device)
    first = enc.encode_frame(frame, 0, 0, present)
    u, v = frame.shape[:2]
    cells = min(frame.shape[2:4]) // enc.last_hint.scale
    if u * v == 1 or (present is not None and not np.all(present)) or cells < PREDICTION_CHECK_MIN_CELLS:
        # nothing to predict, views a sequence would not carry, or too few cells to tell
        return DefaultChoice(enc, first, None)
    frame8 = np.ascontiguousarray(to_uint8(np.asarray(frame)))
    db = prediction_psnr(frame8, enc.last_hint, enc.last_gains, present, enc.last_ring_luma)
    if db >= PREDICTION_FLOOR_DB:
        coarse = enc.coarser_first_hint() if hint_options is None else None
        if coarse is not None and min(frame.shape[2:4]) // coarse.scale >= PREDICTION_CHECK_MIN_CELLS:
            # the hint at half the resolution, judged on the same luma: sent where it predicts
            # the ring as well, for the bytes it saves (coarsening_allowance), its payload coded
            # once here. On this thread after the full hint's check, not beside it on workers:
            # each check's parallel kernels then have the cores to themselves, and the
            # coarser hint's gains are measured only where it is sent
            db_coarse = prediction_psnr(frame8, coarse, enc.last_gains, present, enc.last_ring_luma,
                                        grid_scale=enc.last_hint.scale)
            coarse_payload = key_payload(coarse)
            if db - db_coarse <= coarsening_allowance(first, len(coarse_payload)):
                gains = None if enc.last_gains is None else measure_gains(
                    frame8, enc.gain_grid, present=present, disparity=coarse.values(), axes=coarse.axes)
                return DefaultChoice(enc, enc.coarsen_first_hint(frame8, first, present, gains, coarse_payload),
                                     db_coarse)
        return DefaultChoice(enc, first, db)
    views = Encoder(quality=quality, depth_hint=views_hint, hint_options=opts, gain_grid=gain_grid, preset="balanced",
                    residual=quality, residual_mode="views", post_filter=post_filter, device=device)
    return DefaultChoice(views, None, db)


def coarsening_allowance(first: Packet, coarse_hint_bytes: int) -> float:
    """How many dB of :func:`prediction_psnr` the default may lose by sending frame 0's hint
    at twice the scale (a payload of ``coarse_hint_bytes`` instead of ``first.hint``): the
    lesser of :data:`HINT_COARSEN_MAX_LOSS_DB` and :data:`HINT_COARSEN_DB_PER_PERCENT` per
    percent of the packet's bytes saved (negative where the coarser hint is larger)."""
    total = len(first.image) + len(first.hint) + len(first.gain) + len(first.residual)
    coarse = total - len(first.hint) + int(coarse_hint_bytes)
    saved_percent = 100.0 * float(np.log(max(total, 1) / max(coarse, 1)))
    return min(HINT_COARSEN_MAX_LOSS_DB, HINT_COARSEN_DB_PER_PERCENT * saved_percent)

