"""Where a stream's frames come from: the built-in synthetic clip or an LF file/video."""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfstream.errors import LFValueError
from lfstream.io.readers import ReadOptions, load_lf, open_video_lf, reads_lazily

#: Bump when the renderer's output changes, so stale cached clips are not reused.
BUILTIN_CLIP_VERSION = 1


def cache_dir() -> Path | None:
    """Where lfstream keeps derived data between runs: ``$LFSTREAM_CACHE``, else
    ``$XDG_CACHE_HOME/lfstream``, else ``~/.cache/lfstream``; ``None`` if it cannot be made
    (then nothing is cached)."""
    base = os.environ.get("LFSTREAM_CACHE")
    if base is None:
        xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        base = os.path.join(xdg, "lfstream")
    try:
        path = Path(base)
        path.mkdir(parents=True, exist_ok=True)
        return path if os.access(path, os.W_OK) else None
    except OSError:
        return None


def synthetic_source(frames: int = 24, views: int = 7, size: tuple[int, int] = (375, 540),
                     seed: int = 2024, cache: bool = True) -> Iterator[np.ndarray]:
    """The built-in clip: a layered synthetic scene with motion, a pan, sensor noise and
    vignetting (deterministic).

    Rendering costs ~0.4 s a frame at 7x7x375x540, more than the whole codec, so with
    ``cache`` the first run writes the frames it renders to :func:`cache_dir` (a raw
    ``.npy``, 30 MB a frame, renamed into place only when complete) and later runs read
    them back memory-mapped (read-only frames): the source is then never the pipeline's
    bottleneck.
    """
    from lfstream.synth import SynthConfig, iter_clip

    cfg = SynthConfig(frames=frames, views=views, size=size, layers=4, motion=1.0, camera_pan=0.4,
                      noise=1.5, vignetting=0.2, seed=seed)
    folder = cache_dir() if cache else None
    shape = (frames, views, views, size[0], size[1], 3)
    path = None if folder is None else folder / (
        f"builtin-v{BUILTIN_CLIP_VERSION}-{frames}x{views}x{views}x{size[0]}x{size[1]}-seed{seed}.npy")
    if path is not None and path.exists():
        try:
            clip = np.load(path, mmap_mode="r")
        except (OSError, ValueError):
            clip = None
        if clip is not None and clip.shape == shape and clip.dtype == np.uint8:
            # read-only views of the mapped file, not copies: a 30 MB copy a frame page-faults
            # a fresh buffer, and beside the pipeline's other threads those faults cost
            # 20-55 ms of system time a frame (measured per thread); the views fault in
            # page-cache pages only
            yield from clip
            return
    store = None
    if path is not None:
        from lfstream.io._fs import temp_sibling

        tmp = temp_sibling(path)
        try:
            store = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.uint8, shape=shape)
        except OSError:
            store = None
    done = 0
    try:
        for lf, _ in iter_clip(cfg):
            if store is not None:
                store[done] = lf
            done += 1
            yield lf
    finally:
        if store is not None:
            store.flush()
            del store
            # the cache is a convenience: a folder that went away meanwhile (a test's temporary
            # cache removed before this generator was collected) must not raise from here
            try:
                if done == frames:
                    os.replace(tmp, path)  # complete: later runs read it
                else:
                    tmp.unlink(missing_ok=True)  # a stream stopped early leaves no partial cache
            except OSError:
                pass


@dataclass
class Source:
    """The frames of a stream and what is known about them.

    Attributes:
        frames: iterator of ``(U, V, H, W, 3)`` uint8 frames.
        fps: frame rate, when the source records one.
        present: ``(U, V)`` mask of the views that exist (a folder with missing views read
            with ``allow_missing``); ``None``: all views.
        total: number of frames, when known (progress and ETA).
    """

    frames: Iterator[np.ndarray]
    fps: float | None = None
    present: np.ndarray | None = None
    total: int | None = None


def file_source(path: str | os.PathLike, options: ReadOptions | None = None) -> Source:
    """The frames of an LF file; mosaic videos and ``.lfs`` streams are read lazily (one
    frame in memory at a time). With ``options.allow_missing`` a folder with missing views streams: the encoder
    sends the centre view (which must exist) and the metrics count the present views only."""
    opts = options or ReadOptions()
    path = Path(path)
    if reads_lazily(path):
        # frame by frame, crop and flips applied (the flips were once skipped here)
        video = open_video_lf(path, opts)
        return Source(video.frames, video.fps, None, video.count or opts.max_frames)
    loaded = load_lf(path, opts)
    present = loaded.present
    if present is not None and present.all():
        present = None
    if present is not None:
        u, v = present.shape
        if not present[u // 2, v // 2]:
            raise LFValueError(f"{path}: the centre view is missing; it is the view the codec sends")
    lf = loaded.lf if loaded.lf.ndim == 6 else loaded.lf[None]
    return Source(iter(lf), loaded.fps, present, len(lf))


__all__ = ["BUILTIN_CLIP_VERSION", "Source", "cache_dir", "synthetic_source", "file_source"]
