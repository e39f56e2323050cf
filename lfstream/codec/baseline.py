"""Pseudo-sequence baselines: the views of a light field coded as the frames of one video.

The seed compares its codec with HEVC (x265) coding the views in raster order; AV1
(SVT-AV1) is the stronger modern anchor. Both run in-process through PyAV, on 8-bit
yuv420p (BT.601 limited range, as PyAV's default conversion, done by
:func:`lfstream.io.video.rgb_to_video_i420`, 1.7x faster than swscale), one closed GOP holding every
view of a frame, and the decoded views are measured with the same metrics as lfstream's
own output. Views are padded by edge replication to even size (4:2:0 needs it) and to at
least :data:`ENCODER_MIN_SIDE` on each side, and cropped after decoding; the padding's bits
are counted.

* HEVC: libx265, preset ``medium``, ``keyint = U*V`` (one intra frame, then P/B frames),
  constant QP (``qp``) or, to hit a target rate, a bisection on x265's fractional CRF.
* AV1: libsvtav1, preset 8, one key frame per LF, integer CRF 1..63 (bisection to the
  closest integer for a target rate).

Timing is not done here: callers (the benchmark harness) time ``encode``/``decode``.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from lfstream.codec.deadline import call_with_deadline, encoder_deadline
from lfstream.errors import LFValueError
from lfstream.io.video import rgb_to_video_i420
from lfstream.lightfield import check_lf, to_uint8

ORDERS = ("raster", "serpentine", "spiral")
#: Views narrower or lower than this are padded up to it before coding: one x265 CTU and one
#: SVT-AV1 superblock. Frames smaller than a block take the encoders' least exercised paths:
#: x265 (PyAV 18.1 wheel) writes past its heap in CRF mode on frames under 56 px wide
#: (valgrind: invalid writes in ``Lookahead::cuTree`` on 40x48 and 64x48 frames; glibc
#: aborts), and a CI run crashed (SIGSEGV) inside an encoder's flush on 34x48 views.
ENCODER_MIN_SIDE = 64


def view_order(u: int, v: int, order: str = "raster") -> list[tuple[int, int]]:
    """The order in which views become frames.

    ``raster``: row by row; ``serpentine``: rows alternately left-to-right and
    right-to-left (neighbouring frames are always neighbouring views); ``spiral``: from the
    centre view outwards, ring by ring.
    """
    if order == "raster":
        return [(a, b) for a in range(u) for b in range(v)]
    if order == "serpentine":
        return [(a, b if a % 2 == 0 else v - 1 - b) for a in range(u) for b in range(v)]
    if order == "spiral":
        u0, v0 = u // 2, v // 2
        seen, out = set(), []
        a, b = u0, v0
        out.append((a, b))
        seen.add((a, b))
        step, direction = 1, 0
        moves = [(0, 1), (1, 0), (0, -1), (-1, 0)]
        while len(out) < u * v:
            for _ in range(2):
                da, db = moves[direction % 4]
                for _ in range(step):
                    a, b = a + da, b + db
                    if 0 <= a < u and 0 <= b < v and (a, b) not in seen:
                        seen.add((a, b))
                        out.append((a, b))
                direction += 1
            step += 1
        return out
    raise LFValueError(f"order: one of {', '.join(ORDERS)}, got {order!r}")


@dataclass(frozen=True)
class PseudoSequenceCodec:
    """One video codec configuration for pseudo-sequence coding."""

    name: str
    encoder: str
    decoder: str
    container: str
    quality_range: tuple[float, float]  # bigger value = fewer bits
    fractional: bool

    def options(self, quality: float, gop: int, constant_qp: bool, preset: str | None = None) -> dict[str, str]:
        if self.name == "hevc":
            rc = f"qp={int(round(quality))}" if constant_qp else f"crf={quality:.3f}"
            return {"preset": preset or "medium",
                    "x265-params": f"{rc}:keyint={gop}:min-keyint={gop}:scenecut=0:log-level=error:frame-threads=1"}
        from lfstream.codec.centre.av1 import svt_options

        return {"preset": preset or "8", "crf": str(int(round(quality))), "g": str(gop), **svt_options()}


CODECS = {
    "hevc": PseudoSequenceCodec("hevc", "libx265", "hevc", "hevc", (0.0, 51.0), True),
    "av1": PseudoSequenceCodec("av1", "libsvtav1", "libdav1d", "ivf", (1.0, 63.0), False),
}


def _codec(name: str) -> PseudoSequenceCodec:
    if name not in CODECS:
        raise LFValueError(f"codec: one of {', '.join(CODECS)}, got {name!r}")
    return CODECS[name]


def coded_size(size: tuple[int, int]) -> tuple[int, int]:
    """The frame size views of ``size`` (H, W) are coded at: even, and at least
    :data:`ENCODER_MIN_SIDE` on each side (edge-replicated; decoding crops back)."""
    h, w = size
    return max(h + h % 2, ENCODER_MIN_SIDE), max(w + w % 2, ENCODER_MIN_SIDE)


def encode_views(lf: np.ndarray, codec: str = "hevc", quality: float = 34, order: str = "raster",
                 constant_qp: bool = True, preset: str | None = None) -> bytes:
    """Codes one LF frame ``(U, V, H, W, 3)`` as a pseudo-sequence; returns the bitstream.
    ``preset``: the encoder's speed preset (x265 ``medium`` and SVT-AV1 ``8`` by default)."""
    import av

    spec = _codec(codec)
    u, v, h, w, _ = check_lf(lf, allow_video=False)
    frame_lf = to_uint8(np.asarray(lf))
    ph, pw = coded_size((h, w))

    if spec.encoder == "libsvtav1":
        from lfstream.codec.centre.av1 import quiet_svt_log

        quiet_svt_log()

    def run() -> bytes:  # self-contained, so the deadline guard can retry it on a fresh encoder
        buf = io.BytesIO()
        with av.open(buf, mode="w", format=spec.container) as container:
            stream = container.add_stream(spec.encoder, rate=Fraction(25, 1),
                                          options=spec.options(quality, u * v, constant_qp, preset))
            stream.width, stream.height, stream.pix_fmt = pw, ph, "yuv420p"
            for a, b in view_order(u, v, order):
                frame = av.VideoFrame.from_ndarray(rgb_to_video_i420(frame_lf[a, b], (ph, pw)), format="yuv420p")
                for packet in stream.encode(frame):
                    container.mux(packet)
            for packet in stream.encode():
                container.mux(packet)
        return buf.getvalue()

    return call_with_deadline(run, encoder_deadline(u * v * ph * pw), f"{codec} pseudo-sequence")


