"""Light-field I/O: readers for every common layout, writers that never leave a torn file.

- :mod:`~lfstream.io.readers`: :func:`load_lf` / :func:`read_lf` with :class:`ReadOptions`
  (format detection, missing views, crops, flips); :func:`open_video_lf` reads a mosaic
  video frame by frame.
- :mod:`~lfstream.io.images`, :mod:`~lfstream.io.video`, :mod:`~lfstream.io.pfm`: single
  images and lenslet images, mosaic videos (PyAV), disparity maps.
- :mod:`~lfstream.io.writers`: :func:`write_lf`; :class:`FrameWriter` writes a video frame by
  frame.
- :mod:`~lfstream.io._fs`: atomic writes and fresh output folders, shared by every writer.
"""

from lfstream.io.images import IMAGE_EXTS, read_eslf, read_image, write_image
from lfstream.io.pfm import read_pfm, write_pfm
from lfstream.io.readers import (
    LAZY_EXTS,
    LoadedLF,
    ReadOptions,
    VideoLF,
    load_lf,
    open_lf_frames,
    open_video_lf,
    read_lf,
    read_mosaic_video,
    reads_lazily,
    video_folder_format,
)
from lfstream.io.video import (
    GRID_METADATA_KEY,
    GRID_METADATA_PREFIX,
    VIDEO_EXTS,
    VideoWriter,
    grid_metadata,
    iter_video_frames,
    video_grid_and_fps,
    write_video,
)
from lfstream.io.writers import FrameWriter, write_lf

__all__ = [
    "IMAGE_EXTS",
    "VIDEO_EXTS",
    "GRID_METADATA_KEY",
    "GRID_METADATA_PREFIX",
    "ReadOptions",
    "LoadedLF",
    "VideoLF",
    "VideoWriter",
    "load_lf",
    "read_lf",
    "open_video_lf",
    "open_lf_frames",
    "reads_lazily",
    "video_folder_format",
    "LAZY_EXTS",
    "write_lf",
    "FrameWriter",
    "read_image",
    "write_image",
    "read_eslf",
    "read_mosaic_video",
    "iter_video_frames",
    "video_grid_and_fps",
    "grid_metadata",
    "write_video",
    "read_pfm",
    "write_pfm",
]
