"""Writing light fields: arrays, folders of views and mosaic videos (never a torn file)."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from lfstream.errors import LFValueError
from lfstream.io._fs import atomic_write_bytes, check_new_file
from lfstream.io.images import IMAGE_EXTS, write_image
from lfstream.io.video import VIDEO_EXTS, grid_metadata, write_video
from lfstream.lightfield import check_lf, to_mosaic


def write_lf(
    path: str | os.PathLike,
    lf: np.ndarray,
    *,
    fps: float = 30.0,
    lossless: bool = True,
    disparity: np.ndarray | None = None,
    overwrite: bool = False,
    image_ext: str = ".png",
) -> Path:
    """Writes a light field. The format follows ``path``:

    * ``*.npy``: the array as is; ``*.npz``: keys ``lf`` (and ``disparity`` if given);
    * a video extension: a mosaic video with the grid in its metadata (lossless FFV1 for
      ``.mkv``, x264 RGB QP 0 for ``.mp4`` when ``lossless``, else x264 CRF 18);
    * anything else: a folder of ``R_C.png`` views (0-based); a video ``(T, ...)`` becomes
      one sub-folder per frame, ``frame_000000/`` ….

    An existing file or non-empty folder is an error unless ``overwrite=True``.
    """
    path = Path(path)
    lf = np.asarray(lf)
    check_lf(lf)
    ext = path.suffix.lower()
    if path.exists() and (path.is_file() or any(path.iterdir())):
        check_new_file(path, overwrite)
    if ext == ".npy":
        buf = _npy_bytes(lf)
        atomic_write_bytes(path, buf)
    elif ext == ".npz":
        bio = io.BytesIO()
        arrays = {"lf": lf} if disparity is None else {"lf": lf, "disparity": np.asarray(disparity, np.float32)}
        np.savez_compressed(bio, **arrays)
        atomic_write_bytes(path, bio.getvalue())
    elif ext in VIDEO_EXTS:
        if lf.dtype != np.uint8:
            raise LFValueError(f"{path}: video output needs uint8 data, got {lf.dtype}")
        video = lf if lf.ndim == 6 else lf[None]
        frames = [to_mosaic(f) for f in video]
        write_video(path, frames, fps=fps, lossless=lossless, metadata=grid_metadata(tuple(video.shape[1:3])))
    elif ext in IMAGE_EXTS or ext in (".pfm", ".lfs"):
        raise LFValueError(f"{path}: cannot write a light field as {ext}; use .npy, .npz, a video or a folder")
    else:
        if lf.dtype != np.uint8:
            raise LFValueError(f"{path}: image folders need uint8 data, got {lf.dtype}")
        path.mkdir(parents=True, exist_ok=True)
        if lf.ndim == 6:
            for t, frame in enumerate(lf):
                _write_views(path / f"frame_{t:06d}", frame, image_ext)
        else:
            _write_views(path, lf, image_ext)
    return path


def _write_views(folder: Path, lf: np.ndarray, image_ext: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for u in range(lf.shape[0]):
        for v in range(lf.shape[1]):
            write_image(folder / f"{u}_{v}{image_ext}", lf[u, v])


def _npy_bytes(arr: np.ndarray) -> bytes:
    bio = io.BytesIO()
    np.save(bio, np.ascontiguousarray(arr), allow_pickle=False)
    return bio.getvalue()


__all__ = ["write_lf"]
