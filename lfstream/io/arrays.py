"""NumPy array files (``.npy``, ``.npz``) as light fields: their headers checked against the
file's size before anything is allocated, one frame or a video, a range of frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lfstream.errors import LFFileError, LFFormatError, LFShapeError
from lfstream.io.images import eight_bit
from lfstream.io.read_options import LoadedLF, ReadOptions
from lfstream.lightfield import check_lf, frames_in_range

_ARRAY_MAGIC = {".npy": (b"\x93NUMPY", "a NumPy .npy file"), ".npz": (b"PK", "a NumPy .npz (zip) archive")}


def _npy_header(fh) -> tuple[tuple[int, ...], np.dtype]:
    """The shape and dtype a ``.npy`` header declares (``fh`` at its magic; left after it)."""
    version = np.lib.format.read_magic(fh)
    read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    shape, _, dtype = read_header(fh)
    return shape, dtype


def _check_declared_size(fh, available: int, name: str) -> None:
    """Refuses an array whose header declares more data than its file holds (a truncated or
    forged ``.npy``: numpy would first try to allocate what the header says, up to
    petabytes). ``fh`` is at the array's magic; ``available``: its bytes, header included."""
    shape, dtype = _npy_header(fh)
    declared = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if declared > available - fh.tell():
        raise LFFormatError(f"{name}: its header declares a {'x'.join(map(str, shape))} {dtype} array ({declared} "
                            f"bytes), the file holds {max(available - fh.tell(), 0)}: truncated or not an array file")


def _read_array_file(path: Path, opts: ReadOptions | None = None) -> LoadedLF:
    """A ``.npy`` or ``.npz`` light field, the frames of ``opts``' range only where it is a
    video (a ``.npy``'s range copied out of the mapped file: the rest is never read)."""
    opts = ReadOptions() if opts is None else opts
    magic, what = _ARRAY_MAGIC[path.suffix.lower()]
    try:
        with open(path, "rb") as fh:
            head = fh.read(len(magic))
    except OSError as exc:
        raise LFFileError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    if head != magic:
        raise LFFormatError(f"{path}: not {what} ({'empty file' if not head else 'its first bytes are ' + repr(head)})")
    try:
        if path.suffix.lower() == ".npy":
            with open(path, "rb") as fh:
                _check_declared_size(fh, path.stat().st_size, str(path))
            ranged = opts.first_frame > 0 or opts.max_frames is not None
            lf = np.load(path, allow_pickle=False, mmap_mode="r" if ranged else None)
            disparity = None
            fmt = "npy"
        else:
            with np.load(path, allow_pickle=False) as z:
                keys = list(z.keys())
                if not keys:
                    raise LFFormatError(f"{path}: empty .npz archive")
                key = "lf" if "lf" in keys else keys[0]
                for name in {key, "disparity"} & set(keys):
                    member = z.zip.getinfo(f"{name}.npy")
                    with z.zip.open(member) as fh:
                        _check_declared_size(fh, member.file_size, f"{path} ({name})")
                lf = z[key]
                disparity = z["disparity"] if "disparity" in keys else None
            fmt = "npz"
    except (ValueError, OSError, EOFError, KeyError) as exc:
        if isinstance(exc, LFFormatError):
            raise
        raise LFFormatError(f"{path}: not a readable {path.suffix} array ({exc})") from exc
    # uint8, float in [0, 1], or 16-bit samples (taken to 8 bits as 16-bit images are); any
    # other integer type's scale is a guess (uint16 ones were read as floats and saturated
    # to white), so it is refused
    if not isinstance(lf, np.ndarray) or not (lf.dtype == np.uint8 or lf.dtype == np.uint16 or lf.dtype.kind == "f"):
        raise LFFormatError(f"{path}: {getattr(lf, 'dtype', type(lf))} samples; expected uint8, uint16 or float "
                            "in [0, 1]")
    try:
        check_lf(lf, name=str(path))
    except LFShapeError as exc:
        raise LFFormatError(str(exc)) from exc
    if lf.ndim == 6:
        if disparity is not None and disparity.ndim in (3, 5) and len(disparity) == len(lf):
            # a map per frame, every view's or the centre view's: the range's
            disparity = _frame_range(disparity, opts, path)
        lf = _frame_range(lf, opts, path)
    if isinstance(lf, np.memmap) or (isinstance(lf.base, np.ndarray) and lf.size < lf.base.size):
        # the range copied out of the mapped file (a .npy; a still whole), or out of the
        # whole array (a .npz's member is read whole), which is then freed
        lf = np.array(lf)
    if lf.dtype == np.uint16:
        lf = eight_bit(lf)
    return LoadedLF(lf=lf, format=fmt, path=path, disparity=disparity)


def _frame_range(frames, opts: ReadOptions, path: Path):
    """The frames ``opts`` asks for (``first_frame``, ``max_frames``) of a ``(T, ...)`` array
    (or a list)."""
    _range_count(len(frames), opts, path)
    stop = None if opts.max_frames is None else opts.first_frame + opts.max_frames
    return frames[opts.first_frame:stop]


def _range_count(count: int | None, opts: ReadOptions, path: Path) -> int | None:
    """How many frames a video of ``count`` frames gives read from ``opts.first_frame`` for at
    most ``opts.max_frames`` (``None`` where the count is not known).

    Raises:
        LFValueError: the first frame asked for is past the video's end.
    """
    return frames_in_range(count, opts.first_frame, opts.max_frames, path) if count else count


#: Decoder threads of each view's video in a folder of view videos: one decoder a view, all
#: open at once (49 for 7x7), so FFmpeg's own choice (one a core, plus one) would start
#: thousands of threads on a large machine; two let a view's decode overlap the next's.
#: Two were as fast as FFmpeg's choice on two cores, for the same CPU time.
