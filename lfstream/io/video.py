"""Video files through PyAV: mosaic LF videos and an incremental, atomic writer.

A mosaic video stores each LF frame as its sub-aperture mosaic (views tiled row-major,
:func:`lfstream.lightfield.to_mosaic`); the view grid is kept in the container's
``comment`` tag as ``lfstream-grid=UxV``.
"""

from __future__ import annotations

import itertools
import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from lfstream.errors import LFFileError, LFFormatError, LFShapeError, LFValueError
from lfstream.io._fs import temp_sibling

VIDEO_EXTS = (".mp4", ".mkv", ".avi", ".mov", ".webm", ".nut")
#: Metadata key a mosaic video stores its view grid under ("UxV").
GRID_METADATA_KEY = "comment"
GRID_METADATA_PREFIX = "lfstream-grid="
#: A video padded to even size for 4:2:0 records its true frame size ("HxW") here.
SIZE_METADATA_PREFIX = "lfstream-size="
#: x264's settings for a lossless ``.mp4``/``.mov`` (RGB, QP 0). ``fastdecode`` codes with
#: CAVLC instead of CABAC: a lossless mosaic is mostly residual bits, and CABAC's serial
#: arithmetic decoding of them made reading the file the slowest stage of streaming it.
#: Against ``veryfast`` with CABAC it reads and writes about three times faster for a few
#: per cent more bytes (more with sensor noise, which CAVLC codes less tightly;
#: ``bench/video_io.py``). ``faster`` rather than ``veryfast``: fewer bytes on noise-free clips.
LOSSLESS_X264 = {"qp": "0", "preset": "faster", "tune": "fastdecode"}
#: The lossless codec by extension: x264 RGB in ``.mp4``/``.mov`` (the smallest files: it
#: predicts a frame from the one before), FFV1 in ``.mkv`` (the archival standard), Ut Video
#: in ``.avi``/``.nut`` (each frame on its own, planes predicted from the left neighbour and
#: Huffman-coded: the quickest to read; ``bench/video_io.py`` compares them). Without noise
#: x264's predictions pay and repeated frames cost it almost nothing, so ``.avi`` is the
#: format to stream from disk, ``.mp4`` to keep.
LOSSLESS_CODECS = {".mkv": ("ffv1", "bgr0"), ".avi": ("utvideo", "gbrp"), ".nut": ("utvideo", "gbrp")}


def _parse_pair(prefix: str, value: str | None) -> tuple[int, int] | None:
    """``(a, b)`` of ``PREFIXaxb`` inside a metadata string, or ``None``."""
    m = re.search(re.escape(prefix) + r"(\d+)x(\d+)", value or "")
    return (int(m.group(1)), int(m.group(2))) if m else None


def _open_container(path: Path):
    import av

    try:
        return av.open(str(path))
    except (av.error.FFmpegError, OSError) as exc:  # type: ignore[attr-defined]
        raise LFFormatError(f"{path}: not a readable video ({exc})") from exc


def iter_video_frames(path: Path, max_frames: int | None = None, threads: int | None = None,
                      first_frame: int = 0) -> Iterator[np.ndarray]:
    """Yields the frames of a video file as uint8 RGB ``(H, W, 3)``, from frame
    ``first_frame`` on; ``threads``: the decoder's threads (``None``: FFmpeg's choice; 1
    where many small videos are decoded side by side, one view each, and their threads
    would only crowd the cores).

    The frames before ``first_frame`` are skipped as cheaply as the codec allows: an
    intra-only codec's (Ut Video, the ``.avi`` mosaics) are not decoded at all, only read
    from the container; others' (x264, FFV1) are decoded, each frame predicting from the
    ones before, but not converted to RGB."""
    import av

    with _open_container(path) as container:
        if not container.streams.video:
            raise LFFormatError(f"{path}: has no video stream")
        stream = container.streams.video[0]
        if threads is not None:
            stream.codec_context.thread_count = int(threads)
        size = _parse_pair(SIZE_METADATA_PREFIX, _tags(container).get(GRID_METADATA_KEY))
        try:
            for frame in itertools.islice(_decoded_from(container, stream, first_frame, path), max_frames):
                img = frame.to_ndarray(format="rgb24")
                yield img[: size[0], : size[1]] if size is not None else img
        except av.error.FFmpegError as exc:  # type: ignore[attr-defined]
            raise LFFormatError(f"{path}: video decoding failed ({exc})") from exc


