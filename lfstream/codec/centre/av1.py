"""The centre view as an AV1 intra frame (SVT-AV1 encoder, dav1d decoder, both inside PyAV):
the ``balanced`` and ``best`` presets (JPEG, the ``fast`` preset: :mod:`lfstream.codec.centre.jpeg`).

On the shared samples' centre views (``bench/rd.py`` has the light-field curves) an AV1 key
frame takes a third fewer bytes than JPEG at equal PSNR on the noisy Lytro capture and about
4x fewer on the clean rendered seahorse, for tens of times the encoding time. Everything else
in a packet (the depth hint, the gains) is unchanged, so the AV1 centre moves the codec's
whole rate-distortion curve to fewer bits.

Both coders take one ``quality`` in 1..100 (higher: better, more bits); for AV1 it maps
linearly onto SVT-AV1's CRF 63..1. Both are deterministic: the same image and quality give
the same bytes (SVT-AV1 at a fixed preset, checked by tests/codec/centre/test_av1.py).
"""

from __future__ import annotations

import errno
import os
import platform
from fractions import Fraction

import cv2
import numpy as np

from lfstream.codec.centre.jpeg import QUALITY_RANGE
from lfstream.codec.deadline import call_with_deadline, encoder_deadline
from lfstream.errors import BitstreamError, LFValueError

#: SVT-AV1 speed presets lfstream uses (13 fastest): see :data:`lfstream.codec.encoder.PRESETS`.
AV1_SPEED_RANGE = (4, 13)


def av1_crf(quality: int) -> int:
    """SVT-AV1's CRF for a quality in 1..100: 100 -> 1, 1 -> 63, linear in between."""
    lo, hi = QUALITY_RANGE
    if not lo <= quality <= hi:
        raise LFValueError(f"quality: an integer in {lo}..{hi}, got {quality!r}")
    return int(round(63 - (quality - 1) * 62 / 99))


#: SVT-AV1's fastest presets (this one up) at CRF 1-4 write sequences dav1d refuses as
#: invalid data on real views (seahorse's views, keyed views and prediction residuals,
#: presets 11-13, qualities 95-100; CRF 5 and presets up to 10 decoded): those presets'
#: lowest CRF is :data:`SVT_FAST_MIN_CRF`, a step of margin above the lowest that decoded.
SVT_CRF_FLOOR_FROM = 11
SVT_FAST_MIN_CRF = 6


def svt_crf(quality: int, speed: int) -> int:
    """The CRF SVT-AV1 is given for ``quality`` at preset ``speed`` (:func:`av1_crf`, at least
    :data:`SVT_FAST_MIN_CRF` from preset :data:`SVT_CRF_FLOOR_FROM` up)."""
    crf = av1_crf(quality)
    return max(crf, SVT_FAST_MIN_CRF) if speed >= SVT_CRF_FLOOR_FROM else crf


