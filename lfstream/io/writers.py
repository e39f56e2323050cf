"""Writing light fields: arrays, folders of views and mosaic videos (never a torn file)."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from lfstream.errors import LFFileError, LFShapeError, LFValueError
from lfstream.io._fs import atomic_write_bytes, check_new_file, temp_sibling
from lfstream.io.images import IMAGE_EXTS, write_image
from lfstream.io.video import VIDEO_EXTS, VideoWriter, grid_metadata, write_video
from lfstream.lightfield import check_lf, to_mosaic

#: Files that are not light fields (a disparity map, a coded stream, a 256-colour GIF): a
#: light field written there is refused rather than made a folder of that name.
NOT_LF_EXTS = (".pfm", ".lfs", ".gif")


def write_lf(
    path: str | os.PathLike,
    lf: np.ndarray,
    *,
    fps: float = 30.0,
    lossless: bool = True,
    disparity: np.ndarray | None = None,
    overwrite: bool = False,
    image_ext: str = ".png",
    present: np.ndarray | None = None,
) -> Path:
    """Writes a light field or LF video; the format follows ``path``.

    * ``*.npy``: the array as is; ``*.npz``: keys ``lf`` (and ``disparity`` if given);
    * a video extension: a mosaic video with the grid in its metadata (when ``lossless``:
      Ut Video for ``.avi``/``.nut``, FFV1 for ``.mkv``, x264 RGB QP 0 for ``.mp4``/``.mov``,
      VP9 for ``.webm``; else x264 CRF 18, VP9 in ``.webm``; :class:`lfstream.io.VideoWriter`);
    * anything else: a folder of ``R_C.png`` views (0-based); a video becomes one sub-folder
      per frame, ``frame_000000/`` ….

    Args:
        path: the output.
        lf: the light field (uint8 for images and videos).
        fps: a video's frame rate.
        lossless: a video's codec, lossless or x264 CRF 18.
        disparity: ground-truth disparity for a ``.npz``.
        overwrite: replace an existing file or fill a non-empty folder (else an error).
        image_ext: the image format of a folder's views.
        present: mask of the views that exist; a folder gets images of those only.

    Returns:
        The path written.

    Shape:
        - lf: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)``
        - disparity: ``(U, V, H, W)``, ``(H, W)`` or with a leading ``T``
        - present: ``(U, V)``
    """
    path = Path(path)
    lf = np.asarray(lf)
    check_lf(lf)
    ext = path.suffix.lower()
    if disparity is not None:
        # every view's map, or the centre view's (per frame of a video); another shape was
        # written as it came and read back beside the light field it does not describe
        shape = np.shape(disparity)
        if shape not in (lf.shape[:-1], lf.shape[:-5] + lf.shape[-3:-1]):
            raise LFShapeError(f"{path}: disparity {shape} matches neither the views {lf.shape[:-1]} nor the centre "
                               f"view {lf.shape[:-5] + lf.shape[-3:-1]}")
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
    elif ext in IMAGE_EXTS or ext in NOT_LF_EXTS:
        raise LFValueError(f"{path}: cannot write a light field as {ext}; use .npy, .npz, a video or a folder")
    else:
        if lf.dtype != np.uint8:
            raise LFValueError(f"{path}: image folders need uint8 data, got {lf.dtype}")
        path.mkdir(parents=True, exist_ok=True)
        if lf.ndim == 6:
            for t, frame in enumerate(lf):
                _write_views(path / f"frame_{t:06d}", frame, image_ext, present)
        else:
            _write_views(path, lf, image_ext, present)
    return path


class NpyWriter:
    """A ``.npy`` of ``count`` frames written one at a time: memory-mapped under a
    temporary name (allocated at the first frame, with its shape and dtype) and renamed into
    place when closed, so nothing is held in memory and nothing torn is left. The caller
    checks that ``path`` may be written (:func:`lfstream.io._fs.check_new_file`)."""

    def __init__(self, path: str | os.PathLike, count: int) -> None:
        self.path = Path(path)
        if not (isinstance(count, (int, np.integer)) and count >= 1):
            raise LFValueError(f"{self.path}: a .npy written frame by frame needs the frame count, got {count!r}")
        self._count = int(count)
        self._store = None
        self._tmp = temp_sibling(self.path)
        self.frames = 0

    def write(self, frame: np.ndarray) -> None:
        """Stores the next frame (every frame the first's shape and dtype)."""
        frame = np.asarray(frame)
        if self._store is None:
            try:
                self._store = np.lib.format.open_memmap(self._tmp, mode="w+", dtype=frame.dtype,
                                                        shape=(self._count, *frame.shape))
            except OSError as exc:
                raise LFFileError(f"{self.path}: cannot write ({exc.strerror or exc})") from exc
        if self.frames >= self._count or frame.shape != self._store.shape[1:]:
            raise LFValueError(f"{self.path}: frame {self.frames} of shape {frame.shape} does not fit "
                               f"{self._store.shape}")
        self._store[self.frames] = frame
        self.frames += 1

    def close(self, partial: bool = False) -> None:
        """Renames the file into place. It must hold its ``count`` frames, unless
        ``partial`` (a stream damaged or interrupted part way): then it is cut to the frames
        written so far (none: nothing is kept)."""
        if self._store is None:
            return
        store, self._store = self._store, None
        store.flush()
        del store
        if self.frames != self._count and not (partial and self.frames):
            self._tmp.unlink(missing_ok=True)
            raise LFValueError(f"{self.path}: {self.frames} of {self._count} frames written; nothing kept")
        try:
            if self.frames != self._count:
                _truncate_npy(self._tmp, self.frames)
            os.replace(self._tmp, self.path)
        except OSError as exc:
            self._tmp.unlink(missing_ok=True)
            raise LFFileError(f"{self.path}: cannot write ({exc.strerror or exc})") from exc
        except BaseException:  # Ctrl-C / SIGTERM while finalising: no temporary file left
            self._tmp.unlink(missing_ok=True)
            raise

    def abort(self) -> None:
        """Discards what was written."""
        self._store = None
        self._tmp.unlink(missing_ok=True)


class FrameWriter:
    """Writes an LF video frame by frame to what :func:`write_lf` writes whole, holding one
    frame at a time: a mosaic video (the file appears when closed), a ``.npy`` of ``count``
    frames (memory-mapped, renamed into place when all are written), a ``.npz``
    (:class:`NpzWriter`: the frames deflated into the archive when closed) or a folder of
    ``frame_NNNNNN/`` view folders. A context manager: the output is finalised when the block
    ends normally, or on Ctrl-C with the frames so far, and discarded on any other exception.

    Args:
        path: the output; an existing file or non-empty folder is an error unless
            ``overwrite``.
        count: frames to come (required for ``.npy``; the file holds exactly that many).
        fps, lossless, image_ext: as :func:`write_lf`.
        first_index: the number of the first frame's folder (``frame_NNNNNN/``), the next
            ones counting on: a range of a video keeps its source's frame numbers.
        disparity: a ``.npz``'s ground-truth disparity (:class:`NpzWriter`); refused for the
            formats that hold none.
        present: ``(U, V)`` mask of the views that exist; a folder gets images of those only
            (the arrays and videos hold every view, the missing ones as the frames give them).
    """

    def __init__(self, path: str | os.PathLike, count: int | None = None, *, fps: float = 30.0, lossless: bool = True,
                 overwrite: bool = False, image_ext: str = ".png", first_index: int = 0,
                 disparity: np.ndarray | None = None, present: np.ndarray | None = None) -> None:
        self.path = Path(path)
        self._ext = self.path.suffix.lower()
        if self._ext in IMAGE_EXTS or self._ext in NOT_LF_EXTS:
            raise LFValueError(f"{self.path}: cannot write a light field frame by frame as {self._ext}; use .npy, "
                               ".npz, a video or a folder")
        self._array = NpyWriter(self.path, count) if self._ext == ".npy" else (
            NpzWriter(self.path, disparity) if self._ext == ".npz" else None)
        if disparity is not None and self._ext != ".npz":
            raise LFValueError(f"{self.path}: a {self._ext or 'folder'} holds no disparity; write a .npz")
        if self.path.exists() and (self.path.is_file() or any(self.path.iterdir())):
            check_new_file(self.path, overwrite)
        self._fps, self._lossless, self._image_ext = fps, lossless, image_ext
        self._video = None
        self._made_folder = False
        self._first_index = int(first_index)
        self._present = None if present is None else np.asarray(present, bool)
        self.frames = 0

    def write(self, lf: np.ndarray) -> None:
        """Appends one frame ``(U, V, H, W, 3)`` uint8."""
        lf = np.asarray(lf)
        check_lf(lf, allow_video=False)
        if lf.dtype != np.uint8:
            raise LFValueError(f"{self.path}: frames must be uint8, got {lf.dtype}")
        if self._ext in VIDEO_EXTS:
            if self._video is None:
                self._video = VideoWriter(self.path, self._fps, self._lossless, metadata=grid_metadata(lf.shape[:2]))
            self._video.write(to_mosaic(lf))
        elif self._array is not None:
            self._array.write(lf)
        else:
            if not self.path.exists():
                self.path.mkdir(parents=True)
                self._made_folder = True
            _write_views(self.path / f"frame_{self._first_index + self.frames:06d}", lf, self._image_ext, self._present)
        self.frames += 1

    def close(self, partial: bool = False) -> None:
        """Finalises the output. A ``.npy`` must have received its ``count`` frames, unless
        ``partial`` (a stream damaged or interrupted part way): then it holds the frames
        written so far (no frame at all: nothing is kept)."""
        if self._video is not None:
            self._video.close()
        if self._array is not None:
            self._array.close(partial)

    def abort(self) -> None:
        """Discards what was written (a folder keeps its complete frames; one this writer
        made and wrote nothing to is removed)."""
        if self._video is not None:
            self._video.abort()
        if self._array is not None:
            self._array.abort()
        if self._made_folder and self.path.is_dir() and not any(self.path.iterdir()):
            self.path.rmdir()

    def __enter__(self) -> FrameWriter:
        return self

    def __exit__(self, exc_type, *exc) -> None:
        if exc_type is None:
            self.close()
        elif exc_type is KeyboardInterrupt:  # the frames so far, as a complete file
            self.close(partial=True)
        else:
            self.abort()


#: Bytes of the frames file an :class:`NpzWriter` deflates into its archive at a time.
NPZ_COPY_CHUNK = 16 << 20


class NpzWriter:
    """A ``.npz`` of frames written one at a time, the archive :func:`write_lf` writes (the
    member ``lf.npy`` deflated, as ``np.savez_compressed`` writes it): the frames are appended
    to a temporary file of raw frames beside the output, and deflated into the archive's
    member when closed, :data:`NPZ_COPY_CHUNK` bytes at a time, the header sized by the
    frames written; then renamed into place. Memory holds a frame and a chunk, not the
    video (``lfstream decode -o x.npz`` held every decoded frame); the disk holds the raw
    frames meanwhile (what a ``.npy`` of them would take). The caller checks that ``path``
    may be written (:func:`lfstream.io._fs.check_new_file`). ``disparity``: written beside
    the frames as the member ``disparity.npy`` (as :func:`write_lf`'s), cut to the frames
    written where it has a map per frame (``(T, ...)``, an output closed part way)."""

    def __init__(self, path: str | os.PathLike, disparity: np.ndarray | None = None) -> None:
        self.path = Path(path)
        self.disparity = None if disparity is None else np.asarray(disparity, np.float32)
        self._raw = temp_sibling(self.path, "frames")
        self._fh = None
        self._frame: tuple[tuple[int, ...], np.dtype] | None = None
        self.frames = 0

    def write(self, frame: np.ndarray) -> None:
        """Appends the next frame (every frame the first's shape and dtype)."""
        frame = np.ascontiguousarray(frame)
        if self._fh is None:
            try:
                self._fh = open(self._raw, "wb")
            except OSError as exc:
                raise LFFileError(f"{self.path}: cannot write ({exc.strerror or exc})") from exc
            self._frame = (frame.shape, frame.dtype)
        if (frame.shape, frame.dtype) != self._frame:
            raise LFValueError(f"{self.path}: frame {self.frames} of shape {frame.shape} ({frame.dtype}) unlike the "
                               f"first's {self._frame[0]} ({self._frame[1]})")
        try:
            self._fh.write(memoryview(frame).cast("B"))
        except OSError as exc:
            raise LFFileError(f"{self.path}: cannot write ({exc.strerror or exc})") from exc
        self.frames += 1

    def close(self, partial: bool = False) -> None:
        """Deflates the frames written into the archive and renames it into place (none
        written: nothing is kept). ``partial``: as :meth:`NpyWriter.close`, for the callers
        (every frame written is kept either way)."""
        if self._fh is None:
            return
        fh, self._fh = self._fh, None
        fh.close()
        if not self.frames:
            self._raw.unlink(missing_ok=True)
            return
        import zipfile

        shape, dtype = self._frame
        header = {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                  "shape": (self.frames, *shape)}
        tmp = temp_sibling(self.path)
        try:
            with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as archive, \
                    archive.open("lf.npy", "w", force_zip64=True) as member, open(self._raw, "rb") as raw:
                np.lib.format.write_array_header_1_0(member, header)
                while chunk := raw.read(NPZ_COPY_CHUNK):
                    member.write(chunk)
            if self.disparity is not None:
                d = self.disparity
                if d.ndim in (3, 5) and len(d) > self.frames:  # a map per frame: those written
                    d = d[: self.frames]
                with zipfile.ZipFile(tmp, "a", compression=zipfile.ZIP_DEFLATED, allowZip64=True) as archive, \
                        archive.open("disparity.npy", "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, np.ascontiguousarray(d))
            os.replace(tmp, self.path)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise LFFileError(f"{self.path}: cannot write ({exc.strerror or exc})") from exc
        except BaseException:  # Ctrl-C / SIGTERM while deflating: no temporary file left
            tmp.unlink(missing_ok=True)
            raise
        finally:
            self._raw.unlink(missing_ok=True)

    def abort(self) -> None:
        """Discards what was written."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        self._raw.unlink(missing_ok=True)


def _truncate_npy(path: Path, frames: int) -> None:
    """Cuts a ``.npy`` of ``(count, ...)`` down to its first ``frames`` along axis 0: the
    header's shape rewritten in place (padded to the header's length, as the format allows)
    and the data after them dropped."""
    with open(path, "r+b") as fh:
        major, _ = np.lib.format.read_magic(fh)
        read_header = np.lib.format.read_array_header_1_0 if major == 1 else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = read_header(fh)
        data_start = fh.tell()
        length_bytes = 2 if major == 1 else 4
        header = f"{{'descr': {np.lib.format.dtype_to_descr(dtype)!r}, 'fortran_order': {fortran}, " \
                 f"'shape': {(frames, *shape[1:])}, }}"
        room = data_start - (6 + 2 + length_bytes)  # the old header's length, padding and newline included
        fh.seek(6 + 2 + length_bytes)
        fh.write(header.ljust(room - 1).encode("latin1") + b"\n")
        fh.truncate(data_start + frames * int(np.prod(shape[1:], dtype=np.int64)) * dtype.itemsize)


def _write_views(folder: Path, lf: np.ndarray, image_ext: str, present: np.ndarray | None = None) -> None:
    """One image per view; views ``present`` marks missing are not written (a folder can
    say they are absent, as the source did)."""
    folder.mkdir(parents=True, exist_ok=True)
    for u in range(lf.shape[0]):
        for v in range(lf.shape[1]):
            if present is None or present[u, v]:
                write_image(folder / f"{u}_{v}{image_ext}", lf[u, v])


def _npy_bytes(arr: np.ndarray) -> bytes:
    bio = io.BytesIO()
    np.save(bio, np.ascontiguousarray(arr), allow_pickle=False)
    return bio.getvalue()


__all__ = ["write_lf", "FrameWriter", "NpyWriter", "NpzWriter"]
