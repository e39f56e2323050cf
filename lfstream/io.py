"""Readers and writers for light fields, light-field videos and disparity maps.

Every reader returns arrays in the convention of :mod:`lfstream.lightfield`: a frame
``(U, V, H, W, 3)`` or a video ``(T, U, V, H, W, 3)``, uint8 for image and video sources,
the stored dtype for ``.npy``/``.npz``.

Formats are detected from the path:

========================  =====================================================================
``*.npy`` / ``*.npz``     one frame or a video (``.npz``: key ``lf``, optional ``disparity``)
``*.lfs``                 an lfstream bitstream (decoded with flat disparity for ``info``)
folder of images          ``R_C.png`` (0-based), ``input_CamNNN.png`` (HCI, ``NNN = row*n + col``),
                          ``NAME_RR_CC.png`` (1-based, Lytro exports)
single image              a lenslet/ESLF image (``angular=N``) or a mosaic (``grid=(U, V)``)
video file                frames are SAI mosaics; grid from ``grid=`` or the file's metadata
folder of videos          one video per view, named like the image folders
folder of frames          sub-folders or files, each one LF frame in any format above
``*.pfm``                 a disparity map (:func:`read_pfm`), not a light field
========================  =====================================================================
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Iterator, Sequence

import cv2
import numpy as np

from lfstream.errors import LFFileError, LFFormatError, LFMissingViewsError, LFShapeError, LFValueError
from lfstream.lightfield import (
    MAX_VIEW_SIDE,
    MAX_VIEWS_PER_AXIS,
    check_lf,
    from_mosaic,
    from_sensor,
    to_mosaic,
)

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".webp")
VIDEO_EXTS = (".mp4", ".mkv", ".avi", ".mov", ".webm", ".nut")
#: Metadata key a mosaic video stores its view grid under ("UxV").
GRID_METADATA_KEY = "comment"
GRID_METADATA_PREFIX = "lfstream-grid="

_RE_RC = re.compile(r"^(\d+)_(\d+)$")
_RE_HCI = re.compile(r"^input_Cam(\d{3})$")
_RE_LYTRO = re.compile(r"^(.*?)_(\d{2})_(\d{2})$")


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
    extra: dict = field(default_factory=dict)

    @property
    def frames(self) -> int:
        return int(self.lf.shape[0]) if self.lf.ndim == 6 else 1

    @property
    def views(self) -> tuple[int, int]:
        return int(self.lf.shape[-5]), int(self.lf.shape[-4])

    @property
    def size(self) -> tuple[int, int]:
        return int(self.lf.shape[-3]), int(self.lf.shape[-2])


# ----------------------------------------------------------------------------------------
# Images


def read_image(path: Path) -> np.ndarray:
    """Reads an image file as uint8 RGB ``(H, W, 3)``, or RGBA ``(H, W, 4)`` if it has alpha.

    16-bit images are scaled to 8 bits (``round(x / 257)``); grayscale becomes three equal
    channels.
    """
    path = Path(path)
    if not path.is_file():
        raise LFFileError(f"{path}: no such file")
    data = np.fromfile(str(path), dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise LFFormatError(f"{path}: not a readable image")
    if img.dtype == np.uint16:
        img = ((img.astype(np.uint32) + 128) // 257).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise LFFormatError(f"{path}: unsupported image sample type {img.dtype}")
    if img.ndim == 2:
        return np.repeat(img[:, :, None], 3, axis=2)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGBA)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def write_image(path: Path, img: np.ndarray) -> None:
    """Writes a uint8 RGB ``(H, W, 3)`` image; the format follows the extension."""
    path = Path(path)
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] not in (1, 3):
        raise LFShapeError(f"{path}: expected uint8 (H, W, 3) image, got {img.dtype} {img.shape}")
    bgr = img if img.shape[2] == 1 else cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(path.suffix or ".png", bgr)
    if not ok:
        raise LFFileError(f"{path}: cannot encode image with extension {path.suffix!r}")
    _atomic_write_bytes(path, buf.tobytes())


def _atomic_write_bytes(path: Path, data: bytes) -> None:
    # Write beside the target, then rename: an interrupted write never leaves a torn file.
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise LFFileError(f"{path}: cannot write ({exc.strerror or exc})") from exc


# ----------------------------------------------------------------------------------------
# Folders of views


def _view_name_index(stem: str) -> tuple[str, int, int, str] | None:
    """Parses a view file stem into (scheme, row, col, prefix); row/col 0-based (HCI: linear)."""
    m = _RE_HCI.match(stem)
    if m:
        return "hci", int(m.group(1)), -1, ""
    m = _RE_RC.match(stem)
    if m:
        return "rc", int(m.group(1)), int(m.group(2)), ""
    m = _RE_LYTRO.match(stem)
    if m:
        return "lytro", int(m.group(2)) - 1, int(m.group(3)) - 1, m.group(1)
    return None


def _scan_view_files(folder: Path, exts: Sequence[str]) -> tuple[str, dict[tuple[int, int], Path], tuple[int, int]]:
    """Finds the view files of a folder and their grid positions; returns (scheme, map, grid)."""
    entries: dict[str, list[tuple[int, int, Path]]] = {}
    for p in sorted(folder.iterdir()):
        if not p.is_file() or p.suffix.lower() not in exts:
            continue
        parsed = _view_name_index(p.stem)
        if parsed is None:
            continue
        scheme, r, c, _prefix = parsed
        entries.setdefault(scheme, []).append((r, c, p))
    if not entries:
        raise LFFormatError(
            f"{folder}: no view files named R_C, input_CamNNN or NAME_RR_CC with extension in {list(exts)}"
        )
    if len(entries) > 1:
        raise LFFormatError(f"{folder}: mixes view naming schemes {sorted(entries)}")
    scheme, items = next(iter(entries.items()))
    if scheme == "hci":
        # HCI numbers views row-major on an n x n grid; infer n from the largest index.
        top = max(r for r, _, _ in items)
        n = int(np.ceil(np.sqrt(top + 1)))
        views = {(r // n, r % n): p for r, _, p in items}
        grid = (n, n)
    else:
        views = {}
        for r, c, p in items:
            if r < 0 or c < 0:
                raise LFFormatError(f"{p}: view index out of range")
            if (r, c) in views:
                raise LFFormatError(f"{folder}: two files for view ({r}, {c}): {views[(r, c)].name}, {p.name}")
            views[(r, c)] = p
        grid = (max(r for r, _ in views) + 1, max(c for _, c in views) + 1)
    if max(grid) > MAX_VIEWS_PER_AXIS:
        raise LFFormatError(f"{folder}: view grid {grid} exceeds the limit of {MAX_VIEWS_PER_AXIS} per axis")
    return scheme, views, grid


def _missing_message(folder: Path, missing: list[tuple[int, int]], grid: tuple[int, int]) -> str:
    shown = ", ".join(f"({r},{c})" for r, c in missing[:12])
    more = f" and {len(missing) - 12} more" if len(missing) > 12 else ""
    return (
        f"{folder}: {len(missing)} of {grid[0] * grid[1]} views of the {grid[0]}x{grid[1]} grid are missing: "
        f"{shown}{more} (pass allow_missing=True / --allow-missing to load the present views with a mask)"
    )


def _assemble_views(
    folder: Path,
    views: dict[tuple[int, int], object],
    grid: tuple[int, int],
    load_view,
    allow_missing: bool,
) -> tuple[np.ndarray, np.ndarray | None]:
    missing = [(r, c) for r in range(grid[0]) for c in range(grid[1]) if (r, c) not in views]
    if missing and not allow_missing:
        raise LFMissingViewsError(_missing_message(folder, missing, grid), missing)
    lf: np.ndarray | None = None
    ref_shape: tuple[int, ...] | None = None
    ref_name = ""
    for (r, c), src in sorted(views.items()):
        img = load_view(src)
        if lf is None:
            ref_shape, ref_name = img.shape, str(src)
            lf = np.zeros(img.shape[:-3] + (grid[0], grid[1]) + img.shape[-3:], np.uint8)
        elif img.shape != ref_shape:
            raise LFShapeError(f"{src}: view shape {img.shape} differs from {ref_name} {ref_shape}")
        lf[..., r, c, :, :, :] = img
    assert lf is not None
    if not missing:
        return lf, None
    present = np.zeros(grid, bool)
    for r, c in views:
        present[r, c] = True
    return lf, present


def _read_rgb_view(p: Path) -> np.ndarray:
    img = read_image(p)
    return img[:, :, :3]


# ----------------------------------------------------------------------------------------
# Lenslet (ESLF) images


def read_eslf(path: Path, angular: int, crop: int | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Reads a Lytro-style lenslet image whose microlens images are ``angular x angular`` pixels.

    Returns ``(lf, weight)``: ``lf`` is ``(k, k, H, W, 3)`` uint8 with ``k = crop or angular``
    (the central views), ``weight`` the alpha channel as ``(k, k, H, W)`` float32 in
    ``[0, 1]`` (``None`` without alpha). Black or masked corner views are common in such
    files; the weight keeps that information instead of pretending those samples are dark.
    """
    if not isinstance(angular, (int, np.integer)) or not 1 <= angular <= MAX_VIEWS_PER_AXIS:
        raise LFValueError(f"angular: must be an integer in 1..{MAX_VIEWS_PER_AXIS}, got {angular!r}")
    img = read_image(path)
    h, w = img.shape[:2]
    if h % angular or w % angular:
        raise LFShapeError(f"{path}: image size {h}x{w} is not a multiple of the angular size {angular}")
    full = from_sensor(img, angular)  # (N, N, H, W, 3 or 4)
    if crop is not None:
        if not 1 <= crop <= angular:
            raise LFValueError(f"crop: must be in 1..{angular}, got {crop}")
        s = angular // 2 - crop // 2
        full = full[s : s + crop, s : s + crop]
    full = np.ascontiguousarray(full)
    weight = None
    if full.shape[-1] == 4:
        weight = full[..., 3].astype(np.float32) / 255.0
        full = np.ascontiguousarray(full[..., :3])
    return full, weight


