"""Rate control: the configuration that gives the best measured quality at a target size.

The encoder's knobs are the preset (the centre view's codec: JPEG or AV1), its quality and
whether the depth hint is sent. The hint and the gain maps do not depend on the centre
view's coding, so they are computed once per frame; the size at every quality then costs
one centre-view encode per frame, and a search (:func:`_quality_bracket`: bisection's bracket
in fewer encodes) finds, for every preset with the hint and without it, the quality whose
stream is closest to the target. The candidates are decoded
on the first frame and the one with the higher MPSNR (over the views that exist) wins: the
encoder has the whole light field, so it can measure instead of guess.

The residual layer (:mod:`lfstream.codec.residual`) is a candidate too: the centre view takes
a share of the target (:data:`RESIDUAL_SHARES`), the residual's quality is searched the same
way to fill the rest. Measured on lytro_bikes at 0.08 bpp, a centre view at about half the
budget was best (35.1 dB; a quarter 34.8, two thirds 35.0, nine tenths 34.1).

The last candidates code the views themselves as the residual's sequence (modes ``views`` and
``half-views``, :mod:`lfstream.codec.residual`): where warping cannot predict the scene they
are the better stream (toys_array), elsewhere the measurement leaves them out. A residual's or
the views' quality search stops at the first probe within :data:`PROBE_NEAR` of the target
(each probe is an AV1 sequence of every view).

A stream sees one frame at a time: it chooses on its first frame and then follows the
budget frame by frame (:func:`follow_rate`).

Without a target (the default encode: no ``bpp``, no preset named) the choice is cheaper:
:func:`choose_default` codes the first frame with the hint, its centre view by the number
of views (:func:`default_preset`: JPEG from 7x7 views up, AV1 with fewer), and checks, at the
hint's resolution, how well the centre view and the hint predict the outer
views (:func:`prediction_psnr`); where they miss by far (a camera array whose views are
tens of pixels apart, a rig that is not a grid) no warp can carry the scene, and the
stream codes the views themselves instead (``views``, the ``balanced`` preset: one AV1
sequence keyed by the centre view).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader, pack_header, pack_packet
from lfstream.codec.hint import HintOptions, key_payload
from lfstream.codec.intra import AV1_MIN_VIEW, CentreCoding, av1_fits, encode_centre
from lfstream.codec.jpeg import QUALITY_RANGE, PostFilterChooser
from lfstream.codec.residual import VIEW_MODES, coded_size
from lfstream.codec.shading import measure_gains
from lfstream.errors import LFValueError
from lfstream.lightfield import centre_view, to_uint8

#: How far from the target a chosen configuration may land (relative), when it can.
RATE_TOLERANCE = 0.15
#: The second hint precision rate control tries (the default sends 1/4 resolution): at low
#: rates a 1/8 map costs a third of the bytes for 0.1-0.3 dB (measured on the shared samples).
COARSE_HINT_SCALE = 8
#: Shares of the target the centre view (with hint and gains) takes in residual candidates.
RESIDUAL_SHARES = (0.35, 0.55)
#: The preset of residual candidates when rate control may choose (AV1 centre and residual
#: at SVT-AV1 preset 8: the best measured quality per byte).
RESIDUAL_PRESET = "best"
#: A stream under a bit budget moves the centre's quality by at most this many steps a frame.
FOLLOW_MAX_STEP = 6
#: ... and only when the next frame's share of the budget is off the last frame by more than this.
FOLLOW_DEADBAND = 0.03
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
#: Rate control's searches: ``model`` predicts each family's size and quality from trials on
#: the first frame and codes once (:mod:`lfstream.codec.rate_model`, the default); ``quick``
#: codes every frame once in the default's configuration
#: (:func:`choose_default` under the named preset) and searches the centre view's quality, and
#: the residual's where the centre cannot spend the target (:func:`_quick_configuration`);
#: ``full`` tries every preset, hint precision, the residual layer and the views modes, and
#: decodes each candidate to keep the best measured one. The quick search is the ``fast``
#: preset's.
SEARCHES = ("model", "quick", "full")
#: The quick search adds the residual layer where the centre view alone needs a quality above
#: this: past it a JPEG spends its bits on a view the warp then blurs (lytro_bikes at 0.08
#: bpp: q96 alone 33.17 dB, q88 with a residual 34.85; at 0.04 q85 alone loses 0.38 dB MPSNR
#: to a residual but wins 0.014 MSSIM).
QUICK_MAX_CENTRE_QUALITY = 90
#: ... and tries the hint at twice the scale and no hint where the hint takes at least this
#: share of the target (lytro_bikes at 0.005 and 0.01 bpp, where the 1/4 hint is 53-100 % of
#: the target: the 1/8 one gives +0.4...+2.2 dB; cotton at 0.01: no hint +4.3 dB).
QUICK_HINT_SHARE = 0.2
#: Both searches take the first residual (or views) quality whose stream lands within this
#: share of the target instead of bracketing the nearest: each probe is an AV1 sequence of
#: every view. Measured:
#: the quick search's probes on synthetic, seahorse, bikes, translucent at 0.04-0.1 bpp 69 ->
#: 45 for -0.10...0.00 dB; the full search 20-38 % faster on the same scenes at 0.01-0.08 bpp,
#: -0.07...+0.34 dB.
PROBE_NEAR = 0.05
#: Relative size change per quality step the follower assumes (AV1 centre views measured 3-5 %,
#: JPEG 1.5-3 % around the qualities rate control picks).
FOLLOW_STEP_GROWTH = 0.04


@dataclass(frozen=True)
class RateChoice:
    """The configuration rate control picked, what it measured, and its stream (header and
    packets, the same bytes an encoder with this preset, quality and hint setting writes)."""

    quality: int
    depth_hint: bool
    bpp: float
    mpsnr_first_frame: float | None  # None: not measured (the quick search measures sizes only)
    candidates: tuple[dict, ...]
    header: StreamHeader
    packets: tuple[Packet, ...]
    preset: str = "fast"
    hint_options: HintOptions = HintOptions()  # the chosen hint's options (the default without a hint)
    residual: int | None = None  # the residual layer's quality; None: no residual
    residual_mode: str = "prediction"  # what the residual codes (lfstream.codec.residual.RESIDUAL_MODES)

    def stream(self, present: np.ndarray | None = None) -> bytes:
        """The chosen ``.lfs`` stream (recording ``present``, the views the source had)."""
        from lfstream.codec.bitstream import with_present

        return pack_header(with_present(self.header, present)) + b"".join(
            pack_packet(p, self.header.version) for p in self.packets)


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
    (dB) of the decoder's warp (:func:`lfstream.codec.warp.warp_views_at`) against those
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
    from lfstream.codec.warp import warp_views_at
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


#: What rate control (a ``bpp`` target) chooses itself, and so refuses beside it: option ->
#: why (the callers put their own names to it: ``residual`` / ``--residual``).
RATE_CONTROL_CHOOSES = {
    "residual": "chooses the residual layer itself; give one or the other",
    "post_filter": "names the post-filter itself; give one or the other",
    "hance_map": "does not measure its configurations with JPEG-Hance strength maps; give one or the other",
}


def rate_control_conflict(residual: int | None = None, residual_mode: str = "prediction", post_filter: bool = True,
                          hance_map: bool = False) -> str | None:
    """The first option given beside a ``bpp`` target that rate control chooses itself
    (:data:`RATE_CONTROL_CHOOSES`: ``"residual"``, ``"post_filter"``, ``"hance_map"``), or
    ``None``: the one check behind :func:`lfstream.encode`, ``lfstream encode`` and the
    stream's configuration."""
    if residual is not None or residual_mode != "prediction":
        return "residual"
    if not post_filter:
        return "post_filter"
    if hance_map:
        return "hance_map"
    return None


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
    from lfstream.codec.encoder import Encoder

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


