"""What every rate control shares: the configuration it chose (:class:`RateChoice`), the
checks of a target, a stream's size, and the follower that holds a video to its budget: a
stream sees one frame at a time, chooses on its first frame and then follows the budget
frame by frame (:func:`follow_rate`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader, pack_header, pack_packet
from lfstream.codec.centre import CentreCoding
from lfstream.codec.centre.jpeg import QUALITY_RANGE
from lfstream.codec.encoder import preset_coding
from lfstream.codec.hint import HintOptions
from lfstream.errors import LFValueError

#: How far from the target a chosen configuration may land (relative), when it can.
RATE_TOLERANCE = 0.15


#: A stream under a bit budget moves the centre's quality by at most this many steps a frame.
FOLLOW_MAX_STEP = 6


#: ... and only when the next frame's share of the budget is off the last frame by more than this.
FOLLOW_DEADBAND = 0.03


#: Rate control's searches: ``model`` predicts each family's size and quality from trials on
#: the first frame and codes once (:mod:`lfstream.codec.rate.model`, the default); ``quick``
#: codes every frame once in the default's configuration
#: (:func:`choose_default` under the named preset) and searches the centre view's quality, and
#: the residual's where the centre cannot spend the target (:func:`_quick_configuration`);
#: ``full`` tries every preset, hint precision, the residual layer and the views modes, and
#: decodes each candidate to keep the best measured one. The quick search is the ``fast``
#: preset's.
SEARCHES = ("model", "quick", "full")


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
    # the encoder after the frames coded, and the budget it follows (lfstream.codec.rate.follow);
    # None where the choice kept no encoder (the searches recode the centre view apart)
    follower: object | None = field(default=None, compare=False, repr=False)

    def stream(self, present: np.ndarray | None = None) -> bytes:
        """The chosen ``.lfs`` stream (recording ``present``, the views the source had)."""
        from lfstream.codec.bitstream import with_present

        return pack_header(with_present(self.header, present)) + b"".join(
            pack_packet(p, self.header.version) for p in self.packets)


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
    from lfstream.codec.decoder import Decoder
    from lfstream.metrics import mpsnr

    decoded = Decoder(header).decode_packet(packets[0]).lf
    return float(np.minimum(mpsnr(frames[0], decoded, present=present), 100.0))


def validate_target(target_bpp: float, search: str | None = None, preset: str | None = None) -> None:
    """A ``bpp`` target, a search (:data:`SEARCHES`) and a preset, else one
    :class:`~lfstream.errors.LFValueError` before any encoding."""


    # a number only: a string or None is the same one line (np.isfinite raised a TypeError
    # on it, and a numeric string got past a float() check to fail at the comparison)
    number = isinstance(target_bpp, (int, float, np.integer, np.floating)) and not isinstance(target_bpp, bool)
    if not (number and np.isfinite(target_bpp) and target_bpp > 0):
        raise LFValueError(f"bpp: a positive target in bits per pixel, got {target_bpp!r}")
    if search is not None and search not in SEARCHES:
        raise LFValueError(f"search: one of {', '.join(SEARCHES)}, got {search!r}")
    if preset is not None:
        preset_coding(preset)  # an unknown name fails before any encoding