# ----------------------------------------------------------------------------------------
# Video


def _parse_grid(value: str | None) -> tuple[int, int] | None:
    if not value:
        return None
    m = re.search(re.escape(GRID_METADATA_PREFIX) + r"(\d+)x(\d+)", value)
    return (int(m.group(1)), int(m.group(2))) if m else None


def _open_container(path: Path):
    import av

    try:
        return av.open(str(path))
    except (av.error.FFmpegError, OSError) as exc:  # type: ignore[attr-defined]
        raise LFFormatError(f"{path}: not a readable video ({exc})") from exc


def iter_video_frames(path: Path, max_frames: int | None = None) -> Iterator[np.ndarray]:
    """Yields the frames of a video file as uint8 RGB ``(H, W, 3)``."""
    import av

    with _open_container(path) as container:
        if not container.streams.video:
            raise LFFormatError(f"{path}: has no video stream")
        stream = container.streams.video[0]
        try:
            for i, frame in enumerate(container.decode(stream)):
                if max_frames is not None and i >= max_frames:
                    break
                yield frame.to_ndarray(format="rgb24")
        except av.error.FFmpegError as exc:  # type: ignore[attr-defined]
            raise LFFormatError(f"{path}: video decoding failed ({exc})") from exc


def video_grid_and_fps(path: Path) -> tuple[tuple[int, int] | None, float | None]:
    """Reads the view grid stored in a mosaic video's metadata and its frame rate."""
    with _open_container(path) as container:
        # Matroska upper-cases tag names, MP4 keeps them: look the key up case-insensitively.
        tags = {k.lower(): v for k, v in container.metadata.items()}
        if container.streams.video:
            tags.update({k.lower(): v for k, v in container.streams.video[0].metadata.items()})
        grid = _parse_grid(tags.get(GRID_METADATA_KEY))
        fps = None
        if container.streams.video and container.streams.video[0].average_rate:
            fps = float(container.streams.video[0].average_rate)
    return grid, fps


