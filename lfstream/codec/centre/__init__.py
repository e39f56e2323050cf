"""The centre view's coding: JPEG (:mod:`~lfstream.codec.centre.jpeg`, the seed's choice and
the ``fast`` preset, with its post-filters), an AV1 intra frame (:mod:`~lfstream.codec.centre.av1`,
the ``balanced`` and ``best`` presets), and the JPEG-Hance strength map
(:mod:`~lfstream.codec.centre.hance`). This module chooses between the two coders by the
stream's codec id."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lfstream.codec.bitstream import CODEC_AV1, CODEC_JPEG, CODEC_NAMES
from lfstream.codec.centre.av1 import AV1_SPEED_RANGE, decode_av1, encode_av1, svt_crf
from lfstream.codec.centre.jpeg import decode_jpeg, encode_jpeg
from lfstream.errors import BitstreamError, LFValueError

CODEC_IDS = {name: cid for cid, name in CODEC_NAMES.items()}


@dataclass(frozen=True)
class CentreCoding:
    """How the centre view is coded.

    Attributes:
        codec: ``"jpeg"`` or ``"av1"``.
        speed: SVT-AV1 preset (``AV1_SPEED_RANGE``; higher is faster, fewer bits saved);
            ignored for JPEG.
    """

    codec: str = "jpeg"
    speed: int = 12

    def __post_init__(self) -> None:
        if self.codec not in CODEC_IDS:
            raise LFValueError(f"centre codec: one of {', '.join(CODEC_IDS)}, got {self.codec!r}")
        lo, hi = AV1_SPEED_RANGE
        if not isinstance(self.speed, (int, np.integer)) or not lo <= self.speed <= hi:
            raise LFValueError(f"AV1 speed preset: an integer in {lo}..{hi}, got {self.speed!r}")

    @property
    def codec_id(self) -> int:
        return CODEC_IDS[self.codec]

    def as_meta(self, quality: int) -> dict:
        """What the stream header records (the decoder needs only the codec id)."""
        if self.codec == "jpeg":
            return {"codec": "jpeg", "quality": int(quality)}
        return {"codec": "av1", "quality": int(quality), "crf": svt_crf(quality, self.speed), "svt_preset": int(self.speed)}


def encode_centre(img: np.ndarray, quality: int, coding: CentreCoding) -> bytes:
    """The centre view's payload in the chosen coding."""
    if coding.codec == "jpeg":
        return encode_jpeg(img, quality)
    return encode_av1(img, quality, coding.speed)


def decode_centre(data: bytes, codec_id: int, size: tuple[int, int], frame: int | None = None) -> np.ndarray:
    """A centre-view payload to uint8 RGB ``(H, W, 3)`` by the header's codec id."""
    if codec_id == CODEC_JPEG:
        return decode_jpeg(data, size, frame)
    if codec_id == CODEC_AV1:
        return decode_av1(data, size, frame)
    raise BitstreamError(f"unknown centre-view codec id {codec_id}", frame)


__all__ = ["CODEC_IDS", "CentreCoding", "encode_centre", "decode_centre"]