#: Packets past a frame's decode position whose timestamps can still come before it in
#: display order (H.264 and HEVC reorder across at most 16 frames).
REORDER_MARGIN = 32


def _decoded_from(container, stream, first_frame: int, path: Path | None = None) -> Iterator:
    """The video stream's decoded frames (PyAV's) from frame ``first_frame`` on, in display
    order. An intra-only codec's packets are its frames, in order, each decodable alone: the
    first ``first_frame`` non-empty ones are read and dropped undecoded (an empty packet
    repeats a frame in AVI and decodes to nothing; the last one flushes the decoder). An
    inter codec's (``path`` given) start at the last key frame at or before it
    (:func:`_key_frame_before`), the frames between decoded and dropped; where the packets
    give no timestamps, or the key frame is the first, every frame before it is decoded."""
    if first_frame <= 0:
        yield from container.decode(stream)
        return
    if stream.codec_context.codec.intra_only:
        skipped = 0
        for packet in container.demux(stream):
            if skipped < first_frame and packet.size > 0:
                skipped += 1
                continue
            yield from packet.decode()
        return
    found = None if path is None else _key_frame_before(path, first_frame)
    if found is not None:
        key, target = found
        container.seek(key, stream=stream, backward=True, any_frame=False)
        frames = container.decode(stream)
        head = next(frames, None)
        if head is not None and head.pts is not None and head.pts <= target:
            for frame in itertools.chain([head], frames):
                if frame.pts is None or frame.pts >= target:
                    yield frame
            return
        container.seek(0, stream=stream, backward=True, any_frame=True)  # not where it should be: from the start
        stream.codec_context.flush_buffers()
    for i, frame in enumerate(container.decode(stream)):
        if i >= first_frame:
            yield frame


def _key_frame_before(path: Path, first_frame: int) -> tuple[int, int] | None:
    """``(key, target)``: the presentation timestamps of the last key frame at or before
    frame ``first_frame`` (display order) and of that frame, read from the packets of the
    file's first ``first_frame + REORDER_MARGIN`` frames (no frame decoded); ``None`` where
    the packets carry no timestamps, the video ends before the frame, or the key frame is
    the first frame (nothing to skip)."""
    with _open_container(path) as probe:
        stream = probe.streams.video[0]
        stamps: list[tuple[int, bool]] = []
        for packet in probe.demux(stream):
            if packet.size == 0:
                continue
            if packet.pts is None:
                return None
            stamps.append((int(packet.pts), bool(packet.is_keyframe)))
            if len(stamps) > first_frame + REORDER_MARGIN:
                break
    if len(stamps) <= first_frame:
        return None
    target = sorted(p for p, _ in stamps)[first_frame]
    keys = [p for p, key in stamps if key and p <= target]
    if not keys or max(keys) <= min(p for p, _ in stamps):
        return None
    return max(keys), target


def _tags(container) -> dict[str, str]:
    # Matroska upper-cases tag names, MP4 keeps them: look keys up case-insensitively.
    tags = {k.lower(): v for k, v in container.metadata.items()}
    if container.streams.video:
        tags.update({k.lower(): v for k, v in container.streams.video[0].metadata.items()})
    return tags


@dataclass(frozen=True)
class VideoInfo:
    """What a video's container says, read without decoding a frame.

    Attributes:
        grid: the mosaic's view grid ``(U, V)`` from the metadata, or ``None``.
        fps: frame rate, or ``None``.
        count: frames, from the container's count or (``count_frames``) its packets;
            ``None`` where neither was asked for nor recorded.
        size: ``(H, W)`` of a frame as the readers return it (a padded frame's true size).
        codec: the video stream's codec (FFmpeg's name: ``h264``, ``utvideo``, ``ffv1``, ...).
        pixel_format: its pixel format (``gbrp``/``bgr0`` exact RGB, ``yuv420p`` lossy).
    """

    grid: tuple[int, int] | None
    fps: float | None
    count: int | None
    size: tuple[int, int]
    codec: str | None = None
    pixel_format: str | None = None