def read_mosaic_video(
    path: Path, grid: tuple[int, int] | None = None, max_frames: int | None = None
) -> tuple[np.ndarray, float | None]:
    """Reads a video whose frames are SAI mosaics; returns ``((T, U, V, H, W, 3), fps)``."""
    stored, fps = video_grid_and_fps(path)
    grid = grid or stored
    if grid is None:
        raise LFFormatError(f"{path}: the view grid is not in the file's metadata; pass grid=(U, V) / --grid UxV")
    frames = [from_mosaic(f, grid) for f in iter_video_frames(path, max_frames)]
    if not frames:
        raise LFFormatError(f"{path}: contains no frames")
    return np.ascontiguousarray(np.stack(frames)), fps


class VideoWriter:
    """Incremental video writer (context manager): frames go in one by one, the file is
    written under a temporary name and renamed when closed, so an interrupted write never
    leaves a broken file and a closed one is always complete and playable.

    Codecs by extension and ``lossless``: FFV1 (``.mkv``/``.avi``/``.nut``) or x264 RGB at
    QP 0 (``.mp4``/``.mov``) when lossless; x264 (yuv420p, yuv444p for odd sizes) at ``crf``
    otherwise; ``.gif`` an animated GIF.
    """

    def __init__(self, path: str | os.PathLike, fps: float = 30.0, lossless: bool = True, crf: int = 18,
                 metadata: dict[str, str] | None = None, preset: str = "medium") -> None:
        self.path = Path(path)
        ext = self.path.suffix.lower()
        if ext not in VIDEO_EXTS + (".gif",):
            raise LFValueError(f"{self.path}: unsupported video extension; use one of {VIDEO_EXTS + ('.gif',)}")
        self._ext, self._fps, self._lossless, self._crf = ext, fps, lossless, crf
        self._metadata, self._preset = metadata or {}, preset
        self._container = None
        self._stream = None
        self._size: tuple[int, int] | None = None
        self._tmp = self.path.with_name(f".{self.path.stem}.tmp{os.getpid()}{ext}")
        self.frames = 0

    def _open(self, h: int, w: int) -> None:
        import av

        ext = self._ext
        if ext == ".gif":
            codec, pix_fmt, options = "gif", "rgb8", {}
        elif self._lossless:
            codec, pix_fmt, options = ("ffv1", "bgr0", {}) if ext in (".mkv", ".avi", ".nut") else (
                "libx264rgb", "rgb24", {"qp": "0", "preset": "veryfast"})
        else:
            # 4:2:0 needs even sizes; odd-sized frames keep full chroma instead of being cropped.
            pix_fmt = "yuv420p" if h % 2 == 0 and w % 2 == 0 else "yuv444p"
            codec, options = "libx264", {"crf": str(self._crf), "preset": self._preset}
        try:
            self._container = av.open(str(self._tmp), mode="w")
            for k, v in self._metadata.items():
                self._container.metadata[k] = v
            self._stream = self._container.add_stream(codec, rate=Fraction(self._fps).limit_denominator(1001),
                                                      options=options)
            self._stream.width, self._stream.height, self._stream.pix_fmt = w, h, pix_fmt
        except (av.error.FFmpegError, OSError) as exc:  # type: ignore[attr-defined]
            raise LFFileError(f"{self.path}: cannot open for writing ({exc})") from exc
        self._size = (h, w)

    def write(self, img: np.ndarray) -> None:
        import av

        if self._size is None:
            self._open(img.shape[0], img.shape[1])
        h, w = self._size
        if img.shape != (h, w, 3) or img.dtype != np.uint8:
            raise LFShapeError(f"{self.path}: every frame must be uint8 ({h}, {w}, 3), got {img.dtype} {img.shape}")
        try:
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(img), format="rgb24")
            for packet in self._stream.encode(frame):
                self._container.mux(packet)
        except av.error.FFmpegError as exc:  # type: ignore[attr-defined]
            raise LFFileError(f"{self.path}: video encoding failed ({exc})") from exc
        self.frames += 1

    def close(self) -> None:
        """Flushes and renames into place (a writer that got no frames leaves nothing)."""
        import av

        if self._container is None:
            return
        try:
            for packet in self._stream.encode():
                self._container.mux(packet)
            self._container.close()
            os.replace(self._tmp, self.path)
        except (av.error.FFmpegError, OSError) as exc:  # type: ignore[attr-defined]
            raise LFFileError(f"{self.path}: video finalisation failed ({exc})") from exc
        finally:
            self._container = None
            self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> "VideoWriter":
        return self

    def abort(self) -> None:
        """Discards the file being written."""
        if self._container is not None:
            try:
                self._container.close()
            except Exception:  # the file is deleted anyway
                pass
            self._container = None
        self._tmp.unlink(missing_ok=True)

    def __exit__(self, exc_type, *exc) -> None:
        # an exception inside the block discards the half-written file
        self.abort() if exc_type is not None else self.close()