def decode_views(data: bytes, codec: str, views: tuple[int, int], size: tuple[int, int], order: str = "raster") -> np.ndarray:
    """Decodes a pseudo-sequence back to ``(U, V, H, W, 3)`` uint8."""
    import av

    spec = _codec(codec)
    u, v = views
    h, w = size
    out = np.empty((u, v, h, w, 3), np.uint8)
    positions = view_order(u, v, order)
    k = 0
    with av.open(io.BytesIO(data), mode="r", format=spec.container) as container:
        for frame in container.decode(video=0):
            if k >= len(positions):
                break
            a, b = positions[k]
            out[a, b] = frame.to_ndarray(format="rgb24")[:h, :w]
            k += 1
    if k != len(positions):
        raise LFValueError(f"{codec} pseudo-sequence decoded {k} of {len(positions)} views")
    return out


@dataclass
class BaselineResult:
    codec: str
    order: str
    quality: float
    bytes: int
    bpp: float
    data: bytes
    constant_qp: bool = False  # how ``quality`` was applied (x265 QP instead of CRF)


def encode_at_bpp(lf: np.ndarray, codec: str, target_bpp: float, order: str = "raster", tolerance: float = 0.02,
                  max_steps: int = 14, preset: str | None = None) -> BaselineResult:
    """Searches the codec's quality parameter for the rate closest to ``target_bpp``.

    HEVC bisects x265's fractional CRF until within ``tolerance`` (relative); AV1 bisects
    integer CRF and returns the closest. The rate falls monotonically with the parameter.
    """
    from lfstream.metrics import bpp as bits_per_pixel  # metrics imports torch: only when searching

    spec = _codec(codec)
    if not (np.isfinite(target_bpp) and target_bpp > 0):
        raise LFValueError(f"target bpp must be positive, got {target_bpp!r}")
    lo, hi = spec.quality_range
    shape = np.asarray(lf).shape
    fractional = spec.fractional  # x265's CRF is fractional (views are padded to a safe size)
    best: BaselineResult | None = None
    for _ in range(max_steps):
        q = 0.5 * (lo + hi) if fractional else float(int(round(0.5 * (lo + hi))))
        data = encode_views(lf, codec, q, order, constant_qp=False, preset=preset)
        rate = bits_per_pixel(len(data), shape)
        res = BaselineResult(codec, order, q, len(data), rate, data)
        if best is None or abs(rate - target_bpp) < abs(best.bpp - target_bpp):
            best = res
        if abs(rate - target_bpp) <= tolerance * target_bpp:
            break
        if rate > target_bpp:
            lo = q
        else:
            hi = q
        if not fractional and hi - lo <= 1:
            for q2 in (lo, hi):
                data = encode_views(lf, codec, q2, order, constant_qp=False, preset=preset)
                rate = bits_per_pixel(len(data), shape)
                if abs(rate - target_bpp) < abs(best.bpp - target_bpp):
                    best = BaselineResult(codec, order, q2, len(data), rate, data)
            break
    assert best is not None
    return best


__all__ = ["ORDERS", "CODECS", "ENCODER_MIN_SIDE", "coded_size",
           "view_order", "encode_views", "decode_views", "encode_at_bpp", "BaselineResult"]