#: The keys every rate-control candidate row has beside its configuration (one schema for
#: the model's rows and the searches'): the searches code every row they list and predict none.
SEARCHED = {"family": None, "coded": True, "predicted_db": None, "predicted_bpp": None}


def _stream_bytes(header: StreamHeader, packets) -> int:
    """Bytes of the ``.lfs`` stream ``header`` and ``packets`` make."""
    return len(pack_header(header)) + sum(p.size(header.version) for p in packets)


def _at_quality(header: StreamHeader, packets: list[Packet], quality: int, images: list[bytes],
                coding: CentreCoding) -> tuple[StreamHeader, list[Packet]]:
    """The stream at another quality: the header records it, each packet carries its centre
    view coded at it; hints and gains do not depend on it."""
    meta = {**header.meta, "quality": quality}
    if "centre" in meta:
        meta["centre"] = coding.as_meta(quality)
    at_q = replace(header, quality=quality, meta=meta)
    return at_q, [replace(p, image=img) for p, img in zip(packets, images)]


def _quality_bracket(size, target_bytes: float, near: float = 0.0) -> tuple[int, int]:
    """The bracket ``(lo, hi)``, ``hi = lo + 1``, of qualities around ``target_bytes`` over
    :data:`QUALITY_RANGE`: ``size(lo) <= target_bytes < size(hi)`` where the range allows
    (``size(q)`` grows with ``q``; it caches what it encodes). The same bracket as plain
    bisection (which probes ``(lo + hi) // 2`` and never the range's ends) in fewer probes,
    each an encode of the centre view or of the residual: after two bisection steps, each
    probe interpolates log-size linearly between the probes nearest the target (a codec's
    sizes are close to log-linear in its quality), strictly inside the bracket. Measured on
    the samples' centre views (80 targets each): 5.0 probes on average instead of 6.7 (AV1
    4.4-4.7, JPEG 5.2-5.5), at most 9. ``near`` > 0: the search stops at the first probe
    within that share of the target and returns it as ``(q, q)``."""
    lo, hi = QUALITY_RANGE
    log_target = float(np.log(target_bytes)) if target_bytes > 0 else -np.inf
    known: dict[int, float] = {}  # probed quality -> log size

    def probe(q: int) -> bool:
        nonlocal lo, hi
        got = size(q)
        known[q] = float(np.log(max(got, 1)))
        if known[q] <= log_target:
            lo = q
        else:
            hi = q
        return near > 0 and abs(got - target_bytes) <= near * target_bytes

    for _ in range(2):
        if hi - lo > 1 and probe(mid := (lo + hi) // 2):
            return mid, mid
    while hi - lo > 1:
        below = sorted(q for q in known if known[q] <= log_target)
        above = sorted(q for q in known if known[q] > log_target)
        # the probes nearest the target on either side; beyond every probe, the nearest two
        pair = (below[-1], above[0]) if below and above else (below[-2:] if below else above[:2])
        guess = (lo + hi) / 2
        if len(pair) == 2 and known[pair[1]] != known[pair[0]]:
            a, b = pair
            guess = a + (log_target - known[a]) * (b - a) / (known[b] - known[a])
        q = int(min(max(round(guess), lo + 1), hi - 1))
        if probe(q):
            return q, q
    return lo, hi


def _fitting_quality(size, target_bytes: float, near: float = 0.0) -> int | None:
    """Of the bracket around ``target_bytes`` (:func:`_quality_bracket`), the quality whose
    ``size`` is nearest the target without passing it by more than :data:`RATE_TOLERANCE`;
    ``None`` when even the lowest quality does not fit (it is encoded only where every probe
    passed the target). ``near`` > 0: the first probe within that share of the target is
    taken (:func:`_quality_bracket`; both searches' residual and views use
    :data:`PROBE_NEAR`)."""
    limit = target_bytes * (1 + RATE_TOLERANCE)
    bracket = _quality_bracket(size, target_bytes, near)
    if bracket[0] == QUALITY_RANGE[0] and size(QUALITY_RANGE[0]) > limit:
        return None
    fits = [q for q in sorted(set(bracket)) if size(q) <= limit]
    return min(fits, key=lambda k: abs(size(k) - target_bytes)) if fits else None


def _best_quality(frames: np.ndarray, packets: list[Packet], header: StreamHeader, target_bytes: float,
                  coding: CentreCoding, key_interval: int) -> tuple[int, list[bytes]]:
    """The quality whose stream is closest to ``target_bytes`` (:func:`_quality_bracket`;
    sizes grow with quality) and that stream's centre-view payloads, JPEGs naming their
    post-filter as an :class:`~lfstream.codec.encoder.Encoder` with hint key frames every
    ``key_interval`` frames names it (the search sizes leave its 10 bytes out)."""
    centres = [centre_view(to_uint8(f)) for f in frames]
    cache: dict[int, tuple[int, list[bytes]]] = {}

    def size(q: int) -> int:
        if q not in cache:
            images = [encode_centre(c, q, coding) for c in centres]
            at_q, moved = _at_quality(header, packets, q, images, coding)
            cache[q] = (_stream_bytes(at_q, moved), images)
        return cache[q][0]

    q = min(_quality_bracket(size, target_bytes), key=lambda k: abs(size(k) - target_bytes))
    if coding.codec != "jpeg":
        return q, cache[q][1]
    chooser = PostFilterChooser(key_interval)
    return q, [chooser.mark(c, img) for c, img in zip(centres, cache[q][1])]


def _residual_candidate(frames: np.ndarray, packets: list[Packet], header: StreamHeader, quality: int,
                        images: list[bytes], coding: CentreCoding, preset: str, opts: HintOptions,
                        gain_grid: int, target_bytes: float) -> tuple[int, StreamHeader, list[Packet]] | None:
    """The residual quality whose stream (centre at ``quality``) lands within
    :data:`PROBE_NEAR` of the target (else the nearest without passing it by more than
    :data:`RATE_TOLERANCE`, :func:`_fitting_quality`); ``None`` when even quality 1 does not
    fit."""
    from lfstream.codec.encoder import RESIDUAL_SPEED, Encoder, residual_meta
    from lfstream.codec.residual import encode_residual

    at_q, moved = _at_quality(header, packets, quality, images, coding)
    ref = Encoder(quality=quality, depth_hint=header.has_hint, hint_options=opts, gain_grid=gain_grid, preset=preset,
                  residual=1)
    u, v, h, w = frames.shape[1:5]
    predictions = [ref.predict(p, (u, v), (h, w)) for p in moved]  # in stream order: delta hints
    frames8 = [to_uint8(f) for f in frames]
    base = _stream_bytes(at_q, moved)
    cache: dict[int, tuple[int, list[bytes]]] = {}

    def size(r: int) -> int:
        if r not in cache:
            payloads = [encode_residual(f, pred, r, RESIDUAL_SPEED[preset]) for f, pred in zip(frames8, predictions)]
            cache[r] = (base + sum(len(x) for x in payloads), payloads)
        return cache[r][0]

    r = _fitting_quality(size, target_bytes, PROBE_NEAR)
    if r is None:
        return None
    meta = {**at_q.meta, "residual": residual_meta(r, RESIDUAL_SPEED[preset])}
    with_res = replace(at_q, meta=meta)
    return r, with_res, [replace(p, residual=x) for p, x in zip(moved, cache[r][1])]


def _views_candidate(frames: np.ndarray, present: np.ndarray | None, preset: str, fps: float,
                     target_bytes: float, hint: bool, mode: str = "views") -> tuple[int, StreamHeader, list[Packet]] | None:
    """The stream whose residual codes the views themselves (``mode``: ``views`` or
    ``half-views``; no gains; the hint only with ``hint``: it does not shape the views, and costs toys_array 0.003 bpp)
    closest to the target without passing it by more than :data:`RATE_TOLERANCE`:
    the centre view and the views' sequence at one quality (the centre is one view among
    U * V: a better centre would buy 1/(U * V) of the MPSNR), searched like the centre's.
    ``None`` when even quality 1 does not fit. Its quality search stops within
    :data:`PROBE_NEAR` of the target, as the residual's (:func:`_fitting_quality`)."""
    from lfstream.codec.encoder import Encoder

    cache: dict[int, tuple[int, StreamHeader, list[Packet]]] = {}

    def size(q: int) -> int:
        if q not in cache:
            enc = Encoder(quality=q, depth_hint=hint, preset=preset, residual=q, residual_mode=mode)
            header = enc.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps)
            packets = [enc.encode_frame(f, t, int(round(t * 1e6 / fps)), present) for t, f in enumerate(frames)]
            cache[q] = (_stream_bytes(header, packets), header, packets)
        return cache[q][0]

    q = _fitting_quality(size, target_bytes, PROBE_NEAR)
    return None if q is None else (q, cache[q][1], cache[q][2])


