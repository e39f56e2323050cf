"""Where a stream's frames come from: the built-in synthetic clip or an LF file/video."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from lfstream.errors import LFValueError
from lfstream.io.readers import ReadOptions, load_lf
from lfstream.io.video import VIDEO_EXTS, iter_video_frames, video_grid_and_fps
from lfstream.lightfield import from_mosaic


def synthetic_source(frames: int = 24, views: int = 7, size: tuple[int, int] = (375, 540),
                     seed: int = 2024) -> Iterator[np.ndarray]:
    """The built-in clip: a layered synthetic scene with motion, a pan, sensor noise and
    vignetting, rendered frame by frame (deterministic)."""
    from lfstream.synth import SynthConfig, iter_clip

    cfg = SynthConfig(frames=frames, views=views, size=size, layers=4, motion=1.0, camera_pan=0.4,
                      noise=1.5, vignetting=0.2, seed=seed)
    for lf, _ in iter_clip(cfg):
        yield lf


def file_source(path: str | os.PathLike, options: ReadOptions | None = None) -> tuple[Iterator[np.ndarray], float | None]:
    """Frames of an LF file and its frame rate; mosaic videos are read lazily (one frame in
    memory at a time)."""
    opts = options or ReadOptions()
    path = Path(path)
    if path.is_file() and path.suffix.lower() in VIDEO_EXTS and not opts.crop:
        grid, fps = video_grid_and_fps(path)
        grid = opts.grid or grid
        if grid is not None:
            return (from_mosaic(f, grid) for f in iter_video_frames(path, opts.max_frames)), fps
    loaded = load_lf(path, opts)
    if loaded.present is not None and not loaded.present.all():
        raise LFValueError(f"{path}: streaming needs every view (this source has {int((~loaded.present).sum())} missing)")
    lf = loaded.lf if loaded.lf.ndim == 6 else loaded.lf[None]
    return iter(lf), loaded.fps


__all__ = ["synthetic_source", "file_source"]
