"""The residual layer: what the decoder's prediction misses, coded per view.

One coded view and a disparity cannot carry occlusions, view-dependent light or per-view
noise, so without a residual the decoded quality saturates however many bits the centre
view gets (bikes: 32.7 dB at 0.08 bpp where x265 reaches 34.1). The encoder runs the
decoder's own prediction, takes ``residual = view - prediction + 128`` (clipped to 8 bits)
for every view but the centre and codes the residual views as one AV1 sequence (SVT-AV1,
serpentine view order so neighbouring frames are neighbouring views; 4:2:0 BT.601 full
range as :func:`lfstream.codec.centre.av1.rgb_to_i420`). Measured on lytro_bikes at 0.08 bpp:
35.1 dB with the residual against 32.7 without (JPEG-coded residuals spent 0.3-0.8 bpp for
less: per-view noise is what a residual mostly holds, and only inter prediction across
views codes it cheaply).

Three modes (:data:`RESIDUAL_MODES`): ``prediction`` codes ``view - prediction``; ``views`` codes
the views themselves (the "prediction" is mid-grey, so the decoder skips the warp);
``half-views`` codes them at half size. With an AV1 centre view at the residual's own
quality, ``views`` is coded as one sequence of every view whose key frame *is* the centre
view (format 4, :func:`encode_views_keyed`): the packet's centre payload is that sequence's
first packet, a key frame that decodes alone, and the residual payload the rest, so the
light field pays for one intra frame, not two (the anchor's pseudo-sequence structure).
Measured on toys_array (9x9x240x320, SVT-AV1 preset 8, qualities 20-65): 1-4 % fewer bytes
and +0.03-0.12 dB against the centre coded apart (format 2, which other streams keep).
Where warping cannot predict a scene the residual of a poor prediction costs more than the
views: on toys_array (7.5 px between neighbouring views, occlusions everywhere; the hint's
warp reconstructs even the nearest views at 22-24 dB) rate control's best prediction-residual
stream at 0.08 bpp decoded at 23.4 dB where the views coded as one sequence reach 28.0 dB at
0.076 bpp. Rate control measures both and picks (:mod:`lfstream.codec.rate`).

Payload (little-endian)::

    format   u8   1 (prediction), 2 (views), 3 (half-views) or 4 (views after the centre's key frame)
    codec    u8   2 = AV1 (the bitstream's codec ids)
    frames   u16  number of coded residual views (U * V - 1)
    then per AV1 packet: length u32, bytes

A format-4 payload's packets continue the AV1 sequence the packet's centre payload starts:
the decoder feeds the centre payload first and drops its frame.

The decoder adds a ``prediction`` residual only to the prediction it was computed against: the
hint's (or, without a hint, the flat) warp of the decoded centre view with the gains, JPEG-Hance
off (:class:`lfstream.codec.decoder.Decoder` decides); a ``views`` residual replaces the views
whatever the decoder's settings.
"""

from __future__ import annotations

import errno
import os
import struct

import numpy as np

from lfstream.codec.baseline import view_order
from lfstream.codec.bitstream import CODEC_AV1
from lfstream.codec.centre import CentreCoding
from lfstream.codec.centre.av1 import i420_to_rgb, pad_to_even, rgb_to_i420, svtav1_encoder
from lfstream.codec.centre.jpeg import QUALITY_RANGE
from lfstream.codec.deadline import call_with_deadline, encoder_deadline
from lfstream.errors import BitstreamError, LFValueError

RESIDUAL_FORMAT = 1  # view - prediction
VIEWS_FORMAT = 2  # the views themselves
HALF_VIEWS_FORMAT = 3  # the views at half the size in each dimension
VIEWS_KEYED_FORMAT = 4  # the views, continuing the sequence the centre payload's key frame starts
#: What a residual layer codes: the prediction's error, the views themselves, or the views at
#: half size (up-sampled bicubically at decode: the lowest rates of scenes no warp predicts;
#: toys_array: 0.013-0.023 bpp at 21.0-22.9 dB, where full-size views cannot go under 0.026).
RESIDUAL_MODES = ("prediction", "views", "half-views")
#: The modes that code the views themselves (the decoder does not warp).
VIEW_MODES = ("views", "half-views")
_FORMAT_MODES = {RESIDUAL_FORMAT: "prediction", VIEWS_FORMAT: "views", HALF_VIEWS_FORMAT: "half-views",
                 VIEWS_KEYED_FORMAT: "views"}
