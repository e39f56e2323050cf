"""The codec's entry points: :func:`encode` (``lfstream.encode``), above the encoder and the
rate control it configures, and the decoding of a stream (:func:`decode`, :func:`iter_decode`,
:func:`decode_file`, :func:`lfs_frames`) above :class:`~lfstream.codec.decoder.Decoder`."""

from __future__ import annotations

import io
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from lfstream.codec.bitstream import (
    Limits,
    Packet,
    StreamHeader,
    StreamWriter,
    count_packets,
    header_present,
    iter_packets,
    read_header,
)
from lfstream.codec.decoder import BATCH_RANGE, DecodedFrame, Decoder
from lfstream.codec.encoder import frames_of
from lfstream.codec.hint import HintOptions
from lfstream.codec.rate import (
    RATE_CONTROL_CHOOSES,
    rate_control_conflict,
)
from lfstream.codec.stream_encoder import CodingOptions, StreamEncoder
from lfstream.errors import BitstreamError, LFFileError, LFStreamError, LFValueError
from lfstream.lightfield import check_first_frame, frames_in_range


def encode(
    lf: np.ndarray,
    quality: int = 50,
    depth_hint: bool = True,
    fps: float = 30.0,
    hint_options: HintOptions | None = None,
    gain_grid: int = 4,
    present: np.ndarray | None = None,
    bpp: float | None = None,
    preset: str | None = None,
    residual: int | None = None,
    residual_mode: str = "prediction",
    post_filter: bool = True,
    device: str = "cpu",
    hance_map: bool = False,
) -> bytes:
    """Encodes one light field or an LF video to ``.lfs`` bytes.

    With no ``preset``, ``bpp`` or ``residual`` named, the coding is chosen per stream
    (:func:`lfstream.codec.rate.choose_default`): the seed's JPEG centre view and the depth
    hint from 7x7 views up, an AV1 centre with fewer views, and the views coded as one AV1
    sequence keyed by the centre view where the first frame shows that warping cannot predict
    them; the hint at 1/8 of the view instead of 1/4 where the first frame shows it predicts
    the views as well for the bytes it saves. A named preset is used as it is.

    Args:
        lf: the light field(s), uint8 or float in ``[0, 1]``.
        quality: the centre view's quality, 1..100.
        depth_hint: send the depth hint (else the centre view alone).
        fps: the stream's frame rate.
        hint_options: the hint's sweep and coding (:class:`HintOptions`).
        gain_grid: cells per axis of the per-view gain maps.
        present: mask of the views that exist (the centre view must); recorded in the stream,
            whose decode leaves the missing views zero.
        bpp: a target size in bits per pixel instead of ``quality`` and ``depth_hint``: rate
            control (:mod:`lfstream.codec.rate`) picks the quality, the hint, the preset (unless
            ``preset`` names one) and the residual layer.
        preset: the centre view's coding (:data:`PRESETS`).
        residual: quality 1..100 of the residual layer (:mod:`lfstream.codec.residual`), ``None``
            for none.
        residual_mode: what the residual codes: ``prediction``, ``views`` or ``half-views``
            (:attr:`Encoder.residual_mode`).
        post_filter: name the decoder's JPEG post-filter the encoder measured best
            (:attr:`Encoder.post_filter`; ``False``: the default filter).
        device: where the hint's plane sweep runs (:attr:`Encoder.device`).
        hance_map: send a JPEG-Hance strength map with each JPEG centre view
            (:attr:`Encoder.hance_map`; not with ``bpp``).

    Returns:
        The ``.lfs`` stream (:mod:`lfstream.codec.bitstream`).

    Raises:
        LFStreamError: bad shape, dtype, non-finite values or parameters.

    Shape:
        - lf: ``(U, V, H, W, 3)`` or ``(T, U, V, H, W, 3)``
        - present: ``(U, V)``
    """
    try:
        frames = frames_of(np.asarray(lf) if not hasattr(lf, "numpy") else lf.cpu().numpy())
    except (TypeError, ValueError, AttributeError) as exc:
        if isinstance(exc, LFStreamError):
            raise
        raise LFValueError(f"lf: not an array ({exc})") from exc
    if bpp is not None:
        conflict = rate_control_conflict(residual, residual_mode, post_filter, hance_map)
        if conflict:
            raise LFValueError(f"{conflict}: rate control (bpp) {RATE_CONTROL_CHOOSES[conflict]}")
    stream = StreamEncoder(CodingOptions(quality=quality, bpp=bpp, preset=preset, depth_hint=depth_hint, residual=residual,
                                         residual_mode=residual_mode, post_filter=post_filter, hance_map=hance_map,
                                         device=device, hint_options=hint_options, gain_grid=gain_grid), fps, present)
    packets = [stream.encode_frame(frame) for frame in frames]
    buf = io.BytesIO()
    writer = StreamWriter(buf, stream.header)
    for packet in packets:
        writer.write(packet)
    return buf.getvalue()