def follow_rate(quality: int, target_bpp: float, spent_bits: float, done_pixels: int, last_bits: float,
                frame_pixels: int) -> int:
    """The centre view's quality for the next frame of a stream under a bit budget.

    Rate control picks the configuration on the first frame, a key frame; the frames after it
    send delta hints and gain maps and cost less (built-in clip at 0.01 bpp: ~20 % less), so
    a stream kept at the first frame's quality lands under its target. This follower compares
    what the next frame may spend (the budget of every frame so far and the next, minus what
    was spent) with what the last frame took, and moves the quality by the steps that ratio
    needs at :data:`FOLLOW_STEP_GROWTH` a step, at most :data:`FOLLOW_MAX_STEP`, not at all
    within :data:`FOLLOW_DEADBAND`.
    """
    lo, hi = QUALITY_RANGE
    if last_bits <= 0:
        return quality
    allowed = target_bpp * (done_pixels + frame_pixels) - spent_bits
    if allowed <= 0:
        return max(lo, quality - FOLLOW_MAX_STEP)
    ratio = float(np.log(allowed / last_bits))
    if abs(ratio) <= np.log1p(FOLLOW_DEADBAND):
        return quality
    step = int(np.clip(round(ratio / np.log1p(FOLLOW_STEP_GROWTH)), -FOLLOW_MAX_STEP, FOLLOW_MAX_STEP))
    return int(np.clip(quality + step, lo, hi))


