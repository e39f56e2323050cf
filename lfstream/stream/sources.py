"""Where a stream's frames come from: the built-in synthetic clip or an LF file/video."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfstream.errors import LFValueError
from lfstream.io.readers import ReadOptions, open_lf_frames

#: Bump when the renderer's output changes, so stale cached clips are not reused.
BUILTIN_CLIP_VERSION = 2
#: The longest built-in clip ``lfstream stream`` renders ahead, during its warm-up (about 0.4
#: s a 7x7x375x540 frame: 48 frames in the shadow of a fresh install's ~30 s of compiling);
#: a longer one renders as it streams on its first run, its frames flowing from the start.
PRERENDER_MAX_FRAMES = 48


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


def _layout_frames(frames: int) -> int:
    """The clip length the scene is laid out for: every clip up to :data:`PRERENDER_MAX_FRAMES`
    frames is the start of that one, so one cache file serves them all."""
    return max(frames, PRERENDER_MAX_FRAMES)


def _clip_config(frames: int, views: int, size: tuple[int, int], seed: int):
    from lfstream.synth import SynthConfig

    return SynthConfig(frames=frames, views=views, size=size, layers=4, motion=1.0, camera_pan=0.4,
                       noise=1.5, vignetting=0.2, seed=seed, travel_frames=_layout_frames(frames))


def _clip_cache(frames: int, views: int, size: tuple[int, int], seed: int) -> Path | None:
    """The cache file of the built-in clip with these parameters (``None``: no cache folder):
    one file for every length up to :data:`PRERENDER_MAX_FRAMES` (it holds the longest
    rendered so far), one per length beyond."""
    folder = cache_dir()
    layout = _layout_frames(frames)
    return None if folder is None else folder / (
        f"builtin-v{BUILTIN_CLIP_VERSION}-layout{layout}x{views}x{views}x{size[0]}x{size[1]}-seed{seed}.npy")


def _cached_clip(path: Path | None, shape: tuple[int, ...]) -> np.ndarray | None:
    """The first ``shape[0]`` frames of the cached clip at ``path``, memory-mapped read-only,
    where it is there, whole and at least that long."""
    if path is None or not path.exists():
        return None
    try:
        clip = np.load(path, mmap_mode="r")
    except (OSError, ValueError):
        return None
    if clip.dtype != np.uint8 or clip.ndim != len(shape) or clip.shape[1:] != shape[1:] or len(clip) < shape[0]:
        return None
    return clip[: shape[0]]


def _fits_on_disk(folder: Path, nbytes: int) -> bool:
    """Whether ``nbytes`` leave a quarter of ``folder``'s free space: the cache is a
    memory-mapped file, and a mapped page written past a full disk is a SIGBUS, not an error."""
    import shutil

    try:
        return nbytes <= 0.75 * shutil.disk_usage(folder).free
    except OSError:
        return False


def _render_clip(frames: int, views: int, size: tuple[int, int], seed: int, path: Path | None,
                 stop: threading.Event | None = None) -> Iterator[np.ndarray]:
    """Renders the clip frame by frame, storing each in a temporary sibling of ``path``
    (where it can be written) that is renamed into place once every frame is in it; a render
    stopped early (``stop`` set, or the generator closed) leaves no partial cache."""
    from lfstream.synth import iter_clip

    shape = (frames, views, views, size[0], size[1], 3)
    store = None
    if path is not None and _fits_on_disk(path.parent, int(np.prod(shape))):
        from lfstream.io._fs import temp_sibling

        tmp = temp_sibling(path)
        try:
            store = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.uint8, shape=shape)
        except OSError:
            store = None
    done = 0
    try:
        for lf, _ in iter_clip(_clip_config(frames, views, size, seed)):
            if stop is not None and stop.is_set():
                break
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
                if done == frames and _cached_clip(path, shape) is None:
                    os.replace(tmp, path)  # complete, and longer than what is there: later runs read it
                else:
                    tmp.unlink(missing_ok=True)  # stopped early (no partial cache), or not needed
            except OSError:
                pass


def synthetic_source(frames: int = 24, views: int = 7, size: tuple[int, int] = (375, 540),
                     seed: int = 2024, cache: bool = True) -> Iterator[np.ndarray]:
    """The built-in clip: a layered synthetic scene with motion, a pan, sensor noise and
    vignetting (deterministic).

    Rendering costs ~0.4 s a frame at 7x7x375x540, more than the whole codec, so with
    ``cache`` the first run writes the frames it renders to :func:`cache_dir` (a raw
    ``.npy``, 30 MB a frame, renamed into place only when complete; :func:`render_builtin_clip`
    renders it ahead, as ``lfstream stream`` does while its kernels load) and later runs read
    them back memory-mapped (read-only frames): the source is then never the pipeline's
    bottleneck.
    """
    shape = (frames, views, views, size[0], size[1], 3)
    path = _clip_cache(frames, views, size, seed) if cache else None
    clip = _cached_clip(path, shape)
    if clip is not None:
        # read-only views of the mapped file, not copies: a 30 MB copy a frame page-faults
        # a fresh buffer, and beside the pipeline's other threads those faults cost
        # 20-55 ms of system time a frame (measured per thread); the views fault in
        # page-cache pages only
        yield from clip
        return
    yield from _render_clip(frames, views, size, seed, path)


def render_builtin_clip(frames: int = 24, views: int = 7, size: tuple[int, int] = (375, 540), seed: int = 2024,
                        stop: threading.Event | None = None) -> Path | None:
    """Renders the built-in clip into its cache (:func:`synthetic_source`) where it is not
    there yet, so that a stream of it reads it back instead of rendering as it goes; returns
    the cache file, ``None`` where there is no cache folder or no room for the file on its
    disk (nothing is rendered: the frames would have to be held in memory) or ``stop`` was
    set first. The rendering runs numpy
    and OpenCV, which release the GIL: ``lfstream stream`` runs it beside the kernels'
    warm-up (:class:`lfstream.stream.Pipeline`'s ``prepare``), so a first run's count of
    frames a second is the pipeline's, not the renderer's."""
    path = _clip_cache(frames, views, size, seed)
    shape = (frames, views, views, size[0], size[1], 3)
    if path is None or not (path.exists() or _fits_on_disk(path.parent, int(np.prod(shape)))):
        return None  # nowhere to keep it: the stream renders as it goes
    if _cached_clip(path, shape) is None:
        for _ in _render_clip(frames, views, size, seed, path, stop):
            pass
    return path if path.exists() else None


@dataclass
class Source:
    """The frames of a stream and what is known about them.

    Attributes:
        frames: iterator of ``(U, V, H, W, 3)`` uint8 frames.
        fps: frame rate, when the source records one.
        present: ``(U, V)`` mask of the views that exist (a folder with missing views read
            with ``allow_missing``); ``None``: all views.
        total: number of frames, when known (progress and ETA).
        prepare: work to do before the stream is timed, given an event that asks it to stop
            (:func:`render_builtin_clip`); ``None``: none.
    """

    frames: Iterator[np.ndarray]
    fps: float | None = None
    present: np.ndarray | None = None
    total: int | None = None
    prepare: Callable[[threading.Event], object] | None = None


def file_source(path: str | os.PathLike, options: ReadOptions | None = None) -> Source:
    """The frames of an LF file (:func:`lfstream.io.open_lf_frames`: LF videos read lazily,
    one frame in memory at a time). With ``options.allow_missing`` a folder with missing
    views streams: the encoder sends the centre view (which must exist) and the metrics count
    the present views only."""
    opts = options or ReadOptions()
    video = open_lf_frames(path, opts)
    if video.present is not None and not video.present[video.views[0] // 2, video.views[1] // 2]:
        raise LFValueError(f"{path}: the centre view is missing; it is the view the codec sends")
    return Source(video.frames, video.fps, video.present, video.count or opts.max_frames)


__all__ = ["BUILTIN_CLIP_VERSION", "PRERENDER_MAX_FRAMES", "Source", "cache_dir", "synthetic_source",
           "render_builtin_clip", "file_source"]
