"""The frames after the first under a bit budget: x264's ABR in spirit. Each frame's quality
follows the bits spent so far (:func:`~lfstream.codec.rate.common.follow_rate`); a frame
whose size is far off what the budget allows it (or over :data:`FRAME_CAP` times its share)
is coded once more at the quality the size model gives."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfstream.codec.bitstream import Packet, StreamHeader
from lfstream.codec.centre.jpeg import QUALITY_RANGE
from lfstream.codec.rate.common import FOLLOW_MAX_STEP, FOLLOW_STEP_GROWTH, _stream_bytes, follow_rate

#: The most one frame of a video may cost, in multiples of its share of the target.
FRAME_CAP = 3.0
#: A video frame whose size is off what the budget allows it by more than this factor (either
#: way) is coded once more.
FRAME_REDO = 1.25
#: What a stream's bits go to: the centre view (and hint) alone, a residual of the
#: prediction, or the views themselves as one sequence (:mod:`lfstream.codec.rate.model`).
FAMILIES = ("centre", "prediction", "views")


def family_of(residual: int | None, residual_mode: str | None) -> str:
    """The family (:data:`FAMILIES`) of a configuration."""
    from lfstream.codec.residual import VIEW_MODES

    if residual is None:
        return "centre"
    return "views" if residual_mode in VIEW_MODES else "prediction"


def set_quality(encoder, quality: int, family: str, step: int) -> None:
    """Moves a stream's qualities: the centre's; a residual's by the same step; the views'
    sequence is one quality."""
    lo, hi = QUALITY_RANGE
    encoder.quality = int(quality)
    if family == "views":
        encoder.residual = int(quality)
    elif family == "prediction" and encoder.residual is not None:
        encoder.residual = int(np.clip(encoder.residual + step, lo, hi))


@dataclass
class RateFollower:
    """A stream's encoder after its first frame, and the budget it follows.

    Attributes:
        encoder: the :class:`~lfstream.codec.encoder.Encoder` that coded frame 0 (its hint
            and gain trackers continue from there).
        family: what the bits go to (:data:`FAMILIES`).
        header: the stream's header (its version sets each packet's size).
        target_bpp: the target, bits per pixel.
        frame_pixels: pixels of one frame (``U * V * H * W``).
        spent_bits: bits of the stream so far, header included.
        last_bits: bits of the last frame's packet.
        frames: frames coded so far.
    """

    encoder: object  # lfstream.codec.encoder.Encoder
    family: str
    header: StreamHeader
    target_bpp: float
    frame_pixels: int
    spent_bits: float
    last_bits: float
    frames: int = 1

    @classmethod
    def after(cls, encoder, family: str, header: StreamHeader, first: Packet, target_bpp: float,
              frame_pixels: int) -> RateFollower:
        """The follower of a stream whose frame 0 is ``first``."""
        return cls(encoder, family, header, float(target_bpp), int(frame_pixels),
                   8.0 * _stream_bytes(header, [first]), 8.0 * first.size(header.version))

    @property
    def frame_budget(self) -> float:
        """A frame's share of the target, in bytes."""
        return self.target_bpp * self.frame_pixels / 8.0

    def encode_frame(self, frame: np.ndarray, t: int, timestamp_us: int, present: np.ndarray | None = None) -> Packet:
        """The next frame's packet, its quality moved by the bits spent so far (and coded once
        more where it missed its allowance by far)."""
        enc, n = self.encoder, self.frames
        q0 = int(enc.quality)
        q = follow_rate(q0, self.target_bpp, self.spent_bits, n * self.frame_pixels, self.last_bits, self.frame_pixels)
        set_quality(enc, q, self.family, q - q0)
        pkt = enc.encode_frame(frame, t, timestamp_us, present)
        got = pkt.size(self.header.version)
        allowed = max(self.target_bpp * (n + 1) * self.frame_pixels / 8.0 - self.spent_bits / 8.0, 1.0)
        budget = self.frame_budget
        if got > FRAME_CAP * budget or not 1 / FRAME_REDO <= got / allowed <= FRAME_REDO:
            # past the bound, or far off what the budget allows: coded once more at the
            # quality the follower's size model gives (a frame over the bound at least as low
            # as one step of the follower)
            step = int(np.clip(round(np.log(allowed / got) / np.log1p(FOLLOW_STEP_GROWTH)), -3 * FOLLOW_MAX_STEP,
                               3 * FOLLOW_MAX_STEP))
            if got > FRAME_CAP * budget:
                step = min(step, -FOLLOW_MAX_STEP)
            q2 = int(np.clip(q + step, *QUALITY_RANGE))
            if q2 != q:
                set_quality(enc, q2, self.family, q2 - q)
                pkt = enc.encode_frame(frame, t, timestamp_us, present)
        self.last_bits = 8.0 * pkt.size(self.header.version)
        self.spent_bits += self.last_bits
        self.frames += 1
        return pkt


__all__ = ["FRAME_CAP", "FRAME_REDO", "FAMILIES", "family_of", "set_quality", "RateFollower"]