def video_info(path: Path, count_frames: bool = False) -> VideoInfo:
    """A video's :class:`VideoInfo`; ``count_frames``: count the packets where the container
    keeps no frame count (Matroska), reading the file but decoding nothing."""
    with _open_container(path) as container:
        if not container.streams.video:
            raise LFFormatError(f"{path}: has no video stream")
        tags = _tags(container)
        stream = container.streams.video[0]
        fps = float(stream.average_rate) if stream.average_rate else None
        count = int(stream.frames) or None
        if count is None and count_frames:
            try:
                count = sum(1 for packet in container.demux(stream) if packet.size)
            except Exception as exc:  # noqa: BLE001 - PyAV's errors: a damaged file
                raise LFFormatError(f"{path}: not a readable video ({exc})") from exc
        size = _parse_pair(SIZE_METADATA_PREFIX, tags.get(GRID_METADATA_KEY)) or (stream.height, stream.width)
        ctx = stream.codec_context
        return VideoInfo(_parse_pair(GRID_METADATA_PREFIX, tags.get(GRID_METADATA_KEY)), fps, count, size,
                         ctx.name, getattr(ctx.format, "name", None))


def video_grid_and_fps(path: Path) -> tuple[tuple[int, int] | None, float | None]:
    """Reads the view grid stored in a mosaic video's metadata and its frame rate."""
    info = video_info(path)
    return info.grid, info.fps


def collect_frames(frames: Iterator[np.ndarray], count: int | None, source: Path) -> np.ndarray:
    """The frames of an iterator as one ``(T, ...)`` array. Where ``count`` (what the file
    says it holds) is known, they are written into one array allocated up front: stacking a
    list copied every frame once more into fresh pages. Fewer frames than ``count`` give the ones read; more
    are appended."""
    first = next(frames, None)
    if first is None:
        raise LFFormatError(f"{source}: contains no frames")
    if not count or count < 2:
        return np.ascontiguousarray(np.stack([first, *frames]))
    out = np.empty((count, *first.shape), first.dtype)
    out[0] = first
    n = 1
    extra = []
    for f in frames:
        if n < count:
            out[n] = f
        else:
            extra.append(f)
        n += 1
    if n < count:
        return out[:n]
    return np.concatenate([out, np.stack(extra)]) if extra else out