_HEAD = struct.Struct("<BBH")
_LEN = struct.Struct("<I")
#: Residual values are stored with this offset (8-bit mid-grey is "no correction").
OFFSET = 128


def coded_size(size: tuple[int, int], mode: str) -> tuple[int, int]:
    """The size a residual's views are coded at (before padding to even)."""
    h, w = size
    return ((h + 1) // 2, (w + 1) // 2) if mode == "half-views" else (h, w)


def residual_views(views: tuple[int, int]) -> list[tuple[int, int]]:
    """The views a residual covers, in coding order: serpentine over the grid (rows
    alternate direction, so consecutive frames are neighbouring views), centre skipped."""
    u, v = views
    return [(a, b) for a, b in view_order(u, v, "serpentine") if (a, b) != (u // 2, v // 2)]


def check_residual_quality(quality: int) -> int:
    lo, hi = QUALITY_RANGE
    if isinstance(quality, bool) or not isinstance(quality, (int, np.integer)) or not lo <= quality <= hi:
        raise LFValueError(f"residual: a quality in {lo}..{hi}, got {quality!r}")
    return int(quality)


def check_residual_mode(mode: str) -> str:
    if mode not in RESIDUAL_MODES:
        raise LFValueError(f"residual_mode: one of {', '.join(RESIDUAL_MODES)}, got {mode!r}")
    return mode


def residual_mode(data: bytes) -> str | None:
    """The mode of a residual payload (``None``: empty or not a known format; the decode
    names the damage)."""
    return _FORMAT_MODES.get(data[0]) if data else None


def encode_residual(lf: np.ndarray, prediction: np.ndarray | None, quality: int, speed: int = 8,
                    half: bool = False) -> bytes:
    """Codes ``lf - prediction`` (or, with ``prediction=None``, the views themselves: mode
    ``views``; with ``half`` too, at half size: ``half-views``) for every view but the centre
    as one AV1 sequence.

    Args:
        lf: the original frame, uint8.
        prediction: what the decoder reconstructs without the residual, uint8; ``None``: a
            ``views`` residual.
        quality: 1..100 (SVT-AV1 CRF 63..1, as the centre view's AV1 coding).
        speed: SVT-AV1 preset.

    Shape:
        - lf, prediction: ``(U, V, H, W, 3)``
    """
    _check_coding(quality, speed)
    fmt = RESIDUAL_FORMAT
    if half and prediction is not None:
        raise LFValueError("residual: half size is a mode of the views, not of a prediction's error")
    if prediction is None:  # the views: against mid-grey, they are coded as they are
        fmt, prediction = VIEWS_FORMAT, np.broadcast_to(np.uint8(OFFSET), lf.shape)
    if half:
        import cv2

        fmt = HALF_VIEWS_FORMAT
        if lf.dtype == np.uint8 and lf.ndim == 5:
            ch, cw = coded_size(lf.shape[2:4], "half-views")
            lf = np.stack([np.stack([cv2.resize(view, (cw, ch), interpolation=cv2.INTER_AREA) for view in row])
                           for row in lf])
            prediction = np.broadcast_to(np.uint8(OFFSET), lf.shape)
    if lf.shape != prediction.shape or lf.dtype != np.uint8 or prediction.dtype != np.uint8:
        raise LFValueError(f"residual: lf {lf.shape} {lf.dtype} and prediction {prediction.shape} {prediction.dtype} "
                           "must be uint8 of one shape")
    u, v, h, w, _ = lf.shape
    order = _coded_order((u, v))

    def frame_at(k: int) -> np.ndarray:
        a, b = order[k]
        return np.clip(lf[a, b].astype(np.int16) - prediction[a, b] + OFFSET, 0, 255).astype(np.uint8)

    packets = _encode_sequence(frame_at, len(order), (h, w), quality, speed, "AV1 residual sequence")
    return _payload(fmt, len(order), packets)


def _check_coding(quality: int, speed: int) -> None:
    """A residual layer's quality and SVT-AV1 preset (the same preset range as the centre
    view's AV1 coding), else LFValueError."""
    check_residual_quality(quality)
    CentreCoding("av1", speed)


def _coded_order(views: tuple[int, int]) -> list[tuple[int, int]]:
    """:func:`residual_views`, refusing a single-view light field (nothing to code)."""
    order = residual_views(views)
    if not order:
        raise LFValueError("residual: a single-view light field has nothing to correct")
    return order


def _payload(fmt: int, frames: int, packets: list[bytes]) -> bytes:
    """A residual payload of format ``fmt`` covering ``frames`` views: the head, then each AV1
    packet behind its length."""
    return _HEAD.pack(fmt, CODEC_AV1, frames) + b"".join(_LEN.pack(len(data)) + data for data in packets)


def _encode_sequence(frame_at, count: int, size: tuple[int, int], quality: int, speed: int,
                     what: str) -> list[bytes]:
    """``count`` RGB frames (``frame_at(k)``, uint8 ``size``) as one SVT-AV1 sequence with a
    single key frame (the first): its packets' bytes, in decoding order."""
    import av

    h, w = size

    def run() -> list[bytes]:
        # self-contained (its own encoder, frames made on the way) so the deadline guard can retry it
        ctx = svtav1_encoder((h + h % 2, w + w % 2), quality, speed, gop=count)
        packets: list[bytes] = []
        for k in range(count):
            frame = av.VideoFrame.from_ndarray(rgb_to_i420(pad_to_even(frame_at(k))), format="yuv420p")
            frame.pts = k
            packets.extend(bytes(p) for p in ctx.encode(frame))
        packets.extend(bytes(p) for p in ctx.encode(None))
        return packets

    return call_with_deadline(run, encoder_deadline(count * h * w), what)


def encode_views_keyed(lf: np.ndarray, quality: int, speed: int) -> tuple[bytes, bytes]:
    """Every view as one AV1 sequence whose key frame is the centre view (format 4): the
    centre payload (the key frame's packet, an AV1 centre view that decodes alone) and the
    residual payload (the other views, :func:`residual_views` order, continuing that
    sequence).

    Args:
        lf: the frame, uint8.
        quality: 1..100 (SVT-AV1 CRF 63..1) of the whole sequence, the centre's included.
        speed: SVT-AV1 preset.

    Shape:
        - lf: ``(U, V, H, W, 3)``
    """
    _check_coding(quality, speed)
    if lf.dtype != np.uint8 or lf.ndim != 5:
        raise LFValueError(f"residual: lf must be (U, V, H, W, 3) uint8, got {lf.shape} {lf.dtype}")
    u, v, h, w, _ = lf.shape
    order = [(u // 2, v // 2), *_coded_order((u, v))]
    packets = _encode_sequence(lambda k: lf[order[k]], len(order), (h, w), quality, speed, "AV1 views sequence")
    if len(packets) < 2:  # pragma: no cover - SVT-AV1 emits one packet per shown frame
        raise LFValueError("AV1 views sequence: the encoder emitted a single packet")
    return packets[0], _payload(VIEWS_KEYED_FORMAT, len(order) - 1, packets[1:])


#: The most dav1d worker threads a residual sequence gets (frame threading across the views)
_DECODER_THREADS = max(1, min(4, os.cpu_count() or 1))
#: Payload bytes from which a sequence of the views themselves is decoded with worker
#: threads; below it, and for every ``prediction`` residual, one thread (:func:`_decoder_threads`).
_THREADED_MIN_BYTES = 96_000


def _decoder_threads(fmt: int, nbytes: int) -> int:
    """dav1d threads for a residual payload of format ``fmt``, ``nbytes`` long. Frame
    threading pays only where the whole sequence has much to decode: starting the workers
    and filling and draining their pipeline is a cost per sequence. Measured on the 2-core
    machine (the whole light field's decode, one thread against two, alternating rounds):
    views sequences of 122-651 KB (lytro_translucent at 0.1 bpp, lytro_bikes q60 and q85,
    toys_array q50 and q80 and its default) 3-15 % faster on two threads; those of 1-65 KB
    (seahorse at 0.02-0.1 bpp, lytro_translucent 0.01, lytro_bikes 0.04, dino 0.04,
    toys_array q20, half-size views) 3-28 % faster on one, lytro_translucent at 0.04 bpp
    (65 KB) within 4 % either way; neither the bits a pixel nor the bytes a frame separated
    them (seahorse at 0.1 bpp, 2.2 KB a frame, faster on one; toys_array q50, 2.0 KB a
    frame, on two). A ``prediction`` residual decodes beside the warp, which keeps both
    cores busy: one thread was faster at every rate measured (synthetic 0.01-0.12 bpp,
    lytro_bikes 0.15 and 0.40: 2-7 %)."""
    if fmt == RESIDUAL_FORMAT:
        return 1
    return _DECODER_THREADS if nbytes >= _THREADED_MIN_BYTES else 1


def _drain(ctx) -> None:
    """Flushes a decoder left with frames in flight, so that freeing it joins idle workers."""
    try:
        ctx.flush_buffers()
    except Exception:  # noqa: BLE001 - a failing flush leaves nothing more to do
        pass


def decode_residual(data: bytes, views: tuple[int, int], size: tuple[int, int],
                    frame: int | None = None, centre: bytes | None = None) -> np.ndarray:
    """The residual views' decoded 4:2:0 planes, in :func:`residual_views` order.

    ``centre``: the packet's centre payload, which a format-4 payload's sequence starts with
    (fed to the decoder first, its frame dropped).

    Raises:
        BitstreamError: a malformed payload, the wrong number or size of frames, a format-4
            payload without its centre (names ``frame``).

    Shape:
        - output: ``(U * V - 1, 3 * PH / 2, PW)`` uint8, PyAV's yuv420p layout (PH, PW: the
          view size rounded up to even)
    """
    import av

    order = residual_views(views)
    if len(data) < _HEAD.size:
        raise BitstreamError(f"residual payload truncated ({len(data)} bytes)", frame)
    fmt, codec, count = _HEAD.unpack_from(data)
    if fmt not in _FORMAT_MODES or codec != CODEC_AV1:
        raise BitstreamError(f"residual payload format {fmt} / codec {codec} unknown (expected "
                             f"{' or '.join(map(str, _FORMAT_MODES))} / {CODEC_AV1})", frame)
    if count != len(order):
        raise BitstreamError(f"residual payload covers {count} views, the stream has {len(order)} besides the centre",
                             frame)
    h, w = coded_size(size, _FORMAT_MODES[fmt])
    packets = []
    lead = 0  # frames decoded before the residual's own: the centre's key frame
    if fmt == VIEWS_KEYED_FORMAT:
        if not centre:
            raise BitstreamError("residual payload continues the centre view's AV1 sequence, and there is no AV1 "
                                 "centre view to start it", frame)
        packets.append(centre)
        lead = 1
    pos = _HEAD.size
    while pos < len(data):
        if pos + _LEN.size > len(data):
            raise BitstreamError("residual payload truncated inside a packet length", frame)
        (n,) = _LEN.unpack_from(data, pos)
        pos += _LEN.size
        if n == 0 or pos + n > len(data) or len(packets) >= 2 * count + lead:
            raise BitstreamError("residual payload: a packet length or count outside the payload", frame)
        packets.append(data[pos:pos + n])
        pos += n
    ctx = av.CodecContext.create("libdav1d", "r")
    from lfstream.codec.centre.av1 import max_av1_pixels

    # dav1d refuses a frame larger than the coded views before allocating it
    ctx.options = {"max_pixels": str(max_av1_pixels((h, w)))}
    # Worker threads where they pay (:func:`_decoder_threads`). A test-suite run once hung
    # with dav1d's workers parked on futexes while a sequence was torn down:
    # the decoder was then freed with frames in flight (a loop that stopped early, without a
    # flush). So nothing is left in flight on any way out: every packet decoded and the
    # decoder flushed, and where decoding fails or is interrupted, its buffers flushed
    # (dav1d_flush: the workers drained) before the context is freed.
    ctx.thread_count = _decoder_threads(fmt, len(data))
    decoded = []
    failure = None
    try:
        for p in packets:
            decoded.extend(ctx.decode(av.Packet(p)))
        decoded.extend(ctx.decode(None))
    except (av.error.FFmpegError, ValueError) as exc:
        _drain(ctx)
        if getattr(exc, "errno", None) == errno.ERANGE:  # refused by max_pixels
            failure = f"residual frames are larger than the header says ({h}x{w})"
        else:
            failure = f"residual is not a decodable AV1 sequence ({exc})"
    except BaseException:  # Ctrl-C, a deadline: drained as well
        _drain(ctx)
        raise
    if failure is None and len(decoded) != count + lead:
        failure = f"residual holds {len(decoded) - lead} AV1 frames, expected {count}"
    bad = [f for f in decoded[lead:] if f.format.name != "yuv420p" or (f.height, f.width) != (h + h % 2, w + w % 2)]
    if failure is None and bad:
        failure = f"residual frame is {bad[0].height}x{bad[0].width} {bad[0].format.name}, header says {h}x{w}"
    if failure is not None:
        # the decoder and its frames freed here, on the thread that made them, before the
        # error leaves: an error raised beside them kept this frame (and through it the
        # dav1d context) alive until the caller dropped it, often on another thread, and a
        # long run of hostile streams grew the process's memory by kilobytes a stream
        del ctx, decoded, bad
        raise BitstreamError(failure, frame)
    planes = np.empty((count, (h + h % 2) * 3 // 2, w + w % 2), np.uint8)
    for k, f in enumerate(decoded[lead:]):
        _copy_i420(f, planes[k])
    return planes


def _copy_i420(f, out: np.ndarray) -> None:
    """A decoded yuv420p frame's planes into ``out``, PyAV's ``(3H/2, W)`` layout, with one
    copy per plane."""
    h, w = f.height, f.width
    shapes = ((h, w), (h // 2, w // 2), (h // 2, w // 2))
    if any(p.line_size < pw or p.buffer_size < ph * p.line_size for p, (ph, pw) in zip(f.planes, shapes)):
        out[...] = f.to_ndarray(format="yuv420p")  # a layout this copy does not expect
        return
    flat = out.reshape(-1)
    pos = 0
    for plane, (ph, pw) in zip(f.planes, shapes):
        rows = np.frombuffer(plane, np.uint8, count=ph * plane.line_size).reshape(ph, plane.line_size)  # padded rows
        flat[pos:pos + ph * pw].reshape(ph, pw)[...] = rows[:, :pw]
        pos += ph * pw


def apply_residual(lf: np.ndarray, data: bytes, frame: int | None = None, centre: bytes | None = None,
                   planes: np.ndarray | None = None) -> np.ndarray:
    """``lf`` (the prediction the residual was computed against) with the residual added,
    in place (one fused pass: YCbCr to RGB, offset, saturation); a ``views`` residual
    replaces every view but the centre instead. Returns ``lf``. ``centre``: the packet's
    centre payload (:func:`decode_residual`); ``planes``: what :func:`decode_residual`
    gives for ``data``, where the caller decoded it already (the decoder does, beside the
    warp).

    Shape:
        - lf: ``(U, V, H, W, 3)`` uint8
    """
    from lfstream.codec.residual_kernels import add_i420_residual

    u, v, h, w, _ = lf.shape
    if planes is None:
        planes = decode_residual(data, (u, v), (h, w), frame, centre)
    positions = np.array(residual_views((u, v)), np.int64)
    mode = residual_mode(data)
    if mode == "half-views":  # small views: converted, then up-sampled
        import cv2

        ch, cw = coded_size((h, w), "half-views")
        for (a, b), p in zip(positions, planes):
            cv2.resize(i420_to_rgb(p)[:ch, :cw], (w, h), dst=lf[a, b], interpolation=cv2.INTER_CUBIC)
        return lf
    # the kernel writes rows of the (U, V, H, W * 3) layout
    target = lf if lf.flags.c_contiguous else np.ascontiguousarray(lf)
    add_i420_residual(target, planes, positions, OFFSET, mode == "views")  # views: stored (no offset), not added
    if target is not lf:
        lf[...] = target
    return lf


def residual_images(data: bytes, views: tuple[int, int], size: tuple[int, int],
                    frame: int | None = None, centre: bytes | None = None) -> list[np.ndarray]:
    """The residual views as RGB images (offset by :data:`OFFSET`; a ``views`` residual's
    are the views, a ``half-views`` one's at :func:`coded_size`), in
    :func:`residual_views` order: the plain path the fused :func:`apply_residual` is
    tested against.

    Shape:
        - output: ``U * V - 1`` arrays ``(H, W, 3)`` uint8
    """
    h, w = coded_size(size, residual_mode(data) or "prediction")
    return [i420_to_rgb(p)[:h, :w] for p in decode_residual(data, views, size, frame, centre)]


__all__ = ["RESIDUAL_FORMAT", "VIEWS_FORMAT", "HALF_VIEWS_FORMAT", "VIEWS_KEYED_FORMAT", "RESIDUAL_MODES", "VIEW_MODES",
           "coded_size", "OFFSET", "check_residual_mode", "residual_mode",
           "residual_views", "check_residual_quality", "encode_residual", "encode_views_keyed", "decode_residual",
           "apply_residual", "residual_images"]
