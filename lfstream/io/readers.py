"""Reading light fields and LF videos in every supported layout.

Every reader returns arrays in the convention of :mod:`lfstream.lightfield`: a frame
``(U, V, H, W, 3)`` or a video ``(T, U, V, H, W, 3)``, uint8 for image and video sources,
the stored dtype for ``.npy``/``.npz``.

Formats are detected from the path:

========================  =====================================================================
``*.npy`` / ``*.npz``     one frame or a video (``.npz``: key ``lf``, optional ``disparity``)
``*.lfs``                 an lfstream bitstream, decoded (:func:`lfstream.decode`'s defaults)
folder of images          ``R_C.png`` (0-based), ``input_CamNNN.png`` (HCI, ``NNN = row*n + col``),
                          ``NAME_RR_CC.png`` (1-based, Lytro exports)
single image              a lenslet/ESLF image (``angular=N``) or a mosaic (``grid=(U, V)``)
video file                frames are SAI mosaics; grid from ``grid=`` or the file's metadata
folder of videos          one video per view, named like the image folders
folder of frames          sub-folders or files, each one LF frame in any format above
``*.pfm``                 a disparity map (:func:`lfstream.io.read_pfm`), not a light field
========================  =====================================================================
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfstream.errors import LFFileError, LFFormatError, LFShapeError, LFValueError
from lfstream.io.arrays import _frame_range, _npy_header, _range_count, _read_array_file
from lfstream.io.images import IMAGE_EXTS, read_eslf, read_image
from lfstream.io.read_options import LoadedLF, ReadOptions
from lfstream.io.video import VIDEO_EXTS, collect_frames, iter_video_frames, video_info
from lfstream.io.view_files import (
    _assemble_views,
    _classify_folder,
    _missing_views,
    _present_mask,
    _read_rgb_view,
    _scan_view_files,
)
from lfstream.lightfield import (
    check_crop,
    crop_views,
    from_mosaic,
)

_LAYERED_READERS = {".lfs": ("lfstream.codec.api", "lfs_frames")}
#: What :func:`open_video_lf` reads frame by frame.
LAZY_EXTS = VIDEO_EXTS + tuple(_LAYERED_READERS)


def reads_lazily(path: str | os.PathLike) -> bool:
    """Whether ``path`` is an LF video :func:`open_video_lf` reads one frame at a time (a
    mosaic video, an ``.lfs`` stream, or a folder of one video per view)."""
    path = Path(path)
    if path.is_dir():
        try:
            return _lazy_folder_kind(path) is not None
        except (LFFormatError, OSError):
            return False
    return path.suffix.lower() in LAZY_EXTS and path.is_file()


def video_folder_format(folder: str | os.PathLike) -> str:
    """The format :func:`load_lf` names a folder that :func:`reads_lazily`: ``"view-videos"``
    (one video per view) or ``"frames-folder"`` (one sub-folder of view images, or one
    single-frame ``.npy``, per frame)."""
    return "view-videos" if _lazy_folder_kind(Path(folder)) == "view-videos" else "frames-folder"


def _frame_entries(folder: Path) -> list[Path]:
    """A frames folder's entries in name order (hidden ones left out)."""
    return sorted(p for p in folder.iterdir() if not p.name.startswith("."))


def _lazy_folder_kind(folder: Path, kind: str | None = None) -> str | None:
    """``"view-videos"`` (one video per view) or ``"frame-folders"`` (one sub-folder of view
    images per frame, as :func:`lfstream.io.write_lf` and ``lfstream decode`` write a video,
    or one single-frame ``.npy`` per frame), which :func:`open_video_lf` reads frame by frame;
    ``None`` for other folders (read whole). ``kind``: :func:`_classify_folder`'s answer,
    where the caller has it."""
    kind = kind or _classify_folder(folder)
    if kind == "view-videos":
        return kind
    entries = _frame_entries(folder) if kind == "frames-folder" else []
    if entries and all(p.is_dir() for p in entries) and _classify_folder(entries[0]) == "sai-folder":
        return "frame-folders"
    if entries and all(p.is_file() and p.suffix.lower() == ".npy" for p in entries) and _one_frame_npy(entries[0]):
        return "frame-folders"  # one light field a .npy file: read the same way, a file at a time
    return None