class VideoWriter:
    """Incremental video writer (context manager): frames go in one by one, the file is
    written under a temporary name and renamed when closed, so an interrupted write never
    leaves a broken file and a closed one is always complete and playable.

    Codecs by extension and ``lossless`` (:data:`LOSSLESS_CODECS`): FFV1 (``.mkv``), Ut Video
    (``.avi``/``.nut``, the quickest to read), x264 RGB at QP 0 (``.mp4``/``.mov``,
    :data:`LOSSLESS_X264`: CAVLC, the smallest) or VP9 in RGB (``.webm``, slow) when lossless;
    x264 yuv420p (plays everywhere; odd sizes padded, the true size recorded and cropped
    back by :func:`iter_video_frames`) at ``crf`` otherwise (VP9 in ``.webm``); ``.gif`` an
    animated GIF (not for light fields: :func:`lfstream.io.write_lf` refuses it).
    """

    def __init__(self, path: str | os.PathLike, fps: float = 30.0, lossless: bool = True, crf: int = 18,
                 metadata: dict[str, str] | None = None, preset: str = "medium", threads: int | None = None,
                 low_delay: bool = False, fast_search: bool = False) -> None:
        self.path = Path(path)
        ext = self.path.suffix.lower()
        if ext not in VIDEO_EXTS + (".gif",):
            raise LFValueError(f"{self.path}: unsupported video extension; use one of {VIDEO_EXTS + ('.gif',)}")
        self._ext, self._fps, self._lossless, self._crf = ext, fps, lossless, crf
        self._metadata, self._preset = metadata or {}, preset
        # encoder threads (None: the codec's own choice); a caller running many writers in one
        # thread gives each one thread rather than multiplying x264's frame threads
        self._threads = threads
        # x264's default lookahead (10 frames at veryfast, plus B-frames) holds frames back
        # and encodes them when the file is closed: a dozen plane writers then spend ~0.3-0.4 s
        # at close (7x7x375x540 stream, 13 planes). One frame of lookahead and one B-frame
        # encode each frame as it comes (measured: same CPU, -2 % bytes at crf - 1, flush
        # 300 -> 50 ms)
        self._low_delay = low_delay
        # x264's diamond motion search and its quickest sub-pixel refinement (me=dia, subme=1):
        # measured on 13 focal planes of 376 x 540 at veryfast, crf 17, low delay: 40-45 ->
        # 28-31 ms of CPU a frame, -2 % bytes, -0.02 dB
        self._fast_search = fast_search
        self._container = None
        self._stream = None
        self._size: tuple[int, int] | None = None
        self._tmp = temp_sibling(self.path)
        self.frames = 0
        self.packets = 0  # packets muxed so far (a low-delay writer keeps up with its frames)

    def _open(self, h: int, w: int) -> None:
        import av

        ext = self._ext
        if ext == ".gif":
            codec, pix_fmt, options = "gif", "rgb8", {}
        elif ext == ".webm":
            # WebM holds VP8, VP9 and AV1 only (x264 was refused there, with a traceback): VP9,
            # lossless in RGB, or yuv420p at the CRF; libvpx's realtime speed, still far slower
            # than the quick lossless formats (.avi and .mp4)
            codec, options = "libvpx-vp9", {"deadline": "realtime", "cpu-used": "8", "row-mt": "1"}
            if self._lossless:
                pix_fmt, options = "gbrp", {**options, "lossless": "1"}
            else:
                pix_fmt, options = "yuv420p", {**options, "crf": str(self._crf), "b": "0"}
        elif self._lossless:
            codec, pix_fmt = LOSSLESS_CODECS.get(ext, ("libx264rgb", "rgb24"))
            options = dict(LOSSLESS_X264) if codec == "libx264rgb" else {}
        else:
            # yuv420p H.264 (High profile) plays in every browser and player; 4:2:0 needs even
            # sizes, so odd frames are padded by edge replication and the true size is recorded
            # (readers crop it back, see iter_video_frames)
            pix_fmt = "yuv420p"
            codec, options = "libx264", {"crf": str(self._crf), "preset": self._preset}
            # B-frames behind x264's full lookahead made its output depend on the contents of
            # uninitialised memory (the same frames gave different files in different runs;
            # MALLOC_PERTURB_ shows it): no B-frames there, +5-20 % bytes on focal-plane
            # videos at -0.0..-0.4 dB. The low-delay settings (one B-frame, a one-frame
            # lookahead) give the same bytes every run as they are.
            params = (["rc-lookahead=1", "bframes=1"] if self._low_delay else ["bframes=0"]) + (
                ["me=dia", "subme=1"] if self._fast_search else [])
            if params:
                options["x264-params"] = ":".join(params)
        if self._threads is not None and codec != "gif":
            options = {**options, "threads": str(int(self._threads))}
        ph, pw = (h + h % 2, w + w % 2) if pix_fmt == "yuv420p" else (h, w)
        metadata = dict(self._metadata)
        if (ph, pw) != (h, w):
            note = f"{SIZE_METADATA_PREFIX}{h}x{w}"
            metadata[GRID_METADATA_KEY] = f"{metadata[GRID_METADATA_KEY]} {note}" if GRID_METADATA_KEY in metadata else note
        try:
            # bit-exact muxing: Matroska otherwise writes random segment and track UIDs, and
            # the same frames would not give the same file twice
            self._container = av.open(str(self._tmp), mode="w", container_options={"fflags": "+bitexact"})
            for k, v in metadata.items():
                self._container.metadata[k] = v
            self._stream = self._container.add_stream(codec, rate=Fraction(self._fps).limit_denominator(1001),
                                                      options=options)
            self._stream.width, self._stream.height, self._stream.pix_fmt = pw, ph, pix_fmt
        except (av.error.FFmpegError, OSError, ValueError) as exc:  # type: ignore[attr-defined]
            # ValueError: PyAV's for a codec the container does not hold
            raise LFFileError(f"{self.path}: cannot open for writing ({exc})") from exc
        self._size = (h, w)
        self._padded = (ph, pw)

    def write(self, img: np.ndarray) -> None:
        import av

        if self._size is None:
            self._open(img.shape[0], img.shape[1])
        h, w = self._size
        if img.shape != (h, w, 3) or img.dtype != np.uint8:
            raise LFShapeError(f"{self.path}: every frame must be uint8 ({h}, {w}, 3), got {img.dtype} {img.shape}")
        ph, pw = self._padded
        try:
            if self._stream.pix_fmt == "yuv420p":
                frame = av.VideoFrame.from_ndarray(rgb_to_video_i420(img, (ph, pw)), format="yuv420p")
            else:
                frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(img), format="rgb24")
            for packet in self._stream.encode(frame):
                self._container.mux(packet)
                self.packets += 1
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
                self.packets += 1
            self._container.close()
            os.replace(self._tmp, self.path)
        except (av.error.FFmpegError, OSError) as exc:  # type: ignore[attr-defined]
            raise LFFileError(f"{self.path}: video finalisation failed ({exc})") from exc
        finally:
            self._container = None
            self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> VideoWriter:
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