def iter_decode(fh, depth: str = "auto", occlusion: bool = True, limits: Limits = Limits(),
                max_frames: int | None = None, hance: str = "auto", device: str = "cpu",
                batch: int = 1, deblock: bool = True, out: np.ndarray | None = None,
                first_frame: int = 0, preset: str = "fast", precision: str = "auto",
                synthesize_missing: bool = False) -> Iterator[DecodedFrame]:
    """Decodes a stream frame by frame, in bounded memory.

    Every complete frame before a damaged packet is yielded, then :class:`BitstreamError`
    names the damaged frame. The packets before ``first_frame`` are only followed
    (:meth:`Decoder.follow`: their hints and gain maps read, so that the deltas after them
    resolve; nothing warped), so the frames decoded are byte for byte those of a decode from
    the start.

    Args:
        fh: a binary file object at the start of the stream.
        depth, occlusion, hance, device, deblock, preset, precision: :class:`Decoder`'s.
        limits: bounds checked before anything is allocated.
        max_frames: at most this many frames, counted from ``first_frame``.
        batch: frames per network batch.
        out: an array the ``k``-th frame decoded (``k < T``) goes into
            (:meth:`Decoder.decode_batch`); later frames get arrays of their own.
        first_frame: the stream's frame to start at.
        synthesize_missing: keep the prediction of the views the source lacked instead of zeros.

    Returns:
        An iterator of :class:`DecodedFrame`, each with its stream index as
        :attr:`DecodedFrame.seq`.

    Shape:
        - out: ``(T, U, V, H, W, 3)`` uint8
        - each frame's ``lf``: ``(U, V, H, W, 3)`` uint8; ``disparity``: ``(H, W)`` float32
    """
    lo, hi = BATCH_RANGE
    if not isinstance(batch, int) or not lo <= batch <= hi:
        raise LFValueError(f"batch: an integer in {lo}..{hi}, got {batch!r}")
    check_first_frame(first_frame)
    header = read_header(fh, limits)
    dec = Decoder(header, depth=depth, occlusion=occlusion, hance=hance, device=device, deblock=deblock,
                  preset=preset, precision=precision)
    pending: list[Packet] = []
    present = header_present(header)
    missing = None if present is None or synthesize_missing else ~present

    done = 0  # frames decoded: the index into ``out`` of the next

    def decoded(packets: list[Packet]) -> list[DecodedFrame]:
        nonlocal done
        dests = None if out is None else [out[k] if k < len(out) else None
                                          for k in range(done, done + len(packets))]
        done += len(packets)
        frames = dec.decode_batch(packets, out=dests)
        if missing is not None:  # views the source never had are zero, never invented
            for f in frames:
                f.lf[missing] = 0
        return frames

    try:
        for k, packet in enumerate(iter_packets(fh, header, limits)):
            if k < first_frame:
                dec.follow(packet)
                continue
            if max_frames is not None and k - first_frame >= max_frames:
                break
            pending.append(packet)
            if len(pending) >= batch:
                yield from decoded(pending)
                pending = []
    except BitstreamError:
        # frames read before a damaged packet are still delivered, then the error
        if pending:
            yield from decoded(pending)
        raise
    if pending:
        yield from decoded(pending)


