"""What every reader takes (:class:`ReadOptions`) and gives back (:class:`LoadedLF`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfstream.errors import LFValueError
from lfstream.lightfield import check_first_frame


@dataclass(frozen=True)
class ReadOptions:
    """How to interpret a light-field source (every reader takes the same options).

    Attributes:
        angular: microlens size in pixels of a lenslet (ESLF) image (Lytro Illum: 14; some
            decoders write 15).
        crop: keep the central ``crop x crop`` views.
        grid: ``(U, V)`` of a mosaic image or mosaic video without stored metadata.
        flip_u, flip_v: reverse the view rows / columns, for sources whose view order
            disagrees with lfstream's (HCI) disparity convention.
        allow_missing: load a folder with missing views, zero-filled, with ``present`` set;
            without it missing views raise :class:`~lfstream.errors.LFMissingViewsError`.
        max_frames: read at most this many frames of a video.
        first_frame: the video's frame to start at (0: its first); the frames before it
            are skipped, decoding as little of them as the format allows (an intra-only
            video, such as an ``.avi``, decodes none; an ``.lfs`` stream only reads their
            hints and gain maps). With ``max_frames``, a range.
    """

    angular: int | None = None
    crop: int | None = None
    grid: tuple[int, int] | None = None
    flip_u: bool = False
    flip_v: bool = False
    allow_missing: bool = False
    max_frames: int | None = None
    first_frame: int = 0

    def __post_init__(self) -> None:
        check_first_frame(self.first_frame)
        if self.max_frames is not None and (not isinstance(self.max_frames, (int, np.integer)) or self.max_frames < 1):
            raise LFValueError(f"max_frames: a positive integer, got {self.max_frames!r}")
        if self.crop is not None and (not isinstance(self.crop, (int, np.integer)) or self.crop < 1):
            raise LFValueError(f"crop: a positive integer, got {self.crop!r}")



@dataclass
class LoadedLF:
    """A light field read from disk together with what the source said about it.

    Attributes:
        lf: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)``.
        format: detected format name (``npy``, ``npz``, ``sai-folder``, ``eslf``, ``mosaic``,
            ``video``, ``view-videos``, ``frames-folder``, ``lfs``).
        path: the path read.
        present: ``(U, V)`` bool mask of views that exist in the source, or ``None`` when
            all are present. Missing views are zero in ``lf``.
        weight: per-sample weight ``(U, V, H, W)`` float32 from a lenslet image's alpha
            channel, or ``None``.
        disparity: ground-truth disparity ``(U, V, H, W)`` or ``(T, U, V, H, W)`` if the
            source carries one (``.npz`` from :mod:`lfstream.synth`).
        fps: frame rate of video sources, else ``None``.
    """

    lf: np.ndarray
    format: str
    path: Path
    present: np.ndarray | None = None
    weight: np.ndarray | None = None
    disparity: np.ndarray | None = None
    fps: float | None = None

    @property
    def frames(self) -> int:
        return int(self.lf.shape[0]) if self.lf.ndim == 6 else 1

    @property
    def views(self) -> tuple[int, int]:
        return int(self.lf.shape[-5]), int(self.lf.shape[-4])

    @property
    def size(self) -> tuple[int, int]:
        return int(self.lf.shape[-3]), int(self.lf.shape[-2])


__all__ = ["ReadOptions", "LoadedLF"]
