"""One exception hierarchy for everything lfstream raises on purpose.

Every class derives from :class:`LFStreamError`; where a Python built-in is the natural
category (a bad value, a failing file) the class also derives from it, so callers who
catch ``ValueError`` or ``OSError`` keep working.
"""

from __future__ import annotations


class LFStreamError(Exception):
    """Base class of every error lfstream raises deliberately."""


class LFValueError(LFStreamError, ValueError):
    """A parameter or array has an invalid value, shape or dtype."""


class LFShapeError(LFValueError):
    """An array does not follow the (T,)U,V,H,W,C convention or sizes disagree."""


class LFFileError(LFStreamError, OSError):
    """A file or folder cannot be read or written."""


class LFFormatError(LFFileError):
    """A file exists but its content or naming is not a supported light-field format."""


class LFMissingViewsError(LFFormatError):
    """A sub-aperture folder lacks some views of its grid."""

    def __init__(self, message: str, missing: list[tuple[int, int]]):
        super().__init__(message)
        self.missing = missing


class BitstreamError(LFValueError):
    """An ``.lfs`` stream or packet is corrupt, truncated or exceeds a limit."""

    def __init__(self, message: str, frame: int | None = None):
        super().__init__(message if frame is None else f"frame {frame}: {message}")
        self.frame = frame


class EncoderStalledError(LFStreamError):
    """A third-party encoder (SVT-AV1, x265) did not return within its deadline on every
    attempt (:mod:`lfstream.codec.deadline`)."""


class WeightsError(LFFileError):
    """A shipped network weights file is missing or does not match its SHA-256."""


__all__ = [
    "LFStreamError",
    "LFValueError",
    "LFShapeError",
    "LFFileError",
    "LFFormatError",
    "LFMissingViewsError",
    "BitstreamError",
    "WeightsError",
    "EncoderStalledError",
]