def rgb_to_i420(img: np.ndarray) -> np.ndarray:
    """RGB (even sizes) to planar 4:2:0 in PyAV's ``(3H/2, W)`` layout: BT.601 full range
    (the decoder inverts the same matrix: no range squeeze), chroma by 2x2 means.

    OpenCV's own RGB->I420 conversion decimates chroma and its inverse replicates it: on the
    synthetic views that alone caps the round trip at 30.2 dB against 35.3 dB here (bikes
    38.7 vs 42.5), which is JPEG q100's ceiling."""
    h, w = img.shape[:2]
    ycc = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2YCrCb)
    cr = cv2.resize(ycc[..., 1], (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    cb = cv2.resize(ycc[..., 2], (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    return np.concatenate([ycc[..., 0].ravel(), cb.ravel(), cr.ravel()]).reshape(h * 3 // 2, w)


def i420_to_rgb(planes: np.ndarray) -> np.ndarray:
    """The inverse of :func:`rgb_to_i420`: chroma up-sampled bilinearly (centre-aligned,
    the phase of the 2x2 means)."""
    h, w = planes.shape[0] * 2 // 3, planes.shape[1]
    flat = planes.ravel()
    y = flat[:h * w].reshape(h, w)
    cb = flat[h * w:h * w + h * w // 4].reshape(h // 2, w // 2)
    cr = flat[h * w + h * w // 4:].reshape(h // 2, w // 2)
    up = [cv2.resize(c, (w, h), interpolation=cv2.INTER_LINEAR) for c in (cr, cb)]
    # cv2.merge interleaves the planes as np.dstack does, in a third of the time (0.1 against
    # 0.33 ms at 512 x 512)
    return cv2.cvtColor(cv2.merge([np.ascontiguousarray(y), up[0], up[1]]), cv2.COLOR_YCrCb2RGB)


def pad_to_even(img: np.ndarray) -> np.ndarray:
    """``img`` padded by edge replication to even height and width (4:2:0 needs them);
    ``img`` itself when they are even already.

    Shape:
        - img: ``(H, W, C)``; output ``(H + H % 2, W + W % 2, C)``
    """
    h, w = img.shape[:2]
    if h % 2 == 0 and w % 2 == 0:
        return img
    return np.pad(img, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


#: The smallest frame, on each side after padding to even, lfstream gives SVT-AV1. SVT-AV1
#: 4.1.0 accepts frames down to 4 x 4 but writes past its heap on small ones (valgrind, presets
#: 4 / 8 / 12 / 13: invalid writes and a crash on 4x4, 16x16 and 24x24 frames, invalid reads
#: on 8x8 and 64x24 (H x W) ones; clean on every frame from 32 x 32 up that was tried).
AV1_MIN_SIZE = 32
#: The smallest view AV1 codes, as the errors name it.
AV1_MIN_VIEW = f"{AV1_MIN_SIZE - 1}x{AV1_MIN_SIZE - 1}"


def av1_fits(size: tuple[int, int]) -> bool:
    """Whether lfstream codes frames of ``size`` (H, W) with SVT-AV1 (:data:`AV1_MIN_SIZE`)."""
    h, w = size
    return h + h % 2 >= AV1_MIN_SIZE and w + w % 2 >= AV1_MIN_SIZE


def quiet_svt_log() -> None:
    """SVT-AV1 prints its configuration to stderr, about twenty lines an encoder, at its
    default log level; it reads ``SVT_LOG`` once, when its first encoder starts. Errors only
    (level 1), unless the user set the variable."""
    os.environ.setdefault("SVT_LOG", "1")


#: The widest x86 instruction set SVT-AV1 may use. Capped at AVX2, the set every development
#: and benchmark machine of this project has: the bytes then do not depend on whether a host
#: also has AVX-512, and SVT-AV1's AVX-512 kernels (chosen by default where the CPU has them)
#: are a path none of our machines exercises. A CI run once crashed (SIGSEGV) inside an
#: SVT-AV1 or x265 flush on a host that may have had them; valgrind finds nothing in the AVX2
#: paths (tests' 34x48 and 64x64 views).
SVT_X86_ASM = "avx2"


def svt_options() -> dict[str, str]:
    """Options for every SVT-AV1 encoder lfstream opens: the instruction-set cap
    (:data:`SVT_X86_ASM`) on x86-64; none elsewhere (SVT-AV1 names other sets there)."""
    if platform.machine().lower() in ("x86_64", "amd64"):
        return {"svtav1-params": f"asm={SVT_X86_ASM}"}
    return {}


def svtav1_encoder(size: tuple[int, int], quality: int, speed: int, gop: int | None = None):
    """An SVT-AV1 encoder context for even-sized 4:2:0 frames at ``quality`` (1..100, mapped
    by :func:`av1_crf`) and preset ``speed``; ``gop``: the key-frame interval, if set."""
    import av

    if not av1_fits(size):  # checked by every caller first; here so that no path reaches SVT-AV1
        raise LFValueError(f"AV1 codes views of at least {AV1_MIN_VIEW} pixels, got {size[0]}x{size[1]}")
    quiet_svt_log()
    ctx = av.CodecContext.create("libsvtav1", "w")
    ctx.height, ctx.width = size
    ctx.pix_fmt = "yuv420p"
    ctx.time_base = Fraction(1, 25)
    options = {"preset": str(int(speed)), "crf": str(svt_crf(quality, speed)), **svt_options()}
    if gop is not None:
        options["g"] = str(int(gop))
    ctx.options = options
    return ctx


def encode_av1(img: np.ndarray, quality: int, speed: int = 12) -> bytes:
    """One AV1 key frame (4:2:0, 8 bit) of a uint8 RGB image; odd sizes are padded by edge
    replication (the decoder crops to the header's size).

    Shape:
        - img: ``(H, W, 3)`` uint8
    """
    import av

    img = pad_to_even(img)
    i420 = rgb_to_i420(img)

    def run() -> bytes:
        ctx = svtav1_encoder(img.shape[:2], quality, speed)
        frame = av.VideoFrame.from_ndarray(i420, format="yuv420p")
        frame.pts = 0
        return b"".join(bytes(p) for p in ctx.encode(frame)) + b"".join(bytes(p) for p in ctx.encode(None))

    data = call_with_deadline(run, encoder_deadline(img.shape[0] * img.shape[1]), "AV1 centre view")
    if not data:  # pragma: no cover - the encoder always emits a key frame for one input frame
        raise LFValueError("AV1 encoding produced no data")
    return data


#: A centre view smaller than this many pixels is decoded on one dav1d thread: starting its
#: worker threads cost more than they save on one key frame (measured on the 2-core machine,
#: the decode alone: cotton's and dino's 512 x 512 centres 1.01 -> 0.89 and 1.95 -> 1.70 ms,
#: seahorse's 500 x 500 0.48 -> 0.34, the synthetic 375 x 540 0.87 -> 0.67), while a
#: 1080 x 1920 one decodes faster threaded.
AV1_THREADED_MIN_PIXELS = 1 << 20


def max_av1_pixels(size: tuple[int, int]) -> int:
    """The most pixels a decoded AV1 frame of views of ``size`` may have (padded to even)."""
    return (size[0] + size[0] % 2) * (size[1] + size[1] % 2)


def decode_av1(data: bytes, size: tuple[int, int], frame: int | None = None) -> np.ndarray:
    """AV1 key-frame bytes to uint8 RGB ``(H, W, 3)``; checks the size the header promised."""
    import av

    h, w = size
    failure = None
    try:
        ctx = av.CodecContext.create("libdav1d", "r")
        # dav1d refuses a frame larger than the stream's before allocating it
        ctx.options = {"max_pixels": str(max_av1_pixels(size))}
        if h * w < AV1_THREADED_MIN_PIXELS:
            ctx.thread_count = 1
        frames = list(ctx.decode(av.Packet(data))) + list(ctx.decode(None))
    except (av.error.FFmpegError, ValueError) as exc:
        if getattr(exc, "errno", None) == errno.ERANGE:  # refused by max_pixels
            failure = f"centre view's AV1 frame is larger than the header says ({h}x{w})"
        else:
            failure = f"centre view is not a decodable AV1 frame ({exc})"
    if failure is None and len(frames) != 1:
        failure = f"centre view holds {len(frames)} AV1 frames, expected 1"
    elif failure is None and (frames[0].format.name != "yuv420p"
                              or (frames[0].height, frames[0].width) != (h + h % 2, w + w % 2)):
        failure = f"centre view is {frames[0].height}x{frames[0].width} {frames[0].format.name}, header says {h}x{w}"
    if failure is not None:
        # raised outside the handler, unchained, the decoder and its frames freed first: an
        # error raised beside them would keep them alive as long as the caller keeps it
        # (lfstream.codec.residual's note)
        ctx = frames = None
        raise BitstreamError(failure, frame)
    return i420_to_rgb(frames[0].to_ndarray(format="yuv420p"))[:h, :w]


__all__ = ["AV1_SPEED_RANGE", "AV1_MIN_SIZE", "AV1_MIN_VIEW", "av1_fits",
           "av1_crf", "svt_crf", "SVT_CRF_FLOOR_FROM", "SVT_FAST_MIN_CRF",
           "rgb_to_i420", "i420_to_rgb", "pad_to_even",
           "svtav1_encoder", "quiet_svt_log", "svt_options", "SVT_X86_ASM",
           "AV1_THREADED_MIN_PIXELS", "encode_av1", "decode_av1", "max_av1_pixels"]