def _one_frame_npy(path: Path) -> bool:
    """Whether a ``.npy`` holds one light field ``(U, V, H, W, C)`` (its header read only)."""
    try:
        with open(path, "rb") as fh:
            return len(_npy_header(fh)[0]) == 5
    except (OSError, ValueError):
        return False


@dataclass
class VideoLF:
    """An LF video's light fields, decoded one at a time (:func:`open_video_lf`).

    Attributes:
        frames: ``(U, V, H, W, 3)`` uint8 frames, C-contiguous, with the options' crop and
            flips applied; one frame in memory at a time.
        fps: the container's frame rate, or ``None``.
        count: how many frames it yields where the file says (at most ``max_frames``;
            counted where asked for), else ``None``.
        views: ``(U, V)`` of the frames it yields (the crop applied).
        size: ``(H, W)`` of their views.
        path: the file (or the folder of view videos).
        present: ``(U, V)`` mask of the views that exist (a folder of view videos read with
            ``allow_missing``: the missing views are zero in every frame); ``None``: all.
        damage: where the file is known to be damaged before a frame is read (an ``.lfs``,
            whose packets are counted): the error the frames end with, after the ``count``
            complete ones before it; ``None``: none known.
    """

    frames: Iterator[np.ndarray]
    fps: float | None
    count: int | None
    views: tuple[int, int]
    size: tuple[int, int]
    path: Path
    present: np.ndarray | None = None
    damage: Exception | None = None