def _first_frame_mpsnr(frames: np.ndarray, present: np.ndarray | None, header: StreamHeader,
                       packets: list[Packet]) -> float:
    """MPSNR (dB, at most 100) of a candidate stream's first frame (a key frame) as decoded."""
    from lfstream.codec.decoder import decode
    from lfstream.metrics import mpsnr

    first = pack_header(header) + pack_packet(packets[0], header.version)
    return float(np.minimum(mpsnr(frames[0], decode(first)[0], present=present), 100.0))


def _family(c: dict) -> str:
    """A candidate's family in the model's words (:mod:`lfstream.codec.rate_model`)."""
    if c["residual"] is None:
        return "centre"
    return "views" if c["residual_mode"] in VIEW_MODES else "prediction"


def _choice(candidates: list[dict], target_bpp: float) -> RateChoice:
    """The candidate within :data:`RATE_TOLERANCE` of the target with the best measured
    first-frame MPSNR (else the nearest to the target), as a :class:`RateChoice`."""
    def rank(c: dict) -> tuple:
        off = abs(c["bpp"] - target_bpp) / target_bpp
        measured = c["mpsnr_first_frame"] if c["mpsnr_first_frame"] is not None else 0.0
        return (off > RATE_TOLERANCE, -measured if off <= RATE_TOLERANCE else off)

    best = min(candidates, key=rank)
    header_q, packets_q, opts_q = best["_stream"]
    report = tuple({**{k: v for k, v in c.items() if k != "_stream"}, "family": _family(c)} for c in candidates)
    return RateChoice(best["quality"], best["depth_hint"], best["bpp"], best["mpsnr_first_frame"], report, header_q,
                      packets_q, best["preset"], opts_q, best["residual"], best["residual_mode"] or "prediction")