def write_video(
    path: Path,
    frames: Sequence[np.ndarray] | np.ndarray,
    fps: float = 30.0,
    lossless: bool = True,
    crf: int = 18,
    metadata: dict[str, str] | None = None,
) -> None:
    """Writes uint8 RGB frames ``(T, H, W, 3)`` to a video file through PyAV (see
    :class:`VideoWriter` for codecs and the atomic rename)."""
    path = Path(path)
    if len(frames) == 0:
        raise LFValueError(f"{path}: no frames to write")
    with VideoWriter(path, fps, lossless, crf, metadata) as writer:
        for img in frames:
            writer.write(img)


# ----------------------------------------------------------------------------------------
# PFM disparity maps


def read_pfm(path: Path) -> np.ndarray:
    """Reads a PFM file (HCI benchmark disparity format) as float32 ``(H, W)`` or ``(H, W, 3)``.

    Rows are stored bottom-to-top in PFM; the result is top-to-bottom.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            header = fh.readline().strip()
            if header not in (b"Pf", b"PF"):
                raise LFFormatError(f"{path}: not a PFM file (header {header[:8]!r})")
            dims = fh.readline().split()
            scale_line = fh.readline().strip()
            try:
                w, h = int(dims[0]), int(dims[1])
                scale = float(scale_line)
            except (ValueError, IndexError) as exc:
                raise LFFormatError(f"{path}: malformed PFM header") from exc
            if not (0 < w <= MAX_VIEW_SIDE and 0 < h <= MAX_VIEW_SIDE) or scale == 0:
                raise LFFormatError(f"{path}: PFM size {w}x{h} or scale {scale} out of range")
            ch = 3 if header == b"PF" else 1
            count = w * h * ch
            data = np.fromfile(fh, dtype="<f4" if scale < 0 else ">f4", count=count)
    except FileNotFoundError as exc:
        raise LFFileError(f"{path}: no such file") from exc
    except IsADirectoryError as exc:
        raise LFFileError(f"{path}: is a folder, not a PFM file") from exc
    if data.size != count:
        raise LFFormatError(f"{path}: truncated PFM ({data.size} of {count} values)")
    arr = data.reshape((h, w, ch) if ch == 3 else (h, w))[::-1]
    return np.ascontiguousarray(arr.astype(np.float32))


def write_pfm(path: Path, disp: np.ndarray) -> None:
    """Writes float32 ``(H, W)`` (or ``(H, W, 3)``) as little-endian PFM."""
    arr = np.asarray(disp, dtype=np.float32)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] != 3):
        raise LFShapeError(f"{path}: PFM needs (H, W) or (H, W, 3), got {arr.shape}")
    h, w = arr.shape[:2]
    header = f"{'PF' if arr.ndim == 3 else 'Pf'}\n{w} {h}\n-1.0\n".encode()
    body = np.ascontiguousarray(arr[::-1]).astype("<f4").tobytes()
    _atomic_write_bytes(Path(path), header + body)


# ----------------------------------------------------------------------------------------
# Top-level read / write


def _read_array_file(path: Path) -> LoadedLF:
    try:
        if path.suffix.lower() == ".npy":
            lf = np.load(path, allow_pickle=False)
            disparity = None
            fmt = "npy"
        else:
            with np.load(path, allow_pickle=False) as z:
                keys = list(z.keys())
                if not keys:
                    raise LFFormatError(f"{path}: empty .npz archive")
                key = "lf" if "lf" in keys else keys[0]
                lf = z[key]
                disparity = z["disparity"] if "disparity" in keys else None
            fmt = "npz"
    except (ValueError, OSError, EOFError) as exc:
        if isinstance(exc, LFFormatError):
            raise
        raise LFFormatError(f"{path}: not a readable {path.suffix} array ({exc})") from exc
    if not isinstance(lf, np.ndarray) or lf.dtype.kind not in "uf":
        raise LFFormatError(f"{path}: expected a numeric array, got {getattr(lf, 'dtype', type(lf))}")
    try:
        check_lf(lf, name=str(path))
    except LFShapeError as exc:
        raise LFFormatError(str(exc)) from exc
    return LoadedLF(lf=lf, format=fmt, path=path, disparity=disparity)


def _classify_folder(folder: Path) -> str:
    files = [p for p in folder.iterdir() if not p.name.startswith(".")]
    if not files:
        raise LFFormatError(f"{folder}: empty folder")
    exts = {p.suffix.lower() for p in files if p.is_file()}
    named = [p for p in files if p.is_file() and _view_name_index(p.stem) is not None]
    if named and any(p.suffix.lower() in IMAGE_EXTS for p in named):
        return "sai-folder"
    if named and any(p.suffix.lower() in VIDEO_EXTS for p in named):
        return "view-videos"
    if any(p.is_dir() for p in files) or exts & {".npy", ".npz", ".lfs"} or exts & set(VIDEO_EXTS):
        return "frames-folder"
    raise LFFormatError(f"{folder}: no light-field files recognised (extensions found: {sorted(exts) or 'none'})")


def load_lf(
    path: str | os.PathLike,
    *,
    angular: int | None = None,
    crop: int | None = None,
    grid: tuple[int, int] | None = None,
    flip_u: bool = False,
    flip_v: bool = False,
    allow_missing: bool = False,
    max_frames: int | None = None,
) -> LoadedLF:
    """Reads a light field (any supported format) together with its metadata.

    Args:
        path: file or folder; the format is detected (see the module docstring).
        angular: microlens size in pixels for a lenslet (ESLF) image (Lytro Illum: 14;
            some decoders write 15).
        crop: keep the central ``crop x crop`` views.
        grid: ``(U, V)`` of a mosaic image or mosaic video without stored metadata.
        flip_u / flip_v: reverse the view rows / columns, for sources whose view order
            disagrees with lfstream's (HCI) disparity convention.
        allow_missing: load a folder with missing views, zero-filled, with ``present`` set;
            without it missing views raise :class:`LFMissingViewsError`.
        max_frames: read at most this many frames of a video.

    Raises:
        LFFileError: the path does not exist or cannot be read.
        LFFormatError: the content is not a supported light field.
    """
    path = Path(path)
    if not path.exists():
        raise LFFileError(f"{path}: no such file or folder")
    if path.is_dir():
        loaded = _load_folder(path, grid=grid, allow_missing=allow_missing, max_frames=max_frames, angular=angular)
    else:
        ext = path.suffix.lower()
        if ext in (".npy", ".npz"):
            loaded = _read_array_file(path)
            if max_frames is not None and loaded.lf.ndim == 6:
                loaded.lf = loaded.lf[:max_frames]
        elif ext == ".lfs":
            from lfstream.codec import decode_file

            lf, fps = decode_file(path, depth="flat", max_frames=max_frames)
            loaded = LoadedLF(lf=lf, format="lfs", path=path, fps=fps)
        elif ext in VIDEO_EXTS:
            lf, fps = read_mosaic_video(path, grid, max_frames)
            loaded = LoadedLF(lf=lf, format="video", path=path, fps=fps)
        elif ext in IMAGE_EXTS:
            if angular is not None:
                lf, weight = read_eslf(path, angular, crop)
                crop = None  # already applied, on the weight too
                loaded = LoadedLF(lf=lf, format="eslf", path=path, weight=weight)
            elif grid is not None:
                loaded = LoadedLF(lf=np.ascontiguousarray(from_mosaic(read_image(path)[:, :, :3], grid)), format="mosaic", path=path)
            else:
                raise LFFormatError(
                    f"{path}: a single image is a lenslet image (pass angular=N / --angular N) "
                    "or a mosaic (pass grid=(U, V) / --grid UxV)"
                )
        elif ext == ".pfm":
            raise LFFormatError(f"{path}: a PFM file holds a disparity map, not a light field (use read_pfm)")
        else:
            raise LFFormatError(f"{path}: unknown light-field format {ext or '(no extension)'}")
    if crop is not None:
        _apply_crop(loaded, crop)
    if flip_u or flip_v:
        _apply_flips(loaded, flip_u, flip_v)
    return loaded


def _apply_crop(loaded: LoadedLF, k: int) -> None:
    from lfstream.lightfield import crop_views

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


def _load_folder(
    folder: Path,
    grid: tuple[int, int] | None,
    allow_missing: bool,
    max_frames: int | None,
    angular: int | None,
) -> LoadedLF:
    kind = _classify_folder(folder)
    if kind == "sai-folder":
        _, views, found_grid = _scan_view_files(folder, IMAGE_EXTS)
        lf, present = _assemble_views(folder, views, grid or found_grid, _read_rgb_view, allow_missing)
        return LoadedLF(lf=lf, format="sai-folder", path=folder, present=present)
    if kind == "view-videos":
        _, views, found_grid = _scan_view_files(folder, VIDEO_EXTS)

        def load_video(p: Path) -> np.ndarray:
            frames = list(iter_video_frames(p, max_frames))
            if not frames:
                raise LFFormatError(f"{p}: contains no frames")
            return np.stack(frames)  # (T, H, W, 3)

        stacked, present = _assemble_views(folder, views, grid or found_grid, load_video, allow_missing)
        # _assemble_views placed the grid axes before (H, W, 3): (T, U, V, H, W, 3) already.
        _, fps = video_grid_and_fps(next(iter(views.values())))
        return LoadedLF(lf=stacked, format="view-videos", path=folder, present=present, fps=fps)
    # frames-folder: every entry one frame (or a clip), concatenated along T in name order.
    entries = sorted(p for p in folder.iterdir() if not p.name.startswith("."))
    parts: list[np.ndarray] = []
    disps: list[np.ndarray] = []
    fps = None
    for p in entries:
        if p.is_file() and p.suffix.lower() not in (".npy", ".npz", ".lfs") + VIDEO_EXTS:
            continue
        sub = load_lf(p, grid=grid, allow_missing=False, angular=angular)
        arr = sub.lf if sub.lf.ndim == 6 else sub.lf[None]
        if parts and arr.shape[1:] != parts[0].shape[1:]:
            raise LFShapeError(f"{p}: frame shape {arr.shape[1:]} differs from the first frame's {parts[0].shape[1:]}")
        parts.append(arr)
        if sub.disparity is not None:
            disps.append(sub.disparity if sub.disparity.ndim == 5 else sub.disparity[None])
        fps = fps or sub.fps
        if max_frames is not None and sum(len(a) for a in parts) >= max_frames:
            break
    if not parts:
        raise LFFormatError(f"{folder}: no light-field frames found")
    lf = np.concatenate(parts)[:max_frames]
    disparity = np.concatenate(disps)[: len(lf)] if len(disps) == len(parts) else None
    return LoadedLF(lf=lf, format="frames-folder", path=folder, disparity=disparity, fps=fps)


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
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Reads a light field; see :func:`load_lf` for the arguments and formats.

    Returns:
        The light field ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)``. With
        ``return_mask=True``, a pair ``(lf, present)`` where ``present`` is the ``(U, V)`` bool
        mask of views that exist (all True when none is missing); missing views are zero.
        Without it, a folder with missing views raises :class:`LFMissingViewsError`.
    """
    loaded = load_lf(
        path, angular=angular, crop=crop, grid=grid, flip_u=flip_u, flip_v=flip_v,
        allow_missing=return_mask, max_frames=max_frames,
    )
    if not return_mask:
        return loaded.lf
    present = loaded.present if loaded.present is not None else np.ones(loaded.views, bool)
    return loaded.lf, present


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
    if path.exists() and not overwrite:
        if path.is_file() or any(path.iterdir()):
            raise LFFileError(f"{path}: already exists (pass overwrite=True / --overwrite to replace it)")
    if ext == ".npy":
        buf = _npy_bytes(lf)
        _atomic_write_bytes(path, buf)
    elif ext == ".npz":
        import io as _io

        bio = _io.BytesIO()
        arrays = {"lf": lf} if disparity is None else {"lf": lf, "disparity": np.asarray(disparity, np.float32)}
        np.savez_compressed(bio, **arrays)
        _atomic_write_bytes(path, bio.getvalue())
    elif ext in VIDEO_EXTS:
        if lf.dtype != np.uint8:
            raise LFValueError(f"{path}: video output needs uint8 data, got {lf.dtype}")
        video = lf if lf.ndim == 6 else lf[None]
        u, v = video.shape[1:3]
        frames = [to_mosaic(f) for f in video]
        write_video(path, frames, fps=fps, lossless=lossless, metadata={GRID_METADATA_KEY: f"{GRID_METADATA_PREFIX}{u}x{v}"})
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
    import io as _io

    bio = _io.BytesIO()
    np.save(bio, np.ascontiguousarray(arr), allow_pickle=False)
    return bio.getvalue()


__all__ = [
    "LoadedLF",
    "VideoWriter",
    "load_lf",
    "read_lf",
    "write_lf",
    "read_image",
    "write_image",
    "read_eslf",
    "read_mosaic_video",
    "iter_video_frames",
    "write_video",
    "read_pfm",
    "write_pfm",
]