def open_video_lf(path: str | os.PathLike, options: ReadOptions | None = None, count_frames: bool = False) -> VideoLF:
    """An LF video read lazily — a mosaic video (grid from ``options.grid`` or the file's
    metadata) or an ``.lfs`` stream (decoded as :func:`lfstream.decode` decodes it) — with
    the crop and flips of ``options`` applied to each frame: what :func:`load_lf` reads of
    it, without holding the video in memory. Its frame count, views and view size come
    from the container or header, the grid and the crop are checked, before any frame is
    decoded; ``count_frames``: count a video's packets where its container keeps no count
    (Matroska), reading the file once but decoding nothing.

    Raises:
        LFFileError: the file does not exist.
        LFFormatError: not a readable video, or no grid known.
        LFShapeError, LFValueError: a mosaic that is not a multiple of the grid, a crop
            larger than the grid.
        BitstreamError: an ``.lfs`` damaged before its first complete frame (counted before
            any is decoded; later damage ends the frames, :attr:`VideoLF.damage`).
    """
    opts = options or ReadOptions()
    path = Path(path)
    present, damage = None, None
    if path.is_dir():
        lazy = _lazy_folder_kind(path)
        if lazy is None:
            raise LFFormatError(f"{path}: not an LF video folder (one video per view, or one sub-folder per frame)")
        read_folder = _view_videos if lazy == "view-videos" else _frame_folders
        decoded, fps, count, views, size, present = read_folder(path, opts, count_frames)
    elif not path.is_file():
        raise LFFileError(f"{path}: no such file")
    elif path.suffix.lower() in _LAYERED_READERS:
        import importlib

        module, name = _LAYERED_READERS[path.suffix.lower()]
        decoded, header, count, damage = getattr(importlib.import_module(module), name)(
            path, max_frames=opts.max_frames, first_frame=opts.first_frame)
        fps, views, size = header.fps, header.views, header.size
        if header.meta.get("present") is not None:  # the views its source had (the rest decode as zero)
            present = np.asarray(header.meta["present"], bool)
    else:
        info = video_info(path, count_frames=count_frames)
        grid, fps, count = opts.grid or info.grid, info.fps, info.count
        if grid is None:
            raise LFFormatError(f"{path}: the view grid is not in the file's metadata; pass grid=(U, V) / --grid UxV")
        (mh, mw), (u, v) = info.size, grid
        if u < 1 or v < 1 or mh % u or mw % v:  # refused before a frame is read (a stream: before its folder fills)
            raise LFShapeError(f"{path}: mosaic size {mh}x{mw} is not a multiple of the view grid {u}x{v}")
        views, size = (u, v), (mh // u, mw // v)

        def mosaics() -> Iterator[np.ndarray]:  # the video is opened for decoding at the first frame asked for
            for img in iter_video_frames(path, opts.max_frames, first_frame=opts.first_frame):
                yield from_mosaic(img, grid)

        decoded = mosaics()
    if opts.crop is not None:
        check_crop(views, opts.crop)
        views = (opts.crop, opts.crop)
        present = None if present is None else np.ascontiguousarray(crop_views(present[..., None, None, None],
                                                                              opts.crop)[..., 0, 0, 0])
    count = _range_count(count, opts, path)
    flips = tuple(a for a, f in ((0, opts.flip_u), (1, opts.flip_v)) if f)
    if present is not None and flips:
        present = np.ascontiguousarray(np.flip(present, axis=flips))
    if present is not None and present.all():
        present = None

    def frames() -> Iterator[np.ndarray]:
        n = 0
        for lf in decoded:
            if opts.crop is not None:
                lf = crop_views(lf, opts.crop)
            n += 1
            yield np.ascontiguousarray(np.flip(lf, axis=flips) if flips else lf)
        if n == 0 and opts.first_frame:  # a count the container did not record
            raise LFValueError(f"{path}: first_frame {opts.first_frame}: the video ends before it")

    return VideoLF(frames(), fps, count, tuple(views), tuple(size), path, present, damage)


VIEW_DECODER_THREADS = 2


def _view_videos(folder: Path, opts: ReadOptions, count_frames: bool):
    """:func:`open_video_lf` of a folder of one video per view (``R_C.mp4``, ...): each light
    field assembled from one frame of every view's video; the views' sizes and frame counts
    checked from their containers before any frame is decoded (:data:`VIEW_DECODER_THREADS`
    threads a decoder). Returns ``(frames, fps, count, views, size, present)``.

    Raises:
        LFMissingViewsError: a view without a video (unless ``opts.allow_missing``).
        LFShapeError: views of different sizes or frame counts.
        LFFormatError: a video that ends before the others (where no count was known).
    """
    _, views, found = _scan_view_files(folder, VIDEO_EXTS)
    grid = opts.grid or found
    missing = _missing_views(folder, views, grid, opts.allow_missing)
    if any(r >= grid[0] or c >= grid[1] for r, c in views):
        raise LFFormatError(f"{folder}: views beyond the grid {grid[0]}x{grid[1]}")
    infos = {k: video_info(p, count_frames=count_frames) for k, p in sorted(views.items())}
    k0, first = next(iter(infos.items()))
    for k, info in infos.items():
        if info.size != first.size:
            raise LFShapeError(f"{views[k]}: view size {info.size} differs from {views[k0].name}'s {first.size}")
    counts = [info.count for info in infos.values()]
    if all(counts) and len(set(counts)) > 1:
        k1 = next(k for k, info in infos.items() if info.count != first.count)
        raise LFShapeError(f"{folder}: the view videos hold different frame counts ({views[k0].name} {first.count}, "
                           f"{views[k1].name} {infos[k1].count})")
    present = _present_mask(views, grid) if missing else None
    h, w = first.size

    def frames() -> Iterator[np.ndarray]:
        readers = {k: iter_video_frames(p, opts.max_frames, threads=VIEW_DECODER_THREADS, first_frame=opts.first_frame)
                   for k, p in sorted(views.items())}
        try:
            while True:
                lf = np.zeros((*grid, h, w, 3), np.uint8) if missing else np.empty((*grid, h, w, 3), np.uint8)
                ended = [k for k, reader in readers.items() if not _next_view(reader, lf, k, views[k])]
                if len(ended) == len(readers):
                    return
                if ended:
                    raise LFFormatError(f"{views[ended[0]]}: ends before the other views' videos")
                yield lf
        finally:
            for reader in readers.values():
                reader.close()

    return frames(), first.fps, (counts[0] if all(counts) else None), tuple(grid), (h, w), present


def _frame_folders(folder: Path, opts: ReadOptions, count_frames: bool = False):
    """:func:`open_video_lf` of a folder of one sub-folder of view images (or one ``.npy``)
    per frame (``frame_000000/`` ...): one entry read at a time, in name order;
    the first is read up front for the views and their size, the count is the number of
    sub-folders. Returns ``(frames, fps, count, views, size, present)`` (no frame rate).

    Raises:
        LFShapeError: a frame whose views, size or missing views differ from the first's.
    """
    everything = _frame_entries(folder)
    entries = _frame_range(everything, opts, folder)  # a first frame past the end: refused before any is read
    inner = ReadOptions(angular=opts.angular, grid=opts.grid, allow_missing=opts.allow_missing)
    first = load_lf(entries[0], inner)

    def frames() -> Iterator[np.ndarray]:
        for k, entry in enumerate(entries):
            loaded = first if k == 0 else load_lf(entry, inner)
            if loaded.lf.shape != first.lf.shape or not np.array_equal(_mask_of(loaded), _mask_of(first)):
                raise LFShapeError(f"{entry}: a frame of {loaded.lf.shape} (views present: "
                                   f"{'all' if loaded.present is None else int(loaded.present.sum())}) unlike "
                                   f"{entries[0].name}'s {first.lf.shape}")
            yield np.ascontiguousarray(loaded.lf)

    return frames(), None, len(everything), first.lf.shape[:2], first.lf.shape[2:4], first.present


def _mask_of(loaded: LoadedLF) -> np.ndarray:
    """A loaded light field's views-present mask, all ``True`` where it has none."""
    return np.ones(loaded.lf.shape[-5:-3], bool) if loaded.present is None else loaded.present


def _next_view(reader: Iterator[np.ndarray], lf: np.ndarray, k: tuple[int, int], path: Path) -> bool:
    """Reads the next frame of view ``k``'s video into ``lf``; ``False`` at its end."""
    img = next(reader, None)
    if img is None:
        return False
    if img.shape != lf.shape[2:]:
        raise LFShapeError(f"{path}: a frame of shape {img.shape}, the views' are {lf.shape[2:]}")
    lf[k] = img
    return True


def open_lf_frames(path: str | os.PathLike, options: ReadOptions | None = None) -> VideoLF:
    """Any light field as frames, one at a time: an LF video lazily (:func:`open_video_lf`),
    anything else read whole (:func:`load_lf`) and handed out frame by frame; ``present``
    ``None`` where every view exists. The one door for callers that process frame by frame
    (the stream's source, ``lfstream batch``)."""
    opts = options or ReadOptions()
    if reads_lazily(path):
        return open_video_lf(path, opts)
    loaded = load_lf(path, opts)
    lf = loaded.lf if loaded.lf.ndim == 6 else loaded.lf[None]
    present = None if loaded.present is None or loaded.present.all() else loaded.present
    return VideoLF(iter(lf), loaded.fps, len(lf), tuple(lf.shape[1:3]), tuple(lf.shape[3:5]), Path(path), present)


def load_lf(path: str | os.PathLike, options: ReadOptions | None = None, **kwargs) -> LoadedLF:
    """Reads a light field (any supported format) together with its metadata.

    Args:
        path: file or folder; the format is detected (see the module docstring).
        options: how to interpret the source (:class:`ReadOptions`); or its fields as
            keyword arguments (``angular=14, crop=7, ...``).

    Raises:
        LFFileError: the path does not exist or cannot be read.
        LFFormatError: the content is not a supported light field.
    """
    opts = dataclasses.replace(options or ReadOptions(), **kwargs) if kwargs else (options or ReadOptions())
    path = Path(path)
    if not path.exists():
        raise LFFileError(f"{path}: no such file or folder")
    crop = opts.crop
    if path.is_dir():
        loaded = _load_folder(path, opts)
    else:
        ext = path.suffix.lower()
        if ext in (".npy", ".npz"):
            loaded = _read_array_file(path, opts)
        elif ext in LAZY_EXTS:
            # crop and flips frame by frame as it is read (one copy of each frame)
            video = open_video_lf(path, opts)
            return LoadedLF(lf=collect_frames(video.frames, video.count, path),
                            format="video" if ext in VIDEO_EXTS else ext.lstrip("."), path=path, fps=video.fps)
        elif ext in IMAGE_EXTS:
            if opts.angular is not None:
                lf, weight = read_eslf(path, opts.angular, crop)
                crop = None  # already applied, on the weight too
                loaded = LoadedLF(lf=lf, format="eslf", path=path, weight=weight)
            elif opts.grid is not None:
                lf = np.ascontiguousarray(from_mosaic(read_image(path)[:, :, :3], opts.grid))
                loaded = LoadedLF(lf=lf, format="mosaic", path=path)
            else:
                raise LFFormatError(
                    f"{path}: a single image is a lenslet image (pass angular=N / --angular N) "
                    "or a mosaic (pass grid=(U, V) / --grid UxV)"
                )
        elif ext == ".pfm":
            raise LFFormatError(f"{path}: a PFM file holds a disparity map, not a light field (use read_pfm)")
        else:
            raise LFFormatError(f"{path}: unknown light-field format {ext or '(no extension)'}")
    if opts.first_frame and loaded.lf.ndim == 5:
        raise LFValueError(f"{path}: first_frame {opts.first_frame}: a single light field, not a video")
    if crop is not None:
        _apply_crop(loaded, crop)
    if opts.flip_u or opts.flip_v:
        _apply_flips(loaded, opts.flip_u, opts.flip_v)
    return loaded


def _apply_crop(loaded: LoadedLF, k: int) -> None:
    loaded.lf = np.ascontiguousarray(crop_views(loaded.lf, k))
    u, v = loaded.lf.shape[-5:-3]
    for name in ("present", "weight", "disparity"):
        arr = getattr(loaded, name)
        if arr is None:
            continue
        # present: (U, V); weight / disparity: (..., U, V, H, W)
        ax = arr.ndim - 2 if name == "present" else arr.ndim - 4
        full_u, full_v = arr.shape[ax], arr.shape[ax + 1]
        su, sv = full_u // 2 - k // 2, full_v // 2 - k // 2
        idx = [slice(None)] * arr.ndim
        idx[ax], idx[ax + 1] = slice(su, su + k), slice(sv, sv + k)
        setattr(loaded, name, np.ascontiguousarray(arr[tuple(idx)]))


def _apply_flips(loaded: LoadedLF, flip_u: bool, flip_v: bool) -> None:
    def flip(arr: np.ndarray, view_axis_u: int) -> np.ndarray:
        axes = tuple(a for a, f in ((view_axis_u, flip_u), (view_axis_u + 1, flip_v)) if f)
        return np.ascontiguousarray(np.flip(arr, axis=axes))

    loaded.lf = flip(loaded.lf, loaded.lf.ndim - 5)
    if loaded.present is not None:
        loaded.present = flip(loaded.present, 0)
    for name in ("weight", "disparity"):
        arr = getattr(loaded, name)
        if arr is not None:
            setattr(loaded, name, flip(arr, arr.ndim - 4))
    if loaded.disparity is not None and (flip_u != flip_v):
        # Mirroring one view axis only would need a per-axis disparity; refuse to guess.
        raise LFValueError("flip_u and flip_v must agree for a source with ground-truth disparity")
    if loaded.disparity is not None:
        loaded.disparity = -loaded.disparity


def _load_folder(folder: Path, opts: ReadOptions) -> LoadedLF:
    kind = _classify_folder(folder)
    lazy = _lazy_folder_kind(folder, kind)
    if lazy is not None:  # an LF video folder: the lazy reader's frames, collected
        # (the crop and flips come after, as for any folder)
        video = open_video_lf(folder, dataclasses.replace(opts, crop=None, flip_u=False, flip_v=False))
        return LoadedLF(lf=collect_frames(video.frames, video.count, folder), format=video_folder_format(folder),
                        path=folder,
                        present=video.present, fps=video.fps)
    if kind == "sai-folder":
        _, views, found_grid = _scan_view_files(folder, IMAGE_EXTS)
        lf, present = _assemble_views(folder, views, opts.grid or found_grid, _read_rgb_view, opts.allow_missing)
        return LoadedLF(lf=lf, format="sai-folder", path=folder, present=present)
    # frames-folder: every entry one frame (or a clip), concatenated along T in name order.
    entries = _frame_entries(folder)
    parts: list[np.ndarray] = []
    disps: list[np.ndarray] = []
    fps = None
    for p in entries:
        if p.is_file() and p.suffix.lower() not in (".npy", ".npz", ".lfs") + VIDEO_EXTS:
            continue
        sub = load_lf(p, ReadOptions(angular=opts.angular, grid=opts.grid))
        arr = sub.lf if sub.lf.ndim == 6 else sub.lf[None]
        if parts and arr.shape[1:] != parts[0].shape[1:]:
            raise LFShapeError(f"{p}: frame shape {arr.shape[1:]} differs from the first frame's {parts[0].shape[1:]}")
        parts.append(arr)
        if sub.disparity is not None:
            disps.append(sub.disparity if sub.disparity.ndim == 5 else sub.disparity[None])
        fps = fps or sub.fps
        if opts.max_frames is not None and sum(len(a) for a in parts) >= opts.first_frame + opts.max_frames:
            break
    if not parts:
        raise LFFormatError(f"{folder}: no light-field frames found")
    lf = _frame_range(np.concatenate(parts), opts, folder)
    disparity = None
    if len(disps) == len(parts):
        disparity = _frame_range(np.concatenate(disps), opts, folder)
    return LoadedLF(lf=lf, format="frames-folder", path=folder, disparity=disparity, fps=fps)


def read_mosaic_video(
    path: Path, grid: tuple[int, int] | None = None, max_frames: int | None = None
) -> tuple[np.ndarray, float | None]:
    """Reads a video whose frames are SAI mosaics; returns ``((T, U, V, H, W, 3), fps)``
    (:func:`lfstream.io.open_video_lf`'s frames, collected)."""
    video = open_video_lf(path, ReadOptions(grid=grid, max_frames=max_frames))
    return collect_frames(video.frames, video.count, Path(path)), video.fps


def read_lf(
    path: str | os.PathLike,
    *,
    angular: int | None = None,
    crop: int | None = None,
    grid: tuple[int, int] | None = None,
    flip_u: bool = False,
    flip_v: bool = False,
    return_mask: bool = False,
    max_frames: int | None = None,
    first_frame: int = 0,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Reads a light field or LF video; the format is detected from the path.

    Args:
        path: a file or folder (every layout :mod:`lfstream.io.readers` lists).
        angular, crop, grid, flip_u, flip_v, max_frames, first_frame: how to read it
            (:class:`ReadOptions`).
        return_mask: also return the mask of the views that exist.

    Returns:
        The light field, uint8 (16-bit samples taken to 8 bits, floats as stored). With
        ``return_mask=True``, a pair ``(lf, present)`` where ``present`` is the ``(U, V)``
        bool mask of views that exist (all True when none is missing); missing views are zero.
        Without it, a folder with missing views raises :class:`LFMissingViewsError`.

    Raises:
        LFFileError: the path does not exist or cannot be read.
        LFFormatError: the content is not a light field lfstream reads.

    Shape:
        - output: ``(U, V, H, W, 3)`` for one light field, ``(T, U, V, H, W, 3)`` for a video
        - present: ``(U, V)``
    """
    opts = ReadOptions(angular=angular, crop=crop, grid=grid, flip_u=flip_u, flip_v=flip_v,
                       allow_missing=return_mask, max_frames=max_frames, first_frame=first_frame)
    loaded = load_lf(path, opts)
    if not return_mask:
        return loaded.lf
    present = loaded.present if loaded.present is not None else np.ones(loaded.views, bool)
    return loaded.lf, present


__all__ = ["ReadOptions", "LoadedLF", "VideoLF", "LAZY_EXTS", "load_lf", "read_lf", "open_video_lf", "open_lf_frames",
           "read_mosaic_video",
           "reads_lazily"]