def _quick_configuration(frames: np.ndarray, target_bpp: float, fps: float, present: np.ndarray | None,
                         hint_options: HintOptions | None, gain_grid: int, preset: str,
                         residual: bool, views_hint: bool = False) -> RateChoice | None:
    """Rate control's quick search (:data:`SEARCHES`) under ``preset``: the default's
    configuration of the first frame (:func:`choose_default`: the hint, at 1/8 of the view
    where that predicts as well as at 1/4), every frame coded once, then only the centre
    view's quality searched to the target (:func:`_best_quality`: about five centre-view
    encodes). Two kinds of rates need more:

    - low, where the hint takes :data:`QUICK_HINT_SHARE` of the target or more: the hint at
      twice the scale and no hint are candidates too (their centre views get those bytes);
    - high, where even the best centre view leaves more than :data:`RATE_TOLERANCE` of the
      target unspent or needs a quality above :data:`QUICK_MAX_CENTRE_QUALITY` (the
      prediction saturates): the residual layer fills the rest, the centre at the larger of
      :data:`RESIDUAL_SHARES`, its quality the first probe within :data:`PROBE_NEAR` of the
      target; and, with every view present, the views coded as one sequence (mode
      ``views``, searched the same way; the hint only with ``views_hint``).

    Where more than one candidate lands within the tolerance, each first frame is decoded
    and the better MPSNR wins, as in the full search; one candidate is not decoded
    (``mpsnr_first_frame`` ``None``). ``None`` where nothing lands within the tolerance or
    the prediction fails (the default would code the views): the full search decides there.
    """
    from lfstream.codec.encoder import Encoder
    from lfstream.metrics import bpp

    views, size = tuple(frames.shape[1:3]), tuple(frames.shape[3:5])
    target_bytes = target_bpp * int(np.prod(frames.shape[:5])) / 8.0
    choice = choose_default(frames[0], 50, present, hint_options, gain_grid, post_filter=False, preset=preset)
    if choice.codes_views:
        return None
    enc = choice.encoder
    opts = enc.hint_options

    def coded(encoder: Encoder, first: Packet | None = None) -> list[Packet]:
        return [first if t == 0 and first is not None else encoder.encode_frame(f, t, int(round(t * 1e6 / fps)), present)
                for t, f in enumerate(frames)]

    candidates: list[dict] = []

    def add(q: int, r: int | None, at_q: StreamHeader, moved: list[Packet], hint: HintOptions | None,
            mode: str = "prediction") -> None:
        got = _stream_bytes(at_q, moved)
        if abs(got - target_bytes) <= RATE_TOLERANCE * target_bytes:
            candidates.append({"preset": preset, "quality": q, "depth_hint": at_q.has_hint,
                               "hint_scale": hint.hint_scale if at_q.has_hint and hint is not None else None,
                               "residual": r, "residual_mode": None if r is None else mode, "bpp": bpp(got, frames.shape),
                               "mpsnr_first_frame": None, **SEARCHED, "_stream": (at_q, tuple(moved), hint or HintOptions())})

    def centre_only(encoder: Encoder, packets: list[Packet], hint: HintOptions | None) -> tuple[int, int]:
        header = encoder.header(views, size, fps)
        q, images = _best_quality(frames, packets, header, target_bytes, encoder.coding, encoder.hint_options.key_interval)
        at_q, moved = _at_quality(header, packets, q, images, encoder.coding)
        add(q, None, at_q, moved, hint)
        return q, _stream_bytes(at_q, moved)

    packets = coded(enc, choice.first)
    q, got = centre_only(enc, packets, opts)
    if sum(len(p.hint) for p in packets) >= QUICK_HINT_SHARE * target_bytes:
        coarse = replace(opts, hint_scale=2 * opts.hint_scale)
        if hint_options is None and min(size) // coarse.hint_scale >= PREDICTION_CHECK_MIN_CELLS:
            enc_c = Encoder(quality=50, depth_hint=True, hint_options=coarse, gain_grid=gain_grid, preset=preset,
                            post_filter=False)
            centre_only(enc_c, coded(enc_c), coarse)
        enc_n = Encoder(quality=50, depth_hint=False, gain_grid=gain_grid, preset=preset, post_filter=False)
        centre_only(enc_n, coded(enc_n), None)
    saturated = got < target_bytes * (1 - RATE_TOLERANCE) or q > QUICK_MAX_CENTRE_QUALITY
    if saturated and residual and views[0] * views[1] > 1 and av1_fits(size):
        enc_r = Encoder(quality=50, depth_hint=True, hint_options=opts, gain_grid=gain_grid, preset=preset,
                        residual=1)
        header_r = enc_r.header(views, size, fps)
        q_r, images = _best_quality(frames, packets, header_r, RESIDUAL_SHARES[-1] * target_bytes, enc_r.coding,
                                    opts.key_interval)
        found = _residual_candidate(frames, packets, header_r, q_r, images, enc_r.coding, preset, opts, gain_grid,
                                    target_bytes)
        if found is not None:
            add(q_r, found[0], found[1], found[2], opts)
        if present is None or np.all(present):
            # the views themselves: where warping misses what the residual must then carry
            # (seahorse at 0.04-0.1 bpp: +1.5...+2.4 dB over the residual)
            views_found = _views_candidate(frames, present, preset, fps, target_bytes, views_hint)
            if views_found is not None:
                q_v, at_v, moved_v = views_found
                add(q_v, q_v, at_v, moved_v, HintOptions() if views_hint else None, "views")
    if not candidates:
        return None
    if len(candidates) > 1:
        for c in candidates:
            c["mpsnr_first_frame"] = _first_frame_mpsnr(frames, present, c["_stream"][0], list(c["_stream"][1]))
    return _choice(candidates, target_bpp)