#: BT.601 limited-range chroma rows (U, V) of RGB -> YCbCr with the offset column, the
#: conversion FFmpeg's swscale applies to untagged SD video
_RGB_TO_UV = np.array([[-0.1482, -0.2910, 0.4392, 128.0], [0.4392, -0.3678, -0.0714, 128.0]], np.float32)


def rgb_to_video_i420(img: np.ndarray, size: tuple[int, int] | None = None) -> np.ndarray:
    """RGB to planar 4:2:0 YCbCr as players expect it (BT.601, limited range: what PyAV's
    swscale produces for untagged video, luma within one level, chroma within two), padded
    by edge replication to
    ``size`` (even). Chroma is the 2 x 2 area mean, as swscale's.
    (:func:`lfstream.codec.centre.av1.rgb_to_i420` is the codec's own full-range conversion,
    which its decoder inverts.)

    Shape:
        - img: ``(H, W, 3)`` uint8
        - output: ``(3 * h // 2, w)`` uint8, ``(h, w) = size`` (default ``(H, W)``, even)
    """
    import cv2

    h, w = size if size is not None else img.shape[:2]
    if h % 2 or w % 2 or h < img.shape[0] or w < img.shape[1]:
        raise LFValueError(f"4:2:0 needs an even size that holds the image, got {(h, w)} for {img.shape[:2]}")
    if (h, w) != img.shape[:2]:
        img = cv2.copyMakeBorder(img, 0, h - img.shape[0], 0, w - img.shape[1], cv2.BORDER_REPLICATE)
    out = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2YUV_I420)  # Y as swscale's; its chroma is not
    uv = cv2.transform(cv2.resize(img, (w // 2, h // 2), interpolation=cv2.INTER_AREA), _RGB_TO_UV)
    flat, n = out.reshape(-1), (h // 2) * (w // 2)  # the planes lie back to back (h / 2 may be odd)
    flat[h * w:h * w + n] = uv[..., 0].ravel()
    flat[h * w + n:] = uv[..., 1].ravel()
    return out


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


def grid_metadata(views: tuple[int, int]) -> dict[str, str]:
    """The container metadata that records a mosaic video's view grid."""
    return {GRID_METADATA_KEY: f"{GRID_METADATA_PREFIX}{views[0]}x{views[1]}"}


__all__ = ["VIDEO_EXTS", "GRID_METADATA_KEY", "GRID_METADATA_PREFIX", "SIZE_METADATA_PREFIX", "LOSSLESS_X264", "LOSSLESS_CODECS",
           "VideoWriter", "rgb_to_video_i420", "write_video", "iter_video_frames", "VideoInfo", "video_info",
           "video_grid_and_fps", "collect_frames", "grid_metadata"]