def stack_frames(frames: list[np.ndarray]) -> np.ndarray:
    """Decoded frames as one ``(T, ...)`` array; a single frame is returned as a view with a
    new leading axis rather than copied (the copy of a 7x7x375x540 frame, into freshly
    page-faulted memory, was ~10 % of a one-frame decode)."""
    if len(frames) == 1:
        return frames[0][np.newaxis]
    return np.stack(frames)


def decode(data: bytes, depth: str = "auto", occlusion: bool = True, limits: Limits = Limits(),
           hance: str = "auto", device: str = "cpu", deblock: bool = True, first_frame: int = 0,
           max_frames: int | None = None, preset: str = "fast", precision: str = "auto",
           synthesize_missing: bool = False) -> np.ndarray:
    """Decodes ``.lfs`` bytes to every frame's light field.

    The frames are decoded into one array sized by the packets counted first
    (:func:`video_array`), not decoded apart and then stacked (the stack copied every frame
    into fresh pages).

    Args:
        data: the stream.
        depth, occlusion, hance, device, deblock, preset, precision: :class:`Decoder`'s.
        limits: bounds checked before anything is allocated.
        first_frame, max_frames: a range of the stream's frames (:func:`iter_decode`: the
            same bytes as those frames of a whole decode).
        synthesize_missing: keep the decoder's prediction of the views the source lacked
            (the stream's present-view mask) instead of zeros.

    Returns:
        uint8 light fields, one per decoded frame.

    Raises:
        LFStreamError: corrupt, truncated or hostile input (the error names the frame; the
            frames decoded before the damage are in its ``partial`` attribute).

    Shape:
        - output: ``(T, U, V, H, W, 3)``
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise LFValueError(f"data: expected bytes, got {type(data).__name__}")
    check_first_frame(first_frame)
    buf = io.BytesIO(bytes(data))
    try:
        header = read_header(buf, limits)
        count = count_packets(buf, header, limits)[0]
    except BitstreamError:  # a damaged header: the decode below names it
        count = None
    out = None if count is None else video_array(
        header, frames_in_range(count, first_frame, max_frames, "stream") if count else 0)
    buf.seek(0)
    frames: list[np.ndarray] = []
    try:
        for f in iter_decode(buf, depth, occlusion, limits, hance=hance, device=device, deblock=deblock, out=out,
                             first_frame=first_frame, max_frames=max_frames, preset=preset, precision=precision,
                             synthesize_missing=synthesize_missing):
            frames.append(f.lf)
    except BitstreamError as exc:
        exc.partial = frames_array(frames, out) if frames else None  # type: ignore[attr-defined]
        raise
    if not frames:
        raise BitstreamError("stream holds no frames")
    return frames_array(frames, out)


#: The most of the machine's memory :func:`decode` reserves up front for the frames it
#: counted; a longer stream is decoded frame by frame and stacked (as any stream was).
VIDEO_ARRAY_MEMORY_SHARE = 0.5


def video_array(header: StreamHeader, count: int) -> np.ndarray | None:
    """The ``(T, U, V, H, W, 3)`` array for ``count`` frames of a stream with ``header`` (its
    complete packets, :func:`lfstream.codec.bitstream.count_packets`, or a range of them), or
    ``None`` where there are none or they would take more than
    :data:`VIDEO_ARRAY_MEMORY_SHARE` of the machine's memory: a stream cannot make the
    decoder reserve memory its frames could not fill."""
    u, v = header.views
    h, w = header.size
    frame_bytes = u * v * h * w * 3
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # not reported: reserve nothing
        memory = 0
    if count == 0 or count * frame_bytes > VIDEO_ARRAY_MEMORY_SHARE * memory:
        return None
    return np.empty((count, u, v, h, w, 3), np.uint8)


def frames_array(frames: list[np.ndarray], out: np.ndarray | None) -> np.ndarray:
    """The decoded frames as one array: the first ``len(frames)`` of ``out`` (a
    :func:`video_array` they were decoded into, :func:`iter_decode`'s ``out``) where they
    are its frames, else stacked (:func:`stack_frames`)."""
    if out is not None and len(frames) <= len(out) and all(
            f.shape == out.shape[1:] and f.ctypes.data == out[k].ctypes.data for k, f in enumerate(frames)):
        return out[: len(frames)]
    return stack_frames(frames)


def decode_file(path: str | os.PathLike, depth: str = "auto", max_frames: int | None = None,
                hance: str = "auto", device: str = "cpu", first_frame: int = 0,
                preset: str = "fast", precision: str = "auto") -> tuple[np.ndarray, float]:
    """Decodes an ``.lfs`` file (from frame ``first_frame``, :func:`iter_decode`; ``preset``,
    ``precision``: the networks' weights and precision, :class:`Decoder`'s); returns ``(lf, fps)``."""
    path = Path(path)
    check_first_frame(first_frame)
    with _errors_naming(path), open(path, "rb") as fh:
        header = read_header(fh)
        count = count_packets(fh, header)[0]  # (none: the decode below names the damage)
        out = video_array(header, frames_in_range(count, first_frame, max_frames, path) if count else 0)
        fh.seek(0)
        frames = [f.lf for f in iter_decode(fh, depth=depth, max_frames=max_frames, hance=hance, device=device,
                                            out=out, first_frame=first_frame, preset=preset,
                                            precision=precision)]
    if not frames:
        raise BitstreamError(f"{path}: stream holds no frames")
    return frames_array(frames, out), header.fps


def lfs_frames(path: str | os.PathLike, max_frames: int | None = None, first_frame: int = 0
               ) -> tuple[Iterator[np.ndarray], StreamHeader, int, BitstreamError | None]:
    """An ``.lfs`` file as a light field for the readers (:func:`lfstream.io.open_video_lf`,
    :func:`lfstream.io.load_lf`): its frames decoded one at a time as :func:`decode` decodes
    them (the hint where the stream has one), its header (frame rate, views, view size),
    its count of complete frames (the packets are counted, checksums and all, before any is
    decoded) and the damage that ended the count, ``None`` where the stream ends cleanly
    (a stream cut short, a recording interrupted: the frames before it are yielded, then
    the error, as a damaged video gives its frames before the damage); from frame
    ``first_frame`` (:func:`iter_decode`) for at most ``max_frames``. It was decoded whole with flat
    disparity, for ``info``, which reads headers now: every other command given an ``.lfs``
    (``refocus``, ``stream``, ``view``) then saw the centre view copied to every view, a
    light field without parallax.

    Raises:
        LFFileError: the file cannot be read.
        BitstreamError: a damaged header or first packet (no frame to read); later damage,
            named with the file, after the frames before it.
    """
    path = Path(path)
    with _errors_naming(path), open(path, "rb") as fh:
        header = read_header(fh)
        count, damage = count_packets(fh, header)
    if damage is not None:
        damage = BitstreamError(f"{path}: {damage}")
        if count == 0:
            raise damage
    if count == 0:
        raise BitstreamError(f"{path}: stream holds no frames")

    def frames() -> Iterator[np.ndarray]:
        with _errors_naming(path), open(path, "rb") as fh:
            for f in iter_decode(fh, max_frames=max_frames, first_frame=first_frame):
                yield f.lf

    return frames(), header, count, damage


@contextmanager
def _errors_naming(path: str | os.PathLike) -> Iterator[None]:
    """A file's read errors as lfstream's, naming the file: :class:`LFFileError` for the
    system's, :class:`BitstreamError` (its message prefixed) for a damaged stream."""
    try:
        yield
    except OSError as exc:
        raise LFFileError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    except BitstreamError as exc:
        raise BitstreamError(f"{path}: {exc}") from exc


__all__ = ["encode", "decode", "iter_decode", "decode_file", "lfs_frames", "stack_frames",
           "video_array", "frames_array", "VIDEO_ARRAY_MEMORY_SHARE"]