def validate_target(target_bpp: float, search: str | None = None, preset: str | None = None) -> None:
    """A ``bpp`` target, a search (:data:`SEARCHES`) and a preset, else one
    :class:`~lfstream.errors.LFValueError` before any encoding."""
    from lfstream.codec.encoder import preset_coding

    # a number only: a string or None is the same one line (np.isfinite raised a TypeError
    # on it, and a numeric string got past a float() check to fail at the comparison)
    number = isinstance(target_bpp, (int, float, np.integer, np.floating)) and not isinstance(target_bpp, bool)
    if not (number and np.isfinite(target_bpp) and target_bpp > 0):
        raise LFValueError(f"bpp: a positive target in bits per pixel, got {target_bpp!r}")
    if search is not None and search not in SEARCHES:
        raise LFValueError(f"search: one of {', '.join(SEARCHES)}, got {search!r}")
    if preset is not None:
        preset_coding(preset)  # an unknown name fails before any encoding


def choose_configuration(frames: np.ndarray, target_bpp: float, fps: float, present: np.ndarray | None = None,
                         hint_options: HintOptions | None = None, gain_grid: int = 4,
                         preset: str | None = None, residual: bool = True, views_hint: bool = False,
                         search: str | None = None) -> RateChoice:
    """The (preset, quality, depth hint, hint precision, residual) whose stream lands nearest
    ``target_bpp`` with the best first-frame MPSNR (see the module docstring). ``preset``:
    the only preset to consider; ``None`` considers every preset (and the residual layer
    with :data:`RESIDUAL_PRESET`). ``hint_options``: the only hint options to consider;
    ``None`` tries the default and a 1/8-resolution hint. ``residual``: whether residual
    candidates are tried (they cost a decode and several AV1 sequence encodes per frame).
    ``views_hint``: a candidate that codes the views themselves carries the depth hint too
    (a stream fits its focal planes to it; the views do not need it). ``search``: one of
    :data:`SEARCHES`; ``None``: ``quick`` under the ``fast`` preset (a fast encode is what it
    promises), ``full`` otherwise. The quick search searches one named preset: with
    ``preset=None`` the full search runs whatever ``search`` says.

    Shape:
        - frames: ``(T, U, V, H, W, 3)``
    """
    from lfstream.codec.encoder import PRESETS, Encoder
    from lfstream.metrics import bpp

    validate_target(target_bpp, search, preset)
    if search == "model":
        raise LFValueError("search: the model is lfstream.codec.rate_model.choose_rate's")
    if preset is not None and (search or ("quick" if preset == "fast" else "full")) == "quick":
        quick = _quick_configuration(frames, target_bpp, fps, present, hint_options, gain_grid, preset, residual,
                                     views_hint)
        if quick is not None:
            return quick
    presets = tuple(PRESETS) if preset is None else (preset,)
    if not av1_fits(frames.shape[3:5]):  # views too small for AV1: the JPEG preset alone, no residual
        if preset not in (None, "fast"):
            raise LFValueError(f"preset {preset!r}: AV1 codes views of at least {AV1_MIN_VIEW} pixels, these are "
                               f"{frames.shape[3]}x{frames.shape[4]}")
        presets, residual = ("fast",), False
    pixels = int(np.prod(frames.shape[:5]))
    target_bytes = target_bpp * pixels / 8.0
    candidates = []

    def add(name: str, q: int, hint_scale: int | None, r: int | None, mode: str | None, at_q: StreamHeader,
            moved: list[Packet], opts: HintOptions) -> None:
        candidates.append({"preset": name, "quality": q, "depth_hint": at_q.has_hint, "hint_scale": hint_scale,
                           "residual": r, "residual_mode": mode, "bpp": bpp(_stream_bytes(at_q, moved), frames.shape),
                           "mpsnr_first_frame": _first_frame_mpsnr(frames, present, at_q, moved), **SEARCHED,
                           "_stream": (at_q, tuple(moved), opts)})

    hints = [hint_options] if hint_options is not None else [HintOptions(), HintOptions(hint_scale=COARSE_HINT_SCALE)]
    res_preset = RESIDUAL_PRESET if preset is None else preset
    for hint, opts in [(True, h) for h in hints] + [(False, HintOptions())]:
        # hints and gains do not depend on the preset: one encode per frame, the centre
        # view recoded per preset and quality (so no post-filter is measured on these q50 ones)
        enc = Encoder(quality=50, depth_hint=hint, hint_options=opts, gain_grid=gain_grid, post_filter=False)
        packets = [enc.encode_frame(f, t, int(round(t * 1e6 / fps)), present) for t, f in enumerate(frames)]
        for name in presets:
            enc_p = Encoder(quality=50, depth_hint=hint, hint_options=opts, gain_grid=gain_grid, preset=name)
            header = enc_p.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps)
            q, images = _best_quality(frames, packets, header, target_bytes, enc_p.coding, opts.key_interval)
            at_q, moved = _at_quality(header, packets, q, images, enc_p.coding)
            add(name, q, opts.hint_scale if hint else None, None, None, at_q, moved, opts)
        if not (residual and hint and opts.hint_scale == HintOptions().hint_scale and frames.shape[1] * frames.shape[2] > 1):
            continue
        enc_r = Encoder(quality=50, depth_hint=True, hint_options=opts, gain_grid=gain_grid, preset=res_preset,
                        residual=1)
        header_r = enc_r.header(tuple(frames.shape[1:3]), tuple(frames.shape[3:5]), fps)
        for share in RESIDUAL_SHARES:
            q, images = _best_quality(frames, packets, header_r, share * target_bytes, enc_r.coding,
                                      opts.key_interval)
            found = _residual_candidate(frames, packets, header_r, q, images, enc_r.coding, res_preset, opts,
                                        gain_grid, target_bytes)
            if found is not None:
                r, at_q, moved = found
                add(res_preset, q, opts.hint_scale, r, "prediction", at_q, moved, opts)

    if residual and frames.shape[1] * frames.shape[2] > 1 and (present is None or np.all(present)):
        # the views themselves (scenes warping cannot predict: toys_array); not where views
        # are missing: a prediction reconstructs those, a coded sequence would not
        for mode in VIEW_MODES:
            if not av1_fits(coded_size(tuple(frames.shape[3:5]), mode)):
                continue  # half-size views of small views: below what AV1 codes
            found = _views_candidate(frames, present, res_preset, fps, target_bytes, views_hint, mode)
            if found is not None:
                q, at_q, moved = found
                add(res_preset, q, HintOptions().hint_scale if views_hint else None, q, mode, at_q, moved, HintOptions())

    return _choice(candidates, target_bpp)


__all__ = ["RATE_CONTROL_CHOOSES", "rate_control_conflict",
           "RATE_TOLERANCE", "SEARCHES", "QUICK_MAX_CENTRE_QUALITY", "QUICK_HINT_SHARE", "PROBE_NEAR",
           "COARSE_HINT_SCALE", "RESIDUAL_SHARES", "RESIDUAL_PRESET", "FOLLOW_MAX_STEP",
           "FOLLOW_DEADBAND", "FOLLOW_STEP_GROWTH", "PREDICTION_FLOOR_DB", "PREDICTION_CHECK_MIN_CELLS",
           "HINT_COARSEN_MAX_LOSS_DB", "HINT_COARSEN_DB_PER_PERCENT", "coarsening_allowance",
           "DEFAULT_PRESET_BY_VIEWS", "default_preset",
           "RateChoice", "DefaultChoice",
           "choose_configuration", "validate_target", "choose_default", "uses_default_choice", "follow_rate", "prediction_psnr"]
