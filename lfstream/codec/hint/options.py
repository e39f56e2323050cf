"""The depth hint's options and the payload's framing: :class:`HintOptions`, versions, kinds and
coders of the payload, and the view axes' convention (:func:`is_standard`)."""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from lfstream.errors import BitstreamError, LFValueError


class HintReferenceError(BitstreamError):
    """A delta hint refers to a frame this decoder never received (lost in transport)."""


_HEADER = struct.Struct("<BBBBffHHI")


_AXES = struct.Struct("<4f")


#: The payload's format (its first byte); 1 to 5 were written by development builds and are
#: refused with a line that says so.
HINT_FORMAT = 6


OLDER_HINT_FORMATS = (1, 2, 3, 4, 5)


#: The kind byte's flag: the view axes follow the header.
KIND_AXES = 0x80


GEOMETRY_MODES = ("auto", "standard")


#: Largest entry of a view-axes matrix a payload may carry (|A| <= 8: a view step moving a
#: point eight times its disparity is not a light field this codec models).
MAX_AXIS_ENTRY = 8.0


KIND_FULL, KIND_DELTA, KIND_REPEAT = 0, 1, 2


#: How a body is coded (the header's fourth byte, zero before coders existed): zstd, or
#: context-adaptive range coding of the map's levels (full maps; :mod:`lfstream.codec._entropy`)
CODER_ZSTD, CODER_CONTEXT = 0, 1


_ZSTD_LEVEL = 9  # delta maps: level 19 costs ~3 ms for a few hundred bytes less


@dataclass(frozen=True)
class HintOptions:
    """Sweep and coding parameters of the depth hint.

    Attributes:
        max_disparity: search ``[-max_disparity, max_disparity]`` px per view step; ``None``
            (default) derives the range from the scene (coarse pass or previous frame).
        hint_scale: the map is sent at ``1 / hint_scale`` resolution (block means of the
            sweep's map).
        work_scale: the sweep runs at ``1 / work_scale`` (a divisor of ``hint_scale``):
            measured on the real samples, sweeping at the sent resolution (1/4) loses 0.3 to
            2.5 dB of decoded MPSNR against 1/2, which costs about four times the time.
        step: candidate spacing, as the change of the outermost view's shift in pixels of
            the working resolution (smaller: finer, slower); the parabolic fit refines it.
        min_spacing: the candidates' spacing is at least this many pixels of the full view
            per view step (0: ``step`` alone). On a 7x7 grid ``step`` alone spaces them 1/6
            px apart; a quarter pixel (a third fewer candidates) encodes faster, decoded
            MPSNR within 0.02 dB of the finer sweep on the real captures (synthetic clip +0.04 dB), MSSIM within
            0.0001, and on the ground truth of 14 synthetic 7x7x375x540 scenes MSEx100
            28.63 -> 28.19, BadPix(0.07) 0.406 -> 0.356. It does not bind on 5x5 or 3x3 grids
            (1/4 and 1/2 px already), where wider spacing lost: seahorse (5x5) -0.09 dB at
            3/8 px, -0.21 dB on a 128x160 crop.
        box_radius: cost aggregation window radius at the working resolution.
        coarse_scale: resolution divisor of the range-finding pass.
        search_limit: largest ``|disparity|`` (px per view step) the range pass considers.
        key_interval: in a video, a full (non-delta) map at least every this many frames,
            so a receiver that lost packets recovers.
        geometry: ``"auto"`` estimates the capture's view axes on a stream's first frame
            (:func:`estimate_view_axes`); ``"standard"`` assumes the convention (``A = I``).
        median: size (1, 3 or 5) of a median filter on the sent grid; 1: none. The sweep's
            outliers (textureless and occluded pixels) cost bits and help no view.
        precision: quantisation step, as the displacement it makes at the outermost view, in
            pixels (0: the 8-bit grid's finest step). The payload's format is the same; the
            encoder only uses every k-th level, which codes in fewer bytes. Measured
            (with ``median=3``, q50, one frame, against the 8-bit map without the median):
            9-25 % off the stream's bytes on the shared samples and the synthetic clip
            (most of it hint bytes) at MPSNR within 0.05 dB and MSSIM within 0.0005.
    """

    max_disparity: float | None = None
    hint_scale: int = 4
    work_scale: int = 2
    step: float = 0.25
    min_spacing: float = 0.25
    box_radius: int = 2
    coarse_scale: int = 8
    search_limit: float = 16.0
    key_interval: int = 30
    geometry: str = "auto"
    median: int = 3
    precision: float = 0.2

    def validate(self) -> None:
        if self.max_disparity is not None and not (np.isfinite(self.max_disparity) and 0 < self.max_disparity <= 64):
            raise LFValueError(f"max_disparity: in (0, 64] or None, got {self.max_disparity}")
        if not (1 <= self.hint_scale <= 64 and 1 <= self.coarse_scale <= 256 and 0 <= self.box_radius <= 32):
            raise LFValueError("hint options: hint_scale in 1..64, coarse_scale in 1..256, box_radius in 0..32")
        if not (1 <= self.work_scale <= self.hint_scale):
            raise LFValueError("hint options: work_scale in 1..hint_scale")
        if not (0.01 <= self.step <= 2 and 0 < self.search_limit <= 64 and self.key_interval >= 1):
            raise LFValueError("hint options: step in [0.01, 2], search_limit in (0, 64], key_interval >= 1")
        if self.median not in (1, 3, 5):
            raise LFValueError(f"hint options: median 1, 3 or 5, got {self.median!r}")
        if not (np.isfinite(self.min_spacing) and 0 <= self.min_spacing <= 4):
            raise LFValueError(f"hint options: min_spacing in [0, 4] px, got {self.min_spacing!r}")
        if not (np.isfinite(self.precision) and 0 <= self.precision <= 4):
            raise LFValueError(f"hint options: precision in [0, 4] px, got {self.precision!r}")
        if self.geometry not in GEOMETRY_MODES:
            raise LFValueError(f"hint options: geometry one of {', '.join(GEOMETRY_MODES)}, got {self.geometry!r}")

    def as_meta(self) -> dict:
        """What the stream header records about the hint."""
        return {"max_disparity": self.max_disparity, "hint_scale": self.hint_scale, "work_scale": self.work_scale,
                "step": self.step, "box_radius": self.box_radius, "median": self.median, "precision": self.precision}


def is_standard(axes: np.ndarray | None) -> bool:
    """Whether view axes are the convention's (``None`` or exactly the identity)."""
    return axes is None or bool(np.array_equal(np.asarray(axes), np.eye(2)))
